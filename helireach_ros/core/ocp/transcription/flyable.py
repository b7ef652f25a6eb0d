"""The default ("flyable") transcription: the verified mesh with controls a helicopter can fly.

The verified scheme's plans are optimal to the knife edge of a point-mass model: pitch steps of 18°
between intervals, 40° nose up at touchdown, the collective from zero to its maximum in one step, paths
that pass millimetres above the ground at 100 kt and zoom back up. This scheme keeps the verified
scheme's free final time and geometric Radau mesh (:mod:`~helireach_ros.core.ocp.transcription.verified`)
and changes what a plan may be:

* **Continuous controls.** u = (C_T, θ) is piecewise linear (first-order hold) between the K + 1
  interval breakpoints; u₀ is the NLP parameter's control (what is flown at the plan's start: the
  pre-failure trim, or the current plan's control when re-planning), so a plan never jumps.
  The replay integrates exactly this function.
* **Rate limits.** Per interval, :math:`|u_{k+1} - u_k| \\le \\dot u_{max} h_k` with h_k = T · f_k
  (linear in the decision): |dC_T/dt| ≤ C_T,max / t_travel, |dθ/dt| ≤ θ̇_max, each backed off by
  :data:`RATE_BACKOFF` (IPOPT meets constraints only to its violation tolerance; the replay checks the true
  limits). With a linear control this bounds the rate everywhere, not only at the nodes.
* **Attitude limits.** −θ_up ≤ θ ≤ θ_down along the path (the flare attitude limit instead of the
  paper's ±40°), and the touchdown window −θ_td,up ≤ θ(T) ≤ θ_td,down, tightened by
  :data:`TOUCHDOWN_ATTITUDE_MARGIN` (the replay's contact may come slightly before T, where θ is still
  rotating out of the flare; the replay checks the true window at contact). The control is linear between
  breakpoints, so bounds at the breakpoints hold everywhere.
* **On the ground.** h(T) = 0 exactly (the paper accepts |h| ≤ 1 ft), so the touchdown limits are met
  at contact, with the rotor within its limits until then.
* **No ground skims.** Below the commit height h_c the path may not climb:
  :math:`y_i + M\\,s(h_i - h_c) \\ge 0` at every collocation point, with s the smooth positive part
  (:func:`~helireach_ros.core.aircraft.smooth.smooth_positive`, width 5 cm) and M = 10 s⁻¹: below h_c the descent
  rate is non-negative (to within M·s, < 1.3 cm/s half a metre below h_c); above it, climbing is
  allowed. A skim that dips below h_c and climbs away is infeasible; the replay checks the rule on the
  integrated path.
* **Touchdown rotor limit.** Below h_c (the final flare and cushion) Ω may droop to
  ``touchdown_min_rotor_speed_ratio`` × Ω₀; above it the in-flight limit holds (a smooth step in h that
  reaches the in-flight limit at h_c). Both carry the rotor back-off, which grows from 0 at the plan's
  start to all of it after 1 s: a re-plan from a rotor near its limit (the collective cannot drop at
  once) may still keep it above the limit; a rotor below the limit has no plan. The upper limit's back-off
  (the bound Ω ≤ (max ratio − back-off) Ω₀) starts after the first interval: within it Ω may be up to the
  true limit, so a re-plan from a rotor that a flare has sped up past the NLP's line still has a plan (the
  replay checks the true limit everywhere).

The limits are the airframe's :class:`~helireach_ros.core.aircraft.airframe.FlyabilityLimits`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from helireach_ros.core.aircraft.smooth import smooth_positive
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.ocp.settings import FOOTPRINT_OBJECTIVES
from helireach_ros.core.ocp.transcription.base import DISTANCE_SCALE, DecodedPlan
from helireach_ros.core.ocp.transcription.verified import _TIME_SCALE, VerifiedTranscription

__all__ = ["COMMIT_GAIN", "COMMIT_SMOOTHING", "RATE_BACKOFF", "TOUCHDOWN_ATTITUDE_MARGIN", "FlyableTranscription"]

COMMIT_GAIN = 10.0  # 1/s: M in y + M s(h − h_c) ≥ 0; climbing allowed at M m/s per metre above h_c
COMMIT_SMOOTHING = 0.05  # m: width of the smooth positive part
TOUCHDOWN_ATTITUDE_MARGIN = np.radians(0.5)  # rad the NLP keeps θ(T) inside the touchdown window
RATE_BACKOFF = 0.01  # the NLP plans at 99 % of the rate limits: IPOPT meets constraints to 1e-4, the replay to 1e-6
_BACKOFF_RAMP_S = 1.0  # s over which the rotor back-off grows from 0 to all of it
_ROTOR_STEP_WIDTH = 0.1  # m: width of the step from the in-flight to the touchdown rotor-speed limit


class FlyableTranscription(VerifiedTranscription):
    """Free-final-time Radau collocation with rate-limited continuous controls (see the module docstring)."""

    def _build(self) -> None:
        settings, airframe = self.settings, self.airframe
        flyability = airframe.flyability
        intervals = settings.intervals
        self._build_mesh()
        # u_0 is the parameter's; the decision holds u_1 … u_K
        self.control_lower = np.array([0.0, -flyability.max_nose_up_pitch])
        self.control_upper = np.array([airframe.max_thrust_coefficient, flyability.max_nose_down_pitch])
        decision = ca.SX.sym("w", 2 + 2 * intervals + len(self.state_rows) * self.n_states)
        self.decision = decision
        time_scaled, slack = decision[0], decision[1]
        control_scale = ca.DM(self.control_scale)
        decided = ca.reshape(decision[2 : 2 + 2 * intervals], 2, intervals)
        states = ca.reshape(decision[2 + 2 * intervals :], len(self.state_rows), self.n_states)
        landing_time = time_scaled * _TIME_SCALE

        physical_states = self.point_states(states, landing_time, self.initial_state)
        breakpoints = ca.horzcat(self.initial_control, decided * ca.repmat(control_scale, 1, intervals))
        control_at_point = ca.horzcat(
            *[
                breakpoints[:, k] + float(tau) * (breakpoints[:, k + 1] - breakpoints[:, k])
                for k in range(intervals)
                for tau in self.radau
            ]
        )
        residuals = self.collocation_residuals(physical_states, control_at_point, landing_time)

        rates = (1.0 - RATE_BACKOFF) * ca.DM([airframe.max_thrust_coefficient_rate, flyability.max_pitch_rate])
        rate_rows = []
        for k in range(intervals):
            change = (breakpoints[:, k + 1] - breakpoints[:, k]) / control_scale
            allowed = rates * landing_time * float(self.fractions[k]) / control_scale
            rate_rows += [change - allowed, -change - allowed]
        heights, descent_rates = physical_states[StateIndex.HEIGHT, :], physical_states[StateIndex.DESCENT_RATE, :]
        commit = (
            descent_rates + COMMIT_GAIN * smooth_positive(heights - flyability.commit_height, COMMIT_SMOOTHING)
        ) / self.state_scale[0]
        # Ω ≥ the in-flight limit above the commit height, ≥ the touchdown limit below it (smooth step, fully the
        # in-flight limit from h_c on: 0.5 (1 + tanh 3) = 0.9975 of it, inside the rotor back-off)
        omega0 = airframe.nominal_rotor_speed
        flight_low = airframe.limits.min_rotor_speed_ratio
        touchdown_low = flyability.touchdown_min_rotor_speed_ratio
        step = 0.5 * (1.0 + ca.tanh((heights - flyability.commit_height + 3.0 * _ROTOR_STEP_WIDTH) / _ROTOR_STEP_WIDTH))
        # The back-off (room for the path's overshoot between nodes, where the flare swings Ω) grows from 0 at the
        # plan's start to all of it after _BACKOFF_RAMP_S: a re-plan from a rotor near its limit (the collective
        # cannot drop at once) may still keep it above the limit; below the limit there is no plan.
        point_times = landing_time * ca.DM(self._point_fractions()).T
        backoff_now = settings.rotor_speed_backoff * ca.fmin(point_times / _BACKOFF_RAMP_S, 1.0)
        rotor_margin = (
            physical_states[StateIndex.ROTOR_SPEED, :] / omega0
            - touchdown_low
            - backoff_now
            - (flight_low - touchdown_low) * step
        )
        terminal_scaled = states[:, -1]
        margins = []
        if settings.objective == "reach_avoid":
            # to the true limit in the first interval, the back-off after it: the NLP holds the back-off in the first
            # interval too, except from a rotor above its line (variable_bounds); measured to the true limit, the
            # first interval's margin is never overstated
            ceiling_backoff = np.full(self.n_states, settings.rotor_speed_backoff)
            ceiling_backoff[: settings.degree] = 0.0
            margins = self._path_margins(
                rotor_ratio=physical_states[StateIndex.ROTOR_SPEED, :] / omega0,
                floor=rotor_margin,
                ceiling_backoff=ca.DM(ceiling_backoff).T,
                touchdown_pitch=breakpoints[1, -1],
            )

        scaled_controls = breakpoints / ca.repmat(control_scale, 1, intervals + 1)
        smoothness = settings.smoothness_weight * self.smoothness(scaled_controls)
        # the touchdown distance from the start, in DISTANCE_SCALE units
        touchdown_distance = physical_states[StateIndex.DISTANCE, -1] - self.initial_state[StateIndex.DISTANCE]
        travelled = touchdown_distance / DISTANCE_SCALE
        if settings.objective in FOOTPRINT_OBJECTIVES:  # J ≤ −margin held by the slack's bound
            sign = 1.0 if settings.objective == "nearest_touchdown" else -1.0
            self.objective = sign * travelled + smoothness
        else:
            self.objective = slack + smoothness
        self.constraints = ca.vertcat(
            residuals,
            self.epigraph(slack, terminal_scaled),
            *rate_rows,
            ca.reshape(commit, -1, 1),
            ca.reshape(rotor_margin, -1, 1),
            *[ca.reshape(margin - slack, -1, 1) for margin in margins],
            *([travelled] if settings.objective == "site" else []),
        )
        n_equalities = residuals.numel()
        n_rates = 4 * intervals
        n_margins = sum(margin.numel() for margin in margins)
        self.lbg = np.concatenate([
            np.zeros(n_equalities), np.full(6 + n_rates, -np.inf), np.zeros(2 * self.n_states),
            np.full(n_margins, -np.inf),
        ])  # fmt: skip
        self.ubg = np.concatenate(
            [np.zeros(n_equalities + 6 + n_rates), np.full(2 * self.n_states, np.inf), np.zeros(n_margins)]
        )
        if settings.objective == "site":  # no site until a solve gives one
            self.site_row = self.lbg.size
            self.lbg = np.append(self.lbg, -np.inf)
            self.ubg = np.append(self.ubg, np.inf)

        self.state_lower[2] = touchdown_low * omega0  # the height-dependent limit (and back-off) is the constraint
        state_low, state_high = self.scaled_state_bounds(self.n_states, self.state_rows)
        touchdown_height = self.state_index(self.n_states - 1, 3)
        state_low[touchdown_height] = state_high[touchdown_height] = 0.0  # h(T) = 0: the plan ends on the ground
        if airframe.headwind:  # a contact, not a graze (PlannerSettings.wind_touchdown_min_descent_rate)
            touchdown_descent = self.state_index(self.n_states - 1, StateIndex.DESCENT_RATE)
            state_low[touchdown_descent] = settings.wind_touchdown_min_descent_rate / self.state_scale[0]
        # The upper rotor back-off holds from the start, except for a re-plan from a rotor between the NLP's line
        # and the true limit (a flare speeds it up): that one must bring it inside, and may take the first interval
        # to (variable_bounds). Given to every plan, the first interval's room was what the closed loop flew:
        # re-planned every 0.25 s, it rode the true limit and crossed it with a 5 % model error.
        first_interval = [self.state_index(point, 2) for point in range(settings.degree)]  # Ω in interval 1
        control_low, control_high = self.scaled_control_bounds(intervals)
        # θ(T) inside the window by a margin: the replay's contact can come a little before T, where θ is on
        # its way from the flare attitude (at 20 deg/s, 0.5 deg is 25 ms of margin).
        window_low, window_high = self._touchdown_window()
        control_low[-1] = window_low / self.control_scale[1]
        control_high[-1] = window_high / self.control_scale[1]
        # the slack's bound: free above the terminal terms, or J ≤ −margin itself for the footprint's ends
        slack_high = -settings.footprint_margin if settings.objective in FOOTPRINT_OBJECTIVES else 1e3
        self.lbx = np.concatenate([[settings.min_time_to_land / _TIME_SCALE, -10.0], control_low, state_low])
        self.ubx = np.concatenate([[settings.max_time_to_land / _TIME_SCALE, slack_high], control_high, state_high])
        self._ubx_above_line = self.ubx.copy()
        states_start = self.ubx.size - state_high.size
        self._ubx_above_line[states_start + np.asarray(first_interval)] = (
            airframe.limits.max_rotor_speed_ratio * omega0 / self.state_scale[2]
        )

    def _path_margins(self, *, rotor_ratio, floor, ceiling_backoff, touchdown_pitch) -> list:
        """The reach-avoid value's path and touchdown margins, each 0 at its limit (as the NLP holds it, back-off
        included) and −1 the airframe's :class:`~helireach_ros.core.aircraft.airframe.MarginScales` inside it.

        .. math:: m_{floor} = -\\frac{\\Omega/\\Omega_0 - r_{floor}}{s_{floor}}, \\quad
                  m_{ceiling} = \\frac{\\Omega/\\Omega_0 - r_{ceiling}}{s_{ceiling}}, \\quad
                  m_\\theta = \\frac{|\\theta(T) - \\theta_c| - \\Delta\\theta}{s_\\theta}

        with r the ratios the NLP holds, θ_c and Δθ the centre and half-width of the touchdown window it holds.

        Args:
            rotor_ratio: Ω/Ω₀ at the collocation points.
            floor: Ω/Ω₀ minus the rotor floor the NLP holds there (≥ 0 is feasible).
            ceiling_backoff: the back-off of the rotor ceiling at the points (fraction of Ω₀).
            touchdown_pitch: θ(T), rad.
        """
        scales = self.airframe.margin_scales
        ceiling = self.airframe.limits.max_rotor_speed_ratio
        low, high = self._touchdown_window()
        centre, half = 0.5 * (low + high), 0.5 * (high - low)
        return [
            -floor / scales.rotor_floor,
            (rotor_ratio - (ceiling - ceiling_backoff)) / scales.rotor_ceiling,
            ca.vertcat(
                (touchdown_pitch - centre - half) / scales.touchdown_pitch,
                (centre - touchdown_pitch - half) / scales.touchdown_pitch,
            ),
        ]

    def _touchdown_window(self) -> tuple[float, float]:
        """θ(T) bounds the NLP holds: the touchdown window tightened by :data:`TOUCHDOWN_ATTITUDE_MARGIN`, rad; a
        footprint end's by ``footprint_margin`` of the window's width more, as its J is held inside the touchdown
        limits (an end rides no limit: the nearest one pitches up at the full rate into its touchdown, and its replayed
        contact, a little before T, came 0.2 deg past the 12 deg limit with the 0.5 deg margin alone)."""
        flyability = self.airframe.flyability
        margin = TOUCHDOWN_ATTITUDE_MARGIN
        if self.settings.objective in FOOTPRINT_OBJECTIVES:
            width = flyability.touchdown_max_nose_up_pitch + flyability.touchdown_max_nose_down_pitch
            margin += self.settings.footprint_margin * width
        return (
            margin - flyability.touchdown_max_nose_up_pitch,
            flyability.touchdown_max_nose_down_pitch - margin,
        )

    def variable_bounds(self, parameter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The bounds for a solve from ``parameter``: the rotor ceiling's back-off everywhere, unless the initial Ω is
        above the NLP's line (Ω_max − back-off), when the first interval may reach the true limit on its way inside.

        .. math:: \\Omega_k \\le \\begin{cases} \\Omega_{max} & k \\in \\text{interval 1 and } \\Omega(0) >
            \\Omega_{max} - b\\,\\Omega_0 \\\\ \\Omega_{max} - b\\,\\Omega_0 & \\text{otherwise} \\end{cases}
        """
        above_line = float(parameter[StateIndex.ROTOR_SPEED]) > self.state_upper[StateIndex.ROTOR_SPEED]
        return self.lbx, self._ubx_above_line if above_line else self.ubx

    def initial_guess(self, initial_state: np.ndarray) -> np.ndarray:
        lower, upper = self.variable_bounds(initial_state)
        return np.clip(super().initial_guess(initial_state), lower, upper)

    def interval_controls(self, control_times: np.ndarray, control_values: np.ndarray) -> np.ndarray:
        """The decided breakpoints u_1 … u_K (u_0 is the parameter's)."""
        return np.asarray(control_values, dtype=float)[:, 1 : self.settings.intervals + 1]

    def _interval_ends(self, values: np.ndarray, interval: int) -> tuple[np.ndarray, np.ndarray]:
        """Linear between breakpoints."""
        return values[:, interval], values[:, interval + 1]

    def decode(self, solution: np.ndarray, initial_state: np.ndarray) -> DecodedPlan:
        intervals = self.settings.intervals
        landing_time = float(solution[0]) * _TIME_SCALE
        decided = solution[2 : 2 + 2 * intervals].reshape(2, intervals, order="F") * self.control_scale[:, None]
        controls = np.column_stack([np.asarray(initial_state, dtype=float)[6:8], decided])
        states = self.decoded_states(solution, landing_time, initial_state)
        control_times = np.concatenate([self.interval_starts, [1.0]]) * landing_time
        return self.decoded_plan(landing_time, initial_state, states, control_times, controls, "linear")
