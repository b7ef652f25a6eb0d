"""The planner node's solvers without ROS (core/workers/planner_backend.py): what it loads, and that a failure's solve
or fallback answers with a plan or a reason, never an exception."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.units import FT, KT
from helireach_ros.core.workers.planner_backend import BackendSettings, PlannerBackend


@pytest.fixture(scope="module")
def reports() -> list[tuple[str, str]]:
    return []


@pytest.fixture(scope="module")
def backend(reports: list[tuple[str, str]]) -> PlannerBackend:
    settings = BackendSettings(solver_workers=0, warm_up=False)
    return PlannerBackend(
        load_airframe("uh60a_class"), load_settings(), settings, lambda *report: reports.append(report)
    )


def test_an_in_process_backend_loads_the_shipped_envelope_and_plans_for_the_files_weight(backend, reports) -> None:
    assert backend.envelope is not None and backend.envelope_note.startswith("envelope ")
    assert backend.pool is None and math.isnan(backend.warm_up_ms) and reports == []
    assert backend.reaction_delay_s == backend.settings.reaction_delay_s
    weight = backend.weight_now(now_ns=0)
    assert (weight.gross_weight, weight.source, weight.reason) == (
        backend.airframe.gross_weight, "file", "estimate_weight is false",
    )  # fmt: skip
    state = initial_state_after_failure(backend.airframe, 500 * FT, 75 * KT).as_array()
    stored = backend.envelope.nearest_plan(state[3], state[1], -state[0])
    plan, error = backend.solve(state, stored.warm_start, gross_weight=backend.airframe.gross_weight)
    assert error == "" and plan is not None and plan.safe and plan.verified
    assert backend.ready_weights() == {backend.airframe.gross_weight}
    fallback = backend.fallback_plan(state)
    assert fallback.kind == "envelope_plan" and fallback.time_to_land > 0.0


def test_a_refused_state_is_a_reason_not_an_exception(backend) -> None:
    plan, error = backend.solve(np.full(6, np.nan), None, gross_weight=backend.airframe.gross_weight)
    assert plan is None and error.startswith("ValueError")


def test_an_unusable_envelope_is_reported_and_the_backend_plans_cold() -> None:
    reports: list[tuple[str, str]] = []
    settings = BackendSettings(envelope_file="/nonexistent/envelope.npz", solver_workers=0, warm_up=False)
    backend = PlannerBackend(load_airframe("uh60a_class"), load_settings(), settings, lambda *r: reports.append(r))
    assert backend.envelope is None and "not usable" in backend.envelope_note
    assert reports == [("warning", backend.envelope_note)]
    off = PlannerBackend(
        load_airframe("uh60a_class"), load_settings(), BackendSettings(envelope_file="none", solver_workers=0,
        warm_up=False), lambda *r: reports.append(r),
    )  # fmt: skip
    assert off.envelope is None and off.envelope_note.startswith("no envelope (disabled)")
    state = initial_state_after_failure(off.airframe, 500 * FT, 75 * KT).as_array()
    assert off.fallback_plan(state).kind == "autorotation_entry"
