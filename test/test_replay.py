"""Replay: ``/clock`` from the log's time, refused rates and topics (exit 2), ``--start``, ``--loop``, ``--recover``.

Real rclpy middleware in one process with discovery off (conftest ``no_ros_discovery``); the logs are real MCAP files
written by the product's writer.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from test_log_recovery import killed_copy
from test_mcap_log import LATCHED, ODOM, STATUS, VOLATILE, write_log

from helireach_ros.cli.main import main as helireach_main
from helireach_ros.ros.nodes.recorder import qos_profile
from helireach_ros.ros.replay import CLOCK_TOPIC, replay_log


@pytest.fixture
def context(no_ros_discovery: None) -> Iterator[Context]:
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


class Listener:
    """A node hearing the replayed topics and /clock on a spinning executor; counts what arrived."""

    def __init__(self, context: Context) -> None:
        self.node = Node("listener", context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
        self.lock = threading.Condition()
        self.received: list[tuple[str, int]] = []  # (topic, its time: clock ns or odometry stamp ns)
        keep_all = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(Clock, CLOCK_TOPIC, self._on_clock, keep_all)
        self.node.create_subscription(Odometry, ODOM, self._on_odometry, qos_profile(VOLATILE))
        self.node.create_subscription(DiagnosticStatus, STATUS, self._on_status, qos_profile(LATCHED))
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _keep(self, topic: str, stamp_ns: int) -> None:
        with self.lock:
            self.received.append((topic, stamp_ns))
            self.lock.notify_all()

    def _on_clock(self, message: Clock) -> None:
        self._keep(CLOCK_TOPIC, message.clock.sec * 1_000_000_000 + message.clock.nanosec)

    def _on_odometry(self, message: Odometry) -> None:
        self._keep(ODOM, message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec)

    def _on_status(self, _message: DiagnosticStatus) -> None:
        self._keep(STATUS, 0)

    def wait_for(self, topic: str, count: int) -> list[int]:
        return self.wait_until(topic, lambda stamps: len(stamps) >= count)

    def wait_until(self, topic: str, condition: Callable[[list[int]], bool], timeout: float = 10) -> list[int]:
        with self.lock:
            assert self.lock.wait_for(lambda: condition(self.of(topic)), timeout=timeout), self.received
            return self.of(topic)

    def of(self, topic: str) -> list[int]:
        return [stamp for t, stamp in self.received if t == topic]

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(timeout=5)
        self.node.destroy_node()


@pytest.fixture
def listener(context: Context) -> Iterator[Listener]:
    heard = Listener(context)
    yield heard
    heard.close()


def test_replay_publishes_the_log_time_on_clock(context: Context, listener: Listener, tmp_path: Path) -> None:
    log = tmp_path / "flight.mcap"
    written = write_log(log)  # a status, then five odometry messages 40 ms apart
    player = Node("player", context=context)
    try:
        assert replay_log(log, rate=1.0, node=player, context=context) == len(written)
        listener.wait_for(ODOM, 5)
        stamps = [stamp for _, _, stamp in written]
        clock = listener.wait_until(CLOCK_TOPIC, lambda clocks: stamps[-1] in clocks)
    finally:
        player.destroy_node()
    assert clock == sorted(clock) and clock[0] == stamps[0] and clock[-1] == stamps[-1]
    assert set(stamps) <= set(clock)
    assert len(set(clock) - set(stamps)) >= 3, "no clock between messages 40 ms apart (40 Hz while waiting)"
    # A use_sim_time node runs on the log's time (its own /clock subscription may be served a moment later).
    deadline = time.monotonic() + 10
    while listener.node.get_clock().now().nanoseconds != stamps[-1] and time.monotonic() < deadline:
        time.sleep(0.01)
    assert listener.node.get_clock().now().nanoseconds == stamps[-1]


def test_start_skips_into_the_log_keeping_the_latched_status(
    context: Context, listener: Listener, tmp_path: Path
) -> None:
    log = tmp_path / "flight.mcap"
    written = write_log(log)
    player = Node("player", context=context)
    try:
        # Odometry at 40..200 ms; from 100 ms: the three at 120, 160, 200 ms and the status of t = 0.
        assert replay_log(log, rate=0, node=player, context=context, start_s=0.1) == 4
        odometry = listener.wait_for(ODOM, 3)
        assert listener.wait_for(STATUS, 1) == [0]
        assert listener.wait_for(CLOCK_TOPIC, 1)[0] == written[0][2] + 100_000_000  # the clock starts at --start
    finally:
        player.destroy_node()
    assert len(odometry) == 3 and odometry == sorted(odometry)
    with pytest.raises(ValueError, match="start"):
        replay_log(log, node=player, context=context, start_s=-1.0)
    with pytest.raises(ValueError, match=r"start 1 s is past the end of .* \(its messages span 0\.\d+ s\)"):
        replay_log(log, node=player, context=context, start_s=1.0)  # nothing would be replayed: say so


def test_a_replay_reports_its_progress(context: Context, listener: Listener, tmp_path: Path) -> None:
    log = tmp_path / "flight.mcap"
    write_log(log)
    player = Node("player", context=context)
    reports: list[tuple[int, float]] = []
    try:
        count = replay_log(
            log, rate=0, node=player, context=context, on_progress=lambda *report: reports.append(report),
            progress_interval_s=0.0,
        )  # fmt: skip
    finally:
        player.destroy_node()
    assert len(reports) == count and [n for n, _ in reports] == list(range(1, count + 1))
    log_times = [log_s for _, log_s in reports]
    assert log_times == sorted(log_times) and log_times[0] >= 0.0


def test_loops_play_the_log_again(context: Context, listener: Listener, tmp_path: Path) -> None:
    log = tmp_path / "flight.mcap"
    written = write_log(log)
    player = Node("player", context=context)
    try:
        # Paced (rate 1): a KEEP_LAST 10 publisher replaying 15 messages at full speed may overwrite unacked ones.
        assert replay_log(log, rate=1.0, node=player, context=context, loops=3) == 3 * len(written)
        odometry = listener.wait_for(ODOM, 15)
    finally:
        player.destroy_node()
    assert odometry[:5] == odometry[5:10] == odometry[10:15]


def test_bad_rates_and_unknown_topics_exit_2_naming_what_the_log_has(
    context: Context, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "flight.mcap"
    write_log(log)
    for rate in ("-1", "nan", "inf", "fast"):
        with pytest.raises(SystemExit) as exited:
            helireach_main(["replay", str(log), "--rate", rate])
        assert exited.value.code == 2 and "--rate" in capsys.readouterr().err
    assert helireach_main(["replay", str(log), "--topics", "/nope", ODOM]) == 2
    error = capsys.readouterr().err
    assert "/nope" in error and f"the log has {STATUS}, {ODOM}" in error
    for option in ("--start", "--discovery-wait"):
        with pytest.raises(SystemExit) as exited:
            helireach_main(["replay", str(log), option, "-2"])
        assert exited.value.code == 2 and option in capsys.readouterr().err
    with pytest.raises(ValueError, match="rate"):
        replay_log(log, rate=-1.0, context=context)
    with pytest.raises(ValueError, match="/nope"):
        replay_log(log, topics=["/nope"], context=context)


def test_a_killed_recording_plays_only_with_recover(
    no_ros_discovery: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    killed, _ = killed_copy(tmp_path)
    assert helireach_main(["replay", str(killed), "--rate", "0"]) == 1
    error = capsys.readouterr().err
    assert "truncated" in error and "--recover" in error and "helireach log recover" in error
    assert helireach_main(["replay", str(killed), "--rate", "0", "--recover"]) == 0
    captured = capsys.readouterr()
    assert "WARNING" in captured.err and "never closed" in captured.err
    assert "replayed 60 messages" in captured.out  # the complete chunks; the open one was lost


def test_the_loop_command_plays_until_interrupted(localhost_ros_domain: int, tmp_path: Path) -> None:
    log = tmp_path / "flight.mcap"
    write_log(log)
    context = Context()
    rclpy.init(context=context)
    listener = Listener(context)
    player = subprocess.Popen(
        [str(Path(sys.executable).parent / "helireach"), "replay", str(log), "--loop", "--rate", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        odometry = listener.wait_until(ODOM, lambda stamps: len(stamps) >= 15, timeout=40)  # three passes
        player.send_signal(signal.SIGINT)
        out, err = player.communicate(timeout=20)
    finally:
        if player.poll() is None:
            player.kill()
            player.communicate()
        listener.close()
        rclpy.try_shutdown(context=context)
    assert player.returncode == 130, err
    assert out.startswith("interrupted")
    assert odometry[:5] == odometry[5:10] == odometry[10:15]
