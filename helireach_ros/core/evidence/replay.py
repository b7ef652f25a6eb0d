"""Independent replay of a landing plan: integrate the model with the plan's controls.

A collocation solution satisfies the dynamics only at its points; between them — above all in the
flare — the real trajectory under the same controls can differ (the paper's own settings call 81 %
of unsafe-in-replay states safe). This module integrates the model from the initial state with the
plan's control function using CVODES (adaptive Adams, tight tolerances), a method that shares
nothing with the collocation scheme but the model, and judges the landing on that trajectory:

* the path ends at the plan's landing time, or earlier where it meets h = −ground_clearance (the
  ground: a real vehicle does not continue below it); the state at that crossing, interpolated
  between the dense samples that straddle it, is part of the path;
* the replayed value is the smallest J along the path up to that end (sampled densely);
* the landing is within limits when that value is ≤ 0 and the rotor speed stayed within its
  true limits until then (the NLP keeps a back-off from them at its nodes).

Flyable plans (``method: flyable``) are judged **at ground contact**, as a real landing is: the last
control is held after the plan's end (for up to :data:`CONTACT_SEARCH_S`) until the path meets the
ground; the value is J of the state at contact, the rotor must stay within its limits until then (below the
commit height: the airframe's touchdown rotor limit), and the
flown control function and path must meet the airframe's flyability limits
(:func:`~helireach_ros.core.evidence.flyability.check_flyability`). A path that never meets the ground does not land.

The model is not stiff over the flight envelope, so CVODES runs its Adams method with functional
iteration (30 % faster than BDF here, same result to 1e-5); should it fail, the replay judges the
part it integrated, which cannot make a plan look better.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.model import NO_DISTURBANCE, STATE_NAMES, disturbed_dynamics_function
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.evidence.flyability import FlyabilityReport, check_flyability
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.ocp.transcription.base import DecodedPlan, terminal_cost

__all__ = [
    "CONTACT_SEARCH_S",
    "NOT_REPLAYED",
    "ReplaySummary",
    "StoredControls",
    "control_function",
    "not_replayed",
    "replay_controls",
    "replay_plan",
    "replay_remainder",
    "segment_integrator",
    "segment_parameters",
]

CONTACT_SEARCH_S = 10.0  # s a flyable plan's last control is held after its end, looking for ground contact
_CONTACT_PIECE_S = 0.25  # s per integrated piece of that search


@dataclass(frozen=True)
class ReplaySummary:
    """The outcome of integrating a plan's controls through the model.

    Attributes:
        value: the smallest J along the replayed path (≤ 0: a safe touchdown happened).
        lands_within_limits: value ≤ 0 and the rotor speed within its limits up to that moment.
        touchdown_time: time of the best touchdown moment (argmin of J), s.
        touchdown_state: the replayed state then (SI).
        ground_contact_time: when the path met h = −ground_clearance (interpolated), or None if it
            had not by the plan's landing time; the replayed path (``times``, ``states``) ends there.
        rotor_speed_within_limits: Ω stayed within its limits (± margin) up to touchdown.
        max_deviation: per state, the largest |replay − plan| at the plan's nodes (SI).
        times: the dense replay times, s.
        states: the dense replayed states, 6 × len(times).
        flyability: rates, attitudes, touchdown attitude and commit-height climb of the flown controls and
            path (always measured).
        judged_at_contact: the landing was judged at ground contact and needs ``flyability`` within limits
            (flyable plans); otherwise the paper's rule (best J along the path) and flyability is reported only.
        replayed: False for a plan that was not integrated (:func:`not_replayed`): the numbers are NaN and it
            does not land.
    """

    value: float
    lands_within_limits: bool
    touchdown_time: float
    touchdown_state: np.ndarray
    ground_contact_time: float | None
    rotor_speed_within_limits: bool
    max_deviation: dict[str, float]
    times: np.ndarray
    states: np.ndarray
    flyability: FlyabilityReport
    judged_at_contact: bool
    replayed: bool = True


NOT_REPLAYED = "not replayed: the NLP found no landing, which no replay can change"


def not_replayed(settings: PlannerSettings, initial_state: np.ndarray) -> ReplaySummary:
    """The summary of a plan that is not integrated, because its NLP already answers ``failed`` or ``unsafe``
    and a replay only ever confirms a landing (:meth:`~helireach_ros.core.planning.planner.LandingPlanner.plan` with
    ``replay_not_safe=False``, the envelope's sweep): NaN numbers, no landing, the reason as the violation."""
    nan = float("nan")
    state = np.asarray(initial_state, dtype=float)[:6]
    return ReplaySummary(
        value=nan,
        lands_within_limits=False,
        touchdown_time=nan,
        touchdown_state=np.full(6, nan),
        ground_contact_time=None,
        rotor_speed_within_limits=False,
        max_deviation={name: nan for name in STATE_NAMES},
        times=np.zeros(1),
        states=state[:, None].copy(),
        flyability=FlyabilityReport(nan, nan, nan, nan, None, nan, (NOT_REPLAYED,)),
        judged_at_contact=settings.method == "flyable",
        replayed=False,
    )


def control_function(control_times: np.ndarray, control_values: np.ndarray, interpolation: str, times) -> np.ndarray:
    """A plan's controls at the given times (2 × len(times)); held constant outside the plan.

    Args:
        control_times: the breakpoints, s.
        control_values: 2 × n; per interval (``"zero_order_hold"``) or per breakpoint (``"linear"``).
        interpolation: ``"zero_order_hold"`` or ``"linear"``.
        times: where to evaluate, s.
    """
    times = np.atleast_1d(np.asarray(times, dtype=float))
    if interpolation == "zero_order_hold":
        index = np.searchsorted(control_times, times, side="right") - 1
        return control_values[:, np.clip(index, 0, control_values.shape[1] - 1)]
    return np.vstack([np.interp(times, control_times, row) for row in control_values])


@lru_cache(maxsize=16)
def segment_integrator(airframe: Airframe, samples: int, relative_tolerance: float) -> ca.Function:
    """CVODES over one control segment in normalised time σ ∈ [0, 1], outputs at ``samples`` points.

    Parameters p = (u_start[2], u_end[2], duration, d[3]) (:func:`segment_parameters`): the control varies
    linearly over the segment (constant when u_start = u_end), dx/dσ = duration · f(x, u(σ), d), with d the
    disturbance accelerations of :func:`~helireach_ros.core.aircraft.model.disturbed_dynamics_function` (0: the model).
    """
    state = ca.SX.sym("x", 6)
    parameters = ca.SX.sym("p", 8)
    sigma = ca.SX.sym("t")
    control = parameters[0:2] + sigma * (parameters[2:4] - parameters[0:2])
    ode = parameters[4] * disturbed_dynamics_function(airframe)(state, control, parameters[5:8])
    grid = np.linspace(0.0, 1.0, samples + 1)[1:]
    options: dict[str, Any] = {
        "reltol": relative_tolerance,
        "abstol": relative_tolerance * 1e-2,
        "max_num_steps": 100000,
        "linear_multistep_method": "adams",
        "nonlinear_solver_iteration": "functional",
    }
    return ca.integrator("replay_segment", "cvodes", {"x": state, "p": parameters, "t": sigma, "ode": ode}, 0.0,
                         grid, options)  # fmt: skip


def segment_parameters(
    control_start: np.ndarray, control_end: np.ndarray, duration: float, disturbance: np.ndarray | None = None
) -> np.ndarray:
    """The parameter vector of a :func:`segment_integrator` segment (``disturbance`` None: the model as it is)."""
    disturbance = NO_DISTURBANCE if disturbance is None else disturbance
    return np.concatenate([control_start, control_end, [duration], disturbance])


def _segments(plan: DecodedPlan, hold_after: float = 0.0) -> list[tuple[float, float, np.ndarray, np.ndarray]]:
    """(start, end, control at start, control at end) for each piece of the control function, plus ``hold_after``
    seconds of the last control after the plan's end."""
    breakpoints = plan.control_times
    pieces = []
    for k in range(len(breakpoints) - 1):
        start, end = float(breakpoints[k]), float(breakpoints[k + 1])
        if end - start <= 1e-9:
            continue
        if plan.control_interpolation == "zero_order_hold":
            value = plan.control_values[:, k]
            pieces.append((start, end, value, value))
        else:
            pieces.append((start, end, plan.control_values[:, k], plan.control_values[:, k + 1]))
    last = control_function(plan.control_times, plan.control_values, plan.control_interpolation, [plan.time_to_land])
    last = last[:, 0]
    if breakpoints[-1] < plan.time_to_land - 1e-9:
        pieces.append((float(breakpoints[-1]), plan.time_to_land, last, last))
    if hold_after > 0.0:
        end = max(plan.time_to_land, float(breakpoints[-1]))
        # short pieces: the replay stops after the first one that meets the ground, and the contact state is
        # interpolated between samples ~30 ms apart
        starts = end + np.arange(0.0, hold_after, _CONTACT_PIECE_S)
        stops = np.minimum(starts + _CONTACT_PIECE_S, end + hold_after)
        pieces.extend((float(start), float(stop), last, last) for start, stop in zip(starts, stops, strict=True))
    return pieces


def _flown_controls(plan: DecodedPlan, end_time: float) -> tuple[np.ndarray, np.ndarray]:
    """The control function's breakpoints and values from 0 to ``end_time`` (the value there included)."""
    inside = plan.control_times[plan.control_times < end_time - 1e-9]
    times = np.append(inside, end_time)
    if plan.control_interpolation == "zero_order_hold":
        count = len(inside)
        return times, plan.control_values[:, : max(count, 1)]
    return times, control_function(plan.control_times, plan.control_values, "linear", times)


def replay_controls(
    airframe: Airframe,
    settings: PlannerSettings,
    initial_state: np.ndarray,
    plan: object,
    disturbance: np.ndarray | None = None,
) -> ReplaySummary:
    """:func:`replay_plan` for a control function alone (a stored plan, or a plan's rounded copy): ``plan`` has
    ``control_times``, ``control_values``, ``control_interpolation`` and ``time_to_land``; with no NLP states to
    compare, ``max_deviation`` is measured at the start only."""
    start = np.asarray(initial_state, dtype=float)[:6]
    decoded = DecodedPlan(
        float(plan.time_to_land),  # type: ignore[attr-defined]
        np.zeros(1),
        start[:, None],
        np.asarray(plan.control_times, dtype=float),  # type: ignore[attr-defined]
        np.asarray(plan.control_values, dtype=float),  # type: ignore[attr-defined]
        str(plan.control_interpolation),  # type: ignore[attr-defined]
        np.zeros(1),
        start[:, None],
    )
    return replay_plan(airframe, settings, start, decoded, disturbance)


@dataclass(frozen=True)
class StoredControls:
    """A control function alone, as :func:`replay_controls` reads it."""

    control_times: np.ndarray
    control_values: np.ndarray
    control_interpolation: str
    time_to_land: float


def replay_remainder(
    airframe: Airframe,
    settings: PlannerSettings,
    plan: Any,
    elapsed_s: float,
    state: np.ndarray,
    disturbance: np.ndarray | None = None,
) -> ReplaySummary:
    """The rest of a plan flown from a later measured state: its control function from ``elapsed_s`` on (the
    control there included, times shifted to start at 0) replayed from ``state``, as :func:`replay_controls` judges
    a landing. ``plan`` has ``control_times``, ``control_values``, ``control_interpolation`` and ``time_to_land``.

    What the closed loop needs to compare a re-plan with the plan being flown: both from the same measured state,
    in the same model and disturbance. A plan already past its end flies its last control (the replay's contact
    search holds it).
    """
    times = np.asarray(plan.control_times, dtype=float)
    values = np.asarray(plan.control_values, dtype=float)
    elapsed = min(max(float(elapsed_s), 0.0), float(times[-1]))
    later = times > elapsed + 1e-9
    if str(plan.control_interpolation) == "zero_order_hold":
        # piece k holds values[:, k] on [times[k], times[k + 1]); the piece flown at ``elapsed`` comes first
        piece = min(int(np.searchsorted(times, elapsed, side="right")) - 1, values.shape[1] - 1)
        remaining_values = values[:, max(piece, 0) :]
        remaining_times = np.concatenate([[elapsed], times[later]])[: remaining_values.shape[1] + 1]
    else:
        now = control_function(times, values, "linear", np.array([elapsed]))
        remaining_times = np.concatenate([[elapsed], times[later]])
        remaining_values = np.column_stack([now, values[:, later]])
    rest = StoredControls(
        remaining_times - elapsed,
        remaining_values,
        str(plan.control_interpolation),
        max(float(plan.time_to_land) - elapsed, float(remaining_times[-1] - elapsed)),
    )
    return replay_controls(airframe, settings, state, rest, disturbance)


def replay_plan(
    airframe: Airframe,
    settings: PlannerSettings,
    initial_state: np.ndarray,
    plan: DecodedPlan,
    disturbance: np.ndarray | None = None,
) -> ReplaySummary:
    """Integrates the plan's controls from the initial state and judges the landing.

    Args:
        airframe: the model's parameters (the same the plan was made for).
        settings: replay tolerances.
        initial_state: the state at the failure (6, SI).
        plan: the decoded NLP solution.
        disturbance: the disturbance accelerations the plan was made for (None: the model as it is).
    """
    integrator = segment_integrator(airframe, settings.replay_samples_per_interval, settings.replay_relative_tolerance)
    state = np.asarray(initial_state, dtype=float)[:6]
    times, states = [0.0], [state]
    clearance = airframe.limits.ground_clearance
    at_contact = settings.method == "flyable"
    for start, end, control_start, control_end in _segments(plan, CONTACT_SEARCH_S if at_contact else 0.0):
        parameters = segment_parameters(control_start, control_end, end - start, disturbance)
        try:
            outputs = np.asarray(integrator(x0=state, p=parameters)["xf"])
        except RuntimeError:
            break  # the integrator gave up (e.g. stiff blow-up): judge what was integrated
        grid = start + (end - start) * np.linspace(0.0, 1.0, outputs.shape[1] + 1)[1:]
        times.extend(grid.tolist())
        states.extend(outputs.T)
        state = outputs[:, -1]
        if state[StateIndex.HEIGHT] < -clearance or not np.all(np.isfinite(state)):
            break
    times_array = np.asarray(times)
    states_array = np.asarray(states).T

    below = np.flatnonzero(states_array[3] < -clearance)
    ground_contact_time = None
    if below.size:
        # The path ends where it meets the ground; the state at that crossing, interpolated between the
        # samples that straddle it, is the touchdown and is judged with the samples before it.
        first = int(below[0])
        if first > 0:
            before, after = states_array[:, first - 1], states_array[:, first]
            fraction = (before[3] + clearance) / (before[3] - after[3])
            contact_time = times_array[first - 1] + fraction * (times_array[first] - times_array[first - 1])
            times_array = np.append(times_array[:first], contact_time)
            states_array = np.column_stack([states_array[:, :first], before + fraction * (after - before)])
        else:  # started below the ground: nothing to fly
            times_array, states_array = times_array[:1], states_array[:, :1]
        ground_contact_time = float(times_array[-1])
    costs = terminal_cost(airframe, states_array)
    # at contact: the state there (or, without contact, the end of the search, which cannot land)
    best = len(costs) - 1 if at_contact else int(np.argmin(costs))
    value = float(costs[best])
    flown_times, flown_values = _flown_controls(plan, float(times_array[best]))
    touchdown_pitch = None
    if ground_contact_time is not None and best == len(costs) - 1:
        touchdown_pitch = float(flown_values[1, -1])
    flyability = check_flyability(
        airframe, flown_times, flown_values, plan.control_interpolation, states_array[3, : best + 1], touchdown_pitch
    )

    omega0 = airframe.nominal_rotor_speed
    margin = settings.rotor_speed_replay_margin * omega0
    rotor = states_array[2, : best + 1]
    low = np.full(rotor.shape, airframe.limits.min_rotor_speed_ratio)
    if at_contact:  # flyable: the touchdown limit below the commit height
        low[states_array[3, : best + 1] < airframe.flyability.commit_height] = (
            airframe.flyability.touchdown_min_rotor_speed_ratio
        )
    rotor_ok = bool(
        np.all(rotor >= low * omega0 - margin)
        and np.all(rotor <= airframe.limits.max_rotor_speed_ratio * omega0 + margin)
    )
    deviation = _node_deviation(times_array, states_array, plan)
    lands = bool(value <= 0.0 and rotor_ok and np.isfinite(value))
    if at_contact:
        lands = lands and ground_contact_time is not None and flyability.within_limits
    return ReplaySummary(
        value=value,
        lands_within_limits=lands,
        touchdown_time=float(times_array[best]),
        touchdown_state=states_array[:, best].copy(),
        ground_contact_time=ground_contact_time,
        rotor_speed_within_limits=rotor_ok,
        max_deviation=deviation,
        times=times_array,
        states=states_array,
        flyability=flyability,
        judged_at_contact=at_contact,
    )


def _node_deviation(times: np.ndarray, states: np.ndarray, plan: DecodedPlan) -> dict[str, float]:
    """Largest |replay − plan| per state at the plan's nodes inside the replayed span."""
    inside = plan.node_times <= times[-1] + 1e-9
    if not np.any(inside):
        return {name: float("nan") for name in STATE_NAMES}
    replayed = np.vstack([np.interp(plan.node_times[inside], times, row) for row in states])
    difference = np.abs(replayed - plan.node_states[:, inside]).max(axis=1)
    return {name: float(value) for name, value in zip(STATE_NAMES, difference, strict=True)}
