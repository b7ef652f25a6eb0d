"""Planner node: on an engine failure, plan the landing, publish it, and keep re-planning down to the ground.

The node translates: ROS inputs to core calls, their answers to messages. The failure handling is
:class:`~helireach_ros.core.landing_supervisor.LandingSupervisor`, the statuses are
:mod:`helireach_ros.core.plan_status`, solves run in a :class:`~helireach_ros.core.solver_pool.SolverPool` (or on the
node's solver thread), live verdicts come from :class:`~helireach_ros.core.live_reachability.LiveEvaluator`. What it
does, parameter by parameter: docs/guides/planner-node.md.

Run: ``python -m helireach_ros.ros.nodes.planner_node`` (or the ``helireach_planner`` console script).
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeoutError
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

from helireach_ros.core.disturbance import DisturbanceSettings, DisturbanceTracker
from helireach_ros.core.failure_episode import EpisodePhase, EpisodeState, FailureEpisode, PublishedPlan
from helireach_ros.core.fallback import FallbackPlan, fallback_plan
from helireach_ros.core.landing_supervisor import (
    EpisodeAction,
    LandingSupervisor,
    ReplanGate,
    SupervisorSettings,
    TimerAction,
)
from helireach_ros.core.live_reachability import LiveEvaluator, LiveSettings, LiveVerdict, solve_with_cold_check
from helireach_ros.core.model import clip_rotor_speed_noise
from helireach_ros.core.plan_status import (
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
from helireach_ros.core.solver_pool import PRIORITY_FAILURE, PRIORITY_LIVE, SolverPool, SolverPoolSettings
from helireach_ros.core.units import FT, KT
from helireach_ros.core.vehicle_readings import (
    OdometryReading,
    RotorReading,
    StateLimits,
    helicopter_state,
    state_problems,
)
from helireach_ros.core.weight_tracking import (
    WeightChoice,
    WeightSample,
    WeightTracker,
    WeightTrackingSettings,
    plausible_band,
    ready_choice,
)
from helireach_ros.ros import fast_logging
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameters import declare_aircraft, declare_checked_parameter
from helireach_ros.ros.plan_messages import PlanMessages, plan_messages
from helireach_ros.ros.qos import QosWatch

__all__ = ["LandingPlannerNode", "main"]

_PLAN_HISTORY = 200  # robust verdicts kept for inspection (demo, tests)
_ROTOR_NOISE_TOLERANCE = 0.01  # fraction of Ω₀ a measured rotor speed may lie outside its limits as noise
_POOL_READY_TIMEOUT_S = 60.0  # start-up waits at most this long for one ready solver worker
# The default solve_timeout: the deadline, but at least this. A kill is for a hung worker, not a slow one (a killed
# worker is out for seconds while it rebuilds its NLPs): an unsafe failure plan for an estimated weight (plain CasADi
# functions, 300 iterations) measured 1.05 s on an idle 2-core machine, over 1 s wherever the machine is loaded.
_MIN_SOLVE_TIMEOUT_S = 3.0
_NO_REPLANNING_PERIOD_S = 1e9  # replan_period 0 (re-planning off): the closed loop of the robust check flies one plan
_QUEUE_WAIT_S = 5.0  # a failure job no worker took within solve_timeout + this is withdrawn (all workers down)
_LIVE_TIMEOUT_FACTOR = 4.0  # live job timeout = this × solve_timeout (the cold check may solve twice)


class LandingPlannerNode(Node):
    """Plans landings after engine failures and re-plans during the descent.

    Parameters: ``airframe``, ``gross_weight`` (N, 0 = the airframe file's), ``density_altitude`` (m, NaN = the
    file's), ``planner_settings`` (file, '' = config/planner.yaml), ``envelope_file``
    ('' = the shipped one, ``none`` = no envelope), ``deadline`` (s), ``replan_period`` (s, 0 = off),
    ``replan_min_height`` (m), ``replan_min_remaining`` (s), ``state_timeout`` (s), ``max_message_age`` (s),
    ``assume_total_power_loss``, ``warm_up``, ``world_frame``, ``rotor_joint``, ``diagnostics_period``;
    ``solver_workers`` (0 = solve in this process), ``solve_timeout`` (s, NaN = ``deadline``, ≥ 3 s); ``live_rate``
    (Hz, 0 = off), ``live_power_fraction``, ``live_max_state_age`` (s), ``standby_max_age`` (s);
    ``estimate_weight``, ``weight_estimate_window`` (s), ``weight_estimate_step``, ``weight_estimate_error``;
    ``estimate_disturbance``, ``disturbance_gain``.
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_planner", **node_options)
        declare = partial(declare_checked_parameter, self)
        load_aircraft = declare_aircraft(self)
        settings_file = declare("planner_settings", "", "planner settings file ('' = config/planner.yaml)")
        envelope_file = declare("envelope_file", "", "envelope for warm starts/fallbacks ('' = shipped, 'none' = off)")
        self._deadline = declare("deadline", 0.25, "fallback if no plan this long after the failure, s", (0.001, 60.0))
        self._replan_period = declare("replan_period", 0.25, "closed-loop re-planning period, s (0 = off)", (0.0, 60.0))
        self._replan_min_height = declare("replan_min_height", 0.5, "no re-planning below this height, m", (0.0, 1e3))
        self._replan_min_remaining = declare(
            "replan_min_remaining", 0.3, "no re-planning when the plan has less time left, s", (0.0, 60.0)
        )
        self._state_timeout = declare("state_timeout", 0.5, "older states are not planned from, s", (0.01, 60.0))
        self._max_message_age = declare(
            "max_message_age", 1.0, "first plan from a state later after the failure = late, s", (0.001, 3600.0)
        )
        self._assume_total_power_loss = declare(
            "assume_total_power_loss", True, "plan with zero engine power (else the measured power)"
        )
        warm_up = declare("warm_up", True, "solve one landing at startup (first-call costs)")
        self._world_frame = declare("world_frame", rm.DEFAULT_WORLD_FRAME, "frame of the landing path")
        self._rotor_joint = declare("rotor_joint", rm.ROTOR_JOINT, "JointState joint of the main rotor")
        diagnostics_period = declare("diagnostics_period", 1.0, "period of /diagnostics, s", (0.05, 60.0))
        solver_workers = declare("solver_workers", 2, "solver worker processes (0 = solve in this process)", (0, 16))
        solve_timeout = declare(
            "solve_timeout",
            math.nan,
            "a worker's failure plan not back this long = hung, s (NaN = deadline, at least 3 s)",
            (0.001, 600.0),
        )
        # Not the deadline itself by default: a slow solve is not a hung one, and its plan must still replace the
        # deadline's fallback (a dead worker is seen at once whatever the timeout).
        self._solve_timeout = max(self._deadline, _MIN_SOLVE_TIMEOUT_S) if math.isnan(solve_timeout) else solve_timeout
        reaction_delay = declare(
            "reaction_delay",
            math.nan,
            "s the controls stay at the pre-failure trim before a failure plan starts (NaN = the planner settings')",
            (0.0, 10.0),
        )
        self._reaction_delay = reaction_delay  # NaN until the settings are loaded
        live_rate = declare("live_rate", 5.0, "live evaluations before a failure, Hz (0 = off)", (0.0, 100.0))
        live_power_fraction = declare(
            "live_power_fraction", 0.0, "engine power left after the assumed failure, of the measured power", (0.0, 1.0)
        )
        live_max_state_age = declare(
            "live_max_state_age", 0.3, "an older state is not evaluated live, s", (0.001, 60.0)
        )
        standby_max_age = declare(
            "standby_max_age",
            0.3,
            "standby plan only from a state at most this much older than the failure, s",
            (0.001, 60.0),
        )
        self._estimate_weight = declare(
            "estimate_weight", False, "plan for the gross weight estimated from the steady flight before a failure"
        )
        self._weight_window = declare(
            "weight_estimate_window", 1.0, "steady flight averaged for the weight estimate, s", (0.1, 30.0)
        )
        self._weight_step = declare(
            "weight_estimate_step", 0.005, "quantum of the estimated relative weight change", (0.001, 0.05)
        )
        self._weight_error = declare(
            "weight_estimate_error",
            0.02,
            "estimates outside the uncertainty set's weight range widened by this fraction are refused",
            (0.0, 0.2),
        )
        self._estimate_disturbance = declare(
            "estimate_disturbance",
            True,
            "re-plan for the model plus the disturbance accelerations learnt from each re-planning interval",
        )
        self._disturbance_gain = declare(
            "disturbance_gain", 0.3, "fraction of each interval's prediction error the estimate takes", (0.01, 1.0)
        )
        robust_verification = declare(
            "robust_verification",
            False,
            "verify each failure plan robustly in a low-priority process (the plan is published 'robust: pending')",
        )
        self._robust_uncertainty = declare(
            "robust_uncertainty", "", "uncertainty set of the robust verification ('' = config/uncertainty.yaml)"
        )
        self._live_settings = (
            LiveSettings(
                rate_hz=live_rate,
                power_fraction=live_power_fraction,
                max_state_age_s=live_max_state_age,
                standby_max_age_s=standby_max_age,
            )
            if live_rate > 0.0
            else None
        )

        self._lock = threading.Lock()  # latest state, weight tracker
        self.supervisor = LandingSupervisor(
            SupervisorSettings(
                deadline=self._deadline,
                replan_min_height=self._replan_min_height,
                replan_min_remaining=self._replan_min_remaining,
                max_message_age=self._max_message_age,
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

        self.planner: Any | None = None  # the in-process LandingPlanner, or the SolverPool; None = not configured
        self._airframe_problems: list[str] = []  # derived figures outside helicopter ranges (a unit mistake?)
        self._pool: SolverPool | None = None
        self.envelope: Any | None = None
        self._setup_error = ""
        self._weights: WeightTracker | None = None  # None: no estimation (off, or not configured)
        self._weights_off_reason = "estimate_weight is false"
        self._built_weights: set[float] = set()  # in-process planners built (solver_workers = 0)
        self._robust: Any | None = None  # a BackgroundRobustVerification when robust_verification is on
        self.robust_verdicts: list[tuple[tuple[int, int, int], Any | None]] = []  # published: (key, summary|None)
        try:
            self._setup_core(load_aircraft, settings_file, envelope_file, warm_up, solver_workers)
            self._setup_weight_estimation()
            if robust_verification:
                self._setup_robust_verification()
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
        self._qos_watch = QosWatch(self, diagnostics_period)
        self._qos_watch.create_subscription(Odometry, rm.TOPIC_STATE, self._on_state, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(JointState, rm.TOPIC_ROTOR_STATE, self._on_rotor, rm.SENSOR_QOS)
        self._qos_watch.create_subscription(Header, rm.TOPIC_FAILURE_EVENT, self._on_failure_event, rm.EVENT_QOS)
        self._qos_watch.create_subscription(
            DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, self._on_episode, rm.LATCHED_QOS
        )
        # A periodic check, never cancelled or reset from the solver thread (cancelling a timer that the
        # executor is about to fire raises inside the executor). Every half deadline:
        # the fallback goes out within 1.5 deadlines without waking the executor needlessly.
        self.create_timer(max(self._deadline / 2.0, 0.005), self._on_deadline)
        if self._replan_period > 0.0:
            self.create_timer(self._replan_period, self._on_replan_timer)
        self.create_timer(diagnostics_period, self._publish_diagnostics)
        self._live_publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        if self._live_settings is not None:
            self.create_timer(1.0 / self._live_settings.rate_hz, self._on_live_timer)

    # -- startup -----------------------------------------------------------------------------------------------
    def _setup_core(
        self,
        load_aircraft: Callable[[], Any],
        settings_file: str,
        envelope_file: str,
        warm_up: bool,
        solver_workers: int,
    ) -> None:
        """Loads airframe, settings and envelope; starts the solver pool, or builds the NLP here and warms it up."""
        from helireach_ros.core.airframe_plausibility import implausible_figures
        from helireach_ros.core.model import initial_state_after_failure
        from helireach_ros.core.planner import get_planner
        from helireach_ros.core.settings import load_settings

        started = time.perf_counter()
        # Today's weight and density altitude change the model, hence the NLP and which envelope matches
        # (one made for other conditions is refused: cold starts, autorotation-entry fallback).
        self.airframe = load_aircraft()
        self._airframe_problems = implausible_figures(self.airframe)
        self.settings = load_settings(settings_file or None)
        if math.isnan(self._reaction_delay):
            self._reaction_delay = self.settings.reaction_delay_s
        self.envelope, self._envelope_note = self._load_envelope(envelope_file)
        self.warm_up_ms = math.nan
        if solver_workers > 0:
            # The workers build and warm up their own NLPs; the fallback needs airframe/settings/envelope only.
            self._pool = SolverPool(
                self.airframe,
                self.settings,
                SolverPoolSettings(workers=solver_workers, warm_up=warm_up, default_timeout_s=self._solve_timeout),
            )
            self.planner = self._pool
            if not self._pool.wait_ready(_POOL_READY_TIMEOUT_S):
                self.get_logger().error(
                    f"no solver worker ready after {_POOL_READY_TIMEOUT_S:g} s (last error: "
                    f"{self._pool.last_error or 'none'}): failures get fallbacks until one is"
                )
        else:
            self.planner = get_planner(self.airframe, self.settings)
        if warm_up and self._pool is None:
            state = initial_state_after_failure(self.airframe, 500.0 * FT, 75.0 * KT)
            stored = (
                self.envelope.nearest_plan(state.height, state.forward_speed, -state.descent_rate)
                if self.envelope
                else None
            )
            warm_up_started = time.perf_counter()
            self.planner.plan(state.as_array(), stored.warm_start if stored else None)
            self.warm_up_ms = 1e3 * (time.perf_counter() - warm_up_started)
        self.startup_s = time.perf_counter() - started
        where = f"{solver_workers} solver workers" if self._pool is not None else "solving in this process"
        self.get_logger().info(
            f"planner ready for {self.airframe.name} ({self.settings.method}, {self.settings.intervals} intervals) "
            f"in {self.startup_s:.2f} s, {where}; {self._envelope_note}"
        )

    def _setup_robust_verification(self) -> None:
        """The background robust verification of failure plans: the uncertainty set's design, the node's policy."""
        from helireach_ros.core.background_verification import BackgroundRobustVerification
        from helireach_ros.core.closed_loop import ClosedLoopSettings
        from helireach_ros.core.uncertainty import DEFAULT_UNCERTAINTY_FILE, load_uncertainty_set

        uncertainty = load_uncertainty_set(self._robust_uncertainty or DEFAULT_UNCERTAINTY_FILE)
        models = uncertainty.verification_design()
        policy = ClosedLoopSettings(
            replan_period=self._replan_period if self._replan_period > 0.0 else _NO_REPLANNING_PERIOD_S,
            min_height=self._replan_min_height,
            min_remaining=self._replan_min_remaining,
            estimate_disturbance=self._estimate_disturbance,
            disturbance=DisturbanceSettings(gain=self._disturbance_gain),
        )
        design = f"resolution-IV corners of {uncertainty.name!r} ({len(models)})"
        self._robust = BackgroundRobustVerification(models, design, policy)
        self._robust.prepare(self.airframe, self._robust_settings())
        self.get_logger().info(f"robust verification of failure plans on: {design}, in a low-priority process")

    def _robust_settings(self) -> Any:
        """The planner settings with this node's reaction delay (what its failure plans are made with)."""
        if self._reaction_delay == self.settings.reaction_delay_s:
            return self.settings
        return self.settings.replace(reaction_delay_s=self._reaction_delay)

    def _setup_weight_estimation(self) -> None:
        """The weight tracker, its band from the uncertainty set; an unreadable set disables it (file's weight)."""
        self._built_weights = {self.airframe.gross_weight}
        if not self._estimate_weight:
            return
        from helireach_ros.core.uncertainty import load_uncertainty_set

        try:
            band = plausible_band(load_uncertainty_set(), self._weight_error)
        except Exception as error:  # a broken uncertainty file must not stop the planner: plan for the file's weight
            self._weights_off_reason = f"no plausible weight band ({type(error).__name__}: {error})"
            self.get_logger().error(f"weight estimation off: {self._weights_off_reason}")
            return
        settings = WeightTrackingSettings(window_s=self._weight_window, band=band, step=self._weight_step)
        self._weights = WeightTracker(self.airframe, settings)

    def _weight_now(self) -> WeightChoice:
        """The weight to plan for now (the tracker's choice, or the file's with the reason)."""
        with self._lock:
            if self._weights is None:
                return WeightChoice(self.airframe.gross_weight, "file", 0.0, self._weights_off_reason)
            return self._weights.choice(self._now_ns())

    def ready_weights(self) -> set[float]:
        """Weights a ready solver holds (a failure plan for one builds no NLP)."""
        if self._pool is not None:
            return self._pool.ready_weights()
        with self._lock:
            return set(self._built_weights)

    def _in_process_planner(self, gross_weight: float) -> Any:
        """The in-process planner for a weight (built at its first use, then cached by get_planner)."""
        if gross_weight == self.airframe.gross_weight:
            return self.planner
        from helireach_ros.core.planner import get_planner

        return get_planner(self.airframe.with_conditions(gross_weight=gross_weight), self.settings)

    def _load_envelope(self, path: str) -> tuple[Any | None, str]:
        if path.strip().lower() == "none":
            return None, "no envelope (disabled): cold starts, autorotation-entry fallback"
        try:
            from helireach_ros.core.envelope.data import default_envelope_path, load_envelope

            resolved = path or str(default_envelope_path())
            envelope = load_envelope(resolved, self.airframe, self.settings, 0.0)
            return envelope, f"envelope {envelope.envelope_id} for warm starts and fallbacks"
        except Exception as error:  # missing or mismatched: plan cold, fall back to the autorotation entry
            note = f"envelope not usable ({type(error).__name__}: {error}): cold starts, autorotation-entry fallback"
            self.get_logger().warning(note)
            return None, note

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
            reading = rm.read_rotor(message, self._rotor_joint)
        except ValueError:
            return
        if state_problems(StateLimits(), rotor=reading):
            return
        now_ns = self._now_ns()
        # Steady flight before the failure only (after it the episode's weight is fixed); receive times, as every
        # freshness check here (a replayed log's stamps are old).
        before_failure = self.supervisor.before_failure
        with self._lock:
            self._rotor = (reading, now_ns)
            odometry = self._odometry
            if self._weights is not None and before_failure and odometry is not None:
                if now_ns - odometry[1] <= self._state_timeout * 1e9:
                    state = odometry[0]
                    sample = WeightSample(
                        now_ns, state.forward_speed, state.climb_rate, reading.rotor_speed, reading.engine_power
                    )
                    self._weights.add(sample)

    def current_state(self, measured_power: bool = False) -> tuple[np.ndarray, int, str, str] | None:
        """(state y, v, Ω, h, z, P; its stamp ns; vehicle frame; rotor-speed source), or None without a fresh state.

        Without a fresh rotor speed Ω₀ is assumed (the source says so; re-plans and live evaluations are then
        skipped). Ω within 1 % of Ω₀ outside the rotor limits is clipped to them (sensor noise); farther out it
        is kept. P is 0 with ``assume_total_power_loss`` (plans after a failure), else the measured power (the
        rotor reading's torque × Ω; 0 if not measured); ``measured_power`` always gives the measured power (live
        evaluation applies ``live_power_fraction`` to it).
        """
        now_ns = self._now_ns()
        timeout_ns = self._state_timeout * 1e9
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
        if power is None or (self._assume_total_power_loss and not measured_power):
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
        if self.planner is not None:
            why = self._weights_off_reason if self._weights is None else "no live evaluation yet (where NLPs are built)"
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
            if self._pool is not None:
                timeout_s = _LIVE_TIMEOUT_FACTOR * self._solve_timeout
                try:
                    job = self._pool.submit(
                        failure_now,
                        warm_start,
                        PRIORITY_LIVE,
                        timeout_s,
                        True,
                        None,
                        self._reaction_delay,
                        weight.gross_weight,
                    )
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
            solve = partial(self._in_process_planner(weight.gross_weight).plan, reaction_delay_s=self._reaction_delay)
            future.set_result(solve_with_cold_check(solve, state, warm_start))
            with self._lock:
                self._built_weights.add(weight.gross_weight)
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
                messages = plan_messages(verdict.plan, stamp_ns, frame, self._world_frame)
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
        if self._pool is not None:
            self._pool.close()
        if self._robust is not None:
            self._robust.close()
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
        if self._estimate_disturbance and failure.disturbance is None:  # after publishing: off the failure path
            weight = self.episode_weight.gross_weight
            model = self.airframe if weight == self.airframe.gross_weight else self.airframe.with_conditions(weight)
            failure.disturbance = DisturbanceTracker(model, DisturbanceSettings(gain=self._disturbance_gain))
            failure.disturbance.update(stamp_ns * 1e-9, state, _controls_from_stamp(plan, stamp_ns))  # 1st interval

    def _solve(
        self,
        state: np.ndarray,
        warm_start: Any,
        initial_control: Any = None,
        reaction_delay_s: float | None = None,
        disturbance: np.ndarray | None = None,
    ) -> tuple[Any | None, str]:
        """A failure plan or re-plan (blocking; on the solver thread): (plan, "") or (None, why not).

        ``initial_control``/``reaction_delay_s``: None for a failure plan (trim before the failure, the node's
        reaction delay); a re-plan passes the control being flown and 0, and the disturbance estimate.
        """
        delay = self._reaction_delay if reaction_delay_s is None else reaction_delay_s
        weight = self.episode_weight.gross_weight  # one the solvers hold (fixed at the failure)
        try:
            if self._pool is None:
                planner = self._in_process_planner(weight)
                return planner.plan(state, warm_start, initial_control, delay, disturbance=disturbance), ""
            future = self._pool.submit(
                state, warm_start, PRIORITY_FAILURE, self._solve_timeout, False, initial_control, delay, weight,
                disturbance,
            )  # fmt: skip
            try:
                # The pool fails the job solve_timeout after a worker took it; the extra wait covers the queue.
                return future.result(timeout=self._solve_timeout + _QUEUE_WAIT_S), ""
            except FutureTimeoutError:
                future.cancel()
                return None, f"no solver worker took the job within {self._solve_timeout + _QUEUE_WAIT_S:g} s"
        except (ValueError, RuntimeError) as error:  # SolverWorkerError is a RuntimeError
            return None, f"{type(error).__name__}: {error}"

    def _on_deadline(self) -> None:
        self._publish_robust_verdicts()
        failure = self.supervisor.deadline_fallback_due(self._now_ns())
        if failure is None:
            return
        current = self.current_state()
        if current is None:
            self._publish_status_only(failure, f"no plan within {self._deadline:g} s and no valid state")
            return
        state, stamp_ns, _, _ = current
        self._publish_fallback(failure, state, stamp_ns, f"no plan within the {self._deadline:g} s deadline")

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
        """The best available controls without a converged solve (:func:`helireach_ros.core.fallback.fallback_plan`)."""
        return fallback_plan(state, self.airframe, self.settings, self.envelope)

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
            if messages is None or not messages.matches(plan, stamp_ns, frame, self._world_frame):
                messages = plan_messages(plan, stamp_ns, frame, self._world_frame)
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
        weight = self.episode_weight.gross_weight
        model = self.airframe if weight == self.airframe.gross_weight else self.airframe.with_conditions(weight)
        key = (failure.failure_id, failure.event_stamp_ns, stamp_ns)
        assert self._robust is not None  # called only with robust verification on
        self._robust.submit(key, model, self._robust_settings(), plan)
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
        if self.planner is None:
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
        current = self.current_state() if failure is not None and failure.active else None
        health = PlannerHealth(
            airframe=self.airframe.name,
            method=self.settings.method,
            startup_s=self.startup_s,
            warm_up_ms=self.warm_up_ms,
            envelope_note=self._envelope_note,
            has_envelope=self.envelope is not None,
            failures=self.supervisor.failure_count,
            solving=self.solving,
            episode_phase=self.supervisor.episode.phase.value,
            solve_timeout_s=self._solve_timeout,
            ready_weights=len(self.ready_weights()),
            weight_now=self._weight_now(),
            airframe_problems=tuple(self._airframe_problems),
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
