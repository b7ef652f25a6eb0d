"""The demo's site scenario end to end: the composed system (simulated vehicle with the demo's 5 % drag mismatch, real
nodes, real IPOPT workers) told of a landing site beyond where it would land by itself; the live evaluations plan for
the site before the failure, the standby plan is the site's, and the closed loop lands on it."""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.serialization import deserialize_message

from helireach_ros.cli.demo import demo_site, run_demo, summary
from helireach_ros.core.mcap_log import read_log
from helireach_ros.ros import messages as rm

pytestmark = [pytest.mark.system, pytest.mark.realtime]

SITE_FT = "2400:2800"  # along the track from the run's start; the failure comes ~415 ft in, the plain demo lands ~2200


def _run_site_demo(out: str):
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"
    return run_demo(
        out, context=Context(), handle_signals=False, robust_verification=False, site=demo_site(SITE_FT), figures=False
    )


@pytest.fixture(scope="module")
def site_demo(tmp_path_factory):
    """The demo with ``--site-ft 2400:2800``, in a fresh interpreter of its own (a real-time closed loop)."""
    out = tmp_path_factory.mktemp("site_demo")
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_run_site_demo, str(out)).result(timeout=300)


def _statuses(log_path, topic: str) -> list[dict[str, str]]:
    return [
        rm.status_values(deserialize_message(message.cdr, DiagnosticStatus))
        for message in read_log(log_path)
        if message.topic == topic
    ]


def test_the_closed_loop_lands_on_the_site_within_limits(site_demo) -> None:
    text = summary(site_demo)
    assert site_demo.touchdown is not None and site_demo.touchdown.within_limits, text
    assert site_demo.on_site and site_demo.site.contains(site_demo.touchdown_distance), text
    assert site_demo.landed_within_limits
    assert "ON the site" in text and "SAFE: landed within limits on the site" in text


def test_the_standby_plan_published_at_the_failure_is_the_sites(site_demo) -> None:
    standby = site_demo.standby_plan
    assert standby is not None, summary(site_demo)
    assert standby.plan.verified and standby.plan.touchdown_window is not None
    first = site_demo.first_plan
    assert first is not None and not first.fallback and first.plan.touchdown_window is not None
    assert first.plan.safe


def test_the_statuses_name_the_site_before_and_after_the_failure(site_demo) -> None:
    live = _statuses(site_demo.log_path, rm.TOPIC_LIVE_REACHABILITY)
    aimed = [values for values in live if values.get("landing_site") == "demo_site"]
    assert aimed and len(aimed) == len([values for values in live if "on_site" in values])
    assert any(values["on_site"] == "true" and int(values["sites_reachable"]) == 1 for values in aimed)
    plans = _statuses(site_demo.log_path, rm.TOPIC_PLAN_STATUS)
    first = next(values for values in plans if "landing_site" in values)
    assert first["landing_site"] == "demo_site" and first["on_site"] == "true" and first["standby"] == "true"
    assert float(first["site_start_m"]) == pytest.approx(site_demo.site.start_m, abs=1e-3)


def test_a_mission_managers_sites_replace_the_parameters_and_the_live_verdicts_aim_at_them(context) -> None:
    """Monitor + planner (real workers): the parameter's site out of reach, then a mission manager's latched list with
    a reachable site: the planner adopts it, says so on /helireach/landing_sites, and the live verdicts land on it; a
    malformed list is refused and the sites in use are kept."""
    from test_live_planner_ros import LEVEL, stream_until
    from test_ros_nodes import monitor_and_planner

    harness, _ = monitor_and_planner(
        context, replan_period=0.0, live_rate=5.0, landing_sites="far:5000:5100", landing_sites_topic=True
    )
    adopted = harness.listen(DiagnosticStatus, rm.TOPIC_LANDING_SITES)
    live = harness.listen(DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY)
    mission = harness.probe.create_publisher(DiagnosticStatus, rm.TOPIC_MISSION_LANDING_SITES, rm.LATCHED_QOS)
    try:
        assert harness.spin_until(lambda: bool(adopted))
        first = rm.status_values(adopted[-1])
        assert first["source"] == "parameter" and first["landing_sites"] == "far:5000:5100"

        def aimed_at(name: str, on_site: str):
            return lambda: any(
                rm.status_values(m).get("landing_site") == name and rm.status_values(m).get("on_site") == on_site
                for m in live
            )

        assert stream_until(harness, LEVEL, aimed_at("far", "false")), "no live verdict for the parameter's site"
        values = {"landing_sites": "field:150:450;far:5000:5100", "selected_site": "field"}
        mission.publish(rm.diagnostic_status(DiagnosticStatus.OK, "mission: landing sites", "", "", values))
        assert harness.spin_until(lambda: rm.status_values(adopted[-1])["source"] == "topic")
        now = rm.status_values(adopted[-1])
        assert now["selected_site"] == now["selection"] == "field" and now["site_count"] == "2"
        assert adopted[-1].level == DiagnosticStatus.OK
        live.clear()
        assert stream_until(harness, LEVEL, aimed_at("field", "true")), "the live verdicts do not land on the new site"
        broken = {"landing_sites": "field:450:150"}  # reversed ends
        mission.publish(rm.diagnostic_status(DiagnosticStatus.OK, "mission: landing sites", "", "", broken))
        assert harness.spin_until(lambda: "refused" in rm.status_values(adopted[-1])["reason"])
        kept = rm.status_values(adopted[-1])
        assert kept["landing_sites"] == "field:150:450;far:5000:5100" and kept["selection"] == "field"
    finally:
        harness.close()
