"""The default ("verified") transcription: free final time, multi-interval Radau, physical time.

The landing time T is a decision variable; [0, T] is split into K intervals whose lengths shrink
geometrically towards touchdown (ratio ``final_interval_ratio`` last/first), so the flare — where
the paper's single-interval log-time scheme is least accurate — gets the finest mesh. In each
interval the state is a degree-d polynomial through the interval start and d Radau IIA points, the
control is constant (what the replay integrates exactly), and

.. math:: \\sum_{j=0}^{d} C_{ij} x_{k,j} = h_k f(x_{k,i}, u_k), \\qquad i = 1..d,

with :math:`C_{ij} = L_j'(\\tau_i)` on [0, 1]. Minimising J(x(T)) over T is the BRT value of the
paper's time-freeze formulation (freezing after touchdown is the same as stopping at T).
Ground and rotor-speed limits hold at every collocation point (simple variable bounds).

**Closed-form states** (``closed_form_states``, the default). The distance z and the engine power P feed
nothing but Ω̇ (P), and their ODEs are linear: ż = v, Ṗ = −P/τ. Their collocation equations are then solved
in closed form, per interval with :math:`C = [c_0 \\; C_1]`,

.. math:: z_k = C_1^{-1} (h_k v_k - c_0 z_{k,0}), \\qquad P_k = -(C_1 + \\tfrac{h_k}{\\tau} I)^{-1} c_0 P_{k,0},

(the stage values of interval k), so only (y, v, Ω, h) are decision variables. The solution is the one the
six-state NLP has (its z and P equations hold exactly), with a third fewer variables and equations, and
without the six-state NLP's degenerate P ≥ 0 bound when the engine has no power left (P ≡ 0).
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np

from helireach_ros.core.aircraft.model import disturbed_dynamics_function
from helireach_ros.core.ocp.collocation import lagrange_basis_derivatives, lagrange_basis_values, radau_iia_points
from helireach_ros.core.ocp.transcription.base import DecodedPlan, Transcription, terminal_cost

__all__ = ["VerifiedTranscription", "interval_fractions"]

_TIME_SCALE = 10.0  # s; T is optimised as T / 10
_DECIDED_ROWS = (0, 1, 2, 3)  # y, v, Ω, h: the decision states when z and P are in closed form
_CURVE_SAMPLES = 8  # polynomial samples per interval for figures


def interval_fractions(count: int, final_ratio: float) -> np.ndarray:
    """Interval lengths as fractions of T, geometric with last/first = ``final_ratio``; sums to 1."""
    if count == 1:
        return np.ones(1)
    lengths = final_ratio ** (np.arange(count) / (count - 1))
    return lengths / lengths.sum()


class VerifiedTranscription(Transcription):
    """Free-final-time multi-interval Radau collocation (see the module docstring)."""

    def _build(self) -> None:
        settings = self.settings
        intervals, degree = settings.intervals, settings.degree
        self._build_mesh()
        decision = ca.SX.sym("w", 2 + 2 * intervals + len(self.state_rows) * self.n_states)
        self.decision = decision
        time_scaled, slack = decision[0], decision[1]
        controls = ca.reshape(decision[2 : 2 + 2 * intervals], 2, intervals)
        states = ca.reshape(decision[2 + 2 * intervals :], len(self.state_rows), self.n_states)
        landing_time = time_scaled * _TIME_SCALE

        physical_states = self.point_states(states, landing_time, self.initial_state)
        physical_controls = controls * ca.repmat(ca.DM(self.control_scale), 1, intervals)
        control_at_point = ca.repmat(physical_controls, degree, 1)
        control_at_point = ca.reshape(control_at_point, 2, self.n_states)
        residuals = self.collocation_residuals(physical_states, control_at_point, landing_time)
        terminal_scaled = states[:, -1]

        self.objective = slack + settings.smoothness_weight * self.smoothness(controls)
        self.constraints = ca.vertcat(residuals, self.epigraph(slack, terminal_scaled))
        n_equalities = residuals.numel()
        self.lbg = np.concatenate([np.zeros(n_equalities), np.full(6, -np.inf)])
        self.ubg = np.zeros(n_equalities + 6)

        state_low, state_high = self.scaled_state_bounds(self.n_states, self.state_rows)
        control_low, control_high = self.scaled_control_bounds(intervals)
        self.lbx = np.concatenate([[settings.min_time_to_land / _TIME_SCALE, -10.0], control_low, state_low])
        self.ubx = np.concatenate([[settings.max_time_to_land / _TIME_SCALE, 1e3], control_high, state_high])

    def _build_mesh(self) -> None:
        """The geometric interval mesh, the Radau IIA points and the matrices on them."""
        settings = self.settings
        self.fractions = interval_fractions(settings.intervals, settings.final_interval_ratio)
        self.interval_starts = np.concatenate([[0.0], np.cumsum(self.fractions)[:-1]])
        self.radau = radau_iia_points(settings.degree)
        support = np.concatenate([[0.0], self.radau])
        self.collocation_matrix = lagrange_basis_derivatives(support, self.radau)
        self.curve_points = np.linspace(0.0, 1.0, _CURVE_SAMPLES + 1)[1:]
        self.curve_basis = lagrange_basis_values(support, self.curve_points)
        self.n_states = settings.intervals * settings.degree
        self.state_rows = _DECIDED_ROWS if settings.closed_form_states else tuple(range(6))
        self.closed_form = self._closed_form_function() if len(self.state_rows) < 6 else None

    def _closed_form_function(self) -> ca.Function:
        """(T, x₀, v at the points) → (z, P at the points): their collocation solutions (module docstring)."""
        degree = self.settings.degree
        start_column = ca.DM(self.collocation_matrix[:, 0])
        stage_matrix = self.collocation_matrix[:, 1:]
        landing_time, initial = ca.SX.sym("T"), ca.SX.sym("x0", 6)
        speeds = ca.SX.sym("v", 1, self.n_states)
        distance_start, power_start = initial[4], initial[5]
        distances, powers = [], []
        for k in range(self.settings.intervals):
            step = landing_time * float(self.fractions[k])
            stage_speeds = speeds[0, k * degree : (k + 1) * degree].T
            distance = ca.DM(np.linalg.inv(stage_matrix)) @ (step * stage_speeds - start_column * distance_start)
            decay = ca.DM(stage_matrix) + step / self.airframe.engine_time_constant * ca.DM.eye(degree)
            power = ca.solve(decay, -start_column * power_start)
            distances.append(distance.T)
            powers.append(power.T)
            distance_start, power_start = distance[-1], power[-1]
        return ca.Function(
            "closed_form_states", [landing_time, initial, speeds], [ca.horzcat(*distances), ca.horzcat(*powers)]
        )

    def point_states(self, decided, landing_time, initial):
        """The six physical states at the points from the decided ones (scaled, ``state_rows`` of them) and the
        initial state: z and P from :attr:`closed_form` (None when all six are decided). SX in the NLP, numpy
        when decoding."""
        rows = list(self.state_rows)
        symbolic = isinstance(decided, ca.SX)
        scale = self.state_scale[rows][:, None]
        physical = decided * ca.repmat(ca.DM(scale), 1, self.n_states) if symbolic else np.asarray(decided) * scale
        if len(rows) == 6:
            return physical
        headwind = self.airframe.headwind
        ground_speeds = physical[1, :] - headwind if headwind else physical[1, :]  # calm: the expression as before
        distance, power = self.closed_form(landing_time, initial, ground_speeds)
        if symbolic:
            return ca.vertcat(physical, distance, power)
        return np.vstack([physical, np.asarray(distance), np.asarray(power)])

    def state_index(self, point: int, row: int) -> int:
        """Index of state ``row`` at collocation point ``point`` among the decided states."""
        return point * len(self.state_rows) + self.state_rows.index(row)

    def collocation_residuals(self, physical_states, control_at_point, landing_time) -> ca.SX:
        """The scaled collocation equations of the decided states (``state_rows``, per point)."""
        degree = self.settings.degree
        state_scale = ca.DM(self.state_scale)
        derivatives = self.dynamics.map(self.n_states)(physical_states, control_at_point, self.disturbance)
        residuals = []
        previous_end = self.initial_state
        for k in range(self.settings.intervals):
            columns = [previous_end] + [physical_states[:, k * degree + i] for i in range(degree)]
            step = landing_time * float(self.fractions[k])
            for i in range(degree):
                slope = sum(float(self.collocation_matrix[i, j]) * columns[j] for j in range(degree + 1))
                residual = (slope - step * derivatives[:, k * degree + i]) / state_scale
                residuals.append(residual[list(self.state_rows)])  # closed-form rows hold exactly
            previous_end = columns[-1]
        return ca.vertcat(*residuals)

    def _point_fractions(self) -> np.ndarray:
        """Times of the collocation points as fractions of T (excluding 0)."""
        return (self.interval_starts[:, None] + self.fractions[:, None] * self.radau[None, :]).reshape(-1)

    def initial_guess(self, initial_state: np.ndarray) -> np.ndarray:
        landing_time = self.guess_landing_time(initial_state)
        times = self._point_fractions() * landing_time
        states = self.guess_states(initial_state, times, landing_time)
        controls = np.tile([[self.hover_thrust_coefficient], [0.0]], (1, self.settings.intervals))
        return np.concatenate(
            [
                [landing_time / _TIME_SCALE, 0.0],
                (controls / self.control_scale[:, None]).reshape(-1, order="F"),
                (states / self.state_scale[:, None])[list(self.state_rows)].reshape(-1, order="F"),
            ]
        )

    @cached_property
    def _interval_integrator(self) -> ca.Function:
        """CVODES over one interval in normalised time σ ∈ [0, 1], the control linear in σ, outputs at the Radau
        points: p = (u_start[2], u_end[2], interval length, d[3])."""
        state, parameters, sigma = ca.SX.sym("x", 6), ca.SX.sym("p", 8), ca.SX.sym("s")
        control = parameters[0:2] + sigma * (parameters[2:4] - parameters[0:2])
        ode = parameters[4] * disturbed_dynamics_function(self.airframe)(state, control, parameters[5:8])
        options = {"reltol": 1e-6, "abstol": 1e-8, "max_num_steps": 20000}
        problem = {"x": state, "p": parameters, "t": sigma, "ode": ode}
        return ca.integrator("warm_start_interval", "cvodes", problem, 0.0, list(self.radau), options)

    def interval_controls(self, control_times: np.ndarray, control_values: np.ndarray) -> np.ndarray:
        """The stored control function as this scheme's control decision (2 × K): one value per interval."""
        return np.asarray(control_values, dtype=float)[:, : self.settings.intervals]

    def primal_from_controls(
        self, initial_state: np.ndarray, control_times: np.ndarray, control_values: np.ndarray
    ) -> np.ndarray | None:
        """The control function flown from its own initial state through the Radau points of the same mesh
        stretched to its landing time (the states the NLP collocated, to the integrator's accuracy); the slack is
        the terminal J. None when the function has another number of intervals or the flight leaves the model."""
        intervals = self.settings.intervals
        control_times = np.asarray(control_times, dtype=float)
        values = np.asarray(control_values, dtype=float)
        if control_times.shape != (intervals + 1,) or not np.all(np.isfinite(values)):
            return None
        landing_time = float(control_times[-1])
        if not self.settings.min_time_to_land <= landing_time <= self.settings.max_time_to_land:
            return None
        decided = self.interval_controls(control_times, values)
        state = np.asarray(initial_state, dtype=float)[:6]
        disturbance = np.zeros(3)
        points = []
        for k in range(intervals):
            start, end = self._interval_ends(values, k)
            step = landing_time * float(self.fractions[k])
            try:
                outputs = np.asarray(self._interval_integrator(x0=state, p=np.concatenate([start, end, [step],
                                                                                         disturbance]))["xf"])
            except RuntimeError:
                return None
            points.append(outputs)
            state = outputs[:, -1]
        states = np.hstack(points)
        if states.shape != (6, self.n_states) or not np.all(np.isfinite(states)):
            return None
        slack = float(terminal_cost(self.airframe, states[:, -1]))
        rows = list(self.state_rows)
        primal = np.concatenate(
            [
                [landing_time / _TIME_SCALE, slack],
                (decided / self.control_scale[:, None]).reshape(-1, order="F"),
                (states[rows] / self.state_scale[rows, None]).reshape(-1, order="F"),
            ]
        )
        return np.clip(primal, self.lbx, self.ubx)

    def _interval_ends(self, values: np.ndarray, interval: int) -> tuple[np.ndarray, np.ndarray]:
        """The control at the start and the end of an interval (constant: zero-order hold)."""
        return values[:, interval], values[:, interval]

    def decode(self, solution: np.ndarray, initial_state: np.ndarray) -> DecodedPlan:
        intervals = self.settings.intervals
        landing_time = float(solution[0]) * _TIME_SCALE
        controls = solution[2 : 2 + 2 * intervals].reshape(2, intervals, order="F") * self.control_scale[:, None]
        states = self.decoded_states(solution, landing_time, initial_state)
        control_times = np.concatenate([self.interval_starts, [1.0]]) * landing_time
        return self.decoded_plan(landing_time, initial_state, states, control_times, controls, "zero_order_hold")

    def decoded_states(self, solution: np.ndarray, landing_time: float, initial_state: np.ndarray) -> np.ndarray:
        """The six physical states at the points (6 × n) of a solution (its states follow its 2 + 2K controls)."""
        decided = solution[2 + 2 * self.settings.intervals :].reshape(len(self.state_rows), self.n_states, order="F")
        return self.point_states(decided, landing_time, np.asarray(initial_state, dtype=float)[:6])

    def decoded_plan(
        self,
        landing_time: float,
        initial_state: np.ndarray,
        states: np.ndarray,
        control_times: np.ndarray,
        controls: np.ndarray,
        interpolation: str,
    ) -> DecodedPlan:
        """A :class:`DecodedPlan` from physical states at the points and a control function."""
        intervals, degree = self.settings.intervals, self.settings.degree
        node_times = np.concatenate([[0.0], self._point_fractions() * landing_time])
        node_states = np.column_stack([np.asarray(initial_state, dtype=float)[:6], states])
        # Each interval's polynomial runs through its start (the previous interval's end) and its d points.
        starts = node_states[:, 0 : self.n_states : degree]
        blocks = np.concatenate([starts[:, :, None], states.reshape(6, intervals, degree)], axis=2)
        curve_states = np.einsum("sj,ikj->iks", self.curve_basis, blocks).reshape(6, -1)
        curve_times = (
            (self.interval_starts[:, None] + self.fractions[:, None] * self.curve_points[None, :]) * landing_time
        ).reshape(-1)
        return DecodedPlan(
            landing_time,
            node_times,
            node_states,
            control_times,
            controls,
            interpolation,
            np.concatenate([[0.0], curve_times]),
            np.column_stack([node_states[:, 0], curve_states]),
        )
