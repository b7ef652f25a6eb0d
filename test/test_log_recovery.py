"""Crash-safe logs: one rosbag2 record, the time-based chunk close, recovery of a killed recorder's file
(``helireach log recover``), the metadata a standalone recorder writes, and the bringup's recorder-first start.

Independent checks: mcap's seeking (indexed) reader and ``rosbags``. Cross-process tests use LOCALHOST discovery
on a domain of their own (conftest); waits are "poll until a condition holds, with a deadline".
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
import yaml
from mcap.reader import make_reader
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Bool
from test_mcap_log import (
    BURST,
    ODOM,
    VOLATILE,
    count_readable,
    odometry,
    rosbags_messages,
    talker_in,
    wait_for,
    write_log,
)

from helireach_ros.cli.main import main as helireach_main
from helireach_ros.core.mcap_log import (
    McapLogError,
    McapLogWriter,
    is_finished_log,
    log_damage,
    read_log,
    read_log_metadata,
    recover_log,
)
from helireach_ros.core.mcap_log.run_metadata import status_metadata_updates
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.recorder import qos_profile

pytestmark = [pytest.mark.system]

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
TIMEOUT_S = 40.0
FLAG = "/vehicle/engine_failure"


def metadata_names(log: Path) -> list[str]:
    with open(log, "rb") as stream:
        return [record.name for record in make_reader(stream).iter_metadata()]


def indexed_messages(log: Path) -> list[tuple[str, bytes, int]]:
    """(topic, data, log time) through mcap's seeking reader: needs summary, index and footer."""
    with open(log, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_summary() is not None
        return [(c.topic, bytes(m.data), m.log_time) for _, c, m in reader.iter_messages(log_time_order=True)]


def killed_copy(tmp_path: Path, name: str = "killed.mcap") -> tuple[Path, list[tuple[str, bytes, int]]]:
    """A log as a SIGKILL leaves it: the bytes on disk while the writer is still open (no summary/footer)."""
    path = tmp_path / "open.mcap"
    cdr = serialize_message(Bool(data=True))
    t0 = 1_700_000_000_000_000_000
    written = [(FLAG, cdr, t0 + i * 10_000_000) for i in range(70)]  # the last 10 stay in the open chunk
    writer = McapLogWriter(path, metadata={"airframe": "uh60a_class"}, chunk_size=1024, max_chunk_age=None)
    writer.add_topic(FLAG, "std_msgs/msg/Bool", VOLATILE)
    for k, (topic, data, stamp) in enumerate(written):
        if k == 20:
            writer.update_metadata({"envelope_id": "hv-1"})  # learnt during the run (a metadata record ends a chunk)
        writer.write(topic, data, stamp)
    killed = tmp_path / name
    killed.write_bytes(path.read_bytes())
    writer.close()
    return killed, written


# --- writer -------------------------------------------------------------------------------------------------------


def test_a_finished_log_has_exactly_one_rosbag2_record_with_the_true_duration(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    written = write_log(log)
    assert metadata_names(log).count("rosbag2") == 1
    bag = yaml.safe_load(read_log_metadata(log)["rosbag2"]["serialized_metadata"])
    stamps = [stamp for _, _, stamp in written]
    assert bag["duration"]["nanoseconds"] == max(stamps) - min(stamps) > 0
    assert bag["starting_time"]["nanoseconds_since_epoch"] == min(stamps)
    assert bag["message_count"] == len(written) and bag["custom_data"] == {"airframe": "R22"}


def test_the_open_chunk_is_written_once_its_oldest_message_is_max_chunk_age_old(tmp_path: Path) -> None:
    log = tmp_path / "age.mcap"
    cdr = serialize_message(Bool(data=True))
    with McapLogWriter(log, chunk_size=1 << 20, max_chunk_age=0.05) as writer:
        writer.add_topic(FLAG, "std_msgs/msg/Bool", VOLATILE)
        writer.write(FLAG, cdr, 1)
        assert count_readable(log) == 0  # a young chunk stays in memory (the size limit is far)
        assert not writer.flush_stale()
        time.sleep(0.06)  # monotonic time passes max_chunk_age: no timing threshold is asserted
        assert writer.flush_stale()  # the idle path (the recorder's timer)
        assert count_readable(log) == 1
        writer.write(FLAG, cdr, 2)
        time.sleep(0.06)
        writer.write(FLAG, cdr, 3)  # the busy path: the write that finds the chunk old completes it
        assert count_readable(log) == 3
    with pytest.raises(ValueError, match="max_chunk_age"):
        McapLogWriter(tmp_path / "bad.mcap", max_chunk_age=float("nan"))


# --- recovery -----------------------------------------------------------------------------------------------------


def test_recover_log_rewrites_a_killed_file_into_a_finished_indexed_one(tmp_path: Path) -> None:
    killed, written = killed_copy(tmp_path)
    assert not is_finished_log(killed)
    assert "rosbag2" not in read_log_metadata(killed, allow_truncated=True)  # written once, at close
    report = recover_log(killed)
    assert report.output == tmp_path / "killed.recovered.mcap" and is_finished_log(report.output)
    recovered = indexed_messages(report.output)
    on_disk = list(read_log(killed, allow_truncated=True))
    assert 0 < len(recovered) == len(on_disk) == report.messages < len(written)  # the open chunk was lost
    assert recovered == written[: len(recovered)]
    assert (report.start_ns, report.end_ns) == (written[0][2], recovered[-1][2])
    assert metadata_names(report.output).count("rosbag2") == 1
    assert metadata_names(report.output).count("helireach") == 1
    metadata = read_log_metadata(report.output)
    assert metadata["helireach"] == {"airframe": "uh60a_class", "envelope_id": "hv-1"}  # the last record won
    bag = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])
    assert bag["message_count"] == len(recovered) and bag["duration"]["nanoseconds"] == report.end_ns - report.start_ns
    _, rosbags_view = rosbags_messages(report.output, tmp_path)
    assert [message.data for _, message in rosbags_view] == [True] * len(recovered)
    assert "recovered" in report.describe() and str(report.output) in report.describe()

    with pytest.raises(McapLogError, match="output exists"):
        recover_log(killed)
    with pytest.raises(McapLogError, match="finished"):
        recover_log(report.output, tmp_path / "again.mcap")
    with pytest.raises(McapLogError, match="new file"):
        recover_log(killed, killed)


def test_recovery_reports_a_chunk_cut_in_the_middle(tmp_path: Path) -> None:
    killed, written = killed_copy(tmp_path)
    data = killed.read_bytes()
    offset, chunks = 8, []  # walk the top-level records (opcode, u64 length) after the magic
    while offset < len(data):
        if data[offset] == 0x06:
            chunks.append(offset)
        offset += 9 + int.from_bytes(data[offset + 1 : offset + 9], "little")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: chunks[-1] + 100])  # inside the last complete chunk, as a truncated copy ends
    report = recover_log(cut)
    assert report.dropped_bytes == 100 and report.dropped_span_ns is not None
    start, end = report.dropped_span_ns
    assert report.end_ns < start <= end <= written[-1][2]
    assert "incomplete record of 100 bytes" in report.describe()


def damaged_finished_log(tmp_path: Path) -> tuple[Path, list[tuple[str, bytes, int]], tuple[int, int]]:
    """A finished (closed) log with 8 bytes overwritten inside its second chunk; returns it, what was written and
    the log-time span of the damaged chunk (from the summary's chunk index, read before the damage)."""
    path = tmp_path / "finished.mcap"
    cdr = serialize_message(Bool(data=True))
    t0 = 1_700_000_000_000_000_000
    written = [(FLAG, cdr, t0 + i * 10_000_000) for i in range(70)]
    with McapLogWriter(path, metadata={"airframe": "uh60a_class"}, chunk_size=1024, max_chunk_age=None) as writer:
        writer.add_topic(FLAG, "std_msgs/msg/Bool", VOLATILE)
        for topic, data, stamp in written:
            writer.write(topic, data, stamp)
    data = bytearray(path.read_bytes())
    offset, chunks = 8, []
    while offset < len(data) and data[offset] != 0x0F:  # the data section's records, up to DataEnd
        if data[offset] == 0x06:
            chunks.append(offset)
        offset += 9 + int.from_bytes(data[offset + 1 : offset + 9], "little")
    with open(path, "rb") as stream:
        index = next(i for i in make_reader(stream).get_summary().chunk_indexes if i.chunk_start_offset == chunks[1])
    lost_span = (index.message_start_time, index.message_end_time)
    second_length = int.from_bytes(data[chunks[1] + 1 : chunks[1] + 9], "little")
    middle = chunks[1] + 9 + second_length // 2
    data[middle : middle + 8] = bytes(8) if data[middle : middle + 8] != bytes(8) else b"\xff" * 8
    path.write_bytes(bytes(data))
    assert len(chunks) >= 3
    return path, written, lost_span


def test_a_finished_log_with_a_damaged_chunk_is_salvaged_and_never_read_in_part_silently(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    damaged, written, (lost_start, lost_end) = damaged_finished_log(tmp_path)
    assert is_finished_log(damaged)
    damage = log_damage(damaged)
    assert len(damage) == 1 and "damaged chunk" in damage[0] and FLAG in damage[0] and "messages from" in damage[0]
    with pytest.raises(McapLogError, match=r"damaged MCAP data.*log recover"):
        list(read_log(damaged, allow_truncated=True))  # not a silent early end
    report = recover_log(damaged)
    kept = [message for message in written if not lost_start <= message[2] <= lost_end]
    assert report.damaged == tuple(damage) and 0 < report.messages == len(kept) < len(written)
    assert indexed_messages(report.output) == kept  # every intact chunk, in order; only the damaged one is lost
    assert f"lost: {damage[0]}" in report.describe() and not log_damage(report.output)
    assert helireach_main(["log", "recover", str(damaged), str(tmp_path / "again.mcap")]) == 0
    assert "damaged chunk" in capsys.readouterr().out
    with pytest.raises(McapLogError, match="log is damaged: a damaged chunk"):
        from helireach_ros.ros.replay import check_playback

        check_playback(damaged, 1.0, None, 0.0, allow_truncated=True)


def test_log_recover_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    killed, _ = killed_copy(tmp_path)
    out = tmp_path / "fixed.mcap"
    assert helireach_main(["log", "recover", str(killed), str(out)]) == 0
    assert f"into {out}" in capsys.readouterr().out and is_finished_log(out)
    assert helireach_main(["log", "recover", str(killed), str(out)]) == 2  # exists
    assert "--force" in capsys.readouterr().err
    assert helireach_main(["log", "recover", str(killed), str(out), "--force"]) == 0
    assert helireach_main(["log", "recover", str(out)]) == 0
    assert "already finished" in capsys.readouterr().out
    assert helireach_main(["log", "recover", str(tmp_path / "missing.mcap")]) == 2


def test_a_recorder_killed_with_sigkill_loses_at_most_one_second(localhost_ros_domain: int, tmp_path: Path) -> None:
    """The real recorder process (default flush policy), a talker at 50 Hz, kill -9, `helireach log recover`."""
    topics = f"['{ODOM}:nav_msgs/msg/Odometry']"
    recorder = subprocess.Popen(
        [str(BIN / "helireach_recorder"), "--ros-args", "-p", f"log_dir:={tmp_path}", "-p", f"topics:={topics}"],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    context = Context()
    rclpy.init(context=context)
    node, executor = talker_in(context)
    sent: list[Odometry] = []
    try:
        publisher = node.create_publisher(Odometry, ODOM, qos_profile(BURST))
        wait_for(
            lambda: publisher.get_subscription_count() > 0,
            TIMEOUT_S,
            lambda: executor.spin_once(timeout_sec=0.05),
            "the recorder process to subscribe",
        )
        deadline = time.monotonic() + 2.5
        while time.monotonic() < deadline:
            sent.append(odometry(len(sent)))
            publisher.publish(sent[-1])
            executor.spin_once(timeout_sec=0.02)
        time.sleep(0.05)  # the last messages cross the wire (they are then in the recorder's open chunk)
        killed_at_ns = time.time_ns()
        recorder.send_signal(signal.SIGKILL)
        recorder.wait(timeout=10)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert recorder.returncode == -signal.SIGKILL
    (log,) = tmp_path.glob("*.mcap")
    assert not is_finished_log(log)
    out = tmp_path / "recovered" / "run.mcap"
    out.parent.mkdir()
    assert helireach_main(["log", "recover", str(log), str(out)]) == 0
    recovered = indexed_messages(out)  # mcap's seeking reader: summary, index, footer
    assert recovered and [deserialize_message(data, Odometry) for _, data, _ in recovered] == sent[: len(recovered)]
    assert killed_at_ns - recovered[-1][2] <= 1_000_000_000, "more than 1 s of messages lost"
    _, rosbags_view = rosbags_messages(out, tmp_path)
    assert len(rosbags_view) == len(recovered)


# --- metadata -----------------------------------------------------------------------------------------------------


def test_status_values_update_the_metadata_by_the_documented_rules() -> None:
    known = {"airframe": "uh60a_class", "airframe_digest": "abc", "gross_weight_n": "70000.0", "envelope_id": ""}
    assert status_metadata_updates(known, {"envelope_id": "hv-1"}, "safety_status") == {"envelope_id": "hv-1"}
    assert status_metadata_updates({**known, "envelope_id": "hv-1"}, {"envelope_id": "hv-1"}, "safety_status") == {}
    same = {"airframe": "uh60a_class", "gross_weight_n": "7.0e4", "envelope_id": "hv-2"}
    assert status_metadata_updates(known, same, "plan_status") == {"envelope_id": "hv-2"}
    heavier = {"airframe": "uh60a_class", "gross_weight_n": "77700.0"}
    assert status_metadata_updates(known, heavier, "plan_status") == {**heavier, "airframe_digest": ""}


def test_a_standalone_recorder_writes_the_metadata_replay_compare_needs(
    localhost_ros_domain: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Multi-process: `helireach_recorder` in its own process beside `helireach bringup --with-sim --no-record`."""
    params = ["--params-file", str(REPO / "config" / "nodes.yaml"), "-p", f"helireach_recorder:log_dir:={tmp_path}"]
    recorder_stderr = tmp_path / "recorder.stderr"  # its traceback, should it exit with an error
    with recorder_stderr.open("wb") as stderr_file:  # the child keeps its own descriptor
        recorder = subprocess.Popen(
            [str(BIN / "helireach_recorder"), "--ros-args", *params],
            cwd=REPO,
            stdout=subprocess.DEVNULL,
            stderr=stderr_file,
        )
    bringup = subprocess.Popen(
        [str(BIN / "helireach"), "bringup", "--with-sim", "--no-record"],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(lambda: len(list(tmp_path.glob("*.mcap"))) == 1, TIMEOUT_S, lambda: time.sleep(0.1), "the log")
        (log,) = tmp_path.glob("*.mcap")

        def first_plan_on_disk() -> bool:
            try:
                return any(m.topic == rm.TOPIC_PLAN_STATUS for m in read_log(log, allow_truncated=True))
            except McapLogError:
                return False

        wait_for(first_plan_on_disk, 3 * TIMEOUT_S, lambda: time.sleep(0.2), "a plan status in the log")
        time.sleep(1.0)  # the trajectory published with it reaches the disk too (flush policy: < 1 s)
    finally:
        for process in (recorder, bringup):
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        for process in (recorder, bringup):
            try:
                process.wait(timeout=TIMEOUT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
    assert recorder.returncode == 0, recorder_stderr.read_text()[-3000:]
    assert is_finished_log(log)
    metadata = read_log_metadata(log)["helireach"]
    assert metadata["airframe"] == "uh60a_class" and metadata["planner_settings"] and metadata["airframe_digest"]
    statuses = [m for m in read_log(log) if m.topic == rm.TOPIC_SAFETY_STATUS]
    from diagnostic_msgs.msg import DiagnosticStatus

    logged_ids = {rm.status_values(deserialize_message(m.cdr, DiagnosticStatus))["envelope_id"] for m in statuses}
    assert metadata["envelope_id"] and metadata["envelope_id"] in logged_ids
    capsys.readouterr()
    assert helireach_main(["replay", str(log), "--compare"]) == 0
    assert "1 of 1 logged plans reproduced" in capsys.readouterr().out


# --- bringup ------------------------------------------------------------------------------------------------------


def test_the_bringup_records_the_simulated_vehicle_from_its_first_message(
    no_ros_discovery: None, tmp_path: Path
) -> None:
    from helireach_ros.ros.bringup import build_system

    system = build_system(
        with_sim=True, log_dir=tmp_path, context=Context(), ros_args=["-p", "helireach_planner:warm_up:=false"]
    )
    try:
        assert system.recorder is not None and system.sim is not None
        assert {rm.TOPIC_ODOMETRY, rm.TOPIC_ROTOR, rm.TOPIC_ENGINE_FAILURE} <= set(system.recorder.recorded_topics)
        assert system.recorder.wait_until_recording(0.0), "built, but the recorder has not matched every publisher"
        system.spin_until(lambda: system.recorder.message_count > 50, TIMEOUT_S)
    finally:
        system.shutdown()
    odometry_log = [m for m in read_log(system.log_path) if m.topic == rm.TOPIC_ODOMETRY]
    first = deserialize_message(odometry_log[0].cdr, Odometry)
    assert rm.stamp_nanoseconds(first.header.stamp) == system.sim.start_ns, "the vehicle's first message is missing"
    assert metadata_names(system.log_path).count("rosbag2") == 1
    assert os.path.getsize(system.log_path) > 0


def test_a_recorder_with_a_broken_airframe_still_records_and_says_less(no_ros_discovery: None, tmp_path: Path) -> None:
    from rclpy.parameter import Parameter

    from helireach_ros.ros.nodes.recorder import McapRecorder

    context = Context()
    rclpy.init(context=context)
    overrides = [Parameter("log_dir", value=str(tmp_path)), Parameter("airframe", value="no_such_airframe")]
    try:
        recorder = McapRecorder(context=context, parameter_overrides=overrides)
        recorder.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    metadata = read_log_metadata(recorder.log_path)["helireach"]
    assert metadata["software_version"] and "airframe_digest" not in metadata and "planner_settings" not in metadata
