"""``helireach replay``: republish a recorded run, or compare its plans with a re-run.

* ``helireach replay LOG.mcap [--rate X] [--topics T ...] [--start S] [--loop] [--recover]`` republishes a log
  with its original timing and QoS, and ``/clock`` (:mod:`helireach_ros.ros.replay`: rules, exit codes). To
  re-run the nodes against a recorded failure, start ``helireach bringup`` with the monitor's
  ``max_message_age`` at 0 (the log's stamps are old) and replay only the vehicle topics:
  ``--topics /vehicle/odometry /vehicle/rotor /vehicle/engine_failure``.
* ``helireach replay LOG.mcap --compare`` publishes nothing: it re-runs the planner on every logged
  failure state (as the planner node did: same airframe and settings, warm-started from the envelope)
  and reports the difference to the logged plan (:mod:`helireach_ros.ros.plan_comparison`); exit code 0
  when every plan is reproduced.
"""

from __future__ import annotations

import argparse
import math
import sys

__all__ = ["register"]


def _run_replay(arguments: argparse.Namespace) -> int:
    if arguments.compare:
        return _run_compare(arguments)
    from helireach_ros.ros.replay import run_replay

    return run_replay(arguments)


def _run_compare(arguments: argparse.Namespace) -> int:
    from helireach_ros.core.mcap_log import McapLogError
    from helireach_ros.ros.plan_comparison import compare_logged_plans, logged_plan_counts

    try:
        comparisons = compare_logged_plans(arguments.log)
        counts = logged_plan_counts(arguments.log)
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
    skipped = ", ".join(
        f"{counts[kind]} {label}" for kind, label in (("standby", "standby"), ("replan", "re-plans"),
                                                        ("fallback", "fallbacks")) if counts.get(kind)
    )  # fmt: skip
    not_compared = f" (each failure's first refined plan; not compared: {skipped})" if skipped else ""
    print(f"{reproduced} of {len(comparisons)} logged plans reproduced{not_compared}")
    return 0 if reproduced == len(comparisons) else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds ``replay`` to the ``helireach`` command."""
    from helireach_ros.ros.replay import add_playback_arguments  # imports no rclpy

    replay = subparsers.add_parser(
        "replay",
        help="republish an MCAP log, or compare its plans with a re-run",
        description="Republishes a helireach MCAP log with its original timing and QoS; with --compare, re-runs the "
        "planner on each logged failure state and reports the difference to the logged plan instead.",
    )
    add_playback_arguments(replay)
    replay.add_argument("--compare", action="store_true", help="re-run the planner on the logged failure states")
    replay.set_defaults(handler=_run_replay)
