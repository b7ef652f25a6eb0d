"""Cockpit display node: a live web page of the H-V envelope, the operating point, the safety status and the plan.

The node subscribes to the helireach topics and serves one page (``helireach_ros/web/``) from an aiohttp
HTTP + WebSocket server running on its own asyncio thread. It is read-only: it creates no publishers of its
own (rclpy's ``/rosout`` and ``/parameter_events`` aside) and ignores everything a browser sends.

Data flow: ROS callbacks (any executor thread) store the latest value of each topic under a lock and wake the
server; each connected page has one sender task that sends the *latest* snapshot, at most ``max_update_rate_hz``
times per second and at least every ``heartbeat`` (so a page can tell a silent server from a quiet sky). Nothing
is queued per message: a 60 Hz (or 6 kHz) state stream costs each page at most one frame per send interval, the
rest are dropped, and a page that cannot keep up only slows its own sender.

The status banner follows ``/helireach/safety_status`` only: OK → SAFE, WARN → CAUTION, ERROR → AVOID,
STALE (or any unknown level, or silence longer than ``stale_after_s``) → NO DATA. The page applies the same
silence rule to the WebSocket itself.

Wire format (JSON text frames, SI units; the page converts to ft/kt for people)::

    {"config": {...},      # on connect and on change: units, stale_after_s, rotor limits, airframe
     "envelope": {...},    # on connect and on change: H-V grid, status codes, boundary, or an error
     "plan": {...} | null, # on change: trajectory, predicted path, plan status
     "live": {...}}        # every frame: status banner, state, rotor, failure, time to touchdown

Run: ``helireach display`` or ``python -m helireach_ros.nodes.display --ros-args -p port:=8080``.
"""

from __future__ import annotations

import asyncio
import json
import math
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from importlib import resources as importlib_resources
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from aiohttp import WSCloseCode, WSMsgType, web
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from helireach_ros import ros_messages as rm
from helireach_ros.units import FT, KT

__all__ = [
    "BANNER_LEVELS",
    "DEFAULT_BIND",
    "DEFAULT_PORT",
    "CockpitDisplay",
    "DisplayServerError",
    "banner_level",
    "boundary_segments",
    "create_display_with_fallback",
    "envelope_section",
    "hold_until_interrupted",
    "main",
    "path_section",
    "plan_status_section",
    "rotor_limits_section",
    "run_display",
    "trajectory_section",
    "web_directory",
]

DEFAULT_PORT = 8080
DEFAULT_BIND = "127.0.0.1"


# Keys of the DiagnosticStatus values (first match wins; the status/planner nodes own the names, see msg_docs/).
_MARGIN_KEYS = ("margin_ft_kt", "margin")
_ENVELOPE_ID_KEYS = ("envelope_id",)
_PLAN_VERIFIED_KEYS = ("verified",)
_PLAN_FALLBACK_KEYS = ("fallback", "is_fallback")
_PLAN_SAFE_KEYS = ("safe", "status")
_PLAN_VALUE_KEYS = ("value",)
_PLAN_TIME_TO_LAND_KEYS = ("time_to_land_s", "time_to_land")
_PLAN_SOLVE_TIME_KEYS = ("solve_time_ms",)

#: Banner level per DiagnosticStatus level; anything else is NO DATA (never optimistic).
BANNER_LEVELS: dict[bytes, str] = {
    DiagnosticStatus.OK: "safe",
    DiagnosticStatus.WARN: "caution",
    DiagnosticStatus.ERROR: "avoid",
    DiagnosticStatus.STALE: "nodata",
}

# Which page file each URL serves: nothing else in the package (or on disk) is reachable.
_WEB_FILES: dict[str, tuple[str, str]] = {
    "/": ("index.html", "text/html"),
    "/index.html": ("index.html", "text/html"),
    "/app.js": ("app.js", "text/javascript"),
    "/style.css": ("style.css", "text/css"),
}
_SECURITY_HEADERS = {
    # Everything comes from this server; the WebSocket too ('self' covers ws: to the same host in CSP 3).
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
        "base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
_MAX_POINTS = 2000  # longer trajectories/paths are decimated for the page (keeps frames small)
_MAX_INCOMING_MESSAGE_BYTES = 4096  # the page sends nothing; a client that does is ignored (or cut off)
_SEND_TIMEOUT_S = 10.0  # a page that cannot take one frame in this long is disconnected
_PLAN_STAMP_TOLERANCE_S = 10.0  # a plan stamped further from the receipt time uses the receipt time instead


class DisplayServerError(RuntimeError):
    """The web server could not start (address in use, bad bind address, missing page files)."""


def web_directory() -> Path:
    """The folder holding the page (``index.html``, ``app.js``, ``style.css``) inside the package."""
    return Path(str(importlib_resources.files("helireach_ros") / "web"))


# ----------------------------------------------------------------------------------------------------------
# Message → JSON-ready sections (pure functions; no ROS node needed, so they are easy to reason about)
# ----------------------------------------------------------------------------------------------------------


def _finite(value: Any) -> float | None:
    """A finite float, or None for NaN/inf/garbage (JSON has no NaN; the page shows '---')."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def _finite_list(values: Iterable[Any]) -> list[float | None]:
    return [_finite(value) for value in values]


def _lookup(values: Mapping[str, str], keys: Sequence[str]) -> str | None:
    for key in keys:
        if key in values:
            return values[key]
    return None


def _parse_bool(text: str | None) -> bool | None:
    if text is None:
        return None
    lowered = text.strip().lower()
    if lowered in ("true", "1", "yes", "safe", "verified"):
        return True
    if lowered in ("false", "0", "no", "unsafe", "unverified", "failed"):
        return False
    return None


def _decimation(count: int) -> np.ndarray:
    """Indices keeping at most ``_MAX_POINTS`` samples, always including the first and last."""
    if count <= _MAX_POINTS:
        return np.arange(count)
    return np.unique(np.linspace(0, count - 1, _MAX_POINTS).round().astype(int))


def banner_level(level: bytes | int) -> str:
    """The banner for a DiagnosticStatus level: ``safe``/``caution``/``avoid``/``nodata`` (unknown → nodata)."""
    key = bytes([level]) if isinstance(level, int) else bytes(level)
    return BANNER_LEVELS.get(key, "nodata")


def envelope_section(envelope: Any) -> dict[str, Any]:
    """The H-V diagram data of an envelope (see :mod:`helireach_ros.envelope`), SI units.

    Returns:
        ``{"available": True, "heights_m", "speeds_ms", "status" (H×S codes: 0 safe, 1 unsafe, 2 unverified or
        failed), "boundary" ([[height_m, speed_ms], ...]), "envelope_id", "airframe", "method", "power_fraction"}``.

    Raises:
        ValueError: if the arrays are inconsistent (the caller shows NO DATA with the message).
    """
    heights = np.asarray(envelope.heights, dtype=float)
    speeds = np.asarray(envelope.speeds, dtype=float)
    status = np.asarray(envelope.status)
    if heights.ndim != 1 or speeds.ndim != 1 or heights.size < 2 or speeds.size < 2:
        raise ValueError("envelope grid axes must be 1-D with at least two nodes each")
    if status.shape != (heights.size, speeds.size):
        raise ValueError(f"envelope status is {status.shape}, expected {(heights.size, speeds.size)}")
    if not (np.all(np.isfinite(heights)) and np.all(np.isfinite(speeds))):
        raise ValueError("envelope grid axes hold NaN/inf")
    if np.any(np.diff(heights) <= 0) or np.any(np.diff(speeds) <= 0):
        raise ValueError("envelope grid axes must be strictly ascending")
    codes = np.where(status == "safe", 0, np.where(status == "unsafe", 1, 2))
    boundary = np.asarray(envelope.boundary, dtype=float).reshape(-1, 2)
    metadata = dict(getattr(envelope, "metadata", {}) or {})
    return {
        "available": True,
        "heights_m": heights.tolist(),
        "speeds_ms": speeds.tolist(),
        "status": codes.tolist(),
        "boundary": [[_finite(height), _finite(speed)] for height, speed in boundary],
        "boundary_segments": [
            [_finite(value) for value in segment]
            for segment in boundary_segments(heights, speeds, codes == 0, boundary)
        ],
        "envelope_id": str(envelope.envelope_id),
        "airframe": str(getattr(envelope, "airframe_name", "") or ""),
        "method": str(metadata.get("method", "")),
        "power_fraction": _finite(metadata.get("power_fraction")),
    }


def boundary_segments(
    heights: np.ndarray, speeds: np.ndarray, safe: np.ndarray, boundary: np.ndarray
) -> list[tuple[float, ...]]:
    """Joins the envelope's boundary points into a curve, cell by cell (marching squares).

    A grid edge whose end nodes differ (safe / not safe) holds one refined boundary point (the last point
    proven safe, possibly the safe node itself). Every cell has 0, 2 or 4 such edges: two crossings are
    joined by a segment, four (a saddle) are paired around the cell. Edges without a point are skipped.

    Args:
        heights: grid heights, m, ascending (H).
        speeds: grid speeds, m/s, ascending (S).
        safe: H × S booleans, True where the node is safe.
        boundary: B × 2 points (height m, speed m/s).

    Returns:
        Segments ``(height_1, speed_1, height_2, speed_2)`` in m and m/s.
    """
    heights, speeds = np.asarray(heights, dtype=float), np.asarray(speeds, dtype=float)
    safe = np.asarray(safe, dtype=bool)
    tolerance_h = 1e-4 * float(np.min(np.diff(heights)))
    tolerance_v = 1e-4 * float(np.min(np.diff(speeds)))
    # edge ("h", row, column): height = heights[row], speed in [speeds[column], speeds[column + 1]];
    # edge ("v", row, column): speed = speeds[column], height in [heights[row], heights[row + 1]]
    on_edge: dict[tuple[str, int, int], list[tuple[float, float]]] = {}
    for height, speed in np.asarray(boundary, dtype=float).reshape(-1, 2):
        if not (math.isfinite(height) and math.isfinite(speed)):
            continue
        point = (float(height), float(speed))
        spans_v = np.flatnonzero((speeds[:-1] - tolerance_v <= speed) & (speed <= speeds[1:] + tolerance_v))
        spans_h = np.flatnonzero((heights[:-1] - tolerance_h <= height) & (height <= heights[1:] + tolerance_h))
        for row in np.flatnonzero(np.abs(heights - height) <= tolerance_h):
            for column in spans_v:
                on_edge.setdefault(("h", int(row), int(column)), []).append(point)
        for column in np.flatnonzero(np.abs(speeds - speed) <= tolerance_v):
            for row in spans_h:
                on_edge.setdefault(("v", int(row), int(column)), []).append(point)

    def crossing(kind: str, row: int, column: int) -> tuple[float, float] | None:
        candidates = on_edge.get((kind, row, column))
        if not candidates:
            return None
        if kind == "h":
            middle = (heights[row], 0.5 * (speeds[column] + speeds[column + 1]))
        else:
            middle = (0.5 * (heights[row] + heights[row + 1]), speeds[column])
        # a node point sits on every edge at that node; the point inside the edge is the better one
        return min(candidates, key=lambda p: abs(p[0] - middle[0]) / tolerance_h + abs(p[1] - middle[1]) / tolerance_v)

    segments: list[tuple[float, ...]] = []
    for row in range(heights.size - 1):
        for column in range(speeds.size - 1):
            edges = (
                ("h", row, column, safe[row, column] != safe[row, column + 1]),
                ("v", row, column + 1, safe[row, column + 1] != safe[row + 1, column + 1]),
                ("h", row + 1, column, safe[row + 1, column] != safe[row + 1, column + 1]),
                ("v", row, column, safe[row, column] != safe[row + 1, column]),
            )  # counter-clockwise: bottom, right, top, left
            points = [crossing(kind, r, c) for kind, r, c, changes in edges if changes]
            points = [point for point in points if point is not None]
            if len(points) == 2:
                segments.append((*points[0], *points[1]))
            elif len(points) == 4:  # saddle: cut off the safe corners (never join them across the cell)
                first, second = ((0, 1), (2, 3)) if safe[row, column + 1] else ((1, 2), (3, 0))
                segments += [(*points[first[0]], *points[first[1]]), (*points[second[0]], *points[second[1]])]
    return segments


def rotor_limits_section(airframe: Any = None, metadata: Mapping[str, Any] | None = None) -> dict[str, Any] | None:
    """Rotor speed limits Ω₀, Ω_min = r_min Ω₀, Ω_max = r_max Ω₀ (rad/s) from an Airframe or envelope metadata.

    Args:
        airframe: an :class:`helireach_ros.airframe.Airframe` (wins if given).
        metadata: an envelope's metadata; its ``airframe`` entry is ``Airframe.as_dict()``.

    Returns:
        ``{"nominal_rad_s", "min_rad_s", "max_rad_s", "source"}`` or None when neither holds usable limits.
    """
    if airframe is not None:
        nominal = _finite(airframe.nominal_rotor_speed)
        low, high = airframe.limits.min_rotor_speed_ratio, airframe.limits.max_rotor_speed_ratio
        source = f"airframe {airframe.name}"
    else:
        entry = (metadata or {}).get("airframe")
        if not isinstance(entry, Mapping) or not isinstance(entry.get("limits"), Mapping):
            return None
        nominal = _finite(entry.get("nominal_rotor_speed"))
        low, high = entry["limits"].get("min_rotor_speed_ratio"), entry["limits"].get("max_rotor_speed_ratio")
        source = f"envelope airframe {entry.get('name', '')}".strip()
    low, high = _finite(low), _finite(high)
    if nominal is None or low is None or high is None or nominal <= 0 or not 0 < low < high:
        return None
    return {"nominal_rad_s": nominal, "min_rad_s": low * nominal, "max_rad_s": high * nominal, "source": source}


def trajectory_section(message: JointTrajectory) -> dict[str, Any]:
    """Collective and pitch against time from a landing trajectory (:func:`ros_messages.read_trajectory`).

    Returns:
        ``{"t_s", "collective", "pitch_rad", "stamp_s"}`` (lists), or ``{"error": text}`` for an unreadable one.
    """
    try:
        stamp_ns, times, values = rm.read_trajectory(message)
    except ValueError as error:
        return {"error": str(error)}
    keep = _decimation(times.size)
    return {
        "t_s": times[keep].tolist(),
        "collective": values[0, keep].tolist(),
        "pitch_rad": values[1, keep].tolist(),
        "stamp_s": stamp_ns * 1e-9,
    }


def path_section(message: PathMsg) -> dict[str, Any]:
    """The predicted landing path: forward distance x and height z (m), and forward speed where derivable.

    Speed along the path, ``v = dx/dt``, needs increasing pose stamps; without them ``speed_ms`` is None
    (the page then draws the profile only, not the path on the H-V diagram).
    """
    poses = list(message.poses)
    if not poses:
        return {"error": "path has no poses"}
    keep = _decimation(len(poses))
    x = np.array([poses[int(i)].pose.position.x for i in keep], dtype=float)
    z = np.array([poses[int(i)].pose.position.z for i in keep], dtype=float)
    stamps_ns = np.array([rm.stamp_nanoseconds(poses[int(i)].header.stamp) for i in keep], dtype=np.int64)
    stamps = (stamps_ns - stamps_ns[0]) * 1e-9  # relative first: seconds since 1970 lose precision as floats
    speed: list[float | None] | None = None
    if x.size >= 2 and np.all(np.diff(stamps) > 0) and np.all(np.isfinite(x)):
        speed = _finite_list(np.gradient(x, stamps))
    return {"x_m": _finite_list(x), "z_m": _finite_list(z), "speed_ms": speed}


def plan_status_section(message: DiagnosticStatus) -> dict[str, Any]:
    """The plan's verdict: level, flags (safe/verified/fallback), value, timing, predicted touchdown, all values.

    The keys are the planner node's (``helireach_ros.nodes.planner_node``, ``msg_docs/``); a missing key is None.
    """
    values = rm.status_values(message)
    return {
        "level": banner_level(message.level),
        "message": str(message.message),
        "safe": _parse_bool(_lookup(values, _PLAN_SAFE_KEYS)),
        "verified": _parse_bool(_lookup(values, _PLAN_VERIFIED_KEYS)),
        "fallback": _parse_bool(_lookup(values, _PLAN_FALLBACK_KEYS)),
        "value": _finite(_lookup(values, _PLAN_VALUE_KEYS)),
        "time_to_land_s": _finite(_lookup(values, _PLAN_TIME_TO_LAND_KEYS)),
        "solve_time_ms": _finite(_lookup(values, _PLAN_SOLVE_TIME_KEYS)),
        "replan_index": _finite(values.get("replan_index")),
        "touchdown_descent_rate_ms": _finite(values.get("predicted_touchdown_descent_rate_m_s")),
        "touchdown_forward_speed_ms": _finite(values.get("predicted_touchdown_forward_speed_m_s")),
        "values": values,
    }


def _to_json(value: Any) -> str:
    # allow_nan=False: a NaN that slipped through is a bug to see, not invalid JSON for the page
    return json.dumps(value, allow_nan=False, separators=(",", ":"))


# ----------------------------------------------------------------------------------------------------------
# Latest-value store shared by ROS callbacks (writers) and the web server (reader)
# ----------------------------------------------------------------------------------------------------------


@dataclass
class _Received:
    """A message's content with its receipt time (``time.monotonic``)."""

    content: Any
    received: float


@dataclass
class _Latest:
    """The newest value of everything the page shows (guarded by the node's lock)."""

    status: _Received | None = None
    last_known_banner: str | None = None
    state: _Received | None = None
    rotor: _Received | None = None
    failure: _Received | None = None
    trajectory: _Received | None = None
    path: _Received | None = None
    plan_status: _Received | None = None
    plan_reference: float | None = None  # monotonic time of the plan's t = 0
    held: bool = False
    versions: dict[str, int] = field(default_factory=lambda: {"config": 1, "envelope": 1, "plan": 1})


class _PageServer:
    """aiohttp server on its own asyncio thread; one rate-limited, latest-value-only sender per page.

    Args:
        bind: address to listen on.
        port: TCP port (0 = any free port).
        frame: ``frame(sent_versions) -> (json_text, versions)``: the message for a page that has seen
            ``sent_versions`` of the versioned sections (called on the server thread).
        min_interval_s: shortest time between two frames to one page.
        heartbeat_s: longest time between two frames to one page.
        log_warning: where to report page errors.
    """

    def __init__(
        self,
        bind: str,
        port: int,
        frame: Callable[[dict[str, int]], tuple[str, dict[str, int]]],
        min_interval_s: float,
        heartbeat_s: float,
        log_warning: Callable[[str], None],
    ) -> None:
        self._frame = frame
        self.min_interval_s = min_interval_s
        self.heartbeat_s = heartbeat_s
        self._log_warning = log_warning
        self._loop = asyncio.new_event_loop()
        self._wakeups: set[asyncio.Event] = set()
        self._sockets: set[web.WebSocketResponse] = set()
        self._wake_pending = False
        self._runner: web.AppRunner | None = None
        self.address: tuple[str, int] | None = None
        started = threading.Event()
        failure: list[BaseException] = []
        self._thread = threading.Thread(
            target=self._run, args=(bind, port, started, failure), name="helireach_display_http", daemon=True
        )
        self._thread.start()
        started.wait()
        if failure:
            self._thread.join(timeout=5.0)
            raise DisplayServerError(f"cannot serve the display on {bind}:{port}: {failure[0]}") from failure[0]

    # -- server thread ---------------------------------------------------------------------------------
    def _run(self, bind: str, port: int, started: threading.Event, failure: list[BaseException]) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start(bind, port))
        except Exception as error:  # address in use, bad address: reported to the constructor
            failure.append(error)
            started.set()
            self._loop.run_until_complete(self._cleanup())
            self._loop.close()
            return
        started.set()
        self._loop.run_forever()
        self._loop.run_until_complete(self._cleanup())
        self._loop.close()

    async def _start(self, bind: str, port: int) -> None:
        app = web.Application()
        for route in _WEB_FILES:
            app.router.add_get(route, self._serve_file)
        app.router.add_get("/ws", self._serve_websocket)
        self._runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=1.0)
        await self._runner.setup()
        await web.TCPSite(self._runner, bind, port, reuse_address=True).start()
        host, bound_port = self._runner.addresses[0][:2]
        self.address = (str(host), int(bound_port))

    async def _cleanup(self) -> None:
        for socket in list(self._sockets):
            await socket.close(code=WSCloseCode.GOING_AWAY, message=b"display stopped")
        if self._runner is not None:
            await self._runner.cleanup()

    async def _serve_file(self, request: web.Request) -> web.StreamResponse:
        name, content_type = _WEB_FILES[request.path]
        try:
            body = (web_directory() / name).read_bytes()
        except OSError as error:
            self._log_warning(f"display page file {name} unreadable: {error}")
            raise web.HTTPInternalServerError(text=f"display page file {name} is missing from the package") from None
        return web.Response(body=body, content_type=content_type, charset="utf-8", headers=_SECURITY_HEADERS)

    async def _serve_websocket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and origin.split("://", 1)[-1] != request.host:
            # another web site in the same browser must not read the feed (cross-site WebSocket hijacking)
            raise web.HTTPForbidden(text="cross-origin WebSocket refused")
        socket = web.WebSocketResponse(
            heartbeat=max(self.heartbeat_s * 4.0, 5.0), max_msg_size=_MAX_INCOMING_MESSAGE_BYTES
        )
        await socket.prepare(request)
        wakeup = asyncio.Event()
        self._wakeups.add(wakeup)
        self._sockets.add(socket)
        sender = asyncio.ensure_future(self._send_frames(socket, wakeup))
        try:
            async for message in socket:  # read only to see pings and closes; whatever the page says is ignored
                if message.type == WSMsgType.ERROR:
                    break
        finally:
            sender.cancel()
            self._wakeups.discard(wakeup)
            self._sockets.discard(socket)
            await asyncio.gather(sender, return_exceptions=True)
            await socket.close()
        return socket

    async def _send_frames(self, socket: web.WebSocketResponse, wakeup: asyncio.Event) -> None:
        sent_versions: dict[str, int] = {}
        try:
            while not socket.closed:
                text, sent_versions = self._frame(sent_versions)
                await asyncio.wait_for(socket.send_str(text), timeout=_SEND_TIMEOUT_S)
                # rate limit: whatever arrives meanwhile only re-sets the event; the next frame is the latest value
                await asyncio.sleep(self.min_interval_s)
                try:
                    await asyncio.wait_for(wakeup.wait(), timeout=max(self.heartbeat_s - self.min_interval_s, 0.0))
                except TimeoutError:
                    pass
                wakeup.clear()
        except (ConnectionError, TimeoutError, RuntimeError) as error:  # gone, or too slow to take a frame
            self._log_warning(f"display page dropped: {error!r}")
            await socket.close(code=WSCloseCode.TRY_AGAIN_LATER, message=b"dropped")
        except Exception as error:  # a frame that cannot be built: the page sees silence and shows NO DATA
            self._log_warning(f"display frame failed: {type(error).__name__}: {error}")
            await socket.close(code=WSCloseCode.INTERNAL_ERROR, message=b"frame error")

    def _wake_all(self) -> None:
        self._wake_pending = False
        for wakeup in self._wakeups:
            wakeup.set()

    # -- any thread ------------------------------------------------------------------------------------
    def notify(self) -> None:
        """Tells every page sender that something changed (coalesced; cheap at kHz rates)."""
        if self._wake_pending or self._loop.is_closed():
            return
        self._wake_pending = True
        try:
            self._loop.call_soon_threadsafe(self._wake_all)
        except RuntimeError:  # loop closed during shutdown
            pass

    @property
    def page_count(self) -> int:
        """Pages connected right now."""
        return len(self._sockets)

    def stop(self, timeout_s: float = 5.0) -> None:
        """Closes every page (WebSocket code 1001) and the listening socket; joins the server thread."""
        if self._thread.is_alive():
            try:
                self._loop.call_soon_threadsafe(self._loop.stop)
            except RuntimeError:
                pass
            self._thread.join(timeout=timeout_s)


# ----------------------------------------------------------------------------------------------------------
# The node
# ----------------------------------------------------------------------------------------------------------


class CockpitDisplay(Node):
    """Serves the cockpit page and pushes the latest helireach data to it (read-only).

    Parameters (ROS): ``port`` (8080; 0 = any free port, see :attr:`url`), ``bind`` (127.0.0.1; another address
    only when given), ``envelope_file`` (default: the shipped envelope), ``airframe`` (rotor limits; default: the
    envelope's airframe), ``state_topic`` (``/helireach/state``; ``/vehicle/odometry`` has the same layout),
    ``rotor_topic`` (``/vehicle/rotor``; the monitor's ``/helireach/rotor_state`` has the same layout),
    ``stale_after_s`` (NO DATA after this long without a safety status), ``max_update_rate_hz`` (frames per
    second per page).

    Raises:
        DisplayServerError: if the web server cannot listen on ``bind:port``.
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_display", **node_options)
        self._lock = threading.Lock()
        self._latest = _Latest()
        # a bad override is logged and the default used (ros_messages.declare_checked_parameter)
        declare = partial(rm.declare_checked_parameter, self)
        self._port = declare("port", DEFAULT_PORT, "TCP port of the page (0 = any free port)", (0, 65535))
        self._bind = declare("bind", DEFAULT_BIND, "listen address; loopback unless set explicitly")
        self._envelope_file = declare("envelope_file", "", "H-V envelope file ('' = the shipped envelope)")
        self._airframe_name = declare("airframe", "", "airframe for rotor limits ('' = the envelope's)")
        state_topic = declare("state_topic", rm.TOPIC_STATE, "nav_msgs/Odometry vehicle state topic")
        rotor_topic = declare("rotor_topic", rm.TOPIC_ROTOR, "sensor_msgs/JointState rotor speed topic")
        self._stale_after_s = declare(
            "stale_after_s", 2.0, "NO DATA after this long without a message, s", (0.1, 3600.0), read_only=False
        )
        self._max_update_rate_hz = declare(
            "max_update_rate_hz", 25.0, "most frames per second sent to one page", (1.0, 120.0)
        )
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._state_topic = state_topic
        envelope, envelope_data = self._load_envelope()
        self._envelope_id = envelope_data.get("envelope_id")
        self._config = self._config_section(envelope, envelope_data)
        self._config_json = _to_json(self._config)
        self._envelope_json = _to_json(envelope_data)
        self._plan_json = "null"

        # QoS as documented in msg_docs (ros_messages): the safety status and the plan are latched, so a page opened
        # after the failure shows the plan; sensor streams with BEST_EFFORT, which matches any publisher
        for message_type, topic, callback, qos in (
            (DiagnosticStatus, rm.TOPIC_SAFETY_STATUS, self._on_safety_status, rm.LATCHED_QOS),
            (Odometry, state_topic, self._on_state, rm.SENSOR_QOS),
            (JointState, rotor_topic, self._on_rotor, rm.SENSOR_QOS),
            (Header, rm.TOPIC_FAILURE_EVENT, self._on_failure, rm.EVENT_QOS),
            (JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, self._on_trajectory, rm.LATCHED_QOS),
            (PathMsg, rm.TOPIC_LANDING_PATH, self._on_path, rm.LATCHED_QOS),
            (DiagnosticStatus, rm.TOPIC_PLAN_STATUS, self._on_plan_status, rm.LATCHED_QOS),
        ):
            self.create_subscription(message_type, topic, self._never_raising(callback, topic), qos)

        if self._bind not in ("127.0.0.1", "::1", "localhost"):
            self.get_logger().warning(f"display listens on {self._bind}, not loopback: reachable from the network")
        try:
            self._server = _PageServer(
                self._bind,
                self._port,
                self._frame,
                *self._frame_timing(),
                log_warning=self.get_logger().warning,
            )
        except DisplayServerError:
            super().destroy_node()
            raise
        self.get_logger().info(f"cockpit display at {self.url} (state from {state_topic})")

    # -- parameters ------------------------------------------------------------------------------------
    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        for parameter in parameters:
            if parameter.name == "stale_after_s":
                value = _finite(parameter.value)
                if value is None or value <= 0:
                    return SetParametersResult(successful=False, reason="stale_after_s must be a positive number")
        for parameter in parameters:
            if parameter.name == "stale_after_s":
                self._stale_after_s = float(parameter.value)
                with self._lock:
                    self._config = {**self._config, "stale_after_s": self._stale_after_s}
                    self._config_json = _to_json(self._config)
                    self._latest.versions["config"] += 1
                if hasattr(self, "_server"):
                    self._server.min_interval_s, self._server.heartbeat_s = self._frame_timing()
                    self._server.notify()
        return SetParametersResult(successful=True)

    def _frame_timing(self) -> tuple[float, float]:
        """The (shortest, longest) time between two frames to one page, s.

        The shortest is the rate limit; the longest, a heartbeat well within ``stale_after_s``, lets the page
        tell a quiet sky from a dead link (the rate limit never stretches past it).
        """
        heartbeat = min(0.5, self._stale_after_s / 3.0)
        return min(1.0 / self._max_update_rate_hz, heartbeat), heartbeat

    # -- envelope and airframe ---------------------------------------------------------------------------
    def _load_envelope(self) -> tuple[Any, dict[str, Any]]:
        """Loads the envelope for the diagram; any failure gives an 'unavailable' section and a logged error."""
        path = self._envelope_file or "(shipped envelope)"
        try:
            from helireach_ros import envelope as envelope_module

            path = self._envelope_file or str(envelope_module.default_envelope_path())
            envelope = envelope_module.load_envelope(path)
            section = envelope_section(envelope)
        except Exception as error:  # missing module, missing/corrupt file: the page shows NO DATA, node runs on
            reason = f"{type(error).__name__}: {error}"
            if str(path) not in reason:
                reason = f"{path}: {reason}"
            self.get_logger().error(f"H-V diagram unavailable: {reason}")
            return None, {"available": False, "reason": reason, "file": str(path)}
        self.get_logger().info(f"H-V diagram: envelope {section['envelope_id']} from {path}")
        return envelope, {**section, "file": str(path)}

    def _config_section(self, envelope: Any, envelope_data: Mapping[str, Any]) -> dict[str, Any]:
        """Units, staleness and rotor limits (explicit ``airframe`` → envelope metadata → envelope's airframe)."""
        rotor_limits, airframe_label = None, str(envelope_data.get("airframe", ""))
        try:
            from helireach_ros.airframe import load_airframe

            if self._airframe_name:
                airframe = load_airframe(self._airframe_name)
                rotor_limits, airframe_label = rotor_limits_section(airframe=airframe), airframe.name
            elif envelope is not None:
                rotor_limits = rotor_limits_section(metadata=getattr(envelope, "metadata", None))
                if rotor_limits is None and airframe_label:
                    rotor_limits = rotor_limits_section(airframe=load_airframe(airframe_label))
        except Exception as error:  # the gauge then shows the speed without limits
            self.get_logger().error(f"rotor speed limits unavailable: {type(error).__name__}: {error}")
        return {
            "units": {"m_per_ft": FT, "ms_per_kt": KT},
            "stale_after_s": self._stale_after_s,
            "rotor_limits": rotor_limits,
            "airframe": airframe_label,
            "state_topic": self.resolve_topic_name(self._state_topic),
        }

    # -- ROS callbacks (any executor thread) -------------------------------------------------------------
    def _never_raising(self, callback: Callable[[Any], None], topic: str) -> Callable[[Any], None]:
        """Wraps a subscription callback: a message it cannot digest is logged and dropped, never raised."""

        def guarded(message: Any) -> None:
            try:
                callback(message)
            except Exception as error:
                self.get_logger().warning(
                    f"ignored a bad message on {topic}: {type(error).__name__}: {error}", throttle_duration_sec=5.0
                )

        return guarded

    def _store(self, update: Callable[[_Latest, float], None]) -> None:
        """Applies an update to the latest values under the lock (receipt time = now) and wakes the pages."""
        with self._lock:
            update(self._latest, time.monotonic())
        self._server_notify()

    def _server_notify(self) -> None:
        server = getattr(self, "_server", None)
        if server is not None:
            server.notify()

    def _on_safety_status(self, message: DiagnosticStatus) -> None:
        values = rm.status_values(message)
        content = {
            "level": banner_level(message.level),
            "message": str(message.message),
            "margin": _finite(_lookup(values, _MARGIN_KEYS)),
            "envelope_id": _lookup(values, _ENVELOPE_ID_KEYS),
        }

        def update(latest: _Latest, now: float) -> None:
            latest.status = _Received(content, now)
            if content["level"] != "nodata":
                latest.last_known_banner = content["level"]

        self._store(update)

    def _on_state(self, message: Odometry) -> None:
        reading = rm.read_odometry(message)
        content = {
            "height_m": _finite(reading.height),
            "speed_ms": _finite(reading.forward_speed),
            "climb_ms": _finite(reading.climb_rate),
        }

        def update(latest: _Latest, now: float) -> None:
            latest.state = _Received(content, now)

        self._store(update)

    def _on_rotor(self, message: JointState) -> None:
        try:
            speed = _finite(rm.read_rotor(message).rotor_speed)
        except ValueError:  # no main_rotor velocity: shown as "no main rotor speed"
            speed = None

        def update(latest: _Latest, now: float) -> None:
            latest.rotor = _Received({"speed_rad_s": speed}, now)

        self._store(update)

    def _on_failure(self, message: Header) -> None:
        failure_stamp = rm.stamp_nanoseconds(message.stamp) * 1e-9

        def update(latest: _Latest, now: float) -> None:
            latest.failure = _Received({"stamp_s": failure_stamp}, now)
            plan = latest.trajectory
            # a plan stamped before this failure belongs to an earlier one: clear it until the new plan arrives
            if plan is not None and 0.0 < plan.content.get("stamp_s", 0.0) < failure_stamp:
                latest.trajectory = latest.path = latest.plan_status = None
                latest.plan_reference = None
            self._rebuild_plan(latest)

        self._store(update)

    def _on_trajectory(self, message: JointTrajectory) -> None:
        section = trajectory_section(message)
        now_ros = self.get_clock().now().nanoseconds * 1e-9
        stamp = section.get("stamp_s", 0.0)

        def update(latest: _Latest, now: float) -> None:
            latest.trajectory = _Received(section, now)
            # t = 0 of the plan: its stamp if plausible on our clock, else when it arrived
            lag = now_ros - stamp
            latest.plan_reference = now - lag if stamp > 0 and 0.0 <= lag <= _PLAN_STAMP_TOLERANCE_S else now
            self._rebuild_plan(latest)

        self._store(update)

    def _on_path(self, message: PathMsg) -> None:
        self._store_plan_part("path", path_section(message))

    def _on_plan_status(self, message: DiagnosticStatus) -> None:
        self._store_plan_part("plan_status", plan_status_section(message))

    def _store_plan_part(self, part: str, section: dict[str, Any]) -> None:
        def update(latest: _Latest, now: float) -> None:
            setattr(latest, part, _Received(section, now))
            self._rebuild_plan(latest)

        self._store(update)

    def _rebuild_plan(self, latest: _Latest) -> None:
        """Re-serialises the plan section (called under the lock on every plan-related message)."""
        parts = {"trajectory": latest.trajectory, "path": latest.path, "status": latest.plan_status}
        if latest.failure is None and all(part is None for part in parts.values()):
            plan = None
        else:
            plan = {name: (part.content if part is not None else None) for name, part in parts.items()}
        self._plan_json = _to_json(plan)
        latest.versions["plan"] += 1

    # -- frames for the pages (server thread) -------------------------------------------------------------
    def _frame(self, sent_versions: dict[str, int]) -> tuple[str, dict[str, int]]:
        now = time.monotonic()
        with self._lock:
            versions = dict(self._latest.versions)
            parts = [
                f'"{name}":{text}'
                for name, text in (
                    ("config", self._config_json),
                    ("envelope", self._envelope_json),
                    ("plan", self._plan_json),
                )
                if sent_versions.get(name) != versions[name]
            ]
            live = self._live_section(self._latest, now)
        parts.append('"live":' + _to_json(live))
        return "{" + ",".join(parts) + "}", versions

    def _live_section(self, latest: _Latest, now: float) -> dict[str, Any]:
        """What changes every frame: the banner (with staleness decided here), state, rotor, plan timing."""
        stale_after = self._stale_after_s

        def age(received: _Received | None) -> float | None:
            return None if received is None else max(now - received.received, 0.0)

        status_age = age(latest.status)
        if latest.status is None:
            banner = {"level": "nodata", "message": "no safety status received", "margin": None, "envelope_id": None}
        else:
            banner = dict(latest.status.content)
            if status_age is not None and status_age > stale_after:
                banner.update(level="nodata", message=f"safety status silent for {status_age:.1f} s")
        if latest.held:
            banner.update(level="nodata", message="display held: ROS stopped, showing the last data")
        mismatch = bool(banner.get("envelope_id") and self._envelope_id and banner["envelope_id"] != self._envelope_id)
        live: dict[str, Any] = {
            "status": {
                **banner,
                "age_s": status_age,
                "last_level": latest.last_known_banner,
                "envelope_mismatch": mismatch,
            },
            "state": None,
            "rotor": None,
            "failure": None,
            "plan_clock": None,
            "held": latest.held,
        }
        if latest.state is not None:
            live["state"] = {
                **latest.state.content,
                "age_s": age(latest.state),
                "stale": age(latest.state) > stale_after,
            }
        if latest.rotor is not None:
            live["rotor"] = {
                **latest.rotor.content,
                "age_s": age(latest.rotor),
                "stale": age(latest.rotor) > stale_after,
            }
        if latest.failure is not None:
            live["failure"] = {"age_s": age(latest.failure)}
        if latest.trajectory is not None and latest.plan_reference is not None:
            live["plan_clock"] = self._plan_clock(latest, now)
        return live

    @staticmethod
    def _plan_clock(latest: _Latest, now: float) -> dict[str, Any]:
        """Time since the plan's t = 0 and the time left to touchdown (plan status, else the trajectory's end)."""
        elapsed = now - float(latest.plan_reference or now)
        time_to_land = None
        if latest.plan_status is not None:
            time_to_land = latest.plan_status.content.get("time_to_land_s")
        if time_to_land is None:
            times = [t for t in latest.trajectory.content.get("t_s", []) if t is not None] if latest.trajectory else []
            time_to_land = times[-1] if times else None
        remaining = None if time_to_land is None else max(time_to_land - elapsed, 0.0)
        return {"elapsed_s": elapsed, "time_to_touchdown_s": remaining, "time_to_land_s": time_to_land}

    # -- public --------------------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """The page's address, e.g. ``http://127.0.0.1:8080/`` (the actual port when ``port`` was 0)."""
        host, port = self._server.address or (self._bind, self._port)
        host = {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(host, host)
        return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"

    @property
    def page_count(self) -> int:
        """Pages connected right now."""
        return self._server.page_count

    def hold(self) -> None:
        """Marks the data as held (ROS stopped): pages keep the last plan and track, the banner shows NO DATA."""
        with self._lock:
            self._latest.held = True
        self._server_notify()

    def destroy_node(self) -> None:
        """Stops the web server (pages get WebSocket close 1001) and destroys the node."""
        server = getattr(self, "_server", None)
        if server is not None:
            server.stop()
        super().destroy_node()


def hold_until_interrupted(display: CockpitDisplay) -> None:
    """Keeps serving ``display`` (data frozen, marked held) until SIGINT or SIGTERM; for ``--hold``."""
    import signal

    display.hold()
    interrupted = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: interrupted.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        print(f"helireach display: holding {display.url} (Ctrl-C to stop)", flush=True)
        while not interrupted.wait(0.5):
            pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def create_display_with_fallback(preferred_port: int = DEFAULT_PORT, **node_options: Any) -> CockpitDisplay:
    """A display on ``preferred_port``, or on any free port when that one is taken (a demo must not fail
    because 8080 is busy); read the address from :attr:`CockpitDisplay.url`."""
    try:
        return CockpitDisplay(parameter_overrides=[Parameter("port", value=preferred_port)], **node_options)
    except DisplayServerError:
        return CockpitDisplay(parameter_overrides=[Parameter("port", value=0)], **node_options)


def run_display(
    args: list[str] | None = None, parameter_overrides: list[Parameter] | None = None, hold: bool = False
) -> int:
    """Runs the display until Ctrl-C/SIGTERM (then, with ``hold``, keeps the page up until the next one).

    Args:
        args: ROS command-line arguments (``--ros-args ...``), as for ``rclpy.init``.
        parameter_overrides: node parameters, e.g. ``[Parameter("port", value=0)]``.
        hold: keep serving the last data after ROS stops.

    Returns:
        0, or 1 when the web server cannot start.
    """
    # SIGTERM as well as SIGINT end spinning cleanly (rclpy's handlers wake the blocked executor)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.ALL)
    display = None
    try:
        display = CockpitDisplay(parameter_overrides=parameter_overrides or [])
        print(f"helireach display: {display.url}", flush=True)
        rclpy.spin(display)
    except DisplayServerError as error:
        print(f"helireach display: {error}", file=sys.stderr, flush=True)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()
        if display is not None:
            if hold:
                hold_until_interrupted(display)
            display.destroy_node()
    return 0


def main(args: list[str] | None = None) -> None:
    """Console entry point (ros2/demos style): ``python -m helireach_ros.nodes.display --ros-args ...``."""
    code = run_display(args)
    if code:
        raise SystemExit(code)


if __name__ == "__main__":
    main()
