"""The planning steps of a failure episode, without ROS: the first plan, the re-plans, the deadline's fallback.

The planner node owns a :class:`FailurePlanner` and translates: an input or a timer becomes one of its calls, and
what it decides to publish comes back through a :class:`PlanSink` (the node's publishers). The rules are the
:class:`~helireach_ros.core.policies.landing_supervisor.LandingSupervisor`'s; the solves are the
:class:`~helireach_ros.core.workers.planner_backend.PlannerBackend`'s. The steps run on the solver thread:

- **the first plan** from the current state, warm-started from the envelope's nearest stored plan, for the episode's
  gross weight (fixed when the failure starts: the last live evaluation's, or one a solver holds, so that the failure
  path never builds an NLP). A solve that fails publishes the fallback when the supervisor says so; a safe plan's
  robust verification and the disturbance estimate start after it is published (off the failure path);
- **a re-plan** from the current state, from the control being flown at the state's stamp (the flyable controls stay
  continuous), with no reaction delay, for the model plus what the last interval taught of its error
  (:class:`~helireach_ros.core.estimation.disturbance.DisturbanceTracker`); a failed re-plan keeps the current plan,
  and so does a converged one that is not safe while the current plan's remainder, replayed from the same state, still
  lands (:func:`~helireach_ros.core.policies.landing_supervisor.keeps_current_plan`);
- **the deadline's fallback** when no plan is out in time (:func:`~helireach_ros.core.planning.fallback.fallback_plan`);
- **the landing site**, fixed when the failure starts (the standby plan's, else the selection's). Without a standby
  plan on the site, the first plan lands anywhere (the site NLP is slower: the deadline is met by the compiled one)
  and the site's plan from the same state follows it when verified. Every re-plan lands on the site when a plan for
  it is verified from the state, else anywhere
  (:func:`~helireach_ros.core.policies.landing_sites.solve_site_or_anywhere`): one re-plan that cannot verify the site
  (a model error the disturbance estimate has not learnt yet) does not give it up for the rest of the descent: every
  re-plan tries it (measured in the site demo: re-plans that skipped the site for a few solves after a miss, as the
  live evaluations do, made 54-68 of 64-73 plans for it and touched down as little as 41 ft inside its near end;
  keeping the unverified current site plan instead of landing elsewhere let the rotor droop to 61 %). The price:
  re-plans towards a site beyond reach cost their attempt (up to ``site_max_iterations``) every time. The first plan
  follows the live evidence (:meth:`~helireach_ros.core.policies.landing_sites.SiteSelection.worth_trying`): a site the
  last live evaluation could not reach costs it no attempt.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.estimation.disturbance import DisturbanceSettings, DisturbanceTracker
from helireach_ros.core.estimation.weight_tracking import WeightChoice, ready_choice
from helireach_ros.core.evidence.replay import replay_remainder
from helireach_ros.core.policies.failure_episode import FailureEpisode
from helireach_ros.core.policies.landing_sites import LandingSite, SiteSelection, site_values
from helireach_ros.core.policies.landing_supervisor import LandingSupervisor, ReplanGate, keeps_current_plan
from helireach_ros.core.policies.plan_status import PlannerHealth, SolverPoolHealth, StatusReport, planner_health_report
from helireach_ros.core.policies.vehicle_readings import CurrentState, LatestReadings, RotorSource
from helireach_ros.core.workers.live_scheduling import LiveScheduler, StandbyPlan
from helireach_ros.core.workers.planner_backend import PlannerBackend

if TYPE_CHECKING:
    from helireach_ros.core.planning.planner import LandingPlan
    from helireach_ros.core.policies.live_reachability import AnyWarmStart

__all__ = ["FailurePlanner", "PlanSink", "RobustKey", "controls_from_stamp"]

RobustKey = tuple[int, int, int]
"""A robust verification's key: (failure id, failure event stamp ns, plan state stamp ns)."""


class PlanSink(Protocol):
    """Where a :class:`FailurePlanner` publishes (the planner node's publishers)."""

    def publish_plan(
        self, failure: FailureEpisode, plan: LandingPlan, current: CurrentState, warm_source: str, *, replan: bool,
        robust_pending: bool,
    ) -> None:  # fmt: skip
        """A converged plan (safe, unverified or unsafe), if the supervisor allows it."""

    def publish_fallback(self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int, reason: str) -> None:
        """The fallback for ``state``, if the supervisor allows it."""

    def publish_no_plan(self, failure: FailureEpisode, text: str) -> None:
        """A status without a plan (an error), if nothing is out yet."""

    def robust_pending(self, key: RobustKey) -> None:
        """A plan's robust verification was submitted."""

    def report(self, level: str, text: str, throttle_s: float = 0.0) -> None:
        """A line for the operator (``"info"``, ``"warning"``, ``"error"``), at most every ``throttle_s``."""


def controls_from_stamp(plan: LandingPlan, stamp_ns: int) -> Callable[[float], np.ndarray]:
    """A plan's controls as a function of time in seconds (the plan starts at its state's stamp)."""
    start = stamp_ns * 1e-9
    return lambda time: plan.controls_at([time - start])[:, 0]


class FailurePlanner:
    """A failure episode's planning steps (see the module docstring).

    Args:
        backend: the solvers (None: not configured; every step then says so).
        setup_error: why there is no backend.
        supervisor: the failure-handling rules.
        readings: the latest vehicle readings.
        sink: where plans and statuses go.
        clock_ns: now, ns.
        zero_power: plan with zero engine power (a total power loss) rather than the measured power.
        disturbance: the re-plans' disturbance estimate (None: off).
        sites: the landing sites and their selection (None: land anywhere).
    """

    def __init__(
        self,
        backend: PlannerBackend | None,
        setup_error: str,
        supervisor: LandingSupervisor,
        readings: LatestReadings | None,
        sink: PlanSink,
        clock_ns: Callable[[], int],
        *,
        zero_power: bool,
        disturbance: DisturbanceSettings | None,
        sites: SiteSelection | None = None,
    ) -> None:
        self.backend = backend
        self.setup_error = setup_error
        self.supervisor = supervisor
        self.readings = readings
        self._sink = sink
        self._clock_ns = clock_ns
        self._zero_power = zero_power
        self._disturbance = disturbance
        self._lock = threading.Lock()
        self._episode_weight: WeightChoice | None = None
        self._sites = sites
        self._episode_site: LandingSite | None = None
        self._site_standby = False  # the standby plan published at the failure lands on the episode's site

    @property
    def not_configured(self) -> str:
        """The status text of a planner that cannot plan."""
        return f"planner not configured ({self.setup_error})"

    def current(self) -> CurrentState | None:
        """The state to plan a failure from now (None: no fresh state)."""
        if self.readings is None:
            return None
        return self.readings.current(self._clock_ns(), zero_power=self._zero_power)

    # -- the episode's weight -----------------------------------------------------------------------------------
    def fix_weight(self, latest: WeightChoice | None) -> None:
        """Fixes the episode's gross weight at its start: the last live evaluation's ``latest`` (no estimate in the
        failure callback), or one a solver holds (never an NLP built in the failure path)."""
        backend = self.backend
        if backend is None:
            return
        why = backend.weights_off_reason if backend.weights is None else "no live evaluation yet (where NLPs are built)"
        configured = backend.airframe.gross_weight
        latest = latest or WeightChoice(configured, "file", 0.0, why)
        with self._lock:
            self._episode_weight = ready_choice(latest, configured, backend.ready_weights())

    def fix_site(self, standby: StandbyPlan | None) -> None:
        """Fixes the episode's landing site at its start: the standby plan's (``standby``: the one published at the
        failure, None: none), else the selection's (None: anywhere)."""
        site = standby.site if standby is not None else None
        if site is None and self._sites is not None:
            site = self._sites.selected()
        with self._lock:
            self._episode_site = site
            self._site_standby = standby is not None and standby.lands_on_site

    @property
    def episode_site(self) -> LandingSite | None:
        """The landing site of the current (or last) failure episode (None: anywhere)."""
        with self._lock:
            return self._episode_site

    def site_values(self, plan: LandingPlan) -> dict[str, object]:
        """A plan's landing-site keys for its status (none without a site)."""
        reachable = self._sites.reachable_count() if self._sites is not None else None
        return site_values(self.episode_site, plan, reachable)

    @property
    def episode_weight(self) -> WeightChoice:
        """The gross weight the current (or last) failure episode plans for (the file's before any failure)."""
        with self._lock:
            weight = self._episode_weight
        if weight is not None:
            return weight
        configured = self.backend.airframe.gross_weight if self.backend is not None else float("nan")
        return WeightChoice(configured, "file", 0.0, "no failure")

    # -- the steps ----------------------------------------------------------------------------------------------
    def solve(
        self,
        state: np.ndarray,
        warm_start: AnyWarmStart,
        initial_control: np.ndarray | None = None,
        reaction_delay_s: float | None = None,
        disturbance: np.ndarray | None = None,
        *,
        to_site: bool = True,
        every_time: bool = False,
    ) -> tuple[LandingPlan | None, str]:
        """A failure plan or re-plan for the episode's weight (blocking): (plan, "") or (None, why not); on the
        episode's site if it has one, ``to_site`` and a plan for it is verified, else anywhere. The site is tried
        when the evidence says it is worth it, or ``every_time`` (the re-plans)."""
        if self.backend is None:
            return None, self.not_configured
        site = self.episode_site if to_site else None
        tried = site is not None and self._sites is not None and (every_time or self._sites.worth_trying(site))
        plan, error = self.backend.solve(
            state, warm_start, gross_weight=self.episode_weight.gross_weight, initial_control=initial_control,
            reaction_delay_s=reaction_delay_s, disturbance=disturbance,
            touchdown_window=site.window_from(state) if site is not None and tried else None,
        )  # fmt: skip
        if tried and plan is not None and site is not None and self._sites is not None:
            self._sites.record(site, plan.touchdown_window is not None and plan.safe)
        return plan, error

    def first_plan(self, failure: FailureEpisode, retry: bool = False) -> None:
        """The first plan of a failure (see the module docstring). ``retry``: called again because no converged plan
        is out yet; a fallback already out is not repeated."""
        if not failure.active:
            return
        current = self.current()
        if current is None:
            self._sink.publish_no_plan(failure, "no valid vehicle state at the failure: waiting for one")
            return
        state, stamp_ns = current.state, current.stamp_ns
        envelope = self.backend.envelope if self.backend is not None else None
        stored = envelope.nearest_plan_to(state) if envelope is not None else None
        warm_start, source = (stored.warm_start, "envelope") if stored is not None else (None, "none")
        with self._lock:
            # Without a standby plan on the site, the deadline is met by a landing anywhere (a site plan costs 3-6x a
            # compiled solve, an unreachable site its whole iteration limit); the site plan follows it.
            site_after = self._episode_site is not None and not self._site_standby
        plan, error = self.solve(state, warm_start, to_site=not site_after)
        if plan is None or not plan.solver.success:
            reason = error or (f"solver {plan.solver.status}" if plan is not None else "no plan")
            self._sink.report("error", f"failure #{failure.failure_id}: no converged plan ({reason})")
            if self.supervisor.fallback_after_failed_solve(failure, retry=retry, stamp_ns=stamp_ns):
                self.publish_fallback(failure, state, stamp_ns, reason)
            return
        if site_after and plan.safe:  # published first: the site plan is off the deadline's path
            self._sink.publish_plan(failure, plan, current, source, replan=False, robust_pending=False)
            on_site, _ = self.solve(state, plan.warm_start)
            if on_site is None or not on_site.safe or on_site.touchdown_window is None or not failure.active:
                return self._after_first_plan(failure, plan, stamp_ns, publish=None)
            plan, source = on_site, "previous_plan"
        self._after_first_plan(failure, plan, stamp_ns, publish=(current, source))

    def _after_first_plan(
        self,
        failure: FailureEpisode,
        plan: LandingPlan,
        stamp_ns: int,
        *,
        publish: tuple[CurrentState, str] | None,
    ) -> None:
        """Publishes the failure's first plan (``publish``: its state and warm-start source; None: out already), then,
        off the failure path, starts its robust verification and the disturbance estimate."""
        robust = self.backend is not None and self.backend.robust is not None and plan.safe
        if publish is not None:
            current, source = publish
            self._sink.publish_plan(failure, plan, current, source, replan=False, robust_pending=robust)
        if robust:  # after publishing: off the failure path
            self._submit_robust(failure, plan, stamp_ns)
        if self._disturbance is not None and failure.disturbance is None:  # after publishing: off the failure path
            assert self.backend is not None  # a plan came from it
            model = self.backend.model_for(self.episode_weight.gross_weight)
            failure.disturbance = DisturbanceTracker(model, self._disturbance)
            first_interval = controls_from_stamp(plan, stamp_ns)
            failure.disturbance.update(stamp_ns * 1e-9, plan.initial_state, first_interval)

    def _submit_robust(self, failure: FailureEpisode, plan: LandingPlan, stamp_ns: int) -> None:
        """Queues the plan's robust verification (its verdict is pending until it comes back)."""
        assert self.backend is not None and self.backend.robust is not None  # called only with robust verification
        key = (failure.failure_id, failure.event_stamp_ns, stamp_ns)
        model = self.backend.model_for(self.episode_weight.gross_weight)
        self.backend.robust.submit(key, model, self.backend.robust_settings(), plan)
        self._sink.robust_pending(key)

    def replan(self, failure: FailureEpisode) -> None:
        """One closed-loop re-plan from the current state, warm-started from the current plan."""
        current = self.current()
        if current is None:
            return
        state, stamp_ns = current.state, current.stamp_ns
        decision = self.supervisor.replan_decision(
            failure,
            rotor_measured=current.rotor_source is RotorSource.MEASURED,
            height=state[StateIndex.HEIGHT],
            stamp_ns=stamp_ns,
        )
        if decision is None or decision.previous is None:
            return
        if decision.gate is ReplanGate.PAUSE_NO_ROTOR:
            self._sink.report(
                "warning",
                f"failure #{failure.failure_id}: re-planning paused: no measured rotor speed (the current plan is "
                f"kept; {failure.replans_skipped_no_rotor} re-plans skipped)",
                throttle_s=1.0,
            )
            return
        if decision.gate is ReplanGate.END_CLOSED_LOOP:
            self._sink.report(
                "info",
                f"failure #{failure.failure_id}: closed loop ends at {state[StateIndex.HEIGHT]:.2f} m, "
                f"{decision.remaining:.2f} s to go ({failure.replans} re-plans, {failure.replans_failed} failed, "
                f"{failure.replans_kept_out} kept out)",
            )
            return
        previous = decision.previous
        flying = previous.plan.controls_at([(stamp_ns - previous.stamp_ns) * 1e-9])[:, 0]
        # what the last interval taught of the model's error (the current plan's controls were flown in it)
        flown = controls_from_stamp(previous.plan, previous.stamp_ns)
        tracker = failure.disturbance
        disturbance = tracker.update(stamp_ns * 1e-9, state, flown) if tracker is not None else None
        plan, error = self.solve(state, previous.plan.warm_start, flying, 0.0, disturbance, every_time=True)
        self.supervisor.replan_solved(failure, converged=plan is not None and plan.solver.success)
        if plan is None or not plan.solver.success:
            reason = error or (f"solver {plan.solver.status}" if plan is not None else "no plan")
            self._sink.report("warning", f"re-plan failed ({reason}); keeping the current plan", throttle_s=1.0)
            return
        elapsed_s = (stamp_ns - previous.stamp_ns) * 1e-9
        if keeps_current_plan(
            replan_safe=plan.safe,
            for_site=plan.touchdown_window is not None or previous.plan.touchdown_window is not None,
            current_lands_from_here=lambda: self._lands_from(previous.plan, elapsed_s, state, plan.disturbance),
        ):
            self.supervisor.replan_kept_out(failure)
            self._sink.report(
                "info",
                f"failure #{failure.failure_id}: re-plan not safe (value {plan.value:+.2f}); the current plan still "
                f"lands from this state: flying it on ({failure.replans_kept_out} kept out)",
                throttle_s=1.0,
            )
            return
        self._sink.publish_plan(failure, plan, current, "previous_plan", replan=True, robust_pending=False)

    def _lands_from(self, plan: LandingPlan, elapsed_s: float, state: np.ndarray, disturbance: np.ndarray) -> bool:
        """Whether the rest of ``plan`` from ``elapsed_s`` on, flown from ``state`` in the episode's model with
        ``disturbance``, lands within limits (its independent replay)."""
        assert self.backend is not None  # a re-plan came from it
        model = self.backend.model_for(self.episode_weight.gross_weight)
        return replay_remainder(model, self.backend.settings, plan, elapsed_s, state, disturbance).lands_within_limits

    def deadline(self) -> None:
        """The deadline's fallback, if it is due now (once per failure)."""
        failure = self.supervisor.deadline_fallback_due(self._clock_ns())
        if failure is None:
            return
        deadline = self.supervisor.settings.deadline
        current = self.current()
        if current is None:
            self._sink.publish_no_plan(failure, f"no plan within {deadline:g} s and no valid state")
            return
        self.publish_fallback(failure, current.state, current.stamp_ns, f"no plan within the {deadline:g} s deadline")

    def publish_fallback(self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int, reason: str) -> None:
        """Publishes the fallback for ``state``, or says that there is none."""
        if self.backend is None:
            self._sink.publish_no_plan(failure, f"{reason}; no fallback available ({self.not_configured})")
            return
        self._sink.publish_fallback(failure, state, stamp_ns, reason)

    # -- health -------------------------------------------------------------------------------------------------
    def health_report(self, live: LiveScheduler | None, *, solving: bool, solve_timeout_s: float) -> StatusReport:
        """The planner's ``/diagnostics`` status: its solvers, envelope, weight, live evaluation and failure."""
        backend = self.backend
        if backend is None:
            return StatusReport("ERROR", f"not configured: {self.setup_error}", {})
        pool = backend.pool
        failure = self.supervisor.failure
        asked = failure is not None and failure.active and failure.replans_skipped_no_rotor
        current = self.current() if asked else None
        health = PlannerHealth(
            airframe=backend.airframe.name,
            method=backend.settings.method,
            startup_s=backend.startup_s,
            warm_up_ms=backend.warm_up_ms,
            envelope_note=backend.envelope_note,
            has_envelope=backend.envelope is not None,
            failures=self.supervisor.failure_count,
            solving=solving,
            episode_phase=self.supervisor.episode.phase.value,
            solve_timeout_s=solve_timeout_s,
            ready_weights=len(backend.ready_weights()),
            weight_now=backend.weight_now(self._clock_ns()),
            airframe_problems=tuple(backend.airframe_problems),
            pool=None
            if pool is None
            else SolverPoolHealth(
                pool.pool_settings.workers, pool.ready_workers, pool.busy_workers, pool.restarts, pool.last_error
            ),
            rotor_measured=None if current is None else current.rotor_source is RotorSource.MEASURED,
        )
        if live is None:
            return planner_health_report(health, None, failure)
        with live.lock:
            return planner_health_report(health, live.evaluator, failure)
