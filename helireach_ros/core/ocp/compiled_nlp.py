"""Compiled NLP functions: C code generated from a landing NLP, built once and cached by the NLP's hash.

IPOPT spends part of every iteration evaluating the NLP's functions (objective, constraints, their
derivatives and the Lagrangian Hessian). CasADi can generate C code for them; compiled with a C
compiler, the same functions run in a shared library instead of CasADi's virtual machine. The answers
are the same functions, so this is a *performance-only* choice: it is not part of
:class:`~helireach_ros.core.ocp.settings.PlannerSettings` and does not invalidate an envelope file.

The cache key is the SHA-256 of the NLP (CasADi's serialisation of f and g as functions of the decision
vector and the parameter), the CasADi version, the compiler and its flags: any change of the airframe,
the settings or the transcription code gives another key, so a stale library is never loaded. Each
library is stored with the SHA-256 of its bytes and loaded only if it still matches (a damaged shared
library can crash the process that loads it).

Modes (:class:`CodegenSettings`, from the environment by default):

- ``cached`` (default): use the compiled library if the cache holds one for this NLP, otherwise the plain
  functions (and say so in :attr:`NlpFunctions.description`). Never compiles: a planner that finds no
  library starts at once and works, slower.
- ``build``: compile at first use if the cache has no library (tens of seconds; ``make nlp-cache`` runs
  this ahead of time). A failed build (no compiler, a bad ``CC``) falls back to the plain functions.
- ``off``: always the plain functions.

Building happens only where a planner is constructed (start-up), never inside a solve.
Run ``helireach nlp-cache`` (``make nlp-cache``) to build the library for the default airframe and settings.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shlex
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca

__all__ = [
    "CODEGEN_MODES",
    "LINEAR_SOLVERS",
    "CodegenSettings",
    "NlpFunctions",
    "build_library",
    "compile_into_cache",
    "ipopt_solvers",
    "library_intact",
    "library_path",
    "nlp_functions",
    "nlp_key",
]

log = logging.getLogger(__name__)

CODEGEN_MODES = ("cached", "build", "off")
LINEAR_SOLVERS = ("block_ldl", "mumps")
"""IPOPT's linear solver for the KKT systems: the package's block LDL^T (:mod:`helireach_ros.core.ocp.block_ldl`, the
default; MUMPS wherever it cannot be built) or MUMPS."""
_DEFAULT_FLAGS = ("-O1",)  # measured: as fast as -O2 for these functions, and compiles in ~11 s instead of ~27 s


def _default_cache_dir() -> str:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "helireach_ros", "nlp")


@dataclass(frozen=True)
class CodegenSettings:
    """Whether and how the NLP functions are compiled (performance only; see the module docstring).

    Attributes:
        mode: ``"cached"``, ``"build"`` or ``"off"``.
        cache_dir: where compiled libraries live (one ``<key>.so`` per NLP, one per block LDL^T source).
        compiler: the C compiler command.
        flags: compiler flags (``-shared -fPIC`` are always added).
        linear_solver: one of :data:`LINEAR_SOLVERS`. Also performance only: the same KKT systems are solved, and
            every plan called safe is still replayed (measured: the same statuses and replay verdicts).
    """

    mode: str = "cached"
    cache_dir: str = field(default_factory=_default_cache_dir)
    compiler: str = "gcc"
    flags: tuple[str, ...] = _DEFAULT_FLAGS
    linear_solver: str = "block_ldl"

    def __post_init__(self) -> None:
        if self.mode not in CODEGEN_MODES:
            raise ValueError(f"code generation mode must be one of {CODEGEN_MODES}, got {self.mode!r}")
        if self.linear_solver not in LINEAR_SOLVERS:
            raise ValueError(f"linear solver must be one of {LINEAR_SOLVERS}, got {self.linear_solver!r}")
        if not self.compiler.strip():
            raise ValueError("the C compiler command must not be empty")
        if not isinstance(self.flags, tuple):
            raise ValueError("compiler flags must be a tuple of strings")

    @classmethod
    def from_environment(cls) -> CodegenSettings:
        """``HELIREACH_NLP_CODEGEN`` (mode), ``HELIREACH_NLP_CACHE`` (directory), ``CC``, ``HELIREACH_NLP_CFLAGS``,
        ``HELIREACH_LINEAR_SOLVER``."""
        flags = os.environ.get("HELIREACH_NLP_CFLAGS")
        return cls(
            mode=os.environ.get("HELIREACH_NLP_CODEGEN", "cached"),
            cache_dir=os.environ.get("HELIREACH_NLP_CACHE") or _default_cache_dir(),
            compiler=os.environ.get("CC") or "gcc",
            flags=tuple(shlex.split(flags)) if flags else _DEFAULT_FLAGS,
            linear_solver=os.environ.get("HELIREACH_LINEAR_SOLVER") or "block_ldl",
        )


@dataclass(frozen=True)
class NlpFunctions:
    """What :func:`nlp_functions` gives ``nlpsol``: the symbolic NLP or a compiled library, and what it is."""

    source: dict | str
    compiled: bool
    description: str


def nlp_key(nlp: dict, settings: CodegenSettings) -> str:
    """SHA-256 of the NLP (f, g of x and p), the CasADi version, the compiler and its flags."""
    function = ca.Function("landing_nlp", [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]])
    digest = hashlib.sha256()
    for part in (function.serialize(), ca.CasadiMeta.version(), settings.compiler, *settings.flags):
        digest.update(part.encode())
        digest.update(b"\0")
    return digest.hexdigest()


def library_path(nlp: dict, settings: CodegenSettings) -> Path:
    """Where the compiled library for this NLP lives (whether or not it exists)."""
    return Path(settings.cache_dir) / f"landing_nlp_{nlp_key(nlp, settings)[:32]}.so"


def build_library(nlp: dict, settings: CodegenSettings) -> Path:
    """Generates C code for the NLP's functions and compiles it into the cache (atomically).

    Raises:
        RuntimeError: the compiler is missing or fails (the message says which and why).
    """
    target = library_path(nlp, settings)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=".generate-") as work:
        solver = ca.nlpsol("landing_nlp", "ipopt", nlp, {"print_time": False})
        # generate_dependencies writes into the working directory; a relative name in a private folder
        source = "landing_nlp.c"
        previous = os.getcwd()
        try:
            os.chdir(work)
            solver.generate_dependencies(source)
        finally:
            os.chdir(previous)
        return compile_into_cache(Path(work) / source, target, settings.compiler, settings.flags)


def compile_into_cache(
    source: Path, target: Path, compiler: str, flags: Sequence[str], libraries: Sequence[str] = ()
) -> Path:
    """Compiles one C file into the shared library ``target`` with a checksum beside it (:func:`library_intact`).

    Both files appear by atomic renames: a concurrent process sees no library, a whole one, or one whose checksum
    does not match yet (then it does not load it); never a half-written file.

    Raises:
        RuntimeError: the compiler is missing or fails (the message says which and why).
    """
    command_start = shlex.split(compiler)
    if not command_start or shutil.which(command_start[0]) is None:
        raise RuntimeError(f"C compiler {compiler!r} not found")
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=".build-") as work:
        built = Path(work) / target.name
        command = [*command_start, *flags, "-shared", "-fPIC", str(source), "-o", str(built), *libraries]
        try:
            result = subprocess.run(command, capture_output=True, text=True, check=False)
        except OSError as error:
            raise RuntimeError(f"cannot run {compiler!r}: {error}") from None
        if result.returncode != 0:
            raise RuntimeError(f"{shlex.join(command)} failed: {result.stderr.strip()[-500:]}")
        checksum = Path(work) / "checksum"
        checksum.write_text(_file_digest(built) + "\n")
        os.replace(built, target)
        os.replace(checksum, _checksum_path(target))
    return target


def _checksum_path(library: Path) -> Path:
    return library.with_name(library.name + ".sha256")


def _file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def library_intact(library: Path) -> bool:
    """The library matches the checksum written with it: loading a truncated or damaged shared library can
    crash the process (SIGBUS in the dynamic loader), so it is checked before ``dlopen``."""
    try:
        return _checksum_path(library).read_text().strip() == _file_digest(library)
    except OSError:
        return False


def nlp_functions(nlp: dict, settings: CodegenSettings | None = None) -> NlpFunctions:
    """The NLP for ``nlpsol``: the compiled library when the cache has it (or ``build`` mode makes it), else plain.

    Never raises for a missing or failing compiler: the plain functions always work, and
    :attr:`NlpFunctions.description` says which kind is in use and why.
    """
    settings = settings or CodegenSettings.from_environment()
    if settings.mode == "off":
        return NlpFunctions(nlp, False, "plain CasADi functions (code generation off)")
    path = library_path(nlp, settings)
    if path.is_file() and not library_intact(path):
        if settings.mode == "cached":
            return NlpFunctions(nlp, False, f"plain CasADi functions ({path} does not match its checksum)")
        log.warning("%s does not match its checksum: rebuilding it", path)
    if not path.is_file() or not library_intact(path):
        if settings.mode == "cached":
            return NlpFunctions(
                nlp, False, f"plain CasADi functions (no compiled library {path.name} in {settings.cache_dir}; "
                "build it with 'make nlp-cache')"
            )  # fmt: skip
        try:
            build_library(nlp, settings)
        except (RuntimeError, OSError) as error:
            log.warning("NLP code generation failed, using the plain functions: %s", error)
            return NlpFunctions(nlp, False, f"plain CasADi functions (build failed: {error})")
    return NlpFunctions(str(path), True, f"compiled library {path}")


def ipopt_solvers(
    nlp: dict, options: dict[str, dict], settings: CodegenSettings | None = None
) -> tuple[dict[str, ca.Function], str]:
    """One IPOPT solver per option set, all on the same NLP functions (compiled when available).

    A library that exists but does not load (truncated, another architecture) is reported and the plain
    functions are used instead, so a broken cache never stops a planner.

    Returns:
        The solvers by name, and the description of the functions they use.
    """
    functions = nlp_functions(nlp, settings)
    if functions.compiled:
        try:
            return {name: ca.nlpsol(name, "ipopt", functions.source, opts) for name, opts in options.items()}, (
                functions.description
            )
        except RuntimeError as error:
            log.warning("cannot load %s, using the plain functions: %s", functions.source, error)
            functions = NlpFunctions(nlp, False, f"plain CasADi functions (cannot load {functions.source})")
    return {name: ca.nlpsol(name, "ipopt", nlp, opts) for name, opts in options.items()}, functions.description
