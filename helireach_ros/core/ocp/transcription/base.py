"""What the two landing transcriptions share: scaling, bounds, the epigraph objective, IPOPT.

The reachability value of a state x₀ is the best terminal cost over all admissible controls and
landing times,

.. math:: V(x_0) = \\min_{T \\ge 0,\\ u(\\cdot)} J(x(T)), \\qquad
          J(x) = \\max\\Big(\\frac{|y|}{y_{max}}, \\frac{|v|}{v_{max}}, \\frac{|h|}{h_{tol}}\\Big) - 1,

subject to the dynamics, control limits, the ground (h ≥ −clearance) and rotor-speed limits along
the path. J is the paper's terminal function with each term divided by its limit: the zero level
set — the safe/unsafe boundary — is the paper's, the value is dimensionless, and its minimum −1 is
a touchdown with zero speeds, so minimising J also prefers the gentlest touchdown. The max is
written as an epigraph (a slack above each term). A small control-smoothness term makes the plan
unique among equally good ones; it can only raise the value (a conservative bias).
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import casadi as ca
import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.model import disturbed_dynamics_function, trim_level_flight
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.ocp.block_ldl import linear_solver_options
from helireach_ros.core.ocp.compiled_nlp import CodegenSettings, ipopt_solvers
from helireach_ros.core.ocp.settings import PlannerSettings

__all__ = ["PARAMETER_SIZE", "DecodedPlan", "Transcription", "terminal_cost"]

SUCCESS_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
DISTANCE_SCALE = 100.0  # m: the touchdown distance's unit in the footprint objectives and the site row
PARAMETER_SIZE = 11  # (y, v, Ω, h, z, P) at the start, the controls (C_T, θ) being flown then, the disturbance d


def terminal_cost(airframe: Airframe, state) -> np.ndarray:
    """The normalised landing cost J of a state (≤ 0 is a safe touchdown); numpy, vectorised on columns (a 0-d
    array for one state: ``float()`` it)."""
    limits = airframe.limits
    state = np.asarray(state, dtype=float)
    return np.asarray(
        np.maximum.reduce(
            [
                np.abs(state[StateIndex.DESCENT_RATE]) / limits.max_descent_rate,
                np.abs(state[StateIndex.FORWARD_SPEED] - airframe.headwind) / limits.max_forward_speed,
                np.abs(state[StateIndex.HEIGHT]) / limits.height_tolerance,
            ]
        )
        - 1.0
    )


@dataclass(frozen=True)
class DecodedPlan:
    """An NLP solution in physical units.

    Attributes:
        time_to_land: s.
        node_times: times of the state nodes, s (starting at 0).
        node_states: 6 × len(node_times), SI.
        control_times: breakpoints of the control representation, s.
        control_values: 2 × n: the control on each interval (zero-order hold, n = breakpoints − 1)
            or at each breakpoint (linear, n = breakpoints).
        control_interpolation: ``"zero_order_hold"`` or ``"linear"``.
        curve_times: dense times on the collocation polynomial, s (for figures).
        curve_states: the collocation polynomial there, 6 × len(curve_times).
    """

    time_to_land: float
    node_times: np.ndarray
    node_states: np.ndarray
    control_times: np.ndarray
    control_values: np.ndarray
    control_interpolation: str
    curve_times: np.ndarray
    curve_states: np.ndarray


class Transcription(ABC):
    """A landing NLP built once for an (airframe, settings) pair and solved for many initial states.

    The NLP parameter is the initial state, the control flown then and the disturbance accelerations the
    dynamics carry (:func:`~helireach_ros.core.aircraft.model.disturbed_dynamics_function`; :data:`PARAMETER_SIZE`).
    Subclasses define the decision vector, constraints, cold initial guess and decoding; this class supplies scaling,
    bounds and the IPOPT solvers (on compiled NLP functions when the cache has them,
    :mod:`helireach_ros.core.ocp.compiled_nlp`; ``nlp_functions`` says which; with the block LDL^T as IPOPT's linear
    solver where it can be built, :mod:`helireach_ros.core.ocp.block_ldl`; ``linear_solver`` says which).
    """

    block_banded_kkt: ClassVar[bool] = True
    """Whether the KKT systems are block-banded over collocation intervals, which the block LDL^T is made and
    measured for; a transcription whose are not gets MUMPS."""
    site_row: int | None = None
    """The constraint row of the touchdown distance from the start (/ ``DISTANCE_SCALE`` m), whose bounds are a
    landing site's, given per solve (the ``site`` objective); a row over every interval, so the KKT systems are not
    block-banded and the NLP gets MUMPS."""

    # What a subclass's ``_build`` defines: the NLP and the bounds of its variables and constraints.
    decision: ca.SX
    objective: ca.SX
    constraints: ca.SX
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray

    def __init__(self, airframe: Airframe, settings: PlannerSettings, codegen: CodegenSettings | None = None) -> None:
        self.airframe = airframe
        self.settings = settings
        self.dynamics = disturbed_dynamics_function(airframe)
        hover = trim_level_flight(airframe, 0.0)
        # Scales bring every decision variable to O(1): IPOPT's steps and tolerances are then comparable.
        self.state_scale = np.array([10.0, 30.0, airframe.nominal_rotor_speed, 100.0, 100.0, hover.power])
        self.control_scale = np.array([airframe.max_thrust_coefficient, airframe.limits.max_pitch_angle])
        self.hover_thrust_coefficient = hover.thrust_coefficient
        limits = airframe.limits
        omega0 = airframe.nominal_rotor_speed
        # Tightened by the back-off: the limits hold at the nodes, the replay checks them in between.
        rotor_low = (limits.min_rotor_speed_ratio + settings.rotor_speed_backoff) * omega0
        rotor_high = (limits.max_rotor_speed_ratio - settings.rotor_speed_backoff) * omega0
        self.state_lower = np.array([-60.0, -30.0, rotor_low, -limits.ground_clearance, -1e4, 0.0])
        self.state_upper = np.array([100.0, 120.0, rotor_high, 1e4, 1e5, 1e9])
        self.control_lower = np.array([0.0, -limits.max_pitch_angle])
        self.control_upper = np.array([airframe.max_thrust_coefficient, limits.max_pitch_angle])
        # The NLP parameter: the initial state, the control flown at that moment (only the flyable scheme,
        # whose controls are continuous, uses the control; one parameter layout keeps every caller alike) and
        # the disturbance accelerations (zero: the model as it is).
        self.parameters = ca.SX.sym("p", PARAMETER_SIZE)
        self.initial_state = self.parameters[0:6]
        self.initial_control = self.parameters[6:8]
        self.disturbance = self.parameters[8:11]
        self._build()
        nlp = {"x": self.decision, "p": self.parameters, "f": self.objective, "g": self.constraints}
        base = {
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "print_time": False,
            "ipopt.tol": settings.tolerance,
            "ipopt.max_iter": settings.iteration_limit,
            "ipopt.acceptable_tol": 1e-5,
            "ipopt.acceptable_iter": 5,
            "ipopt.mu_strategy": "adaptive",
        }
        warm = dict(base)
        warm.update(
            {
                "ipopt.warm_start_init_point": "yes",
                "ipopt.warm_start_bound_push": settings.warm_start_bound_push,
                "ipopt.warm_start_mult_bound_push": settings.warm_start_bound_push,
                # only here: a neighbour's solution is interior already; on a cold guess these slow IPOPT down
                "ipopt.bound_push": settings.warm_bound_push,
                "ipopt.bound_frac": settings.warm_bound_push,
                "ipopt.mu_init": 1e-4,
            }
        )
        codegen = codegen or CodegenSettings.from_environment()
        linear_solver, self.linear_solver = linear_solver_options(
            codegen
            if self.block_banded_kkt and self.site_row is None
            else dataclasses.replace(codegen, linear_solver="mumps")
        )
        base.update(linear_solver)
        warm.update(linear_solver)
        solvers, self.nlp_functions = ipopt_solvers(nlp, {"landing_cold": base, "landing_warm": warm}, codegen)
        self.cold_solver, self.warm_solver = solvers["landing_cold"], solvers["landing_warm"]

    # -- to be provided by each scheme -------------------------------------------------------------
    @abstractmethod
    def _build(self) -> None:
        """Sets decision, objective, constraints, lbx/ubx/lbg/ubg (numpy, scaled)."""

    @abstractmethod
    def initial_guess(self, initial_state: np.ndarray) -> np.ndarray:
        """A cold-start decision vector for an initial state."""

    @abstractmethod
    def decode(self, solution: np.ndarray, initial_state: np.ndarray) -> DecodedPlan:
        """The decision vector in physical units."""

    def variable_bounds(self, parameter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The decision vector's bounds (lbx, ubx) for a solve from this parameter (its initial state); the scheme's
        fixed bounds unless it holds some per initial state."""
        return self.lbx, self.ubx

    def primal_from_controls(
        self, initial_state: np.ndarray, control_times: np.ndarray, control_values: np.ndarray
    ) -> np.ndarray | None:
        """A primal point of this NLP from a stored plan's control function (breakpoints from 0 to its landing time,
        values as :class:`DecodedPlan` holds them) flown from that plan's initial state: the stored solution, to
        the integrator's accuracy, when only the control function was kept. None where the scheme cannot rebuild
        one (the caller then solves cold)."""
        return None

    # -- shared pieces ---------------------------------------------------------------------------------
    def epigraph(self, slack, terminal_state_scaled):
        """Constraints ``±term − 1 − slack ≤ 0`` for the three normalised terminal terms."""
        limits = self.airframe.limits
        speed = terminal_state_scaled[1] * self.state_scale[1]
        ground_speed = speed - self.airframe.headwind if self.airframe.headwind else speed  # calm: as before
        terms = [
            terminal_state_scaled[0] * self.state_scale[0] / limits.max_descent_rate,
            ground_speed / limits.max_forward_speed,
            terminal_state_scaled[3] * self.state_scale[3] / limits.height_tolerance,
        ]
        return ca.vertcat(*[sign * term - 1.0 - slack for term in terms for sign in (1.0, -1.0)])

    def smoothness(self, controls_scaled) -> ca.SX:
        """Sum of squared differences of consecutive scaled controls (columns = time)."""
        differences = controls_scaled[:, 1:] - controls_scaled[:, :-1]
        return ca.sumsqr(differences)

    def scaled_state_bounds(self, count: int, rows: tuple[int, ...] = tuple(range(6))) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``count`` consecutive scaled states (column-major, ``rows`` of the six per state)."""
        rows_index = list(rows)
        return (
            np.tile(self.state_lower[rows_index] / self.state_scale[rows_index], count),
            np.tile(self.state_upper[rows_index] / self.state_scale[rows_index], count),
        )

    def scaled_control_bounds(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``count`` consecutive scaled controls."""
        return (
            np.tile(self.control_lower / self.control_scale, count),
            np.tile(self.control_upper / self.control_scale, count),
        )

    def guess_landing_time(self, initial_state: np.ndarray) -> float:
        """A rough landing time for cold starts: a steep autorotation descent plus a flare."""
        height = max(float(initial_state[StateIndex.HEIGHT]), 0.0)
        return float(np.clip(3.0 + height / 15.0, 1.0, 0.8 * self.settings.max_time_to_land))

    def guess_states(self, initial_state: np.ndarray, times: np.ndarray, landing_time: float) -> np.ndarray:
        """A straight-line guess from the initial state to a gentle touchdown (6 × len(times))."""
        fraction = np.clip(times / landing_time, 0.0, 1.0)
        height = max(float(initial_state[StateIndex.HEIGHT]), 0.0)
        speed = float(initial_state[StateIndex.FORWARD_SPEED])
        omega0 = self.airframe.nominal_rotor_speed
        states = np.empty((6, len(times)))
        states[StateIndex.DESCENT_RATE] = height / landing_time * np.sin(math.pi * fraction) * 1.5
        states[StateIndex.FORWARD_SPEED] = speed * (1.0 - fraction)
        states[StateIndex.ROTOR_SPEED] = (
            float(initial_state[StateIndex.ROTOR_SPEED])
            + (omega0 - float(initial_state[StateIndex.ROTOR_SPEED])) * fraction
        )
        states[StateIndex.HEIGHT] = height * (1.0 - fraction)
        states[StateIndex.DISTANCE] = float(initial_state[StateIndex.DISTANCE]) + speed * landing_time * (
            fraction - fraction**2 / 2.0
        )
        states[StateIndex.ENGINE_POWER] = float(initial_state[StateIndex.ENGINE_POWER]) * np.exp(
            -times / self.airframe.engine_time_constant
        )
        return np.clip(states, self.state_lower[:, None], self.state_upper[:, None])
