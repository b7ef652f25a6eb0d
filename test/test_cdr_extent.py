"""The end of a CDR message's content, read from its schema: the log cuts the bytes the ROS 2 serializer leaves
after messages with empty sequences, and every reader (rclpy, rosbags) still decodes what is kept."""

from __future__ import annotations

import random

import pytest
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty, Float64MultiArray, MultiArrayDimension, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from helireach_ros.core.mcap_log import read_log
from helireach_ros.core.mcap_log.cdr_extent import CdrLayoutError, cdr_extent, parse_ros2msg_layout
from helireach_ros.core.mcap_log.records import QosDescription
from helireach_ros.core.mcap_log.schemas import message_definition
from helireach_ros.core.mcap_log.writer import McapLogWriter

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def _type_name(message) -> str:
    module = type(message).__module__.split(".")[0]
    return f"{module}/msg/{type(message).__name__}"


def _layout(type_name: str):
    return parse_ros2msg_layout(type_name, message_definition(type_name)[1])


def _values(rng: random.Random, length: int) -> list[float]:
    return [rng.uniform(-1.0, 1.0) for _ in range(length)]


def _random_messages(rng: random.Random) -> list:
    """Messages with sequences that are empty or not, strings of every length modulo 4, nesting and fixed arrays."""
    trajectory = JointTrajectory(joint_names=["thrust_coefficient", "pitch_angle"][: rng.randint(0, 2)])
    for index in range(rng.randint(0, 5)):
        point = JointTrajectoryPoint(
            positions=_values(rng, rng.randint(0, 2)), velocities=_values(rng, rng.randint(0, 1))
        )
        point.time_from_start = Duration(sec=index, nanosec=rng.randint(0, 999_999_999))
        trajectory.points.append(point)
    array = Float64MultiArray(data=_values(rng, rng.randint(0, 3)))
    array.layout.dim = [MultiArrayDimension(label="x" * rng.randint(0, 5), size=2, stride=2)][: rng.randint(0, 1)]
    diagnostics = DiagnosticArray(
        status=[
            DiagnosticStatus(
                name="n" * rng.randint(0, 7),
                message="m" * rng.randint(0, 7),
                values=[KeyValue(key="k" * rng.randint(0, 3), value="v" * rng.randint(0, 9))] * rng.randint(0, 2),
            )
        ]
        * rng.randint(0, 3)
    )
    joints = JointState(
        name=["rotor"] * rng.randint(0, 1),
        velocity=_values(rng, rng.randint(0, 1)),
        effort=_values(rng, rng.randint(0, 1)),
    )
    path = Path(poses=[PoseStamped()] * rng.randint(0, 3))
    return [trajectory, array, diagnostics, joints, path, Odometry(), Empty(), String(data="s" * rng.randint(0, 6))]


def test_the_content_of_rclpy_messages_is_what_rosbags_writes_and_every_reader_decodes_it() -> None:
    rng = random.Random(20261204)
    left_over = 0
    for _ in range(40):
        for message in _random_messages(rng):
            type_name = _type_name(message)
            serialized = serialize_message(message)
            extent = cdr_extent(_layout(type_name), serialized)
            content = serialized[:extent]
            left_over += len(serialized) - extent
            decoded = TYPESTORE.deserialize_cdr(content, type_name)  # raises on a size mismatch
            assert len(TYPESTORE.serialize_cdr(decoded, type_name)) == extent
            assert deserialize_message(content, type(message)) == message
    assert left_over > 0, "the serializer leaves bytes after empty sequences: the case this exists for"


def test_big_endian_messages_are_laid_out_too() -> None:
    point = TYPESTORE.types["trajectory_msgs/msg/JointTrajectoryPoint"]
    duration = TYPESTORE.types["builtin_interfaces/msg/Duration"]
    import numpy as np

    empty = np.array([], dtype=np.float64)
    message = point(
        positions=np.array([1.0, 2.0]), velocities=empty, accelerations=empty, effort=empty,
        time_from_start=duration(sec=1, nanosec=2),
    )  # fmt: skip
    big_endian = bytes(
        TYPESTORE.serialize_cdr(message, "trajectory_msgs/msg/JointTrajectoryPoint", little_endian=False)
    )
    assert big_endian[1] == 0
    assert cdr_extent(_layout("trajectory_msgs/msg/JointTrajectoryPoint"), big_endian + b"\xff" * 8) == len(big_endian)


def test_constants_bounded_types_and_fixed_arrays_in_a_schema() -> None:
    schema = "\n".join(
        [
            "# a comment line",
            "uint8 LEVEL=2  # a constant is not serialized",
            'string NAME = "x"',
            "uint8 level",
            "string<=8 label",
            "float64[<=3] bounded",
            "int16[2] pair",
            "Inner inner",
            "=" * 80,
            "MSG: demo_pkg/Inner",
            "bool flag",
        ]
    )
    layout = parse_ros2msg_layout("demo_pkg/msg/Outer", schema)
    header = b"\x00\x01\x00\x00"
    body = bytes([7]) + b"\x00" * 3 + (3).to_bytes(4, "little") + b"ab\x00"  # level, pad, label "ab"
    body += b"\x00" + (1).to_bytes(4, "little") + b"\x00" * 8  # pad to 4, count 1 (ends 8-aligned), a double
    body += b"\x01\x00\x02\x00" + b"\x01"  # int16[2], inner.flag
    assert cdr_extent(layout, header + body + b"junk") == len(header + body)


def test_what_cannot_be_laid_out_is_refused() -> None:
    with pytest.raises(CdrLayoutError, match="no definition"):
        parse_ros2msg_layout("demo_pkg/msg/Outer", "Missing field\n")
    with pytest.raises(CdrLayoutError, match="wstring"):
        parse_ros2msg_layout("demo_pkg/msg/Outer", "wstring text\n")
    layout = _layout("std_msgs/msg/String")
    with pytest.raises(CdrLayoutError, match="ends at byte"):
        cdr_extent(layout, serialize_message(String(data="hello"))[:9])
    with pytest.raises(CdrLayoutError, match="encapsulation"):
        cdr_extent(layout, b"\x00\x03\x00\x00abcd")  # XCDR2: not what ROS 2 writes


def test_the_log_keeps_the_content_and_keeps_a_malformed_message_whole(tmp_path) -> None:
    trajectory = JointTrajectory(points=[JointTrajectoryPoint(positions=[0.5])])
    serialized = serialize_message(trajectory)
    truncated = serialize_message(String(data="hello"))[:9]
    log = tmp_path / "log.mcap"
    with McapLogWriter(log) as writer:
        writer.add_topic("/trajectory", "trajectory_msgs/msg/JointTrajectory", QosDescription())
        writer.add_topic("/text", "std_msgs/msg/String", QosDescription())
        writer.write("/trajectory", serialized, 1)
        writer.write("/text", truncated, 2)
    stored = {message.topic: message.cdr for message in read_log(log)}
    assert len(serialized) > len(stored["/trajectory"])
    assert (
        TYPESTORE.deserialize_cdr(stored["/trajectory"], "trajectory_msgs/msg/JointTrajectory").points[0].positions[0]
        == 0.5
    )
    assert stored["/text"] == truncated
