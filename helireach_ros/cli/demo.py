"""``make demo``: the whole story of an engine failure, in one process, with the embedded defaults.

The envelope status node holds the shipped H-V envelope; the simulated helicopter cruises at 500 ft /
75 kt (scenario ``demo_500ft_75kt``: its drag is 5 % higher than the planner's model, sensors are
noisy); the engine fails; the planner publishes a verified landing plan, then re-plans from the
current state four times a second down to the ground; the vehicle touches down and reports its
descent rate, forward speed and rotor speed. Every topic goes to an MCAP log.

Writes ``<out>/hv_diagram.png`` (the H-V diagram with the flown track), ``<out>/landing_plan.png``
(the first plan: states, replay and controls) and ``<out>/logs/helireach_*.mcap``; prints a summary.
Exits 0 only if the landing met the limits. ``--hold`` keeps the nodes running after touchdown
(the cockpit display page, served by default, stays up with them) until Ctrl-C.

``--mismatch NAME`` flies a model-mismatch preset instead of the scenario's own
(:mod:`helireach_ros.core.flight.mismatch_presets`: ``none``, ``drag+5`` = the default scenario's, ``weight+5`` = an
unknown 5 % heavier aircraft, ``weight-5``, ``heavy+draggy``, ``light+clean``). With a preset the planner estimates
the gross weight before the failure (planner parameter ``estimate_weight``; off by default, so ``make demo`` is
unchanged); ``--no-estimate-weight`` / ``--estimate-weight`` choose explicitly. The summary names the preset and the
weight the planner used.

The planner verifies its failure plan robustly in the background (planner parameter ``robust_verification``, on
in the demo, ``--no-robust-verification`` to turn it off): the plan goes out flagged ``robust: pending`` and the
summary gives the verdict, or says it was still pending at touchdown.

``--site-ft START:END`` adds a landing site along the track (ft of the odometry's along-track distance from where the
run starts; the failure comes about 415 ft in): the planner's ``landing_sites`` parameter. The live evaluations before
the failure plan to land on it, so the standby plan is the site's; the failure plan and the re-plans land on it (or
anywhere, saying so, if it cannot be reached); the summary gives where the vehicle touched down and whether that is on
the site, and the demo exits 0 only if the landing met the limits *on the site*.

Run: ``python -m helireach_ros.cli.demo --out out [--hold] [--no-display] [--scenario NAME] [--mismatch NAME]
[--site-ft START:END]``.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.flight.mismatch_presets import MISMATCH_PRESET_NAMES
from helireach_ros.core.policies.landing_sites import LandingSite
from helireach_ros.ros.executors import DEFAULT_EXECUTOR, EXECUTOR_KINDS

__all__ = ["DemoResult", "demo_ros_arguments", "demo_site", "main", "register", "run_demo"]

_TOUCHDOWN_TIMEOUT_S = 120.0  # wall time from start; the demo scenario lands about 16 s in


class DemoResult:
    """What a demo run produced (for the summary and for tests).

    Attributes:
        status_before_failure: the last safety verdict while cruising (level name, message) or None.
        status_during_descent: how often each (level, evidence) of the safety status was seen from the failure to
            the touchdown (sampled at every executor wake-up).
        touchdown: the vehicle's :class:`~helireach_ros.core.flight.simulation.TouchdownReport` (None on timeout).
        first_plan: the first published plan record
        (:class:`~helireach_ros.core.policies.failure_episode.PublishedPlan`)
            made after the failure (the standby plan is not it).
        standby_plan: the standby plan record (the live plan published on the failure), or None.
        plans: every plan published for the failure.
        robust_verdicts: the planner's robust verdicts of the failure's plans (None: pending), in order.
        replans_failed, replans_kept_out: re-plans that did not converge, and converged re-plans kept out (not safe
            while the current plan still landed from their state); the current plan was flown on either way.
        log_path: the MCAP log.
        message_count: messages recorded.
        track: N × 2 (height m, speed m/s) flown.
        figures: paths written.
    """

    def __init__(self) -> None:
        self.status_before_failure: tuple[str, str] | None = None
        self.status_during_descent: dict[tuple[str, str], int] = {}
        self.touchdown: Any = None
        self.first_plan: Any = None
        self.standby_plan: Any = None
        self.plans: list[Any] = []
        self.robust_verdicts: list[Any] = []  # RobustSummary (None: pending) of the failure's plans, in order
        self.replans_failed = 0  # re-plans that did not converge (the current plan was kept)
        self.replans_kept_out = 0  # converged re-plans not safe while the current plan still landed (flown on)
        self.log_path: Path | None = None
        self.message_count = 0
        self.track = np.zeros((0, 2))
        self.figures: list[Path] = []
        self.scenario: Any = None
        self.limits: Any = None
        self.flyability: Any = None
        self.nominal_rotor_speed = float("nan")
        self.mismatch_preset: str | None = None  # None: the scenario's own mismatch
        self.planned_weight: Any = None  # the planner's WeightChoice for the failure
        self.file_gross_weight = float("nan")
        self.site: Any = None  # the LandingSite asked for (None: anywhere)
        self.touchdown_distance = float("nan")  # m along the track where the vehicle met the ground

    @property
    def on_site(self) -> bool | None:
        """The vehicle touched down on the site (None: no site asked for)."""
        if self.site is None:
            return None
        return self.touchdown is not None and bool(self.site.contains(self.touchdown_distance))

    @property
    def landed_within_limits(self) -> bool:
        """The vehicle touched down within the landing limits (and on the site, if one was asked for)."""
        return self.touchdown is not None and bool(self.touchdown.within_limits) and self.on_site is not False


def run_demo(
    out_dir: str | os.PathLike[str],
    scenario: str | None = None,
    hold: bool = False,
    display: bool = False,
    params_files: tuple[str, ...] = (),
    context: Any = None,
    handle_signals: bool = True,
    figures: bool = True,
    executor: str = DEFAULT_EXECUTOR,
    mismatch: str | None = None,
    estimate_weight: bool | None = None,
    robust_verification: bool = True,
    site: LandingSite | None = None,
    footprint_period_s: float = 0.0,
    headwind_kt: float = 0.0,
) -> DemoResult:
    """Runs the demo (see the module docstring) and returns what it produced.

    ``mismatch``: a preset the vehicle flies (None: the scenario's own); ``estimate_weight``: the planner's
    parameter (None: on with a preset, else its configured value); ``site``: a landing site (None: anywhere);
    ``footprint_period_s``: the planner's live footprint period (0: off); ``headwind_kt``: the wind the vehicle flies
    in and every node is told of (the aircraft parameter ``headwind``; the status node then has no envelope: the
    shipped ones are calm).
    """
    if estimate_weight is None and mismatch is not None:
        estimate_weight = True  # the presets are there to show what the estimate buys
    from helireach_ros.ros.bringup import build_system
    from helireach_ros.ros.messages import LEVEL_NAMES

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    extra = []
    if display:
        from helireach_ros.display.node import create_display_with_fallback

        extra.append(create_display_with_fallback)
    result = DemoResult()
    result.mismatch_preset = mismatch
    result.site = site
    system = build_system(
        params_files,
        with_sim=True,
        log_dir=out / "logs",
        scenario=scenario,
        extra_nodes=extra,
        context=context,
        ros_args=demo_ros_arguments(
            mismatch, estimate_weight, robust_verification, site, footprint_period_s, headwind_kt
        ),
        executor=executor,
        command="python -m helireach_ros.cli.demo",
    )
    sim, planner, status = system.sim, system.planner, system.envelope_status
    assert sim is not None
    result.log_path, result.scenario = system.log_path, sim.scenario
    result.limits = sim.vehicle.airframe.limits
    result.flyability = sim.vehicle.airframe.flyability
    result.nominal_rotor_speed = sim.vehicle.nominal_airframe.nominal_rotor_speed
    for node in system.extra:
        if hasattr(node, "url"):
            print(f"helireach demo: cockpit display at {node.url}", flush=True)
    signals = system.stop_on_signals() if handle_signals else contextlib.nullcontext()
    try:
        with signals:
            started = time.monotonic()

            def cruising() -> bool:
                verdict = status.verdict
                if verdict is not None and sim.vehicle.phase == "cruise":
                    result.status_before_failure = (LEVEL_NAMES.get(verdict.level, "?"), verdict.message)
                return sim.vehicle.phase != "cruise"

            system.spin_until(cruising, _TOUCHDOWN_TIMEOUT_S)
            remaining = _TOUCHDOWN_TIMEOUT_S - (time.monotonic() - started)

            def landed() -> bool:
                verdict = status.verdict
                if verdict is not None:
                    key = (LEVEL_NAMES.get(verdict.level, "?"), str(verdict.values.get("evidence", "?")))
                    result.status_during_descent[key] = result.status_during_descent.get(key, 0) + 1
                return sim.touchdown is not None

            system.spin_until(landed, remaining)
            system.drain()
            result.touchdown = sim.touchdown
            result.planned_weight = planner.episode_weight if planner.planner is not None else None
            result.file_gross_weight = planner.airframe.gross_weight if planner.planner is not None else math.nan
            supervisor = planner.supervisor
            failure = supervisor.failure
            if failure is not None:
                result.replans_failed, result.replans_kept_out = failure.replans_failed, failure.replans_kept_out
            result.plans = [record for record in supervisor.published_plans if record.failure_id == 1]
            result.robust_verdicts = [summary for key, summary in planner.robust_verdicts if key[0] == 1]
            standby = [record for record in result.plans if supervisor.is_standby(record)]
            result.standby_plan = standby[0] if standby else None
            converged = [record for record in result.plans if not record.fallback and not supervisor.is_standby(record)]
            result.first_plan = converged[0] if converged else (result.plans[0] if result.plans else None)
            result.track = np.array(
                [[state[StateIndex.HEIGHT], state[StateIndex.FORWARD_SPEED]] for _, state in sim.vehicle.history]
            )
            result.touchdown_distance = float(sim.vehicle.state[StateIndex.DISTANCE])
            if hold and not system.stop_requested:
                print("helireach demo: holding the nodes after touchdown; Ctrl-C to end", flush=True)
                system.spin_until(lambda: False, math.inf, step_s=0.1)
    finally:
        if system.recorder is not None:
            result.message_count = system.recorder.message_count
        system.shutdown()
    if figures:
        result.figures = _write_figures(out, result, status.envelope)
    return result


def demo_ros_arguments(
    mismatch: str | None,
    estimate_weight: bool | None,
    robust_verification: bool = True,
    site: LandingSite | None = None,
    footprint_period_s: float = 0.0,
    headwind_kt: float = 0.0,
) -> list[str]:
    """The ``-p`` arguments for a mismatch preset (the vehicle), the planner's ``estimate_weight``, its
    ``robust_verification``, its ``landing_sites`` and its ``footprint_period``, and every node's ``headwind``.

    Raises:
        ValueError: an unknown preset.
    """
    arguments: list[str] = []
    if mismatch is not None:
        if mismatch not in MISMATCH_PRESET_NAMES:
            raise ValueError(f"unknown mismatch preset {mismatch!r} (one of {', '.join(MISMATCH_PRESET_NAMES)})")
        arguments += ["-p", f"helireach_sim_vehicle:mismatch:={mismatch}"]
    if estimate_weight is not None:
        arguments += ["-p", f"helireach_planner:estimate_weight:={'true' if estimate_weight else 'false'}"]
    arguments += ["-p", f"helireach_planner:robust_verification:={'true' if robust_verification else 'false'}"]
    if site is not None:
        arguments += ["-p", f"helireach_planner:landing_sites:={site.name}:{site.start_m:.3f}:{site.end_m:.3f}"]
    if footprint_period_s > 0.0:
        arguments += ["-p", f"helireach_planner:footprint_period:={footprint_period_s:g}"]
    if headwind_kt:
        from helireach_ros.core.units import KT

        arguments += ["-p", f"headwind:={headwind_kt * KT!r}"]
    return arguments


def demo_site(text: str) -> LandingSite:
    """The demo's landing site from ``"START:END"`` in ft along the track.

    Raises:
        ValueError: not two numbers, or start > end.
    """
    from helireach_ros.core.units import FT

    parts = text.split(":")
    try:
        start_ft, end_ft = (float(part) for part in parts)
    except ValueError:
        raise ValueError(f"--site-ft is START:END in ft, got {text!r}") from None
    return LandingSite("demo_site", start_ft * FT, end_ft * FT)


def _write_figures(out: Path, result: DemoResult, envelope: Any) -> list[Path]:
    written = []
    if envelope is not None and len(result.track):
        from helireach_ros.core.envelope.plot import plot_envelope

        written.append(plot_envelope(envelope, out / "hv_diagram.png", track=result.track, title_extra="flown track"))
    plan = result.first_plan.plan if result.first_plan is not None else None
    if plan is not None and hasattr(plan, "replay"):
        from helireach_ros.core.planning.plan_plot import plot_landing_plan

        written.append(plot_landing_plan(plan, out / "landing_plan.png"))
    return written


def summary(result: DemoResult) -> str:
    """The human-readable summary (feet, knots, percent)."""
    from helireach_ros.core.units import FT, KT

    scenario, limits = result.scenario, result.limits
    mismatch = ", ".join(f"{name} {fraction:+.0%}" for name, fraction in scenario.parameter_mismatch.items()) or "none"
    preset = f"preset {result.mismatch_preset}" if result.mismatch_preset is not None else "the scenario's own"
    lines = [
        f"helireach demo: {scenario.name}: {scenario.height / FT:.0f} ft, {scenario.forward_speed / KT:.0f} kt, "
        f"engine failure at {scenario.failure_time:g} s (vehicle vs model, {preset}: {mismatch})",
    ]
    weight = result.planned_weight
    if weight is not None:
        note = f" ({weight.reason})" if weight.reason else ""
        lines.append(
            f"  planned gross weight      : {weight.gross_weight:.0f} N, {100 * weight.relative_change:+.1f} % vs the "
            f"file's {result.file_gross_weight:.0f} N, {weight.source}{note}"
        )
    level, message = result.status_before_failure or ("none", "no safety status received")
    lines.append(f"  status before the failure : {level}: {message}")
    samples = sum(result.status_during_descent.values())
    if samples:
        shares = sorted(result.status_during_descent.items(), key=lambda item: -item[1])
        seen = ", ".join(
            f"{level} from the {source} {100 * count / samples:.0f} %"
            if count >= samples / 100
            else f"{level} from the {source} <1 %"
            for (level, source), count in shares
        )
        lines.append(f"  status during the descent : {seen}")
    first = result.first_plan
    if first is None:
        lines.append("  landing plan              : none published")
    elif first.fallback:
        lines.append(f"  landing plan              : FALLBACK {first.plan.description} after {first.latency_ms:.0f} ms")
    else:
        plan = first.plan
        lines.append(
            f"  landing plan              : {plan.status.upper()} (value {plan.value:+.2f}), IPOPT "
            f"{plan.solver.solve_time_ms:.0f} ms / {plan.solver.iterations} iterations, failure to trajectory "
            f"{first.latency_ms:.0f} ms, land in {plan.time_to_land:.1f} s"
        )
    if result.standby_plan is not None:
        standby = result.standby_plan
        verified = "verified" if standby.plan.verified else "NOT verified"
        after = f"{standby.latency_ms:.0f} ms after the failure"
        aimed = ""
        if result.site is not None:
            aimed = ", for the site" if standby.plan.touchdown_window is not None else ", off-site (site not reachable)"
        lines.append(f"  standby plan              : published {after}, {verified}{aimed}")
    replans = max((record.replan_index for record in result.plans), default=0)
    learnt = next(
        (record.plan.disturbance for record in reversed(result.plans) if record.replan_index and not record.fallback),
        None,
    )
    error = (
        f"; model error learnt by the last: d_y {learnt[0]:+.2f} m/s², d_v {learnt[1]:+.2f} m/s², "
        f"d_Ω {learnt[2]:+.2f} rad/s²"
        if learnt is not None and np.any(learnt)
        else ""
    )
    unused = ", ".join(
        text
        for count, text in (
            (result.replans_failed, f"{result.replans_failed} not converged"),
            (result.replans_kept_out, f"{result.replans_kept_out} kept out (the current plan still landed)"),
        )
        if count
    )
    unused = f" ({unused})" if unused else ""
    lines.append(f"  closed loop               : {replans} re-plans from the current state{unused}{error}")
    if result.robust_verdicts:
        final = next((summary for summary in reversed(result.robust_verdicts) if summary is not None), None)
        if final is None:
            robust = "pending at touchdown (a low-priority process; the verdict follows on /helireach/robust_verdict)"
        elif final.robust:
            robust = f"ROBUST: lands closed loop in all {final.models_flown} models ({final.design})"
        else:
            robust = f"NOT robust ({final.design}, {final.seconds:.0f} s): {final.reason}"
        lines.append(f"  robust verification       : {robust}")
    touchdown = result.touchdown
    if touchdown is None:
        lines.append("  touchdown                 : none (timeout)")
    else:
        omega0 = result.nominal_rotor_speed
        lines.append(
            f"  touchdown                 : {touchdown.descent_rate / FT:.1f} ft/s (limit "
            f"{limits.max_descent_rate / FT:.0f}), {touchdown.forward_speed / KT:.1f} kt (limit "
            f"{limits.max_forward_speed / KT:.0f}), rotor {100 * touchdown.rotor_speed / omega0:.0f} % (in flight "
            f"{100 * touchdown.min_rotor_speed / omega0:.1f}-{100 * touchdown.max_rotor_speed / omega0:.1f} %, limits "
            f"{100 * limits.min_rotor_speed_ratio:.0f}-{100 * limits.max_rotor_speed_ratio:.0f} %, "
            f"{100 * result.flyability.touchdown_min_rotor_speed_ratio:.0f} % below "
            f"{result.flyability.commit_height / FT:.0f} ft), {touchdown.time_after_failure:.1f} s after the failure"
        )
    site = result.site
    if site is not None:
        where = f"{result.touchdown_distance / FT:.0f} ft along the track"
        answer = "ON the site" if result.on_site else "OFF the site"
        planned = [record for record in result.plans if not record.fallback]
        for_site = sum(record.plan.touchdown_window is not None for record in planned)
        lines.append(
            f"  landing site              : {site.name} {site.start_m / FT:.0f}-{site.end_m / FT:.0f} ft; touched down "
            f"{where}: {answer} ({site.margin_m(result.touchdown_distance) / FT:+.0f} ft inside its nearer end); "
            f"{for_site} of {len(planned)} plans made for it"
        )
    verdict = (
        "SAFE: landed within limits" + (" on the site" if site is not None else "")
        if result.landed_within_limits
        else "UNSAFE: " + (touchdown.reason if touchdown is not None else "no touchdown")
    )
    if touchdown is not None and touchdown.within_limits and not result.landed_within_limits:
        verdict = "NOT ON THE SITE: landed within limits, off the site"
    lines.append(f"  result                    : {verdict}")
    lines.append(f"  MCAP log                  : {result.log_path} ({result.message_count} messages)")
    for figure in result.figures:
        lines.append(f"  figure                    : {figure}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``python -m helireach_ros.cli.demo``; exits 0 only if the landing met the limits."""
    parser = argparse.ArgumentParser(prog="helireach-demo", description=__doc__.split("\n\n")[0])
    _add_arguments(parser)
    arguments = parser.parse_args(argv)
    return _run(arguments)


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out", help="folder for the figures and the MCAP log")
    parser.add_argument("--scenario", default=None, help="simulated scenario (default: demo_500ft_75kt)")
    parser.add_argument(
        "--mismatch",
        choices=MISMATCH_PRESET_NAMES,
        default=None,
        help="model mismatch the vehicle flies instead of the scenario's own (default: the scenario's; "
        "demo_500ft_75kt's is drag+5)",
    )
    parser.add_argument(
        "--estimate-weight",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="the planner plans for the gross weight it estimates before the failure (default: on with --mismatch, "
        "else the planner's parameter, off)",
    )
    parser.add_argument(
        "--robust-verification",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="verify the failure plan robustly in a low-priority process (planner parameter robust_verification; "
        "default: on)",
    )
    parser.add_argument(
        "--site-ft",
        default=None,
        metavar="START:END",
        help="a landing site along the track, ft from where the run starts (the failure comes ~415 ft in); the "
        "planner lands on it (e.g. 2400:2800)",
    )
    parser.add_argument(
        "--footprint-period",
        type=float,
        default=0.0,
        metavar="S",
        help="the planner's live reachable footprint at most every S s before the failure (0 = off, the default)",
    )
    parser.add_argument(
        "--headwind-kt",
        "--wind-kt",
        type=float,
        default=0.0,
        help="a steady wind along the track [kt], positive against the flight: the vehicle flies in it, the planner "
        "plans for it (the status node has no envelope for it: the shipped ones are calm)",
    )
    parser.add_argument("--hold", action="store_true", help="keep the nodes running after touchdown until Ctrl-C")
    parser.add_argument(
        "--no-display", dest="display", action="store_false", help="do not serve the cockpit display page"
    )
    parser.add_argument("--params-file", action="append", default=[], help="extra ROS parameter file (repeatable)")
    parser.add_argument(
        "--executor", choices=EXECUTOR_KINDS, default=DEFAULT_EXECUTOR, help="executor kind (default: %(default)s)"
    )


def register(subparsers: Any) -> None:
    """Adds ``helireach demo`` (the same options as ``python -m helireach_ros.cli.demo``)."""
    parser = subparsers.add_parser("demo", help="the engine-failure demo", description=__doc__.split("\n\n")[0])
    _add_arguments(parser)
    parser.set_defaults(handler=_run)


def _run(arguments: argparse.Namespace) -> int:
    try:
        site = demo_site(arguments.site_ft) if arguments.site_ft else None
        result = run_demo(
            arguments.out,
            arguments.scenario,
            hold=arguments.hold,
            display=arguments.display,
            params_files=tuple(arguments.params_file),
            executor=arguments.executor,
            mismatch=arguments.mismatch,
            estimate_weight=arguments.estimate_weight,
            robust_verification=arguments.robust_verification,
            site=site,
            footprint_period_s=arguments.footprint_period,
            headwind_kt=arguments.headwind_kt,
        )
    except (FileNotFoundError, ValueError) as error:  # a missing parameter file, a bad parameter or scenario
        print(f"helireach demo: {error}", file=sys.stderr)
        return 2
    print(summary(result), flush=True)
    return 0 if result.landed_within_limits else 1


if __name__ == "__main__":
    sys.exit(main())
