"""Robust verification: does a landing still work when the planner's model is wrong?

A plan is verified *nominally* by its replay (:mod:`helireach_ros.core.evidence.replay`): the model it was
made with, flown open loop. Here the same landing is flown through perturbed models
(:class:`~helireach_ros.core.flight.uncertainty.PerturbedModel`: other airframe parameters, another density
altitude, a plan latency) on the simulated vehicle (:class:`~helireach_ros.core.flight.simulation.SimulatedVehicle`,
the model integrated by the replay's CVODES segments, to ground contact), twice:

* **open loop**: the plan's controls as planned, from the failure; the plan reaches the vehicle after the
  model's latency (trim controls until then) and its last control holds after its end. This shows how much
  the landing leans on feedback: little survives a 5 % weight error open loop;
* **closed loop**: :func:`~helireach_ros.core.robustness.closed_loop.fly_closed_loop`, the planner node's re-planning
  policy in lock-step time, with the model's latency; the planner keeps the nominal model throughout.

Each flight is judged against the *true* limits (the vehicle's touchdown report: descent and forward
speed at contact, rotor speed in flight). The verdict is

  robust  ⇔  the plan is safe nominally  ∧  the closed loop lands within limits in every model flown,

so a single failing model (or an empty list of models) makes it not robust; the open-loop results are
reported beside it and do not enter the verdict. "Robust" holds for the models flown (by default the
resolution-IV corners of :meth:`~helireach_ros.core.flight.uncertainty.UncertaintySet.verification_design`),
not for every point of the set; the verdict names its design.

Sensor noise and its seed are the scenario's (zero noise gives a deterministic verdict).

With ``stop_at_first_failure`` the flights stop at the first model whose closed loop fails: the verdict
cannot change after it, and an envelope (:mod:`helireach_ros.core.robustness.envelope_verdicts`) does not pay for the
rest. Such a verdict lists the models flown, not the design; ``design_size`` says how many it holds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.model import initial_state_after_failure
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.flight.simulation import (
    ControlSchedule,
    Scenario,
    SensorNoise,
    SimulatedVehicle,
    TouchdownReport,
)
from helireach_ros.core.flight.uncertainty import PerturbedModel
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.planning.planner import LandingPlan, LandingPlanner
from helireach_ros.core.robustness.closed_loop import ClosedLoopSettings, fly_closed_loop

__all__ = [
    "ModelOutcome",
    "RobustVerdict",
    "failure_state",
    "fly_open_loop",
    "model_vehicle",
    "own_landing",
    "scenario_at",
    "verify_plan_robust",
    "verify_robust",
]

_STATE_TOLERANCE = 1e-6  # SI; a plan from another state is not this scenario's plan
_OPEN_LOOP_STEP_S = 1.0  # advance in steps until touchdown (the scenario's max_flight_time ends a flight)


@dataclass(frozen=True)
class ModelOutcome:
    """How one flight through one perturbed model ended.

    Attributes:
        model: the perturbed model.
        touchdown: the vehicle's report against the true limits.
        plans: plans flown (1 open loop; converged plans in the closed loop).
        failed_plans: closed-loop solves that did not converge.
    """

    model: PerturbedModel
    touchdown: TouchdownReport
    plans: int = 1
    failed_plans: int = 0

    @property
    def within_limits(self) -> bool:
        """Touched down within the true limits, the rotor speed within its limits in flight."""
        return self.touchdown.within_limits


@dataclass(frozen=True)
class RobustVerdict:
    """The robust verification of one plan (see the module docstring).

    Attributes:
        robust: the nominal plan is safe and the closed loop landed within limits in every model.
        nominal_status: the plan's own (nominal-model) status.
        design: which models were flown (e.g. ``"resolution-IV corners of 'default' (16)"``).
        closed_loop: one outcome per model, in order.
        open_loop: one outcome per model, in order (not part of the verdict).
        plan: the plan verified.
        design_size: models in the design (more than flown when the flights stopped at the first failure).
    """

    robust: bool
    nominal_status: str
    design: str
    closed_loop: tuple[ModelOutcome, ...]
    open_loop: tuple[ModelOutcome, ...]
    plan: LandingPlan
    design_size: int = -1

    def __post_init__(self) -> None:
        if self.design_size < 0:
            object.__setattr__(self, "design_size", len(self.closed_loop))

    @property
    def stopped_early(self) -> bool:
        """The flights stopped at the first failing model (fewer flown than the design holds)."""
        return len(self.closed_loop) < self.design_size

    @property
    def closed_loop_landed(self) -> int:
        """Closed-loop flights that landed within the true limits."""
        return sum(outcome.within_limits for outcome in self.closed_loop)

    @property
    def open_loop_landed(self) -> int:
        """Open-loop flights that landed within the true limits (reported, not part of the verdict)."""
        return sum(outcome.within_limits for outcome in self.open_loop)

    @property
    def first_failure(self) -> ModelOutcome | None:
        """The first closed-loop flight that did not land within limits (None: none failed)."""
        return next((outcome for outcome in self.closed_loop if not outcome.within_limits), None)

    @property
    def failing_models(self) -> tuple[str, ...]:
        """Labels of the models whose closed loop did not land within limits."""
        return tuple(outcome.model.label for outcome in self.closed_loop if not outcome.within_limits)

    @property
    def reason(self) -> str:
        """Why the verdict is not robust ("" when it is)."""
        if self.robust:
            return ""
        if self.nominal_status != "safe":
            return f"the plan is {self.nominal_status} in the nominal model"
        if not self.closed_loop:
            return "no perturbed model was flown"
        first = self.first_failure
        assert first is not None  # not robust, safe nominally and flown: a model failed
        flown = (
            f"{len(self.closed_loop)}"
            if not self.stopped_early
            else (f"{len(self.closed_loop)} flown (stopped at the first failure) of {self.design_size}")
        )
        return (
            f"{len(self.failing_models)} of {flown} models fail closed loop; "
            f"first {first.model.label}: {first.touchdown.reason}"
        )


def failure_state(scenario: Scenario, airframe: Airframe) -> np.ndarray:
    """The exact state (y, v, Ω, h, z = 0, P) at the scenario's failure from level trim, SI."""
    return initial_state_after_failure(
        airframe, scenario.height, scenario.forward_speed, scenario.power_fraction
    ).as_array()


def model_vehicle(
    scenario: Scenario,
    model: PerturbedModel,
    airframe: Airframe,
    settings: PlannerSettings,
    start: LandingPlan | None = None,
) -> SimulatedVehicle:
    """The simulated vehicle that *is* the perturbed model: the scenario flown by ``model.airframe(airframe)``.

    The vehicle judges its touchdown against the limits of the airframe it is given, which a perturbation
    does not change (density altitude and mismatch parameters leave the limits and Ω₀ alone). With ``start``
    it starts at the failure in that plan's initial state, holding its initial control (the scenario's
    failure time must be 0).

    Raises:
        ValueError: the scenario has a mismatch of its own (it would be silently replaced).
    """
    if scenario.parameter_mismatch:
        raise ValueError(f"scenario {scenario.name!r} has its own parameter mismatch: pass it as the model instead")
    perturbed = dataclasses.replace(scenario, parameter_mismatch=model.mismatch)
    if start is None:
        return SimulatedVehicle(perturbed, model.conditions(airframe), settings)
    return SimulatedVehicle(perturbed, model.conditions(airframe), settings, start.initial_state, start.initial_control)


def own_landing(
    model: PerturbedModel,
    airframe: Airframe,
    settings: PlannerSettings,
    height: float,
    speed: float,
    power_fraction: float = 0.0,
) -> LandingPlan:
    """The landing a planner that *knows* the perturbed model plans for it, cold, after a failure from level trim at
    (height m, speed m/s): whether the model can land at all. A model without a safe landing of its own cannot be
    landed within limits by any re-planning policy of this NLP (up to IPOPT's local optimum), so a robust verdict
    that includes it is out of reach whatever the policy."""
    from helireach_ros.core.planning.planner import get_planner

    true_airframe = model.airframe(airframe)
    state = initial_state_after_failure(true_airframe, height, speed, power_fraction)
    return get_planner(true_airframe, settings).plan(state)


def scenario_at(plan: LandingPlan, noise: SensorNoise | None = None, seed: int = 0) -> Scenario:
    """A scenario that starts at the failure in ``plan``'s initial state (for :func:`verify_plan_robust`)."""
    height, speed = float(plan.initial_state[StateIndex.HEIGHT]), float(plan.initial_state[StateIndex.FORWARD_SPEED])
    return Scenario(
        name="from_plan_state", height=min(max(height, 0.0), 5000.0), forward_speed=min(max(speed, 0.0), 120.0),
        failure_time=0.0, noise=noise or SensorNoise(), seed=seed,
    )  # fmt: skip


def fly_open_loop(vehicle: SimulatedVehicle, plan: LandingPlan, latency: float) -> TouchdownReport:
    """Flies one plan made at the failure, open loop: it reaches the vehicle ``latency`` s after the failure."""
    if not (math.isfinite(latency) and latency >= 0.0):
        raise ValueError(f"latency must be >= 0, got {latency!r}")
    vehicle.advance(max(vehicle.scenario.failure_time - vehicle.time, 0.0) + latency)
    vehicle.follow(ControlSchedule.from_plan(plan, vehicle.scenario.failure_time))
    while not vehicle.landed:
        vehicle.advance(_OPEN_LOOP_STEP_S)
    assert vehicle.touchdown is not None
    return vehicle.touchdown


def verify_robust(
    scenario: Scenario,
    planner: LandingPlanner,
    models: Sequence[PerturbedModel],
    policy: ClosedLoopSettings | None = None,
    plan: LandingPlan | None = None,
    design: str = "",
    stop_at_first_failure: bool = False,
) -> RobustVerdict:
    """Flies the scenario's landing through every model, open and closed loop, and gives the verdict.

    Args:
        scenario: the flight (height, speed, failure time, power left, sensor noise and seed); no mismatch.
        planner: built for the nominal airframe; it plans (and re-plans) in every model.
        models: the perturbed models (e.g. ``uncertainty_set.verification_design()``).
        policy: the re-planning policy; its latency is replaced by each model's.
        plan: the plan to fly open loop (default: planned now from :func:`failure_state`); it must start
            from the scenario's failure state.
        design: a description of ``models`` for the verdict.
        stop_at_first_failure: fly no further model once one fails closed loop (the verdict is then settled).

    Raises:
        ValueError: the plan starts from another state, or the scenario has its own mismatch.
    """
    state = failure_state(scenario, planner.airframe)
    if plan is None:
        plan = planner.plan(state)
    elif not np.allclose(plan.initial_state[[0, 1, 2, 3, 5]], state[[0, 1, 2, 3, 5]], rtol=0.0, atol=_STATE_TOLERANCE):
        raise ValueError(f"the plan starts from {plan.initial_state}, not from the scenario's failure state {state}")
    return _fly_models(scenario, planner, models, policy, plan, design, stop_at_first_failure, start=None)


def verify_plan_robust(
    plan: LandingPlan,
    planner: LandingPlanner,
    models: Sequence[PerturbedModel],
    policy: ClosedLoopSettings | None = None,
    design: str = "",
    stop_at_first_failure: bool = False,
    noise: SensorNoise | None = None,
) -> RobustVerdict:
    """:func:`verify_robust` for a plan made from any state (e.g. the planner node's plan at a failure).

    Every vehicle starts at the failure in the plan's initial state (y, v, Ω, h, z, P), holding the plan's
    initial control; the open loop flies the plan after each model's latency, the closed loop plans from
    there as the planner node does.
    """
    scenario = scenario_at(plan, noise)
    return _fly_models(scenario, planner, models, policy, plan, design, stop_at_first_failure, start=plan)


def _fly_models(
    scenario: Scenario,
    planner: LandingPlanner,
    models: Sequence[PerturbedModel],
    policy: ClosedLoopSettings | None,
    plan: LandingPlan,
    design: str,
    stop_at_first_failure: bool,
    start: LandingPlan | None,
) -> RobustVerdict:
    policy = policy or ClosedLoopSettings()
    open_loop, closed_loop = [], []
    for model in models:
        vehicle = model_vehicle(scenario, model, planner.airframe, planner.settings, start)
        open_loop.append(ModelOutcome(model, fly_open_loop(vehicle, plan, model.latency)))
        vehicle = model_vehicle(scenario, model, planner.airframe, planner.settings, start)
        result = fly_closed_loop(vehicle, planner, dataclasses.replace(policy, latency=model.latency))
        closed_loop.append(ModelOutcome(model, result.touchdown, result.plans, result.failed_plans))
        if stop_at_first_failure and not closed_loop[-1].within_limits:
            break
    robust = plan.safe and bool(closed_loop) and all(outcome.within_limits for outcome in closed_loop)
    return RobustVerdict(
        robust=robust,
        nominal_status=plan.status,
        design=design or f"{len(models)} given models",
        closed_loop=tuple(closed_loop),
        open_loop=tuple(open_loop),
        plan=plan,
        design_size=len(models),
    )
