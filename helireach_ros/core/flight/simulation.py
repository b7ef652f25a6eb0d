"""A simulated helicopter for closed-loop tests: the planner's model with a mismatch, noise and a scenario.

ROS-free; :mod:`helireach_ros.ros.nodes.sim_vehicle` wraps it in a node. The vehicle integrates the same
model the planner uses (:func:`~helireach_ros.core.aircraft.model.dynamics_function`, through the replay's CVODES
segment integrator), but with its own airframe — the nominal one with some parameters scaled by
``1 + fraction`` (the *parameter mismatch*) — so a plan made for the nominal airframe does not fly
exactly as predicted, which is what closed-loop re-planning has to absorb. Sensors add seeded
Gaussian noise.

Flight phases: ``cruise`` (level trim of the true airframe, the engine holds Ω₀), ``autorotation``
(from the failure time: engine power drops to ``power_fraction`` of trim power and decays with the
engine time constant; the vehicle follows the latest control schedule, holding the trim controls
until the first one arrives) and ``landed`` (ground contact, h = 0).

Touchdown is ground contact (h = 0). The landing met the limits when, at contact, the planner's
landing cost (:func:`~helireach_ros.core.ocp.transcription.base.terminal_cost`) J = max(|y|/y_max, |v|/v_max) − 1
is ≤ 0, and Ω stayed within its limits (plus the replay's margin) in flight: from the failure until
the vehicle entered the planner's touchdown set (J ≤ 0 with |h| ≤ h_tol, the paper's landing
conditions), after which the rotor's energy is no longer needed.

Control schedules are piecewise linear in time (``time_from_start`` points, values held outside);
:func:`piecewise_linear_controls` turns a plan's zero-order-hold controls into such points exactly
(two points per breakpoint), the same points the planner node publishes in a ``JointTrajectory``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from helireach_ros.core.aircraft.airframe import Airframe, ConfigError, load_airframe
from helireach_ros.core.aircraft.model import trim_level_flight
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.evidence.replay import segment_integrator, segment_parameters
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.ocp.transcription.base import terminal_cost
from helireach_ros.core.resources import config_path
from helireach_ros.core.units import FT, KT, UnitError, convert_to_si

__all__ = [
    "HOLD_STEP_S",
    "MISMATCH_PARAMETERS",
    "ControlSchedule",
    "Measurement",
    "Scenario",
    "SensorNoise",
    "SimulatedVehicle",
    "TouchdownReport",
    "load_scenario",
    "mismatched_airframe",
    "piecewise_linear_controls",
]

HOLD_STEP_S = 1e-6
"""Width of the step between the two points that encode a zero-order-hold breakpoint, s."""

MISMATCH_PARAMETERS = (
    "gross_weight",
    "rotor_radius",
    "rotor_solidity",
    "blade_drag_coefficient",
    "rotor_inertia",
    "horizontal_drag_area",
    "vertical_drag_area",
    "rotor_power_efficiency",
    "engine_time_constant",
)
"""Airframe parameters a scenario may perturb (fractions of the nominal value)."""

_SAMPLES_PER_SEGMENT = 4  # integrator outputs per segment, to locate ground contact by interpolation
_MAX_SEGMENT_S = 0.05  # long segments are split so contact is found within a few ms
_PHASES = ("cruise", "autorotation", "landed")


def piecewise_linear_controls(
    control_times: np.ndarray, control_values: np.ndarray, interpolation: str, hold_step: float = HOLD_STEP_S
) -> tuple[np.ndarray, np.ndarray]:
    """Points (t, u) whose linear interpolation reproduces a plan's control function.

    A zero-order hold with value uₖ on [tₖ, tₖ₊₁) becomes the points (tₖ, uₖ) and
    (tₖ₊₁ − δ, uₖ), δ = ``hold_step``, so any consumer that interpolates linearly between strictly
    increasing times flies the hold (the ramps last δ). Linear controls are returned as they are.

    Args:
        control_times: breakpoints, s (ascending).
        control_values: 2 × (n − 1) values per interval (zero-order hold) or 2 × n (linear).
        interpolation: ``"zero_order_hold"`` or ``"linear"``.
        hold_step: δ, s.

    Returns:
        (times, values 2 × len(times)), times strictly increasing.
    """
    breakpoints = np.asarray(control_times, dtype=float)
    values = np.asarray(control_values, dtype=float).reshape(2, -1)
    if interpolation == "linear":
        return breakpoints.copy(), values.copy()
    if interpolation != "zero_order_hold":
        raise ValueError(f"unknown control interpolation {interpolation!r}")
    times: list[float] = []
    points: list[np.ndarray] = []
    for k in range(values.shape[1]):
        start, end = float(breakpoints[k]), float(breakpoints[k + 1])
        if end - start <= 2.0 * hold_step:
            continue  # a degenerate interval: nothing to hold
        times.extend((start, end - hold_step))
        points.extend((values[:, k], values[:, k]))
    # The last value holds until the last breakpoint (and beyond, as every schedule does).
    times.append(float(breakpoints[-1]))
    points.append(points[-1] if points else values[:, -1])
    return np.asarray(times), np.asarray(points).T


@dataclass(frozen=True)
class ControlSchedule:
    """Controls (C_T, θ) to follow from a given vehicle time: linear between points, held outside.

    Attributes:
        start_time: vehicle time at which ``times`` start (the plan's initial state), s.
        times: time from start of each point, s (strictly increasing).
        values: 2 × len(times): C_T and θ (rad, positive nose down).
    """

    start_time: float
    times: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=float).reshape(-1)
        values = np.asarray(self.values, dtype=float).reshape(2, -1)
        if times.size == 0 or values.shape[1] != times.size:
            raise ValueError(f"a control schedule needs one (C_T, theta) per time, got {times.size} times")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(values)) and math.isfinite(self.start_time)):
            raise ValueError("a control schedule must be finite")
        if np.any(np.diff(times) <= 0.0):
            raise ValueError("control schedule times must be strictly increasing")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)

    @classmethod
    def from_plan(cls, plan: Any, start_time: float) -> ControlSchedule:
        """The schedule of a plan-like object (``control_times``, ``control_values``, ``control_interpolation``)."""
        times, values = piecewise_linear_controls(plan.control_times, plan.control_values, plan.control_interpolation)
        return cls(start_time, times, values)

    @property
    def end_time(self) -> float:
        """Vehicle time of the last point, s."""
        return self.start_time + float(self.times[-1])

    def at(self, time: float) -> np.ndarray:
        """(C_T, θ) at a vehicle time."""
        local = time - self.start_time
        return np.array([np.interp(local, self.times, row) for row in self.values])

    def breakpoints_between(self, start: float, end: float) -> np.ndarray:
        """Vehicle times of the points strictly inside (start, end)."""
        absolute = self.start_time + self.times
        return absolute[(absolute > start) & (absolute < end)]


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of the Gaussian sensor noise, SI (0 = exact)."""

    height: float = 0.0
    forward_speed: float = 0.0
    climb_rate: float = 0.0
    rotor_speed: float = 0.0


@dataclass(frozen=True)
class Scenario:
    """A simulated flight: trim at a height and speed, an engine failure at a time, what differs from the model.

    Attributes:
        name: identifier.
        description: one line for people.
        airframe: airframe name or file (the planner's nominal airframe).
        height: initial height above ground, m.
        forward_speed: initial forward speed, m/s.
        failure_time: time of the engine failure after the start, s.
        power_fraction: engine power left at the failure, fraction of trim power (0 = total loss).
        parameter_mismatch: the true vehicle's parameters are the nominal ones × (1 + fraction).
        noise: sensor noise.
        seed: seed of the noise generator.
        max_flight_time: give up (no touchdown) this long after the failure, s.
    """

    name: str
    description: str = ""
    airframe: str = "uh60a_class"
    height: float = 500.0 * FT
    forward_speed: float = 75.0 * KT
    failure_time: float = 3.0
    power_fraction: float = 0.0
    parameter_mismatch: Mapping[str, float] = field(default_factory=dict)
    noise: SensorNoise = SensorNoise()
    seed: int = 0
    max_flight_time: float = 60.0

    def __post_init__(self) -> None:
        problems = []
        if not (math.isfinite(self.height) and 0.0 <= self.height <= 5000.0):
            problems.append(f"height must lie in [0, 5000] m, got {self.height!r}")
        if not (math.isfinite(self.forward_speed) and 0.0 <= self.forward_speed <= 120.0):
            problems.append(f"forward_speed must lie in [0, 120] m/s, got {self.forward_speed!r}")
        if not (math.isfinite(self.failure_time) and 0.0 <= self.failure_time <= 3600.0):
            problems.append(f"failure_time must lie in [0, 3600] s, got {self.failure_time!r}")
        if not 0.0 <= self.power_fraction <= 1.0:
            problems.append(f"power_fraction must lie in [0, 1], got {self.power_fraction!r}")
        if not (math.isfinite(self.max_flight_time) and 1.0 <= self.max_flight_time <= 3600.0):
            problems.append(f"max_flight_time must lie in [1, 3600] s, got {self.max_flight_time!r}")
        for name, fraction in self.parameter_mismatch.items():
            if name not in MISMATCH_PARAMETERS:
                problems.append(
                    f"parameter_mismatch: unknown parameter {name!r} (one of {', '.join(MISMATCH_PARAMETERS)})"
                )
            elif not (isinstance(fraction, int | float) and -0.5 <= fraction <= 0.5):
                problems.append(f"parameter_mismatch.{name} must be a fraction in [-0.5, 0.5], got {fraction!r}")
        for name, value in dataclasses.asdict(self.noise).items():
            if not (math.isfinite(value) and value >= 0.0):
                problems.append(f"sensor_noise.{name} must be >= 0, got {value!r}")
        if problems:
            raise ConfigError(f"scenario {self.name!r}: " + "; ".join(problems))
        object.__setattr__(self, "parameter_mismatch", dict(self.parameter_mismatch))

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready, SI."""
        return dataclasses.asdict(self)


_SCENARIO_QUANTITIES = {  # key -> dimension of its {value, unit}
    "height": "length",
    "forward_speed": "speed",
    "failure_time": "time",
    "max_flight_time": "time",
}
_NOISE_QUANTITIES = {
    "height": "length",
    "forward_speed": "speed",
    "climb_rate": "speed",
    "rotor_speed": "angular_speed",
}


def _quantity(document: Mapping[str, Any], key: str, dimension: str, where: str) -> float:
    entry = document[key]
    if not (isinstance(entry, Mapping) and set(entry) <= {"value", "unit"} and {"value", "unit"} <= set(entry)):
        raise ConfigError(f"{where}{key} must be {{value: <number>, unit: <unit>}}, got {entry!r}")
    if isinstance(entry["value"], bool) or not isinstance(entry["value"], int | float):
        raise ConfigError(f"{where}{key}.value must be a number, got {entry['value']!r}")
    try:
        return convert_to_si(entry["value"], str(entry["unit"]), dimension)
    except UnitError as error:
        raise ConfigError(f"{where}{key}: {error}") from None


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Loads a scenario from ``config/scenarios/<name>.yaml`` or a file.

    Quantities are written ``{value, unit}`` (e.g. ``height: {value: 500, unit: ft}``) and converted
    to SI; unknown keys, wrong units and out-of-range values raise :class:`ConfigError` naming the file.
    """
    text = str(name_or_path)
    relative = text if text.endswith((".yaml", ".yml")) else f"scenarios/{text}.yaml"
    try:
        source = config_path(relative)
        document = yaml.safe_load(source.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise ConfigError(f"cannot read scenario {text!r}: {error}") from None
    where = f"{source}: "
    if not isinstance(document, dict):
        raise ConfigError(f"{where}a scenario must be a mapping")
    known = {"name", "description", "airframe", "power_fraction", "parameter_mismatch", "sensor_noise", "seed"}
    unknown = sorted(set(document) - known - set(_SCENARIO_QUANTITIES))
    if unknown:
        raise ConfigError(f"{where}unknown scenario key(s): {', '.join(unknown)}")
    fields: dict[str, Any] = {"name": str(document.get("name", source.stem))}
    for key in ("description", "airframe"):
        if key in document:
            fields[key] = str(document[key])
    for key, dimension in _SCENARIO_QUANTITIES.items():
        if key in document:
            fields[key] = _quantity(document, key, dimension, where)
    if "power_fraction" in document:
        fields["power_fraction"] = float(document["power_fraction"])
    if "seed" in document:
        if isinstance(document["seed"], bool) or not isinstance(document["seed"], int):
            raise ConfigError(f"{where}seed must be an integer, got {document['seed']!r}")
        fields["seed"] = document["seed"]
    mismatch = document.get("parameter_mismatch") or {}
    if not isinstance(mismatch, dict):
        raise ConfigError(f"{where}parameter_mismatch must map parameter names to fractions")
    fields["parameter_mismatch"] = mismatch
    noise = document.get("sensor_noise") or {}
    if not isinstance(noise, dict) or set(noise) - set(_NOISE_QUANTITIES):
        raise ConfigError(f"{where}sensor_noise may only hold {', '.join(_NOISE_QUANTITIES)} as {{value, unit}}")
    fields["noise"] = SensorNoise(
        **{
            key: _quantity(noise, key, dimension, where + "sensor_noise.")
            for key, dimension in _NOISE_QUANTITIES.items()
            if key in noise
        }
    )
    try:
        return Scenario(**fields)
    except ConfigError as error:
        raise ConfigError(f"{where}{error}") from None


def mismatched_airframe(airframe: Airframe, mismatch: Mapping[str, float]) -> Airframe:
    """The airframe with each named parameter multiplied by ``1 + fraction`` (name marked ``+mismatch``)."""
    if not mismatch:
        return airframe
    changes = {name: getattr(airframe, name) * (1.0 + fraction) for name, fraction in mismatch.items()}
    return dataclasses.replace(airframe, name=f"{airframe.name}+mismatch", **changes)


@dataclass(frozen=True)
class Measurement:
    """What the vehicle's sensors report (noisy), SI.

    Attributes:
        time: vehicle time, s.
        height: above ground, m.
        distance: along-track distance, m.
        forward_speed: m/s.
        climb_rate: m/s, positive up (= −descent rate).
        rotor_speed: Ω, rad/s.
        engine_power: W (exact: there is no power sensor model).
        pitch_angle: the commanded θ, rad (positive nose down).
        engine_failed: the engine-failure flag.
    """

    time: float
    height: float
    distance: float
    forward_speed: float
    climb_rate: float
    rotor_speed: float
    engine_power: float
    pitch_angle: float
    engine_failed: bool


@dataclass(frozen=True)
class TouchdownReport:
    """How the simulated vehicle met the ground.

    Attributes:
        time_after_failure: time of ground contact after the failure, s.
        descent_rate: y at contact, m/s. forward_speed: at contact over the ground (the airspeed v less the
            headwind: what the touchdown limit is about), m/s. rotor_speed: Ω at contact, rad/s.
        min_rotor_speed, max_rotor_speed: Ω range in flight (see the module docstring), rad/s.
        value: J at contact (≤ 0: within the touchdown limits; inf without a contact).
        rotor_speed_within_limits: Ω stayed within its limits (± the replay margin) until the touchdown set.
        within_limits: J ≤ 0 and the rotor speed stayed within limits.
        reason: a short explanation when not within limits.
        min_rotor_speed_to_contact: the lowest Ω until ground contact, rad/s (the cushion below the touchdown
            set included).
        rotor_held_to_contact: Ω stayed within its limits until ground contact (the replay's rule for flyable
            plans), not only until the touchdown set (|h| ≤ the height tolerance at the touchdown speeds).
    """

    time_after_failure: float
    descent_rate: float
    forward_speed: float
    rotor_speed: float
    min_rotor_speed: float
    max_rotor_speed: float
    value: float
    rotor_speed_within_limits: bool
    within_limits: bool
    reason: str = ""
    min_rotor_speed_to_contact: float = math.nan
    rotor_held_to_contact: bool = False

    @property
    def within_limits_to_contact(self) -> bool:
        """Within limits with the rotor judged until ground contact."""
        return self.within_limits and self.rotor_held_to_contact


class SimulatedVehicle:
    """The closed-loop vehicle: trim, failure, follow control schedules, detect touchdown.

    Args:
        scenario: the flight.
        airframe: the nominal airframe (default: ``scenario.airframe`` loaded); the vehicle flies it
            with ``scenario.parameter_mismatch`` applied.
        settings: planner settings (the replay tolerance, the rotor-speed margin, and the method: the touchdown judges
            the rotor by the rule of the plans flown, so ``flyable`` allows the touchdown rotor limit below the
            commit height).
        failure_state: start at the failure in this state (y, v, Ω, h, z, P, SI; P the power left) instead of
            level trim at the scenario's height and speed, e.g. a measured state a plan was made from; the
            scenario's ``failure_time`` must then be 0.
        failure_controls: (C_T, θ) held from that start until a schedule takes over (with ``failure_state``).
    """

    def __init__(
        self,
        scenario: Scenario,
        airframe: Airframe | None = None,
        settings: PlannerSettings | None = None,
        failure_state: np.ndarray | None = None,
        failure_controls: np.ndarray | None = None,
    ) -> None:
        self.scenario = scenario
        self.nominal_airframe = airframe if airframe is not None else load_airframe(scenario.airframe)
        self.airframe = mismatched_airframe(self.nominal_airframe, scenario.parameter_mismatch)
        self.settings = settings or PlannerSettings()
        self._integrator = segment_integrator(
            self.airframe, _SAMPLES_PER_SEGMENT, self.settings.replay_relative_tolerance
        )
        self._rng = np.random.default_rng(scenario.seed)
        # trimmed at its height: in ground effect the rotor needs less power there than out of it
        self.trim = trim_level_flight(self.airframe, scenario.forward_speed, scenario.height)
        self.time = 0.0
        self.state = np.array(
            [0.0, scenario.forward_speed, self.airframe.nominal_rotor_speed, scenario.height, 0.0, self.trim.power]
        )
        self.phase = "cruise"
        self.schedule: ControlSchedule | None = None
        self.touchdown: TouchdownReport | None = None
        self._held_controls = np.array([self.trim.thrust_coefficient, self.trim.pitch_angle])
        self._followed: list[tuple[float, ControlSchedule]] = []  # (time it was received, schedule), in order
        self._rotor_range = (math.inf, -math.inf)
        self._rotor_low_above_commit = math.inf  # flyable plans: the in-flight limit holds above the commit height
        self._rotor_low_to_contact = math.inf
        self._in_touchdown_set = False
        if failure_state is not None:
            self._start_at_failure(np.asarray(failure_state, float), failure_controls)
        self.history: list[tuple[float, np.ndarray]] = [(0.0, self.state.copy())]

    def _start_at_failure(self, state: np.ndarray, controls: np.ndarray | None) -> None:
        if self.scenario.failure_time != 0.0:
            raise ValueError("a vehicle started in a failure state needs the scenario's failure_time 0")
        if state.shape != (6,) or not np.all(np.isfinite(state)):
            raise ValueError(f"failure_state must be 6 finite numbers (y, v, Ω, h, z, P), got {state!r}")
        if controls is None or np.shape(controls) != (2,) or not np.all(np.isfinite(controls)):
            raise ValueError(f"failure_controls must be (C_T, θ), got {controls!r}")
        self.state = state.copy()
        self._held_controls = np.asarray(controls, float).copy()
        self.phase = "autorotation"
        self._note_sample(self.state)

    @property
    def engine_failed(self) -> bool:
        """True from the failure time on."""
        return self.phase != "cruise"

    @property
    def landed(self) -> bool:
        """Touched down (or gave up after ``max_flight_time``)."""
        return self.phase == "landed"

    def follow(self, schedule: ControlSchedule) -> None:
        """Follows this schedule from now on (the latest received plan wins)."""
        self.schedule = schedule
        self._followed.append((self.time, schedule))

    def flown_controls(self, time: float) -> np.ndarray:
        """(C_T, θ) the vehicle applied at a past (or the present) time: the schedule it was following then.

        :meth:`controls` answers for the schedule followed *now*, which for a time before it arrived is not
        what was flown (what a flight-control computer would record, and what a model-error estimate needs).
        """
        schedule = next((followed for since, followed in reversed(self._followed) if since <= time), None)
        if self.phase != "cruise" and schedule is not None and time >= schedule.start_time:
            return schedule.at(time)
        return self._held_controls

    def controls(self, time: float | None = None) -> np.ndarray:
        """(C_T, θ) the vehicle applies at a time (default: now)."""
        time = self.time if time is None else time
        if self.phase == "autorotation" and self.schedule is not None and time >= self.schedule.start_time:
            return self.schedule.at(time)
        return self._held_controls

    def advance(self, duration: float) -> None:
        """Advances the vehicle by ``duration`` seconds (no-op once landed)."""
        if not (math.isfinite(duration) and duration >= 0.0):
            raise ValueError(f"duration must be finite and >= 0, got {duration!r}")
        end = self.time + duration
        while self.phase != "landed" and self.time < end - 1e-12:
            if self.phase == "cruise":
                self._cruise_until(min(end, self.scenario.failure_time))
            else:
                self._autorotate_until(end)

    def _cruise_until(self, end: float) -> None:
        # Level trim is an equilibrium of the true airframe with the engine holding power: only z moves (over the
        # ground: the airspeed less the headwind)
        ground_speed = self.state[StateIndex.FORWARD_SPEED] - self.airframe.headwind
        self.state[StateIndex.DISTANCE] += ground_speed * (end - self.time)
        self.time = end
        if self.time >= self.scenario.failure_time:
            self.phase = "autorotation"
            self.state[StateIndex.ENGINE_POWER] = self.scenario.power_fraction * self.trim.power
            self._note_sample(self.state)
        self.history.append((self.time, self.state.copy()))

    def _autorotate_until(self, end: float) -> None:
        limit = self.scenario.failure_time + self.scenario.max_flight_time
        cuts = [min(end, limit)]
        if self.schedule is not None:
            cuts.extend(self.schedule.breakpoints_between(self.time, cuts[0]))
            if self.time < self.schedule.start_time < cuts[0]:
                cuts.append(self.schedule.start_time)
        for cut in sorted(cuts):
            while self.phase == "autorotation" and self.time < cut - 1e-12:
                self._segment(min(cut, self.time + _MAX_SEGMENT_S))
        if self.phase == "autorotation" and self.time >= limit - 1e-12:
            self._finish(f"no touchdown within {self.scenario.max_flight_time:.0f} s of the failure")

    def _segment(self, end: float) -> None:
        """Integrates to ``end`` with controls linear between their values at the ends; stops at ground contact."""
        start = self.time
        control_start = self.controls(start)
        control_end = self.controls(end - 1e-12) if self.schedule is not None else control_start
        parameters = segment_parameters(control_start, control_end, end - start)  # the true vehicle: no d
        try:
            outputs = np.asarray(self._integrator(x0=self.state, p=parameters)["xf"])
        except RuntimeError as error:
            self._finish(f"the vehicle model could not be integrated: {error}")
            return
        times = start + (end - start) * np.linspace(0.0, 1.0, outputs.shape[1] + 1)[1:]
        for time, state in zip(times, outputs.T, strict=True):
            if not np.all(np.isfinite(state)):
                self._finish("the vehicle state became non-finite")
                return
            if (
                state[StateIndex.HEIGHT] <= 0.0
            ):  # contact between the previous sample and this one: interpolate to h = 0
                fraction = self.state[StateIndex.HEIGHT] / (self.state[StateIndex.HEIGHT] - state[StateIndex.HEIGHT])
                self.time += fraction * (float(time) - self.time)
                self.state = self.state + fraction * (state - self.state)
                self.state[StateIndex.HEIGHT] = 0.0
                self._note_sample(self.state)
                self._finish("")
                return
            self.time, self.state = float(time), state.copy()
            self._note_sample(self.state)
        self.history.append((self.time, self.state.copy()))

    def _note_sample(self, state: np.ndarray) -> None:
        """Tracks Ω in flight: from the failure until the vehicle is in the touchdown set (J ≤ 0), and until contact."""
        self._rotor_low_to_contact = min(self._rotor_low_to_contact, float(state[StateIndex.ROTOR_SPEED]))
        if self._in_touchdown_set:
            return
        self._rotor_range = (
            min(self._rotor_range[0], float(state[StateIndex.ROTOR_SPEED])),
            max(self._rotor_range[1], float(state[StateIndex.ROTOR_SPEED])),
        )
        if state[StateIndex.HEIGHT] >= self.nominal_airframe.flyability.commit_height:
            self._rotor_low_above_commit = min(self._rotor_low_above_commit, float(state[StateIndex.ROTOR_SPEED]))
        self._in_touchdown_set = bool(terminal_cost(self.nominal_airframe, state) <= 0.0)

    def _finish(self, reason: str) -> None:
        limits = self.airframe.limits
        omega0 = self.nominal_airframe.nominal_rotor_speed
        margin = self.settings.rotor_speed_replay_margin * omega0
        low, high = self._rotor_range
        # flyable plans (the replay's rule): below the commit height the rotor may droop to the touchdown limit
        flyability = self.airframe.flyability
        flyable = self.settings.method == "flyable"
        low_limit = flyability.touchdown_min_rotor_speed_ratio if flyable else limits.min_rotor_speed_ratio
        rotor_ok = bool(
            low >= low_limit * omega0 - margin
            and self._rotor_low_above_commit >= limits.min_rotor_speed_ratio * omega0 - margin
            and high <= limits.max_rotor_speed_ratio * omega0 + margin
        )
        value = float(terminal_cost(self.nominal_airframe, self.state)) if not reason else math.inf
        ground_speed = float(self.state[StateIndex.FORWARD_SPEED] - self.nominal_airframe.headwind)
        if not reason and value > 0.0:
            reason = (
                f"touchdown at {self.state[StateIndex.DESCENT_RATE] / FT:.1f} ft/s and "
                f"{ground_speed / KT:.1f} kt exceeds the limits "
                f"({limits.max_descent_rate / FT:.1f} ft/s, {limits.max_forward_speed / KT:.1f} kt)"
            )
        if not reason and not rotor_ok:
            reason = f"rotor speed left its limits in flight ({100 * low / omega0:.1f}-{100 * high / omega0:.1f} %)"
        self.touchdown = TouchdownReport(
            time_after_failure=self.time - self.scenario.failure_time,
            descent_rate=float(self.state[StateIndex.DESCENT_RATE]),
            forward_speed=ground_speed,
            rotor_speed=float(self.state[StateIndex.ROTOR_SPEED]),
            min_rotor_speed=low,
            max_rotor_speed=high,
            value=value,
            rotor_speed_within_limits=rotor_ok,
            within_limits=not reason,
            reason=reason,
            min_rotor_speed_to_contact=self._rotor_low_to_contact,
            rotor_held_to_contact=rotor_ok and self._rotor_low_to_contact >= low_limit * omega0 - margin,
        )
        self.history.append((self.time, self.state.copy()))
        self.phase = "landed"
        self.state = self.state.copy()
        self.state[[0, 1]] = 0.0  # at rest on the ground from now on

    def measure(self) -> Measurement:
        """The sensors now: the true state plus seeded Gaussian noise (none once landed)."""
        noise = self.scenario.noise
        deviation = self._rng.standard_normal(4) * np.array(
            [noise.height, noise.forward_speed, noise.climb_rate, noise.rotor_speed]
        )
        if self.landed:
            deviation[:] = 0.0
        y, v, rotor_speed, height, distance, power = self.state
        return Measurement(
            time=self.time,
            height=float(height + deviation[0]),
            distance=float(distance),
            forward_speed=float(v + deviation[1]),
            climb_rate=float(-y + deviation[2]),
            rotor_speed=float(rotor_speed + deviation[3]),
            engine_power=max(float(power), 0.0),  # the decay integrates to tiny negatives
            pitch_angle=float(self.controls()[1]),
            engine_failed=self.engine_failed,
        )
