"""What the momentum rotor costs the NLP: cold flyable plans with the paper's rotor and the momentum rotor, one run.

Run: .venv/bin/python bench/rotor_model_cost.py [--airframe oh58a_class] [--codegen off|cached|build]

Prints, per rotor model, the size of the dynamics' Lagrangian Hessian (expression nodes), the NLP build time, and
over 16 states (100-700 ft, 0-80 kt) the median IPOPT iterations, the median solve time and the time per iteration,
then the ratios momentum / paper. ``--codegen build`` compiles each NLP first (about 10 s for the paper's rotor,
about 3 min for the momentum rotor on 2 cores); the default ``off`` measures the plain CasADi functions.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import casadi as ca
import numpy as np
from _common import command_line, loadavg_text

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import dynamics_function, initial_state_after_failure
from helireach_ros.core.ocp.compiled_nlp import CodegenSettings
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import LandingPlanner
from helireach_ros.core.units import FT, KT

HEIGHTS_FT = (100, 300, 500, 700)
SPEEDS_KT = (0, 40, 60, 80)


def _hessian_nodes(airframe) -> int:
    dynamics = dynamics_function(airframe)
    state, control, multipliers = ca.SX.sym("x", 6), ca.SX.sym("u", 2), ca.SX.sym("l", 6)
    lagrangian = ca.dot(multipliers, dynamics(state, control))
    hessian = ca.hessian(lagrangian, ca.vertcat(state, control))[0]
    return ca.Function("hessian", [state, control, multipliers], [hessian]).n_nodes()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--airframe", default="oh58a_class")
    parser.add_argument("--codegen", choices=("off", "cached", "build"), default="off")
    arguments = parser.parse_args(argv)
    codegen = dataclasses.replace(CodegenSettings.from_environment(), mode=arguments.codegen)
    print(f"load {loadavg_text()}")
    results = {}
    for choice in ("paper", "momentum"):
        airframe = load_airframe(arguments.airframe).with_rotor_model_choice(choice)
        started = time.perf_counter()
        planner = LandingPlanner(airframe, load_settings(), codegen)
        build_s = time.perf_counter() - started
        iterations, solve_ms = [], []
        for height in HEIGHTS_FT:
            for speed in SPEEDS_KT:
                plan = planner.plan(initial_state_after_failure(airframe, height * FT, speed * KT))
                iterations.append(plan.solver.iterations)
                solve_ms.append(plan.solver.solve_time_ms)
        results[choice] = {
            "hessian nodes": _hessian_nodes(airframe),
            "build s": build_s,
            "median iterations": float(np.median(iterations)),
            "median solve ms": float(np.median(solve_ms)),
            "ms per iteration": float(np.sum(solve_ms) / np.sum(iterations)),
        }
        print(f"{choice:8s} " + "  ".join(f"{key} {value:.3g}" for key, value in results[choice].items())
              + f"  ({planner.nlp_functions.split('(')[0].strip()})", flush=True)  # fmt: skip
    ratios = {key: results["momentum"][key] / results["paper"][key] for key in results["paper"]}
    print("momentum / paper: " + "  ".join(f"{key} {value:.2f}x" for key, value in ratios.items()))
    print(f"load {loadavg_text()}; command: {command_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
