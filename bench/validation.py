"""The rotor model against published helicopter data: the paper's rotor and the momentum rotor side by side.

Run: .venv/bin/python bench/validation.py [--write docs/results/validation.md] [--airframes uh60a_class oh58a_class]

Per airframe and rotor model (``paper``: hover inflow at every speed, as in Kirchner et al. 2020; ``momentum``:
core/aircraft/inflow.py with ground effect):

* level-flight power over hover power (out of ground effect) against speed: the bucket's depth and speed;
* steady autorotation descent against speed (Ω = Ω₀): the minimum and its speed, and the vertical descent over v_h;
* the rotor's decay right after a total power loss from trim in hover and at 100 kt, in % of Ω₀ per second;
* flyable landing plans (the default planner settings) down the hover column and at the issue's check states,
  without and with a 1 s reaction delay: the hover avoid band (lowest and highest not-safe height).

The anchors (shared reference validation-anchors.md) are printed beside them.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time

import numpy as np
from _common import loadavg_text, results_footer

from helireach_ros.core.aircraft.airframe import Airframe, load_airframe
from helireach_ros.core.aircraft.inflow import InflowModel
from helireach_ros.core.aircraft.model import (
    dynamics_function,
    initial_state_after_failure,
    steady_autorotation,
    trim_level_flight,
)
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import LandingPlanner
from helireach_ros.core.units import FT, KT

SPEEDS_KT = np.arange(0.0, 125.0, 5.0)
HOVER_HEIGHTS_FT = (5, 10, 20, 30, 50, 75, 100, 150, 200, 300, 400, 500, 600, 700, 800)
CHECK_STATES = {
    "uh60a_class": ((100, 100), (500, 75), (200, 80)),
    "oh58a_class": ((700, 60), (500, 75)),
    "s300c_class": ((500, 50), (300, 40)),
}
DESCENT_AT_KT = (30, 47, 55)  # the anchors' speeds: Schweizer 300 (30, 47 kt), R44 (55 kt)
ANCHORS = (
    ("power bucket", "minimum power well below hover power near 50-80 kt (utility helicopters)"),
    ("steady autorotation, Schweizer 300 (FAA HFH fig. 7-3)", "1,600 ft/min at 47 kt (its minimum); > 2,200 at 30 kt"),
    ("steady autorotation, other light singles", "R44 ≈ 1,350 ft/min at 55 kt; Bell 206 minimum-descent speed 50 kt"),
    ("vertical autorotation", "ideal (no profile power) at V_d ≈ 1.7 v_h; real ones faster"),
    ("H-V hover band, light singles", "low 5-10 ft, high 400-450 ft; knee 35-80 kt"),
    ("cruise power loss", "rotor decays fast without collective: the certification delay is about 1 s"),
)


def _models(airframe: Airframe) -> dict[str, Airframe]:
    momentum = dataclasses.replace(airframe.rotor_model, inflow=InflowModel.MOMENTUM, ground_effect=True)
    return {"paper": airframe.paper_model(), "momentum": airframe.with_rotor_model(momentum)}


def _performance(airframe: Airframe) -> dict[str, str]:
    power = np.array([trim_level_flight(airframe, speed * KT).power for speed in SPEEDS_KT])
    descent = np.array([steady_autorotation(airframe, speed * KT)[0] for speed in SPEEDS_KT])
    hover_induced = math.sqrt(airframe.gross_weight / (2.0 * airframe.air_density * airframe.disk_area))
    dynamics = dynamics_function(airframe)

    def decay(speed_kt: float) -> float:
        trim = trim_level_flight(airframe, speed_kt * KT)
        state = [0.0, speed_kt * KT, airframe.nominal_rotor_speed, 1000.0, 0.0, 0.0]
        rate = float(dynamics(state, [trim.thrust_coefficient, trim.pitch_angle])[2])
        return 100.0 * rate / airframe.nominal_rotor_speed

    bucket = int(np.argmin(power))
    slowest = int(np.argmin(descent))
    return {
        "hover power (OGE)": f"{power[0] / 1e3:,.0f} kW",
        "minimum power / hover": f"{power[bucket] / power[0]:.2f} at {SPEEDS_KT[bucket]:.0f} kt",
        "power at 120 kt / hover": f"{power[-1] / power[0]:.2f}",
        "autorotation descent at 0 kt": f"{descent[0] / FT * 60:,.0f} ft/min = {descent[0] / hover_induced:.2f} v_h",
        "minimum autorotation descent": f"{descent[slowest] / FT * 60:,.0f} ft/min at {SPEEDS_KT[slowest]:.0f} kt "
        f"({100 * (1 - descent[slowest] / descent[0]):.0f} % below 0 kt)",
        "autorotation descent at " + ", ".join(f"{speed}" for speed in DESCENT_AT_KT) + " kt": ", ".join(
            f"{steady_autorotation(airframe, speed * KT)[0] / FT * 60:,.0f}" for speed in DESCENT_AT_KT
        )
        + " ft/min",
        "rotor decay after the failure, hover / 100 kt": f"{decay(0.0):.1f} / {decay(100.0):.1f} %/s",
    }


def _plans(airframe: Airframe, delay: float) -> dict[str, str]:
    planner = LandingPlanner(airframe, load_settings(reaction_delay_s=delay))
    not_safe, solve_ms = [], []
    for height in HOVER_HEIGHTS_FT:
        plan = planner.plan(initial_state_after_failure(airframe, height * FT, 0.0))
        solve_ms.append(plan.solver.solve_time_ms)
        if not plan.safe:
            not_safe.append(height)
    row = {"hover heights not safe": ", ".join(f"{h}" for h in not_safe) + " ft" if not_safe else "none"}
    for height, speed in CHECK_STATES.get(airframe.name, ()):
        plan = planner.plan(initial_state_after_failure(airframe, height * FT, speed * KT))
        solve_ms.append(plan.solver.solve_time_ms)
        touchdown = plan.states[:, -1]
        row[f"{height} ft / {speed} kt"] = (
            f"{plan.status} (J {plan.value:+.2f}; {touchdown[0] / FT:.0f} ft/s, {touchdown[1] / KT:.0f} kt)"
        )
    row["median solve time (cold)"] = f"{np.median(solve_ms):.0f} ms"
    return row


def _table(columns: dict[str, dict[str, str]]) -> str:
    keys = list(dict.fromkeys(key for column in columns.values() for key in column))
    lines = ["| | " + " | ".join(columns) + " |", "|---|" + "---|" * len(columns)]
    lines += [f"| {key} | " + " | ".join(column.get(key, "") for column in columns.values()) + " |" for key in keys]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--airframes", nargs="+", default=["uh60a_class", "oh58a_class", "s300c_class"])
    parser.add_argument("--write", metavar="FILE.md", help="write the results page (docs/results/validation.md)")
    arguments = parser.parse_args(argv)
    started = time.perf_counter()
    load_before = loadavg_text()
    sections = []
    for name in arguments.airframes:
        models = _models(load_airframe(name))
        performance = {label: _performance(model) for label, model in models.items()}
        plans = {
            f"{label}, delay {delay:g} s": _plans(model, delay)
            for label, model in models.items()
            for delay in (0.0, 1.0)
        }
        sections.append(f"### {name}\n\nPerformance (sea-level ISA, out of ground effect):\n\n{_table(performance)}\n\n"
                        f"Flyable landing plans (default planner settings):\n\n{_table(plans)}\n")  # fmt: skip
        print(sections[-1], flush=True)
    footer = results_footer(load_before, f"{time.perf_counter() - started:.0f} s")
    print(footer)
    if arguments.write:
        with open(arguments.write, "w") as page:
            page.write(
                "# Validation: the rotor model against published data\n\n"
                "Generated by `bench/validation.py --write docs/results/validation.md`; do not edit by hand. "
                "The method and the sources of the momentum rotor are in `helireach_ros/core/aircraft/inflow.py`.\n\n"
                "## Published anchors\n\n"
                + _table({"published (validation anchors)": dict(ANCHORS)})
                + "\n\n## Measured\n\n" + "\n".join(sections) + f"\n{footer}\n"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
