"""Executors for the helireach nodes: which one spins them.

The composed system (:mod:`helireach_ros.bringup`, the demo) and the per-node console scripts take an
executor *kind*:

- ``single_threaded`` (the default): rclpy's ``SingleThreadedExecutor``. No helireach callback blocks
  (the planner solves on a thread of its own), so one thread serves every node.
- ``events``: rclpy's C++ ``EventsExecutor``, experimental in Jazzy. It dispatches from middleware
  events instead of rebuilding a wait set in Python on every wake-up and uses the least CPU, but the
  7.1 wheels carry known crash bugs (ros2/rclpy#1644, #1718), so it is opt-in.
- ``multi_threaded``: rclpy's ``MultiThreadedExecutor``, whose shutdown here also joins its pool. In
  rclpy 7.1 its dispatch loop spins on ready callbacks and starves the other threads of the GIL:
  with it, the composed demo's re-plans arrived up to 1.8 s late (README, "Failure to trajectory").

rclpy is imported on first use, so command-line parsers can offer the kinds cheaply.
"""

from __future__ import annotations

import functools
import os
from typing import Any

__all__ = ["DEFAULT_EXECUTOR", "EXECUTOR_KINDS", "MIN_EXECUTOR_THREADS", "create_executor"]

EXECUTOR_KINDS = ("events", "single_threaded", "multi_threaded")
"""The executor kinds :func:`create_executor` accepts."""
DEFAULT_EXECUTOR = "single_threaded"
"""The executor kind of the composed system and of the per-node scripts."""
MIN_EXECUTOR_THREADS = 4


@functools.cache
def _joining_multi_threaded_executor() -> type:
    from rclpy.executors import MultiThreadedExecutor

    class JoiningMultiThreadedExecutor(MultiThreadedExecutor):
        """A MultiThreadedExecutor whose shutdown also waits for callbacks still running in its pool.

        rclpy 7.1's ``shutdown`` returns while pool threads may still run callbacks; destroying the
        nodes then makes those callbacks fail ("cannot use Destroyable because destruction was requested").
        """

        def shutdown(self, timeout_sec: float | None = None) -> bool:
            done = super().shutdown(timeout_sec)
            pool = getattr(self, "_executor", None)  # the ThreadPoolExecutor (not public API)
            if pool is not None:
                pool.shutdown(wait=True)
            return done

    return JoiningMultiThreadedExecutor


def create_executor(kind: str, context: Any = None, num_threads: int | None = None) -> Any:
    """An executor of the given kind (see the module docstring).

    Args:
        kind: one of :data:`EXECUTOR_KINDS`.
        context: the ``rclpy.context.Context`` it serves (default: rclpy's default context).
        num_threads: threads of a ``multi_threaded`` executor (default: max(4, CPUs)); ignored otherwise.

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
    if kind == "multi_threaded":
        threads = num_threads if num_threads is not None else max(MIN_EXECUTOR_THREADS, os.cpu_count() or 1)
        return _joining_multi_threaded_executor()(num_threads=threads, context=context)
    raise ValueError(f"unknown executor kind {kind!r}; expected one of {', '.join(EXECUTOR_KINDS)}")
