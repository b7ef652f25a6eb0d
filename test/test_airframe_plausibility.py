"""Airframe plausibility: a plausible wrong unit warns by key; the shipped airframes load silently."""

from __future__ import annotations

import warnings

import pytest
import yaml

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.plausibility import (
    PLAUSIBILITY_RANGES,
    AirframePlausibilityWarning,
    implausible_figures,
)
from helireach_ros.core.resources import config_path


@pytest.mark.parametrize("name", ["uh60a_class", "oh58a_class"])
def test_shipped_airframes_load_without_a_warning(name):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        airframe = load_airframe(name)
    assert implausible_figures(airframe) == []


def _uh60_variant(tmp_path, key: str, value: float, unit: str):
    document = yaml.safe_load(config_path("airframes/uh60a_class.yaml").read_text())
    document["parameters"][key] = {"value": value, "unit": unit, "source": "test: a unit slip"}
    path = tmp_path / f"uh60a_{key}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_rotor_radius_in_metres_instead_of_feet_warns_by_key_and_still_loads(tmp_path):
    path = _uh60_variant(tmp_path, "rotor_radius", 26.83, "m")  # the file's 26.83 ft, i.e. radius x 3.28
    with pytest.warns(AirframePlausibilityWarning) as caught:
        airframe = load_airframe(path)
    assert airframe.rotor_radius == pytest.approx(26.83)  # a warning, never a refusal
    messages = [str(warning.message) for warning in caught]
    keys = {message.split(": ")[2].split(" = ")[0] for message in messages}
    assert {"tip_speed", "disk_loading", "hover_blade_loading", "hover_power_loading"} <= keys
    tip = next(message for message in messages if "tip_speed = " in message)
    assert str(path) in tip and "724.4 m/s" in tip and "[150, 250] m/s" in tip and "Leishman" in tip


@pytest.mark.parametrize(
    ("key", "value", "unit", "figure"),
    [
        ("rotor_radius", 53.67, "ft", "tip_speed"),  # the diameter given as the radius
        ("rotor_solidity", 0.2, "-", "rotor_solidity"),  # 2.5 x: chord and radius in different units
        ("gross_weight", 16000.0, "N", "hover_blade_loading"),  # N for lbf: a 4.4 x lighter aircraft
    ],
)
def test_other_unit_slips_warn_naming_the_figure(tmp_path, key, value, unit, figure):
    with pytest.warns(AirframePlausibilityWarning) as caught:
        load_airframe(_uh60_variant(tmp_path, key, value, unit))
    assert any(f": {figure} = " in str(warning.message) for warning in caught), [str(w.message) for w in caught]


def test_every_range_has_a_source_and_contains_both_shipped_airframes():
    shipped = [load_airframe("uh60a_class"), load_airframe("oh58a_class")]
    for check in PLAUSIBILITY_RANGES:
        assert check.source.strip() and check.low < check.high
        for airframe in shipped:
            assert check.low <= check.value(airframe) <= check.high, (check.key, airframe.name)
