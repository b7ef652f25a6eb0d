"""Re-running the planner on the failures of a recorded log, and comparing with what was published.

``helireach replay LOG.mcap --compare`` (:mod:`helireach_ros.cli.replay`) prints the comparison; the
system tests use it to check that a run's first plans are reproducible from its log.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from helireach_ros.core.status_contracts import PlanStatusValues

__all__ = ["PlanComparison", "compare_logged_plans", "logged_plan_counts", "plan_kind"]


@dataclass(frozen=True)
class PlanComparison:
    """A logged plan against the planner re-run on its initial state.

    Attributes:
        failure_id: which failure of the log.
        logged_status, rerun_status: the plans' statuses.
        logged_time_to_land, rerun_time_to_land: s.
        logged_value, rerun_value: the NLP values.
        max_thrust_difference: largest |ΔC_T| over the plan (both trajectories as published).
        max_pitch_difference: largest |Δθ|, rad.
        reproduced: same status and differences within the tolerances.
    """

    failure_id: int
    logged_status: str
    rerun_status: str
    logged_time_to_land: float
    rerun_time_to_land: float
    logged_value: float
    rerun_value: float
    max_thrust_difference: float
    max_pitch_difference: float
    reproduced: bool


def _logged_plans(path: Path) -> tuple[list[tuple[PlanStatusValues, Any]], dict[str, Any]]:
    """(status values, trajectory message) of each failure's first converged plan in a log, and its metadata."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from rclpy.serialization import deserialize_message
    from trajectory_msgs.msg import JointTrajectory

    from helireach_ros.core.mcap_log import read_log, read_log_metadata
    from helireach_ros.ros import messages as rm

    statuses, trajectories = [], {}
    for message in read_log(path):
        if message.topic == rm.TOPIC_PLAN_STATUS:
            logged = PlanStatusValues.from_values(rm.status_values(deserialize_message(message.cdr, DiagnosticStatus)))
            if plan_kind(logged) == "first":
                statuses.append(logged)
        elif message.topic == rm.TOPIC_LANDING_TRAJECTORY:
            trajectory = deserialize_message(message.cdr, JointTrajectory)
            trajectories[rm.stamp_nanoseconds(trajectory.header.stamp)] = trajectory
    pairs = [(logged, trajectories.get(logged.state_stamp_ns or -1)) for logged in statuses]
    return pairs, read_log_metadata(path)


def plan_kind(plan: PlanStatusValues) -> str:
    """What a logged plan status is: ``first`` (a failure's first converged plan: what ``--compare`` re-runs),
    ``standby``, ``replan``, ``fallback``, or ``other`` (no plan yet, ended, landed)."""
    if plan.fallback is True:
        return "fallback"
    if plan.fallback is not False or plan.status not in ("safe", "unsafe", "unverified"):
        return "other"
    # A standby plan was made before the failure from a live state, warm-started along the live chain (not in the
    # log): the first plan *of the failure* is the refined one that follows it.
    if plan.standby is True:
        return "standby"
    return "first" if plan.replan_index == 0 else "replan"


def logged_plan_counts(path: str | Path) -> dict[str, int]:
    """How many plan statuses of each :func:`plan_kind` a log holds (what ``--compare`` did and did not re-run)."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from rclpy.serialization import deserialize_message

    from helireach_ros.core.mcap_log import read_log
    from helireach_ros.ros import messages as rm

    counts: dict[str, int] = {}
    for message in read_log(path):
        if message.topic == rm.TOPIC_PLAN_STATUS:
            values = rm.status_values(deserialize_message(message.cdr, DiagnosticStatus))
            kind = plan_kind(PlanStatusValues.from_values(values))
            counts[kind] = counts.get(kind, 0) + 1
    return counts


def _controls_on_grid(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    return np.vstack([np.interp(grid, times, row) for row in values])


def compare_logged_plans(
    path: str | Path,
    thrust_tolerance: float = 2e-4,
    pitch_tolerance: float = math.radians(0.5),
    time_tolerance: float = 0.05,
) -> list[PlanComparison]:
    """Re-runs the planner on each logged failure state and compares with the logged plan.

    Only each failure's first plan is compared: closed-loop re-plans were warm-started from the
    previous plan, which the log does not hold, and the landing NLP can have several equally good
    optima. The re-run uses the airframe and planner settings recorded in the log's metadata and, like the
    planner node, a warm start from the shipped envelope's nearest stored plan when it matches.

    Args:
        path: the ``.mcap`` log.
        thrust_tolerance: largest accepted |ΔC_T|.
        pitch_tolerance: largest accepted |Δθ|, rad.
        time_tolerance: largest accepted difference in time to land, s.

    Raises:
        McapLogError: unreadable log. ValueError: the log holds no plan or lacks its metadata.
    """
    from helireach_ros.core.aircraft.airframe import load_airframe
    from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
    from helireach_ros.core.flight.simulation import piecewise_linear_controls
    from helireach_ros.core.ocp.settings import PlannerSettings
    from helireach_ros.core.planning.planner import get_planner
    from helireach_ros.ros import messages as rm

    pairs, metadata = _logged_plans(Path(path))
    if not pairs:
        raise ValueError(f"{path}: no converged landing plan in the log")
    recorded = metadata.get("helireach", {})
    if "planner_settings" not in recorded or "airframe" not in recorded:
        raise ValueError(
            f"{path}: the log's metadata names no airframe/planner settings (the recorder could not load them: "
            "see its log; or an older recorder)"
        )
    airframe = load_airframe(recorded["airframe"])
    if recorded.get("gross_weight_n") and recorded.get("density_altitude_m"):  # the planner node's conditions
        airframe = airframe.with_conditions(float(recorded["gross_weight_n"]), float(recorded["density_altitude_m"]))
    if recorded.get("airframe_digest") and recorded["airframe_digest"] != airframe.digest():
        raise ValueError(f"{path}: airframe {airframe.name!r} differs from the logged one (digest)")
    settings = PlannerSettings(**json.loads(recorded["planner_settings"]))
    planner = get_planner(airframe, settings)
    try:
        envelope = load_envelope(default_envelope_path(), airframe, settings, 0.0)
    except Exception:
        envelope = None
    comparisons = []
    for logged, trajectory in pairs:
        if logged.initial_state is None:
            raise ValueError(f"{path}: a plan status of failure {logged.failure_id} has no readable initial state")
        state = np.array(logged.initial_state)
        stored = envelope.nearest_plan_to(state) if envelope is not None else None
        # the control flown at the plan's start and its reaction delay, as logged (older logs: the defaults)
        control = None if logged.initial_control is None else np.array(logged.initial_control)
        # the weight the plan was made for (the planner node's estimate; older logs: the airframe's)
        weight = logged.planned_gross_weight if logged.planned_gross_weight is not None else airframe.gross_weight
        solver = planner if weight == airframe.gross_weight else get_planner(airframe.with_conditions(weight), settings)
        # the model error the plan was made for (re-plans with estimate_disturbance; older logs: none)
        disturbance = np.zeros(3) if logged.disturbance is None else np.array(logged.disturbance)
        warm_start = stored.warm_start if stored is not None else None
        plan = solver.plan(state, warm_start, control, logged.reaction_delay_s, disturbance)
        rerun_times, rerun_values = piecewise_linear_controls(
            plan.control_times, plan.control_values, plan.control_interpolation
        )
        if trajectory is not None:
            _, logged_times, logged_values = rm.read_trajectory(trajectory)
            grid = np.union1d(logged_times, rerun_times)
            difference = np.abs(
                _controls_on_grid(logged_times, logged_values, grid)
                - _controls_on_grid(rerun_times, rerun_values, grid)
            ).max(axis=1)
        else:
            difference = np.array([math.inf, math.inf])
        logged_time = math.nan if logged.time_to_land_s is None else logged.time_to_land_s
        reproduced = bool(
            logged.status == plan.status
            and difference[0] <= thrust_tolerance
            and difference[1] <= pitch_tolerance
            and abs(logged_time - plan.time_to_land) <= time_tolerance
        )
        comparisons.append(
            PlanComparison(
                failure_id=-1 if logged.failure_id is None else logged.failure_id,
                logged_status=logged.status or "",
                rerun_status=plan.status,
                logged_time_to_land=logged_time,
                rerun_time_to_land=plan.time_to_land,
                logged_value=math.nan if logged.value is None else logged.value,
                rerun_value=plan.value,
                max_thrust_difference=float(difference[0]),
                max_pitch_difference=float(difference[1]),
                reproduced=reproduced,
            )
        )
    return comparisons
