"""The planner node's weight policy without ROS: averaging, steadiness, band, quantisation, hold; mismatch presets."""

from __future__ import annotations

import math

import pytest

from helireach_ros.core.aircraft.model import trim_flight
from helireach_ros.core.estimation.weight_tracking import (
    WeightChoice,
    WeightSample,
    WeightTracker,
    WeightTrackingSettings,
    plausible_band,
    quantised_weight,
    ready_choice,
)
from helireach_ros.core.flight.mismatch_presets import MISMATCH_PRESET_NAMES, apply_mismatch_preset, mismatch_preset
from helireach_ros.core.flight.simulation import load_scenario, mismatched_airframe
from helireach_ros.core.flight.uncertainty import load_uncertainty_set
from helireach_ros.core.units import KT

PERIOD_NS = 40_000_000  # 25 Hz, as the simulated vehicle publishes
SPEED = 75 * KT


def feed(tracker: WeightTracker, power: float | None, count: int = 25, start_ns: int = 10**9, **overrides) -> int:
    """``count`` samples of level flight at 75 kt and Ω₀; returns the last stamp."""
    omega0 = tracker.airframe.nominal_rotor_speed
    stamp = start_ns
    for index in range(count):
        stamp = start_ns + index * PERIOD_NS
        values = {"forward_speed": SPEED, "climb_rate": 0.0, "rotor_speed": omega0, "engine_power": power}
        values.update({key: value(index) if callable(value) else value for key, value in overrides.items()})
        tracker.add(WeightSample(stamp, **values))
    return stamp


def power_of(airframe, mismatch: dict[str, float]) -> float:
    return trim_flight(mismatched_airframe(airframe, mismatch), SPEED, 0.0).power


def test_steady_flight_of_a_heavier_aircraft_gives_its_weight_quantised(airframe) -> None:
    tracker = WeightTracker(airframe)
    last = feed(tracker, power_of(airframe, {"gross_weight": 0.05}))
    choice = tracker.choice(last)
    assert choice.source == "estimate" and choice.reason == ""
    assert choice.estimated_change == pytest.approx(0.05, abs=1e-6)
    assert choice.gross_weight == quantised_weight(airframe.gross_weight, 0.05, 0.005)
    assert choice.relative_change == pytest.approx(0.05, abs=1e-12)


def test_quantisation_rounds_to_the_step_and_zero_is_exactly_the_file_weight() -> None:
    assert quantised_weight(70_000.0, 0.0123, 0.005) == pytest.approx(70_000.0 * 1.01)
    assert quantised_weight(70_000.0, 0.0024, 0.005) == 70_000.0
    assert quantised_weight(70_000.0, -0.05, 0.005) == pytest.approx(66_500.0)


def test_without_engine_power_the_file_weight_is_used_and_the_reason_says_so(airframe) -> None:
    tracker = WeightTracker(airframe)
    choice = tracker.choice(feed(tracker, None))
    assert (choice.source, choice.gross_weight) == ("file", airframe.gross_weight)
    assert "no engine power" in choice.reason


def test_an_implausible_estimate_is_refused_and_stays_the_reason_after_the_window(airframe) -> None:
    band = plausible_band(load_uncertainty_set())
    assert band == pytest.approx((-0.07, 0.07))
    tracker = WeightTracker(airframe, WeightTrackingSettings(band=band))
    # the uncertainty set's heavy, draggy corner: its power reads as +8.5 %, outside what the set calls plausible
    last = feed(tracker, power_of(airframe, mismatch_preset("heavy+draggy")))
    choice = tracker.choice(last)
    assert (choice.source, choice.gross_weight) == ("file", airframe.gross_weight)
    assert "outside the plausible band" in choice.reason and choice.estimated_change > 0.07
    later = tracker.choice(last + 2 * 10**9)  # the samples are too old now; the refusal is still why
    assert later.source == "file" and "outside the plausible band" in later.reason and "old" in later.reason
    # a power no weight in 0.7-1.3 x explains
    tracker = WeightTracker(airframe)
    choice = tracker.choice(feed(tracker, 3.0 * power_of(airframe, {})))
    assert choice.source == "file" and "no plausible weight" in choice.reason


@pytest.mark.parametrize(
    ("overrides", "reason"),
    [
        ({"forward_speed": lambda index: SPEED + 0.1 * index}, "speed varies"),
        ({"climb_rate": lambda index: 0.05 * index}, "climb rate varies"),
        ({"rotor_speed": lambda index: 25.0}, "rotor speed"),
    ],
    ids=["accelerating", "climbing_up", "rotor_off_governed_speed"],
)
def test_unsteady_flight_holds_the_last_estimate_then_falls_back(airframe, overrides, reason) -> None:
    tracker = WeightTracker(airframe, WeightTrackingSettings(hold_s=5.0))
    heavy = power_of(airframe, {"gross_weight": 0.05})
    unsteady_from = 2 * 10**9
    assert tracker.choice(feed(tracker, heavy)).source == "estimate"
    now = feed(tracker, heavy, start_ns=unsteady_from, **overrides)
    held = tracker.choice(now)
    assert held.source == "held" and reason in held.reason
    assert held.gross_weight == quantised_weight(airframe.gross_weight, 0.05, 0.005)
    later = feed(tracker, heavy, start_ns=unsteady_from + 6 * 10**9, **overrides)
    expired = tracker.choice(later)
    assert (expired.source, expired.gross_weight) == ("file", airframe.gross_weight) and reason in expired.reason


def test_too_few_out_of_order_or_non_finite_samples_give_no_estimate(airframe) -> None:
    tracker = WeightTracker(airframe)
    power = power_of(airframe, {})
    last = feed(tracker, power, count=5)
    assert not tracker.add(WeightSample(last, SPEED, 0.0, airframe.nominal_rotor_speed, power))  # not newer
    assert not tracker.add(WeightSample(last + 1, math.nan, 0.0, airframe.nominal_rotor_speed, power))
    choice = tracker.choice(last)
    assert choice.source == "file" and "5 steady-flight samples" in choice.reason


def test_a_weight_no_solver_holds_yet_is_replaced_by_the_nearest_one_they_hold() -> None:
    choice = WeightChoice(73_500.0, "estimate", 0.05)
    assert ready_choice(choice, 70_000.0, {70_000.0, 73_500.0}) is choice
    nearest = ready_choice(choice, 70_000.0, {70_000.0, 73_150.0})
    assert (nearest.gross_weight, nearest.source) == (73_150.0, "held") and "not built" in nearest.reason
    fallback = ready_choice(choice, 70_000.0, set())
    assert (fallback.gross_weight, fallback.source, fallback.relative_change) == (70_000.0, "file", 0.0)


def test_mismatch_presets() -> None:
    assert set(MISMATCH_PRESET_NAMES) >= {"none", "drag+5", "weight+5", "weight-5"}
    assert mismatch_preset("weight+5") == {"gross_weight": 0.05}
    assert mismatch_preset("drag+5") == load_scenario("demo_500ft_75kt").parameter_mismatch  # today's demo
    ranges = load_uncertainty_set().ranges()
    heavy = mismatch_preset("heavy+draggy")
    assert heavy == {name: ranges[name].high for name in heavy} and heavy["gross_weight"] == pytest.approx(0.05)
    light = mismatch_preset("light+clean")
    assert light == {name: ranges[name].low for name in light} and light["horizontal_drag_area"] == pytest.approx(-0.2)
    scenario = apply_mismatch_preset(load_scenario("demo_500ft_75kt"), "weight+5")
    assert scenario.parameter_mismatch == {"gross_weight": 0.05} and scenario.name == "demo_500ft_75kt:weight+5"
    with pytest.raises(ValueError, match="unknown mismatch preset"):
        mismatch_preset("weight+50")
