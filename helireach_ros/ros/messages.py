"""Everything the nodes agree on: topic names, types and QoS, and conversions between messages and core types.

Conventions (REP-103, SI on the wire; see ``msg_docs/`` for each topic):

* ``nav_msgs/Odometry`` of the vehicle: ``pose.pose.position.z`` = height above ground (m),
  ``pose.pose.position.x`` = distance along the track (m), orientation = pitch attitude θ about +y
  (positive nose down, FLU); the twist is expressed in ``child_frame_id``, a gravity- and
  heading-aligned frame (``base_stabilized``): ``twist.linear.x`` = forward speed v (m/s),
  ``twist.linear.z`` = climb rate (m/s, positive up; the model's descent rate is y = −climb rate).
* ``sensor_msgs/JointState`` of the rotor: joint ``main_rotor``, ``velocity`` = Ω (rad/s); optional
  ``effort`` = the engine's drive torque referred to the rotor shaft (N m), so engine power P = τ Ω.
* ``trajectory_msgs/JointTrajectory`` of the landing: joints ``collective_thrust_coefficient`` (C_T)
  and ``pitch_angle`` (θ, rad), ``time_from_start`` from the plan's initial state, whose stamp is the
  header stamp. Zero-order-hold controls are encoded exactly with two points per interval
  (:func:`~helireach_ros.core.flight.simulation.piecewise_linear_controls`): linear interpolation between the
  points reproduces the plan.
* ``diagnostic_msgs/DiagnosticStatus``: ``values`` are strings; numbers in SI with the unit in the
  key (``height_m``), written with :func:`format_value` (round-trip precision).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from builtin_interfaces.msg import Duration as DurationMsg
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, Quaternion
from nav_msgs.msg import Odometry, Path
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.flight.simulation import piecewise_linear_controls
from helireach_ros.core.policies.vehicle_readings import OdometryReading, RotorReading
from helireach_ros.core.status_values import format_value

__all__ = [
    "COLLECTIVE_JOINT",
    "DEFAULT_BODY_FRAME",
    "DEFAULT_WORLD_FRAME",
    "DIAGNOSTIC_LEVELS",
    "EVENT_QOS",
    "LATCHED_QOS",
    "LEVEL_NAMES",
    "NO_QOS_EVENTS_PUBLISHER",
    "NO_QOS_EVENTS_SUBSCRIPTION",
    "PITCH_JOINT",
    "ROTOR_JOINT",
    "SENSOR_QOS",
    "STREAM_QOS",
    "TOPICS",
    "TOPIC_DIAGNOSTICS",
    "TOPIC_ENGINE_FAILURE",
    "TOPIC_FAILURE_EPISODE",
    "TOPIC_FAILURE_EVENT",
    "TOPIC_LANDING_PATH",
    "TOPIC_LANDING_SITES",
    "TOPIC_LANDING_TRAJECTORY",
    "TOPIC_LIVE_REACHABILITY",
    "TOPIC_MISSION_LANDING_SITES",
    "TOPIC_ODOMETRY",
    "TOPIC_PLAN_STATUS",
    "TOPIC_REACHABLE_FOOTPRINT",
    "TOPIC_READY",
    "TOPIC_ROBUST_VERDICT",
    "TOPIC_ROTOR",
    "TOPIC_ROTOR_STATE",
    "TOPIC_SAFETY_STATUS",
    "TOPIC_STATE",
    "TOPIC_TOUCHDOWN",
    "TopicSpec",
    "diagnostic_array",
    "diagnostic_status",
    "duration_message",
    "duration_seconds",
    "failure_flag",
    "format_value",
    "odometry_message",
    "path_message",
    "pitch_quaternion",
    "read_odometry",
    "read_rotor",
    "read_trajectory",
    "rotor_message",
    "stamp_message",
    "stamp_nanoseconds",
    "status_values",
    "trajectory_message",
]

# --- topics -------------------------------------------------------------------------------------------------
TOPIC_ODOMETRY = "/vehicle/odometry"
TOPIC_ROTOR = "/vehicle/rotor"
TOPIC_ENGINE_FAILURE = "/vehicle/engine_failure"
TOPIC_STATE = "/helireach/state"
TOPIC_ROTOR_STATE = "/helireach/rotor_state"
TOPIC_FAILURE_EVENT = "/helireach/failure_event"
TOPIC_FAILURE_EPISODE = "/helireach/failure_episode"
TOPIC_SAFETY_STATUS = "/helireach/safety_status"
TOPIC_LIVE_REACHABILITY = "/helireach/live_reachability"
TOPIC_REACHABLE_FOOTPRINT = "/helireach/reachable_footprint"
TOPIC_LANDING_SITES = "/helireach/landing_sites"
TOPIC_MISSION_LANDING_SITES = "/mission/landing_sites"  # an input: a mission manager's sites (landing_sites_topic)
TOPIC_LANDING_TRAJECTORY = "/helireach/landing_trajectory"
TOPIC_LANDING_PATH = "/helireach/landing_path"
TOPIC_PLAN_STATUS = "/helireach/plan_status"
TOPIC_ROBUST_VERDICT = "/helireach/robust_verdict"
TOPIC_TOUCHDOWN = "/helireach/touchdown"
TOPIC_DIAGNOSTICS = "/diagnostics"
TOPIC_READY = "/helireach/ready"

ROTOR_JOINT = "main_rotor"
COLLECTIVE_JOINT = "collective_thrust_coefficient"
PITCH_JOINT = "pitch_angle"
DEFAULT_WORLD_FRAME = "odom"
DEFAULT_BODY_FRAME = "base_stabilized"

# --- QoS ----------------------------------------------------------------------------------------------------
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""The current value of a state (safety status, the plan, touchdown): late joiners get it at once."""
STREAM_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Streams the helireach nodes and the simulated vehicle publish (state, rotor, diagnostics)."""
EVENT_QOS = STREAM_QOS
"""Events that must not be lost, published reliably: the engine-failure flag (sim) and the failure event (which
the planner and the display also *subscribe* reliably: a best-effort publisher of it is an incompatible-QoS ERROR)."""
SENSOR_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
"""What the nodes *subscribe* their inputs with (the vehicle's three topics, the canonical state, /diagnostics):
matches reliable and best-effort, volatile and transient-local publishers alike (``ros/qos.py`` says why)."""


# rclpy gives every publisher and subscription a QoS-event handler by default (it logs incompatible QoS); each
# one is a waitable the executor re-adds to its wait set on every wait, which in a composed process with a
# 25 Hz vehicle doubled the CPU time of the demo. The helireach nodes register only the incompatible-QoS
# callback, on their inputs and own outputs (helireach_ros.ros.qos.QosWatch); other endpoints use these.
NO_QOS_EVENTS_PUBLISHER: dict[str, Any] = {"event_callbacks": PublisherEventCallbacks(use_default_callbacks=False)}
"""``create_publisher`` keyword arguments: no QoS-event handler."""
NO_QOS_EVENTS_SUBSCRIPTION: dict[str, Any] = {
    "event_callbacks": SubscriptionEventCallbacks(use_default_callbacks=False)
}
"""``create_subscription`` keyword arguments: no QoS-event handler."""


@dataclass(frozen=True)
class TopicSpec:
    """The contract of one topic: type, publisher QoS, and which node publishes it."""

    name: str
    type_name: str
    qos: QoSProfile
    publisher: str


TOPICS: dict[str, TopicSpec] = {
    spec.name: spec
    for spec in (
        TopicSpec(TOPIC_ODOMETRY, "nav_msgs/msg/Odometry", STREAM_QOS, "helireach_sim_vehicle"),
        TopicSpec(TOPIC_ROTOR, "sensor_msgs/msg/JointState", STREAM_QOS, "helireach_sim_vehicle"),
        TopicSpec(TOPIC_ENGINE_FAILURE, "std_msgs/msg/Bool", EVENT_QOS, "helireach_sim_vehicle"),
        TopicSpec(TOPIC_STATE, "nav_msgs/msg/Odometry", STREAM_QOS, "helireach_monitor"),
        TopicSpec(TOPIC_ROTOR_STATE, "sensor_msgs/msg/JointState", STREAM_QOS, "helireach_monitor"),
        TopicSpec(TOPIC_FAILURE_EVENT, "std_msgs/msg/Header", EVENT_QOS, "helireach_monitor"),
        TopicSpec(TOPIC_FAILURE_EPISODE, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_monitor"),
        TopicSpec(
            TOPIC_SAFETY_STATUS, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_envelope_status"
        ),
        TopicSpec(TOPIC_LIVE_REACHABILITY, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_planner"),
        TopicSpec(TOPIC_REACHABLE_FOOTPRINT, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_planner"),
        TopicSpec(TOPIC_LANDING_SITES, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_planner"),
        TopicSpec(TOPIC_LANDING_TRAJECTORY, "trajectory_msgs/msg/JointTrajectory", LATCHED_QOS, "helireach_planner"),
        TopicSpec(TOPIC_LANDING_PATH, "nav_msgs/msg/Path", LATCHED_QOS, "helireach_planner"),
        TopicSpec(TOPIC_PLAN_STATUS, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_planner"),
        TopicSpec(TOPIC_ROBUST_VERDICT, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_planner"),
        TopicSpec(TOPIC_TOUCHDOWN, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_sim_vehicle"),
        TopicSpec(TOPIC_DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray", STREAM_QOS, "every helireach node"),
        TopicSpec(TOPIC_READY, "diagnostic_msgs/msg/DiagnosticStatus", LATCHED_QOS, "helireach_bringup"),
    )
}
"""Every topic of the system (defaults; all remappable)."""

LEVEL_NAMES = {
    DiagnosticStatus.OK: "OK",
    DiagnosticStatus.WARN: "WARN",
    DiagnosticStatus.ERROR: "ERROR",
    DiagnosticStatus.STALE: "STALE",
}
"""Human names of the DiagnosticStatus levels (which are ``bytes`` in rclpy)."""
#: DiagnosticStatus level per name (the core's verdicts name their level).
DIAGNOSTIC_LEVELS = {name: level for level, name in LEVEL_NAMES.items()}


# --- time ---------------------------------------------------------------------------------------------------
def stamp_nanoseconds(stamp: TimeMsg) -> int:
    """A ``builtin_interfaces/Time`` as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def stamp_message(nanoseconds: int) -> TimeMsg:
    """Integer nanoseconds as a ``builtin_interfaces/Time``."""
    seconds, remainder = divmod(int(nanoseconds), 1_000_000_000)
    return TimeMsg(sec=seconds, nanosec=remainder)


def duration_message(seconds: float) -> DurationMsg:
    """Seconds (≥ 0) as a ``builtin_interfaces/Duration``, rounded to the nanosecond."""
    whole, remainder = divmod(round(seconds * 1e9), 1_000_000_000)
    return DurationMsg(sec=int(whole), nanosec=int(remainder))


def duration_seconds(duration: DurationMsg) -> float:
    """A ``builtin_interfaces/Duration`` in seconds."""
    return duration.sec + duration.nanosec * 1e-9


def pitch_quaternion(pitch_angle: float) -> Quaternion:
    """The attitude of a pitch θ about +y (FLU: positive nose down), as a quaternion."""
    return Quaternion(x=0.0, y=math.sin(0.5 * pitch_angle), z=0.0, w=math.cos(0.5 * pitch_angle))


# --- vehicle state --------------------------------------------------------------------------------------------
def odometry_message(
    stamp_ns: int,
    height: float,
    distance: float,
    forward_speed: float,
    climb_rate: float,
    pitch_angle: float = 0.0,
    frame_id: str = DEFAULT_WORLD_FRAME,
    child_frame_id: str = DEFAULT_BODY_FRAME,
) -> Odometry:
    """A vehicle ``Odometry`` in the module's conventions (see the module docstring)."""
    message = Odometry()
    message.header.stamp = stamp_message(stamp_ns)
    message.header.frame_id = frame_id
    message.child_frame_id = child_frame_id
    message.pose.pose.position.x = float(distance)
    message.pose.pose.position.z = float(height)
    message.pose.pose.orientation = pitch_quaternion(pitch_angle)
    message.twist.twist.linear.x = float(forward_speed)
    message.twist.twist.linear.z = float(climb_rate)
    return message


def read_odometry(message: Odometry) -> OdometryReading:
    """The height, distance, forward speed and climb rate of a vehicle ``Odometry`` (not validated)."""
    return OdometryReading(
        stamp_nanoseconds(message.header.stamp),
        float(message.pose.pose.position.z),
        float(message.pose.pose.position.x),
        float(message.twist.twist.linear.x),
        float(message.twist.twist.linear.z),
    )


def rotor_message(
    stamp_ns: int, rotor_speed: float, engine_power: float | None = None, joint_name: str = ROTOR_JOINT
) -> JointState:
    """A rotor ``JointState``: velocity Ω, and effort = engine torque P/Ω when the power is known."""
    message = JointState()
    message.header.stamp = stamp_message(stamp_ns)
    message.name = [joint_name]
    message.velocity = [float(rotor_speed)]
    if engine_power is not None and rotor_speed > 0.0:
        message.effort = [float(engine_power) / float(rotor_speed)]
    return message


def read_rotor(message: JointState, joint_name: str = ROTOR_JOINT) -> RotorReading:
    """Ω and (if an effort is given) engine power P = τ Ω from a rotor ``JointState``.

    Raises:
        ValueError: the joint or its velocity is missing.
    """
    names = list(message.name)
    if joint_name not in names:
        raise ValueError(f"joint {joint_name!r} not in JointState names {names}")
    index = names.index(joint_name)
    if len(message.velocity) != len(names):
        raise ValueError(f"JointState has {len(message.velocity)} velocities for {len(names)} joints")
    rotor_speed = float(message.velocity[index])
    power = None
    if len(message.effort) == len(names):
        power = float(message.effort[index]) * rotor_speed
    return RotorReading(stamp_nanoseconds(message.header.stamp), rotor_speed, power)


# --- landing plans ------------------------------------------------------------------------------------------
def trajectory_message(plan: Any, stamp_ns: int, frame_id: str = DEFAULT_BODY_FRAME) -> JointTrajectory:
    """The plan's controls as a ``JointTrajectory`` (C_T and θ against time from the plan's initial state).

    Args:
        plan: anything with ``control_times``, ``control_values``, ``control_interpolation``
            (a :class:`~helireach_ros.core.planning.planner.LandingPlan` or an envelope's stored plan).
        stamp_ns: the stamp of the state the plan starts from.
        frame_id: the vehicle frame the pitch angle refers to.
    """
    times, values = piecewise_linear_controls(plan.control_times, plan.control_values, plan.control_interpolation)
    message = JointTrajectory()
    message.header.stamp = stamp_message(stamp_ns)
    message.header.frame_id = frame_id
    message.joint_names = [COLLECTIVE_JOINT, PITCH_JOINT]
    message.points = [
        JointTrajectoryPoint(positions=[float(values[0, k]), float(values[1, k])], time_from_start=duration_message(t))
        for k, t in enumerate(times)
    ]
    return message


def read_trajectory(message: JointTrajectory) -> tuple[int, np.ndarray, np.ndarray]:
    """(stamp ns, times s, values 2 × n) of a landing ``JointTrajectory``, joints in any order.

    Raises:
        ValueError: missing joints, no points, ragged or non-finite points, times not increasing.
    """
    names = list(message.joint_names)
    missing = [joint for joint in (COLLECTIVE_JOINT, PITCH_JOINT) if joint not in names]
    if missing:
        raise ValueError(f"trajectory lacks joint(s) {', '.join(missing)}")
    if not message.points:
        raise ValueError("trajectory has no points")
    columns = [names.index(COLLECTIVE_JOINT), names.index(PITCH_JOINT)]
    times, values = [], []
    for index, point in enumerate(message.points):
        if len(point.positions) != len(names):
            raise ValueError(f"point {index} has {len(point.positions)} positions for {len(names)} joints")
        times.append(duration_seconds(point.time_from_start))
        values.append([float(point.positions[column]) for column in columns])
    times_array, values_array = np.asarray(times), np.asarray(values).T
    if not (np.all(np.isfinite(times_array)) and np.all(np.isfinite(values_array))):
        raise ValueError("trajectory holds non-finite values")
    if np.any(np.diff(times_array) <= 0.0):
        raise ValueError("trajectory time_from_start must be strictly increasing")
    return stamp_nanoseconds(message.header.stamp), times_array, values_array


def path_message(
    times: np.ndarray, states: np.ndarray, stamp_ns: int, frame_id: str = DEFAULT_WORLD_FRAME, pitch=None
) -> Path:
    """Predicted positions as a ``nav_msgs/Path``: x = distance, z = height, pose stamps = stamp + t.

    Args:
        times: s from the initial state. states: 6 × len(times) model states (z = row 4, h = row 3).
        stamp_ns: the initial state's stamp. frame_id: the world frame.
        pitch: optional θ per pose (rad) for the orientation.
    """
    message = Path()
    message.header.stamp = stamp_message(stamp_ns)
    message.header.frame_id = frame_id
    poses = []
    for k, time in enumerate(np.asarray(times, dtype=float)):
        pose = PoseStamped()
        pose.header.stamp = stamp_message(stamp_ns + round(time * 1e9))
        pose.header.frame_id = frame_id
        pose.pose.position.x = float(states[StateIndex.DISTANCE, k])
        pose.pose.position.z = float(states[StateIndex.HEIGHT, k])
        pose.pose.orientation = pitch_quaternion(float(pitch[k]) if pitch is not None else 0.0)
        poses.append(pose)
    message.poses = poses
    return message


# --- diagnostics --------------------------------------------------------------------------------------------
def diagnostic_status(
    level: bytes, name: str, message: str, hardware_id: str, values: Mapping[str, Any] | None = None
) -> DiagnosticStatus:
    """A ``DiagnosticStatus`` with values formatted by :func:`format_value`."""
    return DiagnosticStatus(
        level=level,
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=key, value=format_value(value)) for key, value in (values or {}).items()],
    )


def status_values(status: DiagnosticStatus) -> dict[str, str]:
    """The values of a ``DiagnosticStatus`` as a dict."""
    return {item.key: item.value for item in status.values}


def diagnostic_array(stamp_ns: int, *statuses: DiagnosticStatus) -> DiagnosticArray:
    """A ``/diagnostics`` message."""
    array = DiagnosticArray()
    array.header = Header(stamp=stamp_message(stamp_ns))
    array.status = list(statuses)
    return array


def failure_flag(engine_failed: bool) -> Bool:
    """The ``/vehicle/engine_failure`` message."""
    return Bool(data=bool(engine_failed))
