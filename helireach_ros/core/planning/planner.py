"""Landing plans: solve the reachability NLP for a state, replay it, and say what it means.

``plan_landing(state, airframe, settings)`` is the library's entry point. A plan is ``safe`` only
when the NLP value is ≤ 0 **and** the independent replay (:mod:`helireach_ros.core.evidence.replay`) lands
within limits; a plan whose NLP says safe but whose replay does not land is ``unverified``, never
safe. Solvers are built once per (airframe, settings) and cached; a previous plan's solution can
warm-start the next solve.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.model import (
    CONTROL_NAMES,
    DISTURBANCE_NAMES,
    NO_DISTURBANCE,
    STATE_NAMES,
    STATE_UNITS,
    HelicopterState,
    trim_controls,
)
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.evidence.plan_verdict import PlanStatus
from helireach_ros.core.evidence.replay import (
    ReplaySummary,
    control_function,
    not_replayed,
    replay_plan,
    segment_integrator,
    segment_parameters,
)
from helireach_ros.core.ocp.compiled_nlp import CodegenSettings
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.ocp.transcription.base import (
    DISTANCE_SCALE,
    SUCCESS_STATUSES,
    DecodedPlan,
    Transcription,
    terminal_cost,
)
from helireach_ros.core.ocp.transcription.flyable import FlyableTranscription
from helireach_ros.core.ocp.transcription.paper import PaperTranscription
from helireach_ros.core.ocp.transcription.verified import VerifiedTranscription
from helireach_ros.core.units import FT, KT

__all__ = [
    "STATUSES",
    "ControlFunctionWarmStart",
    "LandingPlan",
    "LandingPlanner",
    "SolverStats",
    "WarmStart",
    "get_planner",
    "plan_landing",
]

STATUSES = tuple(PlanStatus)
TRANSCRIPTIONS: dict[str, type[Transcription]] = {
    "flyable": FlyableTranscription,
    "verified": VerifiedTranscription,
    "paper": PaperTranscription,
}
# Solver statuses of plans decided without the NLP: the reaction delay alone (the delay segment is the plan, the
# replay judges it; with the flyable rule, the held controls fly on to the ground), or a flyable plan's ground
# contact at the failure itself (below the commit height the path may not climb, so a state on the ground and not
# climbing touches down as it is; decided so only when that state is outside the touchdown limits).
GROUND_DURING_DELAY = "ground contact during the reaction delay"
ROTOR_LIMIT_DURING_DELAY = "rotor speed outside its limits during the reaction delay"
GROUND_AT_FAILURE = "ground contact at the failure, outside the touchdown limits"
DECIDED_BY_DELAY = (GROUND_DURING_DELAY, ROTOR_LIMIT_DURING_DELAY)
DECIDED_WITHOUT_NLP = (*DECIDED_BY_DELAY, GROUND_AT_FAILURE)

log = logging.getLogger(__name__)
_DELAY_SAMPLES = 20  # states checked along the reaction-delay segment (ground, rotor limits)


@dataclass(frozen=True)
class SolverStats:
    """What IPOPT reported: status text, success, iterations, wall time, whether warm-started."""

    status: str
    success: bool
    iterations: int
    solve_time_ms: float
    warm_started: bool


@dataclass(frozen=True)
class WarmStart:
    """A solution of the same NLP (same airframe and settings) to start the next solve from."""

    primal: np.ndarray
    bound_multipliers: np.ndarray
    constraint_multipliers: np.ndarray


@dataclass(frozen=True)
class ControlFunctionWarmStart:
    """A stored plan's control function to start the next solve from, when its NLP solution was not kept: the
    planner flies it from the stored plan's own start to rebuild that plan's primal point (multipliers zero),
    as close to the stored solution as the stored solution itself is to the new problem.

    Attributes:
        initial_state: the stored plan's state at its start (6, SI).
        control_times: breakpoints from 0 to the landing time, s (including any reaction-delay segment).
        control_values: 2 × n, as :class:`~helireach_ros.core.ocp.transcription.base.DecodedPlan` holds them.
        reaction_delay_s: the stored plan's delay segment at its start, s (flown, then stripped).
    """

    initial_state: np.ndarray
    control_times: np.ndarray
    control_values: np.ndarray
    reaction_delay_s: float = 0.0


@dataclass(frozen=True)
class LandingPlan:
    """A landing plan from one initial state, with its verification.

    Attributes:
        method: ``"flyable"``, ``"verified"`` or ``"paper"``.
        status: ``"safe"`` (NLP value ≤ 0 and the replay lands within limits), ``"unsafe"``
            (value > 0), ``"unverified"`` (value ≤ 0 but the replay does not land within
            limits) or ``"failed"`` (the solver did not converge).
        value: the NLP's optimal J (dimensionless; ≤ 0 means a safe landing is reachable).
        initial_state: (y, v, Ω, h, z, P) at the failure, SI.
        time_to_land: s.
        times: node times, s; ``states`` are the NLP's states there (6 × len(times)).
        control_times, control_values, control_interpolation: the control function (see
            :class:`~helireach_ros.core.ocp.transcription.base.DecodedPlan`); :meth:`controls_at` evaluates it.
        replay: the independent ODE check.
        solver: IPOPT statistics.
        nominal_rotor_speed: Ω₀ of the airframe, rad/s (for rotor speed in percent).
        warm_start: this solution, to warm-start a later solve.
        initial_control: (C_T, θ) flown at the plan's start (the flyable plan's controls start there).
        reaction_delay_s: s at the start during which ``initial_control`` is held before the NLP's plan takes
            over (part of ``times``, the control function and the replay).
        disturbance: the disturbance accelerations (d_y, d_v, d_Ω) the plan and its replay were made with
            (:func:`~helireach_ros.core.aircraft.model.disturbed_dynamics_function`; zero: the model as it is).
        touchdown_window: the landing site (start, end; m of touchdown distance from the initial state) the plan
            was made for (the ``site`` objective): safe only if the replayed touchdown lies inside it. None: anywhere.
        headwind: m/s, the airframe's (the forward speeds are airspeeds; the touchdown is judged over the ground).
    """

    method: str
    status: PlanStatus
    value: float
    initial_state: np.ndarray
    time_to_land: float
    times: np.ndarray
    states: np.ndarray
    control_times: np.ndarray
    control_values: np.ndarray
    control_interpolation: str
    curve_times: np.ndarray
    curve_states: np.ndarray
    replay: ReplaySummary
    solver: SolverStats
    nominal_rotor_speed: float
    warm_start: WarmStart = field(repr=False)
    initial_control: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    reaction_delay_s: float = 0.0
    disturbance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    touchdown_window: tuple[float, float] | None = None
    headwind: float = 0.0

    def __post_init__(self) -> None:
        # a plan decoded from a worker's bytes carries its status as a plain string: the same status, typed
        object.__setattr__(self, "status", PlanStatus(self.status))

    @property
    def safe(self) -> bool:
        """NLP value ≤ 0 and the replay confirmed the landing."""
        return self.status == PlanStatus.SAFE

    @property
    def verified(self) -> bool:
        """The replay of the plan's controls lands within limits."""
        return self.replay.lands_within_limits

    def controls_at(self, times) -> np.ndarray:
        """The planned (C_T, θ) at the given times, 2 × len(times)."""
        return control_function(self.control_times, self.control_values, self.control_interpolation, times)

    @property
    def controls(self) -> np.ndarray:
        """The planned controls at the node times (2 × len(times))."""
        return self.controls_at(self.times)

    @property
    def touchdown_ground_speed(self) -> float:
        """The replayed touchdown's forward speed over the ground, m/s (the airspeed less the headwind)."""
        return float(self.replay.touchdown_state[StateIndex.FORWARD_SPEED] - self.headwind)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary: the fields of ``helireach plan --json``."""
        touchdown = self.replay.touchdown_state
        return {
            "status": self.status,
            "safe": self.safe,
            "verified": self.verified,
            "method": self.method,
            "value": self.value,
            "time_to_land_s": self.time_to_land,
            "reaction_delay_s": self.reaction_delay_s,
            "initial_state": dict(zip(STATE_NAMES, self.initial_state.tolist(), strict=True)),
            "initial_control": dict(zip(CONTROL_NAMES, self.initial_control.tolist(), strict=True)),
            "touchdown": {
                "time_s": self.replay.touchdown_time,
                "descent_rate_ft_s": float(touchdown[0] / FT),
                "forward_speed_kt": float(touchdown[1] / KT),
                "ground_speed_kt": self.touchdown_ground_speed / KT,
                "rotor_speed_pct": float(100.0 * touchdown[2] / self.nominal_rotor_speed),
                "height_ft": float(touchdown[3] / FT),
            },
            "replay": {
                "value": self.replay.value,
                "lands_within_limits": self.replay.lands_within_limits,
                "ground_contact_time_s": self.replay.ground_contact_time,
                "rotor_speed_within_limits": self.replay.rotor_speed_within_limits,
                "judged_at_contact": self.replay.judged_at_contact,
                "max_deviation": self.replay.max_deviation,
            },
            "flyability": self.replay.flyability.to_dict(),
            "solver": {
                "status": self.solver.status,
                "success": self.solver.success,
                "iterations": self.solver.iterations,
                "solve_time_ms": self.solver.solve_time_ms,
                "warm_started": self.solver.warm_started,
            },
            "trajectory": {
                "t_s": self.times.tolist(),
                "state_names": list(STATE_NAMES),
                "state_units": list(STATE_UNITS),
                "states": self.states.tolist(),
                "control_names": list(CONTROL_NAMES),
                "control_units": ["1", "rad"],
                "controls": self.controls.tolist(),
                "control_t_s": self.control_times.tolist(),
                "control_values": self.control_values.tolist(),
                "control_interpolation": self.control_interpolation,
            },
        }


def _validate_state(state: np.ndarray, airframe: Airframe) -> None:
    if state.shape != (6,):
        raise ValueError(f"a helicopter state has 6 components (y, v, Omega, h, z, P), got shape {state.shape}")
    bad = [name for name, value in zip(STATE_NAMES, state, strict=True) if not np.isfinite(value)]
    if bad:
        raise ValueError(f"state is not finite in: {', '.join(bad)}")
    if state[StateIndex.HEIGHT] < -airframe.limits.ground_clearance:
        raise ValueError(
            f"height {state[StateIndex.HEIGHT]:.2f} m is below the ground clearance "
            f"(-{airframe.limits.ground_clearance} m)"
        )
    if state[StateIndex.ROTOR_SPEED] <= 0.0:
        raise ValueError(f"rotor speed must be positive, got {state[StateIndex.ROTOR_SPEED]!r} rad/s")
    if state[StateIndex.ENGINE_POWER] < 0.0:
        raise ValueError(f"engine power must be >= 0, got {state[StateIndex.ENGINE_POWER]!r} W")


class LandingPlanner:
    """Owns the NLP and solvers for one (airframe, settings); thread-safe, one solve at a time."""

    def __init__(self, airframe: Airframe, settings: PlannerSettings, codegen: CodegenSettings | None = None) -> None:
        # the paper's method reproduces the paper: its scheme and its rotor model, whatever the airframe file says
        self.airframe = airframe.paper_model() if settings.method == "paper" else airframe
        self.settings = settings
        started = time.perf_counter()
        self.transcription: Transcription = TRANSCRIPTIONS[settings.method](self.airframe, settings, codegen)
        self.build_time_s = time.perf_counter() - started
        self._lock = threading.Lock()
        log.info(
            "landing NLP (%s) built in %.2f s on %s, linear solver %s",
            settings.method, self.build_time_s, self.nlp_functions, self.linear_solver,
        )  # fmt: skip

    @property
    def nlp_functions(self) -> str:
        """Which NLP functions the solvers use: compiled (the library's path) or plain, and why."""
        return self.transcription.nlp_functions

    @property
    def linear_solver(self) -> str:
        """IPOPT's linear solver: the block LDL^T (the library's path) or MUMPS, and why."""
        return self.transcription.linear_solver

    def plan(
        self,
        state: HelicopterState | np.ndarray,
        warm_start: WarmStart | ControlFunctionWarmStart | None = None,
        initial_control: np.ndarray | None = None,
        reaction_delay_s: float | None = None,
        disturbance: np.ndarray | None = None,
        *,
        replay_not_safe: bool = True,
        touchdown_window: tuple[float, float] | None = None,
    ) -> LandingPlan:
        """Solves, replays and classifies a landing from ``state``.

        With a reaction delay > 0 the controls stay at ``initial_control`` for the delay (integrated
        as the replay does), the NLP plans from the state that leads to, and the plan carries the delay segment.

        Args:
            state: the state at the failure.
            warm_start: a previous plan's :attr:`LandingPlan.warm_start` (same airframe/settings), or a stored plan's
                control function (:class:`ControlFunctionWarmStart`) that the planner flies to rebuild one.
            initial_control: (C_T, θ) being flown at ``state`` (None: the trim of steady flight at its speed and
                climb rate, :func:`~helireach_ros.core.aircraft.model.trim_controls`, i.e. the flight before a failure).
                Re-plans pass the current plan's control, so the flyable controls stay continuous.
            reaction_delay_s: s the controls stay at ``initial_control`` first (None: ``settings.reaction_delay_s``;
                re-plans during a descent pass 0).
            disturbance: (d_y, d_v, d_Ω) accelerations (m/s², m/s², rad/s²) added to the model's ẏ, v̇, Ω̇ in the
                NLP, the delay segment and the replay: what the closed loop has learnt of the model's error
                (:mod:`helireach_ros.core.estimation.disturbance`). None: the model as it is.
            replay_not_safe: False: a plan the NLP already answers ``failed`` or ``unsafe`` is not replayed (a
                replay cannot make it safe; its :attr:`LandingPlan.replay` is
                :func:`~helireach_ros.core.evidence.replay.not_replayed`). For callers that need only the status,
                such as the envelope; every plan that may be called safe is replayed either way.
            touchdown_window: the landing site, (start, end) m of touchdown distance from ``state`` along the track,
                for the ``site`` objective (required there, refused elsewhere). The NLP holds its touchdown
                ``settings.site_backoff_m`` inside the site (its middle, for a shorter site); the plan is safe only
                if the replayed touchdown lies inside the site's true ends, as strictly as the touchdown limits.

        Raises:
            ValueError: for a non-finite or non-physical state or control, or a warm start of another NLP.
        """
        initial = state.as_array() if isinstance(state, HelicopterState) else np.asarray(state, dtype=float)
        initial = initial.reshape(-1)
        _validate_state(initial, self.airframe)
        control = self._initial_control(initial, initial_control)
        disturbance = _checked_disturbance(disturbance)
        window = self._checked_window(touchdown_window)
        transcription = self.transcription
        stored_controls = warm_start if isinstance(warm_start, ControlFunctionWarmStart) else None
        # a stored control function is rebuilt into a solver warm start below, once the delay has not decided the
        # landing without the NLP
        solver_warm_start = None if isinstance(warm_start, ControlFunctionWarmStart) else warm_start
        if solver_warm_start is not None and (
            solver_warm_start.primal.shape != transcription.lbx.shape
            or solver_warm_start.constraint_multipliers.shape != transcription.lbg.shape
        ):
            raise ValueError("warm start comes from another NLP (different method or resolution)")
        delay = self.settings.reaction_delay_s if reaction_delay_s is None else float(reaction_delay_s)
        if not (np.isfinite(delay) and 0.0 <= delay <= 10.0):
            raise ValueError(f"the reaction delay must lie in [0, 10] s, got {reaction_delay_s!r}")
        if delay > 0.0:
            start, outcome = self._after_delay(initial, control, delay, disturbance)
        else:
            start, outcome = initial, GROUND_AT_FAILURE if self._touches_down_outside_limits(initial) else ""
        if stored_controls is not None and not outcome:
            solver_warm_start = self._rebuilt_warm_start(stored_controls)
        if outcome:
            decoded, solver_stats, warm = self._without_nlp(initial, start, control, delay, outcome, solver_warm_start)
        else:
            parameter = np.concatenate([start, control, disturbance])
            # the site's row counts from the NLP's start: after a delay, the distance flown in it is taken off
            flown = float(start[StateIndex.DISTANCE] - initial[StateIndex.DISTANCE])
            decoded, solver_stats, warm = self._solve(parameter, solver_warm_start, window, flown)
            if delay > 0.0:
                decoded = _with_delay(decoded, initial, control, delay)
        decided_by_replay = solver_stats.status in DECIDED_WITHOUT_NLP  # its value is the replay's
        value = math.nan if decided_by_replay else float(terminal_cost(self.airframe, decoded.node_states[:, -1]))
        if not replay_not_safe and not decided_by_replay and (not solver_stats.success or value > 0.0):
            replay = not_replayed(self.settings, initial)
        else:
            replay = replay_plan(self.airframe, self.settings, initial, decoded, disturbance)
        if decided_by_replay:
            value = replay.value
        if not solver_stats.success:
            status = PlanStatus.FAILED
        elif value > 0.0:
            status = PlanStatus.UNSAFE
        elif not replay.lands_within_limits or not _inside(window, replay.touchdown_state, initial):
            status = PlanStatus.UNVERIFIED
        else:
            status = PlanStatus.SAFE
        return LandingPlan(
            method=self.settings.method,
            status=status,
            value=value,
            initial_state=initial,
            time_to_land=decoded.time_to_land,
            times=decoded.node_times,
            states=decoded.node_states,
            control_times=decoded.control_times,
            control_values=decoded.control_values,
            control_interpolation=decoded.control_interpolation,
            curve_times=decoded.curve_times,
            curve_states=decoded.curve_states,
            replay=replay,
            solver=solver_stats,
            nominal_rotor_speed=self.airframe.nominal_rotor_speed,
            warm_start=warm,
            initial_control=control,
            reaction_delay_s=delay,
            disturbance=disturbance,
            touchdown_window=window,
            headwind=self.airframe.headwind,
        )

    def carried_warm_start(
        self, warm_start: WarmStart | ControlFunctionWarmStart | None
    ) -> WarmStart | ControlFunctionWarmStart | None:
        """A warm start of the same landing NLP with or without the landing site's row (the ``site`` objective
        appends one constraint row, its touchdown distance, to the touchdown-cost NLP; the decisions are the same):
        the site row's multiplier dropped, or a zero one appended. Anything else is returned as it is (and
        :meth:`plan` refuses a warm start of another NLP)."""
        if not isinstance(warm_start, WarmStart):
            return warm_start
        rows = self.transcription.lbg.size
        multipliers = warm_start.constraint_multipliers
        if warm_start.primal.shape != self.transcription.lbx.shape or abs(multipliers.size - rows) != 1:
            return warm_start
        carried = multipliers[:rows] if multipliers.size > rows else np.append(multipliers, 0.0)
        return WarmStart(warm_start.primal, warm_start.bound_multipliers, carried)

    def _rebuilt_warm_start(self, stored: ControlFunctionWarmStart) -> WarmStart | None:
        """The stored plan's primal point from its control function, flown from its own start (after its delay
        segment); None (a cold solve) where the transcription cannot rebuild one."""
        times = np.asarray(stored.control_times, dtype=float)
        values = np.asarray(stored.control_values, dtype=float)
        start = np.asarray(stored.initial_state, dtype=float)[:6]
        if stored.reaction_delay_s > 0.0:  # fly the delay segment, then restart the clock where the NLP starts
            held = values[:, 0]
            start = self._after_delay(start, held, stored.reaction_delay_s, np.zeros(3))[0]
            keep = times >= stored.reaction_delay_s - 1e-9
            times = times[keep] - stored.reaction_delay_s
            values = values[:, -times.size :] if values.shape[1] == keep.size else values[:, -(times.size - 1) :]
        primal = self.transcription.primal_from_controls(start, times, values)
        if primal is None:
            return None
        return WarmStart(primal, np.zeros_like(primal), np.zeros_like(self.transcription.lbg))

    def _initial_control(self, state: np.ndarray, initial_control: np.ndarray | None) -> np.ndarray:
        if initial_control is None:
            return trim_controls(self.airframe, state)
        control = np.asarray(initial_control, dtype=float).reshape(-1)
        if control.shape != (2,) or not np.all(np.isfinite(control)):
            raise ValueError(f"the initial control is (C_T, theta), finite; got {initial_control!r}")
        return control

    def _touches_down_outside_limits(self, state: np.ndarray) -> bool:
        """A flyable plan from ``state`` meets the ground at once, outside the touchdown limits: the state is at
        the ground (h ≤ −ground clearance), not climbing (below the commit height the plan may not climb) and its
        landing cost J > 0. The NLP has nothing to plan there (it spent up to its iteration limit on such
        states, e.g. 300 iterations at h = 0 in the descending slices of the envelope); the replay judges it."""
        return bool(
            self.settings.method == "flyable"
            and state[StateIndex.HEIGHT] <= -self.airframe.limits.ground_clearance
            and state[StateIndex.DESCENT_RATE] >= 0.0
            and terminal_cost(self.airframe, state) > 0.0
        )

    def _after_delay(
        self, state: np.ndarray, control: np.ndarray, delay: float, disturbance: np.ndarray
    ) -> tuple[np.ndarray, str]:
        """The state after ``delay`` s of constant ``control`` (the replay's integrator, so both agree), and
        ``""`` or the :data:`DECIDED_BY_DELAY` status when the delay alone decides the landing."""
        settings, limits = self.settings, self.airframe.limits
        integrator = segment_integrator(self.airframe, _DELAY_SAMPLES, settings.replay_relative_tolerance)
        try:
            samples = np.asarray(integrator(x0=state, p=segment_parameters(control, control, delay, disturbance))["xf"])
        except RuntimeError as error:
            raise ValueError(f"the reaction-delay segment cannot be integrated: {error}") from None
        end = samples[:, -1].copy()
        end[5] = max(float(end[5]), 0.0)
        omega0 = self.airframe.nominal_rotor_speed
        if np.any(samples[3] < -limits.ground_clearance):
            return end, GROUND_DURING_DELAY
        if np.any(samples[2] < limits.min_rotor_speed_ratio * omega0) or np.any(
            samples[2] > limits.max_rotor_speed_ratio * omega0
        ):
            return end, ROTOR_LIMIT_DURING_DELAY
        return end, ""

    def _checked_window(self, window: tuple[float, float] | None) -> tuple[float, float] | None:
        """A landing site for the ``site`` objective (required there, refused elsewhere), as finite floats."""
        site_objective = self.settings.objective == "site"
        if window is None:
            if site_objective:
                raise ValueError("the site objective needs a touchdown_window (start, end) in m")
            return None
        if not site_objective:
            raise ValueError(f"a touchdown_window needs the site objective, not {self.settings.objective!r}")
        start, end = (float(value) for value in window)
        if not (math.isfinite(start) and math.isfinite(end) and start <= end):
            raise ValueError(f"a touchdown window is (start, end) with start <= end, finite; got {window!r}")
        return start, end

    def _solve(
        self,
        parameter: np.ndarray,
        warm_start: WarmStart | None,
        window: tuple[float, float] | None = None,
        flown_m: float = 0.0,
    ) -> tuple[DecodedPlan, SolverStats, WarmStart]:
        transcription = self.transcription
        lbg, ubg = transcription.lbg, transcription.ubg
        if window is not None and transcription.site_row is not None:
            backoff = min(self.settings.site_backoff_m, 0.5 * (window[1] - window[0]))
            lbg, ubg = lbg.copy(), ubg.copy()
            lbg[transcription.site_row] = (window[0] + backoff - flown_m) / DISTANCE_SCALE
            ubg[transcription.site_row] = (window[1] - backoff - flown_m) / DISTANCE_SCALE
        lbx, ubx = transcription.variable_bounds(parameter)
        arguments: dict[str, Any] = {
            "p": parameter,
            "lbx": lbx,
            "ubx": ubx,
            "lbg": lbg,
            "ubg": ubg,
        }
        if warm_start is None:
            solver = transcription.cold_solver
            arguments["x0"] = transcription.initial_guess(parameter)
        else:
            solver = transcription.warm_solver
            arguments["x0"] = warm_start.primal
            arguments["lam_x0"] = warm_start.bound_multipliers
            arguments["lam_g0"] = warm_start.constraint_multipliers
        with self._lock:
            started = time.perf_counter()
            result = solver(**arguments)
            elapsed_ms = 1e3 * (time.perf_counter() - started)
            stats = solver.stats()
        primal = np.asarray(result["x"]).reshape(-1)
        solver_stats = SolverStats(
            status=str(stats.get("return_status", "unknown")),
            success=str(stats.get("return_status")) in SUCCESS_STATUSES,
            iterations=int(stats.get("iter_count", -1)),
            solve_time_ms=elapsed_ms,
            warm_started=warm_start is not None,
        )
        warm = WarmStart(primal, np.asarray(result["lam_x"]).reshape(-1), np.asarray(result["lam_g"]).reshape(-1))
        return transcription.decode(primal, parameter), solver_stats, warm

    def _without_nlp(
        self,
        initial: np.ndarray,
        end: np.ndarray,
        control: np.ndarray,
        delay: float,
        outcome: str,
        warm_start: WarmStart | None,
    ) -> tuple[DecodedPlan, SolverStats, WarmStart]:
        """The delay or the ground decides (``outcome``): the plan is the delay segment (none without a delay), the
        replay judges it."""
        transcription = self.transcription
        times = np.array([0.0, delay])
        states = np.column_stack([initial, end])
        controls = np.column_stack([control, control])
        decoded = DecodedPlan(delay, times, states, times, controls, "linear", times, states)
        stats = SolverStats(outcome, True, 0, 0.0, False)
        if warm_start is None:  # a valid warm start of this NLP, for a caller that chains solves
            guess = transcription.initial_guess(np.concatenate([initial, control, NO_DISTURBANCE]))
            warm_start = WarmStart(guess, np.zeros_like(guess), np.zeros_like(transcription.lbg))
        return decoded, stats, warm_start


MAX_DISTURBANCE = np.array([5.0, 5.0, 10.0])
"""Largest |d| the planner accepts per component (m/s², m/s², rad/s²): half a g, and the rotor's whole
speed range in ~3 s; anything larger is not a model error but a broken estimate."""


def _checked_disturbance(disturbance: np.ndarray | None) -> np.ndarray:
    if disturbance is None:
        return np.zeros(3)
    values = np.asarray(disturbance, dtype=float).reshape(-1)
    if values.shape != (3,) or not np.all(np.isfinite(values)) or np.any(np.abs(values) > MAX_DISTURBANCE):
        names = ", ".join(DISTURBANCE_NAMES)
        bounds = MAX_DISTURBANCE.tolist()
        raise ValueError(f"the disturbance is ({names}), finite, within ±{bounds}; got {disturbance!r}")
    return values


def _with_delay(plan: DecodedPlan, initial: np.ndarray, control: np.ndarray, delay: float) -> DecodedPlan:
    """The NLP's plan (from the state after the delay) preceded by the delay segment of constant ``control``."""
    # Zero-order hold: ``control`` on [0, delay]. Linear: the NLP's first breakpoint is ``control`` too, so the
    # function is constant over the delay.
    control_times = np.concatenate([[0.0], plan.control_times + delay])
    return DecodedPlan(
        time_to_land=plan.time_to_land + delay,
        node_times=np.concatenate([[0.0], plan.node_times + delay]),
        node_states=np.column_stack([initial, plan.node_states]),
        control_times=control_times,
        control_values=np.column_stack([control, plan.control_values]),
        control_interpolation=plan.control_interpolation,
        curve_times=np.concatenate([[0.0], plan.curve_times + delay]),
        curve_states=np.column_stack([initial, plan.curve_states]),
    )


def _inside(window: tuple[float, float] | None, touchdown: np.ndarray, initial: np.ndarray) -> bool:
    """Whether a replayed touchdown lies inside a landing site (always, without one)."""
    if window is None:
        return True
    distance = float(touchdown[StateIndex.DISTANCE] - initial[StateIndex.DISTANCE])
    return window[0] <= distance <= window[1]


def get_planner(
    airframe: Airframe, settings: PlannerSettings, codegen: CodegenSettings | None = None
) -> LandingPlanner:
    """The cached planner for an (airframe, settings) pair: the NLP is built once per process.

    ``codegen`` (performance only) defaults to :meth:`CodegenSettings.from_environment`: compiled NLP
    functions when the cache holds them, otherwise the plain ones.
    """
    return _cached_planner(airframe, settings, codegen or CodegenSettings.from_environment())


@lru_cache(maxsize=16)
def _cached_planner(airframe: Airframe, settings: PlannerSettings, codegen: CodegenSettings) -> LandingPlanner:
    return LandingPlanner(airframe, settings, codegen)


def plan_landing(
    state: HelicopterState | np.ndarray,
    airframe: Airframe,
    settings: PlannerSettings | None = None,
    warm_start: WarmStart | None = None,
    initial_control: np.ndarray | None = None,
) -> LandingPlan:
    """Plans a landing after an engine failure from ``state`` and verifies it by replay.

    Args:
        state: (y, v, Ω, h, z, P) in SI, e.g. from
            :func:`~helireach_ros.core.aircraft.model.initial_state_after_failure`.
        airframe: the helicopter.
        settings: transcription and solver settings (default: :class:`PlannerSettings`, the ``flyable`` method).
        warm_start: a previous plan's ``warm_start`` for the same airframe and settings.
        initial_control: (C_T, θ) flown at ``state`` (None: the trim of steady flight there).

    Returns:
        The plan; ``plan.safe`` is True only if the NLP value is ≤ 0 and the replay confirms it.
    """
    return get_planner(airframe, settings or PlannerSettings()).plan(state, warm_start, initial_control)
