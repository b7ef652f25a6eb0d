"""Airframes and landing limits: immutable SI dataclasses loaded from validated YAML.

Every number in an airframe file is written as ``{value, unit, source}``; the loader converts it
to SI, checks its dimension and physical range, and rejects unknown or missing keys with a message
that names the key and the file. Gross weight and density altitude can be overridden for sweeps.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from helireach_ros.core.aircraft.inflow import PAPER_ROTOR_MODEL, InflowModel, RotorModel
from helireach_ros.core.aircraft.plausibility import warn_if_implausible
from helireach_ros.core.resources import config_path
from helireach_ros.core.units import UnitError, convert_to_si

__all__ = [
    "ROTOR_MODEL_CHOICES",
    "Airframe",
    "ConfigError",
    "FlyabilityLimits",
    "LandingLimits",
    "MarginScales",
    "isa_density",
    "load_airframe",
    "parse_airframe",
]

MAX_WIND = 30.0  # m/s (58 kt): a wind the planner is asked to plan in, at most

ROTOR_MODEL_CHOICES = ("airframe", "paper", "momentum")
"""Names a user may choose a rotor model by (:meth:`Airframe.with_rotor_model_choice`)."""

SEA_LEVEL_DENSITY = 1.225
"""ISA sea-level air density, kg/m³."""


class ConfigError(ValueError):
    """A configuration file that is missing, malformed, or holds non-physical values."""


@dataclass(frozen=True)
class LandingLimits:
    """What counts as a safe touchdown, and the limits the landing must respect on the way.

    Attributes:
        max_descent_rate: |y| at touchdown, m/s (paper: 8 ft/s).
        max_forward_speed: |v| at touchdown, m/s (paper: 6 kt).
        height_tolerance: |h| that counts as "on the ground", m (paper: 1 ft).
        ground_clearance: the path must stay above ``h = −ground_clearance``, m (the paper has none).
        max_thrust_coefficient_over_solidity: blade stall, C_T ≤ this × σ (paper: 0.15).
        max_pitch_angle: |θ| ≤ this, rad (paper: 40°).
        min_rotor_speed_ratio: Ω ≥ this × Ω₀ along the path (the paper has none).
        max_rotor_speed_ratio: Ω ≤ this × Ω₀ along the path (the paper has none).
    """

    max_descent_rate: float
    max_forward_speed: float
    height_tolerance: float
    ground_clearance: float
    max_thrust_coefficient_over_solidity: float
    max_pitch_angle: float
    min_rotor_speed_ratio: float
    max_rotor_speed_ratio: float


@dataclass(frozen=True)
class FlyabilityLimits:
    """What a real helicopter can fly, beyond the paper's point-mass limits (the ``flyable`` plans respect them).

    Pitch θ is positive nose down (the model's convention); the limits are magnitudes.

    Attributes:
        max_nose_up_pitch: the flare attitude limit, θ ≥ −this along the path, rad.
        max_nose_down_pitch: θ ≤ this along the path, rad.
        touchdown_max_nose_up_pitch: at ground contact θ ≥ −this (tail strike), rad.
        touchdown_max_nose_down_pitch: at ground contact θ ≤ this (skid toes / nose gear first), rad.
        max_pitch_rate: |dθ/dt| ≤ this, rad/s.
        collective_full_travel_time: the fastest the collective moves through its whole range (C_T from 0 to
            its stall limit), s: |dC_T/dt| ≤ C_T,max / this.
        commit_height: below this height the plan may not climb again (h non-increasing until touchdown: no
            ground skims, no zooms back up from near the ground), m.
        touchdown_min_rotor_speed_ratio: below the commit height (the final flare and cushion) Ω may droop to
            this × Ω₀ instead of ``limits.min_rotor_speed_ratio``: the cushion trades rotor speed for thrust.
    """

    max_nose_up_pitch: float = math.radians(25.0)
    max_nose_down_pitch: float = math.radians(25.0)
    touchdown_max_nose_up_pitch: float = math.radians(12.0)
    touchdown_max_nose_down_pitch: float = math.radians(5.0)
    max_pitch_rate: float = math.radians(20.0)
    collective_full_travel_time: float = 1.0
    commit_height: float = 20.0 * 0.3048
    touchdown_min_rotor_speed_ratio: float = 0.80


@dataclass(frozen=True)
class MarginScales:
    """The units of the reach-avoid value's margins (``objective: reach_avoid``): how far from its limit a quantity
    must be for a margin of −1. They say how the planner weighs one limit against another (a per cent of rotor speed
    against a foot per second at touchdown), not what the aircraft is: the same states are safe whatever they are.

    The touchdown terms keep J's units (the limits: −1 is a touchdown at zero speeds).

    Attributes:
        rotor_floor: fraction of Ω₀ above the rotor-speed floor the NLP holds that is a margin of −1.
        rotor_ceiling: fraction of Ω₀ below the rotor-speed ceiling the NLP holds that is a margin of −1.
        touchdown_pitch: rad inside the touchdown attitude window's nearer edge that is a margin of −1.
    """

    rotor_floor: float = 0.15
    rotor_ceiling: float = 0.15
    touchdown_pitch: float = math.radians(8.5)


@dataclass(frozen=True)
class Airframe:
    """A helicopter's parameters for the paper's six-state model, all SI.

    Attributes:
        name: identifier, e.g. ``"uh60a_class"``.
        gross_weight: W, N.
        rotor_radius: R, m.
        rotor_solidity: σ_R = N_b c / (π R).
        nominal_rotor_speed: Ω₀, rad/s.
        blade_drag_coefficient: c_d, blade profile drag coefficient.
        rotor_inertia: I_R, kg m².
        horizontal_drag_area: f_ez, m² (drag of forward motion).
        vertical_drag_area: f_eh, m² (drag of vertical motion).
        rotor_power_efficiency: η, main-rotor power / engine shaft power.
        engine_time_constant: κ, s.
        density_altitude: m; sets the air density through the ISA.
        gravity: g, m/s².
        limits: the landing and path limits.
        flyability: the attitude, rate and touchdown-attitude limits of flyable plans (the YAML's optional
            ``flyability`` section; the :class:`FlyabilityLimits` defaults, all assumed, where it is missing).
        rotor_model: the rotor's aerodynamics (inflow, ground effect, induced and profile power; the YAML's
            ``rotor_model`` section; where it is missing, the paper's rotor, which the file was written for).
        margin_scales: the units of the reach-avoid value's margins (the YAML's optional ``margin_scales``
            section; the :class:`MarginScales` defaults where it is missing).
        paper_reproduction: ``(section.key, SI value)`` pairs of the YAML's optional ``paper_reproduction``
            section: the numbers the paper's reproduction (:meth:`paper_model`) uses where this file's own differ.
        headwind: m/s, a steady wind along the track, positive against the direction of flight (a tailwind is
            negative); a condition of the day like the density altitude (:meth:`with_conditions`). The model's
            forward speed v is the airspeed (the rotor and the fuselage see the air); the distance flown and the
            touchdown speed are over the ground, v − headwind. Uniform with height (no boundary layer yet).
        sources: where each number came from (not part of equality or the hash).
    """

    name: str
    gross_weight: float
    rotor_radius: float
    rotor_solidity: float
    nominal_rotor_speed: float
    blade_drag_coefficient: float
    rotor_inertia: float
    horizontal_drag_area: float
    vertical_drag_area: float
    rotor_power_efficiency: float
    engine_time_constant: float
    density_altitude: float
    gravity: float
    limits: LandingLimits
    flyability: FlyabilityLimits = FlyabilityLimits()
    rotor_model: RotorModel = PAPER_ROTOR_MODEL
    margin_scales: MarginScales = MarginScales()
    paper_reproduction: tuple[tuple[str, float], ...] = ()
    headwind: float = 0.0
    sources: tuple[tuple[str, str], ...] = field(default=(), compare=False, repr=False)

    @property
    def mass(self) -> float:
        """m = W / g, kg."""
        return self.gross_weight / self.gravity

    @property
    def air_density(self) -> float:
        """ρ at the density altitude (ISA), kg/m³."""
        return isa_density(self.density_altitude)

    @property
    def disk_area(self) -> float:
        """π R², m²."""
        return math.pi * self.rotor_radius**2

    @property
    def max_thrust_coefficient(self) -> float:
        """The stall limit on C_T."""
        return self.limits.max_thrust_coefficient_over_solidity * self.rotor_solidity

    @property
    def max_thrust_coefficient_rate(self) -> float:
        """|dC_T/dt| limit of flyable plans, 1/s: the whole collective range in ``collective_full_travel_time``."""
        return self.max_thrust_coefficient / self.flyability.collective_full_travel_time

    def with_conditions(
        self, gross_weight: float | None = None, density_altitude: float | None = None, headwind: float | None = None
    ) -> Airframe:
        """Returns a copy at another gross weight (N), density altitude (m) and/or headwind (m/s)."""
        changes: dict[str, Any] = {}
        if headwind is not None:
            _check_range("headwind", headwind, -MAX_WIND, MAX_WIND, "m/s")
            changes["headwind"] = float(headwind)
        if gross_weight is not None:
            _check_range("gross_weight", gross_weight, 1.0, 1e7, "N")
            changes["gross_weight"] = float(gross_weight)
        if density_altitude is not None:
            _check_range("density_altitude", density_altitude, -1000.0, 9000.0, "m")
            changes["density_altitude"] = float(density_altitude)
        return dataclasses.replace(self, **changes)

    def with_rotor_model(self, rotor_model: RotorModel) -> Airframe:
        """Returns a copy with another rotor model (e.g. :meth:`paper_model` for the paper's)."""
        return dataclasses.replace(self, rotor_model=rotor_model)

    def paper_rotor(self) -> Airframe:
        """This airframe with the paper's rotor model (hover inflow, no ground effect), its other numbers kept."""
        hub_height = self.rotor_model.hub_height
        return self.with_rotor_model(dataclasses.replace(PAPER_ROTOR_MODEL, hub_height=hub_height))

    def paper_model(self) -> Airframe:
        """The paper's reproduction (the ``paper`` method's airframe): the paper's rotor, and the file's
        ``paper_reproduction`` numbers where they differ from its own (e.g. the paper's 6 kt touchdown speed)."""
        changes: dict[str, Any] = {
            key.split(".", 1)[1]: value for key, value in self.paper_reproduction if key.startswith("parameters.")
        }
        limits = {key.split(".", 1)[1]: value for key, value in self.paper_reproduction if key.startswith("limits.")}
        changes.update(limits=dataclasses.replace(self.limits, **limits), paper_reproduction=())
        reproduction = dataclasses.replace(self, **changes)
        return reproduction.paper_rotor()

    def with_rotor_model_choice(self, choice: str) -> Airframe:
        """The airframe with the rotor model a user chose by name (:data:`ROTOR_MODEL_CHOICES`): ``airframe`` (its
        file's), ``paper`` (the paper's rotor) or ``momentum`` (momentum inflow, with ground effect where the file
        gives the hub height, and the file's factors).

        Raises:
            ConfigError: an unknown choice.
        """
        if choice == "airframe":
            return self
        if choice == "paper":
            return self.paper_rotor()
        if choice == "momentum":
            model = self.rotor_model
            return self.with_rotor_model(
                dataclasses.replace(model, inflow=InflowModel.MOMENTUM, ground_effect=model.hub_height is not None)
            )
        raise ConfigError(f"rotor model must be one of {', '.join(ROTOR_MODEL_CHOICES)}, got {choice!r}")

    def as_dict(self) -> dict[str, Any]:
        """All parameters in SI (plus the derived air density and mass), JSON-serialisable.

        The rotor model is left out when it is the paper's, so an airframe written before the rotor model existed
        keeps its digest (and the envelopes computed for it stay valid).
        """
        data = dataclasses.asdict(self)
        data.pop("sources")
        if not self.paper_reproduction:  # as before the section existed: the same digest
            data.pop("paper_reproduction")
        if self.rotor_model.is_paper:
            data.pop("rotor_model")
        if self.margin_scales == MarginScales():  # as before the section existed: the same digest
            data.pop("margin_scales")
        if self.headwind == 0.0:  # calm, as before wind existed: the same digest
            data.pop("headwind")
        data["air_density"] = self.air_density
        data["mass"] = self.mass
        return data

    def digest(self) -> str:
        """A short hash of the parameters (not the sources): equal airframes, equal digests."""
        canonical = json.dumps(self.as_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(canonical.encode()).hexdigest()[:16]


def isa_density(density_altitude: float) -> float:
    """Air density at a density altitude in the International Standard Atmosphere (troposphere).

    .. math:: \\rho = \\rho_0 (1 - L h / T_0)^{g M / (R L) - 1}

    Args:
        density_altitude: m.

    Returns:
        kg/m³.
    """
    lapse_rate, sea_level_temperature, exponent = 0.0065, 288.15, 4.2558797
    return SEA_LEVEL_DENSITY * (1.0 - lapse_rate * density_altitude / sea_level_temperature) ** exponent


# key -> (dimension, minimum, maximum) in SI; the ranges reject typos and wrong units, not design choices.
_PARAMETER_SCHEMA: dict[str, tuple[str, float, float]] = {
    "gross_weight": ("force", 100.0, 1e6),
    "rotor_radius": ("length", 0.5, 30.0),
    "rotor_solidity": ("dimensionless", 0.01, 0.3),
    "nominal_rotor_speed": ("angular_speed", 5.0, 200.0),
    "blade_drag_coefficient": ("dimensionless", 0.001, 0.05),
    "rotor_inertia": ("inertia", 1.0, 1e6),
    "horizontal_drag_area": ("area", 0.01, 50.0),
    "vertical_drag_area": ("area", 0.01, 500.0),
    "rotor_power_efficiency": ("dimensionless", 0.3, 1.0),
    "engine_time_constant": ("time", 0.01, 60.0),
    "density_altitude": ("length", -1000.0, 9000.0),
    "gravity": ("acceleration", 9.0, 10.5),
}

_LIMITS_SCHEMA: dict[str, tuple[str, float, float]] = {
    "max_descent_rate": ("speed", 0.01, 30.0),
    "max_forward_speed": ("speed", 0.01, 30.0),
    "height_tolerance": ("length", 0.001, 10.0),
    "ground_clearance": ("length", 0.0, 10.0),
    "max_thrust_coefficient_over_solidity": ("dimensionless", 0.01, 0.5),
    "max_pitch_angle": ("angle", math.radians(1.0), math.radians(89.0)),
    "min_rotor_speed_ratio": ("dimensionless", 0.1, 1.0),
    "max_rotor_speed_ratio": ("dimensionless", 1.0, 3.0),
}


_FLYABILITY_SCHEMA: dict[str, tuple[str, float, float]] = {
    "max_nose_up_pitch": ("angle", math.radians(1.0), math.radians(89.0)),
    "max_nose_down_pitch": ("angle", math.radians(1.0), math.radians(89.0)),
    "touchdown_max_nose_up_pitch": ("angle", 0.0, math.radians(89.0)),
    "touchdown_max_nose_down_pitch": ("angle", 0.0, math.radians(89.0)),
    "max_pitch_rate": ("angular_speed", math.radians(0.5), math.radians(360.0)),
    "collective_full_travel_time": ("time", 0.01, 30.0),
    "commit_height": ("length", 0.0, 100.0),
    "touchdown_min_rotor_speed_ratio": ("dimensionless", 0.1, 1.0),
}
_MARGIN_SCALES_SCHEMA: dict[str, tuple[str, float, float]] = {
    "rotor_floor": ("dimensionless", 0.005, 1.0),
    "rotor_ceiling": ("dimensionless", 0.005, 1.0),
    "touchdown_pitch": ("angle", math.radians(0.1), math.radians(45.0)),
}


def _check_range(key: str, value: float, low: float, high: float, unit: str, where: str = "") -> None:
    if not math.isfinite(value) or not low <= value <= high:
        raise ConfigError(f"{where}{key} = {value!r} {unit} is outside the physical range [{low:g}, {high:g}] {unit}")


def _parse_section(
    section: Any, schema: dict[str, tuple[str, float, float]], section_name: str, where: str
) -> tuple[dict[str, float], list[tuple[str, str]]]:
    if not isinstance(section, dict):
        raise ConfigError(f"{where}{section_name!r} must be a mapping of key: {{value, unit, source}}")
    unknown = sorted(set(section) - set(schema))
    if unknown:
        raise ConfigError(f"{where}unknown key(s) in {section_name!r}: {', '.join(unknown)}")
    missing = sorted(set(schema) - set(section))
    if missing:
        raise ConfigError(f"{where}missing key(s) in {section_name!r}: {', '.join(missing)}")
    values: dict[str, float] = {}
    sources: list[tuple[str, str]] = []
    for key, (dimension, low, high) in schema.items():
        entry = section[key]
        label = f"{section_name}.{key}"
        if (
            not isinstance(entry, dict)
            or set(entry) - {"value", "unit", "source", "note"}
            or not ({"value", "unit", "source"} <= set(entry))
        ):
            raise ConfigError(f"{where}{label} must be {{value: <number>, unit: <unit>, source: <text>}}")
        raw = entry["value"]
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise ConfigError(f"{where}{label}.value must be a number, got {raw!r}")
        if not str(entry["source"]).strip():
            raise ConfigError(f"{where}{label}.source is empty: say where the number comes from, or 'assumed'")
        try:
            si_value = convert_to_si(raw, str(entry["unit"]), dimension)
        except UnitError as error:
            raise ConfigError(f"{where}{label}: {error}") from None
        _check_range(label, si_value, low, high, _si_unit(dimension), where)
        values[key] = si_value
        sources.append((label, str(entry["source"])))
    return values, sources


def _si_unit(dimension: str) -> str:
    return {
        "force": "N", "length": "m", "dimensionless": "", "angular_speed": "rad/s", "inertia": "kg*m^2",
        "area": "m^2", "time": "s", "acceleration": "m/s^2", "speed": "m/s", "angle": "rad",
    }.get(dimension, "")  # fmt: skip


def parse_airframe(document: Any, where: str = "") -> Airframe:
    """Builds an :class:`Airframe` from a parsed YAML document.

    Args:
        document: the mapping with ``name``, ``parameters`` and ``limits``.
        where: a prefix for error messages (the file name).

    Raises:
        ConfigError: naming the offending key.
    """
    if not isinstance(document, dict):
        raise ConfigError(f"{where}an airframe file must be a mapping with name, parameters, limits")
    allowed = {
        "name", "description", "parameters", "limits", "flyability", "rotor_model", "margin_scales",
        "paper_reproduction",
    }  # fmt: skip
    unknown = sorted(set(document) - allowed)
    if unknown:
        raise ConfigError(f"{where}unknown top-level key(s): {', '.join(unknown)}")
    for key in ("name", "parameters", "limits"):
        if key not in document:
            raise ConfigError(f"{where}missing top-level key: {key}")
    parameters, parameter_sources = _parse_section(document["parameters"], _PARAMETER_SCHEMA, "parameters", where)
    limits, limit_sources = _parse_section(document["limits"], _LIMITS_SCHEMA, "limits", where)
    if limits["min_rotor_speed_ratio"] >= limits["max_rotor_speed_ratio"]:
        raise ConfigError(f"{where}limits.min_rotor_speed_ratio must be below limits.max_rotor_speed_ratio")
    if "flyability" in document:
        flyability, flyability_sources = _parse_section(document["flyability"], _FLYABILITY_SCHEMA, "flyability", where)
        flyability_limits = FlyabilityLimits(**flyability)
    else:  # airframe files older than the flyable plans: the documented assumed defaults, said so in the sources
        flyability_limits = FlyabilityLimits()
        flyability_sources = [(f"flyability.{key}", "helireach default (assumed)") for key in _FLYABILITY_SCHEMA]
    if flyability_limits.touchdown_max_nose_up_pitch > flyability_limits.max_nose_up_pitch or (
        flyability_limits.touchdown_max_nose_down_pitch > flyability_limits.max_nose_down_pitch
    ):
        raise ConfigError(f"{where}flyability: the touchdown attitude window must lie inside the path's pitch limits")
    if flyability_limits.touchdown_min_rotor_speed_ratio > limits["min_rotor_speed_ratio"]:
        raise ConfigError(
            f"{where}flyability.touchdown_min_rotor_speed_ratio must not exceed limits.min_rotor_speed_ratio"
        )
    if max(flyability_limits.max_nose_up_pitch, flyability_limits.max_nose_down_pitch) > limits["max_pitch_angle"]:
        raise ConfigError(f"{where}flyability: the pitch limits must lie inside limits.max_pitch_angle")
    if "margin_scales" in document:
        scales, scale_sources = _parse_section(document["margin_scales"], _MARGIN_SCALES_SCHEMA, "margin_scales", where)
        margin_scales = MarginScales(**scales)
    else:
        margin_scales = MarginScales()
        scale_sources = [(f"margin_scales.{key}", "helireach default (assumed)") for key in _MARGIN_SCALES_SCHEMA]
    rotor_model, rotor_sources = _parse_rotor_model(document.get("rotor_model"), where)
    paper_reproduction, paper_sources = _parse_paper_reproduction(document.get("paper_reproduction"), where)
    return Airframe(
        name=str(document["name"]),
        limits=LandingLimits(**limits),
        flyability=flyability_limits,
        rotor_model=rotor_model,
        margin_scales=margin_scales,
        paper_reproduction=paper_reproduction,
        sources=tuple(
            parameter_sources + limit_sources + flyability_sources + scale_sources + rotor_sources + paper_sources
        ),
        **parameters,
    )


def _parse_paper_reproduction(section: Any, where: str) -> tuple[tuple[tuple[str, float], ...], list[tuple[str, str]]]:
    """The optional ``paper_reproduction`` section: ``parameters`` and ``limits`` entries (any subset, each
    ``{value, unit, source}``) that the paper's reproduction uses instead of the file's own."""
    if section is None:
        return (), []
    if not isinstance(section, dict) or set(section) - {"parameters", "limits"}:
        raise ConfigError(f"{where}'paper_reproduction' must be a mapping with 'parameters' and/or 'limits'")
    values: list[tuple[str, float]] = []
    sources: list[tuple[str, str]] = []
    for name, schema in (("parameters", _PARAMETER_SCHEMA), ("limits", _LIMITS_SCHEMA)):
        entries = section.get(name, {})
        if not isinstance(entries, dict):
            raise ConfigError(f"{where}paper_reproduction.{name} must be a mapping")
        subset = {key: schema[key] for key in entries if key in schema}
        parsed, parsed_sources = _parse_section(entries, subset, f"paper_reproduction.{name}", where)
        values += [(f"{name}.{key}", value) for key, value in parsed.items()]
        sources += parsed_sources
    return tuple(values), sources


_ROTOR_MODEL_SCHEMA: dict[str, tuple[str, float, float]] = {
    "induced_power_factor": ("dimensionless", 1.0, 2.0),
    "profile_power_speed_factor": ("dimensionless", 0.0, 10.0),
    "hub_height": ("length", 0.1, 20.0),
}
_SWITCHES = {True: True, False: False, "on": True, "off": False}


def _parse_rotor_model(section: Any, where: str) -> tuple[RotorModel, list[tuple[str, str]]]:
    """The ``rotor_model`` section: ``inflow`` (momentum | paper_hover), ``ground_effect`` (on | off) and the
    numbers of :data:`_ROTOR_MODEL_SCHEMA` as ``{value, unit, source}``."""
    if section is None:  # airframe files older than the rotor model keep the model they were written for
        return PAPER_ROTOR_MODEL, [
            ("rotor_model.inflow", "paper_hover: the airframe file has no rotor_model section"),
            ("rotor_model.ground_effect", "off: the airframe file has no rotor_model section"),
        ]
    if not isinstance(section, dict):
        raise ConfigError(f"{where}'rotor_model' must be a mapping")
    switches = {"inflow", "ground_effect"}
    unknown = sorted(set(section) - switches - set(_ROTOR_MODEL_SCHEMA))
    if unknown:
        raise ConfigError(f"{where}unknown key(s) in 'rotor_model': {', '.join(unknown)}")
    inflow_name = section.get("inflow", InflowModel.MOMENTUM.value)
    try:
        inflow = InflowModel(inflow_name)
    except ValueError:
        choices = " | ".join(model.value for model in InflowModel)
        raise ConfigError(f"{where}rotor_model.inflow must be {choices}, got {inflow_name!r}") from None
    ground_effect = section.get("ground_effect", "on")
    if isinstance(ground_effect, str):
        ground_effect = ground_effect.lower()
    if not isinstance(ground_effect, bool | str) or ground_effect not in _SWITCHES:
        raise ConfigError(f"{where}rotor_model.ground_effect must be on | off, got {ground_effect!r}")
    numbers = {key: section[key] for key in _ROTOR_MODEL_SCHEMA if key in section}
    required = ["induced_power_factor", "profile_power_speed_factor"]
    if _SWITCHES[ground_effect]:
        required.append("hub_height")
    missing = [key for key in required if key not in numbers]
    if missing:
        raise ConfigError(f"{where}missing key(s) in 'rotor_model': {', '.join(missing)}")
    schema = {key: _ROTOR_MODEL_SCHEMA[key] for key in numbers}
    values, sources = _parse_section(numbers, schema, "rotor_model", where)
    sources = [("rotor_model.inflow", inflow.value), ("rotor_model.ground_effect", str(ground_effect)), *sources]
    return RotorModel(inflow=inflow, ground_effect=_SWITCHES[ground_effect], **values), sources


def load_airframe(name_or_path: str | Path) -> Airframe:
    """Loads an airframe by name (``config/airframes/<name>.yaml``) or from a YAML file path.

    Derived rotor figures outside the broad range of helicopters (tip speed, disk loading, solidity, blade
    and power loading: :mod:`~helireach_ros.core.aircraft.plausibility`) give an
    ``AirframePlausibilityWarning`` naming the figure, its value and range; the airframe still loads.

    Raises:
        ConfigError: the file is missing, unreadable, or invalid (the message names the key).
    """
    candidate = Path(name_or_path).expanduser()
    try:
        path = candidate if candidate.suffix in {".yaml", ".yml"} else config_path(f"airframes/{name_or_path}.yaml")
        text = path.read_text()
    except (FileNotFoundError, OSError) as error:
        raise ConfigError(f"airframe {str(name_or_path)!r}: {error}") from None
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML: {error}") from None
    airframe = parse_airframe(document, where=f"{path}: ")
    # a plausible wrong unit (rotor radius in m instead of ft) passes the physical ranges: warn, never refuse
    warn_if_implausible(airframe, where=f"{path}: ")
    return airframe
