"""The uncertainty set: how far the real helicopter may differ from the model the planner uses.

``config/uncertainty.yaml`` gives a closed range for each uncertain quantity, each with a note saying where
it comes from (or "assumed"):

* airframe parameters (a subset of :data:`~helireach_ros.core.flight.simulation.MISMATCH_PARAMETERS`) as relative
  ranges: true value = file value × (1 + f), f ∈ [low, high] (written in ``%`` or as a fraction ``-``);
* the density altitude as an offset from the airframe's, [low, high] (a length);
* the plan latency, s from the measurement a plan starts from to the vehicle flying it, [low, high];
* the sensor noise: standard deviations ``{value, unit, note}`` (not ranges: noise is random by nature).

A parameter the file does not list is taken as exact; that is a statement the file makes, so every listed
range must be explicit (a zero-width range ``{low: 0, high: 0}`` is allowed and says "exact" out loud).

A point of the set is a :class:`PerturbedModel` (the fractions, the density-altitude offset, the latency).
The set offers

* :meth:`UncertaintySet.corners`: the full factorial, every combination of range ends (2^k for k
  non-degenerate ranges: 256 for the default set);
* :meth:`UncertaintySet.verification_design`: a two-level resolution-IV design of corners, 2n runs with
  n the smallest power of two ≥ k: the foldover of a Sylvester–Hadamard design. Every run is a corner, each
  range's low and high end appear in half the runs, and no main effect is aliased with a two-factor
  interaction (16 runs for the default set's k = 8; the full factorial for k ≤ 3). This is what robust
  verification flies by default: a finite design, not a proof over the whole set;
* :meth:`UncertaintySet.draw`: seeded uniform draws inside every range (the set states ranges, not
  distributions; uniform is the assumption that favours no point of a range).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from helireach_ros.core.aircraft.airframe import Airframe, ConfigError
from helireach_ros.core.flight.simulation import MISMATCH_PARAMETERS, SensorNoise, mismatched_airframe
from helireach_ros.core.resources import config_path
from helireach_ros.core.units import FT, UnitError, convert_to_si

__all__ = [
    "DEFAULT_UNCERTAINTY_FILE",
    "PerturbedModel",
    "UncertainRange",
    "UncertaintySet",
    "load_uncertainty_set",
    "parse_uncertainty_set",
    "resolution_iv_signs",
]

DEFAULT_UNCERTAINTY_FILE = "uncertainty.yaml"
"""The shipped set, relative to ``config/``."""

# Sanity bounds that reject typos and wrong units (a fraction written as a per cent number), not design choices.
_MAX_RELATIVE = 1.0  # |f| <= 100 %
_MAX_DENSITY_ALTITUDE_OFFSET = 2000.0  # m
_MAX_LATENCY = 5.0  # s
_NOISE_DIMENSIONS = {
    "height": "length", "forward_speed": "speed", "climb_rate": "speed", "rotor_speed": "angular_speed"
}  # fmt: skip
_RELATIVE_UNITS = {"%": 0.01, "-": 1.0, "1": 1.0}


@dataclass(frozen=True)
class UncertainRange:
    """A closed range [low, high] in SI (a fraction for airframe parameters), with its note."""

    low: float
    high: float
    note: str

    @property
    def ends(self) -> tuple[float, ...]:
        """(low, high), or (low,) for a zero-width range."""
        return (self.low,) if self.low == self.high else (self.low, self.high)

    def at(self, sign: float) -> float:
        """The low end for sign < 0, the high end otherwise."""
        return self.low if sign < 0 else self.high


@dataclass(frozen=True)
class PerturbedModel:
    """One point of the uncertainty set: the true vehicle the planner does not know about.

    Attributes:
        mismatch: airframe parameter → fraction f (true = nominal × (1 + f)).
        density_altitude_offset: true density altitude − the airframe's, m.
        latency: plan latency, s.
        label: a short name (e.g. ``gross_weight+5%,horizontal_drag_area-20%,...``).
    """

    mismatch: Mapping[str, float]
    density_altitude_offset: float = 0.0
    latency: float = 0.0
    label: str = "nominal"

    def __post_init__(self) -> None:
        object.__setattr__(self, "mismatch", dict(self.mismatch))

    def airframe(self, nominal: Airframe) -> Airframe:
        """The true airframe: the nominal one at the offset density altitude, with the mismatch applied."""
        return mismatched_airframe(self.conditions(nominal), self.mismatch)

    def conditions(self, nominal: Airframe) -> Airframe:
        """The nominal airframe at the true density altitude (no parameter mismatch yet)."""
        if self.density_altitude_offset == 0.0:
            return nominal
        return nominal.with_conditions(density_altitude=nominal.density_altitude + self.density_altitude_offset)

    def values(self) -> dict[str, float]:
        """The point by name: each parameter's fraction, ``density_altitude`` (offset, m), ``plan_latency`` (s)."""
        return {**self.mismatch, "density_altitude": self.density_altitude_offset, "plan_latency": self.latency}

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready, SI."""
        return dataclasses.asdict(self)


def _label(mismatch: Mapping[str, float], density_altitude_offset: float, latency: float) -> str:
    parts = [f"{name}{100 * fraction:+.0f}%" for name, fraction in mismatch.items()]
    parts.append(f"density_altitude{density_altitude_offset / FT:+.0f}ft")
    parts.append(f"latency{latency:.2f}s")
    return ",".join(parts)


def resolution_iv_signs(factors: int) -> np.ndarray:
    """A two-level resolution-IV design for ``factors`` factors: runs × factors of ±1.

    With n the smallest power of two ≥ ``factors``, take the Sylvester–Hadamard matrix H_n, its
    ``factors − 1`` first non-constant columns and a column of +1, and append the negated rows (the
    foldover): 2n runs, balanced, main effects clear of two-factor interactions. For ``factors`` ≤ 3 the
    runs are the full factorial; ``factors`` = 0 gives one empty run.
    """
    if factors < 0:
        raise ValueError(f"factors must be >= 0, got {factors!r}")
    if factors == 0:
        return np.ones((1, 0))
    order = 1
    while order < factors:
        order *= 2
    hadamard = np.ones((1, 1))
    while hadamard.shape[0] < order:
        hadamard = np.block([[hadamard, hadamard], [hadamard, -hadamard]])
    half = np.hstack([hadamard[:, 1:factors], np.ones((order, 1))])
    return np.vstack([half, -half])


@dataclass(frozen=True)
class UncertaintySet:
    """The ranges of everything the planner's model may get wrong (see the module docstring).

    Attributes:
        name: identifier.
        parameters: (airframe parameter, range of its fraction f), in file order.
        density_altitude: range of the density-altitude offset, m.
        plan_latency: range of the plan latency, s.
        sensor_noise: standard deviations, SI.
        noise_notes: (sensor, note) for each noise entry.
    """

    name: str
    parameters: tuple[tuple[str, UncertainRange], ...]
    density_altitude: UncertainRange
    plan_latency: UncertainRange
    sensor_noise: SensorNoise
    noise_notes: tuple[tuple[str, str], ...] = ()

    def _ranges(self) -> list[tuple[str, UncertainRange]]:
        return [*self.parameters, ("density_altitude", self.density_altitude), ("plan_latency", self.plan_latency)]

    def ranges(self) -> dict[str, UncertainRange]:
        """Every range by name: the parameters, ``density_altitude`` and ``plan_latency`` (the keys of
        :meth:`PerturbedModel.values`)."""
        return dict(self._ranges())

    def _model(self, values: Mapping[str, float]) -> PerturbedModel:
        mismatch = {name: values[name] for name, _ in self.parameters}
        offset, latency = values["density_altitude"], values["plan_latency"]
        return PerturbedModel(mismatch, offset, latency, _label(mismatch, offset, latency))

    @property
    def uncertain_quantities(self) -> tuple[str, ...]:
        """Names of the ranges of non-zero width (the factors of the designs)."""
        return tuple(name for name, interval in self._ranges() if interval.low != interval.high)

    def corners(self) -> tuple[PerturbedModel, ...]:
        """Every combination of range ends (the full factorial; one model if no range has width)."""
        names = [name for name, _ in self._ranges()]
        return tuple(
            self._model(dict(zip(names, ends, strict=True)))
            for ends in itertools.product(*(interval.ends for _, interval in self._ranges()))
        )

    def verification_design(self) -> tuple[PerturbedModel, ...]:
        """The resolution-IV corners robust verification flies (:func:`resolution_iv_signs`)."""
        ranges = dict(self._ranges())
        factors = self.uncertain_quantities
        models = []
        for signs in resolution_iv_signs(len(factors)):
            values = {name: interval.low for name, interval in ranges.items()}  # zero-width ranges
            values.update({name: ranges[name].at(sign) for name, sign in zip(factors, signs, strict=True)})
            models.append(self._model(values))
        return tuple(models)

    def draw(self, rng: np.random.Generator | int, count: int = 1) -> tuple[PerturbedModel, ...]:
        """``count`` models drawn uniformly inside every range (a generator, or a seed for a new one)."""
        generator = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        return tuple(
            self._model({name: float(generator.uniform(r.low, r.high)) for name, r in self._ranges()})
            for _ in range(count)
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready, SI (fractions for the parameters)."""
        return dataclasses.asdict(self)


def _number(entry: Mapping[str, Any], key: str, label: str, where: str) -> float:
    raw = entry[key]
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        raise ConfigError(f"{where}{label}.{key} must be a finite number, got {raw!r}")
    return float(raw)


def _note(entry: Mapping[str, Any], label: str, where: str) -> str:
    note = str(entry["note"]).strip()
    if not note:
        raise ConfigError(f"{where}{label}.note is empty: say where the number comes from, or 'assumed'")
    return note


def _entry(entry: Any, keys: set[str], label: str, where: str) -> Mapping[str, Any]:
    if not isinstance(entry, Mapping) or set(entry) != keys:
        layout = ", ".join(f"{key}: ..." for key in sorted(keys))
        raise ConfigError(f"{where}{label} must be {{{layout}}}, got {entry!r}")
    return entry


def _range(entry: Any, label: str, dimension: str, bounds: tuple[float, float], where: str) -> UncertainRange:
    """A ``{low, high, unit, note}`` entry in SI (``dimension`` "relative": a fraction from % or -)."""
    entry = _entry(entry, {"low", "high", "unit", "note"}, label, where)
    low, high, unit = _number(entry, "low", label, where), _number(entry, "high", label, where), str(entry["unit"])
    if dimension == "relative":
        if unit not in _RELATIVE_UNITS:
            raise ConfigError(f"{where}{label}.unit must be one of {', '.join(_RELATIVE_UNITS)}, got {unit!r}")
        low, high = low * _RELATIVE_UNITS[unit], high * _RELATIVE_UNITS[unit]
    else:
        try:
            low, high = convert_to_si(low, unit, dimension), convert_to_si(high, unit, dimension)
        except UnitError as error:
            raise ConfigError(f"{where}{label}: {error}") from None
    if low > high:
        raise ConfigError(f"{where}{label}: low ({entry['low']!r}) is above high ({entry['high']!r})")
    if low < bounds[0] or high > bounds[1]:
        raise ConfigError(
            f"{where}{label} = [{low:g}, {high:g}] (SI) is outside the accepted range [{bounds[0]:g}, {bounds[1]:g}]"
        )
    return UncertainRange(low, high, _note(entry, label, where))


def parse_uncertainty_set(document: Any, where: str = "") -> UncertaintySet:
    """Builds an :class:`UncertaintySet` from a parsed YAML document.

    Raises:
        ConfigError: naming the offending key (and ``where``, the file).
    """
    required = {"name", "parameters", "density_altitude", "plan_latency", "sensor_noise"}
    if not isinstance(document, Mapping):
        raise ConfigError(f"{where}an uncertainty set must be a mapping with {', '.join(sorted(required))}")
    unknown = sorted(set(document) - required - {"description"})
    if unknown:
        raise ConfigError(f"{where}unknown key(s): {', '.join(unknown)}")
    missing = sorted(required - set(document))
    if missing:
        raise ConfigError(f"{where}missing key(s): {', '.join(missing)}")
    section = document["parameters"]
    if not isinstance(section, Mapping):
        raise ConfigError(f"{where}parameters must map airframe parameters to {{low, high, unit, note}}")
    unknown = sorted(set(section) - set(MISMATCH_PARAMETERS))
    if unknown:
        raise ConfigError(
            f"{where}unknown parameter(s) {', '.join(map(str, unknown))}: choose from {', '.join(MISMATCH_PARAMETERS)}"
        )
    parameters = tuple(
        (name, _range(entry, f"parameters.{name}", "relative", (-_MAX_RELATIVE, _MAX_RELATIVE), where))
        for name, entry in section.items()
    )
    for name, interval in parameters:
        if interval.low <= -1.0:
            raise ConfigError(f"{where}parameters.{name}: a fraction of -100 % or less makes the parameter vanish")
    offset_bounds = (-_MAX_DENSITY_ALTITUDE_OFFSET, _MAX_DENSITY_ALTITUDE_OFFSET)
    density_altitude = _range(document["density_altitude"], "density_altitude", "length", offset_bounds, where)
    plan_latency = _range(document["plan_latency"], "plan_latency", "time", (0.0, _MAX_LATENCY), where)
    noise_section = document["sensor_noise"]
    if not isinstance(noise_section, Mapping) or set(noise_section) != set(_NOISE_DIMENSIONS):
        sensors = ", ".join(_NOISE_DIMENSIONS)
        raise ConfigError(f"{where}sensor_noise must give each of {sensors} as {{value, unit, note}}")
    noise: dict[str, float] = {}
    notes = []
    for key, dimension in _NOISE_DIMENSIONS.items():
        label = f"sensor_noise.{key}"
        entry = _entry(noise_section[key], {"value", "unit", "note"}, label, where)
        try:
            noise[key] = convert_to_si(_number(entry, "value", label, where), str(entry["unit"]), dimension)
        except UnitError as error:
            raise ConfigError(f"{where}{label}: {error}") from None
        if noise[key] < 0.0:
            raise ConfigError(f"{where}{label}.value must be >= 0 (a standard deviation), got {entry['value']!r}")
        notes.append((key, _note(entry, label, where)))
    return UncertaintySet(
        str(document["name"]), parameters, density_altitude, plan_latency, SensorNoise(**noise), tuple(notes)
    )


def load_uncertainty_set(name_or_path: str | Path = DEFAULT_UNCERTAINTY_FILE) -> UncertaintySet:
    """Loads an uncertainty set: a file path, or a name relative to ``config/`` (default the shipped set).

    Raises:
        ConfigError: the file is missing, unreadable or invalid (the message names the file and the key).
    """
    text = str(name_or_path)
    relative = text if text.endswith((".yaml", ".yml")) else f"{text}.yaml"
    try:
        path = config_path(relative)
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise ConfigError(f"cannot read uncertainty set {text!r}: {error}") from None
    return parse_uncertainty_set(document, where=f"{path}: ")
