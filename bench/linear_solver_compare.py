"""IPOPT's linear solvers side by side: the block LDL^T (the default) against MUMPS, on the plan-latency states.

Run: .venv/bin/python bench/linear_solver_compare.py [--states 60] [--method flyable|verified] [--envelope]
     [--pairing values|structure] [--dump DIR] [--check-inertia DIR]

The two planners (``CodegenSettings.linear_solver`` ``mumps`` and ``block_ldl``; compiled NLP functions if the cache
holds them) solve the same states, interleaved state by state: a cold solve, then a warm solve from that cold plan
half a cell away (what the planner node does), as ``bench/plan_latency.py`` does. Prints per solver: total and
per-iteration IPOPT time, iterations, statuses, replay verdicts, and the ratio of the block LDL^T's time to MUMPS's
measured in the same run, with the load average. ``--envelope`` also computes the 41 × 25 envelope with each, in
this process, and compares every node.

``--pairing structure`` gives the block LDL^T pairs chosen by the structure alone (``BLOCK_LDL_STRUCTURAL_PAIRS``).
``--dump DIR`` makes it write the first 400 KKT matrices it factorizes, with the inertia it reported, into DIR
(``BLOCK_LDL_DUMPDIR``); ``--check-inertia DIR`` compares each with the inertia of its dense eigenvalues (numpy),
the check that found the structural pairs' wrong inertia.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

import numpy as np
from _common import ENVELOPE_GRID, StateGrid, command_line, loadavg_text, summary

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.compiled_nlp import CodegenSettings
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import LandingPlanner
from helireach_ros.core.units import FT, KT


def _codegen(linear_solver: str) -> CodegenSettings:
    return dataclasses.replace(CodegenSettings.from_environment(), linear_solver=linear_solver)


def _compare(airframe, method: str, points) -> None:
    settings = load_settings(method=method)
    configurations = {name: LandingPlanner(airframe, settings, _codegen(name)) for name in ("mumps", "block_ldl")}
    for name, planner in configurations.items():
        print(f"  {name}: {planner.nlp_functions}; linear solver {planner.linear_solver}")
    kinds = ("cold", "warm")
    times = {name: {kind: [] for kind in kinds} for name in configurations}
    iterations = {name: {kind: [] for kind in kinds} for name in configurations}
    statuses = {name: {kind: [] for kind in kinds} for name in configurations}
    values = {name: {kind: [] for kind in kinds} for name in configurations}
    verified = {name: {kind: [] for kind in kinds} for name in configurations}
    for height_ft, speed_kt in points:
        state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT)
        nearby = initial_state_after_failure(airframe, (height_ft + 10.0) * FT, (speed_kt + 2.5) * KT)
        for name, planner in configurations.items():
            cold = planner.plan(state)
            warm = planner.plan(nearby, warm_start=cold.warm_start)
            for kind, plan in (("cold", cold), ("warm", warm)):
                times[name][kind].append(plan.solver.solve_time_ms)
                iterations[name][kind].append(plan.solver.iterations)
                statuses[name][kind].append(plan.status)
                values[name][kind].append(plan.value)
                verified[name][kind].append(plan.verified)
    print(f"\nmethod {method}, {len(points)} states; load average {loadavg_text()}")
    for name in configurations:
        for kind in kinds:
            total, count = np.sum(times[name][kind]), np.sum(iterations[name][kind])
            stats = summary(times[name][kind])
            print(
                f"  {name:6s} {kind}: total {total:8.1f} ms, p50 {stats['median']:6.1f} / p95 {stats['p95']:6.1f} ms, "
                f"{np.mean(iterations[name][kind]):5.1f} iterations, {total / max(count, 1):.2f} ms per iteration, "
                f"{sum(verified[name][kind])} verified safe"
            )
    for kind in kinds:
        same = sum(a == b for a, b in zip(statuses["mumps"][kind], statuses["block_ldl"][kind], strict=True))
        gap = np.nanmax(np.abs(np.subtract(values["mumps"][kind], values["block_ldl"][kind])))
        verdicts = sum(a == b for a, b in zip(verified["mumps"][kind], verified["block_ldl"][kind], strict=True))
        ratio = np.sum(times["block_ldl"][kind]) / np.sum(times["mumps"][kind])
        per_iteration = (np.sum(times["block_ldl"][kind]) / np.sum(iterations["block_ldl"][kind])) / (
            np.sum(times["mumps"][kind]) / np.sum(iterations["mumps"][kind])
        )
        print(
            f"  {kind}: block_ldl / mumps total time {ratio:.3f}x, per iteration {per_iteration:.3f}x; same status at "
            f"{same} of {len(points)}, same replay verdict at {verdicts}; max |value difference| {gap:.1e}"
        )


def _compare_envelopes(airframe) -> None:
    """The 41 x 25 default envelope computed in this process with MUMPS, then with the block LDL^T."""
    from helireach_ros.core.envelope.compute import EnvelopeJob, compute_envelope

    results = {}
    for name in ("mumps", "block_ldl"):
        job = EnvelopeJob(
            airframe, load_settings(), 0.0, ENVELOPE_GRID.heights_si(), ENVELOPE_GRID.speeds_si(),
            codegen=_codegen(name),
        )  # fmt: skip
        started = time.perf_counter()
        envelope = compute_envelope(job)
        wall = time.perf_counter() - started
        ipopt_s = sum(envelope.metadata["compute"]["phase_ipopt_s"].values())
        counts = {
            status: int((envelope.status == status).sum()) for status in ("safe", "unsafe", "unverified", "failed")
        }
        print(f"  envelope, {name}: {wall:.1f} s wall, IPOPT {ipopt_s:.1f} s, {counts}; load average {loadavg_text()}")
        results[name] = envelope
    same = int(np.sum(results["mumps"].status == results["block_ldl"].status))
    values = [results[name].arrays["value"] for name in ("mumps", "block_ldl")]
    gap = np.nanmax(np.abs(values[0] - values[1]))
    print(f"  envelope: identical classification at {same} of {results['mumps'].status.size} nodes; "
          f"max |value difference| {gap:.1e}")  # fmt: skip


def check_inertia(directory: Path) -> None:
    """The inertia each dumped factorization reported against its dense eigenvalues."""
    wrong = total = perturbed_total = 0
    weakest_all: list[float] = []
    for path in sorted(directory.glob("f*.txt")):
        lines = path.read_text().split("\n")
        n, nz, negative, perturbed = (int(word) for word in lines[0].split())
        entries = np.loadtxt(lines[1 + n : 1 + n + nz])
        matrix = np.zeros((n, n))
        rows, columns = entries[:, 0].astype(int) - 1, entries[:, 1].astype(int) - 1
        np.add.at(matrix, (rows, columns), entries[:, 2])
        off_diagonal = rows != columns
        np.add.at(matrix, (columns[off_diagonal], rows[off_diagonal]), entries[off_diagonal, 2])
        weakest = _weakest_pair(matrix, np.array([int(word) for word in lines[1 : 1 + n]]))
        eigenvalues = np.linalg.eigvalsh(matrix)
        # eigvalsh's error is a small multiple of eps * max |eigenvalue|: a sign within that is undetermined
        undetermined = np.abs(eigenvalues).min() < 64 * np.finfo(float).eps * np.abs(eigenvalues).max()
        dense_negative = int(np.sum(eigenvalues < 0.0))
        total += 1
        perturbed_total += perturbed > 0 or undetermined
        if perturbed == 0 and not undetermined and dense_negative != negative:
            wrong += 1
            print(
                f"  {path.name}: reported {negative} negative eigenvalues, dense {dense_negative}; weakest 2x2 pair "
                f"{weakest:.1e} of its multiplier's largest entry"
            )
        weakest_all.append(weakest)
    print(
        f"inertia: wrong in {wrong} of {total - perturbed_total} factorizations reported regular whose dense "
        f"inertia is determined ({total} dumped)"
    )
    if weakest_all:
        print(f"weakest 2x2 pair per factorization: median {np.median(weakest_all):.1e}, min {np.min(weakest_all):.1e}")


def _weakest_pair(matrix: np.ndarray, code: np.ndarray) -> float:
    """The smallest |a_ij| / max_k |a_kj| over the block LDL^T's 2x2 pairs (i primal, j its multiplier)."""
    by_block: dict[int, list[int]] = {}
    for node, value in enumerate(code):
        by_block.setdefault(int(value) >> 1, [None, None])[int(value) & 1] = node
    weakest = 1.0
    for primal, multiplier in by_block.values():
        if primal is None or multiplier is None:
            continue
        row = np.abs(matrix[multiplier])
        row[multiplier] = 0.0
        largest = row.max()
        if largest > 0:
            weakest = min(weakest, abs(matrix[multiplier, primal]) / largest)
    return weakest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=60)
    parser.add_argument("--airframe", default="uh60a_class")
    parser.add_argument("--method", choices=("flyable", "verified"), default="flyable")
    parser.add_argument(
        "--pairing",
        choices=("values", "structure"),
        default="values",
        help="the block LDL^T's 2x2 pairs: by the Jacobian's values (default) or by structure only",
    )
    parser.add_argument("--dump", type=Path, help="write the block LDL^T's first 400 KKT matrices here")
    parser.add_argument("--check-inertia", type=Path, help="check the matrices dumped in this folder and stop")
    parser.add_argument("--envelope", action="store_true", help="also compute the 41 x 25 envelope with each solver")
    arguments = parser.parse_args()
    print(f"command: {command_line()}; load average {loadavg_text()}")
    if arguments.check_inertia is not None:
        check_inertia(arguments.check_inertia)
        return
    if arguments.pairing == "structure":
        os.environ["BLOCK_LDL_STRUCTURAL_PAIRS"] = "1"
    if arguments.dump is not None:
        arguments.dump.mkdir(parents=True, exist_ok=True)
        os.environ["BLOCK_LDL_DUMPDIR"] = str(arguments.dump)
    os.environ.setdefault("BLOCK_LDL_TIMES", "1")
    started = time.perf_counter()
    airframe = load_airframe(arguments.airframe)
    _compare(airframe, arguments.method, StateGrid.of_about(arguments.states).cells(serpentine=True))
    if arguments.envelope:
        _compare_envelopes(airframe)
    print(f"done in {time.perf_counter() - started:.0f} s; load average {loadavg_text()}")


if __name__ == "__main__":
    main()
