"""The flight-manual H-V diagram of an envelope (matplotlib, Agg: no display needed, safe in any thread).

Knots on x, feet on y. A 3-D envelope is drawn one climb slice at a time (the slice nearest the asked
climb rate, named in the title), or every slice in a multi-panel figure. Several envelopes can be
overlaid: each one's not-proven-safe region is outlined in its own colour, labelled from its metadata
(method, reaction delay, climb slice, and the airframe, weight and density altitude where the files
differ). The region not proven safe is shaded: inside each grid cell the shaded part
is bounded by the cell's not-safe corners and the refined boundary points on its edges (marching
squares; an ambiguous saddle cell is shaded through its middle, the conservative choice). The
refined boundary is drawn as a curve through those points. Unverified and failed nodes get their
own markers. An optional flown track (height m, speed m/s) is drawn on top. An envelope with robust verdicts
(:mod:`helireach_ros.core.robustness.envelope_verdicts`) also gets its **robust boundary**: the edge of the set not
proven robustly safe (cells with a corner that is not robust), dashed, and markers on the safe nodes that are not
robust.
"""

from __future__ import annotations

import os
import pathlib

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, PathPatch
from matplotlib.path import Path

from helireach_ros.core.envelope.data import ROBUST_CODES, STATUS_CODES, Envelope
from helireach_ros.core.units import FT, KT, LBF

_FPM = FT / 60.0
_OVERLAY_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf")
_NODE_MARKERS = (
    ("unverified", "D", "#ff7f0e", "unverified (NLP safe, replay failed)"),
    ("failed", "X", "#9467bd", "failed (solver did not converge)"),
    ("no_trim", "s", "#7f7f7f", "no trim (no steady flight there)"),
)

__all__ = [
    "all_slices_figure",
    "boundary_geometry",
    "envelope_figure",
    "overlay_figure",
    "overlay_labels",
    "plot_all_slices",
    "plot_envelope",
    "plot_overlay",
    "region_outline",
]

_UNSAFE_COLOUR = "#d62728"
_ROBUST_COLOUR = "#1f4fb4"


def _robust_only(envelope: Envelope) -> Envelope | None:
    """A 2-D envelope whose only safe nodes are the robust ones (None: no robust verdict in this slice).

    For drawing the robust boundary with :func:`region_outline`; its refined points are dropped (they refine
    the nominal boundary).
    """
    if not envelope.has_robust_verdict:
        return None
    arrays = envelope.arrays
    robust_code = arrays["robust_code"]
    if np.all(robust_code == ROBUST_CODES["not_computed"]):
        return None
    codes = np.array(arrays["status_code"], copy=True)
    codes[(codes == STATUS_CODES["safe"]) & (robust_code != ROBUST_CODES["robust"])] = STATUS_CODES["unverified"]
    arrays["status_code"] = codes
    arrays["boundary"] = arrays["boundary_unsafe_side"] = np.zeros((0, 2))
    arrays["boundary_edge"] = np.zeros((0, 4), np.int32)
    return Envelope(arrays, envelope.metadata)


def _draw_robust(axes, envelope: Envelope, marker_size: float, counts: bool) -> list:
    """The robust boundary and the safe-but-not-robust nodes; legend handles (none without a robust verdict)."""
    robust_only = _robust_only(envelope)
    if robust_only is None:
        return []
    axes.add_collection(
        LineCollection(region_outline(robust_only), colors=_ROBUST_COLOUR, linewidths=2.2, linestyles="--", zorder=3)
    )
    speeds_kt, heights_ft = envelope.speeds / KT, envelope.heights / FT
    grid_speed, grid_height = np.meshgrid(speeds_kt, heights_ft)
    robust_code = envelope.arrays["robust_code"]
    not_robust = (envelope.status == "safe") & (robust_code != ROBUST_CODES["robust"])
    robust = robust_code == ROBUST_CODES["robust"]
    axes.plot(grid_speed[not_robust], grid_height[not_robust], "o", markerfacecolor="none",
              markeredgecolor=_ROBUST_COLOUR, markersize=marker_size * 0.8, linestyle="none", zorder=4)  # fmt: skip
    axes.plot(grid_speed[robust], grid_height[robust], "o", color=_ROBUST_COLOUR, markersize=marker_size * 0.6,
              linestyle="none", zorder=4)  # fmt: skip
    design = envelope.metadata.get("robust", {}).get("design", "")
    return [
        Line2D([], [], color=_ROBUST_COLOUR, linewidth=2.2, linestyle="--", label=f"robust boundary ({design})"),
        Line2D([], [], marker="o", color=_ROBUST_COLOUR, linestyle="none",
               label=f"robust: {int(robust.sum())}" if counts else "robust"),
        Line2D([], [], marker="o", markerfacecolor="none", markeredgecolor=_ROBUST_COLOUR, linestyle="none",
               label=f"safe, not robust: {int(not_robust.sum())}" if counts else "safe, not robust"),
    ]  # fmt: skip


def _crossings(envelope: Envelope) -> dict[tuple[int, int, int, int], tuple[float, float]]:
    """(row, column) pairs of neighbouring nodes → the boundary point between them (speed kt, height ft).

    Both orientations of an edge are keyed. Edges without a refined point get their midpoint.
    """
    points: dict[tuple[int, int, int, int], tuple[float, float]] = {}
    for (row0, column0, row1, column1), (height, speed) in zip(
        envelope.arrays["boundary_edge"].tolist(), envelope.boundary.tolist(), strict=True
    ):
        point = (speed / KT, height / FT)
        points[(row0, column0, row1, column1)] = points[(row1, column1, row0, column0)] = point
    return points


def boundary_geometry(envelope: Envelope) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Polygons of the not-proven-safe region and segments of the refined boundary curve, in (kt, ft).

    A cell edge between a safe and a not-safe node is cut at its refined boundary point, or at its
    middle when it has none (next to an unverified or failed node); the curve joins refined points only.

    Returns:
        (polygons, segments): each polygon an n × 2 array (counter-clockwise), each segment a 2 × 2 array.
    """
    safe = envelope.arrays["status_code"] == STATUS_CODES["safe"]
    speeds_kt, heights_ft = envelope.speeds / KT, envelope.heights / FT
    refined = _crossings(envelope)
    polygons: list[np.ndarray] = []
    segments: list[np.ndarray] = []
    for row in range(heights_ft.size - 1):
        for column in range(speeds_kt.size - 1):
            corners = [(row, column), (row, column + 1), (row + 1, column + 1), (row + 1, column)]
            bad = [not safe[corner] for corner in corners]
            if not any(bad):
                continue
            vertices: list[tuple[tuple[float, float], bool]] = []  # (point, is a refined crossing)
            for k, corner in enumerate(corners):
                following = corners[(k + 1) % 4]
                if bad[k]:
                    vertices.append(((speeds_kt[corner[1]], heights_ft[corner[0]]), False))
                if bad[k] != bad[(k + 1) % 4]:
                    midpoint = (
                        0.5 * (speeds_kt[corner[1]] + speeds_kt[following[1]]),
                        0.5 * (heights_ft[corner[0]] + heights_ft[following[0]]),
                    )
                    point = refined.get((*corner, *following))
                    vertices.append((midpoint, False) if point is None else (point, True))
            polygons.append(np.array([point for point, _ in vertices]))
            for k, (point, is_crossing) in enumerate(vertices):
                following_point, following_is_crossing = vertices[(k + 1) % len(vertices)]
                if is_crossing and following_is_crossing:
                    segments.append(np.array([point, following_point]))
    return polygons, segments


def _power_text(power_fraction: float) -> str:
    return "total power loss" if power_fraction == 0.0 else f"{100.0 * power_fraction:.0f} % power left"


def _climb_text(envelope: Envelope) -> str:
    """The climb slice an envelope (or slice) stands for, for titles and labels ('' for a 2-D envelope)."""
    climb = envelope.metadata.get("climb_slice")
    if not climb:
        return ""
    return f"climb {climb['climb_rate_fpm']:+,.0f} ft/min (slice {climb['index'] + 1} of {climb['of']})"


def _chosen_slice(envelope: Envelope, climb_rate: float | None) -> Envelope:
    """The 2-D envelope to draw: a 3-D envelope's slice nearest ``climb_rate`` (None: level flight)."""
    if not envelope.is_3d:
        return envelope
    return envelope.slice(envelope.nearest_slice(0.0 if climb_rate is None else climb_rate))


def _region_path(polygons: list[np.ndarray]) -> Path:
    # one compound path, filled once: no darker seams where cells meet
    return Path.make_compound_path(*(Path(np.vstack([p, p[:1]]), closed=True) for p in polygons))


def region_outline(envelope: Envelope) -> list[np.ndarray]:
    """Segments (2 × 2, kt and ft) of the not-proven-safe region's edge inside the grid.

    The edges of :func:`boundary_geometry`'s cell polygons that belong to one polygon only, without the grid's
    own border: the whole boundary, also where it has no refined points (next to unverified, failed or
    no-trim nodes), where the refined curve has gaps.
    """
    polygons, _ = boundary_geometry(envelope)
    speeds_kt, heights_ft = envelope.speeds / KT, envelope.heights / FT
    counts: dict[tuple, int] = {}
    for polygon in polygons:
        for start, end in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
            key = tuple(sorted((tuple(np.round(start, 9)), tuple(np.round(end, 9)))))
            counts[key] = counts.get(key, 0) + 1

    def on_border(start: tuple, end: tuple) -> bool:
        return any(
            start[axis] == end[axis] and start[axis] in (low, high)
            for axis, (low, high) in enumerate(((speeds_kt[0], speeds_kt[-1]), (heights_ft[0], heights_ft[-1])))
        )

    return [np.array(edge) for edge, count in counts.items() if count == 1 and not on_border(*edge)]


def _draw_diagram(axes, envelope: Envelope, marker_size: float = 7.0, counts: bool = True) -> list:
    """Draws one 2-D envelope (region, refined boundary, grid, special nodes) on ``axes``; returns legend handles.

    ``counts``: the node markers' labels give their number (False: one legend for several panels).
    """
    speeds_kt, heights_ft = envelope.speeds / KT, envelope.heights / FT
    polygons, segments = boundary_geometry(envelope)
    if polygons:
        axes.add_patch(PathPatch(_region_path(polygons), facecolor=_UNSAFE_COLOUR, edgecolor="none", alpha=0.35))
    axes.add_collection(LineCollection(segments, colors="black", linewidths=1.8))
    handles: list = [
        Patch(facecolor=_UNSAFE_COLOUR, alpha=0.35, label="avoid: safe landing not proven"),
        Line2D([], [], color="black", linewidth=1.8, label="refined boundary (±2 ft / ±1 kt)"),
    ]
    status = envelope.status
    grid_speed, grid_height = np.meshgrid(speeds_kt, heights_ft)
    axes.plot(grid_speed.ravel(), grid_height.ravel(), ".", color="0.75", markersize=2, zorder=1)
    for name, marker, colour, label in _NODE_MARKERS:
        mask = status == name
        if np.any(mask):
            axes.plot(grid_speed[mask], grid_height[mask], marker, color=colour, markersize=marker_size,
                      linestyle="none", markeredgecolor="black", markeredgewidth=0.6, zorder=4)  # fmt: skip
        if name != "no_trim" or np.any(mask) or not counts:  # no-trim nodes exist only off level flight
            handles.append(
                Line2D([], [], marker=marker, color=colour, markeredgecolor="black", linestyle="none",
                       label=f"{label}: {int(mask.sum())}" if counts else label)
            )  # fmt: skip
    handles += _draw_robust(axes, envelope, marker_size, counts)
    _label_axes(axes, envelope)
    return handles


def _label_axes(axes, envelope: Envelope) -> None:
    speeds_kt, heights_ft = envelope.speeds / KT, envelope.heights / FT
    axes.set_xlim(speeds_kt[0], speeds_kt[-1])
    axes.set_ylim(heights_ft[0], heights_ft[-1])
    axes.set_xlabel("forward speed (kt)")
    axes.set_ylabel("height above ground (ft)")
    axes.grid(True, color="0.85", linewidth=0.6)


def _conditions(envelope: Envelope) -> tuple[float, float]:
    """(weight lbf, density altitude ft) from the metadata (NaN when unknown)."""
    airframe = envelope.metadata.get("airframe", {})
    return (
        float(airframe.get("gross_weight", float("nan"))) / LBF,
        float(airframe.get("density_altitude", float("nan"))) / FT,
    )


def _title(envelope: Envelope) -> str:
    weight_lbf, altitude_ft = _conditions(envelope)
    return (
        f"H-V diagram: {envelope.airframe_name}, W = {weight_lbf:,.0f} lbf, density altitude {altitude_ft:,.0f} ft, "
        f"{_power_text(envelope.power_fraction)}"
    )


def _save(figure: Figure, out_path: str | os.PathLike[str]) -> pathlib.Path:
    path = pathlib.Path(out_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    return path


def _footer(envelope: Envelope, figure: Figure, start: str) -> None:
    grid = f"{envelope.heights.size} x {envelope.speeds.size} nodes"
    if envelope.climb_rates is not None:
        grid = f"{envelope.climb_rates.size} x {grid}"
    flight = "steady flight at each climb rate" if envelope.is_3d or _climb_text(envelope) else "level trim"
    figure.text(
        0.01, 0.005,
        f"envelope {start} · method {envelope.metadata.get('method', '?')} · {grid} · {flight} at failure",
        fontsize=7, color="0.4",
    )  # fmt: skip


def plot_envelope(
    envelope: Envelope,
    out_path: str | os.PathLike[str],
    track: np.ndarray | None = None,
    title_extra: str | None = None,
    climb_rate: float | None = None,
) -> pathlib.Path:
    """Draws the H-V diagram (:func:`envelope_figure`) and writes it (format from the extension: .png, .svg, .pdf).

    Returns:
        The path written.
    """
    return _save(envelope_figure(envelope, track, title_extra, climb_rate), out_path)


def envelope_figure(
    envelope: Envelope,
    track: np.ndarray | None = None,
    title_extra: str | None = None,
    climb_rate: float | None = None,
) -> Figure:
    """The H-V diagram of one envelope.

    Args:
        envelope: the envelope (3-D: the slice nearest ``climb_rate`` is drawn, the title says which).
        track: optional N × 2 array of (height m, speed m/s) drawn as the flown track.
        title_extra: appended to the title.
        climb_rate: m/s, positive up, for a 3-D envelope (None: the slice nearest level flight).

    Raises:
        ValueError: a track that is not N × 2, or a climb rate that is not finite.
    """
    drawn = _chosen_slice(envelope, climb_rate)
    figure = Figure(figsize=(8.5, 6.5), dpi=120)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot(1, 1, 1)
    handles = _draw_diagram(axes, drawn)
    if track is not None:
        points = np.asarray(track, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2:
            raise ValueError(f"track must be an N x 2 array of (height m, speed m/s), got shape {points.shape}")
        finite = points[np.all(np.isfinite(points), axis=1)]
        if finite.size:
            axes.plot(finite[:, 1] / KT, finite[:, 0] / FT, "-", color="#1f77b4", linewidth=2.0, zorder=5)
            axes.plot(finite[-1, 1] / KT, finite[-1, 0] / FT, "o", color="#1f77b4", markersize=7, zorder=6)
        handles.append(Line2D([], [], color="#1f77b4", linewidth=2.0, marker="o", label="flown track (now: dot)"))
    figure.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 0.025), ncol=3, fontsize=8, frameon=False)
    title = _title(drawn)
    if _climb_text(drawn):
        asked = 0.0 if climb_rate is None else climb_rate
        title += f"\n{_climb_text(drawn)}: the stored slice nearest {asked / _FPM:+,.0f} ft/min"
    if title_extra:
        title += f"\n{title_extra}"
    axes.set_title(title, fontsize=10)
    _footer(envelope, figure, envelope.envelope_id)
    figure.tight_layout(rect=(0, 0.11, 1, 1))
    return figure


def plot_all_slices(
    envelope: Envelope, out_path: str | os.PathLike[str], title_extra: str | None = None
) -> pathlib.Path:
    """Writes :func:`all_slices_figure`; returns the path written."""
    return _save(all_slices_figure(envelope, title_extra), out_path)


def all_slices_figure(envelope: Envelope, title_extra: str | None = None) -> Figure:
    """Every climb slice of a 3-D envelope, one panel each (ascending climb rate, titled by it), in one figure.

    Raises:
        ValueError: a 2-D envelope.
    """
    if envelope.climb_rates is None:
        raise ValueError("a 2-D envelope has one slice: use plot_envelope")
    count = envelope.climb_rates.size
    columns = min(count, 4)
    rows = -(-count // columns)
    figure = Figure(figsize=(4.2 * columns, 3.6 * rows + 1.2), dpi=110)
    FigureCanvasAgg(figure)
    legend: list = []
    for index in range(count):
        drawn = envelope.slice(index)
        axes = figure.add_subplot(rows, columns, index + 1)
        legend = _draw_diagram(axes, drawn, marker_size=4.0, counts=False)
        axes.set_title(f"{drawn.metadata['climb_slice']['climb_rate_fpm']:+,.0f} ft/min", fontsize=9)
    figure.legend(handles=legend, loc="lower center", ncol=3, fontsize=8, frameon=False)
    title = f"{_title(envelope)}\nby climb rate at the failure"
    figure.suptitle(title + (f"\n{title_extra}" if title_extra else ""), fontsize=11)
    _footer(envelope, figure, envelope.envelope_id)
    figure.tight_layout(rect=(0, 0.1 if rows == 1 else 0.06, 1, 0.93))
    return figure


def overlay_labels(envelopes: list[Envelope], names: list[str] | None = None) -> list[str]:
    """One legend label per envelope from its metadata.

    Always the method and the reaction delay (files made before the delay existed had none: 0 s) and, for a
    climb slice, its climb rate; the airframe, rotor model, weight, density altitude and power loss only where the
    files differ. Labels that are still equal get the file name (``names``) or the envelope id.
    """

    def delay(envelope: Envelope) -> float:
        return float(envelope.metadata.get("settings", {}).get("reaction_delay_s", 0.0))

    facts = [
        {
            "airframe": envelope.airframe_name,
            "rotor": envelope.rotor_model_text,
            "weight": f"W {_conditions(envelope)[0]:,.0f} lbf",
            "altitude": f"DA {_conditions(envelope)[1]:,.0f} ft",
            "power": _power_text(envelope.power_fraction),
        }
        for envelope in envelopes
    ]
    differing = [key for key in facts[0] if len({fact[key] for fact in facts}) > 1]
    labels = []
    for envelope, fact in zip(envelopes, facts, strict=True):
        parts = [f"{envelope.metadata.get('method', '?')}", f"delay {delay(envelope):g} s"]
        parts += [fact[key] for key in differing]
        if _climb_text(envelope):
            parts.append(f"{envelope.metadata['climb_slice']['climb_rate_fpm']:+,.0f} ft/min")
        labels.append(", ".join(parts))
    return [
        f"{label} ({names[index] if names else envelopes[index].envelope_id})" if labels.count(label) > 1 else label
        for index, label in enumerate(labels)
    ]


def overlay_figure(
    envelopes: list[Envelope],
    names: list[str] | None = None,
    climb_rate: float | None = None,
    title_extra: str | None = None,
) -> Figure:
    """The boundaries of several envelopes in one H-V figure (see :func:`plot_overlay`)."""
    if not envelopes:
        raise ValueError("no envelope to draw")
    drawn = [_chosen_slice(envelope, climb_rate) for envelope in envelopes]
    figure = Figure(figsize=(8.5, 6.5), dpi=120)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot(1, 1, 1)
    handles = []
    for index, (envelope, label) in enumerate(zip(drawn, overlay_labels(drawn, names), strict=True)):
        colour = _OVERLAY_COLOURS[index % len(_OVERLAY_COLOURS)]
        polygons, segments = boundary_geometry(envelope)
        if polygons:  # the region lightly filled in its colour, the refined boundary as a line
            axes.add_patch(PathPatch(_region_path(polygons), facecolor=colour, edgecolor="none", alpha=0.10))
        axes.add_collection(LineCollection(region_outline(envelope), colors=colour, linewidths=1.2, linestyles="--"))
        axes.add_collection(LineCollection(segments, colors=colour, linewidths=2.0))
        handles.append(Patch(facecolor=colour, edgecolor=colour, alpha=0.6, label=label))
    low_speed = min(float(e.speeds[0]) for e in drawn) / KT
    high_speed = max(float(e.speeds[-1]) for e in drawn) / KT
    _label_axes(axes, drawn[0])
    axes.set_xlim(low_speed, high_speed)
    axes.set_ylim(min(float(e.heights[0]) for e in drawn) / FT, max(float(e.heights[-1]) for e in drawn) / FT)
    figure.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 0.02), ncol=2, fontsize=8, frameon=False)
    title = "H-V boundaries compared (shaded: safe landing not proven; solid: refined boundary; dashed: its grid edge)"
    if title_extra:
        title += f"\n{title_extra}"
    axes.set_title(title, fontsize=10)
    rows = -(-len(handles) // 2)
    figure.tight_layout(rect=(0, 0.04 + 0.035 * rows, 1, 1))
    return figure


def plot_overlay(
    envelopes: list[Envelope],
    out_path: str | os.PathLike[str],
    names: list[str] | None = None,
    climb_rate: float | None = None,
    title_extra: str | None = None,
) -> pathlib.Path:
    """Writes the boundaries of several envelopes overlaid in one H-V figure, one legend entry per envelope.

    Args:
        envelopes: the envelopes (3-D ones: the slice nearest ``climb_rate``, None: level).
        out_path: the image file.
        names: file names, to tell apart envelopes whose metadata labels are equal.
        climb_rate: m/s, positive up.
        title_extra: appended to the title.
    """
    return _save(overlay_figure(envelopes, names, climb_rate, title_extra), out_path)
