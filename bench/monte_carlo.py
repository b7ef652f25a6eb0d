"""Closed loop under uncertainty: how often the re-planning landing stays within limits.

Run: nice -n 10 .venv/bin/python bench/monte_carlo.py [--runs 200] [--first-seed 0 | --seeds S ...]
     [--workers 2] [--margins 0/0 0.25/0.02] [--uncertainty config/uncertainty.yaml] [--no-weight-check]
     [--policies none weight disturbance weight+disturbance ...] [--objectives terminal reach_avoid]
     [--replan-periods 0.25 0.1] [--replan-min-heights 0.5 0.3] [--state-gains 1 0.5] [--disturbance-windows 0 8]
     [--planner-models nominal truth] [--noise set none] [--truth-check] [--json]

Each run is the lock-step closed loop (:func:`~helireach_ros.core.robustness.closed_loop.fly_closed_loop`, the planner
node's re-planning policy, every 0.25 s) of a vehicle whose true parameters, density altitude and plan
latency are drawn uniformly from the uncertainty set (:mod:`helireach_ros.core.flight.uncertainty`), with the
set's sensor noise, after a total power loss from level trim. The planner keeps the nominal model. Run
``seed`` flies initial state ``seed mod len(states)``; its draw and its noise come from ``seed`` alone, so
``--seeds S`` repeats a run exactly.

Initial states: 500 ft / 75 kt; for each of 100, 200, 250, 300, 350, 400, 450 and 550 ft the slowest speed
(1 kt steps) at least 30 ft/kt inside the boundary of the shipped envelope's level slice (``Envelope.margin``;
kept only within 20-40 ft/kt: with the shipped envelope 100 ft has none); three states deep
inside (700 ft / 40 kt, 350 ft / 110 kt, 600 ft / 90 kt).

Margins (``--margins T/R``): the planner plans inside tightened limits (touchdown descent and forward
speed × (1 − T), rotor-speed limits R × Ω₀ further inside) while every landing is judged against the true
ones. This needs no change to the NLP: its limits are the airframe's, so the planner is simply built for
an airframe with tightened limits.

Prints, per margin setting: the success rate with its 95 % Wilson interval overall and per initial state,
the touchdown descent-rate and forward-speed distributions, the rotor-speed range, the success rate in the
lower and upper half of each range (what the failures lean on), each failure's seed;
then (unless ``--no-weight-check``) the acceptance case, an unknown +5 % weight from 500 ft / 75 kt, for a few
latencies and noise seeds. Parallel over ``--workers`` local processes. ``--json`` also writes the numbers to
docs/results/data/monte_carlo.json.

``--truth-check``: for every run also solve the landing in the run's *true* model (a planner built for the drawn
airframe, cold IPOPT from the same initial state). A run whose true model has no safe landing from there cannot be
landed within limits by any re-planning policy of this NLP (up to IPOPT's local optimum); the report splits the
failures into those and the ones the policy lost.

Re-planning policies (``--policies``, each ``none`` or a ``+``-joined set; every policy is run with every
margin setting, on the same draws): ``weight``: plan for the gross weight estimated from the engine power of
the steady flight before the failure (:mod:`helireach_ros.core.estimation.gross_weight`, which also absorbs the drag and
c_d errors into that weight); ``disturbance``: re-plan for the model plus the disturbance accelerations
learnt from each re-planning interval's prediction error (:mod:`helireach_ros.core.estimation.disturbance`);
``latency``: each re-plan starts from the current plan flown ahead in the model for the latency
(:attr:`~helireach_ros.core.robustness.closed_loop.ClosedLoopSettings.compensate_latency`); ``keep``: a re-plan that
is not safe is kept out while the current plan, replayed from its state, still lands
(:attr:`~helireach_ros.core.robustness.closed_loop.ClosedLoopSettings.keep_landing_plan`; the planner node's policy is
``disturbance+keep``). ``--state-gains``: the
disturbance estimate's state gain α (below 1 an α–β observer whose filtered state the plans start from).
``--disturbance-windows``: W, the disturbance estimate as the mean of the last W intervals' implied disturbances
(:attr:`~helireach_ros.core.estimation.disturbance.DisturbanceSettings.window`; 0: the filter of gain
``--disturbance-gain``, the default); each is run with every other setting, on the same draws.

Re-planning periods (``--replan-periods``): s between re-plans (the planner node's ``replan_period``); each is run
with every objective, policy and margin setting, on the same draws. ``--replan-min-heights``: m below which the closed
loop stops re-planning and flies the current plan to the ground (the planner node's ``replan_min_height``; the
``replan_min_remaining`` rule holds either way), likewise.

Planner models (``--planner-models``): ``nominal`` (the planner keeps the airframe file's model, as the nodes do)
or ``truth``, an oracle that plans with each run's true model (drawn parameters and density altitude) and still
meets its latency and sensor noise. The oracle is no policy the package could fly; it bounds what any estimation of
the model can buy: what it loses is lost to latency, noise, the mesh and the re-planning itself.

Sensor noise (``--noise``): ``set`` (the uncertainty set's) or ``none`` (exact measurements, the same draws):
what the noise alone costs.

Objectives (``--objectives``, the planner settings' ``objective``; each is run with every policy and margin
setting, on the same draws): ``terminal`` (the touchdown cost, limits hard) or ``reach_avoid`` (the worst
normalised margin, :class:`~helireach_ros.core.ocp.settings.PlannerSettings`).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from functools import lru_cache

import numpy as np
from _common import Record, add_json_argument, loadavg_text, summary, wilson_interval

from helireach_ros.core.aircraft.airframe import Airframe, load_airframe
from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
from helireach_ros.core.estimation.disturbance import DisturbanceSettings
from helireach_ros.core.flight.simulation import Scenario, SensorNoise, load_scenario
from helireach_ros.core.flight.uncertainty import (
    DEFAULT_UNCERTAINTY_FILE,
    PerturbedModel,
    UncertaintySet,
    load_uncertainty_set,
)
from helireach_ros.core.ocp.settings import OBJECTIVES, PlannerSettings, load_settings
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings, fly_closed_loop
from helireach_ros.core.robustness.verification import model_vehicle, own_landing
from helireach_ros.core.units import FT, KT

NEAR_BOUNDARY_HEIGHTS_FT = (100.0, 200.0, 250.0, 300.0, 350.0, 400.0, 450.0, 550.0)
NEAR_BOUNDARY_MARGIN = (20.0, 30.0, 40.0)  # accepted low, target, accepted high, ft/kt
DEEP_STATES = ((700.0, 40.0), (350.0, 110.0), (600.0, 90.0))  # ft, kt
WEIGHT_CHECK_LATENCIES = (0.05, 0.1, 0.3)
WEIGHT_CHECK_SEEDS = (7, 8, 9)


def initial_states() -> list[tuple[float, float, float]]:
    """(height ft, speed kt, envelope margin ft/kt) of the runs' initial states (see the module docstring)."""
    envelope = load_envelope(default_envelope_path())
    low, target, high = NEAR_BOUNDARY_MARGIN
    states = [(500.0, 75.0)]
    for height in NEAR_BOUNDARY_HEIGHTS_FT:
        speed = next(
            (float(v) for v in range(0, 121) if envelope.margin(height * FT, v * KT) >= target),
            math.nan,
        )
        if math.isfinite(speed) and low <= envelope.margin(height * FT, speed * KT) <= high:
            states.append((height, speed))
    states.extend(DEEP_STATES)
    return [(height, speed, envelope.margin(height * FT, speed * KT)) for height, speed in states]


@dataclasses.dataclass(frozen=True)
class Margin:
    """Planning margins: touchdown rates × (1 − touchdown), rotor limits ``rotor`` × Ω₀ further inside."""

    touchdown: float
    rotor: float

    @classmethod
    def parse(cls, text: str) -> Margin:
        touchdown, _, rotor = text.partition("/")
        margin = cls(float(touchdown), float(rotor or 0.0))
        if not (0.0 <= margin.touchdown < 1.0 and 0.0 <= margin.rotor < 0.1):
            raise argparse.ArgumentTypeError(f"margin {text!r}: need T/R with 0 <= T < 1, 0 <= R < 0.1")
        return margin

    def label(self) -> str:
        return f"touchdown -{100 * self.touchdown:.0f} %, rotor {100 * self.rotor:.0f} % inside"

    def planning_airframe(self, airframe: Airframe) -> Airframe:
        """The airframe the planner is built for: the true one with tightened limits."""
        if self.touchdown == 0.0 and self.rotor == 0.0:
            return airframe
        limits = airframe.limits
        tightened = dataclasses.replace(
            limits,
            max_descent_rate=limits.max_descent_rate * (1.0 - self.touchdown),
            max_forward_speed=limits.max_forward_speed * (1.0 - self.touchdown),
            min_rotor_speed_ratio=limits.min_rotor_speed_ratio + self.rotor,
            max_rotor_speed_ratio=limits.max_rotor_speed_ratio - self.rotor,
        )
        return dataclasses.replace(airframe, name=f"{airframe.name}+margins", limits=tightened)


@lru_cache(maxsize=1)
def _context(uncertainty_file: str) -> tuple[Airframe, PlannerSettings, UncertaintySet]:
    return load_airframe("uh60a_class"), load_settings(None), load_uncertainty_set(uncertainty_file)


PLANNER_MODELS = ("nominal", "truth")
"""``--planner-models``: the airframe file's model (as the nodes plan) or each run's true model (an oracle)."""

POLICY_PARTS = {
    "weight": "estimate_weight", "disturbance": "estimate_disturbance", "latency": "compensate_latency",
    "keep": "keep_landing_plan",
}  # fmt: skip
"""``--policies`` words and the :class:`ClosedLoopSettings` switch each turns on."""


def _window(text: str) -> int:
    """A ``--disturbance-windows`` entry: an integer >= 0 (0: the exponential filter)."""
    try:
        window = int(text)
    except ValueError:
        window = -1
    if window < 0:
        raise argparse.ArgumentTypeError(f"disturbance window {text!r}: need an integer >= 0")
    return window


def parse_policy(text: str) -> str:
    """A ``--policies`` entry: ``none`` or ``+``-joined :data:`POLICY_PARTS` words."""
    parts = [] if text == "none" else text.split("+")
    unknown = [part for part in parts if part not in POLICY_PARTS]
    if unknown or len(set(parts)) != len(parts):
        raise argparse.ArgumentTypeError(f"policy {text!r}: 'none' or {'+'.join(POLICY_PARTS)} parts, each once")
    return text


def closed_loop_settings(
    policy: str,
    latency: float,
    disturbance_gain: float,
    replan_period: float = ClosedLoopSettings().replan_period,
    state_gain: float = DisturbanceSettings().state_gain,
    disturbance_window: int | None = DisturbanceSettings().window,
    min_height: float = ClosedLoopSettings().min_height,
) -> ClosedLoopSettings:
    """The re-planning policy of a run."""
    parts = [] if policy == "none" else policy.split("+")
    switches = {switch: part in parts for part, switch in POLICY_PARTS.items()}  # each one explicit
    return ClosedLoopSettings(
        latency=latency, replan_period=replan_period, min_height=min_height,
        disturbance=DisturbanceSettings(gain=disturbance_gain, state_gain=state_gain, window=disturbance_window),
        **switches,
    )  # fmt: skip


@dataclasses.dataclass(frozen=True)
class Flight:
    """One closed-loop landing to fly (a worker process's task): the initial state, the drawn true model and noise,
    and the planner's side (margins, policy, objective, re-planning period)."""

    uncertainty_file: str
    margin: Margin
    height_ft: float
    speed_kt: float
    model: PerturbedModel
    noise: SensorNoise
    noise_seed: int
    policy: str
    disturbance_gain: float
    objective: str | None = None
    replan_period: float = ClosedLoopSettings().replan_period
    planner_model: str = "nominal"
    state_gain: float = DisturbanceSettings().state_gain
    disturbance_window: int | None = DisturbanceSettings().window
    replan_min_height: float = ClosedLoopSettings().min_height


def _settings(flight: Flight) -> tuple[Airframe, PlannerSettings]:
    airframe, settings, _ = _context(flight.uncertainty_file)
    return airframe, settings if flight.objective is None else settings.replace(objective=flight.objective)


def fly(flight: Flight) -> dict:
    """One closed-loop landing (a worker process's job)."""
    airframe, settings = _settings(flight)
    planning = flight.model.airframe(airframe) if flight.planner_model == "truth" else airframe
    planner = get_planner(flight.margin.planning_airframe(planning), settings)
    scenario = Scenario(
        name="monte_carlo", height=flight.height_ft * FT, forward_speed=flight.speed_kt * KT, noise=flight.noise,
        seed=flight.noise_seed,
    )  # fmt: skip
    vehicle = model_vehicle(scenario, flight.model, airframe, settings)  # judged against the true limits
    started = time.perf_counter()
    policy = closed_loop_settings(
        flight.policy, flight.model.latency, flight.disturbance_gain, flight.replan_period, flight.state_gain,
        flight.disturbance_window, flight.replan_min_height,
    )  # fmt: skip
    result = fly_closed_loop(vehicle, planner, policy)
    report = result.touchdown
    omega0 = airframe.nominal_rotor_speed
    return {
        "within": report.within_limits,
        "within_contact": report.within_limits_to_contact,
        "touchdown_value": report.value,
        "rotor_min_contact_pct": 100 * report.min_rotor_speed_to_contact / omega0,
        "descent_ft_s": report.descent_rate / FT,
        "speed_kt": abs(report.forward_speed) / KT,
        "rotor_min_pct": 100 * report.min_rotor_speed / omega0,
        "rotor_max_pct": 100 * report.max_rotor_speed / omega0,
        "reason": report.reason,
        "plans": result.plans,
        "failed_plans": result.failed_plans,
        "unsafe_plans": result.unsafe_plans,
        "kept_out_plans": result.kept_out_plans,
        "wall_s": time.perf_counter() - started,
    }


def own_model_landing(flight: Flight) -> dict:
    """The truth check of a flight's draw (a worker process's job): a planner that knows the true model, cold."""
    airframe, settings = _settings(flight)
    own = own_landing(flight.model, airframe, settings, flight.height_ft * FT, flight.speed_kt * KT)
    return {"truth_safe": own.safe, "truth_value": own.value}


def run_tasks(tasks: list[Flight], workers: int, job=fly) -> list[dict]:
    if workers <= 1:
        return [job(task) for task in tasks]
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        return list(pool.map(job, tasks, chunksize=1))


def _distribution(stats: dict) -> str:
    return "min {min:.1f}  5% {p5:.1f}  median {median:.1f}  95% {p95:.1f}  max {max:.1f}".format(**stats)


def success_rate(within: int, runs: int) -> dict:
    """``within`` of ``runs``: the share in % and its 95 % Wilson interval in %."""
    low, high = wilson_interval(within, runs)
    return {"within": within, "runs": runs, "percent": 100 * within / max(runs, 1), "ci95": [100 * low, 100 * high]}


def _rate(within: int, runs: int) -> str:
    rate = success_rate(within, runs)
    low, high = rate["ci95"]
    return f"{within:4d}/{runs:<4d} {rate['percent']:5.1f} %  [{low:5.1f}, {high:5.1f}] %"


TOUCHDOWN_QUANTITIES = {
    "descent_ft_s": "touchdown descent rate ft/s",
    "speed_kt": "touchdown |forward speed| kt",
    "rotor_min_pct": "rotor minimum in flight %",
    "rotor_min_contact_pct": "rotor minimum to ground contact %",
    "rotor_max_pct": "rotor maximum in flight %",
    "touchdown_value": "touchdown J (the landing's margin, <= 0 within limits)",
}
"""The per-run results :func:`report` gives the distribution of, and their labels."""


TRUTH_MARGIN = 0.05
"""A draw whose own best landing has J above −this is a knife edge: a landing within 5 % of a touchdown limit even
with perfect knowledge of the aircraft. The truth check also reports the rate over the draws with more room."""

JUDGING_RULES = {
    "within": "rotor judged until the touchdown set",
    "within_contact": "rotor judged until ground contact",
}
"""The per-run verdicts: the rotor's limits held until the vehicle is in the touchdown set (|h| within the height
tolerance at touchdown speeds), or until ground contact (the replay's rule for flyable plans)."""


def report(
    policy: str, margin: Margin, states: list, seeds: list[int], draws: dict, results: list[dict], airframe, uncertainty
) -> dict:
    """Prints one policy and margin setting's results; returns the printed numbers."""
    limits = airframe.limits
    touchdown_rotor_floor = airframe.flyability.touchdown_min_rotor_speed_ratio
    print(f"\n== policy {policy}; margins: {margin.label()} ==")
    print(
        f"{'initial state':>16} {'margin':>7}  {'within/runs':>9} {'rate':>7}  95 % Wilson CI  "
        f"| to contact: {'within/runs':>9} {'rate':>7}  95 % Wilson CI"
    )
    numbers: dict = {"policy": policy, "margins": margin.label(), "states": []}
    for index, (height, speed, envelope_margin) in enumerate(states):
        mine = [r for seed, r in zip(seeds, results, strict=True) if seed % len(states) == index]
        within, at_contact = sum(r["within"] for r in mine), sum(r["within_contact"] for r in mine)
        print(
            f"{height:6.0f} ft {speed:4.0f} kt {envelope_margin:7.0f}  {_rate(within, len(mine))}  "
            f"| {_rate(at_contact, len(mine))}"
        )
        numbers["states"].append(
            {"height_ft": height, "speed_kt": speed, "envelope_margin": envelope_margin,
             **success_rate(within, len(mine)), "to_contact": success_rate(at_contact, len(mine))}
        )  # fmt: skip
    within, at_contact = sum(r["within"] for r in results), sum(r["within_contact"] for r in results)
    numbers["all"] = success_rate(within, len(results))
    numbers["all_to_contact"] = success_rate(at_contact, len(results))
    print(f"{'all':>16} {'':>7}  {_rate(within, len(results))}  | {_rate(at_contact, len(results))}")
    limit_values = {
        "descent_ft_s": limits.max_descent_rate / FT, "speed_kt": limits.max_forward_speed / KT,
        "rotor_min_pct": 100 * limits.min_rotor_speed_ratio, "rotor_max_pct": 100 * limits.max_rotor_speed_ratio,
        "rotor_min_contact_pct": 100 * touchdown_rotor_floor, "touchdown_value": 0.0,
    }  # fmt: skip
    numbers["touchdown"] = {}
    for key, label in TOUCHDOWN_QUANTITIES.items():
        stats = summary((r[key] for r in results), tails=True)
        numbers["touchdown"][key] = {**stats, "limit": limit_values[key]}
        print(f"{label} (limit {limit_values[key]:.0f}): {_distribution(stats)}")
    plans, unsafe = sum(r["plans"] for r in results), sum(r["unsafe_plans"] for r in results)
    failed, wall = sum(r["failed_plans"] for r in results), float(np.median([r["wall_s"] for r in results]))
    kept_out = sum(r["kept_out_plans"] for r in results)
    numbers.update(
        plans=plans, unsafe_plans=unsafe, kept_out_plans=kept_out, failed_plans=failed, wall_per_run_median_s=wall
    )
    print(
        f"plans {plans}, called not safe {unsafe} ({kept_out} of them kept out), solver failures {failed}; "
        f"closed-loop wall per run median {wall:.1f} s"
    )
    print("success by half of each range (lower half | upper half): what the failures lean on")
    numbers["halves"] = {}
    for name in uncertainty.uncertain_quantities:
        interval = uncertainty.ranges()[name]
        halves: tuple[list[bool], list[bool]] = ([], [])
        for seed, r in zip(seeds, results, strict=True):
            halves[draws[seed].values()[name] > 0.5 * (interval.low + interval.high)].append(r["within"])
        numbers["halves"][name] = [success_rate(sum(half), len(half)) for half in halves]
        print(f"  {name:24} " + " | ".join(_rate(sum(half), len(half)) for half in halves))
    failures = [(seed, r) for seed, r in zip(seeds, results, strict=True) if not r["within_contact"]]
    if results and results[0]["truth_safe"] is not None:
        attainable = [r for r in results if r["truth_safe"]]
        without = sum(not r["truth_safe"] for _, r in failures)  # by the stricter rule
        landed = {rule: sum(r[rule] for r in attainable) for rule in JUDGING_RULES}
        numbers["truth_check"] = {
            "runs_without_safe_landing": len(results) - len(attainable), "failures_without_safe_landing": without,
            "runs_with_one": success_rate(landed["within"], len(attainable)),
            "runs_with_one_to_contact": success_rate(landed["within_contact"], len(attainable)),
        }  # fmt: skip
        print(
            f"truth check: {len(results) - len(attainable)} of {len(results)} runs have no safe landing in their own "
            f"true model (cold IPOPT), {without} of the {len(failures)} failures; runs with one: "
            + "; ".join(f"{_rate(landed[rule], len(attainable))} ({label})" for rule, label in JUDGING_RULES.items())
        )
        with_margin = [r for r in attainable if r["truth_value"] <= -TRUTH_MARGIN]
        landed_with_margin = sum(r["within_contact"] for r in with_margin)
        numbers["truth_check"]["runs_with_margin_to_contact"] = success_rate(landed_with_margin, len(with_margin))
        print(
            f"  of the runs whose own landing has J <= -{TRUTH_MARGIN:g} (not a knife edge): "
            f"{_rate(landed_with_margin, len(with_margin))} (rotor judged until ground contact)"
        )
    print(
        f"failures to contact ({len(failures)}): seed, initial state, latency, reason[, J of the true model's own plan]"
    )
    numbers["failures"] = []
    for seed, r in failures:
        height, speed, _ = states[seed % len(states)]
        if r["within"]:  # within limits until the touchdown set: the rotor drooped in the last foot
            r = {**r, "reason": f"rotor down to {r['rotor_min_contact_pct']:.1f} % before ground contact"}
        truth = "" if r["truth_safe"] is None else f"; true model's own plan J {r['truth_value']:+.3f}"
        print(
            f"  seed {seed:4d}  {height:4.0f} ft {speed:4.0f} kt  latency {draws[seed].latency:.2f} s  "
            f"{r['reason']}{truth}"
        )
        numbers["failures"].append(
            {"seed": seed, "height_ft": height, "speed_kt": speed, "latency_s": draws[seed].latency,
             "reason": r["reason"], **({} if r["truth_safe"] is None else {"truth_value": r["truth_value"]})}
        )  # fmt: skip
    return numbers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=200, help="runs per setting (seeds first-seed ...)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--seeds", type=int, nargs="+", help="exactly these runs (overrides --runs)")
    parser.add_argument("--workers", type=int, default=2, help="local processes (the machine is shared: modest)")
    parser.add_argument("--margins", type=Margin.parse, nargs="+", default=[Margin(0.0, 0.0)], help="T/R ...")
    parser.add_argument("--uncertainty", default=DEFAULT_UNCERTAINTY_FILE)
    parser.add_argument("--no-weight-check", action="store_true", help="skip the +5 %% weight acceptance case")
    parser.add_argument(
        "--policies", type=parse_policy, nargs="+", default=["none"], help="re-planning policies (see the docstring)"
    )
    parser.add_argument(
        "--objectives", nargs="+", choices=OBJECTIVES, default=[None], help="planner objectives (default: the file's)"
    )
    parser.add_argument(
        "--truth-check", action="store_true", help="also solve each run's landing in its true model (see docstring)"
    )
    parser.add_argument(
        "--disturbance-gain", type=float, default=DisturbanceSettings().gain, help="the disturbance filter's gain"
    )
    parser.add_argument(
        "--replan-periods", type=float, nargs="+", default=[ClosedLoopSettings().replan_period],
        help="s between re-plans (each is run with every objective, policy and margin setting)",
    )  # fmt: skip
    parser.add_argument(
        "--state-gains", type=float, nargs="+", default=[DisturbanceSettings().state_gain],
        help="the disturbance observer's state gain alpha (1: plan from the raw measurement)",
    )  # fmt: skip
    parser.add_argument(
        "--disturbance-windows", "--disturbance-window", type=_window, nargs="+", default=[0],
        help="W: the disturbance estimate as the mean of the last W intervals (0: the filter of --disturbance-gain)",
    )  # fmt: skip
    parser.add_argument(
        "--noise",
        nargs="+",
        choices=("set", "none"),
        default=["set"],
        help="the uncertainty set's sensor noise or exact measurements (each is run with every other setting)",
    )
    parser.add_argument(
        "--planner-models", nargs="+", choices=PLANNER_MODELS, default=["nominal"],
        help="what the planner knows: the file's model or (an oracle) each run's true one",
    )  # fmt: skip
    parser.add_argument(
        "--replan-min-heights", type=float, nargs="+", default=[ClosedLoopSettings().min_height],
        help="m below which re-planning stops (each is run with every other setting)",
    )  # fmt: skip
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    airframe, _, uncertainty = _context(arguments.uncertainty)
    states = initial_states()
    seeds = arguments.seeds or list(range(arguments.first_seed, arguments.first_seed + arguments.runs))
    print(f"command: {record.command}; load average {record.load_before}")
    print(
        f"uncertainty set {uncertainty.name!r} ({', '.join(uncertainty.uncertain_quantities)}), uniform draws; "
        f"{len(seeds)} runs per margin setting over {len(states)} initial states, {arguments.workers} workers"
    )
    print(f"disturbance filter gain {arguments.disturbance_gain:g} (policies with 'disturbance'; unused with a window)")
    draws, noise_seeds = {}, {}
    for seed in seeds:
        draw_sequence, noise_sequence = np.random.SeedSequence(seed).spawn(2)
        draws[seed] = uncertainty.draw(np.random.default_rng(draw_sequence))[0]
        noise_seeds[seed] = int(noise_sequence.generate_state(1)[0])
    numbers: dict = {
        "uncertainty_set": uncertainty.name, "uncertain_quantities": list(uncertainty.uncertain_quantities),
        "runs": len(seeds), "initial_states": len(states), "workers": arguments.workers,
        "disturbance_gain": arguments.disturbance_gain, "disturbance_windows": arguments.disturbance_windows,
        "settings": [],
    }  # fmt: skip
    file_objective = _context(arguments.uncertainty)[1].objective

    def flights(
        margin: Margin,
        policy: str,
        objective: str,
        replan_period: float,
        planner_model: str = "nominal",
        state_gain: float = DisturbanceSettings().state_gain,
        noise: str = "set",
        window: int = 0,
        min_height: float = ClosedLoopSettings().min_height,
    ) -> list[Flight]:
        sensor_noise = uncertainty.sensor_noise if noise == "set" else SensorNoise()
        return [
            Flight(arguments.uncertainty, margin, *states[seed % len(states)][:2], draws[seed],
                   sensor_noise, noise_seeds[seed], policy, arguments.disturbance_gain, objective,
                   replan_period, planner_model, state_gain, window or None, min_height)
            for seed in seeds
        ]  # fmt: skip

    truths: list[dict] = [{"truth_safe": None, "truth_value": math.nan} for _ in seeds]
    if arguments.truth_check:  # once per draw: whether the true model can land does not depend on the policy
        started = time.perf_counter()
        truths = run_tasks(
            flights(Margin(0.0, 0.0), "none", file_objective, arguments.replan_periods[0]), arguments.workers,
            own_model_landing,
        )  # fmt: skip
        print(f"truth check of the {len(seeds)} draws: wall {time.perf_counter() - started:.0f} s")
    settings = itertools.product(
        arguments.noise, arguments.planner_models, [objective or file_objective for objective in arguments.objectives],
        arguments.replan_periods, arguments.replan_min_heights, arguments.state_gains, arguments.disturbance_windows,
        arguments.policies, arguments.margins,
    )  # fmt: skip
    for noise, planner_model, objective, replan_period, min_height, state_gain, window, policy, margin in settings:
        started = time.perf_counter()
        estimate = f"window {window}" if window else f"filter gain {arguments.disturbance_gain:g}"
        print(
            f"\n== planner model {planner_model}, objective {objective}, a re-plan every {replan_period:g} s down to "
            f"{min_height:g} m, "
            f"state gain {state_gain:g}, disturbance {estimate}, sensor noise {noise} =="
        )
        flown = flights(margin, policy, objective, replan_period, planner_model, state_gain, noise, window, min_height)
        results = run_tasks(flown, arguments.workers)
        results = [{**truth, **result} for truth, result in zip(truths, results, strict=True)]
        setting = report(policy, margin, states, seeds, draws, results, airframe, uncertainty)
        setting.update(
            objective=objective,
            replan_period_s=replan_period,
            replan_min_height_m=min_height,
            planner_model=planner_model,
            state_gain=state_gain,
            disturbance_window=window,
            sensor_noise=noise,
        )
        setting["wall_s"] = time.perf_counter() - started
        numbers["settings"].append(setting)
        print(f"wall {setting['wall_s']:.0f} s; load average {loadavg_text()}")
    if not arguments.no_weight_check:
        numbers["weight_check"] = weight_check(arguments)
    print(f"load average at the end {loadavg_text()}")
    if arguments.json:
        record.write(numbers)


def weight_check(arguments: argparse.Namespace) -> list[dict]:
    """The acceptance case: +5 % weight the planner does not know, the demo's noise, 500 ft / 75 kt. Prints and
    returns each landing."""
    demo = load_scenario("demo_500ft_75kt")
    print("\n== unknown +5 % gross weight, 500 ft / 75 kt, the demo's sensor noise, no other error ==")
    tasks, keys = [], []
    for policy in arguments.policies:
        for margin in arguments.margins:
            for latency in WEIGHT_CHECK_LATENCIES:
                for seed in WEIGHT_CHECK_SEEDS:
                    model = PerturbedModel({"gross_weight": 0.05}, latency=latency, label="gross_weight+5%")
                    tasks.append(
                        Flight(arguments.uncertainty, margin, 500.0, 75.0, model, demo.noise, seed, policy,
                               arguments.disturbance_gain)
                    )  # fmt: skip
                    keys.append((policy, margin, latency, seed))
    landings = []
    for (policy, margin, latency, seed), r in zip(keys, run_tasks(tasks, arguments.workers), strict=True):
        verdict = "within limits" if r["within"] else f"OUTSIDE: {r['reason']}"
        print(
            f"  {policy:12} {margin.label():34} latency {latency:.2f} s seed {seed}: {r['descent_ft_s']:4.1f} ft/s "
            f"{r['speed_kt']:4.1f} kt rotor {r['rotor_min_pct']:.1f}-{r['rotor_max_pct']:.1f} %  {verdict}"
        )
        landings.append(
            {"policy": policy, "margins": margin.label(), "latency_s": latency, "seed": seed,
             **{key: r[key] for key in TOUCHDOWN_QUANTITIES}, "within_limits": r["within"],
             "reason": "" if r["within"] else r["reason"]}
        )  # fmt: skip
    return landings


if __name__ == "__main__":
    main()
