"""H-V envelope throughput: wall time and nodes/s for a full grid with 1 and 2 workers, and where the time goes.

Run: .venv/bin/python bench/envelope_throughput.py [--workers 1,2] [--heights-ft 0:800:41] [--speeds-kt 0:120:25]

Each run is the complete pipeline of ``helireach envelope compute`` (sweep, cold re-checks, boundary
refinement) with the default airframe and planner settings; 1 worker runs in this process, more use a
local process pool (worker start-up included). Prints per run: wall time, nodes/s, the share of nodes
re-solved cold, solve counts, per-phase wall time; then, from a few sweep columns timed in this process,
how a node's time splits between IPOPT and the rest of ``plan`` (decode + CVODES replay). The machine's
load average is printed too: other processes on a shared machine slow every number here.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from helireach_ros.core.airframe import load_airframe
from helireach_ros.core.envelope.compute import EnvelopeJob, _solve_point, _warm_start_of, compute_envelope
from helireach_ros.core.envelope.data import STATUS_CODES
from helireach_ros.core.envelope.grid import parse_range
from helireach_ros.core.envelope.workers import make_executor
from helireach_ros.core.planner import get_planner
from helireach_ros.core.settings import load_settings
from helireach_ros.core.units import FT, KT


def _run(job: EnvelopeJob, workers: int) -> None:
    load_before = os.getloadavg()[0]
    started = time.perf_counter()
    executor = make_executor(workers)
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
    print(f"\n{workers} worker(s) [{executor.description}]")
    print(f"  wall time            {wall:7.1f} s   ({nodes / wall:.1f} nodes/s, {solves / wall:.1f} solves/s)")
    print(f"  phases               {phases}")
    print(f"  nodes re-solved cold {counters['cold_rechecks'] / nodes:7.1%}  ({counters['cold_rechecks']} of {nodes})")
    print(
        f"  solves               {solves} = sweep {counters['sweep_solves']} ({counters['sweep_warm_solves']} warm) "
        f"+ re-checks {counters['cold_rechecks']} + boundary {counters['bisection_solves']} "
        f"({counters['bisection_cold_solves']} cold) for {len(envelope.boundary)} boundary points"
    )
    print(f"  result               {counts}, envelope {envelope.envelope_id}")
    print(f"  load average         {load_before:.2f} before, {os.getloadavg()[0]:.2f} after")


def _time_split(job: EnvelopeJob, columns: list[int]) -> None:
    """IPOPT versus the rest of plan() (decode + replay), per node, over a few sweep columns in this process."""
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts (default: %(default)s)")
    parser.add_argument("--heights-ft", default="0:800:41")
    parser.add_argument("--speeds-kt", default="0:120:25")
    parser.add_argument("--airframe", default="uh60a_class")
    arguments = parser.parse_args()
    airframe, settings = load_airframe(arguments.airframe), load_settings()
    job = EnvelopeJob(
        airframe, settings, 0.0, parse_range(arguments.heights_ft, FT), parse_range(arguments.speeds_kt, KT)
    )
    print(
        f"envelope throughput: {airframe.name}, {len(job.heights)} x {len(job.speeds)} grid "
        f"({arguments.heights_ft} ft, {arguments.speeds_kt} kt), method {settings.method}, {settings.intervals} "
        f"intervals; {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, Python "
        f"{platform.python_version()}"
    )
    for workers in (int(item) for item in arguments.workers.split(",")):
        _run(job, workers)
    _time_split(job, [0, len(job.speeds) // 2, len(job.speeds) - 1])


if __name__ == "__main__":
    main()
