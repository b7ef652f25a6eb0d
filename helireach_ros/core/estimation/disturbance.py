"""What the flight says about the model's error: disturbance accelerations for the next plan.

Between two re-plans the closed loop knows where the vehicle was, which controls it flew, and where it is
now. Integrating the planner's model over that interval from the earlier measurement, with the controls
flown and the current estimate d̂, predicts the later one; the difference is the part of the motion the
model missed. As constant accelerations on ẏ, v̇ and Ω̇
(:func:`~helireach_ros.core.aircraft.model.disturbed_dynamics_function`), with Δt the interval:

.. math:: \\hat d \\leftarrow \\operatorname{clip}\\Big(\\hat d
          + g\\,\\frac{(x_{meas} - x_{pred})_{y, v, \\Omega}}{\\Delta t}\\Big)

a first-order filter of gain g ∈ (0, 1] (offset-free model-predictive control: the next plan is made for
the model plus d̂, so a constant error is learnt instead of re-discovered at every re-plan). A heavier
aircraft than the model's sinks faster and spins its rotor up faster in the flare; without d̂ every
re-plan expects the rotor to stop where the model says and is wrong by the same amount again, until the
rotor reaches its limit and no plan is feasible (measured in :mod:`helireach_ros.core.robustness.verification`'s
corners). Sensor noise enters d̂ as σ√2 / Δt, damped by g; the estimate is clipped to
:data:`~helireach_ros.core.planning.planner.MAX_DISTURBANCE`.

**Filtered state.** With a state gain α < 1 the tracker is an α–β observer (Kalata 1984; the steady-state
Kalman filter of a measured quantity and its constant rate): the prediction starts from the previous *estimate*
x̂ rather than the previous measurement, and each measurement z corrects both,

.. math:: \\hat x \\leftarrow \\hat x^- + \\alpha\\,(z - \\hat x^-), \\qquad
          \\hat d \\leftarrow \\hat d + g\\,\\frac{(z - \\hat x^-)_{y, v, \\Omega}}{\\Delta t},

so sensor noise no longer enters d̂ twice per interval and the next plan starts from x̂ instead of a raw sample.
α = 1 is the plain filter above (x̂ = z).

The plans made for d̂ are judged by their replay in the same disturbed model: ``safe`` then means "safe in
the model corrected by what this flight has shown", which is what the plan is flown in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.evidence.replay import segment_integrator, segment_parameters
from helireach_ros.core.planning.planner import MAX_DISTURBANCE

__all__ = ["DisturbanceSettings", "DisturbanceTracker", "IntervalEstimate", "observe_interval", "predict_state"]

_PREDICTION_SEGMENTS = 5  # the flown control is sampled at 6 times over the interval, linear in between
_PREDICTION_SAMPLES = 2
_MEASURED = 5  # y, v, Ω, h, z are measured and filtered; the energy state P is not (the planner's input keeps it)


@dataclass(frozen=True)
class DisturbanceSettings:
    """How the closed loop learns the model's error.

    Attributes:
        gain: g, the fraction of each interval's prediction error taken into the estimate (1: the last
            interval's error alone; smaller: averaged over ~1/g intervals, less sensor noise). 0.3 by measurement
            (``bench/monte_carlo.py --policies disturbance --disturbance-gain G``; docs/method/envelopes.md).
        state_gain: α, the fraction of each prediction error taken into the state estimate the next plan starts
            from (1: the measurement itself; smaller: an α–β observer, less sensor noise in both estimates).
        relative_tolerance: of the prediction's integrator.
    """

    gain: float = 0.3
    state_gain: float = 1.0
    relative_tolerance: float = 1e-6

    def __post_init__(self) -> None:
        for name in ("gain", "state_gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 < value <= 1.0):
                raise ValueError(f"{name} must lie in (0, 1], got {value!r}")


def predict_state(
    airframe: Airframe,
    state: np.ndarray,
    controls_at: Callable[[float], np.ndarray],
    start_time: float,
    duration: float,
    disturbance: np.ndarray,
    relative_tolerance: float = 1e-6,
) -> np.ndarray:
    """The model's state ``duration`` s after ``state``, flying ``controls_at(t)`` from ``start_time`` on.

    The control is sampled at the ends of :data:`_PREDICTION_SEGMENTS` equal sub-intervals and taken as
    linear in between (the flyable plans' controls are piecewise linear; a plan switch inside a
    sub-interval is smoothed over it).
    """
    integrator = segment_integrator(airframe, _PREDICTION_SAMPLES, relative_tolerance)
    current = np.asarray(state, dtype=float)[:6].copy()
    step = duration / _PREDICTION_SEGMENTS
    for index in range(_PREDICTION_SEGMENTS):
        begin = start_time + index * step
        parameters = segment_parameters(controls_at(begin), controls_at(begin + step), step, disturbance)
        current = np.asarray(integrator(x0=current, p=parameters)["xf"])[:, -1]
    return current


class IntervalEstimate(NamedTuple):
    """What one re-planning interval teaches: d̂ and the filtered state x̂ at its end (SI, 6)."""

    disturbance: np.ndarray
    state: np.ndarray


def observe_interval(
    airframe: Airframe,
    estimate: np.ndarray,
    previous_state: np.ndarray,
    measured_state: np.ndarray,
    controls_at: Callable[[float], np.ndarray],
    start_time: float,
    duration: float,
    settings: DisturbanceSettings | None = None,
) -> IntervalEstimate:
    """d̂ and x̂ after one interval (see the module docstring).

    Args:
        airframe: the planner's model.
        estimate: d̂ before the interval (3,).
        previous_state: x̂ at ``start_time`` (6, SI; the measurement itself with a state gain of 1).
        measured_state: the measured state ``duration`` s later.
        controls_at: the controls flown, as a function of time.
        start_time: s.
        duration: s, > 0.

    Returns:
        The new estimates; where the prediction cannot be made (a non-finite state, an integrator failure) the
        old d̂, so a bad interval never makes it worse than it was, and the measurement as x̂.
    """
    settings = settings or DisturbanceSettings()
    estimate = np.asarray(estimate, dtype=float).reshape(3)
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be > 0, got {duration!r}")
    measured = np.asarray(measured_state, dtype=float)[:6]
    if not (np.all(np.isfinite(previous_state[:6])) and np.all(np.isfinite(measured))):
        return IntervalEstimate(estimate, measured.copy())
    try:
        predicted = predict_state(
            airframe, previous_state, controls_at, start_time, duration, estimate, settings.relative_tolerance
        )
    except RuntimeError:
        return IntervalEstimate(estimate, measured.copy())
    error = measured - predicted
    filtered = measured.copy()
    filtered[:_MEASURED] -= (1.0 - settings.state_gain) * error[:_MEASURED]  # x̂⁻ + α (z − x̂⁻); z exactly at α = 1
    learnt = np.clip(estimate + settings.gain * error[:3] / duration, -MAX_DISTURBANCE, MAX_DISTURBANCE)
    return IntervalEstimate(learnt, filtered)


class DisturbanceTracker:
    """The estimate d̂ of one descent, fed with each re-planning tick's measurement (the planner node's and the
    lock-step closed loop's policy alike); with ``state_gain`` < 1 also the filtered state x̂ the next plan starts
    from (see the module docstring).

    Args:
        airframe: the planner's model.
        settings: the filter.
    """

    def __init__(self, airframe: Airframe, settings: DisturbanceSettings | None = None) -> None:
        self.airframe = airframe
        self.settings = settings or DisturbanceSettings()
        self.estimate = np.zeros(3)
        self._previous: tuple[float, np.ndarray] | None = None

    @property
    def state(self) -> np.ndarray | None:
        """x̂, the filtered state at the latest measurement (SI, 6; the measurement itself with ``state_gain``
        1); None before the first."""
        return None if self._previous is None else self._previous[1].copy()

    def update(self, time: float, state: np.ndarray, controls_at: Callable[[float], np.ndarray]) -> np.ndarray:
        """Takes the measurement at ``time`` (s) and the controls flown since the previous one; returns d̂.

        The first measurement of a descent only starts the interval; one not later than the previous one (a
        repeated or out-of-order stamp) is ignored.
        """
        measured = np.asarray(state, dtype=float)[:6].copy()
        if self._previous is None:
            self._previous = (time, measured)
        elif time > self._previous[0]:
            start, previous = self._previous
            self.estimate, filtered = observe_interval(
                self.airframe, self.estimate, previous, measured, controls_at, start, time - start, self.settings
            )
            self._previous = (time, filtered)
        return self.estimate.copy()

    def reset(self) -> None:
        """A new descent: nothing learnt yet."""
        self.estimate = np.zeros(3)
        self._previous = None
