"""Which gross weight to plan for, from the steady flight the planner node sees before a failure.

:func:`~helireach_ros.core.estimation.gross_weight.estimate_gross_weight` turns one steady flight (speed, climb rate,
engine power) into the weight whose trim power is that power. On line the readings are noisy and the aircraft is not
always steady, so :class:`WeightTracker` adds the policy around it:

- **A short average.** The samples of the last ``window_s`` (state stamps; out-of-order or non-finite samples are
  dropped) are averaged; at least ``min_samples`` are needed and the newest must be at most ``max_sample_age_s``
  old at the query.
- **Steady flight only.** Over the window the forward speed and the climb rate must each vary by at most
  ``max_speed_spread`` / ``max_climb_rate_spread`` (max − min), the engine power by at most ``max_power_spread``
  of its mean, and the rotor speed must stay within ``rotor_speed_tolerance`` of Ω₀ (the trim is at Ω₀). A
  sample without an engine power reading (the rotor ``JointState`` has no effort) makes the window unusable.
- **Bounded.** An estimate outside ``band`` (relative to the file's weight; by default the uncertainty set's
  weight range widened by the estimate's own error, :func:`plausible_band`) is refused: the model is then wrong
  in more than the weight, and the file's weight is used, with the reason.
- **Quantised.** The relative change is rounded to ``step`` (0.5 %), so a solver worker holds a few planners
  (one NLP per weight, built once) instead of one per reading; :func:`quantised_weight` is the single rounding.
- **Held.** A weight once estimated is kept for ``hold_s`` while the flight is not steady (weight changes only by
  fuel burn, ~0.1 %/min); older, the file's weight is used again and the reason says why.

A :class:`WeightChoice` is the answer: the weight, where it comes from (``estimate``, ``held`` or ``file``) and why.
:func:`ready_choice` then restricts it to the weights the solvers have already built (a new weight's NLP is built
at a live evaluation before any failure, never in the failure path). Pure policy: no ROS, no threads, times in ns.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Collection
from dataclasses import dataclass, replace

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.estimation.gross_weight import estimate_gross_weight
from helireach_ros.core.flight.uncertainty import UncertaintySet

__all__ = [
    "ESTIMATE_ERROR",
    "WeightChoice",
    "WeightSample",
    "WeightTracker",
    "WeightTrackingSettings",
    "plausible_band",
    "quantised_weight",
    "ready_choice",
]

ESTIMATE_ERROR = 0.02
"""Fraction the estimate itself may be off (a 2 % power error is a ~2 % weight error;
:mod:`helireach_ros.core.estimation.gross_weight`)."""


@dataclass(frozen=True)
class WeightTrackingSettings:
    """The estimation policy (module docstring); SI, fractions relative to the file's weight or Ω₀.

    Attributes:
        window_s: averaging window, s.
        min_samples: samples needed in the window.
        max_sample_age_s: the newest sample may be at most this old at a query, s.
        max_speed_spread: m/s (max − min of the forward speed over the window; 1 m/s ≈ 2 kt).
        max_climb_rate_spread: m/s (0.5 m/s ≈ 100 ft/min).
        max_power_spread: fraction of the mean engine power.
        rotor_speed_tolerance: fraction of Ω₀ every sample's rotor speed must lie within.
        band: (low, high) relative weight changes an estimate may have.
        step: quantum of the relative weight change.
        hold_s: how long an estimate is kept while the flight is not steady, s.
    """

    window_s: float = 1.0
    min_samples: int = 10
    max_sample_age_s: float = 0.5
    max_speed_spread: float = 1.0
    max_climb_rate_spread: float = 0.5
    max_power_spread: float = 0.05
    rotor_speed_tolerance: float = 0.02
    band: tuple[float, float] = (-0.07, 0.07)
    step: float = 0.005
    hold_s: float = 60.0

    def __post_init__(self) -> None:
        positive = ("window_s", "max_sample_age_s", "max_speed_spread", "max_climb_rate_spread", "max_power_spread")
        for name in (*positive, "rotor_speed_tolerance", "step", "hold_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if not (isinstance(self.min_samples, int) and self.min_samples >= 1):
            raise ValueError(f"min_samples must be an integer >= 1, got {self.min_samples!r}")
        low, high = self.band
        if not (math.isfinite(low) and math.isfinite(high) and -0.5 < low <= 0.0 <= high < 0.5):
            raise ValueError(f"band must satisfy -0.5 < low <= 0 <= high < 0.5, got {self.band!r}")


def plausible_band(uncertainty: UncertaintySet, estimate_error: float = ESTIMATE_ERROR) -> tuple[float, float]:
    """The relative weight changes an estimate may have: the set's ``gross_weight`` range ± ``estimate_error``.

    Raises:
        ValueError: the set has no ``gross_weight`` range.
    """
    ranges = uncertainty.ranges()
    if "gross_weight" not in ranges:
        raise ValueError(f"uncertainty set {uncertainty.name!r} has no gross_weight range")
    weight = ranges["gross_weight"]
    return weight.low - estimate_error, weight.high + estimate_error


def quantised_weight(file_weight: float, relative_change: float, step: float) -> float:
    """file_weight × (1 + relative_change rounded to ``step``): the one rounding every part of the system uses, so
    the planner caches keyed by the weight meet (0 gives exactly the file's weight)."""
    steps = round(relative_change / step)
    return file_weight if steps == 0 else file_weight * (1.0 + steps * step)


@dataclass(frozen=True)
class WeightSample:
    """One steady-flight reading: state stamp (ns), speed and climb rate (m/s), Ω (rad/s), engine power (W or None)."""

    stamp_ns: int
    forward_speed: float
    climb_rate: float
    rotor_speed: float
    engine_power: float | None


@dataclass(frozen=True)
class WeightChoice:
    """The gross weight to plan for.

    Attributes:
        gross_weight: N (quantised).
        source: ``estimate`` (from the current window), ``held`` (an earlier estimate, the flight is not steady
            now) or ``file`` (the airframe file's / the node's configured weight).
        relative_change: gross_weight / the file's − 1.
        reason: for ``held`` and ``file``, why not a current estimate ("" for ``estimate``).
        estimated_change: the last raw estimate's relative change (NaN: none), unquantised.
        stamp_ns: stamp of the newest sample of the estimate used (0 for ``file``).
    """

    gross_weight: float
    source: str
    relative_change: float
    reason: str = ""
    estimated_change: float = math.nan
    stamp_ns: int = 0


def ready_choice(choice: WeightChoice, file_weight: float, ready_weights: Collection[float]) -> WeightChoice:
    """``choice`` if its weight is among ``ready_weights`` (built in a solver), else the nearest ready weight
    (the file's weight is always ready), with the reason: a weight is never built in the failure path."""
    if choice.gross_weight in ready_weights or choice.gross_weight == file_weight:
        return choice
    nearest = min((*ready_weights, file_weight), key=lambda weight: abs(weight - choice.gross_weight))
    note = f"{100 * choice.relative_change:+.1f} % not built in a solver yet"
    return replace(
        choice,
        gross_weight=nearest,
        source="held" if nearest != file_weight else "file",
        relative_change=nearest / file_weight - 1.0,
        reason=f"{note}; {choice.reason}" if choice.reason else note,
    )


class WeightTracker:
    """Collects steady-flight samples and answers :meth:`choice` (module docstring).

    Args:
        airframe: the planner's model at the configured (file) weight.
        settings: the policy.
    """

    def __init__(self, airframe: Airframe, settings: WeightTrackingSettings | None = None) -> None:
        self.airframe = airframe
        self.settings = settings or WeightTrackingSettings()
        self._samples: deque[WeightSample] = deque()
        self._accepted: WeightChoice | None = None
        self._refusal: WeightChoice | None = None  # the last refused estimate (its reason outlives the window)

    def add(self, sample: WeightSample) -> bool:
        """Adds a reading; False (dropped) when out of order or not finite."""
        values = (sample.forward_speed, sample.climb_rate, sample.rotor_speed)
        power_ok = sample.engine_power is None or math.isfinite(sample.engine_power)
        if not (all(math.isfinite(value) for value in values) and power_ok):
            return False
        if self._samples and sample.stamp_ns <= self._samples[-1].stamp_ns:
            return False
        self._samples.append(sample)
        oldest_ns = sample.stamp_ns - int(self.settings.window_s * 1e9)
        while self._samples and self._samples[0].stamp_ns < oldest_ns:
            self._samples.popleft()
        return True

    def reset(self) -> None:
        """Forgets the samples and any estimate (e.g. another airframe)."""
        self._samples.clear()
        self._accepted = None
        self._refusal = None

    def _file(self, reason: str, estimated_change: float = math.nan) -> WeightChoice:
        return WeightChoice(self.airframe.gross_weight, "file", 0.0, reason, estimated_change)

    def _unsteady_reason(self, now_ns: int) -> str:
        """Why the current window cannot be used ("" when it can)."""
        settings, samples = self.settings, self._samples
        if len(samples) < settings.min_samples:
            return f"{len(samples)} steady-flight samples in {settings.window_s:g} s (need {settings.min_samples})"
        age_s = (now_ns - samples[-1].stamp_ns) * 1e-9
        if age_s > settings.max_sample_age_s:
            return f"newest sample {age_s:.2f} s old"
        if any(sample.engine_power is None for sample in samples):
            return "no engine power measured (rotor JointState without effort)"
        omega0 = self.airframe.nominal_rotor_speed
        if any(abs(sample.rotor_speed / omega0 - 1.0) > settings.rotor_speed_tolerance for sample in samples):
            return f"rotor speed not within {100 * settings.rotor_speed_tolerance:g} % of its governed speed"
        speeds = [sample.forward_speed for sample in samples]
        climbs = [sample.climb_rate for sample in samples]
        powers = [float(sample.engine_power or 0.0) for sample in samples]
        mean_power = sum(powers) / len(powers)
        if max(speeds) - min(speeds) > settings.max_speed_spread:
            return f"speed varies by {max(speeds) - min(speeds):.2f} m/s (not steady)"
        if max(climbs) - min(climbs) > settings.max_climb_rate_spread:
            return f"climb rate varies by {max(climbs) - min(climbs):.2f} m/s (not steady)"
        if mean_power <= 0.0 or (max(powers) - min(powers)) > settings.max_power_spread * mean_power:
            return "engine power not steady"
        return ""

    def choice(self, now_ns: int) -> WeightChoice:
        """The weight to plan for now: a current estimate, a held one, or the file's (with the reason)."""
        reason = self._unsteady_reason(now_ns)
        if not reason:
            samples = self._samples
            count = len(samples)
            speed = sum(sample.forward_speed for sample in samples) / count
            climb = sum(sample.climb_rate for sample in samples) / count
            power = sum(float(sample.engine_power or 0.0) for sample in samples) / count
            try:
                estimate = estimate_gross_weight(self.airframe, max(speed, 0.0), climb, power)
            except ValueError as error:
                return self._refused(f"no plausible weight explains the power ({error})")
            low, high = self.settings.band
            change = estimate.relative_change
            if not low <= change <= high:
                band = f"{100 * low:+.1f}…{100 * high:+.1f} %"
                return self._refused(f"estimate {100 * change:+.1f} % outside the plausible band {band}", change)
            weight = quantised_weight(self.airframe.gross_weight, change, self.settings.step)
            accepted = WeightChoice(
                weight, "estimate", weight / self.airframe.gross_weight - 1.0, "", change, samples[-1].stamp_ns
            )
            self._accepted, self._refusal = accepted, None
            return accepted
        return self._held_or_file(reason, now_ns)

    def _refused(self, reason: str, change: float = math.nan) -> WeightChoice:
        """An implausible estimate is not held over: the file's weight (a sound estimate earlier may be wrong now)."""
        self._accepted = None
        self._refusal = self._file(f"{reason}: planning for the file's weight", change)
        return self._refusal

    def _held_or_file(self, reason: str, now_ns: int) -> WeightChoice:
        accepted = self._accepted
        if accepted is not None:
            age_s = (now_ns - accepted.stamp_ns) * 1e-9
            if age_s <= self.settings.hold_s:
                return replace(accepted, source="held", reason=f"estimate from {age_s:.1f} s ago ({reason})")
            self._accepted = None
        if self._refusal is not None:  # the last estimate was refused: that is the reason that matters
            return replace(self._refusal, reason=f"{self._refusal.reason} ({reason} now)")
        return self._file(f"{reason}: planning for the file's weight", math.nan)
