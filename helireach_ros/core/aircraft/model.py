"""The six-state helicopter model after power loss (Lee 1985; Kirchner et al. 2020, eq. 13), with a rotor model.

State x = (y, v, Ω, h, z, P): descent rate y (m/s, positive down), forward speed v (m/s), rotor
speed Ω (rad/s), height above ground h (m), distance z (m), engine power P (W).
Control u = (C_T, θ): thrust coefficient and pitch angle (rad, positive nose down, REP-103 FLU).

.. math::

    \\dot y &= g - \\frac{\\rho}{m} A (\\Omega R)^2 C_T \\cos\\theta - \\tfrac12 \\frac{\\rho}{m} f_{eh} V_f y \\\\
    \\dot v &= \\frac{\\rho}{m} A (\\Omega R)^2 C_T \\sin\\theta - \\tfrac12 \\frac{\\rho}{m} f_{ez} V_f v \\\\
    \\dot\\Omega &= \\frac{1}{I_R \\Omega}\\Big(P - \\frac{1}{\\eta} \\rho A (\\Omega R)^3 C_P\\Big), \\quad
        C_P = \\tfrac18 \\sigma c_d + C_T \\lambda, \\quad
        \\lambda = \\frac{v\\sin\\theta - y\\cos\\theta + \\nu}{\\Omega R}, \\quad \\nu = \\Omega R \\sqrt{C_T/2}
        \\ \\text{(the paper's rotor; the momentum rotor below)} \\\\
    \\dot h &= -y, \\quad \\dot z = v, \\quad \\dot P = -P/\\kappa

Deviations from the paper, on purpose:

* vertical drag opposes descent (``−½ρ f_eh V_f y / m``); the paper prints ``+``, a sign typo;
* √C_T, 1/Ω and V_f = √(y² + v²) use smooth guarded forms (below) so the NLP has finite
  derivatives at C_T = 0, Ω → 0 and V_f = 0; the guards change values by < 1e-6 relative in the
  flight envelope;
* the rotor's aerodynamics are the airframe's :class:`~helireach_ros.core.aircraft.inflow.RotorModel`: either the
  paper's hover induced velocity at every speed (its U_T defined but unused;
  :data:`~helireach_ros.core.aircraft.inflow.PAPER_ROTOR_MODEL`, what the shipped airframes and the ``paper`` method
  use), or momentum-theory induced velocity in forward flight, climb and descent with an empirical vortex-ring bridge,
  ground effect, an induced power factor and profile power that grows with the advance ratio
  (:mod:`~helireach_ros.core.aircraft.inflow`, :func:`_rotor_terms`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.inflow import (
    InflowModel,
    induced_velocity,
    momentum_inflow_ratio,
    momentum_root_residual,
)
from helireach_ros.core.aircraft.smooth import smooth_positive
from helireach_ros.core.aircraft.state_index import StateIndex

__all__ = [
    "CONTROL_NAMES",
    "DISTURBANCE_NAMES",
    "DISTURBANCE_UNITS",
    "NO_DISTURBANCE",
    "OUT_OF_GROUND_EFFECT",
    "STATE_NAMES",
    "STATE_UNITS",
    "HelicopterState",
    "TrimCondition",
    "clip_rotor_speed_noise",
    "disturbed_dynamics_function",
    "dynamics_function",
    "implicit_inflow_functions",
    "initial_state_after_failure",
    "smooth_positive",
    "state_from_sensors",
    "steady_autorotation",
    "trim_controls",
    "trim_flight",
    "trim_level_flight",
]

STATE_NAMES = ("descent_rate", "forward_speed", "rotor_speed", "height", "distance", "engine_power")


STATE_UNITS = ("m/s", "m/s", "rad/s", "m", "m", "W")
CONTROL_NAMES = ("thrust_coefficient", "pitch_angle")
DISTURBANCE_NAMES = ("descent_acceleration", "forward_acceleration", "rotor_acceleration")
"""What :func:`disturbed_dynamics_function` adds to ẏ, v̇ and Ω̇: the model's error as constant accelerations."""
DISTURBANCE_UNITS = ("m/s²", "m/s²", "rad/s²")
NO_DISTURBANCE = np.zeros(3)
NO_DISTURBANCE.flags.writeable = False
"""The model as it is (zero disturbance accelerations); read-only."""

_THRUST_GUARD = 1e-7  # C_T below which √C_T is smoothed (trim C_T is ~6e-3)
_SPEED_GUARD = 1e-2  # m/s added in quadrature to V_f
_ROTOR_GUARD_RATIO = 0.05  # 1/Ω smoothed below 5 % of Ω₀, far outside any rotor-speed limit


@dataclass(frozen=True)
class HelicopterState:
    """A state of the model in SI (see the module docstring for the conventions)."""

    descent_rate: float
    forward_speed: float
    rotor_speed: float
    height: float
    distance: float = 0.0
    engine_power: float = 0.0

    def as_array(self) -> np.ndarray:
        """The state vector (y, v, Ω, h, z, P)."""
        return np.array(
            [self.descent_rate, self.forward_speed, self.rotor_speed, self.height, self.distance, self.engine_power]
        )

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> HelicopterState:
        """A state from ``{name: value}`` in SI with the names of :data:`STATE_NAMES` (what ``plan --json`` prints
        as ``initial_state``); ``distance`` and ``engine_power`` may be left out (0).

        Raises:
            ValueError: an unknown or missing name, or a value that is not a finite number.
        """
        unknown = sorted(set(values) - set(STATE_NAMES))
        if unknown:
            raise ValueError(f"unknown state component(s) {unknown}; expected {list(STATE_NAMES)}")
        missing = [name for name in STATE_NAMES[:4] if name not in values]
        if missing:
            raise ValueError(f"state component(s) {missing} missing")
        components = []
        for name in STATE_NAMES:
            value = values.get(name, 0.0)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"state component {name!r} must be a finite number, got {value!r}")
            components.append(float(value))
        return cls(*components)

    @classmethod
    def from_array(cls, values) -> HelicopterState:
        """Builds a state from a length-6 vector."""
        array = np.asarray(values, dtype=float).reshape(-1)
        if array.size != 6:
            raise ValueError(f"a helicopter state has 6 components (y, v, Omega, h, z, P), got {array.size}")
        return cls(*(float(component) for component in array))


def _rotor_speeds(airframe: Airframe, state, control):
    """v_h = ΩR √(C_T/2) (C_T guarded), U_T and U_P: what the induced velocity depends on, m/s."""
    y, v, rotor_speed = state[StateIndex.DESCENT_RATE], state[StateIndex.FORWARD_SPEED], state[StateIndex.ROTOR_SPEED]
    thrust_coefficient, pitch = control[0], control[1]
    hover_induced_velocity = rotor_speed * airframe.rotor_radius * ca.sqrt(
        smooth_positive(thrust_coefficient, _THRUST_GUARD) / 2.0
    )
    edgewise_speed = v * ca.cos(pitch) + y * ca.sin(pitch)
    axial_speed = v * ca.sin(pitch) - y * ca.cos(pitch)
    return hover_induced_velocity, edgewise_speed, axial_speed


def _rotor_terms(airframe: Airframe, state, control, momentum_roots=None):
    """Thrust per unit mass and rotor power required (shared by dynamics and trim).

    With U_P = v sinθ − y cosθ the air speed down through the disk and U_T = v cosθ + y sinθ the one in its plane,
    ν the induced velocity of :mod:`~helireach_ros.core.aircraft.inflow`, κ the induced power factor and K the profile
    power's speed factor (:class:`~helireach_ros.core.aircraft.inflow.RotorModel`):

    .. math:: C_P = \\tfrac18 \\sigma c_d (1 + K \\mu^2) + C_T \\frac{U_P + \\kappa \\nu}{\\Omega R},
        \\quad \\mu = \\frac{U_T}{\\Omega R}.

    The paper's model (κ = 1, K = 0, ν = ΩR √(C_T/2)) is built as the paper writes it. ``momentum_roots``: see
    :func:`~helireach_ros.core.aircraft.inflow.induced_velocity`.
    """
    rotor_speed, height = state[StateIndex.ROTOR_SPEED], state[StateIndex.HEIGHT]
    thrust_coefficient = control[0]
    rotor_model = airframe.rotor_model
    density = airframe.air_density
    tip_speed = rotor_speed * airframe.rotor_radius
    thrust_per_mass = density / airframe.mass * airframe.disk_area * tip_speed**2 * thrust_coefficient
    # v_h from the shared tip-speed node, as before the rotor model existed: the paper's NLP keeps its exact
    # derivative expressions (its degenerate optima move with rounding otherwise)
    hover_induced_velocity = tip_speed * ca.sqrt(smooth_positive(thrust_coefficient, _THRUST_GUARD) / 2.0)
    guarded_tip_speed = smooth_positive(rotor_speed, _ROTOR_GUARD_RATIO * airframe.nominal_rotor_speed) * (
        airframe.rotor_radius
    )
    descent_rate, forward_speed = state[StateIndex.DESCENT_RATE], state[StateIndex.FORWARD_SPEED]
    axial_speed = forward_speed * ca.sin(control[1]) - descent_rate * ca.cos(control[1])
    profile = airframe.rotor_solidity * airframe.blade_drag_coefficient / 8.0
    if rotor_model.is_paper:
        inflow_ratio = (axial_speed + hover_induced_velocity) / guarded_tip_speed
        power_coefficient = profile + thrust_coefficient * inflow_ratio
    else:
        _, edgewise_speed, _ = _rotor_speeds(airframe, state, control)
        induced = induced_velocity(
            rotor_model,
            hover_induced_velocity=hover_induced_velocity,
            edgewise_speed=edgewise_speed,
            axial_speed=axial_speed,
            height=height,
            rotor_radius=airframe.rotor_radius,
            momentum_roots=momentum_roots,
        )
        advance_ratio = edgewise_speed / guarded_tip_speed
        induced_power_factor = rotor_model.effective_induced_power_factor
        power_coefficient = profile * (1.0 + rotor_model.effective_profile_power_speed_factor * advance_ratio**2) + (
            thrust_coefficient * (axial_speed + induced_power_factor * induced) / guarded_tip_speed
        )
    rotor_power = density * airframe.disk_area * tip_speed**3 * power_coefficient / airframe.rotor_power_efficiency
    return thrust_per_mass, rotor_power


def _fuselage_speed(y, v):
    return ca.sqrt(y**2 + v**2 + _SPEED_GUARD**2)


def _state_derivative(airframe: Airframe, state, control, momentum_roots=None):
    y, v, rotor_speed, _, _, power = (state[i] for i in range(6))
    pitch = control[1]
    drag_per_speed = 0.5 * airframe.air_density / airframe.mass * _fuselage_speed(y, v)
    thrust_per_mass, rotor_power = _rotor_terms(airframe, state, control, momentum_roots)
    guarded_rotor_speed = smooth_positive(rotor_speed, _ROTOR_GUARD_RATIO * airframe.nominal_rotor_speed)
    return ca.vertcat(
        airframe.gravity - thrust_per_mass * ca.cos(pitch) - drag_per_speed * airframe.vertical_drag_area * y,
        thrust_per_mass * ca.sin(pitch) - drag_per_speed * airframe.horizontal_drag_area * v,
        (power - rotor_power) / (airframe.rotor_inertia * guarded_rotor_speed),
        -y,
        v - airframe.headwind if airframe.headwind else v,  # over the ground (calm: the expression as before)
        -power / airframe.engine_time_constant,
    )


@lru_cache(maxsize=64)
def dynamics_function(airframe: Airframe) -> ca.Function:
    """The model as a CasADi function ``f(x[6], u[2]) -> xdot[6]``, built once per airframe.

    Every user of the model (NLP, replay, simulator, trim) calls this one function.
    """
    state = ca.SX.sym("x", 6)
    control = ca.SX.sym("u", 2)
    return ca.Function(
        "helicopter_dynamics", [state, control], [_state_derivative(airframe, state, control)], ["x", "u"], ["xdot"]
    )


@lru_cache(maxsize=64)
def disturbed_dynamics_function(airframe: Airframe) -> ca.Function:
    r"""The model plus constant disturbance accelerations, ``f(x[6], u[2], d[3]) -> xdot[6]``:

    .. math:: \dot x = f(x, u) + (d_y, d_v, d_\Omega, 0, 0, 0)

    d (:data:`DISTURBANCE_NAMES`) is what the closed loop learns of the model's error from the flight
    (:mod:`helireach_ros.core.estimation.disturbance`): a heavier aircraft sinks and spins its rotor up faster than
    the model says, and d carries the difference into the next plan. d = 0 is :func:`dynamics_function`.
    """
    state = ca.SX.sym("x", 6)
    control = ca.SX.sym("u", 2)
    disturbance = ca.SX.sym("d", 3)
    derivative = dynamics_function(airframe)(state, control) + ca.vertcat(disturbance, ca.DM.zeros(3))
    return ca.Function(
        "disturbed_helicopter_dynamics", [state, control, disturbance], [derivative], ["x", "u", "d"], ["xdot"]
    )


@lru_cache(maxsize=64)
def implicit_inflow_functions(airframe: Airframe) -> tuple[ca.Function, ca.Function, ca.Function]:
    r"""The momentum rotor with its two momentum roots as inputs, for an NLP that carries them as variables.

    Returns ``(dynamics, residuals, roots)``: ``dynamics(x[6], u[2], d[3], r[2]) -> xdot[6]`` is
    :func:`disturbed_dynamics_function` with r = (ν_G(U_T, U_P), ν_G(0, U_P)) in m/s given instead of found by
    Newton steps; ``residuals(x, u, r) -> [2]`` are :func:`~helireach_ros.core.aircraft.inflow.momentum_root_residual`
    over the hover v_h² (zero at the roots; O(1)); ``roots(x, u) -> r[2]`` are the Newton-step roots every other
    consumer uses (a consistent starting point). Equal to :func:`disturbed_dynamics_function` at the roots, to the
    Newton steps' accuracy.

    Raises:
        ValueError: the airframe has the paper's rotor (it has no momentum roots).
    """
    if airframe.rotor_model.inflow is not InflowModel.MOMENTUM:
        raise ValueError(f"{airframe.name} has the paper's rotor: no momentum roots to carry")
    state, control = ca.SX.sym("x", 6), ca.SX.sym("u", 2)
    disturbance, roots = ca.SX.sym("d", 3), ca.SX.sym("r", 2)
    derivative = _state_derivative(airframe, state, control, roots) + ca.vertcat(disturbance, ca.DM.zeros(3))
    hover, edgewise, axial = _rotor_speeds(airframe, state, control)
    hover_squared = airframe.gross_weight / (2.0 * airframe.air_density * airframe.disk_area)
    residuals = ca.vertcat(
        momentum_root_residual(roots[0], hover_induced_velocity=hover, edgewise_speed=edgewise, axial_speed=axial),
        momentum_root_residual(roots[1], hover_induced_velocity=hover, edgewise_speed=0.0, axial_speed=axial),
    ) / hover_squared
    found = hover * ca.vertcat(
        momentum_inflow_ratio(edgewise / hover, axial / hover), momentum_inflow_ratio(0.0, axial / hover)
    )
    return (
        ca.Function(
            "implicit_dynamics", [state, control, disturbance, roots], [derivative], ["x", "u", "d", "r"], ["xdot"]
        ),
        ca.Function("momentum_root_residuals", [state, control, roots], [residuals], ["x", "u", "r"], ["residual"]),
        ca.Function("momentum_roots", [state, control], [found], ["x", "u"], ["r"]),
    )


@dataclass(frozen=True)
class TrimCondition:
    """Steady, unaccelerated flight on a straight path at constant rotor speed (Ω = Ω₀).

    Attributes:
        forward_speed: m/s.
        thrust_coefficient: C_T.
        pitch_angle: θ, rad (positive nose down).
        power: engine power that holds Ω = Ω₀, W.
        climb_rate: m/s, positive up (0 = level flight; the model's descent rate y is −climb_rate).
    """

    forward_speed: float
    thrust_coefficient: float
    pitch_angle: float
    power: float
    climb_rate: float = 0.0


OUT_OF_GROUND_EFFECT = 1.0e3
"""m: a height at which the ground effect is negligible (k_G − 1 < 1e-4 for rotors up to 20 m): trims and steady
autorotations are computed there unless a height is given."""


def trim_flight(
    airframe: Airframe, forward_speed: float, climb_rate: float = 0.0, height: float = OUT_OF_GROUND_EFFECT
) -> TrimCondition:
    """Trims steady flight (ẏ = v̇ = Ω̇ = 0, Ω = Ω₀) at a forward speed and climb rate.

    With y = −climb_rate and D = ½ρ V_f the drag per unit speed and area (V_f = √(y² + v²), guarded as
    in the model), the thrust T and pitch θ balance weight and drag exactly as :func:`dynamics_function`
    computes them:

    .. math:: T\\cos\theta = W - D f_{eh}\\,y, \\qquad T\\sin\theta = D f_{ez}\\,v,

    and the engine supplies the rotor power that holds Ω₀ (:func:`dynamics_function`'s Ω̇ = 0) at ``height`` (m; the
    ground effect lowers the power near the ground, not the thrust and pitch).

    Raises:
        ValueError: a negative or non-finite speed, a non-finite climb rate, a trim needing C_T above the
            stall limit, or a descent so steep that the rotor would need negative engine power to hold Ω₀
            (it autorotates: no powered trim exists there).
    """
    if not np.isfinite(forward_speed) or forward_speed < 0.0:
        raise ValueError(f"forward speed must be finite and >= 0 m/s, got {forward_speed!r}")
    if not np.isfinite(climb_rate):
        raise ValueError(f"climb rate must be finite, got {climb_rate!r}")
    descent_rate = -float(climb_rate)
    drag_per_speed = float(0.5 * airframe.air_density * _fuselage_speed(descent_rate, forward_speed))
    vertical = airframe.gross_weight - drag_per_speed * airframe.vertical_drag_area * descent_rate
    horizontal = drag_per_speed * airframe.horizontal_drag_area * forward_speed
    if vertical <= 0.0:
        raise ValueError(f"a descent at {-climb_rate:.1f} m/s is faster than the fuselage's terminal descent")
    pitch = float(np.arctan2(horizontal, vertical))
    tip_speed = airframe.nominal_rotor_speed * airframe.rotor_radius
    dynamic_pressure_area = airframe.air_density * airframe.disk_area * tip_speed**2
    thrust_coefficient = float(np.hypot(vertical, horizontal) / dynamic_pressure_area)
    if thrust_coefficient > airframe.max_thrust_coefficient:
        raise ValueError(
            f"flight at {forward_speed:.1f} m/s, climb {climb_rate:.1f} m/s needs C_T = {thrust_coefficient:.4f}, "
            f"above the stall limit {airframe.max_thrust_coefficient:.4f}"
        )
    state = [descent_rate, forward_speed, airframe.nominal_rotor_speed, float(height), 0.0, 0.0]
    _, rotor_power = _rotor_terms(airframe, state, [thrust_coefficient, pitch])
    if float(rotor_power) < 0.0:
        raise ValueError(
            f"at {forward_speed:.1f} m/s and {-climb_rate:.1f} m/s descent the rotor autorotates "
            f"(needs {float(rotor_power) / 1e3:.0f} kW): no powered trim"
        )
    return TrimCondition(forward_speed, thrust_coefficient, pitch, float(rotor_power), float(climb_rate))


def trim_level_flight(
    airframe: Airframe, forward_speed: float, height: float = OUT_OF_GROUND_EFFECT
) -> TrimCondition:
    """Trims level flight (y = 0): :func:`trim_flight` at zero climb rate."""
    return trim_flight(airframe, forward_speed, 0.0, height)


def trim_controls(airframe: Airframe, state) -> np.ndarray:
    """The controls (C_T, θ) of steady flight at a state's forward speed and climb rate: what was flown before a
    failure from that state (the flyable plans start from them).

    Where no powered trim exists (a descent the rotor autorotates in, C_T beyond stall, v < 0), the level-flight
    trim at the same speed (clipped to ≥ 0) stands in: the nearest steady flight the aircraft could have been in.
    """
    state = np.asarray(state, dtype=float).reshape(-1)
    speed = max(float(state[StateIndex.FORWARD_SPEED]), 0.0)
    try:
        trim = trim_flight(airframe, speed, -float(state[StateIndex.DESCENT_RATE]))
    except ValueError:
        trim = trim_level_flight(airframe, speed)
    return np.array([trim.thrust_coefficient, trim.pitch_angle])


def initial_state_after_failure(
    airframe: Airframe,
    height: float,
    forward_speed: float,
    power_fraction: float = 0.0,
    climb_rate: float = 0.0,
    rotor_speed: float | None = None,
) -> HelicopterState:
    """The state at the instant of an engine failure from steady flight.

    Args:
        airframe: the helicopter.
        height: above ground, m.
        forward_speed: m/s.
        power_fraction: engine power left, as a fraction of the power the rotor absorbed in that
            flight (0 = total loss, the paper's case); it then decays with the engine time constant κ.
        climb_rate: m/s, positive up (0 = level trim, the default); the flight is trimmed on that path.
        rotor_speed: rad/s at the failure (None = Ω₀, the trim's).
    """
    if not 0.0 <= power_fraction <= 1.0:
        raise ValueError(f"power fraction must lie in [0, 1], got {power_fraction!r}")
    if not np.isfinite(height):
        raise ValueError(f"height must be finite, got {height!r}")
    if rotor_speed is not None and not (np.isfinite(rotor_speed) and rotor_speed > 0.0):
        raise ValueError(f"rotor speed must be finite and > 0 rad/s, got {rotor_speed!r}")
    trim = trim_flight(airframe, forward_speed, climb_rate, max(float(height), 0.0))
    omega = airframe.nominal_rotor_speed if rotor_speed is None else float(rotor_speed)
    return HelicopterState(-trim.climb_rate, forward_speed, omega, height, 0.0, power_fraction * trim.power)


def state_from_sensors(
    height: float,
    forward_speed: float,
    climb_rate: float,
    rotor_speed: float,
    distance: float = 0.0,
    engine_power: float = 0.0,
) -> np.ndarray:
    """The model state (y, v, Ω, h, z, P) from sensor readings, SI; y = −climb rate.

    Negative heights and powers (sensor noise near zero) count as 0.
    """
    return np.array(
        [-climb_rate, forward_speed, rotor_speed, max(height, 0.0), distance, max(engine_power, 0.0)], dtype=float
    )


def clip_rotor_speed_noise(airframe: Airframe, rotor_speed: float, tolerance_ratio: float = 0.01) -> float:
    """A measured rotor speed with sensor noise across a rotor-speed limit taken back to the limit.

    Noise can put Ω a hair outside its limits, where the landing NLP has no solution at all; only
    ``tolerance_ratio`` × Ω₀ beyond a limit is clipped. A rotor truly outside its limits is returned
    as measured (no safe plan exists): clipping it inside would plan with rotor energy the aircraft
    does not have.
    """
    limits, omega0 = airframe.limits, airframe.nominal_rotor_speed
    low, high = limits.min_rotor_speed_ratio * omega0, limits.max_rotor_speed_ratio * omega0
    tolerance = tolerance_ratio * omega0
    if low - tolerance <= rotor_speed < low:
        return low
    if high < rotor_speed <= high + tolerance:
        return high
    return rotor_speed


def steady_autorotation(
    airframe: Airframe, forward_speed: float, height: float = OUT_OF_GROUND_EFFECT
) -> tuple[float, float, float]:
    """Finds the steady power-off descent (ẏ = v̇ = Ω̇ = 0 at Ω = Ω₀, P = 0) at a forward speed (out of ground
    effect unless a height in m is given).

    Returns:
        (descent rate y in m/s, thrust coefficient C_T, pitch angle θ in rad).
    """
    unknowns = ca.SX.sym("w", 3)  # y, C_T, θ
    state = ca.vertcat(unknowns[0], forward_speed, airframe.nominal_rotor_speed, height, 0.0, 0.0)
    derivative = dynamics_function(airframe)(state, ca.vertcat(unknowns[1], unknowns[2]))
    residual = ca.Function("autorotation_residual", [unknowns], [derivative[:3]])
    solver = ca.rootfinder("steady_autorotation", "newton", residual, {"abstol": 1e-12})
    hover = trim_level_flight(airframe, 0.0)
    solution = np.asarray(solver(ca.DM([15.0, hover.thrust_coefficient, 0.0]))).reshape(-1)
    return float(solution[0]), float(solution[1]), float(solution[2])
