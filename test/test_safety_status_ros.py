"""The safety status node holds the envelope to its validity domain (real rclpy, the shipped envelope).

Outside the domain (a descent, a rotor off its governed speed) only a live verdict may answer; with none, the
status is STALE and says why; with the live planner, a descent the level-trim envelope calls safe is an ERROR.
The live verdicts themselves are tested in ``test_live_planner_ros.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.parameter import Parameter
from test_ros_nodes import OMEGA0, Harness, level_is

from helireach_ros.core.envelope.data import (
    ROBUST_ARRAYS,
    ROBUST_CODES,
    Envelope,
    default_envelope_path,
    load_envelope,
    save_envelope,
)
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode

FPM = FT / 60.0


@pytest.fixture(scope="module")
def level_trim_envelope(tmp_path_factory) -> str:
    """The shipped 3-D envelope's level-flight slice as a 2-D file: what a level-trim H-V envelope says."""
    shipped = load_envelope(default_envelope_path())
    level = shipped.slice(shipped.nearest_slice(0.0))
    return str(save_envelope(level, tmp_path_factory.mktemp("envelope") / "level_trim.npz"))


@pytest.fixture(scope="module")
def robust_verdict_envelope(tmp_path_factory, level_trim_envelope: str) -> str:
    """The level-trim envelope with robust verdicts: robust at every safe node but those within 20 ft / 5 kt of
    500 ft / 75 kt, which are safe in the nominal model only (written here: the node reads what the file says;
    computing verdicts is tested in ``test_robust_envelope.py``)."""
    level = load_envelope(level_trim_envelope)
    safe = level.status == "safe"
    codes = np.where(safe, ROBUST_CODES["robust"], ROBUST_CODES["nominal_not_safe"])
    near = np.ix_(np.abs(level.heights - 500 * FT) <= 20.5 * FT, np.abs(level.speeds - 75 * KT) <= 5.5 * KT)
    codes[near] = np.where(safe[near], ROBUST_CODES["not_robust"], codes[near])
    arrays = level.arrays
    arrays.update({name: np.zeros(codes.shape, np.int16) for name in ROBUST_ARRAYS[1:]})
    arrays.update(robust_code=codes.astype(np.int8), robust_seconds=np.zeros(codes.shape, np.float32))
    envelope = Envelope(arrays, dict(level.metadata, robust={"design": "written by the test"}))
    return str(save_envelope(envelope, tmp_path_factory.mktemp("robust") / "robust_verdicts.npz"))


def test_the_status_uses_the_envelopes_robust_verdict_by_default_and_says_which_it_used(
    context: Context, robust_verdict_envelope: str
) -> None:
    status_node = EnvelopeStatusNode(
        context=context, parameter_overrides=[Parameter("envelope_file", value=robust_verdict_envelope)]
    )
    harness = Harness(context, VehicleMonitor(context=context), status_node)
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        # safe in the nominal model only: CAUTION, not SAFE
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.WARN))
        values = rm.status_values(statuses[-1])
        assert "not robust" in statuses[-1].message
        assert values["envelope_verdict"] == "robust" and values["envelope_status"] == "not_robust"
        # 400 ft / 90 kt: robust, and far from the not-robust nodes and from the boundary
        assert harness.keep_publishing(400 * FT, 90 * KT, until=level_is(statuses, DiagnosticStatus.OK))
        assert statuses[-1].message.startswith("SAFE (robust)")
        # asked for the nominal verdict, the same state is SAFE again, and the status says so
        result = status_node.set_parameters([Parameter("envelope_verdict", value="nominal")])[0]
        assert result.successful
        assert harness.keep_publishing(
            500 * FT, 75 * KT, until=lambda: rm.status_values(statuses[-1]).get("envelope_verdict") == "nominal"
        )
        assert statuses[-1].level == DiagnosticStatus.OK and statuses[-1].message.startswith("SAFE: margin")
        refused = status_node.set_parameters([Parameter("envelope_verdict", value="optimistic")])[0]
        assert not refused.successful and "must be one of" in refused.reason
    finally:
        harness.close()


def test_outside_the_envelope_domain_without_a_live_verdict_the_status_is_stale(context: Context) -> None:
    harness = Harness(context, VehicleMonitor(context=context), EnvelopeStatusNode(context=context))
    statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
    try:
        # Level flight at nominal rotor speed: inside the domain, the envelope answers.
        assert harness.keep_publishing(500 * FT, 75 * KT, until=level_is(statuses, DiagnosticStatus.OK))
        assert rm.status_values(statuses[-1])["evidence"] == "envelope"
        # the shipped envelope has no robust verdict: the nominal one answers, and the status says why
        assert rm.status_values(statuses[-1])["envelope_verdict"] == "nominal"
        assert rm.status_values(statuses[-1])["envelope_verdict_note"] == "the envelope has no robust verdict"
        # 200 ft, 100 kt: its descent slices stop at -2,000 ft/min; at -2,500 the envelope does not speak for it.
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


def test_with_the_live_planner_a_descent_the_envelope_calls_safe_is_an_error(
    context: Context, level_trim_envelope: str
) -> None:
    planner = LandingPlannerNode(
        context=context,
        parameter_overrides=[Parameter("solver_workers", value=0), Parameter("replan_period", value=0.0)],
    )
    status_node = EnvelopeStatusNode(
        context=context, parameter_overrides=[Parameter("envelope_file", value=level_trim_envelope)]
    )
    harness = Harness(context, VehicleMonitor(context=context), status_node, planner)
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
        # 40 ft, 85 kt, 1,800 ft/min down: outside the level-trim envelope's domain (its lookup says safe); the
        # live verdict says no safe landing exists from there.
        assert harness.keep_publishing(
            40 * FT, 85 * KT, climb_rate=-1800 * FPM, until=level_is(statuses, DiagnosticStatus.ERROR)
        ), statuses[-1].message
        values = rm.status_values(statuses[-1])
        assert (
            values["evidence"] == "live" and values["live_status"] == "unsafe" and values["envelope_status"] == "safe"
        )
        assert "outside the envelope's domain" in statuses[-1].message
    finally:
        harness.close()
