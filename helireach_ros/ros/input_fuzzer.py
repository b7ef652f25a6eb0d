"""Hostile vehicle inputs for fuzz and soak runs: seeded messages, each with the verdict the contract owes it.

A :class:`VehicleInputFuzzer` draws messages for the three vehicle inputs (``/vehicle/odometry``,
``/vehicle/rotor``, ``/vehicle/engine_failure``) and, less often, garbage on the canonical state topics that
the planner and status node read (``/helireach/state``, ``/helireach/rotor_state``), each sent through a
publisher of a random QoS kind (:data:`PUBLISHER_QOS`). Every message is either *clearly valid* (finite,
mid-range, stamped now and after the previous valid one, in the documented frames) or carries exactly
*one* clear defect (:data:`ODOMETRY_DEFECTS`, :data:`ROTOR_DEFECTS`): nothing is left to a borderline
judgement, so a test can hold the system to the contract (``msg_docs/vehicle_*.md``):

- a state the monitor republishes, a plan called safe, and a SAFE status must all come from a valid message;
- every invalid message that reached the monitor is counted as rejected or dropped.

Use it against the composed system (``test/test_fuzz_inputs.py``) or your own setup (``bench/soak.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from helireach_ros.core.policies.vehicle_readings import StateLimits
from helireach_ros.ros import messages as rm

__all__ = [
    "ODOMETRY_DEFECTS",
    "PUBLISHER_QOS",
    "ROTOR_DEFECTS",
    "FuzzMessage",
    "VehicleInputFuzzer",
]

PUBLISHER_QOS: dict[str, QoSProfile] = {
    "reliable": QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=10,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    ),
    "best_effort": QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=5,
        reliability=ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.VOLATILE,
    ),
    "latched": QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    ),
}
"""The publisher QoS kinds drawn from: every one must be heard by the monitor (it subscribes best effort)."""

ODOMETRY_DEFECTS = (
    "nan_height",
    "inf_speed",
    "nan_climb",
    "height_out_of_range",
    "speed_out_of_range",
    "climb_out_of_range",
    "stamp_old",
    "stamp_future",
    "stamp_zero",
    "stamp_out_of_order",
    "wrong_frame",
    "wrong_child_frame",
)
ROTOR_DEFECTS = (
    "nan_speed",
    "negative_speed",
    "speed_out_of_range",
    "missing_joint",
    "velocity_count",
    "stamp_old",
    "stamp_future",
    "stamp_out_of_order",
)
_SECOND = 1_000_000_000


@dataclass(frozen=True)
class FuzzMessage:
    """One drawn message.

    Attributes:
        topic: where it goes.
        message: the ROS message.
        qos_kind: a key of :data:`PUBLISHER_QOS`.
        valid: whether the contract accepts it.
        defect: '' or the one defect it carries.
        stamp_ns: its header stamp (None for ``Bool``).
    """

    topic: str
    message: Any
    qos_kind: str
    valid: bool
    defect: str = ""
    stamp_ns: int | None = None


class VehicleInputFuzzer:
    """Draws :class:`FuzzMessage` s (see the module docstring).

    Args:
        seed: the random seed (a run is reproduced by its seed).
        invalid_share: fraction of odometry and rotor messages with a defect.
        internal_share: fraction of messages that are garbage on the canonical state topics.
        failure_share: fraction of messages that are engine-failure flags; a flag is true with
            ``failure_true_share`` (bursts of failures and recoveries).
        limits: the plausible ranges the valid messages stay well inside.
        max_message_age_s: the monitor's; old stamps are made twice as old.
    """

    def __init__(
        self,
        seed: int,
        invalid_share: float = 0.4,
        internal_share: float = 0.05,
        failure_share: float = 0.1,
        failure_true_share: float = 0.2,
        limits: StateLimits | None = None,
        max_message_age_s: float = 1.0,
    ) -> None:
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.invalid_share = invalid_share
        self.internal_share = internal_share
        self.failure_share = failure_share
        self.failure_true_share = failure_true_share
        self.limits = limits or StateLimits()
        self.old_ns = int(2 * max_message_age_s * _SECOND) + _SECOND
        self.last_valid_stamp_ns = {"odometry": 0, "rotor": 0}

    def _qos(self) -> str:
        return str(self.rng.choice(list(PUBLISHER_QOS)))

    def _stamp(self, kind: str, now_ns: int) -> int:
        """A valid stamp: now, strictly after the previous valid one of this input."""
        stamp = max(now_ns, self.last_valid_stamp_ns[kind] + 1)
        self.last_valid_stamp_ns[kind] = stamp
        return stamp

    def _defective_stamp(self, kind: str, defect: str, now_ns: int) -> int:
        if defect == "stamp_old":
            return now_ns - self.old_ns
        if defect == "stamp_future":
            return now_ns + 10 * _SECOND
        if defect == "stamp_zero":
            return 0
        if defect == "stamp_out_of_order":
            return max(self.last_valid_stamp_ns[kind] - 1_000_000, 1)
        return self._stamp(kind, now_ns)

    def next(self, now_ns: int) -> FuzzMessage:
        """The next message, stamped relative to ``now_ns`` (the receiving clock's now)."""
        draw = self.rng.random()
        if draw < self.internal_share:
            return self._internal_garbage(now_ns)
        if draw < self.internal_share + self.failure_share:
            engine_failed = bool(self.rng.random() < self.failure_true_share)
            return FuzzMessage(rm.TOPIC_ENGINE_FAILURE, Bool(data=engine_failed), self._qos(), True)
        if self.rng.random() < 0.5:
            return self._odometry(now_ns)
        return self._rotor(now_ns)

    def _odometry(self, now_ns: int) -> FuzzMessage:
        defect = str(self.rng.choice(ODOMETRY_DEFECTS)) if self.rng.random() < self.invalid_share else ""
        if defect == "stamp_out_of_order" and self.last_valid_stamp_ns["odometry"] == 0:
            defect = "stamp_old"  # nothing accepted yet to be out of order with
        limits = self.limits
        height = float(self.rng.uniform(10.0, 0.5 * limits.max_height))
        speed = float(self.rng.uniform(0.0, 0.5 * limits.max_forward_speed))
        climb = float(self.rng.uniform(-0.3, 0.3) * limits.max_climb_rate)
        values = {"height": height, "speed": speed, "climb": climb}
        bad_values = {
            "nan_height": ("height", math.nan),
            "inf_speed": ("speed", math.inf),
            "nan_climb": ("climb", math.nan),
            "height_out_of_range": ("height", 10.0 * limits.max_height),
            "speed_out_of_range": ("speed", -3.0 * limits.max_forward_speed),
            "climb_out_of_range": ("climb", 3.0 * limits.max_climb_rate),
        }
        if defect in bad_values:
            field_name, bad_value = bad_values[defect]
            values[field_name] = bad_value
        stamp = self._defective_stamp("odometry", defect, now_ns)
        frame = "map_ned" if defect == "wrong_frame" else rm.DEFAULT_WORLD_FRAME
        child = "base_link_frd" if defect == "wrong_child_frame" else rm.DEFAULT_BODY_FRAME
        message: Odometry = rm.odometry_message(
            stamp, values["height"], 0.0, values["speed"], values["climb"], frame_id=frame, child_frame_id=child
        )
        return FuzzMessage(rm.TOPIC_ODOMETRY, message, self._qos(), not defect, defect, stamp)

    def _rotor(self, now_ns: int) -> FuzzMessage:
        defect = str(self.rng.choice(ROTOR_DEFECTS)) if self.rng.random() < self.invalid_share else ""
        if defect == "stamp_out_of_order" and self.last_valid_stamp_ns["rotor"] == 0:
            defect = "stamp_old"
        speed = float(self.rng.uniform(0.8, 1.1) * 27.0)
        speed = {"nan_speed": math.nan, "negative_speed": -speed, "speed_out_of_range": 1e5}.get(defect, speed)
        stamp = self._defective_stamp("rotor", defect, now_ns)
        message: JointState = rm.rotor_message(stamp, 1.0)
        message.velocity = [speed]
        if defect == "missing_joint":
            message.name = ["tail_rotor"]
        elif defect == "velocity_count":
            message.velocity = [speed, speed]
        return FuzzMessage(rm.TOPIC_ROTOR, message, self._qos(), not defect, defect, stamp)

    def _internal_garbage(self, now_ns: int) -> FuzzMessage:
        """A rogue publisher on a canonical topic: always invalid values (the consumers check values)."""
        if self.rng.random() < 0.5:
            message = rm.odometry_message(now_ns, math.nan, 0.0, float(self.rng.uniform(0, 60)), math.inf)
            return FuzzMessage(rm.TOPIC_STATE, message, self._qos(), False, "internal_nan", now_ns)
        message = rm.rotor_message(now_ns, 1.0)
        message.velocity = [-1.0]
        return FuzzMessage(rm.TOPIC_ROTOR_STATE, message, self._qos(), False, "internal_negative_rotor", now_ns)
