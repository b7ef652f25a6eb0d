"""Landing solves in worker processes: same answers as in process, dead and hung workers replaced, priorities.

Real worker processes with real IPOPT; workers are killed with real signals.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import time

import numpy as np
import pytest

from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.array_codec import decode_dataclass, encode_dataclass
from helireach_ros.core.planning.planner import (
    ControlFunctionWarmStart,
    LandingPlan,
    WarmStart,
    get_planner,
    plan_landing,
)
from helireach_ros.core.units import FT, KT
from helireach_ros.core.workers.solver_pool import (
    PRIORITY_FAILURE,
    PRIORITY_LIVE,
    SolverPool,
    SolverPoolSettings,
    SolverWorkerError,
)

STATES_FT_KT = [(500, 75), (150, 0), (60, 100)]


@pytest.fixture(scope="module")
def pool(airframe, settings):
    with SolverPool(airframe, settings, SolverPoolSettings(workers=2)) as solver_pool:
        assert solver_pool.wait_ready(120.0, 2), "workers did not start"
        yield solver_pool


def assert_same_dataclass(first, second, path: str = "") -> None:
    for field in dataclasses.fields(first):
        one, other = getattr(first, field.name), getattr(second, field.name)
        where = f"{path}.{field.name}"
        if dataclasses.is_dataclass(one):
            assert_same_dataclass(one, other, where)
        elif isinstance(one, np.ndarray):
            assert one.dtype == other.dtype and np.array_equal(one, other), where
        else:
            assert type(one) is type(other) and one == other, where


def test_a_plan_crosses_the_codec_unchanged(airframe, settings) -> None:
    plan = plan_landing(initial_state_after_failure(airframe, 500 * FT, 75 * KT), airframe, settings)
    assert_same_dataclass(plan, decode_dataclass(LandingPlan, encode_dataclass(plan)))


def test_the_codec_refuses_foreign_or_broken_bytes(airframe, settings) -> None:
    plan = plan_landing(initial_state_after_failure(airframe, 500 * FT, 75 * KT), airframe, settings)
    data = encode_dataclass(plan)
    with pytest.raises(ValueError):
        decode_dataclass(LandingPlan, data[:-10])  # truncated
    with pytest.raises(ValueError, match="missing"):
        decode_dataclass(LandingPlan, encode_dataclass(plan.warm_start))  # another class's fields
    with pytest.raises(ValueError, match="not allowed"):
        header = b'[["primal","|O",[1]]]'
        decode_dataclass(WarmStart, len(header).to_bytes(4, "little") + header + b"\0" * 8)
    with pytest.raises(ValueError):
        decode_dataclass(WarmStart, b"\x80\x04pickle")


@pytest.mark.parametrize(("height_ft", "speed_kt"), STATES_FT_KT)
def test_the_pool_answers_as_the_planner_in_process(pool, airframe, settings, height_ft, speed_kt) -> None:
    state = initial_state_after_failure(airframe, height_ft * FT, speed_kt * KT).as_array()
    local = plan_landing(state, airframe, settings)
    remote = pool.plan(state)
    assert remote.status == local.status
    assert remote.value == pytest.approx(local.value, abs=1e-9)
    assert remote.time_to_land == pytest.approx(local.time_to_land, abs=1e-9)
    assert remote.replay.lands_within_limits == local.replay.lands_within_limits
    warm = pool.plan(state, local.warm_start)
    assert warm.solver.warm_started and warm.status == local.status
    # a stored plan's control function crosses the process boundary too (what an envelope file without the
    # solver state offers), and the worker rebuilds its warm start
    stored = ControlFunctionWarmStart(state, local.control_times, local.control_values)
    rebuilt = pool.plan(state, stored)
    assert rebuilt.solver.warm_started and rebuilt.status == local.status


def test_the_pool_plans_for_the_requested_disturbance(pool, airframe, settings) -> None:
    state = initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()
    disturbance = np.array([0.5, -0.1, 0.3])
    local = get_planner(airframe, settings).plan(state, disturbance=disturbance)
    remote = pool.plan(state, disturbance=disturbance)
    assert np.array_equal(remote.disturbance, disturbance)
    assert remote.value == pytest.approx(local.value, abs=1e-9)
    assert remote.value != pytest.approx(pool.plan(state).value, abs=1e-6)  # the disturbance reached the NLP


def test_a_state_the_planner_refuses_is_a_value_error_and_the_pool_goes_on(pool, airframe) -> None:
    with pytest.raises(ValueError, match="rotor speed"):
        pool.plan(np.array([0.0, 10.0, -1.0, 100.0, 0.0, 0.0]))
    assert pool.plan(initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()).solver.success


def _busy_worker_pid(pool: SolverPool, timeout_s: float = 5.0) -> int:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with pool._lock:
            busy = [worker.process.pid for worker in pool._workers if worker.job is not None]
        if busy:
            return busy[0]
        time.sleep(0.001)
    raise AssertionError("no worker took the job")


def test_a_worker_killed_mid_solve_fails_its_job_at_once_and_is_restarted(pool, airframe) -> None:
    restarts = pool.restarts
    state = initial_state_after_failure(airframe, 700 * FT, 40 * KT).as_array()
    future = pool.submit(state, timeout_s=30.0)  # a cold solve: tens of ms to kill it in
    os.kill(_busy_worker_pid(pool), signal.SIGKILL)
    killed = time.monotonic()
    with pytest.raises(SolverWorkerError, match="died"):
        future.result(timeout=5.0)
    assert time.monotonic() - killed < 1.0
    assert pool.restarts == restarts + 1
    assert pool.wait_ready(120.0, 2), "the replacement worker did not start"
    assert pool.plan(state).solver.success


def test_a_hung_worker_is_killed_after_the_job_timeout_and_restarted(pool, airframe) -> None:
    restarts = pool.restarts
    state = initial_state_after_failure(airframe, 700 * FT, 40 * KT).as_array()
    future = pool.submit(state, timeout_s=0.5)
    os.kill(_busy_worker_pid(pool), signal.SIGSTOP)  # hangs like a solver that never returns
    stopped = time.monotonic()
    with pytest.raises(SolverWorkerError, match=r"no answer within 0\.5 s"):
        future.result(timeout=10.0)
    assert 0.3 < time.monotonic() - stopped < 2.0
    assert pool.restarts == restarts + 1
    assert pool.wait_ready(120.0, 2)


def test_failure_plans_never_wait_for_live_evaluations(pool, airframe) -> None:
    # Four live evaluations, the worker running the first one frozen (SIGSTOP): the other worker stays free of
    # live work, so a failure plan submitted now is solved at once, and no live job spills onto that worker.
    # Freezing the worker makes this independent of how long either solve takes.
    assert pool.wait_ready(120.0, 2)
    live_state = initial_state_after_failure(airframe, 600 * FT, 30 * KT).as_array()
    live = [pool.submit(live_state, priority=PRIORITY_LIVE, timeout_s=60.0) for _ in range(4)]
    live_worker = _busy_worker_pid(pool)
    os.kill(live_worker, signal.SIGSTOP)
    try:
        failure_state = initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()
        failure = pool.submit(failure_state, priority=PRIORITY_FAILURE, timeout_s=30.0)
        failure.result(timeout=30.0)
        assert not any(future.done() for future in live), "a live job ran on the worker kept for failures"
    finally:
        os.kill(live_worker, signal.SIGCONT)
    for future in live:
        future.result(timeout=60.0)
