"""Envelope status node: is the current state inside the proven-safe part of the H-V envelope?

Loads an envelope file (parameter ``envelope_file``; empty = the shipped one) and answers, for every
canonical state (``/helireach/state``), the envelope's conservative status and margin
(:meth:`helireach_ros.core.envelope.data.Envelope.query`). Publishes ``/helireach/safety_status``
(``diagnostic_msgs/DiagnosticStatus``, latched) when the verdict changes and every
``publish_period``:

====== ==========================================================================================
level  meaning
====== ==========================================================================================
OK     safe, and at least ``warn_margin`` (ft/kt units) from the boundary
WARN   safe, but closer than ``warn_margin`` to the boundary
ERROR  not proven safe: unsafe, unverified or failed grid nodes around the state, or outside the grid
STALE  no envelope (missing, corrupt or mismatched file), no state for ``stale_timeout``, or an
       invalid state (non-finite, far below ground, out of range)
====== ==========================================================================================

Heights between the monitor's ``min_height`` and 0 count as 0 (sensor noise on the ground). Setting
``envelope_file`` at run time reloads the envelope. Run: ``python -m helireach_ros.ros.nodes.envelope_status``.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import partial
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameters import declare_aircraft, declare_checked_parameter

__all__ = ["EnvelopeStatusNode", "SafetyVerdict", "evaluate_safety", "main"]


@dataclass(frozen=True)
class SafetyVerdict:
    """One safety status: level, short text for people, and the values published with it."""

    level: bytes
    message: str
    values: dict[str, Any]


def _where(height: float, speed: float) -> str:
    return f"{height / FT:.0f} ft, {speed / KT:.0f} kt"


def evaluate_safety(
    envelope: Any | None,
    reading: rm.OdometryReading | None,
    state_age_s: float,
    stale_timeout_s: float,
    warn_margin: float,
    envelope_error: str = "",
    limits: rm.StateLimits | None = None,
) -> SafetyVerdict:
    """The safety verdict for a state (see the module docstring for the levels).

    Args:
        envelope: the loaded :class:`~helireach_ros.core.envelope.data.Envelope`, or None.
        reading: the latest state, or None if none was received.
        state_age_s: time since that state was received, s.
        stale_timeout_s: older states are stale.
        warn_margin: WARN below this margin (ft/kt units).
        envelope_error: why there is no envelope.
        limits: plausible ranges (default :class:`~helireach_ros.ros.messages.StateLimits`).
    """
    envelope_id = envelope.envelope_id if envelope is not None else ""
    values: dict[str, Any] = {"envelope_id": envelope_id, "warn_margin_ft_kt": warn_margin}
    if envelope is None:
        return SafetyVerdict(DiagnosticStatus.STALE, f"NO DATA: no envelope ({envelope_error})", values)
    if reading is None:
        return SafetyVerdict(DiagnosticStatus.STALE, "NO DATA: no vehicle state received", values)
    values.update(
        height_m=reading.height,
        forward_speed_m_s=reading.forward_speed,
        climb_rate_m_s=reading.climb_rate,
        state_age_s=state_age_s,
    )
    if state_age_s > stale_timeout_s:
        return SafetyVerdict(DiagnosticStatus.STALE, f"NO DATA: vehicle state {state_age_s:.1f} s old", values)
    problems = rm.state_problems(limits or rm.StateLimits(), odometry=reading)
    if problems:
        return SafetyVerdict(DiagnosticStatus.STALE, f"NO DATA: invalid state ({'; '.join(problems)})", values)
    height = max(reading.height, 0.0)
    query = envelope.query(height, reading.forward_speed)
    values.update(envelope_status=query.status, envelope_value=query.value, margin_ft_kt=query.margin)
    where = _where(height, reading.forward_speed)
    if query.status == "safe" and query.margin >= warn_margin:
        return SafetyVerdict(DiagnosticStatus.OK, f"SAFE: {where}, margin {query.margin:.0f}", values)
    if query.status == "safe":
        return SafetyVerdict(DiagnosticStatus.WARN, f"CAUTION: {query.margin:.0f} from the boundary ({where})", values)
    if query.status == "outside":
        return SafetyVerdict(DiagnosticStatus.ERROR, f"AVOID: outside the envelope grid, unknown ({where})", values)
    if query.status == "unsafe":
        return SafetyVerdict(DiagnosticStatus.ERROR, f"AVOID: no safe landing ({where})", values)
    return SafetyVerdict(DiagnosticStatus.ERROR, f"AVOID: safe landing not proven, {query.status} ({where})", values)


class EnvelopeStatusNode(Node):
    """Publishes the safety status of the current state against an H-V envelope.

    Parameters: ``airframe``, ``gross_weight``, ``density_altitude`` (the aircraft today, shared with the
    planner: :func:`~helireach_ros.ros.messages.declare_aircraft`; an envelope made for another aircraft is
    refused), ``envelope_file`` ('' = shipped; settable at run time), ``warn_margin`` (ft/kt units;
    settable), ``stale_timeout`` (s), ``publish_period`` (s), ``diagnostics_period`` (s).
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_envelope_status", **node_options)
        declare = partial(declare_checked_parameter, self)
        load_aircraft = declare_aircraft(self)
        envelope_file = declare("envelope_file", "", "H-V envelope file ('' = the shipped one)", read_only=False)
        self._warn_margin = declare(
            "warn_margin", 20.0, "WARN below this distance to the boundary (ft/kt units)", (0.0, 1e4), read_only=False
        )
        self._stale_timeout = declare("stale_timeout", 0.5, "a state older than this is stale, s", (0.01, 60.0))
        publish_period = declare("publish_period", 0.5, "steady publishing period of the status, s", (0.01, 60.0))
        diagnostics_period = declare("diagnostics_period", 1.0, "period of /diagnostics, s", (0.05, 60.0))

        self._lock = threading.Lock()
        self._envelope: Any | None = None
        self._envelope_error = ""
        self._envelope_path = ""
        # The envelope must be for the aircraft the planner flies today (same parameters as the planner):
        # a status read off an envelope made for a lighter aircraft would be optimistic.
        try:
            self.aircraft: Any | None = load_aircraft()
            self._aircraft_error = ""
        except Exception as error:  # a broken airframe file or conditions: STALE with the reason, never a crash
            self.aircraft, self._aircraft_error = None, f"aircraft not configured ({type(error).__name__}: {error})"
        self._reading: rm.OdometryReading | None = None
        self._received_ns = 0
        self._last_published: tuple[bytes, str] | None = None
        self._last_verdict: SafetyVerdict | None = None

        self._status_publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_SAFETY_STATUS, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._load_envelope(envelope_file)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.create_subscription(
            Odometry, rm.TOPIC_STATE, self._on_state, rm.SENSOR_QOS, **rm.NO_QOS_EVENTS_SUBSCRIPTION
        )
        self.create_timer(publish_period, self._publish_steady)
        self.create_timer(diagnostics_period, self._publish_diagnostics)
        self._publish(force=True)

    @property
    def envelope(self) -> Any | None:
        """The loaded envelope (None if loading failed)."""
        return self._envelope

    @property
    def verdict(self) -> SafetyVerdict | None:
        """The last published verdict."""
        return self._last_verdict

    def _load_envelope(self, path: str) -> None:
        try:
            from helireach_ros.core.envelope.data import default_envelope_path, load_envelope

            if self.aircraft is None:
                raise RuntimeError(self._aircraft_error)
            resolved = path or str(default_envelope_path())
            envelope, error = load_envelope(resolved, self.aircraft), ""
            self.get_logger().info(f"envelope {envelope.envelope_id} loaded from {resolved}: {envelope!r}")
        except Exception as exc:  # a missing module, file or a corrupt one: STALE, never a crash
            resolved = path or "(shipped envelope)"
            envelope, error = None, f"{type(exc).__name__}: {exc}"
            self.get_logger().error(f"no envelope, safety status is STALE: {error}")
        with self._lock:
            self._envelope, self._envelope_error, self._envelope_path = envelope, error, resolved

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        for parameter in parameters:
            if parameter.name == "envelope_file" and parameter.type_ != Parameter.Type.STRING:
                return SetParametersResult(successful=False, reason="envelope_file must be a string")
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:
            if parameter.name == "envelope_file":
                self._load_envelope(parameter.value)
            elif parameter.name == "warn_margin":
                self._warn_margin = float(parameter.value)
        self._publish(force=True)

    def _on_state(self, message: Odometry) -> None:
        with self._lock:
            self._reading = rm.read_odometry(message)
            self._received_ns = self.get_clock().now().nanoseconds
        self._publish(force=False)

    def _publish_steady(self) -> None:
        self._publish(force=True)

    def _publish(self, force: bool) -> None:
        """Publishes the current verdict if forced or if its level or envelope status changed."""
        now_ns = self.get_clock().now().nanoseconds
        with self._lock:
            age = (now_ns - self._received_ns) * 1e-9 if self._reading is not None else float("inf")
            verdict = evaluate_safety(
                self._envelope, self._reading, age, self._stale_timeout, self._warn_margin, self._envelope_error
            )
            key = (verdict.level, str(verdict.values.get("envelope_status", "")))
            if not force and key == self._last_published:
                return
            self._last_published = key
            self._last_verdict = verdict
        self._status_publisher.publish(
            rm.diagnostic_status(
                verdict.level, f"{self.get_name()}: safety", verdict.message, "vehicle", verdict.values
            )
        )

    def _publish_diagnostics(self) -> None:
        with self._lock:
            verdict, path, error = self._last_verdict, self._envelope_path, self._envelope_error
            envelope_id = self._envelope.envelope_id if self._envelope is not None else ""
        if self._envelope is None:
            status = rm.diagnostic_status(
                DiagnosticStatus.ERROR,
                f"{self.get_name()}: envelope",
                f"no envelope: {error}",
                "helireach",
                {"envelope_file": path},
            )
        else:
            level_name = rm.LEVEL_NAMES.get(verdict.level, "?") if verdict is not None else "none"
            status = rm.diagnostic_status(
                DiagnosticStatus.OK,
                f"{self.get_name()}: envelope",
                f"envelope loaded; safety {level_name}",
                "helireach",
                {"envelope_file": path, "envelope_id": envelope_id},
            )
        self._diagnostics_publisher.publish(rm.diagnostic_array(self.get_clock().now().nanoseconds, status))


def main(args: list[str] | None = None) -> None:
    """Runs the envelope status node until Ctrl-C or SIGTERM."""
    run_node(EnvelopeStatusNode, args)


if __name__ == "__main__":
    main()
