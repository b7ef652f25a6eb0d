"""Message → JSON-ready sections for the cockpit page (pure functions: no node, no server).

Each function turns one ROS message (or the loaded envelope/airframe) into the dict the page reads, in SI
units; NaN and infinities become ``null`` (JSON has none; the page shows '---'). The key names of the
status/planner nodes' ``DiagnosticStatus`` values are theirs (see ``msg_docs/``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Path as PathMsg
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.policies.failure_episode import EpisodeState
from helireach_ros.core.status_contracts import (
    PlanStatusValues,
    RobustVerdictValues,
    SafetyStatusValues,
    TouchdownValues,
)
from helireach_ros.core.status_values import format_value, parse_bool
from helireach_ros.ros import messages as rm

__all__ = [
    "BANNER_LEVELS",
    "banner_level",
    "boundary_segments",
    "envelope_section",
    "episode_section",
    "finite",
    "footprint_section",
    "path_section",
    "plan_status_section",
    "robust_verdict_section",
    "rotor_limits_section",
    "safety_status_section",
    "site_section",
    "site_verdict",
    "to_json",
    "touchdown_section",
    "trajectory_section",
]

# Keys of the DiagnosticStatus values (first match wins; the status/planner nodes own the names, see msg_docs/).

#: Banner level per DiagnosticStatus level; anything else is NO DATA (never optimistic).
BANNER_LEVELS: dict[bytes, str] = {
    DiagnosticStatus.OK: "safe",
    DiagnosticStatus.WARN: "caution",
    DiagnosticStatus.ERROR: "avoid",
    DiagnosticStatus.STALE: "nodata",
}
_MAX_POINTS = 2000  # longer trajectories/paths are decimated for the page (keeps frames small)


# ----------------------------------------------------------------------------------------------------------
# Message → JSON-ready sections (pure functions; no ROS node needed, so they are easy to reason about)
# ----------------------------------------------------------------------------------------------------------


def finite(value: Any) -> float | None:
    """A finite float, or None for NaN/inf/garbage (JSON has no NaN; the page shows '---')."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def _finite_list(values: Iterable[Any]) -> list[float | None]:
    return [finite(value) for value in values]


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
    """The H-V diagram data of an envelope (see :mod:`helireach_ros.core.envelope.data`), SI units.

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
        "boundary": [[finite(height), finite(speed)] for height, speed in boundary],
        "boundary_segments": [
            [finite(value) for value in segment] for segment in boundary_segments(heights, speeds, codes == 0, boundary)
        ],
        "envelope_id": str(envelope.envelope_id),
        "airframe": str(getattr(envelope, "airframe_name", "") or ""),
        "method": str(metadata.get("method", "")),
        "power_fraction": finite(metadata.get("power_fraction")),
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
        for edge_row in np.flatnonzero(np.abs(heights - height) <= tolerance_h):
            for edge_column in spans_v:
                on_edge.setdefault(("h", int(edge_row), int(edge_column)), []).append(point)
        for edge_column in np.flatnonzero(np.abs(speeds - speed) <= tolerance_v):
            for edge_row in spans_h:
                on_edge.setdefault(("v", int(edge_row), int(edge_column)), []).append(point)

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
            crossings = [crossing(kind, r, c) for kind, r, c, changes in edges if changes]
            points = [point for point in crossings if point is not None]
            if len(points) == 2:
                segments.append((*points[0], *points[1]))
            elif len(points) == 4:  # saddle: cut off the safe corners (never join them across the cell)
                first, second = ((0, 1), (2, 3)) if safe[row, column + 1] else ((1, 2), (3, 0))
                segments += [(*points[first[0]], *points[first[1]]), (*points[second[0]], *points[second[1]])]
    return segments


def rotor_limits_section(airframe: Any = None, metadata: Mapping[str, Any] | None = None) -> dict[str, Any] | None:
    """Rotor speed limits Ω₀, Ω_min = r_min Ω₀, Ω_max = r_max Ω₀ (rad/s) from an Airframe or envelope metadata.

    Args:
        airframe: an :class:`helireach_ros.core.aircraft.airframe.Airframe` (wins if given).
        metadata: an envelope's metadata; its ``airframe`` entry is ``Airframe.as_dict()``.

    Returns:
        ``{"nominal_rad_s", "min_rad_s", "max_rad_s", "source"}`` or None when neither holds usable limits.
    """
    if airframe is not None:
        nominal = finite(airframe.nominal_rotor_speed)
        low, high = airframe.limits.min_rotor_speed_ratio, airframe.limits.max_rotor_speed_ratio
        source = f"airframe {airframe.name}"
    else:
        entry = (metadata or {}).get("airframe")
        if not isinstance(entry, Mapping) or not isinstance(entry.get("limits"), Mapping):
            return None
        nominal = finite(entry.get("nominal_rotor_speed"))
        low, high = entry["limits"].get("min_rotor_speed_ratio"), entry["limits"].get("max_rotor_speed_ratio")
        source = f"envelope airframe {entry.get('name', '')}".strip()
    low, high = finite(low), finite(high)
    if nominal is None or low is None or high is None or nominal <= 0 or not 0 < low < high:
        return None
    return {"nominal_rad_s": nominal, "min_rad_s": low * nominal, "max_rad_s": high * nominal, "source": source}


def trajectory_section(message: JointTrajectory) -> dict[str, Any]:
    """Collective and pitch against time from a landing trajectory (:func:`helireach_ros.ros.messages.read_trajectory`).

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

    The keys are the planner node's (``helireach_ros.ros.nodes.planner_node``, ``msg_docs/``); a missing key is None.
    """
    values = rm.status_values(message)
    plan = PlanStatusValues.from_values(values)
    return {
        "level": banner_level(message.level),
        "message": str(message.message),
        "safe": plan.safe,
        "verified": plan.verified,
        "fallback": plan.fallback,
        "value": finite(plan.value),
        "time_to_land_s": finite(plan.time_to_land_s),
        "solve_time_ms": finite(plan.solve_time_ms),
        "replan_index": finite(plan.replan_index),
        "status": plan.status,
        "late": plan.late,
        "late_by_s": finite(plan.late_by_s),
        "state_delay_s": finite(plan.state_delay_s),
        "touchdown_descent_rate_ms": finite(plan.touchdown_descent_rate),
        "touchdown_forward_speed_ms": finite(plan.touchdown_forward_speed),
        "standby": plan.standby,
        # robust only once verified robustly (pending: the verdict follows on /helireach/robust_verdict)
        "robust": plan.robust if isinstance(plan.robust, bool) else None,
        "gross_weight_n": finite(plan.gross_weight),
        "density_altitude_m": finite(plan.density_altitude),
        "site": site_section(values),
        "values": values,
    }


def robust_verdict_section(message: DiagnosticStatus) -> dict[str, Any]:
    """The failure plan's robust verdict from ``/helireach/robust_verdict`` (``msg_docs/``).

    ``robust`` is ``"pending"``, ``"true"`` or ``"false"`` as sent, anything else None (the page then shows no
    verdict); ``failure_id`` and ``failure_stamp_ns`` name the failure it belongs to (the page shows it only beside
    that failure's plan).
    """
    verdict = RobustVerdictValues.from_values(rm.status_values(message))
    return {
        "robust": None if verdict.robust is None else format_value(verdict.robust),
        "error": verdict.error is True,
        "failure_id": None if verdict.failure_id is None else str(verdict.failure_id),
        "failure_stamp_ns": None if verdict.failure_stamp_ns is None else str(verdict.failure_stamp_ns),
        "models_flown": finite(verdict.models_flown),
        "design_size": finite(verdict.design_size),
        "level": banner_level(message.level),
        "message": str(message.message),
    }


def episode_section(message: DiagnosticStatus) -> dict[str, Any]:
    """The failure episode from ``/helireach/failure_episode`` (the monitor's episode model, ``msg_docs/``).

    Returns:
        ``{"phase", "episode_id", "flag_changes", "level", "message"}``; an unreadable one is phase ``unknown``
        with the ``error`` (the page then shows it, never a guessed phase).
    """
    try:
        state = EpisodeState.from_values(rm.status_values(message))
    except ValueError as error:
        return {"phase": "unknown", "episode_id": None, "flag_changes": None, "level": "nodata", "error": str(error)}
    return {
        "phase": state.phase.value,
        "episode_id": state.episode_id,
        "flag_changes": state.flag_changes,
        "started_ns": state.started_ns,
        "ended_ns": state.ended_ns,
        "level": banner_level(message.level),
        "message": str(message.message),
    }


def touchdown_section(message: DiagnosticStatus) -> dict[str, Any]:
    """The vehicle's touchdown report from ``/helireach/touchdown`` (``msg_docs/helireach_touchdown.md``), SI.

    ``within_limits`` is None when the report does not say (the page then says the result is unknown).
    """
    touchdown = TouchdownValues.from_values(rm.status_values(message))
    return {
        "within_limits": touchdown.within_limits,
        "descent_rate_ms": finite(touchdown.descent_rate),
        "forward_speed_ms": finite(touchdown.forward_speed),
        "max_descent_rate_ms": finite(touchdown.max_descent_rate),
        "max_forward_speed_ms": finite(touchdown.max_forward_speed),
        "rotor_speed_pct": finite(touchdown.rotor_speed_pct),
        "time_after_failure_s": finite(touchdown.time_after_failure_s),
        "reason": touchdown.reason or "",
        "level": banner_level(message.level),
        "message": str(message.message),
    }


def to_json(value: Any) -> str:
    # allow_nan=False: a NaN that slipped through is a bug to see, not invalid JSON for the page
    return json.dumps(value, allow_nan=False, separators=(",", ":"))


def safety_status_section(message: DiagnosticStatus) -> dict[str, Any]:
    """The banner's content from a ``/helireach/safety_status`` message (level, text, margin, envelope id)."""
    status = SafetyStatusValues.from_values(rm.status_values(message))
    return {
        "level": banner_level(message.level),
        "message": str(message.message),
        "margin": finite(status.margin),
        "envelope_id": status.envelope_id,
    }


# ----------------------------------------------------------------------------------------------------------
# Reachable footprint and landing sites (msg_docs/helireach_reachable_footprint.md, the site keys of the live
# reachability and the plan status): the side view's ground line
# ----------------------------------------------------------------------------------------------------------


def _stamp_ns(text: str | None) -> int | None:
    try:
        return int(text) if text is not None else None
    except ValueError:
        return None


def footprint_section(message: DiagnosticStatus) -> dict[str, Any]:
    """The live reachable footprint from ``/helireach/reachable_footprint``, SI (along-track metres).

    Never optimistic: an end counts (``*_verified`` True, its distances set) only when the message says ``true`` and
    its along-track distance is finite; ``off`` is True for a STALE or ``off`` message, an unknown level or status
    (nothing is drawn for it). ``sites`` maps each ``site_<name>`` to ``reachable``/``not_reachable``/``unknown`` (any
    other word: ``unknown``).

    Returns:
        ``{"status", "off", "level", "message", "reason", "nearest_distance_m", "farthest_distance_m", "nearest_m",
        "farthest_m", "nearest_verified", "farthest_verified", "state_stamp_ns", "sites", "sites_in_footprint"}``.
    """
    values = rm.status_values(message)
    status = values.get("status")
    # STALE (status off: no footprint solved), a level or status from the future: nothing to draw
    off = banner_level(message.level) == "nodata" or status not in ("reachable", "partial", "unknown")
    section: dict[str, Any] = {
        "status": status if status in ("reachable", "partial", "unknown", "off") else None,
        "off": off,
        "level": banner_level(message.level),
        "message": str(message.message),
        "reason": values.get("reason", ""),
        "state_stamp_ns": _stamp_ns(values.get("state_stamp_ns")),
        "distance_m": finite(values.get("distance_m")),
    }
    for end in ("nearest", "farthest"):
        along = finite(values.get(f"{end}_distance_m"))
        verified = not off and parse_bool(values.get(f"{end}_verified")) is True and along is not None
        section[f"{end}_verified"] = verified
        section[f"{end}_distance_m"] = along if verified else None
        section[f"{end}_m"] = finite(values.get(f"{end}_m")) if verified else None
    words = ("reachable", "not_reachable", "unknown")
    section["sites"] = {
        name[len("site_") :]: (value if value in words and not off else "unknown")
        for name, value in values.items()
        if name.startswith("site_") and len(name) > len("site_")
    }
    section["sites_in_footprint"] = None if off else finite(values.get("sites_in_footprint"))
    return section


def site_section(values: Mapping[str, str]) -> dict[str, Any] | None:
    """The landing-site keys of a live reachability or plan status (``landing_site``, ``site_start_m``, ...), SI.

    Returns:
        ``{"name", "start_m", "end_m", "planned", "on_site", "touchdown_distance_m", "margin_m",
        "sites_reachable"}`` (flags True/False/None as sent), or None without a site (no finite ``site_start_m`` and
        ``site_end_m``: the keys are absent when no sites are configured).
    """
    start, end = finite(values.get("site_start_m")), finite(values.get("site_end_m"))
    if start is None or end is None:
        return None
    return {
        "name": str(values.get("landing_site", "")),
        "start_m": min(start, end),
        "end_m": max(start, end),
        "planned": parse_bool(values.get("site_planned")),
        "on_site": parse_bool(values.get("on_site")),
        "touchdown_distance_m": finite(values.get("touchdown_distance_m")),
        "margin_m": finite(values.get("site_margin_m")),
        "sites_reachable": finite(values.get("sites_reachable")),
    }


def site_verdict(site: Mapping[str, Any], source: str, current: bool, plan_void: bool = False) -> tuple[str, str]:
    """What the side view says of the selected site: ``(kind, words)``.

    ``kind`` is ``reachable`` (green: a verified safe plan lands on it, ``on_site`` true), ``not_reachable`` (red:
    no plan for the site was verified, ``site_planned`` false), ``unknown`` (a plan for the site whose replay does not
    land on it, or keys missing) or ``stale`` (a live verdict older than the display's live age, or a plan status that
    no longer applies): never reachable unless the message says so of a verdict that holds now.

    Args:
        site: a :func:`site_section`.
        source: ``live`` (``/helireach/live_reachability``: "if the engine failed now") or ``plan`` (the plan status).
        current: the live verdict's state is recent enough (ignored for a plan).
        plan_void: the plan status no longer applies (status ``ended``, or no failure episode under way).
    """
    if source == "live" and not current:
        return "stale", "REACHABILITY STALE"
    if source == "plan" and plan_void:
        return "stale", "NO PLAN"
    if site.get("on_site") is True:
        return "reachable", "ON SITE" if source == "plan" else "REACHABLE"
    if site.get("planned") is False:
        return "not_reachable", "NOT REACHABLE" + (" \u00b7 LANDING OFF-SITE" if source == "plan" else "")
    if site.get("planned") is True:
        return "unknown", "NOT VERIFIED ON SITE"
    return "unknown", "REACHABILITY UNKNOWN"
