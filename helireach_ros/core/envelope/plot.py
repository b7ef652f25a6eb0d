"""The flight-manual H-V diagram of an envelope (matplotlib, Agg: no display needed, safe in any thread).

Knots on x, feet on y. The region not proven safe is shaded: inside each grid cell the shaded part
is bounded by the cell's not-safe corners and the refined boundary points on its edges (marching
squares; an ambiguous saddle cell is shaded through its middle, the conservative choice). The
refined boundary is drawn as a curve through those points. Unverified and failed nodes get their
own markers. An optional flown track (height m, speed m/s) is drawn on top.
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

from helireach_ros.core.envelope.data import STATUS_CODES, Envelope
from helireach_ros.core.units import FT, KT, LBF

__all__ = ["boundary_geometry", "plot_envelope"]

_UNSAFE_COLOUR = "#d62728"


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


def plot_envelope(
    envelope: Envelope,
    out_path: str | os.PathLike[str],
    track: np.ndarray | None = None,
    title_extra: str | None = None,
) -> pathlib.Path:
    """Draws the H-V diagram and writes it (format from the extension: .png, .svg, .pdf).

    Args:
        envelope: the envelope.
        out_path: the image file.
        track: optional N × 2 array of (height m, speed m/s) drawn as the flown track.
        title_extra: appended to the title.

    Returns:
        The path written.

    Raises:
        ValueError: a track that is not N × 2.
    """
    figure = Figure(figsize=(8.5, 6.5), dpi=120)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot(1, 1, 1)
    speeds_kt, heights_ft = envelope.speeds / KT, envelope.heights / FT
    polygons, segments = boundary_geometry(envelope)
    if polygons:  # one compound path, filled once: no darker seams where cells meet
        region = Path.make_compound_path(*(Path(np.vstack([p, p[:1]]), closed=True) for p in polygons))
        axes.add_patch(PathPatch(region, facecolor=_UNSAFE_COLOUR, edgecolor="none", alpha=0.35))
    axes.add_collection(LineCollection(segments, colors="black", linewidths=1.8))
    handles: list = [
        Patch(facecolor=_UNSAFE_COLOUR, alpha=0.35, label="avoid: safe landing not proven"),
        Line2D([], [], color="black", linewidth=1.8, label="refined boundary (±2 ft / ±1 kt)"),
    ]
    status = envelope.status
    grid_speed, grid_height = np.meshgrid(speeds_kt, heights_ft)
    axes.plot(grid_speed.ravel(), grid_height.ravel(), ".", color="0.75", markersize=2, zorder=1)
    for name, marker, colour in (("unverified", "D", "#ff7f0e"), ("failed", "X", "#9467bd")):
        mask = status == name
        if np.any(mask):
            axes.plot(grid_speed[mask], grid_height[mask], marker, color=colour, markersize=7, linestyle="none",
                      markeredgecolor="black", markeredgewidth=0.6, zorder=4)  # fmt: skip
        label = "unverified (NLP safe, replay failed)" if name == "unverified" else "failed (solver did not converge)"
        handles.append(
            Line2D([], [], marker=marker, color=colour, markeredgecolor="black", linestyle="none",
                   label=f"{label}: {int(mask.sum())}")
        )  # fmt: skip
    if track is not None:
        points = np.asarray(track, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2:
            raise ValueError(f"track must be an N x 2 array of (height m, speed m/s), got shape {points.shape}")
        finite = points[np.all(np.isfinite(points), axis=1)]
        if finite.size:
            axes.plot(finite[:, 1] / KT, finite[:, 0] / FT, "-", color="#1f77b4", linewidth=2.0, zorder=5)
            axes.plot(finite[-1, 1] / KT, finite[-1, 0] / FT, "o", color="#1f77b4", markersize=7, zorder=6)
        handles.append(Line2D([], [], color="#1f77b4", linewidth=2.0, marker="o", label="flown track (now: dot)"))
    axes.set_xlim(speeds_kt[0], speeds_kt[-1])
    axes.set_ylim(heights_ft[0], heights_ft[-1])
    axes.set_xlabel("forward speed (kt)")
    axes.set_ylabel("height above ground (ft)")
    axes.grid(True, color="0.85", linewidth=0.6)
    figure.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 0.025), ncol=3, fontsize=8, frameon=False)
    airframe = envelope.metadata.get("airframe", {})
    weight_lbf = float(airframe.get("gross_weight", float("nan"))) / LBF
    altitude_ft = float(airframe.get("density_altitude", float("nan"))) / FT
    title = (
        f"H-V diagram: {envelope.airframe_name}, W = {weight_lbf:,.0f} lbf, density altitude {altitude_ft:,.0f} ft, "
        f"{_power_text(envelope.power_fraction)}"
    )
    if title_extra:
        title += f"\n{title_extra}"
    axes.set_title(title, fontsize=10)
    figure.text(
        0.01, 0.005,
        f"envelope {envelope.envelope_id} · method {envelope.metadata.get('method', '?')} · "
        f"{heights_ft.size} x {speeds_kt.size} nodes · level trim at failure",
        fontsize=7, color="0.4",
    )  # fmt: skip
    figure.tight_layout(rect=(0, 0.11, 1, 1))
    path = pathlib.Path(out_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    return path
