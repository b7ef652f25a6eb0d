"""Robust verdicts in an envelope: computed by flying the landings (real IPOPT, real closed loops), stored,
queried conservatively, drawn, and refused when inconsistent ("robust envelope")."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import yaml

from helireach_ros.core.envelope.compute import EnvelopeJob, compute_envelope
from helireach_ros.core.envelope.data import (
    ROBUST_ARRAYS,
    ROBUST_CODES,
    Envelope,
    EnvelopeError,
    load_envelope,
    save_envelope,
)
from helireach_ros.core.envelope.plot import plot_envelope
from helireach_ros.core.flight.uncertainty import parse_uncertainty_set
from helireach_ros.core.robustness.envelope_verdicts import RobustEnvelopeJob, add_robust_verdicts
from helireach_ros.core.units import FT, KT

pytestmark = [pytest.mark.slow]

_SENSORS = (("height", "ft"), ("forward_speed", "kt"), ("climb_rate", "ft/s"), ("rotor_speed", "rad/s"))
_PARAMETERS = (
    "gross_weight", "horizontal_drag_area", "vertical_drag_area", "blade_drag_coefficient", "rotor_inertia",
    "rotor_power_efficiency",
)  # fmt: skip


def uncertainty_document(**widened: tuple[float, float]) -> dict:
    """An uncertainty set with every range of zero width (the exact model, 0.05 s latency) but ``widened`` (%)."""
    parameters = {
        name: {"low": widened.get(name, (0, 0))[0], "high": widened.get(name, (0, 0))[1], "unit": "%", "note": "test"}
        for name in _PARAMETERS
    }
    return {
        "name": "test",
        "parameters": parameters,
        "density_altitude": {"low": 0, "high": 0, "unit": "ft", "note": "test"},
        "plan_latency": {"low": 0.05, "high": 0.05, "unit": "s", "note": "test"},
        "sensor_noise": {sensor: {"value": 0, "unit": unit, "note": "test"} for sensor, unit in _SENSORS},
    }


def uncertainty(**widened: tuple[float, float]):
    """:func:`uncertainty_document`, parsed."""
    return parse_uncertainty_set(uncertainty_document(**widened))


def uncertainty_file(path, **widened: tuple[float, float]) -> str:
    """:func:`uncertainty_document` as a YAML file (for the command line and node parameters); its path."""
    path.write_text(yaml.safe_dump(uncertainty_document(**widened)))
    return str(path)


@pytest.fixture(scope="module")
def nominal(airframe, settings) -> Envelope:
    """Four level-trim nodes around 500 ft / 75 kt, all nominally safe."""
    job = EnvelopeJob(airframe, settings, 0.0, (450 * FT, 500 * FT), (70 * KT, 75 * KT))
    envelope = compute_envelope(job)
    assert np.all(envelope.status == "safe")
    return envelope


@pytest.fixture(scope="module")
def exact_model(nominal, airframe, settings) -> Envelope:
    return add_robust_verdicts(nominal, RobustEnvelopeJob(airframe, settings, uncertainty()))


def test_in_the_exact_model_every_safe_node_is_robust_and_the_verdict_is_stored(exact_model, tmp_path) -> None:
    """The closed loop in the model itself lands: robust everywhere; the file keeps it through its checksum."""
    assert exact_model.has_robust_verdict
    assert np.all(exact_model.robust_status == "robust")
    assert np.all(exact_model.arrays["robust_models_flown"] == 1)
    assert np.all(exact_model.arrays["robust_closed_loop_landed"] == 1)
    assert np.all(exact_model.arrays["robust_failure_attainable"] == -1)  # no failing model to ask about
    metadata = exact_model.metadata["robust"]
    assert metadata["design"] == "resolution-IV corners of 'test' (1)" and metadata["counts"]["robust"] == 4
    assert metadata["cost"]["nodes_flown"] == 4 and metadata["cost"]["seconds_per_node_mean"] > 0
    loaded = load_envelope(save_envelope(exact_model, tmp_path / "robust.npz"))
    assert loaded.envelope_id == exact_model.envelope_id and loaded.has_robust_verdict
    answer = loaded.query(475 * FT, 72 * KT, verdict="robust")
    assert answer.status == "safe" and answer.verdict == "robust"
    assert loaded.query(475 * FT, 72 * KT).verdict == "nominal"  # the default stays the nominal verdict


def test_a_model_whose_closed_loop_fails_makes_the_node_not_robust_and_stops_its_flights(
    nominal, airframe, settings
) -> None:
    """Constructed: 20-25 % heavier than planned does not land; the first failing model settles the verdict."""
    job = RobustEnvelopeJob(airframe, settings, uncertainty(gross_weight=(20, 25)))
    assert len(job.models()) == 2
    heavy = add_robust_verdicts(nominal, job)
    assert np.all(heavy.robust_status == "not_robust")
    assert np.all(heavy.arrays["robust_models_flown"] == 1)  # stopped at the first failure
    assert np.all(heavy.arrays["robust_closed_loop_landed"] == 0)
    # whether the failing model could land at all, with a planner that knows it: asked, and recorded
    attainable = heavy.arrays["robust_failure_attainable"]
    assert np.all(np.isin(attainable, (0, 1)))
    robust = heavy.metadata["robust"]
    assert robust["not_robust_failing_model_has_no_landing"] + robust["not_robust_failing_model_has_a_landing"] == 4
    answer = heavy.query(500 * FT, 75 * KT, verdict="robust")
    assert answer.status == "not_robust" and answer.verdict == "robust" and answer.margin < 0
    assert heavy.query(500 * FT, 75 * KT).status == "safe"  # nominally it still is


def _with_robust_codes(envelope: Envelope, codes: np.ndarray) -> Envelope:
    arrays = envelope.arrays
    arrays["robust_code"] = codes.astype(np.int8)
    return Envelope(arrays, envelope.metadata)


def test_one_not_robust_corner_makes_the_cell_not_robust_and_a_node_without_a_verdict_falls_back(
    exact_model,
) -> None:
    codes = np.array(exact_model.arrays["robust_code"], copy=True)
    codes[1, 1] = ROBUST_CODES["not_robust"]  # 500 ft / 75 kt
    mixed = _with_robust_codes(exact_model, codes)
    inside = mixed.query(475 * FT, 72 * KT, verdict="robust")
    assert inside.status == "not_robust" and inside.by_interpolation
    assert mixed.query(450 * FT, 70 * KT, verdict="robust").status == "safe"
    codes[1, 1] = ROBUST_CODES["not_computed"]
    partial = _with_robust_codes(exact_model, codes)
    assert partial.query(475 * FT, 72 * KT, verdict="robust").verdict == "nominal"  # a node without a verdict
    assert partial.query(450 * FT, 70 * KT, verdict="robust").verdict == "robust"
    with pytest.raises(ValueError, match="verdict must be one of"):
        mixed.query(475 * FT, 72 * KT, verdict="optimistic")


def test_an_inconsistent_robust_verdict_is_refused(exact_model) -> None:
    arrays = exact_model.arrays
    codes = np.array(arrays["status_code"], copy=True)
    codes[0, 0] = 1  # unsafe, yet robust_code says robust
    with pytest.raises(EnvelopeError, match="robust that is not safe"):
        Envelope(dict(arrays, status_code=codes), exact_model.metadata)
    incomplete = {name: array for name, array in arrays.items() if name != ROBUST_ARRAYS[-1]}
    with pytest.raises(EnvelopeError, match="robust verdict without"):
        Envelope(incomplete, exact_model.metadata)
    with pytest.raises(EnvelopeError, match="unknown codes"):
        _with_robust_codes(exact_model, np.full((2, 2), 7))


def test_the_diagram_draws_the_robust_boundary(nominal, exact_model, tmp_path) -> None:
    codes = np.array(exact_model.arrays["robust_code"], copy=True)
    codes[1, :] = ROBUST_CODES["not_robust"]
    with_boundary = _with_robust_codes(exact_model, codes)
    sizes = [plot_envelope(e, tmp_path / f"{i}.png").stat().st_size for i, e in enumerate((nominal, with_boundary))]
    assert sizes[1] > sizes[0]  # the dashed boundary, node markers and legend entries add pixels


def test_the_cli_adds_robust_verdicts_to_a_file_and_queries_them(exact_model, nominal, tmp_path) -> None:
    source = save_envelope(nominal, tmp_path / "nominal.npz")
    set_file = uncertainty_file(tmp_path / "heavy.yaml", gross_weight=(20, 25))
    out = tmp_path / "robust.npz"
    helireach = [sys.executable, "-m", "helireach_ros.cli"]
    done = subprocess.run(
        [*helireach, "envelope", "robust", str(source), "--out", str(out), "--workers", "1", "--quiet",
         "--uncertainty", set_file],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "'not_robust': 4" in done.stdout
    query = [*helireach, "envelope", "query", str(out), "--height-ft", "475", "--speed-kt", "72"]
    assert subprocess.run(query, capture_output=True, timeout=120).returncode == 0  # nominal: safe
    robust = subprocess.run([*query, "--verdict", "robust"], capture_output=True, text=True, timeout=120)
    assert robust.returncode == 1 and "not_robust (robust verdict" in robust.stdout
    other = subprocess.run(
        [*helireach, "envelope", "robust", str(source), "--out", str(out), "--airframe", "oh58a_class"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert other.returncode == 2 and "airframe" in other.stderr
