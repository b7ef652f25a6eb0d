"""Pilot-facing quantities for the cockpit page (pure functions, SI in, plain numbers out; no ROS).

* **Thrust, % of weight** (the collective, as an estimate, not a lever position): T = ρ A (Ω R)² C_T, shown as
  100 T / W. :func:`thrust_scale` gives 100 ρ A (Ω₀ R)² / W, so the page computes
  ``thrust_pct = scale · C_T · (Ω / Ω₀)²`` with the measured rotor speed Ω (Ω₀ when none is fresh, and it says so).
  ρ and W are the plan's (its ``density_altitude_m`` and ``gross_weight_n``) when the plan status carries them,
  else the airframe file's.
* **Pitch attitude, nose up positive**: the model's θ is positive nose down; the page shows −θ in degrees.
* **Margins along the axes** (:func:`axis_margins`): feet above/below the H-V boundary at the current speed, and
  knots faster/slower than it at the current height.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["axis_margins", "line_margin", "thrust_scale"]


def thrust_scale(
    air_density: float, disk_area: float, rotor_radius: float, nominal_rotor_speed: float, weight: float
) -> float | None:
    """100 ρ A (Ω₀ R)² / W: thrust in % of the weight per unit C_T at Ω₀ (None if any input is not positive)."""
    values = (air_density, disk_area, rotor_radius, nominal_rotor_speed, weight)
    if not all(isinstance(v, int | float) and math.isfinite(v) and v > 0 for v in values):
        return None
    return 100.0 * air_density * disk_area * (nominal_rotor_speed * rotor_radius) ** 2 / weight


def line_margin(edges: np.ndarray, cell_safe: np.ndarray, x: float) -> dict[str, Any] | None:
    """Along one grid line: whether ``x`` is in a safe cell and its offset from the nearest change of status.

    Args:
        edges: ascending cell edges (n + 1). cell_safe: n booleans. x: the position on the line.

    Returns:
        ``{"safe", "offset"}``: offset = x − the nearest position where the status changes (> 0: the change
        is below/slower); beyond the last edge counts as not safe (outside the grid), the first edge (0 ft,
        0 kt) is not a boundary. ``offset`` None: no change on the line. None if x is outside the edges.
    """
    if not (math.isfinite(x) and edges[0] <= x <= edges[-1]):
        return None
    cell = min(int(np.searchsorted(edges, x, side="right")) - 1, cell_safe.size - 1)
    changes = [edges[i] for i in range(1, cell_safe.size) if cell_safe[i - 1] != cell_safe[i]]
    if cell_safe[-1]:
        changes.append(edges[-1])  # outside the grid is never safe
    offset = None
    if changes:
        nearest = min(changes, key=lambda position: abs(x - position))
        offset = float(x - nearest)
    return {"safe": bool(cell_safe[cell]), "offset": offset}


def axis_margins(
    heights: np.ndarray, speeds: np.ndarray, safe_nodes: np.ndarray, height: float, speed: float
) -> dict[str, Any] | None:
    """Feet above/below the boundary at this speed and knots from it at this height (SI in, SI offsets out).

    A cell counts as safe only when all four of its nodes are (the envelope's node rule); a state exactly on a
    grid line is judged by the cells on one side, which can only shorten a safe margin (never optimistic).

    Returns:
        ``{"vertical": line_margin over heights, "horizontal": line_margin over speeds}`` (m and m/s offsets),
        or None when the state is outside the grid or not finite.
    """
    heights, speeds = np.asarray(heights, dtype=float), np.asarray(speeds, dtype=float)
    safe = np.asarray(safe_nodes, dtype=bool)
    if not (math.isfinite(height) and math.isfinite(speed)):
        return None
    if not (heights[0] <= height <= heights[-1] and speeds[0] <= speed <= speeds[-1]):
        return None
    cells = safe[:-1, :-1] & safe[1:, :-1] & safe[:-1, 1:] & safe[1:, 1:]
    column = min(int(np.searchsorted(speeds, speed, side="right")) - 1, speeds.size - 2)
    row = min(int(np.searchsorted(heights, height, side="right")) - 1, heights.size - 2)
    return {
        "vertical": line_margin(heights, cells[:, column], height),
        "horizontal": line_margin(speeds, cells[row, :], speed),
    }
