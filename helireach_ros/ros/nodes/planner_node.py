"""Planner node: on an engine failure, plan the landing, publish it, and keep re-planning down to the ground.

The node translates: ROS inputs to core calls, their answers to messages. The failure handling is
:class:`~helireach_ros.core.policies.landing_supervisor.LandingSupervisor`, the statuses are
:mod:`helireach_ros.core.policies.plan_status`, the solvers are
:class:`~helireach_ros.core.workers.planner_backend.PlannerBackend` (a solver pool, or this process), live verdicts
come from :class:`~helireach_ros.core.policies.live_reachability.LiveEvaluator`. What it does, parameter by
parameter: docs/guides/planner-node.md.

Run: ``python -m helireach_ros.ros.nodes.planner_node`` (or the ``helireach_planner`` console script).
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.logging import LoggingSeverity
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.estimation.weight_tracking import WeightChoice
from helireach_ros.core.planning.fallback import FallbackPlan
from helireach_ros.core.policies.failure_episode import EpisodePhase, EpisodeState, FailureEpisode, PublishedPlan
from helireach_ros.core.policies.landing_sites import (
    SiteSelection,
    footprint_off_reason,
    footprint_off_report,
    sites_from_message,
    sites_report,
)
from helireach_ros.core.policies.landing_supervisor import EpisodeAction, LandingSupervisor, TimerAction
from helireach_ros.core.policies.plan_status import (
    PlannerIdentity,
    StatusReport,
    converged_plan_report,
    episode_end_report,
    fallback_report,
    no_plan_report,
    robust_report,
)
from helireach_ros.core.policies.vehicle_readings import CurrentState, LatestReadings, RotorSource
from helireach_ros.core.workers.failure_planning import FailurePlanner, RobustKey
from helireach_ros.core.workers.live_scheduling import LiveScheduler
from helireach_ros.core.workers.planner_backend import PlannerBackend
from helireach_ros.core.workers.solver_thread import SolverThread
from helireach_ros.ros import fast_logging
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.nodes.planner_parameters import PlannerParameters
from helireach_ros.ros.parameters import declare_aircraft, declare_parameters
from helireach_ros.ros.plan_messages import PlanMessages, plan_messages
from helireach_ros.ros.qos import QosWatch

if TYPE_CHECKING:
    from rclpy.publisher import Publisher

    from helireach_ros.core.aircraft.airframe import Airframe
    from helireach_ros.core.envelope.data import Envelope
    from helireach_ros.core.ocp.settings import PlannerSettings
    from helireach_ros.core.planning.planner import LandingPlan, LandingPlanner
    from helireach_ros.core.robustness.background import RobustSummary
    from helireach_ros.core.workers.solver_pool import SolverPool

__all__ = ["LandingPlannerNode", "main"]

_SEVERITIES = {"error": LoggingSeverity.ERROR, "warning": LoggingSeverity.WARN, "info": LoggingSeverity.INFO}
_PLAN_HISTORY = 200  # robust verdicts kept for inspection (demo, tests)


class LandingPlannerNode(Node):
    """Plans landings after engine failures and re-plans during the descent.

    Parameters: ``helireach_planner --help``; what each does: docs/guides/planner-node.md.
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_planner", **node_options)
        load_aircraft = declare_aircraft(self)
        self.config = config = declare_parameters(self, PlannerParameters)
        self.supervisor = LandingSupervisor(config.supervisor_settings())
        self.solver_thread = SolverThread(self.get_logger().error)
        self.robust_verdicts: list[tuple[RobustKey, RobustSummary | None]] = []  # published: (key, summary|None)
        self._backend: PlannerBackend | None = None  # None = not configured (a broken airframe or settings file)
        self.readings: LatestReadings | None = None
        self.sites = self._site_selection()
        self.footprint_off = "planner not configured"
        setup_error = ""
        try:
            from helireach_ros.core.ocp.settings import load_settings

            self._start_backend(load_aircraft(), load_settings(config.planner_settings or None))
        except Exception as error:  # a broken airframe/settings file: say so on every channel, keep running
            setup_error = f"{type(error).__name__}: {error}"
            self.get_logger().error(f"planner not configured, no plans will be made: {setup_error}")
        self.failures = FailurePlanner(
            self._backend, setup_error, self.supervisor, self.readings, self, self._now_ns,
            zero_power=config.assume_total_power_loss, disturbance=config.disturbance_settings(), sites=self.sites,
        )  # fmt: skip

        def latched(message_type: Any, topic: str) -> Publisher:
            return self.create_publisher(message_type, topic, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER)

        self._trajectory_publisher = latched(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY)
        self._path_publisher = latched(PathMsg, rm.TOPIC_LANDING_PATH)
        self._status_publisher = latched(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
        self._robust_publisher = latched(DiagnosticStatus, rm.TOPIC_ROBUST_VERDICT)
        self._live_publisher = latched(DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY)
        self._footprint_publisher = latched(DiagnosticStatus, rm.TOPIC_REACHABLE_FOOTPRINT)
        self._sites_publisher = latched(DiagnosticStatus, rm.TOPIC_LANDING_SITES)
        self._publish(self._sites_publisher, "landing sites", sites_report(self.sites, self._sites_note))
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        live_settings = config.live_settings()
        self.live: LiveScheduler | None = None
        if live_settings is not None and self._backend is not None:
            self.live = LiveScheduler(
                live_settings, self._backend, self.solver_thread, self._now_ns,
                partial(self._publish, self._live_publisher, "live reachability"),
                lambda plan, stamp_ns, frame: plan_messages(plan, stamp_ns, frame, config.world_frame), self.sites,
                config.footprint_period if not self.footprint_off else 0.0,
                partial(self._publish, self._footprint_publisher, "reachable footprint"),
            )  # fmt: skip
        if self.footprint_off:  # the latched topic says why there is none (never a silent absence)
            self._publish(self._footprint_publisher, "reachable footprint", footprint_off_report(self.footprint_off))
        # Inputs through a QosWatch: an incompatible publisher is an ERROR "<node>: QoS" on /diagnostics. The
        # failure event stays RELIABLE (one message per failure must not be lost; a best-effort one is reported).
        self._qos_watch = QosWatch(self, config.diagnostics_period)
        self._qos_watch.create_subscription(Odometry, rm.TOPIC_STATE, self._on_state, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(JointState, rm.TOPIC_ROTOR_STATE, self._on_rotor, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(Header, rm.TOPIC_FAILURE_EVENT, self._on_failure_event, rm.EVENT_QOS)
        self._qos_watch.create_subscription(
            DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, self._on_episode, rm.LATCHED_QOS
        )
        if config.landing_sites_topic and self.sites is not None:
            self._qos_watch.create_subscription(
                DiagnosticStatus, rm.TOPIC_MISSION_LANDING_SITES, self._on_mission_sites, rm.LATCHED_QOS
            )
        # A periodic check, never cancelled or reset from the solver thread (cancelling a timer that the
        # executor is about to fire raises inside the executor). Every half deadline:
        # the fallback goes out within 1.5 deadlines without waking the executor needlessly.
        self.create_timer(max(config.deadline / 2.0, 0.005), self._on_deadline)
        if config.replan_period > 0.0:
            self.create_timer(config.replan_period, self._on_replan_timer)
        self.create_timer(config.diagnostics_period, self._publish_diagnostics)
        if self.live is not None:
            self.create_timer(1.0 / self.live.settings.rate_hz, self._on_live_timer)

    # -- startup -----------------------------------------------------------------------------------------------
    def _site_selection(self) -> SiteSelection | None:
        """The landing sites; broken ones are an error and the node lands anywhere (a plan must still come)."""
        self._sites_note = ""
        try:
            sites = self.config.site_selection()
        except ValueError as error:
            self._sites_note = f"landing sites not usable: {error}"
            self.get_logger().error(f"{self._sites_note}; landing anywhere")
            return None
        if sites is not None:
            self.get_logger().info(sites_report(sites).text)
        return sites

    def _start_backend(self, airframe: Airframe, settings: PlannerSettings) -> None:
        """Loads the envelope, starts the solver pool (or builds the NLP here and warms it up), the estimators."""
        logger = self.get_logger()
        report = {"error": logger.error, "warning": logger.warning, "info": logger.info}
        # Today's weight and density altitude change the model, hence the NLP and which envelope matches (one made
        # for other conditions is refused: cold starts, autorotation-entry fallback).
        self.airframe, self.settings = airframe, settings
        self.readings = LatestReadings(airframe, int(self.config.state_timeout * 1e9), rm.DEFAULT_BODY_FRAME)
        if self.sites is not None and settings.method != "flyable":
            self._sites_note = f"landing sites need the flyable method, not {settings.method!r}"
            logger.error(f"{self._sites_note}: landing anywhere")
            self.sites = None
        self.footprint_off = footprint_off_reason(
            period_s=self.config.footprint_period,
            live=self.config.live_rate > 0.0,
            pool=self.config.solver_workers > 0,
            method=settings.method,
        )
        backend_settings = self.config.backend_settings(
            site_planning=self.sites is not None, footprint=not self.footprint_off
        )
        backend = PlannerBackend(airframe, settings, backend_settings, lambda level, text: report[level](text))
        self._backend = backend
        where = f"{backend_settings.solver_workers} solver workers" if backend.pool else "solving in this process"
        logger.info(
            f"planner ready for {airframe.name} ({settings.method}, {settings.intervals} intervals) "
            f"in {backend.startup_s:.2f} s, {where}; {backend.envelope_note}"
        )

    @property
    def planner(self) -> LandingPlanner | SolverPool | None:
        """The in-process LandingPlanner or the SolverPool; None: not configured (a broken airframe or settings)."""
        return self._backend.planner if self._backend is not None else None

    @property
    def envelope(self) -> Envelope | None:
        """The envelope used for warm starts and fallbacks (None: none usable)."""
        return self._backend.envelope if self._backend is not None else None

    def ready_weights(self) -> set[float]:
        """Weights a ready solver holds (a failure plan for one builds no NLP)."""
        return self._backend.ready_weights() if self._backend is not None else set()

    # -- inputs ------------------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _on_state(self, message: Odometry) -> None:
        if self.readings is not None:  # the monitor reports implausible states; they are ignored here
            self.readings.add_odometry(rm.read_odometry(message), self._now_ns(), message.child_frame_id)

    def _on_rotor(self, message: JointState) -> None:
        try:
            reading = rm.read_rotor(message, self.config.rotor_joint)
        except ValueError:
            return
        if self.readings is None or self._backend is None:
            return
        sample = self.readings.add_rotor(reading, self._now_ns())
        # Steady flight before the failure only (after it the episode's weight is fixed).
        if sample is not None and self.supervisor.before_failure:
            self._backend.add_weight_sample(sample)

    def current_state(self, measured_power: bool = False) -> CurrentState | None:
        """The state to plan from now (:meth:`LatestReadings.current`), or None without a fresh state. P is 0 with
        ``assume_total_power_loss`` unless ``measured_power`` (live evaluation applies ``live_power_fraction``)."""
        if self.readings is None:
            return None
        zero_power = self.config.assume_total_power_loss and not measured_power
        return self.readings.current(self._now_ns(), zero_power=zero_power)

    # -- the failure --------------------------------------------------------------------------------------------
    def _on_failure_event(self, message: Header) -> None:
        self._start_failure(rm.stamp_nanoseconds(message.stamp))

    def _on_mission_sites(self, message: DiagnosticStatus) -> None:
        """A mission manager's landing sites replace the current ones (a failure under way keeps its site)."""
        assert self.sites is not None  # subscribed only with sites
        try:
            sites, selected = sites_from_message(rm.status_values(message))
            self.sites.replace(sites, selected)
        except ValueError as error:
            note = f"refused /mission/landing_sites, keeping the sites in use: {error}"
            self.get_logger().warning(note, throttle_duration_sec=5.0)
            self._publish(self._sites_publisher, "landing sites", sites_report(self.sites, note))
            return
        report = sites_report(self.sites)
        self._publish(self._sites_publisher, "landing sites", report)
        self.get_logger().info(report.text)

    def _on_episode(self, message: DiagnosticStatus) -> None:
        """Follows the monitor's failure episode: starts a missed one, stops planning for an ended one."""
        try:
            state = EpisodeState.from_values(rm.status_values(message))
        except ValueError as error:
            self.get_logger().warning(f"unreadable failure episode ignored: {error}", throttle_duration_sec=5.0)
            return
        action, failure = self.supervisor.observe_episode(state)
        if action is EpisodeAction.START and state.started_ns is not None:
            self._start_failure(state.started_ns)
        elif action is EpisodeAction.STOP and failure is not None:
            self._stop_failure(failure, state)

    def _start_failure(self, failure_stamp_ns: int) -> None:
        """Starts planning for the failure stamped ``failure_stamp_ns`` (once: its event and state both announce it)."""
        failure = self.supervisor.start_failure(failure_stamp_ns, self._now_ns())
        if failure is None:
            return
        self.failures.fix_weight(self.live.latest_weight if self.live is not None else None)
        standby = self.live.pause(failure_stamp_ns) if self.live is not None else None
        self.failures.fix_site(standby)
        if standby is not None and (plan := standby.verdict.plan) is not None:
            verdict = standby.verdict
            current = CurrentState(verdict.state, verdict.state_stamp_ns, standby.frame, RotorSource.MEASURED)
            messages = standby.messages if isinstance(standby.messages, PlanMessages) else None
            self.publish_plan(failure, plan, current, "live", replan=False, standby=standby.weight, messages=messages)
        if self._backend is None:
            self.publish_no_plan(failure, self.failures.not_configured)
            return
        self.solver_thread.submit(self.failures.first_plan, failure, queue=True)
        fast_logging.warning(self.get_logger(), f"engine failure #{failure.failure_id}: planning the landing")

    def _stop_failure(self, failure: FailureEpisode, state: EpisodeState) -> None:
        """Says that planning for ``failure`` stopped (the supervisor stopped it), so a late joiner's latched status
        is not the last plan of an episode that is over."""
        outcome = EpisodePhase(failure.outcome)
        report = episode_end_report(failure, outcome, state, self._now_ns())
        self._publish(self._status_publisher, "landing plan", report)
        if self.live is not None:
            self.live.pause()  # forget the verdicts from before and during the episode; evaluation resumes afresh
        fast_logging.warning(
            self.get_logger(),
            f"failure #{failure.failure_id}: episode {outcome.value}; planning stopped "
            f"({failure.replans} re-plans, {failure.replans_failed} failed, {failure.replans_kept_out} kept out)",
        )

    # -- timers -------------------------------------------------------------------------------------------------
    def _on_live_timer(self) -> None:
        if self.live is not None and not self.supervisor.live_paused():
            self.live.tick(self.current_state(measured_power=True))

    def _on_deadline(self) -> None:
        self._publish_robust_verdicts()
        self.failures.deadline()

    def _on_replan_timer(self) -> None:
        action, failure = self.supervisor.timer_action(planner_ready=self._backend is not None)
        if action is TimerAction.RETRY_FIRST_PLAN:
            self.solver_thread.submit(self.failures.first_plan, failure, True)
        elif action is TimerAction.REPLAN:
            self.solver_thread.submit(self.failures.replan, failure)

    # -- publishing (the FailurePlanner's PlanSink) --------------------------------------------------------------
    def report(self, level: str, text: str, throttle_s: float = 0.0) -> None:
        """A log line (the sink's report). rclpy refuses one call site that logs at different severities or
        filters, so each (severity, throttled) pair has its own line."""
        logger = self.get_logger()
        if throttle_s <= 0.0:
            fast_logging.log_line(logger, _SEVERITIES[level], text)
        elif level == "error":
            logger.error(text, throttle_duration_sec=throttle_s)
        elif level == "warning":
            logger.warning(text, throttle_duration_sec=throttle_s)
        else:
            logger.info(text, throttle_duration_sec=throttle_s)

    def publish_fallback(self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int, reason: str) -> None:
        """Publishes the fallback for ``state`` if the supervisor allows it (else says there is none)."""
        try:
            if self._backend is None:
                raise RuntimeError(self.failures.not_configured)
            fallback = self._backend.fallback_plan(state)
        except Exception as error:  # the last resort must not take the node down
            self.publish_no_plan(failure, f"{reason}; no fallback available ({error})")
            return
        with self.supervisor.publication(failure, fallback=True) as allowed:
            if not allowed:
                return  # a newer failure came, this one is over, or a converged plan came first
            since_ns = failure.event_received_ns
            record = self._record(failure, fallback, stamp_ns, "none", fallback=True, since_ns=since_ns)
            self._trajectory_publisher.publish(rm.trajectory_message(fallback, stamp_ns))
            report = fallback_report(
                fallback,
                identity=self._identity(),
                failure=failure,
                state=state,
                stamp_ns=stamp_ns,
                reason=reason,
                lateness=self.supervisor.lateness(failure, stamp_ns, replan=False),
                latency_ms=record.latency_ms,
            )
            self._publish(self._status_publisher, "landing plan", report)
            self.supervisor.remember(failure, record)
        self.get_logger().warning(f"failure #{failure.failure_id}: published fallback {fallback.description}")

    @property
    def episode_weight(self) -> WeightChoice:
        """The gross weight the current (or last) failure episode plans for (the file's before any failure)."""
        return self.failures.episode_weight

    def _identity(self) -> PlannerIdentity:
        envelope_id = self.envelope.envelope_id if self.envelope is not None else ""
        return PlannerIdentity(
            self.airframe.name, self.airframe.gross_weight, self.airframe.density_altitude, envelope_id
        )

    def _publish(self, publisher: Publisher, what: str, report: StatusReport) -> None:
        """Publishes a status report as ``<node>: <what>``."""
        hardware_id = self.airframe.name if self._backend is not None else "helireach"
        level = rm.DIAGNOSTIC_LEVELS[report.level]
        name = f"{self.get_name()}: {what}"
        publisher.publish(rm.diagnostic_status(level, name, report.text, hardware_id, report.values))

    def _record(
        self,
        failure: FailureEpisode,
        plan: LandingPlan | FallbackPlan,
        stamp_ns: int,
        warm_source: str,
        *,
        fallback: bool,
        since_ns: int,
    ) -> PublishedPlan:
        """The record of a publication now (its latency counted from ``since_ns``)."""
        now_ns = self._now_ns()
        return PublishedPlan(
            failure.failure_id, failure.replans, stamp_ns, plan, fallback, (now_ns - since_ns) * 1e-6, now_ns,
            warm_source,
        )  # fmt: skip

    def publish_plan(
        self,
        failure: FailureEpisode,
        plan: LandingPlan,
        current: CurrentState,
        warm_source: str,
        *,
        replan: bool,
        robust_pending: bool = False,
        standby: WeightChoice | None = None,
        messages: PlanMessages | None = None,
    ) -> None:
        """Publishes a converged plan (safe, unverified or unsafe) as trajectory, path and status.

        ``standby``: the weight of a live verdict's plan published on the failure (flagged so; the refined plan
        replaces it). ``messages``: its trajectory and path built beforehand (used only if they match plan, stamp and
        frames). ``robust_pending``: its robust verification follows (``robust: pending``).
        """
        stamp_ns, frame = current.stamp_ns, current.frame
        with self.supervisor.publication(failure, fallback=False) as allowed:
            if not allowed:
                return  # a newer failure superseded this one, or it ended, while solving
            since_ns = stamp_ns if replan else failure.event_received_ns
            record = self._record(failure, plan, stamp_ns, warm_source, fallback=False, since_ns=since_ns)
            if messages is None or not messages.matches(plan, stamp_ns, frame, self.config.world_frame):
                messages = plan_messages(plan, stamp_ns, frame, self.config.world_frame)
            self._trajectory_publisher.publish(messages.trajectory_cdr)
            self._path_publisher.publish(messages.path_cdr)
            robust = self._backend.robust if self._backend is not None else None
            report = converged_plan_report(
                plan,
                identity=self._identity(),
                failure=failure,
                stamp_ns=stamp_ns,
                warm_source=warm_source,
                rotor_source=current.rotor_source,
                replan_index=failure.replans if replan else 0,
                lateness=self.supervisor.lateness(failure, stamp_ns, replan=replan),
                latency_ms=record.latency_ms,
                weight=standby or self.episode_weight,
                standby=standby is not None,
                robust_design=robust.design if robust_pending and robust is not None else None,
                sites=self.failures.site_values(plan),
            )
            self._publish(self._status_publisher, "landing plan", report)
            self.supervisor.remember(failure, record, standby=standby is not None)
        if not replan:
            fast_logging.info(
                self.get_logger(), f"failure #{failure.failure_id}: {report.text} ({record.latency_ms:.0f} ms)"
            )

    def robust_pending(self, key: RobustKey) -> None:
        """A plan's robust verification was submitted: its verdict is published as pending."""
        self._publish_robust(key, None)

    def _publish_robust_verdicts(self) -> None:
        """Publishes the robust verdicts that came back (polled; the worker never calls into the node)."""
        robust = self._backend.robust if self._backend is not None else None
        if robust is None:
            return
        for key, summary in robust.finished():
            self._publish_robust(key, summary)
            text = "robust" if summary.robust else f"NOT robust: {summary.reason}"
            fast_logging.info(self.get_logger(), f"failure #{key[0]}: first plan {text} ({summary.seconds:.1f} s)")

    def _publish_robust(self, key: RobustKey, summary: RobustSummary | None) -> None:
        """The robust verdict of a failure plan (a RobustSummary), or None: pending."""
        robust = self._backend.robust if self._backend is not None else None
        design = robust.design if robust is not None else ""
        self._publish(self._robust_publisher, "robust verdict", robust_report(key, summary, design))
        self.robust_verdicts.append((key, summary))
        del self.robust_verdicts[:-_PLAN_HISTORY]

    def publish_no_plan(self, failure: FailureEpisode, text: str) -> None:
        """An error status without a plan, if nothing is out for ``failure`` yet."""
        self.get_logger().error(f"failure #{failure.failure_id}: {text}")
        with self.supervisor.publication(failure, fallback=False) as allowed:
            if allowed and self.supervisor.no_plan_may_be_reported(failure):
                self._publish(self._status_publisher, "landing plan", no_plan_report(failure, text))

    # -- inspection and shutdown ---------------------------------------------------------------------------------
    @property
    def solving(self) -> bool:
        """A solve is pending or running on the solver thread."""
        return self.solver_thread.busy

    def destroy_node(self) -> None:
        """Stops the solver workers (their jobs fail), lets a running in-process solve finish (queued ones are
        dropped), then destroys the node."""
        if self.live is not None:
            self.live.pause()  # the jobs failed by closing the pool are not verdicts
        if self._backend is not None:
            self._backend.close()
        self.solver_thread.shutdown()
        super().destroy_node()

    def _publish_diagnostics(self) -> None:
        timeout_s = self.config.solve_timeout_s
        report = self.failures.health_report(self.live, solving=self.solving, solve_timeout_s=timeout_s)
        hardware_id = self.airframe.name if self._backend is not None else "helireach"
        name = f"{self.get_name()}: planner"
        status = rm.diagnostic_status(rm.DIAGNOSTIC_LEVELS[report.level], name, report.text, hardware_id, report.values)
        self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), status))


def main(args: list[str] | None = None) -> None:
    """Runs the planner node until Ctrl-C or SIGTERM."""
    raise SystemExit(run_node(LandingPlannerNode, args))  # 2: bad command line or parameter (one line on stderr)


if __name__ == "__main__":
    main()
