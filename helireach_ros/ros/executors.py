"""Executors for the helireach nodes: which one spins them.

The composed system (:mod:`helireach_ros.ros.bringup`, the demo) and the per-node console scripts take an
executor *kind*:

- ``single_threaded`` (the default): rclpy's ``SingleThreadedExecutor``. No helireach callback blocks
  (the planner solves on a thread of its own), so one thread serves every node.
- ``events``: rclpy's C++ ``EventsExecutor``, experimental in Jazzy. It dispatches from middleware
  events instead of rebuilding a wait set in Python on every wake-up and uses the least CPU, but the
  7.1 wheels carry known crash bugs (ros2/rclpy#1644, #1718), so it is opt-in.

rclpy's ``MultiThreadedExecutor`` is not offered: in rclpy 7.1 its dispatch loop spins on ready
callbacks and starves every other thread of the GIL. Under it the composed demo's re-plans arrived
up to 1.8 s late, and with the planner's solver thread the failure-latency bench got no plan at all
within 10 s (README, "Failure to trajectory").

rclpy is imported on first use, so command-line parsers can offer the kinds cheaply. :func:`run_node` is the
body of every node's ``main`` (ros2/demos style).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ["DEFAULT_EXECUTOR", "EXECUTOR_KINDS", "create_executor", "run_node"]

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
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    raise ValueError(f"unknown executor kind {kind!r}; expected one of {', '.join(EXECUTOR_KINDS)}")


def run_node(node_class: Callable[[], Node], args: list[str] | None = None) -> None:
    """The body of a node's ``main``: init, spin until Ctrl-C or SIGTERM, destroy, shut down (ros2/demos style).

    Args:
        node_class: builds the node (called after ``rclpy.init``).
        args: command-line arguments (default ``sys.argv``).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    # rclpy's own SIGINT and SIGTERM handlers wake the blocked executor and make spin() raise, so the
    # node is destroyed (the recorder finishes its log); a Python signal.signal() handler would only
    # run after the wait returned.
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.ALL)
    node = None
    try:
        node = node_class()
        executor = create_executor(DEFAULT_EXECUTOR)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
