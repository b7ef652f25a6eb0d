"""The planner node's failure-handling rules (core/policies/landing_supervisor.py), without ROS: every branch of the
fallback, deadline, timer and re-plan decisions, including the orders of events the chaos and fuzz tests found."""

from __future__ import annotations

import itertools
import subprocess
import sys
import threading
from types import SimpleNamespace

import pytest

from helireach_ros.core.policies.failure_episode import EpisodePhase, EpisodeState, FailureEpisode, PublishedPlan
from helireach_ros.core.policies.landing_supervisor import (
    CurrentPlan,
    EpisodeAction,
    LandingSupervisor,
    ReplanGate,
    SupervisorSettings,
    TimerAction,
    deadline_due,
    fallback_after_failed_first_plan,
    keeps_current_plan,
    replan_gate,
    replan_timer_action,
)


def test_the_rules_load_without_ros() -> None:
    code = "import sys, helireach_ros.core.policies.landing_supervisor; sys.exit('rclpy' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


@pytest.mark.parametrize(("replan_safe", "for_site", "lands"), list(itertools.product([False, True], repeat=3)))
def test_a_re_plan_is_kept_out_only_if_not_safe_while_the_current_plan_still_lands(
    replan_safe: bool, for_site: bool, lands: bool
) -> None:
    """The current plan's replay is asked for only when it can matter (a re-plan not safe, no site)."""
    asked = []

    def current_lands_from_here() -> bool:
        asked.append(True)
        return lands

    kept = keeps_current_plan(
        replan_safe=replan_safe, for_site=for_site, current_lands_from_here=current_lands_from_here
    )
    assert kept == (not replan_safe and not for_site and lands)
    assert bool(asked) == (not replan_safe and not for_site)


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


# -- the state machine on a fake clock (the node's races, without ROS) -------------------------------------------------
S = 1_000_000_000  # ns per second: the fake clock's unit


def _record(failure: FailureEpisode, stamp_ns: int, *, fallback: bool = False, time_to_land: float = 10.0):
    plan = SimpleNamespace(time_to_land=time_to_land)  # the supervisor reads a plan's time to land only
    return PublishedPlan(failure.failure_id, failure.replans, stamp_ns, plan, fallback, 1.0, stamp_ns, "none")


def _supervisor() -> LandingSupervisor:
    return LandingSupervisor(
        SupervisorSettings(deadline=0.25, replan_min_height=0.5, replan_min_remaining=0.3, max_message_age=1.0)
    )


def _failed_episode(started_s: float, phase: EpisodePhase = EpisodePhase.FAILED, episode_id: int = 1) -> EpisodeState:
    ended = None if phase is EpisodePhase.FAILED else int((started_s + 5.0) * S)
    return EpisodeState(phase=phase, episode_id=episode_id, started_ns=int(started_s * S), ended_ns=ended, flag=True)


def test_a_failure_starts_once_whether_its_event_or_the_monitors_episode_announces_it() -> None:
    supervisor = _supervisor()
    assert supervisor.live_paused() is False and supervisor.before_failure
    failure = supervisor.start_failure(10 * S, now_ns=10 * S + 1000)
    assert failure is not None and failure.failure_id == 1 and supervisor.failure is failure
    assert supervisor.start_failure(10 * S, now_ns=11 * S) is None  # the episode state announcing the same failure
    assert supervisor.observe_episode(_failed_episode(10.0)) == (EpisodeAction.NONE, None)
    assert supervisor.live_paused() and not supervisor.before_failure
    # a missed event: the monitor's state of a newer episode starts it; an older episode's late state starts nothing
    assert supervisor.observe_episode(_failed_episode(20.0, episode_id=2))[0] is EpisodeAction.START
    assert supervisor.observe_episode(_failed_episode(5.0))[0] is EpisodeAction.NONE
    assert supervisor.failure_count == 1


def test_the_deadline_fallback_is_due_once_and_only_with_nothing_out() -> None:
    supervisor = _supervisor()
    assert supervisor.deadline_fallback_due(now_ns=100 * S) is None  # no failure
    failure = supervisor.start_failure(10 * S, now_ns=10 * S)
    assert failure is not None
    assert supervisor.deadline_fallback_due(now_ns=int(10.2 * S)) is None  # 0.2 s < 0.25 s
    assert supervisor.deadline_fallback_due(now_ns=int(10.3 * S)) is failure
    assert supervisor.deadline_fallback_due(now_ns=int(10.4 * S)) is None  # handled once
    second = supervisor.start_failure(20 * S, now_ns=20 * S)
    assert second is not None
    with supervisor.publication(second, fallback=False) as allowed:
        assert allowed
        supervisor.remember(second, _record(second, 20 * S))
    assert supervisor.deadline_fallback_due(now_ns=21 * S) is None  # a plan went out in time


def test_a_plan_solved_for_a_superseded_or_finished_failure_is_never_published() -> None:
    supervisor = _supervisor()
    first = supervisor.start_failure(10 * S, now_ns=10 * S)
    second = supervisor.start_failure(12 * S, now_ns=12 * S)
    assert first is not None and second is not None and second.failure_id == 2
    with supervisor.publication(first, fallback=False) as allowed:  # first's solve returns after second started
        assert not allowed
    action, stopped = supervisor.observe_episode(_failed_episode(12.0, EpisodePhase.ENDED, episode_id=2))
    assert action is EpisodeAction.STOP and stopped is second and second.outcome == "ended" and not second.active
    assert supervisor.observe_episode(_failed_episode(12.0, EpisodePhase.ENDED, episode_id=2))[0] is EpisodeAction.NONE
    for fallback in (False, True):
        with supervisor.publication(second, fallback=fallback) as allowed:
            assert not allowed  # the episode is over: its last status is "ended", nothing follows it
    assert supervisor.timer_action(planner_ready=True) == (TimerAction.IDLE, second)
    assert supervisor.live_paused() is False and supervisor.before_failure  # ended: live evaluation resumes


def test_a_fallback_never_follows_a_converged_plan_and_a_failed_solve_respects_the_standby() -> None:
    supervisor = _supervisor()
    failure = supervisor.start_failure(10 * S, now_ns=10 * S)
    assert failure is not None
    assert supervisor.fallback_after_failed_solve(failure, retry=False, stamp_ns=10 * S)
    standby = _record(failure, int(9.9 * S))
    with supervisor.publication(failure, fallback=False) as allowed:
        assert allowed
        supervisor.remember(failure, standby, standby=True)
    assert supervisor.is_standby(standby) and supervisor.current_plan(failure) is CurrentPlan.STANDBY
    assert not supervisor.fallback_after_failed_solve(failure, retry=False, stamp_ns=10 * S)  # the standby stays
    assert supervisor.timer_action(planner_ready=True) == (TimerAction.RETRY_FIRST_PLAN, failure)
    converged = _record(failure, 10 * S)
    with supervisor.publication(failure, fallback=False) as allowed:
        assert allowed
        supervisor.remember(failure, converged)
    assert supervisor.current_plan(failure) is CurrentPlan.CONVERGED
    with supervisor.publication(failure, fallback=True) as allowed:
        assert not allowed  # e.g. the deadline's fallback racing the converged plan
    assert supervisor.timer_action(planner_ready=True) == (TimerAction.REPLAN, failure)
    assert supervisor.timer_action(planner_ready=False) == (TimerAction.IDLE, failure)
    assert supervisor.published_plans == [standby, converged] and supervisor.standby_plans == [standby]


def test_a_first_plan_is_late_after_a_fallback_or_from_a_late_state_never_after_a_standby() -> None:
    supervisor = _supervisor()
    failure = supervisor.start_failure(10 * S, now_ns=10 * S)
    assert failure is not None
    assert supervisor.lateness(failure, 11 * S, replan=True) is None
    on_time = supervisor.lateness(failure, int(10.5 * S), replan=False)
    assert on_time is not None and not on_time.late
    with supervisor.publication(failure, fallback=False):
        supervisor.remember(failure, _record(failure, int(9.9 * S)), standby=True)
    after_standby = supervisor.lateness(failure, int(10.5 * S), replan=False)
    assert after_standby is not None and not after_standby.late
    late_state = supervisor.lateness(failure, int(11.5 * S), replan=False)
    assert late_state is not None and late_state.state_late and late_state.late_by_s == pytest.approx(0.5)
    with supervisor.publication(failure, fallback=True) as allowed:
        assert not allowed  # the replay-verified standby is never replaced by a fallback
    second = supervisor.start_failure(20 * S, now_ns=20 * S)
    assert second is not None
    with supervisor.publication(second, fallback=True) as allowed:  # the deadline's fallback
        assert allowed
        supervisor.remember(second, _record(second, int(20.3 * S), fallback=True))
    after_fallback = supervisor.lateness(second, int(20.5 * S), replan=False)
    assert after_fallback is not None and after_fallback.after_fallback and after_fallback.late


def test_the_closed_loop_pauses_without_a_rotor_reading_and_ends_near_the_ground() -> None:
    supervisor = _supervisor()
    failure = supervisor.start_failure(10 * S, now_ns=10 * S)
    assert failure is not None
    assert supervisor.replan_decision(failure, rotor_measured=True, height=50.0, stamp_ns=11 * S) is None  # no plan
    with supervisor.publication(failure, fallback=False):
        supervisor.remember(failure, _record(failure, 10 * S, time_to_land=8.0))
    decision = supervisor.replan_decision(failure, rotor_measured=True, height=50.0, stamp_ns=11 * S)
    assert decision is not None and decision.gate is ReplanGate.REPLAN and decision.remaining == pytest.approx(7.0)
    paused = supervisor.replan_decision(failure, rotor_measured=False, height=50.0, stamp_ns=12 * S)
    assert paused is not None and paused.gate is ReplanGate.PAUSE_NO_ROTOR and failure.replans_skipped_no_rotor == 1
    supervisor.replan_solved(failure, converged=True)
    supervisor.replan_solved(failure, converged=False)
    assert (failure.replans, failure.replans_failed) == (1, 1)
    ending = supervisor.replan_decision(failure, rotor_measured=True, height=50.0, stamp_ns=int(17.8 * S))
    assert ending is not None and ending.gate is ReplanGate.END_CLOSED_LOOP  # 0.2 s of the plan to go
    assert not failure.active and not supervisor.failure_active
    assert supervisor.replan_decision(failure, rotor_measured=True, height=50.0, stamp_ns=18 * S) is None
    assert supervisor.timer_action(planner_ready=True) == (TimerAction.IDLE, failure)
    assert supervisor.live_paused()  # the episode itself runs until the monitor says landed or ended


def test_concurrent_publications_and_a_stop_leave_one_consistent_history() -> None:
    # The solver thread publishes re-plans while the executor stops the episode: every record published before the
    # stop is in the history, none after it, and the stop happens once.
    supervisor = _supervisor()
    failure = supervisor.start_failure(10 * S, now_ns=10 * S)
    assert failure is not None
    published: list[int] = []
    stop_at = threading.Event()

    def publish_many() -> None:
        for index in range(2000):
            with supervisor.publication(failure, fallback=False) as allowed:
                if not allowed:
                    return
                supervisor.remember(failure, _record(failure, 10 * S + index))
                published.append(index)
            if index == 500:
                stop_at.set()

    worker = threading.Thread(target=publish_many)
    worker.start()
    stop_at.wait(timeout=10.0)
    action, _ = supervisor.observe_episode(_failed_episode(10.0, EpisodePhase.LANDED))
    worker.join(timeout=10.0)
    assert action is EpisodeAction.STOP and failure.outcome == "landed"
    assert len(failure.history) == len(published) and 500 < len(published) < 2000
