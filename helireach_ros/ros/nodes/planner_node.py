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

import contextlib
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.aircraft.model import clip_rotor_speed_noise
from helireach_ros.core.estimation.disturbance import DisturbanceSettings, DisturbanceTracker
from helireach_ros.core.estimation.weight_tracking import WeightChoice, WeightSample, ready_choice
from helireach_ros.core.planning.fallback import FallbackPlan
from helireach_ros.core.policies.failure_episode import EpisodePhase, EpisodeState, FailureEpisode, PublishedPlan
from helireach_ros.core.policies.landing_supervisor import (
    EpisodeAction,
    LandingSupervisor,
    ReplanGate,
    SupervisorSettings,
    TimerAction,
)
from helireach_ros.core.policies.live_reachability import LiveEvaluator, LiveSettings, LiveVerdict
from helireach_ros.core.policies.plan_status import (
    PlannerHealth,
    PlannerIdentity,
    SolverPoolHealth,
    StatusReport,
    converged_plan_report,
    episode_end_report,
    fallback_report,
    live_report,
    no_plan_report,
    planner_health_report,
    robust_report,
)
from helireach_ros.core.policies.vehicle_readings import (
    OdometryReading,
    RotorReading,
    StateLimits,
    helicopter_state,
    state_problems,
)
from helireach_ros.core.workers.planner_backend import BackendSettings, PlannerBackend
from helireach_ros.ros import fast_logging
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.nodes.planner_parameters import PlannerParameters
from helireach_ros.ros.parameters import declare_aircraft, declare_parameters
from helireach_ros.ros.plan_messages import PlanMessages, plan_messages
from helireach_ros.ros.qos import QosWatch

__all__ = ["LandingPlannerNode", "main"]

_PLAN_HISTORY = 200  # robust verdicts kept for inspection (demo, tests)
_ROTOR_NOISE_TOLERANCE = 0.01  # fraction of Ω₀ a measured rotor speed may lie outside its limits as noise
# The default solve_timeout: the deadline, but at least this. A kill is for a hung worker, not a slow one (a killed
# worker is out for seconds while it rebuilds its NLPs): an unsafe failure plan for an estimated weight (plain CasADi
# functions, 300 iterations) measured 1.05 s on an idle 2-core machine, over 1 s wherever the machine is loaded.
_MIN_SOLVE_TIMEOUT_S = 3.0
_NO_REPLANNING_PERIOD_S = 1e9  # replan_period 0 (re-planning off): the closed loop of the robust check flies one plan


class LandingPlannerNode(Node):
    """Plans landings after engine failures and re-plans during the descent.

    Parameters: ``helireach_planner --help``; what each does: docs/guides/planner-node.md.
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_planner", **node_options)
        load_aircraft = declare_aircraft(self)
        self.config = config = declare_parameters(self, PlannerParameters)
        # Not the deadline itself by default: a slow solve is not a hung one, and its plan must still replace the
        # deadline's fallback (a dead worker is seen at once whatever the timeout).
        self._solve_timeout = (
            max(config.deadline, _MIN_SOLVE_TIMEOUT_S) if math.isnan(config.solve_timeout) else config.solve_timeout
        )
        self._live_settings = (
            LiveSettings(
                rate_hz=config.live_rate,
                power_fraction=config.live_power_fraction,
                max_state_age_s=config.live_max_state_age,
                standby_max_age_s=config.standby_max_age,
            )
            if config.live_rate > 0.0
            else None
        )

        self._lock = threading.Lock()  # latest state, weight tracker
        self.supervisor = LandingSupervisor(
            SupervisorSettings(
                deadline=self.config.deadline,
                replan_min_height=self.config.replan_min_height,
                replan_min_remaining=self.config.replan_min_remaining,
                max_message_age=self.config.max_message_age,
            )
        )
        self._odometry: tuple[OdometryReading, int, str] | None = None
        self._rotor: tuple[RotorReading, int] | None = None
        # Live evaluation: the evaluator and the job in flight, guarded by _live_lock. A generation number
        # drops verdicts that come back after a failure started or after a reset.
        self._live_lock = threading.Lock()
        self._live = LiveEvaluator(self._live_settings) if self._live_settings is not None else None
        self._live_job: Future | None = None
        self._live_generation = 0
        self._live_frame = rm.DEFAULT_BODY_FRAME  # vehicle frame of the standby verdict's state
        self._standby_messages: PlanMessages | None = None  # the standby's messages, built when its verdict came

        self._backend: PlannerBackend | None = None  # None = not configured (a broken airframe or settings file)
        self._setup_error = ""
        self.robust_verdicts: list[tuple[tuple[int, int, int], Any | None]] = []  # published: (key, summary|None)
        backend = BackendSettings(
            envelope_file=config.envelope_file,
            solver_workers=config.solver_workers,
            warm_up=config.warm_up,
            solve_timeout_s=self._solve_timeout,
            reaction_delay_s=config.reaction_delay,
            estimate_weight=self.config.estimate_weight,
            weight_window_s=self.config.weight_estimate_window,
            weight_step=self.config.weight_estimate_step,
            weight_error=self.config.weight_estimate_error,
            robust_policy=self._replanning_policy() if config.robust_verification else None,
            robust_uncertainty=self.config.robust_uncertainty,
        )
        try:
            from helireach_ros.core.ocp.settings import load_settings

            self._start_backend(load_aircraft(), load_settings(config.planner_settings or None), backend)
        except Exception as error:  # a broken airframe/settings file: say so on every channel, keep running
            self._setup_error = f"{type(error).__name__}: {error}"
            self.get_logger().error(f"planner not configured, no plans will be made: {self._setup_error}")
        self._live_weight: WeightChoice | None = None  # the weight of the latest live verdict (the standby's)
        self._latest_weight: WeightChoice | None = None  # the weight the latest live evaluation was started for
        self._failure_weight: WeightChoice | None = None  # the current failure episode's weight

        # One solve at a time, off the executor: a slow solve must not hold up the deadline or the inputs.
        self._solver_thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="helireach_solver")
        self._solve_job: Future | None = None
        self._trajectory_publisher = self.create_publisher(
            JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._path_publisher = self.create_publisher(
            PathMsg, rm.TOPIC_LANDING_PATH, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._status_publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_PLAN_STATUS, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._robust_publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_ROBUST_VERDICT, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        # Inputs through a QosWatch: an incompatible publisher is an ERROR "<node>: QoS" on /diagnostics. The
        # failure event stays RELIABLE (one message per failure must not be lost; a best-effort one is reported).
        self._qos_watch = QosWatch(self, config.diagnostics_period)
        self._qos_watch.create_subscription(Odometry, rm.TOPIC_STATE, self._on_state, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(JointState, rm.TOPIC_ROTOR_STATE, self._on_rotor, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(Header, rm.TOPIC_FAILURE_EVENT, self._on_failure_event, rm.EVENT_QOS)
        self._qos_watch.create_subscription(
            DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, self._on_episode, rm.LATCHED_QOS
        )
        # A periodic check, never cancelled or reset from the solver thread (cancelling a timer that the
        # executor is about to fire raises inside the executor). Every half deadline:
        # the fallback goes out within 1.5 deadlines without waking the executor needlessly.
        self.create_timer(max(self.config.deadline / 2.0, 0.005), self._on_deadline)
        if self.config.replan_period > 0.0:
            self.create_timer(self.config.replan_period, self._on_replan_timer)
        self.create_timer(config.diagnostics_period, self._publish_diagnostics)
        self._live_publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        if self._live_settings is not None:
            self.create_timer(1.0 / self._live_settings.rate_hz, self._on_live_timer)

    # -- startup -----------------------------------------------------------------------------------------------
    def _start_backend(self, airframe: Any, settings: Any, backend_settings: BackendSettings) -> None:
        """Loads the envelope, starts the solver pool (or builds the NLP here and warms it up), the estimators."""
        logger = self.get_logger()
        report = {"error": logger.error, "warning": logger.warning, "info": logger.info}
        # Today's weight and density altitude change the model, hence the NLP and which envelope matches (one made
        # for other conditions is refused: cold starts, autorotation-entry fallback).
        self.airframe, self.settings = airframe, settings
        backend = PlannerBackend(airframe, settings, backend_settings, lambda level, text: report[level](text))
        self._backend = backend
        where = f"{backend_settings.solver_workers} solver workers" if backend.pool else "solving in this process"
        logger.info(
            f"planner ready for {airframe.name} ({settings.method}, {settings.intervals} intervals) "
            f"in {backend.startup_s:.2f} s, {where}; {backend.envelope_note}"
        )

    @property
    def planner(self) -> Any | None:
        """The in-process LandingPlanner or the SolverPool; None: not configured (a broken airframe or settings)."""
        return self._backend.planner if self._backend is not None else None

    @property
    def envelope(self) -> Any | None:
        """The envelope used for warm starts and fallbacks (None: none usable)."""
        return self._backend.envelope if self._backend is not None else None

    @property
    def _pool(self) -> Any | None:
        return self._backend.pool if self._backend is not None else None

    @property
    def _robust(self) -> Any | None:
        return self._backend.robust if self._backend is not None else None

    def _replanning_policy(self) -> Any:
        """This node's re-planning policy as the closed loop flies it (what the robust verification checks)."""
        from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings

        return ClosedLoopSettings(
            replan_period=self.config.replan_period if self.config.replan_period > 0.0 else _NO_REPLANNING_PERIOD_S,
            min_height=self.config.replan_min_height,
            min_remaining=self.config.replan_min_remaining,
            estimate_disturbance=self.config.estimate_disturbance,
            disturbance=DisturbanceSettings(gain=self.config.disturbance_gain),
        )

    def _weight_now(self) -> WeightChoice:
        """The weight to plan for now (the tracker's choice, or the file's with the reason)."""
        assert self._backend is not None  # asked only with a planner
        return self._backend.weight_now(self._now_ns())

    def ready_weights(self) -> set[float]:
        """Weights a ready solver holds (a failure plan for one builds no NLP)."""
        return self._backend.ready_weights() if self._backend is not None else set()

    # -- inputs ------------------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _on_state(self, message: Odometry) -> None:
        reading = rm.read_odometry(message)
        if state_problems(StateLimits(), odometry=reading):
            return  # the monitor filters; a direct publisher's garbage is ignored here too
        with self._lock:
            self._odometry = (reading, self._now_ns(), message.child_frame_id or rm.DEFAULT_BODY_FRAME)

    def _on_rotor(self, message: JointState) -> None:
        try:
            reading = rm.read_rotor(message, self.config.rotor_joint)
        except ValueError:
            return
        if state_problems(StateLimits(), rotor=reading):
            return
        now_ns = self._now_ns()
        with self._lock:
            self._rotor = (reading, now_ns)
            odometry = self._odometry
        backend = self._backend
        if backend is None or backend.weights is None or odometry is None:
            return
        # Steady flight before the failure only (after it the episode's weight is fixed); receive times, as every
        # freshness check here (a replayed log's stamps are old).
        if self.supervisor.before_failure and now_ns - odometry[1] <= self.config.state_timeout * 1e9:
            state = odometry[0]
            sample = WeightSample(
                now_ns, state.forward_speed, state.climb_rate, reading.rotor_speed, reading.engine_power
            )
            backend.add_weight_sample(sample)

    def current_state(self, measured_power: bool = False) -> tuple[np.ndarray, int, str, str] | None:
        """(state y, v, Ω, h, z, P; its stamp ns; vehicle frame; rotor-speed source), or None without a fresh state.

        Without a fresh rotor speed Ω₀ is assumed (the source says so; re-plans and live evaluations are then
        skipped). Ω within 1 % of Ω₀ outside the rotor limits is clipped to them (sensor noise); farther out it
        is kept. P is 0 with ``assume_total_power_loss`` (plans after a failure), else the measured power (the
        rotor reading's torque × Ω; 0 if not measured); ``measured_power`` always gives the measured power (live
        evaluation applies ``live_power_fraction`` to it).
        """
        now_ns = self._now_ns()
        timeout_ns = self.config.state_timeout * 1e9
        with self._lock:
            odometry, rotor = self._odometry, self._rotor
        if odometry is None or now_ns - odometry[1] > timeout_ns:
            return None
        reading, _, frame = odometry
        if rotor is not None and now_ns - rotor[1] <= timeout_ns:
            rotor_speed, source = rotor[0].rotor_speed, "measured"
            power = rotor[0].engine_power
        else:
            rotor_speed, source, power = self.airframe.nominal_rotor_speed, "assumed_nominal", None
        if power is None or (self.config.assume_total_power_loss and not measured_power):
            power = 0.0
        rotor_speed = clip_rotor_speed_noise(self.airframe, rotor_speed, _ROTOR_NOISE_TOLERANCE)
        return helicopter_state(reading, rotor_speed, power), reading.stamp_ns, frame, source

    # -- the failure --------------------------------------------------------------------------------------------
    def _on_failure_event(self, message: Header) -> None:
        self._start_failure(rm.stamp_nanoseconds(message.stamp))

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
        # The episode's weight, fixed now: the last live evaluation's (no bisection in the failure callback), one a
        # solver holds (never an NLP built in the failure path).
        if self._backend is not None:
            backend = self._backend
            why = (
                backend.weights_off_reason
                if backend.weights is None
                else "no live evaluation yet (where NLPs are built)"
            )
            latest = self._latest_weight or WeightChoice(self.airframe.gross_weight, "file", 0.0, why)
            self._failure_weight = ready_choice(latest, self.airframe.gross_weight, self.ready_weights())
        standby = self._pause_live(failure_stamp_ns)
        if standby is not None and self.planner is not None:
            self._publish_plan(
                failure,
                standby.plan,
                standby.state_stamp_ns,
                self._live_frame,
                "live",
                "measured",
                replan=False,
                standby=True,
                messages=self._standby_messages,
            )
        if self.planner is None:
            self._publish_status_only(failure, f"planner not configured ({self._setup_error})")
            return
        self._submit(self._plan_initial, failure, queue=True)
        fast_logging.warning(self.get_logger(), f"engine failure #{failure.failure_id}: planning the landing")

    def _stop_failure(self, failure: FailureEpisode, state: EpisodeState) -> None:
        """Says that planning for ``failure`` stopped (the supervisor stopped it), so a late joiner's latched status
        is not the last plan of an episode that is over."""
        outcome = EpisodePhase(failure.outcome)
        report = episode_end_report(failure, outcome, state, self._now_ns())
        self._publish(self._status_publisher, "landing plan", report)
        self._pause_live()  # forget the verdicts from before and during the episode; evaluation resumes afresh
        fast_logging.warning(
            self.get_logger(),
            f"failure #{failure.failure_id}: episode {outcome.value}; planning stopped "
            f"({failure.replans} re-plans, {failure.replans_failed} failed)",
        )

    # -- live evaluation -----------------------------------------------------------------------------------------
    def _pause_live(self, failure_stamp_ns: int | None = None) -> LiveVerdict | None:
        """Drops the live verdict in flight; with a failure stamp returns its standby, else resets the evaluator."""
        with self._live_lock:
            self._live_generation += 1
            self._live_job = None
            if self._live is None:
                return None
            if failure_stamp_ns is not None:
                return self._live.standby(failure_stamp_ns)
            self._live.reset()
            return None

    def _on_live_timer(self) -> None:
        """Starts a live evaluation if one is due and none is in flight (see the module docstring)."""
        if self._live is None or self.planner is None or self.supervisor.live_paused():
            return
        now_ns = self._now_ns()
        current = self.current_state(measured_power=True)
        if current is None or current[3] != "measured":
            return  # no verdict from an assumed rotor speed: the latched one ages and says so (state_age_s)
        state, stamp_ns, frame, _ = current
        with self._live_lock:
            if self._live_job is not None and not self._live_job.done():
                return
            # Due half a period early: the timer keeps the rate, its jitter must not skip a period.
            if not self._live.due(now_ns + self._live.settings.period_ns // 2):
                return
            # The envelope's nearest plan (~2 ms in the 3-D file) only when no neighbouring live solution can start it.
            envelope = self.envelope
            needs_fallback = envelope is not None and not self._live.warm_start_applies(state)
            stored = envelope.nearest_plan(state[3], state[1], -state[0]) if envelope and needs_fallback else None
            prepared = self._live.prepare(state, stamp_ns, now_ns, stored.warm_start if stored is not None else None)
            if prepared is None:
                return  # the state is older than live_max_state_age
            failure_now, warm_start = prepared
            generation = self._live_generation
            weight = self._weight_now()  # a weight no solver holds yet is built here, before any failure
            self._latest_weight = weight
            done = partial(self._live_done, generation, failure_now, stamp_ns, frame, now_ns, weight)
            if self._pool is not None and self._backend is not None:
                try:
                    job = self._backend.submit_live(failure_now, warm_start, weight.gross_weight)
                except RuntimeError:  # the pool is closed: the node is being destroyed
                    return
                self._live_job = job
        if self._pool is not None:
            job.add_done_callback(done)  # outside the lock: a job already done calls back at once, here
            return
        self._submit(self._live_in_process, done, failure_now, warm_start, weight)  # skipped while a solve runs

    def _live_in_process(
        self, done: Callable[[Future], None], state: np.ndarray, warm_start: Any, weight: WeightChoice
    ) -> None:
        """Without a pool: the live solve on the solver thread (cold check as in the workers)."""
        future: Future = Future()
        try:
            assert self._backend is not None  # live jobs are made only with a planner
            future.set_result(self._backend.solve_live(state, warm_start, weight.gross_weight))
        except (ValueError, RuntimeError) as error:
            future.set_exception(error)
        done(future)

    def _live_done(
        self,
        generation: int,
        state: np.ndarray,
        stamp_ns: int,
        frame: str,
        started_ns: int,
        weight: WeightChoice,
        future: Future,
    ) -> None:
        """Records a finished live solve and publishes its verdict (runs on the pool's or the solver thread)."""
        try:
            plan, error = future.result(), ""
        except Exception as exception:  # a refused state, a dead or hung worker, a closed pool: an error verdict
            plan, error = None, f"{type(exception).__name__}: {exception}"
        with contextlib.suppress(Exception):  # the node may be shutting down
            with self._live_lock:
                if generation != self._live_generation or self._live is None:
                    return  # a failure started (or the evaluator was reset) meanwhile: not evidence any more
                verdict = self._live.record(state, stamp_ns, started_ns, self._now_ns(), plan, error)
                self._live_weight = weight  # the standby, if any, is this latest verdict
                standby = self._live.standby_verdict is verdict
                if standby:
                    self._live_frame = frame  # the vehicle frame of the standby's state
                report = live_report(
                    verdict,
                    standby=standby,
                    weight=weight,
                    configured_weight=self.airframe.gross_weight,
                    power_fraction=self._live.settings.power_fraction,
                    now_ns=self._now_ns(),
                )
                self._publish(self._live_publisher, "live reachability", report)
            if standby:  # its messages now, off the executor and outside the lock: the failure only publishes them
                messages = plan_messages(verdict.plan, stamp_ns, frame, self.config.world_frame)
                with self._live_lock:
                    if generation == self._live_generation:
                        self._standby_messages = messages

    # -- the solver thread ---------------------------------------------------------------------------------------
    def _submit(self, job: Callable[..., None], *args: Any, queue: bool = False) -> bool:
        """Runs ``job(*args)`` on the solver thread; without ``queue`` only if no solve is pending or running."""
        with self._lock:
            if not queue and self._solve_job is not None and not self._solve_job.done():
                return False
            try:
                self._solve_job = self._solver_thread.submit(self._run_job, job, *args)
            except RuntimeError:  # the node is being destroyed
                return False
        return True

    def _run_job(self, job: Callable[..., None], *args: Any) -> None:
        try:
            job(*args)
        except Exception as error:  # an unexpected error must not silently end planning for this failure
            with contextlib.suppress(Exception):  # the context may already be shut down
                self.get_logger().error(f"planning step {job.__name__} failed: {type(error).__name__}: {error}")

    @property
    def solving(self) -> bool:
        """A solve is pending or running on the solver thread."""
        with self._lock:
            return self._solve_job is not None and not self._solve_job.done()

    def destroy_node(self) -> None:
        """Stops the solver workers (their jobs fail), lets a running in-process solve finish (queued ones are
        dropped), then destroys the node."""
        self._pause_live()  # the jobs failed by closing the pool are not verdicts
        if self._backend is not None:
            self._backend.close()
        self._solver_thread.shutdown(wait=True, cancel_futures=True)
        super().destroy_node()

    def is_standby(self, record: PublishedPlan) -> bool:
        """Whether a published plan is a standby plan (a live verdict's plan published on the failure)."""
        return self.supervisor.is_standby(record)

    @property
    def published_plans(self) -> list[PublishedPlan]:
        """The plans published (the latest ``_PLAN_HISTORY``), oldest first."""
        return self.supervisor.published_plans

    @property
    def standby_plans(self) -> list[PublishedPlan]:
        """The standby plans published, oldest first."""
        return self.supervisor.standby_plans

    def _plan_initial(self, failure: FailureEpisode, retry: bool = False) -> None:
        """The first plan of a failure, warm-started from the envelope's nearest stored plan.

        ``retry``: called again because no converged plan is out yet; a fallback already out is not repeated.
        """
        if not failure.active:
            return
        current = self.current_state()
        if current is None:
            self._publish_status_only(failure, "no valid vehicle state at the failure: waiting for one")
            return
        state, stamp_ns, frame, rotor_source = current
        stored = self.envelope.nearest_plan(state[3], state[1], -state[0]) if self.envelope is not None else None
        warm_start, source = (stored.warm_start, "envelope") if stored is not None else (None, "none")
        plan, error = self._solve(state, warm_start)
        if plan is None or not plan.solver.success:
            reason = error or (f"solver {plan.solver.status}" if plan is not None else "no plan")
            self.get_logger().error(f"failure #{failure.failure_id}: no converged plan ({reason})")
            if self.supervisor.fallback_after_failed_solve(failure, retry=retry, stamp_ns=stamp_ns):
                self._publish_fallback(failure, state, stamp_ns, reason)
            return
        robust = self._robust is not None and plan.safe
        self._publish_plan(failure, plan, stamp_ns, frame, source, rotor_source, replan=False, robust_pending=robust)
        if robust:  # after publishing: off the failure path
            self._submit_robust(failure, plan, stamp_ns)
        if self.config.estimate_disturbance and failure.disturbance is None:  # after publishing: off the failure path
            assert self._backend is not None  # a plan came from it
            model = self._backend.model_for(self.episode_weight.gross_weight)
            failure.disturbance = DisturbanceTracker(model, DisturbanceSettings(gain=self.config.disturbance_gain))
            failure.disturbance.update(stamp_ns * 1e-9, state, _controls_from_stamp(plan, stamp_ns))  # 1st interval

    def _solve(
        self,
        state: np.ndarray,
        warm_start: Any,
        initial_control: Any = None,
        reaction_delay_s: float | None = None,
        disturbance: np.ndarray | None = None,
    ) -> tuple[Any | None, str]:
        """A failure plan or re-plan for the episode's weight (blocking; on the solver thread): (plan, "") or (None,
        why not); see :meth:`PlannerBackend.solve`."""
        if self._backend is None:
            return None, f"planner not configured ({self._setup_error})"
        return self._backend.solve(
            state, warm_start, gross_weight=self.episode_weight.gross_weight, initial_control=initial_control,
            reaction_delay_s=reaction_delay_s, disturbance=disturbance,
        )  # fmt: skip

    def _on_deadline(self) -> None:
        self._publish_robust_verdicts()
        failure = self.supervisor.deadline_fallback_due(self._now_ns())
        if failure is None:
            return
        current = self.current_state()
        if current is None:
            self._publish_status_only(failure, f"no plan within {self.config.deadline:g} s and no valid state")
            return
        state, stamp_ns, _, _ = current
        self._publish_fallback(failure, state, stamp_ns, f"no plan within the {self.config.deadline:g} s deadline")

    def _on_replan_timer(self) -> None:
        action, failure = self.supervisor.timer_action(planner_ready=self.planner is not None)
        if action is TimerAction.RETRY_FIRST_PLAN:
            self._submit(self._plan_initial, failure, True)
        elif action is TimerAction.REPLAN:
            self._submit(self._replan, failure)

    def _replan(self, failure: FailureEpisode) -> None:
        """One closed-loop re-plan from the current state, warm-started from the current plan."""
        current = self.current_state()
        if current is None:
            return
        state, stamp_ns, frame, rotor_source = current
        decision = self.supervisor.replan_decision(
            failure, rotor_measured=rotor_source == "measured", height=state[3], stamp_ns=stamp_ns
        )
        if decision is None or decision.previous is None:
            return
        if decision.gate is ReplanGate.PAUSE_NO_ROTOR:
            self.get_logger().warning(
                f"failure #{failure.failure_id}: re-planning paused: no measured rotor speed (the current plan is "
                f"kept; {failure.replans_skipped_no_rotor} re-plans skipped)",
                throttle_duration_sec=1.0,
            )
            return
        if decision.gate is ReplanGate.END_CLOSED_LOOP:
            self.get_logger().info(
                f"failure #{failure.failure_id}: closed loop ends at {state[3]:.2f} m, {decision.remaining:.2f} s to "
                f"go ({failure.replans} re-plans, {failure.replans_failed} failed)"
            )
            return
        previous = decision.previous
        # from the control being flown at the state's stamp (the flyable controls stay continuous), no delay
        flying = previous.plan.controls_at([(stamp_ns - previous.stamp_ns) * 1e-9])[:, 0]
        # what the last interval taught of the model's error (the current plan's controls were flown in it)
        flown = _controls_from_stamp(previous.plan, previous.stamp_ns)
        tracker = failure.disturbance
        disturbance = tracker.update(stamp_ns * 1e-9, state, flown) if tracker is not None else None
        plan, error = self._solve(state, previous.plan.warm_start, flying, 0.0, disturbance)
        converged = plan is not None and plan.solver.success
        self.supervisor.replan_solved(failure, converged=converged)
        if not converged:
            reason = error or (f"solver {plan.solver.status}" if plan is not None else "no plan")
            self.get_logger().warning(f"re-plan failed ({reason}); keeping the current plan", throttle_duration_sec=1.0)
            return
        self._publish_plan(failure, plan, stamp_ns, frame, "previous_plan", rotor_source, replan=True)

    # -- fallbacks -----------------------------------------------------------------------------------------------
    def fallback_plan(self, state: np.ndarray) -> FallbackPlan:
        """The best available controls without a converged solve
        (:func:`helireach_ros.core.planning.fallback.fallback_plan`)."""
        if self._backend is None:
            raise RuntimeError(f"planner not configured ({self._setup_error})")
        return self._backend.fallback_plan(state)

    def _publish_fallback(self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int, reason: str) -> None:
        try:
            fallback = self.fallback_plan(state)
        except Exception as error:  # the last resort must not take the node down
            self._publish_status_only(failure, f"{reason}; no fallback available ({error})")
            return
        with self.supervisor.publication(failure, fallback=True) as allowed:
            if not allowed:
                return  # a newer failure came, this one is over, or a converged plan came first
            now_ns = self._now_ns()
            record = PublishedPlan(
                failure.failure_id, failure.replans, stamp_ns, fallback, True,
                (now_ns - failure.event_received_ns) * 1e-6, now_ns, "none",
            )  # fmt: skip
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

    # -- publishing ----------------------------------------------------------------------------------------------
    @property
    def episode_weight(self) -> WeightChoice:
        """The gross weight the current (or last) failure episode plans for (the file's before any failure)."""
        weight = self._failure_weight
        return weight if weight is not None else WeightChoice(self.airframe.gross_weight, "file", 0.0, "no failure")

    def _identity(self) -> PlannerIdentity:
        envelope_id = self.envelope.envelope_id if self.envelope is not None else ""
        return PlannerIdentity(
            self.airframe.name, self.airframe.gross_weight, self.airframe.density_altitude, envelope_id
        )

    def _publish(self, publisher: Any, what: str, report: StatusReport) -> None:
        """Publishes a status report as ``<node>: <what>``."""
        hardware_id = self.airframe.name if self.planner is not None else "helireach"
        level = rm.DIAGNOSTIC_LEVELS[report.level]
        name = f"{self.get_name()}: {what}"
        publisher.publish(rm.diagnostic_status(level, name, report.text, hardware_id, report.values))

    def _publish_plan(
        self,
        failure: FailureEpisode,
        plan: Any,
        stamp_ns: int,
        frame: str,
        warm_source: str,
        rotor_source: str,
        replan: bool,
        standby: bool = False,
        messages: PlanMessages | None = None,
        robust_pending: bool = False,
    ) -> None:
        """Publishes a converged plan (safe, unverified or unsafe) as trajectory, path and status.

        ``standby``: the live verdict's plan published on the failure (flagged so; the refined plan replaces it).
        ``messages``: its trajectory and path built beforehand (used only if they match plan, stamp and frames).
        ``robust_pending``: its robust verification follows (``robust: pending``; the verdict on
        ``/helireach/robust_verdict``).
        """
        live_weight = self._live_weight or WeightChoice(self.airframe.gross_weight, "file", 0.0, "")
        weight = live_weight if standby else self.episode_weight
        with self.supervisor.publication(failure, fallback=False) as allowed:
            if not allowed:
                return  # a newer failure superseded this one, or it ended, while solving
            now_ns = self._now_ns()
            reference_ns = failure.event_received_ns if not replan else stamp_ns
            record = PublishedPlan(
                failure.failure_id, failure.replans, stamp_ns, plan, False, (now_ns - reference_ns) * 1e-6, now_ns,
                warm_source,
            )  # fmt: skip
            if messages is None or not messages.matches(plan, stamp_ns, frame, self.config.world_frame):
                messages = plan_messages(plan, stamp_ns, frame, self.config.world_frame)
            self._trajectory_publisher.publish(messages.trajectory_cdr)
            self._path_publisher.publish(messages.path_cdr)
            report = converged_plan_report(
                plan,
                identity=self._identity(),
                failure=failure,
                stamp_ns=stamp_ns,
                warm_source=warm_source,
                rotor_source=rotor_source,
                replan_index=failure.replans if replan else 0,
                lateness=self.supervisor.lateness(failure, stamp_ns, replan=replan),
                latency_ms=record.latency_ms,
                weight=weight,
                standby=standby,
                robust_design=self._robust.design if robust_pending and self._robust is not None else None,
            )
            self._publish(self._status_publisher, "landing plan", report)
            self.supervisor.remember(failure, record, standby=standby)
        if not replan:
            fast_logging.info(
                self.get_logger(), f"failure #{failure.failure_id}: {report.text} ({record.latency_ms:.0f} ms)"
            )

    def _submit_robust(self, failure: FailureEpisode, plan: Any, stamp_ns: int) -> None:
        """Queues the plan's robust verification and publishes its verdict as pending."""
        key = (failure.failure_id, failure.event_stamp_ns, stamp_ns)
        assert self._robust is not None and self._backend is not None  # called only with robust verification on
        model = self._backend.model_for(self.episode_weight.gross_weight)
        self._robust.submit(key, model, self._backend.robust_settings(), plan)
        self._publish_robust(key, None)

    def _publish_robust_verdicts(self) -> None:
        """Publishes the robust verdicts that came back (polled; the worker never calls into the node)."""
        if self._robust is None:
            return
        for key, summary in self._robust.finished():
            self._publish_robust(key, summary)
            text = "robust" if summary.robust else f"NOT robust: {summary.reason}"
            fast_logging.info(self.get_logger(), f"failure #{key[0]}: first plan {text} ({summary.seconds:.1f} s)")

    def _publish_robust(self, key: tuple[int, int, int], summary: Any | None) -> None:
        """The robust verdict of a failure plan (a RobustSummary), or None: pending."""
        design = self._robust.design if self._robust is not None else ""
        self._publish(self._robust_publisher, "robust verdict", robust_report(key, summary, design))
        self.robust_verdicts.append((key, summary))
        del self.robust_verdicts[:-_PLAN_HISTORY]

    def _publish_status_only(self, failure: FailureEpisode, text: str) -> None:
        self.get_logger().error(f"failure #{failure.failure_id}: {text}")
        with self.supervisor.publication(failure, fallback=False) as allowed:
            if allowed and self.supervisor.no_plan_may_be_reported(failure):
                self._publish(self._status_publisher, "landing plan", no_plan_report(failure, text))

    # -- diagnostics ---------------------------------------------------------------------------------------------
    @property
    def failure_active(self) -> bool:
        """A failure is being handled and the closed loop has not ended."""
        return self.supervisor.failure_active

    def _publish_diagnostics(self) -> None:
        backend = self._backend
        if backend is None:
            status = rm.diagnostic_status(
                DiagnosticStatus.ERROR,
                f"{self.get_name()}: planner",
                f"not configured: {self._setup_error}",
                "helireach",
            )
            self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), status))
            return
        pool = self._pool
        failure = self.supervisor.failure
        asked = failure is not None and failure.active and failure.replans_skipped_no_rotor
        current = self.current_state() if asked else None
        health = PlannerHealth(
            airframe=self.airframe.name,
            method=self.settings.method,
            startup_s=backend.startup_s,
            warm_up_ms=backend.warm_up_ms,
            envelope_note=backend.envelope_note,
            has_envelope=self.envelope is not None,
            failures=self.supervisor.failure_count,
            solving=self.solving,
            episode_phase=self.supervisor.episode.phase.value,
            solve_timeout_s=self._solve_timeout,
            ready_weights=len(self.ready_weights()),
            weight_now=self._weight_now(),
            airframe_problems=tuple(backend.airframe_problems),
            pool=None
            if pool is None
            else SolverPoolHealth(
                pool.pool_settings.workers, pool.ready_workers, pool.busy_workers, pool.restarts, pool.last_error
            ),
            rotor_measured=None if current is None else current[3] == "measured",
        )
        with self._live_lock:
            report = planner_health_report(health, self._live, failure)
        status = rm.diagnostic_status(
            rm.DIAGNOSTIC_LEVELS[report.level], f"{self.get_name()}: planner", report.text, self.airframe.name,
            report.values,
        )  # fmt: skip
        self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), status))


def _controls_from_stamp(plan: Any, stamp_ns: int) -> Callable[[float], np.ndarray]:
    """A plan's controls as a function of time in seconds (the plan starts at its state's stamp)."""
    start = stamp_ns * 1e-9
    return lambda time: plan.controls_at([time - start])[:, 0]


def main(args: list[str] | None = None) -> None:
    """Runs the planner node until Ctrl-C or SIGTERM."""
    raise SystemExit(run_node(LandingPlannerNode, args))  # 2: bad command line or parameter (one line on stderr)


if __name__ == "__main__":
    main()
