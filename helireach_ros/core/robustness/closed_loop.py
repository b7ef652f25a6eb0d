"""Closed-loop landing without ROS: the planner node's re-planning loop in simulated, lock-step time.

After the failure the planner plans from the measured state, then re-plans every ``replan_period``
from the current measurement, warm-started from its previous plan, until the vehicle is below
``min_height`` or the current plan has less than ``min_remaining`` to go, and flying the current plan on when a
re-plan is not safe but the current plan, replayed from the same state, still lands — the policy of
:class:`~helireach_ros.ros.nodes.planner_node.LandingPlannerNode`
(:mod:`helireach_ros.core.policies.landing_supervisor`). Each plan is indexed from the time of
the measurement it starts from and reaches the vehicle ``latency`` seconds later (solve, transport),
as a :class:`~helireach_ros.core.flight.simulation.ControlSchedule`; until then the vehicle flies the previous one.

With ``estimate_weight``, the planner first estimates today's gross weight from the steady flight before the
failure (:func:`~helireach_ros.core.estimation.gross_weight.estimate_gross_weight`: the weight whose trim power is the
measured engine power) and plans for it ("estimation where it pays").

Unlike the real-time ROS system this is deterministic (seeded noise, fixed latency), so it measures
what the closed loop tolerates: ``bench/closed_loop_latency.py`` sweeps the latency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from helireach_ros.core.aircraft.model import clip_rotor_speed_noise, state_from_sensors
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.estimation.disturbance import DisturbanceSettings, DisturbanceTracker, predict_state
from helireach_ros.core.estimation.gross_weight import estimate_gross_weight
from helireach_ros.core.evidence.replay import replay_remainder
from helireach_ros.core.flight.simulation import ControlSchedule, Measurement, SimulatedVehicle, TouchdownReport
from helireach_ros.core.planning.planner import LandingPlan, LandingPlanner, get_planner
from helireach_ros.core.policies.landing_supervisor import keeps_current_plan, plan_time_remaining, replanning_ends

__all__ = ["ClosedLoopResult", "ClosedLoopSettings", "fly_closed_loop", "measured_state"]

_BEFORE_FAILURE_S = 0.1  # s before the failure at which the steady flight is measured


@dataclass(frozen=True)
class ClosedLoopSettings:
    """The re-planning policy (the planner node's parameters of the same names).

    Attributes:
        replan_period: s between plans.
        latency: s from the measurement a plan starts from to the vehicle flying it.
        min_height: m; no re-planning below.
        min_remaining: s; no re-planning when the current plan has less time to go.
        rotor_noise_tolerance: fraction of Ω₀ a measured rotor speed may lie outside its limits as noise.
        estimate_weight: plan for the gross weight estimated from the steady flight just before the failure
            (its measured engine power), not the airframe file's.
        estimate_disturbance: re-plan for the model plus the disturbance accelerations learnt from the
            prediction error of each re-planning interval (:mod:`helireach_ros.core.estimation.disturbance`); on, as in
            the planner node.
        compensate_latency: a re-plan starts ``latency`` s after its measurement: from the state the planner's
            model (with the disturbance estimate) predicts along the current plan for that long, with the control
            the current plan flies then. Off by default, as in the planner node: measured in
            ``bench/monte_carlo.py --policies disturbance+latency`` without a significant change of the landing
            rate (docs/method/planning.md).
        disturbance: how that estimate is made (with ``estimate_disturbance``, plans start from its filtered
            state, the measurement itself at its default state gain of 1).
        site: a landing site, (start, end) m along the track in the vehicle's distance coordinate (None: land
            anywhere). Every plan is made for it (a planner with the ``site`` objective), each re-plan for what is
            left of the way there from the measured distance.
        keep_landing_plan: a converged re-plan that is not safe is kept out while the current plan, replayed from the
            re-plan's state, still lands (:func:`~helireach_ros.core.policies.landing_supervisor.keeps_current_plan`);
            on, as in the planner node.
    """

    replan_period: float = 0.25
    latency: float = 0.05
    min_height: float = 0.5
    min_remaining: float = 0.3
    rotor_noise_tolerance: float = 0.01
    estimate_weight: bool = False
    estimate_disturbance: bool = True
    compensate_latency: bool = False
    disturbance: DisturbanceSettings = field(default_factory=DisturbanceSettings)
    site: tuple[float, float] | None = None
    keep_landing_plan: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.replan_period) and self.replan_period > 0.0):
            raise ValueError(f"replan_period must be > 0, got {self.replan_period!r}")
        if not (math.isfinite(self.latency) and self.latency >= 0.0):
            raise ValueError(f"latency must be >= 0, got {self.latency!r}")


@dataclass(frozen=True)
class ClosedLoopResult:
    """How a closed-loop descent ended.

    Attributes:
        touchdown: the vehicle's touchdown report.
        plans: converged plans made (the first included).
        failed_plans: solves that did not converge (the vehicle kept its current plan).
        unsafe_plans: converged plans not called safe (value > 0 or the replay failed).
        kept_out_plans: of those, re-plans kept out because the current plan still landed from their state.
        planned_gross_weight: N, the weight the plans were made for (the estimate with ``estimate_weight``).
        final_disturbance: the disturbance estimate of the last re-plan (zero without ``estimate_disturbance``).
        touchdown_distance: m along the track where the vehicle met the ground (its distance coordinate).
        on_site: the touchdown lies on the policy's site (None without one).
    """

    touchdown: TouchdownReport
    plans: int
    failed_plans: int
    unsafe_plans: int
    kept_out_plans: int = 0
    planned_gross_weight: float = math.nan
    final_disturbance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    touchdown_distance: float = math.nan
    on_site: bool | None = None


def measured_state(measurement: Measurement, vehicle: SimulatedVehicle, rotor_noise_tolerance: float) -> np.ndarray:
    """The planner's initial state (y, v, Ω, h, z, P = 0) from a measurement, as the planner node forms it."""
    rotor_speed = clip_rotor_speed_noise(vehicle.nominal_airframe, measurement.rotor_speed, rotor_noise_tolerance)
    return state_from_sensors(
        measurement.height, measurement.forward_speed, measurement.climb_rate, rotor_speed, measurement.distance
    )


def _flown_ahead(
    planner: LandingPlanner,
    state: np.ndarray,
    current: tuple[float, LandingPlan],
    now: float,
    duration: float,
    disturbance: np.ndarray,
) -> np.ndarray:
    """The state ``duration`` s after ``now`` in the planner's model plus the disturbance, flying the current plan
    (started at ``current[0]``); the state itself where the model cannot be integrated."""
    started, plan = current

    def controls_at(time: float) -> np.ndarray:
        return plan.controls_at([time])[:, 0]

    try:
        ahead = predict_state(planner.airframe, state, controls_at, now - started, duration, disturbance)
    except RuntimeError:
        return state
    ahead[5] = 0.0  # the energy state P starts at 0 in every plan
    return ahead


def _lands_from(
    planner: LandingPlanner, current: tuple[float, LandingPlan], time: float, state: np.ndarray, disturbance: np.ndarray
) -> bool:
    """Whether the current plan (started at ``current[0]``), flown on from ``state`` at ``time``, still lands."""
    start, plan = current
    remainder = replay_remainder(planner.airframe, planner.settings, plan, time - start, state, disturbance)
    return remainder.lands_within_limits


def fly_closed_loop(
    vehicle: SimulatedVehicle, planner: LandingPlanner, settings: ClosedLoopSettings | None = None
) -> ClosedLoopResult:
    """Flies the vehicle from its failure to the ground, re-planning as the planner node does.

    Args:
        vehicle: a vehicle before or at its failure (it is advanced to the failure first).
        planner: built for the vehicle's nominal airframe.
        settings: the re-planning policy.

    Returns:
        The touchdown and plan counts.
    """
    settings = settings or ClosedLoopSettings()
    if settings.estimate_weight:
        if vehicle.engine_failed:
            raise ValueError("estimate_weight needs the vehicle before its failure (steady flight to measure)")
        vehicle.advance(max(vehicle.scenario.failure_time - vehicle.time - _BEFORE_FAILURE_S, 0.0))
        steady = vehicle.measure()  # the last steady flight before the failure
        estimate = estimate_gross_weight(planner.airframe, steady.forward_speed, steady.climb_rate, steady.engine_power)
        planner = get_planner(planner.airframe.with_conditions(gross_weight=estimate.gross_weight), planner.settings)
    if not vehicle.engine_failed:
        vehicle.advance(max(vehicle.scenario.failure_time - vehicle.time, 0.0))
    pending: list[tuple[float, ControlSchedule]] = []  # (arrival time, schedule), in order
    current: tuple[float, LandingPlan] | None = None  # (time it starts from, plan)
    plans = failed = unsafe = kept_out = 0
    tracker = DisturbanceTracker(planner.airframe, settings.disturbance)
    disturbance = np.zeros(3)
    replanning = True
    while not vehicle.landed:
        now = vehicle.time
        if replanning:
            state = measured_state(vehicle.measure(), vehicle, settings.rotor_noise_tolerance)
            if settings.estimate_disturbance:
                disturbance = tracker.update(now, state, vehicle.flown_controls)
                filtered = tracker.state  # the measurement itself with a state gain of 1
                state = state if filtered is None else filtered
            # a re-plan starts where the vehicle will be when it reaches it: the measurement flown ahead along the
            # current plan for the latency (in the planner's model with the disturbance estimate)
            starts = now + settings.latency if settings.compensate_latency and current is not None else now
            if current is not None and starts > now:
                state = _flown_ahead(planner, state, current, now, starts - now, disturbance)
            remaining = plan_time_remaining(current[1].time_to_land, starts - current[0]) if current else math.inf
            if replanning_ends(state[StateIndex.HEIGHT], remaining, settings.min_height, settings.min_remaining):
                replanning = False
            else:
                here = state[StateIndex.DISTANCE]
                window = None if settings.site is None else (settings.site[0] - here, settings.site[1] - here)
                if current is None:  # the failure plan: from the trim flown before, after the reaction delay
                    plan = planner.plan(state, touchdown_window=window)
                else:  # a re-plan: from the control being flown when it starts (continuous), no reaction delay
                    flying = current[1].controls_at([starts - current[0]])[:, 0]
                    plan = planner.plan(
                        state, current[1].warm_start, initial_control=flying, reaction_delay_s=0.0,
                        disturbance=disturbance, touchdown_window=window,
                    )  # fmt: skip
                if not plan.solver.success:
                    failed += 1
                else:
                    plans += 1
                    unsafe += not plan.safe
                    if (
                        current is not None
                        and settings.keep_landing_plan
                        and keeps_current_plan(
                            replan_safe=plan.safe,
                            for_site=window is not None,
                            current_lands_from_here=partial(_lands_from, planner, current, starts, state, disturbance),
                        )
                    ):
                        kept_out += 1
                    else:
                        current = (starts, plan)
                        pending.append((now + settings.latency, ControlSchedule.from_plan(plan, starts)))
        next_tick = now + settings.replan_period
        while pending and pending[0][0] <= next_tick and not vehicle.landed:
            arrival, schedule = pending.pop(0)
            vehicle.advance(max(arrival - vehicle.time, 0.0))
            vehicle.follow(schedule)
        if not vehicle.landed:
            vehicle.advance(max(next_tick - vehicle.time, 0.0))
    assert vehicle.touchdown is not None
    where = float(vehicle.state[StateIndex.DISTANCE])
    on_site = None if settings.site is None else settings.site[0] <= where <= settings.site[1]
    return ClosedLoopResult(
        vehicle.touchdown, plans, failed, unsafe, kept_out, planner.airframe.gross_weight, disturbance, where, on_site
    )
