"""Soak: the composed system under a steady stream of fuzzed inputs for a long time; memory and latency over time.

Run: .venv/bin/python bench/soak.py [--minutes 30] [--interval-s 60] [--rate-hz 100] [--seed 7]

The composed system (monitor, envelope status, planner, recorder) runs in this process (discovery off). A
vehicle node publishes a clean state at 50 Hz (500 ft, 75 kt) interleaved with fuzzed messages
(:class:`~helireach_ros.ros.input_fuzzer.VehicleInputFuzzer`, no failure flags) at ``--rate-hz``. Once per
interval the engine fails (flag true for 8 s, then false for the recovery hold). Each interval prints:
resident memory and its growth, threads, open files, the monitor's state latency (clean odometry publish →
``/helireach/state`` receipt, p50/p95/max), failure → first trajectory, and the monitor's counts.
The load average is printed with every row.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

from _common import command_line, loadavg_text, summary
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.bringup import build_system
from helireach_ros.ros.input_fuzzer import PUBLISHER_QOS, VehicleInputFuzzer

FAILURE_S = 8.0


def resident_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def percentile_text(samples: list[float]) -> str:
    stats = summary(samples)
    if not stats["n"]:
        return "    ---"
    return f"{stats['median']:5.1f}/{stats['p95']:5.1f}/{stats['max']:6.1f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--interval-s", type=float, default=60.0)
    parser.add_argument("--rate-hz", type=float, default=100.0, help="fuzzed messages per second")
    parser.add_argument("--seed", type=int, default=7)
    arguments = parser.parse_args()
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"
    print(f"command: {command_line()}; load average {loadavg_text()}")
    with tempfile.TemporaryDirectory() as log_dir:
        system = build_system(log_dir=log_dir, context=Context())
        try:
            return soak(system, arguments)
        finally:
            system.shutdown()


def soak(system, arguments: argparse.Namespace) -> int:
    vehicle = Node("soak_vehicle", context=system.context)
    system.executor.add_node(vehicle)
    clean = {
        "odometry": vehicle.create_publisher(Odometry, rm.TOPIC_ODOMETRY, rm.STREAM_QOS),
        "rotor": vehicle.create_publisher(JointState, rm.TOPIC_ROTOR, rm.STREAM_QOS),
        "flag": vehicle.create_publisher(Bool, rm.TOPIC_ENGINE_FAILURE, rm.EVENT_QOS),
    }
    fuzzed = {
        (topic, kind): vehicle.create_publisher(message_type, topic, qos)
        for topic, message_type in ((rm.TOPIC_ODOMETRY, Odometry), (rm.TOPIC_ROTOR, JointState))
        for kind, qos in PUBLISHER_QOS.items()
    }
    sent_at: dict[int, float] = {}
    latencies: list[float] = []
    trajectories: list[float] = []

    def on_state(message: Odometry) -> None:
        sent = sent_at.pop(rm.stamp_nanoseconds(message.header.stamp), None)
        if sent is not None:
            latencies.append(1e3 * (time.monotonic() - sent))

    monitor_values: dict[str, str] = {}

    def on_diagnostics(message: DiagnosticArray) -> None:
        for status in message.status:
            if status.name.endswith("monitor: vehicle state"):
                monitor_values.update(rm.status_values(status))

    vehicle.create_subscription(Odometry, rm.TOPIC_STATE, on_state, rm.SENSOR_QOS)
    vehicle.create_subscription(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, on_diagnostics, rm.SENSOR_QOS)
    vehicle.create_subscription(
        JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, lambda _: trajectories.append(time.monotonic()), rm.LATCHED_QOS
    )
    fuzzer = VehicleInputFuzzer(arguments.seed, failure_share=0.0, internal_share=0.0)
    start = time.monotonic()
    memory_start = resident_mb()
    next_clean = next_fuzz = start
    interval_start = start
    failure_at = start + arguments.interval_s / 2
    failure_latencies: list[float] = []
    engine_failed = False
    print("  t_min  rss_MB  d_MB  threads fds  state_ms p50/p95/max  failure->traj_ms  odom valid/rejected/ooo  load")
    while time.monotonic() - start < 60.0 * arguments.minutes:
        now = time.monotonic()
        if now >= next_clean:
            stamp = vehicle.get_clock().now().nanoseconds
            sent_at[stamp] = now
            clean["odometry"].publish(rm.odometry_message(stamp, 500 * FT, 0.0, 75 * KT, 0.0))
            clean["rotor"].publish(rm.rotor_message(stamp, 27.0))
            clean["flag"].publish(Bool(data=engine_failed))
            next_clean += 0.02
        if now >= next_fuzz:
            drawn = fuzzer.next(vehicle.get_clock().now().nanoseconds)
            fuzzed[(drawn.topic, drawn.qos_kind)].publish(drawn.message)
            next_fuzz += 1.0 / arguments.rate_hz
        if not engine_failed and now >= failure_at:
            engine_failed, trajectories_before = True, len(trajectories)
        if engine_failed and now >= failure_at + FAILURE_S:
            engine_failed = False
            if len(trajectories) > trajectories_before:
                failure_latencies.append(1e3 * (trajectories[trajectories_before] - failure_at))
            failure_at += arguments.interval_s
        system.executor.spin_once(timeout_sec=0.002)
        if len(sent_at) > 10_000:  # states that never came back (rejected by the fuzz stream's order): forget
            sent_at.clear()
        if now - interval_start >= arguments.interval_s:
            counts = "/".join(
                monitor_values.get(f"odometry_{key}", "?") for key in ("valid", "rejected", "out_of_order")
            )
            print(
                f"  {(now - start) / 60:5.1f}  {resident_mb():6.1f} {resident_mb() - memory_start:+5.1f}  "
                f"{len(os.listdir('/proc/self/task')):7d} {len(os.listdir('/proc/self/fd')):4d}  "
                f"{percentile_text(latencies):>22s}  {percentile_text(failure_latencies):>16s}  "
                f"{counts:>23s}  {loadavg_text()}",
                flush=True,
            )
            latencies.clear()
            failure_latencies.clear()
            interval_start = now
    print(f"reproduce: {command_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
