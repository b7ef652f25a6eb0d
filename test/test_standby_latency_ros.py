"""Failure → standby trajectory on the wire, in the composed system with real rclpy.

What is tested is what the failure callback publishes, never how long it takes (the milliseconds are measured
by ``bench/failure_latency.py``): a failure gives the verified standby plan, published as the very messages built
when its verdict came (``helireach_ros/ros/plan_messages.py``), then the refined plan; shutdown is clean and the
log holds both trajectories.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.mcap_log import read_log
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.bringup import HelireachSystem, build_system

LEVEL = (500 * FT, 75 * KT)  # a safe level state: the live verdict there is a standby
TIMEOUT_S = 20.0


class Vehicle:
    """A vehicle interface: streams a level state, raises the flag, takes trajectories."""

    def __init__(self, system: HelireachSystem) -> None:
        self.node = Node("test_vehicle", context=system.context)
        self.odometry = self.node.create_publisher(Odometry, rm.TOPIC_ODOMETRY, rm.STREAM_QOS)
        self.rotor = self.node.create_publisher(JointState, rm.TOPIC_ROTOR, rm.STREAM_QOS)
        self.flag = self.node.create_publisher(Bool, rm.TOPIC_ENGINE_FAILURE, rm.EVENT_QOS)
        self.trajectories: list[JointTrajectory] = []
        self.statuses: list[dict[str, str]] = []
        self.live: list[dict[str, str]] = []
        self.node.create_subscription(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, self.trajectories.append, 10)
        self.node.create_subscription(
            DiagnosticStatus, rm.TOPIC_PLAN_STATUS, lambda m: self.statuses.append(rm.status_values(m)), 10
        )
        self.node.create_subscription(
            DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY, lambda m: self.live.append(rm.status_values(m)), 10
        )
        system.executor.add_node(self.node)

    def stream(self, system: HelireachSystem, until: Callable[[], bool], engine_failed: bool = False) -> bool:
        """Publishes the state and the flag every 20 ms while the main thread spins ``system``."""
        deadline = time.monotonic() + TIMEOUT_S
        while not until() and time.monotonic() < deadline:
            stamp = self.node.get_clock().now().nanoseconds
            self.odometry.publish(rm.odometry_message(stamp, LEVEL[0], 0.0, LEVEL[1], 0.0))
            self.rotor.publish(rm.rotor_message(stamp, 27.0))
            self.flag.publish(Bool(data=engine_failed))
            system.spin_until(lambda: False, 0.02, step_s=0.005)
        return until()


def _record_published(monkeypatch, planner: Any, name: str) -> list[tuple[Any, Any]]:
    """Each message the planner's publisher ``name`` publishes, with the planner's prebuilt standby messages then."""
    publisher = getattr(planner, name)
    published: list[tuple[Any, Any]] = []
    publish = publisher.publish

    def recording(message: Any) -> None:
        published.append((message, planner.live.standby_messages))
        publish(message)

    monkeypatch.setattr(publisher, "publish", recording)
    return published


def test_a_failure_in_the_composed_system_gives_the_prebuilt_standby_then_the_refined_plan(
    no_ros_discovery, tmp_path, monkeypatch
) -> None:
    system = build_system(
        log_dir=tmp_path,
        context=Context(),
        ros_args=["-p", "helireach_planner:replan_period:=0.0", "-p", "helireach_planner:standby_max_age:=5.0"],
    )
    vehicle = Vehicle(system)
    planner = system.planner
    trajectories = _record_published(monkeypatch, planner, "_trajectory_publisher")
    paths = _record_published(monkeypatch, planner, "_path_publisher")
    try:
        assert vehicle.stream(system, lambda: any(values["standby"] == "true" for values in vehicle.live))
        assert planner.live.standby_messages is not None  # built when the standby verdict came, before any failure
        assert not trajectories and not paths
        assert vehicle.stream(system, lambda: len(vehicle.statuses) >= 2, engine_failed=True), vehicle.statuses
        first, refined = vehicle.statuses[0], vehicle.statuses[1]
        assert (first["standby"], first["status"], first["verified"]) == ("true", "safe", "true")
        assert (refined["standby"], refined["fallback"]) == ("false", "false")
        supervisor = planner.supervisor
        assert [supervisor.is_standby(record) for record in supervisor.published_plans[:2]] == [True, False]
        # the standby went out as the very messages built beforehand (the failure callback only published them)
        (trajectory, prebuilt), (path, prebuilt_then) = trajectories[0], paths[0]
        assert prebuilt is not None and prebuilt_then is prebuilt
        assert trajectory is prebuilt.trajectory_cdr and path is prebuilt.path_cdr
        standby_record = planner.supervisor.published_plans[0]
        assert prebuilt.matches(standby_record.plan, standby_record.stamp_ns, prebuilt.frame, prebuilt.world_frame)
        assert int(first["state_stamp_ns"]) == prebuilt.stamp_ns
        assert vehicle.trajectories[0] == prebuilt.trajectory
        # the refined plan's messages are built for it
        refined_trajectory = deserialize_message(trajectories[1][0], JointTrajectory)
        assert trajectories[1][0] is not prebuilt.trajectory_cdr and vehicle.trajectories[1] == refined_trajectory
        system.drain()  # the recorder's copies still queued (as `helireach bringup` does before shutting down)
    finally:
        system.shutdown()
        vehicle.node.destroy_node()
    logged = [message for message in read_log(system.log_path) if message.topic == rm.TOPIC_LANDING_TRAJECTORY]
    assert [deserialize_message(message.cdr, JointTrajectory) for message in logged[:2]] == vehicle.trajectories[:2]
