"""The input contract with real rclpy: QoS kinds a vehicle may publish with, incompatible QoS, frames, stamp order.

Same set-up as ``test_ros_nodes.py`` (its harness: one context per test, discovery off, spin until a condition).
"""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header
from test_ros_nodes import OMEGA0, TIMEOUT_S, Harness, level_is
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
from helireach_ros.core.policies.vehicle_readings import OdometryReading
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode, evaluate_safety
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode

BEST_EFFORT = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
"""What many vehicle drivers publish with (the sensor-data profile)."""
S = 1_000_000_000


def statuses_named(diagnostics: list[DiagnosticArray], name: str) -> list[DiagnosticStatus]:
    return [status for array in diagnostics for status in array.status if status.name == name]


def until_latest(diagnostics: list[DiagnosticArray], name: str, check: Callable[[DiagnosticStatus], bool]):
    return lambda: bool(statuses_named(diagnostics, name)) and check(statuses_named(diagnostics, name)[-1])


def test_a_best_effort_failure_flag_gives_a_failure_event_and_a_plan(context: Context) -> None:
    planner = LandingPlannerNode(context=context, parameter_overrides=[Parameter("replan_period", value=0.0)])
    harness = Harness(context, VehicleMonitor(context=context), planner)
    flag = harness.probe.create_publisher(Bool, rm.TOPIC_ENGINE_FAILURE, BEST_EFFORT)
    odometry = harness.probe.create_publisher(Odometry, rm.TOPIC_ODOMETRY, BEST_EFFORT)
    events = harness.listen(Header, rm.TOPIC_FAILURE_EVENT, rm.EVENT_QOS)
    trajectories = harness.listen(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
    try:

        def drive(engine_failed: bool, until: Callable[[], bool]) -> bool:
            """A best-effort driver: state, rotor and flag every 20 ms."""
            deadline = time.monotonic() + TIMEOUT_S
            while not until() and time.monotonic() < deadline:
                stamp = harness.now_ns()
                odometry.publish(rm.odometry_message(stamp, 500 * FT, 0.0, 75 * KT, 0.0))
                harness.rotor.publish(rm.rotor_message(stamp, OMEGA0))
                flag.publish(Bool(data=engine_failed))
                harness.spin_until(lambda: False, 0.02)
            return until()

        assert drive(False, lambda: planner.current_state() is not None)
        assert drive(True, lambda: bool(events) and bool(trajectories)), "a best-effort flag was not heard"
        assert len(events) == 1
    finally:
        harness.close()


def test_an_incompatible_input_is_an_error_on_diagnostics_and_in_the_safety_status(context: Context) -> None:
    planner = LandingPlannerNode(
        context=context,
        parameter_overrides=[Parameter("replan_period", value=0.0), Parameter("warm_up", value=False)],
    )
    harness = Harness(context, VehicleMonitor(context=context), EnvelopeStatusNode(context=context), planner)
    safety = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, BEST_EFFORT)
    qos_status = "helireach_planner: QoS"
    try:
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(safety, DiagnosticStatus.OK))
        assert harness.spin_until(until_latest(diagnostics, qos_status, lambda s: s.level == DiagnosticStatus.OK))
        # A replacement monitor publishing its failure events best effort: the planner's RELIABLE input cannot
        # hear it (one event per failure must not be lost), so that must be loud, not silent.
        incompatible = harness.probe.create_publisher(Header, rm.TOPIC_FAILURE_EVENT, BEST_EFFORT)
        assert harness.keep_publishing(
            500 * FT, 75 * KT, until=until_latest(diagnostics, qos_status, lambda s: s.level == DiagnosticStatus.ERROR)
        )
        report = statuses_named(diagnostics, qos_status)[-1]
        assert rm.TOPIC_FAILURE_EVENT in report.message and "RELIABILITY" in report.message
        assert rm.TOPIC_FAILURE_EVENT in rm.status_values(report)["input_problems"]
        # The safety status is ERROR too, whatever the envelope says here (500 ft, 75 kt is safe).
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(safety, DiagnosticStatus.ERROR))
        assert safety[-1].message.startswith("INPUT QOS")
        assert "helireach_planner" in safety[-1].message and rm.TOPIC_FAILURE_EVENT in safety[-1].message
        assert "RELIABILITY" in safety[-1].message
        # While that publisher exists the problem stays, past the 2 s hold (the graph still lists it).
        seen_reports, seen_safety = len(statuses_named(diagnostics, qos_status)), len(safety)
        held_until = time.monotonic() + 3.0
        harness.keep_publishing(500 * FT, 75 * KT, until=lambda: time.monotonic() > held_until)
        later_reports = statuses_named(diagnostics, qos_status)[seen_reports:]
        assert len(later_reports) >= 2 and {s.level for s in later_reports} == {DiagnosticStatus.ERROR}
        assert {s.level for s in safety[seen_safety:]} == {DiagnosticStatus.ERROR}
        # The incompatible publisher gone, both recover (after the hold time).
        harness.probe.destroy_publisher(incompatible)
        assert harness.keep_publishing(
            500 * FT, 75 * KT, until=until_latest(diagnostics, qos_status, lambda s: s.level == DiagnosticStatus.OK)
        )
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(safety, DiagnosticStatus.OK))
    finally:
        harness.close()


def test_an_output_subscriber_requesting_more_is_an_error_on_diagnostics_only(context: Context) -> None:
    harness = Harness(context, VehicleMonitor(context=context), EnvelopeStatusNode(context=context))
    safety = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, BEST_EFFORT)
    qos_status = "helireach_monitor: QoS"
    try:
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(safety, DiagnosticStatus.OK))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # /helireach/state is volatile
        harness.probe.create_subscription(Odometry, rm.TOPIC_STATE, lambda message: None, latched)
        assert harness.keep_publishing(
            500 * FT, 75 * KT, until=until_latest(diagnostics, qos_status, lambda s: s.level == DiagnosticStatus.ERROR)
        )
        report = statuses_named(diagnostics, qos_status)[-1]
        assert rm.TOPIC_STATE in report.message and "DURABILITY" in report.message
        assert rm.status_values(report)["input_problems"] == ""
        # That subscriber gets nothing, but the helireach inputs are fine: the safety status stays the envelope's.
        assert safety[-1].level == DiagnosticStatus.OK, safety[-1].message
    finally:
        harness.close()


def test_wrong_frames_are_rejected_naming_the_frames_and_the_expected_frames_are_parameters(context: Context) -> None:
    monitor = VehicleMonitor(context=context)
    harness = Harness(context, monitor)
    states = harness.listen(Odometry, rm.TOPIC_STATE, BEST_EFFORT)
    try:

        def publish_wrong_frames_until(condition: Callable[[], bool]) -> bool:
            deadline = time.monotonic() + TIMEOUT_S
            while not condition() and time.monotonic() < deadline:
                stamp = harness.now_ns()
                message = rm.odometry_message(stamp, 150.0, 0.0, 38.0, 0.0, 0.0, "map_ned", "base_link_frd")
                harness.odometry.publish(message)
                harness.spin_until(lambda: False, 0.02)
            return condition()

        count = lambda node, key: int(rm.status_values(node.diagnostic()).get(key, "0"))  # noqa: E731
        assert publish_wrong_frames_until(lambda: count(monitor, "odometry_rejected") >= 3)
        assert count(monitor, "odometry_wrong_frame") == count(monitor, "odometry_rejected")
        status = monitor.diagnostic()
        assert status.level == DiagnosticStatus.STALE  # no valid state at all
        assert "frame_id 'map_ned' is not the expected 'odom'" in status.message
        assert "child_frame_id 'base_link_frd' is not the expected 'base_stabilized'" in status.message
        assert rm.status_values(status)["odometry_valid"] == "0" and not states
        # A monitor told the vehicle's frames (parameters) takes them.
        harness.executor.remove_node(monitor)
        configured = VehicleMonitor(
            context=context,
            parameter_overrides=[
                Parameter("world_frame", value="map_ned"),
                Parameter("body_frame", value="base_link_frd"),
            ],
        )
        harness.nodes.append(configured)
        harness.executor.add_node(configured)
        assert publish_wrong_frames_until(lambda: bool(states))
        assert count(configured, "odometry_wrong_frame") == 0 and states[-1].header.frame_id == "map_ned"
    finally:
        harness.close()


def test_out_of_order_stamps_are_dropped_counted_and_the_state_never_goes_backwards(context: Context) -> None:
    # A long stale timeout: the WARN about the drops lasts that long, so its check does not race the clock.
    monitor = VehicleMonitor(context=context, parameter_overrides=[Parameter("stale_timeout", value=30.0)])
    harness = Harness(context, monitor)
    states = harness.listen(Odometry, rm.TOPIC_STATE, BEST_EFFORT)
    try:
        start = harness.now_ns()

        def handled(n: int) -> bool:
            """The monitor has decided on ``n`` odometry and ``n`` rotor messages."""
            values = rm.status_values(monitor.diagnostic())
            kinds = ("odometry", "rotor")
            return all(int(values[f"{kind}_valid"]) + int(values.get(f"{kind}_out_of_order", 0)) == n for kind in kinds)

        offsets = [0.0, -0.1, 0.0, 0.05, 0.02, 0.1]  # older, equal, newer, older, newer
        for index, offset in enumerate(offsets):
            harness.publish_state(150.0 + index, 38.0, stamp_ns=start + round(offset * S))
            # One message at a time, so the order the monitor sees is the order sent.
            assert harness.spin_until(lambda n=index + 1: handled(n)), index
        assert harness.spin_until(lambda: len(states) == 3)
        stamps = [rm.stamp_nanoseconds(state.header.stamp) for state in states]
        assert stamps == [start, start + round(0.05 * S), start + round(0.1 * S)]
        assert [state.pose.pose.position.z for state in states] == [150.0, 153.0, 155.0]
        values = rm.status_values(monitor.diagnostic())
        assert (values["odometry_valid"], values["odometry_out_of_order"]) == ("3", "3")
        assert (values["rotor_valid"], values["rotor_out_of_order"]) == ("3", "3")
        assert "older than the latest accepted" in values["last_out_of_order"]
        status = monitor.diagnostic()
        assert status.level == DiagnosticStatus.WARN and "dropped" in status.message
    finally:
        harness.close()


def test_input_problems_override_a_safe_envelope_answer() -> None:
    """The pure verdict: never SAFE with an input problem; the envelope's answer is kept in the text and values."""
    envelope = load_envelope(default_envelope_path())
    reading = OdometryReading(0, 500 * FT, 0.0, 75 * KT, 0.0)
    omega = float(envelope.metadata["airframe"]["nominal_rotor_speed"])  # measured: the envelope's domain
    safe = evaluate_safety(envelope, reading, 0.0, 0.5, 20.0, rotor_speed=omega)
    assert safe.level == DiagnosticStatus.OK
    problem = "helireach_planner: /helireach/failure_event: a publisher offers incompatible RELIABILITY"
    verdict = evaluate_safety(envelope, reading, 0.0, 0.5, 20.0, input_problems=[problem], rotor_speed=omega)
    assert verdict.level == DiagnosticStatus.ERROR
    assert verdict.message.startswith("INPUT QOS") and problem in verdict.message and safe.message in verdict.message
    assert verdict.values["input_qos_problems"] == problem
    assert verdict.values["envelope_status"] == "safe"


def test_a_reported_input_problem_counts_until_its_report_is_older_than_the_timeout(context: Context) -> None:
    status = EnvelopeStatusNode(context=context, parameter_overrides=[Parameter("qos_report_timeout", value=1.0)])
    harness = Harness(context, VehicleMonitor(context=context), status)
    safety = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    reporter = harness.probe.create_publisher(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS)
    report = rm.diagnostic_status(
        DiagnosticStatus.ERROR,
        "vehicle_bridge: QoS",
        "/bridge/in: a publisher offers incompatible DURABILITY",
        "helireach",
        {"input_problems": "/bridge/in: a publisher offers incompatible DURABILITY"},
    )
    try:
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(safety, DiagnosticStatus.OK))
        reporter.publish(rm.diagnostic_array(harness.now_ns(), report))  # once: then the reporter falls silent
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(safety, DiagnosticStatus.ERROR))
        assert "vehicle_bridge: /bridge/in" in safety[-1].message and "DURABILITY" in safety[-1].message
        reported_at = time.monotonic()
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(safety, DiagnosticStatus.OK))
        assert time.monotonic() - reported_at >= 0.9  # not before qos_report_timeout (1 s)
    finally:
        harness.close()


def test_oversized_vehicle_messages_are_rejected_unread_and_counted_beside_valid_ones(context: Context) -> None:
    """A stream of 1.7 MB JointStates beside the vehicle's rotor readings: each is refused by its size before it is
    read (counted, an ERROR naming the bound), and every valid reading beside it is still used."""
    monitor = VehicleMonitor(context=context)
    harness = Harness(context, monitor)
    flood = harness.probe.create_publisher(JointState, rm.TOPIC_ROTOR, BEST_EFFORT)
    oversized = JointState(name=[f"joint_{index:06d}" for index in range(100_000)])  # ~1.7 MB of names
    oversized.velocity = array("d", [OMEGA0]) * 100_000
    try:
        rounds = 20
        for index in range(rounds):
            flood.publish(oversized)
            flood.publish(oversized)
            harness.publish_state(150.0, 38.0)

            def handled(n: int = index + 1) -> bool:
                values = rm.status_values(monitor.diagnostic())
                return int(values["rotor_valid"]) == n and int(values["rotor_oversized"]) == 2 * n

            assert harness.spin_until(handled), rm.status_values(monitor.diagnostic())
        status = monitor.diagnostic()
        values = rm.status_values(status)
        assert values["rotor_rejected"] == str(2 * rounds) and values["odometry_oversized"] == "0"
        assert status.level == DiagnosticStatus.ERROR and "exceeds max_input_bytes 65536" in status.message
    finally:
        harness.close()
