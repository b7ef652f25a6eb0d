"""Robust verdicts for an envelope: which nominally safe nodes still land when the model is wrong.

For every node of an envelope's level slice that is ``safe`` (nominally: its plan replays to a landing
within limits in the model it was made with), :func:`~helireach_ros.core.robustness.verification.verify_robust`
flies the node's landing through every model of a design of the uncertainty set
(:meth:`~helireach_ros.core.flight.uncertainty.UncertaintySet.verification_design`, by default its 16
resolution-IV corners): closed loop with the planner node's re-planning policy and each model's latency,
and open loop with the plan as made. The node is ``robust`` when the closed loop lands within the true limits
in every model. The flights stop at the first model whose closed loop fails (``stop_at_first_failure``):
after it the verdict cannot change, and most of the cost of a not-robust node is saved.

Stored per node, beside the nominal status (arrays of the same grid shape; a file without them has no robust
verdict, and every reader treats it as before):

===================================  =====================================================================
``robust_code`` (int8)               :data:`ROBUST_CODES`: ``robust``, ``not_robust`` (a model failed closed
                                     loop), ``nominal_not_safe`` (not flown: robust needs nominal safety),
                                     ``not_computed`` (not flown: a climb slice other than level flight)
``robust_models_flown`` (int16)      closed-loop flights made (≤ the design's size when stopped early)
``robust_closed_loop_landed``        of those, landed within the true limits
``robust_open_loop_landed``          open-loop flights (the same models) that landed (reported only)
``robust_seconds`` (float32)         wall time of the node's verification, s
``robust_failure_attainable`` (int8) for a ``not_robust`` node: 1 when the first failing model has a safe
                                     landing of its own from the node (its own planner, cold: the policy
                                     lost it), 0 when it has none (no planner of this NLP could land it,
                                     up to IPOPT's local optimum); −1 otherwise
===================================  =====================================================================

The metadata's ``robust`` entry names the design, the models, the uncertainty set, the re-planning policy and
the cost. Only level-trim nodes are flown: the simulated vehicle starts from level trim
(:class:`~helireach_ros.core.flight.simulation.Scenario`); a 3-D envelope's other slices are ``not_computed``, and a
query there answers with the nominal verdict and says so (:meth:`Envelope.query
<helireach_ros.core.envelope.data.Envelope.query>`).

A node's task is independent of every other (no warm start passes between nodes; each re-solves its own
nominal plan warm from the stored one), so it runs on any executor of :mod:`.workers`: local processes or
Dask (``--dask-local N``, ``--scheduler``), with identical results.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.envelope.data import ROBUST_ARRAYS, ROBUST_CODES, Envelope, EnvelopeError
from helireach_ros.core.envelope.progress import NullProgress, Progress
from helireach_ros.core.envelope.workers import SerialExecutor
from helireach_ros.core.flight.uncertainty import PerturbedModel, UncertaintySet
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings

__all__ = ["LEVEL_TOLERANCE", "NodeRobustness", "RobustEnvelopeJob", "add_robust_verdicts", "verify_node"]

LEVEL_TOLERANCE = 1e-6
"""m/s: a climb slice within this of 0 is the level slice whose nodes are flown."""


@dataclass(frozen=True)
class RobustEnvelopeJob:
    """What the robust verdicts are computed for.

    Attributes:
        airframe, settings: the envelope's (checked against its metadata).
        uncertainty: the uncertainty set; its design is what is flown.
        policy: the re-planning policy of the closed loop (the planner node's); each model's latency replaces
            its ``latency``.
        stop_at_first_failure: fly no further model of a node once one fails (the verdict is settled).
        full_factorial: fly every corner of the set instead of its resolution-IV design.
    """

    airframe: Airframe
    settings: PlannerSettings
    uncertainty: UncertaintySet
    policy: ClosedLoopSettings = dataclasses.field(default_factory=ClosedLoopSettings)
    stop_at_first_failure: bool = True
    full_factorial: bool = False

    def models(self) -> tuple[PerturbedModel, ...]:
        """The models flown at each node, in order (the resolution-IV design starts at its worst corner)."""
        return self.uncertainty.corners() if self.full_factorial else self.uncertainty.verification_design()

    def design(self) -> str:
        """The design's name, as the metadata and the verdicts give it."""
        kind = "every corner" if self.full_factorial else "resolution-IV corners"
        return f"{kind} of {self.uncertainty.name!r} ({len(self.models())})"


@dataclass(frozen=True)
class NodeRobustness:
    """The robust verification of one node (what the envelope stores)."""

    code: int
    models_flown: int
    closed_loop_landed: int
    open_loop_landed: int
    seconds: float
    plans: int
    failure_attainable: int = -1


def verify_node(
    job: RobustEnvelopeJob, height: float, speed: float, power_fraction: float, warm_start
) -> NodeRobustness:
    """Flies one level-trim node (height m, speed m/s) through the job's models (a task: runs in any worker).

    The nominal plan is re-solved from the stored one (warm start) so the flights start from the planner's
    own plan; if that plan is not safe the node is ``nominal_not_safe`` without a flight.
    """
    from helireach_ros.core.flight.simulation import Scenario
    from helireach_ros.core.planning.planner import get_planner
    from helireach_ros.core.robustness.verification import failure_state, own_landing, verify_robust

    started = time.perf_counter()
    scenario = Scenario(name="envelope_node", height=height, forward_speed=speed, power_fraction=power_fraction)
    planner = get_planner(job.airframe, job.settings)
    plan = planner.plan(failure_state(scenario, job.airframe), warm_start=warm_start)
    if not plan.safe:
        return NodeRobustness(ROBUST_CODES["nominal_not_safe"], 0, 0, 0, time.perf_counter() - started, 1)
    verdict = verify_robust(
        scenario, planner, job.models(), job.policy, plan=plan, design=job.design(),
        stop_at_first_failure=job.stop_at_first_failure,
    )  # fmt: skip
    failure = verdict.first_failure
    attainable = -1
    if failure is not None:
        attainable = int(own_landing(failure.model, job.airframe, job.settings, height, speed, power_fraction).safe)
    return NodeRobustness(
        code=ROBUST_CODES["robust" if verdict.robust else "not_robust"],
        models_flown=len(verdict.closed_loop),
        closed_loop_landed=verdict.closed_loop_landed,
        open_loop_landed=verdict.open_loop_landed,
        seconds=time.perf_counter() - started,
        plans=1 + sum(outcome.plans + outcome.failed_plans for outcome in verdict.closed_loop),
        failure_attainable=attainable,
    )


def _node_task(job: RobustEnvelopeJob, node: tuple[int, ...], height: float, speed: float, power_fraction: float,
               warm_start) -> tuple[tuple[int, ...], NodeRobustness]:  # fmt: skip
    return node, verify_node(job, height, speed, power_fraction, warm_start)


def add_robust_verdicts(
    envelope: Envelope,
    job: RobustEnvelopeJob,
    executor=None,
    progress: Progress | None = None,
    command: str | None = None,
) -> Envelope:
    """The envelope with a robust verdict at every node (see the module docstring).

    Args:
        envelope: a complete envelope made for ``job.airframe`` and ``job.settings``.
        job: the uncertainty set, policy and design.
        executor: from :func:`~helireach_ros.core.envelope.workers.make_executor` (default: in this process).
        progress: progress reporting.
        command: the command line to record.

    Raises:
        EnvelopeError: a partial envelope, or one made for another airframe or other settings.
    """
    if not envelope.complete:
        raise EnvelopeError("robust verdicts need a complete envelope")
    envelope.check_matches(job.airframe, job.settings)
    executor = executor or SerialExecutor()
    progress = progress or NullProgress()
    arrays = envelope.arrays
    shape = arrays["status_code"].shape
    climbs = envelope.climb_rates if envelope.climb_rates is not None else np.zeros(1)
    level = [index for index, climb in enumerate(climbs) if abs(float(climb)) <= LEVEL_TOLERANCE]
    codes = np.full(shape, ROBUST_CODES["not_computed"], np.int8)
    flown, landed, open_landed = (np.zeros(shape, np.int16) for _ in range(3))
    seconds = np.zeros(shape, np.float32)
    attainable = np.full(shape, -1, np.int8)
    tasks = []
    for slice_index in level:
        for row, column in np.ndindex(envelope.heights.size, envelope.speeds.size):
            node = (slice_index, row, column) if envelope.is_3d else (row, column)
            if envelope.status[node] != "safe":
                codes[node] = ROBUST_CODES["nominal_not_safe"]
                continue
            stored = envelope.stored_plan(row, column, slice_index)
            # a node decided without the NLP (e.g. a touchdown within the reaction delay) stores no plan: cold
            warm_start = stored.warm_start if envelope.has_stored_plan(row, column, slice_index) else None
            tasks.append((job, node, stored.height, stored.speed, envelope.power_fraction, warm_start))
    started = time.perf_counter()
    plans = 0
    progress.start("robust verification", len(tasks))
    for node, result in executor.map_unordered(_node_task, tasks):
        codes[node], flown[node], landed[node] = result.code, result.models_flown, result.closed_loop_landed
        open_landed[node], seconds[node] = result.open_loop_landed, result.seconds
        attainable[node] = result.failure_attainable
        plans += result.plans
        progress.advance()
    progress.finish()
    wall = time.perf_counter() - started
    new_arrays = dict(arrays)
    new_arrays.update(zip(ROBUST_ARRAYS, (codes, flown, landed, open_landed, seconds, attainable), strict=True))
    metadata = envelope.metadata
    metadata["robust"] = _robust_metadata(job, codes, seconds, plans, wall, executor.description, command)
    metadata["robust"]["not_robust_failing_model_has_no_landing"] = int(np.sum(attainable == 0))
    metadata["robust"]["not_robust_failing_model_has_a_landing"] = int(np.sum(attainable == 1))
    return Envelope(new_arrays, metadata, envelope.solver_state)


def _robust_metadata(job: RobustEnvelopeJob, codes: np.ndarray, seconds: np.ndarray, plans: int, wall: float,
                     executor: str, command: str | None) -> dict[str, Any]:  # fmt: skip
    flown = seconds[(codes == ROBUST_CODES["robust"]) | (codes == ROBUST_CODES["not_robust"])]
    policy = dataclasses.asdict(job.policy)
    return {
        "design": job.design(),
        "models": [model.label for model in job.models()],
        "uncertainty": job.uncertainty.as_dict(),
        "policy": {name: value for name, value in policy.items() if name != "latency"},
        "latency": "each model's",
        "stop_at_first_failure": job.stop_at_first_failure,
        "counts": {name: int(np.sum(codes == code)) for name, code in ROBUST_CODES.items()},
        "cost": {
            "wall_time_s": round(wall, 3),
            "executor": executor,
            "nodes_flown": int(flown.size),
            "seconds_per_node_mean": round(float(np.mean(flown)), 3) if flown.size else None,
            "seconds_per_node_max": round(float(np.max(flown)), 3) if flown.size else None,
            "node_seconds_total": round(float(np.sum(flown)), 3),
            "plans_solved": plans,
        },
        "command": command,
    }
