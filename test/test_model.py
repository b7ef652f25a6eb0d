"""Model sanity: trim balances weight and drag, autorotation has a steady descent, signs are physical."""

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import (
    dynamics_function,
    initial_state_after_failure,
    steady_autorotation,
    trim_flight,
    trim_level_flight,
)
from helireach_ros.core.units import FT, KT


@pytest.fixture(scope="module")
def uh60():
    return load_airframe("uh60a_class")


def test_hover_trim_thrust_balances_weight(uh60):
    trim = trim_level_flight(uh60, 0.0)
    tip_speed = uh60.nominal_rotor_speed * uh60.rotor_radius
    thrust = uh60.air_density * uh60.disk_area * tip_speed**2 * trim.thrust_coefficient
    assert thrust == pytest.approx(uh60.gross_weight, rel=1e-12)
    assert trim.pitch_angle == 0.0
    assert 0.0 < trim.thrust_coefficient < uh60.max_thrust_coefficient


@pytest.mark.parametrize("speed_kt", [0.0, 40.0, 75.0, 120.0])
def test_level_trim_is_an_equilibrium_with_trim_power(uh60, speed_kt):
    trim = trim_level_flight(uh60, speed_kt * KT)
    state = initial_state_after_failure(uh60, 100.0, speed_kt * KT, power_fraction=1.0).as_array()
    derivative = np.asarray(dynamics_function(uh60)(state, [trim.thrust_coefficient, trim.pitch_angle])).ravel()
    np.testing.assert_allclose(derivative[:4], [0.0, 0.0, 0.0, 0.0], atol=1e-9)
    assert derivative[4] == pytest.approx(speed_kt * KT)
    assert trim.power > 0.0
    assert trim.pitch_angle >= 0.0  # nose down to pull forward against drag


def test_trim_power_grows_with_speed_in_the_papers_hover_inflow(uh60):
    # The paper's rotor takes hover inflow at every speed, so it has no power bucket (the momentum rotor's bucket is
    # in test_inflow.py).
    powers = [trim_level_flight(uh60.paper_model(), v * KT).power for v in (0.0, 40.0, 80.0, 120.0)]
    assert np.all(np.diff(powers) > 0.0)
    # UH-60A-class hover power is of the order of the installed power (two ~1,500 shp engines).
    assert 1000.0 < powers[0] / 745.7 < 3500.0


@pytest.mark.parametrize("speed_kt", [0.0, 30.0, 60.0])
def test_steady_autorotation_descends_at_constant_rotor_speed(uh60, speed_kt):
    height = 100.0  # the equilibrium is the one at this height: ground effect still changes the inflow slightly here
    descent_rate, thrust_coefficient, pitch = steady_autorotation(uh60, speed_kt * KT, height)
    state = np.array([descent_rate, speed_kt * KT, uh60.nominal_rotor_speed, height, 0.0, 0.0])
    derivative = np.asarray(dynamics_function(uh60)(state, [thrust_coefficient, pitch])).ravel()
    np.testing.assert_allclose(derivative[:3], 0.0, atol=1e-8)
    assert 20.0 < descent_rate / FT < 80.0  # a steep power-off descent, tens of ft/s
    assert 0.0 < thrust_coefficient < uh60.max_thrust_coefficient


def test_vertical_drag_opposes_descent(uh60):
    dynamics = dynamics_function(uh60)
    falling = np.asarray(dynamics([20.0, 0.0, 27.0, 100.0, 0.0, 0.0], [0.0, 0.0])).ravel()
    climbing = np.asarray(dynamics([-20.0, 0.0, 27.0, 100.0, 0.0, 0.0], [0.0, 0.0])).ravel()
    assert falling[0] < uh60.gravity < climbing[0]


def test_power_off_rotor_decays_in_level_flight(uh60):
    trim = trim_level_flight(uh60, 75 * KT)
    state = initial_state_after_failure(uh60, 150.0, 75 * KT, power_fraction=0.0).as_array()
    derivative = np.asarray(dynamics_function(uh60)(state, [trim.thrust_coefficient, trim.pitch_angle])).ravel()
    assert derivative[2] < 0.0


def test_trim_beyond_stall_is_refused(uh60):
    heavy = uh60.with_conditions(gross_weight=3.0 * uh60.gross_weight)
    with pytest.raises(ValueError, match="stall"):
        trim_level_flight(heavy, 0.0)


def test_initial_state_after_failure_keeps_a_fraction_of_trim_power(uh60):
    trim = trim_level_flight(uh60, 50 * KT, 200 * FT)  # trim power at the state's height, in ground effect or not
    state = initial_state_after_failure(uh60, 200 * FT, 50 * KT, power_fraction=0.25)
    assert state.engine_power == pytest.approx(0.25 * trim.power)
    assert state.height == pytest.approx(200 * FT)
    with pytest.raises(ValueError):
        initial_state_after_failure(uh60, 200 * FT, 50 * KT, power_fraction=1.5)
    with pytest.raises(ValueError):
        initial_state_after_failure(uh60, float("nan"), 50 * KT)


FPM = FT / 60.0


@pytest.mark.parametrize(("speed_kt", "climb_fpm"), [(0, -2000), (40, -2000), (75, -1500), (75, 1500), (120, -1000)])
def test_trim_on_a_flight_path_is_an_equilibrium(uh60, speed_kt, climb_fpm):
    trim = trim_flight(uh60, speed_kt * KT, climb_fpm * FPM)
    state = initial_state_after_failure(
        uh60, 300 * FT, speed_kt * KT, power_fraction=1.0, climb_rate=climb_fpm * FPM
    ).as_array()
    assert state[0] == pytest.approx(-climb_fpm * FPM)  # y is the descent rate
    derivative = np.asarray(dynamics_function(uh60)(state, [trim.thrust_coefficient, trim.pitch_angle])).ravel()
    np.testing.assert_allclose(derivative[:3], [0.0, 0.0, 0.0], atol=1e-9)
    assert derivative[3] == pytest.approx(climb_fpm * FPM)


def test_power_to_hold_the_rotor_falls_in_a_descent_and_rises_in_a_climb(uh60):
    # -1,500 ft/min: powered at 75 kt, short of the steady autorotation's ~1,900 ft/min there
    powers = [trim_flight(uh60, 75 * KT, climb * FPM).power for climb in (-1500, -1000, 0, 1500)]
    assert np.all(np.diff(powers) > 0.0)
    assert trim_flight(uh60, 75 * KT, 0.0) == trim_level_flight(uh60, 75 * KT)


def test_a_descent_too_steep_for_powered_flight_is_refused(uh60):
    with pytest.raises(ValueError, match=r"autorotates|terminal"):
        trim_flight(uh60, 75 * KT, -8000 * FPM)
    with pytest.raises(ValueError, match="climb rate"):
        trim_flight(uh60, 75 * KT, float("nan"))


def test_the_failure_state_takes_the_measured_rotor_speed(uh60):
    state = initial_state_after_failure(uh60, 200 * FT, 50 * KT, rotor_speed=0.95 * uh60.nominal_rotor_speed)
    assert state.rotor_speed == pytest.approx(0.95 * uh60.nominal_rotor_speed)
    with pytest.raises(ValueError, match="rotor speed"):
        initial_state_after_failure(uh60, 200 * FT, 50 * KT, rotor_speed=-1.0)
