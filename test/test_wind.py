"""Wind along the track (Airframe.headwind): the model flies through the air, the distance and the touchdown are
judged over the ground; calm is the model as before (same NLP, same airframe digest). Real IPOPT and replay."""

from __future__ import annotations

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe
from helireach_ros.core.aircraft.model import dynamics_function, initial_state_after_failure
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.ocp.transcription.base import terminal_cost
from helireach_ros.core.planning.footprint import touchdown_distance
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.units import FT, KT

HEADWIND = 15 * KT


@pytest.fixture(scope="module")
def airframe():
    return load_airframe("uh60a_class")


def test_calm_is_the_airframe_as_before_and_a_wind_is_a_condition_of_the_day(airframe) -> None:
    assert airframe.headwind == 0.0 and airframe.with_conditions(headwind=0.0).digest() == airframe.digest()
    windy = airframe.with_conditions(headwind=HEADWIND)
    assert windy.digest() != airframe.digest() and windy.headwind == HEADWIND
    with pytest.raises(ConfigError, match="headwind"):
        airframe.with_conditions(headwind=100.0)


def test_the_aircraft_flies_through_the_air_and_travels_over_the_ground(airframe) -> None:
    state = initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()
    control = np.array([0.006, 0.05])
    calm = np.asarray(dynamics_function(airframe)(state, control)).reshape(-1)
    windy = np.asarray(dynamics_function(airframe.with_conditions(headwind=HEADWIND))(state, control)).reshape(-1)
    moved = StateIndex.DISTANCE
    assert windy[moved] == pytest.approx(calm[moved] - HEADWIND)  # ż = v − W
    assert np.delete(windy, moved) == pytest.approx(np.delete(calm, moved))  # the air sees the same aircraft
    touchdown = np.array([1.0, HEADWIND, state[2], 0.0, 0.0, 0.0])  # 15 kt airspeed into a 15 kt wind
    assert float(terminal_cost(airframe.with_conditions(headwind=HEADWIND), touchdown)) == pytest.approx(
        1.0 / airframe.limits.max_descent_rate - 1.0
    )  # no ground speed left: only the descent rate counts


def test_into_the_wind_the_landing_is_shorter_and_slower_over_the_ground_downwind_it_is_unsafe(airframe) -> None:
    settings = load_settings(objective="reach_avoid")
    plans = {}
    for headwind in (-HEADWIND, 0.0, HEADWIND):
        windy = airframe.with_conditions(headwind=headwind)
        state = initial_state_after_failure(windy, 500 * FT, 75 * KT).as_array()
        plans[headwind] = get_planner(windy, settings).plan(state)
    calm, into, downwind = plans[0.0], plans[HEADWIND], plans[-HEADWIND]
    assert calm.safe and into.safe and into.value < calm.value  # more margin into the wind
    assert into.touchdown_ground_speed == pytest.approx(
        into.replay.touchdown_state[StateIndex.FORWARD_SPEED] - HEADWIND
    )
    assert into.touchdown_ground_speed < calm.touchdown_ground_speed
    assert touchdown_distance(into) < touchdown_distance(calm)
    # a 15 kt tailwind adds 15 kt to a touchdown the flare cannot bring below ~13 kt of airspeed: over the limit
    assert not downwind.safe and downwind.touchdown_ground_speed > airframe.limits.max_forward_speed


def test_into_the_wind_the_touchdown_cost_plan_makes_contact_instead_of_grazing_and_is_verified(airframe) -> None:
    """Into a 15 kt wind the touchdown cost could reach J = −1 (no sink, no ground speed): a graze whose replayed
    contact comes at the flare attitude. The wind's minimum touchdown descent rate makes it a contact."""
    settings = load_settings()
    windy = airframe.with_conditions(headwind=HEADWIND)
    state = initial_state_after_failure(windy, 500 * FT, 75 * KT).as_array()
    plan = get_planner(windy, settings).plan(state)
    assert plan.safe and plan.verified and plan.replay.flyability.within_limits
    floor = settings.wind_touchdown_min_descent_rate
    assert plan.states[StateIndex.DESCENT_RATE, -1] >= floor - 1e-6
    assert plan.value > -1.0 + 0.5 * floor / airframe.limits.max_descent_rate  # off the degenerate floor
    assert 0.0 <= plan.touchdown_ground_speed < 5 * KT
    calm = get_planner(airframe, settings).plan(initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array())
    assert calm.states[StateIndex.DESCENT_RATE, -1] > 1.0  # calm keeps its own touchdown (the bound is wind's only)
