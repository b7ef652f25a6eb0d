"""What a landing plan for a landing site costs against the plain ("anywhere") landing plan, on the same states.

Run: .venv/bin/python bench/site_latency.py [--states 20] [--repeats 1] [--airframe uh60a_class] [--baseline] [--json]

States: a height × speed grid over 200–700 ft × 40–100 kt (about ``--states`` nodes), level flight, total power
loss. For each state, untimed: the anywhere plan (touchdown cost, cold), its natural touchdown distance, the
anywhere plan of the neighbouring state 10 ft higher and 2.5 kt faster (the warm start the planner node's envelope
gives: its nearest stored plan is at most half a grid cell away) and the reachable footprint (nearest and farthest
verified touchdown, 4 NLPs warm from the anywhere plan and cold; its solve-time total and wall time are reported).
A state whose anywhere plan is not safe or whose footprint lacks a verified end is listed and not timed (a site
inside the footprint needs both ends).

Then, per state, the kinds below are timed interleaved (their order rotated from state to state, so that load and
cache effects hit every kind alike), ``--repeats`` times each:

* ``anywhere, cold`` / ``anywhere, warm``: the touchdown-cost plan, cold and warm from the neighbour's plan;
* ``site beyond, cold/warm``: a 60 m site centred a third of the way from the natural touchdown to the footprint's
  farthest end; ``site short, cold/warm``: the same towards the nearest end (each kept inside the footprint). Warm
  starts are the neighbour's anywhere plan carried across the site row (``carried_warm_start``), as the node does;
* ``unreachable site``: a 60 m site 200 m beyond the farthest end, through ``solve_site_or_anywhere`` (the site
  attempt, warm, then a cold anywhere plan) timed as one call, as the node's failure plan makes it.

Per kind: IPOPT solve time (the sum of both solves for the unreachable site), the wall time of the whole call
(solve, decode and the independent replay), p50/p90/max; the share of safe plans (a site plan is safe only when its
replay touches down on the site; the unreachable kind counts the anywhere plan it falls back to) and each kind's
total as a ratio to the ``anywhere, warm`` total of the same run: the comparison that holds on a busy machine.
``--baseline`` is accepted for uniformity with the other benches: the baseline (anywhere, warm) is always run and
every ratio is against it. Prints the command, the machine, each NLP's functions (compiled or plain) and linear
solver, and the load average at the start and the end;
``--json`` also writes the numbers to docs/results/data/site_latency.json.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import numpy as np
from _common import Record, StateGrid, add_json_argument, loadavg_text, machine_text

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.footprint import reachable_footprint, touchdown_distance
from helireach_ros.core.planning.planner import LandingPlan, LandingPlanner, get_planner
from helireach_ros.core.policies.landing_sites import solve_site_or_anywhere
from helireach_ros.core.units import FT, KT

SITE_LENGTH_M = 60.0
UNREACHABLE_BEYOND_M = 200.0
NEIGHBOUR = (10.0, 2.5)  # ft higher, kt faster: half a cell of the default envelope grid
BASELINE = "anywhere, warm"
KINDS = (
    "anywhere, cold",
    BASELINE,
    "site beyond, cold",
    "site beyond, warm",
    "site short, cold",
    "site short, warm",
    "unreachable site",
)


def _percentiles(values: list[float]) -> dict[str, float | int | None]:
    """``p50``, ``p90``, ``max`` and ``n`` (NaNs dropped; ``None`` when nothing is left)."""
    data = np.asarray([value for value in values if not math.isnan(value)], dtype=float)
    if not data.size:
        return {"p50": None, "p90": None, "max": None, "n": 0}
    p50, p90 = np.percentile(data, [50, 90])
    return {"p50": float(p50), "p90": float(p90), "max": float(data.max()), "n": int(data.size)}


def _text(stats: dict[str, float | int | None]) -> str:
    if not stats["n"]:
        return f"{'none':>26s}"
    return " ".join(f"{stats[key]:8.1f}" for key in ("p50", "p90", "max"))


def _grid(count: int) -> StateGrid:
    """About ``count`` states over 200–700 ft × 40–100 kt."""
    columns = max(2, round(math.sqrt(count * 0.8)))
    rows = max(2, math.ceil(count / columns))
    return StateGrid(f"200:700:{rows}", f"40:100:{columns}")


def _site(centre: float, nearest: float, farthest: float) -> tuple[float, float]:
    """A ``SITE_LENGTH_M`` site around ``centre``, moved inside [nearest, farthest] (the whole footprint if
    shorter)."""
    half = 0.5 * SITE_LENGTH_M
    if farthest - nearest <= SITE_LENGTH_M:
        return nearest, farthest
    centre = min(max(centre, nearest + half), farthest - half)
    return centre - half, centre + half


class _Timed:
    """One kind's samples: IPOPT ms, wall ms, iterations, safe, status."""

    def __init__(self) -> None:
        self.solve: list[float] = []
        self.wall: list[float] = []
        self.iterations: list[int] = []
        self.safe: list[bool] = []
        self.statuses: dict[str, int] = {}
        self.first_solve: list[float] = []  # the first NLP's IPOPT ms (the unreachable kind: the site attempt)
        self.first_ipopt: dict[str, int] = {}  # ... and IPOPT's return status

    def add(self, plans: list[LandingPlan], result: LandingPlan, wall_ms: float) -> None:
        self.solve.append(sum(plan.solver.solve_time_ms for plan in plans))
        self.wall.append(wall_ms)
        self.iterations.append(sum(plan.solver.iterations for plan in plans))
        self.safe.append(result.safe)
        self.statuses[str(result.status)] = self.statuses.get(str(result.status), 0) + 1
        self.first_solve.append(plans[0].solver.solve_time_ms)
        self.first_ipopt[plans[0].solver.status] = self.first_ipopt.get(plans[0].solver.status, 0) + 1


def _prepare(planner: LandingPlanner, airframe, settings, height_ft: float, speed_kt: float) -> dict:
    """The untimed part of a state: anywhere plan, natural touchdown, neighbour's plan, footprint and sites."""
    state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT).as_array()
    neighbour_state = initial_state_after_failure(
        airframe, (height_ft + NEIGHBOUR[0]) * FT, (speed_kt + NEIGHBOUR[1]) * KT
    ).as_array()
    anywhere = planner.plan(state)
    neighbour = planner.plan(neighbour_state)
    started = time.perf_counter()
    footprint = reachable_footprint(state, airframe, settings, warm_starts=(anywhere.warm_start,))
    footprint_wall = 1e3 * (time.perf_counter() - started)
    natural = touchdown_distance(anywhere)
    row = {
        "height_ft": height_ft, "speed_kt": speed_kt, "anywhere_status": str(anywhere.status),
        "neighbour_status": str(neighbour.status), "natural_m": natural, "nearest_m": footprint.nearest_m,
        "farthest_m": footprint.farthest_m,
        "footprint_solve_ms": sum(plan.solver.solve_time_ms for plan in footprint.tried),
        "footprint_wall_ms": footprint_wall,
    }  # fmt: skip
    why = ""
    if not anywhere.safe:
        why = f"anywhere plan {anywhere.status}"
    elif not footprint.reachable:
        ends = (("nearest", footprint.nearest), ("farthest", footprint.farthest))
        missing = [name for name, end in ends if end is None]
        why = f"footprint {' and '.join(missing)} end not verified"
    row["skipped"] = why
    if not why:
        nearest, farthest = footprint.nearest_m, footprint.farthest_m
        row["sites"] = {
            "site beyond": _site(natural + (farthest - natural) / 3.0, nearest, farthest),
            "site short": _site(natural - (natural - nearest) / 3.0, nearest, farthest),
            "unreachable site": (
                farthest + UNREACHABLE_BEYOND_M, farthest + UNREACHABLE_BEYOND_M + SITE_LENGTH_M
            ),
        }  # fmt: skip
    return {"state": state, "neighbour": neighbour, "row": row}


def _measure(kind: str, prepared: dict, planner: LandingPlanner, site_planner: LandingPlanner) -> tuple:
    """Times one kind at one state: (plans solved, the plan returned, wall ms)."""
    state, warm = prepared["state"], prepared["neighbour"].warm_start
    sites = prepared["row"]["sites"]
    solved: list[LandingPlan] = []

    def anywhere(at: np.ndarray, start) -> LandingPlan:
        solved.append(planner.plan(at, planner.carried_warm_start(start)))
        return solved[-1]

    def on_site(window: tuple[float, float]) -> Callable[[np.ndarray, object], LandingPlan]:
        def solve(at: np.ndarray, start) -> LandingPlan:
            solved.append(site_planner.plan(at, site_planner.carried_warm_start(start), touchdown_window=window))
            return solved[-1]

        return solve

    started = time.perf_counter()
    if kind == "anywhere, cold":
        result = anywhere(state, None)
    elif kind == BASELINE:
        result = anywhere(state, warm)
    elif kind == "unreachable site":
        result = solve_site_or_anywhere(on_site(sites[kind]), anywhere, state, warm)
    else:
        site, start = kind.rsplit(", ", 1)
        result = on_site(sites[site])(state, warm if start == "warm" else None)
    return solved, result, 1e3 * (time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=20, help="about this many states over 200-700 ft x 40-100 kt")
    parser.add_argument("--repeats", type=int, default=1, help="timed solves of each kind per state")
    parser.add_argument("--airframe", default="uh60a_class")
    parser.add_argument(
        "--baseline",
        action="store_true",
        help=f"accepted for uniformity: the baseline ({BASELINE}) is always run and the ratios are against it",
    )
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    airframe = load_airframe(arguments.airframe)
    settings = load_settings()
    grid = _grid(arguments.states)
    points = grid.cells(serpentine=True)
    print(f"command: {record.command}")
    print(f"machine: {machine_text()}; {len(points)} states ({grid.describe()}), {arguments.repeats} repeat(s)")
    print(f"load average before: {record.load_before}")
    planner = get_planner(airframe, settings)
    site_planner = get_planner(airframe, settings.replace(objective="site"))
    nlps = {
        name: {"build_s": built.build_time_s, "functions": built.nlp_functions, "linear_solver": built.linear_solver}
        for name, built in (("anywhere", planner), ("site", site_planner))
    }
    for name, nlp in nlps.items():
        print(f"{name} NLP: built in {nlp['build_s']:.2f} s; {nlp['functions']}; linear solver {nlp['linear_solver']}")

    rows, prepared_states = [], []
    print(
        f"\n{'state':>15s} {'natural':>8s} {'nearest':>8s} {'farthest':>8s}  "
        f"{'footprint solve / wall ms':>25s}  site beyond / short (m from the state)"
    )
    for height_ft, speed_kt in points:
        prepared = _prepare(planner, airframe, settings, height_ft, speed_kt)
        row = prepared["row"]
        rows.append(row)
        sites = row.get("sites", {})
        inside = [window for name, window in sites.items() if name != "unreachable site"]
        where = "  ".join(f"{start:.0f}-{end:.0f}" for start, end in inside)
        print(
            f"{height_ft:6.0f} ft {speed_kt:3.0f} kt {row['natural_m']:8.0f} {row['nearest_m']:8.0f} "
            f"{row['farthest_m']:8.0f}  {row['footprint_solve_ms']:11.0f} / {row['footprint_wall_ms']:6.0f}    "
            f"{where or 'not timed: ' + row['skipped']}"
        )
        if not row["skipped"]:
            prepared_states.append(prepared)
    footprint = {
        "solve": _percentiles([row["footprint_solve_ms"] for row in rows]),
        "wall": _percentiles([row["footprint_wall_ms"] for row in rows]),
    }
    print(f"footprint (4 NLPs): IPOPT ms total p50/p90/max {_text(footprint['solve'])}")
    print(f"                    wall ms         p50/p90/max {_text(footprint['wall'])}")

    samples = {kind: _Timed() for kind in KINDS}
    notes: list[str] = []  # site plans inside the footprint that are not safe; unreachable sites that were reached
    for index, prepared in enumerate(prepared_states):
        for repeat in range(arguments.repeats):
            shift = (index * arguments.repeats + repeat) % len(KINDS)
            for kind in KINDS[shift:] + KINDS[:shift]:
                solved, result, wall_ms = _measure(kind, prepared, planner, site_planner)
                samples[kind].add(solved, result, wall_ms)
                row = prepared["row"]
                attempt = solved[0]  # the site plan (the unreachable kind: its site attempt)
                if (kind.startswith("site") and not result.safe) or (kind == "unreachable site" and attempt.safe):
                    window = row["sites"][kind.rsplit(", ", 1)[0]]
                    notes.append(
                        f"{kind} at {row['height_ft']:.0f} ft / {row['speed_kt']:.0f} kt, site "
                        f"{window[0]:.0f}-{window[1]:.0f} m: site plan {attempt.status} (IPOPT "
                        f"{attempt.solver.status}), replayed touchdown {touchdown_distance(attempt):.0f} m"
                    )

    base_solve, base_wall = sum(samples[BASELINE].solve), sum(samples[BASELINE].wall)
    print(
        f"\n{len(prepared_states)} of {len(points)} states timed, {arguments.repeats} repeat(s); "
        f"ratios are totals over the same states against '{BASELINE}'"
    )
    columns = f"{'IPOPT ms p50/p90/max':>26s} | {'wall ms p50/p90/max':>26s}"
    print(f"{'kind':18s} {'safe':>7s} | {columns} | ratio IPOPT / wall | iterations")
    kinds: dict = {}
    for kind, sample in samples.items():
        solve, wall = _percentiles(sample.solve), _percentiles(sample.wall)
        ratios = (sum(sample.solve) / base_solve, sum(sample.wall) / base_wall) if sample.solve else (math.nan,) * 2
        safe = f"{sum(sample.safe)}/{len(sample.safe)}"
        iterations = float(np.mean(sample.iterations)) if sample.iterations else math.nan
        print(
            f"{kind:18s} {safe:>7s} | {_text(solve)} | {_text(wall)} | {ratios[0]:6.2f}x / {ratios[1]:6.2f}x | "
            f"{iterations:6.1f}"
        )
        kinds[kind] = {
            "solve_ms": solve, "wall_ms": wall, "safe": sum(sample.safe), "n": len(sample.safe),
            "statuses": sample.statuses, "iterations_mean": iterations, "ratio_solve": ratios[0],
            "ratio_wall": ratios[1], "ipopt_statuses": sample.first_ipopt,
        }  # fmt: skip
    attempt = samples["unreachable site"]
    kinds["unreachable site"]["site_attempt_solve_ms"] = _percentiles(attempt.first_solve)
    print(
        f"unreachable site: the site attempt alone, IPOPT ms p50/p90/max {_text(_percentiles(attempt.first_solve))}; "
        f"IPOPT says {attempt.first_ipopt}"
    )
    for kind, sample in samples.items():
        if any(not safe for safe in sample.safe):
            print(f"{kind}: plan statuses {sample.statuses}; IPOPT {sample.first_ipopt}")
    for note in notes:
        print(f"  {note}")
    print(f"\nload average after: {loadavg_text()}")
    if arguments.json:
        numbers = {
            "airframe": arguments.airframe, "grid": grid.describe(), "states": len(points),
            "timed_states": len(prepared_states), "repeats": arguments.repeats, "site_length_m": SITE_LENGTH_M,
            "unreachable_beyond_m": UNREACHABLE_BEYOND_M, "neighbour_ft_kt": NEIGHBOUR, "baseline": BASELINE,
            "nlps": nlps, "footprint": footprint, "kinds": kinds, "notes": notes,
            "per_state": rows,
        }  # fmt: skip
        record.write(numbers)


if __name__ == "__main__":
    main()
