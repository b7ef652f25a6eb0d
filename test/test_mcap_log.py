"""MCAP flight logs: writer/reader, recorder node, replay — with real rclpy, mcap and rosbags.

In-process tests isolate DDS with ``ROS_AUTOMATIC_DISCOVERY_RANGE=OFF``; cross-process tests use
``LOCALHOST`` and a ``ROS_DOMAIN_ID`` of its own (conftest.py). Waiting is always "spin/poll until a condition holds,
with a deadline".
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Duration as DurationMsg
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Log
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from helireach_ros.core.mcap_log import (
    McapLogError,
    McapLogWriter,
    QosDescription,
    message_definition,
    read_log,
    read_log_metadata,
    read_log_topics,
)
from helireach_ros.ros.nodes.recorder import McapRecorder, qos_profile
from helireach_ros.ros.replay import replay_log

REPO = Path(__file__).resolve().parents[1]
LATCHED = QosDescription("reliable", "transient_local", 1)
VOLATILE = QosDescription("reliable", "volatile", 10)
STATUS = "/helireach/safety_status"
ODOM = "/vehicle/odometry"
FAILURE = "/vehicle/engine_failure"
ROTOR = "/vehicle/rotor"
TRAJ = "/helireach/landing_trajectory"
CROSS_PROCESS_TIMEOUT_S = 15.0
# Cross-process publishers keep every test message until the recorder acknowledges it (waiting on
# wait_for_all_acked() costs Fast DDS's 3 s heartbeat period per call).
BURST = QosDescription("reliable", "volatile", 100)


# --- helpers ---------------------------------------------------------------------------------------


def wait_for(condition: Callable[[], bool], timeout: float, step: Callable[[], None], what: str) -> None:
    """Run ``step`` until ``condition`` holds; fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what}")
        step()


def odometry(i: int) -> Odometry:
    msg = Odometry()
    msg.header.frame_id = "map"
    msg.header.stamp.sec = 1000 + i
    msg.child_frame_id = "base_link"
    msg.pose.pose.position.x = 10.0 * i
    msg.pose.pose.position.z = 150.0 - i
    msg.twist.twist.linear.x = 30.0 + 0.5 * i
    msg.pose.covariance[0] = 0.25
    return msg


def status(level: bytes, message: str) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=level,
        name="helireach_safety: envelope",
        message=message,
        hardware_id="R22",
        values=[KeyValue(key="margin_m", value="12.5")],
    )


def trajectory() -> JointTrajectory:
    msg = JointTrajectory(joint_names=["x", "h", "u"])
    for k in range(3):
        msg.points.append(
            JointTrajectoryPoint(
                positions=[1.0 * k, 100.0 - 10.0 * k, 20.0], time_from_start=DurationMsg(sec=k, nanosec=5)
            )
        )
    return msg


@pytest.fixture
def ros_context(monkeypatch: pytest.MonkeyPatch) -> Iterator[Context]:
    """A fresh, DDS-isolated rclpy context."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


@pytest.fixture
def cross_process_env(localhost_ros_domain: int) -> dict[str, str]:
    """Environment shared by this process and the recorder subprocess (localhost, own domain)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH", "")]))
    return env


def start_recorder(env: dict[str, str], log_dir: Path, *params: str) -> subprocess.Popen[bytes]:
    topics = f"['{ODOM}:nav_msgs/msg/Odometry','{FAILURE}:std_msgs/msg/Bool']"
    args = ["-p", f"log_dir:={log_dir}", "-p", f"topics:={topics}"]
    for param in params:
        args += ["-p", param]
    return subprocess.Popen(
        [sys.executable, "-m", "helireach_ros.ros.nodes.recorder", "--ros-args", *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )


def one_log(log_dir: Path, proc: subprocess.Popen[bytes]) -> Path:
    logs = list(log_dir.glob("*.mcap"))
    assert len(logs) == 1, logs
    assert re.fullmatch(r"helireach_\d{8}_\d{6}_\d+\.mcap", logs[0].name), logs[0].name
    return logs[0]


def stop(proc: subprocess.Popen[bytes], sig: signal.Signals) -> str:
    proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        pytest.fail(f"recorder did not exit after {sig.name}:\n{out.decode(errors='replace')}")
    return out.decode(errors="replace")


def count_readable(path: Path) -> int:
    """Messages already on disk (completed chunks) of a log being written."""
    try:
        return sum(1 for _ in read_log(path, allow_truncated=True))
    except McapLogError:  # header not written yet
        return 0


def wait_on_disk(log: Path, count: int) -> None:
    """Poll the file a recorder process is writing until ``count`` messages are readable."""
    wait_for(
        lambda: count_readable(log) >= count,
        CROSS_PROCESS_TIMEOUT_S,
        lambda: time.sleep(0.05),  # another process writes the file: nothing to spin here
        f"{count} messages on disk",
    )


def write_log(path: Path, chunk_size: int = 64 * 1024) -> list[tuple[str, bytes, int]]:
    """A small log: one latched status, then five odometry messages 40 ms apart."""
    t0 = 1_700_000_000_000_000_000
    written = [(STATUS, serialize_message(status(DiagnosticStatus.WARN, "low margin")), t0)]
    written += [(ODOM, serialize_message(odometry(i)), t0 + (i + 1) * 40_000_000) for i in range(5)]
    with McapLogWriter(path, metadata={"airframe": "R22"}, chunk_size=chunk_size) as writer:
        writer.add_topic(STATUS, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED)
        writer.add_topic(ODOM, "nav_msgs/msg/Odometry", VOLATILE)
        for topic, cdr, stamp in written:
            writer.write(topic, cdr, stamp, stamp - 1000)
    return written


def rosbags_messages(log: Path, tmp_path: Path) -> tuple[dict[str, object], list[tuple[str, object]]]:
    """Read a log with the independent ``rosbags`` reader.

    rosbags 0.11 opens only rosbag2 *directories* with a ``metadata.yaml``; a bare .mcap is not
    accepted. The test therefore builds that directory here from the log's own ``rosbag2`` metadata
    record (what ``ros2 bag record`` would have written beside it); the product writes no yaml.
    """
    from rosbags.highlevel import AnyReader

    bag = tmp_path / "rosbags_view"
    bag.mkdir()
    shutil.copy(log, bag / log.name)
    serialized = read_log_metadata(log)["rosbag2"]["serialized_metadata"]
    (bag / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": yaml.safe_load(serialized)}))
    with AnyReader([bag]) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
        messages = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    return qos, messages


# --- pure writer/reader ----------------------------------------------------------------------------


def test_qos_yaml_round_trip_and_rosbag2_spelling() -> None:
    text = LATCHED.to_rosbag2_yaml()
    profile = yaml.safe_load(text)[0]
    assert list(profile) == [
        "history", "depth", "reliability", "durability", "deadline", "lifespan",
        "liveliness", "liveliness_lease_duration", "avoid_ros_namespace_conventions",
    ]  # fmt: skip
    assert profile["durability"] == "transient_local"
    assert profile["deadline"] == {"sec": 9223372036, "nsec": 854775807}
    assert QosDescription.from_rosbag2_yaml(text) == LATCHED
    # Pre-Jazzy integer enums, and a remote publisher's unknown history (depth 0).
    legacy = "- history: 3\n  depth: 0\n  reliability: 2\n  durability: 1\n"
    assert QosDescription.from_rosbag2_yaml(legacy) == QosDescription("best_effort", "transient_local", 10)
    assert QosDescription.from_rosbag2_yaml("") == QosDescription()
    with pytest.raises(ValueError):
        QosDescription("sometimes")


def test_schema_is_rosbag2_concatenated_msg_text() -> None:
    encoding, text = message_definition("nav_msgs/msg/Odometry")
    assert encoding == "ros2msg"
    share = Path(sys.prefix, "share")
    assert text.startswith((share / "nav_msgs/msg/Odometry.msg").read_text())
    sections = text.split("\n" + "=" * 80 + "\n")
    names = [s.split("\n", 1)[0] for s in sections[1:]]
    assert names == [
        "MSG: geometry_msgs/PoseWithCovariance", "MSG: geometry_msgs/Pose", "MSG: geometry_msgs/Point",
        "MSG: geometry_msgs/Quaternion", "MSG: geometry_msgs/TwistWithCovariance", "MSG: geometry_msgs/Twist",
        "MSG: geometry_msgs/Vector3", "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time",
    ]  # fmt: skip
    header = next(s for s in sections if s.startswith("MSG: std_msgs/Header\n"))
    assert header.split("\n", 1)[1] == (share / "std_msgs/msg/Header.msg").read_text()


def test_concurrent_writes_and_metadata(tmp_path: Path) -> None:
    path = tmp_path / "threads.mcap"
    cdr = serialize_message(Bool(data=True))
    with McapLogWriter(path, chunk_size=512) as writer:
        writer.add_topic(FAILURE, "std_msgs/msg/Bool", VOLATILE)
        writer.add_metadata("helireach", {"scenario": "hover_failure", "envelope_id": "r22-hv-1"})

        def burst(k: int) -> None:
            for i in range(200):
                writer.write(FAILURE, cdr, 1_000_000 * k + i)

        threads = [threading.Thread(target=burst, args=(k,)) for k in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    times = [m.log_time_ns for m in read_log(path)]
    assert len(times) == 800 and times == sorted(times)
    assert read_log_metadata(path)["helireach"] == {"scenario": "hover_failure", "envelope_id": "r22-hv-1"}
    assert read_log_topics(path)[FAILURE].message_count == 800
    with pytest.raises(McapLogError, match="closed"):
        writer.write(FAILURE, cdr, 1)


def test_truncated_and_corrupt_files_raise_naming_the_file(tmp_path: Path) -> None:
    good = tmp_path / "good.mcap"
    written = write_log(good, chunk_size=256)
    data = good.read_bytes()

    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(data[: data.index(written[-1][1]) + 10])  # cut inside the last chunk
    with pytest.raises(McapLogError, match=re.escape(str(truncated))):
        read_log(truncated)
    with pytest.raises(McapLogError, match="truncated"):
        read_log_metadata(truncated)
    recovered = list(read_log(truncated, allow_truncated=True))
    assert 0 < len(recovered) < len(written)
    assert [m.cdr for m in recovered] == [cdr for _, cdr, _ in written[: len(recovered)]]

    corrupt = tmp_path / "corrupt.mcap"
    payload = written[3][1]
    at = data.index(payload) + len(payload) // 2
    corrupt.write_bytes(data[:at] + bytes(b ^ 0xFF for b in data[at : at + 8]) + data[at + 8 :])
    with pytest.raises(McapLogError, match=re.escape(str(corrupt))):
        list(read_log(corrupt))

    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("hello")
    with pytest.raises(McapLogError, match=re.escape(str(not_mcap))):
        read_log(not_mcap)
    with pytest.raises(McapLogError, match=re.escape(str(tmp_path / "missing.mcap"))):
        read_log(tmp_path / "missing.mcap")


# --- recorder node ---------------------------------------------------------------------------------


def test_recorder_round_trip_read_by_three_readers(ros_context: Context, tmp_path: Path) -> None:
    ctx = ros_context
    talker = Node("talker", context=ctx)
    pubs = {
        ODOM: talker.create_publisher(Odometry, ODOM, qos_profile(VOLATILE)),
        FAILURE: talker.create_publisher(Bool, FAILURE, qos_profile(VOLATILE)),
        STATUS: talker.create_publisher(DiagnosticStatus, STATUS, qos_profile(LATCHED)),
        TRAJ: talker.create_publisher(JointTrajectory, TRAJ, qos_profile(VOLATILE)),
    }
    # Published before the recorder exists: only a TRANSIENT_LOCAL request can still get it.
    pubs[STATUS].publish(status(DiagnosticStatus.WARN, "low margin"))
    metadata = {"airframe": "R22", "envelope_id": "r22-hv-1", "software_version": "0.1.0", "scenario": "t"}
    recorder = McapRecorder(
        metadata=metadata, context=ctx, parameter_overrides=[Parameter("log_dir", value=str(tmp_path))]
    )
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(talker)
    executor.add_node(recorder)

    def spin() -> None:
        executor.spin_once(timeout_sec=0.05)

    try:
        wait_for(lambda: all(p.get_subscription_count() > 0 for p in pubs.values()), 10, spin, "recorder subs")
        sent = [(STATUS, status(DiagnosticStatus.WARN, "low margin"))]
        for i in range(5):
            sent.append((ODOM, odometry(i)))
        sent += [(FAILURE, Bool(data=True)), (TRAJ, trajectory())]
        for topic, msg in sent[1:]:
            pubs[topic].publish(msg)
        wait_for(lambda: recorder.message_count == len(sent), 10, spin, "all messages recorded")
        assert recorder.recorded_topics == sorted(pubs)
        log = recorder.log_path
        assert log.parent == tmp_path and re.fullmatch(rf"helireach_\d{{8}}_\d{{6}}_{os.getpid()}\.mcap", log.name)
    finally:
        executor.shutdown()
        recorder.destroy_node()  # finishes the file
        talker.destroy_node()

    # 1. Our reader: order, exact CDR bytes, offered QoS, metadata.
    logged = list(read_log(log))
    assert [m.log_time_ns for m in logged] == sorted(m.log_time_ns for m in logged)
    by_topic: dict[str, list[bytes]] = {}
    for m in logged:
        by_topic.setdefault(m.topic, []).append(m.cdr)
    for topic in pubs:
        # Compare messages, not bytes: serialize_message() pads to 4 bytes, rmw's wire form does not.
        expected = [msg for t, msg in sent if t == topic]
        assert [deserialize_message(cdr, type(expected[0])) for cdr in by_topic[topic]] == expected
    qos = {m.topic: m.qos for m in logged}
    assert qos[STATUS] == LATCHED and qos[ODOM] == VOLATILE and qos[FAILURE] == VOLATILE
    odom = [deserialize_message(cdr, Odometry) for cdr in by_topic[ODOM]]
    assert [o.pose.pose.position.x for o in odom] == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert all(m.publish_time_ns > 0 for m in logged)
    meta = read_log_metadata(log)
    # What it was handed wins over what the recorder knows itself (its aircraft and settings parameters).
    assert meta["helireach"].items() >= metadata.items()
    assert {"airframe_digest", "planner_settings", "gross_weight_n", "density_altitude_m"} <= set(meta["helireach"])
    bag = yaml.safe_load(meta["rosbag2"]["serialized_metadata"])
    assert bag["version"] == 9 and bag["message_count"] == len(sent) and bag["relative_file_paths"] == [log.name]

    # 2. The mcap library with the ros2 decoder.
    with open(log, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == len(sent)
        schemas = {s.name: s for s in summary.schemas.values()}
        assert schemas["nav_msgs/msg/Odometry"].encoding == "ros2msg"
        assert schemas["nav_msgs/msg/Odometry"].data.decode() == message_definition("nav_msgs/msg/Odometry")[1]
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
        decoded = {}
        for _, channel, _, msg in reader.iter_decoded_messages():
            decoded.setdefault(channel.topic, []).append(msg)
    assert [o.twist.twist.linear.x for o in decoded[ODOM]] == [30.0, 30.5, 31.0, 31.5, 32.0]
    assert decoded[STATUS][0].values[0].value == "12.5" and decoded[STATUS][0].hardware_id == "R22"
    assert decoded[TRAJ][0].points[2].positions[1] == 80.0 and decoded[FAILURE][0].data is True

    # 3. rosbags, an independent implementation.
    rb_qos, rb_messages = rosbags_messages(log, tmp_path)
    assert rb_qos[STATUS].durability.name == "TRANSIENT_LOCAL" and rb_qos[STATUS].depth == 1
    assert rb_qos[ODOM].durability.name == "VOLATILE" and rb_qos[ODOM].reliability.name == "RELIABLE"
    rb_odom = [msg for topic, msg in rb_messages if topic == ODOM]
    assert [o.pose.pose.position.z for o in rb_odom] == [150.0, 149.0, 148.0, 147.0, 146.0]
    assert [msg.joint_names for topic, msg in rb_messages if topic == TRAJ] == [["x", "h", "u"]]


def test_recorder_reports_a_publisher_it_cannot_hear_with_one_event_handler_per_topic(
    ros_context: Context, tmp_path: Path
) -> None:
    """A best-effort publisher appearing on a topic the recorder subscribed reliably is an ERROR line (its messages
    are not logged); the recorder registers one QoS-event handler per recorded topic, not rclpy's default set."""
    ctx = ros_context
    talker = Node("talker", context=ctx)
    reliable = talker.create_publisher(Bool, FAILURE, qos_profile(VOLATILE))
    recorder = McapRecorder(context=ctx, parameter_overrides=[Parameter("log_dir", value=str(tmp_path))])
    listener = Node("rosout_listener", context=ctx)
    errors: list[str] = []
    listener.create_subscription(
        Log, "/rosout", lambda log: errors.append(log.msg) if log.name == recorder.get_name() else None, 100
    )
    executor = SingleThreadedExecutor(context=ctx)
    for node in (talker, recorder, listener):
        executor.add_node(node)

    def spin() -> None:
        executor.spin_once(timeout_sec=0.05)

    try:
        wait_for(lambda: reliable.get_subscription_count() > 0, 10, spin, "the recorder's subscription")
        assert recorder.recorded_topics == [FAILURE]
        assert len(recorder._subscriptions_by_topic[FAILURE].event_handlers) == 1  # incompatible QoS only
        talker.create_publisher(Bool, FAILURE, QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        wait_for(lambda: any("incompatible QoS" in text for text in errors), 10, spin, "the recorder's error")
    finally:
        executor.shutdown()
        for node in (recorder, talker, listener):
            node.destroy_node()
    assert any(FAILURE in text and "RELIABILITY" in text for text in errors), errors


def test_recorder_bounds_message_size_and_the_log_says_what_it_lacks(ros_context: Context, tmp_path: Path) -> None:
    """Messages over ``max_message_bytes`` are not written; the log's metadata counts them per topic."""
    ctx = ros_context
    talker = Node("talker", context=ctx)
    publisher = talker.create_publisher(JointState, ROTOR, qos_profile(VOLATILE))
    recorder = McapRecorder(
        context=ctx,
        parameter_overrides=[Parameter("log_dir", value=str(tmp_path)), Parameter("max_message_bytes", value=4096)],
    )
    executor = SingleThreadedExecutor(context=ctx)
    for node in (talker, recorder):
        executor.add_node(node)

    def spin() -> None:
        executor.spin_once(timeout_sec=0.05)

    try:
        wait_for(lambda: publisher.get_subscription_count() > 0, 10, spin, "the recorder's subscription")
        small = JointState(name=["main_rotor"], velocity=[27.0])
        large = JointState(name=["main_rotor"], velocity=[27.0] * 1000)  # 8 kB
        for message in (small, large, small, large, large):
            publisher.publish(message)
        wait_for(lambda: recorder.message_count == 2 and sum(recorder.oversized_counts.values()) == 3, 10, spin, "")
    finally:
        executor.shutdown()
        for node in (recorder, talker):
            node.destroy_node()
    assert [len(deserialize_message(m.cdr, JointState).velocity) for m in read_log(recorder.log_path)] == [1, 1]
    assert read_log_metadata(recorder.log_path)["helireach"]["oversized_dropped"] == f"{ROTOR}:3"


def talker_in(ctx: Context) -> tuple[Node, SingleThreadedExecutor]:
    node = Node("talker", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    return node, executor


def test_recorder_process_finishes_file_on_sigterm(cross_process_env: dict[str, str], tmp_path: Path) -> None:
    proc = start_recorder(cross_process_env, tmp_path)
    ctx = Context()
    rclpy.init(context=ctx)
    node, executor = talker_in(ctx)
    try:
        odom_pub = node.create_publisher(Odometry, ODOM, qos_profile(BURST))
        fail_pub = node.create_publisher(Bool, FAILURE, qos_profile(BURST))
        wait_for(
            lambda: odom_pub.get_subscription_count() > 0 and fail_pub.get_subscription_count() > 0,
            CROSS_PROCESS_TIMEOUT_S,
            lambda: executor.spin_once(timeout_sec=0.05),
            "the recorder process to subscribe",
        )
        for i in range(12):
            odom_pub.publish(odometry(i))
        fail_pub.publish(Bool(data=True))
        log = one_log(tmp_path, proc)
        wait_on_disk(log, 13)  # the recorder's 1 s flush period writes even the open chunk
    finally:
        output = stop(proc, signal.SIGTERM)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 0, output
    with open(log, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None, "SIGTERM must leave a finished file"
        counts = {}
        for _, channel, _ in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts == {ODOM: 12, FAILURE: 1}
    assert sum(summary.statistics.channel_message_counts.values()) == 13


def test_recorder_killed_leaves_completed_chunks_readable(cross_process_env: dict[str, str], tmp_path: Path) -> None:
    # A 2 KiB chunk holds 3 odometry messages (the first also the schema, so 1 message): 41 messages
    # leave the last one in an open chunk. No periodic flush: only completed chunks reach the disk.
    proc = start_recorder(cross_process_env, tmp_path, "chunk_size:=2048", "flush_period:=0.0")
    ctx = Context()
    rclpy.init(context=ctx)
    node, executor = talker_in(ctx)
    sent = [odometry(i) for i in range(41)]
    try:
        odom_pub = node.create_publisher(Odometry, ODOM, qos_profile(BURST))
        wait_for(
            lambda: odom_pub.get_subscription_count() > 0,
            CROSS_PROCESS_TIMEOUT_S,
            lambda: executor.spin_once(timeout_sec=0.05),
            "the recorder process to subscribe",
        )
        for msg in sent:
            odom_pub.publish(msg)
        log = one_log(tmp_path, proc)
        wait_on_disk(log, len(sent) - 3)
        on_disk = count_readable(log)
    finally:
        stop(proc, signal.SIGKILL)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == -signal.SIGKILL

    # The file has no summary/footer: the strict reader refuses it, naming the file...
    with pytest.raises(McapLogError, match=re.escape(str(log))):
        read_log(log)
    # ...the mcap library's seeking reader cannot open it either (it starts from the footer)...
    with open(log, "rb") as f, pytest.raises(McapError):
        list(make_reader(f).iter_messages())
    # ...while sequential readers recover every completed chunk.
    recovered = list(read_log(log, allow_truncated=True))
    assert on_disk <= len(recovered) < len(sent)
    assert [deserialize_message(m.cdr, Odometry) for m in recovered] == sent[: len(recovered)]
    streamed = []
    with open(log, "rb") as f:
        try:
            for _, _, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                streamed.append(bytes(message.data))
        except Exception:  # the incomplete tail ends the stream
            pass
    assert streamed == [m.cdr for m in recovered]


# --- replay ----------------------------------------------------------------------------------------


def test_replay_republishes_same_bytes_and_keeps_latching(ros_context: Context, tmp_path: Path) -> None:
    ctx = ros_context
    log = tmp_path / "flight.mcap"
    written = write_log(log)
    listener = Node("listener", context=ctx)
    received: list[tuple[str, bytes]] = []
    lock = threading.Condition()

    def keep(topic: str) -> Callable[[bytes], None]:
        def callback(data: bytes) -> None:
            with lock:
                received.append((topic, data))
                lock.notify_all()

        return callback

    listener.create_subscription(Odometry, ODOM, keep(ODOM), qos_profile(VOLATILE), raw=True)
    listener.create_subscription(DiagnosticStatus, STATUS, keep(STATUS), qos_profile(LATCHED), raw=True)
    player = Node("player", context=ctx)
    late_node = Node("late", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(listener)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        started = time.monotonic()
        count = replay_log(log, rate=1.0, node=player, context=ctx)
        elapsed = time.monotonic() - started
        assert count == len(written)
        with lock:
            assert lock.wait_for(lambda: len(received) == len(written), timeout=10), received
            assert sorted(received) == sorted((topic, cdr) for topic, cdr, _ in written)
        assert elapsed >= 0.9 * 0.2  # five odometry messages 40 ms apart after the status

        # Latched: a subscriber joining after the replay still gets the last status.
        assert player.get_publishers_info_by_topic(STATUS)[0].qos_profile.durability == (
            DurabilityPolicy.TRANSIENT_LOCAL
        )
        late: list[bytes] = []
        got_late = threading.Event()

        def late_callback(data: bytes) -> None:
            late.append(data)
            got_late.set()

        late_node.create_subscription(DiagnosticStatus, STATUS, late_callback, qos_profile(LATCHED), raw=True)
        executor.add_node(late_node)
        assert got_late.wait(timeout=10), "latched status not delivered to a late subscriber"
        assert late == [written[0][1]]

        # As fast as possible, one topic only.
        assert replay_log(log, rate=0, node=player, topics=[ODOM], context=ctx) == 5
    finally:
        executor.shutdown()
        spinner.join(timeout=5)
        for node in (listener, player, late_node):
            node.destroy_node()


def test_replay_rejects_damaged_log(ros_context: Context, tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 40)
    with pytest.raises(McapLogError, match=re.escape(str(bad))):
        replay_log(bad, context=ros_context)


def test_replay_command_line(tmp_path: Path) -> None:
    log = tmp_path / "flight.mcap"
    write_log(log)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="OFF")
    command = [sys.executable, "-m", "helireach_ros.ros.replay"]
    done = subprocess.run(
        [*command, str(log), "--rate", "0", "--topics", ODOM], cwd=REPO, env=env, capture_output=True, timeout=30
    )
    assert done.returncode == 0, done.stderr
    assert f"replayed 5 messages from {log}" in done.stdout.decode()
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a log")
    done = subprocess.run([*command, str(bad)], cwd=REPO, env=env, capture_output=True, timeout=30)
    assert done.returncode == 1 and str(bad) in done.stderr.decode()
