"""Envelope families on a cluster: what running the members' tasks together buys, estimated from measured tasks.

Run: .venv/bin/python bench/family_scaling.py [--weights-lb 15000,17000] [--density-altitude-ft 0,4000]
     [--heights-ft 0:800:41] [--speeds-kt 0:120:25] [--estimate-workers 1,2,8,16,32,64,128]
     [--check-workers 2] [--overhead-tasks 400] [--json]

A cluster this machine does not have cannot be timed here, so the bench times what it can and composes the rest:

1. **Every task, timed.** Each member's planner is built first (timed: what every worker pays once per member it
   works on). The family is then computed with its members together (``helireach envelope compute --weights-lb …
   --density-altitude-ft …``, :func:`~helireach_ros.core.envelope.compute.compute_envelopes`) in this process, one
   task at a time; each task's wall time is recorded with the phase round it ran in (a round is one call of the
   executor: every round waits for the one before).
2. **The executors' cost per task**, measured with tasks that do nothing (``--overhead-tasks``) on 2 local
   processes and a Dask LocalCluster of 2 (as ``bench/envelope_throughput.py`` does).
3. **A schedule per worker count W**: each round's tasks go, in the order they were submitted, to the worker that
   is free first (what a process pool or Dask's scheduler does with equal workers), the scheduler hands out at
   most one task per its measured cost per task, and a worker's first task of a member first builds that member's
   planner; a round ends with its last task. Summed over rounds, for the members run one after another (each member
   alone: only its own tasks per round) and together.
4. **A check of the schedule**: the same family computed on ``--check-workers`` fresh local processes, its measured
   wall time (the processes' start-up included) against the schedule's estimate for that many workers.

What the estimate leaves out: a cluster's start-up, moving the envelopes' data (a task's arguments are a few kB, its
result up to ~100 kB of solver state), workers slower or faster than this machine's cores, and the load of other
processes here (printed with the numbers).
"""

from __future__ import annotations

import argparse
import heapq
import os
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
from _common import ENVELOPE_GRID, Record, add_json_argument, loadavg_text, machine_text
from envelope_throughput import _task_overhead

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.envelope.compute import EnvelopeJob, compute_envelopes
from helireach_ros.core.envelope.grid import parse_list, parse_range
from helireach_ros.core.envelope.workers import SerialExecutor, make_executor
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.units import FT, KT, LBF


class _TimedSerialExecutor(SerialExecutor):
    """Runs tasks one at a time in this process and records, per round (one ``map_unordered`` call), the
    (envelope slice index, phase function, wall seconds) of each task."""

    def __init__(self) -> None:
        self.rounds: list[list[tuple[int, str, float]]] = []

    def map_unordered(self, function: Callable[..., Any], tasks: Sequence[tuple[Any, ...]]) -> Iterator[Any]:
        timed: list[tuple[int, str, float]] = []
        self.rounds.append(timed)
        for task in tasks:  # compute's tasks are (slice index, phase function, arguments...)
            started = time.perf_counter()
            result = function(*task)
            timed.append((int(task[0]), getattr(task[1], "__name__", "?"), time.perf_counter() - started))
            yield result


def schedule_seconds(
    rounds: Sequence[Sequence[tuple[int, float]]], workers: int, per_task_s: float, build_s: Sequence[float]
) -> float:
    """Wall time of ``rounds`` of (member, seconds) tasks, one round after another: each round's tasks in
    submission order to the first free of ``workers``, the scheduler starting at most one task per ``per_task_s``, a
    worker's first task of member m preceded by ``build_s[m]``."""
    built: list[set[int]] = [set() for _ in range(workers)]
    total = 0.0
    for tasks in rounds:
        free = [(0.0, worker) for worker in range(workers)]
        finish = 0.0
        for index, (member, seconds) in enumerate(tasks):
            available, worker = heapq.heappop(free)
            start = max(available, index * per_task_s)
            if member not in built[worker]:
                built[worker].add(member)
                seconds += build_s[member]
            heapq.heappush(free, (start + seconds, worker))
            finish = max(finish, start + seconds)
        total += finish
    return total


def _estimates(
    rounds: list[list[tuple[int, str, float]]], build_s: Sequence[float], workers: int, per_task_s: float
) -> tuple[float, float]:
    """(one member after another, all together) estimated wall seconds on ``workers``."""
    tasks = [[(member, seconds) for member, _, seconds in round_tasks] for round_tasks in rounds]
    together = schedule_seconds(tasks, workers, per_task_s, build_s)
    alone = sum(
        schedule_seconds([[task for task in round_tasks if task[0] == member] for round_tasks in tasks], workers,
                         per_task_s, build_s)
        for member in range(len(build_s))
    )  # fmt: skip
    return alone, together


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--weights-lb", default="15000,17000", help="comma-separated gross weights (lbf)")
    parser.add_argument("--density-altitude-ft", default="0,4000", help="comma-separated density altitudes (ft)")
    parser.add_argument("--heights-ft", default=ENVELOPE_GRID.heights_ft)
    parser.add_argument("--speeds-kt", default=ENVELOPE_GRID.speeds_kt)
    parser.add_argument("--airframe", default="uh60a_class")
    parser.add_argument("--estimate-workers", default="1,2,8,16,32,64,128", help="worker counts to estimate")
    parser.add_argument("--check-workers", type=int, default=2, help="local processes to check the estimate (0: no)")
    parser.add_argument("--overhead-tasks", type=int, default=400, help="empty tasks per executor for its cost")
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    print(f"{machine_text()}; load average {loadavg_text()}")

    airframe = load_airframe(arguments.airframe)
    settings = load_settings()
    heights = parse_range(arguments.heights_ft, FT, "--heights-ft")
    speeds = parse_range(arguments.speeds_kt, KT, "--speeds-kt")
    conditions = [
        (weight, altitude)
        for weight in parse_list(arguments.weights_lb, "--weights-lb")
        for altitude in parse_list(arguments.density_altitude_ft, "--density-altitude-ft")
    ]
    jobs = [
        EnvelopeJob(
            airframe.with_conditions(gross_weight=weight * LBF, density_altitude=altitude * FT),
            settings, 0.0, heights, speeds,
        )
        for weight, altitude in conditions
    ]  # fmt: skip
    print(
        f"family: {len(jobs)} members ({', '.join(f'{w:g} lbf / DA {a:g} ft' for w, a in conditions)}), "
        f"{len(heights)} x {len(speeds)} nodes each, {arguments.airframe}"
    )

    build_s = []
    for job in jobs:
        started = time.perf_counter()
        get_planner(job.airframe, job.settings)
        build_s.append(time.perf_counter() - started)
    print(f"planners built in {', '.join(f'{seconds:.2f}' for seconds in build_s)} s (each worker builds its own)")
    timed = _TimedSerialExecutor()
    started = time.perf_counter()
    serial = compute_envelopes(jobs, timed)
    serial_wall = time.perf_counter() - started
    task_seconds = [d for tasks in timed.rounds for _, _, d in tasks]
    by_phase: dict[str, list[float]] = {}
    for tasks in timed.rounds:
        for _, phase, seconds in tasks:
            by_phase.setdefault(phase, []).append(seconds)
    print(
        f"\nin this process, one task at a time: {serial_wall:.1f} s, {len(task_seconds)} tasks in "
        f"{len(timed.rounds)} rounds ({sum(task_seconds):.1f} s in tasks); load average {loadavg_text()}"
    )
    phases = {}
    for phase, seconds in by_phase.items():
        values = np.array(seconds)
        phases[phase] = {
            "tasks": len(values), "sum_s": values.sum(), "median_s": np.median(values), "max_s": values.max(),
        }  # fmt: skip
        print(
            f"  {phase:<14} {len(values):5d} tasks, {values.sum():7.1f} s, median {np.median(values):.3f} s, "
            f"longest {values.max():.2f} s"
        )

    overheads = []
    if arguments.overhead_tasks:
        overheads.append(_task_overhead(2, False, arguments.overhead_tasks))
        overheads.append(_task_overhead(2, True, arguments.overhead_tasks))
    per_task = {item["executor"]: item["per_task_ms"] / 1e3 for item in overheads}
    executors = [("no scheduler cost", 0.0), *per_task.items()]

    counts = [int(count) for count in parse_list(arguments.estimate_workers, "--estimate-workers")]
    estimates = []
    print("\nestimated wall time (s): members one after another / together, speed-up of together over 1 worker")
    for name, cost in executors:
        one_worker = _estimates(timed.rounds, build_s, 1, cost)[1]
        for workers in counts:
            alone, together = _estimates(timed.rounds, build_s, workers, cost)
            estimates.append({
                "executor": name, "per_task_ms": 1e3 * cost, "workers": workers, "one_after_another_s": alone,
                "together_s": together, "speedup": one_worker / together, "efficiency": one_worker / together / workers,
            })  # fmt: skip
            print(
                f"  {name:<45} {workers:4d} workers: {alone:8.1f} / {together:8.1f}  "
                f"({one_worker / together:5.1f}x, {one_worker / together / workers:4.0%} of ideal)"
            )

    check = None
    if arguments.check_workers:
        load_before = loadavg_text()
        executor = make_executor(arguments.check_workers)
        started = time.perf_counter()
        try:
            checked = compute_envelopes(jobs, executor)
        finally:
            executor.close()
        wall = time.perf_counter() - started
        cost = per_task.get(executor.description, 0.0)
        estimate = _estimates(timed.rounds, build_s, arguments.check_workers, cost)[1]
        identical = all(np.array_equal(a.status, b.status) for a, b in zip(serial, checked, strict=True))
        check = {
            "workers": arguments.check_workers, "executor": executor.description, "measured_s": wall,
            "estimated_s": estimate, "ratio": wall / estimate, "identical_statuses": identical,
            "load": f"{load_before} -> {loadavg_text()}",
        }  # fmt: skip
        print(
            f"\ncheck: {executor.description}, together: measured {wall:.1f} s against {estimate:.1f} s estimated "
            f"({wall / estimate:.2f}x); statuses identical to the serial run: {identical}; load average "
            f"{check['load']}"
        )

    if arguments.json:
        record.write({
            "airframe": arguments.airframe, "grid": f"{arguments.heights_ft} ft x {arguments.speeds_kt} kt",
            "members": [{"weight_lb": w, "density_altitude_ft": a} for w, a in conditions],
            "nodes_per_member": len(heights) * len(speeds), "serial_wall_s": serial_wall,
            "tasks": len(task_seconds), "rounds": len(timed.rounds), "phases": phases, "planner_build_s": build_s,
            "task_overhead": overheads, "estimates": estimates, "check": check, "cpus": os.cpu_count(),
        })  # fmt: skip


if __name__ == "__main__":
    main()
