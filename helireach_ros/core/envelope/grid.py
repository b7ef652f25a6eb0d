"""Grid specifications of envelope computations: ``start:stop:count`` ranges, number lists, and the file
name of one condition (weight, density altitude, power loss) of a sweep.
"""

from __future__ import annotations

import math

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.units import FT, KT, LBF

__all__ = ["condition_file_name", "parse_list", "parse_range"]


def parse_range(text: str, unit: float = 1.0, name: str = "range") -> tuple[float, ...]:
    """Parses ``start:stop:count`` (inclusive, evenly spaced) into SI values (× ``unit``).

    Raises:
        ValueError: malformed text, count < 2, or stop <= start.
    """
    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ValueError(f"{name} must be start:stop:count (e.g. 0:800:41), got {text!r}") from None
    if not (math.isfinite(start) and math.isfinite(stop)) or count < 2 or stop <= start:
        raise ValueError(f"{name} {text!r}: need finite start < stop and count >= 2")
    return tuple(float(v) for v in np.linspace(start, stop, count) * unit)


def parse_list(text: str, name: str = "list") -> list[float]:
    """Parses a comma-separated list of numbers."""
    try:
        values = [float(item) for item in text.split(",") if item.strip()]
    except ValueError:
        raise ValueError(f"{name} must be comma-separated numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name} must hold at least one finite number, got {text!r}")
    return values


def condition_file_name(airframe: Airframe, power_fraction: float) -> str:
    """``<airframe>_<weight>lb_da<altitude>ft[_hw<wind>kt]_pf<fraction>.npz``: one file per sweep combination (the
    headwind only when there is one: calm files keep their names)."""
    wind = f"_hw{airframe.headwind / KT:+.0f}kt" if airframe.headwind else ""
    return (
        f"{airframe.name}_{airframe.gross_weight / LBF:.0f}lb_da{airframe.density_altitude / FT:.0f}ft{wind}_"
        f"pf{power_fraction:g}.npz"
    )
