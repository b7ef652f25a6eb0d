"""The published safety status: never wider than its evidence.

Two kinds of evidence can say SAFE before a failure: the **envelope** (a level-trim H-V table, valid only
inside its :class:`~helireach_ros.core.envelope.domain.ValidityDomain`) and the **live verdict** (the landing
NLP solved and replayed from the measured state, :mod:`helireach_ros.core.policies.live_reachability`). After a
failure, the only evidence is the planner's **current plan**. Levels are
``diagnostic_msgs/DiagnosticStatus`` names (the ROS layer maps them).

Before a failure (the rules, in order):

================================================  ===========================================================
situation                                         status
================================================  ===========================================================
no valid, fresh state                             STALE (why)
inside the domain, current live verdict           the more conservative of the two; except that a
                                                  replay-verified live SAFE overrides an envelope answer
                                                  that is not-safe *only by interpolation* (the enclosing
                                                  grid nodes disagree), and the text says so
inside the domain, no current live verdict        the envelope's answer
outside the domain, current live verdict          the live verdict alone (the text names the domain breach)
outside the domain, no current live verdict       STALE: no evidence covers this state (the text says why)
no envelope                                       the live verdict, else STALE
rotor speed not measured                          at most WARN (the envelope assumes Ω₀)
================================================  ===========================================================

Envelope answers: OK safe and at least ``warn_margin`` (ft/kt) from the boundary, WARN safe but closer,
ERROR not proven safe (unsafe, unverified, failed or outside the grid). An envelope with robust verdicts
(:mod:`helireach_ros.core.robustness.envelope_verdicts`) answers by them where it has them (the status node's
``envelope_verdict``): OK then means safe *and* robust (the closed loop lands in every perturbed model flown),
the margin is to the not-robustly-safe set, and a node safe in the nominal model only is WARN (CAUTION: not
robust); the values say which verdict was used (``envelope_verdict``) and, when the robust one was asked for
but not available, why. Live answers: OK safe, WARN safe
with J above ``live_warn_value`` (a touchdown near a limit), ERROR anything else (unsafe, unverified,
failed, solver error).

After a failure (episode ``failed``) the status is the current plan's: OK for a replay-verified plan
(standby or refined; WARN when it was made late), ERROR for a fallback (never verified), an unverified or
unsafe plan, or no plan yet. The plan's word ages with the evidence that the aircraft is flying it, by the rules
before a failure: without a valid, fresh state a verified plan is STALE (nobody knows whether it is being tracked),
and without a fresh rotor-speed reading it is at most WARN (it is safe only if the rotor is where it planned).
``landed``: STALE (the envelope does not apply on the ground). ``ended`` (engine recovered): the rules
before a failure apply again.

Input problems (an input with incompatible QoS, :mod:`helireach_ros.core.policies.qos_problems`) make any status
ERROR, whatever the evidence.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from helireach_ros.core.envelope.domain import DomainCheck, ValidityDomain
from helireach_ros.core.policies.vehicle_readings import OdometryReading, StateLimits, state_problems
from helireach_ros.core.status_contracts import LiveVerdictValues, PlanStatusValues, SafetyStatusValues
from helireach_ros.core.units import FT, KT

__all__ = [
    "LEVEL_ORDER",
    "LIVE_WARN_VALUE",
    "EnvelopeEvidence",
    "LiveEvidence",
    "PlanEvidence",
    "SafetyDecision",
    "assess_safety",
    "decide_safety_status",
    "envelope_domain",
    "live_evidence",
    "more_conservative",
    "plan_evidence",
]

LEVEL_ORDER = {"OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}
"""Conservatism of the levels (a higher one wins): STALE (no evidence) above ERROR (evidence of danger)."""

LIVE_WARN_VALUE = -0.05
"""A safe live verdict with J above this is CAUTION: its touchdown is within 5 % of a landing limit (assumed).
Not −0.1: with the momentum rotor and the flyability limits, the gentlest touchdown from the heart of the envelope
(500 ft, 75 kt) is at J ≈ −0.10 (7.2 ft/s of 8, 13.5 kt of 15; flare held at 25° and 20°/s), and the shipped
envelope's safe level-flight nodes sit at −0.09 to −0.11 wherever they are not next to the boundary, so a caution at
−0.1 would be on nearly everywhere and tell the crew nothing; the boundary layer's nodes are at −0.07 to 0."""


def more_conservative(first: str, second: str) -> str:
    """The more conservative of two level names."""
    return first if LEVEL_ORDER[first] >= LEVEL_ORDER[second] else second


@dataclass(frozen=True)
class EnvelopeEvidence:
    """The envelope's answer at the measured height and speed.

    Attributes:
        status: the query's status (``safe``, ``unsafe``, ``unverified``, ``failed``, ``no_trim`` (a 3-D
            envelope node without steady flight), ``outside``).
        margin: ft/kt from the not-proven-safe set (signed).
        by_interpolation: the enclosing grid nodes disagree (some safe, some not).
        domain: whether the measured state lies in the envelope's validity domain.
        verdict: ``"robust"`` or ``"nominal"``: what the answer rests on
            (:attr:`~helireach_ros.core.envelope.data.EnvelopeQuery.verdict`).
        verdict_note: why the answer is nominal when the robust verdict was asked for ('' otherwise).
    """

    status: str
    margin: float
    by_interpolation: bool
    domain: DomainCheck
    verdict: str = "nominal"
    verdict_note: str = ""


@dataclass(frozen=True)
class LiveEvidence:
    """A live verdict (:class:`~helireach_ros.core.policies.live_reachability.LiveVerdict`) as the status sees it.

    Attributes:
        status: ``safe``, ``unsafe``, ``unverified``, ``failed`` or ``error``.
        value: the NLP value J.
        verified: the replay landed within limits.
        state_age_s: how old its state is now, s.
        current: young enough to be evidence.
        reason: for ``error``.
    """

    status: str
    value: float
    verified: bool
    state_age_s: float
    current: bool
    reason: str = ""


@dataclass(frozen=True)
class PlanEvidence:
    """The planner's current plan after a failure (None in :func:`decide_safety_status`: no plan yet).

    Attributes:
        status: the plan status as published (``safe``, ``unsafe``, ``unverified``, ``fallback``, ``none``, ...).
        verified: a replay-verified safe plan.
        standby: made before the failure by the live evaluation.
        time_to_land_s: s.
        late: made from a state stamped more than the planner's ``max_message_age`` after the failure.
    """

    status: str
    verified: bool
    standby: bool = False
    time_to_land_s: float = math.nan
    late: bool = False


@dataclass(frozen=True)
class SafetyDecision:
    """The status to publish: level name, one line for people, what it rests on, and published values."""

    level: str
    message: str
    source: str
    values: dict[str, Any] = field(default_factory=dict)


def _where(height: float, speed: float) -> str:
    return f"{height / FT:.0f} ft, {speed / KT:.0f} kt"


def _envelope_level(evidence: EnvelopeEvidence, warn_margin: float) -> tuple[str, str]:
    robust = " (robust)" if evidence.verdict == "robust" else ""
    if evidence.status == "safe":
        if evidence.margin >= warn_margin:
            return "OK", f"SAFE{robust}: margin {evidence.margin:.0f}"
        return "WARN", f"CAUTION{robust}: {evidence.margin:.0f} from the boundary"
    if evidence.status == "not_robust":
        return "WARN", "CAUTION: safe in the nominal model only, not robust to the model's uncertainty"
    if evidence.status == "outside":
        return "ERROR", "AVOID: outside the envelope grid, unknown"
    if evidence.status == "unsafe":
        return "ERROR", "AVOID: no safe landing"
    if evidence.status == "no_trim":
        return "ERROR", "AVOID: safe landing not proven, no steady flight at this climb rate in the envelope"
    return "ERROR", f"AVOID: safe landing not proven, {evidence.status}"


def _live_level(evidence: LiveEvidence, live_warn_value: float) -> tuple[str, str]:
    if evidence.status == "safe" and evidence.verified:
        if evidence.value > live_warn_value:
            return "WARN", f"CAUTION (live): landing near a limit, J {evidence.value:+.2f}"
        return "OK", f"SAFE (live, verified): J {evidence.value:+.2f}"
    if evidence.status == "unsafe":
        return "ERROR", f"AVOID (live): no safe landing from this state, J {evidence.value:+.2f}"
    if evidence.status == "error":
        return "ERROR", f"AVOID (live): not evaluated ({evidence.reason})"
    return "ERROR", f"AVOID (live): safe landing not proven, {evidence.status}"


def _after_failure(plan: PlanEvidence | None, state_problem: str, rotor_measured: bool) -> tuple[str, str, str]:
    level, text, source = _plan_level(plan)
    if state_problem:
        level, text = more_conservative(level, "STALE"), f"{text}; NOT TRACKED: {state_problem}"
    elif not rotor_measured:
        level = more_conservative(level, "WARN")
        text = f"{text}; rotor speed not measured: safe only if it is nominal"
    return level, text, source


def _plan_level(plan: PlanEvidence | None) -> tuple[str, str, str]:
    if plan is None:
        return "ERROR", "ENGINE FAILURE: no landing plan yet", "plan"
    if plan.verified and plan.status == "safe":
        kind = "standby plan" if plan.standby else "landing plan"
        if plan.late:  # verified for a state the aircraft was in later than the failure: not the whole story
            return "WARN", f"ENGINE FAILURE: {kind} verified but LATE, land in {plan.time_to_land_s:.1f} s", "plan"
        return "OK", f"ENGINE FAILURE: {kind} verified, land in {plan.time_to_land_s:.1f} s", "plan"
    if plan.status == "fallback":
        return "ERROR", "ENGINE FAILURE: FALLBACK controls, not verified", "plan"
    return "ERROR", f"ENGINE FAILURE: plan {plan.status}, not verified", "plan"


def decide_safety_status(
    *,
    height: float,
    forward_speed: float,
    state_problem: str = "",
    envelope: EnvelopeEvidence | None,
    envelope_note: str = "",
    live: LiveEvidence | None,
    episode: str = "normal",
    plan: PlanEvidence | None = None,
    input_problems: Sequence[str] = (),
    warn_margin: float = 20.0,
    live_warn_value: float = LIVE_WARN_VALUE,
    rotor_measured: bool = True,
) -> SafetyDecision:
    """The safety status from every piece of evidence (the rules are in the module docstring).

    Args:
        height, forward_speed: the measured state, m and m/s (for the text).
        state_problem: why there is no valid, fresh state ('' = there is one).
        envelope: the envelope's answer, or None (no envelope: ``envelope_note`` says why).
        envelope_note: why there is no envelope.
        live: the latest live verdict, or None.
        episode: the failure episode's state (``normal``, ``failed``, ``ended``, ``landed``).
        plan: the planner's current plan after a failure.
        input_problems: inputs with incompatible QoS (each makes the status ERROR).
        warn_margin: envelope WARN margin, ft/kt.
        live_warn_value: live WARN above this J.
        rotor_measured: a fresh rotor-speed reading exists (before a failure the envelope's domain check says the
            same; after it, a plan is then at most WARN).
    """
    values: dict[str, Any] = {"episode": episode}
    if episode == "failed":
        level, text, source = _after_failure(plan, state_problem, rotor_measured)
    elif episode == "landed":
        level, text, source = "STALE", "LANDED: the envelope does not apply on the ground", "none"
    elif state_problem:
        missing = f"; no envelope ({envelope_note})" if envelope is None and envelope_note else ""
        level, text, source = "STALE", f"NO DATA: {state_problem}{missing}", "none"
    else:
        level, text, source = _before_failure(
            _where(height, forward_speed), envelope, envelope_note, live, warn_margin, live_warn_value, values
        )
    if input_problems:
        problems = "; ".join(input_problems)
        values["input_qos_problems"] = problems
        level, text = "ERROR", f"INPUT QOS: incompatible QoS, not trusted ({problems}); {text}"
    values["evidence"] = source
    return SafetyDecision(level, text, source, values)


def _before_failure(
    where: str,
    envelope: EnvelopeEvidence | None,
    envelope_note: str,
    live: LiveEvidence | None,
    warn_margin: float,
    live_warn_value: float,
    values: dict[str, Any],
) -> tuple[str, str, str]:
    current_live = live if live is not None and live.current else None
    if live is not None:
        values.update(live_status=live.status, live_value=live.value, live_state_age_s=live.state_age_s)
    if envelope is not None:
        values.update(SafetyStatusValues(margin=envelope.margin).to_values())
        values.update(
            envelope_status=envelope.status,
            in_domain=envelope.domain.inside,
            domain=" ; ".join(envelope.domain.reasons),
            envelope_verdict=envelope.verdict,
        )
        if envelope.verdict_note:
            values["envelope_verdict_note"] = envelope.verdict_note
    if envelope is None or not envelope.domain.inside:
        why = (
            f"no envelope ({envelope_note})"
            if envelope is None
            else (f"outside the envelope's domain ({'; '.join(envelope.domain.reasons)})")
        )
        if current_live is None:
            stale = "no current live verdict" if live is None else f"live verdict {live.state_age_s:.1f} s old"
            return "STALE", f"NO DATA: {why} and {stale} ({where})", "none"
        level, text = _live_level(current_live, live_warn_value)
        return level, f"{text} ({where}; {why})", "live"
    envelope_level, envelope_text = _envelope_level(envelope, warn_margin)
    if not envelope.domain.known:
        # The envelope assumes what was not measured: never better than CAUTION on its word alone.
        envelope_level = more_conservative(envelope_level, "WARN")
        envelope_text += f" ({'; '.join(envelope.domain.reasons)})"
    if current_live is None:
        return envelope_level, f"{envelope_text} ({where})", "envelope"
    live_level, live_text = _live_level(current_live, live_warn_value)
    if live_level == "OK" and envelope_level == "ERROR" and envelope.by_interpolation:
        return "OK", f"{live_text} ({where}; the envelope is not proven safe here only by interpolation)", "live"
    level = more_conservative(envelope_level, live_level)
    source = "envelope+live"
    text = envelope_text if LEVEL_ORDER[envelope_level] >= LEVEL_ORDER[live_level] else live_text
    return level, f"{text} ({where}; envelope {envelope_level}, live {live_level})", source


@functools.lru_cache(maxsize=4)
def envelope_domain(envelope: Any) -> tuple[ValidityDomain, float]:
    """(validity domain, Ω₀ of its airframe) of a loaded envelope: read once, not at every state message."""
    metadata = envelope.metadata
    return envelope.validity_domain, float(metadata["airframe"]["nominal_rotor_speed"])


def assess_safety(
    envelope: Any | None,
    reading: OdometryReading | None,
    state_age_s: float,
    stale_timeout_s: float,
    warn_margin: float,
    envelope_error: str = "",
    limits: StateLimits | None = None,
    input_problems: Sequence[str] = (),
    *,
    rotor_speed: float | None = None,
    live: LiveEvidence | None = None,
    episode: str = "normal",
    plan: PlanEvidence | None = None,
    live_warn_value: float = LIVE_WARN_VALUE,
    envelope_verdict: str = "robust",
) -> SafetyDecision:
    """The safety status of a state: the evidence gathered here, decided by :func:`decide_safety_status` (the
    module docstring has the rules).

    Args:
        envelope: the loaded :class:`~helireach_ros.core.envelope.data.Envelope`, or None.
        reading: the latest state, or None if none was received.
        state_age_s: time since that state was received, s.
        stale_timeout_s: older states are stale.
        warn_margin: WARN below this margin (ft/kt units).
        envelope_error: why there is no envelope.
        limits: plausible ranges (default :class:`~helireach_ros.core.policies.vehicle_readings.StateLimits`).
        input_problems: one line per input with incompatible QoS (``<node>: <topic>: ...``).
        rotor_speed: the fresh measured rotor speed, rad/s (None: not measured).
        live: the latest live verdict (``/helireach/live_reachability``), or None.
        episode: the failure episode's phase (``/helireach/failure_episode``).
        plan: the current plan of the episode (``/helireach/plan_status``), or None.
        live_warn_value: live WARN above this J.
        envelope_verdict: ``robust`` (the envelope's robust verdict where it has one) or ``nominal``.
    """
    values: dict[str, Any] = {
        **SafetyStatusValues(
            envelope_id=envelope.envelope_id if envelope is not None else "",
            envelope_conditions=envelope.conditions if envelope is not None else "",
        ).to_values(),
        "warn_margin_ft_kt": warn_margin,
    }
    state_problem = ""
    height = forward_speed = math.nan
    if reading is None:
        state_problem = "no vehicle state received"
    else:
        values.update(
            height_m=reading.height,
            forward_speed_m_s=reading.forward_speed,
            climb_rate_m_s=reading.climb_rate,
            state_age_s=state_age_s,
            state_stamp_ns=reading.stamp_ns,
        )
        problems = state_problems(limits or StateLimits(), odometry=reading)
        if state_age_s > stale_timeout_s:
            state_problem = f"vehicle state {state_age_s:.1f} s old"
        elif problems:
            state_problem = f"invalid state ({'; '.join(problems)})"
        height, forward_speed = max(reading.height, 0.0), reading.forward_speed
    evidence = None
    if envelope is not None and reading is not None and not state_problem:
        # a 3-D envelope answers at the measured climb rate; a 2-D one at level trim, its domain checks the rest
        climb_rate = reading.climb_rate if envelope.is_3d else 0.0
        query = envelope.query(height, forward_speed, climb_rate, envelope_verdict)
        validity_domain, omega0 = envelope_domain(envelope)
        domain = validity_domain.check(reading.climb_rate, rotor_speed, omega0, power_fraction=envelope.power_fraction)
        note = ""
        if envelope_verdict == "robust" and query.verdict != "robust":
            note = (
                "the envelope has no robust verdict" if not envelope.has_robust_verdict
                else "no robust verdict at this state's grid nodes"
            )  # fmt: skip
        evidence = EnvelopeEvidence(query.status, query.margin, query.by_interpolation, domain, query.verdict, note)
        values["envelope_value"] = query.value
    decision = decide_safety_status(
        height=height,
        forward_speed=forward_speed,
        state_problem=state_problem,
        envelope=evidence,
        envelope_note=envelope_error,
        live=live,
        episode=episode,
        plan=plan,
        input_problems=input_problems,
        warn_margin=warn_margin,
        live_warn_value=live_warn_value,
        rotor_measured=rotor_speed is not None,
    )
    return dataclasses.replace(decision, values={**values, **decision.values})


def live_evidence(values: Mapping[str, str], now_ns: int, max_age_s: float) -> LiveEvidence | None:
    """A ``/helireach/live_reachability`` message as evidence (its age counted on this node's clock); None when its
    status or state stamp is missing or unreadable (no evidence, never a SAFE)."""
    live = LiveVerdictValues.from_values(values)
    if live.status is None or live.state_stamp_ns is None or ("value" in values and live.value is None):
        return None
    state_age_s = (now_ns - live.state_stamp_ns) * 1e-9
    return LiveEvidence(
        status=live.status,
        value=math.nan if live.value is None else live.value,
        verified=live.verified is True,
        state_age_s=state_age_s,
        current=0.0 <= state_age_s <= max_age_s,
        reason=live.reason or "",
    )


def plan_evidence(values: Mapping[str, str], episode_started_ns: int | None) -> PlanEvidence | None:
    """The plan status as evidence, if it belongs to the current episode (same failure stamp); None when a number it
    carries does not parse (no evidence, never a SAFE)."""
    plan = PlanStatusValues.from_values(values)
    if episode_started_ns is None or plan.failure_stamp_ns != episode_started_ns:
        return None
    numbers = {"time_to_land_s": plan.time_to_land_s, "late_by_s": plan.late_by_s}
    if any(name in values and number is None for name, number in numbers.items()):
        return None
    return PlanEvidence(
        status="fallback" if plan.is_fallback else plan.status or "none",
        verified=plan.replay_verified_safe,
        standby=plan.standby is True,
        time_to_land_s=math.nan if plan.time_to_land_s is None else plan.time_to_land_s,
        late=(plan.late_by_s or 0.0) > 0.0,  # a late *state* (not only after a fallback)
    )
