"""Unit conversion to SI for configuration files and human-facing text.

The numerical core works in SI (REP-103); feet, knots and pounds appear only in configuration
files (converted here, with the unit named next to every number) and in text meant for people.
"""

from __future__ import annotations

import math

__all__ = [
    "FT",
    "FT_PER_S",
    "KT",
    "LBF",
    "UnitError",
    "convert_to_si",
    "dimension_of",
]

FT = 0.3048
"""One foot in metres."""
KT = 1852.0 / 3600.0
"""One knot in metres per second."""
FT_PER_S = FT
"""One foot per second in metres per second."""
LBF = 4.4482216152605
"""One pound-force in newtons."""

# unit -> (dimension, factor to SI)
_UNITS: dict[str, tuple[str, float]] = {
    "-": ("dimensionless", 1.0),
    "1": ("dimensionless", 1.0),
    "m": ("length", 1.0),
    "ft": ("length", FT),
    "in": ("length", 0.0254),
    "m/s": ("speed", 1.0),
    "ft/s": ("speed", FT_PER_S),
    "kt": ("speed", KT),
    "km/h": ("speed", 1.0 / 3.6),
    "m/s^2": ("acceleration", 1.0),
    "ft/s^2": ("acceleration", FT),
    "N": ("force", 1.0),
    "lbf": ("force", LBF),
    "kg": ("mass", 1.0),
    "slug": ("mass", LBF / FT),
    "m^2": ("area", 1.0),
    "ft^2": ("area", FT**2),
    "kg/m^3": ("density", 1.0),
    "slug/ft^3": ("density", (LBF / FT) / FT**3),
    "kg*m^2": ("inertia", 1.0),
    "slug*ft^2": ("inertia", (LBF / FT) * FT**2),
    "rad/s": ("angular_speed", 1.0),
    "rpm": ("angular_speed", 2.0 * math.pi / 60.0),
    "deg/s": ("angular_speed", math.pi / 180.0),
    "rad": ("angle", 1.0),
    "deg": ("angle", math.pi / 180.0),
    "s": ("time", 1.0),
    "W": ("power", 1.0),
    "kW": ("power", 1000.0),
    "hp": ("power", 745.69987158227),
}


class UnitError(ValueError):
    """A unit that is unknown or of the wrong dimension."""


def dimension_of(unit: str) -> str:
    """Returns the physical dimension of a unit name (e.g. ``"ft"`` → ``"length"``).

    Raises:
        UnitError: if the unit is not known.
    """
    try:
        return _UNITS[unit][0]
    except KeyError:
        known = ", ".join(sorted(_UNITS))
        raise UnitError(f"unknown unit {unit!r} (known: {known})") from None


def convert_to_si(value: float, unit: str, dimension: str) -> float:
    """Converts ``value`` in ``unit`` to SI, checking that the unit measures ``dimension``.

    Args:
        value: the number as written.
        unit: its unit, e.g. ``"kt"``.
        dimension: the dimension the caller expects, e.g. ``"speed"``.

    Returns:
        The value in the SI unit of that dimension.

    Raises:
        UnitError: if the unit is unknown or measures another dimension.
    """
    found = dimension_of(unit)
    if found != dimension:
        allowed = ", ".join(sorted(u for u, (d, _) in _UNITS.items() if d == dimension))
        raise UnitError(f"unit {unit!r} measures {found}, expected {dimension} (one of: {allowed})")
    return float(value) * _UNITS[unit][1]
