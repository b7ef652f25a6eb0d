"""The safety status node holds the envelope to its validity domain (real rclpy, the shipped envelope).

Outside the domain (a descent, a rotor off its governed speed) only a live verdict may answer; with none, the
status is STALE and says why; with the live planner, a descent the level-trim envelope calls safe is an ERROR.
The live verdicts themselves are tested in ``test_live_planner_ros.py``.
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.parameter import Parameter
from test_ros_nodes import OMEGA0, Harness, level_is

from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode

FPM = FT / 60.0


def test_outside_the_envelope_domain_without_a_live_verdict_the_status_is_stale(context: Context) -> None:
    harness = Harness(context, VehicleMonitor(context=context), EnvelopeStatusNode(context=context))
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        # Level flight at nominal rotor speed: inside the domain, the envelope answers.
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.OK))
        assert rm.status_values(statuses[-1])["evidence"] == "envelope"
        # 20 ft, 90 kt is safe from level trim; in a 2,000 ft/min descent the envelope does not speak for it.
        assert harness.keep_publishing(
            200 * FT, 100 * KT, climb_rate=-2500 * FPM, until=level_is(statuses, DiagnosticStatus.STALE)
        )
        message = statuses[-1].message
        assert "outside the envelope's domain" in message and "climb rate -2500 ft/min" in message
        assert "no current live verdict" in message
        # A rotor 5 % slow in level flight: outside the domain too.
        assert harness.keep_publishing(
            500 * FT, 75 * KT, rotor_speed=0.95 * OMEGA0, until=lambda: "rotor speed 95.0 %" in statuses[-1].message
        )
        assert statuses[-1].level == DiagnosticStatus.STALE
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.OK))
    finally:
        harness.close()


def test_with_the_live_planner_a_descent_the_envelope_calls_safe_is_an_error(context: Context) -> None:
    planner = LandingPlannerNode(
        context=context,
        parameter_overrides=[Parameter("solver_workers", value=0), Parameter("replan_period", value=0.0)],
    )
    harness = Harness(context, VehicleMonitor(context=context), EnvelopeStatusNode(context=context), planner)
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        assert harness.keep_publishing(
            500 * FT,
            75 * KT,
            until=lambda: (
                level_is(statuses, DiagnosticStatus.OK)()
                and rm.status_values(statuses[-1]).get("evidence") == "envelope+live"
            ),
        ), statuses[-1].message
        # 20 ft, 90 kt, 2,000 ft/min down: outside the envelope's domain (it would say safe); the live verdict says
        # no safe landing exists from there.
        assert harness.keep_publishing(
            200 * FT, 100 * KT, climb_rate=-2500 * FPM, until=level_is(statuses, DiagnosticStatus.ERROR)
        ), statuses[-1].message
        values = rm.status_values(statuses[-1])
        assert (
            values["evidence"] == "live" and values["live_status"] == "unsafe" and values["envelope_status"] == "safe"
        )
        assert "outside the envelope's domain" in statuses[-1].message
    finally:
        harness.close()
