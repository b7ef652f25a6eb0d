"""The planner node's failure-handling rules, without ROS: what to do at a failed first solve, at the deadline, and at
each re-plan tick. The node (:mod:`helireach_ros.ros.nodes.planner_node`) and the lock-step closed loop
(:mod:`helireach_ros.core.robustness.closed_loop`) ask these functions and carry out the answer.

After an engine failure the node solves a first plan from the state at the failure (warm-started from the envelope's
nearest stored plan), publishing the live verdict's standby plan meanwhile if it has one. A first solve that fails
publishes a fallback unless something better is already out (:func:`fallback_after_failed_first_plan`); a failure
with nothing published ``deadline`` seconds after its event gets a fallback (:func:`deadline_due`). Every
``replan_period`` the timer either tries the first plan again, while no converged plan of this failure is out, or
re-plans from the current state (:func:`replan_timer_action`); a re-plan is made only from a measured rotor speed
and stops near the ground (:func:`replan_gate`): below ``min_height`` or with less than ``min_remaining`` seconds of
the current plan to go (a re-plan that close to the ground would arrive after touchdown). A converged re-plan replaces
the current plan unless it is not safe while the current plan, flown on from the same state, still lands
(:func:`keeps_current_plan`).

:class:`LandingSupervisor` holds the node's failure bookkeeping (the current episode, the plans published for it, the
standby records, the monitor's episode state) behind one lock and answers with these rules; the node only solves,
publishes and logs. It has no clock of its own: every call that needs the time is given it (tests use a fake one).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from enum import StrEnum

from helireach_ros.core.policies.failure_episode import (
    EpisodePhase,
    EpisodeState,
    FailureEpisode,
    PlanLateness,
    PublishedPlan,
    episode_outcome,
    episode_starts,
    plan_lateness,
)

__all__ = [
    "CurrentPlan",
    "EpisodeAction",
    "LandingSupervisor",
    "ReplanDecision",
    "ReplanGate",
    "SupervisorSettings",
    "TimerAction",
    "deadline_due",
    "fallback_after_failed_first_plan",
    "keeps_current_plan",
    "plan_time_remaining",
    "replan_gate",
    "replan_timer_action",
    "replanning_ends",
]


class CurrentPlan(StrEnum):
    """What the failure's current (last published) plan is."""

    NONE = "none"
    """Nothing published for this failure yet."""
    FALLBACK = "fallback"
    """A fallback (no converged solve behind it)."""
    STANDBY = "standby"
    """The live verdict's standby plan, published at the failure before the first plan from the failure's state."""
    CONVERGED = "converged"
    """A converged plan from a state of this failure."""


class TimerAction(StrEnum):
    """What a re-plan tick does."""

    IDLE = "idle"
    """No active failure, or no planner."""
    RETRY_FIRST_PLAN = "retry_first_plan"
    """Solve the first plan again: no converged plan from this failure's states is out."""
    REPLAN = "replan"
    """Re-plan from the current state, warm-started from the current plan."""


class ReplanGate(StrEnum):
    """Whether a re-plan is made from the current state."""

    REPLAN = "replan"
    PAUSE_NO_ROTOR = "pause_no_rotor"
    """The rotor speed is not measured: a re-plan from an assumed one could be worse than the current plan, which is
    kept (re-planning resumes with the measurement)."""
    END_CLOSED_LOOP = "end_closed_loop"
    """Near the ground: the closed loop ends and the current plan is flown to touchdown."""


def plan_time_remaining(time_to_land: float, elapsed: float) -> float:
    """Seconds the current plan still has to go: its time to land less the time since its state, s."""
    return time_to_land - elapsed


def replanning_ends(height: float, remaining: float, min_height: float, min_remaining: float) -> bool:
    """Whether the closed loop stops re-planning: below ``min_height`` (m) or under ``min_remaining`` (s) to go."""
    return height < min_height or remaining < min_remaining


def replan_timer_action(*, failure_active: bool, planner_ready: bool, current: CurrentPlan) -> TimerAction:
    """A re-plan tick: retry the first plan while only nothing, a fallback or the standby is out (the standby's
    refinement from the failure's state failed), else re-plan."""
    if not failure_active or not planner_ready:
        return TimerAction.IDLE
    if current is CurrentPlan.CONVERGED:
        return TimerAction.REPLAN
    return TimerAction.RETRY_FIRST_PLAN


def replan_gate(
    *, rotor_measured: bool, height: float, time_remaining: float, min_height: float, min_remaining: float
) -> ReplanGate:
    """Whether to re-plan from a state (``height`` m) with ``time_remaining`` s of the current plan to go."""
    if not rotor_measured:
        return ReplanGate.PAUSE_NO_ROTOR
    if replanning_ends(height, time_remaining, min_height, min_remaining):
        return ReplanGate.END_CLOSED_LOOP
    return ReplanGate.REPLAN


def keeps_current_plan(*, replan_safe: bool, for_site: bool, current_lands_from_here: Callable[[], bool]) -> bool:
    """Whether a converged re-plan is kept out and the current plan flown on: the re-plan is not safe, and the current
    plan's remainder, replayed from the re-plan's state in the same model and disturbance
    (:func:`~helireach_ros.core.evidence.replay.replay_remainder`), still lands within limits. Asked only then (the
    replay costs a few ms); never for a site plan (the remainder's replay does not judge the site).

    Why: IPOPT's answer is a local optimum, and a re-plan warm-started from the current plan can still converge to a
    far worse one (measured in the demo: value +0.77 a quarter second after −0.03, then a touchdown at 27 ft/s). The
    value function is continuous in the state, so the current plan flown on is a candidate the re-plan should have
    matched; when it still lands from the measured state it is evidence for that state, and the status it was
    published with stays true.
    """
    if replan_safe or for_site:
        return False
    return current_lands_from_here()


def fallback_after_failed_first_plan(
    *, retry: bool, any_published: bool, has_plan_from_state: bool, standby_current: bool
) -> bool:
    """Whether a first solve that failed publishes a fallback. Not when it was a retry and something is already out
    (a fallback is not repeated), when a plan from this state or a newer one is out (an older state's fallback must
    not follow it), or when the standby plan is current (a replay-verified standby beats a fallback)."""
    return not ((retry and any_published) or has_plan_from_state or standby_current)


def deadline_due(
    *, failure_active: bool, any_published: bool, already_handled: bool, elapsed_s: float, deadline_s: float
) -> bool:
    """Whether the deadline's fallback is due now: an active failure with nothing published ``deadline_s`` after its
    event, not handled before (the caller marks it handled)."""
    if not failure_active or any_published or already_handled:
        return False
    return elapsed_s >= deadline_s


@dataclass(frozen=True)
class SupervisorSettings:
    """The planner node's failure-handling parameters (same names, SI).

    Attributes:
        deadline: s after the failure event with nothing published at which a fallback is due.
        replan_min_height: m; no re-planning below.
        replan_min_remaining: s; no re-planning when the current plan has less time to go.
        max_message_age: s; a first plan from a state stamped later after the failure is late.
        history: published plans kept for inspection (demo, tests).
    """

    deadline: float = 0.25
    replan_min_height: float = 0.5
    replan_min_remaining: float = 0.3
    max_message_age: float = 1.0
    history: int = 200


class EpisodeAction(StrEnum):
    """What the monitor's failure-episode state asks of the planner."""

    NONE = "none"
    START = "start"
    """A failure the planner has not seen (its event was missed): plan for it."""
    STOP = "stop"
    """The current failure's episode is over (ended or landed): stop planning, say so."""


@dataclass(frozen=True)
class ReplanDecision:
    """A re-plan tick's answer for a state: the gate, and the current plan's time to go (s)."""

    gate: ReplanGate
    remaining: float
    previous: PublishedPlan | None


class LandingSupervisor:
    """The planner node's failure-handling state machine (thread-safe; no clock, no ROS).

    The node calls :meth:`start_failure` on a failure event, :meth:`observe_episode` on the monitor's episode state,
    :meth:`deadline_fallback_due` on its deadline timer, :meth:`timer_action` on its re-plan timer and
    :meth:`replan_decision` before each re-plan; it publishes a plan only inside :meth:`publication`, which refuses
    what must not go out (a plan of a superseded or finished failure, a fallback after a converged plan) and records
    what does, so that the check and the publication are one step for every thread.

    Two locks, as the node had: the failure pointer, counters and episode state under a short one that the
    executor's callbacks take (a rotor reading, a timer), publications and their records under another, held while
    the caller publishes, so that no callback waits for a publication. A stop takes the publication lock: a plan is
    published before it or refused after it.
    """

    def __init__(self, settings: SupervisorSettings | None = None) -> None:
        self.settings = settings or SupervisorSettings()
        self._lock = threading.Lock()  # the failure pointer, count, episode state, counters: short sections only
        self._publish_lock = threading.RLock()  # a publication's decision, the publication and its record; a stop
        self._failure: FailureEpisode | None = None
        self._episode = EpisodeState()  # the monitor's failure-episode state (no_flag until one arrives)
        self._failure_count = 0
        self.published_plans: list[PublishedPlan] = []
        self.standby_plans: list[PublishedPlan] = []

    # -- what is known ------------------------------------------------------------------------------------------
    @property
    def failure(self) -> FailureEpisode | None:
        """The current (or last) failure episode, None before the first."""
        with self._lock:
            return self._failure

    @property
    def failure_count(self) -> int:
        """Failures handled since start-up."""
        with self._lock:
            return self._failure_count

    @property
    def episode(self) -> EpisodeState:
        """The monitor's latest failure-episode state."""
        with self._lock:
            return self._episode

    @property
    def failure_active(self) -> bool:
        """A failure is being handled and its closed loop has not ended."""
        with self._lock:
            return self._failure is not None and self._failure.active

    @property
    def before_failure(self) -> bool:
        """No failure is being planned for (none yet, or the last one is over): steady flight may be measured."""
        with self._lock:
            return self._failure is None or bool(self._failure.outcome)

    def live_paused(self) -> bool:
        """Live evaluation pauses while a failure episode runs (the planner's own or the monitor's) and while it is
        LANDED with the engine still out: on the ground "if the engine failed now" has no answer."""
        with self._lock:
            failure, phase = self._failure, self._episode.phase
        return (failure is not None and not failure.outcome) or phase in (EpisodePhase.FAILED, EpisodePhase.LANDED)

    def is_standby(self, record: PublishedPlan) -> bool:
        """Whether a published plan is a standby plan (a live verdict's plan published on the failure)."""
        return any(record is standby for standby in self.standby_plans)

    def current_plan(self, failure: FailureEpisode) -> CurrentPlan:
        """What the failure's last published plan is."""
        current = failure.current
        if not failure.published or current is None:
            return CurrentPlan.NONE
        if current.fallback:
            return CurrentPlan.FALLBACK
        return CurrentPlan.STANDBY if self.is_standby(current) else CurrentPlan.CONVERGED

    # -- events -------------------------------------------------------------------------------------------------
    def start_failure(self, failure_stamp_ns: int, now_ns: int) -> FailureEpisode | None:
        """A new failure episode for the failure stamped ``failure_stamp_ns``; None if it is the current one already
        (its event and the monitor's state both announce it)."""
        with self._lock:
            if self._failure is not None and self._failure.event_stamp_ns == failure_stamp_ns:
                return None
            self._failure_count += 1
            self._failure = FailureEpisode(self._failure_count, failure_stamp_ns, now_ns)
            return self._failure

    def observe_episode(self, state: EpisodeState) -> tuple[EpisodeAction, FailureEpisode | None]:
        """Follows the monitor's episode: START a missed failure (the caller starts it at ``state.started_ns``),
        STOP the current one when its episode is over (returned, already stopped), else NONE."""
        with self._lock:
            self._episode = state
            failure = self._failure
        if state.started_ns is not None and episode_starts(state, failure.event_stamp_ns if failure else None):
            return EpisodeAction.START, None
        outcome = episode_outcome(state, failure.event_stamp_ns) if failure is not None else None
        if failure is None or outcome is None:
            return EpisodeAction.NONE, None
        with self._publish_lock:  # between publications: one in progress goes out first, none follows
            if failure is not self._failure or not failure.stop(outcome):
                return EpisodeAction.NONE, None
        return EpisodeAction.STOP, failure

    def deadline_fallback_due(self, now_ns: int) -> FailureEpisode | None:
        """The failure whose deadline fallback is due now (marked handled: once per failure), or None."""
        with self._lock:
            failure = self._failure
            if failure is None or not deadline_due(
                failure_active=failure.active,
                any_published=failure.published,
                already_handled=failure.deadline_handled,
                elapsed_s=(now_ns - failure.event_received_ns) * 1e-9,
                deadline_s=self.settings.deadline,
            ):
                return None
            failure.deadline_handled = True
            return failure

    def timer_action(self, *, planner_ready: bool) -> tuple[TimerAction, FailureEpisode | None]:
        """A re-plan tick: what to do, for which failure."""
        with self._lock:
            failure = self._failure
        if failure is None:
            return TimerAction.IDLE, None
        current = self.current_plan(failure)
        action = replan_timer_action(failure_active=failure.active, planner_ready=planner_ready, current=current)
        return action, failure

    def fallback_after_failed_solve(self, failure: FailureEpisode, *, retry: bool, stamp_ns: int) -> bool:
        """Whether a first solve from the state stamped ``stamp_ns`` that failed publishes a fallback."""
        current = failure.current
        return fallback_after_failed_first_plan(
            retry=retry,
            any_published=failure.published,
            has_plan_from_state=failure.has_plan_from(stamp_ns),
            standby_current=current is not None and self.is_standby(current),
        )

    def replan_decision(
        self, failure: FailureEpisode, *, rotor_measured: bool, height: float, stamp_ns: int
    ) -> ReplanDecision | None:
        """Whether to re-plan ``failure`` from a state (``height`` m, stamped ``stamp_ns``); counts a tick without a
        measured rotor and ends the closed loop near the ground (both recorded on the failure). None: the failure's
        closed loop is not running (ended, superseded, or no converged plan out to re-plan from)."""
        with self._lock:
            previous = failure.current
            if not failure.active or failure is not self._failure or previous is None:
                return None
            remaining = plan_time_remaining(previous.plan.time_to_land, (stamp_ns - previous.stamp_ns) * 1e-9)
            gate = replan_gate(
                rotor_measured=rotor_measured,
                height=height,
                time_remaining=remaining,
                min_height=self.settings.replan_min_height,
                min_remaining=self.settings.replan_min_remaining,
            )
            if gate is ReplanGate.PAUSE_NO_ROTOR:
                failure.replans_skipped_no_rotor += 1
            elif gate is ReplanGate.END_CLOSED_LOOP:
                failure.active = False
            return ReplanDecision(gate, remaining, previous)

    def replan_solved(self, failure: FailureEpisode, *, converged: bool) -> None:
        """Counts a re-plan's solve: converged (``replans``, its plan is published next unless it is kept out) or
        failed (the current plan is kept)."""
        with self._lock:
            if converged:
                failure.replans += 1
            else:
                failure.replans_failed += 1

    def replan_kept_out(self, failure: FailureEpisode) -> None:
        """Counts a converged re-plan kept out (:func:`keeps_current_plan`): the current plan is flown on."""
        with self._lock:
            failure.replans_kept_out += 1

    # -- publications -------------------------------------------------------------------------------------------
    def lateness(self, failure: FailureEpisode, stamp_ns: int, *, replan: bool) -> PlanLateness | None:
        """The lateness of a first plan (or fallback) from the state stamped ``stamp_ns``; None for a re-plan.
        Late "after a fallback" only if a fallback went out first (a standby before it is a verified plan)."""
        if replan:
            return None
        after_fallback = any(record.fallback for record in failure.history)
        return plan_lateness(failure.event_stamp_ns, stamp_ns, self.settings.max_message_age, after_fallback)

    @contextmanager
    def publication(self, failure: FailureEpisode, *, fallback: bool) -> Iterator[bool]:
        """Holds the decision while the caller publishes: yields whether a plan (``fallback``: a fallback) of
        ``failure`` may go out. Not when a newer failure superseded it or it is over, nor a fallback once a
        converged plan is out."""
        with self._publish_lock:
            allowed = failure is self._failure and not failure.outcome
            if allowed and fallback:
                allowed = failure.current is None or failure.current.fallback
            yield allowed

    def no_plan_may_be_reported(self, failure: FailureEpisode) -> bool:
        """Whether a "no plan" status may go out for ``failure``: it is current, nothing is published, not over.
        Call inside :meth:`publication`."""
        return failure is self._failure and not failure.published and not failure.outcome

    def remember(self, failure: FailureEpisode, record: PublishedPlan, *, standby: bool = False) -> None:
        """Records a publication (call inside :meth:`publication`): the failure's current plan, the history."""
        with self._publish_lock:
            failure.remember(record)
            self.published_plans.append(record)
            del self.published_plans[: -self.settings.history]
            if standby:
                self.standby_plans.append(record)
                del self.standby_plans[: -self.settings.history]
