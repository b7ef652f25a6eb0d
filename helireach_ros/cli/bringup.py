"""``helireach bringup``: the composed ROS system from the command line.

``helireach bringup [--params-file F ...] [--with-sim] [--scenario S] [--log-dir D] [--no-record] [--display]
[--executor KIND] [--ros-args ...]`` runs the composed nodes (:mod:`helireach_ros.ros.bringup`) until Ctrl-C
or SIGTERM. Exit codes: 0 after Ctrl-C/SIGTERM, 2 for a bad command line, parameter file or parameter value
(one line on stderr, nothing started).
"""

from __future__ import annotations

import argparse
import sys

from helireach_ros.ros.executors import DEFAULT_EXECUTOR, EXECUTOR_KINDS

__all__ = ["register"]


def _run_bringup(arguments: argparse.Namespace) -> int:
    from helireach_ros.ros.node_command_line import CommandLineError, check_ros_arguments

    try:  # one line and exit 2 for what rcl would answer with a traceback (trailing -p, broken YAML)
        files = [argument for path in arguments.params_file for argument in ("--params-file", path)]
        check_ros_arguments([*files, *arguments.ros_args])
    except CommandLineError as error:
        print(f"helireach bringup: error: {error}", file=sys.stderr)
        return 2

    from rclpy.impl.implementation_singleton import rclpy_implementation

    from helireach_ros.ros.bringup import run_bringup

    extra = []
    if arguments.display:
        from helireach_ros.display.node import create_display_with_fallback

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
        # ValueError includes ParameterError: a bad parameter value stops the system before it starts
        print(f"helireach bringup: error: {error}", file=sys.stderr)
        return 2
    except rclpy_implementation.UnknownROSArgsError as error:
        print(f"helireach bringup: error: unknown ROS argument(s) {error}", file=sys.stderr)
        return 2


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds ``bringup`` to the ``helireach`` command."""
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
        help="the executor spinning the nodes (default: %(default)s; see helireach_ros/ros/executors.py)",
    )
    bringup.add_argument(
        "--ros-args",
        nargs=argparse.REMAINDER,
        default=[],
        dest="ros_args",
        help="ROS arguments for every node, e.g. --ros-args -p helireach_planner:deadline:=0.1 (must come last)",
    )
    bringup.set_defaults(handler=_run_bringup)
