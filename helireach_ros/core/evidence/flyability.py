"""Whether a replayed landing is one a helicopter can fly: control rates, attitudes, touchdown attitude, no skims.

The replay (:mod:`helireach_ros.core.evidence.replay`) integrates a plan's control function through the model;
this module judges that function and the integrated path against the airframe's
:class:`~helireach_ros.core.aircraft.airframe.FlyabilityLimits`, as strictly as the landing limits:

* **rates**: the largest |dC_T/dt| and |dθ/dt| of the control function (a piecewise-linear function's
  slopes; a step of a zero-order hold is an infinite rate);
* **attitude**: −θ_up ≤ θ ≤ θ_down and 0 ≤ C_T ≤ C_T,max wherever the function is flown (linear pieces
  take their extremes at the breakpoints);
* **touchdown attitude**: θ at ground contact inside the window; no contact, no landing;
* **no ground skims**: once the path is below the commit height it may not climb again: the largest rise
  of h above its running minimum from that moment on is at most :data:`COMMIT_CLIMB_TOLERANCE`.

Numbers are compared with a relative tolerance of 1e-6 (the NLP's constraints hold to its tolerance,
1e-7): a plan that uses a limit exactly passes, one that exceeds it does not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe

__all__ = ["COMMIT_CLIMB_TOLERANCE", "FlyabilityReport", "check_flyability"]

COMMIT_CLIMB_TOLERANCE = 0.03  # m (0.1 ft): below the commit height, the most the path may rise again
_RELATIVE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class FlyabilityReport:
    """What a replayed plan asks of the aircraft, and which flyability limits it breaks.

    Attributes:
        max_collective_rate: largest |dC_T/dt|, 1/s (inf for a step).
        max_pitch_rate: largest |dθ/dt|, rad/s (inf for a step).
        max_nose_up_pitch: largest nose-up attitude flown (−min θ), rad.
        max_nose_down_pitch: largest nose-down attitude flown (max θ), rad.
        touchdown_pitch: θ at ground contact, rad (None: the path never met the ground).
        commit_climb: the largest rise of h after the path first went below the commit height, m.
        violations: one line per broken limit (empty: flyable).
    """

    max_collective_rate: float
    max_pitch_rate: float
    max_nose_up_pitch: float
    max_nose_down_pitch: float
    touchdown_pitch: float | None
    commit_climb: float
    violations: tuple[str, ...]

    @property
    def within_limits(self) -> bool:
        """No flyability limit is broken."""
        return not self.violations

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, in pilot units (deg, deg/s, ft) beside the SI collective rate."""

        def degrees(value: float | None) -> float | None:
            return None if value is None else math.degrees(value)

        return {
            "within_limits": self.within_limits,
            "violations": list(self.violations),
            "max_collective_rate_per_s": self.max_collective_rate,
            "max_pitch_rate_deg_s": degrees(self.max_pitch_rate),
            "max_nose_up_pitch_deg": degrees(self.max_nose_up_pitch),
            "max_nose_down_pitch_deg": degrees(self.max_nose_down_pitch),
            "touchdown_pitch_deg": degrees(self.touchdown_pitch),
            "commit_climb_ft": self.commit_climb / 0.3048,
        }


def _exceeds(value: float, limit: float) -> bool:
    return value > limit * (1.0 + _RELATIVE_TOLERANCE) + 1e-12


def _largest_rates(control_times: np.ndarray, control_values: np.ndarray, interpolation: str) -> np.ndarray:
    if control_values.shape[1] < 2:
        return np.zeros(2)
    if interpolation == "zero_order_hold":
        steps = np.abs(np.diff(control_values, axis=1)).max(axis=1)
        return np.where(steps > 0.0, np.inf, 0.0)
    durations = np.diff(control_times)
    keep = durations > 1e-9
    if not np.any(keep):
        return np.zeros(2)
    slopes = np.abs(np.diff(control_values, axis=1)[:, keep]) / durations[keep]
    return slopes.max(axis=1)


def check_flyability(
    airframe: Airframe,
    control_times: np.ndarray,
    control_values: np.ndarray,
    interpolation: str,
    path_heights: np.ndarray,
    touchdown_pitch: float | None,
) -> FlyabilityReport:
    """Judges a control function and the heights of its replayed path against the flyability limits.

    Args:
        airframe: its ``flyability`` limits and the stall limit of C_T.
        control_times, control_values, interpolation: the control function flown (see
            :func:`~helireach_ros.core.evidence.replay.control_function`), up to contact.
        path_heights: h along the replayed path up to contact, m.
        touchdown_pitch: θ at ground contact, rad, or None when the path never met the ground.
    """
    limits = airframe.flyability
    values = np.asarray(control_values, dtype=float)
    rates = _largest_rates(np.asarray(control_times, dtype=float), values, interpolation)
    collective_rate, pitch_rate = float(rates[0]), float(rates[1])
    nose_up, nose_down = float(-values[1].min()), float(values[1].max())
    heights = np.asarray(path_heights, dtype=float)
    below = np.flatnonzero(heights < limits.commit_height)
    commit_climb = 0.0
    if below.size:
        after = heights[below[0] :]
        commit_climb = float(np.max(after - np.minimum.accumulate(after)))

    violations = []
    if _exceeds(collective_rate, airframe.max_thrust_coefficient_rate):
        violations.append(
            f"collective rate {collective_rate:.4g}/s above {airframe.max_thrust_coefficient_rate:.4g}/s "
            f"(full travel in {limits.collective_full_travel_time:g} s)"
        )
    if _exceeds(pitch_rate, limits.max_pitch_rate):
        violations.append(
            f"pitch rate {math.degrees(pitch_rate):.1f} deg/s above {math.degrees(limits.max_pitch_rate):.1f} deg/s"
        )
    if _exceeds(nose_up, limits.max_nose_up_pitch):
        violations.append(
            f"nose-up attitude {math.degrees(nose_up):.1f} deg above {math.degrees(limits.max_nose_up_pitch):.1f} deg"
        )
    if _exceeds(nose_down, limits.max_nose_down_pitch):
        violations.append(
            f"nose-down attitude {math.degrees(nose_down):.1f} deg above "
            f"{math.degrees(limits.max_nose_down_pitch):.1f} deg"
        )
    stall = airframe.max_thrust_coefficient
    if values[0].min() < -_RELATIVE_TOLERANCE * stall or _exceeds(float(values[0].max()), stall):
        violations.append("C_T outside [0, stall limit]")
    if touchdown_pitch is None:
        violations.append("no ground contact")
    elif _exceeds(-touchdown_pitch, limits.touchdown_max_nose_up_pitch) or _exceeds(
        touchdown_pitch, limits.touchdown_max_nose_down_pitch
    ):
        violations.append(
            f"touchdown attitude {math.degrees(-touchdown_pitch):+.1f} deg nose-up outside "
            f"[-{math.degrees(limits.touchdown_max_nose_down_pitch):.0f}, "
            f"{math.degrees(limits.touchdown_max_nose_up_pitch):.0f}] deg"
        )
    if commit_climb > COMMIT_CLIMB_TOLERANCE:
        violations.append(
            f"climbs {commit_climb / 0.3048:.2f} ft after going below the commit height "
            f"({limits.commit_height / 0.3048:.0f} ft): a ground skim or zoom"
        )
    return FlyabilityReport(
        collective_rate, pitch_rate, nose_up, nose_down, touchdown_pitch, commit_climb, tuple(violations)
    )
