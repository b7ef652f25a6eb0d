"""The uncertainty set (config/uncertainty.yaml): loads with units, refuses bad entries by name, corners and draws."""

from __future__ import annotations

import copy
import dataclasses
import itertools
from pathlib import Path

import numpy as np
import pytest
import yaml

from helireach_ros.core.aircraft.airframe import ConfigError
from helireach_ros.core.flight.simulation import load_scenario
from helireach_ros.core.flight.uncertainty import (
    PerturbedModel,
    UncertainRange,
    load_uncertainty_set,
    resolution_iv_signs,
)
from helireach_ros.core.resources import config_path
from helireach_ros.core.units import FT, KT


@pytest.fixture(scope="module")
def shipped_document() -> dict:
    return yaml.safe_load(config_path("uncertainty.yaml").read_text())


@pytest.fixture(scope="module")
def uncertainty():
    return load_uncertainty_set()


def test_the_shipped_set_holds_the_issues_defaults_in_si(uncertainty) -> None:
    half_widths = {name: r.high for name, r in uncertainty.parameters}
    assert half_widths == pytest.approx(
        {
            "gross_weight": 0.05,
            "horizontal_drag_area": 0.2,
            "vertical_drag_area": 0.2,
            "blade_drag_coefficient": 0.1,
            "rotor_inertia": 0.1,
            "rotor_power_efficiency": 0.05,
        }
    )
    assert all(r.low == -r.high for _, r in uncertainty.parameters)
    assert (uncertainty.density_altitude.low, uncertainty.density_altitude.high) == pytest.approx((-500 * FT, 500 * FT))
    assert (uncertainty.plan_latency.low, uncertainty.plan_latency.high) == pytest.approx((0.0, 0.3))
    demo_noise = load_scenario("demo_500ft_75kt").noise
    assert dataclasses.asdict(uncertainty.sensor_noise) == pytest.approx(dataclasses.asdict(demo_noise))
    assert uncertainty.sensor_noise.forward_speed == pytest.approx(0.2 * KT)
    assert all(r.note for _, r in uncertainty.parameters) and all(note for _, note in uncertainty.noise_notes)


def _write(tmp_path: Path, document: dict) -> Path:
    path = tmp_path / "set.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def _set(document: dict, dotted: str, value) -> dict:
    changed = copy.deepcopy(document)
    *parents, key = dotted.split(".")
    target = changed
    for parent in parents:
        target = target[parent]
    if value is None:
        del target[key]
    else:
        target[key] = value
    return changed


@pytest.mark.parametrize(
    ("dotted", "value", "named"),
    [
        ("parameters.rotor_colour", {"low": -1, "high": 1, "unit": "%", "note": "x"}, "rotor_colour"),
        ("parameters.gross_weight.note", "  ", "parameters.gross_weight.note"),
        ("parameters.gross_weight.note", None, "parameters.gross_weight"),
        ("parameters.horizontal_drag_area.low", 30, "horizontal_drag_area: low"),
        ("parameters.rotor_inertia.unit", "ft", "parameters.rotor_inertia.unit"),
        ("parameters.rotor_power_efficiency.high", 500, "parameters.rotor_power_efficiency"),
        ("parameters.rotor_power_efficiency.unit", "-", "parameters.rotor_power_efficiency"),  # ±5 = ±500 %
        ("parameters.blade_drag_coefficient.low", True, "parameters.blade_drag_coefficient.low"),
        ("parameters.vertical_drag_area.high", float("nan"), "parameters.vertical_drag_area.high"),
        ("density_altitude.unit", "s", "density_altitude"),
        ("density_altitude", None, "density_altitude"),
        ("plan_latency.low", -0.1, "plan_latency"),
        ("sensor_noise.height.value", -0.3, "sensor_noise.height"),
        ("sensor_noise.rotor_speed", None, "sensor_noise"),
        ("sensor_noise.climb_rate.unit", "rad/s", "sensor_noise.climb_rate"),
        ("margins", {}, "margins"),
    ],
)
def test_bad_entries_are_refused_by_name_and_file(tmp_path, shipped_document, dotted, value, named) -> None:
    path = _write(tmp_path, _set(shipped_document, dotted, value))
    with pytest.raises(ConfigError, match=named.replace(".", r"\.")) as error:
        load_uncertainty_set(path)
    assert str(path) in str(error.value)


def test_a_missing_or_broken_file_is_refused(tmp_path) -> None:
    with pytest.raises(ConfigError, match="no_such_set"):
        load_uncertainty_set(tmp_path / "no_such_set.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("parameters: [unclosed")
    with pytest.raises(ConfigError, match="broken"):
        load_uncertainty_set(broken)


def _ends(uncertainty) -> dict[str, tuple[float, float]]:
    return {name: (r.low, r.high) for name, r in uncertainty.ranges().items()}


def test_corners_are_every_combination_of_range_ends(uncertainty) -> None:
    corners = uncertainty.corners()
    ends = _ends(uncertainty)
    combinations = {tuple(model.values()[name] for name in ends) for model in corners}
    assert len(corners) == 2**8 == len(combinations)
    assert combinations == set(itertools.product(*ends.values()))


def test_a_zero_width_range_is_no_factor(uncertainty) -> None:
    exact = UncertainRange(0.0, 0.0, "exact")
    only_weight = dataclasses.replace(
        uncertainty,
        parameters=(uncertainty.parameters[0], *((name, exact) for name, _ in uncertainty.parameters[1:])),
        density_altitude=exact,
        plan_latency=UncertainRange(0.1, 0.1, "fixed"),
    )
    assert only_weight.uncertain_quantities == ("gross_weight",)
    weights = sorted(model.mismatch["gross_weight"] for model in only_weight.corners())
    assert weights == pytest.approx([-0.05, 0.05])
    assert {model.latency for model in only_weight.verification_design()} == {0.1}


def test_the_verification_design_is_a_balanced_resolution_iv_set_of_corners(uncertainty) -> None:
    design = uncertainty.verification_design()
    ends = _ends(uncertainty)
    assert len(design) == 16 and len({model.label for model in design}) == 16
    signs = np.array([[1.0 if m.values()[name] == high else -1.0 for name, (_, high) in ends.items()] for m in design])
    assert all(m.values()[name] in pair for m in design for name, pair in ends.items())  # every run a corner
    assert np.all(signs.sum(axis=0) == 0)  # each end in half the runs
    for main, (first, second) in itertools.product(range(8), itertools.combinations(range(8), 2)):
        if main not in (first, second):
            assert np.sum(signs[:, main] * signs[:, first] * signs[:, second]) == 0  # no main effect aliased
    for factors in (1, 2, 3):
        assert {tuple(row) for row in resolution_iv_signs(factors)} == set(
            itertools.product((-1.0, 1.0), repeat=factors)
        )


def test_draws_are_seeded_and_inside_the_set(uncertainty) -> None:
    first, again, other = uncertainty.draw(5, 50), uncertainty.draw(5, 50), uncertainty.draw(6, 50)
    assert [m.as_dict() for m in first] == [m.as_dict() for m in again]
    assert [m.as_dict() for m in first] != [m.as_dict() for m in other]
    for model in first:
        for name, (low, high) in _ends(uncertainty).items():
            assert low <= model.values()[name] <= high


def test_a_perturbed_model_changes_the_airframe_it_names_and_not_the_limits(uncertainty, airframe) -> None:
    model = PerturbedModel({"gross_weight": 0.05, "rotor_inertia": -0.1}, density_altitude_offset=500 * FT)
    true = model.airframe(airframe)
    assert true.gross_weight == pytest.approx(1.05 * airframe.gross_weight)
    assert true.rotor_inertia == pytest.approx(0.9 * airframe.rotor_inertia)
    assert true.density_altitude == pytest.approx(airframe.density_altitude + 500 * FT)
    assert true.air_density < airframe.air_density
    assert true.limits == airframe.limits and true.horizontal_drag_area == airframe.horizontal_drag_area
