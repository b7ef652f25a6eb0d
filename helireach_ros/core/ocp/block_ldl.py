"""IPOPT's linear solver for the landing NLPs: a block LDL^T built from ``block_ldl.c``, or MUMPS.

Every IPOPT iteration solves the augmented (KKT) system

.. math::

    \\begin{bmatrix} W + \\Sigma + \\delta_x I & J^T \\\\ J & -\\delta_c I \\end{bmatrix}
    \\begin{bmatrix} \\Delta x \\\\ \\Delta \\lambda \\end{bmatrix} = -\\begin{bmatrix} \\nabla L \\\\ c \\end{bmatrix}

and needs its inertia (n positive, m negative eigenvalues) to know whether to regularise. For the landing NLPs
(~930 rows, ~8 k non-zeros, block-banded over the collocation intervals) MUMPS spent most of an iteration on it.
``block_ldl.c`` pairs each multiplier with a primal variable of its constraint whose Jacobian entry is large
(relative to the constraint's largest; chosen at the first factorization of each solve), eliminates each pair as
one 2×2 pivot in a minimum-degree block order, and reads the inertia off the 2×2 pivots (Sylvester's law of
inertia). It implements MA27's four routines, so IPOPT loads it with its own options ``linear_solver ma27`` and
``hsllib <library>``; HSL itself is not used.

Measured (docs/decisions/block-ldl.md): 0.46–0.50× of MUMPS's IPOPT time on flyable plans with about the
same iterations and the same statuses and replay verdicts at 60 of 60 states, the 41 × 25 envelope classified
identically at all 1025 nodes, and the inertia right in every checked factorization. It is a performance choice
like the compiled NLP functions (:class:`~helireach_ros.core.ocp.compiled_nlp.CodegenSettings`, not the planner
settings): every plan called safe is still checked by the independent replay, so a poor factorization could cost
iterations but never make a state safe.

The library is compiled once per source (``-O2``, ~1 s) into the NLP cache folder the first time a planner is
built (never inside a solve; ``make nlp-cache`` builds it ahead of time) and loaded only while its checksum
matches. Without a C compiler, or if the build fails, IPOPT uses MUMPS and :func:`linear_solver_options` says why.
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

from helireach_ros.core.ocp.compiled_nlp import CodegenSettings, compile_into_cache, library_intact

__all__ = ["SOURCE", "block_ldl_library", "block_ldl_library_path", "linear_solver_options"]

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("block_ldl.c")
"""The C source of the block LDL^T."""
_FLAGS = ("-O2",)  # the flags it was measured with
_LIBRARIES = ("-lm", "-lpthread")


def block_ldl_library_path(settings: CodegenSettings) -> Path:
    """Where the library built from :data:`SOURCE` by ``settings.compiler`` lives (whether or not it exists)."""
    digest = hashlib.sha256()
    for part in (SOURCE.read_bytes(), settings.compiler.encode(), *(flag.encode() for flag in _FLAGS)):
        digest.update(part)
        digest.update(b"\0")
    return Path(settings.cache_dir) / f"block_ldl_{digest.hexdigest()[:32]}.so"


def block_ldl_library(settings: CodegenSettings) -> Path:
    """The compiled block LDL^T, built into the cache first if it is missing or does not match its checksum.

    Raises:
        RuntimeError: the compiler is missing or fails; OSError: the cache folder cannot be written.
    """
    path = block_ldl_library_path(settings)
    if path.is_file() and library_intact(path):
        return path
    return compile_into_cache(SOURCE, path, settings.compiler, _FLAGS, _LIBRARIES)


def linear_solver_options(settings: CodegenSettings) -> tuple[dict[str, str], str]:
    """IPOPT options selecting ``settings.linear_solver``, and a description of the solver in use.

    Never raises for a missing compiler or a failed build: IPOPT then keeps MUMPS, and the description says why.
    """
    if settings.linear_solver == "mumps":
        return {}, "MUMPS"
    try:
        library = block_ldl_library(settings)
    except (RuntimeError, OSError) as error:
        log.warning("block LDL^T unavailable, IPOPT uses MUMPS: %s", error)
        return {}, f"MUMPS (block LDL^T unavailable: {error})"
    return {"ipopt.linear_solver": "ma27", "ipopt.hsllib": str(library)}, f"block LDL^T {library}"
