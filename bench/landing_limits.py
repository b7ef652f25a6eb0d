"""Which limit keeps an airframe from landing with the momentum rotor: the same flyable plans with one limit or one
model element changed at a time.

Run: .venv/bin/python bench/landing_limits.py [--airframe uh60a_class] [--states 500:75 800:0]

For each variant it prints, per failure state (height ft : speed kt, level trim, total power loss), the status, the
value J and the touchdown descent rate and forward speed of the NLP's plan. The variants: the momentum rotor as the
airframe file gives it; an ideal momentum rotor (κ = 1, speed-independent profile power, no ground effect); every
flyability limit relaxed (40° attitudes both ways and at touchdown, 200°/s, full collective in 0.05 s, no commit
height); a 140 % rotor ceiling; rotor floors of 60 % in flight and 50 % at touchdown; touchdown forward-speed limits
of 15 and 20 kt; and the paper's rotor for reference.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys

from _common import command_line, loadavg_text

from helireach_ros.core.aircraft.airframe import Airframe, load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import LandingPlanner
from helireach_ros.core.units import FT, KT


def _variants(momentum: Airframe) -> dict[str, Airframe]:
    limits, flyability = momentum.limits, momentum.flyability
    wide = math.radians(40.0)
    relaxed = dataclasses.replace(
        flyability,
        max_nose_up_pitch=wide,
        max_nose_down_pitch=wide,
        touchdown_max_nose_up_pitch=wide,
        touchdown_max_nose_down_pitch=wide,
        max_pitch_rate=math.radians(200.0),
        collective_full_travel_time=0.05,
        commit_height=0.0,
    )
    ideal = dataclasses.replace(
        momentum.rotor_model, induced_power_factor=1.0, profile_power_speed_factor=0.0, ground_effect=False
    )
    return {
        "momentum rotor (the file's limits)": momentum,
        "ideal momentum rotor (kappa 1, K 0, no ground effect)": momentum.with_rotor_model(ideal),
        "flyability relaxed": dataclasses.replace(momentum, flyability=relaxed),
        "rotor ceiling 140 %": dataclasses.replace(
            momentum, limits=dataclasses.replace(limits, max_rotor_speed_ratio=1.40)
        ),
        "rotor floors 60 % / 50 % at touchdown": dataclasses.replace(
            momentum,
            limits=dataclasses.replace(limits, min_rotor_speed_ratio=0.60),
            flyability=dataclasses.replace(flyability, touchdown_min_rotor_speed_ratio=0.50),
        ),
        "touchdown forward speed 15 kt": dataclasses.replace(
            momentum, limits=dataclasses.replace(limits, max_forward_speed=15.0 * KT)
        ),
        "touchdown forward speed 20 kt": dataclasses.replace(
            momentum, limits=dataclasses.replace(limits, max_forward_speed=20.0 * KT)
        ),
        "paper rotor (reference)": momentum.paper_model(),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--airframe", default="uh60a_class")
    parser.add_argument("--states", nargs="+", default=["500:75", "800:0"], help="height_ft:speed_kt ...")
    arguments = parser.parse_args(argv)
    states = [tuple(float(part) for part in text.split(":")) for text in arguments.states]
    print(f"command: {command_line()}")
    print(f"load average (1/5/15 min): {loadavg_text()}")
    momentum = load_airframe(arguments.airframe).with_rotor_model_choice("momentum")
    print("| variant | " + " | ".join(f"{h:.0f} ft / {v:.0f} kt" for h, v in states) + " |")
    print("|---|" + "---|" * len(states))
    for label, airframe in _variants(momentum).items():
        planner = LandingPlanner(airframe, load_settings())
        cells = []
        for height_ft, speed_kt in states:
            plan = planner.plan(initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT))
            touchdown = plan.states[:, -1]
            cells.append(
                f"{plan.status}, J {plan.value:+.2f} ({touchdown[0] / FT:.1f} ft/s, {touchdown[1] / KT:.1f} kt)"
            )
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    print(f"load average (1/5/15 min): {loadavg_text()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
