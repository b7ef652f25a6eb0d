"""The planner node's failure-handling rules, without ROS: what to do at a failed first solve, at the deadline, and at
each re-plan tick. The node (:mod:`helireach_ros.ros.nodes.planner_node`) and the lock-step closed loop
(:mod:`helireach_ros.core.closed_loop`) ask these functions and carry out the answer.

After an engine failure the node solves a first plan from the state at the failure (warm-started from the envelope's
nearest stored plan), publishing the live verdict's standby plan meanwhile if it has one. A first solve that fails
publishes a fallback unless something better is already out (:func:`fallback_after_failed_first_plan`); a failure
with nothing published ``deadline`` seconds after its event gets a fallback (:func:`deadline_due`). Every
``replan_period`` the timer either tries the first plan again, while no converged plan of this failure is out, or
re-plans from the current state (:func:`replan_timer_action`); a re-plan is made only from a measured rotor speed
and stops near the ground (:func:`replan_gate`): below ``min_height`` or with less than ``min_remaining`` seconds of
the current plan to go (a re-plan that close to the ground would arrive after touchdown).
"""

from __future__ import annotations

from enum import StrEnum

__all__ = [
    "CurrentPlan",
    "ReplanGate",
    "TimerAction",
    "deadline_due",
    "fallback_after_failed_first_plan",
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
