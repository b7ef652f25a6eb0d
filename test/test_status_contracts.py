"""The DiagnosticStatus contracts (core/status_contracts.py): every key is documented on its topic's msg_docs page,
what a producer writes reads back the same, and reading never guesses (unknown flags, garbled numbers and partial
vectors are None)."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.fallback import fallback_plan
from helireach_ros.core.policies.failure_episode import EpisodePhase, EpisodeState, FailureEpisode
from helireach_ros.core.policies.plan_status import (
    PlannerIdentity,
    episode_end_report,
    fallback_report,
    no_plan_report,
    robust_report,
)
from helireach_ros.core.policies.safety_status import live_evidence, plan_evidence
from helireach_ros.core.status_contracts import (
    ROBUST_PENDING,
    LiveVerdictValues,
    PlanStatusValues,
    RobustVerdictValues,
    SafetyStatusValues,
    StatusContract,
    TouchdownValues,
)
from helireach_ros.core.status_values import format_value
from helireach_ros.core.units import FT, KT

MSG_DOCS = Path(__file__).resolve().parent.parent / "msg_docs"
CONTRACTS: tuple[type[StatusContract], ...] = (
    PlanStatusValues,
    LiveVerdictValues,
    RobustVerdictValues,
    TouchdownValues,
    SafetyStatusValues,
)
S = 1_000_000_000


def formatted(values: Mapping[str, Any]) -> dict[str, str]:
    """Values as a message carries them (what ``diagnostic_status`` writes, what a consumer receives)."""
    return {name: format_value(value) for name, value in values.items()}


def documented_keys(topic: str) -> set[str]:
    """Every backticked word of a topic's msg_docs page (keys are written `like_this`)."""
    page = MSG_DOCS / (topic.strip("/").replace("/", "_") + ".md")
    return set(re.findall(r"`([a-z_0-9]+)`", page.read_text(encoding="utf-8")))


def example(contract: type[StatusContract]) -> StatusContract:
    """A contract with every field set to a value of its kind (distinct numbers, both booleans)."""
    values = {}
    for index, field in enumerate(dataclasses.fields(contract)):  # type: ignore[arg-type]
        kind = field.metadata["kind"]
        values[field.name] = {
            "bool": index % 2 == 0,
            "float": 0.1 + index / 7.0,
            "int": 1_000_000_000_123 + index,
            "str": f"text {index}; with spaces",
            "robust": ROBUST_PENDING,
            "vector": tuple(index + part / 3.0 for part in range(len(field.metadata["keys"]))),
        }[kind]
    return contract(**values)


@pytest.mark.parametrize("contract", CONTRACTS, ids=lambda contract: contract.__name__)
def test_every_key_of_a_contract_is_documented_on_its_topics_page(contract: type[StatusContract]) -> None:
    keys = contract.keys()
    assert len(set(keys)) == len(keys)
    assert set(keys) <= documented_keys(contract.topic)


@pytest.mark.parametrize("contract", CONTRACTS, ids=lambda contract: contract.__name__)
def test_what_a_producer_writes_a_consumer_reads_back(contract: type[StatusContract]) -> None:
    written = example(contract)
    assert contract.from_values(formatted(written.to_values())) == written
    assert contract.from_values({}) == contract()  # nothing sent: nothing known
    assert contract().to_values() == {}


def test_reading_never_guesses_a_flag_a_number_or_a_partial_vector() -> None:
    garbled = {"safe": "True", "verified": "1", "fallback": "yes", "standby": "", "robust": "maybe", "value": "high",
               "replan_index": "0.5", "initial_thrust_coefficient": "0.01"}  # fmt: skip
    plan = PlanStatusValues.from_values(garbled)
    assert (plan.safe, plan.verified, plan.fallback, plan.standby, plan.robust) == (None,) * 5
    assert (plan.value, plan.replan_index, plan.initial_control) == (None, None, None)
    assert not plan.replay_verified_safe and not plan.is_fallback
    assert PlanStatusValues.from_values({"robust": "pending"}).robust == ROBUST_PENDING
    assert RobustVerdictValues.from_values({"robust": "false"}).robust is False
    nan = PlanStatusValues.from_values({"value": "nan"}).value
    assert nan is not None and nan != nan  # NaN is a number (not known to be finite), not a missing value


@pytest.fixture(scope="module")
def failure() -> FailureEpisode:
    return FailureEpisode(3, 10 * S, 10 * S + 5_000)


def test_the_planners_reports_read_back_through_the_contracts(failure: FailureEpisode) -> None:
    airframe = load_airframe("uh60a_class")
    state = initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()
    identity = PlannerIdentity(airframe.name, airframe.gross_weight, airframe.density_altitude)
    fallback = fallback_report(
        fallback_plan(state, airframe, load_settings()), identity=identity, failure=failure, state=state,
        stamp_ns=11 * S, reason="deadline", lateness=None, latency_ms=250.0,
    )  # fmt: skip
    read = PlanStatusValues.from_values(formatted(fallback.values))
    assert (read.status, read.safe, read.fallback, read.failure_stamp_ns, read.state_stamp_ns) == (
        "fallback", False, True, 10 * S, 11 * S,
    )  # fmt: skip
    assert read.initial_state == pytest.approx(tuple(state)) and read.late is False
    assert read.gross_weight == read.planned_gross_weight == airframe.gross_weight
    evidence = plan_evidence(formatted(fallback.values), 10 * S)
    assert evidence is not None and evidence.status == "fallback" and not evidence.verified
    assert plan_evidence(formatted(fallback.values), 9 * S) is None  # another episode's plan
    episode = EpisodeState(phase=EpisodePhase.LANDED, episode_id=1, started_ns=10 * S, ended_ns=30 * S)
    for report in (no_plan_report(failure, "no state"), episode_end_report(failure, EpisodePhase.LANDED, episode, 0)):
        read = PlanStatusValues.from_values(formatted(report.values))
        assert read.safe is False and read.fallback is False and read.failure_id == 3
    pending = robust_report((3, 10 * S, 11 * S), None, "corners")
    verdict = RobustVerdictValues.from_values(formatted(pending.values))
    assert (verdict.robust, verdict.design, verdict.failure_id, verdict.state_stamp_ns) == (
        ROBUST_PENDING, "corners", 3, 11 * S,
    )  # fmt: skip


def test_live_evidence_needs_a_status_and_a_state_stamp_and_a_readable_value() -> None:
    values = formatted(LiveVerdictValues(status="safe", value=-0.2, verified=True, state_stamp_ns=10 * S).to_values())
    evidence = live_evidence(values, now_ns=10 * S + S // 10, max_age_s=0.5)
    assert (
        evidence is not None and evidence.verified and evidence.current and evidence.state_age_s == pytest.approx(0.1)
    )
    assert live_evidence({**values, "value": "low"}, now_ns=10 * S, max_age_s=0.5) is None
    assert live_evidence({key: text for key, text in values.items() if key != "state_stamp_ns"}, 10 * S, 0.5) is None
    assert not live_evidence({**values, "verified": "1"}, 10 * S, 0.5).verified  # type: ignore[union-attr]
