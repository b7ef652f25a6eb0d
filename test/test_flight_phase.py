"""The cockpit's flight phase, banner, touchdown result and cue (helireach_ros.core.policies.flight_phase): pure policy.

The cue rules are also checked on a real IPOPT plan (500 ft / 75 kt): every event must sit where its rule says
in the plan's own controls.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.policies.flight_phase import (
    CueEvent,
    CueSettings,
    FlightPhase,
    PhaseInputs,
    PlanVerdictInput,
    TouchdownFromState,
    TouchdownResult,
    decide_phase,
    next_cue,
    plan_banner,
    plan_cue_events,
    worst_level,
)
from helireach_ros.core.units import FT, KT
from helireach_ros.display.pilot_units import axis_margins, line_margin, thrust_scale

FRESH = (("state", 0.1), ("rotor", 0.1), ("safety status", 0.2), ("failure episode", 0.5))
VERIFIED = PlanVerdictInput(status="safe", level="safe", verified=True, fallback=False, late=False, message="SAFE")


def inputs(**changes: object) -> PhaseInputs:
    base = {"source_ages": FRESH, "status_level": "safe", "status_message": "safe", "episode_phase": "normal"}
    return PhaseInputs(**{**base, **changes})


def test_normal_phase_is_the_safety_status() -> None:
    for level in ("safe", "caution", "avoid", "nodata"):
        banner = decide_phase(inputs(status_level=level))
        assert (banner.phase, banner.level) == (FlightPhase.NORMAL, level)
    assert decide_phase(inputs(status_level="strange")).level == "nodata"  # unknown is never optimistic
    no_flag = decide_phase(inputs(episode_phase="no_flag"))
    assert no_flag.phase is FlightPhase.NORMAL and "NO ENGINE-FAILURE FLAG" in no_flag.detail
    no_episode = decide_phase(inputs(episode_phase=None, source_ages=FRESH[:3]))
    assert no_episode.phase is FlightPhase.NORMAL and "NO FAILURE-EPISODE STATUS" in no_episode.detail
    never = decide_phase(inputs(status_level=None, source_ages=FRESH[:2]))
    assert (never.phase, never.level) == (FlightPhase.STALE, "nodata") and "NO SAFETY STATUS" in never.detail


def test_any_silent_source_is_stale_and_a_missing_one_is_not() -> None:
    for index, (name, _) in enumerate(FRESH):
        ages = list(FRESH)
        ages[index] = (name, 2.5)
        banner = decide_phase(inputs(source_ages=tuple(ages), episode_phase="failed", plan=VERIFIED))
        assert (banner.phase, banner.level, banner.word) == (FlightPhase.STALE, "nodata", "STALE")
        assert banner.silent == (name,) and f"{name.upper()} SILENT 2.5 s" in banner.detail
        assert "LAST PHASE AUTOROTATION" in banner.detail
    rotorless = decide_phase(inputs(source_ages=(("state", 0.1), ("rotor", None))))
    assert rotorless.phase is FlightPhase.NORMAL  # a system without that topic is not silent
    assert decide_phase(inputs(held=True)).phase is FlightPhase.STALE
    assert decide_phase(inputs(episode_phase="unknown")).detail == "FAILURE EPISODE UNREADABLE"
    assert decide_phase(inputs(source_ages=(("state", math.nan),))).phase is FlightPhase.STALE


def test_autorotation_banner_is_the_plan_and_never_greener_than_it() -> None:
    banner = decide_phase(inputs(episode_phase="failed", plan=VERIFIED, plan_remaining_s=3.04, status_level="avoid"))
    assert (banner.phase, banner.level, banner.word) == (FlightPhase.AUTOROTATION, "safe", "VERIFIED")
    assert banner.detail.startswith("TOUCHDOWN IN 3.0 s")
    elapsed = decide_phase(inputs(episode_phase="failed", plan=VERIFIED, plan_remaining_s=0.0))
    assert elapsed.level == "caution" and "PLAN TIME ELAPSED" in elapsed.detail
    event_only = decide_phase(inputs(episode_phase=None, failure_event=True, source_ages=FRESH[:3]))
    assert (event_only.phase, event_only.word, event_only.level) == (FlightPhase.AUTOROTATION, "NO PLAN", "avoid")
    cases = {
        "standby": (PlanVerdictInput(**{**vars(VERIFIED), "standby": True}), "STANDBY \u00b7 VERIFIED", "safe"),
        "robust": (PlanVerdictInput(**{**vars(VERIFIED), "robust": True}), "ROBUST", "safe"),
        "late": (PlanVerdictInput(**{**vars(VERIFIED), "late": True}), "VERIFIED \u00b7 LATE", "caution"),
        "late, says OK": (
            PlanVerdictInput(**{**vars(VERIFIED), "late": True, "level": "safe"}),
            "VERIFIED \u00b7 LATE",
            "caution",
        ),
        "own WARN": (PlanVerdictInput(**{**vars(VERIFIED), "level": "caution"}), "VERIFIED", "caution"),
        "fallback": (PlanVerdictInput(fallback=True, verified=False, level="caution"), "FALLBACK", "caution"),
        "fallback, says OK": (PlanVerdictInput(status="fallback", level="safe"), "FALLBACK", "caution"),
        "unverified": (PlanVerdictInput(status="unverified", level="safe", verified=False), "UNVERIFIED", "caution"),
        "verified without status": (PlanVerdictInput(level="safe", verified=True), "UNVERIFIED", "caution"),
        "unsafe": (PlanVerdictInput(status="unsafe", level="avoid", verified=True), "UNSAFE", "avoid"),
        "none": (PlanVerdictInput(status="none", level="avoid"), "NO PLAN", "avoid"),
        "ended": (PlanVerdictInput(status="ended", level="caution"), "NO PLAN \u00b7 ENDED", "nodata"),
        "unknown level": (PlanVerdictInput(**{**vars(VERIFIED), "level": "odd"}), "VERIFIED", "nodata"),
    }
    for name, (plan, word, level) in cases.items():
        assert plan_banner(plan) == (word, level), name
    assert plan_banner(None) == ("NO PLAN", "avoid")


def test_landed_and_ended() -> None:
    within = TouchdownResult("touchdown", True, 1.4, 1.6, 2.4384, 3.0867, 96.0, 12.1)
    banner = decide_phase(inputs(episode_phase="failed", touchdown=within))  # the report alone lands it
    assert (banner.phase, banner.level, banner.word) == (FlightPhase.LANDED, "safe", "LANDED \u00b7 WITHIN LIMITS")
    assert f"SINK {1.4 / FT:.1f} ft/s (LIMIT 8)" in banner.detail and "TOUCHDOWN REPORT" in banner.detail
    outside = TouchdownResult("touchdown", False, 3.0, 1.0, 2.4384, 3.0867, reason="descent rate")
    banner = decide_phase(inputs(episode_phase="landed", touchdown=outside))
    assert (banner.level, banner.word) == ("avoid", "LANDED \u00b7 OUTSIDE LIMITS") and "DESCENT RATE" in banner.detail
    from_state = TouchdownResult("state", True, 1.0, 1.0, 2.4384, 3.0867)
    assert decide_phase(inputs(episode_phase="landed", touchdown=from_state)).level == "caution"
    unknown = decide_phase(inputs(episode_phase="landed"))
    assert (unknown.level, unknown.detail) == ("caution", "TOUCHDOWN RATES UNKNOWN")
    ended = decide_phase(inputs(episode_phase="ended", status_level="caution", status_message="near"))
    assert (ended.phase, ended.level, ended.word) == (FlightPhase.ENDED, "caution", "ENGINE RECOVERED")
    assert "NO LANDING PLAN" in ended.detail and "H-V CAUTION: NEAR" in ended.detail


def test_touchdown_from_state_waits_for_the_report_and_needs_a_flight() -> None:
    limits = load_airframe("uh60a_class").limits
    tracker = TouchdownFromState(0.3, limits.max_descent_rate, limits.max_forward_speed, report_wait_s=1.0)
    for height, climb, speed in ((30.0, -3.0, 20.0), (1.0, -2.0, 2.5), (math.nan, -9.0, 1.0)):
        tracker.observe(height, climb, speed, 10.0)
    assert tracker.result(10.0) is None
    tracker.observe(0.1, -1.0, 1.0, 10.5)
    pending = tracker.result(11.4)
    assert (pending.source, pending.within_limits) == ("pending", None)
    result = tracker.result(11.5)
    # the larger rates of the last state above (2.0 m/s, 2.5 m/s) and the contact (1.0, 1.0)
    assert (result.source, result.descent_rate, result.forward_speed, result.within_limits) == ("state", 2.0, 2.5, True)
    tracker.observe(0.0, -50.0, 50.0, 12.0)  # after the contact nothing changes
    assert tracker.result(13.0) is result
    tracker.reset()
    assert tracker.result(13.0) is None
    tracker.observe(0.0, -0.1, 0.0, 13.0)  # on the ground from the first state on: no touchdown was seen
    assert tracker.result(20.0) is None
    tracker.observe(2.0, -1.0, 1.0, 21.0)
    tracker.observe(0.0, -1.0, limits.max_forward_speed + 0.5, 21.1)
    assert tracker.result(30.0).within_limits is False
    # a vehicle that zeroes its rates on the ground: the crash is not shown as a soft landing
    crash = TouchdownFromState(0.3, limits.max_descent_rate, limits.max_forward_speed, report_wait_s=0.0)
    crash.observe(0.5, -12 * 0.3048, 3.0, 0.0)
    crash.observe(0.0, 0.0, 0.0, 0.05)
    assert crash.result(1.0).within_limits is False and crash.result(1.0).descent_rate == pytest.approx(12 * 0.3048)
    unknown = TouchdownFromState(0.3, None, None, report_wait_s=0.5)
    unknown.observe(1.0, -1.0, 1.0, 0.0)
    unknown.observe(0.0, -1.0, 1.0, 0.0)
    assert unknown.result(1.0).within_limits is None
    assert decide_phase(inputs(episode_phase="landed", touchdown=pending)).detail == "AWAITING THE TOUCHDOWN REPORT"


def test_cue_rules_on_synthetic_controls() -> None:
    times = np.arange(0.0, 10.01, 0.5)
    nose_up = np.where(times < 2.0, -20.0, np.where(times < 6.0, 0.0, 25.0))  # level at 2 s, flare at 6 s
    collective = np.where(times < 9.0, 0.005, 0.01)  # cushion at 9 s (last 3 s: +100 %)
    events = plan_cue_events(times, collective, np.radians(-nose_up))
    assert events == (CueEvent("LEVEL", 2.0), CueEvent("FLARE", 6.0), CueEvent("CUSHION", 9.0))
    assert [next_cue(events, t) for t in (0.0, 1.8, 2.4, 2.6, 3.0, 5.7, 8.0, 9.4, 9.6)] == [
        "LEVEL IN 2 s",
        "LEVEL",
        "LEVEL",
        "FLARE IN 4 s",
        "FLARE IN 3 s",
        "FLARE",
        "CUSHION IN 1 s",
        "CUSHION",
        "HOLD",
    ]
    assert next_cue(events, None) is None and next_cue((), 1.0) == "HOLD"
    # a re-plan during the flare starts nose up: the flare is under way at its start
    flaring = plan_cue_events(times[:4], collective[:4], np.radians(-np.full(4, 20.0)))
    assert flaring == (CueEvent("FLARE", 0.0, under_way=True),) and next_cue(flaring, 0.2) == "FLARE"
    # ... and does not hide what comes next
    assert next_cue((*flaring, CueEvent("CUSHION", 3.0)), 0.2) == "CUSHION IN 3 s"
    assert next_cue((CueEvent("FLARE", 20.0),), 1.0) == "HOLD"  # beyond the 6 s look-ahead
    with pytest.raises(ValueError, match="level_band_deg"):
        CueSettings(level_band_deg=12.0)
    with pytest.raises(ValueError, match="lookahead_s"):
        CueSettings(lookahead_s=math.nan)


def test_cues_sit_where_the_real_plan_changes() -> None:
    from helireach_ros.core.aircraft.model import initial_state_after_failure
    from helireach_ros.core.planning.planner import plan_landing

    airframe = load_airframe("uh60a_class")
    plan = plan_landing(initial_state_after_failure(airframe, 500 * FT, 75 * KT), airframe)
    times = np.linspace(0.0, plan.time_to_land, 400)
    collective, pitch = plan.controls_at(times)
    events = plan_cue_events(times, collective, pitch)
    kinds = [event.kind for event in events]
    assert "FLARE" in kinds and kinds[-1] == "CUSHION"
    nose_up = -np.degrees(pitch)
    for event in events:
        k = int(np.searchsorted(times, event.time_s))
        if event.kind == "FLARE":
            assert nose_up[k - 1] < 10.0 <= nose_up[k]
        elif event.kind == "CUSHION":
            window = (times >= times[-1] - 3.0) & (times < event.time_s)
            assert collective[k] > 1.3 * collective[window].min()
            assert event.time_s >= plan.time_to_land - 3.0


def test_levels_and_pilot_units() -> None:
    assert worst_level("safe", "caution") == "caution" and worst_level("avoid", None) == "nodata"
    airframe = load_airframe("uh60a_class")
    scale = thrust_scale(
        airframe.air_density,
        airframe.disk_area,
        airframe.rotor_radius,
        airframe.nominal_rotor_speed,
        airframe.gross_weight,
    )
    # hover: T = W, so C_T = W / (ρ A (Ω R)²) reads 100 %
    hover_ct = airframe.gross_weight / (
        airframe.air_density * airframe.disk_area * (airframe.nominal_rotor_speed * airframe.rotor_radius) ** 2
    )
    assert scale * hover_ct == pytest.approx(100.0)
    assert thrust_scale(0.0, 1.0, 1.0, 1.0, 1.0) is None
    edges = np.array([0.0, 10.0, 20.0, 30.0])
    assert line_margin(edges, np.array([True, False, True]), 4.0) == {"safe": True, "offset": -6.0}
    assert line_margin(edges, np.array([True, False, True]), 27.0) == {"safe": True, "offset": -3.0}  # grid top
    assert line_margin(edges, np.array([False, False, False]), 5.0) == {"safe": False, "offset": None}
    assert line_margin(edges, np.array([True, True, True]), 40.0) is None
    heights, speeds = np.array([0.0, 10.0, 20.0]), np.array([0.0, 5.0, 10.0])
    safe = np.array([[True, True, True], [False, True, True], [True, True, True]])
    margins = axis_margins(heights, speeds, safe, 15.0, 7.0)
    assert margins["vertical"] == {"safe": True, "offset": -5.0}  # the grid's top: beyond it nothing is proven
    assert margins["horizontal"] == {"safe": True, "offset": 2.0}  # one unsafe corner spoils the cell below 5 kt
    assert axis_margins(heights, speeds, safe, 25.0, 7.0) is None
