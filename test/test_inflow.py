"""The rotor model: textbook limits of the induced velocity, ground effect, the paper's rotor, and the airframe's
``rotor_model`` section."""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest

from helireach_ros.core.aircraft import inflow
from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe, parse_airframe
from helireach_ros.core.aircraft.inflow import PAPER_ROTOR_MODEL, InflowModel, RotorModel
from helireach_ros.core.aircraft.model import dynamics_function, steady_autorotation, trim_level_flight
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import LandingPlanner
from helireach_ros.core.units import FT, KT


def _momentum(airframe):
    return airframe.with_rotor_model(
        dataclasses.replace(airframe.rotor_model, inflow=InflowModel.MOMENTUM, ground_effect=True)
    )


def _glauert_root(edgewise: float, axial: float) -> float:
    """The momentum equation's root by bisection (where it is unique: edgewise² > axial²/8)."""
    low, high = 0.0, 50.0
    for _ in range(200):
        middle = 0.5 * (low + high)
        if middle * math.hypot(edgewise, axial + middle) < 1.0:
            low = middle
        else:
            high = middle
    return low


def test_hover_inflow_is_the_papers_hover_value():
    assert float(inflow.inflow_ratio(0.0, 0.0)) == pytest.approx(1.0, abs=1e-6)
    assert float(inflow.axial_inflow_ratio(0.0)) == pytest.approx(1.0, abs=1e-6)
    velocity = inflow.induced_velocity(
        RotorModel(ground_effect=False), hover_induced_velocity=11.8, edgewise_speed=0.0, axial_speed=0.0,
        height=100.0, rotor_radius=8.0,
    )  # fmt: skip
    assert float(velocity) == pytest.approx(11.8, rel=1e-6)


@pytest.mark.parametrize("climb_ratio", [0.5, 1.0, 3.0])
def test_climb_follows_momentum_theory(climb_ratio):
    expected = -climb_ratio / 2.0 + math.sqrt(climb_ratio**2 / 4.0 + 1.0)
    assert float(inflow.inflow_ratio(0.0, climb_ratio)) == pytest.approx(expected, rel=1e-6)


def test_high_speed_limit_is_thrust_over_two_rho_a_v():
    """ν → T / (2ρAV) = v_h² / V at high speed (Glauert)."""
    hover, speed = 11.8, 60.0
    velocity = inflow.induced_velocity(
        RotorModel(ground_effect=False), hover_induced_velocity=hover, edgewise_speed=speed, axial_speed=0.0,
        height=100.0, rotor_radius=8.0,
    )  # fmt: skip
    assert float(velocity) == pytest.approx(hover**2 / speed, rel=5e-3)


@pytest.mark.parametrize(("edgewise", "axial"), [(1.5, 0.3), (2.0, -0.7), (3.0, -1.5), (4.0, 0.0), (8.0, -4.0)])
def test_forward_flight_is_glauerts_root(edgewise, axial):
    # the raised edgewise speed in descent (uniqueness) moves the root by < 2 % where the vortex ring has gone
    assert float(inflow.inflow_ratio(edgewise, axial)) == pytest.approx(_glauert_root(edgewise, axial), rel=0.02)


def test_ideal_vertical_autorotation_near_minus_1_7_hover_induced_velocities():
    """Leishman (2006): the ideal autorotation (x + ν̂ = 0) lies near V_c / v_h ≈ −1.71."""
    ratios = np.linspace(-2.2, -1.3, 9001)
    total = ratios + np.array([float(inflow.inflow_ratio(0.0, x)) for x in ratios])
    crossing = ratios[np.argmin(np.abs(total))]
    assert abs(total).min() < 1e-3
    assert -1.8 <= crossing <= -1.65


def test_windmill_brake_in_fast_axial_descent():
    for axial in (-2.5, -4.0):
        expected = -axial / 2.0 - math.sqrt(axial**2 / 4.0 - 1.0)
        assert float(inflow.inflow_ratio(0.0, axial)) == pytest.approx(expected, rel=1e-3)


def test_inflow_and_its_derivatives_are_finite_everywhere():
    edgewise, axial = ca.SX.sym("mu"), ca.SX.sym("x")
    ratio = inflow.inflow_ratio(edgewise, axial)
    arguments = ca.vertcat(edgewise, axial)
    function = ca.Function("f", [arguments], [ratio, ca.jacobian(ratio, arguments), ca.hessian(ratio, arguments)[0]])
    for mu in [0.0, 1e-3, 0.5, 1.0, 1.7, 10.0, 1e3]:
        for x in [-1e3, -20.0, -2.05, -2.0, -1.74, -1.0, -0.01, 0.0, 0.01, 1.0, 1e3]:
            values = [np.asarray(value) for value in function(ca.DM([mu, x]))]
            assert all(np.all(np.isfinite(value)) for value in values), (mu, x)
            assert values[0].item() > 0.0


def test_ground_effect_cheeseman_bennett():
    """T_IGE / T_OGE = 1 / (1 − (R/4z)²) at equal power: 4/3 at z/R = 0.5, 64/63 at z/R = 2, none far up."""
    assert 1.0 / float(inflow.ground_effect_factor(0.5)) == pytest.approx(4.0 / 3.0, rel=2e-3)
    assert 1.0 / float(inflow.ground_effect_factor(2.0)) == pytest.approx(64.0 / 63.0, rel=1e-4)
    assert float(inflow.ground_effect_factor(20.0)) == pytest.approx(1.0, abs=1e-3)
    # never stronger than at the floor height, and weaker with speed
    floor = inflow.GROUND_EFFECT_MIN_HEIGHT_RATIO
    assert float(inflow.ground_effect_factor(0.1)) >= 1.0 - (1.0 / (4.0 * floor)) ** 2 - 1e-4
    assert float(inflow.ground_effect_factor(0.6, 2.0)) > float(inflow.ground_effect_factor(0.6, 0.0))


def test_paper_rotor_is_the_papers_equation():
    airframe = load_airframe("uh60a_class").paper_model()
    rng = np.random.default_rng(3)
    function = dynamics_function(airframe)
    for _ in range(20):
        y, v, omega, h = rng.uniform(-5, 20), rng.uniform(0, 60), rng.uniform(20, 31), rng.uniform(0, 200)
        thrust, pitch = rng.uniform(0.001, 0.012), rng.uniform(-0.6, 0.6)
        tip = omega * airframe.rotor_radius
        # the model's guards: smooth_positive(Ω, 0.05 Ω₀) in 1/Ω, smooth_positive(C_T, 1e-7) under the root
        guarded = 0.5 * (omega + math.hypot(omega, 0.05 * airframe.nominal_rotor_speed))
        induced = tip * math.sqrt(0.5 * (thrust + math.hypot(thrust, 1e-7)) / 2.0)
        power_coefficient = airframe.rotor_solidity * airframe.blade_drag_coefficient / 8.0 + thrust * (
            v * math.sin(pitch) - y * math.cos(pitch) + induced
        ) / (guarded * airframe.rotor_radius)
        power = airframe.air_density * airframe.disk_area * tip**3 * power_coefficient
        derivative = np.asarray(function([y, v, omega, h, 0.0, 0.0], [thrust, pitch])).reshape(-1)
        expected = -power / airframe.rotor_power_efficiency / (airframe.rotor_inertia * guarded)
        assert derivative[2] == pytest.approx(expected, rel=1e-9)


def test_momentum_rotor_has_a_power_bucket_and_a_minimum_descent_speed():
    """The shape every helicopter has (validation anchors): minimum power well below hover power at 50-90 kt, and a
    steady autorotation slowest there and much slower than vertically."""
    airframe = _momentum(load_airframe("uh60a_class"))
    speeds_kt = np.arange(0.0, 125.0, 5.0)
    power = np.array([trim_level_flight(airframe, speed * KT).power for speed in speeds_kt])
    descent = np.array([steady_autorotation(airframe, speed * KT)[0] for speed in speeds_kt])
    assert 50.0 <= speeds_kt[np.argmin(power)] <= 90.0
    assert power.min() <= 0.7 * power[0]
    assert 50.0 <= speeds_kt[np.argmin(descent)] <= 90.0
    assert descent.min() <= 0.7 * descent[0]
    # the paper's rotor has neither (what the momentum model fixes)
    paper = airframe.paper_model()
    assert trim_level_flight(paper, 80 * KT).power > trim_level_flight(paper, 0.0).power
    assert steady_autorotation(paper, 80 * KT)[0] > steady_autorotation(paper, 0.0)[0]


def test_ground_effect_lowers_hover_power_near_the_ground():
    airframe = _momentum(load_airframe("uh60a_class"))
    out_of_ground_effect = trim_level_flight(airframe, 0.0).power
    on_the_ground = trim_level_flight(airframe, 0.0, height=0.0).power
    assert 0.6 * out_of_ground_effect < on_the_ground < 0.9 * out_of_ground_effect
    assert trim_level_flight(airframe, 0.0, height=3 * airframe.rotor_radius).power == pytest.approx(
        out_of_ground_effect, rel=0.01
    )


def test_paper_method_uses_the_papers_rotor_whatever_the_airframe_says():
    airframe = _momentum(load_airframe("uh60a_class"))
    planner = LandingPlanner(airframe, load_settings(method="paper"))
    assert planner.airframe.rotor_model.is_paper
    verified = LandingPlanner(airframe, load_settings(method="verified"))
    assert verified.airframe.rotor_model.inflow is InflowModel.MOMENTUM


def test_the_papers_airframe_is_written_as_before_the_rotor_model_existed():
    """Its dictionary (and so its digest, which envelopes carry) has no rotor model and no reproduction section."""
    airframe = load_airframe("uh60a_class")
    paper = airframe.paper_model()
    assert paper.rotor_model.is_paper
    assert "rotor_model" not in paper.as_dict() and "paper_reproduction" not in paper.as_dict()
    assert airframe.digest() != paper.digest() != _momentum(paper).digest()


def _document(rotor_model):
    document = {"name": "t", "parameters": {}, "limits": {}}
    base = load_airframe("uh60a_class")
    for key in ("gross_weight", "rotor_radius", "rotor_solidity", "nominal_rotor_speed", "blade_drag_coefficient",
                "rotor_inertia", "horizontal_drag_area", "vertical_drag_area", "rotor_power_efficiency",
                "engine_time_constant", "density_altitude", "gravity"):  # fmt: skip
        unit = {"gross_weight": "N", "rotor_radius": "m", "nominal_rotor_speed": "rad/s", "rotor_inertia": "kg*m^2",
                "horizontal_drag_area": "m^2", "vertical_drag_area": "m^2", "engine_time_constant": "s",
                "density_altitude": "m", "gravity": "m/s^2"}.get(key, "-")  # fmt: skip
        document["parameters"][key] = {"value": getattr(base, key), "unit": unit, "source": "test"}
    for key in dataclasses.asdict(base.limits):
        unit = "rad" if "pitch" in key else "-" if ("ratio" in key or "coefficient" in key) else (
            "m/s" if ("rate" in key or "speed" in key) else "m")
        document["limits"][key] = {"value": getattr(base.limits, key), "unit": unit, "source": "test"}
    if rotor_model is not None:
        document["rotor_model"] = rotor_model
    return document


def test_rotor_model_section_is_parsed_and_checked():
    numbers = {
        "induced_power_factor": {"value": 1.1, "unit": "-", "source": "test"},
        "profile_power_speed_factor": {"value": 4.7, "unit": "-", "source": "test"},
        "hub_height": {"value": 10.0, "unit": "ft", "source": "test"},
    }
    airframe = parse_airframe(_document({"inflow": "momentum", "ground_effect": "on", **numbers}))
    assert airframe.rotor_model == RotorModel(InflowModel.MOMENTUM, True, 1.1, 4.7, 10.0 * FT)
    assert parse_airframe(_document(None)).rotor_model == PAPER_ROTOR_MODEL
    with pytest.raises(ConfigError, match=r"inflow must be momentum \| paper_hover"):
        parse_airframe(_document({"inflow": "uniform", **numbers}))
    for wrong in ("maybe", ["on"], 1):
        with pytest.raises(ConfigError, match=r"ground_effect must be on \| off"):
            parse_airframe(_document({"ground_effect": wrong, **numbers}))
    with pytest.raises(ConfigError, match=r"missing key.*hub_height"):
        parse_airframe(_document({"inflow": "momentum", "ground_effect": True,
                                  **{k: v for k, v in numbers.items() if k != "hub_height"}}))  # fmt: skip
    with pytest.raises(ConfigError, match="unknown key"):
        parse_airframe(_document({"inflow": "momentum", "ground_effect": "off", "blade_twist": 1, **numbers}))
    with pytest.raises(ConfigError, match="hub_height"):
        parse_airframe(_document({"ground_effect": "on", **numbers, "hub_height": {"value": 90, "unit": "m",
                                                                                    "source": "typo"}}))  # fmt: skip


@pytest.mark.parametrize("name", ["uh60a_class", "oh58a_class", "s300c_class"])
def test_shipped_airframes_give_the_momentum_rotor_a_sourced_hub_height(name):
    airframe = load_airframe(name)
    sources = dict(airframe.sources)
    assert airframe.rotor_model.hub_height is not None and sources["rotor_model.hub_height"]
    momentum = airframe.with_rotor_model_choice("momentum")
    assert momentum.rotor_model.inflow is InflowModel.MOMENTUM and momentum.rotor_model.ground_effect
    with pytest.raises(ConfigError, match="rotor model must be one of"):
        airframe.with_rotor_model_choice("uniform")


def test_the_roots_as_inputs_give_the_closed_form_dynamics():
    """An NLP may carry the momentum roots as variables (model.implicit_inflow_functions): at the Newton roots the
    residuals vanish and the dynamics equal the closed form; off them the residuals do not."""
    from helireach_ros.core.aircraft.model import disturbed_dynamics_function, implicit_inflow_functions

    airframe = _momentum(load_airframe("oh58a_class"))
    dynamics, residuals, roots = implicit_inflow_functions(airframe)
    closed_form = disturbed_dynamics_function(airframe)
    rng = np.random.default_rng(5)
    for _ in range(20):
        state = [rng.uniform(-5, 25), rng.uniform(0, 60), rng.uniform(30, 42), rng.uniform(0, 100), 0.0, 0.0]
        control = [rng.uniform(0.0005, 0.0058), rng.uniform(-0.4, 0.4)]
        found = np.asarray(roots(state, control)).reshape(-1)
        assert np.max(np.abs(np.asarray(residuals(state, control, found)))) < 1e-3
        assert np.asarray(residuals(state, control, 1.2 * found)).max() > 1e-3
        expected = np.asarray(closed_form(state, control, np.zeros(3))).reshape(-1)
        actual = np.asarray(dynamics(state, control, np.zeros(3), found)).reshape(-1)
        np.testing.assert_allclose(actual, expected, rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match="paper's rotor"):
        implicit_inflow_functions(airframe.paper_model())
