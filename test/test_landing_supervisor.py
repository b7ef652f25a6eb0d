"""The planner node's failure-handling rules (core/landing_supervisor.py), without ROS: every branch of the fallback,
deadline, timer and re-plan decisions, including the orders of events the chaos and fuzz tests found."""

from __future__ import annotations

import itertools
import subprocess
import sys

import pytest

from helireach_ros.core.landing_supervisor import (
    CurrentPlan,
    ReplanGate,
    TimerAction,
    deadline_due,
    fallback_after_failed_first_plan,
    replan_gate,
    replan_timer_action,
)


def test_the_rules_load_without_ros() -> None:
    code = "import sys, helireach_ros.core.landing_supervisor; sys.exit('rclpy' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


@pytest.mark.parametrize(
    ("retry", "any_published", "has_plan_from_state", "standby_current"),
    list(itertools.product([False, True], repeat=4)),
)
def test_a_failed_first_solve_publishes_a_fallback_only_when_nothing_better_is_out(
    retry: bool, any_published: bool, has_plan_from_state: bool, standby_current: bool
) -> None:
    publish = fallback_after_failed_first_plan(
        retry=retry, any_published=any_published, has_plan_from_state=has_plan_from_state,
        standby_current=standby_current,
    )  # fmt: skip
    # A retry with something out never repeats a fallback; a plan from this (or a newer) state is never followed by
    # an older state's fallback; the replay-verified standby is never replaced by a fallback.
    expected = not (retry and any_published) and not has_plan_from_state and not standby_current
    assert publish is expected


def test_the_first_failed_solve_of_a_failure_with_nothing_out_falls_back() -> None:
    assert fallback_after_failed_first_plan(
        retry=False, any_published=False, has_plan_from_state=False, standby_current=False
    )
    # the first solve failing after the deadline's fallback went out (not a retry): a fallback from the newer state
    assert fallback_after_failed_first_plan(
        retry=False, any_published=True, has_plan_from_state=False, standby_current=False
    )


@pytest.mark.parametrize(
    ("failure_active", "any_published", "already_handled", "elapsed_s", "due"),
    [
        (True, False, False, 0.5, True),  # the deadline passed with nothing out
        (True, False, False, 0.499, False),  # not yet
        (True, True, False, 5.0, False),  # a plan (or the standby) is out
        (True, False, True, 5.0, False),  # the fallback was already published for this failure
        (False, False, False, 5.0, False),  # the episode ended (engine recovered, landed)
    ],
)
def test_the_deadline_fallback_is_due_once_when_nothing_is_out(
    failure_active: bool, any_published: bool, already_handled: bool, elapsed_s: float, due: bool
) -> None:
    assert deadline_due(
        failure_active=failure_active, any_published=any_published, already_handled=already_handled,
        elapsed_s=elapsed_s, deadline_s=0.5,
    ) is due  # fmt: skip


@pytest.mark.parametrize(
    ("current", "expected"),
    [
        (CurrentPlan.NONE, TimerAction.RETRY_FIRST_PLAN),
        (CurrentPlan.FALLBACK, TimerAction.RETRY_FIRST_PLAN),
        (CurrentPlan.STANDBY, TimerAction.RETRY_FIRST_PLAN),  # its refinement from the failure's state failed
        (CurrentPlan.CONVERGED, TimerAction.REPLAN),
    ],
)
def test_the_timer_retries_until_a_converged_plan_is_out_then_replans(
    current: CurrentPlan, expected: TimerAction
) -> None:
    assert replan_timer_action(failure_active=True, planner_ready=True, current=current) is expected
    assert replan_timer_action(failure_active=False, planner_ready=True, current=current) is TimerAction.IDLE
    assert replan_timer_action(failure_active=True, planner_ready=False, current=current) is TimerAction.IDLE


@pytest.mark.parametrize(
    ("rotor_measured", "height", "time_remaining", "expected"),
    [
        (True, 50.0, 10.0, ReplanGate.REPLAN),
        (False, 50.0, 10.0, ReplanGate.PAUSE_NO_ROTOR),  # whatever the height: the current plan is kept
        (False, 0.5, 0.1, ReplanGate.PAUSE_NO_ROTOR),
        (True, 2.9, 10.0, ReplanGate.END_CLOSED_LOOP),  # below min_height
        (True, 50.0, 0.49, ReplanGate.END_CLOSED_LOOP),  # a re-plan would arrive after touchdown
        (True, 3.0, 0.5, ReplanGate.REPLAN),  # on both thresholds: still re-plans
    ],
)
def test_a_replan_needs_a_measured_rotor_and_stops_near_the_ground(
    rotor_measured: bool, height: float, time_remaining: float, expected: ReplanGate
) -> None:
    gate = replan_gate(
        rotor_measured=rotor_measured, height=height, time_remaining=time_remaining, min_height=3.0,
        min_remaining=0.5,
    )  # fmt: skip
    assert gate is expected
