"""The fallback landing controls: what to fly when no converged plan is available in time.

A fallback is never called safe. In order of preference:

1. the envelope's nearest stored plan (its controls from now on; the cell's status is reported), else
2. a steady autorotation entry: the steady power-off descent controls (ẏ = v̇ = Ω̇ = 0 at Ω₀,
   :func:`~helireach_ros.core.aircraft.model.steady_autorotation`) at the current forward speed clipped to
   0…60 m/s, held for the estimated descent time h / ẏ (clipped to 1 s … the planner's longest landing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.model import steady_autorotation
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.units import FT, KT

__all__ = ["FallbackPlan", "fallback_plan"]


@dataclass(frozen=True)
class FallbackPlan:
    """Controls to fly when no converged plan is available in time (never called safe).

    Attributes:
        kind: ``"envelope_plan"`` or ``"autorotation_entry"``.
        description: for people.
        time_to_land: s (the stored plan's, or the estimated descent time).
        control_times, control_values, control_interpolation: the control function.
        source_status: the status of the envelope cell it comes from (``"none"`` for the entry).
    """

    kind: str
    description: str
    time_to_land: float
    control_times: np.ndarray
    control_values: np.ndarray
    control_interpolation: str
    source_status: str = "none"


def fallback_plan(
    state: np.ndarray, airframe: Airframe, settings: PlannerSettings, envelope: Any | None = None
) -> FallbackPlan:
    """The best available controls without a converged solve (see the module docstring).

    Args:
        state: (y, v, Ω, h, z, P) in SI.
        airframe: the planner's airframe.
        settings: the planner's settings (for the longest landing time).
        envelope: a loaded :class:`~helireach_ros.core.envelope.data.Envelope` matching the planner, or None.
    """
    stored = envelope.nearest_plan_to(state) if envelope is not None else None
    if stored is not None:
        return FallbackPlan(
            "envelope_plan",
            f"envelope plan of {stored.height / FT:.0f} ft, {stored.speed / KT:.0f} kt ({stored.status})",
            stored.time_to_land,
            stored.control_times,
            stored.control_values,
            stored.control_interpolation,
            stored.status,
        )
    speed = float(np.clip(state[StateIndex.FORWARD_SPEED], 0.0, 60.0))
    descent_rate, thrust_coefficient, pitch = steady_autorotation(airframe, speed)
    duration = float(np.clip(state[StateIndex.HEIGHT] / max(descent_rate, 1.0), 1.0, settings.max_time_to_land))
    return FallbackPlan(
        "autorotation_entry",
        f"steady autorotation entry at {speed / KT:.0f} kt (C_T {thrust_coefficient:.4f}, pitch "
        f"{math.degrees(pitch):.1f} deg)",
        duration,
        np.array([0.0, duration]),
        np.array([[thrust_coefficient], [pitch]]),
        "zero_order_hold",
    )
