"""How an envelope's cost grows with resolution, and what a refinement that follows the boundary would save and miss.

Run: nice -n 10 .venv/bin/python bench/envelope_resolution.py [--resolutions 21x13 41x25 81x49] [--workers 2] [--json]

For each grid (heights 0-800 ft x speeds 0-120 kt, level flight, the default airframe and settings) the complete
``helireach envelope compute`` pipeline runs on local worker processes (the brute-force grid): wall time and solves.
Each grid doubles the one before per axis (2n - 1 nodes), so every node of the coarser grid is a node of the finer.
Between consecutive grids it measures what a coarse pass plus refinement would do: solve the coarse grid, then only
the fine nodes inside coarse cells whose four corners disagree (safe against not safe), and give every other fine
node the status its coarse cell's corners agree on. Printed against the brute-force fine grid: the solves that
would take (coarse solves + the fine grid's solves per node x those nodes), and every fine node whose inferred
status differs from the brute force, split into *towards safe* (inferred safe, brute force not: an optimistic miss
that a refinement must never make) and *towards not safe*. ``--json`` writes
docs/results/data/envelope_resolution.json.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np
from _common import Record, add_json_argument, loadavg_text, machine_text

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.envelope.compute import EnvelopeJob, compute_envelope
from helireach_ros.core.envelope.workers import make_executor
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.units import FT, KT


def _solves(envelope) -> int:
    counters = envelope.metadata["compute"]["counters"]
    return int(counters["sweep_solves"] + counters["cold_rechecks"] + counters["bisection_solves"])


def _refinement(coarse, fine, fine_solves: int, coarse_solves: int) -> dict:
    """What a coarse pass plus refinement inside the coarse cells whose corners disagree would solve and miss."""
    coarse_safe = coarse.status == "safe"
    fine_safe = fine.status == "safe"
    rows, columns = coarse_safe.shape
    solved = np.zeros(fine_safe.shape, dtype=bool)
    solved[::2, ::2] = True  # the coarse nodes
    inferred = np.full(fine_safe.shape, -1, dtype=np.int8)  # 1 safe, 0 not safe, -1 solved
    for row in range(rows - 1):
        for column in range(columns - 1):
            corners = coarse_safe[row : row + 2, column : column + 2]
            cell = (slice(2 * row, 2 * row + 3), slice(2 * column, 2 * column + 3))
            if corners.all() or not corners.any():  # cells that share nodes share their corners' statuses
                inferred[cell] = np.int8(corners.all())
            else:
                solved[cell] = True
    inferred[solved] = -1
    refined_nodes = int(solved.sum())
    towards_safe = (inferred == 1) & ~fine_safe
    towards_not_safe = (inferred == 0) & fine_safe
    per_node = fine_solves / fine_safe.size
    coarse_nodes = coarse_safe.size
    estimated = coarse_solves + per_node * (refined_nodes - coarse_nodes)

    def listed(mask: np.ndarray) -> list[dict]:
        return [
            {"height_ft": float(fine.heights[r] / FT), "speed_kt": float(fine.speeds[c] / KT),
             "brute_force": str(fine.status[r, c])}
            for r, c in zip(*np.nonzero(mask), strict=True)
        ]  # fmt: skip

    return {
        "coarse": f"{rows}x{columns}", "fine": f"{fine_safe.shape[0]}x{fine_safe.shape[1]}",
        "fine_nodes_solved": refined_nodes, "fine_nodes": int(fine_safe.size),
        "estimated_solves": estimated, "brute_force_solves": fine_solves,
        "solve_ratio": estimated / fine_solves,
        "towards_safe": listed(towards_safe), "towards_not_safe": listed(towards_not_safe),
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", nargs="+", default=["21x13", "41x25", "81x49"], help="HEIGHTSxSPEEDS")
    parser.add_argument("--workers", type=int, default=2)
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    airframe, settings = load_airframe("uh60a_class"), load_settings()
    print(f"envelope cost against resolution: {airframe.name}, level flight, 0-800 ft x 0-120 kt; {machine_text()}")
    print(f"command: {record.command}; load average {record.load_before}")
    grids, numbers = [], {"airframe": airframe.name, "workers": arguments.workers, "grids": [], "refinements": []}
    for resolution in arguments.resolutions:
        heights_count, speeds_count = (int(part) for part in resolution.split("x"))
        job = EnvelopeJob(
            airframe, settings, 0.0,
            tuple(np.linspace(0.0, 800.0, heights_count) * FT), tuple(np.linspace(0.0, 120.0, speeds_count) * KT),
        )  # fmt: skip
        executor = make_executor(arguments.workers)
        try:
            envelope = compute_envelope(job, executor)
        finally:
            executor.close()
        wall = float(envelope.metadata["compute"]["wall_time_s"])
        solves = _solves(envelope)
        counts = {name: int((envelope.status == name).sum()) for name in ("safe", "unsafe", "unverified", "failed")}
        nodes = envelope.status.size
        print(
            f"  {resolution:>7}: {nodes:5d} nodes, {solves:5d} solves ({solves / nodes:.2f} per node), {wall:6.1f} s "
            f"wall on {arguments.workers} workers; {counts}; load {loadavg_text()}"
        )
        numbers["grids"].append({
            "resolution": resolution, "nodes": int(envelope.status.size), "solves": solves, "wall_s": wall,
            "statuses": counts, "load": loadavg_text(),
        })  # fmt: skip
        grids.append((envelope, solves))
    for (coarse, coarse_solves), (fine, fine_solves) in itertools.pairwise(grids):
        if (fine.status.shape[0] - 1) != 2 * (coarse.status.shape[0] - 1) or (fine.status.shape[1] - 1) != 2 * (
            coarse.status.shape[1] - 1
        ):
            continue
        result = _refinement(coarse, fine, fine_solves, coarse_solves)
        numbers["refinements"].append(result)
        print(
            f"  refine {result['coarse']} -> {result['fine']}: {result['fine_nodes_solved']} of {result['fine_nodes']} "
            f"fine nodes solved, ~{result['estimated_solves']:.0f} solves against {result['brute_force_solves']} "
            f"({result['solve_ratio']:.2f}x); inferred statuses that differ: {len(result['towards_safe'])} towards "
            f"safe, {len(result['towards_not_safe'])} towards not safe"
        )
        for miss in result["towards_safe"]:
            print(f"      towards safe: {miss['height_ft']:.0f} ft {miss['speed_kt']:.0f} kt ({miss['brute_force']})")
    print(f"load average after: {loadavg_text()}")
    if arguments.json:
        record.write(numbers)


if __name__ == "__main__":
    main()
