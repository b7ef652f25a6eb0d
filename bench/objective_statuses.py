"""Does the reach-avoid objective call the same states safe as the touchdown cost, and what does it cost?

Run: nice -n 10 .venv/bin/python bench/objective_statuses.py [--heights 17] [--speeds 13] [--no-envelope]
     [--workers 2] [--json]
     after ``helireach nlp-cache --objective reach_avoid`` (both objectives' NLPs compiled; the run says which ran
     on which functions, and warns when only one was compiled)

Two checks, one run:

1. **The replay-failure grid** (0–800 ft × 0–120 kt, 17 × 13 = 221 failure states, total power loss, the default
   airframe and settings): every state solved cold with ``objective: terminal`` and ``objective: reach_avoid``; the
   statuses (safe / unsafe / unverified / failed) compared state by state, the reach-avoid plan's worst margin and
   the summed and median solve times as a ratio in the same run.
2. **The shipped envelope's level slice** (41 × 25 = 1,025 nodes): the level slice recomputed by
   ``helireach envelope compute`` with ``objective: reach_avoid`` (the same procedure as the shipped file: warm starts
   along columns, cold re-checks, bisected boundary) and compared node by node with the shipped file's statuses.

Every state whose status differs is listed with both values. ``--json`` writes
docs/results/data/objective_statuses.json.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from _common import COARSE_GRID, REPOSITORY, Record, add_json_argument, loadavg_text, summary

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.units import FT, KT

OBJECTIVES = ("terminal", "reach_avoid")


def replay_grid(heights: int, speeds: int) -> dict:
    """Both objectives over the grid, cold; returns the compared statuses and times."""
    airframe, settings = load_airframe("uh60a_class"), load_settings(None)
    planners = {name: get_planner(airframe, settings.replace(objective=name)) for name in OBJECTIVES}
    functions = {name: planner.nlp_functions for name, planner in planners.items()}
    compiled = {name: description.startswith("compiled") for name, description in functions.items()}
    for name in OBJECTIVES:
        print(f"  {name:12} NLP on {functions[name]}")
    if len(set(compiled.values())) > 1:
        # compiled functions solve several times faster than plain ones: the ratio would measure that instead
        print(
            "  WARNING: one objective's NLP is compiled and the other's is not; build both with "
            "'helireach nlp-cache --objective reach_avoid' for a solve-time ratio of the objectives"
        )
    grid_heights = np.linspace(0.0, 800.0, heights)
    grid_speeds = np.linspace(0.0, 120.0, speeds)
    times: dict[str, list[float]] = {name: [] for name in OBJECTIVES}
    counts: dict[str, dict[str, int]] = {name: {} for name in OBJECTIVES}
    changed, worst_margins = [], []
    for height_ft in grid_heights:
        for speed_kt in grid_speeds:
            state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT)
            plans = {}
            for name, planner in planners.items():
                started = time.perf_counter()
                plans[name] = planner.plan(state)
                times[name].append(time.perf_counter() - started)
                counts[name][plans[name].status] = counts[name].get(plans[name].status, 0) + 1
            terminal, reach_avoid = plans["terminal"], plans["reach_avoid"]
            if reach_avoid.solver.success and reach_avoid.status == "safe":
                worst_margins.append(float(reach_avoid.warm_start.primal[1]))
            if terminal.status != reach_avoid.status:
                changed.append(
                    {"height_ft": float(height_ft), "speed_kt": float(speed_kt), "terminal": terminal.status,
                     "reach_avoid": reach_avoid.status, "terminal_value": terminal.value,
                     "reach_avoid_value": reach_avoid.value}
                )  # fmt: skip
    ratio_sum = sum(times["reach_avoid"]) / sum(times["terminal"])
    ratio_median = float(np.median(times["reach_avoid"]) / np.median(times["terminal"]))
    print(f"\n== replay-failure grid: {heights} x {speeds} = {heights * speeds} states, cold solves ==")
    for name in OBJECTIVES:
        print(f"  {name:12} statuses {dict(sorted(counts[name].items()))}; solve s: {_describe(times[name])}")
    print(f"  reach_avoid / terminal solve time: summed {ratio_sum:.2f}x, median {ratio_median:.2f}x")
    print(f"  reach-avoid worst margin of the safe plans: {_describe(worst_margins)}")
    print(f"  states whose status differs: {len(changed)}")
    for row in changed:
        print(
            f"    {row['height_ft']:5.0f} ft {row['speed_kt']:5.0f} kt: terminal {row['terminal']} "
            f"(J {row['terminal_value']:+.3f}), reach_avoid {row['reach_avoid']} (J {row['reach_avoid_value']:+.3f})"
        )
    return {
        "states": heights * speeds, "counts": counts, "changed": changed,
        "solve_s": {name: summary(times[name]) for name in OBJECTIVES},
        "solve_time_ratio": {"summed": ratio_sum, "median": ratio_median},
        "nlp_compiled": compiled,
        "worst_margin": summary(worst_margins) if worst_margins else {},
    }  # fmt: skip


def envelope_level_slice(workers: int) -> dict:
    """The shipped file's level slice against a reach-avoid envelope computed the same way."""
    shipped = load_envelope(default_envelope_path())
    level = int(np.argmin(np.abs(shipped.climb_rates))) if shipped.is_3d else None
    stored = shipped.status[level] if level is not None else shipped.status
    metadata = shipped.metadata
    grid = metadata.get("grid", {})
    with tempfile.TemporaryDirectory() as folder:
        settings_file = Path(folder) / "planner.yaml"
        document = yaml.safe_load((REPOSITORY / "config" / "planner.yaml").read_text())
        document["objective"] = "reach_avoid"
        settings_file.write_text(yaml.safe_dump(document))
        out = Path(folder) / "reach_avoid_level.npz"
        command = [
            sys.executable, "-m", "helireach_ros.cli.main", "envelope", "compute", "--settings", str(settings_file),
            "--heights-ft", grid.get("heights_ft", "0:800:41"), "--speeds-kt", grid.get("speeds_kt", "0:120:25"),
            "--workers", str(workers), "--quiet", "--out", str(out),
        ]  # fmt: skip
        started = time.perf_counter()
        subprocess.run(command, check=True)
        wall = time.perf_counter() - started
        computed = load_envelope(out)
    heights_ft, speeds_kt = computed.heights / FT, computed.speeds / KT
    changed = []
    for row, column in zip(*np.nonzero(computed.status != stored), strict=True):
        changed.append(
            {"height_ft": float(heights_ft[row]), "speed_kt": float(speeds_kt[column]),
             "shipped": str(stored[row, column]), "reach_avoid": str(computed.status[row, column])}
        )  # fmt: skip
    counts = {
        name: {str(s): int(np.sum(statuses == s)) for s in np.unique(statuses)}
        for name, statuses in (("shipped", stored), ("reach_avoid", computed.status))
    }
    print(f"\n== shipped envelope's level slice: {stored.size} nodes, reach-avoid envelope in {wall:.0f} s ==")
    for name, count in counts.items():
        print(f"  {name:12} statuses {count}")
    print(f"  nodes whose status differs: {len(changed)}")
    for row in changed:
        print(f"    {row['height_ft']:5.0f} ft {row['speed_kt']:5.0f} kt: shipped {row['shipped']}, "
              f"reach_avoid {row['reach_avoid']}")  # fmt: skip
    return {"nodes": int(stored.size), "counts": counts, "changed": changed, "wall_s": wall}


def _describe(values: list[float]) -> str:
    if not values:
        return "none"
    stats = summary(values, tails=True)
    return f"median {stats['median']:.3f}, min {stats['min']:.3f}, max {stats['max']:.3f} (n {len(values)})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--heights", type=int, default=len(COARSE_GRID.heights()))
    parser.add_argument("--speeds", type=int, default=len(COARSE_GRID.speeds()))
    parser.add_argument("--no-envelope", action="store_true", help="skip the level-slice envelope")
    parser.add_argument("--workers", type=int, default=2, help="the envelope's local processes")
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    print(f"command: {record.command}; load average {record.load_before}")
    numbers = {"replay_grid": replay_grid(arguments.heights, arguments.speeds)}
    print(f"load average {loadavg_text()}")
    if not arguments.no_envelope:
        numbers["level_slice"] = envelope_level_slice(arguments.workers)
    print(f"load average at the end {loadavg_text()}")
    if arguments.json:
        record.write(numbers)


if __name__ == "__main__":
    main()
