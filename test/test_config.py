"""Airframe and planner configuration: loading, SI conversion, and errors that name the key."""

import copy
import math

import pytest
import yaml

from helireach_ros.core.aircraft.airframe import ConfigError, isa_density, load_airframe, parse_airframe
from helireach_ros.core.ocp.settings import PlannerSettings, load_settings
from helireach_ros.core.resources import config_path


@pytest.fixture(scope="module")
def uh60_document():
    return yaml.safe_load(config_path("airframes/uh60a_class.yaml").read_text())


def test_shipped_airframes_load_in_si():
    uh60 = load_airframe("uh60a_class")
    assert uh60.rotor_radius == pytest.approx(26.83 * 0.3048)
    assert uh60.gross_weight == pytest.approx(16000 * 4.4482216152605)
    assert uh60.limits.max_forward_speed == pytest.approx(15 * 1852 / 3600)
    assert uh60.rotor_model.inflow.value == "momentum" and uh60.rotor_model.ground_effect
    assert uh60.limits.max_pitch_angle == pytest.approx(math.radians(40))
    assert uh60.air_density == pytest.approx(1.225)
    oh58 = load_airframe("oh58a_class")
    assert oh58.nominal_rotor_speed == pytest.approx(354 * 2 * math.pi / 60)
    assert oh58.digest() != uh60.digest()
    assert all(source for _, source in uh60.sources)


def test_every_number_has_unit_and_source(uh60_document):
    for section in ("parameters", "limits"):
        for key, entry in uh60_document[section].items():
            assert {"value", "unit", "source"} <= set(entry), key


def _broken(document, path, value):
    broken = copy.deepcopy(document)
    target = broken
    for key in path[:-1]:
        target = target[key]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return broken


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (("parameters", "rotor_radius"), KeyError, "missing key.*rotor_radius"),
        (("parameters", "rotor_diameter"), {"value": 1, "unit": "m", "source": "x"}, "unknown key.*rotor_diameter"),
        (("parameters", "rotor_radius", "unit"), "kt", "rotor_radius.*measures speed, expected length"),
        (("parameters", "rotor_radius", "unit"), "furlong", "rotor_radius.*unknown unit"),
        (("parameters", "rotor_inertia", "value"), -7000.0, "rotor_inertia.*outside the physical range"),
        (("parameters", "gross_weight", "value"), "heavy", "gross_weight.value must be a number"),
        (("parameters", "blade_drag_coefficient", "source"), " ", "blade_drag_coefficient.source is empty"),
        (("limits", "max_pitch_angle", "value"), 400.0, "max_pitch_angle.*outside the physical range"),
        (("limits",), KeyError, "missing top-level key: limits"),
        (("margin_scales", "rotor_floor", "value"), 0.0, "rotor_floor.*outside the physical range"),
        (("margin_scales", "touchdown_pitch"), KeyError, "missing key.*touchdown_pitch"),
        (("colour",), "red", "unknown top-level key.*colour"),
    ],
)
def test_bad_airframes_are_rejected_naming_the_key(uh60_document, path, value, message):
    with pytest.raises(ConfigError, match=message):
        parse_airframe(_broken(uh60_document, path, value), where="test.yaml: ")


def test_the_papers_reproduction_keeps_the_papers_numbers(uh60_document, tmp_path):
    """``--method paper`` flies the paper's airframe: its rotor, 6 kt at touchdown and the rotor inertia the
    reproduction was measured with; the result is the airframe the file described before its credible model (the
    same digest, so its envelopes stay valid), while ``--rotor-model paper`` swaps only the rotor."""
    uh60 = load_airframe("uh60a_class")
    paper = uh60.paper_model()
    assert paper.rotor_model.is_paper and not paper.paper_reproduction
    assert paper.limits.max_forward_speed == pytest.approx(6 * 1852 / 3600)
    assert paper.rotor_inertia == pytest.approx(7000 * 1.3558179483314004)
    assert uh60.rotor_inertia == pytest.approx(8040 * 1.3558179483314004)
    without = {key: value for key, value in uh60_document.items() if key != "paper_reproduction"}
    without["parameters"] = {**without["parameters"], "rotor_inertia": uh60_document["paper_reproduction"][
        "parameters"]["rotor_inertia"]}  # fmt: skip
    without["limits"] = {**without["limits"], "max_forward_speed": uh60_document["paper_reproduction"]["limits"][
        "max_forward_speed"]}  # fmt: skip
    assert paper.digest() == parse_airframe(without).paper_model().digest()
    rotor_only = uh60.with_rotor_model_choice("paper")
    assert rotor_only.rotor_model.is_paper and rotor_only.limits == uh60.limits
    assert rotor_only.rotor_inertia == uh60.rotor_inertia
    broken = copy.deepcopy(uh60_document)
    broken["paper_reproduction"]["limits"]["max_rotor_rpm"] = {"value": 1, "unit": "-", "source": "x"}
    with pytest.raises(ConfigError, match=r"unknown key.*max_rotor_rpm"):
        parse_airframe(broken, where="test.yaml: ")


def test_margin_scales_are_configuration_that_leaves_the_aircraft_alone(uh60_document):
    """The reach-avoid margins' units come from the file (SI on load, a source each); the defaults written out give
    the airframe of a file without the section, digest included, since they choose among plans, not the aircraft."""
    uh60 = load_airframe("uh60a_class")
    assert uh60.margin_scales.touchdown_pitch == pytest.approx(math.radians(8.5))
    assert dict(uh60.sources)["margin_scales.rotor_floor"].startswith("helireach choice")
    without = {key: value for key, value in uh60_document.items() if key != "margin_scales"}
    assert parse_airframe(without).digest() == uh60.digest()
    steeper = parse_airframe(_broken(uh60_document, ("margin_scales", "rotor_floor", "value"), 0.05))
    assert steeper.margin_scales.rotor_floor == pytest.approx(0.05) and steeper.digest() != uh60.digest()


def test_rotor_speed_limits_must_leave_a_band(uh60_document):
    equal = _broken(_broken(uh60_document, ("limits", "min_rotor_speed_ratio", "value"), 1.0),
                    ("limits", "max_rotor_speed_ratio", "value"), 1.0)  # fmt: skip
    with pytest.raises(ConfigError, match="min_rotor_speed_ratio must be below"):
        parse_airframe(equal)


def test_unknown_airframe_and_bad_yaml_are_clear_errors(tmp_path):
    with pytest.raises(ConfigError, match="no_such_airframe"):
        load_airframe("no_such_airframe")
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_airframe(broken)


def test_conditions_override_weight_and_density_altitude():
    uh60 = load_airframe("uh60a_class")
    high_hot = uh60.with_conditions(gross_weight=80000.0, density_altitude=1500.0)
    assert high_hot.gross_weight == 80000.0
    assert high_hot.air_density == pytest.approx(isa_density(1500.0))
    assert high_hot.air_density < uh60.air_density
    assert high_hot.digest() != uh60.digest()
    with pytest.raises(ConfigError):
        uh60.with_conditions(density_altitude=float("nan"))


def test_isa_density_matches_the_standard_atmosphere():
    assert isa_density(0.0) == pytest.approx(1.225)
    assert isa_density(3048.0) == pytest.approx(0.9046, rel=2e-3)  # 10,000 ft


def test_planner_settings_load_and_validate(tmp_path):
    settings = load_settings()
    assert settings == PlannerSettings()  # config/planner.yaml holds the documented defaults
    assert load_settings(method="paper").method == "paper"
    with pytest.raises(ConfigError, match="method"):
        PlannerSettings(method="magic")
    with pytest.raises(ConfigError, match="intervals"):
        PlannerSettings(intervals=0)
    unknown = tmp_path / "planner.yaml"
    unknown.write_text("method: verified\nmesh: fine\n")
    with pytest.raises(ConfigError, match=r"unknown planner setting.*mesh"):
        load_settings(unknown)
