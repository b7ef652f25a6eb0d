"""Message conversions (ROS types ↔ model quantities) and the topic documentation, without spinning anything."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from sensor_msgs.msg import JointState

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.envelope.data import StoredPlan
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.planning.planner import LandingPlanner
from helireach_ros.core.policies.vehicle_readings import (
    OdometryReading,
    RotorReading,
    StateLimits,
    helicopter_state,
    state_problems,
)
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm

MSG_DOCS = Path(__file__).resolve().parent.parent / "msg_docs"


def test_odometry_round_trip_in_rep103_conventions() -> None:
    message = rm.odometry_message(1_700_000_000_123_456_789, 152.4, 10.0, 38.6, -2.5, pitch_angle=0.1)
    reading = rm.read_odometry(message)
    assert reading == OdometryReading(1_700_000_000_123_456_789, 152.4, 10.0, 38.6, -2.5)
    orientation = message.pose.pose.orientation
    assert math.isclose(2 * math.atan2(orientation.y, orientation.w), 0.1)  # about +y: nose down
    state = helicopter_state(reading, 27.0)
    np.testing.assert_allclose(state, [2.5, 38.6, 27.0, 152.4, 10.0, 0.0])  # y = −climb rate


def test_rotor_power_travels_as_torque() -> None:
    reading = rm.read_rotor(rm.rotor_message(5, 27.0, engine_power=1.35e6))
    assert reading.rotor_speed == 27.0 and math.isclose(reading.engine_power, 1.35e6)
    assert rm.read_rotor(rm.rotor_message(5, 27.0)).engine_power is None
    with pytest.raises(ValueError, match="main_rotor"):
        rm.read_rotor(JointState(name=["tail_rotor"], velocity=[100.0]))
    with pytest.raises(ValueError, match="velocities"):
        rm.read_rotor(JointState(name=["main_rotor"], velocity=[]))


@pytest.mark.parametrize(
    ("reading", "problem"),
    [
        (OdometryReading(0, math.nan, 0.0, 30.0, 0.0), "height is nan"),
        (OdometryReading(0, 100.0, 0.0, math.inf, 0.0), "forward speed is inf"),
        (OdometryReading(0, -5.0, 0.0, 30.0, 0.0), "height -5"),
        (OdometryReading(0, 100.0, 0.0, 30.0, -90.0), "climb rate -90"),
    ],
)
def test_implausible_states_are_named(reading: OdometryReading, problem: str) -> None:
    problems = state_problems(StateLimits(), odometry=reading)
    assert len(problems) == 1 and problems[0].startswith(problem)
    assert state_problems(StateLimits(), odometry=OdometryReading(0, 100.0, 0.0, 30.0, -5.0)) == []
    assert state_problems(StateLimits(), rotor=RotorReading(0, 0.0, None))


def test_trajectory_message_round_trip_holds_the_controls() -> None:
    plan = StoredPlan(
        height=100.0,
        speed=30.0,
        status="safe",
        value=-0.5,
        time_to_land=3.0,
        warm_start=None,
        control_times=np.array([0.0, 1.0, 2.5, 3.0]),
        control_values=np.array([[0.001, 0.006, 0.012], [0.1, -0.2, -0.7]]),
        control_interpolation="zero_order_hold",
    )
    message = rm.trajectory_message(plan, stamp_ns=42)
    stamp, times, values = rm.read_trajectory(message)
    assert stamp == 42 and times[0] == 0.0 and times[-1] == pytest.approx(3.0)
    probe = np.array([0.3, 0.999, 1.2, 2.4, 2.7, 3.0])
    encoded = np.vstack([np.interp(probe, times, row) for row in values])
    np.testing.assert_allclose(encoded, plan.controls_at(probe), atol=1e-9)
    message.joint_names = [rm.PITCH_JOINT, rm.COLLECTIVE_JOINT]  # order does not matter to readers...
    assert rm.read_trajectory(message)[2][0, 0] == pytest.approx(0.1)
    message.joint_names = ["collective"]  # ...but the names do
    with pytest.raises(ValueError, match="lacks joint"):
        rm.read_trajectory(message)


def test_status_values_are_strings_with_full_precision() -> None:
    status = rm.diagnostic_status(DiagnosticStatus.OK, "n", "m", "h", {"x_m": 0.1 + 0.2, "ok": True, "n": 3})
    values = rm.status_values(status)
    assert float(values["x_m"]) == 0.1 + 0.2 and values["ok"] == "true" and values["n"] == "3"


@pytest.mark.parametrize("topic", sorted(rm.TOPICS))
def test_every_topic_is_documented_with_its_type_and_qos(topic: str) -> None:
    spec = rm.TOPICS[topic]
    index = (MSG_DOCS / "README.md").read_text()
    row = next(line for line in index.splitlines() if line.startswith(f"| [`{topic}`]"))
    assert f"`{spec.type_name}`" in row
    latched = spec.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert ("latched" in row) == latched
    assert ("reliable" in row.lower()) == (spec.qos.reliability == ReliabilityPolicy.RELIABLE or latched)
    page = MSG_DOCS / re.search(r"\]\(([^)]+\.md)\)", row).group(1)
    text = page.read_text()
    assert f"`{spec.type_name}`" in text and ("Rate" in text or "rate" in text)


def test_the_trajectory_point_counts_msg_docs_states_are_the_ones_sent() -> None:
    """msg_docs/helireach_landing_trajectory.md states how many points a plan is sent as; the planner's messages
    have them: one per breakpoint of a flyable plan (one more with a reaction delay), two per interval of a
    verified plan and one at the landing time; the last point at the landing time."""
    text = " ".join((MSG_DOCS / "helireach_landing_trajectory.md").read_text().split())
    documented = re.search(r"(\d+) points for the default (\d+) intervals", text)
    verified = re.search(r"(\d+) points for (\d+) intervals", text)
    assert documented is not None and verified is not None, "the page no longer states the point counts"
    points, intervals = int(documented.group(1)), int(documented.group(2))
    assert int(verified.group(2)) == intervals
    assert load_settings().intervals == intervals
    airframe = load_airframe("uh60a_class")
    state = initial_state_after_failure(airframe, 500 * FT, 75 * KT)
    plans = {
        "flyable": LandingPlanner(airframe, load_settings()).plan(state),
        "delayed": LandingPlanner(airframe, load_settings(reaction_delay_s=0.5)).plan(state),
        "verified": LandingPlanner(airframe, load_settings(method="verified")).plan(state),
    }
    counts = {kind: len(rm.trajectory_message(plan, 0).points) for kind, plan in plans.items()}
    assert counts == {"flyable": points, "delayed": points + 1, "verified": int(verified.group(1))}
    for plan in plans.values():
        last = rm.trajectory_message(plan, 0).points[-1].time_from_start
        assert rm.duration_seconds(last) == pytest.approx(plan.time_to_land, abs=2e-6)
