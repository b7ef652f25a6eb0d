"""Two ways to put the momentum rotor's inflow into the landing NLP, measured in one run: fixed Newton steps in the
expression graph (what the planner does) against the two momentum roots as NLP variables per collocation point.

Run: .venv/bin/python bench/inflow_formulation.py [--airframe oh58a_class]

The second is built here, on the flyable transcription, from ``model.implicit_inflow_functions``: 2 variables per
collocation point (the roots in m/s, scaled by 10 m/s, bounded to [1e-7, 300] m/s), 2 equality constraints each
(the momentum residuals), and the dynamics with the roots as inputs. Both solve the same 16 cold flyable plans
(100-700 ft, 0-80 kt) with the default settings and plain CasADi functions; the bench prints median iterations,
median solve time, time per iteration and the statuses, and the ratios.
"""

from __future__ import annotations

import argparse
import sys

import casadi as ca
import numpy as np
from _common import command_line, loadavg_text

from helireach_ros.core import planner as planner_module
from helireach_ros.core.airframe import load_airframe
from helireach_ros.core.compiled_nlp import CodegenSettings
from helireach_ros.core.model import implicit_inflow_functions, initial_state_after_failure
from helireach_ros.core.settings import load_settings
from helireach_ros.core.transcription.flyable import FlyableTranscription
from helireach_ros.core.transcription.verified import _TIME_SCALE, VerifiedTranscription
from helireach_ros.core.units import FT, KT

ROOT_SCALE = 10.0  # m/s
HEIGHTS_FT = (100, 300, 500, 700)
SPEEDS_KT = (0, 40, 60, 80)


class _RootsAsInputs:
    """Stands in for the transcription's dynamics: the map over the points, with the root variables passed in."""

    def __init__(self, dynamics: ca.Function, roots) -> None:
        self.dynamics, self.roots = dynamics, roots

    def map(self, count: int):
        def evaluate(states, controls, disturbance):
            return self.dynamics.map(count)(states, controls, ca.repmat(disturbance, 1, count), self.roots)

        return evaluate


class RootsAsVariables(FlyableTranscription):
    """The flyable transcription with the momentum roots as NLP variables (appended to the decision vector)."""

    def _build(self) -> None:
        count = self.settings.intervals * self.settings.degree
        dynamics, self._residuals, self._roots = implicit_inflow_functions(self.airframe)
        roots_scaled = ca.SX.sym("roots", 2 * count)
        roots = ca.reshape(roots_scaled, 2, count) * ROOT_SCALE
        self.dynamics = _RootsAsInputs(dynamics, roots)
        super()._build()
        intervals = self.settings.intervals
        decision = self.decision
        states = ca.reshape(decision[2 + 2 * intervals :], len(self.state_rows), self.n_states)
        physical_states = self.point_states(states, decision[0] * _TIME_SCALE, self.initial_state)
        decided = ca.reshape(decision[2 : 2 + 2 * intervals], 2, intervals)
        breakpoints = ca.horzcat(self.initial_control, decided * ca.repmat(ca.DM(self.control_scale), 1, intervals))
        controls = ca.horzcat(
            *[
                breakpoints[:, k] + float(tau) * (breakpoints[:, k + 1] - breakpoints[:, k])
                for k in range(intervals)
                for tau in self.radau
            ]
        )
        residuals = self._residuals.map(count)(physical_states, controls, roots)
        self.decision = ca.vertcat(decision, roots_scaled)
        self.constraints = ca.vertcat(self.constraints, ca.reshape(residuals, -1, 1))
        self.lbg, self.ubg = (np.concatenate([bound, np.zeros(2 * count)]) for bound in (self.lbg, self.ubg))
        self.lbx = np.concatenate([self.lbx, np.full(2 * count, 1e-7 / ROOT_SCALE)])
        self.ubx = np.concatenate([self.ubx, np.full(2 * count, 300.0 / ROOT_SCALE)])
        self._root_count = 2 * count

    def initial_guess(self, initial_state: np.ndarray) -> np.ndarray:
        guess = VerifiedTranscription.initial_guess(self, initial_state)
        guess = np.clip(guess, self.lbx[: guess.size], self.ubx[: guess.size])
        states = self.decoded_states(np.concatenate([guess, np.zeros(self._root_count)]), guess[0] * _TIME_SCALE,
                                     initial_state)  # fmt: skip
        control = np.array([self.hover_thrust_coefficient, 0.0])
        roots = np.column_stack(
            [np.asarray(self._roots(states[:, k], control)).reshape(-1) for k in range(self.n_states)]
        )
        return np.clip(np.concatenate([guess, roots.reshape(-1, order="F") / ROOT_SCALE]), self.lbx, self.ubx)

    def decoded_states(self, solution: np.ndarray, landing_time: float, initial_state: np.ndarray) -> np.ndarray:
        return super().decoded_states(solution[: solution.size - self._root_count], landing_time, initial_state)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--airframe", default="oh58a_class")
    arguments = parser.parse_args(argv)
    print(f"command: {command_line()}")
    print(f"load average (1/5/15 min): {loadavg_text()}")
    airframe = load_airframe(arguments.airframe).with_rotor_model_choice("momentum")
    codegen = CodegenSettings(mode="off")
    results = {}
    formulations = (("Newton steps in the graph", FlyableTranscription), ("roots as variables", RootsAsVariables))
    for label, transcription in formulations:
        planner_module.TRANSCRIPTIONS["flyable"] = transcription
        planner = planner_module.LandingPlanner(airframe, load_settings(), codegen)
        iterations, times, statuses = [], [], []
        for height in HEIGHTS_FT:
            for speed in SPEEDS_KT:
                plan = planner.plan(initial_state_after_failure(airframe, height * FT, speed * KT))
                iterations.append(plan.solver.iterations)
                times.append(plan.solver.solve_time_ms)
                statuses.append(plan.status)
        results[label] = (np.median(iterations), np.median(times), np.sum(times) / np.sum(iterations), statuses)
        median_iterations, median_ms, per_iteration, _ = results[label]
        print(f"{label}: median iterations {median_iterations:.1f}, median {median_ms:.1f} ms, "
              f"{per_iteration:.2f} ms per iteration, {planner.nlp_functions.split('(')[0].strip()}",
              flush=True)  # fmt: skip
    planner_module.TRANSCRIPTIONS["flyable"] = FlyableTranscription
    (newton, variables) = results.values()
    same = sum(a == b for a, b in zip(newton[3], variables[3], strict=True))
    print(f"variables / Newton: median solve {variables[1] / newton[1]:.2f}x, per iteration "
          f"{variables[2] / newton[2]:.2f}x, iterations {variables[0] / newton[0]:.2f}x; "
          f"same status {same}/{len(newton[3])}")  # fmt: skip
    print(f"load average (1/5/15 min): {loadavg_text()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
