"""Today's gross weight from the steady flight before a failure (estimation)."""

from __future__ import annotations

import dataclasses

import pytest

from helireach_ros.core.aircraft.model import trim_flight
from helireach_ros.core.estimation.gross_weight import estimate_gross_weight
from helireach_ros.core.flight.simulation import SimulatedVehicle, load_scenario
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings, fly_closed_loop
from helireach_ros.core.units import FT, KT


@pytest.mark.parametrize(("speed_kt", "climb_fpm", "heavier"), [(0, 0, 0.05), (75, 0, -0.08), (110, 500, 0.12)])
def test_the_weight_whose_trim_power_is_the_measured_power(airframe, speed_kt, climb_fpm, heavier) -> None:
    true = airframe.with_conditions(gross_weight=(1 + heavier) * airframe.gross_weight)
    power = trim_flight(true, speed_kt * KT, climb_fpm * FT / 60).power
    estimate = estimate_gross_weight(airframe, speed_kt * KT, climb_fpm * FT / 60, power)
    assert estimate.relative_change == pytest.approx(heavier, abs=1e-6)
    assert estimate.file_weight_power == pytest.approx(trim_flight(airframe, speed_kt * KT, climb_fpm * FT / 60).power)


def test_a_power_no_plausible_weight_explains_is_refused(airframe) -> None:
    cruise = trim_flight(airframe, 75 * KT).power
    with pytest.raises(ValueError, match="outside what"):
        estimate_gross_weight(airframe, 75 * KT, 0.0, 2.0 * cruise)
    for bad in (float("nan"), -1.0, 0.0):
        with pytest.raises(ValueError):
            estimate_gross_weight(airframe, 75 * KT, 0.0, bad)


def test_the_closed_loop_with_an_unknown_5_percent_weight_lands_when_it_estimates_the_weight(airframe, settings):
    """+5 % weight the airframe file does not know: with the file's weight the closed loop lands outside the limits
    (test_closed_loop, re-planning without the disturbance estimate); estimating the weight from the power before
    the failure, the same policy lands within them. (With the disturbance estimate on as well the landing is at
    the speed limit, 5.7–6.3 kt for latencies 0.05–0.15 s with either NLP: a knife edge.)"""
    heavy = dataclasses.replace(load_scenario("demo_500ft_75kt"), parameter_mismatch={"gross_weight": 0.05})
    result = fly_closed_loop(
        SimulatedVehicle(heavy, airframe, settings),
        get_planner(airframe, settings),
        ClosedLoopSettings(latency=0.1, estimate_weight=True, estimate_disturbance=False),
    )
    assert result.planned_gross_weight / airframe.gross_weight - 1.0 == pytest.approx(0.05, abs=0.005)
    assert result.touchdown.within_limits, result.touchdown.reason
