"""Planner node: on an engine failure, plan the landing, publish it, and keep re-planning down to the ground.

**Where solves run.** With ``solver_workers`` ≥ 1 (default 2) every solve (live evaluations, the failure's plan,
re-plans) runs in a :class:`~helireach_ros.core.solver_pool.SolverPool` of worker processes, each holding the NLP
(no GIL shared with the executor). Failure plans and re-plans go at ``PRIORITY_FAILURE`` with a timeout of
``solve_timeout`` (default: ``deadline``, at least 3 s). A worker that dies fails its job at once (within the
pool's 10 ms supervision tick), one that hangs after ``solve_timeout``; the node then falls back exactly as after a
failed solve (and the deadline's fallback goes out after ``deadline`` whatever the worker does), the pool restarts
the worker, and ``/diagnostics`` reports the restarts and the last error. The timeout is not the deadline itself:
a solve that is merely slow (a loaded machine) must still be allowed to replace the deadline's fallback, as
without a pool; live jobs get 4 × ``solve_timeout`` (the cold check may solve twice). Start-up waits (at most
60 s) for one ready worker. With ``solver_workers`` = 0 the node builds the NLP itself
(:func:`~helireach_ros.core.planner.get_planner`) and solves one warm-up landing at start-up. Either way it loads
the envelope (for warm starts and fallbacks) when it was computed for the same airframe, planner settings and
total power loss.

**Live reachability** (:mod:`helireach_ros.core.live_reachability`, ``live_rate`` Hz, 0 = off). Before any
failure, at most one evaluation at a time: the latest valid state with a *measured* rotor speed
(``current_state``, engine power = the rotor reading's measured torque × Ω if given, else 0), the engine assumed
to fail now (``live_power_fraction`` of that power left), warm-started from the previous live solution (the
first from the envelope's nearest stored plan), solved with the cold check (a warm plan that is not safe is
solved again cold), replay-verified. Each verdict goes out on ``/helireach/live_reachability`` (latched
``DiagnosticStatus``; OK only for a replay-verified safe plan). A state older than ``live_max_state_age`` is not
evaluated; without a measured rotor speed nothing is evaluated (the answer would rest on an assumed Ω). Live
evaluation pauses while a failure episode runs (a verdict still in flight is dropped) and while it is LANDED (the
engine still out, on the ground), and starts afresh after ENDED or once the engine runs again.

**The standby plan.** On the failure, if the latest live verdict is replay-verified safe and its state is at
most ``standby_max_age`` older than the failure, its plan is published at once, before the refined solve is
submitted: a normal plan publication stamped with the verdict's own state stamp, ``standby=true`` in the plan
status, text ``STANDBY: …``. It counts as the episode's first plan (no deadline fallback after it; the lateness
rule applies to it as to any first plan). The refined plan from the state at the failure follows as below and
replaces it (``standby=false``); if that solve fails the standby stays (it is verified) and the closed loop keeps
trying.

One failure episode (:mod:`helireach_ros.core.failure_episode`, run by the monitor) is one planning episode:
it starts on the failure event (``/helireach/failure_event``, or the monitor's ``/helireach/failure_episode``
state when the event was missed) and stops when that state says ENDED (engine recovered: a plan status
``ended`` goes out, re-planning stops, nothing is called safe for it again) or LANDED. The first plan is
flagged ``late`` when its state is stamped more than ``max_message_age`` after the failure.

On a failure event the node takes the latest canonical state
(``/helireach/state`` + ``/helireach/rotor_state``), solves warm-started from the envelope's nearest
stored plan, and publishes the trajectory (``/helireach/landing_trajectory``), the predicted path
(``/helireach/landing_path``) and the plan status (``/helireach/plan_status``), all latched, stamped
with the state's stamp. Only a plan whose NLP value is ≤ 0 *and* whose independent replay lands
within limits is called safe.

If no plan is out ``deadline`` seconds after the failure event (the solve is slow or failed), a
fallback is published, flagged ``fallback=true``: the nearest envelope plan's controls from now on
(its cell's status is reported), or without an envelope a standard autorotation entry (steady
autorotation controls at the current speed). A later converged solve replaces it.

While the descent lasts (down to ``replan_min_height``, while the current plan has more than
``replan_min_remaining`` seconds to go) the node re-plans every ``replan_period`` seconds from the
current state, warm-started from its previous plan (closed loop). A re-plan that fails keeps the
current plan. Failure plans and re-plans run on the node's own solver thread, one at a time (a re-plan is
skipped while a solve is still running); with a pool that thread only waits for the worker's answer.
Callbacks only hand work to it (live jobs go to the pool directly, or to the solver thread without one). So
whatever executor spins the node, even a single-threaded one, state reception, the deadline's fallback and
status publishing go on during a solve.

**Gross weight** (``estimate_weight``, off by default; :mod:`helireach_ros.core.weight_tracking`). Before a
failure every rotor reading (Ω, engine power = torque × Ω) with a fresh state (speed, climb rate) is fed to a weight
tracker: over a short window of steady flight, the weight whose trim power is the measured power, bounded by the
uncertainty set's weight range (``config/uncertainty.yaml``) widened by ``weight_estimate_error``, quantised to
``weight_estimate_step``. Live evaluations plan for it (that is where a solver builds a new weight's NLP); at the
failure the episode's weight is fixed: the latest live evaluation's if a solver holds it, else the nearest one held
(the file's at worst), and the pool sends the job to a worker that holds it: no NLP is built in the failure path
(so with ``live_rate`` 0 the file's weight is used).
Failure plans and re-plans use it. Every plan status names it (``planned_gross_weight_n``, ``gross_weight_source``,
``gross_weight_reason``); without an estimate (engine power absent, flight not steady, implausible) the file's
weight is used and the reason says why.

**Model error** (``estimate_disturbance``, on by default; :mod:`helireach_ros.core.disturbance`). From the failure
plan's state on, each re-plan compares the measured state with the model's prediction over the interval since the
previous one (from that state, under the current plan's controls) and updates constant disturbance accelerations on
ẏ, v̇, Ω̇ by ``disturbance_gain`` of the error; the re-plan (NLP and replay) is made for the model plus them, and
its status reports them. The failure plan itself has none (nothing is known yet).

**Robust verification** (``robust_verification``, off by default; :mod:`helireach_ros.core.background_verification`).
Each safe failure plan (the refined one, solved from the state at the failure) is published at once, flagged
``robust: pending``, and then flown through the uncertainty set's design (``robust_uncertainty``, '' =
``config/uncertainty.yaml``): closed loop with this node's re-planning policy and each model's latency, stopping at the
first model that fails, in one worker process at the lowest CPU priority. Its verdict (pending, then robust or not,
with counts and the reason) goes out on ``/helireach/robust_verdict`` (latched), keyed by failure and state stamp.
Off by default: on a 2-core machine the verification (~3–50 s of CPU per plan) takes the idle CPU the re-plans leave,
and a standby plan, a fallback or a re-plan is not verified robustly.

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
from helireach_ros.core.failure_episode import (
    EpisodePhase,
    EpisodeState,
    FailureEpisode,
    PlanLateness,
    PublishedPlan,
    episode_outcome,
    episode_starts,
    late_verdict,
    plan_lateness,
)
from helireach_ros.core.fallback import FallbackPlan, fallback_plan
from helireach_ros.core.landing_supervisor import (
    CurrentPlan,
    ReplanGate,
    TimerAction,
    deadline_due,
    fallback_after_failed_first_plan,
    plan_time_remaining,
    replan_gate,
    replan_timer_action,
)
from helireach_ros.core.live_reachability import LiveEvaluator, LiveSettings, LiveVerdict, solve_with_cold_check
from helireach_ros.core.model import clip_rotor_speed_noise
from helireach_ros.core.plan_verdict import plan_verdict
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

_PLAN_HISTORY = 200  # published plans kept for inspection (demo, tests)
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

        self._lock = threading.Lock()  # latest state, failure bookkeeping
        self._publish_lock = threading.Lock()  # one plan decision/publication at a time
        self._odometry: tuple[OdometryReading, int, str] | None = None
        self._rotor: tuple[RotorReading, int] | None = None
        self._failure: FailureEpisode | None = None
        self._episode = EpisodeState()  # the monitor's failure-episode state (no_flag until one arrives)
        self._failure_count = 0
        self.published_plans: list[PublishedPlan] = []
        # Live evaluation: the evaluator and the job in flight, guarded by _live_lock. A generation number
        # drops verdicts that come back after a failure started or after a reset.
        self._live_lock = threading.Lock()
        self._live = LiveEvaluator(self._live_settings) if self._live_settings is not None else None
        self._live_job: Future | None = None
        self._live_generation = 0
        self._live_frame = rm.DEFAULT_BODY_FRAME  # vehicle frame of the standby verdict's state
        self.standby_plans: list[PublishedPlan] = []  # the published standby records (see is_standby)
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
        with self._lock:
            self._rotor = (reading, now_ns)
            odometry, failure = self._odometry, self._failure
            # Steady flight before the failure only (after it the episode's weight is fixed); receive times, as
            # every freshness check here (a replayed log's stamps are old).
            before_failure = failure is None or bool(failure.outcome)
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
        with self._lock:
            self._episode = state
            failure = self._failure
        if state.started_ns is not None and episode_starts(
            state, failure.event_stamp_ns if failure is not None else None
        ):
            self._start_failure(state.started_ns)
            return
        outcome = episode_outcome(state, failure.event_stamp_ns) if failure is not None else None
        if failure is not None and outcome is not None:
            self._stop_failure(failure, outcome, state)

    def _start_failure(self, failure_stamp_ns: int) -> None:
        """Starts planning for the failure stamped ``failure_stamp_ns`` (once: its event and state both announce it)."""
        now_ns = self._now_ns()
        with self._lock:
            if self._failure is not None and self._failure.event_stamp_ns == failure_stamp_ns:
                return
            self._failure_count += 1
            failure = FailureEpisode(self._failure_count, failure_stamp_ns, now_ns)
            self._failure = failure
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

    def _stop_failure(self, failure: FailureEpisode, outcome: EpisodePhase, state: EpisodeState) -> None:
        """Stops planning for ``failure``; the plan status says so (the last plan no longer applies), so a late
        joiner's latched status is not the last plan of an episode that is over."""
        with self._publish_lock:
            if failure is not self._failure or not failure.stop(outcome):
                return
            status, reason, text = _EPISODE_END_STATUS[outcome]
            values = {
                "status": status,
                "safe": False,
                "verified": False,
                "fallback": False,
                "reason": reason,
                "failure_id": failure.failure_id,
                "failure_stamp_ns": failure.event_stamp_ns,
                "ended_stamp_ns": state.ended_ns if state.ended_ns is not None else self._now_ns(),
                "episode_id": state.episode_id,
                "plans_published": len(failure.history),
                "replans": failure.replans,
            }
            self._status_publisher.publish(
                rm.diagnostic_status(
                    DiagnosticStatus.WARN,
                    f"{self.get_name()}: landing plan",
                    text,
                    self.airframe.name if self.planner is not None else "helireach",
                    values,
                )
            )
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

    def _live_paused(self) -> bool:
        """A failure episode runs (the planner's own, or the monitor's), or it landed and the engine is still out:
        on the ground with a failed engine "if the engine failed now" has no answer (and a drooping rotor made
        every solve fail at full effort)."""
        with self._lock:
            failure, phase = self._failure, self._episode.phase
        return (failure is not None and not failure.outcome) or phase in (EpisodePhase.FAILED, EpisodePhase.LANDED)

    def _on_live_timer(self) -> None:
        """Starts a live evaluation if one is due and none is in flight (see the module docstring)."""
        if self._live is None or self.planner is None or self._live_paused():
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
                self._live_publisher.publish(self._live_status(verdict, standby, weight))
            if standby:  # its messages now, off the executor and outside the lock: the failure only publishes them
                messages = plan_messages(verdict.plan, stamp_ns, frame, self._world_frame)
                with self._live_lock:
                    if generation == self._live_generation:
                        self._standby_messages = messages

    def _live_status(self, verdict: LiveVerdict, standby: bool, weight: WeightChoice) -> DiagnosticStatus:
        """The ``/helireach/live_reachability`` message of a verdict (msg_docs/helireach_live_reachability.md)."""
        assert self._live is not None  # verdicts come from the live evaluator
        plan = verdict.plan
        verified = plan is not None and plan.verified
        values = {
            "status": verdict.status,
            "value": verdict.value,
            "safe": verdict.safe,
            "verified": verified,
            "state_stamp_ns": verdict.state_stamp_ns,
            "solve_time_ms": verdict.solve_time_ms,
            "state_age_s": verdict.state_age_s(self._now_ns()),
            "time_to_land_s": plan.time_to_land if plan is not None else math.nan,
            "power_fraction": self._live.settings.power_fraction,
            "reason": verdict.reason,
            "standby": standby,
            "descent_rate_m_s": verdict.state[0],
            "forward_speed_m_s": verdict.state[1],
            "rotor_speed_rad_s": verdict.state[2],
            "height_m": verdict.state[3],
            "distance_m": verdict.state[4],
            "engine_power_w": verdict.state[5],
            **self._weight_values(weight),
        }
        if plan is None:
            level, text = DiagnosticStatus.ERROR, f"LIVE ERROR: no verdict ({verdict.reason})"
        elif not plan.solver.success:  # plan_verdict would call it unsafe: it is unknown
            level, text = DiagnosticStatus.ERROR, f"if the engine failed now: UNKNOWN (solver {plan.solver.status})"
        else:
            _, text = plan_verdict(plan, "measured")
            level = DiagnosticStatus.OK if verdict.safe and verified else DiagnosticStatus.ERROR
            text = f"if the engine failed now: {text}"
        name = f"{self.get_name()}: live reachability"
        return rm.diagnostic_status(level, name, text, self.airframe.name, values)

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
        return any(record is standby for standby in self.standby_plans)

    def _standby_is_current(self, failure: FailureEpisode) -> bool:
        return failure.current is not None and self.is_standby(failure.current)

    def _current_plan(self, failure: FailureEpisode) -> CurrentPlan:
        if not failure.published or failure.current is None:
            return CurrentPlan.NONE
        if failure.current.fallback:
            return CurrentPlan.FALLBACK
        return CurrentPlan.STANDBY if self._standby_is_current(failure) else CurrentPlan.CONVERGED

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
            if fallback_after_failed_first_plan(
                retry=retry,
                any_published=failure.published,
                has_plan_from_state=failure.has_plan_from(stamp_ns),
                standby_current=self._standby_is_current(failure),
            ):
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
        with self._lock:
            failure = self._failure
            if failure is None or not deadline_due(
                failure_active=failure.active,
                any_published=failure.published,
                already_handled=failure.deadline_handled,
                elapsed_s=(self._now_ns() - failure.event_received_ns) * 1e-9,
                deadline_s=self._deadline,
            ):
                return
            failure.deadline_handled = True
        current = self.current_state()
        if current is None:
            self._publish_status_only(failure, f"no plan within {self._deadline:g} s and no valid state")
            return
        state, stamp_ns, _, _ = current
        self._publish_fallback(failure, state, stamp_ns, f"no plan within the {self._deadline:g} s deadline")

    def _on_replan_timer(self) -> None:
        with self._lock:
            failure = self._failure
        if failure is None:
            return
        action = replan_timer_action(
            failure_active=failure.active, planner_ready=self.planner is not None, current=self._current_plan(failure)
        )
        if action is TimerAction.RETRY_FIRST_PLAN:
            self._submit(self._plan_initial, failure, True)
        elif action is TimerAction.REPLAN:
            self._submit(self._replan, failure)

    def _replan(self, failure: FailureEpisode) -> None:
        """One closed-loop re-plan from the current state, warm-started from the current plan."""
        if not failure.active or failure is not self._failure:
            return
        current = self.current_state()
        if current is None:
            return
        state, stamp_ns, frame, rotor_source = current
        previous = failure.current
        if previous is None:  # the timer re-plans only once a converged plan is out
            return
        remaining = plan_time_remaining(previous.plan.time_to_land, (stamp_ns - previous.stamp_ns) * 1e-9)
        gate = replan_gate(
            rotor_measured=rotor_source == "measured",
            height=state[3],
            time_remaining=remaining,
            min_height=self._replan_min_height,
            min_remaining=self._replan_min_remaining,
        )
        if gate is ReplanGate.PAUSE_NO_ROTOR:
            failure.replans_skipped_no_rotor += 1
            self.get_logger().warning(
                f"failure #{failure.failure_id}: re-planning paused: no measured rotor speed (the current plan is "
                f"kept; {failure.replans_skipped_no_rotor} re-plans skipped)",
                throttle_duration_sec=1.0,
            )
            return
        if gate is ReplanGate.END_CLOSED_LOOP:
            failure.active = False
            self.get_logger().info(
                f"failure #{failure.failure_id}: closed loop ends at {state[3]:.2f} m, {remaining:.2f} s to go "
                f"({failure.replans} re-plans, {failure.replans_failed} failed)"
            )
            return
        # from the control being flown at the state's stamp (the flyable controls stay continuous), no delay
        flying = previous.plan.controls_at([(stamp_ns - previous.stamp_ns) * 1e-9])[:, 0]
        # what the last interval taught of the model's error (the current plan's controls were flown in it)
        flown = _controls_from_stamp(previous.plan, previous.stamp_ns)
        tracker = failure.disturbance
        disturbance = tracker.update(stamp_ns * 1e-9, state, flown) if tracker is not None else None
        plan, error = self._solve(state, previous.plan.warm_start, flying, 0.0, disturbance)
        if plan is None or not plan.solver.success:
            failure.replans_failed += 1
            reason = error or (f"solver {plan.solver.status}" if plan is not None else "no plan")
            self.get_logger().warning(f"re-plan failed ({reason}); keeping the current plan", throttle_duration_sec=1.0)
            return
        failure.replans += 1
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
        with self._publish_lock:
            if failure is not self._failure or failure.outcome:
                return  # a newer failure came, or this one is over
            if failure.current is not None and not failure.current.fallback:
                return  # a converged plan came first
            now_ns = self._now_ns()
            lateness = plan_lateness(failure.event_stamp_ns, stamp_ns, self._max_message_age)
            record = PublishedPlan(
                failure.failure_id,
                failure.replans,
                stamp_ns,
                fallback,
                True,
                (now_ns - failure.event_received_ns) * 1e-6,
                now_ns,
                "none",
            )
            self._trajectory_publisher.publish(rm.trajectory_message(fallback, stamp_ns))
            values = {
                "status": "fallback",
                "safe": False,
                "verified": False,
                "fallback": True,
                "standby": False,
                "fallback_kind": fallback.kind,
                "fallback_source_status": fallback.source_status,
                "reason": reason,
                "time_to_land_s": fallback.time_to_land,
                "latency_ms": record.latency_ms,
                **self._lateness_values(lateness),
                **self._common_values(failure, state, stamp_ns),
            }
            _, text = late_verdict("WARN", f"FALLBACK (not verified): {fallback.description}; {reason}", lateness)
            name = f"{self.get_name()}: landing plan"
            self._status_publisher.publish(
                rm.diagnostic_status(DiagnosticStatus.WARN, name, text, self.airframe.name, values)
            )
            self._remember(failure, record)
        self.get_logger().warning(f"failure #{failure.failure_id}: published fallback {fallback.description}")

    # -- publishing ----------------------------------------------------------------------------------------------
    @staticmethod
    def _lateness_values(lateness: PlanLateness | None) -> dict[str, Any]:
        """``late``, ``late_by_s``, ``state_delay_s``, ``after_fallback`` (re-plans: not late, no delay)."""
        if lateness is None:
            return {"late": False, "late_by_s": 0.0, "after_fallback": False}
        return {
            "late": lateness.late,
            "late_by_s": lateness.late_by_s,
            "state_delay_s": lateness.state_delay_s,
            "after_fallback": lateness.after_fallback,
        }

    @property
    def episode_weight(self) -> WeightChoice:
        """The gross weight the current (or last) failure episode plans for (the file's before any failure)."""
        weight = self._failure_weight
        return weight if weight is not None else WeightChoice(self.airframe.gross_weight, "file", 0.0, "no failure")

    def _weight_values(self, weight: WeightChoice) -> dict[str, Any]:
        """The status keys of the weight a plan was made for (msg_docs/helireach_plan_status.md); ``gross_weight_n``
        stays the configured aircraft's (the recorder's run metadata adopts it)."""
        return {
            "gross_weight_n": self.airframe.gross_weight,
            "planned_gross_weight_n": weight.gross_weight,
            "gross_weight_source": weight.source,
            "gross_weight_change": weight.relative_change,
            "gross_weight_estimate_change": weight.estimated_change,
            "gross_weight_reason": weight.reason,
        }

    def _common_values(
        self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int, weight: WeightChoice | None = None
    ) -> dict[str, Any]:
        """Keys of every plan status; ``weight`` None: a fallback (the file's model)."""
        if weight is None:
            weight = WeightChoice(self.airframe.gross_weight, "file", 0.0, "fallback controls from the file's model")
        return {
            "failure_id": failure.failure_id,
            "failure_stamp_ns": failure.event_stamp_ns,
            "state_stamp_ns": stamp_ns,
            "initial_descent_rate_m_s": state[0],
            "initial_forward_speed_m_s": state[1],
            "initial_rotor_speed_rad_s": state[2],
            "initial_height_m": state[3],
            "initial_distance_m": state[4],
            "initial_engine_power_w": state[5],
            "airframe": self.airframe.name,
            **self._weight_values(weight),
            "density_altitude_m": self.airframe.density_altitude,
            "envelope_id": self.envelope.envelope_id if self.envelope is not None else "",
        }

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
        with self._publish_lock:
            if failure is not self._failure or failure.outcome:
                return  # a newer failure superseded this one, or it ended, while solving
            now_ns = self._now_ns()
            # Late "after a fallback" only if a fallback went out first: a standby before it is a verified plan.
            after_fallback = any(record.fallback for record in failure.history)
            lateness = (
                None
                if replan
                else plan_lateness(failure.event_stamp_ns, stamp_ns, self._max_message_age, after_fallback)
            )
            reference_ns = failure.event_received_ns if not replan else stamp_ns
            record = PublishedPlan(
                failure.failure_id,
                failure.replans,
                stamp_ns,
                plan,
                False,
                (now_ns - reference_ns) * 1e-6,
                now_ns,
                warm_source,
            )
            if messages is None or not messages.matches(plan, stamp_ns, frame, self._world_frame):
                messages = plan_messages(plan, stamp_ns, frame, self._world_frame)
            self._trajectory_publisher.publish(messages.trajectory_cdr)
            self._path_publisher.publish(messages.path_cdr)
            values = {
                **rm.plan_status_values(plan),
                "standby": standby,
                "warm_start": warm_source,
                "replan_index": failure.replans if replan else 0,
                **self._lateness_values(lateness),
                "latency_ms": record.latency_ms,
                "rotor_speed_source": rotor_source,
                **self._common_values(failure, plan.initial_state, stamp_ns, weight),
            }
            if robust_pending and self._robust is not None:
                values.update(robust="pending", robust_design=self._robust.design)
            level_name, text = plan_verdict(plan, rotor_source)
            if standby:
                state_age_s = (failure.event_stamp_ns - stamp_ns) * 1e-9
                text = f"STANDBY (live plan from {state_age_s:.2f} s before the failure; refining): {text}"
            if lateness is not None:
                level_name, text = late_verdict(level_name, text, lateness)
            level = rm.DIAGNOSTIC_LEVELS[level_name]
            self._status_publisher.publish(
                rm.diagnostic_status(level, f"{self.get_name()}: landing plan", text, self.airframe.name, values)
            )
            self._remember(failure, record)
            if standby:
                self.standby_plans.append(record)
                del self.standby_plans[:-_PLAN_HISTORY]
        if not replan:
            fast_logging.info(self.get_logger(), f"failure #{failure.failure_id}: {text} ({record.latency_ms:.0f} ms)")

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
        failure_id, failure_stamp_ns, stamp_ns = key
        values: dict[str, Any] = {
            "failure_id": failure_id, "failure_stamp_ns": failure_stamp_ns, "state_stamp_ns": stamp_ns,
        }  # fmt: skip
        if summary is None:
            design = self._robust.design if self._robust is not None else ""
            level, text = DiagnosticStatus.STALE, f"PENDING: robust verification running ({design})"
            values.update(robust="pending", robust_design=design)
        else:
            values.update(summary.values())
            if summary.robust:
                level = DiagnosticStatus.OK
                text = f"ROBUST: lands closed loop in all {summary.models_flown} models ({summary.design})"
            else:
                level = DiagnosticStatus.ERROR if summary.error else DiagnosticStatus.WARN
                text = f"NOT ROBUST: {summary.reason}"
        self._robust_publisher.publish(
            rm.diagnostic_status(level, f"{self.get_name()}: robust verdict", text, self.airframe.name, values)
        )
        self.robust_verdicts.append((key, summary))
        del self.robust_verdicts[:-_PLAN_HISTORY]

    def _publish_status_only(self, failure: FailureEpisode, text: str) -> None:
        self.get_logger().error(f"failure #{failure.failure_id}: {text}")
        hardware_id = self.airframe.name if self.planner is not None else "helireach"
        values = {
            "status": "none",
            "safe": False,
            "verified": False,
            "fallback": False,
            "reason": text,
            "failure_id": failure.failure_id,
        }
        with self._publish_lock:
            if failure is self._failure and not failure.published and not failure.outcome:
                self._status_publisher.publish(
                    rm.diagnostic_status(
                        DiagnosticStatus.ERROR,
                        f"{self.get_name()}: landing plan",
                        f"NO PLAN: {text}",
                        hardware_id,
                        values,
                    )
                )

    def _remember(self, failure: FailureEpisode, record: PublishedPlan) -> None:
        failure.remember(record)
        self.published_plans.append(record)
        del self.published_plans[:-_PLAN_HISTORY]

    # -- diagnostics ---------------------------------------------------------------------------------------------
    @property
    def failure_active(self) -> bool:
        """A failure is being handled and the closed loop has not ended."""
        with self._lock:
            return self._failure is not None and self._failure.active

    def _publish_diagnostics(self) -> None:
        with self._lock:
            failure = self._failure
        if self.planner is None:
            status = rm.diagnostic_status(
                DiagnosticStatus.ERROR,
                f"{self.get_name()}: planner",
                f"not configured: {self._setup_error}",
                "helireach",
            )
            self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), status))
            return
        values: dict[str, Any] = {
            "airframe": self.airframe.name,
            "method": self.settings.method,
            "startup_s": self.startup_s,
            "warm_up_ms": self.warm_up_ms,
            "envelope": self._envelope_note,
            "failures": self._failure_count,
            "solving": self.solving,
            "failure_episode": self._episode.phase.value,
            "solver_workers": self._pool.pool_settings.workers if self._pool is not None else 0,
            "solve_timeout_s": self._solve_timeout,
            "ready_weights": len(self.ready_weights()),
        }
        weight_now = self._weight_now()
        values |= {
            "weight_estimate_n": weight_now.gross_weight,
            "weight_estimate_source": weight_now.source,
            "weight_estimate_change": weight_now.relative_change,
            "weight_estimate_reason": weight_now.reason,
        }
        problems = [f"implausible airframe: {problem}" for problem in self._airframe_problems]
        no_worker = False
        if self._pool is not None:
            ready = self._pool.ready_workers
            values.update(
                ready_workers=ready,
                busy_workers=self._pool.busy_workers,
                worker_restarts=self._pool.restarts,
                last_worker_error=self._pool.last_error,
            )
            if ready == 0:
                no_worker = True
                problems.append("no solver worker ready (failures get fallbacks)")
            if self._pool.restarts:
                problems.append(f"{self._pool.restarts} solver worker restarts (last: {self._pool.last_error})")
        with self._live_lock:
            live = self._live
            if live is not None:
                latest = live.latest
                values.update(
                    live_rate_hz=live.settings.rate_hz,
                    live_evaluations=live.evaluations,
                    live_errors=live.errors,
                    live_clock_jumps_back=live.clock_jumps_back,
                    live_status=latest.status if latest is not None else "none",
                    standby_available=live.standby_verdict is not None,
                )
            else:
                values["live_rate_hz"] = 0.0
        if failure is not None:
            values.update(
                failure_active=failure.active, replans=failure.replans, replans_failed=failure.replans_failed,
                replans_skipped_no_rotor=failure.replans_skipped_no_rotor,
            )  # fmt: skip
            current = self.current_state() if failure.active and failure.replans_skipped_no_rotor else None
            if current is not None and current[3] != "measured":
                problems.append("re-planning paused: no measured rotor speed (the current plan is kept)")
            values["failure_outcome"] = failure.outcome
            if failure.current is not None:
                values["last_latency_ms"] = failure.current.latency_ms
        level = DiagnosticStatus.OK if self.envelope is not None and not problems else DiagnosticStatus.WARN
        level = DiagnosticStatus.ERROR if no_worker else level
        text = "; ".join(
            ["ready" if self.envelope is not None else "ready without an envelope (cold starts)", *problems]
        )
        status = rm.diagnostic_status(level, f"{self.get_name()}: planner", text, self.airframe.name, values)
        self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), status))


_EPISODE_END_STATUS = {
    EpisodePhase.ENDED: (
        "ended",
        "engine recovered: the failure flag stayed false for the recovery hold",
        "ENDED (engine recovered): no landing plan; the last trajectory no longer applies",
    ),
    EpisodePhase.LANDED: (
        "landed",
        "on the ground: the monitor saw the aircraft landed",
        "LANDED: planning stopped; the last trajectory no longer applies",
    ),
}
"""Plan status, reason and message once an episode is over, per outcome."""


def _controls_from_stamp(plan: Any, stamp_ns: int) -> Callable[[float], np.ndarray]:
    """A plan's controls as a function of time in seconds (the plan starts at its state's stamp)."""
    start = stamp_ns * 1e-9
    return lambda time: plan.controls_at([time - start])[:, 0]


def main(args: list[str] | None = None) -> None:
    """Runs the planner node until Ctrl-C or SIGTERM."""
    raise SystemExit(run_node(LandingPlannerNode, args))  # 2: bad command line or parameter (one line on stderr)


if __name__ == "__main__":
    main()
