"""What each way of storing an envelope's warm-start data costs: file size against failure-path solve time.

Run: .venv/bin/python bench/warm_start_storage.py [--envelope FILE] [--states 60] [--seed 1]

An envelope holds, per node, the plan's control function (what a fallback flies) and, in the file (format versions 1
and 2) or in the user cache (version 3, written by ``helireach envelope compute``), IPOPT's solution (primal, bound
and constraint multipliers: 93 % of a version-2 file). It needs that solver state. For random level-flight failure
states (uniform in 20-780 ft, 0-118 kt) this solves each from the nearest stored plan with the warm start as stored
(float32), rounded to float16, primal only (multipliers zero) in float32 and float16, the primal rebuilt from the
stored control function alone (``ControlFunctionWarmStart``: the function flown from the node's state), and cold; it
prints iterations and solve time (median, p95), whether the status equals the cold solve's, the time the rebuild
takes, and the compressed size of each storage option.
"""

from __future__ import annotations

import argparse
import io
import sys
import time
import warnings

import numpy as np
from _common import command_line, loadavg_text, summary

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.envelope.data import default_envelope_path, read_envelope_file
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import ControlFunctionWarmStart, WarmStart, get_planner
from helireach_ros.core.units import FT, KT


def _rounded(array: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # overflow is counted, not hidden: see _overflows
        return array.astype(np.float16).astype(float)


def _overflows(array: np.ndarray) -> int:
    return int(np.sum(np.abs(array[np.isfinite(array)]) > np.finfo(np.float16).max))


VARIANTS = {
    "float32 (as stored)": lambda w: w,
    "float16 primal and multipliers": lambda w: WarmStart(
        _rounded(w.primal), _rounded(w.bound_multipliers), _rounded(w.constraint_multipliers)
    ),
    "primal only, float32": lambda w: WarmStart(
        w.primal, np.zeros_like(w.bound_multipliers), np.zeros_like(w.constraint_multipliers)
    ),
    "primal only, float16": lambda w: WarmStart(
        _rounded(w.primal), np.zeros_like(w.bound_multipliers), np.zeros_like(w.constraint_multipliers)
    ),
}


def _compressed_mb(arrays: dict[str, np.ndarray]) -> float:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getbuffer().nbytes / 1e6


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envelope", default=str(default_envelope_path()))
    parser.add_argument("--states", type=int, default=60)
    parser.add_argument("--seed", type=int, default=1)
    arguments = parser.parse_args(argv)
    print(f"command: {command_line()}")
    print(f"load average (1/5/15 min): {loadavg_text()}")
    envelope = read_envelope_file(arguments.envelope)
    if envelope.solver_state is None:
        print(f"{arguments.envelope}: no solver state (not in the file, not in the user cache); compute the envelope "
              "with 'helireach envelope compute', which caches it, and pass it with --envelope")  # fmt: skip
        return 2
    airframe = load_airframe(envelope.airframe_name)
    planner = get_planner(airframe, load_settings())
    print(f"NLP functions: {planner.nlp_functions}; linear solver: {planner.linear_solver}")
    rng = np.random.default_rng(arguments.seed)
    rebuilt_name = "primal rebuilt from the control function"
    results: dict[str, list[tuple[int, float, bool]]] = {name: [] for name in (*VARIANTS, rebuilt_name, "cold")}
    rebuild_ms = []
    for _ in range(arguments.states):
        height, speed = rng.uniform(20.0, 780.0) * FT, rng.uniform(0.0, 118.0) * KT
        stored = envelope.nearest_plan(height, speed, 0.0)
        state = initial_state_after_failure(airframe, height, speed)
        cold = planner.plan(state)
        results["cold"].append((cold.solver.iterations, cold.solver.solve_time_ms, True))
        for name, variant in VARIANTS.items():
            if stored is None:
                plan = cold
            else:
                plan = planner.plan(state, warm_start=variant(stored.warm_start))
            results[name].append((plan.solver.iterations, plan.solver.solve_time_ms, plan.status == cold.status))
        plan = cold
        if stored is not None:
            node = initial_state_after_failure(airframe, stored.height, stored.speed, climb_rate=stored.climb_rate)
            started = time.perf_counter()
            planner.transcription.primal_from_controls(node.as_array(), stored.control_times, stored.control_values)
            rebuild_ms.append(1e3 * (time.perf_counter() - started))
            from_controls = ControlFunctionWarmStart(node.as_array(), stored.control_times, stored.control_values)
            plan = planner.plan(state, warm_start=from_controls)
        results[rebuilt_name].append((plan.solver.iterations, plan.solver.solve_time_ms, plan.status == cold.status))
    print("| warm start | median iterations | p95 iterations | median ms | p95 ms | status as cold |")
    print("|---|---|---|---|---|---|")
    for name, rows in results.items():
        iterations, times = summary(row[0] for row in rows), summary(row[1] for row in rows)
        same = sum(row[2] for row in rows)
        print(f"| {name} | {iterations['median']:.0f} | {iterations['p95']:.0f} | {times['median']:.1f} "
              f"| {times['p95']:.1f} | {same}/{len(rows)} |")  # fmt: skip
    rebuild = summary(rebuild_ms)
    print(f"rebuilding a primal from a control function: median {rebuild['median']:.1f} ms, "
          f"p95 {rebuild['p95']:.1f} ms (in plan(), before the solve)")  # fmt: skip
    arrays = envelope.arrays
    answers = {name: array for name, array in arrays.items() if not name.startswith("plan_")}
    controls = {name: arrays[name] for name in ("plan_control_times", "plan_control_values")}
    solver_state = envelope.solver_state
    primal = solver_state["plan_primal"]
    multipliers = {name: solver_state[name] for name in ("plan_bound_multipliers", "plan_constraint_multipliers")}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # float16 overflow: counted below
        sizes = _sizes(answers, controls, primal, multipliers)
    overflow = sum(_overflows(array) for array in multipliers.values())
    print("| stored part | compressed MB |")
    print("|---|---|")
    for name, size in sizes.items():
        print(f"| {name} | {size:.2f} |")
    print(f"multipliers beyond float16's range (become inf): {overflow}")
    print(f"load average (1/5/15 min): {loadavg_text()}")
    return 0


def _sizes(answers, controls, primal, multipliers) -> dict[str, float]:
    return {
        "answers (axes, status, values, boundary, metadata)": _compressed_mb(answers),
        "control functions, float32": _compressed_mb(controls),
        "control functions, float64": _compressed_mb({k: v.astype(float) for k, v in controls.items()}),
        "primal, float32": _compressed_mb({"primal": primal}),
        "primal, float16": _compressed_mb({"primal": primal.astype(np.float16)}),
        "multipliers, float32": _compressed_mb(multipliers),
        "multipliers, float16": _compressed_mb({k: v.astype(np.float16) for k, v in multipliers.items()}),
    }


if __name__ == "__main__":
    sys.exit(main())
