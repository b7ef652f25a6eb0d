"""Airframe plausibility: derived rotor figures compared with broad ranges for helicopters.

The loader (:mod:`helireach_ros.core.aircraft.airframe`) checks every number against a *physical* range, which a
plausible wrong unit passes: a UH-60A rotor radius of 26.83 *m* (the file's 26.83 ft read as metres) is a
legal length, but it gives a 720 m/s tip speed and a disk loading of 29 N/m². The figures below combine
several numbers, so such a slip shows up in at least one of them. They are **warnings, never errors**: an
unusual but real aircraft must still load.

Figures (SI, hover at the file's weight and density altitude, ρ from the ISA):

- tip speed V_tip = Ω₀ R;
- disk loading DL = W / (π R²);
- rotor solidity σ_R (as given);
- blade loading C_T/σ with C_T = W / (ρ π R² V_tip²);
- hover power loading W / P_shaft, with the shaft power from momentum theory plus blade-element profile
  power, P_shaft = (κ W √(DL / (2ρ)) + ρ π R² V_tip³ σ c_d / 8) / η, induced-power factor κ = 1.15.
  This stands in for "trim power against installed power": the airframe files carry no installed power.

Each range says where it comes from (:attr:`PlausibilityRange.source`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from helireach_ros.core.aircraft.airframe import Airframe

__all__ = [
    "INDUCED_POWER_FACTOR",
    "PLAUSIBILITY_RANGES",
    "AirframePlausibilityWarning",
    "PlausibilityRange",
    "implausible_figures",
    "warn_if_implausible",
]

INDUCED_POWER_FACTOR = 1.15
"""κ: induced power over ideal momentum-theory power in hover (Leishman, 2nd ed., §2.4: typically 1.15)."""

_LEISHMAN = "Leishman, Principles of Helicopter Aerodynamics (2nd ed., 2006)"


class AirframePlausibilityWarning(UserWarning):
    """An airframe's derived figure lies outside the broad range of helicopters (likely a wrong unit)."""


@dataclass(frozen=True)
class PlausibilityRange:
    """A derived figure of an airframe and the broad range real helicopters span.

    Attributes:
        key: the figure's name, e.g. ``"tip_speed"``.
        description: what it is, with the airframe keys it is made of.
        unit: SI unit of the value and the range.
        low: lowest plausible value.
        high: highest plausible value.
        source: where the range comes from.
        value: computes the figure from an airframe.
    """

    key: str
    description: str
    unit: str
    low: float
    high: float
    source: str
    value: Callable[[Airframe], float]


def _tip_speed(airframe: Airframe) -> float:
    return airframe.nominal_rotor_speed * airframe.rotor_radius


def _disk_loading(airframe: Airframe) -> float:
    return airframe.gross_weight / airframe.disk_area


def _blade_loading(airframe: Airframe) -> float:
    thrust_coefficient = airframe.gross_weight / (airframe.air_density * airframe.disk_area * _tip_speed(airframe) ** 2)
    return thrust_coefficient / airframe.rotor_solidity


def _hover_power_loading(airframe: Airframe) -> float:
    density = airframe.air_density
    induced = INDUCED_POWER_FACTOR * airframe.gross_weight * math.sqrt(_disk_loading(airframe) / (2.0 * density))
    profile = (
        density * airframe.disk_area * _tip_speed(airframe) ** 3 * airframe.rotor_solidity
        * airframe.blade_drag_coefficient / 8.0
    )  # fmt: skip
    return airframe.gross_weight / ((induced + profile) / airframe.rotor_power_efficiency)


PLAUSIBILITY_RANGES: tuple[PlausibilityRange, ...] = (
    PlausibilityRange(
        "tip_speed", "main-rotor tip speed nominal_rotor_speed x rotor_radius", "m/s", 150.0, 250.0,
        f"{_LEISHMAN}, Ch. 1 and 6: tip speeds of about 180-230 m/s (compressibility above, stall and stored "
        "energy below); widened to 150-250 m/s",
        _tip_speed,
    ),
    PlausibilityRange(
        "disk_loading", "disk loading gross_weight / (pi rotor_radius^2)", "N/m^2", 50.0, 800.0,
        f"{_LEISHMAN}, Ch. 1: helicopters about 100-500 N/m^2 (2-10 lb/ft^2), heavy lifters to about "
        "700 N/m^2; widened to 50-800 N/m^2",
        _disk_loading,
    ),
    PlausibilityRange(
        "rotor_solidity", "rotor_solidity N_b c / (pi R)", "-", 0.03, 0.15,
        f"{_LEISHMAN}, Ch. 6: solidity about 0.05-0.12; widened to 0.03-0.15 (two-bladed teetering rotors "
        "sit near 0.04)",
        lambda airframe: airframe.rotor_solidity,
    ),
    PlausibilityRange(
        "hover_blade_loading", "hover blade loading C_T/sigma from gross_weight, rotor_radius, nominal_rotor_speed, "
        "rotor_solidity, density_altitude", "-", 0.03, 0.13,
        f"{_LEISHMAN}, Ch. 6 and 7: design C_T/sigma about 0.06-0.10, stall near 0.12-0.15; widened to 0.03-0.13",
        _blade_loading,
    ),
    PlausibilityRange(
        "hover_power_loading", "hover power loading gross_weight / shaft power (momentum theory + profile power, "
        "rotor_power_efficiency)", "N/W", 0.018, 0.12,
        "assumed: broad envelope of civil/military helicopters, 3-20 lb/hp (0.018-0.12 N/W) in hover "
        f"(cf. {_LEISHMAN}, Ch. 1, power loading against disk loading)",
        _hover_power_loading,
    ),
)  # fmt: skip
"""The figures checked by :func:`implausible_figures`, each with its range and source."""


def implausible_figures(airframe: Airframe) -> list[str]:
    """Messages for each derived figure of ``airframe`` outside :data:`PLAUSIBILITY_RANGES` (empty: plausible).

    A figure that cannot be computed (non-finite) counts as implausible.
    """
    messages = []
    for check in PLAUSIBILITY_RANGES:
        value = check.value(airframe)
        if not (math.isfinite(value) and check.low <= value <= check.high):
            messages.append(
                f"{check.key} = {value:.4g} {check.unit} is outside the plausible range for helicopters "
                f"[{check.low:g}, {check.high:g}] {check.unit} ({check.description}; range: {check.source}); "
                "check the units of the airframe file"
            )
    return messages


def warn_if_implausible(airframe: Airframe, where: str = "") -> list[str]:
    """Issues one :class:`AirframePlausibilityWarning` per implausible figure; returns the messages.

    Args:
        airframe: the parsed airframe.
        where: a prefix for the messages (the file name).
    """
    messages = [f"{where}airframe {airframe.name!r}: {message}" for message in implausible_figures(airframe)]
    for message in messages:
        warnings.warn(message, AirframePlausibilityWarning, stacklevel=3)
    return messages
