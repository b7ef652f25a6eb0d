"""Cockpit display: the page in headless Chromium (DevTools protocol), real rclpy, real envelope and planner.

In-process tests isolate DDS with ``ROS_AUTOMATIC_DISCOVERY_RANGE=OFF`` and run the ROS executor on a
background thread while the test drives the browser; every wait is "poll until a condition holds, with a
deadline". The cross-process test (the ``helireach display`` command) uses ``LOCALHOST`` and its own
``ROS_DOMAIN_ID`` (conftest.py). Screenshots go to the test's tmp dir, and to ``$HELIREACH_ARTIFACTS/``
when that is set.
Browser tests are skipped only when no Chromium binary exists (install Debian's: ``apt-get install chromium``).
"""

from __future__ import annotations

import asyncio
import base64
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import aiohttp
import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.envelope.data import default_envelope_path, load_envelope
from helireach_ros.core.policies.failure_episode import EpisodePhase, EpisodeState
from helireach_ros.core.policies.flight_phase import plan_cue_events
from helireach_ros.core.policies.landing_sites import (
    LandingSite,
    SiteSelection,
    footprint_off_report,
    footprint_report,
    site_values,
)
from helireach_ros.core.policies.plan_status import plan_values
from helireach_ros.core.status_values import format_value
from helireach_ros.core.units import FT, KT
from helireach_ros.display.node import FOOTPRINT_MAX_AGE_S, CockpitDisplay
from helireach_ros.display.pilot_units import axis_margins
from helireach_ros.display.sections import (
    banner_level,
    boundary_segments,
    episode_section,
    footprint_section,
    path_section,
    plan_status_section,
    robust_verdict_section,
    rotor_limits_section,
    site_section,
    site_verdict,
)
from helireach_ros.display.server import DisplayServerError, web_directory
from helireach_ros.ros import messages as rm

REPO = Path(__file__).resolve().parents[1]
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome-stable", "google-chrome")
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
    "--hide-scrollbars",
    "--window-size=1280,800",
    "--remote-debugging-address=127.0.0.1",
    "--remote-debugging-port=0",
)
VIEWPORT = {"width": 1280, "height": 800}
TIMEOUT_S = 15.0
CROSS_PROCESS_TIMEOUT_S = 30.0
STALE_AFTER_S = 1.0
LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE)


def find_chromium() -> str | None:
    """The Chromium/Chrome binary ($HELIREACH_CHROMIUM, else the first on PATH), or None."""
    explicit = os.environ.get("HELIREACH_CHROMIUM")
    if explicit:
        return explicit if Path(explicit).is_file() else None
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


CHROMIUM = find_chromium()
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="no Chromium binary found (install Debian's: apt-get install -y chromium, or set HELIREACH_CHROMIUM)",
)


def wait_until(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Polls ``condition`` until it holds; fails naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.02)


def save_artifact(tmp_path: Path, name: str, png: bytes) -> Path:
    """Writes a screenshot to the test's tmp dir and, if set, to ``$HELIREACH_ARTIFACTS``."""
    path = tmp_path / name
    path.write_bytes(png)
    artifacts = os.environ.get("HELIREACH_ARTIFACTS")
    if artifacts:
        target = Path(artifacts)
        target.mkdir(parents=True, exist_ok=True)
        (target / name).write_bytes(png)
    return path


def strict_json(text: str) -> Any:
    """json.loads that rejects NaN/Infinity (not JSON; a browser's JSON.parse would throw)."""

    def reject(constant: str) -> None:
        raise ValueError(f"non-JSON constant {constant} in a frame")

    return json.loads(text, parse_constant=reject)


# ------------------------------------------------------------------------------------------------------------
# Headless Chromium over the DevTools protocol (aiohttp WebSocket client)
# ------------------------------------------------------------------------------------------------------------


@dataclass
class Browser:
    """A running headless Chromium and its DevTools HTTP endpoint."""

    process: subprocess.Popen
    devtools: str  # http://127.0.0.1:PORT


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    if CHROMIUM is None:
        pytest.skip("no Chromium binary found")
    profile = tempfile.mkdtemp(prefix="helireach-chromium-")
    process = subprocess.Popen(
        [CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "about:blank"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        port_file = Path(profile) / "DevToolsActivePort"
        deadline = time.monotonic() + 30.0
        while not (port_file.is_file() and port_file.read_text().strip()):
            if process.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"Chromium ({CHROMIUM}) did not start its DevTools endpoint")
            time.sleep(0.05)
        port = int(port_file.read_text().split()[0])
        yield Browser(process, f"http://127.0.0.1:{port}")
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        shutil.rmtree(profile, ignore_errors=True)


class DevToolsPage:
    """One browser tab driven over its DevTools WebSocket."""

    def __init__(self, http: aiohttp.ClientSession, devtools: str, target: dict[str, Any]) -> None:
        self._http = http
        self._devtools = devtools
        self.target = target
        self._socket: aiohttp.ClientWebSocketResponse | None = None
        self._next_id = 0
        self.errors: list[str] = []  # uncaught exceptions and console/CSP errors seen in the page

    @classmethod
    async def open(cls, http: aiohttp.ClientSession, browser: Browser, url: str) -> DevToolsPage:
        async with http.put(f"{browser.devtools}/json/new?about:blank") as response:
            target = await response.json()
        page = cls(http, browser.devtools, target)
        page._socket = await http.ws_connect(target["webSocketDebuggerUrl"], max_msg_size=0)
        await page.send("Page.enable")
        await page.send("Runtime.enable")
        await page.send("Log.enable")
        await page.send("Emulation.setDeviceMetricsOverride", **VIEWPORT, deviceScaleFactor=1, mobile=False)
        await page.send("Page.navigate", url=url)
        return page

    async def send(self, method: str, **params: Any) -> dict[str, Any]:
        assert self._socket is not None
        self._next_id += 1
        command_id = self._next_id
        await self._socket.send_json({"id": command_id, "method": method, "params": params})
        while True:  # events interleave with replies; keep reading until ours
            message = await asyncio.wait_for(self._socket.receive(), timeout=TIMEOUT_S)
            if message.type != aiohttp.WSMsgType.TEXT:
                raise RuntimeError(f"DevTools connection ended: {message}")
            reply = json.loads(message.data)
            event = reply.get("method")
            if event == "Runtime.exceptionThrown":
                self.errors.append(json.dumps(reply["params"]["exceptionDetails"])[:500])
            elif event == "Log.entryAdded" and reply["params"]["entry"]["level"] == "error":
                entry = reply["params"]["entry"]
                # a page that outlives its server logs failed reconnects; anything else is a page error
                if entry.get("source") != "network":
                    self.errors.append(f"{entry.get('source')}: {entry.get('text')}")
            elif event == "Runtime.consoleAPICalled" and reply["params"]["type"] == "error":
                self.errors.append(json.dumps(reply["params"]["args"])[:500])
            if reply.get("id") == command_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    async def evaluate(self, expression: str) -> Any:
        result = await self.send("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in result:
            return None
        return result["result"].get("value")

    async def wait_for(
        self, expression: str, predicate: Callable[[Any], bool], what: str, timeout_s: float = TIMEOUT_S
    ) -> Any:
        deadline = time.monotonic() + timeout_s
        value = None
        while time.monotonic() < deadline:
            value = await self.evaluate(expression)
            if value is not None and predicate(value):
                return value
            await asyncio.sleep(0.05)
        pytest.fail(f"page: timed out after {timeout_s} s waiting for {what}; last {expression} = {value!r}")

    async def banner(self, level: str, what: str, timeout_s: float = TIMEOUT_S, detail: str = "") -> dict[str, Any]:
        """Waits until the banner shows ``level`` (and ``detail`` in its text); returns what it shows."""
        expression = (
            "({word: document.getElementById('banner-word').textContent,"
            " level: document.getElementById('banner').dataset.level,"
            " detail: document.getElementById('banner-detail').textContent,"
            " phase: document.body.dataset.phase, bodyLevel: document.body.dataset.level,"
            " margin: window.helireach.margins})"
        )
        return await self.wait_for(
            expression,
            lambda shown: shown["level"] == level == shown["bodyLevel"] and detail in shown["detail"],
            what,
            timeout_s,
        )

    async def phase(self, phase: str, level: str, what: str, word: str | None = None) -> dict[str, Any]:
        """Waits until ``<body>`` says ``data-phase=phase`` and ``data-level=level`` (and the banner ``word``)."""
        expression = (
            "({phase: document.body.dataset.phase, level: document.body.dataset.level,"
            " word: document.getElementById('banner-word').textContent,"
            " detail: document.getElementById('banner-detail').textContent,"
            " engine: document.getElementById('engine-strip').hidden ? null"
            " : document.getElementById('engine-word').textContent,"
            " timer: document.getElementById('engine-timer').textContent,"
            " cue: window.helireach.cue, readouts: window.helireach.readouts, rotor: window.helireach.rotor,"
            " side: window.helireach.side})"
        )
        return await self.wait_for(
            expression,
            lambda shown: (shown["phase"], shown["level"]) == (phase, level) and word in (None, shown["word"]),
            what,
        )

    async def screenshot(self) -> bytes:
        result = await self.send("Page.captureScreenshot", format="png")
        return base64.b64decode(result["data"])

    async def close(self) -> None:
        if self._socket is not None:
            await self._socket.close()
        async with self._http.get(f"{self._devtools}/json/close/{self.target['id']}"):
            pass


# ------------------------------------------------------------------------------------------------------------
# ROS side: the display beside a publisher of vehicle state, rotor speed and safety status
# ------------------------------------------------------------------------------------------------------------


def status_message(
    level: bytes, message: str, height_m: float, speed_ms: float, margin: float, envelope_id: str
) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=level,
        name="helireach: safety status",
        message=message,
        hardware_id="test",
        values=[
            KeyValue(key="height_m", value=f"{height_m:.3f}"),
            KeyValue(key="forward_speed_m_s", value=f"{speed_ms:.3f}"),
            KeyValue(key="margin_ft_kt", value=repr(float(margin))),
            KeyValue(key="envelope_id", value=envelope_id),
        ],
    )


class VehicleAndStatus(Node):
    """Publishes the state (60 Hz), rotor speed (60 Hz), safety status and failure episode (10 Hz) the test sets;
    the planner's live footprint and live verdict (10 Hz) from ``footprint``/``live``, functions of the stamp now
    (ns) that return the message, as a planner re-solving them from the latest state would."""

    def __init__(self, context: Context, state_topic: str = "/helireach/state") -> None:
        super().__init__("display_test_vehicle", context=context)
        self._lock = threading.Lock()
        self.state: tuple[float, float, float] | None = None  # height m, speed m/s, climb m/s
        self.rotor_speed: float | None = None
        self.status: DiagnosticStatus | None = None
        self.episode: DiagnosticStatus | None = None  # the monitor's episode state, republished like the monitor
        self.distance = 0.0  # m along the track
        self.state_publisher = self.create_publisher(Odometry, state_topic, 10)
        self.rotor_publisher = self.create_publisher(JointState, "/vehicle/rotor", 10)
        self.status_publisher = self.create_publisher(DiagnosticStatus, "/helireach/safety_status", LATCHED)
        self.failure_publisher = self.create_publisher(Header, "/helireach/failure_event", RELIABLE)
        # the planner's topics are latched (msg_docs)
        self.trajectory_publisher = self.create_publisher(JointTrajectory, "/helireach/landing_trajectory", LATCHED)
        self.path_publisher = self.create_publisher(PathMsg, "/helireach/landing_path", LATCHED)
        self.plan_status_publisher = self.create_publisher(DiagnosticStatus, "/helireach/plan_status", LATCHED)
        self.episode_publisher = self.create_publisher(DiagnosticStatus, rm.TOPIC_FAILURE_EPISODE, rm.LATCHED_QOS)
        self.touchdown_publisher = self.create_publisher(DiagnosticStatus, rm.TOPIC_TOUCHDOWN, LATCHED)
        self.robust_publisher = self.create_publisher(DiagnosticStatus, rm.TOPIC_ROBUST_VERDICT, LATCHED)
        self.footprint_publisher = self.create_publisher(DiagnosticStatus, rm.TOPIC_REACHABLE_FOOTPRINT, LATCHED)
        self.live_publisher = self.create_publisher(DiagnosticStatus, rm.TOPIC_LIVE_REACHABILITY, LATCHED)
        self.footprint: Callable[[int], DiagnosticStatus] | None = None
        self.live: Callable[[int], DiagnosticStatus] | None = None
        self.create_timer(1.0 / 60.0, self._publish_vehicle)
        self.create_timer(0.1, self._publish_status)

    def set(self, state: tuple[float, float, float] | None = None, status: DiagnosticStatus | None = None) -> None:
        with self._lock:
            self.state, self.status = state, status

    def _publish_vehicle(self) -> None:
        with self._lock:
            state, rotor_speed = self.state, self.rotor_speed
        stamp = self.get_clock().now().to_msg()
        if state is not None:
            message = Odometry()
            message.header.stamp = stamp
            message.header.frame_id = "odom"
            message.child_frame_id = "base_stabilized"
            message.pose.pose.position.z = state[0]
            message.pose.pose.position.x = self.distance
            message.twist.twist.linear.x = state[1]
            message.twist.twist.linear.z = state[2]
            self.state_publisher.publish(message)
        if rotor_speed is not None:
            rotor = JointState(name=["main_rotor"], velocity=[rotor_speed])
            rotor.header.stamp = stamp
            self.rotor_publisher.publish(rotor)

    def _publish_status(self) -> None:
        with self._lock:
            status, episode = self.status, self.episode
        if status is not None:
            self.status_publisher.publish(status)
        if episode is not None:
            self.episode_publisher.publish(episode)
        footprint, live, now_ns = self.footprint, self.live, self.get_clock().now().nanoseconds
        if footprint is not None:
            self.footprint_publisher.publish(footprint(now_ns))
        if live is not None:
            self.live_publisher.publish(live(now_ns))


class RosHarness:
    """A fresh context, the display node and the test publisher, spun on a background thread."""

    def __init__(self, vehicle_topic: str = "/helireach/state", **display_parameters: Any) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        parameters = {"port": 0, "stale_after_s": STALE_AFTER_S, **display_parameters}
        self.display = CockpitDisplay(
            context=self.context, parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()]
        )
        self.vehicle = VehicleAndStatus(self.context, vehicle_topic)
        self.others: list[Node] = []
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.display)
        self.executor.add_node(self.vehicle)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()
        self.destroyed = False

    def add(self, node: Node) -> Node:
        """Spins another node (e.g. the real status node) beside the display."""
        self.others.append(node)
        self.executor.add_node(node)
        return node

    def destroy_display(self) -> None:
        if not self.destroyed:
            self.executor.remove_node(self.display)
            self.display.destroy_node()
            self.destroyed = True

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self._thread.join(timeout=5.0)
        self.destroy_display()
        for node in [self.vehicle, *self.others]:
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture(autouse=True)
def isolated_dds(no_ros_discovery: None) -> None:
    """Every test here runs without discovery unless it asks for a LOCALHOST domain."""


# ------------------------------------------------------------------------------------------------------------
# A real landing plan (IPOPT) as the planner node would publish it
# ------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def real_plan() -> Any:
    from helireach_ros.core.aircraft.model import initial_state_after_failure
    from helireach_ros.core.planning.planner import plan_landing

    airframe = load_airframe("uh60a_class")
    plan = plan_landing(initial_state_after_failure(airframe, 500 * FT, 75 * KT), airframe)
    assert plan.status in ("safe", "unverified", "unsafe"), plan.status
    return plan


def plan_messages(plan: Any, start: TimeMsg) -> tuple[JointTrajectory, PathMsg, DiagnosticStatus]:
    """The trajectory, predicted path and plan status for ``plan`` as the planner node publishes them."""
    stamp_ns = rm.stamp_nanoseconds(start)
    values = {**plan_values(plan), "replan_index": 0, "failure_id": 1, "failure_stamp_ns": stamp_ns}
    level = DiagnosticStatus.OK if plan.safe else DiagnosticStatus.ERROR
    return (
        rm.trajectory_message(plan, stamp_ns),
        rm.path_message(plan.times, plan.states, stamp_ns),
        rm.diagnostic_status(level, "helireach_planner: landing plan", f"plan {plan.status}", "test", values),
    )


@pytest.fixture(scope="module")
def envelope_file() -> Path:
    """The envelope the display loads: the shipped one."""
    path = Path(os.environ.get("HELIREACH_TEST_ENVELOPE") or default_envelope_path())
    assert path.is_file(), f"shipped envelope {path} is missing"
    return path


@pytest.fixture
def ros(envelope_file: Path) -> Iterator[RosHarness]:
    harness = RosHarness(envelope_file=str(envelope_file))
    try:
        yield harness
    finally:
        harness.close()


def run_page(browser: Browser, url: str, scenario: Callable[[DevToolsPage], Any]) -> Any:
    """Opens ``url`` in a new tab and runs ``await scenario(page)``."""

    async def main() -> Any:
        async with aiohttp.ClientSession() as http:
            page = await DevToolsPage.open(http, browser, url)
            try:
                return await scenario(page)
            finally:
                await page.close()

    return asyncio.run(main())


def display_envelope_id(harness: RosHarness) -> str:
    """The id of the envelope the display loaded (the status node would report the same)."""
    return load_envelope(harness.display.get_parameter("envelope_file").value).envelope_id


MARKER = "window.helireach && window.helireach.marker"
PLAN = "window.helireach && window.helireach.plan"


def near(value: float, expected: float, tolerance: float = 0.05) -> bool:
    return value is not None and abs(value - expected) <= tolerance


# ------------------------------------------------------------------------------------------------------------
# Acceptance: the page follows the safety status, the state and the plan
# ------------------------------------------------------------------------------------------------------------


def expected_margins(envelope: Any, height: float, speed: float, climb: float = 0.0) -> dict[str, str]:
    """What the banner's two margins must read for a state (from the nodes of the envelope's climb slice nearest
    the state's climb rate, as the page's rule)."""
    envelope = envelope.slice(envelope.nearest_slice(climb))
    margins = axis_margins(envelope.heights, envelope.speeds, np.asarray(envelope.status) == "safe", height, speed)
    texts = {}
    for axis, unit, words in (("vertical", FT, ("ABOVE", "BELOW")), ("horizontal", KT, ("FASTER", "SLOWER"))):
        line = margins[axis]
        if line["offset"] is None:
            texts[axis] = "--- CLEAR" if line["safe"] else "--- NO SAFE"
        else:
            texts[axis] = f"{abs(line['offset']) / unit:.0f} {words[0] if line['offset'] >= 0 else words[1]}"
    return texts


@needs_chromium
def test_page_follows_status_state_and_plan(ros: RosHarness, browser: Browser, tmp_path: Path) -> None:
    vehicle = ros.vehicle
    envelope_id = display_envelope_id(ros)
    envelope = load_envelope(ros.display.get_parameter("envelope_file").value)
    cruise = (500 * FT, 75 * KT, 0.0)
    slow = (250 * FT, 40 * KT, -1.0)
    low = (100 * FT, 20 * KT, -2.0)

    async def scenario(page: DevToolsPage) -> None:
        shown = await page.banner("nodata", "STALE before any safety status", detail="NO SAFETY STATUS")
        assert (shown["word"], shown["phase"]) == ("STALE", "stale")
        assert await page.evaluate("document.getElementById('hv-nodata').hidden") is True  # envelope loaded

        vehicle.rotor_speed = 0.99 * 27.0
        vehicle.set(cruise, status_message(DiagnosticStatus.OK, "safe", *cruise[:2], 180.0, envelope_id))
        shown = await page.banner("safe", "SAFE")
        assert (shown["word"], shown["phase"]) == ("SAFE", "normal")
        # no episode heard: the H-V status is shown, and the banner says what is missing
        assert "NO FAILURE-EPISODE STATUS" in shown["detail"]
        shown = await page.wait_for(
            "window.helireach.margins", lambda m: m == expected_margins(envelope, *cruise), "the margins"
        )
        first = await page.wait_for(MARKER, lambda m: near(m["speedKt"], 75) and near(m["heightFt"], 500), "marker")

        vehicle.set(slow, status_message(DiagnosticStatus.WARN, "near the boundary", *slow[:2], 12.0, envelope_id))
        shown = await page.banner("caution", "CAUTION")
        assert shown["word"] == "CAUTION"
        await page.wait_for("window.helireach.margins", lambda m: m == expected_margins(envelope, *slow), "margins")
        second = await page.wait_for(MARKER, lambda m: near(m["speedKt"], 40) and near(m["heightFt"], 250), "marker")
        assert second["x"] < first["x"] and second["y"] > first["y"]  # slower: left; lower: down the canvas

        vehicle.set(low, status_message(DiagnosticStatus.ERROR, "in the unsafe set", *low[:2], -35.0, envelope_id))
        shown = await page.banner("avoid", "AVOID")
        assert shown["word"] == "AVOID"
        await page.wait_for("window.helireach.margins", lambda m: m == expected_margins(envelope, *low), "margins")
        third = await page.wait_for(MARKER, lambda m: near(m["speedKt"], 20) and near(m["heightFt"], 100), "marker")
        assert third["x"] < second["x"] and third["y"] > second["y"]
        save_artifact(tmp_path, "display-avoid.png", await page.screenshot())

        vehicle.set(None, None)  # the status node (and the vehicle) fall silent
        shown = await page.banner("nodata", "STALE once the status topic is silent")
        assert (shown["word"], shown["phase"]) == ("STALE", "stale") and "SAFETY STATUS SILENT" in shown["detail"]
        assert shown["margin"] == {"vertical": "---", "horizontal": "---"}
        await page.wait_for(MARKER, lambda m: m["stale"], "the marker to show a stale state")
        save_artifact(tmp_path, "display-nodata.png", await page.screenshot())

        vehicle.set(cruise, status_message(DiagnosticStatus.OK, "safe", *cruise[:2], 180.0, envelope_id))
        await page.banner("safe", "SAFE again")
        vehicle.set(cruise, status_message(DiagnosticStatus.STALE, "no valid state", *cruise[:2], 180.0, envelope_id))
        shown = await page.banner("nodata", "NO DATA for a STALE status")
        assert "NO VALID STATE" in shown["detail"]

        assert page.errors == [], f"the page reported errors: {page.errors}"

    run_page(browser, ros.display.url, scenario)


def episode_message(phase: EpisodePhase, episode_id: int = 1) -> DiagnosticStatus:
    """The monitor's ``/helireach/failure_episode`` for episode ``episode_id`` in ``phase``."""
    ended = 2_000_000_000 if phase in (EpisodePhase.ENDED, EpisodePhase.LANDED) else None
    started = 1_000_000_000 if episode_id else None
    state = EpisodeState(phase, episode_id, started_ns=started, ended_ns=ended, flag=phase is EpisodePhase.FAILED)
    level = rm.DIAGNOSTIC_LEVELS[state.level_name]
    return rm.diagnostic_status(level, "helireach_monitor: failure episode", state.text, "vehicle", state.as_values())


def touchdown_message(descent_rate: float, forward_speed: float, time_after_failure: float) -> DiagnosticStatus:
    """The vehicle's ``/helireach/touchdown`` (msg_docs/helireach_touchdown.md) for the UH-60A-class limits."""
    limits = load_airframe("uh60a_class").limits
    within = descent_rate <= limits.max_descent_rate and forward_speed <= limits.max_forward_speed
    values = {
        "within_limits": within,
        "descent_rate_m_s": descent_rate,
        "forward_speed_m_s": forward_speed,
        "rotor_speed_pct": 96.0,
        "time_after_failure_s": time_after_failure,
        "max_descent_rate_m_s": limits.max_descent_rate,
        "max_forward_speed_m_s": limits.max_forward_speed,
        "reason": "" if within else "too fast",
    }
    level = DiagnosticStatus.OK if within else DiagnosticStatus.ERROR
    return rm.diagnostic_status(level, "sim: touchdown", "LANDED" if within else "OUTSIDE", "uh60a_class", values)


def robust_verdict_message(robust: str, failure_stamp_ns: int, text: str, failure_id: int = 1) -> DiagnosticStatus:
    """The planner's ``/helireach/robust_verdict`` (msg_docs/helireach_robust_verdict.md) for a failure plan."""
    level = {"pending": DiagnosticStatus.STALE, "true": DiagnosticStatus.OK}.get(robust, DiagnosticStatus.WARN)
    values = {"failure_id": failure_id, "failure_stamp_ns": failure_stamp_ns, "robust": robust}
    if robust != "pending":
        values.update(robust_models_flown=16 if robust == "true" else 1, robust_design_size=16)
    return rm.diagnostic_status(level, "helireach_planner: robust verdict", text, "uh60a_class", values)


def signed_number(text: str) -> float:
    """A page number such as ``+12`` or ``−3`` (U+2212) as a float."""
    return float(text.replace("\u2212", "-").replace("+", ""))


@needs_chromium
def test_whole_run_by_flight_phase(ros: RosHarness, browser: Browser, real_plan: Any, tmp_path: Path) -> None:
    """normal → failure (no plan, then the verified plan) → descent with cues → touchdown → landed → a silent
    source → a landing found in the state → an ended episode: body data-phase/data-level and key texts at each."""
    vehicle = ros.vehicle
    envelope_id = display_envelope_id(ros)
    assert real_plan.safe and real_plan.verified, "the 500 ft / 75 kt plan must be replay-verified for this run"
    cruise = (500 * FT, 75 * KT, 0.0)
    flying = status_message(DiagnosticStatus.OK, "ENGINE FAILURE: landing plan verified", *cruise[:2], 0.0, "")
    trajectory_section_ = rm.read_trajectory(rm.trajectory_message(real_plan, 0))
    flare_times = [
        event.time_s
        for event in plan_cue_events(trajectory_section_[1], *trajectory_section_[2])
        if event.kind == "FLARE"
    ]
    assert flare_times, "the plan has no flare"
    # the plan started this long ago: its flare 3.7 s ahead when it arrives, or as near as a stamp the display
    # believes allows (one under 10 s old; older, it counts from the receipt); the wait for its cue is that longer
    plan_age_s = min(flare_times[0] - 3.7, 9.0)
    cue_wait_s = 5.0 + (flare_times[0] - 3.7 - plan_age_s)
    assert 0.0 < plan_age_s < 10.0

    async def shot(page: DevToolsPage, phase: str) -> None:
        save_artifact(tmp_path, f"display-phase-{phase}.png", await page.screenshot())

    async def scenario(page: DevToolsPage) -> None:
        # NORMAL: the H-V status, no engine strip, no cue
        vehicle.rotor_speed = 27.0
        vehicle.episode = episode_message(EpisodePhase.NORMAL, 0)
        vehicle.set(cruise, status_message(DiagnosticStatus.OK, "safe", *cruise[:2], 180.0, envelope_id))
        shown = await page.phase("normal", "safe", "NORMAL", "SAFE")
        assert shown["engine"] is None and shown["cue"] is None and shown["readouts"]["climbLabel"] == "V/S"
        await shot(page, "normal")

        # engine failure: AUTOROTATION at once, NO PLAN (red) until the plan comes
        for publisher in (vehicle.trajectory_publisher, vehicle.path_publisher, vehicle.plan_status_publisher):
            wait_until(lambda publisher=publisher: publisher.get_subscription_count() > 0, TIMEOUT_S, "display")
        now_ns = vehicle.get_clock().now().nanoseconds
        start = rm.stamp_message(now_ns - round(plan_age_s * 1e9))
        vehicle.failure_publisher.publish(Header(stamp=start, frame_id="failure"))
        vehicle.episode = episode_message(EpisodePhase.FAILED, 1)
        vehicle.set(cruise, flying)
        shown = await page.phase("autorotation", "avoid", "NO PLAN after the failure", "NO PLAN")
        assert shown["engine"] == "ENGINE FAILURE" and shown["timer"].startswith("T+")

        # the verified plan: the banner is the plan; the aircraft a third of the way down it, rotor near its limit
        trajectory, path, plan_status = plan_messages(real_plan, start)
        vehicle.trajectory_publisher.publish(trajectory)
        vehicle.path_publisher.publish(path)
        vehicle.plan_status_publisher.publish(plan_status)
        index = len(real_plan.times) // 3
        y, v, _, h, x = real_plan.states[:5, index]
        vehicle.distance = float(x)
        vehicle.rotor_speed = 1.135 * 27.0  # inside the 3 % amber band below the 115 % limit
        vehicle.set((float(h), float(v), -float(y)), flying)
        await page.phase("autorotation", "safe", "the verified plan", "VERIFIED")
        # its robust verdict: pending, then not robust; a verdict of another failure is not shown beside this plan
        assert (await page.evaluate(PLAN))["robust"] is None
        wait_until(lambda: vehicle.robust_publisher.get_subscription_count() > 0, TIMEOUT_S, "display")
        failure_ns = rm.stamp_nanoseconds(start)
        vehicle.robust_publisher.publish(robust_verdict_message("pending", failure_ns, "PENDING: robust verification"))
        pending = {"kind": "pending", "text": "FIRST PLAN: ROBUST CHECK PENDING"}
        await page.wait_for(PLAN, lambda plan: plan["robust"] == pending, "the robust check pending")
        vehicle.robust_publisher.publish(robust_verdict_message("true", failure_ns + 1, "ROBUST: another failure"))
        await page.wait_for(PLAN, lambda plan: plan["robust"] is None, "no verdict of another failure")
        reason = "first gross_weight+5%: touchdown at 7.4 ft/s and 7.2 kt exceeds the limits"
        vehicle.robust_publisher.publish(robust_verdict_message("false", failure_ns, f"NOT ROBUST: {reason}"))
        not_robust = {"kind": "not_robust", "text": f"FIRST PLAN NOT ROBUST: {reason}"}
        await page.wait_for(PLAN, lambda plan: plan["robust"] == not_robust, "the plan not robust")
        await page.phase("autorotation", "safe", "the verified plan, not robust", "VERIFIED")  # never shown as ROBUST
        shown = await page.wait_for(
            "window.helireach.cue", lambda cue: cue == "FLARE IN 3 s", "the cue FLARE IN 3 s", timeout_s=cue_wait_s
        )
        shown = await page.phase("autorotation", "safe", "the descent", "VERIFIED")
        assert "TOUCHDOWN IN" in shown["detail"]
        readouts = shown["readouts"]
        assert readouts["climbLabel"] == "DESCENT" and readouts["climb"] == f"{y / FT * 60:.0f}"
        assert 20.0 < signed_number(readouts["thrust"]) < 200.0 and readouts["trend"] in ("\u25b2", "\u25bc", "\u25b6")
        assert shown["rotor"] == "caution"
        to_go = (real_plan.states[4, -1] - x) / FT
        assert shown["side"] == {"points": len(real_plan.times), "distance": f"TO TOUCHDOWN {to_go:.0f} ft AHEAD"}
        await shot(page, "autorotation")
        # the flare: the cue says it, then the planned pitch goes nose up past 10°, shown positive (−θ)
        await page.wait_for("window.helireach.cue", lambda cue: cue == "FLARE", "the cue FLARE", timeout_s=5.0)
        await page.wait_for(
            "window.helireach.readouts.pitch", lambda p: p.startswith("+") and signed_number(p) >= 10, "nose up"
        )

        # the rotor sensor falls silent in the descent: STALE, and the verified plan is no longer shown green
        rotor_speed, vehicle.rotor_speed = vehicle.rotor_speed, None
        shown = await page.phase("stale", "nodata", "STALE when the rotor is silent", "STALE")
        assert "ROTOR SILENT" in shown["detail"] and "LAST PHASE AUTOROTATION" in shown["detail"]
        plan = await page.evaluate(PLAN)
        assert plan["badge"] == "VERIFIED" and plan["badgeKind"] == "stale"
        vehicle.rotor_speed = rotor_speed
        await page.phase("autorotation", "safe", "the rotor back", "VERIFIED")

        # touchdown: the vehicle's report decides; the timer stops; the rotor running down is not red
        wait_until(lambda: vehicle.touchdown_publisher.get_subscription_count() > 0, TIMEOUT_S, "display")
        vehicle.rotor_speed = 0.80 * 27.0
        vehicle.set((0.0, 3.0 * KT, 0.0), flying)
        vehicle.touchdown_publisher.publish(touchdown_message(4.6 * FT, 3.1 * KT, 12.1))
        shown = await page.phase("landed", "safe", "LANDED within limits", "LANDED \u00b7 WITHIN LIMITS")
        limits = load_airframe("uh60a_class").limits
        assert f"SINK 4.6 ft/s (LIMIT {limits.max_descent_rate / FT:.0f})" in shown["detail"]
        assert f"SPEED 3.1 kt (LIMIT {limits.max_forward_speed / KT:.0f})" in shown["detail"]
        assert shown["engine"] == "ENGINE FAILURE \u00b7 LANDED" and shown["timer"] == "TOUCHDOWN AT T+12.1 s"
        vehicle.episode = episode_message(EpisodePhase.LANDED, 1)
        shown = await page.phase("landed", "safe", "LANDED by the episode too", "LANDED \u00b7 WITHIN LIMITS")
        assert shown["rotor"] == "ground" and shown["timer"] == "TOUCHDOWN AT T+12.1 s"
        await shot(page, "landed")

        # a silent source: STALE, grey, the last values struck out
        vehicle.set(None, flying)
        shown = await page.phase("stale", "nodata", "STALE when the state is silent", "STALE")
        assert "STATE SILENT" in shown["detail"] and "LAST PHASE LANDED" in shown["detail"]
        decoration = await page.evaluate("getComputedStyle(document.getElementById('height-value')).textDecorationLine")
        assert decoration == "line-through"
        await shot(page, "stale")

        # episode 2: a fallback, then a touchdown found in the state (no report): within limits, but only amber
        vehicle.rotor_speed = 27.0
        vehicle.set((30 * FT, 20 * KT, -2.0), flying)
        vehicle.failure_publisher.publish(Header(stamp=vehicle.get_clock().now().to_msg(), frame_id="failure"))
        vehicle.episode = episode_message(EpisodePhase.FAILED, 2)
        await page.phase("autorotation", "avoid", "episode 2: the old plan is gone", "NO PLAN")
        fallback = DiagnosticStatus(
            level=DiagnosticStatus.WARN,
            message="FALLBACK: nearest envelope plan",
            values=[KeyValue(key="fallback", value="true"), KeyValue(key="verified", value="false")],
        )
        vehicle.plan_status_publisher.publish(fallback)
        await page.phase("autorotation", "caution", "FALLBACK, never green", "FALLBACK")
        vehicle.set((2.0, 5.0 * KT, -1.5), flying)
        await page.wait_for(MARKER, lambda m: near(m["heightFt"], 2.0 / FT, 0.5), "the aircraft near the ground")
        vehicle.set((0.0, 2.0 * KT, -1.2), flying)
        shown = await page.phase("landed", "caution", "LANDED, the report awaited", "LANDED")
        assert shown["detail"] == "AWAITING THE TOUCHDOWN REPORT"
        shown = await page.phase("landed", "caution", "LANDED from the state", "LANDED \u00b7 WITHIN LIMITS")
        # the larger rates of the last state above and the contact state (1.5 m/s and 5 kt above, 1.2 and 2 below)
        assert "FROM STATE" in shown["detail"] and f"SINK {1.5 / FT:.1f} ft/s" in shown["detail"]
        assert "SPEED 5.0 kt" in shown["detail"]

        # episode 3: the engine relights: ENDED, no plan, the H-V status again
        vehicle.set(cruise, status_message(DiagnosticStatus.OK, "safe", *cruise[:2], 180.0, envelope_id))
        vehicle.failure_publisher.publish(Header(stamp=vehicle.get_clock().now().to_msg(), frame_id="failure"))
        vehicle.episode = episode_message(EpisodePhase.FAILED, 3)
        await page.phase("autorotation", "avoid", "episode 3: episode 2's fallback is gone", "NO PLAN")
        vehicle.episode = episode_message(EpisodePhase.ENDED, 3)
        vehicle.plan_status_publisher.publish(ended_plan_status())
        shown = await page.phase("ended", "safe", "ENDED", "ENGINE RECOVERED")
        assert shown["engine"] == "ENGINE RECOVERED \u00b7 EPISODE ENDED" and "NO LANDING PLAN" in shown["detail"]
        plan = await page.wait_for(PLAN, lambda p: p["state"] == "ended" and p.get("badge") == "ENDED", "ENDED")
        assert plan["shown"] is False
        await shot(page, "ended")
        assert page.errors == [], f"the page reported errors: {page.errors}"

    run_page(browser, ros.display.url, scenario)


def ended_plan_status() -> DiagnosticStatus:
    """The planner's plan status once the episode ended (msg_docs/helireach_plan_status.md)."""
    values = {"status": "ended", "safe": False, "verified": False, "fallback": False, "failure_id": 1}
    text = "ENDED (engine recovered): no landing plan; the last trajectory no longer applies"
    return rm.diagnostic_status(DiagnosticStatus.WARN, "helireach_planner: landing plan", text, "test", values)


def test_robust_verdict_section_reads_the_verdict_and_its_failure() -> None:
    pending = robust_verdict_section(robust_verdict_message("pending", 42, "PENDING: robust verification"))
    assert (pending["robust"], pending["failure_id"], pending["failure_stamp_ns"]) == (
        "pending",
        "1",
        "42",
    )  # ids as sent
    assert pending["level"] == "nodata" and pending["models_flown"] is None and pending["error"] is False
    robust = robust_verdict_section(robust_verdict_message("true", 42, "ROBUST: lands"))
    assert (robust["robust"], robust["models_flown"], robust["design_size"], robust["level"]) == (
        "true",
        16,
        16,
        "safe",
    )
    failed = robust_verdict_message("false", 42, "NOT ROBUST: no verdict")
    failed.values.append(KeyValue(key="robust_error", value="true"))
    assert robust_verdict_section(failed)["error"] is True
    garbled = robust_verdict_section(robust_verdict_message("maybe", 42, "?"))
    assert garbled["robust"] is None  # the page shows no verdict rather than guess one


def test_episode_and_plan_status_sections_show_ended_and_late_never_verified_green() -> None:
    ended = plan_status_section(ended_plan_status())
    assert (ended["status"], ended["safe"], ended["verified"], ended["level"]) == ("ended", False, False, "caution")
    for phase in EpisodePhase:
        section = episode_section(episode_message(phase))
        assert (section["phase"], section["episode_id"]) == (phase.value, 1)
    assert episode_section(episode_message(EpisodePhase.ENDED))["message"].startswith("ENDED (engine recovered)")
    broken = DiagnosticStatus(level=DiagnosticStatus.OK, values=[KeyValue(key="phase", value="ended")])
    assert episode_section(broken)["phase"] == "unknown" and episode_section(broken)["level"] == "nodata"
    late = rm.diagnostic_status(
        DiagnosticStatus.WARN,
        "helireach_planner: landing plan",
        "LATE (state 3.5 s after the failure, 2.5 s too late): SAFE: land in 9.9 s",
        "test",
        {"status": "safe", "safe": True, "verified": True, "late": True, "late_by_s": 2.5, "state_delay_s": 3.5},
    )
    section = plan_status_section(late)
    assert (section["late"], section["late_by_s"], section["state_delay_s"], section["level"]) == (
        True,
        2.5,
        3.5,
        "caution",
    )


def envelope_points(envelope: Any, warn_margin: float) -> tuple[tuple[float, float], ...]:
    """(height m, speed m/s) of a state well inside the safe set, one near its boundary and one unsafe."""
    heights = np.linspace(50 * FT, float(envelope.heights[-1]) - 10 * FT, 40)
    speeds = np.linspace(0.0, float(envelope.speeds[-1]) - 5 * KT, 120)
    found: dict[str, tuple[float, float]] = {}
    for height in heights:
        for speed in speeds:
            query = envelope.query(float(height), float(speed))
            if query.status == "safe" and query.margin > 3 * warn_margin:
                found.setdefault("safe", (float(height), float(speed)))
            elif query.status == "safe" and 0.2 * warn_margin < query.margin < 0.8 * warn_margin:
                found.setdefault("caution", (float(height), float(speed)))
            elif query.status == "unsafe":
                found.setdefault("avoid", (float(height), float(speed)))
    assert found.keys() == {"safe", "caution", "avoid"}, f"the envelope lacks test points: {found}"
    return found["safe"], found["caution"], found["avoid"]


@needs_chromium
def test_page_follows_the_real_status_node(browser: Browser, envelope_file: Path, tmp_path: Path) -> None:
    from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
    from helireach_ros.ros.nodes.monitor import VehicleMonitor

    harness = RosHarness(vehicle_topic="/vehicle/odometry", envelope_file=str(envelope_file))
    try:
        harness.add(VehicleMonitor(context=harness.context))
        status_node = harness.add(
            EnvelopeStatusNode(
                context=harness.context, parameter_overrides=[Parameter("envelope_file", value=str(envelope_file))]
            )
        )
        warn_margin = status_node.get_parameter("warn_margin").value
        safe, caution, avoid = envelope_points(load_envelope(envelope_file), warn_margin)
        harness.vehicle.rotor_speed = 27.0

        async def scenario(page: DevToolsPage) -> None:
            for (height, speed), level in ((safe, "safe"), (caution, "caution"), (avoid, "avoid")):
                harness.vehicle.set((height, speed, 0.0))
                await page.banner(level, f"{level} from the status node at {height / FT:.0f} ft {speed / KT:.0f} kt")
                await page.wait_for(MARKER, lambda m, h=height: near(m["heightFt"], h / FT), "the marker")
            harness.vehicle.set(None)  # the vehicle falls silent: the status node says STALE, the display too
            shown = await page.banner("nodata", "NO DATA or STALE once the vehicle is silent")
            assert "OLD" in shown["detail"] or "STATE SILENT" in shown["detail"], shown

        run_page(browser, harness.display.url, scenario)
    finally:
        harness.close()


# ------------------------------------------------------------------------------------------------------------
# The ``helireach display`` command in its own process: a frozen server, Ctrl-C with --hold, a lost link
# ------------------------------------------------------------------------------------------------------------


class StatusOnlyPublisher(Node):
    """Publishes a latched SAFE safety status at 10 Hz (the status node's steady rate)."""

    def __init__(self, context: Context, envelope_id: str) -> None:
        super().__init__("display_test_status", context=context)
        self.publisher = self.create_publisher(DiagnosticStatus, "/helireach/safety_status", LATCHED)
        status = status_message(DiagnosticStatus.OK, "safe", 150.0, 38.0, 120.0, envelope_id)
        self.create_timer(0.1, lambda: self.publisher.publish(status))


@needs_chromium
def test_display_command_link_quiet_hold_and_lost(
    browser: Browser, envelope_file: Path, localhost_ros_domain: int
) -> None:
    command = [sys.executable, "-m", "helireach_ros.cli.main", "display", "--port", "0", "--stale-after", "2"]
    command += ["--envelope", str(envelope_file), "--hold"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=REPO)
    context = Context()
    rclpy.init(context=context)
    publisher = StatusOnlyPublisher(context, load_envelope(envelope_file).envelope_id)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(publisher)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.extend(iter(process.stdout.readline, "")), daemon=True)
        reader.start()
        wait_until(lambda: any("http://" in line for line in lines), CROSS_PROCESS_TIMEOUT_S, "the display URL")
        url = next(line for line in lines if "http://" in line).split()[-1]
        assert url.startswith("http://127.0.0.1:")

        async def scenario(page: DevToolsPage) -> None:
            await page.banner("safe", "SAFE across processes", CROSS_PROCESS_TIMEOUT_S)
            process.send_signal(signal.SIGSTOP)  # the server freezes with the WebSocket open
            try:
                await page.banner("nodata", "NO DATA when the link goes quiet", detail="DISPLAY SERVER")
                assert await page.evaluate("window.helireach.link") == "quiet"
            finally:
                process.send_signal(signal.SIGCONT)
            await page.banner("safe", "SAFE after the server resumes")

            process.send_signal(signal.SIGINT)  # ROS stops; --hold keeps the page
            await page.banner("nodata", "NO DATA while held", detail="HELD")
            async with aiohttp.ClientSession() as http, http.get(url) as response:
                assert response.status == 200
            assert process.poll() is None

            process.send_signal(signal.SIGINT)
            await page.banner("nodata", "NO DATA once the display is gone", detail="LINK LOST")

        run_page(browser, url, scenario)
        assert process.wait(timeout=CROSS_PROCESS_TIMEOUT_S) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        publisher.destroy_node()
        rclpy.try_shutdown(context=context)


# ------------------------------------------------------------------------------------------------------------
# Envelope problems: the diagram says NO DATA, everything else works
# ------------------------------------------------------------------------------------------------------------


def websocket_url(display: CockpitDisplay) -> str:
    return display.url.replace("http://", "ws://", 1) + "ws"


async def read_frame(socket: aiohttp.ClientWebSocketResponse, timeout_s: float = TIMEOUT_S) -> dict[str, Any]:
    message = await asyncio.wait_for(socket.receive(), timeout=timeout_s)
    assert message.type == aiohttp.WSMsgType.TEXT, f"expected a text frame, got {message}"
    return strict_json(message.data)


async def frame_until(
    socket: aiohttp.ClientWebSocketResponse, predicate: Callable[[dict[str, Any]], bool], what: str
) -> dict[str, Any]:
    deadline = time.monotonic() + TIMEOUT_S
    while time.monotonic() < deadline:
        frame = await read_frame(socket, max(deadline - time.monotonic(), 0.01))
        if predicate(frame):
            return frame
    pytest.fail(f"no frame with {what} within {TIMEOUT_S} s")


def live_level(frame: dict[str, Any]) -> str:
    return frame["live"]["status"]["level"]


@needs_chromium
def test_missing_envelope_shows_no_data_diagram(browser: Browser, tmp_path: Path) -> None:
    missing = tmp_path / "no_such_envelope.npz"
    harness = RosHarness(envelope_file=str(missing))
    try:
        status = status_message(DiagnosticStatus.OK, "safe", 150.0, 38.0, 120.0, "x")
        harness.vehicle.set((150.0, 38.0, 0.0), status)

        async def scenario(page: DevToolsPage) -> None:
            await page.banner("safe", "SAFE without an envelope")
            await page.wait_for(
                "document.getElementById('hv-nodata').hidden", lambda hidden: hidden is False, "diagram NO DATA"
            )
            reason = await page.evaluate("document.getElementById('hv-nodata-reason').textContent")
            assert str(missing) in reason
            await page.wait_for(MARKER, lambda m: near(m["heightFt"], 150.0 / FT), "the marker on default axes")
            save_artifact(tmp_path, "display-no-envelope.png", await page.screenshot())

        run_page(browser, harness.display.url, scenario)
    finally:
        harness.close()


def test_corrupt_envelope_gives_no_data_diagram(tmp_path: Path, envelope_file: Path) -> None:
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(envelope_file.read_bytes()[: envelope_file.stat().st_size // 2])  # truncated
    harness = RosHarness(envelope_file=str(corrupt))
    try:
        harness.vehicle.set((150.0, 38.0, 0.0), status_message(DiagnosticStatus.ERROR, "unsafe", 150, 38, -3, "x"))

        async def scenario() -> None:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as socket:
                first = await read_frame(socket)
                assert first["envelope"]["available"] is False
                assert str(corrupt) in first["envelope"]["reason"]
                assert first["config"]["rotor_limits"] is None  # no envelope, no airframe given
                await frame_until(socket, lambda f: live_level(f) == "avoid", "AVOID without an envelope")

        asyncio.run(scenario())
    finally:
        harness.close()


# ------------------------------------------------------------------------------------------------------------
# Server behaviour: latest value only, read-only, files, many pages, bad input, binding, shutdown
# ------------------------------------------------------------------------------------------------------------


def test_frames_carry_the_latest_state_and_are_rate_limited(envelope_file: Path) -> None:
    harness = RosHarness(envelope_file=str(envelope_file), max_update_rate_hz=5.0)
    state_count = 500
    try:

        async def scenario() -> int:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as socket:
                await read_frame(socket)
                message = Odometry()
                for index in range(state_count):  # ~1 kHz for ~0.5 s, while this page reads nothing
                    message.pose.pose.position.z = float(index)
                    harness.vehicle.state_publisher.publish(message)
                    await asyncio.sleep(0.001)
                last = float(state_count - 1)
                frames = 0
                while True:
                    frame = await read_frame(socket)
                    frames += 1
                    state = frame["live"]["state"]
                    if state and state["height_m"] == last:
                        return frames

        frames = asyncio.run(scenario())
        # one frame per state would be 500; at 5 frames/s (+ heartbeats) a page gets a handful
        assert frames < state_count // 10, f"{frames} frames for {state_count} states: frames are not dropped"
    finally:
        harness.close()


def test_display_is_read_only(envelope_file: Path) -> None:
    harness = RosHarness(envelope_file=str(envelope_file))
    try:
        harness.vehicle.set((150.0, 38.0, 0.0), status_message(DiagnosticStatus.WARN, "near", 150, 38, 8, "x"))

        async def scenario() -> None:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as socket:
                await frame_until(socket, lambda f: live_level(f) == "caution", "CAUTION")
                for text in ('{"command": "set_status", "level": 0}', "engine_failure", "x" * 1000):
                    await socket.send_str(text)
                await socket.send_bytes(b"\x00\x01\x02")
                # the browser's words change nothing; frames keep coming on the same connection
                for _ in range(5):
                    frame = await read_frame(socket)
                    assert live_level(frame) == "caution"
                assert not socket.closed

        asyncio.run(scenario())
        topics = {name for name, _ in harness.display.get_publisher_names_and_types_by_node("helireach_display", "/")}
        assert topics <= {"/rosout", "/parameter_events"}, f"the display publishes {topics}"
    finally:
        harness.close()


def test_serves_only_the_page_files(envelope_file: Path) -> None:
    harness = RosHarness(envelope_file=str(envelope_file))
    try:

        async def scenario() -> None:
            base = harness.display.url
            async with aiohttp.ClientSession() as http:
                for path, content_type in (("", "text/html"), ("app.js", "text/javascript"), ("style.css", "text/css")):
                    async with http.get(base + path) as response:
                        assert response.status == 200, path
                        assert response.content_type == content_type
                        assert "default-src 'none'" in response.headers["Content-Security-Policy"]
                        assert (await response.read()) == (web_directory() / (path or "index.html")).read_bytes()
                for path in ("../setup.py", "%2e%2e/setup.py", "web/app.js", "config/planner.yaml", "display.py"):
                    async with http.get(base + path) as response:
                        assert response.status == 404, path
                async with http.ws_connect(websocket_url(harness.display), origin="http://evil.example") as socket:
                    pytest.fail(f"cross-origin WebSocket accepted: {socket}")

        with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
            asyncio.run(scenario())
        assert refused.value.status == 403
    finally:
        harness.close()


def test_host_header_check(envelope_file: Path) -> None:
    """Only loopback names, the bound address and ``allowed_hosts`` with the server's port are answered (421)."""
    harness = RosHarness(envelope_file=str(envelope_file), allowed_hosts="cockpit.example, Panel.Local:9000")
    try:
        port = int(harness.display.url.rsplit(":", 1)[1].strip("/"))

        async def status(http: aiohttp.ClientSession, host: str, path: str = "") -> tuple[int, str]:
            async with http.get(harness.display.url + path, headers={"Host": host}) as response:
                return response.status, await response.text()

        async def scenario() -> None:
            async with aiohttp.ClientSession() as http:
                for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}", f"Cockpit.Example:{port}"):
                    assert (await status(http, host))[0] == 200, host
                assert (await status(http, "panel.local:9000", "app.js"))[0] == 200
                for host in ("evil.example", f"evil.example:{port}", f"127.0.0.1:{port + 1}", "localhost", ""):
                    code, text = await status(http, host)
                    assert code == 421 and "not served here" in text, host
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    async with http.ws_connect(websocket_url(harness.display), headers={"Host": "evil.example"}):
                        pass
                assert refused.value.status == 421

        asyncio.run(scenario())
    finally:
        harness.close()


def test_page_files_load_nothing_from_elsewhere() -> None:
    for name in ("index.html", "app.js", "style.css"):
        text = (web_directory() / name).read_text()
        for forbidden in ("http://", "https://", "@import", "@font-face", "url(", 'src="//'):
            assert forbidden not in text, f"{name} contains {forbidden!r}"
    html = (web_directory() / "index.html").read_text()
    assert 'src="app.js"' in html and 'href="style.css"' in html


def test_many_pages_and_reconnects(envelope_file: Path) -> None:
    harness = RosHarness(envelope_file=str(envelope_file))
    try:
        harness.vehicle.set((150.0, 38.0, 0.0), status_message(DiagnosticStatus.OK, "safe", 150, 38, 50, "x"))

        async def scenario() -> None:
            sessions = [aiohttp.ClientSession() for _ in range(8)]
            sockets = [await session.ws_connect(websocket_url(harness.display)) for session in sessions]
            for socket in sockets:
                first = await read_frame(socket)
                assert {"config", "envelope", "plan", "live"} <= first.keys()
            wait_until(lambda: harness.display.page_count == 8, TIMEOUT_S, "8 pages")
            for session in sessions[:4]:  # vanish without a close handshake, like a killed browser
                await session.connector.close()
            for socket in sockets[4:]:
                await frame_until(socket, lambda f: live_level(f) == "safe", "SAFE on a surviving page")
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as again:
                await frame_until(again, lambda f: live_level(f) == "safe", "SAFE after a reconnect")
            for socket, session in zip(sockets[4:], sessions[4:], strict=True):
                await socket.close()
                await session.close()
            for session in sessions[:4]:
                await session.close()

        asyncio.run(scenario())
        wait_until(lambda: harness.display.page_count == 0, TIMEOUT_S, "every page to be gone")
    finally:
        harness.close()


def test_bad_messages_never_break_the_page(envelope_file: Path) -> None:
    harness = RosHarness(envelope_file=str(envelope_file))
    vehicle = harness.vehicle
    try:

        async def scenario() -> None:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as socket:
                vehicle.set((math.nan, math.inf, -math.inf), status_message(DiagnosticStatus.OK, "ok", 1, 1, 1, "x"))
                frame = await frame_until(socket, lambda f: f["live"]["state"] is not None, "a NaN state")
                assert frame["live"]["state"]["height_m"] is None and frame["live"]["state"]["speed_ms"] is None

                odd = DiagnosticStatus(level=b"\x07", message="level from the future", values=[])
                vehicle.set(None, odd)
                frame = await frame_until(socket, lambda f: f["live"]["status"]["message"] == odd.message, "odd")
                assert live_level(frame) == "nodata" and frame["live"]["status"]["margin"] is None

                other = status_message(DiagnosticStatus.OK, "ok", 1, 1, math.nan, "not-this-envelope")
                vehicle.set(None, other)
                frame = await frame_until(socket, lambda f: f["live"]["status"]["envelope_mismatch"], "mismatch")
                assert live_level(frame) == "safe" and frame["live"]["status"]["margin"] is None

                vehicle.rotor_publisher.publish(JointState(name=["tail_rotor"], velocity=[100.0]))
                frame = await frame_until(socket, lambda f: f["live"]["rotor"] is not None, "a rotor message")
                assert frame["live"]["rotor"]["speed_rad_s"] is None

                for publisher in (vehicle.trajectory_publisher, vehicle.path_publisher):
                    wait_until(lambda p=publisher: p.get_subscription_count() > 0, TIMEOUT_S, "display")
                broken = JointTrajectory(joint_names=["pitch_angle"], points=[JointTrajectoryPoint(positions=[0.1])])
                vehicle.trajectory_publisher.publish(broken)
                vehicle.path_publisher.publish(PathMsg())
                frame = await frame_until(
                    socket, lambda f: bool(f.get("plan") and f["plan"]["trajectory"] and f["plan"]["path"]), "plan"
                )
                assert "collective_thrust_coefficient" in frame["plan"]["trajectory"]["error"]
                assert "no poses" in frame["plan"]["path"]["error"]

                vehicle.set((100.0, 30.0, 0.0), status_message(DiagnosticStatus.ERROR, "unsafe", 100, 30, -4, "x"))
                await frame_until(socket, lambda f: live_level(f) == "avoid", "the node still working")

        asyncio.run(scenario())
    finally:
        harness.close()


def test_a_display_started_after_the_failure_shows_the_latched_plan(envelope_file: Path, real_plan: Any) -> None:
    harness = RosHarness(envelope_file=str(envelope_file))
    try:
        trajectory, path, plan_status = plan_messages(real_plan, harness.vehicle.get_clock().now().to_msg())
        harness.vehicle.trajectory_publisher.publish(trajectory)
        harness.vehicle.path_publisher.publish(path)
        harness.vehicle.plan_status_publisher.publish(plan_status)
        late = harness.add(
            CockpitDisplay(
                context=harness.context,
                parameter_overrides=[Parameter("port", value=0), Parameter("envelope_file", value=str(envelope_file))],
            )
        )

        async def scenario() -> None:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(late)) as socket:
                frame = await frame_until(
                    socket,
                    lambda f: bool(f.get("plan") and all(f["plan"][part] for part in ("trajectory", "path", "status"))),
                    "the whole plan",
                )
                plan = frame["plan"]
                assert len(plan["trajectory"]["t_s"]) == len(trajectory.points)
                assert len(plan["path"]["speed_ms"]) == len(real_plan.times)
                assert plan["status"]["time_to_land_s"] == pytest.approx(real_plan.time_to_land, abs=1e-3)

        asyncio.run(scenario())
    finally:
        harness.close()


def test_loopback_by_default_and_a_clear_error_for_a_busy_port(envelope_file: Path) -> None:
    harness = RosHarness(envelope_file=str(envelope_file))
    try:
        assert harness.display.get_parameter("bind").value == "127.0.0.1"
        assert harness.display.url.startswith("http://127.0.0.1:")
        busy_port = int(harness.display.url.rsplit(":", 1)[1].strip("/"))
        with pytest.raises(DisplayServerError, match=f"127.0.0.1:{busy_port}"):
            CockpitDisplay(context=harness.context, parameter_overrides=[Parameter("port", value=busy_port)])
        with socket.create_connection(("127.0.0.1", busy_port), timeout=5):  # the first one still serves
            pass
    finally:
        harness.close()


def test_destroy_node_closes_pages_and_the_port(envelope_file: Path) -> None:
    harness = RosHarness(envelope_file=str(envelope_file))
    url = harness.display.url
    try:

        async def scenario() -> None:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as page:
                await read_frame(page)
                harness.destroy_display()
                while True:
                    message = await asyncio.wait_for(page.receive(), timeout=TIMEOUT_S)
                    if message.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED):
                        break
                assert page.close_code == aiohttp.WSCloseCode.GOING_AWAY
                with pytest.raises(aiohttp.ClientConnectorError):
                    async with http.get(url):
                        pass

        asyncio.run(scenario())
    finally:
        harness.close()


# ------------------------------------------------------------------------------------------------------------
# Pure helpers
# ------------------------------------------------------------------------------------------------------------


def test_banner_levels() -> None:
    assert banner_level(DiagnosticStatus.OK) == "safe"
    assert banner_level(DiagnosticStatus.WARN) == "caution"
    assert banner_level(DiagnosticStatus.ERROR) == "avoid"
    assert banner_level(DiagnosticStatus.STALE) == "nodata"
    assert banner_level(b"\x09") == "nodata"  # unknown is never optimistic
    assert banner_level(1) == "caution"


def test_rotor_limits_from_airframe_and_envelope_metadata() -> None:
    airframe = load_airframe("uh60a_class")
    expected = (
        airframe.nominal_rotor_speed,
        airframe.limits.min_rotor_speed_ratio * airframe.nominal_rotor_speed,
        airframe.limits.max_rotor_speed_ratio * airframe.nominal_rotor_speed,
    )
    for limits in (
        rotor_limits_section(airframe=airframe),
        rotor_limits_section(metadata={"airframe": airframe.as_dict()}),
    ):
        assert limits is not None
        assert (limits["nominal_rad_s"], limits["min_rad_s"], limits["max_rad_s"]) == pytest.approx(expected)
    assert rotor_limits_section(metadata={"airframe": {"name": "x"}}) is None
    assert rotor_limits_section(metadata={}) is None


def test_path_speed_needs_increasing_stamps() -> None:
    path = PathMsg()
    for index in range(5):
        pose = PoseStamped()
        pose.header.stamp = TimeMsg(sec=100 + index, nanosec=0)
        pose.pose.position.x = 3.0 * index**2  # x = 3 t², v = 6 t
        pose.pose.position.z = 50.0 - index
        path.poses.append(pose)
    section = path_section(path)
    assert section["speed_ms"][1:4] == pytest.approx([6.0, 12.0, 18.0])  # central differences are exact here
    assert section["z_m"] == [50.0, 49.0, 48.0, 47.0, 46.0]
    for pose in path.poses:
        pose.header.stamp = TimeMsg()
    assert path_section(path)["speed_ms"] is None


def undirected(segments: list[tuple[float, ...]]) -> list[tuple[tuple[float, ...], ...]]:
    """Segments as sorted pairs of end points (a segment has no direction)."""
    return sorted(tuple(sorted((segment[:2], segment[2:]))) for segment in segments)


def test_boundary_points_join_into_cell_segments() -> None:
    heights = np.array([0.0, 10.0, 20.0])
    speeds = np.array([0.0, 5.0, 10.0])
    safe = np.array([[False, True, True], [False, True, True], [True, True, True]])
    # one point on each edge between a safe and an unsafe node, plus a node point that also lies on them
    points = np.array([[0.0, 3.0], [10.0, 2.0], [14.0, 0.0], [10.0, 5.0]])
    segments = boundary_segments(heights, speeds, safe, points)
    assert undirected(segments) == undirected([(0.0, 3.0, 10.0, 2.0), (10.0, 2.0, 14.0, 0.0)])
    # a saddle cell: the two safe corners are cut off, never joined
    saddle = np.array([[True, False], [False, True]])
    crossings = np.array([[0.0, 2.0], [5.0, 5.0], [10.0, 3.0], [4.0, 0.0]])
    segments = boundary_segments(heights[:2], speeds[:2], saddle, crossings)
    assert undirected(segments) == undirected([(0.0, 2.0, 4.0, 0.0), (5.0, 5.0, 10.0, 3.0)])


# ------------------------------------------------------------------------------------------------------------
# The side view's ground line: the live reachable footprint and the landing site
# ------------------------------------------------------------------------------------------------------------

GROUND = "window.helireach && window.helireach.ground"
SIDE_PANEL_HIDDEN = "document.getElementById('side-panel').hidden"
HERE_M = 1000.0  # the vehicle's along-track distance in these tests, m
CRUISE = (500 * FT, 75 * KT, 0.0)


def cruise_state() -> np.ndarray:
    """The measured state (y, v, Ω, h, z, P) a footprint or live verdict is solved from."""
    return np.array([0.0, CRUISE[1], 27.0, CRUISE[0], HERE_M, 0.0])


def replayed_landing(start: np.ndarray, touchdown_m: float, window: Any = None, safe: bool = True) -> Any:
    """A stand-in for a replay-verified LandingPlan touching down at ``touchdown_m`` along the track: only what the
    planner's reports read of one (safe, the start, the replay's touchdown, the site window it was made for)."""
    touchdown = np.array(start, dtype=float)
    touchdown[StateIndex.DISTANCE], touchdown[StateIndex.HEIGHT] = touchdown_m, 0.0
    replay = SimpleNamespace(touchdown_state=touchdown)
    return SimpleNamespace(
        safe=safe, initial_state=np.asarray(start, dtype=float), replay=replay, touchdown_window=window
    )


def footprint_message(
    stamp_ns: int, nearest_m: float | None, farthest_m: float | None, sites: SiteSelection | None = None
) -> DiagnosticStatus:
    """The planner's ``/helireach/reachable_footprint`` (msg_docs/helireach_reachable_footprint.md) from the cruise
    state, made by its own report: ends along the track, m (None: that end not verified, sent as NaN)."""
    state = cruise_state()
    nearest, farthest = (None if end is None else replayed_landing(state, end) for end in (nearest_m, farthest_m))
    report = footprint_report(nearest, farthest, state=state, stamp_ns=stamp_ns, solve_time_ms=850.0, sites=sites)
    level = rm.DIAGNOSTIC_LEVELS[report.level]
    return rm.diagnostic_status(
        level, "helireach_planner: reachable footprint", report.text, "uh60a_class", report.values
    )


def footprint_off_message() -> DiagnosticStatus:
    """The planner's one STALE footprint at start-up when it solves none."""
    report = footprint_off_report("footprint_period is 0")
    level = rm.DIAGNOSTIC_LEVELS[report.level]
    return rm.diagnostic_status(
        level, "helireach_planner: reachable footprint", report.text, "uh60a_class", report.values
    )


def live_site_message(stamp_ns: int, site: LandingSite, touchdown_m: float, aimed: bool = True) -> DiagnosticStatus:
    """A safe ``/helireach/live_reachability`` verdict from the cruise state with its landing-site keys: a plan made
    for ``site`` (``aimed``; else one landing anywhere) whose replay touches down at ``touchdown_m``."""
    plan = replayed_landing(cruise_state(), touchdown_m, (site.start_m, site.end_m) if aimed else None)
    values = {
        "status": "safe",
        "safe": True,
        "verified": True,
        "state_stamp_ns": stamp_ns,
        **site_values(site, plan, 1),
    }
    text = "if the engine failed now: SAFE"
    return rm.diagnostic_status(
        DiagnosticStatus.OK, "helireach_planner: live reachability", text, "uh60a_class", values
    )


def fly_cruise(harness: RosHarness) -> None:
    """The vehicle in steady cruise at ``HERE_M``: state, rotor, SAFE status, a normal episode (phase normal)."""
    vehicle = harness.vehicle
    vehicle.distance = HERE_M
    vehicle.rotor_speed = 27.0
    vehicle.episode = episode_message(EpisodePhase.NORMAL, 0)
    vehicle.set(CRUISE, status_message(DiagnosticStatus.OK, "safe", *CRUISE[:2], 180.0, display_envelope_id(harness)))


@needs_chromium
def test_side_view_draws_the_footprint_band_and_the_landing_site(
    ros: RosHarness, browser: Browser, tmp_path: Path
) -> None:
    """Both ends verified: a band between them on the ground line; the live verdict's site, named and REACHABLE;
    once both stop coming (older than the live age), no band and the site's reachability STALE."""
    vehicle = ros.vehicle
    alpha = LandingSite("alpha", HERE_M + 400.0, HERE_M + 600.0)
    sites = SiteSelection([alpha])

    async def scenario(page: DevToolsPage) -> None:
        fly_cruise(ros)
        await page.phase("normal", "safe", "NORMAL", "SAFE")
        assert await page.evaluate(SIDE_PANEL_HIDDEN) is True  # no footprint, no site: no side view in cruise

        vehicle.footprint = lambda now_ns: footprint_message(now_ns, HERE_M + 250.0, HERE_M + 900.0, sites)
        vehicle.live = lambda now_ns: live_site_message(now_ns, alpha, HERE_M + 500.0)
        ground = await page.wait_for(
            GROUND,
            lambda g: bool(g["footprint"] and g["site"]) and g["site"]["kind"] == "reachable",
            "the footprint band and the reachable site",
        )
        footprint, site = ground["footprint"], ground["site"]
        assert footprint["drawn"] == "band"
        assert footprint["nearFt"] == pytest.approx((HERE_M + 250.0) / FT)
        assert footprint["farFt"] == pytest.approx((HERE_M + 900.0) / FT)
        assert ground["text"] == f"FOOTPRINT {250.0 / FT:.0f}\u2013{900.0 / FT:.0f} ft AHEAD \u00b7 1 SITE IN FOOTPRINT"
        assert (site["name"], site["source"], site["inFootprint"]) == ("ALPHA", "live", "reachable")
        assert site["label"] == "SITE ALPHA \u00b7 REACHABLE"
        assert (site["startFt"], site["endFt"]) == pytest.approx((alpha.start_m / FT, alpha.end_m / FT))
        assert await page.evaluate(SIDE_PANEL_HIDDEN) is False
        assert await page.evaluate("document.getElementById('side-footprint').textContent") == ground["text"]
        assert await page.evaluate("document.getElementById('side-title').textContent") == (
            "SIDE VIEW \u00b7 LANDING AREA"
        )
        assert await page.evaluate("document.getElementById('side-distance').hidden") is True  # no plan
        save_artifact(tmp_path, "display-footprint.png", await page.screenshot())

        # a verdict that found no plan for the site: NOT REACHABLE (red), whatever the footprint says
        vehicle.live = lambda now_ns: live_site_message(now_ns, alpha, HERE_M + 300.0, aimed=False)
        await page.wait_for(
            GROUND,
            lambda g: bool(g["site"]) and g["site"]["label"] == "SITE ALPHA \u00b7 NOT REACHABLE",
            "the site not reachable",
        )

        # the planner stops: the latched messages age past the live age; no band, the site no longer judged
        vehicle.footprint = vehicle.live = None
        ground = await page.wait_for(
            GROUND,
            lambda g: (
                g["footprint"] is None and g["text"].startswith("FOOTPRINT STALE") and g["site"]["kind"] == "stale"
            ),
            "the footprint and the site stale",
        )
        assert ground["site"]["label"] == "SITE ALPHA \u00b7 REACHABILITY STALE"
        assert await page.evaluate("document.getElementById('side-footprint').dataset.kind") == "stale"
        save_artifact(tmp_path, "display-footprint-stale.png", await page.screenshot())
        assert page.errors == [], f"the page reported errors: {page.errors}"

    run_page(browser, ros.display.url, scenario)


@needs_chromium
def test_side_view_one_verified_end_is_a_mark_not_a_band(ros: RosHarness, browser: Browser, tmp_path: Path) -> None:
    """One end verified (the other NaN): a mark at that end only and the text says the other is unknown; no end
    verified: nothing on the ground line, the text says UNKNOWN."""
    vehicle = ros.vehicle

    async def scenario(page: DevToolsPage) -> None:
        fly_cruise(ros)
        await page.phase("normal", "safe", "NORMAL", "SAFE")
        vehicle.footprint = lambda now_ns: footprint_message(now_ns, HERE_M + 250.0, None)
        ground = await page.wait_for(GROUND, lambda g: bool(g["footprint"]), "the nearest end")
        assert ground["received"] == "partial"
        assert ground["footprint"]["drawn"] == "nearest" and ground["footprint"]["farFt"] is None
        assert ground["footprint"]["nearFt"] == pytest.approx((HERE_M + 250.0) / FT)
        assert ground["text"] == f"FOOTPRINT NEAREST {250.0 / FT:.0f} ft AHEAD \u00b7 FARTHEST UNKNOWN"
        assert await page.evaluate("document.getElementById('side-footprint').dataset.kind") == "reachable"
        save_artifact(tmp_path, "display-footprint-one-end.png", await page.screenshot())

        vehicle.footprint = lambda now_ns: footprint_message(now_ns, None, HERE_M + 900.0)
        ground = await page.wait_for(
            GROUND, lambda g: bool(g["footprint"]) and g["footprint"]["drawn"] == "farthest", "the farthest end"
        )
        assert ground["footprint"]["nearFt"] is None
        assert ground["text"] == f"FOOTPRINT FARTHEST {900.0 / FT:.0f} ft AHEAD \u00b7 NEAREST UNKNOWN"

        vehicle.footprint = lambda now_ns: footprint_message(now_ns, None, None)
        ground = await page.wait_for(GROUND, lambda g: g["received"] == "unknown", "no end verified")
        assert ground["footprint"] is None and ground["text"] == "FOOTPRINT UNKNOWN (NO END VERIFIED)"
        assert await page.evaluate("document.getElementById('side-footprint').dataset.kind") == "unknown"
        assert page.errors == [], f"the page reported errors: {page.errors}"

    run_page(browser, ros.display.url, scenario)


@needs_chromium
def test_side_view_footprint_off_draws_nothing(ros: RosHarness, browser: Browser, tmp_path: Path) -> None:
    """The planner's STALE ``off`` footprint (and no sites): no side view, nothing drawn, no page error."""
    vehicle = ros.vehicle

    async def scenario(page: DevToolsPage) -> None:
        fly_cruise(ros)
        await page.phase("normal", "safe", "NORMAL", "SAFE")
        wait_until(lambda: vehicle.footprint_publisher.get_subscription_count() > 0, TIMEOUT_S, "display")
        vehicle.footprint_publisher.publish(footprint_off_message())  # once, latched, as the planner at start-up
        ground = await page.wait_for(GROUND, lambda g: g["received"] == "off", "the footprint off")
        assert ground == {"footprint": None, "site": None, "text": "", "received": "off"}
        assert await page.evaluate(SIDE_PANEL_HIDDEN) is True
        assert await page.evaluate("document.getElementById('side-footprint').hidden") is True
        save_artifact(tmp_path, "display-footprint-off.png", await page.screenshot())
        assert page.errors == [], f"the page reported errors: {page.errors}"

    run_page(browser, ros.display.url, scenario)


@needs_chromium
def test_side_view_shows_the_plan_on_its_site(
    ros: RosHarness, browser: Browser, real_plan: Any, tmp_path: Path
) -> None:
    """After the failure: the plan's path and TD with the plan status' site, ON SITE; the footprint (if the engine
    failed *now*) is no longer drawn, however fresh."""
    vehicle = ros.vehicle
    touchdown = float(real_plan.states[StateIndex.DISTANCE, -1])
    bravo = LandingSite("bravo", touchdown - 100.0, touchdown + 100.0)

    async def scenario(page: DevToolsPage) -> None:
        fly_cruise(ros)
        vehicle.distance = 0.0
        await page.phase("normal", "safe", "NORMAL", "SAFE")
        vehicle.footprint = lambda now_ns: footprint_message(now_ns, touchdown - 300.0, touchdown + 300.0)
        await page.wait_for(GROUND, lambda g: bool(g["footprint"]), "the footprint before the failure")

        for publisher in (vehicle.trajectory_publisher, vehicle.path_publisher, vehicle.plan_status_publisher):
            wait_until(lambda publisher=publisher: publisher.get_subscription_count() > 0, TIMEOUT_S, "display")
        start = vehicle.get_clock().now().to_msg()
        vehicle.failure_publisher.publish(Header(stamp=start, frame_id="failure"))
        vehicle.episode = episode_message(EpisodePhase.FAILED, 1)
        flying = status_message(DiagnosticStatus.OK, "ENGINE FAILURE: landing plan verified", *CRUISE[:2], 0.0, "")
        vehicle.set(CRUISE, flying)
        await page.phase("autorotation", "avoid", "NO PLAN after the failure", "NO PLAN")
        ground = await page.wait_for(GROUND, lambda g: g["footprint"] is None, "no footprint once the engine failed")
        assert await page.evaluate(SIDE_PANEL_HIDDEN) is True  # no plan yet, and the footprint no longer applies
        trajectory, path, plan_status = plan_messages(real_plan, start)
        planned = replayed_landing(real_plan.states[:, 0], touchdown, (bravo.start_m, bravo.end_m))
        plan_status.values += [
            KeyValue(key=k, value=format_value(v)) for k, v in site_values(bravo, planned, 1).items()
        ]
        vehicle.trajectory_publisher.publish(trajectory)
        vehicle.path_publisher.publish(path)
        vehicle.plan_status_publisher.publish(plan_status)
        await page.phase("autorotation", "safe", "the verified plan", "VERIFIED")
        ground = await page.wait_for(
            GROUND, lambda g: bool(g["site"]) and g["site"]["source"] == "plan", "the plan's site"
        )
        assert ground["footprint"] is None and ground["text"] == ""  # the engine has failed: the plan decides
        assert ground["site"]["kind"] == "reachable"
        assert ground["site"]["label"] == f"SITE BRAVO \u00b7 ON SITE \u00b7 TD {100.0 / FT:.0f} ft INSIDE"
        side = await page.evaluate("window.helireach.side")
        assert side["points"] == len(real_plan.times) and side["distance"].startswith("TO TOUCHDOWN")
        assert await page.evaluate("document.getElementById('side-title').textContent") == (
            "SIDE VIEW \u00b7 PLANNED PATH"
        )
        save_artifact(tmp_path, "display-plan-on-site.png", await page.screenshot())
        assert page.errors == [], f"the page reported errors: {page.errors}"

    run_page(browser, ros.display.url, scenario)


def test_footprint_frames_age_out_and_the_latest_site_wins(envelope_file: Path) -> None:
    """Without a browser: the frame's footprint is ``current`` only while its state is at most FOOTPRINT_MAX_AGE_S old;
    the site comes from the latest live verdict or plan status that carries one."""
    harness = RosHarness(envelope_file=str(envelope_file))
    vehicle = harness.vehicle
    alpha = LandingSite("alpha", HERE_M + 400.0, HERE_M + 600.0)
    try:

        async def scenario() -> None:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as socket:
                first = await read_frame(socket)
                assert first["live"]["footprint"] is None and first["live"]["site"] is None
                wait_until(lambda: vehicle.footprint_publisher.get_subscription_count() > 0, TIMEOUT_S, "display")
                now_ns = vehicle.get_clock().now().nanoseconds
                vehicle.footprint_publisher.publish(footprint_message(now_ns, HERE_M + 250.0, HERE_M + 900.0))
                vehicle.live_publisher.publish(live_site_message(now_ns, alpha, HERE_M + 500.0))
                frame = await frame_until(
                    socket, lambda f: bool(f["live"]["footprint"] and f["live"]["site"]), "footprint and site"
                )
                footprint, site = frame["live"]["footprint"], frame["live"]["site"]
                assert footprint["current"] is True and footprint["status"] == "reachable"
                assert (footprint["nearest_distance_m"], footprint["farthest_distance_m"]) == (1250.0, 1900.0)
                assert (site["source"], site["kind"], site["current"]) == ("live", "reachable", True)
                frame = await frame_until(
                    socket,
                    lambda f: not f["live"]["footprint"]["current"] and f["live"]["site"]["kind"] == "stale",
                    "an old footprint and live verdict",
                )
                assert frame["live"]["footprint"]["age_s"] > FOOTPRINT_MAX_AGE_S
                assert frame["live"]["footprint"]["nearest_verified"] is True  # still said, no longer current

                # a plan status with a site, received later, is the latest that carries one; it holds only during
                # a failure episode (one of no failure says nothing of now)
                values = {"status": "safe", "safe": True, "verified": True, **site_values(alpha, None, 1)}
                values.update(site_planned=False, on_site=False)
                plan = rm.diagnostic_status(DiagnosticStatus.OK, "helireach_planner: landing plan", "x", "t", values)
                vehicle.plan_status_publisher.publish(plan)
                frame = await frame_until(
                    socket, lambda f: bool(f["live"]["site"]) and f["live"]["site"]["source"] == "plan", "plan site"
                )
                assert (frame["live"]["site"]["kind"], frame["live"]["site"]["words"]) == ("stale", "NO PLAN")
                failure_ns = vehicle.get_clock().now().nanoseconds
                vehicle.failure_publisher.publish(Header(stamp=rm.stamp_message(failure_ns), frame_id="failure"))
                await frame_until(socket, lambda f: f["live"]["failure"] is not None, "the failure")
                values["failure_stamp_ns"] = failure_ns
                vehicle.plan_status_publisher.publish(
                    rm.diagnostic_status(DiagnosticStatus.OK, "helireach_planner: landing plan", "x", "t", values)
                )
                frame = await frame_until(
                    socket,
                    lambda f: bool(f["live"]["site"]) and f["live"]["site"]["kind"] != "stale",
                    "the failure plan's site",
                )
                site = frame["live"]["site"]
                assert site["source"] == "plan"
                assert (site["kind"], site["words"]) == ("not_reachable", "NOT REACHABLE \u00b7 LANDING OFF-SITE")

        asyncio.run(scenario())
    finally:
        harness.close()


def test_footprint_and_site_sections_are_never_optimistic() -> None:
    stamp_ns = 1_000_000_000
    both = footprint_section(footprint_message(stamp_ns, HERE_M + 250.0, HERE_M + 900.0))
    assert (both["off"], both["nearest_verified"], both["farthest_verified"]) == (False, True, True)
    assert (both["nearest_m"], both["farthest_m"], both["state_stamp_ns"]) == (250.0, 900.0, stamp_ns)
    one = footprint_section(footprint_message(stamp_ns, HERE_M + 250.0, None))
    assert (one["status"], one["farthest_verified"], one["farthest_distance_m"]) == ("partial", False, None)
    off = footprint_section(footprint_off_message())
    assert off["off"] is True and not off["nearest_verified"] and not off["farthest_verified"]
    # "true" with no finite distance, or a level from the future: not an end
    lying = rm.diagnostic_status(
        DiagnosticStatus.OK,
        "x",
        "x",
        "x",
        {"status": "reachable", "nearest_verified": True, "nearest_distance_m": math.nan, "farthest_verified": True},
    )
    assert not footprint_section(lying)["nearest_verified"] and not footprint_section(lying)["farthest_verified"]
    future = footprint_message(stamp_ns, HERE_M + 250.0, HERE_M + 900.0)
    future.level = b"\x07"
    assert footprint_section(future)["off"] is True and footprint_section(future)["nearest_verified"] is False

    assert site_section({}) is None  # no sites configured
    site = site_section(rm.status_values(live_site_message(stamp_ns, LandingSite("a", 10.0, 20.0), 15.0)))
    assert site is not None and (site["name"], site["start_m"], site["end_m"], site["on_site"]) == (
        "a",
        10.0,
        20.0,
        True,
    )
    assert site_verdict(site, "live", current=True) == ("reachable", "REACHABLE")
    assert site_verdict(site, "live", current=False) == ("stale", "REACHABILITY STALE")
    assert site_verdict(site, "plan", current=True, plan_void=True) == ("stale", "NO PLAN")
    assert site_verdict({**site, "on_site": None, "planned": None}, "live", current=True)[0] == "unknown"
    assert site_verdict({**site, "on_site": False, "planned": True}, "plan", current=True)[0] == "unknown"
