"""How often the real-time demo lands within limits: ``make demo``'s run, repeated, each in a fresh interpreter.

Run: .venv/bin/python bench/demo_landings.py [--runs 20] [--params-file F ...] [--site-ft START:END] [--json]

The demo (:func:`~helireach_ros.cli.demo.run_demo`: scenario ``demo_500ft_75kt``, its 5 % drag mismatch and sensor
noise, the nodes on the wall clock) is the same every run up to its timing: when each re-plan's state is read, how
long each solve takes, when its plan reaches the vehicle. The lock-step closed loop
(``bench/closed_loop_latency.py``, ``test_closed_loop.py``) fixes those and is deterministic; this bench measures the
real-time system as a user runs it, on this machine and its load. Each run is one process (as ``make demo`` and
``test_ros_system`` run it) with DDS discovery on the local host off, so runs do not hear each other.
``--site-ft`` flies the demo's landing-site variant (``helireach demo --site-ft``, as ``test_landing_sites_ros`` does:
robust verification off): within limits then means on the site too.

Prints, per run, the touchdown (descent rate, forward speed, the rotor's range in flight and at contact), the verdict
and the closed loop's counts (re-plans, not converged, kept out); then the landing rate with its 95 % Wilson
interval and the touchdown distributions, with the load average. ``--json`` also writes them to
docs/results/data/demo_landings.json (bench/results_pages.py reads it).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

from _common import Record, add_json_argument, loadavg_text, summary, wilson_interval

from helireach_ros.core.units import FT, KT

_RUN_TIMEOUT_S = 300.0


def _one_demo(out: str, params_files: tuple[str, ...], site_ft: str | None) -> dict:
    """One demo run in this (fresh) process: its touchdown and closed-loop counts."""
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"
    from rclpy.context import Context

    from helireach_ros.cli.demo import demo_site, run_demo

    site = {} if site_ft is None else {"site": demo_site(site_ft), "robust_verification": False}
    result = run_demo(out, context=Context(), handle_signals=False, figures=False, params_files=params_files, **site)
    touchdown = result.touchdown
    if touchdown is None:
        return {"landed": False, "within": False, "reason": "no touchdown before the demo's timeout"}
    omega0 = result.nominal_rotor_speed
    return {
        "landed": True,
        "within": result.landed_within_limits,
        "within_to_contact": bool(touchdown.within_limits_to_contact),
        "reason": touchdown.reason,
        "descent_rate_ft_s": touchdown.descent_rate / FT,
        "forward_speed_kt": abs(touchdown.forward_speed) / KT,
        "rotor_min_in_flight_pct": 100 * touchdown.min_rotor_speed / omega0,
        "rotor_max_in_flight_pct": 100 * touchdown.max_rotor_speed / omega0,
        "rotor_min_to_contact_pct": 100 * touchdown.min_rotor_speed_to_contact / omega0,
        "touchdown_value": touchdown.value,
        "replans": max((record.replan_index for record in result.plans), default=0),
        "replans_failed": result.replans_failed,
        "replans_kept_out": result.replans_kept_out,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--params-file", action="append", default=[], help="extra ROS parameter file (repeatable)")
    parser.add_argument("--site-ft", default=None, help="the landing-site variant: START:END ft along the track")
    add_json_argument(parser)
    arguments = parser.parse_args()
    record = Record.start()
    print(f"command: {record.command}; load average {record.load_before}")
    runs: list[dict] = []
    context = multiprocessing.get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="helireach_demo_landings_") as scratch:
        for index in range(arguments.runs):
            started = time.perf_counter()
            with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
                out = os.path.join(scratch, f"run{index}")
                task = pool.submit(_one_demo, out, tuple(arguments.params_file), arguments.site_ft)
                run = task.result(timeout=_RUN_TIMEOUT_S)
            run["wall_s"] = time.perf_counter() - started
            run["load"] = loadavg_text()
            runs.append(run)
            verdict = "within limits" if run["within"] else f"OUTSIDE: {run['reason']}"
            touchdown = (
                f"{run['descent_rate_ft_s']:4.1f} ft/s {run['forward_speed_kt']:4.1f} kt, rotor "
                f"{run['rotor_min_in_flight_pct']:.1f}-{run['rotor_max_in_flight_pct']:.1f} % in flight, "
                f"{run['rotor_min_to_contact_pct']:.1f} % to contact; {run['replans']} re-plans, "
                f"{run['replans_failed']} not converged, {run['replans_kept_out']} kept out"
                if run["landed"]
                else "no touchdown"
            )
            print(f"run {index + 1:2d}: {touchdown}; {verdict} ({run['wall_s']:.0f} s, load {run['load']})", flush=True)
    within = sum(run["within"] for run in runs)
    to_contact = sum(run.get("within_to_contact", False) for run in runs)
    low, high = wilson_interval(within, len(runs))
    print(
        f"\nwithin limits: {within} of {len(runs)} ({100 * within / len(runs):.0f} %; 95 % Wilson interval "
        f"{100 * low:.0f}-{100 * high:.0f} %); with the rotor judged to ground contact: {to_contact} of {len(runs)}"
    )
    landed = [run for run in runs if run["landed"]]
    distributions = {
        key: summary((run[key] for run in landed), tails=True)
        for key in ("descent_rate_ft_s", "forward_speed_kt", "rotor_min_to_contact_pct", "touchdown_value")
    }
    for key, stats in distributions.items():
        if stats["n"]:
            print(f"{key}: min {stats['min']:.2f}  median {stats['median']:.2f}  max {stats['max']:.2f}")
    print(f"load average after: {loadavg_text()}")
    if arguments.json:
        numbers = {
            "runs": len(runs), "within": within, "within_to_contact": to_contact, "wilson_95": [low, high],
            "params_files": arguments.params_file, "site_ft": arguments.site_ft, "per_run": runs,
            "distributions": distributions,
        }  # fmt: skip
        record.write(numbers)


if __name__ == "__main__":
    main()
