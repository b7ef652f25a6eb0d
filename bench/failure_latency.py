"""Failure message → landing trajectory on the wire: p50/p95 over many failures at different states.

Run: .venv/bin/python bench/failure_latency.py [--failures 40] [--mode both|composed|cross-process] [--seed 1]
     [--executor single_threaded|events] [--baseline] [--json]

For each failure the bench streams a level-flight state (50 Hz odometry and rotor speed) at a seeded
random (height, speed) over 50–800 ft × 0–115 kt (off the envelope grid, so the warm start is a
neighbouring stored plan, not the same state), lets the planner receive it, then publishes the
engine-failure flag and times, on this process's clock, from ``publish()`` to the arrival of the
landing trajectory stamped with that state. The path is the product's: vehicle flag → monitor →
failure event → planner (warm start from the envelope, IPOPT, independent replay) → trajectory → back.

* ``composed``: monitor, envelope status, planner and MCAP recorder in this process under bringup's
  executor (``--executor``, default single-threaded); the bench's node shares the executor as one of the
  system's extra nodes (``build_system(extra_nodes=...)``, where a vehicle bridge or the display composes in).
* ``cross-process``: ``helireach bringup`` in a child process (LOCALHOST discovery, a random domain
  id); the DDS transport is paid both ways.

Closed-loop re-planning is off (``replan_period:=0``) so every failure starts from an idle planner, as
a real failure would; the deadline stays at its default, and a flagged fallback published first is
counted (and its own latency reported). Between failures the flag is false for longer than the monitor's
``recovery_hold`` (set to 0.2 s here), so each failure is a new episode, and the state is streamed long enough
(``_SETTLE_S``) for a live verdict from it: with the default configuration (solver workers, live evaluation at
5 Hz) the first trajectory of a failure from a safe state is the **standby** plan, then the **refined** plan
from the state at the failure follows; both are timed. The state and the false flag are streamed on a 20 ms
schedule, as a vehicle streams them (not after every ``spin_once``, which flooded the queues), and a failure
without any trajectory within 10 s is counted and reported, not fatal. ``--baseline`` also runs, in the same
run, ``solver_workers:=0 live_rate:=0`` (the legacy configuration: solves on the node's thread, no
standby) and prints the ratio of its failure → first trajectory p50/p95 to the defaults'. ``--site START:END``
also runs, in the same run, the defaults with one landing site ``START``–``END`` m ahead of every failure state
(the bench's odometry stays at distance 0; planner parameter ``landing_sites``): the live evaluations then aim at
the site, so a standby plan is the site's when the site is reachable, and the refined plan lands on it or, not
reachable, anywhere; it prints how many first and refined plans were made for the site and the ratio of its
latencies to the defaults'. Prints the command
line and what it measured on this machine, with the load average; ``--json`` also writes it to
docs/results/data/failure_latency.json.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import rclpy
from _common import Record, add_json_argument, loadavg_text, machine_text, summary, summary_text
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.bringup import build_system
from helireach_ros.ros.executors import DEFAULT_EXECUTOR, EXECUTOR_KINDS

_NO_REPLANNING = ["-p", "helireach_planner:replan_period:=0.0", "-p", "helireach_monitor:recovery_hold:=0.2"]
_BASELINE = ["-p", "helireach_planner:solver_workers:=0", "-p", "helireach_planner:live_rate:=0.0"]
_SETTLE_S = 0.8  # flag false and the state streamed before each failure: episode ended (0.2 s), a live verdict
_TIMEOUT_S = 10.0
_STREAM_PERIOD_S = 0.02  # 50 Hz odometry, rotor speed and (false) failure flag, as a vehicle streams them
_NO_CONVERGENCE_S = 3.0  # after a fallback: give up waiting for a converged plan (the solve failed)


class Vehicle:
    """The bench's side: streams a state, raises the failure flag, receives trajectories and plan statuses."""

    def __init__(self, node: Node, executor: Executor) -> None:
        self.node = node
        self.executor = executor
        executor.add_node(self.node)  # no-op when it is already one of the composed system's nodes
        # No QoS event handlers on the bench's own endpoints: in the composed system they would be waited on with
        # the nodes' (one wait-set entry each, rebuilt in Python on every wake-up) and slow the system it measures.
        quiet_publisher, quiet_subscription = rm.NO_QOS_EVENTS_PUBLISHER, rm.NO_QOS_EVENTS_SUBSCRIPTION
        self.odometry = self.node.create_publisher(Odometry, rm.TOPIC_ODOMETRY, rm.STREAM_QOS, **quiet_publisher)
        self.rotor = self.node.create_publisher(JointState, rm.TOPIC_ROTOR, rm.STREAM_QOS, **quiet_publisher)
        self.failure = self.node.create_publisher(Bool, rm.TOPIC_ENGINE_FAILURE, rm.EVENT_QOS, **quiet_publisher)
        self.arrivals: list[tuple[float, JointTrajectory]] = []
        self.statuses: list[dict[str, str]] = []
        self.node.create_subscription(
            JointTrajectory,
            rm.TOPIC_LANDING_TRAJECTORY,
            lambda message: self.arrivals.append((time.perf_counter(), message)),
            rm.STREAM_QOS,
            **quiet_subscription,
        )
        self.node.create_subscription(
            DiagnosticStatus,
            rm.TOPIC_PLAN_STATUS,
            lambda message: self.statuses.append(rm.status_values(message)),
            rm.STREAM_QOS,
            **quiet_subscription,
        )
        self.stamps: set[int] = set()
        self.details: list[tuple[float, float, int]] = []  # (IPOPT ms, planner event->publish ms, iterations)
        self.stale = 0  # failures planned from a state older than the one streamed for them
        self.lost = 0  # failures without any trajectory within _TIMEOUT_S

    def spin_for(self, duration_s: float, state: tuple[float, float] | None = None) -> None:
        """Spins, streaming ``state`` (height m, speed m/s) and a false failure flag every 20 ms when given.

        On a schedule, not once per ``spin_once``: in the composed system ``spin_once`` returns after *one*
        callback, so publishing on every return streamed at ~1.3 kHz and filled every queue to its depth (the
        true flag then waited behind ~10 queued false ones: ~40 ms of the composed latency before the fix).
        """
        now = time.perf_counter()
        deadline, next_publish = now + duration_s, now
        while now < deadline:
            if state is not None and now >= next_publish:
                next_publish += _STREAM_PERIOD_S
                stamp = self.node.get_clock().now().nanoseconds
                self.stamps.add(stamp)
                self.odometry.publish(rm.odometry_message(stamp, state[0], 0.0, state[1], 0.0))
                self.rotor.publish(rm.rotor_message(stamp, 27.0))
                self.failure.publish(Bool(data=False))
            wake = min(next_publish, deadline) if state is not None else deadline
            self.executor.spin_once(timeout_sec=max(min(wake - now, _STREAM_PERIOD_S), 0.0))
            now = time.perf_counter()

    def wait_for_subscribers(self) -> None:
        """Discovery both ways: the monitor sees the vehicle's topics and the bench sees the planner's."""
        deadline = time.perf_counter() + 30.0
        while (
            self.failure.get_subscription_count() == 0
            or self.odometry.get_subscription_count() == 0
            or self.node.count_publishers(rm.TOPIC_LANDING_TRAJECTORY) == 0
            or self.node.count_publishers(rm.TOPIC_PLAN_STATUS) == 0
        ):
            if time.perf_counter() > deadline:
                raise RuntimeError("the nodes never matched the bench (discovery failed?)")
            self.executor.spin_once(timeout_sec=0.05)

    def fail(self, state: tuple[float, float]) -> dict[str, float | str]:
        """One failure at a state: ms to the first trajectory and its kind, ms to the refined (converged) plan."""
        self.stamps.clear()
        self.spin_for(_SETTLE_S, state)  # ends the previous episode (recovery_hold) and lets a live verdict come
        self.arrivals.clear()
        self.statuses.clear()
        started = time.perf_counter()
        self.failure.publish(Bool(data=True))
        deadline = started + _TIMEOUT_S
        # The planner publishes each trajectory right before its status: the k-th of each belong together.
        while time.perf_counter() < deadline:
            self.executor.spin_once(timeout_sec=0.005)
            mine = [t for t, _ in self.arrivals]
            # statuses without a trajectory (the previous episode's "ended", a "none") are not paired
            statuses = [values for values in self.statuses if values.get("status") not in ("ended", "none")]
            statuses = statuses[: len(mine)]
            if not statuses:
                continue
            first = statuses[0]
            for_site = [values.get("site_planned") == "true" for values in statuses]
            kind = "standby" if first.get("standby") == "true" else "fallback" if first["fallback"] == "true" else ""
            refined = [
                k
                for k, values in enumerate(statuses)
                if values["fallback"] == "false" and values.get("standby") != "true"
            ]
            if refined:
                values = statuses[refined[0]]
                # Re-planning is off, so whatever arrives after the flag answers it; a plan from a state not
                # streamed for this failure (the previous failure's) is counted as stale.
                self.stale += any(
                    int(v.get("state_stamp_ns", -1)) not in self.stamps for v in statuses[: refined[0] + 1]
                )
                self.details.append(
                    (float(values["solve_time_ms"]), float(values["latency_ms"]), int(values["iterations"]))
                )
                return {
                    "first": 1e3 * (mine[0] - started),
                    "kind": kind or "refined",
                    "refined": 1e3 * (mine[refined[0]] - started),
                    "first_in_planner": float(first["latency_ms"]),
                    "first_for_site": for_site[0],
                    "refined_for_site": for_site[refined[0]],
                }
            if kind != "standby" and time.perf_counter() > started + _NO_CONVERGENCE_S:
                first_ms, in_planner = 1e3 * (mine[0] - started), float(first["latency_ms"])
                return {
                    "first": first_ms, "kind": kind, "refined": math.nan, "first_in_planner": in_planner,
                    "first_for_site": for_site[0], "refined_for_site": False,
                }  # fmt: skip
        # Counted, not fatal: the run goes on, and the report says how many (a trajectory that never arrived).
        self.lost += 1
        self.node.get_logger().error(f"no landing trajectory within {_TIMEOUT_S} s ({len(self.arrivals)} arrived)")
        return {
            "first": math.nan, "kind": "none", "refined": math.nan, "first_in_planner": math.nan,
            "first_for_site": False, "refined_for_site": False,
        }  # fmt: skip


def _states(count: int, seed: int) -> list[tuple[float, float]]:
    generator = random.Random(seed)
    return [(generator.uniform(50.0, 800.0) * FT, generator.uniform(0.0, 115.0) * KT) for _ in range(count)]


def _run(vehicle: Vehicle, states: list[tuple[float, float]]) -> dict[str, list]:
    vehicle.wait_for_subscribers()
    vehicle.fail(states[0])  # not counted: discovery of the reverse path and first-call costs
    vehicle.details.clear()
    vehicle.stale = vehicle.lost = 0
    results: dict[str, list] = {
        "first": [], "kind": [], "refined": [], "first_in_planner": [], "first_for_site": [], "refined_for_site": [],
    }  # fmt: skip
    for state in states:
        for key, value in vehicle.fail(state).items():
            results[key].append(value)
    results["details"] = list(vehicle.details)
    results["stale"] = [vehicle.stale]
    results["lost"] = [vehicle.lost]
    return results


def run_composed(states: list[tuple[float, float]], log_dir: str, executor: str, extra: list[str]) -> dict[str, list]:
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"
    arguments = [*_NO_REPLANNING, *extra]
    # The vehicle is one of the system's extra nodes, where a user's vehicle bridge or the display composes in
    # (served after the planner, before the status and the recorder), not a node added after them.
    system = build_system(
        log_dir=log_dir,
        ros_args=arguments,
        context=Context(),
        executor=executor,
        extra_nodes=[lambda **options: Node("bench_vehicle", **options)],
    )
    try:
        return _run(Vehicle(system.extra[0], system.executor), states)
    finally:
        system.shutdown()


def run_cross_process(
    states: list[tuple[float, float]], log_dir: str, executor: str, extra: list[str]
) -> dict[str, list]:
    environment = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(random.randint(1, 200)))
    os.environ.update(environment)
    child = subprocess.Popen(
        [
            *(sys.executable, "-m", "helireach_ros.cli.main", "bringup", "--log-dir", log_dir, "--executor", executor),
            *("--ros-args", *_NO_REPLANNING, *extra),
        ],
        env=environment,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    context = Context()
    rclpy.init(context=context)
    spinner = SingleThreadedExecutor(context=context)
    try:
        line = child.stdout.readline()  # "logging to ...": the child's nodes exist
        if "logging to" not in line:
            raise RuntimeError(f"helireach bringup did not start: {line!r}")
        return _run(Vehicle(Node("bench_vehicle", context=context), spinner), states)
    finally:
        child.terminate()
        child.wait(timeout=30)
        spinner.shutdown()
        rclpy.try_shutdown(context=context)


_LATENCIES = {
    "first": "failure -> first trajectory (any)",
    "first_standby": "  of which the standby plan",
    "first_refined": "  of which the refined plan",
    "first_fallback": "  of which a flagged fallback",
    "standby_in_planner": "  standby: event -> publish in planner",
    "refined": "failure -> refined (converged) plan",
}
"""The latencies :func:`_report` summarises, by key, and the label each is printed with."""


def _report(name: str, results: dict[str, list]) -> dict:
    """Prints one run's latencies and counts; returns them (:data:`_LATENCIES` summaries, counts, the refined
    plans' IPOPT time, iterations and planner event -> publish time)."""
    first, kinds = results["first"], results["kind"]
    samples = {
        "first": first,
        **{f"first_{kind}": [t for t, k in zip(first, kinds, strict=True) if k == kind]
           for kind in ("standby", "refined", "fallback")},
        "standby_in_planner": [t for t, k in zip(results["first_in_planner"], kinds, strict=True) if k == "standby"],
        "refined": results["refined"],
    }  # fmt: skip
    numbers: dict = {"failures": len(first), **{key: summary(samples[key]) for key in _LATENCIES}}
    print(f"\n{name}: {len(first)} failures, load average {loadavg_text()}")
    for key, label in _LATENCIES.items():
        print(f"  {label:<36} {summary_text(numbers[key])}")
    counts = {kind: kinds.count(kind) for kind in ("standby", "refined", "fallback")}
    numbers.update(first_kinds=counts, stale=results["stale"][0], lost=results["lost"][0])
    print(f"  first trajectory was: {counts} (no standby: no safe live verdict at that state, or none yet)")
    print(f"  planned from the previous failure's state (state not yet received): {results['stale'][0]}")
    print(f"  no trajectory received within {_TIMEOUT_S:g} s: {results['lost'][0]}")
    if any(results["first_for_site"]) or any(results["refined_for_site"]):
        standby_for_site = sum(
            site and kind == "standby" for site, kind in zip(results["first_for_site"], kinds, strict=True)
        )
        numbers.update(
            standby_for_site=standby_for_site, refined_for_site=sum(results["refined_for_site"])
        )  # fmt: skip
        print(
            f"  made for the landing site: {standby_for_site} standby plans, {sum(results['refined_for_site'])} "
            f"refined plans (the others landed anywhere: the site not reachable from that state)"
        )
    if not results["details"]:
        return numbers
    solve, planner, iterations = (summary(column) for column in zip(*results["details"], strict=True))
    numbers.update(refined_ipopt=solve, refined_iterations=iterations, refined_in_planner=planner)
    print(
        f"  refined plan: IPOPT p50 {solve['median']:6.1f} ms  p95 {solve['p95']:6.1f} "
        f"ms  (iterations p50 {iterations['median']:.0f}, p95 {iterations['p95']:.0f}); "
        f"planner event -> publish p50 {planner['median']:6.1f} ms  p95 {planner['p95']:6.1f} ms"
    )
    return numbers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--failures", type=int, default=40, help="failures per mode (>= 30)")
    parser.add_argument("--mode", choices=("both", "composed", "cross-process"), default="both")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--executor", choices=EXECUTOR_KINDS, default=DEFAULT_EXECUTOR, help="the system's executor")
    parser.add_argument("--baseline", action="store_true", help="also run solver_workers:=0 live_rate:=0 (legacy)")
    parser.add_argument(
        "--site", default=None, metavar="START:END", help="also run with a landing site START-END m ahead of each state"
    )
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    states = _states(arguments.failures, arguments.seed)
    print(
        f"helireach failure latency: {machine_text()}, {arguments.failures} failures, seed {arguments.seed}, "
        f"load average {record.load_before}"
    )
    print(f"command: {record.command}")
    numbers: dict = {
        "failures": arguments.failures, "seed": arguments.seed, "executor": arguments.executor,
        "states": "50-800 ft x 0-115 kt, level flight, total power loss", "runs": [], "baseline_ratios": {},
    }  # fmt: skip
    configurations = [("solver workers + live evaluation (defaults)", [])]
    if arguments.baseline:
        configurations.append(("baseline: solver_workers:=0 live_rate:=0", _BASELINE))
    if arguments.site:
        start, end = (float(part) for part in arguments.site.split(":"))
        site = ["-p", f"helireach_planner:landing_sites:=bench:{start:g}:{end:g}"]
        configurations.append((f"defaults + landing site {start:g}-{end:g} m ahead", site))
    runners = []
    if arguments.mode in ("both", "composed"):
        runners.append((f"composed (one process, {arguments.executor} executor)", run_composed))
    if arguments.mode in ("both", "cross-process"):
        runners.append(
            (f"cross-process (helireach bringup in a child process, {arguments.executor})", run_cross_process)
        )
    with tempfile.TemporaryDirectory() as log_dir:
        for runner_name, runner in runners:
            runs = []
            for configuration_name, extra in configurations:
                results = runner(states, log_dir, arguments.executor, extra)
                run = _report(f"{runner_name}, {configuration_name}", results)
                numbers["runs"].append({"system": runner_name, "configuration": configuration_name, **run})
                runs.append(run)
            for (configuration_name, _), run in list(zip(configurations, runs, strict=True))[1:]:
                for key, label in (("first", "first trajectory"), ("refined", "refined plan")):
                    stats, defaults = run[key], runs[0][key]
                    if not (stats["n"] and defaults["n"]):
                        continue
                    ratios = {quantile: stats[quantile] / defaults[quantile] for quantile in ("median", "p95")}
                    if configuration_name.startswith("baseline") and key == "first":
                        numbers["baseline_ratios"][runner_name] = ratios
                    print(
                        f"  failure -> {label}, {configuration_name.split(':')[0]} / defaults (same run): p50 "
                        f"{ratios['median']:.2f}x, p95 {ratios['p95']:.2f}x; load average now {loadavg_text()}"
                    )
    print(f"\nstates: {Path(__file__).name} --seed {arguments.seed}: {numbers['states']}")
    if arguments.json:
        record.write(numbers)


if __name__ == "__main__":
    main()
