"""The composed system end to end: the demo's closed-loop landing, its MCAP log, and replays of that log.

One demo run (about 20 s of real time: 3 s cruise, 12 s descent) is shared by the tests of this module.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from mcap.reader import make_reader
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from trajectory_msgs.msg import JointTrajectory

from helireach_ros import __version__
from helireach_ros.cli.demo import run_demo, summary
from helireach_ros.cli.main import main as helireach_main
from helireach_ros.core.flight.simulation import piecewise_linear_controls
from helireach_ros.core.mcap_log import read_log, read_log_metadata
from helireach_ros.core.units import FT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.bringup import ros_arguments
from helireach_ros.ros.executors import create_executor
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode
from helireach_ros.ros.plan_comparison import compare_logged_plans, logged_plan_counts
from helireach_ros.ros.replay import replay_log

pytestmark = [pytest.mark.system, pytest.mark.realtime]

VEHICLE_TOPICS = [rm.TOPIC_ODOMETRY, rm.TOPIC_ROTOR, rm.TOPIC_ENGINE_FAILURE]


def _run_demo_isolated(out: str):
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"
    return run_demo(out, context=Context(), handle_signals=False)


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo, run as ``make demo`` runs it: in a fresh interpreter of its own (a real-time closed loop
    should not share a process with the rest of the test session), returning its result."""
    out = tmp_path_factory.mktemp("demo")
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_run_demo_isolated, str(out)).result(timeout=300)


def test_the_demo_flies_the_mismatched_descent_closed_loop_and_reports_its_touchdown(demo) -> None:
    """The composed system flies the 5 % mismatched aircraft down closed loop and says how it landed.

    Whether one real-time run lands within limits is not asserted: the demo aircraft's own best landing is only 7 %
    inside the touchdown limits (J = -0.072 in its true model; the nominal model's is -0.098), the sensor noise moves
    each re-plan's value by several per cent, and the wall clock decides when each plan arrives, so the real-time
    demo lands within limits in most runs, not all (``bench/demo_landings.py``, docs/results/closed-loop.md). The
    landing itself is asserted where it is repeatable: the same scenario in lock-step time
    (``test_closed_loop.py``: the node's policy lands it at 0.05 and 0.3 s latency for three noise seeds)."""
    assert demo.scenario.name == "demo_500ft_75kt"
    assert demo.scenario.parameter_mismatch and all(
        abs(fraction) == pytest.approx(0.05) for fraction in demo.scenario.parameter_mismatch.values()
    )
    assert demo.status_before_failure is not None and demo.status_before_failure[0] == "OK"
    assert demo.first_plan is not None and not demo.first_plan.fallback and demo.first_plan.plan.safe
    replans = [record for record in demo.plans if record.replan_index > 0]
    assert len(replans) >= 10, "the descent must be flown closed loop"
    touchdown = demo.touchdown
    assert touchdown is not None, "no touchdown"
    limits = demo.limits
    assert demo.landed_within_limits == (touchdown.value <= 0.0 and touchdown.rotor_speed_within_limits)
    if demo.landed_within_limits:
        assert touchdown.descent_rate <= limits.max_descent_rate
        assert abs(touchdown.forward_speed) <= limits.max_forward_speed
    text = summary(demo)
    verdict = "SAFE: landed within limits" if demo.landed_within_limits else f"UNSAFE: {touchdown.reason}"
    assert verdict in text and str(demo.log_path) in text
    assert f"{touchdown.descent_rate / FT:.1f} ft/s (limit {limits.max_descent_rate / FT:.0f})" in text
    assert {figure.name for figure in demo.figures} == {"hv_diagram.png", "landing_plan.png"}
    assert all(figure.stat().st_size > 10_000 for figure in demo.figures)


def test_the_replans_are_made_for_the_model_error_learnt_in_flight(demo) -> None:
    """The vehicle's drag areas are 5 % above the model's: each re-plan is made for the model plus the disturbance
    accelerations learnt from the descent so far (``estimate_disturbance``, on by default), and its logged status
    says which; the failure plan has none (nothing was flown yet)."""
    assert np.array_equal(demo.first_plan.plan.disturbance, np.zeros(3))
    learnt = np.array([record.plan.disturbance for record in demo.plans if record.replan_index > 0])
    assert len(learnt) >= 10 and np.abs(learnt).max() > 0.02, learnt
    logged = [
        rm.status_values(deserialize_message(message.cdr, DiagnosticStatus))
        for message in read_log(demo.log_path)
        if message.topic == rm.TOPIC_PLAN_STATUS
    ]
    replanned = [values for values in logged if values.get("replan_index", "0") != "0"]
    assert replanned and any(float(values["disturbance_descent_acceleration_m_s2"]) != 0.0 for values in replanned)
    assert "model error learnt by the last: d_y" in summary(demo)


def test_the_log_holds_every_topic_and_the_run_metadata(demo) -> None:
    with demo.log_path.open("rb") as stream:
        summary_section = make_reader(stream).get_summary()  # the independent mcap reader; a finished file
    assert summary_section is not None
    channels = {channel.topic: channel for channel in summary_section.channels.values()}
    assert set(rm.TOPICS) <= set(channels), set(rm.TOPICS) - set(channels)
    counts = summary_section.statistics.channel_message_counts
    for spec in rm.TOPICS.values():
        channel = channels[spec.name]
        assert summary_section.schemas[channel.schema_id].name == spec.type_name
        assert counts.get(channel.id, 0) > 0, spec.name
        latched = "transient_local" in channel.metadata["offered_qos_profiles"]
        assert latched == (spec.qos.durability == rm.LATCHED_QOS.durability), spec.name
    record = read_log_metadata(demo.log_path)["helireach"]
    assert record["software_version"] == __version__
    assert record["airframe"] == "uh60a_class" and record["scenario"] == "demo_500ft_75kt"
    assert record["envelope_id"] and record["planner_settings"]
    touchdowns = [m for m in read_log(demo.log_path) if m.topic == rm.TOPIC_TOUCHDOWN]
    assert len(touchdowns) == 1
    logged = deserialize_message(touchdowns[0].cdr, DiagnosticStatus)
    assert (logged.level == DiagnosticStatus.OK) == demo.landed_within_limits  # the log says what the vehicle said


def test_every_message_of_the_log_is_decoded_by_rosbags_mcap_ros2_rclpy_and_read_log(demo) -> None:
    """Three independent decoders read every message whole: rosbags checks that a message's bytes end where its
    content does, which the ROS 2 serializer's leftover bytes after empty sequences used to break (every landing
    trajectory); rclpy reads what the nodes would be replayed."""
    from mcap_ros2.decoder import DecoderFactory
    from rclpy.serialization import deserialize_message as rclpy_deserialize
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    decoders = DecoderFactory()
    counts: dict[str, int] = {}
    with demo.log_path.open("rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            assert schema is not None
            typestore.deserialize_cdr(message.data, schema.name)  # raises on a size mismatch
            decode = decoders.decoder_for(channel.message_encoding, schema)
            assert decode is not None
            decode(message.data)
            package, _, type_name = schema.name.split("/")
            rclpy_deserialize(message.data, getattr(importlib.import_module(f"{package}.msg"), type_name))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts[rm.TOPIC_LANDING_TRAJECTORY] > 10, counts
    own: dict[str, int] = {}
    for message in read_log(demo.log_path):  # the package's own reader: the same messages
        own[message.topic] = own.get(message.topic, 0) + 1
    assert own == counts


def test_replay_compare_reproduces_the_logged_plan(demo, capsys) -> None:
    comparisons = compare_logged_plans(demo.log_path)
    assert len(comparisons) == 1 and comparisons[0].reproduced, comparisons
    assert comparisons[0].logged_status == "safe"
    assert helireach_main(["replay", str(demo.log_path), "--compare"]) == 0
    printed = capsys.readouterr().out
    assert "1 of 1 logged plans reproduced (each failure's first refined plan; not compared: " in printed
    counts = logged_plan_counts(demo.log_path)  # the demo re-plans its descent: those are said, not hidden
    assert counts["first"] == 1 and counts["replan"] > 10 and f"{counts['replan']} re-plans" in printed


def test_a_replayed_failure_drives_fresh_nodes_to_the_logged_plan(demo, no_ros_discovery) -> None:
    """Republish the logged vehicle topics into a fresh monitor and planner: they plan the logged failure again."""
    logged = {}  # state stamp -> logged trajectory
    odometry_stamps = set()
    for message in read_log(demo.log_path):
        if message.topic == rm.TOPIC_LANDING_TRAJECTORY:
            trajectory = deserialize_message(message.cdr, JointTrajectory)
            logged[rm.stamp_nanoseconds(trajectory.header.stamp)] = trajectory
        elif message.topic == rm.TOPIC_ODOMETRY:
            odometry_stamps.add(rm.stamp_nanoseconds(deserialize_message(message.cdr, Odometry).header.stamp))
    context = Context()
    rclpy.init(context=context, args=ros_arguments())
    monitor = VehicleMonitor(context=context, parameter_overrides=[Parameter("max_message_age", value=0.0)])
    planner = LandingPlannerNode(context=context, parameter_overrides=[Parameter("replan_period", value=0.0)])
    probe = Node("test_probe", context=context)
    trajectories: list[JointTrajectory] = []
    probe.create_subscription(JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, trajectories.append, rm.LATCHED_QOS)
    executor = create_executor("single_threaded", context)
    for node in (monitor, planner, probe):
        executor.add_node(node)
    replay = threading.Thread(
        target=replay_log, args=(demo.log_path,), kwargs={"rate": 4.0, "topics": VEHICLE_TOPICS, "context": context}
    )
    try:
        replay.start()
        deadline = time.monotonic() + 30.0
        converged = lambda: [record for record in planner.supervisor.published_plans if not record.fallback]  # noqa: E731
        while not (trajectories and converged()) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert trajectories and converged(), "no plan from the replayed failure"
        record = converged()[0]  # (a fallback may come first on a busy machine: the deadline is short)
        assert record.stamp_ns in odometry_stamps  # planned from a logged vehicle state
        assert record.plan.safe
        if record.stamp_ns in logged:  # the same state as in the original run: the same plan
            times, values = piecewise_linear_controls(
                record.plan.control_times, record.plan.control_values, record.plan.control_interpolation
            )
            _, logged_times, logged_values = rm.read_trajectory(logged[record.stamp_ns])
            grid = np.union1d(times, logged_times)
            for row, logged_row in zip(values, logged_values, strict=True):
                np.testing.assert_allclose(
                    np.interp(grid, times, row), np.interp(grid, logged_times, logged_row), atol=1e-3
                )
    finally:
        while replay.is_alive() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for node in (monitor, planner, probe):
            executor.remove_node(node)
        executor.shutdown(timeout_sec=2.0)
        for node in (monitor, planner, probe):
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        replay.join(timeout=10.0)
