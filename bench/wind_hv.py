"""Wind against calm: the H-V avoid region and the reachable footprint, side by side.

Run: nice -n 10 .venv/bin/python bench/wind_hv.py [--winds-kt -15 0 15] [--heights 17] [--speeds 13]
     [--objective terminal] [--footprint-ft 500 --footprint-kt 75]

For each steady wind along the track (``Airframe.headwind``; + = headwind): every failure state of the grid
(0–800 ft × 0–120 kt airspeed, total power loss, the default airframe) solved cold and replayed; the statuses counted;
every state where a wind is *less safe* than calm listed with both answers (safe < unverified < unsafe = failed), and
why (the replay's flyability violations, the touchdown over the ground); then the footprint from one state. The
solves are statuses, not times: the load does not change them.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from _common import loadavg_text

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.settings import OBJECTIVES, load_settings
from helireach_ros.core.planning.footprint import reachable_footprint
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.units import FT, KT

_RANK = {"safe": 0, "unverified": 1, "unsafe": 2, "failed": 2}  # how far from a verified landing an answer is


def _why(plan) -> str:
    """What decided a plan that is not safe: its value, the touchdown over the ground, the replay's violations."""
    touchdown = f"{plan.replay.touchdown_state[0] / FT:.1f} ft/s, {plan.touchdown_ground_speed / KT:.1f} kt ground"
    broken = "; ".join(plan.replay.flyability.violations) or "no flyability violation"
    return f"J {plan.value:+.2f}, touchdown {touchdown}, {broken}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--winds-kt", type=float, nargs="+", default=[-15.0, 0.0, 15.0])
    parser.add_argument("--heights", type=int, default=17)
    parser.add_argument("--speeds", type=int, default=13)
    parser.add_argument("--objective", choices=("terminal", "reach_avoid"), default="terminal")
    parser.add_argument("--footprint-ft", type=float, default=500.0)
    parser.add_argument("--footprint-kt", type=float, default=75.0)
    arguments = parser.parse_args(argv)
    assert arguments.objective in OBJECTIVES
    load_before = loadavg_text()
    print(f"$ {' '.join([sys.executable, *sys.argv])}\nload before: {load_before}")
    base, settings = load_airframe("uh60a_class"), load_settings(objective=arguments.objective)
    heights = np.linspace(0.0, 800.0, arguments.heights)
    speeds = np.linspace(0.0, 120.0, arguments.speeds)
    statuses: dict[float, dict[tuple[float, float], object]] = {}
    for wind_kt in arguments.winds_kt:
        airframe = base.with_conditions(headwind=wind_kt * KT)
        planner = get_planner(airframe, settings)
        plans = {}
        for height_ft in heights:
            for speed_kt in speeds:
                state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT)
                plans[(float(height_ft), float(speed_kt))] = planner.plan(state)
        statuses[wind_kt] = plans
        counts: dict[str, int] = {}
        for plan in plans.values():
            counts[plan.status] = counts.get(plan.status, 0) + 1
        print(f"wind {wind_kt:+5.1f} kt ({arguments.objective}): {dict(sorted(counts.items()))}")
    calm = statuses.get(0.0)
    if calm is not None:
        for wind_kt, plans in statuses.items():
            if wind_kt == 0.0:
                continue
            worse = [key for key, plan in plans.items() if _RANK[plan.status] > _RANK[calm[key].status]]
            better = [key for key, plan in plans.items() if _RANK[plan.status] < _RANK[calm[key].status]]
            print(f"\nwind {wind_kt:+5.1f} kt against calm: {len(better)} states safer, {len(worse)} less safe")
            for key in worse:
                print(f"  {key[0]:5.0f} ft {key[1]:5.0f} kt: calm {calm[key].status}, wind {plans[key].status} "
                      f"({_why(plans[key])})")  # fmt: skip
    print(f"\nfootprint from {arguments.footprint_ft:.0f} ft / {arguments.footprint_kt:.0f} kt (touchdown ft ahead):")
    for wind_kt in arguments.winds_kt:
        airframe = base.with_conditions(headwind=wind_kt * KT)
        state = initial_state_after_failure(airframe, arguments.footprint_ft * FT, arguments.footprint_kt * KT)
        plan = get_planner(airframe, load_settings()).plan(state)
        warm = (plan.warm_start,) if plan.solver.success else ()
        footprint = reachable_footprint(state.as_array(), airframe, load_settings(), warm_starts=warm)
        ends = (
            f"{footprint.nearest_m / FT:7.0f} - {footprint.farthest_m / FT:7.0f}"
            if footprint.reachable
            else f"nearest {footprint.nearest_m / FT:.0f}, farthest {footprint.farthest_m / FT:.0f} (NaN: not verified)"
        )
        print(f"  wind {wind_kt:+5.1f} kt: {ends}  (touchdown-cost plan: {plan.status})")
    print(f"load after: {loadavg_text()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
