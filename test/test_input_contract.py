"""The input contract and QoS-problem bookkeeping without ROS: frames, stamp order, counters, problem lifetime."""

from __future__ import annotations

from helireach_ros.core.policies.input_contract import (
    ACCEPTED,
    INVALID,
    OUT_OF_ORDER,
    WRONG_FRAME,
    FrameContract,
    InputGate,
    StampOrder,
    frame_problems,
)
from helireach_ros.core.policies.qos_problems import INPUT, OUTPUT, QosProblemLog

ODOM = FrameContract("odom", "base_stabilized")
S = 1_000_000_000


def test_frames_must_match_exactly_and_the_problem_names_both() -> None:
    assert frame_problems(ODOM, "odom", "base_stabilized") == []
    problems = frame_problems(ODOM, "map_ned", "base_link_frd")
    assert problems == [
        "frame_id 'map_ned' is not the expected 'odom'",
        "child_frame_id 'base_link_frd' is not the expected 'base_stabilized'",
    ]
    assert frame_problems(ODOM, "/odom", "base_stabilized")  # no silent normalisation
    assert frame_problems(ODOM, "", "base_stabilized")  # an unset frame is not the documented one
    assert frame_problems(FrameContract(), "anything", "at all") == []  # None = not checked


def test_stamps_must_increase_strictly() -> None:
    order = StampOrder()
    assert order.problem(10 * S, 100 * S) == ""
    order.accept(10 * S, 100 * S)
    assert "older than the latest" in order.problem(9 * S, 101 * S)
    assert "1.000 s older" in order.problem(9 * S, 101 * S)
    assert "equals the latest" in order.problem(10 * S, 101 * S)
    assert order.problem(10 * S + 1, 101 * S) == ""


def test_a_receiving_clock_that_jumps_back_resets_the_order() -> None:
    order = StampOrder()
    order.accept(50 * S, 50 * S)
    assert order.problem(1 * S, 60 * S)  # same clock, older stamp: out of order
    assert order.problem(1 * S, 2 * S) == ""  # the local clock restarted (sim time, a looped replay)
    assert order.latest_ns is None


def test_gate_order_of_checks_and_counts() -> None:
    gate = InputGate(ODOM)
    assert gate.judge(10 * S, 10 * S, "odom", "base_stabilized").reason == ACCEPTED
    wrong = gate.judge(11 * S, 11 * S, "map_ned", "base_stabilized", ["height is nan"])
    assert wrong.reason == WRONG_FRAME and not wrong.accepted  # the frame is checked first
    assert "'map_ned'" in wrong.text and "'odom'" in wrong.text
    invalid = gate.judge(5 * S, 12 * S, "odom", "base_stabilized", ["height is nan"])
    assert invalid.reason == INVALID and invalid.problems == ("height is nan",)
    late = gate.judge(9 * S, 13 * S, "odom", "base_stabilized")
    assert late.reason == OUT_OF_ORDER and "older" in late.text
    assert gate.judge(10 * S, 13 * S, "odom", "base_stabilized").reason == OUT_OF_ORDER  # equal: a repeat
    assert gate.counts == {ACCEPTED: 1, WRONG_FRAME: 1, INVALID: 1, OUT_OF_ORDER: 2}


def test_rejected_messages_never_advance_the_latest_stamp() -> None:
    gate = InputGate(ODOM)
    gate.judge(10 * S, 10 * S, "odom", "base_stabilized")
    gate.judge(20 * S, 11 * S, "map_ned", "base_stabilized")  # a wrong frame far in the future
    gate.judge(30 * S, 12 * S, "odom", "base_stabilized", ["stamp in the future"])
    assert gate.order.latest_ns == 10 * S
    assert gate.judge(11 * S, 13 * S, "odom", "base_stabilized").accepted


def test_a_gate_without_frames_checks_only_values_and_order() -> None:
    gate = InputGate()  # a JointState: no frame contract
    assert gate.judge(1 * S, 1 * S, "whatever").accepted
    assert gate.judge(1 * S, 2 * S).reason == OUT_OF_ORDER


# --- QoS problems ---------------------------------------------------------------------------------------------
def test_a_qos_problem_names_topic_side_and_policy_and_counts_events() -> None:
    log = QosProblemLog(hold_s=2.0)
    log.report("/vehicle/engine_failure", INPUT, "RELIABILITY", 1 * S)
    problem = log.report("/vehicle/engine_failure", INPUT, "RELIABILITY", 2 * S, new_events=2)
    log.report("/helireach/state", OUTPUT, "DURABILITY", 2 * S)
    assert problem.events == 3 and log.total_events == 4
    assert [p.topic for p in log.problems(INPUT)] == ["/vehicle/engine_failure"]
    assert "/vehicle/engine_failure" in problem.text and "RELIABILITY" in problem.text
    assert "not received" in problem.text
    assert "requests DURABILITY" in log.problems(OUTPUT)[0].text


def test_a_qos_problem_ends_only_after_the_hold_and_when_the_graph_is_clean() -> None:
    log = QosProblemLog(hold_s=2.0)
    log.report("/x", INPUT, "DURABILITY", 10 * S)
    assert log.resolve(11 * S, lambda topic, side: False) == []  # within the hold: discovery may lag the event
    assert log.resolve(13 * S, lambda topic, side: True) == []  # the incompatible endpoint is still there
    assert len(log.problems()) == 1
    ended = log.resolve(13 * S, lambda topic, side: False)
    assert [p.topic for p in ended] == ["/x"] and log.problems() == []
