"""Landing plans: solve the reachability NLP for a state, replay it, and say what it means.

``plan_landing(state, airframe, settings)`` is the library's entry point. A plan is ``safe`` only
when the NLP value is ≤ 0 **and** the independent replay (:mod:`helireach_ros.core.verification`) lands
within limits; a plan whose NLP says safe but whose replay does not land is ``unverified``, never
safe. Solvers are built once per (airframe, settings) and cached; a previous plan's solution can
warm-start the next solve.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from helireach_ros.core.airframe import Airframe
from helireach_ros.core.compiled_nlp import CodegenSettings
from helireach_ros.core.model import CONTROL_NAMES, STATE_NAMES, STATE_UNITS, HelicopterState
from helireach_ros.core.settings import PlannerSettings
from helireach_ros.core.transcription.base import SUCCESS_STATUSES, Transcription, terminal_cost
from helireach_ros.core.transcription.paper import PaperTranscription
from helireach_ros.core.transcription.verified import VerifiedTranscription
from helireach_ros.core.units import FT, KT
from helireach_ros.core.verification import ReplaySummary, control_function, replay_plan

__all__ = [
    "STATUSES",
    "LandingPlan",
    "LandingPlanner",
    "SolverStats",
    "WarmStart",
    "get_planner",
    "plan_landing",
]

STATUSES = ("safe", "unsafe", "unverified", "failed")

log = logging.getLogger(__name__)


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
class LandingPlan:
    """A landing plan from one initial state, with its verification.

    Attributes:
        method: ``"verified"`` or ``"paper"``.
        status: ``"safe"`` (NLP value ≤ 0 and the replay lands within limits), ``"unsafe"``
            (value > 0), ``"unverified"`` (value ≤ 0 but the replay does not land within
            limits) or ``"failed"`` (the solver did not converge).
        value: the NLP's optimal J (dimensionless; ≤ 0 means a safe landing is reachable).
        initial_state: (y, v, Ω, h, z, P) at the failure, SI.
        time_to_land: s.
        times: node times, s; ``states`` are the NLP's states there (6 × len(times)).
        control_times, control_values, control_interpolation: the control function (see
            :class:`~helireach_ros.core.transcription.base.DecodedPlan`); :meth:`controls_at` evaluates it.
        replay: the independent ODE check.
        solver: IPOPT statistics.
        nominal_rotor_speed: Ω₀ of the airframe, rad/s (for rotor speed in percent).
        warm_start: this solution, to warm-start a later solve.
    """

    method: str
    status: str
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

    @property
    def safe(self) -> bool:
        """NLP value ≤ 0 and the replay confirmed the landing."""
        return self.status == "safe"

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
            "initial_state": dict(zip(STATE_NAMES, self.initial_state.tolist(), strict=True)),
            "touchdown": {
                "time_s": self.replay.touchdown_time,
                "descent_rate_ft_s": float(touchdown[0] / FT),
                "forward_speed_kt": float(touchdown[1] / KT),
                "rotor_speed_pct": float(100.0 * touchdown[2] / self.nominal_rotor_speed),
                "height_ft": float(touchdown[3] / FT),
            },
            "replay": {
                "value": self.replay.value,
                "lands_within_limits": self.replay.lands_within_limits,
                "ground_contact_time_s": self.replay.ground_contact_time,
                "rotor_speed_within_limits": self.replay.rotor_speed_within_limits,
                "max_deviation": self.replay.max_deviation,
            },
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
    if state[3] < -airframe.limits.ground_clearance:
        raise ValueError(
            f"height {state[3]:.2f} m is below the ground clearance (-{airframe.limits.ground_clearance} m)"
        )
    if state[2] <= 0.0:
        raise ValueError(f"rotor speed must be positive, got {state[2]!r} rad/s")
    if state[5] < 0.0:
        raise ValueError(f"engine power must be >= 0, got {state[5]!r} W")


class LandingPlanner:
    """Owns the NLP and solvers for one (airframe, settings); thread-safe, one solve at a time."""

    def __init__(self, airframe: Airframe, settings: PlannerSettings, codegen: CodegenSettings | None = None) -> None:
        self.airframe = airframe
        self.settings = settings
        started = time.perf_counter()
        scheme = VerifiedTranscription if settings.method == "verified" else PaperTranscription
        self.transcription: Transcription = scheme(airframe, settings, codegen)
        self.build_time_s = time.perf_counter() - started
        self._lock = threading.Lock()
        log.info("landing NLP (%s) built in %.2f s on %s", settings.method, self.build_time_s, self.nlp_functions)

    @property
    def nlp_functions(self) -> str:
        """Which NLP functions the solvers use: compiled (the library's path) or plain, and why."""
        return self.transcription.nlp_functions

    def plan(self, state: HelicopterState | np.ndarray, warm_start: WarmStart | None = None) -> LandingPlan:
        """Solves, replays and classifies a landing from ``state``.

        Args:
            state: the state at the failure.
            warm_start: a previous plan's :attr:`LandingPlan.warm_start` (same airframe/settings).

        Raises:
            ValueError: for a non-finite or non-physical state, or a warm start of another NLP.
        """
        initial = state.as_array() if isinstance(state, HelicopterState) else np.asarray(state, dtype=float)
        initial = initial.reshape(-1)
        _validate_state(initial, self.airframe)
        transcription = self.transcription
        if warm_start is not None and warm_start.primal.shape != transcription.lbx.shape:
            raise ValueError("warm start comes from another NLP (different method or resolution)")
        arguments: dict[str, Any] = {
            "p": initial,
            "lbx": transcription.lbx,
            "ubx": transcription.ubx,
            "lbg": transcription.lbg,
            "ubg": transcription.ubg,
        }
        if warm_start is None:
            solver = transcription.cold_solver
            arguments["x0"] = transcription.initial_guess(initial)
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
        decoded = transcription.decode(primal, initial)
        solver_stats = SolverStats(
            status=str(stats.get("return_status", "unknown")),
            success=str(stats.get("return_status")) in SUCCESS_STATUSES,
            iterations=int(stats.get("iter_count", -1)),
            solve_time_ms=elapsed_ms,
            warm_started=warm_start is not None,
        )
        value = float(terminal_cost(self.airframe, decoded.node_states[:, -1]))
        replay = replay_plan(self.airframe, self.settings, initial, decoded)
        if not solver_stats.success:
            status = "failed"
        elif value > 0.0:
            status = "unsafe"
        elif not replay.lands_within_limits:
            status = "unverified"
        else:
            status = "safe"
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
            warm_start=WarmStart(
                primal, np.asarray(result["lam_x"]).reshape(-1), np.asarray(result["lam_g"]).reshape(-1)
            ),
        )


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
) -> LandingPlan:
    """Plans a landing after an engine failure from ``state`` and verifies it by replay.

    Args:
        state: (y, v, Ω, h, z, P) in SI, e.g. from
            :func:`~helireach_ros.core.model.initial_state_after_failure`.
        airframe: the helicopter.
        settings: transcription and solver settings (default: the ``verified`` method).
        warm_start: a previous plan's ``warm_start`` for the same airframe and settings.

    Returns:
        The plan; ``plan.safe`` is True only if the NLP value is ≤ 0 and the replay confirms it.
    """
    return get_planner(airframe, settings or PlannerSettings()).plan(state, warm_start)
