"""The helireach nodes in one process with real rclpy: topic contract, status transitions, failure → plan, bad input.

Each test has its own ``rclpy.Context`` (discovery OFF: same-process delivery only) and spins until a
condition holds, with a timeout.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure, trim_controls
from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.bringup import build_system
from helireach_ros.ros.executors import DEFAULT_EXECUTOR, EXECUTOR_KINDS, create_executor
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode
from helireach_ros.ros.parameters import ParameterError

TIMEOUT_S = 10.0
OMEGA0 = 27.0  # uh60a_class nominal rotor speed, rad/s (only used as a plausible measured value)


@pytest.fixture(scope="module")
def envelope():
    return load_envelope(default_envelope_path())


class Harness:
    """Nodes under test plus a probe node that publishes vehicle input and records everything."""

    def __init__(self, context: Context, *nodes: Node, executor: str = DEFAULT_EXECUTOR) -> None:
        self.context = context
        self.nodes = list(nodes)
        self.probe = Node("test_probe", context=context)
        self.executor = create_executor(executor, context)
        for node in [*self.nodes, self.probe]:
            self.executor.add_node(node)
        self.received: dict[str, list[Any]] = {}
        self.odometry = self.probe.create_publisher(Odometry, rm.TOPIC_ODOMETRY, rm.STREAM_QOS)
        self.rotor = self.probe.create_publisher(JointState, rm.TOPIC_ROTOR, rm.STREAM_QOS)
        self.failure = self.probe.create_publisher(Bool, rm.TOPIC_ENGINE_FAILURE, rm.EVENT_QOS)

    def listen(self, message_type: type, topic: str, qos=rm.LATCHED_QOS) -> list[Any]:
        messages = self.received.setdefault(topic, [])
        self.probe.create_subscription(message_type, topic, messages.append, qos)
        return messages

    def spin_until(self, condition: Callable[[], bool], timeout_s: float = TIMEOUT_S) -> bool:
        deadline = time.monotonic() + timeout_s
        while not condition() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)
        return condition()

    def now_ns(self) -> int:
        return self.probe.get_clock().now().nanoseconds

    def publish_state(
        self,
        height: float,
        speed: float,
        climb_rate: float = 0.0,
        rotor_speed: float = OMEGA0,
        stamp_ns: int | None = None,
    ) -> int:
        stamp = self.now_ns() if stamp_ns is None else stamp_ns
        self.odometry.publish(rm.odometry_message(stamp, height, 0.0, speed, climb_rate))
        self.rotor.publish(rm.rotor_message(stamp, rotor_speed))
        return stamp

    def keep_publishing(self, height: float, speed: float, until: Callable[[], bool], **kwargs: Any) -> bool:
        """Publishes a state every 20 ms while spinning, until the condition holds."""
        deadline = time.monotonic() + TIMEOUT_S
        while not until() and time.monotonic() < deadline:
            self.publish_state(height, speed, **kwargs)
            self.spin_until(lambda: False, 0.02)
        return until()

    def close(self) -> None:
        for node in [*self.nodes, self.probe]:
            self.executor.remove_node(node)
        self.executor.shutdown(timeout_sec=2.0)
        for node in [*self.nodes, self.probe]:
            node.destroy_node()


def monitor_and_planner(
    context: Context, monitor_parameters: dict | None = None, **planner_parameters: object
) -> tuple[Harness, LandingPlannerNode]:
    """A harness with a monitor and a planner, each with the given parameter overrides; and the planner."""
    monitor = VehicleMonitor(
        context=context,
        parameter_overrides=[Parameter(name, value=value) for name, value in (monitor_parameters or {}).items()],
    )
    planner = LandingPlannerNode(
        context=context,
        parameter_overrides=[Parameter(name, value=value) for name, value in planner_parameters.items()],
    )
    return Harness(context, monitor, planner), planner


def latest_level(messages: list[DiagnosticStatus]) -> bytes | None:
    return messages[-1].level if messages else None


def level_is(messages: list[DiagnosticStatus], level: bytes) -> Callable[[], bool]:
    return lambda: latest_level(messages) == level


def find_state(envelope, predicate: Callable[[Any], bool]) -> tuple[float, float]:
    """A grid-aligned (height m, speed m/s) whose envelope answer satisfies ``predicate``."""
    for height_ft in range(0, 801, 10):
        for speed_kt in range(0, 121, 5):
            query = envelope.query(height_ft * FT, speed_kt * KT)
            if predicate(query):
                return height_ft * FT, speed_kt * KT
    raise AssertionError("no such state in the envelope")


# --- topic contract -----------------------------------------------------------------------------------------
def test_every_topic_has_its_documented_type_and_qos(no_ros_discovery) -> None:
    system = build_system(with_sim=True, record=False, context=Context())
    try:
        probe = system.monitor
        for spec in rm.TOPICS.values():
            assert system.spin_until(lambda spec=spec: bool(probe.get_publishers_info_by_topic(spec.name)), TIMEOUT_S)
            publishers = probe.get_publishers_info_by_topic(spec.name)
            assert {info.topic_type for info in publishers} == {spec.type_name}, spec.name
            for info in publishers:
                assert info.qos_profile.reliability == spec.qos.reliability, spec.name
                assert info.qos_profile.durability == spec.qos.durability, spec.name
        latched = [spec.name for spec in rm.TOPICS.values() if spec.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL]
        assert set(latched) == {
            rm.TOPIC_SAFETY_STATUS,
            rm.TOPIC_FAILURE_EPISODE,
            rm.TOPIC_LIVE_REACHABILITY,
            rm.TOPIC_REACHABLE_FOOTPRINT,
            rm.TOPIC_LANDING_SITES,
            rm.TOPIC_LANDING_TRAJECTORY,
            rm.TOPIC_LANDING_PATH,
            rm.TOPIC_PLAN_STATUS,
            rm.TOPIC_ROBUST_VERDICT,
            rm.TOPIC_TOUCHDOWN,
            rm.TOPIC_READY,
        }
        # Every helireach node reports on /diagnostics.
        reporters: set[str] = set()
        probe.create_subscription(
            DiagnosticArray,
            rm.TOPIC_DIAGNOSTICS,
            lambda array: reporters.update(status.name.split(":")[0] for status in array.status),
            rm.STREAM_QOS,
        )
        names = {"helireach_monitor", "helireach_envelope_status", "helireach_planner", "helireach_sim_vehicle"}
        assert system.spin_until(lambda: names <= reporters, TIMEOUT_S), reporters
    finally:
        system.shutdown()


def test_safety_status_is_latched_for_late_subscribers(context: Context) -> None:
    status = EnvelopeStatusNode(context=context)
    harness = Harness(context, VehicleMonitor(context=context), status)
    try:
        assert harness.keep_publishing(
            500 * FT, 75 * KT, until=lambda: status.verdict is not None and status.verdict.level == DiagnosticStatus.OK
        )
        late = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)  # joins after the publication
        assert harness.spin_until(lambda: bool(late), 2.0)
        assert late[0].level == DiagnosticStatus.OK
        values = rm.status_values(late[0])
        assert values["envelope_id"] == status.envelope.envelope_id
        assert math.isclose(float(values["height_m"]), 500 * FT)
        assert float(values["margin_ft_kt"]) >= float(values["warn_margin_ft_kt"])
    finally:
        harness.close()


# --- status transitions and bad input -------------------------------------------------------------------------
def test_status_goes_safe_warn_unsafe_stale(context: Context, envelope) -> None:
    harness = Harness(context, VehicleMonitor(context=context), EnvelopeStatusNode(context=context))
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        warn_margin = 20.0
        safe = find_state(envelope, lambda q: q.status == "safe" and q.margin >= 2 * warn_margin)
        near = find_state(envelope, lambda q: q.status == "safe" and 0.0 < q.margin < warn_margin / 2)
        unsafe = find_state(envelope, lambda q: q.status == "unsafe" and q.margin < -10.0)
        for state, level in (
            (safe, DiagnosticStatus.OK),
            (near, DiagnosticStatus.WARN),
            (unsafe, DiagnosticStatus.ERROR),
        ):
            assert harness.keep_publishing(*state, until=level_is(statuses, level)), (state, statuses[-1])
        assert "AVOID" in statuses[-1].message
        # No more state: STALE within the stale timeout (published on change and at the steady rate).
        assert harness.spin_until(level_is(statuses, DiagnosticStatus.STALE))
        assert "NO DATA" in statuses[-1].message
    finally:
        harness.close()


@pytest.mark.parametrize(
    ("description", "height", "speed", "stamp_offset_s", "expected_level"),
    [
        ("NaN height", math.nan, 75 * KT, 0.0, DiagnosticStatus.STALE),
        ("infinite speed", 500 * FT, math.inf, 0.0, DiagnosticStatus.STALE),
        ("negative height", -50.0, 75 * KT, 0.0, DiagnosticStatus.STALE),
        ("stale stamp", 500 * FT, 75 * KT, -30.0, DiagnosticStatus.STALE),
        ("out of grid", 2000 * FT, 75 * KT, 0.0, DiagnosticStatus.ERROR),
    ],
)
def test_bad_input_gives_the_documented_status_and_nodes_keep_running(
    context: Context, description: str, height: float, speed: float, stamp_offset_s: float, expected_level: bytes
) -> None:
    monitor = VehicleMonitor(context=context)
    harness = Harness(context, monitor, EnvelopeStatusNode(context=context))
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS)
    try:
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.OK))

        def bad_until(condition: Callable[[], bool]) -> bool:
            deadline = time.monotonic() + TIMEOUT_S
            while not condition() and time.monotonic() < deadline:
                harness.publish_state(height, speed, stamp_ns=harness.now_ns() + int(stamp_offset_s * 1e9))
                harness.spin_until(lambda: False, 0.02)
            return condition()

        assert bad_until(level_is(statuses, expected_level)), (description, statuses[-1])
        if expected_level == DiagnosticStatus.ERROR:
            assert "outside the envelope grid" in statuses[-1].message
            assert rm.status_values(statuses[-1])["envelope_status"] == "outside"
        else:  # rejected by the monitor, which says why on /diagnostics
            reports = lambda: [s for array in diagnostics for s in array.status if "monitor" in s.name]  # noqa: E731
            assert bad_until(lambda: any("rejected" in s.message for s in reports())), description
        # The nodes still work: a valid state is SAFE again.
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.OK))
    finally:
        harness.close()


def test_missing_envelope_file_gives_stale_and_a_valid_file_recovers(context: Context, tmp_path) -> None:
    status = EnvelopeStatusNode(
        context=context, parameter_overrides=[Parameter("envelope_file", value=str(tmp_path / "missing.npz"))]
    )
    harness = Harness(context, VehicleMonitor(context=context), status)
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.STALE))
        assert "no envelope" in statuses[-1].message and "missing.npz" in statuses[-1].message
        corrupt = tmp_path / "corrupt.npz"
        corrupt.write_bytes(b"not an envelope")
        status.set_parameters([Parameter("envelope_file", value=str(corrupt))])
        assert harness.keep_publishing(500 * FT, 75 * KT, until=lambda: "corrupt.npz" in statuses[-1].message)
        assert statuses[-1].level == DiagnosticStatus.STALE
        status.set_parameters([Parameter("envelope_file", value=str(default_envelope_path()))])
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.OK))
    finally:
        harness.close()


def test_broken_parameter_stops_the_node_naming_it_and_its_range(context: Context) -> None:
    """A default the operator did not ask for would be silently wrong (test_parameters.py has the details)."""
    with pytest.raises(ParameterError, match=r"'stale_timeout' of helireach_monitor = -3\.0 .*\[0\.01, 60\]"):
        VehicleMonitor(context=context, parameter_overrides=[Parameter("stale_timeout", value=-3.0)])


# --- failure → plan -------------------------------------------------------------------------------------------
def planner_harness(
    context: Context, *overrides: Parameter, executor: str = DEFAULT_EXECUTOR
) -> tuple[Harness, LandingPlannerNode]:
    planner = LandingPlannerNode(context=context, parameter_overrides=list(overrides))
    return Harness(context, VehicleMonitor(context=context), planner, executor=executor), planner


def trigger_failure(harness: Harness, height: float, speed: float) -> int:
    """Publishes the state (until the planner has it), then the failure flag's rising edge; returns the stamp."""
    planner = next(node for node in harness.nodes if isinstance(node, LandingPlannerNode))
    assert harness.keep_publishing(height, speed, until=lambda: planner.current_state() is not None)
    stamp = harness.publish_state(height, speed)
    assert harness.spin_until(lambda: planner.current_state() is not None and planner.current_state()[1] == stamp)
    harness.failure.publish(Bool(data=False))
    harness.failure.publish(Bool(data=True))
    return stamp


@pytest.mark.parametrize("executor", EXECUTOR_KINDS)
def test_failure_publishes_a_verified_trajectory_path_and_status(context: Context, executor: str) -> None:
    harness, _ = planner_harness(context, Parameter("replan_period", value=0.0), executor=executor)
    trajectories = harness.listen(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
    paths = harness.listen(PathMsg, rm.TOPIC_LANDING_PATH)
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    events = harness.listen(Header, rm.TOPIC_FAILURE_EVENT, rm.EVENT_QOS)
    try:
        stamp = trigger_failure(harness, 500 * FT, 75 * KT)
        # on a loaded machine the deadline's fallback may go out first: wait for the converged plan's status
        converged = lambda: plan_statuses and rm.status_values(plan_statuses[-1])["fallback"] == "false"  # noqa: E731
        assert harness.spin_until(lambda: trajectories and paths and converged())
        assert len(events) == 1
        trajectory = trajectories[-1]
        assert list(trajectory.joint_names) == [rm.COLLECTIVE_JOINT, rm.PITCH_JOINT]
        assert rm.stamp_nanoseconds(trajectory.header.stamp) == stamp
        _, times, values = rm.read_trajectory(trajectory)
        assert np.all(np.diff(times) > 0) and times[0] == 0.0
        status = plan_statuses[-1]
        fields = rm.status_values(status)
        assert status.level == DiagnosticStatus.OK, status.message
        assert (fields["status"], fields["safe"], fields["verified"], fields["fallback"]) == (
            "safe",
            "true",
            "true",
            "false",
        )
        assert fields["warm_start"] == "envelope"
        assert (fields["method"], fields["flyable"], fields["flyability_violations"]) == ("flyable", "true", "")
        # the first plan starts from the trim flown before the failure (what `replay --compare` re-runs it from)
        uh60 = load_airframe("uh60a_class")
        trim = trim_controls(uh60, initial_state_after_failure(uh60, 500 * FT, 75 * KT).as_array())
        assert float(fields["initial_thrust_coefficient"]) == pytest.approx(trim[0], rel=1e-3)
        assert math.isclose(float(fields["time_to_land_s"]), times[-1], rel_tol=1e-6)
        assert math.isclose(float(fields["initial_height_m"]), 500 * FT)
        # The flyable plan's controls are continuous and rate-limited: one point per breakpoint, no steps.
        airframe = load_airframe("uh60a_class")
        slopes = np.abs(np.diff(values, axis=1)) / np.diff(times)
        assert np.all(np.diff(times) > 1e-3)
        assert slopes[0].max() <= airframe.max_thrust_coefficient_rate * (1 + 1e-6)
        assert slopes[1].max() <= airframe.flyability.max_pitch_rate * (1 + 1e-6)
        path = paths[-1]
        assert len(path.poses) > 2 and math.isclose(path.poses[0].pose.position.z, 500 * FT, rel_tol=1e-9)
        assert abs(path.poses[-1].pose.position.z) <= 1.0 * FT
        # A second rising edge is a new failure, a steady flag is not.
        harness.failure.publish(Bool(data=True))
        assert not harness.spin_until(lambda: len(events) > 1, 0.5)
    finally:
        harness.close()


@pytest.mark.parametrize("executor", EXECUTOR_KINDS)
def test_missed_deadline_publishes_a_flagged_fallback_then_the_plan(context: Context, executor: str) -> None:
    """The solve runs on the planner's own thread, so even one executor thread publishes the fallback meanwhile."""
    harness, _ = planner_harness(
        context, Parameter("deadline", value=0.001), Parameter("replan_period", value=0.0), executor=executor
    )
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    trajectories = harness.listen(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
    try:
        trigger_failure(harness, 500 * FT, 75 * KT)
        assert harness.spin_until(lambda: len(plan_statuses) >= 2 and len(trajectories) >= 2)
        first, second = (rm.status_values(status) for status in plan_statuses[:2])
        assert (first["fallback"], first["safe"], first["fallback_kind"]) == ("true", "false", "envelope_plan")
        assert plan_statuses[0].level == DiagnosticStatus.WARN and "FALLBACK" in plan_statuses[0].message
        assert (second["fallback"], second["status"], second["late"]) == ("false", "safe", "true")
    finally:
        harness.close()


def test_without_envelope_the_fallback_is_an_autorotation_entry(context: Context) -> None:
    harness, planner = planner_harness(
        context,
        Parameter("envelope_file", value="none"),
        Parameter("deadline", value=0.001),
        Parameter("replan_period", value=0.0),
    )
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    try:
        assert planner.envelope is None
        trigger_failure(harness, 500 * FT, 75 * KT)
        assert harness.spin_until(lambda: len(plan_statuses) >= 2)
        first, second = (rm.status_values(status) for status in plan_statuses[:2])
        assert (first["fallback"], first["fallback_kind"]) == ("true", "autorotation_entry")
        assert (second["fallback"], second["warm_start"]) == ("false", "none")  # a cold solve still converges
    finally:
        harness.close()


def test_failure_without_a_state_reports_no_plan_then_plans_when_a_state_arrives(context: Context) -> None:
    harness, _ = planner_harness(context, Parameter("replan_period", value=0.1))
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    trajectories = harness.listen(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
    try:
        harness.failure.publish(Bool(data=True))
        assert harness.spin_until(lambda: bool(plan_statuses))
        assert plan_statuses[0].level == DiagnosticStatus.ERROR and "NO PLAN" in plan_statuses[0].message
        planned = lambda: bool(trajectories) and rm.status_values(plan_statuses[-1]).get("status") == "safe"  # noqa: E731
        assert harness.keep_publishing(500 * FT, 75 * KT, until=planned)
    finally:
        harness.close()


def test_unsafe_state_gets_a_best_effort_plan_flagged_unsafe(context: Context, envelope) -> None:
    harness, _ = planner_harness(context, Parameter("replan_period", value=0.0))
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    try:
        height, speed = find_state(envelope, lambda q: q.status == "unsafe" and q.margin < -20.0)
        trigger_failure(harness, height, speed)
        assert harness.spin_until(
            lambda: bool(plan_statuses) and rm.status_values(plan_statuses[-1])["status"] != "fallback"
        )
        fields = rm.status_values(plan_statuses[-1])
        assert fields["safe"] == "false" and fields["status"] in ("unsafe", "unverified")
        assert plan_statuses[-1].level != DiagnosticStatus.OK
    finally:
        harness.close()


def test_a_rotor_below_its_limit_is_not_clipped_into_a_safe_plan(context: Context) -> None:
    """Noise a hair outside the rotor limits is clipped; a rotor truly below its limit is planned as measured."""
    harness, planner = planner_harness(context, Parameter("replan_period", value=0.0))
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    limit = planner.airframe.limits.min_rotor_speed_ratio * OMEGA0
    try:
        noisy = 0.998 * limit
        assert harness.keep_publishing(
            500 * FT,
            75 * KT,
            rotor_speed=noisy,
            until=lambda: (
                (planner.current_state() or [None])[0] is not None
                and planner.current_state()[3] == "measured"
                and math.isclose(planner.current_state()[0][2], limit)
            ),
        )
        slow = 0.80 * OMEGA0  # 5 % of Ω₀ below the limit: the energy the plan may count on is not there
        assert harness.keep_publishing(
            500 * FT,
            75 * KT,
            rotor_speed=slow,
            until=lambda: planner.current_state() is not None and math.isclose(planner.current_state()[0][2], slow),
        )
        harness.publish_state(500 * FT, 75 * KT, rotor_speed=slow)
        harness.failure.publish(Bool(data=False))
        harness.failure.publish(Bool(data=True))
        # No plan exists from there (the NLP fails; a flagged fallback goes out); whatever is published, none is safe.
        assert harness.spin_until(lambda: bool(plan_statuses))
        harness.spin_until(lambda: False, 1.0)
        for status in plan_statuses:
            assert rm.status_values(status)["safe"] == "false", status.message
            assert status.level != DiagnosticStatus.OK
        assert float(rm.status_values(plan_statuses[-1])["initial_rotor_speed_rad_s"]) == pytest.approx(slow)
    finally:
        harness.close()


def test_best_effort_vehicle_publishers_are_accepted(context: Context) -> None:
    """Sensor inputs are subscribed best-effort, so a best-effort vehicle driver connects too."""
    harness = Harness(context, VehicleMonitor(context=context))
    states = harness.listen(Odometry, rm.TOPIC_STATE, rm.STREAM_QOS)
    best_effort = harness.probe.create_publisher(Odometry, rm.TOPIC_ODOMETRY, rm.SENSOR_QOS)
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while not states and time.monotonic() < deadline:
            best_effort.publish(rm.odometry_message(harness.now_ns(), 100.0, 0.0, 30.0, 0.0))
            harness.spin_until(lambda: False, 0.02)
        assert states and math.isclose(states[-1].pose.pose.position.z, 100.0)
        subscriptions = harness.probe.get_subscriptions_info_by_topic(rm.TOPIC_ODOMETRY)
        assert subscriptions and all(s.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for s in subscriptions)
    finally:
        harness.close()


def test_an_unknown_executor_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="multi_threaded"):
        create_executor("multi_threaded")


def test_todays_weight_rebuilds_the_model_and_refuses_the_envelope_made_for_another(context: Context) -> None:
    # 5 % lighter: a landing from 500 ft / 75 kt exists (5 % heavier it does not: J = +0.003, the flare short of
    # rotor energy), so the rebuilt model's plan is SAFE; heavier, refused: the test below
    weight = 0.95 * load_airframe("uh60a_class").gross_weight
    harness, planner = planner_harness(
        context, Parameter("gross_weight", value=weight), Parameter("replan_period", value=0.0)
    )
    trajectories = harness.listen(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    try:
        assert planner.airframe.gross_weight == pytest.approx(weight)
        assert planner.envelope is None  # the shipped one was made for the file's weight
        trigger_failure(harness, 500 * FT, 75 * KT)
        assert harness.spin_until(lambda: trajectories and any(s.level == DiagnosticStatus.OK for s in plan_statuses))
        fields = rm.status_values(plan_statuses[-1])
        assert (fields["fallback"], fields["warm_start"]) == ("false", "none")
    finally:
        harness.close()


def test_the_status_node_refuses_an_envelope_made_for_another_weight(context: Context) -> None:
    """The shipped envelope is for the file's weight: 5 % heavier, its SAFE answers would be optimistic."""
    weight = 1.05 * load_airframe("uh60a_class").gross_weight
    status = EnvelopeStatusNode(context=context, parameter_overrides=[Parameter("gross_weight", value=weight)])
    harness = Harness(context, VehicleMonitor(context=context), status)
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        assert status.envelope is None and status.aircraft.gross_weight == pytest.approx(weight)
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.STALE))
        assert "no envelope" in statuses[-1].message and "W = 16800 lbf" in statuses[-1].message  # today's weight
    finally:
        harness.close()


def test_an_implausible_airframe_is_a_warning_on_the_planners_diagnostics(context: Context, tmp_path) -> None:
    """A unit slip the physical ranges let through (the radius in metres where the file says feet: 724 m/s tip
    speed) is not only a warning on stderr: the planner's /diagnostics say so while it runs."""
    import warnings

    import yaml

    from helireach_ros.core.aircraft.plausibility import AirframePlausibilityWarning
    from helireach_ros.core.resources import config_path

    document = yaml.safe_load(config_path("airframes/uh60a_class.yaml").read_text())
    document["parameters"]["rotor_radius"] = {"value": 26.83, "unit": "m", "source": "test: a unit slip"}
    path = tmp_path / "uh60a_radius_in_m.yaml"
    path.write_text(yaml.safe_dump(document))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AirframePlausibilityWarning)
        planner = LandingPlannerNode(
            context=context,
            parameter_overrides=[
                Parameter("airframe", value=str(path)), Parameter("solver_workers", value=0),
                Parameter("live_rate", value=0.0), Parameter("envelope_file", value="none"),
            ],
        )  # fmt: skip
    harness = Harness(context, planner)
    diagnostics = harness.listen(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS)
    try:
        planner_reports = lambda: [  # noqa: E731
            status for array in diagnostics for status in array.status if status.name == "helireach_planner: planner"
        ]
        assert harness.spin_until(lambda: bool(planner_reports()))
        report = planner_reports()[-1]
        assert report.level == DiagnosticStatus.WARN
        assert "implausible airframe: tip_speed = 724.4 m/s" in report.message
    finally:
        harness.close()
