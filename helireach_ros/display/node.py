"""Cockpit display node: a live web page of the H-V envelope, the operating point, the safety status and the plan.

The node subscribes to the helireach topics and serves one page (``helireach_ros/display/web/``) from an aiohttp
HTTP + WebSocket server running on its own asyncio thread. It is read-only: it creates no publishers of its
own (rclpy's ``/rosout`` and ``/parameter_events`` aside) and ignores everything a browser sends.

Data flow: ROS callbacks (any executor thread) store the latest value of each topic under a lock and wake the
server; each connected page has one sender task that sends the *latest* snapshot, at most ``max_update_rate_hz``
times per second and at least every ``heartbeat`` (so a page can tell a silent server from a quiet sky). Nothing
is queued per message: a 60 Hz (or 6 kHz) state stream costs each page at most one frame per send interval, the
rest are dropped, and a page that cannot keep up only slows its own sender.

The banner follows the flight phase (:mod:`helireach_ros.core.policies.flight_phase`): in NORMAL it is
``/helireach/safety_status`` (OK → SAFE, WARN → CAUTION, ERROR → AVOID, STALE or unknown → NO DATA); in
AUTOROTATION the plan; LANDED the touchdown result (``/helireach/touchdown``, else from the state); ENDED the
recovery; STALE when a streaming source (state, rotor, safety status, failure episode) is silent longer than
``stale_after_s``. The page applies the same silence rule to the WebSocket itself.

The side view's ground line: the live reachable footprint (``/helireach/reachable_footprint``) between its verified
ends, and the selected landing site (the latest ``/helireach/live_reachability`` or ``/helireach/plan_status`` that
carries ``site_start_m``/``site_end_m``). Never optimistic: an unverified end is not an end; a footprint or live
verdict whose state is older than ``LIVE_MAX_AGE_S`` (the status node's ``live_max_age``), or a footprint older than
``FOOTPRINT_MAX_AGE_S``, is not ``current`` (the page then draws no band and says STALE).

Wire format (JSON text frames, SI units; the page converts to ft/kt for people)::

    {"config": {...},      # on connect and on change: units, stale_after_s, rotor limits, airframe
     "envelope": {...},    # on connect and on change: H-V grid, status codes, boundary, or an error
     "plan": {...} | null, # on change: trajectory, predicted path, plan status, robust verdict
     "live": {...}}        # every frame: phase banner, status, state, rotor, failure, episode, touchdown, cue,
                           # footprint and landing site (with their ages)

Run: ``helireach display`` or ``python -m helireach_ros.display.node --ros-args -p port:=8080``.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.policies.flight_phase import (
    CueEvent,
    PhaseInputs,
    PlanVerdictInput,
    TouchdownFromState,
    TouchdownResult,
    decide_phase,
    next_cue,
    plan_cue_events,
)
from helireach_ros.core.status_contracts import LiveVerdictValues
from helireach_ros.core.units import FT, KT
from helireach_ros.display.pilot_units import axis_margins, thrust_scale
from helireach_ros.display.sections import (
    envelope_section,
    episode_section,
    finite,
    footprint_section,
    path_section,
    plan_status_section,
    robust_verdict_section,
    rotor_limits_section,
    safety_status_section,
    site_section,
    site_verdict,
    to_json,
    touchdown_section,
    trajectory_section,
)
from helireach_ros.display.server import DisplayServerError, PageServer
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import node_command_line, shutdown_is_a_normal_stop
from helireach_ros.ros.parameter_table import parameter
from helireach_ros.ros.parameters import ParameterError, declare_parameters
from helireach_ros.ros.qos import QosWatch

__all__ = [
    "DEFAULT_BIND",
    "DEFAULT_PORT",
    "FOOTPRINT_MAX_AGE_S",
    "LIVE_MAX_AGE_S",
    "CockpitDisplay",
    "DisplayParameters",
    "create_display_with_fallback",
    "hold_until_interrupted",
    "main",
    "run_display",
]

DEFAULT_PORT = 8080
DEFAULT_BIND = "127.0.0.1"
_PLAN_STAMP_TOLERANCE_S = 10.0  # a plan stamped further from the receipt time uses the receipt time instead
# A state at or below this height is on the ground (the monitor's landed_height default, msg_docs/...episode.md).
_CONTACT_HEIGHT_M = 0.3
#: A live verdict or footprint whose state is older than this is no evidence, s (the status node's ``live_max_age``
#: default, msg_docs/helireach_live_reachability.md): the side view draws no footprint band and says STALE.
LIVE_MAX_AGE_S = 1.0
#: A footprint whose state is older than this is not drawn, s: the planner publishes one at most every
#: ``footprint_period`` (1 s suggested) and solves its two ends first (~0.3 s warm), so the live age would make the band
#: flicker; the interval is along the track, in the world, and shrinks slowly with the height (assumed).
FOOTPRINT_MAX_AGE_S = 2.5


@dataclass(frozen=True)
class DisplayParameters:
    """The cockpit display's parameters (one table: :mod:`helireach_ros.ros.parameter_table`)."""

    port: int = parameter(DEFAULT_PORT, "TCP port of the page (0 = any free port)", (0, 65535))
    bind: str = parameter(DEFAULT_BIND, "listen address; loopback unless set explicitly")
    envelope_file: str = parameter("", "H-V envelope file ('' = the shipped envelope)")
    airframe: str = parameter("", "airframe for rotor limits ('' = the envelope's)")
    state_topic: str = parameter(rm.TOPIC_STATE, "nav_msgs/Odometry vehicle state topic")
    rotor_topic: str = parameter(rm.TOPIC_ROTOR, "sensor_msgs/JointState rotor speed topic")
    stale_after_s: float = parameter(
        2.0, "NO DATA after this long without a message, s", (0.1, 3600.0), read_only=False
    )
    max_update_rate_hz: float = parameter(25.0, "most frames per second sent to one page", (1.0, 120.0))
    allowed_hosts: str = parameter(
        "", "more Host header names the page answers, comma separated (e.g. for bind 0.0.0.0)"
    )
    rotor_caution_pct: float = parameter(
        3.0, "amber caution band inside each rotor speed limit, % of nominal", (0.0, 15.0)
    )


# ----------------------------------------------------------------------------------------------------------
# Latest-value store shared by ROS callbacks (writers) and the web server (reader)
# ----------------------------------------------------------------------------------------------------------


@dataclass
class _Received:
    """A message's content with its receipt time (``time.monotonic``)."""

    content: Any
    received: float
    state_age_s: float | None = None  # age of the message's state stamp at receipt (this node's clock), s


@dataclass
class _Latest:
    """The newest value of everything the page shows (guarded by the node's lock)."""

    status: _Received | None = None
    last_known_banner: str | None = None
    state: _Received | None = None
    rotor: _Received | None = None
    failure: _Received | None = None
    trajectory: _Received | None = None
    path: _Received | None = None
    plan_status: _Received | None = None
    robust_verdict: _Received | None = None
    episode: _Received | None = None
    touchdown: _Received | None = None
    footprint: _Received | None = None
    live_site: _Received | None = None  # the latest live reachability that carries a landing site
    touchdown_from_state: TouchdownFromState | None = None
    cue_events: tuple[CueEvent, ...] = ()
    margins: dict[str, Any] | None = None
    plan_reference: float | None = None  # monotonic time of the plan's t = 0
    held: bool = False
    versions: dict[str, int] = field(default_factory=lambda: {"config": 1, "envelope": 1, "plan": 1})


def _safe_masks(envelope: Any) -> np.ndarray:
    """One safe mask per climb slice (a 2-D envelope has one)."""
    safe = np.asarray(envelope.status) == "safe"
    return safe if envelope.is_3d else safe[None]


def _most_restrictive(members: Any) -> tuple[Any, Any]:
    """Of family members, the heaviest at the highest density altitude (calm first): the one to draw when it is not
    known which answers, or for several answering together."""
    return max(members, key=lambda item: (-abs(item[0].headwind), item[0].gross_weight, item[0].density_altitude))


def _family_section(envelope: Any, conditions: str, envelope_id: str) -> dict[str, Any]:
    """The diagram of a family member, labelled with its conditions and the id the status reports."""
    section = envelope_section(envelope.slice(envelope.nearest_slice(0.0)))
    section.update(envelope_id=envelope_id, conditions=conditions)
    return section


class CockpitDisplay(Node):
    """Serves the cockpit page and pushes the latest helireach data to it (read-only).

    Parameters (ROS): ``port`` (8080; 0 = any free port, see :attr:`url`), ``bind`` (127.0.0.1; another address
    only when given), ``envelope_file`` (default: the shipped envelope), ``airframe`` (rotor limits; default: the
    envelope's airframe), ``state_topic`` (``/helireach/state``; ``/vehicle/odometry`` has the same layout),
    ``rotor_topic`` (``/vehicle/rotor``; the monitor's ``/helireach/rotor_state`` has the same layout),
    ``stale_after_s`` (STALE after this long without a message of a streaming source), ``max_update_rate_hz``
    (frames per second per page), ``allowed_hosts`` (more ``Host`` header names, comma separated, for a
    non-loopback bind), ``rotor_caution_pct`` (amber band inside each rotor limit, % of Ω₀).

    Raises:
        DisplayServerError: if the web server cannot listen on ``bind:port``.
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_display", **node_options)
        self._lock = threading.Lock()
        self._latest = _Latest()
        self.config = config = declare_parameters(self, DisplayParameters)
        self._port, self._bind, self._envelope_file = config.port, config.bind, config.envelope_file
        self._airframe_name, state_topic, rotor_topic = config.airframe, config.state_topic, config.rotor_topic
        self._stale_after_s = config.stale_after_s  # settable at run time (_on_set_parameters updates it)
        self._max_update_rate_hz, allowed_hosts = config.max_update_rate_hz, config.allowed_hosts
        self._rotor_caution_pct = config.rotor_caution_pct
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._state_topic = state_topic
        self._family: Any | None = None  # an envelope family (envelope_file a family's folder): its members drawn
        envelope, envelope_data = self._load_envelope()
        self._envelope_id = envelope_data.get("envelope_id")
        self._envelope = envelope
        # one safe mask per climb slice (a 2-D envelope has one): margins come from the measured climb rate's
        # nearest slice, the drawn diagram is the level-flight slice
        self._envelope_safe: np.ndarray | None = None
        if envelope is not None:
            self._envelope_safe = _safe_masks(envelope)
        self._config = self._config_section(envelope, envelope_data)
        limits = self._touchdown_limits or {}
        self._latest.touchdown_from_state = TouchdownFromState(
            _CONTACT_HEIGHT_M, limits.get("max_descent_rate_ms"), limits.get("max_forward_speed_ms")
        )
        self._config_json = to_json(self._config)
        self._envelope_json = to_json(envelope_data)
        self._plan_json = "null"

        # QoS as documented in msg_docs (ros/messages.py): the safety status and the plan are latched, so a page opened
        # after the failure shows the plan; sensor streams with BEST_EFFORT, which matches any publisher. An
        # incompatible publisher (a volatile status, a best-effort plan) is logged as an ERROR (the page shows NO DATA)
        qos_watch = QosWatch(self, publish=False)
        for message_type, topic, callback, qos in (
            (DiagnosticStatus, rm.TOPIC_SAFETY_STATUS, self._on_safety_status, rm.LATCHED_QOS),
            (Odometry, state_topic, self._on_state, rm.SENSOR_QOS),
            (JointState, rotor_topic, self._on_rotor, rm.SENSOR_QOS),
            (Header, rm.TOPIC_FAILURE_EVENT, self._on_failure, rm.EVENT_QOS),
            (JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, self._on_trajectory, rm.LATCHED_QOS),
            (PathMsg, rm.TOPIC_LANDING_PATH, self._on_path, rm.LATCHED_QOS),
            (DiagnosticStatus, rm.TOPIC_PLAN_STATUS, self._on_plan_status, rm.LATCHED_QOS),
            (DiagnosticStatus, rm.TOPIC_ROBUST_VERDICT, self._on_robust_verdict, rm.LATCHED_QOS),
            (DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, self._on_episode, rm.LATCHED_QOS),
            (DiagnosticStatus, rm.TOPIC_TOUCHDOWN, self._on_touchdown, rm.LATCHED_QOS),
            (DiagnosticStatus, rm.TOPIC_REACHABLE_FOOTPRINT, self._on_footprint, rm.LATCHED_QOS),
            (DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY, self._on_live_reachability, rm.LATCHED_QOS),
        ):
            qos_watch.create_subscription(message_type, topic, self._never_raising(callback, topic), qos)

        if self._bind not in ("127.0.0.1", "::1", "localhost"):
            self.get_logger().warning(f"display listens on {self._bind}, not loopback: reachable from the network")
        try:
            self._server = PageServer(
                self._bind,
                self._port,
                self._frame,
                *self._frame_timing(),
                log_warning=self.get_logger().warning,
                allowed_hosts=[name for name in allowed_hosts.split(",") if name.strip()],
            )
        except DisplayServerError:
            super().destroy_node()
            raise
        self.get_logger().info(f"cockpit display at {self.url} (state from {state_topic})")

    # -- parameters ------------------------------------------------------------------------------------
    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        for changed in parameters:
            if changed.name == "stale_after_s":
                value = finite(changed.value)
                if value is None or value <= 0:
                    return SetParametersResult(successful=False, reason="stale_after_s must be a positive number")
        for changed in parameters:
            if changed.name == "stale_after_s":
                self._stale_after_s = float(changed.value)
                with self._lock:
                    self._config = {**self._config, "stale_after_s": self._stale_after_s}
                    self._config_json = to_json(self._config)
                    self._latest.versions["config"] += 1
                if hasattr(self, "_server"):
                    self._server.min_interval_s, self._server.heartbeat_s = self._frame_timing()
                    self._server.notify()
        return SetParametersResult(successful=True)

    def _frame_timing(self) -> tuple[float, float]:
        """The (shortest, longest) time between two frames to one page, s.

        The shortest is the rate limit; the longest, a heartbeat well within ``stale_after_s``, lets the page
        tell a quiet sky from a dead link (the rate limit never stretches past it).
        """
        heartbeat = min(0.5, self._stale_after_s / 3.0)
        return min(1.0 / self._max_update_rate_hz, heartbeat), heartbeat

    # -- envelope and airframe ---------------------------------------------------------------------------
    def _load_envelope(self) -> tuple[Any, dict[str, Any]]:
        """Loads the envelope for the diagram; any failure gives an 'unavailable' section and a logged error. A family
        draws its heaviest, highest member until a safety status names the members it answers from."""
        path = self._envelope_file or "(shipped envelope)"
        try:
            from helireach_ros.core.envelope import data as envelope_module
            from helireach_ros.core.envelope.family import EnvelopeFamily, is_family

            path = self._envelope_file or str(envelope_module.default_envelope_path())
            if is_family(path):
                self._family = EnvelopeFamily.load(path)
                member, envelope = _most_restrictive(self._family.members)
                section = _family_section(envelope, member.conditions, envelope.envelope_id)
            else:
                envelope = envelope_module.load_envelope(path)
                section = envelope_section(envelope.slice(envelope.nearest_slice(0.0)))  # the level-flight diagram
                section["envelope_id"] = str(envelope.envelope_id)  # the file's, as the status node reports it
        except Exception as error:  # missing module, missing/corrupt file: the page shows NO DATA, node runs on
            reason = f"{type(error).__name__}: {error}"
            if str(path) not in reason:
                reason = f"{path}: {reason}"
            self.get_logger().error(f"H-V diagram unavailable: {reason}")
            return None, {"available": False, "reason": reason, "file": str(path)}
        self.get_logger().info(f"H-V diagram: envelope {section['envelope_id']} from {path}")
        return envelope, {**section, "file": str(path)}

    def _config_section(self, envelope: Any, envelope_data: Mapping[str, Any]) -> dict[str, Any]:
        """Units, staleness, rotor limits (explicit ``airframe`` → envelope metadata → envelope's airframe),
        touchdown limits and the thrust scale (from the airframe file)."""
        rotor_limits, airframe_label, airframe = None, str(envelope_data.get("airframe", "")), None
        try:
            from helireach_ros.core.aircraft.airframe import load_airframe

            if self._airframe_name:
                airframe = load_airframe(self._airframe_name)
                rotor_limits, airframe_label = rotor_limits_section(airframe=airframe), airframe.name
            elif envelope is not None:
                rotor_limits = rotor_limits_section(metadata=getattr(envelope, "metadata", None))
                if airframe_label:
                    airframe = load_airframe(airframe_label)
                    rotor_limits = rotor_limits or rotor_limits_section(airframe=airframe)
        except Exception as error:  # the gauge then shows the speed without limits
            self.get_logger().error(f"airframe (rotor, touchdown limits) unavailable: {type(error).__name__}: {error}")
        if rotor_limits is not None:
            rotor_limits = {**rotor_limits, "caution_pct": self._rotor_caution_pct}
        touchdown_limits, thrust = None, None
        if airframe is not None:
            touchdown_limits = {
                "max_descent_rate_ms": airframe.limits.max_descent_rate,
                "max_forward_speed_ms": airframe.limits.max_forward_speed,
            }
            thrust = {
                "scale_pct": thrust_scale(
                    airframe.air_density,
                    airframe.disk_area,
                    airframe.rotor_radius,
                    airframe.nominal_rotor_speed,
                    airframe.gross_weight,
                ),
                "source": f"airframe {airframe.name}",
            }
        self._touchdown_limits, self._airframe = touchdown_limits, airframe
        return {
            "units": {"m_per_ft": FT, "ms_per_kt": KT},
            "stale_after_s": self._stale_after_s,
            "rotor_limits": rotor_limits,
            "touchdown_limits": touchdown_limits,
            "thrust": thrust,
            "airframe": airframe_label,
            "state_topic": self.resolve_topic_name(self._state_topic),
        }

    def _thrust_scale_for_plan(self, status: Mapping[str, Any]) -> float | None:
        """The thrust scale for the plan's own weight and density altitude (None: use the airframe file's)."""
        weight, density_altitude = status.get("gross_weight_n"), status.get("density_altitude_m")
        if self._airframe is None or weight is None or density_altitude is None:
            return None
        from helireach_ros.core.aircraft.airframe import isa_density

        airframe = self._airframe
        return thrust_scale(
            isa_density(density_altitude),
            airframe.disk_area,
            airframe.rotor_radius,
            airframe.nominal_rotor_speed,
            weight,
        )

    # -- ROS callbacks (any executor thread) -------------------------------------------------------------
    def _never_raising(self, callback: Callable[[Any], None], topic: str) -> Callable[[Any], None]:
        """Wraps a subscription callback: a message it cannot digest is logged and dropped, never raised."""

        def guarded(message: Any) -> None:
            try:
                callback(message)
            except Exception as error:
                self.get_logger().warning(
                    f"ignored a bad message on {topic}: {type(error).__name__}: {error}", throttle_duration_sec=5.0
                )

        return guarded

    def _store(self, update: Callable[[_Latest, float], None]) -> None:
        """Applies an update to the latest values under the lock (receipt time = now) and wakes the pages."""
        with self._lock:
            update(self._latest, time.monotonic())
        self._server_notify()

    def _server_notify(self) -> None:
        server = getattr(self, "_server", None)
        if server is not None:
            server.notify()

    def _on_safety_status(self, message: DiagnosticStatus) -> None:
        content = safety_status_section(message)
        drawn = self._family_member_for(content.get("envelope_id"))

        def update(latest: _Latest, now: float) -> None:
            latest.status = _Received(content, now)
            if content["level"] != "nodata":
                latest.last_known_banner = content["level"]
            if drawn is not None:
                self._envelope, self._envelope_safe, self._envelope_json, self._envelope_id = drawn
                latest.versions["envelope"] += 1

        self._store(update)

    def _family_member_for(self, envelope_id: Any) -> tuple[Any, np.ndarray, str, str] | None:
        """With a family: the member to draw for a status answering from the members ``envelope_id`` names (their
        ids joined by ``+``; the heaviest, highest of them), as (envelope, safe masks, section JSON, the status's id);
        None when it is the one drawn, or names no member."""
        if self._family is None or not envelope_id or envelope_id == self._envelope_id:
            return None
        named = set(str(envelope_id).split("+"))
        members = [(member, envelope) for member, envelope in self._family.members if envelope.envelope_id in named]
        if not members:
            return None
        member, envelope = _most_restrictive(members)
        conditions = member.conditions if len(members) == 1 else f"{member.conditions} (worst of {len(members)})"
        section = _family_section(envelope, conditions, str(envelope_id))
        return envelope, _safe_masks(envelope), to_json({**section, "file": self._envelope_file}), str(envelope_id)

    def _on_state(self, message: Odometry) -> None:
        reading = rm.read_odometry(message)
        content = {
            "height_m": finite(reading.height),
            "speed_ms": finite(reading.forward_speed),
            "climb_ms": finite(reading.climb_rate),
            "distance_m": finite(reading.distance),
        }
        margins = None
        if self._envelope is not None and content["height_m"] is not None and content["speed_ms"] is not None:
            climb = content["climb_ms"] if content["climb_ms"] is not None else 0.0
            assert self._envelope_safe is not None  # set with the envelope
            safe = self._envelope_safe[self._envelope.nearest_slice(climb)]
            # judged as on the ground below 0 m, as the status node does
            height = max(content["height_m"], 0.0)
            margins = axis_margins(self._envelope.heights, self._envelope.speeds, safe, height, content["speed_ms"])

        def update(latest: _Latest, now: float) -> None:
            latest.state = _Received(content, now)
            latest.margins = margins
            if latest.touchdown_from_state is not None and self._in_failure_episode(latest):
                latest.touchdown_from_state.observe(content["height_m"], content["climb_ms"], content["speed_ms"], now)

        self._store(update)

    @staticmethod
    def _in_failure_episode(latest: _Latest) -> bool:
        """The episode says failed or landed (the monitor may say landed first), or (none heard) a failure came."""
        if latest.episode is not None:
            return latest.episode.content.get("phase") in ("failed", "landed")
        return latest.failure is not None

    @staticmethod
    def _start_episode(latest: _Latest) -> None:
        """A new failure episode: the previous touchdown no longer applies."""
        latest.touchdown = None
        if latest.touchdown_from_state is not None:
            latest.touchdown_from_state.reset()

    def _on_rotor(self, message: JointState) -> None:
        try:
            speed = finite(rm.read_rotor(message).rotor_speed)
        except ValueError:  # no main_rotor velocity: shown as "no main rotor speed"
            speed = None

        def update(latest: _Latest, now: float) -> None:
            latest.rotor = _Received({"speed_rad_s": speed}, now)

        self._store(update)

    def _on_failure(self, message: Header) -> None:
        failure_stamp_ns = rm.stamp_nanoseconds(message.stamp)

        def update(latest: _Latest, now: float) -> None:
            latest.failure = _Received({"stamp_s": failure_stamp_ns * 1e-9}, now)
            self._start_episode(latest)
            # a plan of an earlier failure must not stand for this one: cleared until the new plan arrives
            if self._plan_of_earlier_failure(latest, failure_stamp_ns):
                latest.trajectory = latest.path = latest.plan_status = None
                latest.plan_reference = None
                latest.cue_events = ()
            self._rebuild_plan(latest)

        self._store(update)

    @staticmethod
    def _plan_of_earlier_failure(latest: _Latest, failure_stamp_ns: int) -> bool:
        """Whether the stored plan belongs to a failure before ``failure_stamp_ns``.

        The plan status' ``failure_stamp_ns`` decides when it has one (a standby plan is stamped before the
        failure); else the trajectory's stamp (planned from a state before this failure: an earlier one); a plan
        status alone, with neither, is an earlier one's.
        """
        if latest.plan_status is not None:
            try:
                return int(latest.plan_status.content["values"]["failure_stamp_ns"]) < failure_stamp_ns
            except (KeyError, ValueError):
                pass
        if latest.trajectory is not None:
            return 0 < latest.trajectory.content.get("stamp_s", 0.0) * 1e9 < failure_stamp_ns - 1e3
        return latest.plan_status is not None or latest.path is not None

    def _on_trajectory(self, message: JointTrajectory) -> None:
        section = trajectory_section(message)
        events: tuple[CueEvent, ...] = ()
        if "error" not in section:
            events = plan_cue_events(section["t_s"], section["collective"], section["pitch_rad"])
        now_ros = self.get_clock().now().nanoseconds * 1e-9
        stamp = section.get("stamp_s", 0.0)

        def update(latest: _Latest, now: float) -> None:
            latest.trajectory = _Received(section, now)
            # t = 0 of the plan: its stamp if plausible on our clock, else when it arrived
            lag = now_ros - stamp
            latest.plan_reference = now - lag if stamp > 0 and 0.0 <= lag <= _PLAN_STAMP_TOLERANCE_S else now
            latest.cue_events = events
            self._rebuild_plan(latest)

        self._store(update)

    def _on_episode(self, message: DiagnosticStatus) -> None:
        content = episode_section(message)

        def update(latest: _Latest, now: float) -> None:
            previous = latest.episode.content if latest.episode is not None else {}
            if content["phase"] == "failed" and (
                previous.get("phase") != "failed" or previous.get("episode_id") != content["episode_id"]
            ):
                self._start_episode(latest)
            latest.episode = _Received(content, now)

        self._store(update)

    def _on_path(self, message: PathMsg) -> None:
        self._store_plan_part("path", path_section(message))

    def _on_plan_status(self, message: DiagnosticStatus) -> None:
        section = plan_status_section(message)
        section["thrust_scale_pct"] = self._thrust_scale_for_plan(section)
        self._store_plan_part("plan_status", section)

    def _on_robust_verdict(self, message: DiagnosticStatus) -> None:
        self._store_plan_part("robust_verdict", robust_verdict_section(message))

    def _on_touchdown(self, message: DiagnosticStatus) -> None:
        content = touchdown_section(message)

        def update(latest: _Latest, now: float) -> None:
            latest.touchdown = _Received(content, now)

        self._store(update)

    def _state_age_s(self, stamp_ns: int | None) -> float | None:
        """Age of a message's state stamp on this node's clock now, s (None without a stamp)."""
        if stamp_ns is None or stamp_ns <= 0:
            return None
        return (self.get_clock().now().nanoseconds - stamp_ns) * 1e-9

    def _on_footprint(self, message: DiagnosticStatus) -> None:
        content = footprint_section(message)
        state_age = self._state_age_s(content["state_stamp_ns"])

        def update(latest: _Latest, now: float) -> None:
            latest.footprint = _Received(content, now, state_age)

        self._store(update)

    def _on_live_reachability(self, message: DiagnosticStatus) -> None:
        """Only the landing site of a live verdict (the banner follows the status node, which weighs the verdict)."""
        values = rm.status_values(message)
        site = site_section(values)
        if site is None:  # no sites configured, or a verdict without them: the last site shown ages out
            return
        state_age = self._state_age_s(LiveVerdictValues.from_values(values).state_stamp_ns)

        def update(latest: _Latest, now: float) -> None:
            latest.live_site = _Received(site, now, state_age)

        self._store(update)

    def _store_plan_part(self, part: str, section: dict[str, Any]) -> None:
        def update(latest: _Latest, now: float) -> None:
            setattr(latest, part, _Received(section, now))
            self._rebuild_plan(latest)

        self._store(update)

    def _rebuild_plan(self, latest: _Latest) -> None:
        """Re-serialises the plan section (called under the lock on every plan-related message)."""
        parts = {"trajectory": latest.trajectory, "path": latest.path, "status": latest.plan_status}
        if latest.failure is None and all(part is None for part in parts.values()):
            plan = None
        else:
            plan = {name: (part.content if part is not None else None) for name, part in parts.items()}
            # beside the plan only: the page matches it to the plan's failure (a verdict alone is no plan)
            plan["robust_verdict"] = latest.robust_verdict.content if latest.robust_verdict is not None else None
        self._plan_json = to_json(plan)
        latest.versions["plan"] += 1

    # -- frames for the pages (server thread) -------------------------------------------------------------
    def _frame(self, sent_versions: dict[str, int]) -> tuple[str, dict[str, int]]:
        now = time.monotonic()
        with self._lock:
            versions = dict(self._latest.versions)
            parts = [
                f'"{name}":{text}'
                for name, text in (
                    ("config", self._config_json),
                    ("envelope", self._envelope_json),
                    ("plan", self._plan_json),
                )
                if sent_versions.get(name) != versions[name]
            ]
            live = self._live_section(self._latest, now)
        parts.append('"live":' + to_json(live))
        return "{" + ",".join(parts) + "}", versions

    def _live_section(self, latest: _Latest, now: float) -> dict[str, Any]:
        """What changes every frame: the phase banner (staleness decided here), status, state, rotor, plan timing."""
        stale_after = self._stale_after_s

        def age(received: _Received | None) -> float | None:
            return None if received is None else max(now - received.received, 0.0)

        def stale(received: _Received) -> bool:
            return max(now - received.received, 0.0) > stale_after

        status_age = age(latest.status)
        if latest.status is None:
            banner = {"level": "nodata", "message": "no safety status received", "margin": None, "envelope_id": None}
        else:
            banner = dict(latest.status.content)
            if status_age is not None and status_age > stale_after:
                banner.update(level="nodata", message=f"safety status silent for {status_age:.1f} s")
        if latest.held:
            banner.update(level="nodata", message="display held: ROS stopped, showing the last data")
        mismatch = bool(banner.get("envelope_id") and self._envelope_id and banner["envelope_id"] != self._envelope_id)
        plan_clock = None
        if latest.trajectory is not None and latest.plan_reference is not None:
            plan_clock = self._plan_clock(latest, now)
        touchdown = self._touchdown_result(latest, now)
        status_message = str(latest.status.content.get("message", "")) if latest.status is not None else ""
        phase = decide_phase(
            PhaseInputs(
                source_ages=(
                    ("state", age(latest.state)),
                    ("rotor", age(latest.rotor)),
                    ("safety status", status_age),
                    ("failure episode", age(latest.episode)),
                ),
                stale_after_s=stale_after,
                status_level=latest.status.content["level"] if latest.status is not None else None,
                status_message=("ENVELOPE MISMATCH \u00b7 " if mismatch else "") + status_message,
                episode_phase=latest.episode.content["phase"] if latest.episode is not None else None,
                failure_event=latest.failure is not None,
                plan=self._plan_verdict(latest),
                plan_remaining_s=plan_clock["time_to_touchdown_s"] if plan_clock else None,
                touchdown=touchdown,
                held=latest.held,
            )
        )
        cue = None
        if phase.phase.value == "autorotation" and plan_clock is not None:
            cue = next_cue(latest.cue_events, plan_clock["elapsed_s"])
        live: dict[str, Any] = {
            "phase": {
                "phase": phase.phase.value,
                "level": phase.level,
                "word": phase.word,
                "detail": phase.detail,
                "silent": list(phase.silent),
            },
            "status": {
                **banner,
                "age_s": status_age,
                "last_level": latest.last_known_banner,
                "envelope_mismatch": mismatch,
            },
            "state": None,
            "rotor": None,
            "failure": None,
            "episode": None,
            "plan_clock": plan_clock,
            "cue": cue,
            "touchdown": None if touchdown is None else vars(touchdown),
            "margins": latest.margins,
            "held": latest.held,
        }
        if latest.state is not None:
            live["state"] = {
                **latest.state.content,
                "age_s": age(latest.state),
                "stale": stale(latest.state),
            }
        if latest.rotor is not None:
            live["rotor"] = {
                **latest.rotor.content,
                "age_s": age(latest.rotor),
                "stale": stale(latest.rotor),
            }
        if latest.failure is not None:
            live["failure"] = {"age_s": age(latest.failure)}
        if latest.episode is not None:
            live["episode"] = {**latest.episode.content, "stale": stale(latest.episode)}
        live["footprint"] = self._footprint_live(latest, now)
        live["site"] = self._site_live(latest, now, live["footprint"])
        return live

    @staticmethod
    def _current_state_age(
        received: _Received, now: float, max_age_s: float = LIVE_MAX_AGE_S
    ) -> tuple[float | None, bool]:
        """The age of a message's state now (s; None: no stamp) and whether it is current (0 ≤ age ≤ max age)."""
        if received.state_age_s is None:
            return None, False
        age = received.state_age_s + max(now - received.received, 0.0)
        return age, 0.0 <= age <= max_age_s

    @classmethod
    def _footprint_live(cls, latest: _Latest, now: float) -> dict[str, Any] | None:
        """The footprint with its age; ``current`` only for a drawable one whose state is recent (never a held page)."""
        if latest.footprint is None:
            return None
        age, current = cls._current_state_age(latest.footprint, now, FOOTPRINT_MAX_AGE_S)
        content = latest.footprint.content
        return {**content, "age_s": age, "current": current and not content["off"] and not latest.held}

    @classmethod
    def _site_live(cls, latest: _Latest, now: float, footprint: Mapping[str, Any] | None) -> dict[str, Any] | None:
        """The selected landing site from the latest live verdict or plan status that carries one, with what the
        side view says of it (:func:`~helireach_ros.display.sections.site_verdict`)."""
        candidates: list[tuple[float, str, _Received]] = []
        if latest.live_site is not None:
            candidates.append((latest.live_site.received, "live", latest.live_site))
        if latest.plan_status is not None and latest.plan_status.content.get("site") is not None:
            candidates.append((latest.plan_status.received, "plan", latest.plan_status))
        if not candidates:
            return None
        _, source, received = max(candidates, key=lambda candidate: candidate[0])
        if source == "live":
            site = received.content
            age, current = cls._current_state_age(received, now)
            plan_void = False
        else:  # the plan's word holds during its failure episode only (not once the engine recovered)
            site = received.content["site"]
            age, current = None, True
            plan_void = received.content.get("status") == "ended" or not cls._in_failure_episode(latest)
        current = current and not latest.held
        kind, words = site_verdict(site, source, current, plan_void)
        in_footprint = None
        if footprint is not None and footprint["current"]:
            in_footprint = footprint["sites"].get(site["name"])
        return {
            **site,
            "source": source,
            "age_s": age,
            "current": current,
            "kind": kind,
            "words": words,
            "in_footprint": in_footprint,
        }

    @staticmethod
    def _plan_verdict(latest: _Latest) -> PlanVerdictInput | None:
        """The plan status for the banner; a trajectory without one counts as unverified (never as safe)."""
        if latest.plan_status is None:
            if latest.trajectory is None:
                return None
            return PlanVerdictInput(status="unverified", level="caution", message="no plan status")
        status = latest.plan_status.content
        return PlanVerdictInput(
            status=status.get("status"),
            level=status.get("level"),
            verified=status.get("verified"),
            fallback=status.get("fallback"),
            late=status.get("late"),
            standby=status.get("standby"),
            robust=status.get("robust"),
            message=str(status.get("message") or ""),
        )

    @staticmethod
    def _touchdown_result(latest: _Latest, now: float) -> TouchdownResult | None:
        """The vehicle's touchdown report of this episode, else the one found in the state stream, else None."""
        if latest.touchdown is not None:
            report = latest.touchdown.content
            return TouchdownResult(
                "touchdown",
                report["within_limits"],
                report["descent_rate_ms"],
                report["forward_speed_ms"],
                report["max_descent_rate_ms"],
                report["max_forward_speed_ms"],
                report["rotor_speed_pct"],
                report["time_after_failure_s"],
                str(report.get("reason") or ""),
            )
        return latest.touchdown_from_state.result(now) if latest.touchdown_from_state is not None else None

    @staticmethod
    def _plan_clock(latest: _Latest, now: float) -> dict[str, Any]:
        """Time since the plan's t = 0 and the time left to touchdown (plan status, else the trajectory's end)."""
        elapsed = now - float(latest.plan_reference or now)
        time_to_land = None
        if latest.plan_status is not None:
            time_to_land = latest.plan_status.content.get("time_to_land_s")
        if time_to_land is None:
            times = [t for t in latest.trajectory.content.get("t_s", []) if t is not None] if latest.trajectory else []
            time_to_land = times[-1] if times else None
        remaining = None if time_to_land is None else max(time_to_land - elapsed, 0.0)
        return {"elapsed_s": elapsed, "time_to_touchdown_s": remaining, "time_to_land_s": time_to_land}

    # -- public --------------------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """The page's address, e.g. ``http://127.0.0.1:8080/`` (the actual port when ``port`` was 0)."""
        host, port = self._server.address or (self._bind, self._port)
        host = {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(host, host)
        return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"

    @property
    def page_count(self) -> int:
        """Pages connected right now."""
        return self._server.page_count

    def hold(self) -> None:
        """Marks the data as held (ROS stopped): pages keep the last plan and track, the banner shows NO DATA."""
        with self._lock:
            self._latest.held = True
        self._server_notify()

    def destroy_node(self) -> None:
        """Stops the web server (pages get WebSocket close 1001) and destroys the node."""
        server = getattr(self, "_server", None)
        if server is not None:
            server.stop()
        super().destroy_node()


def hold_until_interrupted(display: CockpitDisplay) -> None:
    """Keeps serving ``display`` (data frozen, marked held) until SIGINT or SIGTERM; for ``--hold``."""
    import signal

    display.hold()
    interrupted = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: interrupted.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        print(f"helireach display: holding {display.url} (Ctrl-C to stop)", flush=True)
        while not interrupted.wait(0.5):
            pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def create_display_with_fallback(preferred_port: int = DEFAULT_PORT, **node_options: Any) -> CockpitDisplay:
    """A display on ``preferred_port``, or on any free port when that one is taken (a demo must not fail
    because 8080 is busy); read the address from :attr:`CockpitDisplay.url`."""
    try:
        return CockpitDisplay(parameter_overrides=[Parameter("port", value=preferred_port)], **node_options)
    except DisplayServerError:
        return CockpitDisplay(parameter_overrides=[Parameter("port", value=0)], **node_options)


def run_display(
    args: list[str] | None = None,
    parameter_overrides: list[Parameter] | None = None,
    hold: bool = False,
    program: str = "helireach display",
) -> int:
    """Runs the display until Ctrl-C/SIGTERM (then, with ``hold``, keeps the page up until the next one).

    Args:
        args: ROS command-line arguments (``--ros-args ...``), as for ``rclpy.init``.
        parameter_overrides: node parameters, e.g. ``[Parameter("port", value=0)]``.
        hold: keep serving the last data after ROS stops.
        program: how error lines name the command.

    Returns:
        0, 1 when the web server cannot start, 2 for a bad parameter value (one line on stderr).
    """
    # SIGTERM as well as SIGINT end spinning cleanly (rclpy's handlers wake the blocked executor)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.ALL)
    display = None
    try:
        with shutdown_is_a_normal_stop():
            display = CockpitDisplay(parameter_overrides=parameter_overrides or [])
            print(f"helireach display: {display.url}", flush=True)
            rclpy.spin(display)
    except DisplayServerError as error:
        print(f"{program}: {error}", file=sys.stderr, flush=True)
        return 1
    except ParameterError as error:
        print(f"{program}: error: {error}", file=sys.stderr, flush=True)
        return 2
    finally:
        rclpy.try_shutdown()
        if display is not None:
            if hold:
                hold_until_interrupted(display)
            display.destroy_node()
    return 0


def main(args: list[str] | None = None) -> None:
    """Console entry point (ros2/demos style): ``python -m helireach_ros.display.node --ros-args ...``.

    ``--help`` prints the usage and a bad command line exits 2, as for every node script
    (:func:`~helireach_ros.ros.executors.node_command_line`).
    """
    arguments, script, early_exit = node_command_line(CockpitDisplay, args)
    if early_exit is not None:
        raise SystemExit(early_exit)
    code = run_display(arguments, program=script)
    if code:
        raise SystemExit(code)


if __name__ == "__main__":
    main()
