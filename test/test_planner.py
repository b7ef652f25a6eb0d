"""Landing plans with real IPOPT and the independent replay: the acceptance cases of the core."""

import numpy as np
import pytest

from helireach_ros.core.airframe import load_airframe
from helireach_ros.core.model import initial_state_after_failure
from helireach_ros.core.planner import WarmStart, get_planner, plan_landing
from helireach_ros.core.settings import PlannerSettings
from helireach_ros.core.units import FT, KT


@pytest.fixture(scope="module")
def uh60():
    return load_airframe("uh60a_class")


@pytest.fixture(scope="module")
def cruise_plan(uh60):
    return plan_landing(initial_state_after_failure(uh60, 500 * FT, 75 * KT), uh60)


def test_cruise_500ft_75kt_is_safe_and_verified(cruise_plan):
    assert cruise_plan.method == "verified"
    assert cruise_plan.solver.success
    assert cruise_plan.value <= 0.0
    assert cruise_plan.safe and cruise_plan.verified and cruise_plan.status == "safe"
    assert 8.0 <= cruise_plan.time_to_land <= 16.0
    touchdown = cruise_plan.replay.touchdown_state
    assert abs(touchdown[0]) <= 8 * FT and abs(touchdown[1]) <= 6 * KT and abs(touchdown[3]) <= 1 * FT


def test_rotor_speed_rises_in_the_flare(cruise_plan):
    """Paper, Fig. 3c: forward kinetic energy goes into the rotor as the helicopter decelerates."""
    rotor, forward_speed, times = cruise_plan.states[2], cruise_plan.states[1], cruise_plan.times
    peak = int(np.argmax(rotor))
    trough = int(np.argmin(rotor[: peak + 1]))
    assert times[peak] > cruise_plan.time_to_land / 2
    assert rotor[peak] - rotor[trough] > 0.1 * cruise_plan.nominal_rotor_speed
    assert forward_speed[peak] < forward_speed[trough] - 5 * KT


def test_replay_follows_the_verified_plan(cruise_plan):
    deviation = cruise_plan.replay.max_deviation
    assert deviation["height"] < 0.3  # m
    assert deviation["descent_rate"] < 0.3  # m/s
    assert cruise_plan.replay.value == pytest.approx(cruise_plan.value, abs=0.05)
    contact = cruise_plan.replay.ground_contact_time  # the replay meets the ground at the planned touchdown
    assert contact is None or contact == pytest.approx(cruise_plan.time_to_land, abs=0.1)
    limits = cruise_plan.states[2] / cruise_plan.nominal_rotor_speed
    assert limits.min() >= 0.85 - 1e-6 and limits.max() <= 1.15 + 1e-6


def test_hover_at_150ft_is_unsafe(uh60):
    plan = plan_landing(initial_state_after_failure(uh60, 150 * FT, 0.0), uh60)
    assert plan.solver.success
    assert plan.value > 0.0
    assert plan.status == "unsafe" and not plan.safe


def test_hover_at_600ft_is_safe(uh60):
    plan = plan_landing(initial_state_after_failure(uh60, 600 * FT, 0.0), uh60)
    assert plan.status == "safe" and plan.verified


def test_paper_method_is_optimistic_at_500ft_75kt(uh60):
    """The paper's settings (one LGR interval, N = 24, c = 3) call this plan safe; its replay does not land."""
    paper = PlannerSettings(method="paper")
    assert (paper.paper_points, paper.paper_time_scale) == (24, 3.0)
    plan = plan_landing(initial_state_after_failure(uh60, 500 * FT, 75 * KT), uh60, paper)
    assert plan.solver.success
    assert plan.value <= 0.0  # the NLP claims a safe landing
    assert plan.replay.value > 0.0  # integrated through the model, it does not land within limits
    assert plan.status == "unverified" and not plan.safe


def test_same_state_gives_the_same_plan(uh60):
    state = initial_state_after_failure(uh60, 300 * FT, 40 * KT)
    first, second = plan_landing(state, uh60), plan_landing(state, uh60)
    np.testing.assert_array_equal(first.control_values, second.control_values)
    assert first.time_to_land == second.time_to_land


def test_warm_start_from_a_neighbour_reaches_the_same_answer(uh60):
    planner = get_planner(uh60, PlannerSettings())
    neighbour = planner.plan(initial_state_after_failure(uh60, 480 * FT, 70 * KT))
    state = initial_state_after_failure(uh60, 500 * FT, 75 * KT)
    cold = planner.plan(state)
    warm = planner.plan(state, warm_start=neighbour.warm_start)
    assert warm.solver.warm_started and not cold.solver.warm_started
    assert warm.status == cold.status == "safe"
    assert warm.value == pytest.approx(cold.value, abs=0.02)
    assert warm.time_to_land == pytest.approx(cold.time_to_land, rel=0.05)


def test_more_engine_power_never_hurts(uh60):
    values = [
        plan_landing(initial_state_after_failure(uh60, 150 * FT, 0.0, power_fraction=fraction), uh60).value
        for fraction in (0.0, 0.5, 1.0)
    ]
    assert values[0] >= values[1] - 1e-3 >= values[2] - 2e-3


def test_light_high_inertia_rotor_survives_the_hover_failure():
    oh58 = load_airframe("oh58a_class")
    plan = plan_landing(initial_state_after_failure(oh58, 150 * FT, 0.0), oh58)
    assert plan.status == "safe"


@pytest.mark.parametrize(
    ("state", "message"),
    [
        ([0.0, np.nan, 27.0, 100.0, 0.0, 0.0], "not finite in: forward_speed"),
        ([0.0, 10.0, 27.0, -5.0, 0.0, 0.0], "below the ground"),
        ([0.0, 10.0, 0.0, 100.0, 0.0, 0.0], "rotor speed must be positive"),
        ([0.0, 10.0, 27.0, 100.0, 0.0], "6 components"),
    ],
)
def test_bad_states_are_refused(uh60, state, message):
    with pytest.raises(ValueError, match=message):
        plan_landing(np.array(state), uh60)


def test_warm_start_from_another_nlp_is_refused(uh60, cruise_plan):
    paper_planner = get_planner(uh60, PlannerSettings(method="paper"))
    with pytest.raises(ValueError, match="another NLP"):
        paper_planner.plan(cruise_plan.initial_state, warm_start=cruise_plan.warm_start)
    with pytest.raises(ValueError, match="another NLP"):
        plan_landing(cruise_plan.initial_state, uh60, warm_start=WarmStart(np.zeros(3), np.zeros(3), np.zeros(1)))
