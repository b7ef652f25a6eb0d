"""The planner node's parameters: one table (see :mod:`helireach_ros.ros.parameter_table`).

The aircraft parameters it shares with the envelope status node (``airframe``, ``gross_weight``,
``density_altitude``) are declared by :func:`~helireach_ros.ros.parameters.declare_aircraft`. What each parameter
does: docs/guides/planner-node.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from helireach_ros.core.estimation.disturbance import DisturbanceSettings
from helireach_ros.core.policies.landing_sites import SiteSelection, parse_site_list
from helireach_ros.core.policies.landing_supervisor import SupervisorSettings
from helireach_ros.core.policies.live_reachability import LiveSettings
from helireach_ros.core.workers.planner_backend import BackendSettings
from helireach_ros.ros import messages as rm
from helireach_ros.ros.parameter_table import parameter

if TYPE_CHECKING:
    from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings

# The default solve_timeout: the deadline, but at least this. A kill is for a hung worker, not a slow one (a killed
# worker is out for seconds while it rebuilds its NLPs): an unsafe failure plan for an estimated weight (plain CasADi
# functions, 300 iterations) measured 1.05 s on an idle 2-core machine, over 1 s wherever the machine is loaded.
_MIN_SOLVE_TIMEOUT_S = 3.0
_NO_REPLANNING_PERIOD_S = 1e9  # replan_period 0 (re-planning off): the closed loop of the robust check flies one plan

__all__ = ["PlannerParameters"]


@dataclass(frozen=True)
class PlannerParameters:
    """The planner node's own parameters, SI (declared in this order)."""

    planner_settings: str = parameter("", "planner settings file ('' = config/planner.yaml)")
    envelope_file: str = parameter("", "envelope for warm starts/fallbacks ('' = shipped, 'none' = off)")
    deadline: float = parameter(0.25, "fallback if no plan this long after the failure, s", (0.001, 60.0))
    replan_period: float = parameter(0.25, "closed-loop re-planning period, s (0 = off)", (0.0, 60.0))
    replan_min_height: float = parameter(0.5, "no re-planning below this height, m", (0.0, 1000.0))
    replan_min_remaining: float = parameter(0.3, "no re-planning when the plan has less time left, s", (0.0, 60.0))
    state_timeout: float = parameter(0.5, "older states are not planned from, s", (0.01, 60.0))
    max_message_age: float = parameter(
        1.0, "first plan from a state later after the failure = late, s", (0.001, 3600.0)
    )
    assume_total_power_loss: bool = parameter(True, "plan with zero engine power (else the measured power)")
    warm_up: bool = parameter(True, "solve one landing at startup (first-call costs)")
    world_frame: str = parameter(rm.DEFAULT_WORLD_FRAME, "frame of the landing path")
    rotor_joint: str = parameter(rm.ROTOR_JOINT, "JointState joint of the main rotor")
    diagnostics_period: float = parameter(1.0, "period of /diagnostics, s", (0.05, 60.0))
    solver_workers: int = parameter(2, "solver worker processes (0 = solve in this process)", (0, 16))
    solve_timeout: float = parameter(
        math.nan, "a worker's failure plan not back this long = hung, s (NaN = deadline, at least 3 s)", (0.001, 600.0)
    )
    reaction_delay: float = parameter(
        math.nan,
        "s the controls stay at the pre-failure trim before a failure plan starts (NaN = the planner settings')",
        (0.0, 10.0),
    )
    live_rate: float = parameter(5.0, "live evaluations before a failure, Hz (0 = off)", (0.0, 100.0))
    live_power_fraction: float = parameter(
        0.0, "engine power left after the assumed failure, of the measured power", (0.0, 1.0)
    )
    live_max_state_age: float = parameter(0.3, "an older state is not evaluated live, s", (0.001, 60.0))
    standby_max_age: float = parameter(
        0.3, "standby plan only from a state at most this much older than the failure, s", (0.001, 60.0)
    )
    estimate_weight: bool = parameter(
        False, "plan for the gross weight estimated from the steady flight before a failure"
    )
    weight_estimate_window: float = parameter(1.0, "steady flight averaged for the weight estimate, s", (0.1, 30.0))
    weight_estimate_step: float = parameter(0.005, "quantum of the estimated relative weight change", (0.001, 0.05))
    weight_estimate_error: float = parameter(
        0.02, "estimates outside the uncertainty set's weight range widened by this fraction are refused", (0.0, 0.2)
    )
    estimate_disturbance: bool = parameter(
        True, "re-plan for the model plus the disturbance accelerations learnt from each re-planning interval"
    )
    disturbance_gain: float = parameter(
        0.3, "fraction of each interval's prediction error the estimate takes", (0.01, 1.0)
    )
    robust_verification: bool = parameter(
        False, "verify each failure plan robustly in a low-priority process (the plan is published 'robust: pending')"
    )
    robust_uncertainty: str = parameter("", "uncertainty set of the robust verification ('' = config/uncertainty.yaml)")
    landing_sites: str = parameter(
        "", "landing sites along the track (odometry x, m): 'name:start_m:end_m' separated by ';' ('' = land anywhere)"
    )
    selected_site: str = parameter("", "the crew's landing site, by name ('' = automatic: the first reachable one)")
    landing_sites_topic: bool = parameter(
        False, "take the landing sites from /mission/landing_sites too (latched; the latest replaces the parameter's)"
    )
    footprint_period: float = parameter(
        0.0,
        "live reachable footprint at most this often, s (0 = off; each takes a live evaluation's slot)",
        (0.0, 3600.0),
    )

    # -- the core's settings, from these parameters ----------------------------------------------------------------
    @property
    def solve_timeout_s(self) -> float:
        """The solve timeout in effect: not the deadline itself by default (a slow solve is not a hung one, and its
        plan must still replace the deadline's fallback; a dead worker is seen at once whatever the timeout)."""
        return max(self.deadline, _MIN_SOLVE_TIMEOUT_S) if math.isnan(self.solve_timeout) else self.solve_timeout

    def supervisor_settings(self) -> SupervisorSettings:
        """The failure-handling rules' settings."""
        return SupervisorSettings(
            deadline=self.deadline,
            replan_min_height=self.replan_min_height,
            replan_min_remaining=self.replan_min_remaining,
            max_message_age=self.max_message_age,
        )

    def live_settings(self) -> LiveSettings | None:
        """The live evaluation's settings (None: off)."""
        if self.live_rate <= 0.0:
            return None
        return LiveSettings(
            rate_hz=self.live_rate,
            power_fraction=self.live_power_fraction,
            max_state_age_s=self.live_max_state_age,
            standby_max_age_s=self.standby_max_age,
        )

    def disturbance_settings(self) -> DisturbanceSettings | None:
        """The re-plans' disturbance estimate (None: off)."""
        return DisturbanceSettings(gain=self.disturbance_gain) if self.estimate_disturbance else None

    def replanning_policy(self) -> ClosedLoopSettings:
        """This node's re-planning policy as the closed loop flies it (what the robust verification checks)."""
        from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings

        return ClosedLoopSettings(
            replan_period=self.replan_period if self.replan_period > 0.0 else _NO_REPLANNING_PERIOD_S,
            min_height=self.replan_min_height,
            min_remaining=self.replan_min_remaining,
            estimate_disturbance=self.estimate_disturbance,
            disturbance=DisturbanceSettings(gain=self.disturbance_gain),
        )

    def site_selection(self) -> SiteSelection | None:
        """The landing sites and their selection (None: no sites, land anywhere).

        Raises:
            ValueError: a malformed site, or a selected site that is not in the list.
        """
        sites = parse_site_list(self.landing_sites)
        if not sites and not self.landing_sites_topic:
            if self.selected_site:
                raise ValueError(f"selected_site {self.selected_site!r} given without landing_sites")
            return None
        return SiteSelection(sites, self.selected_site)

    def backend_settings(self, *, site_planning: bool = False, footprint: bool = False) -> BackendSettings:
        """How the node solves (``site_planning``: with usable landing sites; ``footprint``: the live footprint)."""
        return BackendSettings(
            envelope_file=self.envelope_file,
            solver_workers=self.solver_workers,
            warm_up=self.warm_up,
            solve_timeout_s=self.solve_timeout_s,
            reaction_delay_s=self.reaction_delay,
            estimate_weight=self.estimate_weight,
            weight_window_s=self.weight_estimate_window,
            weight_step=self.weight_estimate_step,
            weight_error=self.weight_estimate_error,
            robust_policy=self.replanning_policy() if self.robust_verification else None,
            robust_uncertainty=self.robust_uncertainty,
            site_planning=site_planning,
            footprint=footprint,
        )
