"""What the bench scripts share: percentile summaries, the failure-state grids, the run's provenance (command,
commit, machine, date, load) and the JSON record the results pages are generated from.

Imported by the bench scripts (which run with ``bench/`` on ``sys.path``). A bench given ``--json`` writes
``docs/results/data/<bench>.json`` (:func:`write_record`): its numbers, exactly what it prints, with the command
that reproduces them, the commit, the UTC date, the machine and the load average before and after;
``bench/results_pages.py`` turns those files into the results pages.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import os
import platform
import shlex
import subprocess
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from helireach_ros.core.envelope.grid import parse_range
from helireach_ros.core.units import FT, KT

__all__ = [
    "COARSE_GRID",
    "DATA_DIR",
    "ENVELOPE_GRID",
    "REPOSITORY",
    "Record",
    "StateGrid",
    "add_json_argument",
    "command_line",
    "git_commit",
    "loadavg_text",
    "machine",
    "machine_text",
    "results_footer",
    "summary",
    "summary_text",
    "utc_date",
    "wilson_interval",
    "write_record",
]

REPOSITORY = Path(__file__).resolve().parent.parent
"""The repository's root (``bench/`` is one of its folders)."""

DATA_DIR = REPOSITORY / "docs" / "results" / "data"
"""Where ``--json`` writes each bench's record and ``bench/results_pages.py`` reads them."""


# --- numbers ------------------------------------------------------------------------------------------------------


def summary(values: Iterable[float], *, tails: bool = False) -> dict[str, float | int | None]:
    """``median``, ``p95`` and ``max`` of ``values`` (NaNs dropped; ``None`` when nothing is left) and ``n``, the
    number of values summarised; with ``tails`` also ``min`` and ``p5``. Percentiles interpolate linearly
    (``numpy.percentile``'s default), so ``median`` is the p50 the benches print."""
    data = np.asarray([value for value in values if not math.isnan(value)], dtype=float)
    quantiles = {"min": 0, "p5": 5, "median": 50, "p95": 95, "max": 100} if tails else {"median": 50, "p95": 95}
    if not data.size:
        return {**dict.fromkeys(quantiles, None), "max": None, "n": 0}
    result: dict[str, float | int | None] = {
        name: float(value) for name, value in zip(quantiles, np.percentile(data, list(quantiles.values())), strict=True)
    }
    result["max"] = float(data.max())
    result["n"] = int(data.size)
    return result


def wilson_interval(successes: int, runs: int, z: float = 1.959964) -> tuple[float, float]:
    """The Wilson score interval for a binomial proportion (95 % for the default z).

    .. math:: \\frac{p + z^2/2n \\pm z\\sqrt{p(1-p)/n + z^2/4n^2}}{1 + z^2/n}
    """
    if runs == 0:
        return 0.0, 1.0
    p = successes / runs
    centre = p + z * z / (2 * runs)
    spread = z * math.sqrt(p * (1 - p) / runs + z * z / (4 * runs * runs))
    scale = 1 + z * z / runs
    return max(0.0, (centre - spread) / scale), min(1.0, (centre + spread) / scale)


def summary_text(stats: Mapping[str, float | int | None], *, width: int = 6, unit: str = "ms", n: bool = True) -> str:
    """A :func:`summary` as the benches print it: ``p50 … ms  p95 … ms  max … ms  (n = …)``; ``none`` if empty."""
    if not stats["n"]:
        return "none"
    labels = {"p50": "median", "p95": "p95", "max": "max"}
    text = "  ".join(f"{label} {stats[key]:{width}.1f} {unit}" for label, key in labels.items())
    return f"{text}  (n = {stats['n']})" if n else text


# --- failure states -----------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class StateGrid:
    """Failure states on an evenly spaced grid over height (ft) × speed (kt), each axis ``start:stop:count``
    (inclusive, as ``helireach envelope compute --heights-ft/--speeds-kt`` take it)."""

    heights_ft: str
    speeds_kt: str

    @classmethod
    def of_about(cls, count: int, lowest_ft: float = 10.0) -> StateGrid:
        """About ``count`` states over ``lowest_ft``–800 ft × 0–120 kt, rows and columns in the plane's proportion."""
        rows = max(2, round(float(np.sqrt(count * 8 / 12))))
        columns = max(2, math.ceil(count / rows))
        return cls(f"{lowest_ft:g}:800:{rows}", f"0:120:{columns}")

    def heights(self) -> tuple[float, ...]:
        """The heights in ft."""
        return parse_range(self.heights_ft, name="heights (ft)")

    def speeds(self) -> tuple[float, ...]:
        """The speeds in kt."""
        return parse_range(self.speeds_kt, name="speeds (kt)")

    def heights_si(self) -> tuple[float, ...]:
        """The heights in m (what :class:`~helireach_ros.core.envelope.compute.EnvelopeJob` takes)."""
        return parse_range(self.heights_ft, FT, "heights (ft)")

    def speeds_si(self) -> tuple[float, ...]:
        """The speeds in m/s."""
        return parse_range(self.speeds_kt, KT, "speeds (kt)")

    def cells(self, serpentine: bool = False) -> list[tuple[float, float]]:
        """(height ft, speed kt) of every node, row by row (height outer); ``serpentine``: every other row
        reversed, so that consecutive states are neighbours."""
        speeds = self.speeds()
        return [
            (height, speed)
            for row, height in enumerate(self.heights())
            for speed in (speeds[::-1] if serpentine and row % 2 else speeds)
        ]

    def describe(self) -> str:
        """``heights 0-800 ft x 17, speeds 0-120 kt x 13``."""
        (low_h, high_h, rows), (low_v, high_v, columns) = self.heights_ft.split(":"), self.speeds_kt.split(":")
        return f"heights {low_h}-{high_h} ft x {rows}, speeds {low_v}-{high_v} kt x {columns}"


ENVELOPE_GRID = StateGrid("0:800:41", "0:120:25")
"""The default envelope's level-flight grid (``helireach envelope compute``'s defaults)."""

COARSE_GRID = StateGrid("0:800:17", "0:120:13")
"""A quarter of the envelope grid's resolution per axis: the benches that solve every node several times."""


# --- provenance ---------------------------------------------------------------------------------------------------


def loadavg_text() -> str:
    """``os.getloadavg()`` as printed by the benches (1, 5 and 15 minutes)."""
    return " ".join(f"{load:.2f}" for load in os.getloadavg())


def git_commit() -> str:
    """``git rev-parse --short HEAD``, with ``-dirty`` when the working tree differs from it (generated results
    under ``docs/results/`` do not count); ``unknown`` outside a git checkout."""

    def git(*arguments: str) -> str:
        return subprocess.run(["git", *arguments], capture_output=True, text=True, cwd=REPOSITORY).stdout.strip()

    commit = git("rev-parse", "--short", "HEAD")
    if not commit:
        return "unknown"
    return commit + ("-dirty" if git("status", "--porcelain", "--", ".", ":(exclude)docs/results") else "")


def machine() -> dict[str, str | int]:
    """The CPU model (``/proc/cpuinfo``'s model name, else ``platform``'s), its CPU count and the Python version."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            model = next((line.split(":", 1)[1].strip() for line in cpuinfo if line.startswith("model name")), model)
    except OSError:
        pass
    return {"cpu": model, "cpus": os.cpu_count() or 0, "python": platform.python_version()}


def machine_text(description: Mapping[str, str | int] | None = None) -> str:
    """``Intel(R) Xeon(R) Processor, 2 CPUs, Python 3.11.2``: :func:`machine` (or ``description``) in a line."""
    description = description or machine()
    return f"{description['cpu']}, {description['cpus']} CPUs, Python {description['python']}"


def utc_date() -> str:
    """The UTC date and time to the minute, ``2026-12-04 17:31 UTC``."""
    return datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")


def command_line(argv: list[str] | None = None) -> str:
    """The command that reproduces this run from the repository's root: ``.venv/bin/python bench/<script> …``."""
    argv = sys.argv if argv is None else argv
    return shlex.join([".venv/bin/python", f"bench/{Path(argv[0]).name}", *argv[1:]])


def results_footer(load_before: str, *details: str) -> str:
    """The line a results page a bench writes itself ends with: the command that reproduces it, the commit, the
    date, the load average before and after, and ``details``."""
    parts = [f"Command: `{command_line()}`", f"commit {git_commit()}", utc_date(),
             f"load {load_before} → {loadavg_text()}", *details]  # fmt: skip
    return "; ".join(parts) + "."


# --- records ------------------------------------------------------------------------------------------------------


def add_json_argument(parser: argparse.ArgumentParser) -> None:
    """The benches' ``--json`` flag."""
    parser.add_argument(
        "--json",
        action="store_true",
        help="also write the numbers to docs/results/data/<bench>.json (bench/results_pages.py reads them)",
    )


def _plain(value: object) -> object:
    """``value`` as JSON can hold it: numpy scalars and arrays as Python numbers and lists, floats to 6 significant
    digits, NaN and infinities as ``None``, tuples as lists, mapping keys as strings."""
    if isinstance(value, Mapping):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_plain(item) for item in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(f"{value:.6g}") if math.isfinite(value) else None
    return value


def write_record(
    name: str,
    command: str,
    numbers: Mapping[str, object],
    *,
    out_dir: Path = DATA_DIR,
    load_before: str | None = None,
    commit: str | None = None,
    date_utc: str | None = None,
) -> Path:
    """Writes ``<out_dir>/<name>.json``: ``bench``, ``command``, ``commit``, ``date_utc``, ``machine``,
    ``load_before``, ``load_after`` and ``numbers`` (what the bench printed). Provenance not given is taken now;
    :class:`Record` takes it when a run starts. Returns the path."""
    record = {
        "bench": name,
        "command": command,
        "commit": commit or git_commit(),
        "date_utc": date_utc or utc_date(),
        "machine": machine(),
        "load_before": load_before or loadavg_text(),
        "load_after": loadavg_text(),
        "numbers": _plain(numbers),
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{name}.json"
    path.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
    return path


@dataclasses.dataclass(frozen=True)
class Record:
    """A bench run's provenance, taken when it starts (:meth:`start`); :meth:`write` adds the numbers and the load
    average at the end."""

    bench: str
    command: str
    commit: str
    date_utc: str
    load_before: str

    @classmethod
    def start(cls, argv: list[str] | None = None) -> Record:
        """This run: the bench named after its script, the command that reproduces it, the commit, date and load."""
        argv = sys.argv if argv is None else argv
        return cls(Path(argv[0]).stem, command_line(argv), git_commit(), utc_date(), loadavg_text())

    def write(self, numbers: Mapping[str, object], *, out_dir: Path = DATA_DIR) -> Path:
        """:func:`write_record` with this run's provenance; prints where it wrote."""
        path = write_record(
            self.bench, self.command, numbers, out_dir=out_dir, load_before=self.load_before, commit=self.commit,
            date_utc=self.date_utc,
        )  # fmt: skip
        print(f"record: {path.relative_to(REPOSITORY) if path.is_relative_to(REPOSITORY) else path}")
        return path
