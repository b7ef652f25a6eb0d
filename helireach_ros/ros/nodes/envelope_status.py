"""Envelope status node: the published safety status, never wider than its evidence.

Translates what arrives into evidence and publishes the decision of
:func:`helireach_ros.core.policies.safety_status.assess_safety` (the module has the rules; no policy lives here) on
``/helireach/safety_status`` (``diagnostic_msgs/DiagnosticStatus``, latched)
when the verdict changes and every ``publish_period``. The evidence:

- the **envelope** (parameter ``envelope_file``; empty = the shipped one): its conservative answer at the
  canonical state (``/helireach/state``, :meth:`helireach_ros.core.envelope.data.Envelope.query`; a 3-D
  envelope at the measured climb rate), which holds only inside the envelope's validity domain
  (:mod:`helireach_ros.core.envelope.domain`: level trim — a 3-D envelope: its climb-rate range — at nominal
  rotor speed, within tolerances; the rotor speed from ``/helireach/rotor_state``);
- the **live verdict** (``/helireach/live_reachability``, from the planner): the landing NLP solved and
  replayed from the measured state, evidence while its state is at most ``live_max_age`` old;
- where the envelope holds **robust verdicts** (``helireach envelope compute --robust``) they are used by
  default (parameter ``envelope_verdict``: ``robust`` or ``nominal``): SAFE then means the landing also held,
  closed loop, in every perturbed model flown, and a state safe only in the nominal model is CAUTION; the
  status's ``envelope_verdict`` value says which verdict it rests on (and ``envelope_verdict_note`` why not the
  robust one, when it was asked for);
- after a failure (``/helireach/failure_episode`` says ``failed``) only the planner's **current plan**
  (``/helireach/plan_status`` of that episode);
- **input QoS**: whatever the rest says, the status is ERROR (``INPUT QOS:``) while a helireach node reports
  an *input* with incompatible QoS (the ``<node>: QoS`` statuses on ``/diagnostics``, each counting for
  ``qos_report_timeout``; :mod:`helireach_ros.ros.qos`) or this node's own input has one.

====== ==========================================================================================
level  meaning
====== ==========================================================================================
OK     SAFE: the evidence covering the state says a verified landing exists (envelope margin at least
       ``warn_margin``; live J at most ``live_warn_value``); after a failure: a verified plan
WARN   CAUTION: safe, but near the boundary or a limit, or the rotor speed is not measured
ERROR  AVOID: not proven safe (unsafe, unverified, failed, outside the grid); after a failure: a fallback,
       an unverified plan or none yet; any input QoS problem
STALE  NO DATA: no valid fresh state, or no evidence covers the state (outside the envelope's domain with no
       current live verdict, or no envelope and no live verdict); on the ground after a landing
====== ==========================================================================================

Heights between the monitor's ``min_height`` and 0 count as 0 (sensor noise on the ground). Setting
``envelope_file`` at run time reloads the envelope. Run: ``python -m helireach_ros.ros.nodes.envelope_status``.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from helireach_ros.core.envelope.data import VERDICTS
from helireach_ros.core.policies.failure_episode import EpisodeState
from helireach_ros.core.policies.safety_status import (
    LIVE_WARN_VALUE,
    LiveEvidence,
    PlanEvidence,
    assess_safety,
    live_evidence,
    plan_evidence,
)
from helireach_ros.core.policies.vehicle_readings import OdometryReading, StateLimits, state_problems
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameter_table import parameter
from helireach_ros.ros.parameters import ParameterError, declare_aircraft, declare_parameters
from helireach_ros.ros.qos import QOS_STATUS_SUFFIX, QosWatch, input_problems_of

__all__ = ["EnvelopeStatusNode", "EnvelopeStatusParameters", "SafetyVerdict", "evaluate_safety", "main"]


@dataclass(frozen=True)
class SafetyVerdict:
    """One safety status: level, short text for people, and the values published with it."""

    level: bytes
    message: str
    values: dict[str, Any]


def evaluate_safety(*args: Any, **kwargs: Any) -> SafetyVerdict:
    """The safety status of a state (:func:`helireach_ros.core.policies.safety_status.assess_safety`, same arguments)
    with its level as the ``DiagnosticStatus`` constant."""
    assessment = assess_safety(*args, **kwargs)
    return SafetyVerdict(rm.DIAGNOSTIC_LEVELS[assessment.level], assessment.message, assessment.values)


@dataclass(frozen=True)
class EnvelopeStatusParameters:
    """The envelope status node's own parameters, SI (one table: :mod:`helireach_ros.ros.parameter_table`); the
    aircraft's (``airframe``, ``gross_weight``, ``density_altitude``) come from ``declare_aircraft``."""

    envelope_file: str = parameter(
        "",
        "H-V envelope file, or an envelope family's folder (the members for today's weight and density altitude; "
        "'' = the shipped file)",
        read_only=False,
    )
    warn_margin: float = parameter(
        20.0, "WARN below this distance to the boundary (ft/kt units)", (0.0, 1e4), read_only=False
    )
    stale_timeout: float = parameter(0.5, "a state older than this is stale, s", (0.01, 60.0))
    publish_period: float = parameter(0.5, "steady publishing period of the status, s", (0.01, 60.0))
    diagnostics_period: float = parameter(1.0, "period of /diagnostics, s", (0.05, 60.0))
    qos_report_timeout: float = parameter(3.0, "a node's QoS report on /diagnostics counts this long, s", (0.1, 600.0))
    live_max_age: float = parameter(
        1.0, "a live verdict whose state is older than this is no evidence, s", (0.01, 60.0)
    )
    live_warn_value: float = parameter(LIVE_WARN_VALUE, "a safe live verdict with J above this is CAUTION", (-1.0, 0.0))
    envelope_verdict: str = parameter(
        "robust",
        "robust: the envelope's robust verdict where it has one (else nominal, and the status says so); nominal",
        read_only=False,
    )


class EnvelopeStatusNode(Node):
    """Publishes the safety status of the current state against an H-V envelope.

    Parameters: ``airframe``, ``gross_weight``, ``density_altitude`` (the aircraft today, shared with the
    planner: :func:`~helireach_ros.ros.messages.declare_aircraft`; an envelope made for another aircraft is
    refused), ``envelope_file`` ('' = shipped; settable at run time), ``envelope_verdict`` (``robust`` or
    ``nominal``; settable), ``warn_margin`` (ft/kt units; settable), ``stale_timeout`` (s), ``publish_period``
    (s), ``diagnostics_period`` (s), ``qos_report_timeout`` (s a node's QoS report on ``/diagnostics`` counts for).
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_envelope_status", **node_options)
        load_aircraft = declare_aircraft(self)
        self.config = config = declare_parameters(self, EnvelopeStatusParameters)
        envelope_file, publish_period, diagnostics_period = (
            config.envelope_file, config.publish_period, config.diagnostics_period,
        )  # fmt: skip
        # settable at run time (on_set_parameters updates them): the table holds the start-up values
        self._warn_margin, self._envelope_verdict = config.warn_margin, config.envelope_verdict
        self._stale_timeout, self._qos_report_timeout = config.stale_timeout, config.qos_report_timeout
        self._live_max_age, self._live_warn_value = config.live_max_age, config.live_warn_value
        if self._envelope_verdict not in VERDICTS:
            raise ParameterError(
                f"parameter 'envelope_verdict' of {self.get_name()} must be one of {', '.join(VERDICTS)}, "
                f"got {self._envelope_verdict!r}"
            )

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
        self._reading: OdometryReading | None = None
        self._received_ns = 0
        self._rotor: tuple[float, int] | None = None  # (rotor speed, received ns)
        self._live: dict[str, str] | None = None  # the latest /helireach/live_reachability values
        self._episode = EpisodeState()
        self._plan: dict[str, str] | None = None  # the latest /helireach/plan_status values
        self._last_published: tuple[bytes, str, str] | None = None
        self._last_verdict: SafetyVerdict | None = None
        # Input problems other helireach nodes report: status name → (received ns, problems text).
        self._qos_reports: dict[str, tuple[int, str]] = {}

        self._qos_watch = QosWatch(self, diagnostics_period)
        self._status_publisher = self._qos_watch.create_publisher(
            DiagnosticStatus, rm.TOPIC_SAFETY_STATUS, rm.LATCHED_QOS
        )
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._load_envelope(envelope_file)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._qos_watch.create_subscription(Odometry, rm.TOPIC_STATE, self._on_state, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(JointState, rm.TOPIC_ROTOR_STATE, self._on_rotor, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY, self._on_live, rm.LATCHED_QOS)
        self._qos_watch.create_subscription(
            DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, self._on_episode, rm.LATCHED_QOS
        )
        self._qos_watch.create_subscription(DiagnosticStatus, rm.TOPIC_PLAN_STATUS, self._on_plan, rm.LATCHED_QOS)
        self._qos_watch.create_subscription(DiagnosticArray, rm.TOPIC_DIAGNOSTICS, self._on_diagnostics, rm.SENSOR_QOS)
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
            from helireach_ros.core.envelope.family import EnvelopeFamily, is_family

            if self.aircraft is None:
                raise RuntimeError(self._aircraft_error)
            resolved = path or str(default_envelope_path())
            envelope: Any
            if is_family(resolved):  # the member(s) for today's weight, density altitude and wind
                aircraft = self.aircraft
                family = EnvelopeFamily.load(resolved, aircraft)
                envelope = family.at(aircraft.gross_weight, aircraft.density_altitude, aircraft.headwind)
            else:
                envelope = load_envelope(resolved, self.aircraft)
            error = ""
            self.get_logger().info(f"envelope {envelope.envelope_id} loaded from {resolved}: {envelope!r}")
        except Exception as exc:  # a missing module, file or a corrupt one: STALE, never a crash
            resolved = path or "(shipped envelope)"
            envelope, error = None, f"{type(exc).__name__}: {exc}"
            self.get_logger().error(f"no envelope, safety status is STALE: {error}")
        with self._lock:
            self._envelope, self._envelope_error, self._envelope_path = envelope, error, resolved

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        for changed in parameters:
            if changed.name == "envelope_file" and changed.type_ != Parameter.Type.STRING:
                return SetParametersResult(successful=False, reason="envelope_file must be a string")
            if changed.name == "envelope_verdict" and changed.value not in VERDICTS:
                return SetParametersResult(
                    successful=False, reason=f"envelope_verdict must be one of {', '.join(VERDICTS)}"
                )
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        for changed in parameters:
            if changed.name == "envelope_file":
                self._load_envelope(changed.value)
            elif changed.name == "warn_margin":
                self._warn_margin = float(changed.value)
            elif changed.name == "envelope_verdict":
                self._envelope_verdict = str(changed.value)
        self._publish(force=True)

    def _on_state(self, message: Odometry) -> None:
        with self._lock:
            self._reading = rm.read_odometry(message)
            self._received_ns = self.get_clock().now().nanoseconds
        self._publish(force=False)

    def _on_rotor(self, message: JointState) -> None:
        try:
            reading = rm.read_rotor(message)
        except ValueError:
            return  # the monitor republishes only valid rotor states; anything else is not a measurement
        if state_problems(StateLimits(), rotor=reading):
            return
        with self._lock:
            self._rotor = (reading.rotor_speed, self.get_clock().now().nanoseconds)

    def _on_live(self, message: DiagnosticStatus) -> None:
        with self._lock:
            self._live = rm.status_values(message)
        self._publish(force=False)

    def _on_episode(self, message: DiagnosticStatus) -> None:
        try:
            episode = EpisodeState.from_values(rm.status_values(message))
        except ValueError as error:
            self.get_logger().warning(f"unreadable failure episode ignored: {error}", throttle_duration_sec=5.0)
            return
        with self._lock:
            self._episode = episode
        self._publish(force=False)

    def _on_plan(self, message: DiagnosticStatus) -> None:
        with self._lock:
            self._plan = rm.status_values(message)
        self._publish(force=False)

    def _evidence(self, now_ns: int) -> tuple[float | None, LiveEvidence | None, str, PlanEvidence | None]:
        """(fresh rotor speed, live evidence, episode phase, current plan) from what arrived (caller holds the lock)."""
        rotor_speed = None
        if self._rotor is not None and (now_ns - self._rotor[1]) * 1e-9 <= self._stale_timeout:
            rotor_speed = self._rotor[0]
        live = live_evidence(self._live, now_ns, self._live_max_age) if self._live is not None else None
        phase = self._episode.phase.value
        episode = "normal" if phase in ("no_flag", "ended") else phase
        plan = None
        if episode == "failed" and self._plan is not None:
            plan = plan_evidence(self._plan, self._episode.started_ns)
        return rotor_speed, live, episode, plan

    def _on_diagnostics(self, array: DiagnosticArray) -> None:
        now_ns = self.get_clock().now().nanoseconds
        own = f"{self.get_name()}{QOS_STATUS_SUFFIX}"
        changed = False
        with self._lock:
            for status in array.status:
                if status.name.endswith(QOS_STATUS_SUFFIX) and status.name != own:
                    problems = input_problems_of(status)
                    previous = self._qos_reports.get(status.name)
                    changed |= previous is None or previous[1] != problems
                    self._qos_reports[status.name] = (now_ns, problems)
        if changed:
            self._publish(force=True)

    def _input_problems(self, now_ns: int) -> list[str]:
        """Input QoS problems of this node and of the fresh reports of the others (caller holds the lock)."""
        own = [f"{self.get_name()}: {text}" for text in self._qos_watch.input_problems()]
        timeout_ns = self._qos_report_timeout * 1e9
        reported = [
            f"{name.removesuffix(QOS_STATUS_SUFFIX)}: {problems}"
            for name, (received_ns, problems) in sorted(self._qos_reports.items())
            if problems and now_ns - received_ns <= timeout_ns
        ]
        return own + reported

    def _publish_steady(self) -> None:
        self._publish(force=True)

    def _publish(self, force: bool) -> None:
        """Publishes the current verdict if forced or if its level or envelope status changed."""
        now_ns = self.get_clock().now().nanoseconds
        with self._lock:
            age = (now_ns - self._received_ns) * 1e-9 if self._reading is not None else float("inf")
            rotor_speed, live, episode, plan = self._evidence(now_ns)
            verdict = evaluate_safety(
                self._envelope,
                self._reading,
                age,
                self._stale_timeout,
                self._warn_margin,
                self._envelope_error,
                input_problems=self._input_problems(now_ns),
                rotor_speed=rotor_speed,
                live=live,
                episode=episode,
                plan=plan,
                live_warn_value=self._live_warn_value,
                envelope_verdict=self._envelope_verdict,
            )
            key = (verdict.level, verdict.message.split(":", 1)[0], str(verdict.values.get("evidence", "")))
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
    raise SystemExit(run_node(EnvelopeStatusNode, args))  # 2: bad command line or parameter (one line on stderr)


if __name__ == "__main__":
    main()
