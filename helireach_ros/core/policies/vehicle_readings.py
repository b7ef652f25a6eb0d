"""What the helireach nodes read from a vehicle, in SI, and whether it is a plausible vehicle state.

The ROS nodes translate a vehicle's ``Odometry`` and rotor ``JointState`` into these readings
(:mod:`helireach_ros.ros.messages`); the input contract (:mod:`~helireach_ros.core.policies.input_contract`) and the
safety status (:mod:`~helireach_ros.core.policies.safety_status`) judge them without ROS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from helireach_ros.core.aircraft.model import state_from_sensors

__all__ = ["OdometryReading", "RotorReading", "StateLimits", "helicopter_state", "state_problems"]


class OdometryReading(NamedTuple):
    """What the helireach nodes read from a vehicle ``Odometry`` (SI)."""

    stamp_ns: int
    height: float
    distance: float
    forward_speed: float
    climb_rate: float


class RotorReading(NamedTuple):
    """What the helireach nodes read from a rotor ``JointState``: Ω (rad/s) and engine power (W) if given."""

    stamp_ns: int
    rotor_speed: float
    engine_power: float | None


@dataclass(frozen=True)
class StateLimits:
    """The range a plausible vehicle state lies in (anything else is rejected as a sensor error).

    Attributes:
        min_height: m (slightly negative: sensors near the ground). max_height: m.
        max_forward_speed: |v|, m/s. max_climb_rate: |climb rate|, m/s.
        min_rotor_speed: rad/s (> 0). max_rotor_speed: rad/s.
    """

    min_height: float = -1.0
    max_height: float = 5000.0
    max_forward_speed: float = 120.0
    max_climb_rate: float = 60.0
    min_rotor_speed: float = 1.0
    max_rotor_speed: float = 200.0


def state_problems(
    limits: StateLimits, odometry: OdometryReading | None = None, rotor: RotorReading | None = None
) -> list[str]:
    """Why a reading is not a plausible vehicle state (empty: it is).

    Non-finite numbers and values outside ``limits`` are problems; each is named with its value.
    """
    checks: list[tuple[str, float, float, float]] = []
    if odometry is not None:
        checks += [
            ("height", odometry.height, limits.min_height, limits.max_height),
            ("forward speed", odometry.forward_speed, -limits.max_forward_speed, limits.max_forward_speed),
            ("climb rate", odometry.climb_rate, -limits.max_climb_rate, limits.max_climb_rate),
            ("distance", odometry.distance, -1e7, 1e7),
        ]
    if rotor is not None:
        checks.append(("rotor speed", rotor.rotor_speed, limits.min_rotor_speed, limits.max_rotor_speed))
        if rotor.engine_power is not None:
            checks.append(("engine power", rotor.engine_power, 0.0, 1e8))
    problems = []
    for name, value, low, high in checks:
        if not math.isfinite(value):
            problems.append(f"{name} is {value}")
        elif not low <= value <= high:
            problems.append(f"{name} {value:.6g} outside [{low:g}, {high:g}]")
    return problems


def helicopter_state(odometry: OdometryReading, rotor_speed: float, engine_power: float = 0.0) -> np.ndarray:
    """The model state (y, v, Ω, h, z, P) from readings
    (:func:`~helireach_ros.core.aircraft.model.state_from_sensors`)."""
    return state_from_sensors(
        odometry.height, odometry.forward_speed, odometry.climb_rate, rotor_speed, odometry.distance, engine_power
    )
