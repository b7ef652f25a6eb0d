"""The ``DiagnosticStatus`` contracts the package's consumers read, one typed codec each.

A status topic's values are strings (``msg_docs/``). Each contract here is a frozen dataclass whose fields name their
key and type once; producers write with :meth:`StatusContract.to_values` and consumers read with
:meth:`StatusContract.from_values`, so a field cannot be written one way and read another (the robust flag of a plan
status, for instance, is ``pending`` or a boolean, and is read as such).

Reading is strict and never guesses: a flag that is not ``true``/``false``, a number that does not parse, a missing
key are None (unknown), and what a consumer makes of unknown is its own rule (the safety status: never SAFE).
Writing leaves out the fields that are None, so a producer can write a contract's part it knows and merge parts.

Contracts: :class:`PlanStatusValues` (``/helireach/plan_status``), :class:`LiveVerdictValues`
(``/helireach/live_reachability``), :class:`RobustVerdictValues` (``/helireach/robust_verdict``),
:class:`TouchdownValues` (``/helireach/touchdown``), :class:`SafetyStatusValues` (``/helireach/safety_status``); the
failure episode's is :class:`~helireach_ros.core.policies.failure_episode.EpisodeState`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Self

from helireach_ros.core.status_values import parse_bool

__all__ = [
    "ROBUST_PENDING",
    "LiveVerdictValues",
    "PlanStatusValues",
    "RobustVerdictValues",
    "SafetyStatusValues",
    "StatusContract",
    "TouchdownValues",
    "read_robust",
]

ROBUST_PENDING = "pending"


def _read_float(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _read_int(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        return None


def read_robust(text: str | None) -> bool | str | None:
    """A robust flag: ``pending``, True, False, or None (missing or anything else: unknown)."""
    return ROBUST_PENDING if text == ROBUST_PENDING else parse_bool(text)


_READERS: dict[str, Any] = {
    "bool": parse_bool,
    "float": _read_float,
    "int": _read_int,
    "str": lambda text: text,
    "robust": read_robust,
}


def key(name: str, kind: str) -> Any:
    """A contract field: its key in the values and how it is read (``bool``, ``float``, ``int``, ``str``,
    ``robust``); None by default (not written, or not known when read)."""
    if kind not in _READERS:
        raise ValueError(f"unknown value kind {kind!r}")
    return dataclasses.field(default=None, metadata={"keys": (name,), "kind": kind})


def vector(*names: str) -> Any:
    """A contract field of several numbers, one key each (a tuple of floats; None when any is missing or
    unreadable: a partial vector is not one)."""
    return dataclasses.field(default=None, metadata={"keys": names, "kind": "vector"})


def _state_keys(prefix: str) -> tuple[str, ...]:
    """The keys of a model state (y, v, Ω, h, z, P; SI), in StateIndex order."""
    names = ("descent_rate_m_s", "forward_speed_m_s", "rotor_speed_rad_s", "height_m", "distance_m", "engine_power_w")
    return tuple(prefix + name for name in names)


class StatusContract:
    """What every contract does: write its known fields as values, read them back strictly."""

    topic: ClassVar[str]

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The contract's keys, in field order."""
        return tuple(name for field in dataclasses.fields(cls) for name in field.metadata["keys"])  # type: ignore[arg-type]

    def to_values(self) -> dict[str, Any]:
        """The known fields under their keys (not yet strings: the message builder formats them)."""
        values: dict[str, Any] = {}
        for field in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, field.name)
            if value is None:
                continue
            if field.metadata["kind"] == "vector":
                values.update(zip(field.metadata["keys"], (float(part) for part in value), strict=True))
            else:
                values[field.metadata["keys"][0]] = value
        return values

    @classmethod
    def from_values(cls, values: Mapping[str, str]) -> Self:
        """The contract's fields from a message's values (a missing or unreadable one is None)."""
        read: dict[str, Any] = {}
        for field in dataclasses.fields(cls):  # type: ignore[arg-type]
            if field.metadata["kind"] == "vector":
                parts = [_read_float(values[name]) if name in values else None for name in field.metadata["keys"]]
                read[field.name] = None if any(part is None for part in parts) else tuple(parts)
            else:
                text = values.get(field.metadata["keys"][0])
                read[field.name] = None if text is None else _READERS[field.metadata["kind"]](text)
        return cls(**read)


@dataclass(frozen=True)
class PlanStatusValues(StatusContract):
    """``/helireach/plan_status``: the plan's verdict and what consumers read of it (msg_docs/helireach_plan_status.md).

    ``robust`` is ``pending`` while the plan's robust verification runs (the verdict follows on
    ``/helireach/robust_verdict``), else not sent.
    """

    topic: ClassVar[str] = "/helireach/plan_status"
    status: str | None = key("status", "str")
    safe: bool | None = key("safe", "bool")
    verified: bool | None = key("verified", "bool")
    fallback: bool | None = key("fallback", "bool")
    standby: bool | None = key("standby", "bool")
    robust: bool | str | None = key("robust", "robust")
    value: float | None = key("value", "float")
    time_to_land_s: float | None = key("time_to_land_s", "float")
    solve_time_ms: float | None = key("solve_time_ms", "float")
    replan_index: int | None = key("replan_index", "int")
    late: bool | None = key("late", "bool")
    late_by_s: float | None = key("late_by_s", "float")
    state_delay_s: float | None = key("state_delay_s", "float")
    touchdown_descent_rate: float | None = key("predicted_touchdown_descent_rate_m_s", "float")
    touchdown_forward_speed: float | None = key("predicted_touchdown_forward_speed_m_s", "float")
    touchdown_rotor_speed: float | None = key("predicted_touchdown_rotor_speed_rad_s", "float")
    gross_weight: float | None = key("gross_weight_n", "float")
    planned_gross_weight: float | None = key("planned_gross_weight_n", "float")
    density_altitude: float | None = key("density_altitude_m", "float")
    failure_id: int | None = key("failure_id", "int")
    failure_stamp_ns: int | None = key("failure_stamp_ns", "int")
    state_stamp_ns: int | None = key("state_stamp_ns", "int")
    initial_state: tuple[float, ...] | None = vector(*_state_keys("initial_"))
    initial_control: tuple[float, ...] | None = vector("initial_thrust_coefficient", "initial_pitch_rad")
    reaction_delay_s: float | None = key("reaction_delay_s", "float")
    disturbance: tuple[float, ...] | None = vector(
        "disturbance_descent_acceleration_m_s2",
        "disturbance_forward_acceleration_m_s2",
        "disturbance_rotor_acceleration_rad_s2",
    )
    reason: str | None = key("reason", "str")

    @property
    def replay_verified_safe(self) -> bool:
        """Safe and replay-verified, both said explicitly (unknown is not)."""
        return self.safe is True and self.verified is True

    @property
    def is_fallback(self) -> bool:
        """A fallback, said explicitly."""
        return self.fallback is True


@dataclass(frozen=True)
class LiveVerdictValues(StatusContract):
    """``/helireach/live_reachability``: "if the engine failed now" (msg_docs/helireach_live_reachability.md)."""

    topic: ClassVar[str] = "/helireach/live_reachability"
    status: str | None = key("status", "str")
    value: float | None = key("value", "float")
    safe: bool | None = key("safe", "bool")
    verified: bool | None = key("verified", "bool")
    state_stamp_ns: int | None = key("state_stamp_ns", "int")
    solve_time_ms: float | None = key("solve_time_ms", "float")
    state_age_s: float | None = key("state_age_s", "float")
    time_to_land_s: float | None = key("time_to_land_s", "float")
    power_fraction: float | None = key("power_fraction", "float")
    reason: str | None = key("reason", "str")
    standby: bool | None = key("standby", "bool")
    state: tuple[float, ...] | None = vector(*_state_keys(""))


@dataclass(frozen=True)
class RobustVerdictValues(StatusContract):
    """``/helireach/robust_verdict``: a failure plan's closed loop through perturbed models
    (msg_docs/helireach_robust_verdict.md)."""

    topic: ClassVar[str] = "/helireach/robust_verdict"
    robust: bool | str | None = key("robust", "robust")
    error: bool | None = key("robust_error", "bool")
    failure_id: int | None = key("failure_id", "int")
    failure_stamp_ns: int | None = key("failure_stamp_ns", "int")
    state_stamp_ns: int | None = key("state_stamp_ns", "int")
    models_flown: int | None = key("robust_models_flown", "int")
    design_size: int | None = key("robust_design_size", "int")
    design: str | None = key("robust_design", "str")
    reason: str | None = key("robust_reason", "str")


@dataclass(frozen=True)
class TouchdownValues(StatusContract):
    """``/helireach/touchdown``: the simulated vehicle's touchdown against the limits (SI;
    msg_docs/helireach_touchdown.md)."""

    topic: ClassVar[str] = "/helireach/touchdown"
    within_limits: bool | None = key("within_limits", "bool")
    descent_rate: float | None = key("descent_rate_m_s", "float")
    forward_speed: float | None = key("forward_speed_m_s", "float")
    rotor_speed_pct: float | None = key("rotor_speed_pct", "float")
    rotor_speed_within_limits: bool | None = key("rotor_speed_within_limits", "bool")
    max_descent_rate: float | None = key("max_descent_rate_m_s", "float")
    max_forward_speed: float | None = key("max_forward_speed_m_s", "float")
    time_after_failure_s: float | None = key("time_after_failure_s", "float")
    reason: str | None = key("reason", "str")


@dataclass(frozen=True)
class SafetyStatusValues(StatusContract):
    """``/helireach/safety_status``: what a cockpit display reads beside the level and text
    (msg_docs/helireach_safety_status.md)."""

    topic: ClassVar[str] = "/helireach/safety_status"
    margin: float | None = key("margin_ft_kt", "float")
    envelope_id: str | None = key("envelope_id", "str")
    envelope_conditions: str | None = key("envelope_conditions", "str")
