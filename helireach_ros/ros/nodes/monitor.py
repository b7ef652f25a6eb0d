"""Monitor node: the gate between the vehicle's sensors and the helireach nodes.

Subscribes the vehicle state (``/vehicle/odometry``, ``/vehicle/rotor``) and the engine-failure flag
(``/vehicle/engine_failure``). Every state message is checked — finite, within the plausible ranges
(parameters), stamp neither older than ``max_message_age`` nor in the future — and only valid ones
are republished unchanged as the canonical state (``/helireach/state``, ``/helireach/rotor_state``).
A rising edge of the failure flag is published as a failure event (``/helireach/failure_event``,
``std_msgs/Header`` stamped with the time the edge was seen). Rejected input is counted, logged
(throttled) and reported on ``/diagnostics``; the node never raises out of a callback.

Run: ``python -m helireach_ros.ros.nodes.monitor`` (or the ``helireach_monitor`` console script).
"""

from __future__ import annotations

import threading
from functools import partial
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header

from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameters import declare_checked_parameter

__all__ = ["VehicleMonitor", "main"]

_FUTURE_TOLERANCE_S = 0.05  # clocks of two machines never agree exactly


class VehicleMonitor(Node):
    """Validates the vehicle state, republishes it, and turns the failure flag into failure events.

    Parameters: ``rotor_joint``; ``max_message_age`` (s; 0 = do not check stamps, for replays of old
    logs); ``stale_timeout`` (s without a valid state before the diagnostics say STALE); the plausible
    ranges ``min_height``, ``max_height`` (m), ``max_forward_speed``, ``max_climb_rate`` (m/s),
    ``min_rotor_speed``, ``max_rotor_speed`` (rad/s); ``diagnostics_period`` (s).
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_monitor", **node_options)
        declare = partial(declare_checked_parameter, self)
        self._rotor_joint = declare("rotor_joint", rm.ROTOR_JOINT, "JointState joint whose velocity is the rotor speed")
        self._max_message_age = declare(
            "max_message_age",
            1.0,
            "reject state messages whose stamp is older than this, s (0 = no check)",
            (0.0, 3600.0),
        )
        self._stale_timeout = declare("stale_timeout", 0.5, "no valid state for this long = STALE, s", (0.01, 60.0))
        defaults = rm.StateLimits()
        self._limits = rm.StateLimits(
            min_height=declare("min_height", defaults.min_height, "lowest plausible height, m", (-100.0, 0.0)),
            max_height=declare("max_height", defaults.max_height, "highest plausible height, m", (1.0, 1e5)),
            max_forward_speed=declare(
                "max_forward_speed", defaults.max_forward_speed, "largest plausible |forward speed|, m/s", (1.0, 500.0)
            ),
            max_climb_rate=declare(
                "max_climb_rate", defaults.max_climb_rate, "largest plausible |climb rate|, m/s", (1.0, 500.0)
            ),
            min_rotor_speed=declare(
                "min_rotor_speed", defaults.min_rotor_speed, "lowest plausible rotor speed, rad/s", (1e-3, 1e3)
            ),
            max_rotor_speed=declare(
                "max_rotor_speed", defaults.max_rotor_speed, "highest plausible rotor speed, rad/s", (1.0, 1e4)
            ),
        )
        diagnostics_period = declare("diagnostics_period", 1.0, "period of /diagnostics, s", (0.05, 60.0))

        self._lock = threading.Lock()
        self._counts = {
            "odometry_valid": 0,
            "odometry_rejected": 0,
            "rotor_valid": 0,
            "rotor_rejected": 0,
            "failure_events": 0,
        }
        self._last_valid_odometry_ns: int | None = None
        self._last_valid_rotor_ns: int | None = None
        self._last_rejection: tuple[int, str] | None = None
        self._engine_failed: bool | None = None
        self._vehicle_frame = rm.DEFAULT_BODY_FRAME

        self._state_publisher = self.create_publisher(
            Odometry, rm.TOPIC_STATE, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._rotor_publisher = self.create_publisher(
            JointState, rm.TOPIC_ROTOR_STATE, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._event_publisher = self.create_publisher(
            Header, rm.TOPIC_FAILURE_EVENT, rm.EVENT_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self.create_subscription(
            Odometry, rm.TOPIC_ODOMETRY, self._on_odometry, rm.SENSOR_QOS, **rm.NO_QOS_EVENTS_SUBSCRIPTION
        )
        self.create_subscription(
            JointState, rm.TOPIC_ROTOR, self._on_rotor, rm.SENSOR_QOS, **rm.NO_QOS_EVENTS_SUBSCRIPTION
        )
        self.create_subscription(
            Bool, rm.TOPIC_ENGINE_FAILURE, self._on_failure_flag, rm.EVENT_QOS, **rm.NO_QOS_EVENTS_SUBSCRIPTION
        )
        self.create_timer(diagnostics_period, self._publish_diagnostics)

    # -- inputs ------------------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _stamp_problems(self, stamp_ns: int, now_ns: int) -> list[str]:
        if self._max_message_age <= 0.0:
            return []
        age = (now_ns - stamp_ns) * 1e-9
        if age > self._max_message_age:
            return [f"stamp is {age:.3f} s old (max_message_age {self._max_message_age:g} s)"]
        if age < -max(_FUTURE_TOLERANCE_S, self._max_message_age):
            return [f"stamp is {-age:.3f} s in the future"]
        return []

    def _reject(self, kind: str, problems: list[str], now_ns: int) -> None:
        text = f"{kind} rejected: {'; '.join(problems)}"
        with self._lock:
            self._counts[f"{kind}_rejected"] += 1
            self._last_rejection = (now_ns, text)
        self.get_logger().warning(text, throttle_duration_sec=1.0)

    def _on_odometry(self, message: Odometry) -> None:
        now_ns = self._now_ns()
        reading = rm.read_odometry(message)
        problems = rm.state_problems(self._limits, odometry=reading) + self._stamp_problems(reading.stamp_ns, now_ns)
        if problems:
            self._reject("odometry", problems, now_ns)
            return
        with self._lock:
            self._counts["odometry_valid"] += 1
            self._last_valid_odometry_ns = now_ns
            self._vehicle_frame = message.child_frame_id or self._vehicle_frame
        self._state_publisher.publish(message)

    def _on_rotor(self, message: JointState) -> None:
        now_ns = self._now_ns()
        try:
            reading = rm.read_rotor(message, self._rotor_joint)
        except ValueError as error:
            self._reject("rotor", [str(error)], now_ns)
            return
        problems = rm.state_problems(self._limits, rotor=reading) + self._stamp_problems(reading.stamp_ns, now_ns)
        if problems:
            self._reject("rotor", problems, now_ns)
            return
        with self._lock:
            self._counts["rotor_valid"] += 1
            self._last_valid_rotor_ns = now_ns
        self._rotor_publisher.publish(message)

    def _on_failure_flag(self, message: Bool) -> None:
        failed = bool(message.data)
        with self._lock:
            rising = failed and not self._engine_failed  # unknown before the first message counts as running
            self._engine_failed = failed
            if rising:
                self._counts["failure_events"] += 1
            frame = self._vehicle_frame
        if rising:
            event = Header(stamp=rm.stamp_message(self._now_ns()), frame_id=frame)
            self._event_publisher.publish(event)
            self.get_logger().warning("ENGINE FAILURE: failure event published")

    # -- diagnostics -------------------------------------------------------------------------------------------
    def diagnostic(self) -> DiagnosticStatus:
        """The monitor's current status (what goes to ``/diagnostics``)."""
        now_ns = self._now_ns()
        with self._lock:
            counts = dict(self._counts)
            odometry_ns, rotor_ns, rejection = (
                self._last_valid_odometry_ns,
                self._last_valid_rotor_ns,
                self._last_rejection,
            )
            engine_failed = self._engine_failed
        timeout_ns = self._stale_timeout * 1e9
        odometry_fresh = odometry_ns is not None and now_ns - odometry_ns <= timeout_ns
        rotor_fresh = rotor_ns is not None and now_ns - rotor_ns <= timeout_ns
        recent_rejection = rejection is not None and now_ns - rejection[0] <= timeout_ns
        if not odometry_fresh:
            level, text = DiagnosticStatus.STALE, "no valid vehicle state"
        elif recent_rejection:
            level, text = DiagnosticStatus.ERROR, rejection[1]
        elif not rotor_fresh:
            level, text = DiagnosticStatus.WARN, "no valid rotor speed"
        else:
            level, text = DiagnosticStatus.OK, "vehicle state valid"
        if recent_rejection and level == DiagnosticStatus.STALE:
            text = f"{text}; {rejection[1]}"
        values: dict[str, Any] = dict(counts)
        values["engine_failed"] = "unknown" if engine_failed is None else engine_failed
        values["state_age_s"] = (now_ns - odometry_ns) * 1e-9 if odometry_ns is not None else float("inf")
        values["rotor_age_s"] = (now_ns - rotor_ns) * 1e-9 if rotor_ns is not None else float("inf")
        values["last_rejection"] = rejection[1] if rejection is not None else ""
        return rm.diagnostic_status(level, f"{self.get_name()}: vehicle state", text, "vehicle", values)

    def _publish_diagnostics(self) -> None:
        self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), self.diagnostic()))


def main(args: list[str] | None = None) -> None:
    """Runs the monitor until Ctrl-C or SIGTERM."""
    run_node(VehicleMonitor, args)


if __name__ == "__main__":
    main()
