"""Boundary-following refinement: the full grid's answers for fewer solves, every safe node on its own
replay-verified plan, slice by slice in 3-D, resumable after Ctrl-C, refused on grids it cannot refine.

The grid (100-500 ft x 0-90 kt, 5 x 7 nodes) is chosen so that one refinement level meets every kind of coarse
cell: corners all safe, all unsafe, and disagreeing.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from test_envelope import interrupt_cli

from helireach_ros.core.aircraft.model import trim_controls
from helireach_ros.core.envelope.compute import EnvelopeJob, compute_envelope
from helireach_ros.core.envelope.data import load_envelope
from helireach_ros.core.envelope.grid import parse_range
from helireach_ros.core.envelope.refinement import REFINEMENT_ARRAY, NodeOrigin, classify, corners
from helireach_ros.core.envelope.workers import make_executor
from helireach_ros.core.evidence.replay import replay_controls
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.units import FT, KT

HEIGHTS_FT, SPEEDS_KT = "100:500:5", "0:90:7"
SAFE, UNSAFE, UNVERIFIED = 0, 1, 2


def _solves(envelope) -> int:
    counters = envelope.metadata["compute"]["counters"]
    return sum(counters[name] for name in ("sweep_solves", "cold_rechecks", "bisection_solves", "interior_solves"))


@pytest.fixture(scope="module")
def full_and_refined(airframe, settings):
    job = EnvelopeJob(airframe, settings, 0.0, parse_range(HEIGHTS_FT, FT), parse_range(SPEEDS_KT, KT))
    return compute_envelope(job), compute_envelope(dataclasses.replace(job, refine_levels=1))


def test_the_refined_grid_is_never_safer_than_the_full_grid_without_its_own_verified_plan(full_and_refined):
    full, refined = full_and_refined
    origin = refined.arrays[REFINEMENT_ARRAY]
    assert {int(NodeOrigin.INTERIOR), int(NodeOrigin.INFERRED_UNSAFE)} <= set(np.unique(origin).tolist())
    safer = (refined.status == "safe") & (full.status != "safe")
    assert np.all(np.isin(origin[safer], (NodeOrigin.INTERIOR, NodeOrigin.INTERPOLATED)))
    assert np.all(refined.arrays["verified"][refined.status == "safe"])
    assert _solves(refined) < _solves(full)
    assert refined.metadata["refinement"]["boundary_following_levels"] == 1
    assert REFINEMENT_ARRAY not in full.arrays


def test_every_interior_node_lands_on_its_own_stored_plan_in_the_replay(full_and_refined, airframe, settings):
    _, refined = full_and_refined
    planner = get_planner(airframe, settings)
    interior = np.argwhere(refined.arrays[REFINEMENT_ARRAY] == NodeOrigin.INTERIOR)
    assert interior.size
    for row, column in interior:
        assert refined.status[row, column] == "safe"
        plan = refined.stored_plan(int(row), int(column))
        start = refined.arrays["plan_initial_state"][row, column]
        assert start[3] == pytest.approx(refined.heights[row]) and start[1] == pytest.approx(refined.speeds[column])
        replay = replay_controls(planner.airframe, planner.settings, start, plan)
        assert replay.lands_within_limits, (row, column, replay.value)


def test_a_fine_grid_keeps_interior_nodes_on_their_corners_mean_plan_where_it_lands(airframe, settings):
    """10 ft x 2.5 kt apart (the 81 x 49 grid's spacing) in a safe region, the corners' mean plan lands from most
    nodes' own states: those nodes are safe on it without a solve, each on a plan that starts from its own trim and
    lands in the replay; the statuses are the full grid's."""
    job = EnvelopeJob(airframe, settings, 0.0, parse_range("720:760:5", FT), parse_range("22.5:32.5:5", KT))
    full, refined = compute_envelope(job), compute_envelope(dataclasses.replace(job, refine_levels=1))
    assert np.array_equal(full.status, refined.status)
    counters = refined.metadata["compute"]["counters"]
    assert counters["interior_replays"] == counters["interior_interpolated"] + counters["interior_solves"]
    assert counters["interior_interpolated"] > 0 and _solves(refined) < _solves(full)
    planner = get_planner(airframe, settings)
    interpolated = np.argwhere(refined.arrays[REFINEMENT_ARRAY] == NodeOrigin.INTERPOLATED)
    assert len(interpolated) == counters["interior_interpolated"]
    for row, column in interpolated:
        assert refined.status[row, column] == "safe" and refined.arrays["verified"][row, column]
        assert refined.arrays["iterations"][row, column] == 0
        plan = refined.stored_plan(int(row), int(column))
        start = refined.arrays["plan_initial_state"][row, column]
        assert start[3] == pytest.approx(refined.heights[row]) and start[1] == pytest.approx(refined.speeds[column])
        assert plan.control_values[:, 0] == pytest.approx(trim_controls(planner.airframe, start), rel=1e-6)
        replay = replay_controls(planner.airframe, planner.settings, start, plan)
        assert replay.lands_within_limits and replay.value == pytest.approx(refined.value[row, column], abs=1e-9)


def test_inferred_nodes_are_unsafe_with_their_least_unsafe_corner_and_no_plan(full_and_refined):
    _, refined = full_and_refined
    inferred = np.argwhere(refined.arrays[REFINEMENT_ARRAY] == NodeOrigin.INFERRED_UNSAFE)
    for row, column in inferred:
        neighbours = corners(int(row), int(column))
        assert all(refined.status[r, c] == "unsafe" for r, c in neighbours)
        assert refined.value[row, column] == min(refined.value[r, c] for r, c in neighbours) > 0.0
        assert np.all(np.isnan(refined.arrays["plan_control_times"][row, column]))
        assert not refined.has_stored_plan(int(row), int(column))


def test_classify_takes_a_node_only_where_every_enclosing_cell_agrees():
    codes = np.full((5, 5), -1)
    codes[::2, ::2] = [[SAFE, UNVERIFIED, UNSAFE], [SAFE, SAFE, UNSAFE], [UNSAFE, UNSAFE, UNSAFE]]
    interior, inferred = classify(codes, 1, (SAFE, UNVERIFIED), UNSAFE)
    # (1, 2) and (2, 1) also border a cell with an unsafe corner
    assert np.argwhere(interior).tolist() == [[0, 1], [1, 0], [1, 1]] and not inferred.any()
    codes[::2, ::2] = [[SAFE, SAFE, SAFE], [SAFE, UNSAFE, UNSAFE], [SAFE, UNSAFE, UNSAFE]]
    interior, inferred = classify(codes, 1, (SAFE, UNVERIFIED), UNSAFE)
    assert np.argwhere(inferred).tolist() == [[3, 3], [3, 4], [4, 3]] and not interior.any()
    # two levels: the step-2 lattice's new nodes come from the step-4 lattice, the rest are left alone
    coarse = np.full((5, 5), -1)
    coarse[::4, ::4] = SAFE
    interior, inferred = classify(coarse, 2, (SAFE, UNVERIFIED), UNSAFE)
    assert np.argwhere(interior).tolist() == [[0, 2], [2, 0], [2, 2], [2, 4], [4, 2]] and not inferred.any()


def _cli(*arguments: str) -> list[str]:
    return [sys.executable, "-m", "helireach_ros.cli.main", "envelope", "compute", "--heights-ft", HEIGHTS_FT,
            "--speeds-kt", SPEEDS_KT, "--workers", "1", *arguments]  # fmt: skip


def test_an_interrupted_refinement_resumes_to_the_same_envelope(full_and_refined, tmp_path):
    _, refined = full_and_refined
    out = tmp_path / "refined.npz"
    interrupt_cli(_cli("--refine-levels", "1", "--out", str(out)), "interior: 1/")
    unrefined = subprocess.run(_cli("--out", str(out), "--resume"), capture_output=True, text=True, timeout=120)
    assert unrefined.returncode == 2 and "refinement level" in unrefined.stderr
    resumed = subprocess.run(_cli("--refine-levels", "1", "--out", str(out), "--resume"), capture_output=True,
                             text=True, timeout=300)  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming" in resumed.stderr
    stored, computed = load_envelope(out).arrays, refined.arrays
    assert set(stored) == set(computed)
    different = [
        name for name in stored
        if name != "solve_time_ms" and not np.array_equal(stored[name], computed[name], equal_nan=True)
    ]  # fmt: skip
    assert different == []


def test_a_grid_the_levels_cannot_halve_is_refused(airframe, settings, tmp_path):
    with pytest.raises(ValueError, match="2\\^2 k \\+ 1"):
        EnvelopeJob(airframe, settings, 0.0, parse_range("0:800:11", FT), parse_range("0:120:9", KT), refine_levels=2)
    refused = subprocess.run(
        _cli("--refine-levels", "2", "--out", str(tmp_path / "x.npz")), capture_output=True, text=True, timeout=120
    )
    assert refused.returncode == 2 and "2^2 k + 1" in refused.stderr


def test_a_3d_envelope_is_refined_slice_by_slice_on_worker_processes(full_and_refined, airframe, settings):
    """Each climb slice of a refined 3-D envelope is the refined 2-D envelope of its climb rate (here on two local
    worker processes against the serial 2-D run: the answer does not depend on where a task ran)."""
    _, level = full_and_refined
    job = EnvelopeJob(airframe, settings, 0.0, parse_range(HEIGHTS_FT, FT), parse_range(SPEEDS_KT, KT),
                      climb_rates=(-1000 * FT / 60.0, 0.0), refine_levels=1)  # fmt: skip
    executor = make_executor(2)
    try:
        stacked = compute_envelope(job, executor)
    finally:
        executor.close()
    origin = stacked.arrays[REFINEMENT_ARRAY]
    assert stacked.is_3d and origin.shape == stacked.status.shape
    level_slice, level_2d = stacked.slice(1).arrays, level.arrays
    different = [
        name for name in level_2d
        if name != "solve_time_ms" and not np.array_equal(level_slice[name], level_2d[name], equal_nan=True)
    ]  # fmt: skip
    assert different == []
    assert np.any(origin[0] != NodeOrigin.GRID) and np.all(stacked.arrays["verified"][stacked.status == "safe"])
