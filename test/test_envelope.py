"""H-V envelopes: file round trip, refusal of corrupt/mismatched/partial files, query semantics, plans, plot.

The computed envelopes here use a 4 x 3 grid (0-600 ft, 0-60 kt): every phase runs (sweep, cold
re-check, boundary refinement) with real IPOPT in a few seconds.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import signal
import subprocess
import sys
import zipfile
from collections.abc import Callable

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.envelope.compute import EnvelopeJob, _checked, _Solution, _sweep_column, compute_envelope
from helireach_ros.core.envelope.data import (
    FORMAT_NAME,
    FORMAT_VERSION,
    FORMAT_VERSION_ANSWERS,
    SOLVER_STATE_ARRAYS,
    SOLVER_STATE_CACHE_ENV,
    STATUS_CODES,
    Envelope,
    EnvelopeError,
    load_envelope,
    read_envelope_file,
    save_envelope,
    solver_state_path,
)
from helireach_ros.core.envelope.grid import parse_list, parse_range
from helireach_ros.core.envelope.plot import boundary_geometry, plot_envelope
from helireach_ros.core.planning.planner import ControlFunctionWarmStart, WarmStart, get_planner
from helireach_ros.core.units import FT, KT

HEIGHTS_FT = "0:600:4"
SPEEDS_KT = "0:60:3"
TIMING_ARRAYS = {"solve_time_ms"}  # differ between runs; everything else must be identical


@pytest.fixture(scope="module")
def small_job(airframe, settings):
    return EnvelopeJob(airframe, settings, 0.0, parse_range(HEIGHTS_FT, FT), parse_range(SPEEDS_KT, KT))


@pytest.fixture(scope="module")
def small_file(small_job, tmp_path_factory):
    """A 4 x 3 envelope computed serially in this process and saved."""
    path = tmp_path_factory.mktemp("envelope") / "small.npz"
    compute_envelope(small_job, out_path=path, command="test")
    return path


@pytest.fixture(scope="module")
def small(small_file):
    return load_envelope(small_file)


def assert_same_results(first: Envelope, second: Envelope) -> None:
    a, b = first.arrays, second.arrays
    assert set(a) == set(b)
    different = [
        name for name in a if name not in TIMING_ARRAYS and not np.array_equal(a[name], b[name], equal_nan=True)
    ]
    assert different == []


def interrupt_cli(command: list[str], at_line: str | Callable[[str], bool], signal_number: int = signal.SIGINT) -> str:
    """Runs ``command``, sends ``signal_number`` (Ctrl-C) when its stderr prints a line starting with ``at_line`` (or
    one ``at_line`` accepts); asserts it exits 130 as interrupted and returns its stderr."""
    process = subprocess.Popen(command, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        for line in process.stderr:  # plain log lines (not a terminal): one per finished task
            if line.startswith(at_line) if isinstance(at_line, str) else at_line(line):
                process.send_signal(signal_number)
                break
        _, errors = process.communicate(timeout=120)
    finally:
        process.kill()
    assert process.returncode == 130, errors
    return errors


def run_cli(*arguments: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "helireach_ros.cli.main", *arguments], capture_output=True, text=True, timeout=timeout
    )


# --- computed envelope: contents and round trip ----------------------------------------------------------


def test_round_trip_keeps_every_array_and_the_metadata(small_file, small, tmp_path):
    copy_path = save_envelope(small, tmp_path / "copy.npz")
    again = load_envelope(copy_path)
    assert_same_results(small, again)
    assert np.array_equal(small.arrays["solve_time_ms"], again.arrays["solve_time_ms"], equal_nan=True)
    assert again.metadata == small.metadata
    assert again.envelope_id == small.envelope_id
    assert again.status.shape == (4, 3)
    assert np.allclose(again.heights / FT, [0, 200, 400, 600])
    assert np.allclose(again.speeds / KT, [0, 30, 60])


def test_metadata_describes_the_computation(small, airframe, settings):
    metadata = small.metadata
    assert metadata["format"] == FORMAT_NAME and metadata["format_version"] == FORMAT_VERSION_ANSWERS
    assert metadata["airframe"]["digest"] == airframe.digest()
    assert metadata["airframe"]["rotor_radius"] == airframe.rotor_radius
    assert metadata["settings"]["intervals"] == settings.intervals
    assert metadata["method"] == settings.method
    assert metadata["power_fraction"] == 0.0
    assert metadata["command"] == "test"
    assert metadata["units"]["heights"] == "m"
    assert metadata["compute"]["wall_time_s"] > 0
    assert metadata["software"]["helireach_ros"]
    assert small.airframe_name == "uh60a_class"


def test_statuses_are_consistent_with_values_and_replay(small):
    status, value, verified = small.status, small.value, small.arrays["verified"]
    assert set(np.unique(status)) <= set(STATUS_CODES)
    assert np.all(verified[status == "safe"])
    assert np.all(value[status == "safe"] <= 0.0)
    assert np.all(value[status == "unsafe"] > 0.0)
    # the hover band of this airframe: 200 ft at hover is unsafe, 600 ft at 60 kt is safe
    assert status[1, 0] == "unsafe" and status[3, 2] == "safe"


def test_boundary_points_lie_between_safe_and_unsafe_neighbours_within_tolerance(small):
    edges = small.arrays["boundary_edge"]
    assert len(edges) > 0
    for (row0, column0, row1, column1), safe_point, unsafe_point in zip(
        edges, small.boundary, small.arrays["boundary_unsafe_side"], strict=True
    ):
        assert small.status[row0, column0] == "safe" and small.status[row1, column1] == "unsafe"
        low = np.minimum([small.heights[row0], small.speeds[column0]], [small.heights[row1], small.speeds[column1]])
        high = np.maximum([small.heights[row0], small.speeds[column0]], [small.heights[row1], small.speeds[column1]])
        assert np.all(safe_point >= low - 1e-9) and np.all(safe_point <= high + 1e-9)
        gap = np.abs(np.asarray(safe_point) - unsafe_point)
        assert gap[0] <= 2 * FT + 1e-9 and gap[1] <= 1 * KT + 1e-9


def test_boundary_points_are_safe_when_solved_again(small, airframe, settings):
    """A refined point is one a cold solve calls safe (it is never carried over by a warm start)."""
    planner = get_planner(airframe, settings)
    for height, speed in small.boundary[:2]:
        plan = planner.plan(initial_state_after_failure(airframe, height, speed))
        assert plan.status == "safe"


def test_nearest_plan_warm_starts_the_planner(small, airframe, settings):
    stored = small.nearest_plan(590 * FT, 58 * KT)
    assert stored is not None
    assert stored.height == pytest.approx(600 * FT) and stored.speed == pytest.approx(60 * KT)
    assert stored.status == "safe"
    controls = stored.controls_at(np.linspace(0.0, stored.time_to_land, 7))
    assert controls.shape == (2, 7) and np.all(np.isfinite(controls))
    planner = get_planner(airframe, settings)
    state = initial_state_after_failure(airframe, 590 * FT, 58 * KT)
    warm = planner.plan(state, warm_start=stored.warm_start)
    assert warm.solver.warm_started and warm.solver.success
    assert warm.status == planner.plan(state).status
    assert small.nearest_plan(math.nan, 0.0) is None


@pytest.mark.parametrize("method", ["flyable", "verified"])
def test_a_stored_control_function_rebuilds_the_stored_solution(small, airframe, settings, method):
    """What a file without the solver's state can still warm-start from: the stored control function flown from
    the stored plan's state gives back its primal point (to the integrator's accuracy), and a solve from it is a
    warm solve with the cold solve's status."""
    if method == "verified":
        # its paper limits let a plan skim the ground in ground effect, which the replay (judged at the first
        # contact) refuses: no momentum-rotor plan of this method verifies, so its mechanics use the paper's rotor
        airframe = airframe.paper_rotor()
    planner = get_planner(airframe, settings.replace(method=method))
    node_state = initial_state_after_failure(airframe, 600 * FT, 60 * KT)
    stored = planner.plan(node_state)
    assert stored.status == "safe"
    rebuilt = planner.transcription.primal_from_controls(
        node_state.as_array(), stored.control_times, stored.control_values
    )
    assert rebuilt is not None
    assert np.max(np.abs(rebuilt - stored.warm_start.primal)) < 0.02  # scaled units: O(1) variables
    state = initial_state_after_failure(airframe, 590 * FT, 58 * KT)
    from_controls = ControlFunctionWarmStart(node_state.as_array(), stored.control_times, stored.control_values)
    warm = planner.plan(state, warm_start=from_controls)
    assert warm.solver.warm_started and warm.solver.success
    assert warm.status == planner.plan(state).status
    # a control function of another mesh cannot be rebuilt: the solve is cold, not wrong
    other = ControlFunctionWarmStart(node_state.as_array(), stored.control_times[:-2], stored.control_values[:, :-2])
    assert not planner.plan(state, warm_start=other).solver.warm_started


def test_the_file_holds_answers_and_control_functions_and_the_cache_the_solver_state(small_file, small, tmp_path):
    """A complete file leaves IPOPT's solution out (it is most of the bytes and changes with the NLP): it goes to
    the user cache, keyed by the file's checksum, and comes back on load; without it, a stored plan's warm start is
    its control function, flown from the node's state."""
    with np.load(small_file) as archive:
        assert not set(SOLVER_STATE_ARRAYS) & set(archive.files)
        assert archive["plan_control_times"].dtype == np.float32 and archive["plan_initial_state"].shape == (4, 3, 6)
    cached = solver_state_path(small.checksum)
    assert cached.is_file() and small.solver_state is not None
    assert isinstance(small.stored_plan(3, 2).warm_start, WarmStart)
    node = initial_state_after_failure(load_airframe("uh60a_class"), small.heights[3], small.speeds[2])
    assert np.allclose(small.arrays["plan_initial_state"][3, 2], node.as_array(), rtol=0, atol=1e-9)
    # a corrupt cache file is ignored (a warning), never trusted: the file alone still answers
    cached.write_bytes(cached.read_bytes()[:-100])
    alone = load_envelope(small_file)
    assert alone.solver_state is None and alone.envelope_id == small.envelope_id
    stored = alone.stored_plan(3, 2)
    assert isinstance(stored.warm_start, ControlFunctionWarmStart)
    assert np.array_equal(stored.warm_start.initial_state, small.arrays["plan_initial_state"][3, 2])
    # saving it again (e.g. with a robust verdict) writes today's format and restores the cache
    again = save_envelope(small, tmp_path / "again.npz")
    assert load_envelope(again).solver_state is not None


def test_an_envelope_of_the_previous_format_keeps_loading(small, tmp_path):
    """A version-2 file (solver state inside, no initial states) loads, and its plans warm-start from the solver
    state; it cannot be turned into today's format (no initial states) and says how to get one."""
    arrays = {name: array for name, array in small.arrays.items() if name != "plan_initial_state"}
    arrays |= {name: np.asarray(array, np.float32) for name, array in small.solver_state.items()}
    old = Envelope(arrays, small.metadata | {"format_version": FORMAT_VERSION})
    path = save_envelope(old, tmp_path / "old.npz")
    loaded = load_envelope(path)
    assert loaded.format_version == FORMAT_VERSION and isinstance(loaded.stored_plan(3, 2).warm_start, WarmStart)
    assert np.array_equal(loaded.status, small.status)
    with pytest.raises(EnvelopeError, match="recompute it"):
        loaded.answers()


def test_the_solver_state_cache_follows_its_environment_variable(small, tmp_path, monkeypatch):
    monkeypatch.setenv(SOLVER_STATE_CACHE_ENV, str(tmp_path / "cache"))
    assert solver_state_path(small.checksum).parent == tmp_path / "cache"
    save_envelope(small, tmp_path / "copy.npz")
    assert solver_state_path(small.checksum).is_file()


def test_a_setting_a_file_predates_counts_as_its_default(small, settings):
    """A planner setting added later, with the behaviour before it as its default, does not invalidate a file
    computed before it existed; a changed value of it does."""
    from helireach_ros.core.envelope.data import settings_differences

    stored = {name: value for name, value in small.metadata["settings"].items() if name != "objective"}
    assert settings_differences(stored, settings) == []
    assert settings_differences(stored, settings.replace(objective="reach_avoid")) == [
        "objective: 'terminal' != 'reach_avoid'"
    ]


# --- refusing bad files ----------------------------------------------------------------------------------


def test_missing_file_is_refused_with_its_name(tmp_path):
    with pytest.raises(EnvelopeError, match=r"nothing-here\.npz"):
        load_envelope(tmp_path / "nothing-here.npz")


def test_truncated_file_is_refused(small_file, tmp_path):
    data = small_file.read_bytes()
    for keep in (len(data) // 2, len(data) - 10, 100):
        truncated = tmp_path / f"truncated_{keep}.npz"
        truncated.write_bytes(data[:keep])
        with pytest.raises(EnvelopeError, match="truncated_"):
            load_envelope(truncated)


def test_flipped_byte_is_refused(small_file, small, tmp_path):
    data = bytearray(small_file.read_bytes())
    data[len(data) // 3] ^= 0xFF
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(bytes(data))
    with pytest.raises(EnvelopeError, match="corrupt"):
        load_envelope(corrupt)
    # anywhere in the file: refused with EnvelopeError (zipfile's and numpy's own errors included: a flip in an
    # array header once raised tokenize.TokenError), or harmless (zip bookkeeping outside the checksummed content)
    original = small_file.read_bytes()
    for position in np.random.default_rng(13).choice(len(original), 300, replace=False):
        flipped = bytearray(original)
        flipped[position] ^= 0xFF
        corrupt.write_bytes(bytes(flipped))
        try:
            loaded = load_envelope(corrupt)
        except EnvelopeError:
            continue
        assert_same_results(small, loaded)


def test_rewritten_content_without_a_matching_checksum_is_refused(small_file, tmp_path):
    """A well-formed archive whose arrays were changed (a cell flipped to safe) fails the checksum."""
    with np.load(small_file, allow_pickle=False) as archive:
        contents = {name: archive[name] for name in archive.files}
    contents["status_code"] = np.zeros_like(contents["status_code"])
    tampered = tmp_path / "tampered.npz"
    np.savez_compressed(tampered, **contents)
    with pytest.raises(EnvelopeError, match="checksum"):
        load_envelope(tampered)


def test_other_files_are_refused(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("not an envelope")
    with pytest.raises(EnvelopeError, match=r"notes\.npz"):
        load_envelope(text)
    other_zip = tmp_path / "other.npz"
    with zipfile.ZipFile(other_zip, "w") as archive:
        buffer = io.BytesIO()
        np.save(buffer, np.arange(3))
        archive.writestr("x.npy", buffer.getvalue())
    with pytest.raises(EnvelopeError, match=r"other\.npz"):
        load_envelope(other_zip)


def test_mismatched_airframe_settings_or_power_are_refused(small_file, airframe, settings):
    assert load_envelope(small_file, airframe=airframe, settings=settings, power_fraction=0.0) is not None
    heavier = airframe.with_conditions(gross_weight=airframe.gross_weight * 1.1)
    with pytest.raises(EnvelopeError, match=r"small\.npz.*computed for airframe"):
        load_envelope(small_file, airframe=heavier)
    with pytest.raises(EnvelopeError, match="intervals"):
        load_envelope(small_file, settings=settings.replace(intervals=settings.intervals + 5))
    with pytest.raises(EnvelopeError, match="power fraction"):
        load_envelope(small_file, power_fraction=0.5)
    with pytest.raises(EnvelopeError, match=r"not for 'oh58a_class'"):
        load_envelope(small_file, airframe=load_airframe("oh58a_class"))


# --- query semantics on a hand-made envelope (exact expectations) ---------------------------------------


def synthetic_envelope(rows: list[list[str]], values: list[list[float]] | None = None) -> Envelope:
    """Heights 0/100/200 ft (rows), speeds 0/10/20 kt (columns); no plans."""
    codes = np.array([[STATUS_CODES[name] for name in row] for row in rows], np.int8)
    shape = codes.shape
    if values is None:
        values = np.where(codes == STATUS_CODES["safe"], -0.5, 0.5)
    values = np.asarray(values, float)

    def cells(fill, dtype, extra=()):
        return np.full(shape + extra, fill, dtype)

    arrays = {
        "heights": np.array([0.0, 100.0, 200.0])[: shape[0]] * FT,
        "speeds": np.array([0.0, 10.0, 20.0])[: shape[1]] * KT,
        "status_code": codes,
        "value": values,
        "time_to_land": cells(5.0, float),
        "replay_value": values.copy(),
        "verified": codes == STATUS_CODES["safe"],
        "iterations": cells(10, np.int32),
        "solve_time_ms": cells(1.0, np.float32),
        "warm_started": cells(False, bool),
        "cold_checked": cells(True, bool),
        "warm_cold_disagree": cells(False, bool),
        "plan_primal": cells(0.5, np.float32, (4,)),
        "plan_bound_multipliers": cells(0.0, np.float32, (4,)),
        "plan_constraint_multipliers": cells(0.0, np.float32, (3,)),
        "plan_control_times": cells(1.0, np.float32, (3,)),
        "plan_control_values": cells(0.1, np.float32, (2, 2)),
        "boundary": np.zeros((0, 2)),
        "boundary_unsafe_side": np.zeros((0, 2)),
        "boundary_edge": np.zeros((0, 4), np.int16),
    }
    arrays["plan_primal"][codes == STATUS_CODES["failed"]] = np.nan
    metadata = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "complete": True, "power_fraction": 0.0,
                "airframe": {"name": "synthetic"}, "control_interpolation": "zero_order_hold"}  # fmt: skip
    return Envelope(arrays, metadata)


@pytest.fixture()
def one_unsafe_node():
    return synthetic_envelope([["safe", "safe", "safe"], ["unsafe", "safe", "safe"], ["safe", "safe", "safe"]])


def query(envelope: Envelope, height_ft: float, speed_kt: float):
    return envelope.query(height_ft * FT, speed_kt * KT)


def test_query_on_nodes(one_unsafe_node):
    at_unsafe = query(one_unsafe_node, 100, 0)
    assert at_unsafe.status == "unsafe" and at_unsafe.value == 0.5
    assert at_unsafe.margin == pytest.approx(-10.0)  # nearest safe element: the node at 100 ft, 10 kt
    far = query(one_unsafe_node, 200, 20)
    assert far.status == "safe" and far.value == -0.5
    assert far.margin == pytest.approx(10.0)  # distance to the cells touching the unsafe node


def test_query_between_nodes_is_safe_only_if_every_enclosing_node_is(one_unsafe_node):
    assert query(one_unsafe_node, 50, 5).status == "unsafe"  # a corner of this cell is unsafe
    assert query(one_unsafe_node, 50, 5).margin == pytest.approx(-5.0)
    assert query(one_unsafe_node, 50, 0).status == "unsafe"  # on a grid line with an unsafe end
    on_safe_line = query(one_unsafe_node, 50, 10)  # on a grid line with two safe ends, next to the unsafe cell
    assert on_safe_line.status == "safe" and on_safe_line.margin == pytest.approx(0.0)
    inside_safe_cell = query(one_unsafe_node, 150, 15)
    assert inside_safe_cell.status == "safe" and inside_safe_cell.margin == pytest.approx(5.0)
    assert query(one_unsafe_node, 150, 5).value == 0.5  # the largest enclosing value


def test_query_outside_the_grid(one_unsafe_node):
    for height_ft, speed_kt in ((-10, 5), (250, 5), (100, 25), (100, -1), (math.nan, 5), (50, math.inf)):
        answer = query(one_unsafe_node, height_ft, speed_kt)
        assert answer.status == "outside"
        assert math.isnan(answer.margin) and math.isnan(answer.value)
    assert one_unsafe_node.query(None, 1.0).status == "outside"
    assert one_unsafe_node.query("high", 1.0).status == "outside"
    assert one_unsafe_node.nearest_plan(None, 1.0) is None
    assert query(one_unsafe_node, 200, 20).status == "safe"  # the grid's corner is inside


def test_margin_sign_matches_status_everywhere(one_unsafe_node):
    generator = np.random.default_rng(3)
    for height_ft, speed_kt in zip(generator.uniform(0, 200, 400), generator.uniform(0, 20, 400), strict=True):
        answer = query(one_unsafe_node, height_ft, speed_kt)
        assert (answer.margin >= 0.0) == (answer.status == "safe")
        assert one_unsafe_node.status_at(height_ft * FT, speed_kt * KT) == answer.status
        assert one_unsafe_node.margin(height_ft * FT, speed_kt * KT) == answer.margin


def test_query_takes_the_most_conservative_enclosing_status():
    envelope = synthetic_envelope([["safe", "unverified", "safe"], ["failed", "safe", "safe"], ["safe"] * 3])
    assert query(envelope, 0, 5).status == "unverified"
    assert query(envelope, 50, 5).status == "failed"
    assert math.isnan(query(envelope, 50, 5).value) or query(envelope, 50, 5).value > 0
    assert query(envelope, 150, 15).status == "safe"
    all_safe = synthetic_envelope([["safe"] * 3] * 3)
    assert query(all_safe, 100, 10).margin == math.inf
    mixed = synthetic_envelope([["unsafe", "unverified", "safe"], ["safe"] * 3, ["safe"] * 3])
    assert query(mixed, 0, 5).status == "unsafe"


def test_nearest_plan_skips_failed_nodes():
    envelope = synthetic_envelope([["failed", "safe", "safe"], ["safe"] * 3, ["safe"] * 3])
    stored = envelope.nearest_plan(0.0, 0.0)
    assert stored is not None and stored.status == "safe"
    assert (stored.height, stored.speed) in {(0.0, 10 * KT), (100 * FT, 0.0)}
    assert stored.warm_start.primal.dtype == np.float64


def test_envelope_is_read_only(one_unsafe_node):
    with pytest.raises(ValueError):
        one_unsafe_node.status[0, 0] = "safe"
    with pytest.raises(ValueError):
        one_unsafe_node.value[0, 0] = -1.0
    metadata = one_unsafe_node.metadata
    metadata["power_fraction"] = 1.0
    assert one_unsafe_node.power_fraction == 0.0


# --- parallel, Dask, interruption, sweeps ----------------------------------------------------------------


def test_local_processes_via_cli_equal_the_serial_run(small, tmp_path):
    out = tmp_path / "two_workers.npz"
    result = run_cli("envelope", "compute", "--heights-ft", HEIGHTS_FT, "--speeds-kt", SPEEDS_KT, "--workers", "2",
                     "--out", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr
    parallel = load_envelope(out)
    assert_same_results(small, parallel)
    command = parallel.metadata["command"]
    assert command.startswith("helireach envelope compute") and "--workers 2" in command
    assert "2 local worker processes" in parallel.metadata["compute"]["executor"]


def test_dask_cluster_run_equals_the_local_run(small, small_job, tmp_path):
    distributed = pytest.importorskip("distributed")
    from helireach_ros.core.envelope.workers import make_executor

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:  # fmt: skip
        executor = make_executor(scheduler=cluster.scheduler_address)
        try:
            on_dask = compute_envelope(small_job, executor, out_path=tmp_path / "dask.npz")
        finally:
            executor.close()
    assert "Dask scheduler" in on_dask.metadata["compute"]["executor"]
    assert_same_results(small, on_dask)


def test_ctrl_c_leaves_a_partial_file_and_resume_finishes_it(small, tmp_path):
    out = tmp_path / "interrupted.npz"
    command = [sys.executable, "-m", "helireach_ros.cli.main", "envelope", "compute", "--heights-ft", HEIGHTS_FT,
               "--speeds-kt", SPEEDS_KT, "--workers", "1", "--out", str(out)]  # fmt: skip
    errors = interrupt_cli(command, "sweep: 4/12")  # one line per finished column
    assert "--resume" in errors
    with pytest.raises(EnvelopeError, match="partial"):
        load_envelope(out)
    partial = read_envelope_file(out, allow_partial=True)
    assert not partial.complete
    refused = run_cli("envelope", "compute", "--heights-ft", HEIGHTS_FT, "--speeds-kt", SPEEDS_KT, "--workers", "1",
                      "--out", str(out))  # fmt: skip
    assert refused.returncode == 2 and "--resume" in refused.stderr
    resumed = run_cli("envelope", "compute", "--heights-ft", HEIGHTS_FT, "--speeds-kt", SPEEDS_KT, "--workers", "1",
                      "--out", str(out), "--resume")  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming" in resumed.stderr
    assert_same_results(small, load_envelope(out))


def test_sweep_over_weights_writes_one_file_per_combination(airframe, tmp_path):
    folder = tmp_path / "sweep"
    result = run_cli("envelope", "compute", "--heights-ft", "300:400:2", "--speeds-kt", "40:50:2", "--workers", "1",
                     "--weights-lb", "15000,17000", "--out", str(folder), "--quiet")  # fmt: skip
    assert result.returncode == 0, result.stderr
    files = sorted(folder.glob("*.npz"))
    assert [path.name for path in files] == [
        "uh60a_class_15000lb_da0ft_pf0.npz",
        "uh60a_class_17000lb_da0ft_pf0.npz",
    ]
    lighter = airframe.with_conditions(gross_weight=15000 * 4.4482216152605)
    assert load_envelope(files[0], airframe=lighter).status.shape == (2, 2)
    with pytest.raises(EnvelopeError):
        load_envelope(files[1], airframe=lighter)


def test_progress_draws_a_bar_on_a_terminal_and_lines_otherwise():
    from helireach_ros.core.envelope.progress import Progress
    from helireach_ros.core.envelope.workers import make_executor

    terminal, log = io.StringIO(), io.StringIO()
    for stream, interactive in ((terminal, True), (log, False)):
        progress = Progress(stream, interactive=interactive)
        progress.start("sweep", 20)
        for _ in range(20):
            progress.advance()
        progress.finish()
    assert "\r" in terminal.getvalue() and "[" + "#" * 30 + "] 20/20" in terminal.getvalue()
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and lines[-1].startswith("sweep: 20/20 (100 %)")
    assert 2 <= len(lines) <= 12  # about every 10 %, not every node
    with pytest.raises(ValueError):
        make_executor(workers=0)


def test_a_worker_that_dies_ends_the_computation_with_an_error_not_a_wait():
    """A worker process that ends abruptly (here ``os._exit``; seen: a segmentation fault in native code) fails its
    tasks at once with an error, which ends the computation (multiprocessing.Pool replaced such a worker and waited
    for its lost task for ever)."""
    import os

    from helireach_ros.core.envelope.workers import WorkerDiedError, make_executor

    executor = make_executor(workers=2)
    try:
        assert sorted(executor.map_unordered(abs, [(-3,), (4,), (-5,)])) == [3, 4, 5]
        with pytest.raises(WorkerDiedError, match="worker process died"):
            list(executor.map_unordered(os._exit, [(1,), (1,)]))
    finally:
        executor.abort()


def test_range_and_list_parsing():
    assert parse_range("0:800:41", FT)[1] == pytest.approx(20 * FT)
    for bad in ("0:800", "800:0:5", "0:800:1", "a:b:c", "0:nan:3"):
        with pytest.raises(ValueError):
            parse_range(bad)
    assert parse_list("14000, 16000") == [14000.0, 16000.0]
    with pytest.raises(ValueError):
        parse_list("14000,heavy")


# --- CLI query and plot ----------------------------------------------------------------------------------


def test_cli_query_json(small_file):
    result = run_cli("envelope", "query", str(small_file), "--height-ft", "200", "--speed-kt", "0", "--json")
    assert result.returncode == 1, result.stderr  # not safe, like helireach plan
    answer = json.loads(result.stdout)
    assert answer["status"] == "unsafe" and answer["value"] > 0 and answer["margin"] < 0
    outside_run = run_cli("envelope", "query", str(small_file), "--height-ft", "900", "--speed-kt", "0", "--json")
    outside = json.loads(outside_run.stdout)
    assert outside["status"] == "outside" and outside["margin"] is None and outside_run.returncode == 1
    text = run_cli("envelope", "query", str(small_file), "--height-ft", "600", "--speed-kt", "60")
    assert text.returncode == 0 and "safe" in text.stdout


def test_cli_query_refuses_a_corrupt_file(small_file, tmp_path):
    corrupt = tmp_path / "half.npz"
    corrupt.write_bytes(small_file.read_bytes()[:5000])
    result = run_cli("envelope", "query", str(corrupt), "--height-ft", "200", "--speed-kt", "0", "--json")
    assert result.returncode == 2 and "half.npz" in result.stderr and result.stdout == ""


def test_plot_writes_the_diagram_with_a_track(small, tmp_path):
    import matplotlib.image

    track = np.array([[500 * FT, 55 * KT], [300 * FT, 40 * KT], [100 * FT, 20 * KT], [0.0, 2 * KT]])
    path = plot_envelope(small, tmp_path / "hv.png", track=track, title_extra="test")
    image = matplotlib.image.imread(path)
    assert image.shape[0] > 400 and image.shape[1] > 600
    with pytest.raises(ValueError, match="N x 2"):
        plot_envelope(small, tmp_path / "bad.png", track=np.zeros(3))
    polygons, segments = boundary_geometry(small)
    assert polygons and segments
    cli = run_cli("envelope", "plot", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "x.png"))
    assert cli.returncode == 2 and not (tmp_path / "x.png").exists()


def test_sweep_warm_through_unsafe_nodes_classifies_like_the_legacy_sweep(airframe, settings):
    """The sweep does not restart cold after every not-safe node; the classification is unchanged.

    A grid through the hover unsafe band (50 ft steps) has nodes deep inside the band, whose warm answers
    from the unsafe node below are kept, and nodes near its edges, which are solved cold as before.
    """
    heights, speeds = parse_range("0:400:9", FT), parse_range("0:20:2", KT)  # 20 kt: above the touchdown limit
    assert speeds[1] > airframe.limits.max_forward_speed
    current = compute_envelope(EnvelopeJob(airframe, settings, 0.0, heights, speeds))
    legacy = compute_envelope(EnvelopeJob(airframe, settings, 0.0, heights, speeds, legacy_sweep=True))
    assert np.any(current.status == "unsafe") and np.any(current.status == "safe")
    assert np.array_equal(current.status, legacy.status)
    new, old = current.metadata["compute"]["counters"], legacy.metadata["compute"]["counters"]
    assert new["sweep_warm_from_not_safe"] > 0 and old["sweep_warm_from_not_safe"] == 0
    cold = {
        name: counters["sweep_solves"] - counters["sweep_warm_solves"] + counters["sweep_guesses_replaced_cold"]
        for name, counters in (("current", new), ("legacy", old))
    }
    assert cold["current"] < cold["legacy"], (cold, new, old)
    kept = current.arrays["warm_from_not_safe"]
    assert np.all(current.status[kept] == "unsafe") and np.all(current.value[kept] >= 0.25)
    assert current.metadata["refinement"]["sweep"] == "warm through not-safe nodes"
    assert {"sweep", "boundary"} <= set(current.metadata["compute"]["phase_ipopt_s"])
    # a ground node's plan (it touches down at once) starts no sweep node: the node above the ground is cold,
    # also above a safe ground node (0 kt), which the legacy sweep warm-starts from
    job = EnvelopeJob(airframe, settings, 0.0, heights, speeds)
    column, legacy_column = (
        _sweep_column(sweep_job, 0)[-1] for sweep_job in (job, dataclasses.replace(job, legacy_sweep=True))
    )
    assert heights[0] == 0.0 and column[0].status == legacy_column[0].status == STATUS_CODES["safe"]
    assert not column[1].warm_started and legacy_column[1].warm_started and column[2].warm_started
    # not-safe NLP answers are not replayed (a replay cannot change their status); every safe one is, and lands;
    # on the ground at 20 kt the replay alone decides (no NLP)
    replayed, solved = np.isfinite(current.arrays["replay_value"]), current.arrays["iterations"] > 0
    assert np.array_equal(replayed[solved], (current.status == "safe")[solved]), current.status
    assert current.status[0, 1] == "unsafe" and not solved[0, 1] and replayed[0, 1]
    # such a node stores no plan, and the nearest plan (warm start, fallback) near it is a neighbour's, flyable
    assert np.all(np.isnan(current.arrays["plan_control_times"][0, 1])) and not current.has_stored_plan(0, 1)
    assert current.has_stored_plan(0, 0)  # the safe ground node at 0 kt was solved: its plan is stored
    nearest = current.nearest_plan(0.0, speeds[1])
    assert (nearest.height, nearest.speed) != (0.0, speeds[1]) and np.all(np.isfinite(nearest.control_times))
    assert np.all(current.arrays["verified"][current.status == "safe"])
    assert np.all(np.isfinite(legacy.arrays["replay_value"][legacy.status == "unsafe"]))


def test_a_computed_envelope_records_where_its_answers_hold(small):
    from helireach_ros.core.envelope.domain import ValidityDomain

    assert small.metadata["validity_domain"] == ValidityDomain().to_metadata()
    assert ValidityDomain.from_metadata(small.metadata) == ValidityDomain()


def test_a_stored_control_function_with_a_delay_segment_warm_starts_after_it(airframe, settings):
    planner = get_planner(airframe, settings.replace(reaction_delay_s=0.5))
    node_state = initial_state_after_failure(airframe, 600 * FT, 60 * KT)
    stored = planner.plan(node_state)
    assert stored.control_times[1] == pytest.approx(0.5)  # the delay segment leads the stored function
    from_controls = ControlFunctionWarmStart(
        node_state.as_array(), stored.control_times, stored.control_values, reaction_delay_s=0.5
    )
    state = initial_state_after_failure(airframe, 590 * FT, 58 * KT)
    warm = planner.plan(state, warm_start=from_controls)
    assert warm.solver.warm_started and warm.solver.success
    assert warm.status == planner.plan(state).status


def test_a_sweep_over_winds_writes_an_hv_diagram_per_wind_that_only_that_wind_accepts(airframe, tmp_path, context):
    """``--headwinds-kt``: one file per wind (calm keeps its name); the status node with the aircraft parameter
    ``headwind`` holds the file of its wind and refuses the calm one, saying which wind each was made for."""
    from rclpy.parameter import Parameter

    from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode

    folder = tmp_path / "winds"
    result = run_cli("envelope", "compute", "--heights-ft", "300:400:2", "--speeds-kt", "40:50:2", "--workers", "1",
                     "--headwinds-kt=0,15", "--out", str(folder), "--quiet")  # fmt: skip
    assert result.returncode == 0, result.stderr
    calm_file = folder / "uh60a_class_16000lb_da0ft_pf0.npz"
    windy_file = folder / "uh60a_class_16000lb_da0ft_hw+15kt_pf0.npz"
    assert sorted(path.name for path in folder.glob("*.npz")) == sorted([calm_file.name, windy_file.name])
    windy = airframe.with_conditions(headwind=15 * KT)
    assert load_envelope(windy_file, airframe=windy).status.shape == (2, 2)
    with pytest.raises(EnvelopeError, match="calm"):
        load_envelope(calm_file, airframe=windy)
    for envelope_file, held in ((windy_file, True), (calm_file, False)):
        overrides = [Parameter("envelope_file", value=str(envelope_file)), Parameter("headwind", value=15 * KT)]
        node = EnvelopeStatusNode(context=context, parameter_overrides=overrides)
        try:
            assert (node.envelope is not None) == held
        finally:
            node.destroy_node()


def test_a_warm_and_a_cold_answer_combine_to_safe_only_on_a_verified_plan_and_never_over_unsafe():
    """:func:`_checked`: unsafe from either start wins; otherwise safe on whichever start's plan landed in the
    replay (the cold one if both); a warm start from a not-safe plan is a guess that the cold answer replaces."""
    codes = STATUS_CODES

    def answer(status: str, value: float, *, warm: bool = False, guess: bool = False) -> _Solution:
        safe = status == "safe"
        return _Solution(codes[status], value, 10.0, value, safe, 20, 1.0, warm, warm_from_not_safe=guess)

    warm_safe, cold_safe = answer("safe", -0.10, warm=True), answer("safe", -0.08)
    warm_unverified, cold_unverified = answer("unverified", -0.12, warm=True), answer("unverified", -0.09)
    warm_unsafe, cold_unsafe = answer("unsafe", 0.05, warm=True), answer("unsafe", 0.02)
    assert _checked(warm_safe, cold_safe) is cold_safe
    assert _checked(warm_safe, cold_unverified) is warm_safe
    assert _checked(warm_unverified, cold_safe) is cold_safe
    assert _checked(warm_unverified, cold_unverified) is cold_unverified  # the larger value
    assert _checked(warm_safe, cold_unsafe) is cold_unsafe and _checked(warm_unsafe, cold_safe) is warm_unsafe
    assert _checked(warm_unsafe, cold_unsafe) is warm_unsafe  # the larger value
    guess = answer("safe", -0.10, warm=True, guess=True)
    assert _checked(guess, cold_unverified) is cold_unverified and _checked(guess, cold_unsafe) is cold_unsafe
