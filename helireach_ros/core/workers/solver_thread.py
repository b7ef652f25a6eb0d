"""The planner's solver thread: one planning step at a time, off the thread that takes the inputs.

A slow solve must not hold up the deadline's fallback or the inputs, so the planner node runs its planning steps
(the first plan, re-plans, in-process live evaluations) here. A step that is not queued is skipped while another is
pending or running (a re-plan tick during a solve); a queued one (the first plan of a failure) always runs. An
exception in a step is reported, never lost silently and never the end of the thread.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

__all__ = ["SolverThread"]


class SolverThread:
    """One worker thread for planning steps (see the module docstring).

    Args:
        report_error: called with a line for a step that raised (from the solver thread).
    """

    def __init__(self, report_error: Callable[[str], None]) -> None:
        self._report_error = report_error
        self._lock = threading.Lock()
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="helireach_solver")
        self._job: Future | None = None

    def submit(self, step: Callable[..., None], *args: Any, queue: bool = False) -> bool:
        """Runs ``step(*args)`` on the thread; without ``queue`` only if no step is pending or running.

        Returns:
            Whether it was submitted (False: skipped, or the thread is shut down).
        """
        with self._lock:
            if not queue and self._job is not None and not self._job.done():
                return False
            try:
                self._job = self._executor.submit(self._run, step, *args)
            except RuntimeError:  # shut down: the node is being destroyed
                return False
        return True

    def _run(self, step: Callable[..., None], *args: Any) -> None:
        try:
            step(*args)
        except Exception as error:  # an unexpected error must not silently end planning for this failure
            with contextlib.suppress(Exception):  # the reporter's context may already be shut down
                self._report_error(f"planning step {step.__name__} failed: {type(error).__name__}: {error}")

    @property
    def busy(self) -> bool:
        """A step is pending or running."""
        with self._lock:
            return self._job is not None and not self._job.done()

    def shutdown(self) -> None:
        """Lets a running step finish and drops the queued ones."""
        self._executor.shutdown(wait=True, cancel_futures=True)
