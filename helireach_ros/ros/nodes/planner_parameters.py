"""The planner node's parameters: one table (see :mod:`helireach_ros.ros.parameter_table`).

The aircraft parameters it shares with the envelope status node (``airframe``, ``gross_weight``,
``density_altitude``) are declared by :func:`~helireach_ros.ros.parameters.declare_aircraft`. What each parameter
does: docs/guides/planner-node.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from helireach_ros.ros import messages as rm
from helireach_ros.ros.parameter_table import parameter

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
