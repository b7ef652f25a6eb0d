"""Executors for the helireach nodes: which one spins them.

The composed system (:mod:`helireach_ros.ros.bringup`, the demo) and the per-node console scripts take an
executor *kind*:

- ``single_threaded`` (the default): rclpy's ``SingleThreadedExecutor``, serving its nodes in the order they
  were added (:mod:`helireach_ros.ros.added_order_executor`). No helireach callback blocks (the planner
  solves on a thread of its own), so one thread serves every node. After each wait the ready callbacks run
  node by node, so the composed system's order is its priority: the failure path (monitor, planner) and the
  trajectory's consumers before the status and the recorder (``HelireachSystem.nodes``).
- ``events``: rclpy's C++ ``EventsExecutor``, experimental in Jazzy. It dispatches from middleware
  events instead of rebuilding a wait set in Python on every wake-up and uses the least CPU, but the
  7.1 wheels carry known crash bugs (ros2/rclpy#1644, #1718), so it is opt-in.

rclpy's ``MultiThreadedExecutor`` is not offered: in rclpy 7.1 its dispatch loop spins on ready
callbacks and starves every other thread of the GIL. Under it the composed demo's re-plans arrived
up to 1.8 s late, and with the planner's solver thread the failure-latency bench got no plan at all
within 10 s (docs/decisions/solver-threads.md).

rclpy is imported on first use, so command-line parsers can offer the kinds cheaply. :func:`run_node` is the
body of every node's ``main`` (ros2/demos style: ``sys.exit(run_node(NodeClass, args))``); it also answers
``--help`` and turns a bad command line or parameter into one line on stderr and exit code 2.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = [
    "DEFAULT_EXECUTOR",
    "EXECUTOR_KINDS",
    "create_executor",
    "node_command_line",
    "run_node",
    "shutdown_is_a_normal_stop",
]

EXECUTOR_KINDS = ("single_threaded", "events")
"""The executor kinds :func:`create_executor` accepts."""
DEFAULT_EXECUTOR = "single_threaded"
"""The executor kind of the composed system and of the per-node scripts."""


def create_executor(kind: str, context: Any = None) -> Any:
    """An executor of the given kind (see the module docstring).

    Args:
        kind: one of :data:`EXECUTOR_KINDS`.
        context: the ``rclpy.context.Context`` it serves (default: rclpy's default context).

    Returns:
        An ``rclpy.executors.Executor`` (or the events executor, which has the same interface).

    Raises:
        ValueError: an unknown kind.
    """
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single_threaded":
        from helireach_ros.ros.added_order_executor import AddedOrderExecutor

        return AddedOrderExecutor(context=context)
    raise ValueError(f"unknown executor kind {kind!r}; expected one of {', '.join(EXECUTOR_KINDS)}")


@contextlib.contextmanager
def shutdown_is_a_normal_stop(context: Any = None) -> Iterator[None]:
    """Within this block, a stop (Ctrl-C, SIGTERM, another shutdown of ``context``; default rclpy's) ends quietly.

    rclpy's signal handler shuts the context down from a thread of its own, so a stop can land between the
    executor's ``context.ok()`` check and the wait set it then builds, or while a node is being built: rclpy
    raises ``RCLError`` ("failed to initialize wait set" / "failed to create timer: the given context is not
    valid") instead of ``ExternalShutdownException`` (ros2/rclpy#1166, ros2/ros2cli#854). Here 37 of 200
    SIGTERMs to a spinning executor did so, and the recorder exited with 1 after finishing its log normally. An
    error raised once the context is no longer ok is therefore a stop; any other error propagates.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    try:
        yield
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:  # rclpy's RCLError is one
        if rclpy.ok(context=context):
            raise


def _one_line(error: BaseException) -> str:
    """rcl's messages end in ``, at /project/src/...`` source locations: keep the reason only."""
    return str(error).split(", at /")[0].replace("failed to initialize rcl: ", "").strip()


def node_command_line(
    node_class: Callable[..., Any], args: list[str] | None = None
) -> tuple[list[str], str, int | None]:
    """What a node script does before ``rclpy.init``: answer ``--help``, refuse a bad command line.

    Args:
        node_class: the node the script runs (its name and parameters make the usage text).
        args: command-line arguments, program name first (default ``sys.argv``).

    Returns:
        ``(arguments, script name, exit code)``; the exit code is None when the node should start, 0 after
        printing the usage, 2 after printing a one-line error on stderr.
    """
    import sys
    from pathlib import Path

    from helireach_ros.ros.node_command_line import (
        CommandLineError,
        check_node_arguments,
        node_name_of,
        node_usage,
        wants_help,
    )

    arguments = list(sys.argv if args is None else args)
    node_name = node_name_of(node_class)
    script = Path(arguments[0]).name if arguments else node_name
    if wants_help(arguments):
        print(node_usage(script, node_name, node_class))
        return arguments, script, 0
    try:
        check_node_arguments(arguments)
    except CommandLineError as error:
        print(f"{script}: error: {error}", file=sys.stderr)
        return arguments, script, 2
    return arguments, script, None


def run_node(node_class: Callable[..., Node], args: list[str] | None = None) -> int:
    """The body of a node's ``main``: init, spin until Ctrl-C or SIGTERM, destroy, shut down (ros2/demos style).

    ``-h``/``--help`` prints the node's usage (:func:`~helireach_ros.ros.node_command_line.node_usage`) without
    starting rclpy. A bad command line (a trailing ``-p``, a missing or broken ``--params-file``, an argument
    outside ``--ros-args``) or a bad parameter value
    (:class:`~helireach_ros.ros.parameters.ParameterError`) prints one line on stderr and returns 2 before
    anything is published. Overrides the node did not declare are warned about once it has declared its
    parameters (:func:`~helireach_ros.ros.parameters.warn_unknown_parameters`).

    Args:
        node_class: builds the node (called after ``rclpy.init``).
        args: command-line arguments, program name first (default ``sys.argv``).

    Returns:
        The exit code for ``sys.exit``: 0 after a normal stop (or ``--help``), 2 for a bad command line or
        parameter.
    """
    import sys

    arguments, script, early_exit = node_command_line(node_class, args)
    if early_exit is not None:
        return early_exit

    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from helireach_ros.ros.parameters import ParameterError, warn_unknown_parameters
    from helireach_ros.ros.qos import drop_parameter_event_handlers

    # rclpy's own SIGINT and SIGTERM handlers wake the blocked executor and make spin() raise, so the
    # node is destroyed (the recorder finishes its log); a Python signal.signal() handler would only
    # run after the wait returned.
    try:
        rclpy.init(args=arguments, signal_handler_options=SignalHandlerOptions.ALL)
    except RuntimeError as error:  # rcl's RCLError / UnknownROSArgsError: what the checks above do not cover
        print(f"{script}: error: bad ROS arguments: {_one_line(error)} (see --help)", file=sys.stderr)
        return 2
    node = None
    try:
        with shutdown_is_a_normal_stop():
            node = node_class()
            drop_parameter_event_handlers(node)
            warn_unknown_parameters(node)
            executor = create_executor(DEFAULT_EXECUTOR)
            executor.add_node(node)
            executor.spin()
    except ParameterError as error:
        print(f"{script}: error: {error}", file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
