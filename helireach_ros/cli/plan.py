"""``helireach plan``: one landing plan from any state, as text, JSON or a figure.

The state at the failure is steady flight trimmed at ``--height-ft``, ``--speed-kt`` and ``--climb-rate-fpm``
(default level), with the rotor at ``--rotor-speed-pct`` of Ω₀ and ``--power-fraction`` of the power the rotor
absorbs in that flight left to the engine; or any state given in SI by ``--state-json FILE`` (the
``initial_state`` object that ``--json`` prints, or a whole ``--json`` output).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from helireach_ros.cli.options import add_rotor_model_option

__all__ = ["register", "run_plan"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the ``plan`` subcommand."""
    parser = subparsers.add_parser(
        "plan",
        help="plan (and verify) a landing after an engine failure from any state",
        description="Solve the reachability NLP from a state at the failure (steady flight at a height, speed and "
        "climb rate, or a state file), replay the plan through the model, and report whether a safe landing is "
        "reachable.",
    )
    parser.add_argument("--airframe", default="uh60a_class", help="airframe name in config/airframes or a YAML path")
    parser.add_argument("--height-ft", type=float, help="height above ground at the failure [ft]")
    parser.add_argument("--speed-kt", type=float, help="forward speed at the failure [kt]")
    parser.add_argument(
        "--climb-rate-fpm", type=float, default=0.0, help="climb rate at the failure [ft/min], < 0 descending (0)"
    )
    parser.add_argument("--rotor-speed-pct", type=float, default=100.0, help="rotor speed, %% of nominal (100)")
    parser.add_argument(
        "--power-fraction",
        type=float,
        default=0.0,
        help="engine power left, fraction of the power the rotor absorbs in that flight (0 = total loss)",
    )
    parser.add_argument(
        "--state-json",
        metavar="FILE",
        help="the state at the failure in SI (descent_rate, forward_speed, rotor_speed, height[, distance, "
        "engine_power]) instead of the flight options; '-' reads standard input",
    )
    parser.add_argument(
        "--method", choices=("flyable", "verified", "paper"), default=None, help="transcription (default: config)"
    )
    parser.add_argument(
        "--reaction-delay-s",
        type=float,
        default=None,
        help="s the pre-failure trim controls are held before the plan starts (default: config, 0)",
    )
    parser.add_argument("--settings", default=None, help="planner settings YAML (default: config/planner.yaml)")
    add_rotor_model_option(parser)
    parser.add_argument("--weight-lb", type=float, default=None, help="override the gross weight [lbf]")
    parser.add_argument("--density-altitude-ft", type=float, default=None, help="override the density altitude [ft]")
    parser.add_argument(
        "--headwind-kt",
        "--wind-kt",
        type=float,
        default=None,
        help="a steady headwind along the track [kt] (negative: tailwind)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", default=None, metavar="FILE.png", help="write the trajectory figure")
    parser.add_argument(
        "--footprint",
        action="store_true",
        help="also the reachable footprint: the nearest and farthest replay-verified touchdown (two more NLPs)",
    )
    parser.add_argument(
        "--site-ft",
        type=_site,
        default=None,
        metavar="START:END",
        help="land on this site: touchdown START..END ft ahead along the track (with the footprint, to say whether "
        "the site is reachable at all)",
    )
    parser.set_defaults(handler=run_plan)


def run_plan(arguments: argparse.Namespace) -> int:
    """Handler of ``helireach plan``; returns 0 if safe (with ``--site-ft``: landed on the site), 1 if not, 2 on bad
    input."""
    from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe
    from helireach_ros.core.ocp.settings import load_settings
    from helireach_ros.core.planning.planner import plan_landing
    from helireach_ros.core.units import FT, KT, LBF

    try:
        airframe = (
            load_airframe(arguments.airframe)
            .with_rotor_model_choice(arguments.rotor_model)
            .with_conditions(
                gross_weight=None if arguments.weight_lb is None else arguments.weight_lb * LBF,
                density_altitude=None if arguments.density_altitude_ft is None else arguments.density_altitude_ft * FT,
                headwind=None if arguments.headwind_kt is None else arguments.headwind_kt * KT,
            )
        )
        settings = load_settings(
            arguments.settings, method=arguments.method, reaction_delay_s=arguments.reaction_delay_s
        )
        state = _state(arguments, airframe)
        plan = plan_landing(state, airframe, settings)
        footprint = None
        if arguments.footprint or arguments.site_ft is not None:
            from helireach_ros.core.planning.footprint import reachable_footprint

            warm = (plan.warm_start,) if plan.solver.success else ()
            footprint = reachable_footprint(state.as_array(), airframe, settings, warm_starts=warm)
        if arguments.site_ft is not None:
            from helireach_ros.core.planning.planner import get_planner

            window = (arguments.site_ft[0] * FT, arguments.site_ft[1] * FT)
            # beyond a verified end of the footprint no landing reaches the site: nothing to solve
            if footprint is not None and footprint.site_reachability(*window) != "not_reachable":
                plan = get_planner(airframe, settings.replace(objective="site")).plan(state, touchdown_window=window)
    except (ConfigError, ValueError) as error:
        print(f"helireach plan: error: {error}", file=sys.stderr)
        return 2

    if arguments.plot:
        from helireach_ros.core.planning.plan_plot import plot_landing_plan

        plot_landing_plan(plan, arguments.plot)
    if arguments.json:
        summary = plan.to_dict()
        summary["airframe"] = airframe.name
        summary["airframe_digest"] = airframe.digest()
        if arguments.site_ft is not None and footprint is not None:
            summary["site"] = _site_summary(footprint, plan, arguments.site_ft)
        if footprint is not None:
            summary["footprint"] = {
                "reachable": footprint.reachable, "nearest_m": _finite(footprint.nearest_m),
                "farthest_m": _finite(footprint.farthest_m), "plans_tried": len(footprint.tried),
            }  # fmt: skip
        print(json.dumps(summary))
    else:
        touchdown = plan.replay.touchdown_state
        rotor_pct = 100 * state.rotor_speed / airframe.nominal_rotor_speed
        print(
            f"{airframe.name}: {state.height / FT:.0f} ft, {state.forward_speed / KT:.0f} kt, "
            f"{-state.descent_rate / FT * 60:+.0f} ft/min, rotor {rotor_pct:.0f} %, "
            f"engine {state.engine_power / 1e3:.0f} kW -> {plan.status.upper()} ({plan.method})\n"
            f"  value {plan.value:+.3f} (<= 0 is safe), replayed value {plan.replay.value:+.3f}\n"
            f"  time to land {plan.time_to_land:.2f} s; replayed touchdown {touchdown[0] / FT:.1f} ft/s, "
            f"{plan.touchdown_ground_speed / KT:.1f} kt over the ground, "
            f"rotor {100 * touchdown[2] / airframe.nominal_rotor_speed:.0f} %\n"
            f"  IPOPT {plan.solver.status}, {plan.solver.iterations} iterations, {plan.solver.solve_time_ms:.0f} ms\n"
            f"  {_flyability_line(plan)}"
        )
        if footprint is not None:
            print(f"  {_footprint_line(footprint)}")
        if arguments.site_ft is not None and footprint is not None:
            print(f"  {_site_line(_site_summary(footprint, plan, arguments.site_ft))}")
        if arguments.plot:
            print(f"  figure: {arguments.plot}")
    if arguments.site_ft is not None and footprint is not None:  # with a site, safe means landed on it
        return 0 if _site_summary(footprint, plan, arguments.site_ft)["landed"] else 1
    return 0 if plan.safe else 1


def _site(text: str) -> tuple[float, float]:
    """``START:END`` in ft, finite, START <= END (argparse type)."""
    try:
        start, end = (float(part) for part in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START:END in ft, got {text!r}") from None
    if not (math.isfinite(start) and math.isfinite(end) and start <= end):
        raise argparse.ArgumentTypeError(f"a site is START:END with START <= END, finite; got {text!r}")
    return start, end


def _site_summary(footprint, plan, site_ft: tuple[float, float]) -> dict:
    """Whether the site is landed on (a replay-verified plan made for it), reachable at all (it overlaps the
    footprint), and, when it is not, the nearest distance a verified landing reaches (ft)."""
    from helireach_ros.core.planning.footprint import touchdown_distance
    from helireach_ros.core.units import FT

    start, end = site_ft
    reachability = footprint.site_reachability(start * FT, end * FT)
    landed = plan.touchdown_window is not None and plan.safe
    nearest = None
    if reachability == "not_reachable":
        nearest = footprint.farthest_m / FT if start > footprint.farthest_m / FT else footprint.nearest_m / FT
    return {
        "start_ft": start, "end_ft": end, "landed": landed, "reachable": str(reachability),
        "touchdown_ft": _finite(touchdown_distance(plan) / FT) if landed else None, "nearest_reachable_ft": nearest,
    }  # fmt: skip


def _site_line(site: dict) -> str:
    where = f"site {site['start_ft']:.0f}-{site['end_ft']:.0f} ft"
    if site["landed"]:
        return f"{where}: LANDED ON, touchdown {site['touchdown_ft']:.0f} ft ahead (replay-verified)"
    if site["reachable"] == "not_reachable":
        nearest = site["nearest_reachable_ft"]
        return f"{where}: NOT REACHABLE (beyond the footprint; nearest reachable touchdown {nearest:.0f} ft)"
    if site["reachable"] == "unknown":
        return f"{where}: no replay-verified landing on it (the footprint's end on that side is not verified either)"
    return f"{where}: inside the footprint, but no replay-verified landing on it"


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _footprint_line(footprint) -> str:
    """The footprint's ends in feet from the failure, or which end no verified landing reaches."""
    from helireach_ros.core.units import FT

    def end(name: str, plan, distance_m: float) -> str:
        return f"{name} {distance_m / FT:.0f} ft" if plan is not None else f"{name}: no verified landing"

    nearest = end("nearest", footprint.nearest, footprint.nearest_m)
    farthest = end("farthest", footprint.farthest, footprint.farthest_m)
    tried = len(footprint.tried)
    return f"footprint: touchdown {nearest}, {farthest} from here (each end replay-verified; {tried} NLPs)"


def _flyability_line(plan) -> str:
    """What the plan asks of the aircraft, and the flyability limits it breaks."""
    report = plan.replay.flyability
    touchdown = (
        "no ground contact"
        if report.touchdown_pitch is None
        else f"touchdown attitude {-math.degrees(report.touchdown_pitch):+.1f} deg nose-up"
    )
    text = (
        f"flyability: pitch rate up to {math.degrees(report.max_pitch_rate):.1f} deg/s, nose up to "
        f"{math.degrees(report.max_nose_up_pitch):.1f} deg, {touchdown}"
    )
    if plan.reaction_delay_s > 0.0:
        text += f", after a {plan.reaction_delay_s:g} s reaction delay"
    if report.violations:
        text += " -- breaks: " + "; ".join(report.violations)
    return text


def _state(arguments: argparse.Namespace, airframe):
    """The state at the failure from the options (see the module docstring)."""
    from helireach_ros.core.aircraft.model import HelicopterState, initial_state_after_failure
    from helireach_ros.core.units import FT, KT

    if arguments.state_json is not None:
        if arguments.height_ft is not None or arguments.speed_kt is not None:
            raise ValueError("--state-json replaces --height-ft/--speed-kt: give one or the other")
        try:
            text = sys.stdin.read() if arguments.state_json == "-" else Path(arguments.state_json).read_text()
            document = json.loads(text)
        except OSError as error:
            raise ValueError(f"--state-json: cannot read {arguments.state_json!r}: {error.strerror}") from error
        except json.JSONDecodeError as error:
            raise ValueError(f"--state-json: not JSON ({error})") from error
        if isinstance(document, dict) and isinstance(document.get("initial_state"), dict):
            document = document["initial_state"]  # a whole `helireach plan --json` output
        if not isinstance(document, dict):
            raise ValueError("--state-json: expected a JSON object of state components")
        return HelicopterState.from_mapping(document)
    if arguments.height_ft is None or arguments.speed_kt is None:
        raise ValueError("give --height-ft and --speed-kt (or --state-json FILE)")
    for name in ("height_ft", "speed_kt", "climb_rate_fpm", "rotor_speed_pct", "power_fraction"):
        if not math.isfinite(getattr(arguments, name)):
            raise ValueError(f"--{name.replace('_', '-')} must be a finite number")
    return initial_state_after_failure(
        airframe,
        arguments.height_ft * FT,
        arguments.speed_kt * KT,
        arguments.power_fraction,
        climb_rate=arguments.climb_rate_fpm * FT / 60.0,
        rotor_speed=arguments.rotor_speed_pct / 100.0 * airframe.nominal_rotor_speed,
    )
