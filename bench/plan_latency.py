"""Solve-time percentiles of landing plans across the H-V plane, cold and warm, for both methods.

Run: .venv/bin/python bench/plan_latency.py [--states 60] [--airframe uh60a_class]

"Cold" solves start from the transcription's generic guess. Two warm starts are timed:
"warm, half a cell" starts from the plan of a state 10 ft and 2.5 kt away — half a cell of the
default 41 × 25 envelope grid, the farthest the planner node's nearest stored plan can be — and
"warm, far neighbour" starts from the previous state of a serpentine walk over this coarse grid
(~100 ft / ~17 kt away). Times are IPOPT wall time per solve; the replay, which follows every
solve, is timed separately. Prints what it measured on this machine.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from helireach_ros.core.airframe import load_airframe
from helireach_ros.core.model import initial_state_after_failure
from helireach_ros.core.planner import get_planner
from helireach_ros.core.settings import load_settings
from helireach_ros.core.units import FT, KT


def _serpentine_grid(count: int) -> list[tuple[float, float]]:
    """About ``count`` (height ft, speed kt) points over 0–800 ft × 0–120 kt, neighbours consecutive."""
    rows = max(2, round(float(np.sqrt(count * 8 / 12))))
    columns = max(2, int(np.ceil(count / rows)))
    heights = np.linspace(10.0, 800.0, rows)
    speeds = np.linspace(0.0, 120.0, columns)
    points = []
    for row, height in enumerate(heights):
        ordered = speeds if row % 2 == 0 else speeds[::-1]
        points.extend((float(height), float(speed)) for speed in ordered)
    return points


def _percentiles(samples: list[float]) -> str:
    array = np.asarray(samples)
    p50, p95 = np.percentile(array, [50, 95])
    return f"p50 {p50:7.1f} ms   p95 {p95:7.1f} ms   max {array.max():7.1f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=60)
    parser.add_argument("--airframe", default="uh60a_class")
    arguments = parser.parse_args()
    airframe = load_airframe(arguments.airframe)
    points = _serpentine_grid(arguments.states)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; {len(points)} states")
    for method in ("verified", "paper"):
        settings = load_settings(method=method)
        started = time.perf_counter()
        planner = get_planner(airframe, settings)
        build_s = time.perf_counter() - started
        cold, warm_near, warm_far, replay, statuses = [], [], [], [], {}
        previous = None
        for height_ft, speed_kt in points:
            state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT)
            started = time.perf_counter()
            cold_plan = planner.plan(state)
            total_ms = 1e3 * (time.perf_counter() - started)
            cold.append(cold_plan.solver.solve_time_ms)
            replay.append(total_ms - cold_plan.solver.solve_time_ms)
            nearby = initial_state_after_failure(airframe, (height_ft + 10.0) * FT, (speed_kt + 2.5) * KT)
            warm_near.append(planner.plan(nearby, warm_start=cold_plan.warm_start).solver.solve_time_ms)
            if previous is not None:
                warm_far.append(planner.plan(state, warm_start=previous.warm_start).solver.solve_time_ms)
            previous = cold_plan
            statuses[cold_plan.status] = statuses.get(cold_plan.status, 0) + 1
        print(f"\nmethod {method}: NLP built in {build_s:.2f} s; statuses {statuses}")
        print(f"  cold solve        {_percentiles(cold)}")
        print(f"  warm, half a cell {_percentiles(warm_near)}   (from a plan 10 ft / 2.5 kt away)")
        print(f"  warm, far         {_percentiles(warm_far)}   (from the previous serpentine state's plan)")
        print(f"  replay + decode   {_percentiles(replay)}")


if __name__ == "__main__":
    main()
