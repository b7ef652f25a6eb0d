"""Computing H-V envelopes: one verified landing plan per grid node, in parallel or on Dask.

For every node (h, V) of a height × speed grid, the helicopter flies level at trim when the
engine fails (:func:`~helireach_ros.core.aircraft.model.initial_state_after_failure`); the planner decides
whether a safe landing is reachable from there. The work runs in three phases:

1. **Sweep.** One task per speed column, heights ascending. The first node is solved cold; each
   next node is warm-started from the previous node's plan, whatever its status (a failed node has
   no plan: the next one is cold). A start from a plan that is not ``safe`` is only a guess, made
   after an ``unsafe`` node of value ≥ ``GUESS_MIN_PREVIOUS_VALUE`` (otherwise the node is solved
   cold, as the legacy sweep does): it is kept (``warm_from_not_safe``) when it answers ``unsafe`` with a
   value of at least ``NEAR_ZERO_VALUE`` (deep inside an unsafe band, where it saves the cold solve:
   a warm solve costs ~1/3 of a cold one); any other answer is replaced by a cold solve at once,
   since the re-check would need it and a false ``unsafe`` must not start the next node. A node on the
   ground (h ≤ 0: its plan touches down at once) starts no other: the node above it flies, and from the
   ground's plan IPOPT needed 75–178 iterations there against 17–81 cold (``GROUND_HEIGHT``). A node the
   NLP answers ``failed`` or ``unsafe`` is not replayed (a replay only ever confirms a landing): its
   ``replay_value`` is NaN and ``verified`` False; every node that may be ``safe`` is replayed.
2. **Cold re-check.** Every warm-started node whose value is near 0 (``|J| < NEAR_ZERO_VALUE``) or
   whose status differs from a 4-neighbour is solved again cold (:func:`_checked`): ``unsafe`` from
   either start wins, otherwise the node is ``safe`` if either start's plan is replay-verified — so a
   warm start never carries the NLP's word across the boundary, only a landing the replay checked. For
   a node started from a not-safe plan the cold answer decides alone (what the legacy sweep
   computes there). A node warm-started from a safe plan that answered ``unsafe`` is not re-solved:
   ``unsafe`` wins whatever the cold answer, so that solve cannot change the verdict.
   Repeated until no such node is left unchecked.
3. **Boundary refinement.** On every grid line between a safe and an unsafe node, the boundary is
   located to within ``2 ft`` / ``1 kt`` by regula falsi on the value (bisection as a safeguard),
   each trial warm-started from the plan of the current safe end. The final safe end is confirmed
   by a cold solve; if that disagrees, the search is redone from the last confirmed point with every
   safe answer confirmed cold. The stored boundary point is the last point proven safe (warm and
   cold), so the refined curve never moves into the unsafe set on a warm start's word.

Warm starts between tasks always pass through the stored float32 form of a plan, so the result
does not depend on where or in which order tasks ran: serial, local processes and a Dask cluster
give identical envelopes, and a resumed computation equals an uninterrupted one.

**3-D envelopes** (``climb_rates``): each climb-rate slice is a 2-D envelope of states trimmed on that flight
path, computed by exactly these phases; the slices' tasks run together in each phase (one pool or cluster
for all), and the result is their stack (:func:`~helireach_ros.core.envelope.data.stack_slices`). A node
whose (speed, climb rate) has no steady powered flight is stored as ``no_trim`` without a solve.

**Families** (one envelope per gross weight and density altitude): :func:`compute_envelopes` runs every
member's tasks together in each phase, as a 3-D envelope's slices, so a cluster gets the whole family's tasks.

Ctrl-C (or SIGTERM) saves a partial envelope file; ``resume=True`` continues it. Tasks that were
running are redone (a sweep task is one column, a few seconds of work).
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import math
import os
import platform
import signal
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from helireach_ros import __version__
from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.envelope.data import (
    FORMAT_NAME,
    FORMAT_VERSION_ANSWERS,
    PENDING,
    PLAN_STORAGE,
    STATUS_CODES,
    Envelope,
    EnvelopeError,
    read_envelope_file,
    save_envelope,
    stack_slices,
)
from helireach_ros.core.envelope.domain import ValidityDomain
from helireach_ros.core.envelope.progress import NullProgress, Progress
from helireach_ros.core.envelope.refinement import (
    REFINEMENT_ARRAY,
    NodeOrigin,
    check_refinable,
    classify,
    corners,
)
from helireach_ros.core.envelope.workers import SerialExecutor
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.units import FT, KT

__all__ = [
    "GROUND_HEIGHT",
    "HEIGHT_TOLERANCE",
    "NEAR_ZERO_VALUE",
    "SPEED_TOLERANCE",
    "ComputeInterrupted",
    "EnvelopeJob",
    "compute_envelope",
    "compute_envelopes",
]

if TYPE_CHECKING:
    from helireach_ros.core.ocp.compiled_nlp import CodegenSettings

log = logging.getLogger(__name__)

NEAR_ZERO_VALUE = 0.25
"""|J| below which a warm-started node is re-solved cold. Chosen when safe nodes far from the boundary sat near
−0.6 (the paper's rotor); with the momentum rotor they sit near −0.1 (99.6 % of the 81 × 49 level slice's safe
nodes within 0.25), so nearly every warm-started safe node is re-checked cold: 2,623 of the full grid's 6,888 solves
there."""
HEIGHT_TOLERANCE = 2.0 * FT
"""Boundary refinement along a height line stops when the bracket is this narrow, m."""
SPEED_TOLERANCE = 1.0 * KT
"""Boundary refinement along a speed line stops when the bracket is this narrow, m/s."""
GUESS_MIN_PREVIOUS_VALUE = 0.35
"""The sweep warm-starts the node above an unsafe node from its plan only if that node's value is at least
this; below it the next node is close to the band's edge and solved cold at once (measured on the shipped
grid: after the 53 unsafe nodes below 0.35, 1 warm answer would have been kept; after the 177 above, 165)."""
GROUND_HEIGHT = 0.0
"""m: a sweep node at or below this height is on the ground at the failure; its plan (touching down at once) is
no warm start for the node above, which is solved cold (measured on the shipped grid's 20 ft row: 2.9x fewer
IPOPT iterations, the same statuses; not with ``legacy_sweep``)."""
EXTRA_NODE_ARRAY = "warm_from_not_safe"
"""An array beyond the file format's required ones: nodes whose sweep solve started from a not-safe plan
(needed to resume exactly; a file without it reads as all False)."""
CHECKPOINT_INTERVAL_S = 60.0
"""A long computation saves a partial file this often (and always on Ctrl-C)."""

_SAFE, _UNSAFE, _UNVERIFIED, _FAILED, _NO_TRIM = (
    STATUS_CODES[name] for name in ("safe", "unsafe", "unverified", "failed", "no_trim")
)
_RANK = {_SAFE: 0, _UNVERIFIED: 1, _FAILED: 2, _NO_TRIM: 3, _UNSAFE: 4}


class ComputeInterrupted(KeyboardInterrupt):
    """The computation was interrupted; a partial file was saved (``path``) if an output was given."""

    def __init__(self, path: Path | None) -> None:
        super().__init__(f"interrupted; partial envelope saved to {path}" if path else "interrupted")
        self.path = path


@dataclass(frozen=True)
class EnvelopeJob:
    """What one envelope is computed for: airframe, settings, power-loss level and grid (SI).

    ``climb_rates`` (m/s, positive up, ascending) makes it a 3-D envelope, one slice per climb rate
    (:meth:`slice_jobs`); ``climb_rate`` is the flight path the nodes of a 2-D job (or of one slice) are
    trimmed on (0: level, today's envelope).
    """

    airframe: Airframe
    settings: PlannerSettings
    power_fraction: float
    heights: tuple[float, ...]
    speeds: tuple[float, ...]
    codegen: CodegenSettings | None = None
    """Compiled NLP functions or not (performance only, not recorded; None: the worker's environment)."""
    legacy_sweep: bool = False
    """The legacy sweep: cold restart after every not-safe node, not-safe nodes replayed, and a cold
    re-check of every candidate. Same classification, more cold solves; kept for same-run comparisons
    (``bench/envelope_throughput.py --baseline``)."""
    climb_rates: tuple[float, ...] | None = None
    """The climb axis of a 3-D envelope, m/s (None: a 2-D envelope at ``climb_rate``)."""
    climb_rate: float = 0.0
    """m/s, positive up: the flight path every node of this (2-D or slice) job is trimmed on."""
    refine_levels: int = 0
    """Boundary-following refinement over this many levels (:mod:`~helireach_ros.core.envelope.refinement`; 0: the
    full grid): the full procedure on every 2^levels-th node first, then per level only on the nodes of the cells
    whose corners disagree; the inside of a safe cell gets one warm solve per node, of an unsafe cell none. Needs
    2^levels k + 1 heights and speeds."""

    def __post_init__(self) -> None:
        axes = [("heights", self.heights, 2), ("speeds", self.speeds, 2)]
        if self.climb_rates is not None:
            axes.append(("climb_rates", self.climb_rates, 1))
        for name, axis, minimum in axes:
            values = np.asarray(axis, dtype=float)
            if (
                values.ndim != 1 or values.size < minimum or not np.all(np.isfinite(values))
                or np.any(np.diff(values) <= 0)
            ):  # fmt: skip
                raise ValueError(f"{name} must hold >= {minimum} finite, strictly ascending values")
        if not math.isfinite(self.climb_rate):
            raise ValueError(f"climb rate must be finite, got {self.climb_rate!r}")
        if not 0.0 <= self.power_fraction <= 1.0:
            raise ValueError(f"power fraction must lie in [0, 1], got {self.power_fraction!r}")
        if self.refine_levels:
            check_refinable((len(self.heights), len(self.speeds)), self.refine_levels)

    def slice_jobs(self) -> tuple[EnvelopeJob, ...]:
        """One 2-D job per climb slice (a 2-D job: itself)."""
        if self.climb_rates is None:
            return (self,)
        return tuple(dataclasses.replace(self, climb_rates=None, climb_rate=float(c)) for c in self.climb_rates)


@dataclass(frozen=True)
class _Solution:
    """One solve at one point, reduced to what the envelope stores (the solver state and the control function as
    float32, the initial state as float64)."""

    status: int
    value: float
    time_to_land: float
    replay_value: float
    verified: bool
    iterations: int
    solve_time_ms: float
    warm_started: bool
    primal: np.ndarray | None = None
    bound_multipliers: np.ndarray | None = None
    constraint_multipliers: np.ndarray | None = None
    control_times: np.ndarray | None = None
    control_values: np.ndarray | None = None
    control_interpolation: str = ""
    initial_state: np.ndarray | None = None  # (6,) SI: the state at the failure the plan starts from
    warm_from_not_safe: bool = False
    point_time_ms: float = 0.0  # solve + decode + replay in the task (phase accounting; not stored)
    point_cpu_ms: float = 0.0  # the same in CPU time of the worker (less sensitive to other load; not stored)
    discarded_solve_ms: float = 0.0  # IPOPT time of a warm guess replaced by this cold solve (not stored)
    origin: int = NodeOrigin.GRID  # how a refined envelope's node got its answer (stored only when refined)
    interpolation_replayed: bool = False  # a refinement replayed its corners' mean plan first (not stored)

    @property
    def conservatism(self) -> tuple[int, float]:
        return _RANK[self.status], (math.inf if math.isnan(self.value) else self.value)


def _more_conservative(first: _Solution, second: _Solution) -> _Solution:
    """The answer that claims less: worse status first, then the larger value; ties keep ``first``."""
    return second if second.conservatism > first.conservatism else first


def _checked(warm: _Solution, cold: _Solution) -> _Solution:
    """Combines a warm-started answer with the cold answer for the same point.

    An ``unsafe`` verdict from either start wins (the larger value if both). Otherwise the point is ``safe`` if
    either start's plan lands within limits in the independent replay (the cold one if both), and otherwise the
    more conservative of the two answers. A warm start never carries the NLP's word across the boundary: a ``safe``
    point has a replay-verified plan of its own, whichever start found it, and no start that calls it unsafe —
    the evidence a refinement's interior node rests on too. (Letting the cold answer decide alone marked
    ``unverified`` the nodes whose warm plan landed and whose cold plan overshot the rotor limits between collocation
    points, which the refinement's interior solves then called safe.)

    A warm answer started from a not-safe plan (``warm_from_not_safe``) is a guess: the cold answer
    decides alone, exactly as if the sweep had solved the node cold.
    """
    if warm.warm_from_not_safe:
        return cold
    if warm.status == _UNSAFE or cold.status == _UNSAFE:
        return _more_conservative(cold, warm)
    for answer in (cold, warm):
        if answer.status == _SAFE:
            return answer
    return _more_conservative(cold, warm)


def _warm_start_of(solution: _Solution):
    """The planner warm start stored in a solution (float32 → float64), or None without a plan."""
    from helireach_ros.core.planning.planner import WarmStart

    if solution.primal is None or solution.status in (_FAILED, _NO_TRIM):
        return None
    # a solution with a primal has its multipliers (the solver returns all three together)
    assert solution.bound_multipliers is not None and solution.constraint_multipliers is not None
    return WarmStart(
        solution.primal.astype(float),
        solution.bound_multipliers.astype(float),
        solution.constraint_multipliers.astype(float),
    )


def _solve_point(job: EnvelopeJob, height: float, speed: float, warm_start=None) -> _Solution:
    """One ``plan`` from trim on ``job.climb_rate`` at (height, speed) after the failure.

    A (speed, climb rate) without steady powered flight is ``no_trim`` (no solve, so not warm-started);
    solver errors become ``failed``. A safe plan is replayed again as the file stores it (its control function in
    float32); if that does not land within limits the node is ``unverified``, so every safe node's stored plan lands.
    """
    from helireach_ros.core.aircraft.model import initial_state_after_failure
    from helireach_ros.core.evidence.replay import replay_controls
    from helireach_ros.core.planning.planner import DECIDED_WITHOUT_NLP, get_planner

    started, started_cpu = time.perf_counter(), time.process_time()
    try:
        state = initial_state_after_failure(job.airframe, height, speed, job.power_fraction, climb_rate=job.climb_rate)
    except ValueError as error:  # e.g. a descent faster than the fuselage's terminal descent
        log.debug("no trim at V=%.2f m/s, climb %.2f m/s: %s", speed, job.climb_rate, error)
        return _Solution(_NO_TRIM, math.nan, math.nan, math.nan, False, -1, 0.0, False)
    try:
        planner = get_planner(job.airframe, job.settings, job.codegen)
        # a node the NLP finds failed or unsafe is not replayed (no replay can change that; not legacy_sweep)
        plan = planner.plan(state, warm_start, replay_not_safe=job.legacy_sweep)
    except (ValueError, RuntimeError) as error:
        log.debug("solve at h=%.2f m, V=%.2f m/s failed: %s", height, speed, error)
        return _Solution(_FAILED, math.nan, math.nan, math.nan, False, -1, 0.0, warm_start is not None)
    failed = plan.status == "failed"
    if plan.solver.status in DECIDED_WITHOUT_NLP:  # no NLP plan to store or to warm-start from
        return _Solution(
            STATUS_CODES[plan.status], plan.value, plan.time_to_land, plan.replay.value, plan.verified, 0, 0.0, False,
            point_time_ms=1e3 * (time.perf_counter() - started), point_cpu_ms=1e3 * (time.process_time() - started_cpu),
        )  # fmt: skip
    control_times, control_values = plan.control_times.astype(np.float32), plan.control_values.astype(np.float32)
    status, verified, replay_value = STATUS_CODES[plan.status], plan.verified, plan.replay.value
    if plan.status == "safe":
        # A safe node rests on the plan the file stores: its float32 control function must land in the replay too.
        stored = dataclasses.replace(plan, control_times=control_times, control_values=control_values)
        replayed = replay_controls(planner.airframe, planner.settings, plan.initial_state, stored, plan.disturbance)
        if not replayed.lands_within_limits:
            status, verified, replay_value = STATUS_CODES["unverified"], False, replayed.value
    return _Solution(
        status=status,
        value=math.nan if failed else plan.value,
        time_to_land=plan.time_to_land,
        replay_value=replay_value,
        verified=verified,
        iterations=plan.solver.iterations,
        solve_time_ms=plan.solver.solve_time_ms,
        warm_started=plan.solver.warm_started,
        primal=plan.warm_start.primal.astype(np.float32),
        bound_multipliers=_stored_bound_multipliers(
            plan.warm_start.bound_multipliers, job.settings.warm_start_bound_push
        ),
        constraint_multipliers=plan.warm_start.constraint_multipliers.astype(np.float32),
        control_times=control_times,
        control_values=control_values,
        control_interpolation=plan.control_interpolation,
        initial_state=np.asarray(plan.initial_state, np.float64),
        point_time_ms=1e3 * (time.perf_counter() - started),
        point_cpu_ms=1e3 * (time.process_time() - started_cpu),
    )


def _stored_bound_multipliers(multipliers: np.ndarray, floor: float) -> np.ndarray:
    """float32 multipliers, those below ``floor`` as 0.

    IPOPT's warm start raises every bound multiplier to ``warm_start_mult_bound_push`` (the settings'
    ``warm_start_bound_push``, passed as ``floor``) anyway, so the warm start is unchanged, and the zeros compress.
    """
    stored = multipliers.astype(np.float32)
    stored[np.abs(stored) < floor] = 0.0
    return stored


# --- tasks (module-level functions: they run in worker processes or on Dask workers) -----------------------


def _sweep_column(
    job: EnvelopeJob, column: int, rows: tuple[int, ...] | None = None
) -> tuple[str, int, tuple[int, ...], list[_Solution]]:
    """Phase 1: one speed column, heights ascending, each node warm-started from the previous node's plan.

    A start from a plan that is not safe is marked ``warm_from_not_safe`` (see :func:`_checked`); with
    ``job.legacy_sweep``, or after an unverified, failed or nearly safe unsafe node, or a node on the ground
    (:data:`GROUND_HEIGHT`), the node is solved cold. ``rows``: only these rows, ascending (default: all), each
    warm-started from the one solved before it.
    """
    speed = job.speeds[column]
    rows = tuple(range(len(job.heights))) if rows is None else rows
    solutions: list[_Solution] = []
    warm_start, previous_safe = None, True
    for height in (job.heights[row] for row in rows):
        solution = _solve_point(job, height, speed, warm_start)
        if warm_start is not None and not previous_safe:
            if solution.status == _UNSAFE and solution.value >= NEAR_ZERO_VALUE:
                solution = dataclasses.replace(solution, warm_from_not_safe=True)
            else:
                # near the boundary (or safe, or failed) the re-check would solve it cold anyway, and a false
                # "unsafe" must not be the start of the next node: solve cold now, as the legacy sweep did
                guess = solution
                solution = _solve_point(job, height, speed)
                solution = dataclasses.replace(
                    solution,
                    discarded_solve_ms=guess.solve_time_ms,
                    point_time_ms=solution.point_time_ms + guess.point_time_ms,
                    point_cpu_ms=solution.point_cpu_ms + guess.point_cpu_ms,
                )
        solutions.append(solution)
        previous_safe = solution.status == _SAFE
        worth_a_guess = solution.status == _UNSAFE and solution.value >= GUESS_MIN_PREVIOUS_VALUE
        warm_start = _warm_start_of(solution) if previous_safe or (worth_a_guess and not job.legacy_sweep) else None
        if height <= GROUND_HEIGHT and not job.legacy_sweep:
            warm_start = None
    return "sweep", column, rows, solutions


@dataclass(frozen=True)
class _CornerMean:
    """What a refinement's interior node takes from its corners: the mean of their solver states (a warm start)
    and of their stored control functions (a candidate plan, float32 as stored, landing at its last time)."""

    warm_start: Any  # planner.WarmStart
    controls: Any  # replay.StoredControls


def _corner_mean(solutions: list[_Solution]) -> _CornerMean | None:
    """The mean of the solutions' solver states and control functions (None if one has no NLP plan)."""
    from helireach_ros.core.evidence.replay import StoredControls
    from helireach_ros.core.planning.planner import WarmStart

    starts = [_warm_start_of(solution) for solution in solutions]
    times = [solution.control_times for solution in solutions if solution.control_times is not None]
    values = [solution.control_values for solution in solutions if solution.control_values is not None]
    if any(start is None for start in starts) or len(times) < len(solutions) or len(values) < len(solutions):
        return None
    warm_start = WarmStart(*(np.mean([getattr(start, name) for start in starts], axis=0) for name in (
        "primal", "bound_multipliers", "constraint_multipliers")))  # fmt: skip
    mean_times = np.mean(times, axis=0).astype(np.float32)
    controls = StoredControls(
        mean_times, np.mean(values, axis=0).astype(np.float32), solutions[0].control_interpolation,
        float(mean_times[-1]),
    )  # fmt: skip
    return _CornerMean(warm_start, controls)


def _interpolated_point(job: EnvelopeJob, height: float, speed: float, mean: _CornerMean) -> _Solution | None:
    """The node ``safe`` on its corners' mean plan, if that plan, replayed from the node's own state, lands within
    limits (otherwise None; the caller solves).

    The plan's first control is the node's own trim (the controls flown when the engine fails, where every NLP plan
    starts). Not with a reaction delay (the plan's delay segment holds its own node's trim) or the legacy sweep.
    """
    from helireach_ros.core.aircraft.model import initial_state_after_failure, trim_controls
    from helireach_ros.core.evidence.replay import replay_controls
    from helireach_ros.core.planning.planner import get_planner

    if job.legacy_sweep or job.settings.reaction_delay_s > 0.0:
        return None
    planner = get_planner(job.airframe, job.settings, job.codegen)
    try:
        state = initial_state_after_failure(job.airframe, height, speed, job.power_fraction, climb_rate=job.climb_rate)
    except ValueError:
        return None
    initial = state.as_array()
    values = mean.controls.control_values.copy()
    values[:, 0] = trim_controls(planner.airframe, initial)
    candidate = dataclasses.replace(mean.controls, control_values=values)
    replayed = replay_controls(planner.airframe, planner.settings, initial, candidate)
    if not replayed.lands_within_limits:
        return None
    start = mean.warm_start
    return _Solution(
        status=_SAFE,
        value=replayed.value,
        time_to_land=candidate.time_to_land,
        replay_value=replayed.value,
        verified=True,
        iterations=0,
        solve_time_ms=0.0,
        warm_started=False,
        primal=start.primal.astype(np.float32),
        bound_multipliers=_stored_bound_multipliers(start.bound_multipliers, job.settings.warm_start_bound_push),
        constraint_multipliers=start.constraint_multipliers.astype(np.float32),
        control_times=candidate.control_times,
        control_values=candidate.control_values,
        control_interpolation=candidate.control_interpolation,
        initial_state=np.asarray(initial, np.float64),
        origin=NodeOrigin.INTERPOLATED,
    )


def _interior_node(
    job: EnvelopeJob, row: int, column: int, mean: _CornerMean
) -> tuple[str, tuple[int, int], _Solution]:
    """Refinement: a node inside cells whose corners are all safe. Its corners' mean plan, if it lands from the
    node's own state (:func:`_interpolated_point`); otherwise one solve from its corners' mean solver state.

    The caller keeps a solved answer only if it is ``safe`` (the NLP's value ≤ 0 and the stored plan
    replay-verified).
    """
    height, speed = job.heights[row], job.speeds[column]
    started, started_cpu = time.perf_counter(), time.process_time()
    interpolated = _interpolated_point(job, height, speed, mean)
    replay_ms, replay_cpu_ms = 1e3 * (time.perf_counter() - started), 1e3 * (time.process_time() - started_cpu)
    if interpolated is not None:
        solution = dataclasses.replace(interpolated, point_time_ms=replay_ms, point_cpu_ms=replay_cpu_ms)
    else:
        solved = _solve_point(job, height, speed, mean.warm_start)
        solution = dataclasses.replace(
            solved,
            origin=NodeOrigin.INTERIOR,
            point_time_ms=solved.point_time_ms + replay_ms,
            point_cpu_ms=solved.point_cpu_ms + replay_cpu_ms,
        )
    return "interior", (row, column), dataclasses.replace(solution, interpolation_replayed=True)


def _cold_check(job: EnvelopeJob, row: int, column: int) -> tuple[str, tuple[int, int], _Solution]:
    """Phase 2: the node solved cold."""
    return "check", (row, column), _solve_point(job, job.heights[row], job.speeds[column])


@dataclass(frozen=True)
class _BoundaryPoint:
    edge: tuple[int, int, int, int]  # (row, column) of the safe node, then of the other node
    safe_point: tuple[float, float]  # (height m, speed m/s): the last point proven safe
    unsafe_point: tuple[float, float]  # the first point found not safe
    solves: int
    cold_solves: int
    solver_ms: float = 0.0  # IPOPT time of its solves (phase accounting; not stored)
    point_time_ms: float = 0.0  # solve + decode + replay time of its solves
    point_cpu_ms: float = 0.0  # the same in CPU time


def _next_trial(
    safe_end: float, safe_value: float, other_end: float, other_value: float, tolerance: float, bisect: bool
) -> float:
    """Where to solve next on the line between the safe end and the other end (scalars along the line).

    Regula falsi: the values straddle 0 (safe ≤ 0 < unsafe), so the linear zero crossing is a good
    guess of the boundary; the trial sits 0.45 × tolerance to one side of it, on the side that
    leaves the narrower bracket if the guess is right, so two good guesses close the bracket.
    Falls back to the midpoint when the values do not straddle 0 or ``bisect`` is set.
    """
    span = other_end - safe_end
    if bisect or not (math.isfinite(safe_value) and math.isfinite(other_value) and safe_value <= 0.0 < other_value):
        return safe_end + 0.5 * span
    root = safe_end + span * safe_value / (safe_value - other_value)
    offset = math.copysign(0.45 * tolerance, span)
    trial = root - offset if abs(other_end - root) <= abs(root - safe_end) else root + offset
    low, high = sorted((safe_end + 0.05 * span, other_end - 0.05 * span))
    return min(max(trial, low), high)


def _bisect_edge(
    job: EnvelopeJob, edge: tuple[int, int, int, int], safe_plan: _Solution, other_value: float
) -> tuple[str, tuple[int, int, int, int], _BoundaryPoint]:
    """Phase 3: locate the boundary between a safe node and an unsafe neighbour along their grid line.

    Trial points (regula falsi with a bisection safeguard, :func:`_next_trial`) are warm-started
    from the plan of the current safe end. The final safe end is then confirmed cold; if the cold
    answer is not safe, the warm search was optimistic somewhere, and the search restarts from the
    last confirmed point with every safe answer confirmed cold. The reported safe point is always
    one where both a warm and a cold solve (or the cold-checked node itself) say safe.
    """
    row0, column0, row1, column1 = edge
    along_height = column0 == column1
    axis = job.heights if along_height else job.speeds
    tolerance = HEIGHT_TOLERANCE if along_height else SPEED_TOLERANCE

    def point(position: float) -> tuple[float, float]:
        return (position, job.speeds[column0]) if along_height else (job.heights[row0], position)

    confirmed = (axis[row0 if along_height else column0], safe_plan.value, _warm_start_of(safe_plan))
    safe_end = confirmed
    other_end, other = axis[row1 if along_height else column1], other_value
    confirm_each = False
    solves = cold_solves = 0
    spent = [0.0, 0.0, 0.0]  # IPOPT ms, solve + replay ms, solve + replay CPU ms

    def solve(position: float, warm_start=None) -> _Solution:
        answer = _solve_point(job, *point(position), warm_start)
        spent[0] += answer.solve_time_ms
        spent[1] += answer.point_time_ms
        spent[2] += answer.point_cpu_ms
        return answer

    while True:
        bisect = False
        while abs(other_end - safe_end[0]) > tolerance:
            width = abs(other_end - safe_end[0])
            trial = _next_trial(safe_end[0], safe_end[1], other_end, other, tolerance, bisect)
            answer = solve(trial, safe_end[2])
            solves += 1
            if answer.status == _SAFE and (confirm_each or safe_end[2] is None):
                if safe_end[2] is not None:
                    answer = solve(trial)  # the boundary's points stand on cold answers
                    solves += 1
                    cold_solves += 1
                if answer.status == _SAFE:
                    confirmed = (trial, answer.value, _warm_start_of(answer))
            if answer.status == _SAFE:
                safe_end = (trial, answer.value, _warm_start_of(answer))
            else:
                other_end, other = trial, answer.value
            bisect = abs(other_end - safe_end[0]) > 0.5 * width  # a poor guess: bisect next
        if safe_end[0] == confirmed[0]:
            break
        cold = solve(safe_end[0])
        solves += 1
        cold_solves += 1
        if cold.status == _SAFE:
            break
        other_end, other = safe_end[0], cold.value
        safe_end, confirm_each = confirmed, True
    boundary = _BoundaryPoint(edge, point(safe_end[0]), point(other_end), solves, cold_solves, *spent)
    return "boundary", edge, boundary


class _InterruptGuard:
    """Turns Ctrl-C/SIGTERM into a request checked between tasks; a second Ctrl-C interrupts at once.

    A KeyboardInterrupt raised inside a CasADi solve could be reported by IPOPT as a stopped (failed)
    solve and stored as a result; a flag read between tasks cannot corrupt a result.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> _InterruptGuard:
        for signum in (signal.SIGINT, signal.SIGTERM):
            try:
                self._previous[signum] = signal.signal(signum, self._handle)
            except ValueError:  # not the main thread: leave signals alone
                break
        return self

    def __exit__(self, *exc_info: object) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum: int, frame: object) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def check(self) -> None:
        if self.requested:
            raise KeyboardInterrupt


# --- the computation's state -----------------------------------------------------------------------------


class _EnvelopeState:
    """Per-node results and boundary points so far; converts to (partial or complete) :class:`Envelope`."""

    def __init__(self, job: EnvelopeJob) -> None:
        self.job = job
        shape = (len(job.heights), len(job.speeds))
        self.shape = shape
        self.solutions: dict[tuple[int, int], _Solution] = {}
        self.cold_checked = np.zeros(shape, bool)
        self.disagree = np.zeros(shape, bool)
        self.boundary: dict[tuple[int, int, int, int], _BoundaryPoint] = {}
        self.counters = dict.fromkeys(
            ("sweep_solves", "sweep_warm_solves", "sweep_warm_from_not_safe", "sweep_guesses_replaced_cold",
             "cold_rechecks", "cold_rechecks_of_not_safe_starts", "cold_rechecks_changed_status",
             "rechecks_skipped_unsafe", "bisection_solves", "bisection_cold_solves", "no_trim_nodes",
             "interior_replays", "interior_interpolated", "interior_solves", "interior_kept",
             "inferred_unsafe_nodes"),
            0,
        )  # fmt: skip
        # per phase: IPOPT seconds and solve + decode + replay seconds summed over tasks (worker time)
        self.phase_solver_seconds: dict[str, float] = {}
        self.phase_point_seconds: dict[str, float] = {}
        self.phase_cpu_seconds: dict[str, float] = {}
        self.skipped_rechecks: set[tuple[int, int]] = set()

    # node access
    def codes(self) -> np.ndarray:
        codes = np.full(self.shape, PENDING, np.int8)
        for (row, column), solution in self.solutions.items():
            codes[row, column] = solution.status
        return codes

    def values(self) -> np.ndarray:
        values = np.full(self.shape, np.nan)
        for (row, column), solution in self.solutions.items():
            values[row, column] = solution.value
        return values

    def _account(self, phase: str, solver_ms: float, point_ms: float, cpu_ms: float) -> None:
        for seconds, spent_ms in (
            (self.phase_solver_seconds, solver_ms), (self.phase_point_seconds, point_ms),
            (self.phase_cpu_seconds, cpu_ms),
        ):  # fmt: skip
            seconds[phase] = seconds.get(phase, 0.0) + spent_ms / 1e3

    def set_column(self, column: int, rows: tuple[int, ...], solutions: list[_Solution]) -> None:
        for row, solution in zip(rows, solutions, strict=True):
            self.solutions[(row, column)] = solution
            self.cold_checked[row, column] = not solution.warm_started
        no_trim = sum(solution.status == _NO_TRIM for solution in solutions)
        self.counters["no_trim_nodes"] += no_trim
        self.counters["sweep_solves"] += len(solutions) - no_trim
        self.counters["sweep_warm_solves"] += sum(solution.warm_started for solution in solutions)
        self.counters["sweep_warm_from_not_safe"] += sum(solution.warm_from_not_safe for solution in solutions)
        self.counters["sweep_guesses_replaced_cold"] += sum(solution.discarded_solve_ms > 0 for solution in solutions)
        self._account(
            "sweep",
            sum(s.solve_time_ms + s.discarded_solve_ms for s in solutions),
            sum(s.point_time_ms for s in solutions),
            sum(s.point_cpu_ms for s in solutions),
        )

    def merge_cold(self, cell: tuple[int, int], cold: _Solution) -> None:
        current = self.solutions[cell]
        self.disagree[cell] = current.status != cold.status
        self.solutions[cell] = _checked(current, cold)
        self.cold_checked[cell] = True
        self.counters["cold_rechecks"] += 1
        self.counters["cold_rechecks_of_not_safe_starts"] += current.warm_from_not_safe
        self.counters["cold_rechecks_changed_status"] += self.solutions[cell].status != current.status
        self._account("cold re-check", cold.solve_time_ms, cold.point_time_ms, cold.point_cpu_ms)

    def set_interior(self, cell: tuple[int, int], solution: _Solution) -> None:
        """Keeps a refinement's interior node if it is safe (its plan replay-verified, interpolated or solved);
        otherwise the node stays pending."""
        self.counters["interior_replays"] += solution.interpolation_replayed
        self.counters["interior_interpolated"] += solution.origin == NodeOrigin.INTERPOLATED
        self.counters["interior_solves"] += solution.origin == NodeOrigin.INTERIOR
        self._account("interior", solution.solve_time_ms, solution.point_time_ms, solution.point_cpu_ms)
        if solution.status == _SAFE:
            self.solutions[cell] = solution
            # a plan of its own that lands in the replay is the node's evidence: not re-checked cold
            self.cold_checked[cell] = True
            self.counters["interior_kept"] += solution.origin == NodeOrigin.INTERIOR

    def infer_unsafe(self, cell: tuple[int, int], step: int) -> None:
        """A refinement's node inside cells whose corners are all unsafe: unsafe without a solve."""
        value = min(self.solutions[corner].value for corner in corners(*cell, step))
        self.solutions[cell] = _Solution(
            _UNSAFE, value, math.nan, math.nan, False, -1, 0.0, False, origin=NodeOrigin.INFERRED_UNSAFE
        )
        self.cold_checked[cell] = True
        self.counters["inferred_unsafe_nodes"] += 1

    def add_boundary(self, point: _BoundaryPoint) -> None:
        self.boundary[point.edge] = point
        self.counters["bisection_solves"] += point.solves
        self.counters["bisection_cold_solves"] += point.cold_solves
        self._account("boundary", point.solver_ms, point.point_time_ms, point.point_cpu_ms)

    # conversion
    def to_envelope(
        self, metadata: dict[str, Any], complete: bool, sizes: dict[str, tuple[int, ...]] | None = None
    ) -> Envelope:
        """This (2-D) grid as an envelope; ``sizes``: the plans' array shapes (default: from its own plans)."""
        shape = self.shape
        sizes = sizes or _plan_sizes(self.solutions.values())
        arrays: dict[str, np.ndarray] = {
            "heights": np.asarray(self.job.heights, float),
            "speeds": np.asarray(self.job.speeds, float),
            "status_code": self.codes(),
            "value": self.values(),
            "cold_checked": self.cold_checked.copy(),
            "warm_cold_disagree": self.disagree.copy(),
        }
        scalar_fields = {
            "time_to_land": (float, np.nan), "replay_value": (float, np.nan), "verified": (bool, False),
            "iterations": (np.int32, -1), "solve_time_ms": (np.float32, np.nan), "warm_started": (bool, False),
            EXTRA_NODE_ARRAY: (bool, False),
        } | ({REFINEMENT_ARRAY: (np.int8, NodeOrigin.GRID)} if self.job.refine_levels else {})  # fmt: skip
        for name, (dtype, fill) in scalar_fields.items():
            array = np.full(shape, fill, dtype)
            attribute = "origin" if name == REFINEMENT_ARRAY else name
            for cell, solution in self.solutions.items():
                array[cell] = getattr(solution, attribute)
            arrays[name] = array
        plan_fields = {
            "plan_primal": "primal", "plan_bound_multipliers": "bound_multipliers",
            "plan_constraint_multipliers": "constraint_multipliers", "plan_control_times": "control_times",
            "plan_control_values": "control_values", "plan_initial_state": "initial_state",
        }  # fmt: skip
        for name, attribute in plan_fields.items():
            dtype = np.float64 if name == "plan_initial_state" else np.float32
            array = np.full(shape + sizes[attribute], np.nan, dtype)
            for cell, solution in self.solutions.items():
                stored = getattr(solution, attribute)
                if stored is not None and stored.shape == sizes[attribute]:
                    array[cell] = stored
            arrays[name] = array
        edges = sorted(self.boundary)
        arrays["boundary"] = np.array([self.boundary[e].safe_point for e in edges], float).reshape(-1, 2)
        arrays["boundary_unsafe_side"] = np.array([self.boundary[e].unsafe_point for e in edges], float).reshape(-1, 2)
        arrays["boundary_edge"] = np.array(edges, np.int16).reshape(-1, 4)
        metadata = dict(metadata, complete=complete)
        metadata["control_interpolation"] = next(
            (s.control_interpolation for s in self.solutions.values() if s.control_interpolation), ""
        )
        return Envelope(arrays, metadata)

    @classmethod
    def from_envelope(cls, job: EnvelopeJob, envelope: Envelope, restore_counters: bool = True) -> _EnvelopeState:
        """The state of a (2-D) partial envelope; ``restore_counters``: continue its recorded counters."""
        state = cls(job)
        arrays = envelope.arrays
        interpolation = envelope.metadata.get("control_interpolation", "")
        for row, column in zip(*np.nonzero(arrays["status_code"] != PENDING), strict=True):
            cell = (int(row), int(column))
            # a partial file holds the solver state (resume warm-starts from it); a complete one may not
            primal = arrays["plan_primal"][cell] if "plan_primal" in arrays else np.full(0, np.nan)
            has_plan = bool(np.all(np.isfinite(primal))) and primal.size > 0
            times = arrays["plan_control_times"][cell]
            has_controls = bool(np.all(np.isfinite(times))) and times.size > 0 and "plan_initial_state" in arrays
            state.solutions[cell] = _Solution(
                status=int(arrays["status_code"][cell]),
                value=float(arrays["value"][cell]),
                time_to_land=float(arrays["time_to_land"][cell]),
                replay_value=float(arrays["replay_value"][cell]),
                verified=bool(arrays["verified"][cell]),
                iterations=int(arrays["iterations"][cell]),
                solve_time_ms=float(arrays["solve_time_ms"][cell]),
                warm_started=bool(arrays["warm_started"][cell]),
                primal=primal.copy() if has_plan else None,
                bound_multipliers=arrays["plan_bound_multipliers"][cell].copy() if has_plan else None,
                constraint_multipliers=arrays["plan_constraint_multipliers"][cell].copy() if has_plan else None,
                control_times=times.copy() if has_controls else None,
                control_values=arrays["plan_control_values"][cell].copy() if has_controls else None,
                control_interpolation=interpolation if has_controls else "",
                initial_state=arrays["plan_initial_state"][cell].copy() if has_controls else None,
                warm_from_not_safe=bool(arrays[EXTRA_NODE_ARRAY][cell]) if EXTRA_NODE_ARRAY in arrays else False,
                origin=int(arrays[REFINEMENT_ARRAY][cell]) if REFINEMENT_ARRAY in arrays else NodeOrigin.GRID,
            )
        state.cold_checked = arrays["cold_checked"].copy()
        state.disagree = arrays["warm_cold_disagree"].copy()
        for index, edge in enumerate(arrays["boundary_edge"].tolist()):
            slice_index, row, column, side = (int(e) for e in edge)
            key = (slice_index, row, column, side)
            state.boundary[key] = _BoundaryPoint(
                key, tuple(arrays["boundary"][index].tolist()), tuple(arrays["boundary_unsafe_side"][index].tolist()),
                0, 0,
            )  # fmt: skip
        compute = envelope.metadata.get("compute", {})
        if restore_counters:
            state.counters.update({k: int(v) for k, v in compute.get("counters", {}).items() if k in state.counters})
        return state


def _plan_sizes(solutions: Iterable[_Solution]) -> dict[str, tuple[int, ...]]:
    sizes: dict[str, tuple[int, ...]] = {}
    for solution in solutions:
        if solution.primal is not None and "primal" not in sizes:
            sizes |= {name: getattr(solution, name).shape for name in ("primal", "bound_multipliers",
                                                                       "constraint_multipliers")}  # fmt: skip
        if solution.control_times is not None and "control_times" not in sizes:
            sizes |= {name: getattr(solution, name).shape for name in ("control_times", "control_values")}
        if len(sizes) == 5:
            break
    defaults = {name: (0,) for name in ("primal", "bound_multipliers", "constraint_multipliers", "control_times")}
    return defaults | {"control_values": (2, 0)} | sizes | {"initial_state": (6,)}


# --- the driver -------------------------------------------------------------------------------------------


def _base_metadata(job: EnvelopeJob, command: str | None, grid_spec: dict[str, str] | None) -> dict[str, Any]:
    import casadi

    from helireach_ros.core.ocp.compiled_nlp import CodegenSettings

    airframe = job.airframe.as_dict() | {"digest": job.airframe.digest()}
    grid = dict(grid_spec or {}, heights_count=len(job.heights), speeds_count=len(job.speeds))
    domain = ValidityDomain(climb_rates=(job.climb_rate,) if job.climb_rates is None else tuple(job.climb_rates))
    three_d: dict[str, Any] = {}
    if job.climb_rates is not None:
        grid["climb_rates_count"] = len(job.climb_rates)
        three_d = {
            "climb_rates_m_s": [float(c) for c in job.climb_rates],
            "climb_rates_fpm": [round(float(c) / (FT / 60.0), 3) for c in job.climb_rates],
        }
    return {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION_ANSWERS,
        "description": (
            "H-V envelope: verified landing analysis from level trim after an engine failure on a height x speed grid"
            if job.climb_rates is None
            else "3-D H-V envelope: verified landing analysis from steady flight on a climb rate x height x speed "
            "grid after an engine failure"
        )
        + " (Kirchner et al. 2020 reachability; helireach_ros)",
        **three_d,
        "units": {
            "heights": "m",
            "speeds": "m/s",
            "value": "1 (<= 0: safe landing reachable)",
            "time_to_land": "s",
            "boundary": "(height m, speed m/s)",
            "margin": "ft and kt in one plane (1 ft = 1 kt = 1)",
            **({"climb_rates": "m/s, positive up"} if job.climb_rates is not None else {}),
        },
        "grid": grid,
        "airframe": airframe,
        "settings": dataclasses.asdict(job.settings),
        "method": job.settings.method,
        "power_fraction": float(job.power_fraction),
        # where the answers hold (trim at nominal rotor speed, within tolerances): core/envelope/domain.py
        "validity_domain": domain.to_metadata(),
        "status_codes": dict(STATUS_CODES, pending=PENDING),
        "plan_storage": PLAN_STORAGE,
        "refinement": {
            "near_zero_value": NEAR_ZERO_VALUE,
            "height_tolerance_m": HEIGHT_TOLERANCE,
            "speed_tolerance_m_s": SPEED_TOLERANCE,
            "sweep": "legacy (cold after not-safe nodes)" if job.legacy_sweep else "warm through not-safe nodes",
            "boundary_following_levels": job.refine_levels,
        },
        "software": {
            "helireach_ros": __version__,
            # requested: a worker without a C compiler solves with MUMPS (the answers agree;
            # docs/decisions/block-ldl.md)
            "linear_solver": (job.codegen or CodegenSettings.from_environment()).linear_solver,
            "casadi": casadi.CasadiMeta.version(),
            "numpy": np.__version__,
            "python": platform.python_version(),
        },
        "command": command,
    }


def _check_resumable(job: EnvelopeJob, envelope: Envelope, path: Path) -> None:
    where = f"partial envelope {str(path)!r}"
    envelope.check_matches(job.airframe, job.settings, job.power_fraction, where=where)
    levels = int(envelope.metadata.get("refinement", {}).get("boundary_following_levels", 0))
    if levels != job.refine_levels:
        raise EnvelopeError(f"{where} was computed with {levels} refinement level(s), not {job.refine_levels}; "
                            "resume it with the --refine-levels it was started with")  # fmt: skip
    if envelope.heights.shape != (len(job.heights),) or not np.allclose(envelope.heights, job.heights, atol=1e-9):
        raise EnvelopeError(f"{where} has another height grid than requested")
    if envelope.speeds.shape != (len(job.speeds),) or not np.allclose(envelope.speeds, job.speeds, atol=1e-9):
        raise EnvelopeError(f"{where} has another speed grid than requested")
    stored, requested = envelope.climb_rates, job.climb_rates
    if (stored is None) != (requested is None) or (
        stored is not None
        and requested is not None
        and (stored.shape != (len(requested),) or not np.allclose(stored, requested, atol=1e-9))
    ):
        raise EnvelopeError(f"{where} has another climb-rate axis than requested")


def _recheck_candidates(state: _EnvelopeState, step: int = 1) -> list[tuple[int, int]]:
    """Warm-solved nodes not yet checked cold whose value is near 0 or whose status differs from a neighbour.

    ``step``: only the nodes of every ``step``-th row and column (a refinement's coarser lattice, whose neighbours
    are ``step`` nodes apart).

    Nodes whose own warm answer is not ``safe`` go first: when the cold solve turns such a lone
    unverified node safe, its safe neighbours no longer differ from it and need no re-check. The
    loop over rounds ends at the same condition either way: no unchecked node is near 0 or differs.
    Unsafe answers warm-started from a safe plan are left out (their verdict cannot change, see
    :func:`_checked`), except with ``legacy_sweep``.
    """
    grid = (slice(None, None, step), slice(None, None, step))
    codes, values = state.codes()[grid], state.values()[grid]
    differs = np.zeros(codes.shape, bool)
    vertical, horizontal = codes[:-1, :] != codes[1:, :], codes[:, :-1] != codes[:, 1:]
    differs[:-1, :] |= vertical
    differs[1:, :] |= vertical
    differs[:, :-1] |= horizontal
    differs[:, 1:] |= horizontal
    with np.errstate(invalid="ignore"):
        near_zero = np.abs(values) < NEAR_ZERO_VALUE
    candidates = (codes != PENDING) & ~state.cold_checked[grid] & (near_zero | differs)
    if not state.job.legacy_sweep:
        # unsafe from a warm start out of a safe plan wins over any cold answer (_checked): nothing to learn
        verdict_fixed = np.zeros(state.shape, bool)
        for cell, solution in state.solutions.items():
            verdict_fixed[cell] = solution.status == _UNSAFE and not solution.warm_from_not_safe
        skipped = candidates & verdict_fixed[grid]
        state.skipped_rechecks.update((step * int(r), step * int(c)) for r, c in zip(*np.nonzero(skipped),
                                                                                     strict=True))  # fmt: skip
        state.counters["rechecks_skipped_unsafe"] = len(state.skipped_rechecks)
        candidates &= ~verdict_fixed[grid]
    not_safe_first = candidates & (codes != _SAFE)
    if np.any(not_safe_first):
        candidates = not_safe_first
    return [(step * int(r), step * int(c)) for r, c in zip(*np.nonzero(candidates), strict=True)]


def _boundary_edges(state: _EnvelopeState) -> list[tuple[int, int, int, int]]:
    """Grid-line neighbours (safe node first) where the other node is unsafe."""
    codes = state.codes()
    other = codes == _UNSAFE
    safe = codes == _SAFE
    edges = []
    rows, columns = state.shape
    for row in range(rows):
        for column in range(columns):
            if not safe[row, column]:
                continue
            for d_row, d_column in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                r, c = row + d_row, column + d_column
                if 0 <= r < rows and 0 <= c < columns and other[r, c]:
                    edges.append((row, column, r, c))
    return edges


def _in_slice(index: int, function: Callable[..., Any], *arguments: Any) -> tuple[int, Any]:
    """Runs one task of climb slice ``index`` (module level: it runs in worker processes or on Dask)."""
    return index, function(*arguments)


def compute_envelope(
    job: EnvelopeJob,
    executor=None,
    out_path: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress: Progress | None = None,
    command: str | None = None,
    grid_spec: dict[str, str] | None = None,
) -> Envelope:
    """Computes (or resumes) one envelope, 2-D or 3-D (``job.climb_rates``); saves it to ``out_path`` if given.

    Args:
        job: airframe, settings, power fraction and grid.
        executor: from :func:`make_executor` (default: serial in this process).
        out_path: the ``.npz`` to write (also where a partial file goes on Ctrl-C).
        resume: continue the partial file at ``out_path``.
        progress: progress reporting (default: none).
        command: the command line to record in the metadata.
        grid_spec: the grid as the user wrote it (recorded in the metadata).

    Returns:
        The complete envelope.

    Raises:
        ComputeInterrupted: on Ctrl-C/SIGTERM, after saving a partial file to ``out_path``.
        EnvelopeError: ``resume`` with a missing or incompatible partial file.
    """
    (envelope,) = compute_envelopes([job], executor, [out_path], resume, progress, command, grid_spec)
    return envelope


@dataclass
class _Member:
    """One envelope of a :func:`compute_envelopes` run: its slices' states, or the finished file it resumed."""

    job: EnvelopeJob
    path: Path | None
    metadata: dict[str, Any]
    states: list[_EnvelopeState]
    previous_wall_time_s: float = 0.0
    finished: Envelope | None = None  # complete before this run: nothing to compute


def _start_member(
    job: EnvelopeJob, path: Path | None, resume: bool, progress: Progress, command: str | None,
    grid_spec: dict[str, str] | None,
) -> _Member:  # fmt: skip
    """A member's states: fresh, or read back from its partial file."""
    member = _Member(job, path, _base_metadata(job, command, grid_spec), [])
    slice_jobs = job.slice_jobs()
    if not resume:
        member.states = [_EnvelopeState(slice_job) for slice_job in slice_jobs]
        return member
    if path is None:
        raise EnvelopeError("resume needs the output file of the interrupted computation")
    previous = read_envelope_file(path, allow_partial=True)
    _check_resumable(job, previous, path)
    if previous.complete:
        progress.message(f"{path}: already complete (envelope {previous.envelope_id}); nothing to do")
        member.finished = previous
        return member
    # the file's counters are totals over the slices: restored once, into the first slice
    member.states = [
        _EnvelopeState.from_envelope(slice_job, previous.slice(index), restore_counters=index == 0)
        for index, slice_job in enumerate(slice_jobs)
    ]
    member.previous_wall_time_s = float(previous.metadata.get("compute", {}).get("wall_time_s", 0.0))
    done = sum(len(state.solutions) for state in member.states)
    total = sum(math.prod(state.shape) for state in member.states)
    progress.message(f"{path}: resuming ({done} of {total} nodes done)")
    return member


def compute_envelopes(
    jobs: Sequence[EnvelopeJob],
    executor=None,
    out_paths: Sequence[str | os.PathLike[str] | None] | None = None,
    resume: bool | Sequence[bool] = False,
    progress: Progress | None = None,
    command: str | None = None,
    grid_spec: dict[str, str] | None = None,
) -> list[Envelope]:
    """Computes (or resumes) several envelopes together, e.g. a family's members over weight and density altitude.

    Every phase runs the tasks of every member at once, as a 3-D envelope's slices do, so a pool or cluster has a
    family's worth of tasks per phase (a 2-D member alone has one sweep task per speed column) and one progress
    display covers the family. Each member's result is what :func:`compute_envelope` computes for its job alone
    (a task's result does not depend on which others run beside it); all members complete at the end of the run.

    Args:
        jobs: one per member; all with the same ``refine_levels``.
        out_paths: one per member (None: not saved), where each member's partial file goes on Ctrl-C/SIGTERM and
            every ``CHECKPOINT_INTERVAL_S``.
        resume: continue the partial files (one flag for all, or one per member); a member whose file is
            complete is returned as it is.
        executor, progress, command, grid_spec: as for :func:`compute_envelope`.

    Returns:
        The complete envelopes, in the order of ``jobs``.

    Raises:
        ComputeInterrupted: on Ctrl-C/SIGTERM, after saving every member's partial file (``path``: the first
            member's file, or their common folder).
        EnvelopeError: resuming a missing or incompatible partial file.
        ValueError: no jobs, lengths that do not match, or different refinement levels.
    """
    executor = executor or SerialExecutor()
    progress = progress or NullProgress()
    paths = [None if path is None else Path(path) for path in (out_paths or [None] * len(jobs))]
    resumes = [bool(resume)] * len(jobs) if isinstance(resume, bool) else [bool(flag) for flag in resume]
    if not jobs or len(paths) != len(jobs) or len(resumes) != len(jobs):
        raise ValueError(f"{len(jobs)} jobs need as many output paths and resume flags")
    refine_levels = {job.refine_levels for job in jobs}
    if len(refine_levels) != 1:
        raise ValueError(f"envelopes computed together need one number of refinement levels, got {refine_levels}")
    (levels,) = refine_levels
    members = [
        _start_member(job, path, flag, progress, command, grid_spec)
        for job, path, flag in zip(jobs, paths, resumes, strict=True)
    ]
    running = [member for member in members if member.finished is None]
    if not running:
        return [member.finished for member in members if member.finished is not None]
    states = [state for member in running for state in member.states]
    together = {"members_computed_together": len(running)} if len(running) > 1 else {}
    saved_paths = [member.path for member in running if member.path is not None]
    if len(saved_paths) > 1 and len({path.parent for path in saved_paths}) == 1:
        interrupted_path: Path | None = saved_paths[0].parent
    else:
        interrupted_path = saved_paths[0] if saved_paths else None

    started = time.perf_counter()
    last_checkpoint = [time.monotonic()]
    phase_seconds: dict[str, float] = {}
    phase_tasks: dict[str, int] = {}  # tasks submitted per phase, this run

    def summed(member: _Member, name: str) -> dict[str, float]:
        total: dict[str, float] = {}
        for state in member.states:
            for phase, seconds in getattr(state, name).items():
                total[phase] = total.get(phase, 0.0) + seconds
        return {phase: round(seconds, 3) for phase, seconds in total.items()}

    def snapshot(member: _Member, complete: bool) -> Envelope:
        member_states = member.states
        counters = {name: sum(state.counters[name] for state in member_states) for name in member_states[0].counters}
        compute = {
            "wall_time_s": round(member.previous_wall_time_s + time.perf_counter() - started, 3),
            # the run's phases and tasks: every member's together when several were computed at once
            "phases_s": {k: round(v, 3) for k, v in phase_seconds.items()},
            "tasks": dict(phase_tasks),
            **together,
            # summed over workers, this member and this run only (a resumed run counts what it computed itself)
            "phase_ipopt_s": summed(member, "phase_solver_seconds"),
            "phase_solve_and_replay_s": summed(member, "phase_point_seconds"),
            "phase_solve_and_replay_cpu_s": summed(member, "phase_cpu_seconds"),
            "executor": executor.description,
            "counters": counters,
            "nodes": sum(math.prod(state.shape) for state in member_states),
            "boundary_points": sum(len(state.boundary) for state in member_states),
            "finished_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds") if complete else None,
        }
        metadata_now = dict(member.metadata, compute=compute)
        if member.job.climb_rates is None:
            return member_states[0].to_envelope(metadata_now, complete)
        sizes = _plan_sizes(solution for state in member_states for solution in state.solutions.values())
        slices = [state.to_envelope(metadata_now, complete, sizes) for state in member_states]
        return stack_slices(slices, member.job.climb_rates, dict(metadata_now, complete=complete))

    def save_partial(*, only_started: bool = False) -> None:
        """Every running member's partial file (``only_started``: only of members with a node solved)."""
        for member in running:
            if member.path is None or (only_started and not any(state.solutions for state in member.states)):
                continue
            save_envelope(snapshot(member, complete=False), member.path)

    def checkpoint() -> None:
        if time.monotonic() - last_checkpoint[0] > CHECKPOINT_INTERVAL_S:
            save_partial()
            last_checkpoint[0] = time.monotonic()

    def run_phase(name: str, function, tasks: list[tuple], units: Callable[[Any], int], handle) -> None:
        """Runs ``function`` on tasks (slice index, arguments...); ``handle(state, result)`` takes each result."""
        phase_started = time.perf_counter()
        phase_tasks[name] = phase_tasks.get(name, 0) + len(tasks)
        progress.start(name, sum(units(arguments) for _, *arguments in tasks))
        try:
            for index, result in executor.map_unordered(
                _in_slice, [(index, function, *arguments) for index, *arguments in tasks]
            ):
                handle(states[index], result)
                progress.advance(units(result))
                guard.check()
                checkpoint()
        finally:
            phase_seconds[name] = phase_seconds.get(name, 0.0) + time.perf_counter() - phase_started
            progress.finish()

    guard = _InterruptGuard()
    try:
        guard.__enter__()
        guard.check()

        def sweep(name: str, step: int) -> None:
            """The sweep over the pending nodes of every ``step``-th column and row, then their cold re-checks."""
            sweeps = [
                (index, state.job, column, pending)
                for index, state in enumerate(states)
                for column in range(0, len(state.job.speeds), step)
                if (pending := tuple(row for row in range(0, len(state.job.heights), step)
                                     if (row, column) not in state.solutions))
            ]  # fmt: skip
            run_phase(
                name, _sweep_column, sweeps,
                lambda item: len(item[-1]),  # a task's pending rows, a result's solutions
                lambda state, result: state.set_column(result[1], result[2], result[3]),
            )  # fmt: skip
            while candidates := [
                (index, state.job, row, column)
                for index, state in enumerate(states)
                for row, column in _recheck_candidates(state, step)
            ]:
                run_phase(
                    "cold re-check", _cold_check, candidates,
                    lambda item: 1, lambda state, result: state.merge_cold(result[1], result[2]),
                )  # fmt: skip

        if levels:
            step = 2**levels
            sweep("coarse sweep", step)
            while step > 1:
                step //= 2
                interior = []
                for index, state in enumerate(states):
                    inside_safe, inside_unsafe = classify(state.codes(), step, (_SAFE,), _UNSAFE)
                    for row, column in zip(*np.nonzero(inside_unsafe), strict=True):
                        if (row, column) not in state.solutions:
                            state.infer_unsafe((int(row), int(column)), step)
                    for row, column in zip(*np.nonzero(inside_safe), strict=True):
                        cell = (int(row), int(column))
                        if cell in state.solutions:  # a resumed run's
                            continue
                        mean = _corner_mean([state.solutions[corner] for corner in corners(*cell, step)])
                        if mean is not None:  # a corner decided without the NLP: the full procedure
                            interior.append((index, state.job, *cell, mean))
                run_phase(
                    "interior", _interior_node, interior,
                    lambda item: 1, lambda state, result: state.set_interior(result[1], result[2]),
                )  # fmt: skip
                if step > 1:
                    sweep("refinement sweep", step)
        sweep("sweep", 1)
        edges = [
            (index, state.job, edge, state.solutions[edge[:2]], state.solutions[edge[2:]].value)
            for index, state in enumerate(states)
            for edge in _boundary_edges(state)
            if edge not in state.boundary
        ]
        run_phase(
            "boundary", _bisect_edge, edges,
            lambda item: 1, lambda state, result: state.add_boundary(result[2]),
        )  # fmt: skip
    except KeyboardInterrupt:
        executor.abort()
        save_partial()
        raise ComputeInterrupted(interrupted_path) from None
    except Exception:
        # e.g. a Dask worker without helireach_ros: keep what was computed, then report the error
        executor.abort()
        save_partial(only_started=True)
        raise
    finally:
        guard.__exit__()
    # Boundary points of edges that are no longer safe/not-safe pairs (resume after a change) are dropped.
    for state in states:
        current_edges = set(_boundary_edges(state))
        state.boundary = {edge: point for edge, point in state.boundary.items() if edge in current_edges}
    for member in running:
        member.finished = snapshot(member, complete=True).answers()  # as the file holds it, solver state and all
        if member.path is not None:
            save_envelope(member.finished, member.path)
    return [member.finished for member in members if member.finished is not None]
