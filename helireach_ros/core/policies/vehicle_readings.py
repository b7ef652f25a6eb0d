"""What the helireach nodes read from a vehicle, in SI, and whether it is a plausible vehicle state.

The ROS nodes translate a vehicle's ``Odometry`` and rotor ``JointState`` into these readings
(:mod:`helireach_ros.ros.messages`); the input contract (:mod:`~helireach_ros.core.policies.input_contract`) and the
safety status (:mod:`~helireach_ros.core.policies.safety_status`) judge them without ROS.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.model import clip_rotor_speed_noise, state_from_sensors
from helireach_ros.core.estimation.weight_tracking import WeightSample

__all__ = [
    "CurrentState",
    "LatestReadings",
    "OdometryReading",
    "RotorReading",
    "RotorSource",
    "StateLimits",
    "helicopter_state",
    "state_problems",
]

ROTOR_NOISE_TOLERANCE = 0.01  # fraction of Ω₀ a measured rotor speed may lie outside its limits as noise


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


class RotorSource(StrEnum):
    """Where a planned-from state's rotor speed came from (the plan status's ``rotor_speed_source``)."""

    MEASURED = "measured"
    ASSUMED_NOMINAL = "assumed_nominal"  # no fresh rotor reading: Ω₀ (re-plans and live evaluations are skipped)


class CurrentState(NamedTuple):
    """The state to plan from now: the model state (y, v, Ω, h, z, P; SI), its stamp, the vehicle frame, the rotor
    speed's source."""

    state: np.ndarray
    stamp_ns: int
    frame: str
    rotor_source: RotorSource


class LatestReadings:
    """The latest plausible odometry and rotor readings with their receive times (thread-safe), and the state they
    make now.

    Freshness is judged by receive time, as every check of the planner's (a replayed log's stamps are old).

    Args:
        airframe: Ω₀ and the rotor limits.
        max_age_ns: older readings are not planned from.
        default_frame: the vehicle frame of a reading without one.
        limits: what a plausible reading is (anything else is ignored: the monitor reports it).
    """

    def __init__(
        self, airframe: Airframe, max_age_ns: int, default_frame: str, limits: StateLimits | None = None
    ) -> None:
        self.airframe = airframe
        self.max_age_ns = max_age_ns
        self.default_frame = default_frame
        self.limits = limits or StateLimits()
        self._lock = threading.Lock()
        self._odometry: tuple[OdometryReading, int, str] | None = None
        self._rotor: tuple[RotorReading, int] | None = None

    def add_odometry(self, reading: OdometryReading, received_ns: int, frame: str) -> bool:
        """Keeps a plausible reading (True); an implausible one is ignored (False)."""
        if state_problems(self.limits, odometry=reading):
            return False
        with self._lock:
            self._odometry = (reading, received_ns, frame or self.default_frame)
        return True

    def add_rotor(self, reading: RotorReading, received_ns: int) -> WeightSample | None:
        """Keeps a plausible reading; returns the steady-flight sample it makes with a fresh odometry (for the weight
        estimate), or None."""
        if state_problems(self.limits, rotor=reading):
            return None
        with self._lock:
            self._rotor = (reading, received_ns)
            odometry = self._odometry
        if odometry is None or received_ns - odometry[1] > self.max_age_ns:
            return None
        state = odometry[0]
        return WeightSample(
            received_ns, state.forward_speed, state.climb_rate, reading.rotor_speed, reading.engine_power
        )

    def current(self, now_ns: int, *, zero_power: bool) -> CurrentState | None:
        """The state to plan from now, or None without a fresh odometry.

        Without a fresh rotor reading Ω₀ is assumed (:attr:`RotorSource.ASSUMED_NOMINAL`). Ω within 1 % of Ω₀
        outside the rotor limits is clipped to them (sensor noise); farther out it is kept. P is the measured power
        (0 if not measured), or 0 with ``zero_power`` (a plan after a total power loss).
        """
        with self._lock:
            odometry, rotor = self._odometry, self._rotor
        if odometry is None or now_ns - odometry[1] > self.max_age_ns:
            return None
        reading, _, frame = odometry
        power: float | None = None
        if rotor is not None and now_ns - rotor[1] <= self.max_age_ns:
            rotor_speed, source, power = rotor[0].rotor_speed, RotorSource.MEASURED, rotor[0].engine_power
        else:
            rotor_speed, source = self.airframe.nominal_rotor_speed, RotorSource.ASSUMED_NOMINAL
        if power is None or zero_power:
            power = 0.0
        rotor_speed = clip_rotor_speed_noise(self.airframe, rotor_speed, ROTOR_NOISE_TOLERANCE)
        return CurrentState(helicopter_state(reading, rotor_speed, power), reading.stamp_ns, frame, source)
