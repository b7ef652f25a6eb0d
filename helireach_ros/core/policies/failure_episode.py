"""One engine failure from its first flag to its end: the episode model, the lateness rule, the planner's records.

**The episode model** (:class:`EpisodeTracker`, a pure state machine: no threads, no clock of its own; every
observation carries its time in ns). The monitor runs it on the engine-failure flag and the valid vehicle
state; its state (:class:`EpisodeState`) is what the planner and the display follow.

======== ============================================ ==============================================
phase    means                                        leaves on
======== ============================================ ==============================================
no_flag  no flag received yet (engine state unknown)  false → normal; true → failed (episode 1)
normal   flag false, no episode running               true → failed (a new episode)
failed   episode running (latched on the first true)  flag false *steadily* for ``recovery_hold`` s
                                                      → ended; a landed state → landed
ended    engine recovered (relit, false alarm)        true → failed (a new episode)
landed   on the ground after the failure              flag false steadily for ``recovery_hold`` s → normal
======== ============================================ ==============================================

Rules:

* **Start, no debounce.** The first true starts the episode at once (a safety tool must not wait); its time
  is the failure stamp.
* **Debounced end.** A failed episode ends only on *evidence*: false messages spanning ``recovery_hold``
  seconds with no true in between. A true restarts the hold; so does silence, because the hold is measured
  between flag messages (a flag that stops arriving never ends an episode). A flag flapping true/false at any
  rate shorter than the hold is one episode (``flag_changes`` counts the flips).
* **Landed.** While failed, a valid state with height ≤ ``landed_height`` and
  \\|climb rate\\| ≤ ``landed_climb_rate`` ends the episode as landed; a still-true flag then starts nothing.
* **Out-of-order flag times** (a clock that jumps back, e.g. simulated time restarting) are counted; the
  observation is applied and a running hold restarts from it, so no episode ends across a jump.

**The lateness rule** (:func:`plan_lateness`): the first plan of an episode should start from a state stamped
at most ``max_message_age`` after the failure; a plan from a later state is still made (it is the best there
is) but flagged late, with ``state_delay_s`` = state stamp − failure stamp and ``late_by_s`` = how far beyond
``max_message_age`` that is; its level is at best WARN (:func:`late_verdict`).

**The planner's records** (:class:`FailureEpisode`, :class:`PublishedPlan`): the plans published for one
episode (the first plan, a fallback, the closed-loop re-plans) and whether planning for it has stopped.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from helireach_ros.core.estimation.disturbance import DisturbanceTracker

__all__ = [
    "EpisodePhase",
    "EpisodeSettings",
    "EpisodeState",
    "EpisodeTracker",
    "EpisodeTransition",
    "FailureEpisode",
    "PlanLateness",
    "PublishedPlan",
    "episode_outcome",
    "episode_starts",
    "late_verdict",
    "plan_lateness",
]


class EpisodePhase(StrEnum):
    """The phase of the engine-failure episode (see the module docstring for the transitions)."""

    NO_FLAG = "no_flag"
    NORMAL = "normal"
    FAILED = "failed"
    ENDED = "ended"
    LANDED = "landed"


#: DiagnosticStatus level name and text of each phase (the text gets the episode's details appended).
_PHASE_REPORT = {
    EpisodePhase.NO_FLAG: ("WARN", "no engine-failure flag received"),
    EpisodePhase.NORMAL: ("OK", "engine normal"),
    EpisodePhase.FAILED: ("ERROR", "ENGINE FAILURE"),
    EpisodePhase.ENDED: ("WARN", "ENDED (engine recovered)"),
    EpisodePhase.LANDED: ("WARN", "LANDED after the engine failure"),
}


@dataclass(frozen=True)
class EpisodeSettings:
    """How the episode model decides (immutable; validated on construction).

    Attributes:
        recovery_hold: s of steadily false flag that end a failed episode (> 0).
        landed_height: m; a state at or below it (and slow vertically) while failed is on the ground (≥ 0).
        landed_climb_rate: m/s; the largest \\|climb rate\\| that still counts as landed (> 0).

    Raises:
        ValueError: a value is not finite or out of its range (the message names it).
    """

    recovery_hold: float = 3.0
    landed_height: float = 0.3
    landed_climb_rate: float = 0.3

    def __post_init__(self) -> None:
        for name, low, inclusive in (
            ("recovery_hold", 0.0, False),
            ("landed_height", 0.0, True),
            ("landed_climb_rate", 0.0, False),
        ):
            value = getattr(self, name)
            if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            if value < low or (value == low and not inclusive):
                raise ValueError(f"{name} must be {'≥' if inclusive else '>'} {low:g}, got {value!r}")


@dataclass(frozen=True)
class EpisodeState:
    """What the episode model knows now (immutable; published by the monitor, followed by planner and display).

    Attributes:
        phase: see :class:`EpisodePhase`.
        episode_id: 1, 2, … per episode; 0 before the first failure.
        started_ns: time of the episode's first true (the failure stamp), None before the first failure.
        ended_ns: time it ended (ended or landed), None while it runs.
        flag: the last flag received (None: none yet).
        flag_changes: flips of the flag since the episode started.
        false_since_ns: start of the current run of false flags (None while true or before any flag).
        out_of_order: flag observations whose time was before the previous one (clock jumps back).
    """

    phase: EpisodePhase = EpisodePhase.NO_FLAG
    episode_id: int = 0
    started_ns: int | None = None
    ended_ns: int | None = None
    flag: bool | None = None
    flag_changes: int = 0
    false_since_ns: int | None = None
    out_of_order: int = 0

    @property
    def level_name(self) -> str:
        """``OK``/``WARN``/``ERROR``: normal, no flag yet or ended/landed, failed."""
        return _PHASE_REPORT[self.phase][0]

    @property
    def text(self) -> str:
        """One line for people, e.g. ``ENGINE FAILURE (episode 2, flag flipped 234 times)``."""
        text = _PHASE_REPORT[self.phase][1]
        if self.episode_id and self.phase is not EpisodePhase.NORMAL:
            text += f" (episode {self.episode_id}"
            text += f", flag flipped {self.flag_changes} times)" if self.flag_changes else ")"
        return text

    def as_values(self) -> dict[str, Any]:
        """The state as DiagnosticStatus values (``phase``, ``episode_id``, stamps in ns, -1 for none)."""
        return {
            "phase": self.phase.value,
            "episode_id": self.episode_id,
            "started_ns": -1 if self.started_ns is None else self.started_ns,
            "ended_ns": -1 if self.ended_ns is None else self.ended_ns,
            "flag": "unknown" if self.flag is None else self.flag,
            "flag_changes": self.flag_changes,
            "false_since_ns": -1 if self.false_since_ns is None else self.false_since_ns,
            "out_of_order": self.out_of_order,
        }

    @classmethod
    def from_values(cls, values: Mapping[str, str]) -> EpisodeState:
        """Reads :meth:`as_values` back (strings as on the wire).

        Raises:
            ValueError: a key is missing or a value unreadable (the caller must not guess a phase).
        """
        try:

            def stamp(key: str) -> int | None:
                number = int(values[key])
                return None if number < 0 else number

            flag_text = values["flag"].strip().lower()
            if flag_text not in ("true", "false", "unknown"):
                raise ValueError(f"flag {values['flag']!r} is not true/false/unknown")
            return cls(
                phase=EpisodePhase(values["phase"]),
                episode_id=int(values["episode_id"]),
                started_ns=stamp("started_ns"),
                ended_ns=stamp("ended_ns"),
                flag=None if flag_text == "unknown" else flag_text == "true",
                flag_changes=int(values["flag_changes"]),
                false_since_ns=stamp("false_since_ns"),
                out_of_order=int(values["out_of_order"]),
            )
        except KeyError as error:
            raise ValueError(f"episode state lacks {error.args[0]!r}") from None


@dataclass(frozen=True)
class EpisodeTransition:
    """A change of phase: from ``previous`` to ``state.phase`` (``started``: a new episode began)."""

    previous: EpisodePhase
    state: EpisodeState

    @property
    def started(self) -> bool:
        """A new episode began (publish one failure event)."""
        return self.state.phase is EpisodePhase.FAILED and self.previous is not EpisodePhase.FAILED


class EpisodeTracker:
    """The episode state machine (module docstring); not thread-safe: its owner serialises the calls."""

    def __init__(self, settings: EpisodeSettings | None = None) -> None:
        self.settings = settings or EpisodeSettings()
        self._state = EpisodeState()
        self._latest_ns: int | None = None

    @property
    def state(self) -> EpisodeState:
        """The current state (an immutable snapshot)."""
        return self._state

    def _clock(self, now_ns: int) -> bool:
        """Records an observation time; True when it went back (counted; a running hold restarts)."""
        jumped = self._latest_ns is not None and now_ns < self._latest_ns
        self._latest_ns = now_ns
        if jumped:
            self._state = replace(self._state, out_of_order=self._state.out_of_order + 1)
        return jumped

    def _move(self, state: EpisodeState) -> EpisodeTransition | None:
        previous, self._state = self._state.phase, state
        return EpisodeTransition(previous, state) if state.phase is not previous else None

    def observe_flag(self, failed: bool, now_ns: int) -> EpisodeTransition | None:
        """One engine-failure flag message received at ``now_ns``; returns the transition it caused, if any."""
        jumped = self._clock(int(now_ns))
        state, now_ns = self._state, int(now_ns)
        changed = state.flag is not None and state.flag != failed
        flips = state.flag_changes + (1 if changed and state.phase is EpisodePhase.FAILED else 0)
        if failed:
            if state.phase in (EpisodePhase.NO_FLAG, EpisodePhase.NORMAL, EpisodePhase.ENDED):
                return self._move(
                    EpisodeState(
                        EpisodePhase.FAILED,
                        state.episode_id + 1,
                        started_ns=now_ns,
                        flag=True,
                        out_of_order=state.out_of_order,
                    )
                )
            return self._move(replace(state, flag=True, flag_changes=flips, false_since_ns=None))
        false_since = now_ns if state.false_since_ns is None or jumped else state.false_since_ns
        held = (now_ns - false_since) * 1e-9 >= self.settings.recovery_hold
        if state.phase is EpisodePhase.NO_FLAG:
            return self._move(replace(state, phase=EpisodePhase.NORMAL, flag=False, false_since_ns=false_since))
        if state.phase is EpisodePhase.FAILED and held:
            return self._move(
                replace(
                    state,
                    phase=EpisodePhase.ENDED,
                    ended_ns=now_ns,
                    flag=False,
                    flag_changes=flips,
                    false_since_ns=false_since,
                )
            )
        if state.phase is EpisodePhase.LANDED and held:
            return self._move(replace(state, phase=EpisodePhase.NORMAL, flag=False, false_since_ns=false_since))
        return self._move(replace(state, flag=False, flag_changes=flips, false_since_ns=false_since))

    def observe_state(self, height: float, climb_rate: float, now_ns: int) -> EpisodeTransition | None:
        """A valid vehicle state (height m, climb rate m/s) at ``now_ns``: ends a failed episode as landed.

        Its time is only recorded as ``ended_ns``: the flag's own times alone measure the recovery hold.
        """
        state = self._state
        on_ground = (
            math.isfinite(height)
            and math.isfinite(climb_rate)
            and height <= self.settings.landed_height
            and abs(climb_rate) <= self.settings.landed_climb_rate
        )
        if state.phase is EpisodePhase.FAILED and on_ground:
            return self._move(replace(state, phase=EpisodePhase.LANDED, ended_ns=int(now_ns)))
        return None


def episode_starts(state: EpisodeState, current_stamp_ns: int | None) -> bool:
    """Whether ``state`` announces a failure newer than the one being handled (stamp ``current_stamp_ns``).

    True for a running (failed) episode that started after the current one, or any when none is handled: a
    planner that missed the failure event (started late, restarted) still plans. An older episode's state
    (delivered late) starts nothing.
    """
    if state.phase is not EpisodePhase.FAILED or state.started_ns is None:
        return False
    return current_stamp_ns is None or state.started_ns > current_stamp_ns


def episode_outcome(state: EpisodeState, failure_stamp_ns: int) -> EpisodePhase | None:
    """How the episode that started at ``failure_stamp_ns`` ended according to ``state``; None: not (known) over.

    ``ENDED`` or ``LANDED`` for that episode (``NORMAL`` again after landing counts as landed); ``ENDED`` when a
    later episode began (this one must have ended first). A state that has seen no failure, or only older
    ones, says nothing about it (None: keep planning; planning never stops without evidence).
    """
    if state.started_ns is None or state.started_ns < failure_stamp_ns:
        return None
    if state.started_ns > failure_stamp_ns:
        return EpisodePhase.ENDED
    return {
        EpisodePhase.ENDED: EpisodePhase.ENDED,
        EpisodePhase.LANDED: EpisodePhase.LANDED,
        EpisodePhase.NORMAL: EpisodePhase.LANDED,
    }.get(state.phase)


@dataclass(frozen=True)
class PlanLateness:
    """How late a plan for a failure is (see :func:`plan_lateness`).

    Attributes:
        state_delay_s: state stamp − failure stamp, s (negative: the state is from before the failure).
        state_late: the state is more than ``max_message_age`` after the failure.
        after_fallback: a fallback went out first (the plan missed the deadline).
        late_by_s: state_delay_s − max_message_age when ``state_late``, else 0.
    """

    state_delay_s: float
    state_late: bool
    after_fallback: bool
    late_by_s: float

    @property
    def late(self) -> bool:
        """Late for either reason."""
        return self.state_late or self.after_fallback


def plan_lateness(
    failure_stamp_ns: int, state_stamp_ns: int, max_message_age: float, after_fallback: bool = False
) -> PlanLateness:
    """The lateness of the first plan (or fallback) of a failure made from a state stamped ``state_stamp_ns``.

    Admissible for an on-time first plan: state stamp − failure stamp ≤ ``max_message_age`` (s, > 0).

    Raises:
        ValueError: ``max_message_age`` is not a positive finite number.
    """
    if not (math.isfinite(max_message_age) and max_message_age > 0.0):
        raise ValueError(f"max_message_age must be a positive finite number, got {max_message_age!r}")
    delay = (int(state_stamp_ns) - int(failure_stamp_ns)) * 1e-9
    state_late = delay > max_message_age
    return PlanLateness(delay, state_late, bool(after_fallback), delay - max_message_age if state_late else 0.0)


def late_verdict(level_name: str, text: str, lateness: PlanLateness) -> tuple[str, str]:
    """The plan verdict of a plan made from a late state: at best WARN, the text says how late.

    A plan that is late only because a fallback came first keeps its verdict (its state is the failure's).
    """
    if not lateness.state_late:
        return level_name, text
    prefix = f"LATE (state {lateness.state_delay_s:.1f} s after the failure, {lateness.late_by_s:.1f} s too late): "
    return ("WARN" if level_name == "OK" else level_name), prefix + text


@dataclass
class PublishedPlan:
    """A plan as published: the core plan (or fallback), its stamp and bookkeeping.

    Attributes:
        failure_id: the episode it belongs to.
        replan_index: re-plans made in the episode before this one.
        stamp_ns: stamp of the state it starts from (its t = 0).
        plan: a :class:`~helireach_ros.core.planning.planner.LandingPlan` or
        :class:`~helireach_ros.core.planning.fallback.FallbackPlan`.
        fallback: whether it is a fallback (never safe).
        latency_ms: from the failure event's receipt (first plan) or the state's stamp (re-plan) to publication.
        published_at_ns: when it was published.
        warm_start_source: ``"envelope"``, ``"previous_plan"`` or ``"none"``.
    """

    failure_id: int
    replan_index: int
    stamp_ns: int
    plan: Any
    fallback: bool
    latency_ms: float
    published_at_ns: int
    warm_start_source: str


@dataclass
class FailureEpisode:
    """The planner's record of one failure episode (mutable bookkeeping, guarded by its owner's lock).

    ``active`` while the closed loop re-plans; ``outcome`` is the episode model's phase that stopped planning
    (``ended``: engine recovered, nothing more is published as a plan; ``landed``), empty while it runs.
    """

    failure_id: int
    event_stamp_ns: int
    event_received_ns: int
    active: bool = True
    published: bool = False
    current: PublishedPlan | None = None
    replans: int = 0
    replans_failed: int = 0
    replans_skipped_no_rotor: int = 0  # re-plan ticks without a measured rotor speed (the current plan was kept)
    replans_kept_out: int = 0  # converged re-plans not safe while the current plan still landed from their state
    deadline_handled: bool = False
    outcome: str = ""
    history: list[PublishedPlan] = field(default_factory=list)
    disturbance: DisturbanceTracker | None = None  # the model's error learnt in this descent (None: not estimated)

    def has_plan_from(self, stamp_ns: int) -> bool:
        """Whether the plan out starts from the state stamped ``stamp_ns`` or a later one.

        A fallback for a solve from that state would then add nothing and go out of order: the deadline's
        fallback, from the newest state, is published while the solve runs, and a solve that fails afterwards
        must not follow it with a fallback from its older state.
        """
        return self.current is not None and self.current.stamp_ns >= stamp_ns

    def remember(self, record: PublishedPlan) -> None:
        """Records a published plan as the episode's current one."""
        self.published = True
        self.current = record
        self.history.append(record)

    def stop(self, outcome: EpisodePhase) -> bool:
        """Stops planning for this episode because it is ``outcome``; False if it had stopped already that way."""
        if self.outcome:
            return False
        self.active = False
        self.outcome = outcome.value
        return True
