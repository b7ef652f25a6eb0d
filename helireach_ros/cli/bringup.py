"""``helireach bringup`` and ``helireach replay``: the ROS system from the command line.

* ``helireach bringup [--params-file F ...] [--with-sim] [--scenario S] [--log-dir D] [--no-record] [--display]
  [--ros-args ...]``
  runs the composed nodes (:mod:`helireach_ros.bringup`) until Ctrl-C or SIGTERM.
* ``helireach replay LOG.mcap [--rate X] [--topics T ...]`` republishes a log with its original timing
  and QoS (:func:`helireach_ros.log_replay.replay_log`). To re-run the nodes against a recorded failure,
  start ``helireach bringup`` with the monitor's ``max_message_age`` at 0 (the log's stamps are old) and
  replay only the vehicle topics: ``--topics /vehicle/odometry /vehicle/rotor /vehicle/engine_failure``.
* ``helireach replay LOG.mcap --compare`` publishes nothing: it re-runs the planner on every logged
  failure state (as the planner node did: same airframe and settings, warm-started from the envelope)
  and reports the difference to the logged plan; exit code 0 when every plan is reproduced.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from helireach_ros.executors import DEFAULT_EXECUTOR, EXECUTOR_KINDS

__all__ = ["PlanComparison", "compare_logged_plans", "register"]

_STATE_KEYS = (
    "initial_descent_rate_m_s",
    "initial_forward_speed_m_s",
    "initial_rotor_speed_rad_s",
    "initial_height_m",
    "initial_distance_m",
    "initial_engine_power_w",
)


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


def _logged_plans(path: Path) -> tuple[list[tuple[dict[str, str], Any]], dict[str, Any]]:
    """(status values, trajectory message) of each failure's first converged plan in a log, and its metadata."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from rclpy.serialization import deserialize_message
    from trajectory_msgs.msg import JointTrajectory

    from helireach_ros import ros_messages as rm
    from helireach_ros.mcap_log import read_log, read_log_metadata

    statuses, trajectories = [], {}
    for message in read_log(path):
        if message.topic == rm.TOPIC_PLAN_STATUS:
            values = rm.status_values(deserialize_message(message.cdr, DiagnosticStatus))
            converged = values.get("status") in ("safe", "unsafe", "unverified") and values.get("fallback") == "false"
            if converged and values.get("replan_index") == "0":
                statuses.append(values)
        elif message.topic == rm.TOPIC_LANDING_TRAJECTORY:
            trajectory = deserialize_message(message.cdr, JointTrajectory)
            trajectories[rm.stamp_nanoseconds(trajectory.header.stamp)] = trajectory
    pairs = [(values, trajectories.get(int(values["state_stamp_ns"]))) for values in statuses]
    return pairs, read_log_metadata(path)


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
    from helireach_ros import ros_messages as rm
    from helireach_ros.airframe import load_airframe
    from helireach_ros.envelope import default_envelope_path, load_envelope
    from helireach_ros.planner import get_planner
    from helireach_ros.settings import PlannerSettings
    from helireach_ros.simulation import piecewise_linear_controls

    pairs, metadata = _logged_plans(Path(path))
    if not pairs:
        raise ValueError(f"{path}: no converged landing plan in the log")
    recorded = metadata.get("helireach", {})
    if "planner_settings" not in recorded or "airframe" not in recorded:
        raise ValueError(f"{path}: the log's metadata names no airframe/planner settings (not a bringup log?)")
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
    for values, trajectory in pairs:
        state = np.array([float(values[key]) for key in _STATE_KEYS])
        stored = envelope.nearest_plan(state[3], state[1]) if envelope is not None else None
        plan = planner.plan(state, stored.warm_start if stored is not None else None)
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
        logged_time = float(values["time_to_land_s"])
        reproduced = bool(
            values["status"] == plan.status
            and difference[0] <= thrust_tolerance
            and difference[1] <= pitch_tolerance
            and abs(logged_time - plan.time_to_land) <= time_tolerance
        )
        comparisons.append(
            PlanComparison(
                failure_id=int(values["failure_id"]),
                logged_status=values["status"],
                rerun_status=plan.status,
                logged_time_to_land=logged_time,
                rerun_time_to_land=plan.time_to_land,
                logged_value=float(values["value"]),
                rerun_value=plan.value,
                max_thrust_difference=float(difference[0]),
                max_pitch_difference=float(difference[1]),
                reproduced=reproduced,
            )
        )
    return comparisons


# --- handlers ---------------------------------------------------------------------------------------------------
def _run_bringup(arguments: argparse.Namespace) -> int:
    from helireach_ros.bringup import run_bringup

    extra = []
    if arguments.display:
        from helireach_ros.nodes.display import create_display_with_fallback

        extra.append(create_display_with_fallback)
    try:
        return run_bringup(
            arguments.params_file,
            with_sim=arguments.with_sim,
            log_dir=arguments.log_dir,
            scenario=arguments.scenario,
            record=not arguments.no_record,
            extra_nodes=extra,
            ros_args=arguments.ros_args,
            executor=arguments.executor,
        )
    except (FileNotFoundError, ValueError) as error:
        print(f"helireach bringup: {error}", file=sys.stderr)
        return 2


def _run_replay(arguments: argparse.Namespace) -> int:
    if arguments.compare:
        return _run_compare(arguments)
    from helireach_ros.log_replay import main as replay_main

    argv = [arguments.log, "--rate", repr(arguments.rate)]
    if arguments.topics:
        argv += ["--topics", *arguments.topics]
    return replay_main(argv)


def _run_compare(arguments: argparse.Namespace) -> int:
    from helireach_ros.mcap_log import McapLogError

    try:
        comparisons = compare_logged_plans(arguments.log)
    except (McapLogError, ValueError, OSError) as error:
        print(f"helireach replay --compare: {error}", file=sys.stderr)
        return 1
    print(
        f"{'failure':>7} {'logged':>10} {'re-run':>10} {'T logged':>9} {'T re-run':>9} "
        f"{'max dC_T':>9} {'max dtheta':>10}  result"
    )
    for comparison in comparisons:
        times = f"{comparison.logged_time_to_land:>8.3f}s {comparison.rerun_time_to_land:>8.3f}s"
        print(
            f"{comparison.failure_id:>7} {comparison.logged_status:>10} "
            f"{comparison.rerun_status:>10} {times} "
            f"{comparison.max_thrust_difference:>9.2e} {math.degrees(comparison.max_pitch_difference):>8.3f}deg  "
            f"{'reproduced' if comparison.reproduced else 'DIFFERENT'}"
        )
    reproduced = sum(comparison.reproduced for comparison in comparisons)
    print(f"{reproduced} of {len(comparisons)} logged plans reproduced")
    return 0 if reproduced == len(comparisons) else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds ``bringup`` and ``replay`` to the ``helireach`` command."""
    bringup = subparsers.add_parser(
        "bringup",
        help="run the helireach ROS 2 nodes in one process",
        description="Runs monitor, envelope status, planner (and optionally the simulated vehicle and the cockpit "
        "display) under one executor, recording every topic to MCAP, until Ctrl-C or SIGTERM.",
    )
    bringup.add_argument(
        "--params-file",
        action="append",
        default=[],
        metavar="FILE",
        help="ROS parameter YAML (after config/nodes.yaml; repeatable)",
    )
    bringup.add_argument("--with-sim", action="store_true", help="also run the simulated vehicle")
    bringup.add_argument("--scenario", help="the simulated vehicle's scenario (name in config/scenarios or a file)")
    bringup.add_argument("--log-dir", help="folder for the MCAP log (default: the recorder's log_dir parameter)")
    bringup.add_argument("--no-record", action="store_true", help="do not record an MCAP log")
    bringup.add_argument("--display", action="store_true", help="also run the cockpit display node")
    bringup.add_argument(
        "--executor",
        choices=EXECUTOR_KINDS,
        default=DEFAULT_EXECUTOR,
        help="the executor spinning the nodes (default: %(default)s; see helireach_ros/executors.py)",
    )
    bringup.add_argument(
        "--ros-args",
        nargs=argparse.REMAINDER,
        default=[],
        dest="ros_args",
        help="ROS arguments for every node, e.g. --ros-args -p helireach_planner:deadline:=0.1 (must come last)",
    )
    bringup.set_defaults(handler=_run_bringup)

    replay = subparsers.add_parser(
        "replay",
        help="republish an MCAP log, or compare its plans with a re-run",
        description="Republishes a helireach MCAP log with its original timing and QoS; with --compare, re-runs the "
        "planner on each logged failure state and reports the difference to the logged plan instead.",
    )
    replay.add_argument("log", help="the .mcap file")
    replay.add_argument("--rate", type=float, default=1.0, help="playback speed factor (0 = as fast as possible)")
    replay.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    replay.add_argument("--compare", action="store_true", help="re-run the planner on the logged failure states")
    replay.set_defaults(handler=_run_replay)
