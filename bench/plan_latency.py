"""Solve-time percentiles of landing plans across the H-V plane, cold and warm, for each method.

Run: .venv/bin/python bench/plan_latency.py [--states 60] [--airframe uh60a_class] [--baseline] [--method flyable]
[--no-replans] [--json]

"Cold" solves start from the transcription's generic guess. Two warm starts are timed:
"warm, half a cell" starts from the plan of a state 10 ft and 2.5 kt away — half a cell of the
default 41 × 25 envelope grid, the farthest the planner node's nearest stored plan can be — and
"warm, far neighbour" starts from the previous state of a serpentine walk over this coarse grid
(~100 ft / ~17 kt away). With the flyable method, a third warm start is what the planner node does
during a descent: the re-plans of lock-step closed-loop descents from 8 states (the demo scenario's 5 %
drag mismatch and noise), each warm from the plan being flown. Times are IPOPT wall time per solve; the
replay, which follows every solve, is timed separately. Prints what it measured on this machine and the load average;
``--json`` also writes it to docs/results/data/plan_latency.json.

``--baseline`` also runs the legacy configuration (IPOPT's warm-solver options of then,
plain CasADi functions, MUMPS), the warm options alone, (verified, flyable) the six-state NLP, distance and engine
power as NLP variables (``closed_form_states`` off), and the current NLP with MUMPS instead of the block LDL^T
(:mod:`helireach_ros.core.ocp.block_ldl`), on the same states (each configuration warm-starts from its
own cold plan of the same state, since the NLPs' layouts differ; the re-plans from the same recorded warm starts),
interleaved state by state so that load changes hit every configuration alike, and prints each
configuration's total solve time as a ratio to the baseline's (the comparison that holds on a busy
machine). The compiled functions are used only if the cache holds them (``make nlp-cache``).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
from _common import Record, StateGrid, add_json_argument, loadavg_text, machine_text, summary, summary_text
from baseline_config import baseline_codegen, baseline_settings, six_state_settings, with_mumps

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.flight.simulation import SimulatedVehicle, load_scenario
from helireach_ros.core.ocp.compiled_nlp import CodegenSettings
from helireach_ros.core.ocp.settings import PlannerSettings, load_settings
from helireach_ros.core.planning.planner import LandingPlanner, WarmStart
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings, fly_closed_loop
from helireach_ros.core.units import FT, KT

_COMMIT_HEIGHT_FT = 20.0  # the flyable plans' commit height: below it, at speed, the NLP is nearly infeasible


def _percentiles(stats: dict) -> str:
    return summary_text(stats, width=7, n=False)


def _configurations(settings: PlannerSettings, baseline: bool) -> list[tuple[str, PlannerSettings, CodegenSettings]]:
    current = ("current", settings, CodegenSettings.from_environment())
    if not baseline:
        return [current]
    before, plain = baseline_settings(settings), baseline_codegen()
    if settings.method == "paper":  # its NLP has no closed-form states
        return [
            ("legacy", before, plain),
            ("warm options, plain functions", settings, plain),
            ("warm options, compiled, MUMPS", settings, with_mumps(current[2])),
            current,
        ]
    six_states = six_state_settings(settings)
    mumps = with_mumps(current[2])
    return [
        ("legacy", before, plain),
        ("warm options, six states, plain functions", six_states, plain),
        ("six states, compiled", six_states, mumps),
        ("closed form, compiled, MUMPS", settings, mumps),
        current,
    ]


def _run_method(airframe, method: str, points, baseline: bool) -> dict:
    """Cold, warm and replay times of every configuration on ``points``: prints them and returns them."""
    configurations = _configurations(load_settings(method=method), baseline)
    planners = []
    numbers: dict = {"configurations": {}}
    for name, settings, codegen in configurations:
        planner = LandingPlanner(airframe, settings, codegen)
        planners.append(planner)
        print(f"\nmethod {method}, {name}: NLP built in {planner.build_time_s:.2f} s on {planner.nlp_functions}")
        numbers["configurations"][name] = {"nlp_build_s": planner.build_time_s, "nlp_functions": planner.nlp_functions}
    samples = [{"cold": [], "near": [], "far": [], "replay": [], "iterations": [], "statuses": {}} for _ in planners]
    disagreements, value_gap = 0, 0.0
    previous = [None] * len(planners)
    for height_ft, speed_kt in points:
        state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT)
        nearby = initial_state_after_failure(airframe, (height_ft + 10.0) * FT, (speed_kt + 2.5) * KT)
        near_plans = []
        for index, (planner, sample) in enumerate(zip(planners, samples, strict=True)):
            # each configuration warm-starts from its own cold plan of the same state (the NLPs' layouts differ)
            started = time.perf_counter()
            cold_plan = planner.plan(state)
            sample["replay"].append(1e3 * (time.perf_counter() - started) - cold_plan.solver.solve_time_ms)
            sample["cold"].append(cold_plan.solver.solve_time_ms)
            sample["statuses"][cold_plan.status] = sample["statuses"].get(cold_plan.status, 0) + 1
            near = planner.plan(nearby, warm_start=cold_plan.warm_start)
            near_plans.append(near)
            sample["near"].append(near.solver.solve_time_ms)
            sample["iterations"].append(near.solver.iterations)
            if previous[index] is not None:
                sample["far"].append(planner.plan(state, warm_start=previous[index].warm_start).solver.solve_time_ms)
            previous[index] = cold_plan
        disagreements += len({plan.status for plan in near_plans}) > 1
        value_gap = max(value_gap, max(abs(plan.value - near_plans[0].value) for plan in near_plans))
    for (name, _, _), sample in zip(configurations, samples, strict=True):
        solved_heights = [height + 10.0 for height, _ in points]  # the half-a-cell states
        pairs = zip(sample["near"], solved_heights, strict=True)
        above = [time for time, height in pairs if height > _COMMIT_HEIGHT_FT]
        stats = {kind: summary(sample[kind]) for kind in ("cold", "near", "far", "replay")}
        stats["near_above_commit"] = summary(above)
        iterations = float(np.mean(sample["iterations"]))
        print(f"\nmethod {method}, {name}: cold statuses {sample['statuses']}")
        print(f"  cold solve        {_percentiles(stats['cold'])}")
        print(
            f"  warm, half a cell {_percentiles(stats['near'])}   (from a plan 10 ft / 2.5 kt away; "
            f"{iterations:.1f} iterations)"
        )
        above_text = _percentiles(stats["near_above_commit"])
        print(f"    above {_COMMIT_HEIGHT_FT:.0f} ft only  {above_text}   ({len(above)} states)")
        print(f"  warm, far         {_percentiles(stats['far'])}   (from the previous serpentine state's plan)")
        print(f"  replay + decode   {_percentiles(stats['replay'])}")
        numbers["configurations"][name].update(
            cold_statuses=sample["statuses"], near_iterations_mean=iterations, **stats
        )
    if baseline:
        print(f"\nmethod {method}: ratios of total solve time to '{configurations[0][0]}' (same states, same run)")
        numbers["ratios_to"] = configurations[0][0]
        for (name, _, _), sample in zip(configurations, samples, strict=True):
            ratios = {kind: np.sum(sample[kind]) / np.sum(samples[0][kind]) for kind in ("cold", "near", "far")}
            print(f"  {name:32s} {', '.join(f'{kind} {ratio:.3f}x' for kind, ratio in ratios.items())}")
            numbers["configurations"][name]["ratios"] = ratios
        print(
            f"  warm half-a-cell plans: status differs between configurations at {disagreements} of {len(points)} "
            f"states; max |value difference| {value_gap:.1e}"
        )
        numbers.update(status_disagreements=disagreements, max_value_difference=value_gap)
    return numbers


_REPLAN_STARTS = ((500, 75), (300, 40), (700, 20), (250, 100), (400, 110), (800, 60), (600, 90), (150, 60))
"""(height ft, speed kt) of the closed-loop descents whose re-plans are timed: across the safe region."""


class _RecordingPlanner:
    """The planner as :func:`fly_closed_loop` sees it, keeping every re-plan's arguments to time them again."""

    def __init__(self, planner: LandingPlanner) -> None:
        self.planner, self.airframe, self.settings = planner, planner.airframe, planner.settings
        self.replans: list[tuple[np.ndarray, object, np.ndarray, object]] = []

    def plan(self, state, warm_start=None, initial_control=None, reaction_delay_s=None, disturbance=None):
        if warm_start is not None:
            self.replans.append((np.asarray(state), warm_start, initial_control, disturbance))
        return self.planner.plan(state, warm_start, initial_control, reaction_delay_s, disturbance=disturbance)


def _state_rows(planner: LandingPlanner) -> tuple[int, ...]:
    return planner.transcription.state_rows


def _warm_start_for(planner: LandingPlanner, recorded_on: LandingPlanner, warm_start: WarmStart) -> WarmStart:
    """A warm start of ``recorded_on``'s NLP in ``planner``'s layout: a six-state solution reduces to the
    closed-form layout by dropping z, P and their collocation equations (their multipliers belong to them)."""
    rows, recorded_rows = _state_rows(planner), _state_rows(recorded_on)
    if rows == recorded_rows:
        return warm_start
    points, head = planner.transcription.n_states, 2 + 2 * planner.settings.intervals
    kept = [point * len(recorded_rows) + recorded_rows.index(row) for point in range(points) for row in rows]
    primal_index = np.concatenate([np.arange(head), head + np.asarray(kept)])
    residual_rows = points * len(recorded_rows)
    constraint_index = np.concatenate([kept, np.arange(residual_rows, warm_start.constraint_multipliers.size)])
    return WarmStart(
        warm_start.primal[primal_index],
        warm_start.bound_multipliers[primal_index],
        warm_start.constraint_multipliers[constraint_index],
    )


def _run_replans(airframe, method: str, baseline: bool) -> dict:
    """Re-plans as the planner node makes them: along closed-loop descents of the demo scenario (5 % drag
    mismatch, sensor noise, re-planning every 0.25 s from the control being flown, warm from the current plan),
    recorded once and then timed for each configuration, interleaved re-plan by re-plan. Prints and returns the
    times."""
    configurations = _configurations(load_settings(method=method), baseline)
    planners = [LandingPlanner(airframe, settings, codegen) for _, settings, codegen in configurations]
    # recorded on the six-state NLP when one is compared: its warm starts reduce exactly to the closed-form layout
    six_state = [planner for planner in planners if len(_state_rows(planner)) == 6]
    recorder = _RecordingPlanner(six_state[-1] if baseline and six_state else planners[-1])
    scenario = load_scenario("demo_500ft_75kt")
    landed = 0
    for height_ft, speed_kt in _REPLAN_STARTS:
        start = dataclasses.replace(scenario, height=height_ft * FT, forward_speed=speed_kt * KT)
        vehicle = SimulatedVehicle(start, airframe, recorder.settings)
        landed += fly_closed_loop(vehicle, recorder, ClosedLoopSettings()).touchdown.within_limits
    samples: list[list[tuple[float, int, bool]]] = [[] for _ in planners]
    statuses: list[dict[str, int]] = [{} for _ in planners]
    for index, (state, warm_start, control, disturbance) in enumerate(recorder.replans):
        order = list(range(len(planners)))
        for which in order if index % 2 == 0 else order[::-1]:
            start = _warm_start_for(planners[which], recorder.planner, warm_start)
            plan = planners[which].plan(state, start, control, 0.0, disturbance=disturbance)
            samples[which].append((plan.solver.solve_time_ms, plan.solver.iterations, plan.solver.success))
            statuses[which][plan.status] = statuses[which].get(plan.status, 0) + 1
    print(
        f"\nmethod {method}: re-plans along {len(_REPLAN_STARTS)} closed-loop descents of {scenario.name} "
        f"({len(recorder.replans)} re-plans, warm from the current plan; {landed} of {len(_REPLAN_STARTS)} "
        "descents landed within limits)"
    )
    numbers: dict = {
        "scenario": scenario.name, "descents": len(_REPLAN_STARTS), "replans": len(recorder.replans),
        "landed_within_limits": landed, "configurations": {},
    }  # fmt: skip
    for (name, _, _), rows, counts in zip(configurations, samples, statuses, strict=True):
        times = summary(time_ms for time_ms, _, _ in rows)
        converged = summary(time_ms for time_ms, _, success in rows if success)
        iterations = float(np.mean([count for _, count, _ in rows]))
        print(f"  {name}: {_percentiles(times)}   ({iterations:.1f} iterations; statuses {counts})")
        print(f"    converged only  {_percentiles(converged)}   ({converged['n']} re-plans)")
        numbers["configurations"][name] = {
            "solve": times, "converged": converged, "iterations_mean": iterations, "statuses": counts
        }
    if baseline:
        totals = [sum(time_ms for time_ms, _, _ in rows) for rows in samples]
        ratios = {name: total / totals[0] for (name, _, _), total in zip(configurations, totals, strict=True)}
        text = ", ".join(f"{name} {ratio:.3f}x" for name, ratio in ratios.items())
        print(f"  total re-plan solve time relative to '{configurations[0][0]}': {text}")
        numbers.update(ratios_to=configurations[0][0], ratios=ratios)
    return numbers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=60)
    parser.add_argument("--airframe", default="uh60a_class")
    parser.add_argument("--method", choices=("flyable", "verified", "paper", "all"), default="all")
    parser.add_argument("--baseline", action="store_true", help="also run the legacy configuration")
    parser.add_argument(
        "--no-replans", action="store_true", help="skip the re-plans along closed-loop descents (flyable only)"
    )
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    airframe = load_airframe(arguments.airframe)
    grid = StateGrid.of_about(arguments.states)
    points = grid.cells(serpentine=True)
    print(f"command: {record.command}")
    print(f"machine: {machine_text()}; {len(points)} states")
    print(f"load average before: {record.load_before}")
    methods = ("flyable", "verified", "paper") if arguments.method == "all" else (arguments.method,)
    numbers: dict = {
        "airframe": arguments.airframe, "states": len(points), "grid": grid.describe(),
        "commit_height_ft": _COMMIT_HEIGHT_FT, "methods": {},
    }  # fmt: skip
    for method in methods:
        numbers["methods"][method] = _run_method(airframe, method, points, arguments.baseline)
    if "flyable" in methods and not arguments.no_replans:
        numbers["replans"] = _run_replans(airframe, "flyable", arguments.baseline)
    print(f"\nload average after: {loadavg_text()}")
    if arguments.json:
        record.write(numbers)


if __name__ == "__main__":
    main()
