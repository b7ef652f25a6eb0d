"""Robust verification of failure plans off the failure path: one low-priority worker process.

A plan is published as soon as its nominal replay has verified it; its robust verification
(:func:`~helireach_ros.core.robustness.verification.verify_plan_robust`: the landing flown closed loop through the
uncertainty set's design, each flight ~1–3 s of CPU) takes seconds, so it runs afterwards, here, and the plan is
flagged ``robust: pending`` until its verdict arrives. The worker runs at the lowest CPU priority (``nice``
19 by default): on a machine whose cores the real-time solves need, it takes only what they leave, and it can
never delay a plan. It stops at the first model that fails (the verdict is then settled) unless told otherwise.

Results are collected by polling (:meth:`BackgroundRobustVerification.finished`), from whichever thread publishes
them; nothing here calls back into the caller.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import threading
import time
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from multiprocessing.pool import AsyncResult
from typing import Any

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.flight.uncertainty import PerturbedModel
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.planning.planner import LandingPlan
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings
from helireach_ros.core.status_contracts import RobustVerdictValues

__all__ = ["BackgroundRobustVerification", "RobustSummary", "summarise_verification"]


@dataclass(frozen=True)
class RobustSummary:
    """A robust verdict as published (small and picklable; :class:`~.robust_verification.RobustVerdict` holds more).

    Attributes:
        robust: the closed loop landed within the true limits in every model flown (and the plan is safe).
        reason: why not ('' when robust); an error text when ``error``.
        design: the models' description.
        design_size: models in the design; ``models_flown``: flown (fewer when stopped at the first failure).
        closed_loop_landed, open_loop_landed: flights that landed within limits.
        seconds: wall time of the verification (in the worker).
        error: the verification itself failed (never robust).
    """

    robust: bool
    reason: str
    design: str
    design_size: int
    models_flown: int
    closed_loop_landed: int
    open_loop_landed: int
    seconds: float
    error: bool = False

    def values(self) -> dict[str, Any]:
        """The status values (``robust`` true/false, counts, reason)."""
        verdict = RobustVerdictValues(
            robust=self.robust, reason=self.reason, design=self.design, design_size=self.design_size,
            models_flown=self.models_flown, error=self.error,
        )  # fmt: skip
        return {
            **verdict.to_values(),
            "robust_closed_loop_landed": self.closed_loop_landed, "robust_open_loop_landed": self.open_loop_landed,
            "robust_seconds": round(self.seconds, 3),
        }  # fmt: skip


def summarise_verification(
    airframe: Airframe,
    settings: PlannerSettings,
    plan: LandingPlan,
    models: Sequence[PerturbedModel],
    policy: ClosedLoopSettings,
    design: str,
    stop_at_first_failure: bool = True,
) -> RobustSummary:
    """Verifies one plan robustly (in any process) and summarises the verdict; errors become ``error``."""
    from helireach_ros.core.planning.planner import get_planner
    from helireach_ros.core.robustness.verification import verify_plan_robust

    started = time.perf_counter()
    try:
        verdict = verify_plan_robust(
            plan, get_planner(airframe, settings), models, policy, design, stop_at_first_failure
        )
    except Exception as error:  # a model that cannot be integrated, a broken plan: never robust, say why
        return RobustSummary(
            False, f"robust verification failed: {type(error).__name__}: {error}", design, len(models), 0, 0, 0,
            time.perf_counter() - started, error=True,
        )  # fmt: skip
    return RobustSummary(
        robust=verdict.robust,
        reason=verdict.reason,
        design=design,
        design_size=verdict.design_size,
        models_flown=len(verdict.closed_loop),
        closed_loop_landed=verdict.closed_loop_landed,
        open_loop_landed=verdict.open_loop_landed,
        seconds=time.perf_counter() - started,
    )


def _lower_priority(niceness: int) -> None:
    os.nice(niceness)


def _build(airframe: Airframe, settings: PlannerSettings) -> float:
    """Builds the worker's planner (the first verification then pays no build time); seconds taken."""
    from helireach_ros.core.planning.planner import get_planner

    started = time.perf_counter()
    get_planner(airframe, settings)
    return time.perf_counter() - started


class BackgroundRobustVerification:
    """Plans verified robustly, one at a time, in a single low-priority worker process.

    Args:
        models: the perturbed models flown (e.g. ``uncertainty_set.verification_design()``).
        design: their description.
        policy: the closed loop's re-planning policy (each model's latency replaces its latency).
        stop_at_first_failure: fly no further model once one fails.
        niceness: added to the worker's nice value (19: only idle CPU).
        timeout_s: a verification without an answer this long after it was queued is given up (reported as an
            error: a worker that died takes its job with it, and a starved one says nothing).
    """

    def __init__(
        self,
        models: Sequence[PerturbedModel],
        design: str,
        policy: ClosedLoopSettings | None = None,
        stop_at_first_failure: bool = True,
        niceness: int = 19,
        timeout_s: float = 900.0,
    ) -> None:
        self.models = tuple(models)
        self.timeout_s = timeout_s
        self.design = design
        self.policy = policy or ClosedLoopSettings()
        self.stop_at_first_failure = stop_at_first_failure
        # A multiprocessing pool, not a ProcessPoolExecutor: close() must kill a verification that is running (tens
        # of seconds), which only Pool.terminate does; a worker that dies is replaced by the pool.
        context = multiprocessing.get_context("forkserver")
        self._pool = context.Pool(1, initializer=_lower_priority, initargs=(niceness,))
        self._lock = threading.Lock()
        self._jobs: list[tuple[Hashable, AsyncResult, float]] = []  # (key, job, monotonic time queued)

    def prepare(self, airframe: Airframe, settings: PlannerSettings) -> AsyncResult:
        """Builds the worker's planner for this airframe and settings ahead of the first plan."""
        return self._pool.apply_async(_build, (airframe, settings))

    def submit(self, key: Hashable, airframe: Airframe, settings: PlannerSettings, plan: LandingPlan) -> None:
        """Queues ``plan`` (made with ``airframe`` and ``settings``); its summary comes back under ``key``."""
        job = self._pool.apply_async(
            summarise_verification,
            (airframe, settings, plan, self.models, dataclasses.replace(self.policy), self.design,
             self.stop_at_first_failure),
        )  # fmt: skip
        with self._lock:
            self._jobs.append((key, job, time.monotonic()))

    @property
    def pending(self) -> int:
        """Verifications queued or running."""
        with self._lock:
            return sum(not job.ready() for _, job, _ in self._jobs)

    def finished(self) -> list[tuple[Hashable, RobustSummary]]:
        """The verifications done (or given up) since the last call, in submission order; a failed or timed-out
        job gives an error summary."""
        now = time.monotonic()
        with self._lock:
            done = [entry for entry in self._jobs if entry[1].ready() or now - entry[2] > self.timeout_s]
            self._jobs = [entry for entry in self._jobs if entry not in done]
        results = []
        for key, job, queued in done:
            if not job.ready():
                reason = f"robust verification failed: no verdict within {self.timeout_s:g} s"
                results.append((key, self._error(reason, now - queued)))
                continue
            try:
                results.append((key, job.get()))
            except Exception as error:  # e.g. a plan that could not be sent to the worker
                results.append((key, self._error(f"robust verification failed: {type(error).__name__}: {error}", 0.0)))
        return results

    def _error(self, reason: str, seconds: float) -> RobustSummary:
        return RobustSummary(False, reason, self.design, len(self.models), 0, 0, 0, seconds, error=True)

    def close(self) -> None:
        """Stops the worker at once; queued and running verifications are dropped."""
        self._pool.terminate()
        self._pool.join()
