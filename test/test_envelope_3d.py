"""3-D H-V envelopes (climb rate × height × speed): file format, conservative 3-D queries, the validity domain,
the computation (CLI, Dask LocalCluster, resume), slice plots and the status node reading a 3-D file.

Query semantics use hand-made envelopes with exact expectations; the computed envelopes use a 2 × 3 × 3 grid
(-4,000 and 0 ft/min, 0-400 ft, 0-120 kt; real IPOPT, a few seconds), whose -4,000 ft/min slice has no powered
trim at 0 and 60 kt (a descent faster than the fuselage's terminal descent there).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.parameter import Parameter
from test_envelope import TIMING_ARRAYS, run_cli, synthetic_envelope
from test_ros_nodes import Harness, level_is

from helireach_ros.core.aircraft.model import trim_flight
from helireach_ros.core.envelope.compute import ComputeInterrupted, EnvelopeJob, compute_envelope
from helireach_ros.core.envelope.data import (
    FORMAT_VERSION,
    FORMAT_VERSION_3D,
    FORMAT_VERSION_ANSWERS,
    STATUS_CODES,
    Envelope,
    EnvelopeError,
    default_envelope_path,
    load_envelope,
    read_envelope_file,
    save_envelope,
    stack_slices,
)
from helireach_ros.core.envelope.domain import ValidityDomain
from helireach_ros.core.envelope.grid import parse_range
from helireach_ros.core.envelope.plot import all_slices_figure, envelope_figure
from helireach_ros.core.envelope.workers import SerialExecutor, make_executor
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor

FPM = FT / 60.0
HEIGHTS_FT, SPEEDS_KT, CLIMBS_FPM = "0:400:3", "0:120:3", "-4000,0"


def stacked(climbs_fpm: list[float], slices: list[list[list[str]]], **metadata) -> Envelope:
    """A 3-D envelope of hand-made 3 × 3 slices (heights 0/100/200 ft, speeds 0/10/20 kt)."""
    parts = [synthetic_envelope(rows) for rows in slices]
    base = parts[0].metadata | {"format_version": FORMAT_VERSION_3D} | metadata
    return stack_slices(parts, [c * FPM for c in climbs_fpm], base)


SAFE = [["safe"] * 3] * 3


@pytest.fixture()
def one_unsafe_node_on_top():
    """Slices at -1,000 and 0 ft/min; every node safe except (0 ft/min, 100 ft, 10 kt)."""
    return stacked([-1000, 0], [SAFE, [["safe"] * 3, ["safe", "unsafe", "safe"], ["safe"] * 3]])


# --- 2-D files are read as before ------------------------------------------------------------------------


def test_a_2d_file_still_loads_and_queries_as_before(tmp_path):
    """A 2-D file stays format version 1 without climb arrays; its level queries ignore nothing and change nothing."""
    one_unsafe_node = synthetic_envelope([["safe"] * 3, ["unsafe", "safe", "safe"], ["safe"] * 3])
    flat = read_envelope_file(save_envelope(one_unsafe_node, tmp_path / "flat.npz"))
    assert flat.metadata["format_version"] == FORMAT_VERSION == 1 and "climb_rates" not in flat.arrays
    assert not flat.is_3d and flat.climb_rates is None and flat.status.shape == (3, 3) and flat.slice(0) is flat
    # the exact answers of test_envelope.py's 2-D query tests, at level flight and within its tolerance
    for climb_fpm in (0, 50, -90):
        assert flat.query(100 * FT, 0.0, climb_fpm * FPM).status == "unsafe"
        assert flat.query(100 * FT, 0.0, climb_fpm * FPM).margin == pytest.approx(-10.0)
        assert flat.query(150 * FT, 15 * KT, climb_fpm * FPM).margin == pytest.approx(5.0)
    assert flat.query(150 * FT, 15 * KT) == flat.query(150 * FT, 15 * KT, 0.0)
    assert flat.query(150 * FT, 15 * KT, -200 * FPM).status == "outside"  # beyond ±0.5 m/s of level


def test_a_2d_file_still_loads_and_queries_level_flight_only(tmp_path):
    """A level slice of the shipped 3-D file written as a 2-D file loads, answers as that slice, and says nothing
    beyond its level-trim tolerance."""
    shipped = read_envelope_file(default_envelope_path())
    level = shipped.slice(shipped.nearest_slice(0.0))
    path = save_envelope(level, tmp_path / "level.npz")
    flat = read_envelope_file(path)
    assert flat.format_version == FORMAT_VERSION_ANSWERS and flat.status.ndim == 2 and not flat.is_3d
    for height_ft, speed_kt in ((200, 5), (700, 100), (300, 40), (20, 90)):
        answer = flat.query(height_ft * FT, speed_kt * KT)
        assert answer.status == shipped.query(height_ft * FT, speed_kt * KT, 0.0).status
        assert flat.query(height_ft * FT, speed_kt * KT, 50 * FPM) == answer
        assert flat.query(height_ft * FT, speed_kt * KT, -200 * FPM).status == "outside"


# --- 3-D queries (exact expectations) --------------------------------------------------------------------


def test_3d_query_on_a_slice_is_that_slice_and_between_slices_needs_every_enclosing_node(one_unsafe_node_on_top):
    envelope = one_unsafe_node_on_top
    assert envelope.is_3d and envelope.status.shape == (2, 3, 3)
    lower, upper = envelope.slice(0), envelope.slice(1)
    for height_ft, speed_kt in ((100, 10), (150, 15), (50, 5), (200, 20), (100, 0)):
        point = (height_ft * FT, speed_kt * KT)
        assert envelope.query(*point, -1000 * FPM) == lower.query(*point, -1000 * FPM)
        assert envelope.query(*point, 0.0) == upper.query(*point, 0.0)
    assert envelope.query(100 * FT, 10 * KT, -1000 * FPM).status == "safe"  # the lower slice is all safe
    between = envelope.query(100 * FT, 10 * KT, -500 * FPM)
    assert between.status == "unsafe" and between.by_interpolation
    assert between.margin == pytest.approx(-10.0)  # the combined slice is the upper one: nearest safe node 10 kt
    # 50 ft / 5 kt at -300 ft/min: a cell corner in the upper slice is the unsafe node
    assert envelope.query(50 * FT, 5 * KT, -300 * FPM).status == "unsafe"
    # the upper slice's margin at a safe corner, 10 kt / 100 ft from the unsafe cells
    far = envelope.query(200 * FT, 20 * KT, -700 * FPM)
    assert far.status == "safe" and far.margin == pytest.approx(upper.query(200 * FT, 20 * KT, 0.0).margin)


def test_3d_query_is_safe_exactly_when_no_enclosing_node_is_unsafe(one_unsafe_node_on_top):
    """Random points in the 3-D grid: safe iff the box of enclosing nodes misses the one unsafe node."""
    generator = np.random.default_rng(11)
    points = zip(
        generator.uniform(0, 200, 600), generator.uniform(0, 20, 600), generator.uniform(-1000, 0, 600), strict=True
    )
    for height_ft, speed_kt, climb_fpm in points:
        answer = one_unsafe_node_on_top.query(height_ft * FT, speed_kt * KT, climb_fpm * FPM)
        touches = 0 < height_ft < 200 and 0 < speed_kt < 20  # the unsafe node is a corner of every cell here
        assert answer.status == ("unsafe" if touches else "safe"), (height_ft, speed_kt, climb_fpm)
        assert (answer.margin >= 0.0) == (answer.status == "safe")


def test_a_climb_rate_outside_the_3d_axis_is_outside_never_safe(one_unsafe_node_on_top):
    envelope = stacked([-1000, 0], [SAFE, SAFE])
    assert envelope.query(100 * FT, 10 * KT, -1000 * FPM).status == "safe"
    for climb_fpm in (-1001, 1, 50, -2000, math.nan, math.inf):  # no level tolerance beyond a 3-D axis
        answer = envelope.query(100 * FT, 10 * KT, climb_fpm * FPM)
        assert answer.status == "outside" and math.isnan(answer.margin)
    assert envelope.query(100 * FT, 10 * KT, None).status == "outside"
    domain = envelope.validity_domain
    assert domain.climb_rate_range() == pytest.approx((-1000 * FPM, 0.0))
    assert domain.check(-1000 * FPM, 27.0, 27.0).inside and domain.check(-500 * FPM, 27.0, 27.0).inside
    for climb_fpm in (-1050, 50):
        check = domain.check(climb_fpm * FPM, 27.0, 27.0)
        assert not check.inside and "ft/min outside -1000…+0 ft/min" in check.reasons[0]
    # a 2-D domain keeps its level tolerance
    assert (
        ValidityDomain().check(-90 * FPM, 27.0, 27.0).inside
        and not ValidityDomain().check(-110 * FPM, 27.0, 27.0).inside
    )


def test_no_trim_nodes_are_never_safe_and_have_no_plan():
    envelope = stacked([-4000, 0], [[["no_trim", "no_trim", "safe"]] * 3, SAFE])
    assert envelope.query(100 * FT, 0.0, -4000 * FPM).status == "no_trim"
    assert envelope.query(100 * FT, 15 * KT, -3000 * FPM).status == "no_trim"  # a no-trim corner in the cell
    assert envelope.query(100 * FT, 20 * KT, -3000 * FPM).status == "safe"
    stored = envelope.nearest_plan(100 * FT, 0.0, -4000 * FPM)
    assert stored is not None and stored.status == "safe"
    assert (stored.climb_rate, stored.speed) in {(0.0, 0.0), (-4000 * FPM, 20 * KT)}


def test_nearest_plan_is_nearest_in_climb_height_and_speed():
    envelope = stacked([-2000, -1000, 0], [SAFE, SAFE, SAFE])
    assert envelope.nearest_plan(100 * FT, 10 * KT, -1400 * FPM).climb_rate == pytest.approx(-1000 * FPM)
    assert envelope.nearest_plan(100 * FT, 10 * KT, -1600 * FPM).climb_rate == pytest.approx(-2000 * FPM)
    assert envelope.nearest_plan(100 * FT, 10 * KT).climb_rate == 0.0  # default: level flight
    plan = envelope.nearest_plan(190 * FT, 2 * KT, -100 * FPM)
    assert (plan.height, plan.speed, plan.climb_rate) == (200 * FT, 0.0, 0.0)
    assert envelope.nearest_plan(math.nan, 0.0) is None


def test_3d_file_round_trip_slices_and_refusals(one_unsafe_node_on_top, tmp_path):
    path = save_envelope(one_unsafe_node_on_top, tmp_path / "three_d.npz")
    again = read_envelope_file(path)
    assert again.is_3d and again.envelope_id == one_unsafe_node_on_top.envelope_id
    np.testing.assert_allclose(again.climb_rates, [-1000 * FPM, 0.0])
    upper = again.slice(-1)
    assert upper.metadata["climb_slice"]["climb_rate_fpm"] == pytest.approx(0.0) and upper.status.shape == (3, 3)
    assert stack_slices([again.slice(0), again.slice(1)], list(again.climb_rates), again.metadata).arrays.keys() == (
        again.arrays.keys()
    )
    assert again.nearest_slice(-600 * FPM) == 0 and again.nearest_slice(-400 * FPM) == 1
    # a version 2 file must hold the climb axis, a version 1 file must not
    flat = synthetic_envelope(SAFE)
    mislabelled = Envelope(flat.arrays, flat.metadata | {"format_version": FORMAT_VERSION_3D})
    with pytest.raises(EnvelopeError, match="climb-rate axis"):
        read_envelope_file(save_envelope(mislabelled, tmp_path / "mislabelled.npz"))
    with pytest.raises(EnvelopeError, match="climb_rates"):
        Envelope(again.arrays | {"climb_rates": np.array([0.0, -1.0])}, again.metadata)  # not ascending
    with pytest.raises(EnvelopeError, match="boundary_slice"):
        Envelope({k: v for k, v in again.arrays.items() if k != "boundary_slice"}, again.metadata)


def test_broken_version_or_domain_metadata_is_refused_with_a_message(tmp_path):
    flat = synthetic_envelope(SAFE)
    with pytest.raises(EnvelopeError, match="validity_domain"):
        Envelope(flat.arrays, flat.metadata | {"validity_domain": {"climb_rate_tolerance": -1.0}})
    for version in ([1], "2", 4):
        path = save_envelope(Envelope(flat.arrays, flat.metadata | {"format_version": version}), tmp_path / "v.npz")
        with pytest.raises(EnvelopeError, match="format version"):
            read_envelope_file(path)
    with pytest.raises(EnvelopeError, match="plan_initial_state"):  # today's format rebuilds plans from it
        Envelope(flat.arrays, flat.metadata | {"format_version": 3})


# --- the computation (real IPOPT) ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def verified_settings(settings):
    return settings.replace(method="verified", reaction_delay_s=0.0)


@pytest.fixture(scope="module")
def job_3d(airframe, verified_settings):
    climbs = tuple(float(c) * FPM for c in CLIMBS_FPM.split(","))
    return EnvelopeJob(airframe, verified_settings, 0.0, parse_range(HEIGHTS_FT, FT), parse_range(SPEEDS_KT, KT),
                       climb_rates=climbs)  # fmt: skip


@pytest.fixture(scope="module")
def computed_3d(tmp_path_factory):
    """The 2 × 3 × 3 envelope computed by the command line (one worker)."""
    out = tmp_path_factory.mktemp("envelope3d") / "small3d.npz"
    result = run_cli("envelope", "compute", "--heights-ft", HEIGHTS_FT, "--speeds-kt", SPEEDS_KT,
                     f"--climb-rates-fpm={CLIMBS_FPM}", "--method", "verified", "--reaction-delay-s", "0",
                     "--workers", "1", "--out", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr
    return out


def same_results(first: Envelope, second: Envelope) -> list[str]:
    """Names of the arrays that differ, beyond timings and the leftovers of failed solves.

    A failed node (IPOPT stopped at its iteration limit) keeps whatever iterate the solver ended on; Dask's
    workers run BLAS single-threaded (its nanny sets ``OMP_NUM_THREADS=1``), so after hundreds of
    non-converging iterations that iterate differs in the last digits and beyond. Its status, and every
    converged node, must be identical.
    """
    a, b = first.arrays, second.arrays
    assert set(a) == set(b)
    assert np.array_equal(a["status_code"], b["status_code"])
    failed = a["status_code"] == STATUS_CODES["failed"]

    def kept(array: np.ndarray) -> np.ndarray:
        if array.shape[: failed.ndim] != failed.shape or array.dtype.kind != "f":
            return array
        array = array.copy()
        array[failed] = np.nan
        return array

    return [
        name
        for name in a
        if name not in TIMING_ARRAYS and not np.array_equal(kept(a[name]), kept(b[name]), equal_nan=True)
    ]


def test_cli_writes_a_3d_file_with_its_axis_command_and_no_trim_nodes(computed_3d, airframe):
    envelope = load_envelope(computed_3d)
    metadata = envelope.metadata
    assert metadata["format_version"] == FORMAT_VERSION_ANSWERS and envelope.status.shape == (2, 3, 3)
    assert metadata["climb_rates_fpm"] == [-4000, 0] and metadata["grid"]["climb_rates_fpm"] == CLIMBS_FPM
    assert metadata["validity_domain"]["climb_rates"] == pytest.approx([-4000 * FPM, 0.0])
    assert f"--climb-rates-fpm={CLIMBS_FPM}" in metadata["command"]
    assert metadata["settings"]["method"] == "verified" and metadata["settings"]["reaction_delay_s"] == 0.0
    for index, climb in enumerate(envelope.climb_rates):
        for column, speed in enumerate(envelope.speeds):
            try:
                trim_flight(airframe, float(speed), float(climb))
                trimmed = True
            except ValueError:
                trimmed = False
            column_status = set(envelope.status[index, :, column])
            assert (column_status == {"no_trim"}) == (not trimmed), (climb / FPM, speed / KT, column_status)
    assert np.sum(envelope.status == "no_trim") == 6  # 0 and 60 kt at -4,000 ft/min
    assert metadata["compute"]["counters"]["no_trim_nodes"] == 6
    # the query interpolates across the slices and refuses climb rates off the axis
    outside = run_cli("envelope", "query", str(computed_3d), "--height-ft", "400", "--speed-kt", "120",
                      "--climb-rate-fpm", "100", "--json")  # fmt: skip
    assert outside.returncode == 1 and '"status": "outside"' in outside.stdout


def test_each_slice_is_the_2d_envelope_of_its_climb_rate(computed_3d, job_3d):
    envelope = load_envelope(computed_3d)
    level = compute_envelope(EnvelopeJob(job_3d.airframe, job_3d.settings, 0.0, job_3d.heights, job_3d.speeds))
    assert same_results(envelope.slice(1), level) == []
    assert level.metadata["format_version"] == FORMAT_VERSION_ANSWERS and not level.is_3d


def test_dask_local_cluster_equals_the_serial_run(computed_3d, job_3d, tmp_path):
    executor = make_executor(dask_local=2)
    try:
        assert "Dask LocalCluster, 2 processes" in executor.description
        on_dask = compute_envelope(job_3d, executor, out_path=tmp_path / "dask.npz")
    finally:
        executor.close()
    assert same_results(load_envelope(computed_3d), on_dask) == []


class _InterruptAfter(SerialExecutor):
    """Runs tasks in this process and raises KeyboardInterrupt (as Ctrl-C would) after ``count`` results."""

    def __init__(self, count: int) -> None:
        self.count = count

    def map_unordered(self, function, tasks):
        for result in super().map_unordered(function, tasks):
            if self.count == 0:
                raise KeyboardInterrupt
            self.count -= 1
            yield result


def test_an_interrupted_3d_computation_resumes_to_the_same_envelope(computed_3d, job_3d, tmp_path):
    out = tmp_path / "interrupted.npz"
    with pytest.raises(ComputeInterrupted):
        compute_envelope(job_3d, _InterruptAfter(4), out_path=out)  # 4 of the 6 sweep columns
    partial = read_envelope_file(out, allow_partial=True)
    assert partial.is_3d and not partial.complete and np.sum(partial.status == "pending") == 6
    other_axis = EnvelopeJob(job_3d.airframe, job_3d.settings, 0.0, job_3d.heights, job_3d.speeds,
                             climb_rates=(-2000 * FPM, 0.0))  # fmt: skip
    with pytest.raises(EnvelopeError, match="climb-rate axis"):
        compute_envelope(other_axis, out_path=out, resume=True)
    resumed = compute_envelope(job_3d, out_path=out, resume=True)
    assert resumed.complete and same_results(load_envelope(computed_3d), resumed) == []


def test_slice_plots_name_their_slice(computed_3d, tmp_path):
    envelope = load_envelope(computed_3d)
    title = envelope_figure(envelope, climb_rate=-3000 * FPM).axes[0].get_title()
    assert "climb -4,000 ft/min (slice 1 of 2)" in title and "nearest -3,000 ft/min" in title
    assert "climb +0 ft/min" in envelope_figure(envelope).axes[0].get_title()  # default: nearest level flight
    panels = all_slices_figure(envelope).axes
    assert [axes.get_title() for axes in panels] == ["-4,000 ft/min", "+0 ft/min"]
    for arguments in (["--climb-rate-fpm", "-1000"], ["--all-slices"]):
        out = tmp_path / f"plot{len(arguments)}.png"
        result = run_cli("envelope", "plot", str(computed_3d), *arguments, "--out", str(out))
        assert result.returncode == 0, result.stderr
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    refused = run_cli("envelope", "plot", str(computed_3d), "--all-slices", "--climb-rate-fpm", "0", "--out",
                      str(tmp_path / "x.png"))  # fmt: skip
    assert refused.returncode == 2


# --- the status node reads a 3-D file --------------------------------------------------------------------


def test_the_status_node_queries_a_3d_envelope_at_the_measured_climb_rate(context: Context, airframe, tmp_path):
    """A 3-D file whose -1,000 ft/min slice is all unsafe and whose level slice is all safe (0-1,000 ft, 0-150 kt).

    Level: OK from the envelope; -1,000 and -500 ft/min: ERROR from the envelope (a 2-D envelope would be
    outside its domain, STALE); -2,000 ft/min: off the climb axis, STALE.
    """
    arrays = {}
    for index, name in enumerate(("unsafe", "safe")):
        part = synthetic_envelope([[name] * 3] * 3).arrays
        part["heights"], part["speeds"] = np.array([0.0, 500.0, 1000.0]) * FT, np.array([0.0, 75.0, 150.0]) * KT
        arrays[index] = part
    metadata = {"format": "helireach-envelope", "format_version": FORMAT_VERSION_3D, "complete": True,
                "power_fraction": 0.0, "airframe": airframe.as_dict() | {"digest": airframe.digest()},
                "control_interpolation": "zero_order_hold"}  # fmt: skip
    slices = [Envelope(arrays[index], metadata) for index in range(2)]
    path = save_envelope(stack_slices(slices, [-1000 * FPM, 0.0], metadata), tmp_path / "status3d.npz")
    status_node = EnvelopeStatusNode(context=context, parameter_overrides=[Parameter("envelope_file", value=str(path))])
    harness = Harness(context, VehicleMonitor(context=context), status_node)
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        assert status_node.envelope is not None and status_node.envelope.is_3d
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.OK))
        assert rm.status_values(statuses[-1])["evidence"] == "envelope"
        for climb_fpm in (-1000, -500):
            assert harness.keep_publishing(
                500 * FT, 75 * KT, climb_rate=climb_fpm * FPM, until=level_is(statuses, DiagnosticStatus.ERROR)
            )
            values = rm.status_values(statuses[-1])
            assert values["evidence"] == "envelope" and values["envelope_status"] == "unsafe", values
        assert harness.keep_publishing(
            500 * FT, 75 * KT, climb_rate=-2000 * FPM, until=level_is(statuses, DiagnosticStatus.STALE)
        )
        assert "climb rate -2000 ft/min outside -1000…+0 ft/min" in statuses[-1].message
    finally:
        harness.close()
