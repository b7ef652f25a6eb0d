"""``helireach plan``: one landing plan from level trim at a height and speed, as text, JSON or a figure."""

from __future__ import annotations

import argparse
import json
import math
import sys

__all__ = ["register", "run_plan"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the ``plan`` subcommand."""
    parser = subparsers.add_parser(
        "plan",
        help="plan (and verify) a landing after an engine failure from level trim",
        description="Solve the reachability NLP from level trim at a height and speed, replay the plan through the "
        "model, and report whether a safe landing is reachable.",
    )
    parser.add_argument("--airframe", default="uh60a_class", help="airframe name in config/airframes or a YAML path")
    parser.add_argument("--height-ft", type=float, required=True, help="height above ground at the failure [ft]")
    parser.add_argument("--speed-kt", type=float, required=True, help="forward speed at the failure [kt]")
    parser.add_argument(
        "--power-fraction", type=float, default=0.0, help="engine power left, fraction of trim power (0 = total loss)"
    )
    parser.add_argument("--method", choices=("verified", "paper"), default=None, help="transcription (default: config)")
    parser.add_argument("--settings", default=None, help="planner settings YAML (default: config/planner.yaml)")
    parser.add_argument("--weight-lb", type=float, default=None, help="override the gross weight [lbf]")
    parser.add_argument("--density-altitude-ft", type=float, default=None, help="override the density altitude [ft]")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", default=None, metavar="FILE.png", help="write the trajectory figure")
    parser.set_defaults(handler=run_plan)


def run_plan(arguments: argparse.Namespace) -> int:
    """Handler of ``helireach plan``; returns 0 if safe, 1 if not, 2 on bad input."""
    from helireach_ros.core.airframe import ConfigError, load_airframe
    from helireach_ros.core.model import initial_state_after_failure
    from helireach_ros.core.planner import plan_landing
    from helireach_ros.core.settings import load_settings
    from helireach_ros.core.units import FT, KT, LBF

    try:
        for name in ("height_ft", "speed_kt", "power_fraction"):
            if not math.isfinite(getattr(arguments, name)):
                raise ValueError(f"--{name.replace('_', '-')} must be a finite number")
        airframe = load_airframe(arguments.airframe).with_conditions(
            gross_weight=None if arguments.weight_lb is None else arguments.weight_lb * LBF,
            density_altitude=None if arguments.density_altitude_ft is None else arguments.density_altitude_ft * FT,
        )
        settings = load_settings(arguments.settings, method=arguments.method)
        state = initial_state_after_failure(
            airframe, arguments.height_ft * FT, arguments.speed_kt * KT, arguments.power_fraction
        )
        plan = plan_landing(state, airframe, settings)
    except (ConfigError, ValueError) as error:
        print(f"helireach plan: error: {error}", file=sys.stderr)
        return 2

    if arguments.plot:
        from helireach_ros.core.plan_plot import plot_landing_plan

        plot_landing_plan(plan, arguments.plot)
    if arguments.json:
        summary = plan.to_dict()
        summary["airframe"] = airframe.name
        summary["airframe_digest"] = airframe.digest()
        print(json.dumps(summary))
    else:
        touchdown = plan.replay.touchdown_state
        print(
            f"{airframe.name}: {arguments.height_ft:.0f} ft, {arguments.speed_kt:.0f} kt, power "
            f"{100 * arguments.power_fraction:.0f} % -> {plan.status.upper()} ({plan.method})\n"
            f"  value {plan.value:+.3f} (<= 0 is safe), replayed value {plan.replay.value:+.3f}\n"
            f"  time to land {plan.time_to_land:.2f} s; replayed touchdown {touchdown[0] / FT:.1f} ft/s, "
            f"{touchdown[1] / KT:.1f} kt, rotor {100 * touchdown[2] / airframe.nominal_rotor_speed:.0f} %\n"
            f"  IPOPT {plan.solver.status}, {plan.solver.iterations} iterations, {plan.solver.solve_time_ms:.0f} ms"
        )
        if arguments.plot:
            print(f"  figure: {arguments.plot}")
    return 0 if plan.safe else 1
