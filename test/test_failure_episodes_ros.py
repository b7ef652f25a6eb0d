"""Failure episodes with real rclpy (monitor + planner): no flag yet, a flapping flag, recovery, a late state.

Same set-up as ``test_ros_nodes.py`` (its harness: one context per test, discovery off, spin until a condition).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context
from rclpy.parameter import Parameter
from std_msgs.msg import Bool, Header
from test_ros_nodes import TIMEOUT_S, Harness, level_is, monitor_and_planner, trigger_failure
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.policies.failure_episode import EpisodePhase, EpisodeState
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode

HEIGHT, SPEED = 500 * FT, 75 * KT  # well inside the safe region


def monitor_reports(diagnostics: list[DiagnosticArray]) -> list[DiagnosticStatus]:
    return [
        status for array in diagnostics for status in array.status if status.name == "helireach_monitor: vehicle state"
    ]


def run_for(harness: Harness, seconds: float, step: Callable[[float], None], period_s: float) -> None:
    """Calls ``step(elapsed)`` every ``period_s`` for ``seconds`` while spinning."""
    start = time.monotonic()
    next_step = start
    while (now := time.monotonic()) < start + seconds:
        if now >= next_step:
            step(now - start)
            next_step += period_s
        harness.executor.spin_once(timeout_sec=max(0.0, min(0.002, next_step - time.monotonic())))


def values_of(statuses: list[DiagnosticStatus]) -> list[dict[str, str]]:
    return [rm.status_values(status) for status in statuses]


# --- no flag yet ----------------------------------------------------------------------------------------------
def test_no_flag_yet_is_a_monitor_warning_and_the_safety_status_stays_as_the_envelope_says(context: Context) -> None:
    harness = Harness(context, VehicleMonitor(context=context), EnvelopeStatusNode(context=context))
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS)
    episodes = harness.listen(DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, rm.STREAM_QOS)
    try:
        reported = lambda: bool(monitor_reports(diagnostics)) and bool(episodes)  # noqa: E731
        assert harness.keep_publishing(
            HEIGHT, SPEED, until=lambda: level_is(statuses, DiagnosticStatus.OK)() and reported()
        )
        report = monitor_reports(diagnostics)[-1]
        assert report.level == DiagnosticStatus.WARN and report.message == "no engine-failure flag received"
        assert rm.status_values(report)["engine_failed"] == "unknown"
        assert rm.status_values(report)["failure_episode"] == "no_flag"
        assert episodes[-1].level == DiagnosticStatus.WARN
        assert EpisodeState.from_values(rm.status_values(episodes[-1])).phase is EpisodePhase.NO_FLAG
        # the first flag clears it
        harness.failure.publish(Bool(data=False))
        assert harness.keep_publishing(
            HEIGHT, SPEED, until=lambda: monitor_reports(diagnostics)[-1].level == DiagnosticStatus.OK
        )
        assert rm.status_values(monitor_reports(diagnostics)[-1])["engine_failed"] == "false"
        assert rm.status_values(episodes[-1])["phase"] == "normal"
    finally:
        harness.close()


# --- a flapping flag ------------------------------------------------------------------------------------------
def test_a_flag_flapping_at_100_hz_is_one_episode_with_a_trajectory_while_it_flaps(context: Context) -> None:
    harness, planner = monitor_and_planner(context, replan_period=0.0)
    events = harness.listen(Header, rm.TOPIC_FAILURE_EVENT, rm.EVENT_QOS)
    trajectories = harness.listen(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    episodes = harness.listen(DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, rm.STREAM_QOS)
    trajectory_during_flapping: list[bool] = []
    try:
        assert harness.keep_publishing(HEIGHT, SPEED, until=lambda: planner.current_state() is not None)
        flips = [0]

        def flap(elapsed: float) -> None:
            harness.failure.publish(Bool(data=flips[0] % 2 == 0))  # true, false, true, … at 100 Hz
            flips[0] += 1
            if flips[0] % 2:
                harness.publish_state(HEIGHT, SPEED)  # the vehicle's 50 Hz state
            if trajectories and not trajectory_during_flapping:
                trajectory_during_flapping.append(True)

        run_for(harness, 3.0, flap, 0.01)
        assert flips[0] >= 200
        assert trajectory_during_flapping, "no trajectory while the flag flapped"
        assert harness.spin_until(lambda: bool(episodes) and rm.status_values(episodes[-1])["phase"] == "failed")
        assert len(events) == 1
        assert {fields["failure_id"] for fields in values_of(plan_statuses)} == {"1"}
        assert {record.failure_id for record in planner.supervisor.published_plans} == {1}
        episode = EpisodeState.from_values(rm.status_values(episodes[-1]))
        assert (episode.phase, episode.episode_id) == (EpisodePhase.FAILED, 1) and episode.flag_changes > 100
        # the first trajectory is the normal one: the converged plan, or the deadline's fallback, for failure 1
        first = values_of(plan_statuses)[0]
        assert first["status"] in ("safe", "fallback") and first["late"] == "false", first
    finally:
        harness.close()


# --- engine recovered -----------------------------------------------------------------------------------------
def test_a_flag_false_for_good_ends_the_episode_after_the_hold_and_replanning_stops(context: Context) -> None:
    hold_s = 0.6
    # The harness holds the state still; a vehicle that does not descend as planned would teach the re-plans a
    # disturbance holding it up (their gentle landings then fail the replay: NOT VERIFIED). Not learning one keeps
    # them to the model's.
    harness, planner = monitor_and_planner(
        context, {"recovery_hold": hold_s}, replan_period=0.1, estimate_disturbance=False
    )
    trajectories = harness.listen(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    episodes = harness.listen(DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, rm.STREAM_QOS)
    try:
        trigger_failure(harness, HEIGHT, SPEED)
        replanned = lambda: any(int(fields.get("replan_index", "0")) >= 2 for fields in values_of(plan_statuses))  # noqa: E731
        assert harness.keep_publishing(HEIGHT, SPEED, until=replanned), values_of(plan_statuses)[-1:]
        assert plan_statuses[-1].level == DiagnosticStatus.OK and plan_statuses[-1].message.startswith("SAFE"), (
            plan_statuses[-1].message
        )

        def relit(_: float) -> None:
            harness.failure.publish(Bool(data=False))
            harness.publish_state(HEIGHT, SPEED)

        ended = lambda: rm.status_values(plan_statuses[-1])["status"] == "ended"  # noqa: E731
        deadline = time.monotonic() + TIMEOUT_S
        while not ended() and time.monotonic() < deadline:
            run_for(harness, 0.04, relit, 0.04)
        assert ended(), values_of(plan_statuses)[-1]
        status = plan_statuses[-1]
        assert status.level == DiagnosticStatus.WARN and status.message.startswith("ENDED (engine recovered)")
        fields = rm.status_values(status)
        assert (fields["safe"], fields["verified"], fields["failure_id"]) == ("false", "false", "1")
        episode = EpisodeState.from_values(rm.status_values(episodes[-1]))
        assert episode.phase is EpisodePhase.ENDED
        assert (episode.ended_ns - episode.false_since_ns) * 1e-9 >= hold_s  # only after the hold of steady false
        assert int(fields["ended_stamp_ns"]) == episode.ended_ns
        assert not planner.supervisor.failure_active
        # nothing more is planned or published for it
        published, trajectory_count = len(plan_statuses), len(trajectories)
        run_for(harness, 1.0, relit, 0.04)
        assert (len(plan_statuses), len(trajectories)) == (published, trajectory_count)
        assert rm.status_values(plan_statuses[-1])["status"] == "ended"
        # a new true is a new episode and planning starts again
        harness.failure.publish(Bool(data=True))
        again = lambda: rm.status_values(plan_statuses[-1]).get("failure_id") == "2"  # noqa: E731
        assert harness.keep_publishing(HEIGHT, SPEED, until=again)
    finally:
        harness.close()


# --- a failure while the state is invalid ---------------------------------------------------------------------
def test_a_failure_planned_from_a_later_state_is_flagged_late_and_never_plain_safe(context: Context) -> None:
    max_age_s = 0.5
    harness, _ = monitor_and_planner(context, max_message_age=max_age_s, replan_period=0.1)
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    events = harness.listen(Header, rm.TOPIC_FAILURE_EVENT, rm.EVENT_QOS)
    try:
        flag = [False]

        def invalid_state(_: float) -> None:  # the vehicle's state is garbage (NaN height) while the engine fails
            harness.failure.publish(Bool(data=flag[0]))
            harness.publish_state(math.nan, SPEED)

        run_for(harness, 0.2, invalid_state, 0.04)
        flag[0] = True
        run_for(harness, 1.5, invalid_state, 0.04)
        assert len(events) == 1
        assert plan_statuses and all(status.level == DiagnosticStatus.ERROR for status in plan_statuses)
        assert "NO PLAN" in plan_statuses[-1].message
        failure_stamp = rm.stamp_nanoseconds(events[0].stamp)

        planned = lambda: rm.status_values(plan_statuses[-1])["status"] not in ("none", "fallback")  # noqa: E731
        assert harness.keep_publishing(HEIGHT, SPEED, until=planned)
        first_plans = [
            (status, fields)
            for status, fields in zip(plan_statuses, values_of(plan_statuses), strict=True)
            if fields["status"] != "none" and fields.get("replan_index", "0") == "0"
        ]
        for status, fields in first_plans:  # a fallback and/or the converged plan: each flagged
            delay = (int(fields["state_stamp_ns"]) - failure_stamp) * 1e-9
            assert delay > 1.5 and math.isclose(float(fields["state_delay_s"]), delay, abs_tol=1e-6)
            assert fields["late"] == "true" and math.isclose(
                float(fields["late_by_s"]), delay - max_age_s, abs_tol=1e-6
            )
            assert status.level != DiagnosticStatus.OK and status.message.startswith("LATE (state ")
        plan = first_plans[-1][1]
        assert plan["status"] == "safe" and plan["safe"] == "true"  # the plan itself is verified, from that state
    finally:
        harness.close()


# --- a planner that missed the event; landing -----------------------------------------------------------------
def test_a_planner_that_missed_the_event_plans_from_the_episode_and_stops_when_landed(context: Context) -> None:
    harness = Harness(context, VehicleMonitor(context=context))
    events = harness.listen(Header, rm.TOPIC_FAILURE_EVENT, rm.EVENT_QOS)
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS)
    try:

        def failed_in_flight(_: float) -> None:
            harness.failure.publish(Bool(data=True))
            harness.publish_state(HEIGHT, SPEED)

        run_for(harness, 0.3, failed_in_flight, 0.04)
        assert len(events) == 1  # published before the planner existed (a restarted planner, say)
        planner = LandingPlannerNode(
            context=context,
            parameter_overrides=[
                Parameter("replan_period", value=0.1),
                Parameter("diagnostics_period", value=0.1),
                Parameter("replan_min_height", value=0.0),  # only the episode's landing may stop the loop here
                Parameter("max_message_age", value=0.1),  # the failure was 0.3 s ago: its state is late
            ],
        )
        harness.nodes.append(planner)
        harness.executor.add_node(planner)
        planned = lambda: bool(plan_statuses) and rm.status_values(plan_statuses[-1])["status"] == "safe"  # noqa: E731
        deadline = time.monotonic() + TIMEOUT_S
        while not planned() and time.monotonic() < deadline:
            run_for(harness, 0.04, failed_in_flight, 0.04)
        assert planned() and len(events) == 1
        fields = rm.status_values(plan_statuses[-1])
        assert int(fields["failure_stamp_ns"]) == rm.stamp_nanoseconds(events[0].stamp)
        assert fields["late"] == "true"  # planned from a state long after the failure, and says so

        def on_the_ground(_: float) -> None:
            harness.failure.publish(Bool(data=True))
            harness.publish_state(0.0, 0.0)

        def planner_says(key: str) -> str | None:
            reports = [s for array in diagnostics for s in array.status if s.name == "helireach_planner: planner"]
            return rm.status_values(reports[-1]).get(key) if reports else None

        deadline = time.monotonic() + TIMEOUT_S
        while planner_says("failure_outcome") != "landed" and time.monotonic() < deadline:
            run_for(harness, 0.04, on_the_ground, 0.04)
        assert planner_says("failure_outcome") == "landed" and planner_says("failure_episode") == "landed"
        assert not planner.supervisor.failure_active
        published = planner.supervisor.published_plans
        assert published and {record.failure_id for record in published} == {1}
        assert len(events) == 1  # the flag still true on the ground starts nothing
        # the latched plan status says the episode is over, not the last plan's verdict (a late joiner reads it)
        assert harness.spin_until(lambda: rm.status_values(plan_statuses[-1])["status"] == "landed")
        landed = plan_statuses[-1]
        assert landed.level == DiagnosticStatus.WARN and landed.message.startswith("LANDED: planning stopped")
        assert rm.status_values(landed)["safe"] == "false" and rm.status_values(landed)["failure_id"] == "1"
        # on the ground with the engine still out, live evaluation stays paused (its solves from a rotor running
        # down only failed, at full effort)
        live = planner.live.evaluator if planner.live is not None else None
        evaluations = (live.evaluations, live.errors) if live is not None else None
        run_for(harness, 1.5, on_the_ground, 0.04)
        assert live is None or (live.evaluations, live.errors) == evaluations
    finally:
        harness.close()


# --- after the failure, the status ages with its evidence -----------------------------------------------------
def test_after_a_failure_a_verified_plan_is_ok_only_while_the_aircraft_is_seen_flying_it(context: Context) -> None:
    """The vehicle stops publishing after the failure: the safety status leaves OK within about stale_timeout and
    says the plan is not tracked; with the state back but no rotor reading it is at most WARN, saying why."""
    monitor = VehicleMonitor(context=context)
    planner = LandingPlannerNode(context=context, parameter_overrides=[Parameter("replan_period", value=0.0)])
    harness = Harness(context, monitor, planner, EnvelopeStatusNode(context=context))
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        trigger_failure(harness, HEIGHT, SPEED)
        verified = lambda: bool(statuses) and statuses[-1].message.startswith("ENGINE FAILURE: ") and (  # noqa: E731
            statuses[-1].level == DiagnosticStatus.OK
        )
        assert harness.keep_publishing(HEIGHT, SPEED, until=verified), statuses[-1].message
        silent_since = time.monotonic()
        assert harness.spin_until(level_is(statuses, DiagnosticStatus.STALE), timeout_s=3.0)
        assert time.monotonic() - silent_since < 0.5 + 0.5 + 0.3  # stale_timeout + publish_period + slack
        assert "NOT TRACKED" in statuses[-1].message and "verified" in statuses[-1].message
        assert rm.status_values(statuses[-1])["episode"] == "failed"

        def odometry_only(_: float) -> None:
            harness.odometry.publish(rm.odometry_message(harness.now_ns(), HEIGHT, 0.0, SPEED, 0.0))

        run_for(harness, 1.5, odometry_only, 0.02)
        assert statuses[-1].level == DiagnosticStatus.WARN
        assert "rotor speed not measured" in statuses[-1].message
    finally:
        harness.close()


def test_re_planning_pauses_without_a_rotor_reading_and_says_so(context: Context) -> None:
    harness, planner = monitor_and_planner(context, replan_period=0.1)
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS)
    try:
        trigger_failure(harness, HEIGHT, SPEED)
        assert harness.keep_publishing(HEIGHT, SPEED, until=lambda: planner.supervisor.published_plans != [])

        def odometry_only(_: float) -> None:  # the rotor joint is gone from the vehicle's messages
            harness.odometry.publish(rm.odometry_message(harness.now_ns(), HEIGHT, 0.0, SPEED, 0.0))

        run_for(harness, 2.0, odometry_only, 0.02)
        reports = [
            status for array in diagnostics for status in array.status if status.name == "helireach_planner: planner"
        ]
        assert int(rm.status_values(reports[-1])["replans_skipped_no_rotor"]) > 0
        assert reports[-1].level == DiagnosticStatus.WARN
        assert "re-planning paused: no measured rotor speed" in reports[-1].message
    finally:
        harness.close()


def test_two_flag_publishers_that_disagree_are_reported(context: Context) -> None:
    harness = Harness(context, VehicleMonitor(context=context))
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS)
    second = harness.nodes[0].create_publisher(Bool, rm.TOPIC_ENGINE_FAILURE, rm.EVENT_QOS)
    try:
        def two_voices(_: float) -> None:  # one vehicle bridge says failed, another says normal
            harness.publish_state(HEIGHT, SPEED)
            harness.failure.publish(Bool(data=True))
            second.publish(Bool(data=False))

        run_for(harness, 2.5, two_voices, 0.04)
        report = monitor_reports(diagnostics)[-1]
        values = rm.status_values(report)
        assert values["failure_flag_publishers"] == "2" and report.level == DiagnosticStatus.WARN
        assert f"2 publishers on {rm.TOPIC_ENGINE_FAILURE} disagree" in report.message
        assert values["failure_episode"] == "failed"  # conservatively: the true one counts
    finally:
        harness.close()
