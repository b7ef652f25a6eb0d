"""acados (SQP, HPIPM) against the package's IPOPT planner on the same landing OCP and the same states.

Run (two interpreters: acados' wheel vendors a slim ``casadi`` that must not shadow the real one):

    python3 -m venv /tmp/acados_venv && /tmp/acados_venv/bin/pip install comma-deps-acados numpy pyyaml
    .venv/bin/python bench/acados_compare.py [--states 30] [--acados-python /tmp/acados_venv/bin/python]

This process (the project's venv) solves every state with the planner (IPOPT, warm-started from a
neighbour's plan half an envelope cell away, as the planner node does) and replays every plan with the
package's own CVODES replay (:func:`helireach_ros.core.verification.replay_plan`). A child process
under the isolated interpreter formulates the same OCP for acados — 20 shooting intervals with the
verified transcription's geometric mesh, piecewise-constant controls, free landing time T as a state,
epigraph slack of the normalised terminal cost, the same rotor-speed back-off and ground bounds, the
same control-smoothness term (previous control carried as a state) — and solves it with SQP + HPIPM
(exact Hessian), warm-started from its own solution at the same neighbour. Its controls come back here
and are replayed and classified exactly like the planner's (``safe`` needs value ≤ 0 and the replay).

Differences that cannot be removed in acados' stage-wise form: the dynamics are integrated by 3 explicit
RK4 steps per interval (the planner: Radau IIA collocation, 3 points), and the rotor-speed and ground
bounds hold at the interval ends only (the planner: at every collocation point). Prints time p50/p95,
iterations, value and classification agreement, replay verdicts, the load, and the ratio of the median
solve times in this run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

_SUBSTEPS = 3


# --- the acados side (runs under the isolated interpreter) -------------------------------------------------------


def _acados_worker(exchange: Path) -> None:
    """Builds the acados OCP from ``exchange/problem.npz`` and writes ``exchange/acados.npz``."""
    import acados

    os.environ.setdefault("ACADOS_SOURCE_DIR", acados.DIR)
    os.environ.setdefault("ACADOS_PYTHON_INTERFACE_PATH", acados.TEMPLATE_DIR)
    sys.path.insert(0, os.path.dirname(acados.__file__))
    import ctypes

    for library in ("libblasfeo.so", "libhpipm.so", "libqpOASES_e.so.3.1", "libacados.so"):  # not on the loader path
        ctypes.CDLL(os.path.join(acados.LIB_DIR, library), mode=ctypes.RTLD_GLOBAL)
    import casadi as ca
    from acados_template import AcadosModel, AcadosOcp, AcadosOcpSolver

    from helireach_ros.core.airframe import load_airframe
    from helireach_ros.core.model import dynamics_function

    problem = dict(np.load(exchange / "problem.npz"))
    config = json.loads(str(problem["config"]))
    airframe = load_airframe(config["airframe"])
    dynamics = dynamics_function(airframe)
    state_scale, control_scale = problem["state_scale"], problem["control_scale"]
    fractions = problem["fractions"]
    intervals = len(fractions)
    time_scale = 10.0

    # augmented scaled state: x (6), T / 10, slack, previous control (2)
    xs = ca.SX.sym("x", 10)
    us = ca.SX.sym("u", 2)
    fraction = ca.SX.sym("fraction")
    physical_control = us * control_scale
    landing_time = xs[6] * time_scale
    step = landing_time * fraction / _SUBSTEPS

    def f(x_scaled):
        return dynamics(x_scaled * state_scale, physical_control) / state_scale

    x = xs[:6]
    for _ in range(_SUBSTEPS):
        k1 = f(x)
        k2 = f(x + 0.5 * step * k1)
        k3 = f(x + 0.5 * step * k2)
        k4 = f(x + step * k3)
        x = x + step / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    model = AcadosModel()
    model.name = "landing"
    model.x, model.u, model.p = xs, us, fraction
    model.disc_dyn_expr = ca.vertcat(x, xs[6], xs[7], us)
    limits = config["limits"]
    terms = [
        xs[0] * state_scale[0] / limits["max_descent_rate"],
        xs[1] * state_scale[1] / limits["max_forward_speed"],
        xs[3] * state_scale[3] / limits["height_tolerance"],
    ]
    model.con_h_expr_e = ca.vertcat(*[sign * term - 1.0 - xs[7] for term in terms for sign in (1.0, -1.0)])
    weight = config["smoothness_weight"]
    model.cost_expr_ext_cost = weight * ca.sumsqr(us - xs[8:10])
    model.cost_expr_ext_cost_0 = 0.0 * ca.sumsqr(us)  # the first interval has no predecessor
    model.cost_expr_ext_cost_e = xs[7]

    ocp = AcadosOcp()
    ocp.model = model
    ocp.dims.N = intervals  # this acados version: dims.N (newer ones: solver_options.N_horizon)
    ocp.solver_options.tf = float(intervals)
    ocp.cost.cost_type = ocp.cost.cost_type_0 = ocp.cost.cost_type_e = "EXTERNAL"
    ocp.parameter_values = np.array([fractions[0]])
    lower, upper = problem["state_lower_scaled"], problem["state_upper_scaled"]
    ocp.constraints.idxbx_0 = np.arange(7)
    ocp.constraints.lbx_0 = np.concatenate([problem["states"][0], [config["min_time_scaled"]]])
    ocp.constraints.ubx_0 = np.concatenate([problem["states"][0], [config["max_time_scaled"]]])
    ocp.constraints.idxbx = np.array([2, 3])
    ocp.constraints.lbx, ocp.constraints.ubx = lower[[2, 3]], upper[[2, 3]]
    ocp.constraints.idxbx_e = np.array([2, 3])
    ocp.constraints.lbx_e, ocp.constraints.ubx_e = lower[[2, 3]], upper[[2, 3]]
    ocp.constraints.idxbu = np.array([0, 1])
    ocp.constraints.lbu, ocp.constraints.ubu = problem["control_lower_scaled"], problem["control_upper_scaled"]
    ocp.constraints.lh_e, ocp.constraints.uh_e = np.full(6, -1e9), np.zeros(6)
    options = ocp.solver_options
    options.integrator_type = "DISCRETE"
    options.nlp_solver_type = "SQP"
    options.qp_solver = "PARTIAL_CONDENSING_HPIPM"
    options.hessian_approx = "EXACT"
    options.regularize_method = "MIRROR"
    options.globalization = "MERIT_BACKTRACKING"
    options.nlp_solver_max_iter = config["max_iterations"]
    options.tol = config["tolerance"]
    options.qp_solver_iter_max = 200
    options.print_level = 0
    for name, value in config["acados_options"].items():  # --acados-options: try other solver settings
        setattr(options, name, value)
    build_dir = exchange / "acados_build"
    ocp.code_export_directory = str(build_dir / "c_generated_code")
    started = time.perf_counter()
    solver = AcadosOcpSolver(ocp, json_file=str(build_dir / "landing_ocp.json"), verbose=False)
    build_s = time.perf_counter() - started
    for k in range(intervals):
        solver.set(k, "p", np.array([fractions[k]]))

    def initialise(guess_x: np.ndarray, guess_u: np.ndarray) -> None:
        for k in range(intervals + 1):
            solver.set(k, "x", guess_x[k])
        for k in range(intervals):
            solver.set(k, "u", guess_u[k])

    def solve(initial: np.ndarray) -> tuple[int, float, int]:
        low = np.concatenate([initial, [config["min_time_scaled"]]])
        high = np.concatenate([initial, [config["max_time_scaled"]]])
        solver.constraints_set(0, "lbx", low)
        solver.constraints_set(0, "ubx", high)
        started = time.perf_counter()
        status = solver.solve()
        elapsed = time.perf_counter() - started
        return status, 1e3 * elapsed, int(np.ravel(solver.get_stats("sqp_iter"))[0])

    results: dict[str, list] = {"status": [], "time_ms": [], "iterations": [], "x": [], "u": [], "cost": []}
    for index in range(len(problem["states"])):
        initialise(problem["guess_x"][index], problem["guess_u"][index])
        solve(problem["neighbours"][index])  # acados' own solution at the neighbour: its warm start
        status, elapsed, iterations = solve(problem["states"][index])
        results["status"].append(status)
        results["time_ms"].append(elapsed)
        results["iterations"].append(iterations)
        results["x"].append(np.array([solver.get(k, "x") for k in range(intervals + 1)]))
        results["u"].append(np.array([solver.get(k, "u") for k in range(intervals)]))
        results["cost"].append(solver.get_cost())
    np.savez(exchange / "acados.npz", build_s=build_s, **{k: np.asarray(v) for k, v in results.items()})


# --- the project side ---------------------------------------------------------------------------------------------


def _compare(arguments: argparse.Namespace) -> None:
    from _common import command_line, loadavg_text, summary

    from helireach_ros.core.airframe import load_airframe
    from helireach_ros.core.model import initial_state_after_failure
    from helireach_ros.core.planner import get_planner
    from helireach_ros.core.settings import load_settings
    from helireach_ros.core.transcription.base import DecodedPlan, terminal_cost
    from helireach_ros.core.units import FT, KT
    from helireach_ros.core.verification import replay_plan

    print(f"command: {command_line()}; load average {loadavg_text()}")
    airframe, settings = load_airframe(arguments.airframe), load_settings()
    planner = get_planner(airframe, settings)
    transcription = planner.transcription
    intervals = settings.intervals
    rng = np.random.default_rng(13)
    points = np.column_stack([rng.uniform(20.0, 800.0, arguments.states), rng.uniform(2.5, 120.0, arguments.states)])
    scale = transcription.state_scale
    states, neighbours, guess_x, guess_u, ipopt = [], [], [], [], []
    for height_ft, speed_kt in points:
        state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT).as_array()
        neighbour = initial_state_after_failure(airframe, (height_ft - 10.0) * FT, (speed_kt - 2.5) * KT).as_array()
        start = planner.plan(neighbour)
        ipopt.append(planner.plan(state, warm_start=start.warm_start))
        ends = start.states[:, :: settings.degree]  # x0 and every interval end
        slack = float(start.warm_start.primal[1])
        controls = start.control_values / transcription.control_scale[:, None]
        previous = np.column_stack([controls[:, :1], controls])  # previous control at each node
        guess_x.append(
            np.column_stack(
                [(ends / scale[:, None]).T, np.full(intervals + 1, start.time_to_land / 10.0),
                 np.full(intervals + 1, slack), previous.T]
            )
        )  # fmt: skip
        guess_u.append(controls.T)
        states.append(state / scale)
        neighbours.append(neighbour / scale)
    limits = airframe.limits
    config = {
        "airframe": arguments.airframe,
        "limits": {
            "max_descent_rate": limits.max_descent_rate,
            "max_forward_speed": limits.max_forward_speed,
            "height_tolerance": limits.height_tolerance,
        },
        "smoothness_weight": settings.smoothness_weight,
        "min_time_scaled": settings.min_time_to_land / 10.0,
        "max_time_scaled": settings.max_time_to_land / 10.0,
        "max_iterations": settings.max_iterations,
        "tolerance": settings.tolerance,
        "acados_options": json.loads(arguments.acados_options),
    }
    with tempfile.TemporaryDirectory(prefix="acados_compare_") as folder:
        exchange = Path(folder)
        np.savez(
            exchange / "problem.npz",
            config=json.dumps(config),
            state_scale=scale,
            control_scale=transcription.control_scale,
            fractions=transcription.fractions,
            state_lower_scaled=transcription.state_lower / scale,
            state_upper_scaled=transcription.state_upper / scale,
            control_lower_scaled=transcription.control_lower / transcription.control_scale,
            control_upper_scaled=transcription.control_upper / transcription.control_scale,
            states=np.array(states),
            neighbours=np.array(neighbours),
            guess_x=np.array(guess_x),
            guess_u=np.array(guess_u),
        )
        environment = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
        child = subprocess.run(
            [arguments.acados_python, __file__, "--worker", str(exchange)], env=environment, text=True,
            capture_output=True, check=False,
        )  # fmt: skip
        if child.returncode != 0:
            print(f"acados worker failed ({child.returncode}):\n{child.stdout[-3000:]}\n{child.stderr[-3000:]}")
            sys.exit(1)
        acados_results = dict(np.load(exchange / "acados.npz"))
    print(f"acados options overridden: {config['acados_options'] or 'none'}")
    print(f"acados OCP generated and compiled in {float(acados_results['build_s']):.1f} s")
    rows = []
    for index, plan in enumerate(ipopt):
        x, u = acados_results["x"][index], acados_results["u"][index]
        landing_time = float(x[0, 6]) * 10.0
        node_states = (x[:, :6] * scale).T
        node_states[:, 0] = states[index] * scale
        decoded = DecodedPlan(
            landing_time,
            np.concatenate([transcription.interval_starts, [1.0]]) * landing_time,
            node_states,
            np.concatenate([transcription.interval_starts, [1.0]]) * landing_time,
            (u * transcription.control_scale).T,
            "zero_order_hold",
            np.zeros(0),
            np.zeros((6, 0)),
        )
        value = float(terminal_cost(airframe, node_states[:, -1]))
        replay = replay_plan(airframe, settings, states[index] * scale, decoded)
        converged = int(acados_results["status"][index]) == 0
        status = (
            "failed" if not converged else "unsafe" if value > 0 else "unverified" if not replay.lands_within_limits
            else "safe"
        )  # fmt: skip
        rows.append((plan, status, value, converged))
    ipopt_ms = np.array([plan.solver.solve_time_ms for plan in ipopt])
    acados_ms = acados_results["time_ms"]
    print(f"\n{len(ipopt)} states (seeded uniform over 20-800 ft x 2.5-120 kt), each warm-started from its own")
    print("solver's solution at a neighbour 10 ft / 2.5 kt away; times are solver wall time per solve")
    for name, times, iterations in (
        ("IPOPT (planner)", ipopt_ms, [plan.solver.iterations for plan in ipopt]),
        ("acados SQP+HPIPM", acados_ms, acados_results["iterations"]),
    ):
        stats = summary(times)
        print(
            f"  {name:18s} p50 {stats['median']:7.2f} ms  p95 {stats['p95']:7.2f} ms  "
            f"iterations mean {np.mean(iterations):5.1f}"
        )
    print(f"  ratio of medians acados / IPOPT: {np.median(acados_ms) / np.median(ipopt_ms):.3f}")
    converged = sum(row[3] for row in rows)
    same = sum(row[0].status == row[1] for row in rows)
    gaps = [abs(row[0].value - row[2]) for row in rows if row[3] and row[0].solver.success]
    print(
        f"  acados converged {converged} of {len(rows)} (acados status codes {acados_results['status'].tolist()}); "
        f"same status as the planner {same} of {len(rows)}"
    )
    if gaps:
        print(f"  |value difference| where both converged: median {np.median(gaps):.2e}, max {np.max(gaps):.2e}")
    verdicts = {}
    for plan, status, _, _ in rows:
        verdicts[(plan.status, status)] = verdicts.get((plan.status, status), 0) + 1
    print("  (planner status, acados status after the same replay): count")
    for key, count in sorted(verdicts.items()):
        print(f"    {key}: {count}")
    adopt = same == len(rows) and np.median(acados_ms) * 2.0 <= np.median(ipopt_ms)
    print(f"  adoption rule (equal verdicts on every state and >= 2x speed): {'met' if adopt else 'not met'}")
    print(f"load average {loadavg_text()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=30)
    parser.add_argument("--airframe", default="uh60a_class")
    parser.add_argument("--acados-python", default="/tmp/acados_venv/bin/python")
    parser.add_argument("--acados-options", default="{}", help="JSON: acados solver_options to override")
    parser.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.worker is not None:
        _acados_worker(arguments.worker)
    else:
        _compare(arguments)


if __name__ == "__main__":
    main()
