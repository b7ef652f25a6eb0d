"""Where an envelope's answer holds: its validity domain.

A (2-D) H-V envelope is computed from *level trim at nominal rotor speed*: each node's landing starts from
y = 0 and Ω = Ω₀ (:func:`~helireach_ros.core.aircraft.model.initial_state_after_failure`). Its answer speaks for the
aircraft only while the aircraft is in such a state, within tolerances:

- **climb rate** within ±``climb_rate_tolerance`` of level flight (default 0.5 m/s ≈ 100 ft/min, *assumed*:
  the band a pilot calls "level"; a 2,000 ft/min descent at 20 ft, 90 kt is unsafe where the level-trim
  envelope says safe — docs/method/live-reachability.md);
- **rotor speed** within ±``rotor_speed_tolerance`` × Ω₀ of Ω₀ (default 1 %, *assumed*: a governor's steady
  band). An unmeasured rotor speed cannot be checked: the state is then *not known* to be inside, and the
  safety status says so (it caps the level at WARN);
- **engine power** does not enter a total-power-loss envelope (P = 0 at the failure whatever the engine gave
  before); an envelope for partial power loss (``power_fraction`` > 0) assumes the trim power before the
  failure, and this module does not yet check it: such envelopes are outside their domain unless the power
  is within ``power_tolerance`` of trim (checked when given).

A **3-D** envelope (a climb-rate axis, ``helireach envelope compute --climb-rates-fpm``) covers its climb-rate
range exactly, from its lowest to its highest slice, with no tolerance beyond the ends (between slices the
query interpolates conservatively); a 2-D envelope, or one with a single slice, covers its climb rate
± ``climb_rate_tolerance`` (:meth:`ValidityDomain.climb_rate_range`).

The tolerances are stored in the envelope file's metadata (``validity_domain``) by ``helireach envelope
compute``; a file without them (made before they existed) gets these defaults.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from helireach_ros.core.units import FT

__all__ = ["DomainCheck", "ValidityDomain"]

_FPM = FT / 60.0


@dataclass(frozen=True)
class DomainCheck:
    """Whether a state lies inside an envelope's validity domain.

    Attributes:
        inside: every checked quantity is within its tolerance.
        known: every quantity could be checked (False: e.g. the rotor speed was not measured).
        reasons: why not inside, or what could not be checked, for people.
    """

    inside: bool
    known: bool
    reasons: tuple[str, ...] = ()


@dataclass(frozen=True)
class ValidityDomain:
    """The tolerances around level trim at Ω₀ within which an envelope's answer holds (module docstring).

    Attributes:
        climb_rate_tolerance: m/s.
        rotor_speed_tolerance: fraction of Ω₀.
        power_tolerance: fraction of trim power (partial-power envelopes only).
        climb_rates: m/s, the climb rates the envelope was computed at (``(0.0,)`` for a 2-D envelope).
    """

    climb_rate_tolerance: float = 0.5
    rotor_speed_tolerance: float = 0.01
    power_tolerance: float = 0.1
    climb_rates: tuple[float, ...] = (0.0,)

    def __post_init__(self) -> None:
        for name in ("climb_rate_tolerance", "rotor_speed_tolerance", "power_tolerance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not self.climb_rates or not all(math.isfinite(rate) for rate in self.climb_rates):
            raise ValueError(f"climb_rates must be finite numbers, got {self.climb_rates!r}")

    def climb_rate_range(self) -> tuple[float, float]:
        """(lowest, highest) climb rate covered, m/s: the slices' range, or one slice ± the tolerance."""
        if len(self.climb_rates) == 1:
            return self.climb_rates[0] - self.climb_rate_tolerance, self.climb_rates[0] + self.climb_rate_tolerance
        return min(self.climb_rates), max(self.climb_rates)

    @classmethod
    def from_metadata(cls, metadata: Mapping[str, Any]) -> ValidityDomain:
        """The domain recorded in an envelope's metadata, or the defaults for a file that records none."""
        recorded = metadata.get("validity_domain")
        if not isinstance(recorded, Mapping):
            return cls()
        default = cls()
        return cls(
            climb_rate_tolerance=float(recorded.get("climb_rate_tolerance", default.climb_rate_tolerance)),
            rotor_speed_tolerance=float(recorded.get("rotor_speed_tolerance", default.rotor_speed_tolerance)),
            power_tolerance=float(recorded.get("power_tolerance", default.power_tolerance)),
            climb_rates=tuple(float(rate) for rate in recorded.get("climb_rates", default.climb_rates)),
        )

    def to_metadata(self) -> dict[str, Any]:
        """JSON-ready, for the envelope file."""
        return {**asdict(self), "climb_rates": list(self.climb_rates)}

    def check(
        self,
        climb_rate: float,
        rotor_speed: float | None,
        nominal_rotor_speed: float,
        engine_power: float | None = None,
        trim_power: float | None = None,
        power_fraction: float = 0.0,
    ) -> DomainCheck:
        """Checks one measured state against the domain.

        Args:
            climb_rate: m/s, positive up.
            rotor_speed: rad/s, or None if not measured.
            nominal_rotor_speed: Ω₀ of the envelope's airframe, rad/s.
            engine_power: W, or None if not measured (only checked for ``power_fraction`` > 0).
            trim_power: W, the trim power at the current speed (only for ``power_fraction`` > 0).
            power_fraction: the envelope's power left after the failure.
        """
        reasons: list[str] = []
        known = True
        low, high = self.climb_rate_range()
        if not math.isfinite(climb_rate) or not low <= climb_rate <= high:
            reasons.append(
                f"climb rate {climb_rate / _FPM:+.0f} ft/min outside {low / _FPM:+.0f}…{high / _FPM:+.0f} ft/min"
            )
        if rotor_speed is None or not math.isfinite(rotor_speed):
            known = False
            reasons.append("rotor speed not measured (the envelope assumes nominal)")
        elif abs(rotor_speed / nominal_rotor_speed - 1.0) > self.rotor_speed_tolerance:
            reasons.append(
                f"rotor speed {100 * rotor_speed / nominal_rotor_speed:.1f} % outside "
                f"100 ± {100 * self.rotor_speed_tolerance:.1f} %"
            )
        if power_fraction > 0.0:
            if engine_power is None or trim_power is None or not trim_power > 0.0:
                known = False
                reasons.append("engine power not measured (the envelope assumes trim power before the failure)")
            elif abs(engine_power / trim_power - 1.0) > self.power_tolerance:
                reasons.append(
                    f"engine power {100 * engine_power / trim_power:.0f} % of trim, outside "
                    f"100 ± {100 * self.power_tolerance:.0f} %"
                )
        outside = [reason for reason in reasons if "not measured" not in reason]
        return DomainCheck(not outside, known, tuple(reasons))
