"""The planner node's solvers and their evidence, without ROS: what a failure is planned with.

A :class:`PlannerBackend` is built once at start-up from the airframe (with today's conditions), the planner settings
and :class:`BackendSettings`: it loads the envelope when it was computed for the same airframe, settings and total
power loss (warm starts, fallbacks; one made for other conditions is refused), starts the
:class:`~helireach_ros.core.workers.solver_pool.SolverPool` (``solver_workers`` ≥ 1) or builds the NLP in this process
and solves one warm-up landing, keeps the gross-weight tracker (``estimate_weight``) and the background robust
verification. The node asks it to solve, to fall back, and what it holds; every solve it makes for a failure either
returns a plan or says why not, never raises.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeoutError
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from helireach_ros.core.estimation.weight_tracking import (
    WeightChoice,
    WeightSample,
    WeightTracker,
    WeightTrackingSettings,
    plausible_band,
)
from helireach_ros.core.planning.fallback import FallbackPlan, fallback_plan
from helireach_ros.core.workers.solver_pool import PRIORITY_FAILURE, PRIORITY_LIVE, SolverPool, SolverPoolSettings

if TYPE_CHECKING:
    from helireach_ros.core.aircraft.airframe import Airframe
    from helireach_ros.core.ocp.settings import PlannerSettings
    from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings

__all__ = ["BackendSettings", "PlannerBackend"]

_POOL_READY_TIMEOUT_S = 60.0  # start-up waits at most this long for one ready solver worker
_QUEUE_WAIT_S = 5.0  # a failure job no worker took within solve_timeout + this is withdrawn (all workers down)
_LIVE_TIMEOUT_FACTOR = 4.0  # live job timeout = this × solve_timeout (the cold check may solve twice)


@dataclass(frozen=True)
class BackendSettings:
    """The planner node's parameters of the same names that decide how it solves (SI).

    Attributes:
        envelope_file: '' = the shipped envelope, ``none`` = no envelope (cold starts, autorotation-entry fallback).
        solver_workers: worker processes (0 = solve in this process).
        warm_up: solve one landing at start-up (in every worker, or here).
        solve_timeout_s: a worker's failure plan not back this long is a hung worker's.
        reaction_delay_s: s the controls stay at the pre-failure trim before a failure plan starts (NaN = the
            planner settings').
        estimate_weight: plan for the gross weight estimated from the steady flight before a failure.
        weight_window_s, weight_step, weight_error: the weight tracker's window, quantum and plausible band's widening.
        robust_policy: the node's re-planning policy, with which each safe failure plan is verified robustly in a
            low-priority process (None: no robust verification).
        robust_uncertainty: the uncertainty set of that verification ('' = config/uncertainty.yaml).
        site_planning: plans may be asked to land on a site (a touchdown window): the site NLP is built at start-up
            too (needs the ``flyable`` method).
        footprint: the live reachable footprint: the workers build its two NLPs at start-up (needs the ``flyable``
            method and a solver pool).
    """

    envelope_file: str = ""
    solver_workers: int = 2
    warm_up: bool = True
    solve_timeout_s: float = 3.0
    reaction_delay_s: float = math.nan
    estimate_weight: bool = False
    weight_window_s: float = 1.0
    weight_step: float = 0.005
    weight_error: float = 0.02
    robust_policy: ClosedLoopSettings | None = None
    robust_uncertainty: str = ""
    site_planning: bool = False
    footprint: bool = False


class PlannerBackend:
    """The solvers, the envelope and the estimators of one planner node (see the module docstring).

    Args:
        airframe: the aircraft with today's conditions.
        settings: the planner settings.
        backend: how to solve.
        report: ``report(level, text)`` for what start-up must tell the operator (``"warning"``, ``"error"``,
            ``"info"``).

    Raises:
        Whatever a broken configuration raises (the node reports it and makes no plans).
    """

    def __init__(
        self,
        airframe: Airframe,
        settings: PlannerSettings,
        backend: BackendSettings,
        report: Callable[[str, str], None],
    ) -> None:
        from helireach_ros.core.aircraft.plausibility import implausible_figures
        from helireach_ros.core.planning.planner import get_planner

        started = time.perf_counter()
        if (backend.site_planning or backend.footprint) and settings.method != "flyable":
            raise ValueError(f"landing sites and the footprint need the flyable method, not {settings.method!r}")
        self.airframe = airframe
        self.settings = settings
        self.backend = backend
        self.airframe_problems = implausible_figures(airframe)
        self.reaction_delay_s = (
            settings.reaction_delay_s if math.isnan(backend.reaction_delay_s) else backend.reaction_delay_s
        )
        self.envelope, self.envelope_note = self._load_envelope(backend.envelope_file, report)
        self.warm_up_ms = math.nan
        self.pool: SolverPool | None = None
        self._lock = threading.Lock()  # the weights built here, the weight tracker
        self._built_weights = {airframe.gross_weight}  # in-process planners built (solver_workers = 0)
        if backend.solver_workers > 0:
            # The workers build and warm up their own NLPs; the fallback needs airframe/settings/envelope only.
            self.pool = SolverPool(
                airframe,
                settings,
                SolverPoolSettings(
                    workers=backend.solver_workers,
                    warm_up=backend.warm_up,
                    default_timeout_s=backend.solve_timeout_s,
                    site_planning=backend.site_planning,
                    footprint=backend.footprint,
                ),
            )
            self.planner: Any = self.pool
            if not self.pool.wait_ready(_POOL_READY_TIMEOUT_S):
                report(
                    "error",
                    f"no solver worker ready after {_POOL_READY_TIMEOUT_S:g} s (last error: "
                    f"{self.pool.last_error or 'none'}): failures get fallbacks until one is",
                )
        else:
            self.planner = get_planner(airframe, settings)
            if backend.site_planning:
                self.in_process_planner(airframe.gross_weight, site=True)
            if backend.warm_up:
                self.warm_up_ms = self._warm_up()
        self.startup_s = time.perf_counter() - started
        self.weights, self.weights_off_reason = self._weight_tracker(report)
        self.robust: Any | None = None  # a BackgroundRobustVerification when robust verification is on
        if backend.robust_policy is not None:
            self._start_robust_verification(backend.robust_policy, report)

    # -- start-up -----------------------------------------------------------------------------------------------
    def _load_envelope(self, path: str, report: Callable[[str, str], None]) -> tuple[Any | None, str]:
        if path.strip().lower() == "none":
            return None, "no envelope (disabled): cold starts, autorotation-entry fallback"
        try:
            from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
            from helireach_ros.core.envelope.family import family_member_path

            resolved = path or str(default_envelope_path())
            # a family: its member for this airframe's conditions, whose plans are this planner's (none between them)
            member = family_member_path(resolved, self.airframe)
            envelope = load_envelope(member or resolved, self.airframe, self.settings, 0.0)
            return envelope, f"envelope {envelope.envelope_id} for warm starts and fallbacks"
        except Exception as error:  # missing or mismatched: plan cold, fall back to the autorotation entry
            note = f"envelope not usable ({type(error).__name__}: {error}): cold starts, autorotation-entry fallback"
            report("warning", note)
            return None, note

    def _warm_up(self) -> float:
        """One landing from 500 ft / 75 kt (first-call costs), ms."""
        from helireach_ros.core.aircraft.model import initial_state_after_failure
        from helireach_ros.core.units import FT, KT

        state = initial_state_after_failure(self.airframe, 500.0 * FT, 75.0 * KT)
        stored = (
            self.envelope.nearest_plan(state.height, state.forward_speed, -state.descent_rate)
            if self.envelope
            else None
        )
        started = time.perf_counter()
        self.planner.plan(state.as_array(), stored.warm_start if stored else None)
        return 1e3 * (time.perf_counter() - started)

    def _weight_tracker(self, report: Callable[[str, str], None]) -> tuple[WeightTracker | None, str]:
        """The weight tracker, its band from the uncertainty set; an unreadable set disables it (file's weight)."""
        if not self.backend.estimate_weight:
            return None, "estimate_weight is false"
        from helireach_ros.core.flight.uncertainty import load_uncertainty_set

        try:
            band = plausible_band(load_uncertainty_set(), self.backend.weight_error)
        except Exception as error:  # a broken uncertainty file must not stop the planner: plan for the file's weight
            reason = f"no plausible weight band ({type(error).__name__}: {error})"
            report("error", f"weight estimation off: {reason}")
            return None, reason
        settings = WeightTrackingSettings(
            window_s=self.backend.weight_window_s, band=band, step=self.backend.weight_step
        )
        return WeightTracker(self.airframe, settings), ""

    def _start_robust_verification(self, policy: ClosedLoopSettings, report: Callable[[str, str], None]) -> None:
        """The background robust verification of failure plans: the uncertainty set's design, the node's policy."""
        from helireach_ros.core.flight.uncertainty import DEFAULT_UNCERTAINTY_FILE, load_uncertainty_set
        from helireach_ros.core.robustness.background import BackgroundRobustVerification

        uncertainty = load_uncertainty_set(self.backend.robust_uncertainty or DEFAULT_UNCERTAINTY_FILE)
        models = uncertainty.verification_design()
        design = f"resolution-IV corners of {uncertainty.name!r} ({len(models)})"
        self.robust = BackgroundRobustVerification(models, design, policy)
        self.robust.prepare(self.airframe, self.robust_settings())
        report("info", f"robust verification of failure plans on: {design}, in a low-priority process")

    # -- what it holds ------------------------------------------------------------------------------------------
    def robust_settings(self) -> PlannerSettings:
        """The planner settings with the node's reaction delay (what its failure plans are made with)."""
        if self.reaction_delay_s == self.settings.reaction_delay_s:
            return self.settings
        return self.settings.replace(reaction_delay_s=self.reaction_delay_s)

    def model_for(self, gross_weight: float) -> Airframe:
        """The airframe at a gross weight (N)."""
        if gross_weight == self.airframe.gross_weight:
            return self.airframe
        return self.airframe.with_conditions(gross_weight=gross_weight)

    def ready_weights(self) -> set[float]:
        """Weights a ready solver holds (a failure plan for one builds no NLP)."""
        if self.pool is not None:
            return self.pool.ready_weights()
        with self._lock:
            return set(self._built_weights)

    def in_process_planner(self, gross_weight: float, *, site: bool = False) -> Any:
        """The in-process planner for a weight, anywhere or for a site (built at its first use, then cached by
        get_planner)."""
        if gross_weight == self.airframe.gross_weight and not site:
            return self.planner
        from helireach_ros.core.planning.planner import get_planner

        settings = self.settings.replace(objective="site") if site else self.settings
        return get_planner(self.model_for(gross_weight), settings)

    def _solve_in_process(
        self,
        state: np.ndarray,
        warm_start: Any,
        gross_weight: float,
        touchdown_window: tuple[float, float] | None,
        *,
        cold_check: bool,
        **request: Any,
    ) -> Any:
        """A solve here (no pool), as a worker makes it (:func:`~helireach_ros.core.policies.landing_sites.
        plan_site_or_anywhere`)."""
        from helireach_ros.core.policies.landing_sites import plan_site_or_anywhere

        site_planner = self.in_process_planner(gross_weight, site=True) if touchdown_window is not None else None
        return plan_site_or_anywhere(
            self.in_process_planner(gross_weight), site_planner, state, warm_start, touchdown_window,
            cold_check=cold_check, **request,
        )  # fmt: skip

    def add_weight_sample(self, sample: WeightSample) -> None:
        """A steady-flight reading for the weight estimate (ignored without estimation)."""
        with self._lock:
            if self.weights is not None:
                self.weights.add(sample)

    def weight_now(self, now_ns: int) -> WeightChoice:
        """The weight to plan for now (the tracker's choice, or the file's with the reason)."""
        with self._lock:
            if self.weights is None:
                return WeightChoice(self.airframe.gross_weight, "file", 0.0, self.weights_off_reason)
            return self.weights.choice(now_ns)

    # -- solving ------------------------------------------------------------------------------------------------
    def solve(
        self,
        state: np.ndarray,
        warm_start: Any,
        *,
        gross_weight: float,
        initial_control: np.ndarray | None = None,
        reaction_delay_s: float | None = None,
        disturbance: np.ndarray | None = None,
        touchdown_window: tuple[float, float] | None = None,
    ) -> tuple[Any | None, str]:
        """A failure plan or re-plan (blocking): (plan, "") or (None, why not).

        ``initial_control``/``reaction_delay_s``: None for a failure plan (trim before the failure, the node's
        reaction delay); a re-plan passes the control being flown and 0, and the disturbance estimate.
        ``touchdown_window``: land on that site (m from the state), else anywhere (the plan's own window says which).
        """
        delay = self.reaction_delay_s if reaction_delay_s is None else reaction_delay_s
        timeout_s = self.backend.solve_timeout_s
        request: dict[str, Any] = {
            "initial_control": initial_control,
            "reaction_delay_s": delay,
            "disturbance": disturbance,
        }
        try:
            if self.pool is None:
                plan = self._solve_in_process(
                    state, warm_start, gross_weight, touchdown_window, cold_check=False, **request
                )
                return plan, ""
            future = self.pool.submit(
                state, warm_start, priority=PRIORITY_FAILURE, timeout_s=timeout_s, gross_weight=gross_weight,
                touchdown_window=touchdown_window, **request,
            )  # fmt: skip
            try:
                # The pool fails the job solve_timeout after a worker took it; the extra wait covers the queue.
                return future.result(timeout=timeout_s + _QUEUE_WAIT_S), ""
            except FutureTimeoutError:
                future.cancel()
                return None, f"no solver worker took the job within {timeout_s + _QUEUE_WAIT_S:g} s"
        except (ValueError, RuntimeError) as error:  # SolverWorkerError is a RuntimeError
            return None, f"{type(error).__name__}: {error}"

    def submit_live(
        self,
        state: np.ndarray,
        warm_start: Any,
        gross_weight: float,
        touchdown_window: tuple[float, float] | None = None,
    ) -> Future:
        """A live evaluation in the pool (cold check, live priority, 4 × solve_timeout).

        Raises:
            RuntimeError: no pool, or it is closed (the node is being destroyed).
        """
        if self.pool is None:
            raise RuntimeError("live jobs go to the pool only; without one they are solved with solve_live")
        timeout_s = _LIVE_TIMEOUT_FACTOR * self.backend.solve_timeout_s
        return self.pool.submit(
            state, warm_start, priority=PRIORITY_LIVE, timeout_s=timeout_s, cold_check=True,
            reaction_delay_s=self.reaction_delay_s, gross_weight=gross_weight, touchdown_window=touchdown_window,
        )  # fmt: skip

    def submit_footprint_end(self, state: np.ndarray, warm_start: Any, objective: str) -> Future:
        """One end of the live reachable footprint in the pool (live priority, 4 × solve_timeout), for the airframe's
        weight (the NLPs built at start-up), with the node's reaction delay.

        Raises:
            RuntimeError: no pool, or it is closed.
            ValueError: the pool was not built with the footprint, or ``objective`` is not an end's.
        """
        if self.pool is None:
            raise RuntimeError("the live footprint is solved in the pool only")
        timeout_s = _LIVE_TIMEOUT_FACTOR * self.backend.solve_timeout_s
        return self.pool.submit(
            state, warm_start, priority=PRIORITY_LIVE, timeout_s=timeout_s, reaction_delay_s=self.reaction_delay_s,
            objective=objective,
        )  # fmt: skip

    def solve_live(
        self,
        state: np.ndarray,
        warm_start: Any,
        gross_weight: float,
        touchdown_window: tuple[float, float] | None = None,
    ) -> Any:
        """A live evaluation in this process (the cold check, as in the workers); the weight is built if new."""
        plan = self._solve_in_process(
            state, warm_start, gross_weight, touchdown_window, cold_check=True, reaction_delay_s=self.reaction_delay_s
        )
        with self._lock:
            self._built_weights.add(gross_weight)
        return plan

    def fallback_plan(self, state: np.ndarray) -> FallbackPlan:
        """The best available controls without a converged solve
        (:func:`helireach_ros.core.planning.fallback.fallback_plan`)."""
        return fallback_plan(state, self.airframe, self.settings, self.envelope)

    def close(self) -> None:
        """Stops the solver workers (their jobs fail) and the robust verification."""
        if self.pool is not None:
            self.pool.close()
        if self.robust is not None:
            self.robust.close()
