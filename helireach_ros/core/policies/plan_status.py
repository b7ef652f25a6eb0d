"""What the planner node says about its plans, without ROS: each status as a level, a text and its key-values.

Every ``DiagnosticStatus`` the planner node publishes is built here as a :class:`StatusReport`; the node only turns
it into a message (name, hardware id). The keys are the contracts of msg_docs/helireach_plan_status.md,
helireach_live_reachability.md and helireach_robust_verdict.md:

* a converged plan (:func:`converged_plan_report`): safe, unverified or unsafe, first plan, standby or re-plan;
* a fallback (:func:`fallback_report`): controls without a converged solve, never safe;
* no plan at all (:func:`no_plan_report`): no state, no planner;
* the episode over (:func:`episode_end_report`): engine recovered or landed, the last trajectory no longer applies;
* a live verdict (:func:`live_report`) and a robust verdict (:func:`robust_report`);
* the node's own health on ``/diagnostics`` (:func:`planner_health_report`, msg_docs/diagnostics.md).

Levels are the ``DiagnosticStatus`` level names (``OK``, ``WARN``, ``ERROR``, ``STALE``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.estimation.weight_tracking import WeightChoice
from helireach_ros.core.evidence.plan_verdict import plan_verdict
from helireach_ros.core.policies.failure_episode import EpisodePhase, PlanLateness, late_verdict
from helireach_ros.core.status_contracts import (
    ROBUST_PENDING,
    LiveVerdictValues,
    PlanStatusValues,
    RobustVerdictValues,
)

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy as np

    from helireach_ros.core.planning.fallback import FallbackPlan
    from helireach_ros.core.policies.failure_episode import EpisodeState, FailureEpisode
    from helireach_ros.core.policies.live_reachability import LiveEvaluator, LiveVerdict

__all__ = [
    "PlannerHealth",
    "PlannerIdentity",
    "SolverPoolHealth",
    "StatusReport",
    "converged_plan_report",
    "episode_end_report",
    "fallback_report",
    "flyability_values",
    "lateness_values",
    "live_report",
    "no_plan_report",
    "plan_values",
    "planner_health_report",
    "robust_report",
    "site_text",
    "weight_values",
]


@dataclass(frozen=True)
class StatusReport:
    """One status: its level name, its text and its key-values (SI, as msg_docs lists them)."""

    level: str
    text: str
    values: dict[str, Any]


@dataclass(frozen=True)
class PlannerIdentity:
    """What every plan status names about the aircraft and the planner's evidence.

    Attributes:
        airframe: the airframe's name.
        gross_weight: N, the configured aircraft's (``gross_weight_n``; the recorder's run metadata adopts it).
        density_altitude: m.
        envelope_id: the envelope used for warm starts and fallbacks ("" = none).
    """

    airframe: str
    gross_weight: float
    density_altitude: float
    envelope_id: str = ""


def flyability_values(report: Any) -> dict[str, Any]:
    """The replay's flyability check: what the plan asks of the aircraft (SI) and the limits it breaks ("" = none)."""
    return {
        "flyable": report.within_limits,
        "flyability_violations": "; ".join(report.violations),
        "max_pitch_rate_rad_s": report.max_pitch_rate,
        "max_collective_rate_per_s": report.max_collective_rate,
        "max_nose_up_pitch_rad": report.max_nose_up_pitch,
        "touchdown_pitch_rad": math.nan if report.touchdown_pitch is None else report.touchdown_pitch,
    }


def plan_values(plan: Any) -> dict[str, Any]:
    """The values that describe a converged plan itself (a :class:`~helireach_ros.core.planning.planner.LandingPlan`);
    the node's bookkeeping (warm start, re-plan index, latency, failure and state) is added by the reports below."""
    touchdown = plan.replay.touchdown_state
    verdict = PlanStatusValues(
        status=plan.status,
        safe=plan.safe,
        verified=plan.verified,
        fallback=False,
        value=plan.value,
        time_to_land_s=plan.time_to_land,
        solve_time_ms=plan.solver.solve_time_ms,
        touchdown_descent_rate=float(touchdown[StateIndex.DESCENT_RATE]),
        touchdown_forward_speed=float(touchdown[StateIndex.FORWARD_SPEED]),
        touchdown_rotor_speed=float(touchdown[StateIndex.ROTOR_SPEED]),
        reaction_delay_s=plan.reaction_delay_s,
        initial_control=tuple(plan.initial_control),
        disturbance=tuple(plan.disturbance),
    )
    return {
        **verdict.to_values(),
        "iterations": plan.solver.iterations,
        "solver_status": plan.solver.status,
        "method": plan.method,
        "headwind_m_s": plan.headwind,
        **flyability_values(plan.replay.flyability),
    }


def lateness_values(lateness: PlanLateness | None) -> dict[str, Any]:
    """``late``, ``late_by_s``, ``state_delay_s``, ``after_fallback`` (None, as for re-plans: not late, no delay)."""
    if lateness is None:
        return {**PlanStatusValues(late=False, late_by_s=0.0).to_values(), "after_fallback": False}
    late = PlanStatusValues(late=lateness.late, late_by_s=lateness.late_by_s, state_delay_s=lateness.state_delay_s)
    return {**late.to_values(), "after_fallback": lateness.after_fallback}


def weight_values(configured_weight: float, weight: WeightChoice) -> dict[str, Any]:
    """The weight a plan was made for; ``gross_weight_n`` stays the configured aircraft's."""
    return {
        **PlanStatusValues(gross_weight=configured_weight, planned_gross_weight=weight.gross_weight).to_values(),
        "gross_weight_source": weight.source,
        "gross_weight_change": weight.relative_change,
        "gross_weight_estimate_change": weight.estimated_change,
        "gross_weight_reason": weight.reason,
    }


def _episode_values(
    identity: PlannerIdentity,
    failure: FailureEpisode,
    state: Sequence[float] | np.ndarray,
    stamp_ns: int,
    weight: WeightChoice,
) -> dict[str, Any]:
    """Keys of every plan and fallback status: the failure, the state planned from, the aircraft."""
    episode = PlanStatusValues(
        failure_id=failure.failure_id,
        failure_stamp_ns=failure.event_stamp_ns,
        state_stamp_ns=stamp_ns,
        density_altitude=identity.density_altitude,
        initial_state=tuple(state),
    )
    return {
        **episode.to_values(),
        "airframe": identity.airframe,
        **weight_values(identity.gross_weight, weight),
        "envelope_id": identity.envelope_id,
    }


def converged_plan_report(
    plan: Any,
    *,
    identity: PlannerIdentity,
    failure: FailureEpisode,
    stamp_ns: int,
    warm_source: str,
    rotor_source: str,
    replan_index: int,
    lateness: PlanLateness | None,
    latency_ms: float,
    weight: WeightChoice,
    standby: bool,
    robust_design: str | None = None,
    sites: dict[str, Any] | None = None,
) -> StatusReport:
    """The status of a converged plan (first plan, standby or re-plan): its verdict, late at best WARN.

    ``lateness`` None for a re-plan; ``robust_design`` names the design its pending robust verification flies;
    ``sites`` the landing site's keys (:func:`~helireach_ros.core.policies.landing_sites.site_values`).
    """
    values = {
        **plan_values(plan),
        **PlanStatusValues(standby=standby, replan_index=replan_index).to_values(),
        "warm_start": warm_source,
        **lateness_values(lateness),
        "latency_ms": latency_ms,
        "rotor_speed_source": rotor_source,
        **_episode_values(identity, failure, plan.initial_state, stamp_ns, weight),
        **(sites or {}),
    }
    if robust_design is not None:
        values.update(PlanStatusValues(robust=ROBUST_PENDING).to_values(), robust_design=robust_design)
    level, text = plan_verdict(plan, rotor_source)
    text += site_text(sites or {}, plan.safe)
    if standby:
        state_age_s = (failure.event_stamp_ns - stamp_ns) * 1e-9
        text = f"STANDBY (live plan from {state_age_s:.2f} s before the failure; refining): {text}"
    if lateness is not None:
        level, text = late_verdict(level, text, lateness)
    return StatusReport(level, text, values)


def fallback_report(
    fallback: FallbackPlan,
    *,
    identity: PlannerIdentity,
    failure: FailureEpisode,
    state: Sequence[float] | np.ndarray,
    stamp_ns: int,
    reason: str,
    lateness: PlanLateness | None,
    latency_ms: float,
) -> StatusReport:
    """The status of a fallback: WARN, never safe; the file's model (no weight estimate behind it)."""
    weight = WeightChoice(identity.gross_weight, "file", 0.0, "fallback controls from the file's model")
    verdict = PlanStatusValues(
        status="fallback", safe=False, verified=False, fallback=True, standby=False, reason=reason,
        time_to_land_s=fallback.time_to_land,
    )  # fmt: skip
    values = {
        **verdict.to_values(),
        "fallback_kind": fallback.kind,
        "fallback_source_status": fallback.source_status,
        "latency_ms": latency_ms,
        **lateness_values(lateness),
        **_episode_values(identity, failure, state, stamp_ns, weight),
    }
    text = f"FALLBACK (not verified): {fallback.description}; {reason}"
    if lateness is not None:
        _, text = late_verdict("WARN", text, lateness)
    return StatusReport("WARN", text, values)


def no_plan_report(failure: FailureEpisode, text: str) -> StatusReport:
    """ERROR: no plan for the failure (no valid state, no planner), and why."""
    verdict = PlanStatusValues(
        status="none", safe=False, verified=False, fallback=False, reason=text, failure_id=failure.failure_id
    )
    return StatusReport("ERROR", f"NO PLAN: {text}", verdict.to_values())


_EPISODE_END = {
    EpisodePhase.ENDED: (
        "ended",
        "engine recovered: the failure flag stayed false for the recovery hold",
        "ENDED (engine recovered): no landing plan; the last trajectory no longer applies",
    ),
    EpisodePhase.LANDED: (
        "landed",
        "on the ground: the monitor saw the aircraft landed",
        "LANDED: planning stopped; the last trajectory no longer applies",
    ),
}


def episode_end_report(
    failure: FailureEpisode, outcome: EpisodePhase, episode: EpisodeState, now_ns: int
) -> StatusReport:
    """WARN: the episode is over (``ended`` or ``landed``): a late joiner's latched status is not the last plan of an
    episode that is over."""
    status, reason, text = _EPISODE_END[outcome]
    verdict = PlanStatusValues(
        status=status, safe=False, verified=False, fallback=False, reason=reason, failure_id=failure.failure_id,
        failure_stamp_ns=failure.event_stamp_ns,
    )  # fmt: skip
    values = {
        **verdict.to_values(),
        "ended_stamp_ns": episode.ended_ns if episode.ended_ns is not None else now_ns,
        "episode_id": episode.episode_id,
        "plans_published": len(failure.history),
        "replans": failure.replans,
    }
    return StatusReport("WARN", text, values)


def live_report(
    verdict: LiveVerdict,
    *,
    standby: bool,
    weight: WeightChoice,
    configured_weight: float,
    power_fraction: float,
    now_ns: int,
    sites: dict[str, Any] | None = None,
) -> StatusReport:
    """A live verdict ("if the engine failed now"): OK only for a replay-verified safe plan; no plan or a solver
    that did not converge is ERROR (unknown, never unsafe by default). ``sites``: the landing site's keys
    (:func:`~helireach_ros.core.policies.landing_sites.site_values`), and the text says whether it is reachable."""
    plan = verdict.plan
    verified = plan is not None and plan.verified
    live = LiveVerdictValues(
        status=verdict.status,
        value=verdict.value,
        safe=verdict.safe,
        verified=verified,
        state_stamp_ns=verdict.state_stamp_ns,
        solve_time_ms=verdict.solve_time_ms,
        state_age_s=verdict.state_age_s(now_ns),
        time_to_land_s=plan.time_to_land if plan is not None else math.nan,
        power_fraction=power_fraction,
        reason=verdict.reason,
        standby=standby,
        state=tuple(verdict.state),
    )
    values = {
        **live.to_values(),
        **weight_values(configured_weight, weight),
        "headwind_m_s": plan.headwind if plan is not None else math.nan,
        **(sites or {}),
    }
    if plan is None:
        return StatusReport("ERROR", f"LIVE ERROR: no verdict ({verdict.reason})", values)
    if not plan.solver.success:  # plan_verdict would call it unsafe: it is unknown
        return StatusReport("ERROR", f"if the engine failed now: UNKNOWN (solver {plan.solver.status})", values)
    _, text = plan_verdict(plan, "measured")
    level = "OK" if verdict.safe and verified else "ERROR"
    return StatusReport(level, f"if the engine failed now: {text}{site_text(sites or {}, plan.safe)}", values)


def site_text(sites: dict[str, Any], safe: bool) -> str:
    """What a status text adds about its landing site ("" without one): on it, or not reachable (and, for a safe
    plan, that it lands off-site: a state that can land is not called unsafe for want of a site)."""
    if "landing_site" not in sites or "on_site" not in sites:
        return ""
    name = sites["landing_site"]
    if sites["on_site"]:
        return f"; on site {name} ({sites['site_margin_m']:.0f} m inside its nearer end)"
    if safe and not sites["site_planned"]:
        return f"; site {name} NOT reachable: landing off-site at {sites['touchdown_distance_m']:.0f} m along the track"
    return f"; site {name} NOT reachable"


def robust_report(key: tuple[int, int, int], summary: Any | None, design: str) -> StatusReport:
    """A failure plan's robust verdict (a :class:`~helireach_ros.core.robustness.verification.RobustSummary`), keyed by
    (failure id, failure stamp, state stamp); None: pending (STALE)."""
    failure_id, failure_stamp_ns, stamp_ns = key
    belongs_to = RobustVerdictValues(failure_id=failure_id, failure_stamp_ns=failure_stamp_ns, state_stamp_ns=stamp_ns)
    values: dict[str, Any] = belongs_to.to_values()
    if summary is None:
        values.update(RobustVerdictValues(robust=ROBUST_PENDING, design=design).to_values())
        return StatusReport("STALE", f"PENDING: robust verification running ({design})", values)
    values.update(summary.values())
    if summary.robust:
        text = f"ROBUST: lands closed loop in all {summary.models_flown} models ({summary.design})"
        return StatusReport("OK", text, values)
    return StatusReport("ERROR" if summary.error else "WARN", f"NOT ROBUST: {summary.reason}", values)


@dataclass(frozen=True)
class SolverPoolHealth:
    """The solver pool's workers now: configured, ready, busy, restarts since start-up and the last error."""

    workers: int
    ready: int
    busy: int
    restarts: int
    last_error: str


@dataclass(frozen=True)
class PlannerHealth:
    """What the planner node knows of itself for ``/diagnostics``.

    Attributes:
        airframe, method: the aircraft's name and the planner's method.
        startup_s, warm_up_ms: start-up time; the in-process warm-up solve's (NaN with a pool).
        envelope_note: which envelope is used, or why none; ``has_envelope``: one is.
        failures: failures handled; ``solving``: a solve is pending or running; ``episode_phase``: the monitor's.
        solve_timeout_s: a failure plan's timeout; ``ready_weights``: weights a ready solver holds.
        weight_now: the weight a failure now would be planned for.
        airframe_problems: derived figures outside helicopter ranges.
        pool: the solver pool's workers (None: solving in the node's process).
        rotor_measured: the current state's rotor speed is measured (None: no current state).
    """

    airframe: str
    method: str
    startup_s: float
    warm_up_ms: float
    envelope_note: str
    has_envelope: bool
    failures: int
    solving: bool
    episode_phase: str
    solve_timeout_s: float
    ready_weights: int
    weight_now: WeightChoice
    airframe_problems: tuple[str, ...] = ()
    pool: SolverPoolHealth | None = None
    rotor_measured: bool | None = None


def planner_health_report(
    health: PlannerHealth, live: LiveEvaluator | None, failure: FailureEpisode | None
) -> StatusReport:
    """The planner's ``/diagnostics`` status: ERROR with no solver worker ready (failures get fallbacks), WARN with
    any other problem or without an envelope (cold starts), else OK."""
    weight = health.weight_now
    values: dict[str, Any] = {
        "airframe": health.airframe,
        "method": health.method,
        "startup_s": health.startup_s,
        "warm_up_ms": health.warm_up_ms,
        "envelope": health.envelope_note,
        "failures": health.failures,
        "solving": health.solving,
        "failure_episode": health.episode_phase,
        "solver_workers": health.pool.workers if health.pool is not None else 0,
        "solve_timeout_s": health.solve_timeout_s,
        "ready_weights": health.ready_weights,
        "weight_estimate_n": weight.gross_weight,
        "weight_estimate_source": weight.source,
        "weight_estimate_change": weight.relative_change,
        "weight_estimate_reason": weight.reason,
    }
    problems = [f"implausible airframe: {problem}" for problem in health.airframe_problems]
    pool = health.pool
    if pool is not None:
        values.update(
            ready_workers=pool.ready, busy_workers=pool.busy, worker_restarts=pool.restarts,
            last_worker_error=pool.last_error,
        )  # fmt: skip
        if pool.ready == 0:
            problems.append("no solver worker ready (failures get fallbacks)")
        if pool.restarts:
            problems.append(f"{pool.restarts} solver worker restarts (last: {pool.last_error})")
    if live is not None:
        latest = live.latest
        values.update(
            live_rate_hz=live.settings.rate_hz,
            live_evaluations=live.evaluations,
            live_errors=live.errors,
            live_clock_jumps_back=live.clock_jumps_back,
            live_status=latest.status if latest is not None else "none",
            standby_available=live.standby_verdict is not None,
        )
    else:
        values["live_rate_hz"] = 0.0
    if failure is not None:
        values.update(
            failure_active=failure.active, replans=failure.replans, replans_failed=failure.replans_failed,
            replans_skipped_no_rotor=failure.replans_skipped_no_rotor, replans_kept_out=failure.replans_kept_out,
        )  # fmt: skip
        if failure.active and failure.replans_skipped_no_rotor and health.rotor_measured is False:
            problems.append("re-planning paused: no measured rotor speed (the current plan is kept)")
        values["failure_outcome"] = failure.outcome
        if failure.current is not None:
            values["last_latency_ms"] = failure.current.latency_ms
    level = "OK" if health.has_envelope and not problems else "WARN"
    level = "ERROR" if pool is not None and pool.ready == 0 else level
    text = "; ".join(["ready" if health.has_envelope else "ready without an envelope (cold starts)", *problems])
    return StatusReport(level, text, values)
