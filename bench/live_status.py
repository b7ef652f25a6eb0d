"""Live reachability: agreement with ``helireach plan``, solve times in and out of process, rate and CPU share.

Run: .venv/bin/python bench/live_status.py [--states 60] [--seconds 20] [--workers 2] [--seed 3]

1. **Agreement.** Two seeded random walks through non-trim states (heights 20–800 ft, speeds 0–120 kt, climb rates
   −3,000…+1,500 ft/min, rotor speed 95–105 %; one from cruise, one from the hover avoid band), evaluated as the
   planner node's live evaluation does (each warm-started from the previous one) and as ``helireach plan`` does
   (cold, in process): status agreement and the largest |ΔJ|.
2. **GIL.** The same warm live solves timed in process and through the solver pool, each with and without a busy
   Python thread in this process (what a busy rclpy executor is): ratios measured in this run.
3. **Rate and CPU share.** The live evaluation at 5 Hz through the pool for ``--seconds``: rate achieved, solve
   p50/p95 (submit → result), and the workers' CPU time per wall second (``/proc/<pid>/stat``).

Failure → first trajectory (standby and refined, composed and cross-process) is measured by
``bench/failure_latency.py``. Prints the load average with its numbers.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time

import numpy as np
from _common import command_line, loadavg_text, machine_text, summary, summary_text

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import get_planner, plan_landing
from helireach_ros.core.policies.live_reachability import LiveEvaluator, LiveSettings, failure_now_state
from helireach_ros.core.units import FT, KT
from helireach_ros.core.workers.solver_pool import PRIORITY_LIVE, SolverPool, SolverPoolSettings

FPM = FT / 60.0


def random_walk(airframe, count: int, seed: int, start: tuple[float, float] = (500.0, 75.0)) -> list[np.ndarray]:
    """Measured non-trim states (engine power = the trim power on that path) along a seeded random walk from
    ``start`` (ft, kt)."""
    rng = np.random.default_rng(seed)
    height, speed, climb, rotor = start[0], start[1], 0.0, 100.0
    states = []
    while len(states) < count:
        height = float(np.clip(height + rng.normal(0, 60), 20, 800))
        speed = float(np.clip(speed + rng.normal(0, 10), 0, 120))
        climb = float(np.clip(climb + rng.normal(0, 600), -3000, 1500))
        rotor = float(np.clip(rotor + rng.normal(0, 1.5), 95, 105))
        try:
            state = initial_state_after_failure(
                airframe, height * FT, speed * KT, 1.0, climb * FPM, rotor / 100 * airframe.nominal_rotor_speed
            )
        except ValueError:
            continue  # no powered trim there (e.g. too steep a descent): not a state to measure
        states.append(state.as_array())
    return states


def agreement(airframe, settings, planner, states: list[np.ndarray]) -> None:
    clock = time.monotonic_ns
    evaluator = LiveEvaluator(LiveSettings(max_state_age_s=3600.0), planner.plan)
    agree, worst, statuses = 0, 0.0, {}
    for state in states:
        now = clock()
        verdict = evaluator.evaluate(state, now, now, clock)
        reference = plan_landing(failure_now_state(state, 0.0), airframe, settings)
        agree += verdict.status == reference.status
        worst = max(worst, abs(verdict.value - reference.value))
        statuses[reference.status] = statuses.get(reference.status, 0) + 1
    print(f"1. agreement with `helireach plan` on {len(states)} non-trim states: {agree}/{len(states)} statuses equal")
    print(f"   largest |dJ| {worst:.2e}; states by status {statuses}")


class BusyThread:
    """A Python thread that never sleeps (what a busy executor does to the GIL)."""

    def __enter__(self) -> BusyThread:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        return self

    def _spin(self) -> None:
        counter = 0
        while not self._stop.is_set():
            counter += 1

    def __exit__(self, *exc_info: object) -> None:
        self._stop.set()
        self._thread.join()


def gil_effect(planner, pool: SolverPool, states: list[np.ndarray]) -> None:
    warm = [planner.plan(failure_now_state(state, 0.0)).warm_start for state in states]
    timings: dict[str, list[float]] = {key: [] for key in ("in process", "in process + busy", "pool", "pool + busy")}
    busy = BusyThread()
    for state, warm_start in zip(states, warm, strict=True):  # interleaved: load changes hit all alike
        for key in timings:
            solve = planner.plan if key.startswith("in process") else pool.plan
            context = busy if key.endswith("busy") else None
            if context is not None:
                context.__enter__()
            started = time.perf_counter()
            solve(failure_now_state(state, 0.0), warm_start)
            timings[key].append(1e3 * (time.perf_counter() - started))
            if context is not None:
                context.__exit__()
    base = float(np.sum(timings["in process"]))
    print("2. warm live solve + replay, same states, same warm starts:")
    for key, samples in timings.items():
        print(f"   {key:18s} {summary_text(summary(samples))}  total {np.sum(samples) / base:.2f}x in-process")


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def live_rate(airframe, pool: SolverPool, seconds: float) -> None:
    settings = LiveSettings(rate_hz=5.0, max_state_age_s=3600.0)
    evaluator = LiveEvaluator(settings)
    states = random_walk(airframe, int(seconds * 6) + 10, seed=11)
    pids = pool.worker_pids()
    cpu_before = sum(cpu_seconds(pid) for pid in pids)
    started = time.monotonic()
    latencies: list[float] = []
    index = 0
    while time.monotonic() - started < seconds:
        now = time.monotonic_ns()
        if not evaluator.due(now):
            time.sleep(0.001)
            continue
        state, warm_start = evaluator.prepare(states[index % len(states)], now, now)
        index += 1
        try:
            plan = pool.submit(state, warm_start, priority=PRIORITY_LIVE, cold_check=True).result()
            error = ""
        except (ValueError, RuntimeError) as exception:
            plan, error = None, str(exception)
        finished = time.monotonic_ns()
        evaluator.record(state, now, now, finished, plan, error)
        latencies.append((finished - now) * 1e-6)
    wall = time.monotonic() - started
    cpu = sum(cpu_seconds(pid) for pid in pool.worker_pids() if pid in pids) - cpu_before
    print(
        f"3. live evaluation at 5 Hz for {wall:.0f} s through the pool: {evaluator.evaluations / wall:.2f} Hz achieved,"
    )
    print(f"   {evaluator.errors} errors; submit -> result {summary_text(summary(latencies))}")
    print(
        f"   solver workers' CPU: {cpu / wall:.2f} CPU-seconds per second ({100 * cpu / wall / os.cpu_count():.0f} % of"
    )
    print(f"   this machine's {os.cpu_count()} cores)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--states", type=int, default=60)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=3)
    arguments = parser.parse_args()
    airframe, settings = load_airframe("uh60a_class"), load_settings()
    planner = get_planner(airframe, settings)
    print(f"command: {command_line()}  ({machine_text()})")
    print(f"load average before: {loadavg_text()}")
    # Half the walk from cruise, half from the low, slow corner (the hover avoid band), so both verdicts occur.
    half = arguments.states // 2
    states = random_walk(airframe, half, arguments.seed)
    states += random_walk(airframe, arguments.states - half, arguments.seed + 1, start=(120.0, 15.0))
    agreement(airframe, settings, planner, states)
    with SolverPool(airframe, settings, SolverPoolSettings(workers=arguments.workers)) as pool:
        if not pool.wait_ready(120.0, arguments.workers):
            print("solver workers did not start")
            return 1
        gil_effect(planner, pool, states[:30])
        live_rate(airframe, pool, arguments.seconds)
    print(f"load average after: {loadavg_text()}")
    print(f"reproduce: {command_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
