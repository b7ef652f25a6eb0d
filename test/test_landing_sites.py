"""Landing sites (core/policies/landing_sites.py) and site plans in the solver pool: parsing, the selection, the
status keys, and "the site, else anywhere" with real IPOPT and the independent replay."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.planning.footprint import touchdown_distance
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.policies.landing_sites import (
    SITE_RETRY_EVERY,
    LandingSite,
    SiteSelection,
    parse_landing_sites,
    site_values,
    solve_site_or_anywhere,
)
from helireach_ros.core.policies.plan_status import site_text
from helireach_ros.core.units import FT, KT
from helireach_ros.core.workers.solver_pool import SolverPool, SolverPoolSettings

_START_M = 1000.0  # the state's along-track distance: sites are in world metres, windows from the state


def test_sites_parse_from_the_parameter_and_bad_ones_are_refused() -> None:
    sites = parse_landing_sites(["field:600:700", " runway : 900.5 : 1200 "])
    assert sites == (LandingSite("field", 600.0, 700.0), LandingSite("runway", 900.5, 1200.0))
    for bad in (["field:700"], ["field:a:700"], ["field:700:600"], ["field:nan:700"], [":1:2"], ["a:1:2", "a:3:4"]):
        with pytest.raises(ValueError):
            parse_landing_sites(bad)
    site = sites[0]
    state = np.zeros(6)
    state[StateIndex.DISTANCE] = 650.0
    assert site.window_from(state) == (-50.0, 50.0)
    assert site.contains(650.0) and not site.contains(701.0)
    assert site.margin_m(640.0) == 40.0 and site.margin_m(590.0) == -10.0


def test_the_crew_choice_holds_and_an_automatic_selection_moves_on_from_an_unreachable_site() -> None:
    sites = parse_landing_sites(["a:0:10", "b:20:30", "c:40:50"])
    with pytest.raises(ValueError, match="not one of"):
        SiteSelection(sites, "d")
    crew = SiteSelection(sites, "b")
    crew.record(sites[1], False)
    assert crew.selected() == sites[1]  # the crew's site stays selected; the plans say it is not reachable
    automatic = SiteSelection(sites)
    assert automatic.selected() == sites[0] and automatic.reachability(sites[0]) is None
    automatic.record(sites[0], True)
    assert automatic.selected() == sites[0] and automatic.reachable_count() == 1
    automatic.record(sites[0], False)
    assert automatic.selected() == sites[1] and automatic.reachable_count() == 0
    automatic.record(sites[2], False)  # evidence about another site does not move the selection
    assert automatic.selected() == sites[1]
    automatic.forget()
    assert automatic.selected() == sites[0] and automatic.reachability(sites[2]) is None


def test_a_site_found_unreachable_is_tried_again_only_every_few_solves() -> None:
    site, other = parse_landing_sites(["a:0:10", "b:20:30"])
    selection = SiteSelection([site, other], "a")
    assert selection.worth_trying(site)  # nothing known: try it
    selection.record(site, False)
    answers = [selection.worth_trying(site) for _ in range(2 * SITE_RETRY_EVERY)]
    assert answers == ([False] * (SITE_RETRY_EVERY - 1) + [True]) * 2
    assert selection.worth_trying(other)  # per site
    selection.record(site, True)
    assert all(selection.worth_trying(site) for _ in range(SITE_RETRY_EVERY + 1))


@pytest.fixture(scope="module")
def state(airframe) -> np.ndarray:
    at = initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()
    at[StateIndex.DISTANCE] = _START_M
    return at


@pytest.fixture(scope="module")
def anywhere(airframe, settings, state):
    """The touchdown-cost plan from 500 ft / 75 kt: where the aircraft lands without a site."""
    return get_planner(airframe, settings).plan(state)


def _solvers(airframe, settings, site: LandingSite, state: np.ndarray):
    on_site = get_planner(airframe, settings.replace(objective="site"))
    planner = get_planner(airframe, settings)

    def solve_site(at, warm):
        return on_site.plan(at, on_site.carried_warm_start(warm), touchdown_window=site.window_from(at))

    def solve_anywhere(at, warm):
        return planner.plan(at, planner.carried_warm_start(warm))

    return solve_site, solve_anywhere


def test_a_reachable_site_beyond_the_natural_touchdown_is_landed_on_and_its_status_says_so(
    airframe, settings, state, anywhere
) -> None:
    natural = _START_M + touchdown_distance(anywhere)
    site = LandingSite("beyond", natural + 40.0, natural + 100.0)  # the footprint's far end is ~120 m beyond
    plan = solve_site_or_anywhere(*_solvers(airframe, settings, site, state), state, anywhere.warm_start)
    assert plan.safe and plan.verified and plan.touchdown_window is not None
    values = site_values(site, plan, reachable_count=1)
    assert values["on_site"] is True and values["site_planned"] is True and values["sites_reachable"] == 1
    assert site.contains(values["touchdown_distance_m"]) and values["site_margin_m"] >= 0.0
    assert values["touchdown_distance_m"] == pytest.approx(plan.replay.touchdown_state[StateIndex.DISTANCE])
    assert "on site beyond" in site_text(values, plan.safe)


def test_an_unreachable_site_lands_anywhere_and_says_both(airframe, settings, state, anywhere) -> None:
    site = LandingSite("too_far", _START_M + 5000.0, _START_M + 5100.0)  # ~16,000 ft from 500 ft: out of reach
    plan = solve_site_or_anywhere(*_solvers(airframe, settings, site, state), state, anywhere.warm_start)
    assert plan.safe and plan.touchdown_window is None  # the state can land, off-site
    values = site_values(site, plan)
    assert values["on_site"] is False and values["site_planned"] is False and "sites_reachable" not in values
    assert values["site_margin_m"] < -4000.0
    text = site_text(values, plan.safe)
    assert "too_far NOT reachable: landing off-site" in text
    assert site_text(values, False).endswith("too_far NOT reachable")  # never "off-site" for a plan that cannot land


def test_a_warm_start_crosses_between_the_site_and_the_anywhere_nlp(airframe, settings, state, anywhere) -> None:
    on_site = get_planner(airframe, settings.replace(objective="site"))
    carried = on_site.carried_warm_start(anywhere.warm_start)
    assert carried.constraint_multipliers.size == anywhere.warm_start.constraint_multipliers.size + 1
    window = (touchdown_distance(anywhere) - 20.0, touchdown_distance(anywhere) + 20.0)
    plan = on_site.plan(state, carried, touchdown_window=window)
    assert plan.solver.warm_started and plan.safe
    back = get_planner(airframe, settings).carried_warm_start(plan.warm_start)
    assert np.array_equal(back.constraint_multipliers, plan.warm_start.constraint_multipliers[:-1])
    with pytest.raises(ValueError, match="another NLP"):  # an uncarried one is refused, as before
        on_site.plan(state, anywhere.warm_start, touchdown_window=window)


def test_the_pool_lands_on_a_site_or_anywhere_and_refuses_a_window_without_site_planning(
    airframe, settings, state, anywhere
) -> None:
    natural = touchdown_distance(anywhere)
    with SolverPool(airframe, settings, SolverPoolSettings(workers=1, site_planning=True)) as pool:
        assert pool.wait_ready(120.0)
        on_site = pool.plan(state, None, touchdown_window=(natural - 200.0, natural - 120.0), timeout_s=20.0)
        assert on_site.safe and on_site.touchdown_window is not None
        assert natural - 200.0 <= touchdown_distance(on_site) <= natural - 120.0
        live = pool.plan(state, on_site.warm_start, cold_check=True, touchdown_window=(5000.0, 5100.0), timeout_s=20.0)
        assert live.safe and live.touchdown_window is None  # off-site: the state can still land
        assert math.isclose(touchdown_distance(live), natural, rel_tol=0.05)
    with SolverPool(airframe, settings, SolverPoolSettings(workers=1, warm_up=False)) as plain:
        with pytest.raises(ValueError, match="site_planning"):
            plain.submit(state, None, touchdown_window=(0.0, 10.0))


def test_the_site_keys_of_a_plan_and_a_live_status_are_documented(airframe, state, anywhere) -> None:
    import re
    from pathlib import Path

    from helireach_ros.core.estimation.weight_tracking import WeightChoice
    from helireach_ros.core.policies.failure_episode import FailureEpisode
    from helireach_ros.core.policies.live_reachability import LiveVerdict
    from helireach_ros.core.policies.plan_status import PlannerIdentity, converged_plan_report, live_report

    def documented(page: str) -> set[str]:
        text = (Path(__file__).resolve().parent.parent / "msg_docs" / page).read_text(encoding="utf-8")
        return set(re.findall(r"`([a-z_0-9]+)`", text))

    site = LandingSite("field", _START_M + 5000.0, _START_M + 5100.0)
    values = site_values(site, anywhere, reachable_count=0)
    weight = WeightChoice(airframe.gross_weight, "file", 0.0, "")
    report = converged_plan_report(
        anywhere, identity=PlannerIdentity(airframe.name, airframe.gross_weight, airframe.density_altitude),
        failure=FailureEpisode(1, 10, 10), stamp_ns=10, warm_source="none", rotor_source="measured", replan_index=0,
        lateness=None, latency_ms=1.0, weight=weight, standby=False, sites=values,
    )  # fmt: skip
    assert report.level == "OK" and "field NOT reachable: landing off-site" in report.text
    assert set(values) <= set(report.values) <= documented("helireach_plan_status.md")
    verdict = LiveVerdict("safe", anywhere.value, state, 9, 10, 12.0, anywhere, "")
    live = live_report(
        verdict, standby=True, weight=weight, configured_weight=airframe.gross_weight, power_fraction=0.0, now_ns=11,
        sites=values,
    )  # fmt: skip
    assert live.level == "OK" and set(live.values) <= documented("helireach_live_reachability.md")


def test_the_live_footprint_takes_evaluation_slots_and_says_what_it_knows_of_each_site(airframe, settings) -> None:
    """The live scheduler with a real solver pool: footprints come every period, verdicts keep coming between them
    and aim at the selected site, and a site beyond the verified far end is not reachable."""
    import threading
    import time

    from helireach_ros.core.policies.live_reachability import LiveSettings
    from helireach_ros.core.policies.vehicle_readings import CurrentState, RotorSource
    from helireach_ros.core.workers.live_scheduling import LiveScheduler
    from helireach_ros.core.workers.planner_backend import BackendSettings, PlannerBackend
    from helireach_ros.core.workers.solver_thread import SolverThread

    measured = initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()
    measured[StateIndex.DISTANCE] = _START_M
    ahead, far = f"ahead:{_START_M + 650}:{_START_M + 700}", f"far:{_START_M + 5000}:{_START_M + 5100}"
    sites = SiteSelection(parse_landing_sites([ahead, far]))
    backend = PlannerBackend(
        airframe,
        settings,
        BackendSettings(envelope_file="none", solver_workers=1, site_planning=True, footprint=True),
        lambda level, text: None,
    )
    verdicts, footprints = [], []
    lock = threading.Lock()

    def collect(into):
        def append(report):
            with lock:
                into.append(report)

        return append

    solver_thread = SolverThread(lambda text: None)
    try:
        scheduler = LiveScheduler(
            LiveSettings(rate_hz=5.0, max_state_age_s=1.0), backend, solver_thread, time.monotonic_ns,
            collect(verdicts), lambda plan, stamp_ns, frame: None, sites,
            footprint_period_s=1.0, publish_footprint=collect(footprints),
        )  # fmt: skip
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:
            with lock:
                if len(footprints) >= 2 and len(verdicts) >= 4:
                    break
            scheduler.tick(CurrentState(measured, time.monotonic_ns(), "base_stabilized", RotorSource.MEASURED))
            time.sleep(0.02)
    finally:
        backend.close()
        solver_thread.shutdown()
    assert len(footprints) >= 2 and len(verdicts) >= 4, (len(footprints), len(verdicts))
    for report in footprints:
        values = report.values
        assert values["farthest_verified"] is True and 700.0 < values["farthest_m"] < 1000.0, report.text
        assert values["farthest_distance_m"] == pytest.approx(_START_M + values["farthest_m"])
        assert values["site_far"] == "not_reachable"  # beyond a verified end: not even in the model
        assert values["site_ahead"] in ("reachable", "unknown")  # "unknown" only while the near end is not verified
        assert report.level == ("OK" if values["nearest_verified"] else "WARN")
    assert all(report.values["landing_site"] == "ahead" for report in verdicts)
    assert any(report.values["on_site"] for report in verdicts)


def test_without_a_safe_landing_the_best_effort_is_a_converged_plan_not_a_failed_attempt(airframe, settings) -> None:
    """150 ft in hover is in the H-V avoid region: no plan is safe, and a site far ahead cannot be reached; the node
    must still get the converged best effort (a failed solve would make it publish a fallback)."""
    state = initial_state_after_failure(airframe, 150 * FT, 0.0).as_array()
    site = LandingSite("far", 3000.0, 3100.0)
    solve_site, solve_anywhere = _solvers(airframe, settings, site, state)
    plan = solve_site_or_anywhere(solve_site, solve_anywhere, state, None)
    assert not plan.safe and plan.solver.success
    attempts = [solve_site(state, None), solve_anywhere(state, None)]
    assert plan.value == pytest.approx(min(p.value for p in attempts if p.solver.success))


def test_a_mission_managers_message_replaces_the_sites_and_the_report_says_what_is_in_use() -> None:
    from helireach_ros.core.policies.landing_sites import sites_from_message, sites_report

    selection = SiteSelection(parse_landing_sites(["a:0:10"]))
    selection.record(selection.sites[0], False)
    sites, selected = sites_from_message({"landing_sites": "b:20:30; c:40:50", "selected_site": "c"})
    selection.replace(sites, selected)
    assert selection.selected() == sites[1] and selection.source == "topic"
    assert selection.reachability(sites[0]) is None and selection.reachable_count() == 0  # the old evidence is gone
    report = sites_report(selection)
    assert report.level == "OK" and report.values["landing_sites"] == "b:20:30;c:40:50"
    assert report.values["selection"] == "c" and "the crew's c" in report.text
    for bad in ({}, {"landing_sites": "b:30:20"}, {"landing_sites": "b:20:30", "selected_site": "z"}):
        with pytest.raises(ValueError):
            selection.replace(*sites_from_message(bad))
    assert selection.selected() == sites[1]  # a refused message changes nothing
    empty = sites_report(SiteSelection(()))
    assert empty.level == "WARN" and empty.values["site_count"] == 0 and "landing anywhere" in empty.text
    assert sites_report(None, "broken").values["reason"] == "broken"
