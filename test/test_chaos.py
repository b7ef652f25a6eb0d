"""Chaos: every helireach node killed with SIGKILL mid-descent in the multi-process system, and started again.

The five nodes run as their console scripts (one process each, LOCALHOST discovery on a domain of this test's
own), the simulated vehicle flying a 1,000 ft / 75 kt cruise with an engine failure. After the first plan, each
helireach node in turn (planner, monitor, envelope status, recorder) is killed with SIGKILL and started again.
The system must recover each time: a fresh safety status within 2 s of the restarted node being up, the planner
re-planning from the current state, and the killed recorder's log recoverable into a finished file. The vehicle
(the aircraft itself) is not killed. Times from restart to recovery are printed.
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
from mcap.reader import make_reader
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from helireach_ros.core.mcap_log import read_log_topics
from helireach_ros.core.mcap_log.recover import recover_log
from helireach_ros.core.resources import config_path
from helireach_ros.ros import messages as rm

pytestmark = [pytest.mark.system, pytest.mark.realtime]

BIN = Path(sys.executable).parent
START_TIMEOUT_S = 60.0
RECOVERY_S = 2.0
SCENARIO = """\
name: chaos_1000ft_75kt
description: 1000 ft / 75 kt cruise, total power loss at 8 s (time for every node to start), no mismatch
airframe: uh60a_class
height: {value: 1000, unit: ft}
forward_speed: {value: 75, unit: kt}
failure_time: {value: 8.0, unit: s}
power_fraction: 0.0
seed: 3
max_flight_time: {value: 90, unit: s}
"""


class Observer:
    """Records the system's outputs with their receipt times (monotonic)."""

    def __init__(self, context: Context) -> None:
        self.node = Node("chaos_observer", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.safety: list[tuple[float, dict[str, str], bytes]] = []
        self.plans: list[tuple[float, dict[str, str]]] = []
        self.states: list[tuple[float, int]] = []
        self.touchdown: list[dict[str, str]] = []
        self.node.create_subscription(
            DiagnosticStatus, rm.TOPIC_SAFETY_STATUS,
            lambda m: self.safety.append((time.monotonic(), rm.status_values(m), m.level)), rm.LATCHED_QOS,
        )  # fmt: skip
        self.node.create_subscription(
            DiagnosticStatus, rm.TOPIC_PLAN_STATUS,
            lambda m: self.plans.append((time.monotonic(), rm.status_values(m))), rm.LATCHED_QOS,
        )  # fmt: skip
        self.node.create_subscription(
            Odometry, rm.TOPIC_STATE,
            lambda m: self.states.append((time.monotonic(), rm.stamp_nanoseconds(m.header.stamp))), rm.SENSOR_QOS,
        )  # fmt: skip
        self.node.create_subscription(
            DiagnosticStatus, rm.TOPIC_TOUCHDOWN, lambda m: self.touchdown.append(rm.status_values(m)), rm.LATCHED_QOS
        )

    def spin_until(self, condition, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not condition() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)
        return condition()

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.executor.shutdown()
        self.node.destroy_node()


class NodeProcess:
    """One console script, its output in a file."""

    def __init__(self, script: str, folder: Path, *parameters: str) -> None:
        self.script, self.folder, self.parameters = script, folder, parameters
        self.starts = 0
        self.process: subprocess.Popen | None = None
        self.start()

    def start(self) -> None:
        self.starts += 1
        log = (self.folder / f"{self.script}.{self.starts}.log").open("w")
        command = [str(BIN / self.script), "--ros-args", "--params-file", str(config_path("nodes.yaml"))]
        for parameter in self.parameters:  # node-qualified: config/nodes.yaml's per-node entries win over a bare -p
            command += ["-p", parameter]
        self.process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ))
        self.started_at = time.monotonic()

    def log_tail(self, lines: int = 20) -> list[str]:
        """The last lines the process printed since its latest start."""
        return (self.folder / f"{self.script}.{self.starts}.log").read_text().splitlines()[-lines:]

    def kill(self) -> None:
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=10.0)

    def stop(self) -> int | None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                return self.process.wait(timeout=20.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
        return self.process.poll()


def test_every_node_killed_mid_descent_recovers_and_the_log_is_recoverable(localhost_ros_domain, tmp_path) -> None:
    scenario = tmp_path / "chaos.yaml"
    scenario.write_text(SCENARIO)
    logs = tmp_path / "logs"
    context = Context()
    rclpy.init(context=context)
    observer = Observer(context)
    recorder = NodeProcess("helireach_recorder", tmp_path, f"helireach_recorder:log_dir:={logs}")
    nodes = {
        "monitor": NodeProcess("helireach_monitor", tmp_path),
        "envelope_status": NodeProcess("helireach_envelope_status", tmp_path),
        "planner": NodeProcess("helireach_planner", tmp_path),
    }
    nodes["recorder"] = recorder
    vehicle = None
    recoveries: dict[str, float] = {}
    try:
        assert observer.spin_until(lambda: bool(observer.safety), START_TIMEOUT_S), "no safety status"
        vehicle = NodeProcess("helireach_sim_vehicle", tmp_path, f"helireach_sim_vehicle:scenario:={scenario}")
        assert observer.spin_until(lambda: bool(observer.plans), START_TIMEOUT_S), "no plan after the failure"

        # Planner: killed while re-planning; started again it plans from the current state.
        planner = nodes["planner"]
        planner.kill()
        killed_at = time.monotonic()
        planner.start()
        # the first status from a state: before its first state the restarted planner may say it waits for one
        def planned_after_restart() -> bool:
            return any(t > killed_at and "state_stamp_ns" in v for t, v in observer.plans)

        assert observer.spin_until(planned_after_restart, START_TIMEOUT_S)
        replanned_at, values = next((t, v) for t, v in observer.plans if t > killed_at and "state_stamp_ns" in v)
        # The reference is the newest state when the new planner process started, not when its status reached this
        # observer: the restarted publisher must be discovered first, and its latched status then arrives late.
        # Measured: a fallback published 0.2 s after its state reached this process 1.7 s later (flaky 2 of 4 runs).
        latest_state = max(stamp for t, stamp in observer.states if t <= planner.started_at)
        assert int(values["state_stamp_ns"]) >= latest_state - int(0.5e9), (
            "the new plan is not from a state after the restart",
            (int(values["state_stamp_ns"]) - latest_state) * 1e-9,
        )
        recoveries["planner (restart -> plan)"] = replanned_at - planner.started_at

        # Monitor: killed, the state stops; started again, the status is fresh within 2 s of the first state.
        for name, output in (("monitor", observer.states), ("envelope_status", observer.safety)):
            node = nodes[name]
            node.kill()
            killed_at = time.monotonic()
            node.start()

            def restarted(output=output, killed_at=killed_at) -> bool:
                return any(entry[0] > killed_at for entry in output)

            # Up: its first message after the restart (a state from the monitor, a status from the status node).
            assert observer.spin_until(restarted, START_TIMEOUT_S), f"{name} published nothing after its restart"
            up_at = next(entry[0] for entry in output if entry[0] > killed_at)

            def fresh_status(up_at=up_at) -> bool:
                return any(t >= up_at and int(v.get("state_stamp_ns", "0")) > 0 for t, v, _ in observer.safety)

            assert observer.spin_until(fresh_status, RECOVERY_S + 1.0), (
                f"{name}: no status from a state within {RECOVERY_S + 1.0:g} s of it being up",
                [(round(t - up_at, 2), v.get("state_stamp_ns"), lvl) for t, v, lvl in observer.safety if t >= up_at],
                [round(t - up_at, 2) for t, _ in observer.states if t >= up_at][-5:],
                node.log_tail(),
            )
            status_at = next(t for t, v, _ in observer.safety if t >= up_at and int(v.get("state_stamp_ns", "0")) > 0)
            recoveries[f"{name} (up -> fresh status)"] = status_at - up_at
            assert status_at - up_at <= RECOVERY_S, recoveries

        # Recorder: killed, its log is truncated; started again it writes a new one.
        killed_logs = set(logs.glob("*.mcap"))
        recorder.kill()
        recorder.start()
        assert observer.spin_until(lambda: vehicle.process.poll() is not None or bool(observer.touchdown), 90.0)
    finally:
        for node in [*nodes.values(), vehicle]:
            if node is not None:
                node.stop()
        observer.close()
        rclpy.try_shutdown(context=context)
        print("recovery times:", {name: f"{seconds:.2f} s" for name, seconds in recoveries.items()})
    assert observer.touchdown, "no touchdown report"
    print("touchdown:", {key: observer.touchdown[-1].get(key) for key in ("within_limits", "reason")})
    (killed,) = killed_logs
    report = recover_log(killed, tmp_path / "recovered.mcap")
    assert report.messages > 0
    with (tmp_path / "recovered.mcap").open("rb") as stream:
        assert make_reader(stream).get_summary() is not None  # the indexed reader opens it
    later = [path for path in logs.glob("*.mcap") if path not in killed_logs]
    assert later and read_log_topics(later[0])[rm.TOPIC_STATE].message_count > 0


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-s"]))
