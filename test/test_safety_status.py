"""The safety status is never wider than its evidence: envelope domain, live verdicts, plans after a failure."""

from __future__ import annotations

import math

import pytest

from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
from helireach_ros.core.envelope.domain import DomainCheck, ValidityDomain
from helireach_ros.core.planning.planner import get_planner
from helireach_ros.core.policies.live_reachability import LiveEvaluator, LiveSettings
from helireach_ros.core.policies.safety_status import (
    EnvelopeEvidence,
    LiveEvidence,
    PlanEvidence,
    decide_safety_status,
    more_conservative,
)
from helireach_ros.core.units import FT, KT

FPM = FT / 60.0
INSIDE = DomainCheck(True, True)
OUTSIDE = DomainCheck(False, True, ("climb rate -2000 ft/min outside -98…+98 ft/min",))
SAFE_LIVE = LiveEvidence("safe", -0.5, True, 0.1, True)
UNSAFE_LIVE = LiveEvidence("unsafe", 0.3, False, 0.1, True)


def decide(**kwargs):
    return decide_safety_status(height=100.0, forward_speed=30.0, **kwargs)


@pytest.fixture(scope="module")
def envelope(airframe, settings):
    return load_envelope(default_envelope_path(), airframe, settings, 0.0)


def test_the_domain_holds_level_trim_at_nominal_rotor_speed(airframe) -> None:
    domain = ValidityDomain()
    omega = airframe.nominal_rotor_speed
    assert domain.check(0.3, omega, omega) == DomainCheck(True, True, ())
    descent = domain.check(-2000 * FPM, omega, omega)
    assert not descent.inside and "climb rate" in descent.reasons[0]
    slow_rotor = domain.check(0.0, 0.95 * omega, omega)
    assert not slow_rotor.inside and "rotor speed 95.0 %" in slow_rotor.reasons[0]
    unknown = domain.check(0.0, None, omega)
    assert unknown.inside and not unknown.known
    assert ValidityDomain.from_metadata({}) == domain  # a file without a recorded domain gets the defaults
    recorded = ValidityDomain(climb_rate_tolerance=1.0, climb_rates=(-5.0, 0.0))
    assert ValidityDomain.from_metadata({"validity_domain": recorded.to_metadata()}) == recorded
    with pytest.raises(ValueError):
        ValidityDomain(rotor_speed_tolerance=-0.1)


def test_inside_the_domain_the_more_conservative_answer_wins() -> None:
    safe_envelope = EnvelopeEvidence("safe", 60.0, False, INSIDE)
    assert decide(envelope=safe_envelope, live=None).level == "OK"
    assert decide(envelope=safe_envelope, live=SAFE_LIVE).level == "OK"
    combined = decide(envelope=safe_envelope, live=UNSAFE_LIVE)
    assert combined.level == "ERROR" and "live" in combined.message
    caution = decide(envelope=EnvelopeEvidence("safe", 5.0, False, INSIDE), live=SAFE_LIVE)
    assert caution.level == "WARN"
    direct = decide(envelope=EnvelopeEvidence("unsafe", -10.0, False, INSIDE), live=SAFE_LIVE)
    assert direct.level == "ERROR"  # the grid says unsafe here, not only between nodes: no override


def test_a_verified_live_safe_overrides_an_envelope_unsafe_only_by_interpolation() -> None:
    decision = decide(envelope=EnvelopeEvidence("unsafe", -3.0, True, INSIDE), live=SAFE_LIVE)
    assert decision.level == "OK" and "only by interpolation" in decision.message and decision.source == "live"
    unverified = LiveEvidence("unverified", -0.2, False, 0.1, True)
    assert decide(envelope=EnvelopeEvidence("unsafe", -3.0, True, INSIDE), live=unverified).level == "ERROR"


def test_outside_the_domain_only_a_live_verdict_may_say_safe() -> None:
    safe_but_outside = EnvelopeEvidence("safe", 60.0, False, OUTSIDE)
    no_live = decide(envelope=safe_but_outside, live=None)
    assert no_live.level == "STALE" and "outside the envelope's domain" in no_live.message
    old_live = decide(envelope=safe_but_outside, live=LiveEvidence("safe", -0.5, True, 3.0, False))
    assert old_live.level == "STALE" and "3.0 s old" in old_live.message
    assert decide(envelope=safe_but_outside, live=SAFE_LIVE).level == "OK"
    assert decide(envelope=safe_but_outside, live=UNSAFE_LIVE).level == "ERROR"
    assert decide(envelope=None, envelope_note="file missing", live=None).level == "STALE"


def test_an_unmeasured_rotor_speed_caps_the_envelope_at_caution() -> None:
    unknown = DomainCheck(True, False, ("rotor speed not measured (the envelope assumes nominal)",))
    decision = decide(envelope=EnvelopeEvidence("safe", 60.0, False, unknown), live=None)
    assert decision.level == "WARN" and "rotor speed not measured" in decision.message


def test_after_a_failure_only_the_current_plan_speaks() -> None:
    safe_envelope = EnvelopeEvidence("safe", 60.0, False, INSIDE)
    assert decide(envelope=safe_envelope, live=SAFE_LIVE, episode="failed").level == "ERROR"  # no plan yet
    verified = PlanEvidence("safe", True, standby=True, time_to_land_s=9.9)
    decision = decide(envelope=None, live=None, episode="failed", plan=verified)
    assert decision.level == "OK" and "standby plan verified" in decision.message
    assert decide(envelope=None, live=None, episode="failed", plan=PlanEvidence("fallback", False)).level == "ERROR"
    late = decide(envelope=None, live=None, episode="failed", plan=PlanEvidence("safe", True, late=True))
    assert late.level == "WARN" and "LATE" in late.message
    assert decide(envelope=safe_envelope, live=None, episode="landed").level == "STALE"
    assert decide(envelope=safe_envelope, live=None, episode="ended").level == "OK"


def test_input_problems_make_any_status_an_error() -> None:
    decision = decide(
        envelope=EnvelopeEvidence("safe", 60.0, False, INSIDE), live=SAFE_LIVE, input_problems=["monitor: flag"]
    )
    assert decision.level == "ERROR" and decision.message.startswith("INPUT QOS")
    assert more_conservative("OK", "STALE") == "STALE" and more_conservative("ERROR", "WARN") == "ERROR"


def test_a_descent_the_level_trim_envelope_calls_safe_is_an_error_with_live_and_stale_without(
    airframe, settings, envelope
) -> None:
    # 40 ft, 85 kt in a 1,800 ft/min descent: the level-trim envelope (the shipped file's level slice) says safe,
    # the ground is ~1.3 s away.
    height, speed, climb = 40 * FT, 85 * KT, -1800 * FPM
    level_trim = envelope.slice(envelope.nearest_slice(0.0))
    query = level_trim.query(height, speed)
    assert query.status == "safe"
    domain = ValidityDomain.from_metadata(level_trim.metadata).check(
        climb, airframe.nominal_rotor_speed, airframe.nominal_rotor_speed
    )
    evidence = EnvelopeEvidence(query.status, query.margin, query.by_interpolation, domain)
    clock_ns = 10**12
    state = initial_state_after_failure(airframe, height, speed, 1.0, climb).as_array()
    verdict = LiveEvaluator(LiveSettings(), get_planner(airframe, settings).plan).evaluate(
        state, clock_ns, clock_ns, lambda: clock_ns
    )
    live = LiveEvidence(verdict.status, verdict.value, verdict.plan.verified, 0.0, True)
    assert decide_safety_status(height=height, forward_speed=speed, envelope=evidence, live=live).level == "ERROR"
    stopped = decide_safety_status(height=height, forward_speed=speed, envelope=evidence, live=None)
    assert stopped.level == "STALE" and "no current live verdict" in stopped.message


def test_the_envelope_query_says_when_its_answer_rests_on_interpolation(envelope) -> None:
    heights, speeds = envelope.heights, envelope.speeds
    on_node = envelope.query(heights[10], speeds[5])
    assert not on_node.by_interpolation
    # Somewhere between a safe and an unsafe node the answer is not-safe by interpolation only.
    found = False
    for row in range(len(heights) - 1):
        for column in range(len(speeds)):
            statuses = {
                envelope.query(heights[row], speeds[column]).status,
                envelope.query(heights[row + 1], speeds[column]).status,
            }
            if statuses == {"safe", "unsafe"}:
                between = envelope.query(0.5 * (heights[row] + heights[row + 1]), speeds[column])
                assert between.status == "unsafe" and between.by_interpolation
                found = True
                break
        if found:
            break
    assert found
    assert math.isnan(envelope.query(-100.0, 0.0).value)


def test_a_robust_verdict_says_so_and_a_node_safe_only_nominally_is_caution() -> None:
    robust = decide(envelope=EnvelopeEvidence("safe", 60.0, False, INSIDE, "robust"), live=None)
    assert robust.level == "OK" and robust.message.startswith("SAFE (robust): margin 60")
    assert robust.values["envelope_verdict"] == "robust" and "envelope_verdict_note" not in robust.values
    nominal_only = decide(envelope=EnvelopeEvidence("not_robust", -10.0, False, INSIDE, "robust"), live=SAFE_LIVE)
    assert nominal_only.level == "WARN"  # the live verdict is nominal too: it cannot lift the caution
    assert "not robust" in nominal_only.message
    fallback = decide(
        envelope=EnvelopeEvidence("safe", 60.0, False, INSIDE, "nominal", "the envelope has no robust verdict"),
        live=None,
    )
    assert fallback.level == "OK" and fallback.message.startswith("SAFE: margin")
    assert fallback.values["envelope_verdict"] == "nominal"
    assert fallback.values["envelope_verdict_note"] == "the envelope has no robust verdict"


def test_after_a_failure_the_plan_ages_with_the_state_and_the_rotor_reading() -> None:
    verified = PlanEvidence("safe", True, time_to_land_s=9.9)
    untracked = decide(
        envelope=None, live=None, episode="failed", plan=verified, state_problem="vehicle state 0.8 s old"
    )
    assert untracked.level == "STALE" and "NOT TRACKED: vehicle state 0.8 s old" in untracked.message
    no_rotor = decide(envelope=None, live=None, episode="failed", plan=verified, rotor_measured=False)
    assert no_rotor.level == "WARN" and "rotor speed not measured" in no_rotor.message
    late = decide(envelope=None, live=None, episode="failed", plan=PlanEvidence("safe", True, late=True),
                  rotor_measured=False)  # fmt: skip
    assert late.level == "WARN" and "LATE" in late.message
    fallback = decide(envelope=None, live=None, episode="failed", plan=PlanEvidence("fallback", False),
                      state_problem="no vehicle state received")  # fmt: skip
    assert fallback.level == "STALE" and fallback.message.startswith("ENGINE FAILURE: FALLBACK")
    assert decide(envelope=None, live=None, episode="failed", plan=verified).level == "OK"
