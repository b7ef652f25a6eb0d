"""Across processes: ``helireach bringup`` in a child process, the vehicle in this one; SIGTERM ends a complete log.

Discovery is LOCALHOST on a domain id of the test's own (conftest); timeouts are generous (discovery takes
up to a few seconds here, and the child builds the NLP before it spins).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.mcap_log import read_log, read_log_topics
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm

pytestmark = [pytest.mark.system]

TIMEOUT_S = 40.0


def wait_for_line(process: subprocess.Popen, prefix: str, timeout_s: float) -> str:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if line.startswith(prefix):
            return line
        if not line and process.poll() is not None:
            break
    raise AssertionError(f"no line starting with {prefix!r} from the child (exit code {process.poll()})")


def test_nodes_in_another_process_plan_a_failure_and_sigterm_leaves_a_complete_log(
    localhost_ros_domain, tmp_path
) -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", "helireach_ros.cli.main", "bringup", "--log-dir", str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=dict(os.environ),
    )
    context = Context()
    rclpy.init(context=context)
    node = Node("test_vehicle", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    statuses: list[DiagnosticStatus] = []
    trajectories: list[JointTrajectory] = []
    ready: list[DiagnosticStatus] = []
    states: list[Odometry] = []
    node.create_subscription(DiagnosticStatus, rm.TOPIC_READY, ready.append, rm.LATCHED_QOS)
    node.create_subscription(Odometry, rm.TOPIC_STATE, states.append, rm.STREAM_QOS)
    node.create_subscription(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS, statuses.append, rm.LATCHED_QOS)
    node.create_subscription(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, trajectories.append, rm.LATCHED_QOS)
    odometry = node.create_publisher(Odometry, rm.TOPIC_ODOMETRY, rm.STREAM_QOS)
    rotor = node.create_publisher(JointState, rm.TOPIC_ROTOR, rm.STREAM_QOS)
    failure = node.create_publisher(Bool, rm.TOPIC_ENGINE_FAILURE, rm.EVENT_QOS)
    stamps: list[int] = []

    engine_failed = Bool(data=False)

    def fly_until(condition, timeout_s: float = TIMEOUT_S) -> bool:
        """Publishes like a vehicle (state and failure flag every 20 ms) until the condition holds."""
        deadline = time.monotonic() + timeout_s
        while not condition() and time.monotonic() < deadline:
            stamps.append(node.get_clock().now().nanoseconds)
            odometry.publish(rm.odometry_message(stamps[-1], 500 * FT, 0.0, 75 * KT, 0.0))
            rotor.publish(rm.rotor_message(stamps[-1], 27.0))
            failure.publish(engine_failed)
            executor.spin_once(timeout_sec=0.02)
        return condition()

    try:
        log_path = Path(wait_for_line(process, "helireach bringup: logging to", TIMEOUT_S).split(" to ", 1)[1].strip())
        # What msg_docs/helireach_ready.md tells a vehicle to wait for: the nodes spinning, its publisher matched
        # (monitor and recorder). Then not even the first message is lost.
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline and not (
            ready and ready[-1].level == DiagnosticStatus.OK and odometry.get_subscription_count() >= 2
        ):
            executor.spin_once(timeout_sec=0.05)
        assert ready and ready[-1].level == DiagnosticStatus.OK, "no /helireach/ready"
        assert "helireach_planner" in rm.status_values(ready[-1])["nodes"].split()
        assert fly_until(lambda: bool(states))
        assert rm.stamp_nanoseconds(states[0].header.stamp) == stamps[0], "the first vehicle message was lost"
        assert fly_until(lambda: statuses and statuses[-1].level == DiagnosticStatus.OK), "no SAFE status"
        # Monitor and recorder both subscribed: the rising edge reaches the planner and the log.
        assert fly_until(lambda: failure.get_subscription_count() >= 2), "monitor or recorder never subscribed"
        engine_failed.data = True
        assert fly_until(lambda: bool(trajectories)), "no landing trajectory"
        assert rm.stamp_nanoseconds(trajectories[0].header.stamp) in stamps
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=TIMEOUT_S) == 0
        printed = process.stdout.read()
        assert f"log written to {log_path}" in printed
        stop_deadline = time.monotonic() + 2.0
        while ready[-1].level != DiagnosticStatus.STALE and time.monotonic() < stop_deadline:
            executor.spin_once(timeout_sec=0.05)
        assert ready[-1].level == DiagnosticStatus.STALE, "the ready status must say the nodes stopped"
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    # Complete, not truncated: the strict reader needs the summary and index that finish() writes.
    topics = read_log_topics(log_path)
    for topic in (
        rm.TOPIC_ODOMETRY,
        rm.TOPIC_ENGINE_FAILURE,
        rm.TOPIC_SAFETY_STATUS,
        rm.TOPIC_LANDING_TRAJECTORY,
        rm.TOPIC_PLAN_STATUS,
        rm.TOPIC_FAILURE_EVENT,
    ):
        assert topics[topic].message_count > 0, topic
    assert sum(1 for message in read_log(log_path) if message.topic == rm.TOPIC_LANDING_TRAJECTORY) >= 1
    first_logged = next(message for message in read_log(log_path) if message.topic == rm.TOPIC_ODOMETRY)
    first_odometry = deserialize_message(first_logged.cdr, Odometry)
    assert rm.stamp_nanoseconds(first_odometry.header.stamp) == stamps[0], "the log must start with the first message"
