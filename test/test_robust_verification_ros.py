"""The planner node's robust verification of its failure plans (real rclpy, real IPOPT, a real worker process).

The plan goes out first, flagged ``robust: pending``; its verdict follows on ``/helireach/robust_verdict`` from a
low-priority process. The uncertainty sets here are small (one or two models) so the closed loops take seconds.
"""

from __future__ import annotations

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.parameter import Parameter
from test_robust_envelope import uncertainty_file
from test_ros_nodes import planner_harness, trigger_failure

from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm

_VERDICT_TIMEOUT_S = 120.0  # a niced worker on a busy 2-core machine: the closed loops take seconds each


@pytest.mark.parametrize(
    ("weight", "robust", "replan_period"),
    [((0, 0), True, 0.25), ((20, 25), False, 0.0)],
    ids=["exact model, re-planning", "heavy, one plan"],
)
def test_the_failure_plan_is_published_pending_and_its_robust_verdict_follows(
    context: Context, tmp_path, weight: tuple[int, int], robust: bool, replan_period: float
) -> None:
    """The verification's closed loop is the node's policy: with ``replan_period`` 0 it flies the one plan."""
    harness, planner = planner_harness(
        context,
        Parameter("robust_verification", value=True),
        Parameter("robust_uncertainty", value=uncertainty_file(tmp_path / "set.yaml", gross_weight=weight)),
        Parameter("replan_period", value=replan_period),
    )
    plan_statuses = harness.listen(DiagnosticStatus, rm.TOPIC_PLAN_STATUS)
    verdicts = harness.listen(DiagnosticStatus, rm.TOPIC_ROBUST_VERDICT)
    try:
        stamp = trigger_failure(harness, 500 * FT, 75 * KT)
        assert harness.spin_until(lambda: plan_statuses and rm.status_values(plan_statuses[-1]).get("robust"))
        status = rm.status_values(plan_statuses[-1])
        assert status["safe"] == "true" and status["robust"] == "pending"
        assert status["robust_design"].startswith("resolution-IV corners of 'test'")
        assert harness.spin_until(
            lambda: verdicts and rm.status_values(verdicts[-1])["robust"] != "pending", _VERDICT_TIMEOUT_S
        )
        pending = [rm.status_values(message)["robust"] for message in verdicts]
        assert pending[0] == "pending"  # said before the verdict
        values = rm.status_values(verdicts[-1])
        assert int(values["state_stamp_ns"]) == stamp and values["failure_id"] == status["failure_id"]
        assert values["robust"] == str(robust).lower(), values
        if robust:
            assert verdicts[-1].level == DiagnosticStatus.OK and values["robust_closed_loop_landed"] == "1"
        else:
            assert verdicts[-1].level == DiagnosticStatus.WARN and verdicts[-1].message.startswith("NOT ROBUST")
            assert values["robust_models_flown"] == "1"  # stopped at the first failing model
            assert "gross_weight+2" in values["robust_reason"]  # the 20 or 25 % heavier model
        assert planner.supervisor.published_plans  # the node is still serving
    finally:
        harness.close()
