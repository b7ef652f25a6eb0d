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

**Windowed estimate** (``window`` W ≥ 1; off by default). Each interval k implies a disturbance of its own,

.. math:: s_k = \\hat d_k + \\frac{(x_{meas} - x_{pred})_{y, v, \\Omega}}{\\Delta t},

what d̂_k plus that interval's error per second says; the filter above is the exponentially weighted mean of
these, d̂ ← d̂ + g (s_k − d̂). The windowed estimate is their plain mean over the last W valid intervals (over all of
them until there are W: an expanding mean with a cap, assumed), clipped to
:data:`~helireach_ros.core.planning.planner.MAX_DISTURBANCE`,

.. math:: \\hat d = \\operatorname{clip}\\Big(\\frac{1}{W}\\sum_{j=k-W+1}^{k} s_j\\Big),

the least-squares estimate of a constant from the last W samples, i.e. a finite-memory (limited-memory) estimate
that forgets what is older than W Δt (Jazwinski 1968, "Limited memory optimal filtering", IEEE Trans. Autom.
Control 13(5); Jazwinski 1970, *Stochastic Processes and Filtering Theory*). The prediction is made with the
current d̂_k and d̂_k is added back: the disturbance learnt within one interval falls ~5 % short (the drag and
inflow damp it), and this way that shortfall multiplies d − d̂_k, not d, so the fixed point is the true d (a
prediction with d = 0 would leave the mean ~5 % short).

Why it passes on less sensor noise (state gain 1, the prediction starting from the measurement z_k = x_k + n_k):
to first order s_k = d + (n_{k+1} − n_k) / Δt − A n_k, with A the model's Jacobian in the measured states. The
difference terms telescope in the mean, leaving (n_k − n_{k−W}) / (W Δt): std σ√2 / (W Δt), falling as 1/W. The
filter's weights do not sum the differences away: its std from them is g √(2 / (2 − g)) σ / Δt (0.33 σ / Δt at
g = 0.3). The window beats the filter by g W / √(2 − g) (0.23 W at g = 0.3: W = 4 about the same, W = 8 ≈ 1.8×,
W = 16 ≈ 3.7×); the A n_k part falls only as 1/√W against √(g / (2 − g)). The price is lag: a change of the
model's error (the drag error grows as v², the flare changes the rotor's load) is followed over W Δt, against
~Δt / g for the filter. With a state gain below 1 the prediction starts from x̂, not z_k, and the telescoping
argument does not hold; the windowed mean still applies (assumed useful, not measured).

The plans made for d̂ are judged by their replay in the same disturbed model: ``safe`` then means "safe in
the model corrected by what this flight has shown", which is what the plan is flown in.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from numbers import Integral
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
        window: W, the number of intervals the windowed estimate averages (see the module docstring: d̂ is the
            mean of the last W intervals' implied disturbances, ``gain`` unused); None or 0: the exponential filter
            of gain g (the default, as before).
    """

    gain: float = 0.3
    state_gain: float = 1.0
    relative_tolerance: float = 1e-6
    window: int | None = None

    def __post_init__(self) -> None:
        for name in ("gain", "state_gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 < value <= 1.0):
                raise ValueError(f"{name} must lie in (0, 1], got {value!r}")
        if self.window is not None and (
            isinstance(self.window, bool) or not isinstance(self.window, Integral) or self.window < 0
        ):
            raise ValueError(f"window must be None or an integer >= 0 (0: no window), got {self.window!r}")

    @property
    def windowed(self) -> bool:
        """Whether d̂ is the windowed mean (``window`` ≥ 1) rather than the exponential filter."""
        return bool(self.window)


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

    Raises:
        ValueError: a non-positive duration, or windowed ``settings`` (that estimate needs the earlier intervals:
            :class:`DisturbanceTracker` keeps them).
    """
    settings = settings or DisturbanceSettings()
    if settings.windowed:
        raise ValueError("the windowed estimate needs the earlier intervals: use DisturbanceTracker")
    estimate = np.asarray(estimate, dtype=float).reshape(3)
    error, filtered = _prediction_error(
        airframe, estimate, previous_state, measured_state, controls_at, start_time, duration, settings
    )
    if error is None:
        return IntervalEstimate(estimate, filtered)
    learnt = np.clip(estimate + settings.gain * error / duration, -MAX_DISTURBANCE, MAX_DISTURBANCE)
    return IntervalEstimate(learnt, filtered)


def _prediction_error(
    airframe: Airframe,
    estimate: np.ndarray,
    previous_state: np.ndarray,
    measured_state: np.ndarray,
    controls_at: Callable[[float], np.ndarray],
    start_time: float,
    duration: float,
    settings: DisturbanceSettings,
) -> tuple[np.ndarray | None, np.ndarray]:
    """(z − x_pred)_{y, v, Ω}, one interval's prediction error with d̂, and x̂ at its end; None for the error (and
    the measurement as x̂) where the prediction cannot be made."""
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be > 0, got {duration!r}")
    measured = np.asarray(measured_state, dtype=float)[:6]
    if not (np.all(np.isfinite(previous_state[:6])) and np.all(np.isfinite(measured))):
        return None, measured.copy()
    try:
        predicted = predict_state(
            airframe, previous_state, controls_at, start_time, duration, estimate, settings.relative_tolerance
        )
    except RuntimeError:
        return None, measured.copy()
    error = measured - predicted
    filtered = measured.copy()
    filtered[:_MEASURED] -= (1.0 - settings.state_gain) * error[:_MEASURED]  # x̂⁻ + α (z − x̂⁻); z exactly at α = 1
    return error[:3], filtered


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
        # the windowed estimate's implied disturbances s_k, the latest last (valid intervals only)
        self._implied: deque[np.ndarray] = deque(maxlen=self.settings.window or 1)

    @property
    def state(self) -> np.ndarray | None:
        """x̂, the filtered state at the latest measurement (SI, 6; the measurement itself with ``state_gain``
        1); None before the first."""
        return None if self._previous is None else self._previous[1].copy()

    def update(self, time: float, state: np.ndarray, controls_at: Callable[[float], np.ndarray]) -> np.ndarray:
        """Takes the measurement at ``time`` (s) and the controls flown since the previous one; returns d̂.

        The first measurement of a descent only starts the interval; one not later than the previous one (a
        repeated or out-of-order stamp) is ignored. With a ``window``, an interval whose prediction cannot be made
        (a non-finite state or prediction, an integrator failure) adds nothing to the window and leaves d̂ as it was.
        """
        measured = np.asarray(state, dtype=float)[:6].copy()
        if self._previous is None:
            self._previous = (time, measured)
        elif time > self._previous[0]:
            start, previous = self._previous
            if self.settings.windowed:
                error, filtered = _prediction_error(
                    self.airframe, self.estimate, previous, measured, controls_at, start, time - start, self.settings
                )
                implied = None if error is None else self.estimate + error / (time - start)  # s_k
                if implied is not None and np.all(np.isfinite(implied)):
                    self._implied.append(implied)
                    mean = np.mean(np.asarray(self._implied), axis=0)
                    self.estimate = np.clip(mean, -MAX_DISTURBANCE, MAX_DISTURBANCE)
            else:
                self.estimate, filtered = observe_interval(
                    self.airframe, self.estimate, previous, measured, controls_at, start, time - start, self.settings
                )
            self._previous = (time, filtered)
        return self.estimate.copy()

    def reset(self) -> None:
        """A new descent: nothing learnt yet."""
        self.estimate = np.zeros(3)
        self._previous = None
        self._implied.clear()
