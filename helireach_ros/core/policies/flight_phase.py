"""The cockpit's flight phase and its banner, the touchdown result, and the plan's guidance cue (ROS-free policy).

The display shows one *phase* at a time, each with its own banner (word, level, detail):

==============  ==========================================================  =========================================
phase           when                                                        banner (level)
==============  ==========================================================  =========================================
``normal``      episode ``normal``/``no_flag`` (or none received and no      the H-V safety status as it says
                failure event)                                               (SAFE/CAUTION/AVOID/NO DATA)
``autorotation`` episode ``failed`` (or a failure event without an episode)   the plan: VERIFIED, STANDBY · VERIFIED,
                                                                             ROBUST, FALLBACK, UNVERIFIED, UNSAFE,
                                                                             NO PLAN (see :func:`plan_banner`)
``landed``      episode ``landed``, or a touchdown report during the         LANDED · WITHIN LIMITS (safe; from the
                episode                                                      state: caution) or · OUTSIDE LIMITS (avoid)
``ended``       episode ``ended`` (engine recovered)                         ENGINE RECOVERED, at the H-V status' level
``stale``       any streaming source silent (state, rotor, safety status,   STALE (nodata); also when held or the
                episode) longer than ``stale_after_s``, or no safety status   episode is unreadable
==============  ==========================================================  =========================================

Never optimistic: a level is never better than its evidence (:data:`LEVEL_RANK`: safe < caution < avoid < nodata;
:func:`worst_level`); a plan is green only when verified, safe, not late, not a fallback and its own status is OK;
a source that never arrived is not "silent" (a system without that node), except the safety status, without
which the normal phase has no evidence at all.

**Touchdown from the state** (:class:`TouchdownFromState`, when no ``/helireach/touchdown`` arrives): the first state
at or below ``contact_height`` after one above it during the episode is the contact, and the larger rates of it and
of the last state above are the result (a vehicle that reports zero rates once on the ground must not make a hard
landing look soft; a display started on the ground sees no touchdown), after
``report_wait_s`` (1 s; until then LANDED "awaiting the touchdown report", caution: in the demo the sampled state
said 6.8 kt 0.2 s before the vehicle's report said 2.6 kt at h = 0). It is sampled, not the vehicle's own report, so
a result within limits is only ``caution``.

**Cue** (:func:`plan_cue_events`, :func:`next_cue`), from the planned controls (pitch nose-up positive p = −θ):

* ``FLARE`` at each time p rises through ``flare_pitch_deg`` (10°) nose up, and at the start of a plan that begins at
  or above it (a re-plan during the flare: "under way", shown only when no other event is ahead);
* ``LEVEL`` at each time |p| comes back within ``level_band_deg`` (5°) after an excursion beyond
  ``level_from_deg`` (10°) either way;
* ``CUSHION`` once, at the first time within the last ``cushion_window_s`` (3 s) of the plan where C_T exceeds
  (1 + ``cushion_rise``) (30 %) times its smallest value in that window so far.

At plan time t the cue is the first event at or after t − ``now_s`` within ``lookahead_s`` (6 s): ``<KIND> IN n s``
(n = the time left rounded up), ``<KIND>`` when under ``now_s`` (0.5 s) away; none within the lookahead: ``HOLD``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import TypeGuard

from helireach_ros.core.units import FT, KT

__all__ = [
    "LEVEL_RANK",
    "CueEvent",
    "CueSettings",
    "FlightPhase",
    "PhaseBanner",
    "PhaseInputs",
    "PlanVerdictInput",
    "TouchdownFromState",
    "TouchdownResult",
    "decide_phase",
    "next_cue",
    "plan_banner",
    "plan_cue_events",
    "touchdown_banner",
    "worst_level",
]


class FlightPhase(StrEnum):
    """What the cockpit page is about now (see the module docstring)."""

    NORMAL = "normal"
    AUTOROTATION = "autorotation"
    LANDED = "landed"
    ENDED = "ended"
    STALE = "stale"


#: How bad a banner level is: a combined level is the worst of its parts (never better than its evidence).
LEVEL_RANK: dict[str, int] = {"safe": 0, "caution": 1, "avoid": 2, "nodata": 3}
_WORDS = {"safe": "SAFE", "caution": "CAUTION", "avoid": "AVOID", "nodata": "NO DATA"}


def worst_level(*levels: str | None) -> str:
    """The worst of ``levels`` by :data:`LEVEL_RANK`; None or an unknown level counts as ``nodata``."""
    return max((level if level in LEVEL_RANK else "nodata" for level in levels), key=LEVEL_RANK.__getitem__)


@dataclass(frozen=True)
class PhaseBanner:
    """The page's banner: ``phase`` and ``level`` go to ``<body data-phase data-level>``; word and detail are shown."""

    phase: FlightPhase
    level: str
    word: str
    detail: str
    silent: tuple[str, ...] = ()


@dataclass(frozen=True)
class PlanVerdictInput:
    """The plan status as the page reads it (``msg_docs/helireach_plan_status.md``); None = key missing.

    ``robust`` is for a later plan kind (a plan that lands within limits under the model's uncertainty): read if
    the planner sends it, never inferred.
    """

    status: str | None = None
    level: str | None = None
    verified: bool | None = None
    fallback: bool | None = None
    late: bool | None = None
    standby: bool | None = None
    robust: bool | None = None
    message: str = ""


def plan_banner(plan: PlanVerdictInput | None) -> tuple[str, str]:
    """(word, level) of the autorotation banner for a plan status (None: none received yet).

    Rules: a fallback → FALLBACK (at best caution); no plan or status ``none`` → NO PLAN (avoid); ``ended`` →
    NO PLAN · ENDED (nodata); ``unsafe`` → UNSAFE (avoid); not verified or not ``safe`` → UNVERIFIED (at
    best caution); verified and safe → VERIFIED (ROBUST when the plan says so), prefixed ``STANDBY ·`` for the
    standby plan, suffixed ``· LATE`` for a late one (at best caution). Every level is also never better than
    the plan status' own.
    """
    if plan is None:
        return "NO PLAN", "avoid"
    own = plan.level if plan.level in LEVEL_RANK else "nodata"
    if plan.fallback is True or plan.status == "fallback":
        return "FALLBACK", worst_level(own, "caution")
    if plan.status == "none":
        return "NO PLAN", "avoid"
    if plan.status == "ended":
        return "NO PLAN \u00b7 ENDED", "nodata"
    if plan.status == "unsafe":
        return "UNSAFE", "avoid"
    if plan.verified is not True or plan.status != "safe":  # a status without a `status` value too
        return "UNVERIFIED", worst_level(own, "caution")
    word = "ROBUST" if plan.robust is True else "VERIFIED"
    level = own
    if plan.standby is True:
        word = f"STANDBY \u00b7 {word}"
    if plan.late is True:
        word, level = f"{word} \u00b7 LATE", worst_level(own, "caution")
    return word, level


@dataclass(frozen=True)
class TouchdownResult:
    """How the aircraft met the ground, SI; ``source`` is ``touchdown`` (the vehicle's report) or ``state``.

    ``within_limits`` None: unknown (no rates). Limits None: not known to the display.
    """

    source: str
    within_limits: bool | None
    descent_rate: float | None = None
    forward_speed: float | None = None
    max_descent_rate: float | None = None
    max_forward_speed: float | None = None
    rotor_speed_pct: float | None = None
    time_after_failure_s: float | None = None
    reason: str = ""


class TouchdownFromState:
    """Finds the touchdown in the state stream when no touchdown report comes (see the module docstring).

    Args:
        contact_height: m; a state at or below it is on the ground.
        max_descent_rate, max_forward_speed: the airframe's touchdown limits, m/s (None: unknown → no verdict).
        report_wait_s: how long after the contact the result stays ``pending`` (a vehicle's own report, exact at
            h = 0, usually follows within a frame; a sampled state must not flash a verdict the report corrects).
    """

    def __init__(
        self,
        contact_height: float,
        max_descent_rate: float | None,
        max_forward_speed: float | None,
        report_wait_s: float = 1.0,
    ) -> None:
        self._contact_height = contact_height
        self._limits = (max_descent_rate, max_forward_speed)
        self._report_wait_s = report_wait_s
        self._result: TouchdownResult | None = None
        self._contact_s: float | None = None
        self._airborne = False
        self._last_airborne: tuple[float, float] = (0.0, 0.0)  # (descent rate, |speed|) of the last state above

    def result(self, now_s: float) -> TouchdownResult | None:
        """The touchdown at time ``now_s`` (s, the clock of :meth:`observe`): None before the contact,
        ``pending`` (no verdict) within ``report_wait_s`` of it, then the rates of the contact state."""
        if self._result is None or self._contact_s is None:
            return None
        if now_s - self._contact_s < self._report_wait_s:
            return TouchdownResult("pending", None)
        return self._result

    def reset(self) -> None:
        """Forgets everything (a new episode)."""
        self._result, self._contact_s, self._airborne, self._last_airborne = None, None, False, (0.0, 0.0)

    def observe(
        self, height: float | None, climb_rate: float | None, forward_speed: float | None, now_s: float
    ) -> None:
        """Feeds one state (m, m/s, m/s) received at ``now_s`` (s); non-finite values are skipped."""
        if self._result is not None or not (
            _is_finite(height) and _is_finite(climb_rate) and _is_finite(forward_speed)
        ):
            return
        if height > self._contact_height:
            self._airborne = True
            self._last_airborne = (-float(climb_rate), abs(float(forward_speed)))
            return
        if not self._airborne:  # on the ground since the first state seen: no touchdown was observed
            return
        # The rates the aircraft met the ground with lie between the last state above and the first on the ground;
        # a vehicle that zeroes its rates on the ground must not make a hard landing look soft: the larger of the two.
        descent = max(-float(climb_rate), self._last_airborne[0])
        speed = max(abs(float(forward_speed)), self._last_airborne[1])
        max_descent, max_speed = self._limits
        within = None if max_descent is None or max_speed is None else descent <= max_descent and speed <= max_speed
        self._result = TouchdownResult("state", within, descent, speed, max_descent, max_speed)
        self._contact_s = now_s


def touchdown_banner(result: TouchdownResult | None) -> tuple[str, str, str]:
    """(word, level, detail) of the landed banner (see the module docstring)."""
    if result is not None and result.source == "pending":
        return "LANDED", "caution", "AWAITING THE TOUCHDOWN REPORT"
    if result is None or result.within_limits is None:
        return "LANDED", "caution", "TOUCHDOWN RATES UNKNOWN"
    parts = []
    if _is_finite(result.descent_rate):
        limit = f" (LIMIT {result.max_descent_rate / FT:.0f})" if _is_finite(result.max_descent_rate) else ""
        parts.append(f"SINK {result.descent_rate / FT:.1f} ft/s{limit}")
    if _is_finite(result.forward_speed):
        limit = f" (LIMIT {result.max_forward_speed / KT:.0f})" if _is_finite(result.max_forward_speed) else ""
        parts.append(f"SPEED {result.forward_speed / KT:.1f} kt{limit}")
    if _is_finite(result.rotor_speed_pct):
        parts.append(f"ROTOR {result.rotor_speed_pct:.0f} %")
    if result.reason and not result.within_limits:
        parts.append(result.reason.upper())
    parts.append("FROM STATE" if result.source == "state" else "TOUCHDOWN REPORT")
    detail = " \u00b7 ".join(parts)
    if not result.within_limits:
        return "LANDED \u00b7 OUTSIDE LIMITS", "avoid", detail
    return "LANDED \u00b7 WITHIN LIMITS", "safe" if result.source == "touchdown" else "caution", detail


@dataclass(frozen=True)
class PhaseInputs:
    """Everything the phase decision reads (plain values; the display node fills it from its latest messages).

    Attributes:
        source_ages: (name, seconds since its last message or None if never) of the streaming sources.
        stale_after_s: a source older than this is silent.
        status_level, status_message: the safety status (None: none received).
        episode_phase: the failure episode's phase (``unknown`` when unreadable; None: none received).
        failure_event: a failure event was received and no later episode state contradicts it.
        plan: the current episode's plan status (None: none yet). plan_remaining_s: time to touchdown left.
        touchdown: the current episode's touchdown (report, else from the state), None before.
        held: the display is held (ROS stopped).
    """

    source_ages: tuple[tuple[str, float | None], ...] = ()
    stale_after_s: float = 2.0
    status_level: str | None = None
    status_message: str = ""
    episode_phase: str | None = None
    failure_event: bool = False
    plan: PlanVerdictInput | None = None
    plan_remaining_s: float | None = None
    touchdown: TouchdownResult | None = None
    held: bool = False


def _underlying_phase(inputs: PhaseInputs) -> FlightPhase | None:
    """The phase the episode (or, without one, the failure event and touchdown) says; None if unreadable."""
    episode = inputs.episode_phase
    if episode == "unknown":
        return None
    if episode == "landed":
        return FlightPhase.LANDED
    if episode == "ended":
        return FlightPhase.ENDED
    failed = episode == "failed" or (episode is None and inputs.failure_event)
    if failed:
        return FlightPhase.LANDED if inputs.touchdown is not None else FlightPhase.AUTOROTATION
    return FlightPhase.NORMAL


def decide_phase(inputs: PhaseInputs) -> PhaseBanner:
    """The phase and banner for ``inputs`` (rules: module docstring)."""
    if inputs.held:
        return PhaseBanner(FlightPhase.STALE, "nodata", "STALE", "DISPLAY HELD: ROS STOPPED, LAST DATA SHOWN")
    silent = tuple(name for name, age in inputs.source_ages if age is not None and not age <= inputs.stale_after_s)
    phase = _underlying_phase(inputs)
    if silent:
        ages = dict(inputs.source_ages)
        detail = " \u00b7 ".join(f"{name.upper()} SILENT {ages[name]:.1f} s" for name in silent)
        if phase is not None:
            detail += f" \u00b7 LAST PHASE {phase.value.upper()}"
        return PhaseBanner(FlightPhase.STALE, "nodata", "STALE", detail, silent)
    if phase is None:
        return PhaseBanner(FlightPhase.STALE, "nodata", "STALE", "FAILURE EPISODE UNREADABLE")
    status_text = (inputs.status_message or "").upper()
    if phase is FlightPhase.NORMAL:
        if inputs.status_level is None:
            return PhaseBanner(FlightPhase.STALE, "nodata", "STALE", "NO SAFETY STATUS RECEIVED")
        level = worst_level(inputs.status_level)
        detail = status_text
        if inputs.episode_phase is None:
            detail += " \u00b7 NO FAILURE-EPISODE STATUS"
        elif inputs.episode_phase == "no_flag":
            detail += " \u00b7 NO ENGINE-FAILURE FLAG RECEIVED"
        return PhaseBanner(phase, level, _WORDS[level], detail)
    if phase is FlightPhase.AUTOROTATION:
        word, level = plan_banner(inputs.plan)
        parts = []
        if inputs.plan_remaining_s is not None:
            if inputs.plan_remaining_s > 0.0:
                parts.append(f"TOUCHDOWN IN {inputs.plan_remaining_s:.1f} s")
            else:  # still airborne past the plan's end: the plan no longer says where we are
                parts.append("PLAN TIME ELAPSED")
                level = worst_level(level, "caution")
        if inputs.plan is not None and inputs.plan.message:
            parts.append(inputs.plan.message.upper())
        elif inputs.plan is None:
            parts.append("PLANNING\u2026")
        return PhaseBanner(phase, level, word, " \u00b7 ".join(parts))
    if phase is FlightPhase.LANDED:
        word, level, detail = touchdown_banner(inputs.touchdown)
        return PhaseBanner(phase, level, word, detail)
    level = worst_level(inputs.status_level)  # ENDED: the engine is back; the H-V status applies again
    detail = "EPISODE ENDED \u00b7 NO LANDING PLAN"
    if inputs.status_level is not None:
        detail += f" \u00b7 H-V {_WORDS[level]}: {status_text}"
    return PhaseBanner(phase, level, "ENGINE RECOVERED", detail)


# ----------------------------------------------------------------------------------------------------------
# The plan's guidance cue
# ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CueSettings:
    """Thresholds of the cue rules (module docstring); immutable, validated.

    Raises:
        ValueError: a value is not finite and positive, or ``level_band_deg`` ≥ ``level_from_deg``.
    """

    flare_pitch_deg: float = 10.0
    level_band_deg: float = 5.0
    level_from_deg: float = 10.0
    cushion_window_s: float = 3.0
    cushion_rise: float = 0.3
    lookahead_s: float = 6.0
    now_s: float = 0.5

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not _is_finite(value) or value <= 0:
                raise ValueError(f"{name} must be a finite positive number, got {value!r}")
        if self.level_band_deg >= self.level_from_deg:
            raise ValueError("level_band_deg must be below level_from_deg")


@dataclass(frozen=True)
class CueEvent:
    """A planned change the pilot is cued for: ``kind`` FLARE, LEVEL or CUSHION at plan time ``time_s``.

    ``under_way``: the plan starts in it (a re-plan during the flare); shown only when nothing else is ahead.
    """

    kind: str
    time_s: float
    under_way: bool = False


def plan_cue_events(
    times: Sequence[float | None],
    collective: Sequence[float | None],
    pitch_rad: Sequence[float | None],
    settings: CueSettings | None = None,
) -> tuple[CueEvent, ...]:
    """The FLARE, LEVEL and CUSHION events of a plan (samples with a missing value are skipped), by time."""
    settings = settings or CueSettings()
    samples = [
        (float(t), float(c), -math.degrees(float(p)))
        for t, c, p in zip(times, collective, pitch_rad, strict=True)
        if _is_finite(t) and _is_finite(c) and _is_finite(p)
    ]
    events: list[CueEvent] = []
    previous_nose_up: float | None = None
    excursion = False
    for time_s, _, nose_up in samples:
        # a plan that starts at or above it (a re-plan during the flare): the flare is under way, at its start
        if (
            previous_nose_up is None or previous_nose_up < settings.flare_pitch_deg
        ) and settings.flare_pitch_deg <= nose_up:
            events.append(CueEvent("FLARE", time_s, under_way=previous_nose_up is None))
        if abs(nose_up) > settings.level_from_deg:
            excursion = True
        elif excursion and abs(nose_up) <= settings.level_band_deg:
            events.append(CueEvent("LEVEL", time_s))
            excursion = False
        previous_nose_up = nose_up
    if samples:
        window_start = samples[-1][0] - settings.cushion_window_s
        lowest = math.inf
        for time_s, thrust_coefficient, _ in samples:
            if time_s < window_start:
                continue
            if lowest < math.inf and thrust_coefficient > (1.0 + settings.cushion_rise) * lowest:
                events.append(CueEvent("CUSHION", time_s))
                break
            lowest = min(lowest, thrust_coefficient)
    return tuple(sorted(events, key=lambda event: event.time_s))


def next_cue(events: Sequence[CueEvent], elapsed_s: float | None, settings: CueSettings | None = None) -> str | None:
    """The cue line at plan time ``elapsed_s`` (None: no plan clock): ``FLARE IN 3 s``, ``CUSHION``, ``HOLD``."""
    settings = settings or CueSettings()
    if not _is_finite(elapsed_s):
        return None
    upcoming = [e for e in events if -settings.now_s <= e.time_s - elapsed_s <= settings.lookahead_s]
    if not upcoming:
        return "HOLD"
    event = next((e for e in upcoming if not e.under_way), upcoming[0])
    ahead = event.time_s - elapsed_s
    return event.kind if ahead < settings.now_s else f"{event.kind} IN {math.ceil(ahead)} s"


def _is_finite(value: object) -> TypeGuard[float]:
    """A finite number (not a bool, not None)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
