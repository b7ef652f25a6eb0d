"""What the closed loop can observe before a failure: today's gross weight, from the power of steady flight.

Weight is known to a few per cent at best, and a plan made for the wrong weight lands outside the limits
(5 % heavier than the airframe file: touchdown at 7.3 kt; ``test/test_closed_loop.py``). Before the failure the
aircraft flies steadily, and in steady flight at Ω₀ the engine supplies exactly the rotor power of the trim
(:func:`~helireach_ros.core.aircraft.model.trim_flight`):

.. math:: P(W) = \\frac{\\rho A (\\Omega_0 R)^3}{\\eta}\\Big(\\frac{\\sigma c_d}{8} + C_T(W)\\,\\lambda(W)\\Big),

which rises monotonically with W (the induced part grows as W^{3/2}). Given the measured engine power at the
measured speed and climb rate, the weight is the root of P(W) = P_measured, found by bisection between
``bounds`` × the file's weight. The estimate carries every other model error that changes the power (drag
areas, c_d, η): it is the weight that makes the model fly as the aircraft does, which is what the planner
needs, not a scale reading. With a power reading δ off, the weight is off by about δ / (d ln P / d ln W), which
is 0.9–1.1 from 40 to 115 kt for the UH-60A class: a 2 % power error is a ~2 % weight error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.model import trim_flight

__all__ = ["WeightEstimate", "estimate_gross_weight"]

_BISECTION_STEPS = 60


@dataclass(frozen=True)
class WeightEstimate:
    """A gross weight that makes the model's steady-flight power equal the measured power.

    Attributes:
        gross_weight: N.
        relative_change: gross_weight / the airframe file's − 1.
        measured_power: W, the engine power it matches.
        file_weight_power: W, the model's power for that flight at the file's weight.
    """

    gross_weight: float
    relative_change: float
    measured_power: float
    file_weight_power: float


def _trim_power(airframe: Airframe, weight: float, forward_speed: float, climb_rate: float) -> float:
    try:
        return trim_flight(airframe.with_conditions(gross_weight=weight), forward_speed, climb_rate).power
    except ValueError:  # beyond stall or autorotating: no powered trim at this weight
        return math.inf if weight > airframe.gross_weight else -math.inf


def estimate_gross_weight(
    airframe: Airframe,
    forward_speed: float,
    climb_rate: float,
    engine_power: float,
    bounds: tuple[float, float] = (0.7, 1.3),
) -> WeightEstimate:
    """The gross weight whose steady-flight power at this speed and climb rate is the measured engine power.

    Args:
        airframe: the model (its gross weight is the prior).
        forward_speed: m/s, climb_rate: m/s positive up, measured in steady flight at Ω₀.
        engine_power: W, measured then.
        bounds: the weights searched, as fractions of the file's.

    Raises:
        ValueError: non-finite or negative inputs, or no weight within ``bounds`` explains the power (the
            flight was not steady, the power reading is wrong, or the model is far off).
    """
    values = (forward_speed, climb_rate, engine_power)
    if not all(math.isfinite(value) for value in values) or forward_speed < 0.0 or engine_power <= 0.0:
        raise ValueError(f"weight estimate needs finite speed >= 0, climb rate and power > 0, got {values!r}")
    low, high = (fraction * airframe.gross_weight for fraction in bounds)
    power_low = _trim_power(airframe, low, forward_speed, climb_rate)
    power_high = _trim_power(airframe, high, forward_speed, climb_rate)
    if not power_low <= engine_power <= power_high:
        raise ValueError(
            f"{engine_power / 1e3:.0f} kW is outside what {bounds[0]:g}-{bounds[1]:g} x the file's weight needs "
            f"in that flight ({power_low / 1e3:.0f}-{power_high / 1e3:.0f} kW)"
        )
    for _ in range(_BISECTION_STEPS):
        middle = 0.5 * (low + high)
        if _trim_power(airframe, middle, forward_speed, climb_rate) < engine_power:
            low = middle
        else:
            high = middle
    weight = 0.5 * (low + high)
    return WeightEstimate(
        gross_weight=weight,
        relative_change=weight / airframe.gross_weight - 1.0,
        measured_power=engine_power,
        file_weight_power=_trim_power(airframe, airframe.gross_weight, forward_speed, climb_rate),
    )
