"""The failure-episode model (no ROS): start, debounced end, landed, re-failure, clock jumps, lateness."""

from __future__ import annotations

import math

import pytest

from helireach_ros.core.policies.failure_episode import (
    EpisodePhase,
    EpisodeSettings,
    EpisodeState,
    EpisodeTracker,
    FailureEpisode,
    PublishedPlan,
    episode_outcome,
    episode_starts,
    late_verdict,
    plan_lateness,
)

MS = 1_000_000  # ns
S = 1_000_000_000
T0 = 1_700_000_000 * S  # a plausible ROS time, ns


def feed(tracker: EpisodeTracker, flags: list[tuple[int, bool]]) -> list:
    """Observes (time ns, flag) pairs; returns the transitions that happened."""
    return [transition for time, flag in flags if (transition := tracker.observe_flag(flag, time)) is not None]


def test_the_first_true_starts_an_episode_at_once_and_unknown_is_no_flag() -> None:
    tracker = EpisodeTracker()
    assert tracker.state.phase is EpisodePhase.NO_FLAG and tracker.state.level_name == "WARN"
    assert "no engine-failure flag received" in tracker.state.text
    transition = tracker.observe_flag(True, T0)
    assert transition is not None and transition.started
    assert (transition.previous, tracker.state.phase) == (EpisodePhase.NO_FLAG, EpisodePhase.FAILED)
    assert (tracker.state.episode_id, tracker.state.started_ns, tracker.state.level_name) == (1, T0, "ERROR")


def test_false_first_is_normal_then_true_starts_episode_one() -> None:
    tracker = EpisodeTracker()
    assert not tracker.observe_flag(False, T0).started
    assert tracker.state.phase is EpisodePhase.NORMAL and tracker.state.level_name == "OK"
    assert tracker.observe_flag(False, T0 + 40 * MS) is None
    assert tracker.observe_flag(True, T0 + 80 * MS).started
    assert (tracker.state.episode_id, tracker.state.started_ns) == (1, T0 + 80 * MS)


def test_a_flag_flapping_at_100_hz_for_4_5_s_is_one_episode() -> None:
    tracker = EpisodeTracker(EpisodeSettings(recovery_hold=3.0))
    flags = [(T0 + k * 10 * MS, k % 2 == 0) for k in range(450)]
    transitions = feed(tracker, flags)
    assert [t.started for t in transitions] == [True]
    state = tracker.state
    assert (state.phase, state.episode_id, state.started_ns) == (EpisodePhase.FAILED, 1, T0)
    assert state.flag_changes == 449 and "flipped 449 times" in state.text


def test_steady_false_for_the_hold_ends_the_episode_and_a_shorter_run_does_not() -> None:
    tracker = EpisodeTracker(EpisodeSettings(recovery_hold=2.0))
    tracker.observe_flag(True, T0)
    # false for 1.96 s, then true again: still the same episode, and the hold starts over
    assert feed(tracker, [(T0 + S + k * 40 * MS, False) for k in range(50)]) == []
    tracker.observe_flag(True, T0 + 3 * S)
    false_run = [(T0 + 4 * S + k * 40 * MS, False) for k in range(51)]  # 0 … 2.0 s
    transitions = feed(tracker, false_run)
    assert [t.state.phase for t in transitions] == [EpisodePhase.ENDED]
    state = tracker.state
    assert (state.ended_ns, state.episode_id, state.false_since_ns) == (T0 + 6 * S, 1, T0 + 4 * S)
    assert state.text.startswith("ENDED (engine recovered)") and state.level_name == "WARN"
    assert episode_outcome(state, T0) is EpisodePhase.ENDED


def test_silence_never_ends_an_episode() -> None:
    tracker = EpisodeTracker(EpisodeSettings(recovery_hold=2.0))
    tracker.observe_flag(True, T0)
    tracker.observe_flag(False, T0 + S)  # one false, then nothing for a long time
    assert tracker.observe_state(500.0, 0.0, T0 + 100 * S) is None
    assert tracker.state.phase is EpisodePhase.FAILED


def test_a_true_after_ended_is_a_new_episode() -> None:
    tracker = EpisodeTracker(EpisodeSettings(recovery_hold=1.0))
    feed(tracker, [(T0, True), (T0 + S, False), (T0 + 2 * S, False)])
    assert tracker.state.phase is EpisodePhase.ENDED
    first = tracker.state
    transition = tracker.observe_flag(True, T0 + 5 * S)
    assert transition.started and transition.previous is EpisodePhase.ENDED
    assert (tracker.state.episode_id, tracker.state.started_ns, tracker.state.ended_ns) == (2, T0 + 5 * S, None)
    assert tracker.state.flag_changes == 0
    assert episode_outcome(tracker.state, first.started_ns) is EpisodePhase.ENDED  # superseded
    assert episode_outcome(tracker.state, T0 + 5 * S) is None
    assert episode_starts(tracker.state, first.started_ns) and not episode_starts(tracker.state, T0 + 5 * S)
    assert episode_outcome(first, T0 + 5 * S) is None  # news of the older episode, delivered late
    assert not episode_starts(first, None)


def test_a_landed_state_ends_the_episode_and_a_still_true_flag_starts_nothing() -> None:
    tracker = EpisodeTracker(EpisodeSettings(recovery_hold=1.0, landed_height=0.3, landed_climb_rate=0.3))
    assert tracker.observe_state(0.0, 0.0, T0) is None  # on the ground without a failure: nothing to end
    tracker.observe_flag(True, T0 + S)
    assert tracker.observe_state(0.2, -2.0, T0 + 2 * S) is None  # touching down fast: not landed yet
    assert tracker.observe_state(math.nan, 0.0, T0 + 2 * S) is None
    transition = tracker.observe_state(0.1, -0.1, T0 + 3 * S)
    assert transition.state.phase is EpisodePhase.LANDED and not transition.started
    assert tracker.observe_flag(True, T0 + 4 * S) is None and tracker.state.phase is EpisodePhase.LANDED
    assert episode_outcome(tracker.state, T0 + S) is EpisodePhase.LANDED
    # engine running again on the ground for the hold: normal, and the next true is episode 2
    assert feed(tracker, [(T0 + 5 * S, False), (T0 + 6 * S, False)])[0].state.phase is EpisodePhase.NORMAL
    assert episode_outcome(tracker.state, T0 + S) is EpisodePhase.LANDED
    assert tracker.observe_flag(True, T0 + 7 * S).started and tracker.state.episode_id == 2


def test_a_clock_jumping_back_is_counted_and_restarts_the_hold() -> None:
    tracker = EpisodeTracker(EpisodeSettings(recovery_hold=2.0))
    feed(tracker, [(T0, True), (T0 + S, False), (T0 + 2 * S, False)])
    # the clock jumps 10 s back: 1.9 s of false on the new clock must not count the 1 s before the jump
    assert feed(tracker, [(T0 - 8 * S, False), (T0 - 8 * S + 1900 * MS, False)]) == []
    assert tracker.state.phase is EpisodePhase.FAILED and tracker.state.out_of_order == 1
    assert tracker.state.false_since_ns == T0 - 8 * S
    assert feed(tracker, [(T0 - 6 * S, False)])[0].state.phase is EpisodePhase.ENDED
    # a true stamped before the last observation still starts an episode (a failure is never dropped)
    assert tracker.observe_flag(True, T0 - 7 * S).started and tracker.state.out_of_order == 2


def test_episode_state_round_trips_through_diagnostic_values() -> None:
    tracker = EpisodeTracker()
    feed(tracker, [(T0, True), (T0 + 10 * MS, False), (T0 + 20 * MS, True)])
    wire = {
        key: str(value).lower() if isinstance(value, bool) else str(value)
        for key, value in tracker.state.as_values().items()
    }
    assert EpisodeState.from_values(wire) == tracker.state
    assert (
        EpisodeState.from_values({key: str(value) for key, value in EpisodeState().as_values().items()})
        == EpisodeState()
    )
    with pytest.raises(ValueError, match="phase"):
        EpisodeState.from_values({k: v for k, v in wire.items() if k != "phase"})
    with pytest.raises(ValueError):
        EpisodeState.from_values({**wire, "phase": "recovered"})


def test_no_failure_seen_never_ends_planning_and_a_missed_event_still_starts_it() -> None:
    running = EpisodeState(EpisodePhase.FAILED, 1, started_ns=T0, flag=True)
    assert episode_outcome(EpisodeState(), T0) is None and episode_outcome(running, T0) is None
    assert episode_starts(running, None) and not episode_starts(running, T0)
    assert not episode_starts(EpisodeState(), None)


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ({"recovery_hold": 0.0}, "recovery_hold"),
        ({"recovery_hold": math.nan}, "recovery_hold"),
        ({"landed_height": -0.1}, "landed_height"),
        ({"landed_climb_rate": 0.0}, "landed_climb_rate"),
        ({"recovery_hold": "3"}, "recovery_hold"),
        ({"landed_height": True}, "landed_height"),
    ],
)
def test_settings_are_validated(settings: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        EpisodeSettings(**settings)


def test_lateness_of_the_first_plan() -> None:
    on_time = plan_lateness(T0, T0 - 20 * MS, 1.0)  # the latest state before the failure: the normal case
    assert (on_time.state_late, on_time.late, on_time.late_by_s) == (False, False, 0.0)
    assert math.isclose(on_time.state_delay_s, -0.02)
    edge = plan_lateness(T0, T0 + S, 1.0)
    assert not edge.late
    late = plan_lateness(T0, T0 + 3500 * MS, 1.0)
    assert late.state_late and late.late and math.isclose(late.late_by_s, 2.5) and math.isclose(late.state_delay_s, 3.5)
    after_fallback = plan_lateness(T0, T0, 1.0, after_fallback=True)
    assert after_fallback.late and not after_fallback.state_late and after_fallback.late_by_s == 0.0
    with pytest.raises(ValueError, match="max_message_age"):
        plan_lateness(T0, T0, 0.0)


def test_a_late_safe_plan_is_at_best_a_warning_that_says_how_late() -> None:
    late = plan_lateness(T0, T0 + 3500 * MS, 1.0)
    level, text = late_verdict("OK", "SAFE: land in 9.9 s", late)
    assert level == "WARN" and text.startswith("LATE (state 3.5 s after the failure, 2.5 s too late): SAFE")
    assert late_verdict("ERROR", "UNSAFE: x", late)[0] == "ERROR"
    assert late_verdict("OK", "SAFE: x", plan_lateness(T0, T0, 1.0, after_fallback=True)) == ("OK", "SAFE: x")


def test_a_fallback_never_follows_a_plan_from_a_newer_state() -> None:
    record = FailureEpisode(1, T0, T0)
    assert not record.has_plan_from(T0)  # nothing out yet
    deadline_fallback = PublishedPlan(1, 0, T0 + 300 * MS, None, True, 250.0, T0 + 310 * MS, "none")
    record.remember(deadline_fallback)
    assert record.has_plan_from(T0 + 100 * MS) and record.has_plan_from(T0 + 300 * MS)  # older or the same state
    assert not record.has_plan_from(T0 + 400 * MS)  # a newer state: its fallback may go out


def test_a_planner_record_stops_once() -> None:
    record = FailureEpisode(1, T0, T0)
    assert record.stop(EpisodePhase.ENDED) and not record.active and record.outcome == "ended"
    assert not record.stop(EpisodePhase.LANDED) and record.outcome == "ended"
