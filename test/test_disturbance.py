"""Disturbance accelerations: the model's error learnt in flight and carried into the next plan.

The NLP, its replay and the delay segment integrate the model plus d = (d_y, d_v, d_Ω); the closed loop
estimates d from each re-planning interval's prediction error. Checked on the real model, the real IPOPT
and the lock-step closed loop; a known disturbance is put into a vehicle by integrating the same disturbed
model, so the estimate has a true value to meet.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from helireach_ros.core.aircraft.model import (
    disturbed_dynamics_function,
    dynamics_function,
    initial_state_after_failure,
)
from helireach_ros.core.estimation.disturbance import (
    DisturbanceSettings,
    DisturbanceTracker,
    observe_interval,
    predict_state,
)
from helireach_ros.core.evidence.replay import replay_plan
from helireach_ros.core.flight.simulation import ControlSchedule, Scenario, SimulatedVehicle, load_scenario
from helireach_ros.core.flight.uncertainty import PerturbedModel
from helireach_ros.core.ocp.transcription.base import DecodedPlan
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings, fly_closed_loop
from helireach_ros.core.robustness.verification import model_vehicle
from helireach_ros.core.units import FT, KT

TRUE_DISTURBANCE = np.array([0.6, -0.2, 0.4])  # m/s², m/s², rad/s²: a heavy, draggy, rotor-fast aircraft
INTERVAL_S = 0.25


@pytest.fixture(scope="module")
def planner(airframe, settings):
    return get_planner(airframe, settings)


@pytest.fixture(scope="module")
def failure_state(airframe):
    return initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()


def test_the_disturbed_model_adds_the_accelerations_and_nothing_else(airframe, failure_state):
    control = np.array([0.005, -0.05])
    nominal = np.asarray(dynamics_function(airframe)(failure_state, control)).reshape(-1)
    disturbed = np.asarray(disturbed_dynamics_function(airframe)(failure_state, control, TRUE_DISTURBANCE)).reshape(-1)
    assert np.allclose(disturbed - nominal, np.concatenate([TRUE_DISTURBANCE, np.zeros(3)]), rtol=0, atol=1e-12)


def test_a_zero_disturbance_is_the_model_as_it_is(planner, failure_state):
    plain = planner.plan(failure_state)
    zero = planner.plan(failure_state, disturbance=np.zeros(3))
    assert zero.status == plain.status == "safe"
    assert zero.value == pytest.approx(plain.value, abs=1e-9)
    assert np.array_equal(zero.disturbance, np.zeros(3))


def test_a_plan_for_a_disturbance_is_replayed_in_the_disturbed_model(planner, airframe, settings, failure_state):
    plan = planner.plan(failure_state, disturbance=TRUE_DISTURBANCE)
    assert plan.solver.success
    assert np.array_equal(plan.disturbance, TRUE_DISTURBANCE)
    decoded = _decoded(plan)
    in_disturbed = replay_plan(airframe, settings, failure_state, decoded, TRUE_DISTURBANCE)
    in_nominal = replay_plan(airframe, settings, failure_state, decoded)
    assert plan.replay.touchdown_state == pytest.approx(in_disturbed.touchdown_state)
    # the same controls in the undisturbed model land elsewhere: the plan's replay is not the nominal one
    assert abs(in_nominal.touchdown_time - in_disturbed.touchdown_time) > 0.05


def _decoded(plan):
    """The plan's decoded NLP solution, to replay it again."""
    return DecodedPlan(
        plan.time_to_land, plan.times, plan.states, plan.control_times, plan.control_values,
        plan.control_interpolation, plan.curve_times, plan.curve_states,
    )  # fmt: skip


def _true_flight(airframe, state, controls_at, disturbance):
    """Where a vehicle whose dynamics carry ``disturbance`` is after one interval (the truth to estimate)."""
    return predict_state(airframe, state, controls_at, 0.0, INTERVAL_S, disturbance)


def test_one_interval_with_gain_one_recovers_a_constant_disturbance(airframe, failure_state):
    def controls_at(time):
        return np.array([0.004 + 0.002 * time, -0.05 - 0.1 * time])

    measured = _true_flight(airframe, failure_state, controls_at, TRUE_DISTURBANCE)
    estimate = observe_interval(
        airframe, np.zeros(3), failure_state, measured, controls_at, 0.0, INTERVAL_S, DisturbanceSettings(gain=1.0)
    ).disturbance
    # one step is ~5 % short (the disturbance changes y, and the drag and inflow damp it within the interval);
    # repeated intervals remove that (the next test), as the fixed point is the true d
    assert estimate == pytest.approx(TRUE_DISTURBANCE, rel=0.1)


def test_a_smaller_gain_converges_over_intervals_and_never_overshoots(airframe, failure_state):
    def controls_at(time):
        return np.array([0.005, -0.05])

    settings = DisturbanceSettings(gain=0.5)
    estimate, state, errors = np.zeros(3), failure_state, []
    for _ in range(8):
        measured = _true_flight(airframe, state, controls_at, TRUE_DISTURBANCE)
        estimate = observe_interval(
            airframe, estimate, state, measured, controls_at, 0.0, INTERVAL_S, settings
        ).disturbance
        errors.append(float(np.max(np.abs(estimate - TRUE_DISTURBANCE))))
        assert np.all(estimate / TRUE_DISTURBANCE <= 1.05)  # approaches from zero, never beyond the truth
        state = measured
    assert errors[-1] < 0.02 < errors[0]
    assert all(later <= earlier + 1e-9 for earlier, later in itertools.pairwise(errors))


def test_a_bad_interval_leaves_the_estimate_alone(airframe, failure_state):
    def controls_at(time):
        return np.array([0.005, -0.05])

    before = np.array([0.1, 0.0, 0.2])
    broken = failure_state.copy()
    broken[2] = math.nan
    assert np.array_equal(
        observe_interval(airframe, before, failure_state, broken, controls_at, 0.0, INTERVAL_S).disturbance, before
    )
    with pytest.raises(ValueError, match="duration"):
        observe_interval(airframe, before, failure_state, failure_state, controls_at, 0.0, 0.0)
    with pytest.raises(ValueError, match="gain"):
        DisturbanceSettings(gain=0.0)


@pytest.mark.parametrize("disturbance", [[math.nan, 0, 0], [0, 0, 50.0], [0.1, 0.2]])
def test_the_planner_refuses_a_nonsense_disturbance(planner, failure_state, disturbance):
    with pytest.raises(ValueError, match="disturbance"):
        planner.plan(failure_state, disturbance=disturbance)


HEAVIER = PerturbedModel({"gross_weight": 0.03}, label="3 % heavier than the model")


def test_the_closed_loop_lands_an_aircraft_heavier_than_its_model_only_when_it_learns_the_disturbance(
    planner, airframe, settings
):
    """3 % heavier than the model: without d every re-plan expects the sink the model predicts and the vehicle
    touches down at 8.3 ft/s (limit 8); learning d, it lands within limits. (The default set's heavy corner, +5 %
    weight with +10 % rotor inertia, was the case while every plan could ride the rotor ceiling through its first
    interval: without d it overspeeded the rotor; it now lands either way.)"""
    scenario = Scenario(name="heavier", height=500 * FT, forward_speed=75 * KT)
    results = {}
    for learn in (False, True):
        vehicle = model_vehicle(scenario, HEAVIER, airframe, settings)
        results[learn] = fly_closed_loop(vehicle, planner, ClosedLoopSettings(latency=0.0, estimate_disturbance=learn))
    assert not results[False].touchdown.within_limits
    assert "exceeds the limits" in results[False].touchdown.reason
    assert results[True].touchdown.within_limits, results[True].touchdown.reason
    # heavier than the model: it sinks faster than predicted (d_y > 0)
    assert results[True].final_disturbance[0] > 0.1, results[True].final_disturbance


def test_the_tracker_learns_across_ticks_and_ignores_repeated_or_old_stamps(airframe, failure_state):
    def controls_at(time):
        return np.array([0.005, -0.05])

    tracker = DisturbanceTracker(airframe, DisturbanceSettings(gain=1.0))
    assert np.array_equal(tracker.update(10.0, failure_state, controls_at), np.zeros(3))  # starts the interval
    later = predict_state(airframe, failure_state, controls_at, 10.0, INTERVAL_S, TRUE_DISTURBANCE)
    learnt = tracker.update(10.0 + INTERVAL_S, later, controls_at)
    assert learnt == pytest.approx(TRUE_DISTURBANCE, rel=0.1)
    assert np.array_equal(tracker.update(10.0 + INTERVAL_S, failure_state, controls_at), learnt)  # same stamp
    assert np.array_equal(tracker.update(10.0, failure_state, controls_at), learnt)  # older stamp
    tracker.reset()
    assert np.array_equal(tracker.estimate, np.zeros(3))


def test_the_observer_filters_the_state_and_still_learns_the_disturbance(airframe, failure_state):
    """A vehicle with a known disturbance, measured with the uncertainty set's sensor noise every 0.25 s for 4 s:
    the α–β observer (state gain 0.5) must give a state closer to the truth than the measurement (what the plain
    filter, state gain 1, plans from) and still learn the disturbance (its mean over the last 2 s and 6 noise
    seeds within 25 % of the true d_y and d_Ω; d_v is small beside its noise)."""
    noise_sigma = np.array([0.1 * FT, 0.2 * KT, 0.05, 0.3 * FT, 0.0])  # y, v, Ω, h, z: config/uncertainty.yaml

    def controls_at(time):
        return np.array([0.0055, 0.02])

    truth = [failure_state[:6].copy()]
    for _ in range(16):
        truth.append(_true_flight(airframe, truth[-1], controls_at, TRUE_DISTURBANCE))
    state_errors: dict[float, list[np.ndarray]] = {1.0: [], 0.5: []}
    learnt: list[np.ndarray] = []
    for state_gain, seed in itertools.product(state_errors, range(6)):
        rng = np.random.default_rng(seed)
        tracker = DisturbanceTracker(airframe, DisturbanceSettings(gain=0.3, state_gain=state_gain))
        for tick, true_state in enumerate(truth):
            measured = true_state.copy()
            measured[:5] += rng.normal(0.0, noise_sigma)
            estimate = tracker.update(tick * INTERVAL_S, measured, controls_at)
            if tick >= 8:  # past the start-up transient
                state_errors[state_gain].append((tracker.state[:3] - true_state[:3]) / noise_sigma[:3])
                if state_gain == 0.5:
                    learnt.append(estimate)
    plain, observed = (np.sqrt(np.mean(np.square(state_errors[gain]), axis=0)) for gain in (1.0, 0.5))
    assert np.all(observed < 0.9 * plain), (observed, plain)  # in noise σ; the plain filter's is ~1
    mean = np.mean(learnt, axis=0)
    assert mean[[0, 2]] == pytest.approx(TRUE_DISTURBANCE[[0, 2]], rel=0.25), mean


def test_an_unknown_5_percent_weight_is_learnt_in_flight_and_brings_the_touchdown_to_the_limits(airframe, settings):
    """The issue's case with the demo's sensor noise: +5 % weight the planner is not told and does not estimate
    before the failure. The disturbance learnt in the descent says it sinks faster than the model (d_y > 0) and
    takes the touchdown from well outside the limits (J ≈ +0.30 without it) to their edge (J ≈ +0.02: 7.5 ft/s,
    6.1 kt). Whether it then lands is a knife edge (2 of 6 noise seeds; 3 of 6 before the upper rotor back-off
    change), so landing it is asserted where the weight is also estimated from the trim before the failure
    (test_estimation)."""
    heavy = dataclasses.replace(load_scenario("demo_500ft_75kt"), parameter_mismatch={"gross_weight": 0.05})

    def fly(estimate: bool):
        loop = ClosedLoopSettings(latency=0.1, estimate_disturbance=estimate)
        return fly_closed_loop(SimulatedVehicle(heavy, airframe, settings), get_planner(airframe, settings), loop)

    learning, blind = fly(True), fly(False)
    assert learning.planned_gross_weight == airframe.gross_weight
    assert learning.final_disturbance[0] > 0.0  # it sinks faster than the model says
    assert not blind.touchdown.within_limits and blind.touchdown.value > 0.0
    assert learning.touchdown.value < 0.25 * blind.touchdown.value, (learning.touchdown, blind.touchdown)


def test_the_vehicle_reports_the_controls_it_flew_not_those_it_flies_now(airframe, settings):
    """The estimate needs what was flown: a plan that arrives later is indexed from its earlier measurement."""
    vehicle = SimulatedVehicle(Scenario(name="two plans", height=500 * FT, forward_speed=75 * KT), airframe, settings)
    vehicle.advance(vehicle.scenario.failure_time)
    first = ControlSchedule(vehicle.time, np.array([0.0, 5.0]), np.array([[0.004, 0.004], [-0.05, -0.05]]))
    vehicle.follow(first)
    vehicle.advance(0.5)
    measured_at = vehicle.time - 0.2  # the second plan starts at a measurement 0.2 s before it arrives
    second = ControlSchedule(measured_at, np.array([0.0, 5.0]), np.array([[0.008, 0.008], [-0.2, -0.2]]))
    vehicle.follow(second)
    vehicle.advance(0.25)
    between = measured_at + 0.1  # flown under the first plan; the second is the one followed now
    assert np.allclose(vehicle.flown_controls(between), first.at(between))
    assert np.allclose(vehicle.controls(between), second.at(between))
    assert np.allclose(vehicle.flown_controls(vehicle.time), second.at(vehicle.time))
    assert np.allclose(vehicle.flown_controls(vehicle.scenario.failure_time - 1.0), vehicle.controls(0.0))  # trim


SENSOR_NOISE_SIGMA = np.array([0.1 * FT, 0.2 * KT, 0.05, 0.3 * FT, 0.0])  # y, v, Ω, h, z: config/uncertainty.yaml


def _steady_truth(airframe, failure_state, controls_at, intervals):
    """The true states every INTERVAL_S of a vehicle carrying TRUE_DISTURBANCE, flying ``controls_at``."""
    truth = [failure_state[:6].copy()]
    for _ in range(intervals):
        truth.append(_true_flight(airframe, truth[-1], controls_at, TRUE_DISTURBANCE))
    return truth


def _tracked_errors(airframe, truth, controls_at, settings, seeds, after, noise_sigma=SENSOR_NOISE_SIGMA):
    """d̂ − d at every tick from ``after`` on, for each noise seed (the truth measured with Gaussian noise)."""
    errors = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        tracker = DisturbanceTracker(airframe, settings)
        for tick, true_state in enumerate(truth):
            measured = true_state.copy()
            measured[:5] += rng.normal(0.0, noise_sigma)
            estimate = tracker.update(tick * INTERVAL_S, measured, controls_at)
            if tick >= after:
                errors.append(estimate - TRUE_DISTURBANCE)
    return np.asarray(errors)


def test_the_windowed_estimate_passes_on_less_sensor_noise_by_the_predicted_factor(airframe, failure_state):
    """A constant true disturbance measured with the uncertainty set's noise every 0.25 s for 6 s, 12 noise seeds.
    The prediction starts from the raw measurement, so the noise in each interval's error is n_{k+1} − n_k: the
    mean of the last W intervals keeps σ√2 / (W Δt), the g = 0.3 filter g √(2 / (2 − g)) σ / Δt; at W = 8 the
    window's rms error is predicted 0.3 · 8 / √1.7 ≈ 1.84 times smaller on every channel (measured 1.6-2.0 over
    four seed sets) and the estimate unbiased."""

    def controls_at(time):
        return np.array([0.0055, 0.02])

    window = 8
    truth = _steady_truth(airframe, failure_state, controls_at, 24)
    seeds = range(12)
    filtered = _tracked_errors(airframe, truth, controls_at, DisturbanceSettings(gain=0.3), seeds, after=12)
    windowed = _tracked_errors(airframe, truth, controls_at, DisturbanceSettings(window=window), seeds, after=12)
    filter_rms, window_rms = (np.sqrt(np.mean(np.square(errors), axis=0)) for errors in (filtered, windowed))
    predicted_ratio = 0.3 * window / math.sqrt(2.0 - 0.3)
    assert np.all(filter_rms / window_rms > 0.75 * predicted_ratio), (filter_rms, window_rms)
    assert np.all(filter_rms / window_rms < 1.3 * predicted_ratio), (filter_rms, window_rms)
    telescoped = math.sqrt(2.0) * SENSOR_NOISE_SIGMA[:3] / (window * INTERVAL_S)
    assert np.all((window_rms > 0.75 * telescoped) & (window_rms < 1.35 * telescoped)), (window_rms, telescoped)
    assert np.all(np.abs(np.mean(windowed, axis=0)) < 0.25 * telescoped)  # no bias beside its noise


def test_the_windowed_estimate_converges_to_the_true_disturbance_without_noise(airframe, failure_state):
    """Exact measurements: the prediction is made with the current d̂ and d̂ is added back, so the ~5 % one
    interval falls short shrinks with d − d̂ and the window's mean reaches the true d once its start-up samples
    have left it; a window of one is the filter of gain 1."""

    def controls_at(time):
        return np.array([0.0055, 0.02])

    truth = _steady_truth(airframe, failure_state, controls_at, 16)
    errors = _tracked_errors(airframe, truth, controls_at, DisturbanceSettings(window=8), [0], 1, np.zeros(5))
    assert np.max(np.abs(errors[0])) < 0.1 * np.max(np.abs(TRUE_DISTURBANCE))  # the first sample: ~5 % short
    assert np.max(np.abs(errors[-1])) < 1e-3, errors[-1]
    one, gain_one = (
        _tracked_errors(airframe, truth[:6], controls_at, settings, [3], 1)
        for settings in (DisturbanceSettings(window=1), DisturbanceSettings(gain=1.0))
    )
    assert np.allclose(one, gain_one, rtol=0.0, atol=1e-12)


def test_the_windowed_tracker_ignores_old_stamps_and_bad_intervals(airframe, failure_state):
    def controls_at(time):
        return np.array([0.005, -0.05])

    tracker = DisturbanceTracker(airframe, DisturbanceSettings(window=4))
    tracker.update(10.0, failure_state, controls_at)
    later = predict_state(airframe, failure_state, controls_at, 10.0, INTERVAL_S, TRUE_DISTURBANCE)
    learnt = tracker.update(10.0 + INTERVAL_S, later, controls_at)
    assert learnt == pytest.approx(TRUE_DISTURBANCE, rel=0.1)
    assert np.array_equal(tracker.update(10.0 + INTERVAL_S, failure_state, controls_at), learnt)  # same stamp
    assert np.array_equal(tracker.update(10.0, failure_state, controls_at), learnt)  # older stamp
    broken = later.copy()
    broken[2] = math.nan
    assert np.array_equal(tracker.update(10.0 + 2 * INTERVAL_S, broken, controls_at), learnt)  # nothing learnt
    assert np.array_equal(tracker.update(10.0 + 3 * INTERVAL_S, later, controls_at), learnt)  # nor from it
    after = predict_state(airframe, later, controls_at, 10.0 + 3 * INTERVAL_S, INTERVAL_S, TRUE_DISTURBANCE)
    assert tracker.update(10.0 + 4 * INTERVAL_S, after, controls_at) == pytest.approx(TRUE_DISTURBANCE, rel=0.1)
    tracker.reset()
    assert np.array_equal(tracker.estimate, np.zeros(3))
    # after a reset the window is empty: an interval the model predicts exactly gives d̂ = 0, not a mean with d
    tracker.update(0.0, failure_state, controls_at)
    exact = predict_state(airframe, failure_state, controls_at, 0.0, INTERVAL_S, np.zeros(3))
    assert np.allclose(tracker.update(INTERVAL_S, exact, controls_at), 0.0, rtol=0.0, atol=1e-9)


@pytest.mark.parametrize("window", [-1, 2.5, True, "8", math.nan])
def test_an_invalid_window_is_refused(window):
    with pytest.raises(ValueError, match="window"):
        DisturbanceSettings(window=window)


def test_no_window_is_the_filter_and_the_windowed_step_needs_the_tracker(airframe, failure_state):
    def controls_at(time):
        return np.array([0.005, -0.05])

    assert not DisturbanceSettings().windowed and not DisturbanceSettings(window=0).windowed
    assert DisturbanceSettings(window=3).windowed
    later = predict_state(airframe, failure_state, controls_at, 0.0, INTERVAL_S, TRUE_DISTURBANCE)
    estimates = []
    for settings in (DisturbanceSettings(), DisturbanceSettings(window=0)):
        tracker = DisturbanceTracker(airframe, settings)
        tracker.update(0.0, failure_state, controls_at)
        estimates.append(tracker.update(INTERVAL_S, later, controls_at))
    assert np.array_equal(*estimates)
    with pytest.raises(ValueError, match="window"):
        observe_interval(
            airframe, np.zeros(3), failure_state, later, controls_at, 0.0, INTERVAL_S, DisturbanceSettings(window=3)
        )
