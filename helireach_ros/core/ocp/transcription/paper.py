"""The paper's transcription, reproduced for comparison (Kirchner et al. 2020, §3, eq. 12).

Time-frozen augmented dynamics ẋ = a(s) f(x, u), a ∈ [0, 1] non-increasing; the log transform
s = c log(2 / (1 − τ)) maps s ∈ [0, ∞) onto τ ∈ [−1, 1); one Legendre–Gauss–Radau interval:

.. math:: \\sum_{j=1}^{N+1} D_{ij} x_j = \\frac{c}{1 - \\tau_i} a_i f(x_i, u_i), \\qquad i = 1..N,

with x₁ = x₀ at τ₁ = −1, the N LGR points as collocation points and τ_{N+1} = 1 (s = ∞) as a
non-collocated support point whose state is the frozen terminal state; J is applied to it.

Reading of the paper, stated because the printed indexing does not add up (D is N × (N+1) but G
has N + 1 blocks): we use the consistent LGR scheme of Garg et al. (2010), in which every
collocation point carries a dynamics equation and the quadrature ``x_{N+1} = x₀ + wᵀG`` is implied
(the differential and integral forms are equivalent). The literal reading adds a free u₀ that
enters only the quadrature, which is still more optimistic. Ground and rotor-speed limits (absent
in the paper) hold at the nodes, as in the verified method. The physical time of each node is
the collocated clock ṫ = a, so t* = wᵀ(a c / (1 − τ)) (paper eq. 13).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from helireach_ros.core.ocp.collocation import (
    lagrange_basis_derivatives,
    lagrange_basis_values,
    lgr_points,
    lgr_weights,
)
from helireach_ros.core.ocp.transcription.base import DecodedPlan, Transcription

__all__ = ["PaperTranscription"]


class PaperTranscription(Transcription):
    """Single-interval LGR collocation with time freeze and log time transform (see module docstring)."""

    # One interval of 24-60 LGR points couples every point to every other: no block band. The block LDL^T, made for
    # the banded systems, crashed on these (a segmentation fault in its factorization: 4 of 8 runs of
    # bench/replay_failures.py's variants, always in the paper one; both workers of a paper-method envelope), so
    # IPOPT keeps MUMPS here (docs/decisions/block-ldl.md).
    block_banded_kkt = False

    def _build(self) -> None:
        count = self.settings.paper_points
        scale_c = self.settings.paper_time_scale
        self.tau = lgr_points(count)
        self.weights = lgr_weights(self.tau)
        support = np.concatenate([self.tau, [1.0]])
        self.differentiation = lagrange_basis_derivatives(support, self.tau)
        self.time_derivative = scale_c / (1.0 - self.tau)  # ds/dτ at the collocation points
        self.curve_basis = lagrange_basis_values(support, np.linspace(-1.0, 1.0, 241))

        decision = ca.SX.sym("w", 1 + 3 * count + 6 * count)
        self.decision = decision
        slack = decision[0]
        controls = ca.reshape(decision[1 : 1 + 2 * count], 2, count)
        freeze = decision[1 + 2 * count : 1 + 3 * count]
        states = ca.reshape(decision[1 + 3 * count :], 6, count)  # x_2 .. x_{N+1}

        state_scale = ca.DM(self.state_scale)
        physical_states = ca.horzcat(self.initial_state, states * ca.repmat(state_scale, 1, count))
        physical_controls = controls * ca.repmat(ca.DM(self.control_scale), 1, count)
        derivatives = self.dynamics.map(count)(physical_states[:, :count], physical_controls, self.disturbance)

        residuals = []
        for i in range(count):
            slope = physical_states @ ca.DM(self.differentiation[i])
            rate = float(self.time_derivative[i]) * freeze[i]
            residuals.append((slope - rate * derivatives[:, i]) / state_scale)
        monotone = freeze[1:] - freeze[:-1]

        self.objective = slack + self.settings.smoothness_weight * self.smoothness(controls)
        self.constraints = ca.vertcat(*residuals, monotone, self.epigraph(slack, states[:, -1]))
        self.lbg = np.concatenate([np.zeros(6 * count), np.full(count - 1 + 6, -np.inf)])
        self.ubg = np.zeros(6 * count + count - 1 + 6)
        control_low, control_high = self.scaled_control_bounds(count)
        state_low, state_high = self.scaled_state_bounds(count)
        self.lbx = np.concatenate([[-10.0], control_low, np.zeros(count), state_low])
        self.ubx = np.concatenate([[1e3], control_high, np.ones(count), state_high])

    def _node_times(self, freeze: np.ndarray) -> np.ndarray:
        """Physical times of x_1..x_{N+1}: the collocated clock dt/dτ = a c / (1 − τ), t(−1) = 0."""
        rates = freeze * self.time_derivative
        times = np.linalg.solve(self.differentiation[:, 1:], rates)
        # The clock polynomial can dip by round-off where a = 0; physical time never runs backwards.
        return np.maximum.accumulate(np.maximum(np.concatenate([[0.0], times]), 0.0))

    def initial_guess(self, initial_state: np.ndarray) -> np.ndarray:
        count = self.settings.paper_points
        landing_time = self.guess_landing_time(initial_state)
        stretched = self.settings.paper_time_scale * np.log(2.0 / (1.0 - self.tau))
        freeze = np.where(stretched <= landing_time, 1.0, 0.0)
        freeze[0] = 1.0
        times = np.minimum(np.concatenate([stretched[1:], [np.inf]]), landing_time)
        states = self.guess_states(initial_state, times, landing_time)
        controls = np.tile([[self.hover_thrust_coefficient], [0.0]], (1, count))
        return np.concatenate(
            [
                [0.0],
                (controls / self.control_scale[:, None]).reshape(-1, order="F"),
                freeze,
                (states / self.state_scale[:, None]).reshape(-1, order="F"),
            ]
        )

    def decode(self, solution: np.ndarray, initial_state: np.ndarray) -> DecodedPlan:
        count = self.settings.paper_points
        controls = solution[1 : 1 + 2 * count].reshape(2, count, order="F") * self.control_scale[:, None]
        freeze = np.clip(solution[1 + 2 * count : 1 + 3 * count], 0.0, 1.0)
        states = solution[1 + 3 * count :].reshape(6, count, order="F") * self.state_scale[:, None]
        node_times = self._node_times(freeze)
        node_states = np.column_stack([np.asarray(initial_state, dtype=float)[:6], states])
        return DecodedPlan(
            float(node_times[-1]),
            node_times,
            node_states,
            node_times[:count],
            controls,
            "linear",
            self.curve_basis @ node_times,
            node_states @ self.curve_basis.T,
        )
