"""The ROS-free closed-loop vehicle: control encoding, scenarios, trim, touchdown judgement, open-loop mismatch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import ConfigError
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.flight.simulation import (
    ControlSchedule,
    SimulatedVehicle,
    load_scenario,
    mismatched_airframe,
    piecewise_linear_controls,
)
from helireach_ros.core.planning.planner import plan_landing
from helireach_ros.core.units import FT, KT

SHIPPED_SCENARIOS = ("demo_500ft_75kt", "nominal_500ft_75kt", "low_hover_100ft")


@pytest.fixture(scope="module")
def plan_500ft_75kt(airframe, settings):
    return plan_landing(initial_state_after_failure(airframe, 500 * FT, 75 * KT), airframe, settings)


def test_zero_order_hold_is_encoded_exactly_as_linear_points(plan_500ft_75kt) -> None:
    plan = plan_500ft_75kt
    times, values = piecewise_linear_controls(plan.control_times, plan.control_values, plan.control_interpolation)
    assert np.all(np.diff(times) > 0)
    # Away from the δ-wide ramps, linear interpolation of the points is the plan's own control function.
    probe = np.linspace(0.0, plan.time_to_land, 2001)
    near_breakpoint = np.min(np.abs(probe[:, None] - plan.control_times[None, :]), axis=1) < 1e-5
    expected = plan.controls_at(probe[~near_breakpoint])
    encoded = np.vstack([np.interp(probe[~near_breakpoint], times, row) for row in values])
    np.testing.assert_allclose(encoded, expected, rtol=0, atol=1e-12)


def test_linear_controls_pass_through_and_unknown_interpolation_is_refused() -> None:
    times, values = piecewise_linear_controls(np.array([0.0, 1.0, 2.0]), np.ones((2, 3)), "linear")
    assert times.tolist() == [0.0, 1.0, 2.0] and values.shape == (2, 3)
    with pytest.raises(ValueError, match="interpolation"):
        piecewise_linear_controls(np.array([0.0, 1.0]), np.ones((2, 1)), "cubic")


@pytest.mark.parametrize("name", SHIPPED_SCENARIOS)
def test_shipped_scenarios_load_in_si(name: str) -> None:
    scenario = load_scenario(name)
    assert scenario.name == name
    assert 0.0 <= scenario.height <= 1000.0 and 0.0 <= scenario.forward_speed <= 80.0


@pytest.mark.parametrize(
    ("document", "message"),
    [
        ("height: {value: 500, unit: kt}\n", "measures speed"),
        ("height: 500\n", "value"),
        ("altitude: {value: 500, unit: ft}\n", "unknown scenario key"),
        ("parameter_mismatch: {gross_weight: 0.9}\n", "fraction"),
        ("parameter_mismatch: {tail_length: 0.1}\n", "unknown parameter"),
        ("sensor_noise: {height: {value: -1, unit: ft}}\n", ">= 0"),
        ("seed: 1.5\n", "seed"),
        (": : :\n", "cannot read"),
    ],
)
def test_broken_scenario_files_are_refused_with_the_file_named(tmp_path, document: str, message: str) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\n" + document)
    with pytest.raises(ConfigError, match=message) as error:
        load_scenario(path)
    assert "broken" in str(error.value)


def test_mismatch_scales_only_the_named_parameters(airframe) -> None:
    true = mismatched_airframe(airframe, {"rotor_inertia": -0.05, "gross_weight": 0.1})
    assert true.rotor_inertia == pytest.approx(0.95 * airframe.rotor_inertia)
    assert true.gross_weight == pytest.approx(1.1 * airframe.gross_weight)
    assert true.rotor_radius == airframe.rotor_radius and true.limits == airframe.limits
    assert mismatched_airframe(airframe, {}) is airframe


def test_cruise_is_level_trim_until_the_failure(airframe) -> None:
    scenario = dataclasses.replace(load_scenario("nominal_500ft_75kt"), failure_time=2.0)
    vehicle = SimulatedVehicle(scenario, airframe)
    start = vehicle.state.copy()
    vehicle.advance(1.5)
    assert vehicle.phase == "cruise" and not vehicle.engine_failed
    np.testing.assert_allclose(vehicle.state[[0, 1, 2, 3, 5]], start[[0, 1, 2, 3, 5]])
    assert vehicle.state[4] == pytest.approx(1.5 * scenario.forward_speed)
    vehicle.advance(1.0)
    assert vehicle.engine_failed and vehicle.state[5] < start[5]


def test_noise_is_seeded(airframe) -> None:
    scenario = load_scenario("demo_500ft_75kt")
    first, second = SimulatedVehicle(scenario, airframe), SimulatedVehicle(scenario, airframe)
    other = SimulatedVehicle(dataclasses.replace(scenario, seed=scenario.seed + 1), airframe)
    assert first.measure() == second.measure()
    assert first.measure().height != other.measure().height


def follow_one_plan(scenario, airframe, settings) -> SimulatedVehicle:
    """Flies the scenario with the plan made at the failure and nothing else (no re-planning)."""
    vehicle = SimulatedVehicle(scenario, airframe, settings)
    vehicle.advance(scenario.failure_time)
    measured = vehicle.measure()
    state = np.array(
        [-measured.climb_rate, measured.forward_speed, measured.rotor_speed, measured.height, measured.distance, 0.0]
    )
    plan = plan_landing(state, airframe, settings)
    assert plan.safe
    vehicle.follow(ControlSchedule.from_plan(plan, vehicle.time))
    while not vehicle.landed:
        vehicle.advance(0.5)
    return vehicle, plan


def test_the_exact_model_flies_the_plan_as_the_replay_predicts(airframe, settings) -> None:
    vehicle, plan = follow_one_plan(load_scenario("nominal_500ft_75kt"), airframe, settings)
    report = vehicle.touchdown
    assert report.within_limits, report.reason
    assert report.time_after_failure == pytest.approx(plan.time_to_land, abs=0.3)
    assert report.descent_rate <= airframe.limits.max_descent_rate
    assert abs(report.forward_speed) <= airframe.limits.max_forward_speed


def test_the_demo_mismatch_defeats_a_single_plan(airframe, settings) -> None:
    """Without re-planning the demo's 5 % drag mismatch lands outside the limits (closed loop: test_ros_system)."""
    vehicle, _ = follow_one_plan(load_scenario("demo_500ft_75kt"), airframe, settings)
    assert not vehicle.touchdown.within_limits
    assert "exceeds the limits" in vehicle.touchdown.reason


def test_a_hover_in_the_avoid_region_crashes(airframe, settings) -> None:
    scenario = load_scenario("low_hover_100ft")
    vehicle = SimulatedVehicle(scenario, airframe, settings)
    while not vehicle.landed:
        vehicle.advance(0.5)  # no plan at all: the trim controls are held
    assert not vehicle.touchdown.within_limits
    assert vehicle.touchdown.descent_rate > airframe.limits.max_descent_rate


def test_bad_schedules_are_refused() -> None:
    with pytest.raises(ValueError, match="increasing"):
        ControlSchedule(0.0, np.array([0.0, 0.0]), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="finite"):
        ControlSchedule(0.0, np.array([0.0, 1.0]), np.array([[0.0, np.nan], [0.0, 0.0]]))
