"""How an envelope's cost grows with resolution, and what boundary-following refinement saves and changes.

Run: nice -n 10 .venv/bin/python bench/envelope_resolution.py [--resolutions 21x13 41x25 81x49] [--levels 1 2]
     [--resolutions-3d 41x25] [--climb-rates-fpm=-2000,-1500,-1000,-500,0,750,1500]
     [--other-airframes oh58a_class s300c_class] [--other-resolutions 41x25] [--workers 2] [--json]

For each grid (heights 0-800 ft x speeds 0-120 kt, level flight, the default airframe and settings) the complete
``helireach envelope compute`` pipeline runs on local worker processes: the full grid (brute force), then the same
grid refined over each of ``--levels`` (``EnvelopeJob.refine_levels``; :mod:`helireach_ros.core.envelope.refinement`)
where the grid's counts allow it. ``--resolutions-3d`` adds 3-D grids on the shipped file's climb-rate axis
(``--climb-rates-fpm``, refined per climb slice). ``--other-airframes`` repeats the comparison on other airframes'
diagrams (other shapes of boundary: where a refinement could miss a pocket) at ``--other-resolutions``. Each
refined envelope is compared with its full grid node by node: its solves (sweep, cold re-checks, interior solves and
boundary bisection; an interior node kept on its corners' mean plan costs a replay, not a solve, and is counted
apart), IPOPT seconds summed over workers and wall time as ratios to the full grid's in the same run,
and every status that differs, split into *towards safe on the node's own replay-verified plan* (the full grid's plan
for that node did not verify; the refined interior solve's did), *towards safe without one* (an optimistic miss the
refinement must never make) and *towards not safe*.
``--json`` writes docs/results/data/envelope_resolution.json.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from _common import Record, add_json_argument, loadavg_text, machine_text

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.envelope.compute import EnvelopeJob, compute_envelope
from helireach_ros.core.envelope.grid import parse_list
from helireach_ros.core.envelope.refinement import REFINEMENT_ARRAY, NodeOrigin, check_refinable
from helireach_ros.core.envelope.workers import make_executor
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.units import FT, KT

SHIPPED_CLIMB_RATES_FPM = "-2000,-1500,-1000,-500,0,750,1500"


def _solves(envelope) -> int:
    counters = envelope.metadata["compute"]["counters"]
    return int(sum(counters.get(name, 0) for name in (
        "sweep_solves", "cold_rechecks", "bisection_solves", "interior_solves")))  # fmt: skip


def _ipopt_s(envelope) -> float:
    return float(sum(envelope.metadata["compute"]["phase_ipopt_s"].values()))


def _differences(full, refined) -> dict:
    """Every node whose status differs, by direction, with where it is and how the refined node got its answer."""
    origin = refined.arrays[REFINEMENT_ARRAY]
    verified = refined.arrays["verified"]
    listed: dict[str, list] = {"towards_safe_verified": [], "towards_safe_unverified": [], "towards_not_safe": []}
    for node in zip(*np.nonzero(full.status != refined.status), strict=True):
        entry = {
            "height_ft": round(float(full.heights[node[-2]] / FT), 1),
            "speed_kt": round(float(full.speeds[node[-1]] / KT), 2),
            "full": str(full.status[node]), "refined": str(refined.status[node]),
            "origin": NodeOrigin(int(origin[node])).name.lower(),
        }  # fmt: skip
        if full.is_3d:
            entry["climb_fpm"] = round(float(full.climb_rates[node[0]] / (FT / 60.0)))
        if refined.status[node] == "safe":
            listed["towards_safe_verified" if verified[node] else "towards_safe_unverified"].append(entry)
        else:
            listed["towards_not_safe"].append(entry)
    return listed


def _compute(job: EnvelopeJob, workers: int):
    executor = make_executor(workers)
    try:
        envelope = compute_envelope(job, executor)
    finally:
        executor.close()
    counts = {name: int((envelope.status == name).sum()) for name in ("safe", "unsafe", "unverified", "failed")}
    if envelope.is_3d:
        counts["no_trim"] = int((envelope.status == "no_trim").sum())
    return envelope, {
        "nodes": int(envelope.status.size), "solves": _solves(envelope), "ipopt_s": round(_ipopt_s(envelope), 1),
        "wall_s": float(envelope.metadata["compute"]["wall_time_s"]), "statuses": counts, "load": loadavg_text(),
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", nargs="*", default=["21x13", "41x25", "81x49"], help="HEIGHTSxSPEEDS, 2-D")
    parser.add_argument("--resolutions-3d", nargs="*", default=["41x25"], help="HEIGHTSxSPEEDS, 3-D")
    parser.add_argument("--climb-rates-fpm", default=SHIPPED_CLIMB_RATES_FPM, help="the 3-D grids' climb axis")
    parser.add_argument("--levels", nargs="+", type=int, default=[1, 2], help="refinement levels to compare")
    parser.add_argument("--other-airframes", nargs="*", default=["oh58a_class", "s300c_class"])
    parser.add_argument("--other-resolutions", nargs="*", default=["41x25"], help="HEIGHTSxSPEEDS, 2-D")
    parser.add_argument("--workers", type=int, default=2)
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    airframe, settings = load_airframe("uh60a_class"), load_settings()
    climb_rates = tuple(rate * FT / 60.0 for rate in parse_list(arguments.climb_rates_fpm, "--climb-rates-fpm"))
    print(f"envelope cost against resolution: {airframe.name}, 0-800 ft x 0-120 kt; {machine_text()}")
    print(f"command: {record.command}; load average {record.load_before}")
    numbers: dict = {"airframe": airframe.name, "workers": arguments.workers, "grids": [],
                     "climb_rates_fpm": arguments.climb_rates_fpm}  # fmt: skip
    grids = [(airframe, resolution, None) for resolution in arguments.resolutions]
    grids += [(airframe, resolution, climb_rates) for resolution in arguments.resolutions_3d]
    grids += [
        (load_airframe(name), resolution, None)
        for name in arguments.other_airframes
        for resolution in arguments.other_resolutions
    ]
    for grid_airframe, resolution, climbs in grids:
        heights_count, speeds_count = (int(part) for part in resolution.split("x"))
        job = EnvelopeJob(
            grid_airframe, settings, 0.0,
            tuple(np.linspace(0.0, 800.0, heights_count) * FT), tuple(np.linspace(0.0, 120.0, speeds_count) * KT),
            climb_rates=climbs,
        )  # fmt: skip
        label = f"{resolution}{'' if climbs is None else f'x{len(climbs)} (3-D)'}"
        if grid_airframe.name != airframe.name:
            label += f", {grid_airframe.name}"
        full, entry = _compute(job, arguments.workers)
        entry |= {"resolution": label, "airframe": grid_airframe.name, "refined": []}
        print(
            f"  {label:>14} full grid: {entry['nodes']:5d} nodes, {entry['solves']:5d} solves "
            f"({entry['solves'] / entry['nodes']:.2f} per node), IPOPT {entry['ipopt_s']:.0f} s, wall "
            f"{entry['wall_s']:.0f} s on {arguments.workers} workers; {entry['statuses']}; load {entry['load']}"
        )
        for levels in arguments.levels:
            try:
                check_refinable((heights_count, speeds_count), levels)
            except ValueError:
                continue
            refined, refined_entry = _compute(dataclasses.replace(job, refine_levels=levels), arguments.workers)
            counters = refined.metadata["compute"]["counters"]
            refined_entry |= {
                "levels": levels,
                "solve_ratio": refined_entry["solves"] / entry["solves"],
                "ipopt_ratio": refined_entry["ipopt_s"] / entry["ipopt_s"],
                "wall_ratio": refined_entry["wall_s"] / entry["wall_s"],
                "interior_solves": int(counters["interior_solves"]),
                "interior_kept": int(counters["interior_kept"]),
                "interior_replays": int(counters["interior_replays"]),
                "interior_interpolated": int(counters["interior_interpolated"]),
                "inferred_unsafe_nodes": int(counters["inferred_unsafe_nodes"]),
                **_differences(full, refined),
            }
            entry["refined"].append(refined_entry)
            print(
                f"  {label:>14} {levels} level(s): {refined_entry['solves']:5d} solves "
                f"({refined_entry['solve_ratio']:.2f}x), IPOPT {refined_entry['ipopt_s']:.0f} s "
                f"({refined_entry['ipopt_ratio']:.2f}x), wall {refined_entry['wall_s']:.0f} s "
                f"({refined_entry['wall_ratio']:.2f}x); interior: {refined_entry['interior_interpolated']} of "
                f"{refined_entry['interior_replays']} on their corners' mean plan (replays, no solve), "
                f"{refined_entry['interior_kept']} of {refined_entry['interior_solves']} solves kept; "
                f"{refined_entry['inferred_unsafe_nodes']} inferred unsafe; "
                f"differ: {len(refined_entry['towards_safe_verified'])} towards safe on their own verified plan, "
                f"{len(refined_entry['towards_safe_unverified'])} towards safe without, "
                f"{len(refined_entry['towards_not_safe'])} towards not safe; load {refined_entry['load']}"
            )
            for key in ("towards_safe_verified", "towards_safe_unverified", "towards_not_safe"):
                for node in refined_entry[key]:
                    print(f"      {key}: {node}")
        numbers["grids"].append(entry)
    print(f"load average after: {loadavg_text()}")
    if arguments.json:
        record.write(numbers)


if __name__ == "__main__":
    main()
