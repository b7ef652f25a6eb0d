"""H-V envelope throughput: wall time and nodes/s for a full grid with 1 and 2 workers, and where the time goes.

Run: .venv/bin/python bench/envelope_throughput.py [--workers 1,2] [--dask-local 2] [--heights-ft 0:800:41]
     [--speeds-kt 0:120:25] [--overhead-tasks 400] [--baseline] [--repeat N] [--json]

Each run is the complete pipeline of ``helireach envelope compute`` (sweep, cold re-checks, boundary
refinement) with the default airframe and planner settings; 1 worker runs in this process, more use a
local process pool (worker start-up included). Prints per run: wall time, nodes/s, the share of nodes
re-solved cold, solve counts, per-phase wall time; then, from a few sweep columns timed in this process,
how a node's time splits between IPOPT and the rest of ``plan`` (decode + CVODES replay). The machine's
load average is printed too: other processes on a shared machine slow every number here. ``--json`` also writes
the numbers to docs/results/data/envelope_throughput.json.

Scaling: every run also prints nodes per core-second (nodes / (wall time × workers)). ``--dask-local N`` adds runs on
a Dask ``LocalCluster`` of N single-threaded worker processes (the executor of ``envelope compute --dask-local``). The
executors' own cost per task is measured with ``--overhead-tasks`` tasks that do nothing (submitted as the envelope's
are, results gathered as they finish) on each executor: per task, what a scheduler adds to a task's solve time; with
the envelope's task count per phase it bounds what a larger cluster would spend on scheduling.

``--baseline`` runs, for each worker count, the legacy configuration (legacy sweep: cold restart
after every not-safe node, every node replayed; the warm-solver options of then; plain CasADi functions; MUMPS; the
planner's own answers, such as a failure on the ground decided without the NLP, are the same in both) and the
current one, alternating ``--repeat`` times, and prints the ratio of their wall times (the comparison that holds on a
busy machine) and whether the two envelopes classify every node identically.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np
from _common import ENVELOPE_GRID, Record, StateGrid, add_json_argument, loadavg_text, machine_text
from baseline_config import baseline_codegen, baseline_settings

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.envelope.compute import EnvelopeJob, _solve_point, _warm_start_of, compute_envelope
from helireach_ros.core.envelope.data import STATUS_CODES
from helireach_ros.core.envelope.workers import make_executor
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import get_planner


def _baseline_job(job: EnvelopeJob) -> EnvelopeJob:
    return dataclasses.replace(
        job, settings=baseline_settings(job.settings), codegen=baseline_codegen(), legacy_sweep=True
    )


def _nothing(value: int) -> int:
    return value


def _task_overhead(workers: int, dask_local: bool, tasks: int) -> dict:
    """Wall time per task of ``tasks`` tasks that do nothing on a fresh executor (start-up not counted): what the
    executor itself costs per task, printed and returned."""
    executor = make_executor(None, dask_local=workers) if dask_local else make_executor(workers)
    try:
        list(executor.map_unordered(_nothing, [(index,) for index in range(min(tasks, 20))]))  # workers started
        started = time.perf_counter()
        results = list(executor.map_unordered(_nothing, [(index,) for index in range(tasks)]))
        wall = time.perf_counter() - started
    finally:
        executor.close()
    assert sorted(results) == list(range(tasks))
    per_task_ms = 1e3 * wall / tasks
    print(
        f"  executor overhead    {executor.description}: {tasks} empty tasks in {wall:.2f} s, {per_task_ms:.2f} ms "
        f"per task ({per_task_ms * workers:.2f} ms of worker time per task); load average {loadavg_text()}"
    )
    return {
        "executor": executor.description, "workers": workers, "tasks": tasks, "wall_s": wall,
        "per_task_ms": per_task_ms, "worker_ms_per_task": per_task_ms * workers,
    }  # fmt: skip


def _run(
    job: EnvelopeJob, workers: int, label: str = "", *, dask_local: bool = False
) -> tuple[float, float, np.ndarray, dict]:
    """Computes the envelope with ``workers`` (local processes, or a Dask LocalCluster) and prints where the time
    went; returns the wall time, the workers' CPU time, the nodes' statuses and the printed numbers."""
    load_before = os.getloadavg()[0]
    started = time.perf_counter()
    executor = make_executor(None, dask_local=workers) if dask_local else make_executor(workers)
    try:
        envelope = compute_envelope(job, executor)
    finally:
        executor.close()
    wall = time.perf_counter() - started
    compute = envelope.metadata["compute"]
    counters = compute["counters"]
    nodes = envelope.status.size
    solves = counters["sweep_solves"] + counters["cold_rechecks"] + counters["bisection_solves"]
    counts = {name: int((envelope.status == name).sum()) for name in ("safe", "unsafe", "unverified", "failed")}
    phases = ", ".join(f"{name} {seconds:.1f} s" for name, seconds in compute["phases_s"].items())
    print(f"\n{workers} worker(s) [{executor.description}]{label}")
    print(
        f"  wall time            {wall:7.1f} s   ({nodes / wall:.1f} nodes/s, {solves / wall:.1f} solves/s, "
        f"{nodes / (wall * workers):.2f} nodes per core-second)"
    )
    tasks = compute.get("tasks", {})
    if tasks:
        print(f"  tasks                {', '.join(f'{name} {count}' for name, count in tasks.items())}")
    print(f"  phases               {phases}")
    worker_time = ", ".join(
        f"{name} {compute['phase_ipopt_s'].get(name, 0.0):.1f} s IPOPT of {seconds:.1f} s solve+replay"
        for name, seconds in compute["phase_solve_and_replay_s"].items()
    )
    print(f"  worker time          {worker_time}")
    cpu = compute["phase_solve_and_replay_cpu_s"]
    print(f"  worker CPU time      {sum(cpu.values()):.1f} s ({', '.join(f'{k} {v:.1f} s' for k, v in cpu.items())})")
    sweep_cold = (
        counters["sweep_solves"] - counters["sweep_warm_solves"] + counters.get("sweep_guesses_replaced_cold", 0)
    )
    print(
        f"  sweep                {sweep_cold} cold solves, {counters.get('sweep_warm_from_not_safe', 0)} kept warm "
        f"answers started from not-safe plans, {counters.get('sweep_guesses_replaced_cold', 0)} replaced cold; "
        f"re-checks skipped (verdict fixed) {counters.get('rechecks_skipped_unsafe', 0)}"
    )
    print(f"  nodes re-solved cold {counters['cold_rechecks'] / nodes:7.1%}  ({counters['cold_rechecks']} of {nodes})")
    print(
        f"  solves               {solves} = sweep {counters['sweep_solves']} ({counters['sweep_warm_solves']} warm) "
        f"+ re-checks {counters['cold_rechecks']} + boundary {counters['bisection_solves']} "
        f"({counters['bisection_cold_solves']} cold) for {len(envelope.boundary)} boundary points"
    )
    not_replayed = int(np.isnan(envelope.arrays["replay_value"]).sum())
    without_nlp = int((envelope.arrays["iterations"] == 0).sum())
    print(
        f"  result               {counts}, envelope {envelope.envelope_id}; {not_replayed} nodes not replayed "
        f"(NLP unsafe/failed), {without_nlp} decided without the NLP (on the ground)"
    )
    load_after = os.getloadavg()[0]
    print(f"  load average         {load_before:.2f} before, {load_after:.2f} after")
    numbers = {
        "workers": workers, "executor": executor.description, "configuration": label.strip() or "current",
        "nodes": nodes, "wall_s": wall, "nodes_per_s": nodes / wall, "solves_per_s": solves / wall,
        "nodes_per_core_s": nodes / (wall * workers), "tasks": tasks,
        "phases_s": compute["phases_s"],
        "worker_ipopt_s": compute["phase_ipopt_s"], "worker_solve_and_replay_s": compute["phase_solve_and_replay_s"],
        "worker_cpu_s": sum(cpu.values()), "sweep_cold_solves": sweep_cold,
        "cold_recheck_share": counters["cold_rechecks"] / nodes, "solves": solves, "counters": counters,
        "boundary_points": len(envelope.boundary), "statuses": counts, "envelope_id": envelope.envelope_id,
        "not_replayed": not_replayed, "decided_without_nlp": without_nlp,
        "load_1min_before": load_before, "load_1min_after": load_after,
    }  # fmt: skip
    return wall, sum(cpu.values()), envelope.status.copy(), numbers


def _time_split(job: EnvelopeJob, columns: list[int]) -> dict:
    """IPOPT versus the rest of plan() (decode + replay), per node, over a few sweep columns in this process:
    prints and returns it."""
    get_planner(job.airframe, job.settings)  # built before timing
    ipopt_ms, total_ms, iterations = [], [], []
    for column in columns:
        warm_start = None
        for height in job.heights:
            started = time.perf_counter()
            solution = _solve_point(job, height, job.speeds[column], warm_start)  # as the sweep does
            total_ms.append(1e3 * (time.perf_counter() - started))
            ipopt_ms.append(solution.solve_time_ms)
            iterations.append(solution.iterations)
            warm_start = _warm_start_of(solution) if solution.status == STATUS_CODES["safe"] else None
    ipopt, total = np.array(ipopt_ms), np.array(total_ms)
    rest = total - ipopt
    print(f"\ntime per node over {len(total)} sweep solves (columns {columns}, 1 process)")
    print(f"  plan() total   median {np.median(total):6.1f} ms, mean {total.mean():6.1f} ms")
    print(
        f"  IPOPT          median {np.median(ipopt):6.1f} ms, mean {ipopt.mean():6.1f} ms "
        f"({ipopt.sum() / total.sum():.0%}), {np.mean(iterations):.1f} iterations on average, "
        f"{ipopt.sum() / np.sum(iterations):.2f} ms per iteration"
    )
    print(
        f"  decode+replay  median {np.median(rest):6.1f} ms, mean {rest.mean():6.1f} ms "
        f"({rest.sum() / total.sum():.0%})"
    )
    return {
        "columns": columns, "solves": len(total),
        "plan_ms": {"median": np.median(total), "mean": total.mean()},
        "ipopt_ms": {"median": np.median(ipopt), "mean": ipopt.mean(), "share": ipopt.sum() / total.sum()},
        "iterations_mean": np.mean(iterations), "ipopt_ms_per_iteration": ipopt.sum() / np.sum(iterations),
        "decode_replay_ms": {"median": np.median(rest), "mean": rest.mean(), "share": rest.sum() / total.sum()},
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts (default: %(default)s)")
    parser.add_argument(
        "--dask-local", default="", help="comma-separated Dask LocalCluster sizes to run too (e.g. 2; default: none)"
    )
    parser.add_argument(
        "--overhead-tasks", type=int, default=400, help="empty tasks per executor for its per-task cost (0: skip)"
    )
    parser.add_argument("--heights-ft", default=ENVELOPE_GRID.heights_ft)
    parser.add_argument("--speeds-kt", default=ENVELOPE_GRID.speeds_kt)
    parser.add_argument("--airframe", default="uh60a_class")
    parser.add_argument("--baseline", action="store_true", help="also run the legacy configuration")
    parser.add_argument("--repeat", type=int, default=1, help="with --baseline: alternating runs of each")
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    airframe, settings = load_airframe(arguments.airframe), load_settings()
    grid = StateGrid(arguments.heights_ft, arguments.speeds_kt)
    job = EnvelopeJob(airframe, settings, 0.0, grid.heights_si(), grid.speeds_si())
    print(
        f"envelope throughput: {airframe.name}, {len(job.heights)} x {len(job.speeds)} grid "
        f"({arguments.heights_ft} ft, {arguments.speeds_kt} kt), method {settings.method}, {settings.intervals} "
        f"intervals; {machine_text()}"
    )
    print(f"command: {record.command}; load average {record.load_before}")
    numbers: dict = {
        "airframe": airframe.name, "grid": grid.describe(), "method": settings.method,
        "intervals": settings.intervals, "runs": [], "baseline_ratios": [],
    }  # fmt: skip
    for workers in (int(item) for item in arguments.workers.split(",")):
        if not arguments.baseline:
            numbers["runs"].append(_run(job, workers)[3])
            continue
        walls: dict[str, list[float]] = {"baseline": [], "current": []}
        cpus: dict[str, list[float]] = {"baseline": [], "current": []}
        statuses = {}
        for _ in range(arguments.repeat):
            for name, variant in (("baseline", _baseline_job(job)), ("current", job)):
                wall, cpu, statuses[name], run = _run(variant, workers, f" {name}")
                walls[name].append(wall)
                cpus[name].append(cpu)
                numbers["runs"].append(run)
        same = int(np.sum(statuses["baseline"] == statuses["current"]))
        ratios = [current / base for current, base in zip(walls["current"], walls["baseline"], strict=True)]
        overall = np.sum(walls["current"]) / np.sum(walls["baseline"])
        cpu_ratio = np.sum(cpus["current"]) / np.sum(cpus["baseline"])
        print(
            f"\n{workers} worker(s): current / baseline wall time {overall:.3f}x "
            f"(per pair {', '.join(f'{r:.3f}' for r in ratios)}), worker CPU time {cpu_ratio:.3f}x; "
            f"identical classification {same} of "
            f"{statuses['current'].size} nodes; load average {loadavg_text()}"
        )
        numbers["baseline_ratios"].append({
            "workers": workers, "wall": overall, "wall_per_pair": ratios, "worker_cpu": cpu_ratio,
            "identical_classification": same, "nodes": statuses["current"].size,
        })  # fmt: skip
    dask_sizes = [int(item) for item in arguments.dask_local.split(",") if item.strip()]
    for workers in dask_sizes:
        numbers["runs"].append(_run(job, workers, " Dask", dask_local=True)[3])
    if arguments.overhead_tasks > 0:
        print(f"\nper-task cost of the executors ({arguments.overhead_tasks} tasks that do nothing)")
        pool_sizes = sorted({int(item) for item in arguments.workers.split(",")} - {1})
        numbers["task_overhead"] = [
            *(_task_overhead(workers, False, arguments.overhead_tasks) for workers in pool_sizes),
            *(_task_overhead(workers, True, arguments.overhead_tasks) for workers in dask_sizes),
        ]
    numbers["time_split"] = _time_split(job, [0, len(job.speeds) // 2, len(job.speeds) - 1])
    if arguments.json:
        record.write(numbers)


if __name__ == "__main__":
    main()
