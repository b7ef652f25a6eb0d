"""Flyable plans: rates, attitudes, touchdown on the ground at touchdown attitude, no skims, delay.

Every check here is made on the independent replay (or on the plan's control function, which the replay
integrates), recomputed in the test from the plan's arrays, not read from the planner's own report.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import yaml

from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe, parse_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure, trim_controls
from helireach_ros.core.evidence.flyability import COMMIT_CLIMB_TOLERANCE, check_flyability
from helireach_ros.core.ocp.transcription.base import terminal_cost
from helireach_ros.core.planning.planner import GROUND_AT_FAILURE, ROTOR_LIMIT_DURING_DELAY, get_planner
from helireach_ros.core.resources import config_path
from helireach_ros.core.units import FT, KT

# (height ft, speed kt) across the plane: the cases, the hover band, the knee, high and low speed
PLANE = [(500, 75), (480, 120), (460, 120), (740, 120), (800, 0), (600, 30), (300, 100), (250, 60), (100, 60)]


@pytest.fixture(scope="module")
def planner(airframe, settings):
    assert settings.method == "flyable", "the shipped default must be the flyable plan"
    return get_planner(airframe, settings)


@pytest.fixture(scope="module")
def plans(planner, airframe):
    return {point: planner.plan(initial_state_after_failure(airframe, point[0] * FT, point[1] * KT)) for point in PLANE}


def _slopes(plan) -> np.ndarray:
    durations = np.diff(plan.control_times)
    keep = durations > 1e-9
    return np.abs(np.diff(plan.control_values, axis=1)[:, keep]) / durations[keep]


def test_the_default_500ft_75kt_plan_is_safe_verified_and_lands_on_the_ground(plans, airframe) -> None:
    plan = plans[(500, 75)]
    assert plan.safe and plan.verified, plan.replay.flyability.violations
    assert plan.control_interpolation == "linear"
    assert plan.replay.judged_at_contact and plan.replay.ground_contact_time is not None
    assert plan.states[3, -1] == pytest.approx(0.0, abs=1e-6)  # the NLP ends at h = 0, not up to 1 ft above
    touchdown = plan.replay.touchdown_state
    assert abs(touchdown[3]) <= 1e-6 + airframe.limits.ground_clearance
    assert touchdown[0] <= airframe.limits.max_descent_rate and abs(touchdown[1]) <= airframe.limits.max_forward_speed


@pytest.mark.parametrize("point", PLANE)
def test_replayed_plans_respect_every_rate_attitude_and_touchdown_limit(plans, airframe, point) -> None:
    plan = plans[point]
    flyability = airframe.flyability
    tolerance = 1.0 + 1e-6
    rates = _slopes(plan).max(axis=1)
    assert rates[0] <= airframe.max_thrust_coefficient_rate * tolerance
    assert rates[1] <= flyability.max_pitch_rate * tolerance
    pitch = plan.control_values[1]
    assert pitch.min() >= -flyability.max_nose_up_pitch * tolerance
    assert pitch.max() <= flyability.max_nose_down_pitch * tolerance
    # the controls start from what was flown before the failure: no jump at t = 0
    np.testing.assert_allclose(plan.controls_at([0.0])[:, 0], trim_controls(airframe, plan.initial_state))
    if plan.safe:
        contact = plan.replay.ground_contact_time
        assert contact is not None
        touchdown_pitch = float(plan.controls_at([contact])[1, 0])
        assert -flyability.touchdown_max_nose_up_pitch <= touchdown_pitch <= flyability.touchdown_max_nose_down_pitch
        assert plan.replay.flyability.within_limits


@pytest.mark.parametrize("point", PLANE)
def test_no_replayed_path_skims_the_ground_and_climbs_away(plans, airframe, point) -> None:
    """Before its final descent (the first time below the commit height) no path is near the ground; from then
    on it never climbs: a pass close to the ground at speed followed by a zoom cannot happen."""
    plan = plans[point]  # unsafe plans too: the NLP keeps the rule whatever the landing's value
    heights = plan.replay.states[3]
    below = np.flatnonzero(heights < airframe.flyability.commit_height)
    assert below.size, "a landing ends on the ground"
    final_descent = heights[below[0] :]
    assert np.all(np.diff(final_descent) <= COMMIT_CLIMB_TOLERANCE)
    assert final_descent.max() - final_descent[-1] >= 0.0
    assert np.all(heights[: below[0]] >= airframe.flyability.commit_height)


def test_the_check_catches_a_skim_a_step_and_a_tail_strike(airframe) -> None:
    """The replay's judge on constructed cases (each breaks one limit and nothing else)."""
    times = np.array([0.0, 1.0, 2.0])
    gentle = np.array([[0.006, 0.006, 0.006], [0.0, -0.1, -0.1]])
    heights = np.array([100.0, 10.0, 0.0])
    assert check_flyability(airframe, times, gentle, "linear", heights, -0.1).within_limits
    skim = np.array([100.0, 0.01, 20.0, 0.0])  # 1 cm above the ground, then back up to 20 m
    report = check_flyability(airframe, times, gentle, "linear", skim, -0.1)
    assert report.commit_climb == pytest.approx(19.99) and "skim" in " ".join(report.violations)
    step = check_flyability(airframe, times, gentle, "zero_order_hold", heights, -0.1)
    assert math.isinf(step.max_pitch_rate) and not step.within_limits
    too_fast = np.array([[0.006, 0.006, 0.006], [0.0, -0.6, -0.1]])  # 0.6 rad/s, the limit is 20 deg/s
    assert any(
        "pitch rate" in line for line in check_flyability(airframe, times, too_fast, "linear", heights, -0.1).violations
    )
    tail_strike = check_flyability(airframe, times, gentle, "linear", heights, -math.radians(15.0))
    assert any("touchdown attitude" in line for line in tail_strike.violations)
    no_contact = check_flyability(airframe, times, gentle, "linear", heights, None)
    assert "no ground contact" in no_contact.violations


def test_a_re_plan_starts_from_the_control_being_flown(planner, airframe) -> None:
    state = initial_state_after_failure(airframe, 300 * FT, 50 * KT).as_array()
    flying = np.array([0.004, -0.2])
    plan = planner.plan(state, initial_control=flying, reaction_delay_s=0.0)
    np.testing.assert_allclose(plan.controls_at([0.0])[:, 0], flying)
    assert _slopes(plan)[1].max() <= airframe.flyability.max_pitch_rate * (1 + 1e-6)


def test_the_reaction_delay_holds_the_trim_then_plans(airframe, settings) -> None:
    delayed = get_planner(airframe, settings.replace(reaction_delay_s=0.3))
    state = initial_state_after_failure(airframe, 500 * FT, 75 * KT)
    plan = delayed.plan(state)
    trim = trim_controls(airframe, state.as_array())
    assert plan.reaction_delay_s == 0.3 and plan.to_dict()["reaction_delay_s"] == 0.3
    np.testing.assert_allclose(plan.controls_at(np.linspace(0.0, 0.3, 7)), np.tile(trim[:, None], (1, 7)), atol=1e-12)
    assert plan.times[0] == 0.0 and np.array_equal(plan.states[:, 0], state.as_array())
    assert plan.replay.times[0] == 0.0  # the replay flies the delay segment too
    assert plan.safe, plan.replay.flyability.violations


def test_a_delay_the_rotor_cannot_survive_is_unsafe_without_a_solve(airframe, settings) -> None:
    """Hover, collective held for 1 s after a total power loss: the rotor falls below 85 % before any input."""
    delayed = get_planner(airframe, settings.replace(reaction_delay_s=1.0))
    plan = delayed.plan(initial_state_after_failure(airframe, 800 * FT, 0.0))
    assert plan.solver.status == ROTOR_LIMIT_DURING_DELAY
    assert plan.status == "unsafe" and not plan.replay.lands_within_limits
    assert plan.replay.states[2].min() < airframe.limits.min_rotor_speed_ratio * airframe.nominal_rotor_speed


def test_a_failure_on_the_ground_outside_the_touchdown_limits_is_unsafe_without_a_solve(airframe, settings) -> None:
    """At the ground and not climbing, a flyable plan touches down as it is: at 30 kt or sinking at 500 ft/min that
    is outside the limits, decided by the replay alone; within them (hover) and climbing away, the NLP plans."""
    planner = get_planner(airframe, settings)
    for speed_kt, climb_fpm in ((30.0, 0.0), (60.0, -500.0)):
        state = initial_state_after_failure(airframe, 0.0, speed_kt * KT, climb_rate=climb_fpm * FT / 60.0)
        plan = planner.plan(state)
        assert plan.solver.status == GROUND_AT_FAILURE and plan.solver.iterations == 0
        assert plan.status == "unsafe" and not plan.replay.lands_within_limits
        assert plan.replay.ground_contact_time == pytest.approx(0.0, abs=1e-6)
        assert plan.value == pytest.approx(terminal_cost(airframe, state.as_array()), rel=1e-3)
    hover = planner.plan(initial_state_after_failure(airframe, 0.0, 0.0))
    assert hover.solver.iterations > 0 and hover.safe
    climbing = planner.plan(initial_state_after_failure(airframe, 0.0, 60 * KT, climb_rate=750 * FT / 60.0))
    assert climbing.solver.status != GROUND_AT_FAILURE and not climbing.safe
    paper = get_planner(airframe, settings.replace(method="verified"))  # may climb from the ground: no shortcut
    assert paper.plan(initial_state_after_failure(airframe, 0.0, 30 * KT)).solver.iterations > 0


def test_the_unsafe_set_grows_with_the_reaction_delay(airframe, settings) -> None:
    """Nesting on a small grid: a state safe with a longer delay is safe with a shorter one, up to the
    certification-style 1 s (700 ft is above the hover band without a delay)."""
    grid = [(h, v) for h in (150, 300, 700) for v in (0, 40, 80)]
    safe_sets = []
    for delay in (0.0, 0.5, 1.0):
        planner = get_planner(airframe, settings.replace(reaction_delay_s=delay))
        safe_sets.append(
            {
                point
                for point in grid
                if planner.plan(initial_state_after_failure(airframe, point[0] * FT, point[1] * KT)).safe
            }
        )
    assert safe_sets[0] >= safe_sets[1] >= safe_sets[2], safe_sets
    assert safe_sets[2] < safe_sets[0], "the delay changed nothing on this grid"


def test_flyability_limits_come_from_the_airframe_file_with_sources(tmp_path) -> None:
    document = yaml.safe_load(config_path("airframes/uh60a_class.yaml").read_text())
    airframe = parse_airframe(document)
    labels = dict(airframe.sources)
    assert "assumed" in labels["flyability.max_nose_up_pitch"]
    assert airframe.flyability.max_nose_up_pitch == pytest.approx(math.radians(25.0))
    without = {key: value for key, value in document.items() if key != "flyability"}
    defaulted = parse_airframe(without)
    assert dict(defaulted.sources)["flyability.max_pitch_rate"] == "helireach default (assumed)"
    wrong = dict(document, flyability=dict(document["flyability"]))
    wrong["flyability"]["touchdown_max_nose_up_pitch"] = {"value": 30.0, "unit": "deg", "source": "test"}
    with pytest.raises(ConfigError, match="touchdown attitude window"):
        parse_airframe(wrong)
    unknown_unit = dict(document, flyability=dict(document["flyability"]))
    unknown_unit["flyability"]["max_pitch_rate"] = {"value": 20.0, "unit": "deg/min", "source": "test"}
    with pytest.raises(ConfigError, match="max_pitch_rate"):
        parse_airframe(unknown_unit)
    assert dataclasses.replace(load_airframe("oh58a_class")).flyability == airframe.flyability


def test_a_replan_from_a_rotor_a_flare_sped_up_past_the_nlps_line_has_a_plan(planner, airframe) -> None:
    """The NLP keeps Ω 1 % inside its limits; in a flare the rotor can be measured between that line and the true
    limit (114.6 % of 115 %) while the controls being flown still speed it up. The back-off starts after the first
    interval, so a re-plan from there converges (it did not: Infeasible/Maximum_Iterations before), and the
    replay holds it to the true limit everywhere."""
    omega0 = airframe.nominal_rotor_speed
    state = np.array([15 * FT, 30 * KT, 1.146 * omega0, 60 * FT, 0.0, 0.0])  # descending at 15 ft/s, 60 ft
    flare = np.array([0.002, -0.35])  # low collective, 20° nose up: what is flown in the flare
    plan = planner.plan(state, None, flare, 0.0)
    assert plan.solver.success, plan.solver.status
    assert plan.safe and plan.replay.rotor_speed_within_limits
    assert np.max(plan.replay.states[2]) <= airframe.limits.max_rotor_speed_ratio * omega0
    # after the first interval the NLP's line holds again
    after_first = plan.times > plan.time_to_land * planner.transcription.fractions[0] + 1e-9
    backoff_line = (airframe.limits.max_rotor_speed_ratio - planner.settings.rotor_speed_backoff) * omega0
    assert after_first.sum() > 50 and np.all(plan.states[2, after_first] <= backoff_line * (1 + 1e-6))


def test_a_replan_from_a_rotor_inside_the_nlps_line_keeps_it_inside_from_the_start(planner, airframe) -> None:
    """The first interval's room up to the true limit is for a rotor already past the NLP's line. From a rotor inside
    it the plan keeps the line at every node from the start: given to every re-plan, that room was what the closed loop
    flew (re-planned every 0.25 s, it rode the true limit). The state is a re-plan of the demo's closed loop as the
    flare speeds the rotor up (110.3 %, 390 ft); with the room, its plan went to 114.7 %."""
    omega0 = airframe.nominal_rotor_speed
    backoff_line = (airframe.limits.max_rotor_speed_ratio - planner.settings.rotor_speed_backoff) * omega0
    state = np.array([12.848, 32.077, 29.782, 118.689, 291.292, 0.0])
    flown = np.array([0.0077, -0.2448])
    disturbance = np.array([-0.035, -0.172, -0.034])
    plan = planner.plan(state, None, flown, 0.0, disturbance=disturbance)
    assert plan.solver.success, plan.solver.status
    assert plan.safe
    assert np.max(plan.states[2]) <= backoff_line * (1 + 1e-6), np.max(plan.states[2]) / omega0
    _, upper = planner.transcription.variable_bounds(np.concatenate([state, flown, disturbance]))
    past_line = state.copy()
    past_line[2] = 1.146 * omega0
    _, upper_past = planner.transcription.variable_bounds(np.concatenate([past_line, flown, disturbance]))
    assert np.sum(upper_past > upper) == planner.settings.degree  # the first interval's rotor nodes, only there
