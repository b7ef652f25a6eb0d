"""The shipped uh60a_class total-power-loss envelope (3-D: seven climb slices): it loads for today's airframe and
settings, has the expected H-V shape, every safe node is verified, and a sample of nodes recomputes to the stored
answers.

If the airframe file or config/planner.yaml changes, the loading test fails on purpose: recompute the file
with the command recorded in its metadata.
"""

from __future__ import annotations

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.envelope.data import (
    FORMAT_VERSION_ANSWERS,
    Envelope,
    default_envelope_path,
    load_envelope,
)
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.units import FT, KT

FPM = FT / 60.0


@pytest.fixture(scope="module")
def shipped_3d():
    """The shipped file, loaded with today's airframe and planner settings (a mismatch fails here)."""
    return load_envelope(
        default_envelope_path(), airframe=load_airframe("uh60a_class"), settings=load_settings(), power_fraction=0.0
    )


@pytest.fixture(scope="module")
def shipped(shipped_3d):
    """Its level-flight slice: the classic H-V diagram."""
    return shipped_3d.slice(shipped_3d.nearest_slice(0.0))


def test_shipped_file_is_compact_3d_and_made_by_the_cli(shipped_3d):
    # the answers and the plans' control functions, not IPOPT's solution (docs/decisions/warm-start-storage.md)
    assert default_envelope_path().stat().st_size <= 2 * 1024 * 1024
    assert shipped_3d.format_version == FORMAT_VERSION_ANSWERS and shipped_3d.solver_state is None  # no cache here
    command = shipped_3d.metadata["command"]
    assert command.startswith("helireach envelope compute") and "--airframe uh60a_class" in command
    assert "--dask-local" in command or "--workers" in command  # in parallel: Dask, or local processes
    assert shipped_3d.complete and shipped_3d.is_3d
    assert shipped_3d.status.shape == (7, 41, 25)
    assert np.allclose(shipped_3d.climb_rates / FPM, [-2000, -1500, -1000, -500, 0, 750, 1500])
    assert np.allclose(shipped_3d.heights[[0, -1]] / FT, [0, 800])
    assert np.allclose(shipped_3d.speeds[[0, -1]] / KT, [0, 120])


def test_every_safe_node_is_verified_and_values_match_statuses(shipped_3d):
    safe = shipped_3d.status == "safe"
    assert np.all(shipped_3d.arrays["verified"][safe])
    assert np.all(shipped_3d.value[safe] <= 0.0)
    assert np.all(shipped_3d.value[shipped_3d.status == "unsafe"] > 0.0)
    # Solver failures (never safe): none in level flight; in descents only near the ground (h <= 40 ft)
    failed = shipped_3d.status == "failed"
    level = shipped_3d.nearest_slice(0.0)
    assert not np.any(failed[level])
    heights_ft = shipped_3d.heights / FT
    for index in np.flatnonzero(shipped_3d.climb_rates < 0.0):
        assert np.all(heights_ft[np.nonzero(failed[index])[0]] <= 40.0)


def test_every_slice_has_the_hover_band_and_no_unsafe_node_at_cruise_height(shipped_3d):
    """Across the slices: the hover band exists at every climb rate; at 300-800 ft and 60-100 kt no node is unsafe
    or failed at any climb rate (where one is not safe, its flyable plan's replay drifted: unverified, or the
    descent is steeper than the steady autorotation there: no_trim), and in level flight 300-500 ft at 60-90 kt
    (the heart of the safe region) is safe."""
    heights_ft, speeds_kt = shipped_3d.heights / FT, shipped_3d.speeds / KT
    cruise = (heights_ft >= 300) & (heights_ft <= 800), (speeds_kt >= 60) & (speeds_kt <= 100)
    for index in range(len(shipped_3d.climb_rates)):
        status = shipped_3d.status[index]
        assert np.any(status[:, 0] == "unsafe"), index
        assert set(status[cruise[0]][:, cruise[1]].ravel()) <= {"safe", "unverified", "no_trim"}, index
    level = shipped_3d.status[shipped_3d.nearest_slice(0.0)]
    heart = (heights_ft >= 300) & (heights_ft <= 500), (speeds_kt >= 60) & (speeds_kt <= 90)
    assert np.all(level[heart[0]][:, heart[1]] == "safe")


def test_hover_has_a_low_speed_unsafe_band_between_tens_and_hundreds_of_feet(shipped):
    heights_ft = shipped.heights / FT
    hover = shipped.status[:, 0]
    unsafe_rows = np.flatnonzero(hover == "unsafe")
    assert unsafe_rows.size > 0
    assert np.array_equal(unsafe_rows, np.arange(unsafe_rows[0], unsafe_rows[-1] + 1))  # one contiguous band
    bottom_ft, top_ft = heights_ft[unsafe_rows[0]], heights_ft[unsafe_rows[-1]]
    assert 10 <= bottom_ft <= 100
    assert 150 <= top_ft <= 600
    assert not np.any(np.isin(hover[unsafe_rows[-1] + 1 :], ("unsafe", "failed")))  # above the band: no avoid
    # the refined boundary at hover brackets the band from below and above
    at_hover = np.sort(shipped.boundary[shipped.boundary[:, 1] == 0.0][:, 0] / FT)
    assert len(at_hover) == 2
    assert heights_ft[unsafe_rows[0] - 1] <= at_hover[0] < bottom_ft
    assert top_ft < at_hover[1] <= heights_ft[unsafe_rows[-1] + 1]


def test_no_avoid_above_the_band_which_narrows_with_speed_to_the_ground(shipped):
    """The flyable plans' H-V shape: the hover band, no unsafe node above it (where a node is not safe there, its
    plan's replay drifted: unverified, never claimed safe), the band's top falling with speed (the knee), and on
    the ground a node is safe exactly where its speed is within the touchdown limit."""
    heights_ft, speeds_kt = shipped.heights / FT, shipped.speeds / KT
    band_top_ft = heights_ft[shipped.status[:, 0] == "unsafe"].max()
    assert 100.0 <= band_top_ft <= 600.0  # "a few hundred feet"
    high = shipped.status[heights_ft > band_top_ft, :]
    assert not np.any(np.isin(high, ("unsafe", "failed")))
    top = [heights_ft[np.flatnonzero(column == "unsafe")].max(initial=-1) for column in shipped.status.T]
    assert max(top[speed] for speed in np.flatnonzero(speeds_kt >= 90)) <= band_top_ft / 2  # the band narrows
    touchdown_limit_kt = load_airframe("uh60a_class").limits.max_forward_speed / KT
    on_ground = shipped.status[0]
    assert np.array_equal(on_ground == "safe", speeds_kt <= touchdown_limit_kt + 1e-9), on_ground


def test_the_rotor_named_is_the_one_its_plans_flew(shipped):
    assert shipped.rotor_model_text == "momentum rotor, ground effect"
    # the paper method flies the airframe's paper reproduction, whatever rotor the file's airframe has
    settings = dict(shipped.metadata["settings"], method="paper")
    assert Envelope(shipped.arrays, dict(shipped.metadata, settings=settings)).rotor_model_text == "paper rotor"


def test_queries_on_the_shipped_envelope(shipped):
    inside_band = shipped.query(200 * FT, 5 * KT)
    assert inside_band.status == "unsafe" and inside_band.margin < 0
    cruise = shipped.query(400 * FT, 90 * KT)
    assert cruise.status == "safe" and cruise.margin > 20  # beyond the status's default warn margin: SAFE there
    assert shipped.query(900 * FT, 50 * KT).status == "outside"


def test_a_sample_of_nodes_recomputes_to_the_stored_answers(shipped):
    """Cold-solved nodes recompute cold; warm-solved nodes recompute from the stored plan below them (its control
    function: the file holds no solver state, so the sweep's exact start is rebuilt, not read)."""
    airframe = load_airframe("uh60a_class")
    planner = get_planner(airframe, load_settings())
    arrays = shipped.arrays
    warm, checked = arrays["warm_started"], arrays["cold_checked"]
    hover_band = np.flatnonzero(~warm[:, 0] & (shipped.status[:, 0] == "unsafe"))  # solved cold, inside the band
    cold_nodes = [
        (int(hover_band[0]), 0),
        *[tuple(int(i) for i in node) for node in np.argwhere(checked & ~warm & (shipped.status == "safe"))[:2]],
    ]
    # warm nodes whose predecessor's stored plan is still the one the sweep used (it was not re-solved cold)
    plain_warm = np.argwhere(warm & ~checked)
    warm_nodes = [
        (int(row), int(column))
        for row, column in plain_warm
        if row > 0 and warm[row - 1, column] and not checked[row - 1, column]
    ]
    warm_nodes = [warm_nodes[0], warm_nodes[len(warm_nodes) // 2]]
    for row, column in cold_nodes + warm_nodes:
        state = initial_state_after_failure(airframe, shipped.heights[row], shipped.speeds[column])
        start = shipped.stored_plan(row - 1, column).warm_start if (row, column) in warm_nodes else None
        plan = planner.plan(state, warm_start=start)
        assert plan.status == shipped.status[row, column], (row, column)
        # an unsafe node's value is how far its best landing misses: the NLP may end in another local optimum of
        # it (as with another linear solver, test_block_ldl.py), so it agrees relatively
        tolerance = {"abs": 1e-4} if plan.status == "safe" else {"rel": 1e-3}
        assert plan.value == pytest.approx(shipped.value[row, column], **tolerance), (row, column)


def test_a_descent_slice_node_recomputes_to_its_stored_answer(shipped_3d):
    airframe = load_airframe("uh60a_class")
    planner = get_planner(airframe, load_settings())
    index = int(np.flatnonzero(np.isclose(shipped_3d.climb_rates / FPM, -1000))[0])
    descent = shipped_3d.slice(index)
    checked, warm = descent.arrays["cold_checked"], descent.arrays["warm_started"]
    row, column = (int(i) for i in np.argwhere(checked & ~warm & (descent.status == "safe"))[0])
    state = initial_state_after_failure(
        airframe, descent.heights[row], descent.speeds[column], climb_rate=float(shipped_3d.climb_rates[index])
    )
    plan = planner.plan(state)
    assert plan.status == "safe" and plan.value == pytest.approx(descent.value[row, column], abs=1e-4)


def test_the_3d_file_answers_at_the_climb_rate_and_not_beyond_its_axis(shipped_3d):
    assert shipped_3d.query(700 * FT, 100 * KT, climb_rate=-1200 * FPM).status == "safe"  # between two slices
    assert shipped_3d.query(200 * FT, 5 * KT, climb_rate=-700 * FPM).status == "unsafe"
    assert shipped_3d.query(700 * FT, 100 * KT, climb_rate=-2500 * FPM).status == "outside"
    assert shipped_3d.query(700 * FT, 100 * KT, climb_rate=2000 * FPM).status == "outside"


@pytest.mark.slow  # ~4,800 replays
def test_every_safe_nodes_stored_plan_lands_as_stored(shipped_3d):
    """A safe node rests on the plan the file holds: its control function, as stored (float32), flown from the
    node's state through the independent replay, lands within every limit."""
    from helireach_ros.core.evidence.replay import replay_controls

    airframe, settings = load_airframe("uh60a_class"), load_settings()
    initial_states = shipped_3d.arrays["plan_initial_state"]
    failing = []
    for node in np.argwhere(shipped_3d.status == "safe"):
        climb_index, row, column = (int(i) for i in node)
        stored = shipped_3d.stored_plan(row, column, climb_index)  # control times, values, interpolation, T
        replay = replay_controls(airframe, settings, initial_states[climb_index, row, column], stored)
        if not replay.lands_within_limits:
            failing.append(((climb_index, row, column), replay.value))
    assert failing == []
