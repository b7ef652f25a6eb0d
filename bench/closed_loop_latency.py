"""How much plan latency the closed-loop landing tolerates: a deterministic sweep without ROS.

Run: .venv/bin/python bench/closed_loop_latency.py [--scenario demo_500ft_75kt] [--seeds 7 8 9]
     [--latencies 0.05 0.1 0.2 0.3 0.4 0.5 0.6 0.8 1.0] [--replan-period 0.25] [--json]

For each latency and noise seed it flies the scenario with
:func:`~helireach_ros.core.robustness.closed_loop.fly_closed_loop` (the planner node's re-planning policy in lock-step
simulated time: every plan reaches the vehicle ``latency`` seconds after the measurement it starts
from) and prints the touchdown descent rate, forward speed, the rotor-speed range in flight and the
verdict against the landing limits. The real-time ROS system's latency is measured by
bench/failure_latency.py; the gap between the two is the closed loop's margin. Prints what it
measured on this machine; ``--json`` also writes it to docs/results/data/closed_loop_latency.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from _common import Record, add_json_argument, loadavg_text

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.flight.simulation import SimulatedVehicle, load_scenario
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings, fly_closed_loop
from helireach_ros.core.units import FT, KT


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="demo_500ft_75kt")
    parser.add_argument("--seeds", type=int, nargs="+", default=[7, 8, 9])
    parser.add_argument("--latencies", type=float, nargs="+", default=[0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0])
    parser.add_argument("--replan-period", type=float, default=0.25)
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    scenario = load_scenario(arguments.scenario)
    airframe = load_airframe(scenario.airframe)
    settings = load_settings(None)
    planner = get_planner(airframe, settings)
    omega0 = airframe.nominal_rotor_speed
    limits = airframe.limits
    print(
        f"helireach closed-loop latency sweep: {scenario.name}, re-plan every {arguments.replan_period:g} s, "
        f"limits {limits.max_descent_rate / FT:.0f} ft/s, {limits.max_forward_speed / KT:.0f} kt, rotor "
        f"{100 * limits.min_rotor_speed_ratio:.0f}-{100 * limits.max_rotor_speed_ratio:.0f} % in flight"
    )
    print(f"load average before (1/5/15 min): {record.load_before}")
    print(f"{'latency s':>9} {'seed':>4} {'ft/s':>5} {'kt':>5} {'rotor % in flight':>18} {'plans':>5}  verdict")
    numbers: dict = {
        "scenario": scenario.name, "replan_period_s": arguments.replan_period, "seeds": arguments.seeds,
        "limits": {"descent_ft_s": limits.max_descent_rate / FT, "forward_speed_kt": limits.max_forward_speed / KT,
                   "rotor_min_percent": 100 * limits.min_rotor_speed_ratio,
                   "rotor_max_percent": 100 * limits.max_rotor_speed_ratio},
        "latencies": [],
    }  # fmt: skip
    for latency in arguments.latencies:
        policy = ClosedLoopSettings(replan_period=arguments.replan_period, latency=latency)
        within, landings = 0, []
        for seed in arguments.seeds:
            vehicle = SimulatedVehicle(dataclasses.replace(scenario, seed=seed), airframe, settings)
            started = time.perf_counter()
            result = fly_closed_loop(vehicle, planner, policy)
            report = result.touchdown
            within += report.within_limits
            verdict = "within limits" if report.within_limits else f"OUTSIDE: {report.reason}"
            landing = {
                "seed": seed, "descent_ft_s": report.descent_rate / FT, "speed_kt": abs(report.forward_speed) / KT,
                "rotor_min_percent": 100 * report.min_rotor_speed / omega0,
                "rotor_max_percent": 100 * report.max_rotor_speed / omega0, "plans": result.plans,
                "within_limits": report.within_limits, "reason": "" if report.within_limits else report.reason,
                "wall_s": time.perf_counter() - started,
            }  # fmt: skip
            landings.append(landing)
            print(
                f"{latency:9.2f} {seed:4d} {landing['descent_ft_s']:5.1f} {landing['speed_kt']:5.1f} "
                f"{landing['rotor_min_percent']:8.1f}-{landing['rotor_max_percent']:5.1f} % "
                f"{result.plans:5d}  {verdict} ({landing['wall_s']:.1f} s)"
            )
        print(f"{'':9} {'':4} latency {latency:g} s: {within} of {len(arguments.seeds)} within limits")
        numbers["latencies"].append({"latency_s": latency, "within_limits": within, "landings": landings})
    print(f"load average after (1/5/15 min): {loadavg_text()}")
    if arguments.json:
        record.write(numbers)


if __name__ == "__main__":
    main()
