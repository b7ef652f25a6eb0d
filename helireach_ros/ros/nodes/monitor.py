"""Monitor node: the gate between the vehicle's sensors and the helireach nodes.

Subscribes the vehicle state (``/vehicle/odometry``, ``/vehicle/rotor``) and the engine-failure flag
(``/vehicle/engine_failure``). Every state message is checked — finite, within the plausible ranges
(parameters), stamp neither older than ``max_message_age`` nor in the future, odometry frames the
expected ``world_frame``/``body_frame``, stamp newer than the latest accepted one of its input (else dropped:
:mod:`helireach_ros.core.policies.input_contract`) — and only valid ones are republished unchanged as the canonical
state (``/helireach/state``, ``/helireach/rotor_state``).
The failure flag and the valid state drive the failure-episode model
(:class:`~helireach_ros.core.policies.failure_episode.EpisodeTracker`): each episode start is published once as a
failure event (``/helireach/failure_event``, ``std_msgs/Header`` stamped with the episode's first true), its state on
``/helireach/failure_episode`` (on change and every ``diagnostics_period``); until a flag arrives the diagnostics WARN
"no engine-failure flag received". Rejected input is counted, logged (throttled) and reported on ``/diagnostics``; the
node never raises out of a callback.

Run: ``python -m helireach_ros.ros.nodes.monitor`` (or the ``helireach_monitor`` console script).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header

from helireach_ros.core.policies.failure_episode import (
    EpisodePhase,
    EpisodeSettings,
    EpisodeState,
    EpisodeTracker,
    EpisodeTransition,
)
from helireach_ros.core.policies.input_contract import OUT_OF_ORDER, WRONG_FRAME, FrameContract, InputGate
from helireach_ros.core.policies.vehicle_readings import StateLimits, state_problems
from helireach_ros.ros import fast_logging
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameter_table import parameter
from helireach_ros.ros.parameters import declare_parameters
from helireach_ros.ros.qos import QosWatch

__all__ = ["MonitorParameters", "VehicleMonitor", "main"]

_FUTURE_TOLERANCE_S = 0.05  # clocks of two machines never agree exactly
_RECENT_FLAGS = 256  # flag observations kept to see whether publishers disagree (1 s at up to 256 Hz)


_LIMITS = StateLimits()  # the plausible ranges' defaults
_EPISODE = EpisodeSettings()  # the failure episode's defaults


@dataclass(frozen=True)
class MonitorParameters:
    """The monitor's parameters, SI (one table: :mod:`helireach_ros.ros.parameter_table`)."""

    rotor_joint: str = parameter(rm.ROTOR_JOINT, "JointState joint whose velocity is the rotor speed")
    max_message_age: float = parameter(
        1.0, "reject state messages whose stamp is older than this, s (0 = no check)", (0.0, 3600.0)
    )
    max_input_bytes: int = parameter(
        65536, "odometry or rotor messages larger than this are rejected unread, bytes", (256, 1 << 30)
    )
    stale_timeout: float = parameter(0.5, "no valid state for this long = STALE, s", (0.01, 60.0))
    min_height: float = parameter(_LIMITS.min_height, "lowest plausible height, m", (-100.0, 0.0))
    max_height: float = parameter(_LIMITS.max_height, "highest plausible height, m", (1.0, 1e5))
    max_forward_speed: float = parameter(
        _LIMITS.max_forward_speed, "largest plausible |forward speed|, m/s", (1.0, 500.0)
    )
    max_climb_rate: float = parameter(_LIMITS.max_climb_rate, "largest plausible |climb rate|, m/s", (1.0, 500.0))
    min_rotor_speed: float = parameter(_LIMITS.min_rotor_speed, "lowest plausible rotor speed, rad/s", (1e-3, 1e3))
    max_rotor_speed: float = parameter(_LIMITS.max_rotor_speed, "highest plausible rotor speed, rad/s", (1.0, 1e4))
    recovery_hold: float = parameter(
        _EPISODE.recovery_hold, "steady false flag that ends an episode, s", (0.01, 3600.0)
    )
    landed_height: float = parameter(_EPISODE.landed_height, "failed and at most this high = landed, m", (0.0, 100.0))
    landed_climb_rate: float = parameter(
        _EPISODE.landed_climb_rate, "largest |climb rate| that counts as landed, m/s", (0.001, 100.0)
    )
    diagnostics_period: float = parameter(1.0, "period of /diagnostics, s", (0.05, 60.0))
    world_frame: str = parameter(rm.DEFAULT_WORLD_FRAME, "required odometry header.frame_id")
    body_frame: str = parameter(rm.DEFAULT_BODY_FRAME, "required odometry child_frame_id")


class VehicleMonitor(Node):
    """Validates the vehicle state, republishes it, and turns the failure flag into failure events.

    Parameters: ``rotor_joint``; ``max_message_age`` (s; 0 = do not check stamps, for replays of old
    logs); ``stale_timeout`` (s without a valid state before the diagnostics say STALE); the plausible
    ranges ``min_height``, ``max_height`` (m), ``max_forward_speed``, ``max_climb_rate`` (m/s),
    ``min_rotor_speed``, ``max_rotor_speed`` (rad/s); the failure episode's ``recovery_hold`` (s),
    ``landed_height`` (m), ``landed_climb_rate`` (m/s); ``diagnostics_period`` (s); ``world_frame``,
    ``body_frame`` (the odometry ``frame_id``/``child_frame_id`` required). Inputs are subscribed BEST_EFFORT
    (every publisher matches); incompatible QoS is the ``<node>: QoS`` status (:mod:`helireach_ros.ros.qos`).
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_monitor", **node_options)
        self.config = config = declare_parameters(self, MonitorParameters)
        self._rotor_joint = config.rotor_joint
        self._max_message_age = config.max_message_age
        self._max_input_bytes = config.max_input_bytes
        self._stale_timeout = config.stale_timeout
        self._limits = StateLimits(
            min_height=config.min_height,
            max_height=config.max_height,
            max_forward_speed=config.max_forward_speed,
            max_climb_rate=config.max_climb_rate,
            min_rotor_speed=config.min_rotor_speed,
            max_rotor_speed=config.max_rotor_speed,
        )
        self._episode_settings = EpisodeSettings(
            recovery_hold=config.recovery_hold,
            landed_height=config.landed_height,
            landed_climb_rate=config.landed_climb_rate,
        )
        diagnostics_period, world_frame, body_frame = config.diagnostics_period, config.world_frame, config.body_frame

        self._lock = threading.Lock()
        self._counts = {
            "odometry_valid": 0,
            "odometry_rejected": 0,
            "rotor_valid": 0,
            "rotor_rejected": 0,
            "odometry_oversized": 0,
            "rotor_oversized": 0,
            "failure_events": 0,
        }
        self._last_valid_odometry_ns: int | None = None
        self._last_valid_rotor_ns: int | None = None
        self._last_rejection: tuple[int, str] | None = None
        self._episodes = EpisodeTracker(self._episode_settings)  # the failure-episode model
        self._vehicle_frame = rm.DEFAULT_BODY_FRAME
        # The input contract (core.policies.input_contract): frames, then values, then stamp order, per stamped input.
        self._gates = {"odometry": InputGate(FrameContract(world_frame, body_frame)), "rotor": InputGate()}
        self._last_drop: tuple[int, str] | None = None
        self._recent_flags: deque[tuple[int, bool]] = deque(maxlen=_RECENT_FLAGS)  # (received ns, value)
        self._qos_watch = QosWatch(self, diagnostics_period)

        self._state_publisher = self._qos_watch.create_publisher(Odometry, rm.TOPIC_STATE, rm.STREAM_QOS)
        self._rotor_publisher = self._qos_watch.create_publisher(JointState, rm.TOPIC_ROTOR_STATE, rm.STREAM_QOS)
        self._event_publisher = self._qos_watch.create_publisher(Header, rm.TOPIC_FAILURE_EVENT, rm.EVENT_QOS)
        self._episode_publisher = self._qos_watch.create_publisher(
            DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, rm.LATCHED_QOS
        )
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        # Every vehicle input BEST_EFFORT, VOLATILE: reliable and best-effort, volatile and latched publishers all
        # match (msg_docs/vehicle_*.md); the flag is published steadily, so a lost sample only delays its edge.
        # Read raw, so that an oversized message is refused before rclpy spends the executor's time building it (a
        # stream of 1.7 MB JointStates made the monitor lose most of the valid rotor messages beside it).
        for kind, message_type, topic, handler in (
            ("odometry", Odometry, rm.TOPIC_ODOMETRY, self._on_odometry),
            ("rotor", JointState, rm.TOPIC_ROTOR, self._on_rotor),
        ):
            self._qos_watch.create_subscription(
                message_type, topic, partial(self._on_raw, kind, message_type, handler), rm.SENSOR_QOS, raw=True
            )
        self._qos_watch.create_subscription(Bool, rm.TOPIC_ENGINE_FAILURE, self._on_failure_flag, rm.SENSOR_QOS)
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

    def _admit(
        self, kind: str, stamp_ns: int, now_ns: int, problems: list[str], frame_id: str = "", child_frame_id: str = ""
    ) -> bool:
        """The input contract of one message (frames, values, stamp order): True if it may be used."""
        with self._lock:
            verdict = self._gates[kind].judge(stamp_ns, now_ns, frame_id, child_frame_id, problems)
            if verdict.reason == OUT_OF_ORDER:
                self._last_drop = (now_ns, f"{kind} dropped: {verdict.text}")
        if verdict.reason == OUT_OF_ORDER:
            self.get_logger().warning(f"{kind} dropped: {verdict.text}", throttle_duration_sec=1.0)
        elif not verdict.accepted:
            self._reject(kind, list(verdict.problems), now_ns)
        return verdict.accepted

    def _on_raw(self, kind: str, message_type: type, handler: Callable[[Any], None], data: bytes) -> None:
        if len(data) > self._max_input_bytes:
            with self._lock:
                self._counts[f"{kind}_oversized"] += 1
            problem = f"a message of {len(data)} bytes exceeds max_input_bytes {self._max_input_bytes}; not read"
            self._reject(kind, [problem], self._now_ns())
            return
        try:
            message = deserialize_message(data, message_type)
        except Exception as error:  # bytes that are not the type: rejected like any bad input, the node runs on
            self._reject(kind, [f"cannot be read as {message_type.__name__}: {error}"], self._now_ns())
            return
        handler(message)

    def _on_odometry(self, message: Odometry) -> None:
        now_ns = self._now_ns()
        reading = rm.read_odometry(message)
        problems = state_problems(self._limits, odometry=reading) + self._stamp_problems(reading.stamp_ns, now_ns)
        if not self._admit(
            "odometry", reading.stamp_ns, now_ns, problems, message.header.frame_id, message.child_frame_id
        ):
            return
        with self._lock:
            self._counts["odometry_valid"] += 1
            self._last_valid_odometry_ns = now_ns
            self._vehicle_frame = message.child_frame_id or self._vehicle_frame
            landing = self._episodes.observe_state(reading.height, reading.climb_rate, now_ns)
        self._state_publisher.publish(message)
        self._report_episode(landing)

    def _on_rotor(self, message: JointState) -> None:
        now_ns = self._now_ns()
        try:
            reading = rm.read_rotor(message, self._rotor_joint)
        except ValueError as error:
            self._admit("rotor", rm.stamp_nanoseconds(message.header.stamp), now_ns, [str(error)])
            return
        problems = state_problems(self._limits, rotor=reading) + self._stamp_problems(reading.stamp_ns, now_ns)
        if not self._admit("rotor", reading.stamp_ns, now_ns, problems):
            return
        with self._lock:
            self._counts["rotor_valid"] += 1
            self._last_valid_rotor_ns = now_ns
        self._rotor_publisher.publish(message)

    def _on_failure_flag(self, message: Bool) -> None:
        now_ns = self._now_ns()
        with self._lock:
            self._recent_flags.append((now_ns, bool(message.data)))
            transition = self._episodes.observe_flag(bool(message.data), now_ns)
            if transition is not None and transition.started:
                self._counts["failure_events"] += 1
        self._report_episode(transition)

    def _report_episode(self, transition: EpisodeTransition | None) -> None:
        """On a phase change: the failure event (once per episode, stamped with its start) and the episode state."""
        if transition is None:
            return
        state = transition.state
        if transition.started and state.started_ns is not None:
            with self._lock:
                frame = self._vehicle_frame
            self._event_publisher.publish(Header(stamp=rm.stamp_message(state.started_ns), frame_id=frame))
        self._publish_episode(state)
        # the log line after the messages: nothing downstream waits for it
        if transition.started:
            text = f"ENGINE FAILURE: episode {state.episode_id}, failure event published"
        else:
            text = f"failure episode: {transition.previous.value} -> {state.text}"
        fast_logging.warning(self.get_logger(), text)

    def _publish_episode(self, state: EpisodeState) -> None:
        values = {**state.as_values(), "recovery_hold_s": self._episode_settings.recovery_hold}
        level = rm.DIAGNOSTIC_LEVELS[state.level_name]
        name = f"{self.get_name()}: failure episode"
        self._episode_publisher.publish(rm.diagnostic_status(level, name, state.text, "vehicle", values))

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
            episode = self._episodes.state
            contract_counts = {
                f"{kind}_{reason}": gate.counts[reason]
                for kind, gate in self._gates.items()
                for reason in (WRONG_FRAME, OUT_OF_ORDER)
            }
            drop = self._last_drop
            recent_flags = {value for received_ns, value in self._recent_flags if now_ns - received_ns <= 1e9}
        timeout_ns = self._stale_timeout * 1e9
        odometry_fresh = odometry_ns is not None and now_ns - odometry_ns <= timeout_ns
        rotor_fresh = rotor_ns is not None and now_ns - rotor_ns <= timeout_ns
        rejection_text = rejection[1] if rejection is not None and now_ns - rejection[0] <= timeout_ns else ""
        recent_rejection = bool(rejection_text)
        if not odometry_fresh:
            level, text = DiagnosticStatus.STALE, "no valid vehicle state"
        elif recent_rejection:
            level, text = DiagnosticStatus.ERROR, rejection_text
        elif not rotor_fresh:
            level, text = DiagnosticStatus.WARN, "no valid rotor speed"
        else:
            level, text = DiagnosticStatus.OK, "vehicle state valid"
        if recent_rejection and level == DiagnosticStatus.STALE:
            text = f"{text}; {rejection_text}"
        if level == DiagnosticStatus.OK and drop is not None and now_ns - drop[0] <= timeout_ns:
            level, text = DiagnosticStatus.WARN, drop[1]  # the state stays valid: the older message was not used
        flag_publishers = self.count_publishers(rm.TOPIC_ENGINE_FAILURE)
        if flag_publishers > 1 and len(recent_flags) > 1:  # handled conservatively (a true one counts); say so
            disagree = (
                f"{flag_publishers} publishers on {rm.TOPIC_ENGINE_FAILURE} disagree (true and false within 1 s; a "
                "true one starts an episode)"
            )
            if level == DiagnosticStatus.OK:
                level, text = DiagnosticStatus.WARN, disagree
            else:
                text = f"{text}; {disagree}"
        if episode.phase is EpisodePhase.NO_FLAG:  # the state may be fine, but a failure could not be seen
            no_flag = "no engine-failure flag received"
            if level == DiagnosticStatus.OK:
                level, text = DiagnosticStatus.WARN, no_flag
            else:
                text = f"{text}; {no_flag}"
        values: dict[str, Any] = dict(counts)
        values.update(contract_counts)
        values["last_out_of_order"] = drop[1] if drop is not None else ""
        values["engine_failed"] = "unknown" if episode.flag is None else episode.flag
        values["failure_flag_publishers"] = flag_publishers
        values.update(failure_episode=episode.phase.value, episode_id=episode.episode_id)
        values["state_age_s"] = (now_ns - odometry_ns) * 1e-9 if odometry_ns is not None else float("inf")
        values["rotor_age_s"] = (now_ns - rotor_ns) * 1e-9 if rotor_ns is not None else float("inf")
        values["last_rejection"] = rejection[1] if rejection is not None else ""
        return rm.diagnostic_status(level, f"{self.get_name()}: vehicle state", text, "vehicle", values)

    def _publish_diagnostics(self) -> None:
        self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), self.diagnostic()))
        with self._lock:
            episode = self._episodes.state
        self._publish_episode(episode)  # periodically too: late joiners (the topic is not latched)


def main(args: list[str] | None = None) -> None:
    """Runs the monitor until Ctrl-C or SIGTERM."""
    raise SystemExit(run_node(VehicleMonitor, args))  # 2: bad command line or parameter (one line on stderr)


if __name__ == "__main__":
    main()
