"""The rotor's induced velocity: momentum theory in every flight state, bridged through the vortex ring, with ground
effect; or the paper's hover value.

Speeds are normalised by the hover induced velocity of the current thrust, v_h = ΩR √(C_T/2) = √(T / 2ρA):
x = U_P / v_h is the axial (through-disk) speed, positive for flow down through the disk (climb), and
μ̂ = U_T / v_h the edgewise (in-plane) speed. The induced velocity is ν = v_h · ν̂(μ̂, x) · k_G.

**Momentum theory** (Glauert; Johnson, *Helicopter Theory*, 1980, §4.1; Leishman, *Principles of Helicopter
Aerodynamics*, 2nd ed., 2006, §2.14 and §3.3) holds in climb, in forward flight and in fast descent:

.. math:: \\hat\\nu_G = \\frac{1}{\\sqrt{\\hat\\mu^2 + (x + \\hat\\nu_G)^2}},

giving ν → T / (2ρAV) at high speed. In axial descent between x ≈ 0 and x ≈ −2 (the vortex-ring and
turbulent-wake states) momentum theory has no valid solution and the equation has several roots.

**Axial descent** follows the empirical curve fitted to the measured data by Leishman (2006, §2.14.4, after Castles
& Gray 1951 and Washizu et al. 1966):

.. math:: \\kappa_f \\hat\\nu_A = \\kappa_f + k_1 x + k_2 x^2 + k_3 x^3 + k_4 x^4, \\quad -2 \\le x \\le 0,

with κ_f = 1.15, k₁ = −1.125, k₂ = −1.372, k₃ = −1.718, k₄ = −0.655. The fit measures the *effective*
induced velocity (it holds the rotor's induced losses, κ_f at hover), so it is divided by κ_f here and the
induced power factor κ (:class:`RotorModel`) multiplies the ideal value in the power, at every speed. Above
x = 0 the axial curve is momentum theory's climb branch, below x ≈ −2.05 the windmill-brake branch
ν̂ = −x/2 − √(x²/4 − 1); the three pieces are joined by smooth steps 0.03 wide in x (the quartic and the
windmill branch cross at x = −2.051). The ideal autorotation (x + ν̂ = 0) then lies at x = −1.74, where
Leishman puts it at about −1.71.

**Forward flight** is momentum theory times the axial curve's excess over momentum theory in axial flight, faded
out as the edgewise speed grows, since the vortex ring cannot form once the wake is blown clear of the disk (its
boundaries lie below μ̂ ≈ 1 in the data that Johnson, NASA TP-2005-213477, 2005, reviews):

.. math:: \\hat\\nu = \\hat\\nu_G(\\hat\\mu, x) \\Big(\\frac{\\hat\\nu_A(x)}{\\hat\\nu_G(0, x)}\\Big)^{w},
    \\qquad w = e^{-\\hat\\mu^4},

so that it is the axial curve at μ̂ = 0, momentum theory at μ̂ ≳ 1.5 (w < 0.01), and in between momentum theory
with the share w of the vortex ring's measured excess (at x = −0.5, where the excess is 6 %, it stays within a few
per cent of momentum theory at every speed).

So that the momentum root is unique and smooth in every state (the NLP needs one smooth branch), it is taken
with the edgewise speed raised in descent, μ̂² + 5/32 min(x, 0)² (a quarter above x²/8, where the
momentum equation starts to have three roots): at μ̂ ≥ 1.5, where w < 0.01, this changes ν̂ by < 2 % in the
glide of an autorotation (1.9 % at μ̂ = 2, x = −1; 0.3 % at μ̂ = 4, x = −0.8), and it makes fast descents at low
speed follow the windmill branch (within 6 %).
The root is found by a fixed number of Newton steps from the exact hover root at the raised speed, so the NLP,
the replay and the simulator evaluate one smooth closed-form function (relative error < 2e-4 anywhere).

**Ground effect** (Cheeseman & Bennett, ARC R&M 3021, 1955) at rotor height z above the ground (z = h + the hub
height above the landing gear):

.. math:: k_G = 1 - \\Big(\\frac{R}{4z}\\Big)^2 \\frac{1}{1 + (U_T/\\nu)^2},

the ratio of the induced velocity in ground effect to the one out of it at equal thrust (T_IGE/T_OGE = 1/k_G at
equal power: 4/3 at z/R = 0.5, 1.016 at z/R = 2). Below z/R = 0.45, where the image method overpredicts the
measured effect (Leishman 2006, §5.6), z is held at 0.45 R (smoothly), which never overstates it.

**The paper's model** (Kirchner et al. 2020, after Lee 1985) uses ν = v_h at every speed, no ground effect,
κ = 1 and profile power independent of speed: :data:`PAPER_ROTOR_MODEL`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import casadi as ca

from helireach_ros.core.aircraft.smooth import smooth_positive

__all__ = [
    "GROUND_EFFECT_MIN_HEIGHT_RATIO",
    "LEISHMAN_QUARTIC",
    "NEWTON_STEPS",
    "PAPER_ROTOR_MODEL",
    "InflowModel",
    "RotorModel",
    "axial_inflow_ratio",
    "ground_effect_factor",
    "induced_velocity",
    "inflow_ratio",
    "inflow_ratio_from_roots",
    "momentum_inflow_ratio",
    "momentum_root_residual",
]


class InflowModel(StrEnum):
    """How the induced velocity is computed."""

    MOMENTUM = "momentum"
    """Momentum theory in every flight state with the empirical vortex-ring bridge (this module), the induced
    power factor and the profile power's speed factor of :class:`RotorModel`."""
    PAPER_HOVER = "paper_hover"
    """The paper's rotor: the hover induced velocity at every speed, ideal induced power (κ = 1) and profile power
    independent of speed (K = 0), whatever :class:`RotorModel`'s factors say."""


@dataclass(frozen=True)
class RotorModel:
    """The rotor aerodynamics beyond the paper's point-mass model (the airframe file's ``rotor_model`` section).

    Attributes:
        inflow: the induced-velocity model.
        ground_effect: whether the induced velocity is reduced near the ground (needs ``hub_height``).
        induced_power_factor: κ, induced power over ideal momentum-theory induced power (1 = ideal); momentum
            inflow only.
        profile_power_speed_factor: K in C_P0 = σ c_d / 8 · (1 + K μ²), μ = U_T / ΩR; momentum inflow only.
        hub_height: rotor hub above the bottom of the landing gear, m (None: unknown; no ground effect).
    """

    inflow: InflowModel = InflowModel.MOMENTUM
    ground_effect: bool = True
    induced_power_factor: float = 1.15
    profile_power_speed_factor: float = 4.65
    hub_height: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "inflow", InflowModel(self.inflow))  # a name given as text becomes the enum
        if self.ground_effect and self.hub_height is None:
            raise ValueError("ground effect needs the rotor hub height above the landing gear")
        if not 1.0 <= self.induced_power_factor <= 2.0:
            raise ValueError(f"induced power factor must lie in [1, 2], got {self.induced_power_factor!r}")
        if not 0.0 <= self.profile_power_speed_factor <= 10.0:
            raise ValueError(f"profile power speed factor must lie in [0, 10], got {self.profile_power_speed_factor!r}")
        if self.hub_height is not None and not 0.1 <= self.hub_height <= 20.0:
            raise ValueError(f"hub height must lie in [0.1, 20] m, got {self.hub_height!r}")

    @property
    def is_paper(self) -> bool:
        """True for the paper's rotor: hover inflow without ground effect (the factors do not apply to it)."""
        return self.inflow is InflowModel.PAPER_HOVER and not self.ground_effect

    @property
    def effective_induced_power_factor(self) -> float:
        """κ as the model uses it (1 for the paper's hover inflow)."""
        return self.induced_power_factor if self.inflow is InflowModel.MOMENTUM else 1.0

    @property
    def effective_profile_power_speed_factor(self) -> float:
        """K as the model uses it (0 for the paper's hover inflow)."""
        return self.profile_power_speed_factor if self.inflow is InflowModel.MOMENTUM else 0.0


PAPER_ROTOR_MODEL = RotorModel(
    inflow=InflowModel.PAPER_HOVER, ground_effect=False, induced_power_factor=1.0, profile_power_speed_factor=0.0
)
"""The paper's rotor model (Kirchner et al. 2020, eq. 13): for reproduction."""

LEISHMAN_QUARTIC = (1.15, -1.125, -1.372, -1.718, -0.655)
"""κ_f, k₁ … k₄ of the axial-descent fit (Leishman 2006, §2.14.4), for −2 ≤ V_c / v_h ≤ 0."""
NEWTON_STEPS = 6
"""Newton steps on the momentum equation (relative error < 2e-4 anywhere in the (μ̂, x) plane; 8 steps: round-off)."""
GROUND_EFFECT_MIN_HEIGHT_RATIO = 0.45
"""z/R below which the ground effect is held constant (the image method overpredicts below it)."""

_JOIN_WIDTH = 0.03  # in x: the smooth steps between the climb branch, the quartic and the windmill branch
_QUARTIC_TO_WINDMILL = -2.051  # where the quartic and the windmill-brake branch cross (both ≈ 0.798)
_RAISED_EDGEWISE = 1.25 / 8.0  # μ̂² + this × min(x, 0)²: a quarter above the three-root threshold x²/8
_VORTEX_RING_EDGEWISE = 1.0  # μ̂ scale of w = exp(-(μ̂ / this)⁴)
_GUARD = 1e-6


def _step(value):
    """A smooth step from 0 (value ≪ 0) to 1 (value ≫ 0), 0.5 at 0."""
    return 0.5 * (1.0 + ca.tanh(value))


def axial_inflow_ratio(axial_ratio):
    """ν̂_A(x): the induced velocity in axial flight over v_h (the module docstring's axial curve).

    Args:
        axial_ratio: x = U_P / v_h, positive in climb.
    """
    x = axial_ratio
    # Each branch is evaluated at an argument held (smoothly) inside its own range, where its weight is not
    # negligible, so that no branch overflows where the steps give it a zero weight (0 · inf would be NaN).
    climb_x = smooth_positive(x + 0.5, 1e-3) - 0.5  # = x above −0.45, where the climb branch has weight
    climb = 1.0 / (climb_x / 2.0 + ca.sqrt(climb_x**2 / 4.0 + 1.0))  # −x/2 + √(x²/4 + 1), no cancellation
    kappa_fit, *coefficients = LEISHMAN_QUARTIC
    quartic = (kappa_fit + sum(k * x ** (i + 1) for i, k in enumerate(coefficients))) / kappa_fit
    windmill_x = -2.0 - smooth_positive(-2.0 - x, 1e-3)  # ≤ −2, = x below −2.05
    windmill = 1.0 / (-windmill_x / 2.0 + ca.sqrt(windmill_x**2 / 4.0 - 1.0))  # −x/2 − √(x²/4 − 1)
    to_climb = _step(x / _JOIN_WIDTH)
    to_quartic = _step((x - _QUARTIC_TO_WINDMILL) / _JOIN_WIDTH)
    return to_climb * climb + (1.0 - to_climb) * (to_quartic * quartic + (1.0 - to_quartic) * windmill)


def momentum_inflow_ratio(edgewise_ratio, axial_ratio, steps: int = NEWTON_STEPS):
    """ν̂_G(μ̂, x): the momentum-theory root with the raised edgewise speed (module docstring), Newton from the
    hover root √(−m/2 + √(m²/4 + 1)) at m = μ̂² + 5/32 min(x, 0)²."""
    x = axial_ratio
    descent = 0.5 * (x - ca.sqrt(x**2 + _GUARD**2))  # smooth min(x, 0)
    edgewise_squared = edgewise_ratio**2 + _RAISED_EDGEWISE * descent**2
    ratio = ca.sqrt(-edgewise_squared / 2.0 + ca.sqrt(edgewise_squared**2 / 4.0 + 1.0))
    for _ in range(steps):
        total = x + ratio
        speed = ca.sqrt(edgewise_squared + total**2)
        residual = ratio * speed - 1.0
        ratio = ratio - residual / (speed + ratio * total / speed)
    return ratio


def inflow_ratio(edgewise_ratio, axial_ratio, steps: int = NEWTON_STEPS):
    """ν̂(μ̂, x) = ν̂_G(μ̂, x) · (ν̂_A(x) / ν̂_G(0, x))^w, w = exp(−μ̂⁴): the induced velocity over v_h out of ground
    effect (the module docstring)."""
    return inflow_ratio_from_roots(
        edgewise_ratio,
        axial_ratio,
        momentum_ratio=momentum_inflow_ratio(edgewise_ratio, axial_ratio, steps),
        axial_momentum_ratio=momentum_inflow_ratio(0.0, axial_ratio, steps),
    )


def inflow_ratio_from_roots(edgewise_ratio, axial_ratio, *, momentum_ratio, axial_momentum_ratio):
    """ν̂ from the momentum roots ν̂_G(μ̂, x) and ν̂_G(0, x), however they were found (Newton steps here, or an NLP
    that carries them as variables with :func:`momentum_root_residual` as constraints)."""
    weight = ca.exp(-((edgewise_ratio / _VORTEX_RING_EDGEWISE) ** 4))
    axial_excess = axial_inflow_ratio(axial_ratio) / axial_momentum_ratio
    return momentum_ratio * ca.exp(weight * ca.log(axial_excess))


def momentum_root_residual(root, *, hover_induced_velocity, edgewise_speed, axial_speed):
    """The momentum equation with the raised edgewise speed in dimensional form, zero at the root (m²/s²):

    .. math:: \\nu_G \\sqrt{U_T^2 + \\tfrac{5}{32}\\min(U_P, 0)^2 + (U_P + \\nu_G)^2} - v_h^2

    (ν̂_G = ν_G / v_h solves :func:`momentum_inflow_ratio`'s equation; with ``edgewise_speed`` 0 it is ν̂_G(0, x)).
    Well scaled as C_T → 0, where the normalised speeds grow without bound.
    """
    descent = 0.5 * (axial_speed - ca.sqrt(axial_speed**2 + (_GUARD * hover_induced_velocity) ** 2))
    speed = ca.sqrt(edgewise_speed**2 + _RAISED_EDGEWISE * descent**2 + (axial_speed + root) ** 2)
    return root * speed - hover_induced_velocity**2


def ground_effect_factor(rotor_height_over_radius, edgewise_over_induced=0.0):
    """k_G: induced velocity in ground effect over the one out of it, at equal thrust (Cheeseman & Bennett 1955).

    Args:
        rotor_height_over_radius: z/R, the rotor's height above the ground over its radius (held at ≥ 0.45).
        edgewise_over_induced: U_T / ν, the in-plane speed over the induced velocity out of ground effect.
    """
    floor = GROUND_EFFECT_MIN_HEIGHT_RATIO
    height = floor + smooth_positive(rotor_height_over_radius - floor, 0.01)
    return 1.0 - (1.0 / (4.0 * height)) ** 2 / (1.0 + edgewise_over_induced**2)


def induced_velocity(
    rotor_model: RotorModel,
    *,
    hover_induced_velocity,
    edgewise_speed,
    axial_speed,
    height,
    rotor_radius: float,
    momentum_roots=None,
):
    """ν, m/s: the rotor's (ideal) induced velocity in any flight state.

    Args:
        rotor_model: which model, and the hub height for ground effect.
        hover_induced_velocity: v_h = ΩR √(C_T/2), m/s (> 0; guard C_T before the square root).
        edgewise_speed: U_T, the air speed in the disk plane, m/s.
        axial_speed: U_P, the air speed through the disk, positive down through it (climb), m/s.
        height: of the landing gear above the ground, m.
        rotor_radius: R, m.
        momentum_roots: (ν_G(U_T, U_P), ν_G(0, U_P)) in m/s, the roots of :func:`momentum_root_residual` (None: found
            by Newton steps here).
    """
    if rotor_model.inflow is InflowModel.PAPER_HOVER:
        velocity = hover_induced_velocity
    elif momentum_roots is None:
        velocity = hover_induced_velocity * inflow_ratio(
            edgewise_speed / hover_induced_velocity, axial_speed / hover_induced_velocity
        )
    else:
        velocity = hover_induced_velocity * inflow_ratio_from_roots(
            edgewise_speed / hover_induced_velocity,
            axial_speed / hover_induced_velocity,
            momentum_ratio=momentum_roots[0] / hover_induced_velocity,
            axial_momentum_ratio=momentum_roots[1] / hover_induced_velocity,
        )
    if rotor_model.ground_effect:
        assert rotor_model.hub_height is not None  # RotorModel checks it
        height_ratio = (height + rotor_model.hub_height) / rotor_radius
        velocity = velocity * ground_effect_factor(height_ratio, edgewise_speed / velocity)
    return velocity
