"""The planner's statuses (core/policies/plan_status.py), without ROS: every key a report carries is documented in its
msg_docs page, and the levels follow the never-optimistic rule (fallbacks, missing plans and unknown verdicts are
never OK)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.estimation.weight_tracking import WeightChoice
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.fallback import fallback_plan
from helireach_ros.core.policies.failure_episode import EpisodePhase, EpisodeState, FailureEpisode, plan_lateness
from helireach_ros.core.policies.live_reachability import LiveVerdict
from helireach_ros.core.policies.plan_status import (
    PlannerIdentity,
    StatusReport,
    episode_end_report,
    fallback_report,
    live_report,
    no_plan_report,
    robust_report,
)
from helireach_ros.core.units import FT, KT

MSG_DOCS = Path(__file__).resolve().parent.parent / "msg_docs"
S = 1_000_000_000


def documented_keys(page: str) -> set[str]:
    """Every backticked word of a msg_docs page (keys are written `like_this`)."""
    return set(re.findall(r"`([a-z_0-9]+)`", (MSG_DOCS / page).read_text(encoding="utf-8")))


@pytest.fixture(scope="module")
def failure() -> FailureEpisode:
    return FailureEpisode(3, 10 * S, 10 * S + 5_000)


def test_a_fallback_is_warn_never_safe_and_every_key_is_documented(failure: FailureEpisode) -> None:
    airframe = load_airframe("uh60a_class")
    state = initial_state_after_failure(airframe, 500 * FT, 75 * KT).as_array()
    fallback = fallback_plan(state, airframe, load_settings())
    identity = PlannerIdentity(airframe.name, airframe.gross_weight, airframe.density_altitude)
    late = plan_lateness(failure.event_stamp_ns, 12 * S, max_message_age=1.0)
    report = fallback_report(
        fallback, identity=identity, failure=failure, state=state, stamp_ns=12 * S, reason="deadline",
        lateness=late, latency_ms=250.0,
    )  # fmt: skip
    assert report.level == "WARN" and report.values["safe"] is False and report.values["fallback"] is True
    assert report.text.startswith("LATE (state 2.0 s after the failure, 1.0 s too late): FALLBACK (not verified)")
    assert report.values["initial_height_m"] == pytest.approx(500 * FT)
    assert report.values["gross_weight_source"] == "file"
    assert set(report.values) <= documented_keys("helireach_plan_status.md")


@pytest.mark.parametrize("outcome", [EpisodePhase.ENDED, EpisodePhase.LANDED])
def test_an_episode_end_and_a_missing_plan_are_never_ok(failure: FailureEpisode, outcome: EpisodePhase) -> None:
    episode = EpisodeState(phase=outcome, episode_id=4, started_ns=10 * S, ended_ns=30 * S, flag=False)
    ended = episode_end_report(failure, outcome, episode, now_ns=31 * S)
    assert ended.level == "WARN" and ended.values["status"] == outcome.value
    assert ended.values["ended_stamp_ns"] == 30 * S
    missing = no_plan_report(failure, "no valid vehicle state")
    assert missing.level == "ERROR" and missing.text == "NO PLAN: no valid vehicle state"
    for report in (ended, missing):
        assert report.values["safe"] is False and report.values["verified"] is False
        assert set(report.values) <= documented_keys("helireach_plan_status.md")


def test_a_live_error_is_unknown_not_ok_and_its_keys_are_documented() -> None:
    state = np.array([5.0, 30.0, 27.0, 150.0, 0.0, 0.0])
    verdict = LiveVerdict("error", float("nan"), state, 9 * S, 10 * S, 12.0, None, "worker died")
    weight = WeightChoice(71_000.0, "file", 0.0, "estimate_weight is false")
    report = live_report(
        verdict, standby=False, weight=weight, configured_weight=71_000.0, power_fraction=0.0, now_ns=11 * S
    )
    assert report == StatusReport("ERROR", "LIVE ERROR: no verdict (worker died)", report.values)
    assert report.values["state_age_s"] == pytest.approx(2.0) and report.values["height_m"] == 150.0
    assert set(report.values) <= documented_keys("helireach_live_reachability.md")


def test_a_pending_robust_verdict_is_stale_and_its_keys_are_documented() -> None:
    report = robust_report((3, 10 * S, 11 * S), None, "resolution-IV corners of 'default' (16)")
    assert report.level == "STALE" and report.values["robust"] == "pending"
    assert set(report.values) <= documented_keys("helireach_robust_verdict.md")
