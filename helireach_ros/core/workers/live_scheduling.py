"""Live evaluation before a failure, scheduled on the planner's solvers: "if the engine failed now, could we land?"

At ``live_rate`` the planner solves the landing from the current state as if the engine failed now
(:class:`~helireach_ros.core.policies.live_reachability.LiveEvaluator`: the warm start, the verdict, the standby
plan). :class:`LiveScheduler` decides when one starts and where it runs, and keeps what belongs to the verdict:

- one evaluation in flight at a time, due half a period early (a timer's jitter must not skip a period); only from a
  state with a measured rotor speed (a verdict for an assumed Ω₀ would answer for a state nobody measured);
- with a solver pool the evaluation is a live-priority job there, else it runs on the solver thread only when no
  failure step is pending or running;
- the envelope's nearest plan is the warm start only when no neighbouring live solution can start it;
- the weight it was made for (a weight no solver holds is built here, before any failure) and, for the standby
  verdict, its vehicle frame and its messages, prepared off the executor when the verdict comes, so that a failure
  only publishes them;
- a generation number: a verdict that comes back after a failure started or after a reset is not evidence any more
  and is dropped;
- with landing sites, the selected site (:class:`~helireach_ros.core.policies.landing_sites.SiteSelection`): each
  evaluation lands on it if it can, else anywhere, and records which, so that the standby plan is the selected
  site's whenever the site is reachable;
- the live reachable footprint (``footprint_period_s``, with a solver pool): at most that often, an evaluation's slot
  goes to the footprint's two ends instead (nearest then farthest touchdown, each one live job, warm from its own
  previous verified solution), published with what they say of each site
  (:func:`~helireach_ros.core.policies.landing_sites.footprint_report`). Its slot is a verdict not made: the standby
  plan is at most one footprint (two solves) older.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from helireach_ros.core.estimation.weight_tracking import WeightChoice
from helireach_ros.core.ocp.settings import FOOTPRINT_OBJECTIVES
from helireach_ros.core.policies.landing_sites import LandingSite, SiteSelection, footprint_report, site_values
from helireach_ros.core.policies.live_reachability import LiveEvaluator, LiveSettings, LiveVerdict
from helireach_ros.core.policies.plan_status import StatusReport, live_report
from helireach_ros.core.policies.vehicle_readings import CurrentState, RotorSource
from helireach_ros.core.workers.planner_backend import PlannerBackend
from helireach_ros.core.workers.solver_thread import SolverThread

if TYPE_CHECKING:
    from helireach_ros.core.planning.planner import LandingPlan
    from helireach_ros.core.policies.live_reachability import AnyWarmStart

__all__ = ["LiveScheduler", "StandbyPlan"]


@dataclass(frozen=True)
class StandbyPlan:
    """The latest safe live verdict handed to a failure: its plan is published at once, flagged ``standby``.

    Attributes:
        verdict: the live verdict (its plan, its state's stamp).
        frame: the vehicle frame of its state.
        weight: the gross weight it was made for.
        messages: its messages as prepared when the verdict came (None: not yet; opaque here).
        site: the landing site it was asked to land on (None: no sites; its plan's window says if it does).
    """

    verdict: LiveVerdict
    frame: str
    weight: WeightChoice
    messages: object | None
    site: LandingSite | None = None

    @property
    def lands_on_site(self) -> bool:
        """Its plan was made for its site (and, being a standby, is verified)."""
        plan = self.verdict.plan
        return self.site is not None and plan is not None and plan.touchdown_window is not None


class LiveScheduler:
    """When and where live evaluations run, and what their verdicts carry (see the module docstring).

    Args:
        settings: the live policy.
        backend: the solvers, the envelope and the weight.
        solver_thread: where an evaluation runs without a solver pool.
        clock_ns: now, ns (the node's clock).
        publish_verdict: called with each verdict's status report (under the scheduler's lock, so that no verdict is
            published after a pause).
        prepare_standby: ``prepare_standby(plan, stamp_ns, frame)`` builds a standby verdict's messages (called off
            the lock, on the thread the verdict came back on).
        sites: the landing sites and their selection (None: land anywhere).
        footprint_period_s: how often the live footprint is solved, s (0: never; needs a pool built with it).
        publish_footprint: called with each footprint's status report (outside the lock).
    """

    def __init__(
        self,
        settings: LiveSettings,
        backend: PlannerBackend,
        solver_thread: SolverThread,
        clock_ns: Callable[[], int],
        publish_verdict: Callable[[StatusReport], None],
        prepare_standby: Callable[[LandingPlan, int, str], object],
        sites: SiteSelection | None = None,
        footprint_period_s: float = 0.0,
        publish_footprint: Callable[[StatusReport], None] | None = None,
    ) -> None:
        self.settings = settings
        self.sites = sites
        self._footprint_period_ns = int(footprint_period_s * 1e9) if publish_footprint is not None else 0
        self._publish_footprint = publish_footprint
        self._footprint_started_ns: int | None = None
        self._latest_warm_start: AnyWarmStart = None  # the latest live plan's: a footprint end's first start
        self._footprint_warm_starts: dict[str, AnyWarmStart] = {}  # each end's previous solution, its next start
        self.evaluator = LiveEvaluator(settings)
        self._backend = backend
        self._solver_thread = solver_thread
        self._clock_ns = clock_ns
        self._publish_verdict = publish_verdict
        self._prepare_standby = prepare_standby
        self._lock = threading.Lock()
        self._job: Future | None = None
        self._generation = 0
        self._standby_frame = ""
        self._standby_weight: WeightChoice | None = None
        self._standby_messages: object | None = None
        self._standby_site: LandingSite | None = None
        self.latest_weight: WeightChoice | None = None  # the weight the latest evaluation was started for

    @property
    def lock(self) -> threading.Lock:
        """Held while a verdict is recorded and published (a reader of the evaluator's counters takes it too)."""
        return self._lock

    @property
    def standby_messages(self) -> object | None:
        """The standby verdict's prepared messages (None: none yet)."""
        with self._lock:
            return self._standby_messages

    def tick(self, current: CurrentState | None) -> None:
        """Starts an evaluation of ``current`` if one is due and none is in flight."""
        if current is None or current.rotor_source is not RotorSource.MEASURED:
            return  # no verdict from an assumed rotor speed: the latched one ages and says so (state_age_s)
        now_ns = self._clock_ns()
        state = current.state
        with self._lock:
            if self._job is not None and not self._job.done():
                return
            if not self.evaluator.due(now_ns + self.settings.period_ns // 2):
                return
            # The envelope's nearest plan (~2 ms in the 3-D file) only when no neighbouring live solution can start it.
            envelope = self._backend.envelope
            stored = None
            if envelope is not None and not self.evaluator.warm_start_applies(state):
                stored = envelope.nearest_plan_to(state)
            prepared = self.evaluator.prepare(
                state, current.stamp_ns, now_ns, stored.warm_start if stored is not None else None
            )
            if prepared is None:
                return  # the state is older than live_max_state_age
            failure_now, warm_start = prepared
            if self._footprint_due(now_ns):  # this slot goes to the footprint's nearer end (the farther follows)
                self._footprint_started_ns = now_ns
                try:
                    job = self._backend.submit_footprint_end(
                        failure_now, self._footprint_start(FOOTPRINT_OBJECTIVES[0]), FOOTPRINT_OBJECTIVES[0]
                    )
                except RuntimeError:  # the pool is closed: the node is being destroyed
                    return
                self._job = job
                done = partial(
                    self._footprint_end, self._generation, failure_now, current.stamp_ns, time.perf_counter()
                )
            else:
                weight = self._backend.weight_now(now_ns)  # a weight no solver holds is built here, before any failure
                self.latest_weight = weight
                site = self.sites.selected() if self.sites is not None else None
                tried = site is not None and self.sites is not None and self.sites.worth_trying(site)
                window = site.window_from(failure_now) if site is not None and tried else None
                done = partial(
                    self._done, self._generation, failure_now, current.stamp_ns, current.frame, now_ns, weight, site,
                    tried,
                )  # fmt: skip
                if self._backend.pool is not None:
                    try:
                        job = self._backend.submit_live(failure_now, warm_start, weight.gross_weight, window)
                    except RuntimeError:  # the pool is closed: the node is being destroyed
                        return
                    self._job = job
        if self._backend.pool is not None:
            job.add_done_callback(done)  # outside the lock: a job already done calls back at once, here
            return
        self._solver_thread.submit(self._solve_in_process, done, failure_now, warm_start, weight, window)

    def _footprint_due(self, now_ns: int) -> bool:
        """Whether this evaluation slot goes to the footprint (on, a pool, and its period over since the last)."""
        if self._footprint_period_ns <= 0 or self._backend.pool is None:
            return False
        last = self._footprint_started_ns
        return last is None or now_ns - last >= self._footprint_period_ns

    def _footprint_start(self, objective: str) -> AnyWarmStart:
        """A footprint end's warm start: its own previous verified solution (the state moves little between two
        footprints; measured: warm from a site plan the nearest end took 294 iterations and did not verify), cold after
        one that did not verify, the latest live plan's for the first."""
        if objective in self._footprint_warm_starts:
            return self._footprint_warm_starts[objective]
        return self._latest_warm_start

    def _footprint_end(
        self,
        generation: int,
        state: np.ndarray,
        stamp_ns: int,
        started: float,
        future: Future,
        nearest: tuple[LandingPlan | None, str] | None = None,
    ) -> None:
        """One footprint end came back (on the pool's thread): submits the farther end after the nearer, then
        publishes both."""
        try:
            plan, error = future.result(), ""
        except Exception as exception:  # a refused state, a dead or hung worker, a closed pool: no answer
            plan, error = None, f"{type(exception).__name__}: {exception}"
        with contextlib.suppress(Exception):  # the node may be shutting down
            with self._lock:
                if generation != self._generation:
                    return  # a failure started (or a reset) meanwhile
                objective = FOOTPRINT_OBJECTIVES[0 if nearest is None else 1]
                # a verified end starts the next from its solution; one that is not starts the next cold
                self._footprint_warm_starts[objective] = plan.warm_start if plan is not None and plan.safe else None
                if nearest is None:
                    farthest = FOOTPRINT_OBJECTIVES[1]
                    job = self._backend.submit_footprint_end(state, self._footprint_start(farthest), farthest)
                    self._job = job
            if nearest is None:
                job.add_done_callback(
                    partial(self._footprint_end, generation, state, stamp_ns, started, nearest=(plan, error))
                )
                return
            report = footprint_report(
                nearest[0], plan, state=state, stamp_ns=stamp_ns, solve_time_ms=1e3 * (time.perf_counter() - started),
                sites=self.sites, reason="; ".join(reason for reason in (nearest[1], error) if reason),
            )  # fmt: skip
            assert self._publish_footprint is not None  # footprints are solved only with a publisher
            self._publish_footprint(report)

    def _solve_in_process(
        self,
        done: Callable[[Future], None],
        state: np.ndarray,
        warm_start: AnyWarmStart,
        weight: WeightChoice,
        window: tuple[float, float] | None,
    ) -> None:
        """Without a pool: the live solve on the solver thread (the cold check, as in the workers)."""
        future: Future = Future()
        try:
            future.set_result(self._backend.solve_live(state, warm_start, weight.gross_weight, window))
        except (ValueError, RuntimeError) as error:
            future.set_exception(error)
        done(future)

    def _done(
        self,
        generation: int,
        state: np.ndarray,
        stamp_ns: int,
        frame: str,
        started_ns: int,
        weight: WeightChoice,
        site: LandingSite | None,
        site_tried: bool,
        future: Future,
    ) -> None:
        """Records a finished evaluation and publishes its verdict (on the pool's or the solver thread)."""
        try:
            plan, error = future.result(), ""
        except Exception as exception:  # a refused state, a dead or hung worker, a closed pool: an error verdict
            plan, error = None, f"{type(exception).__name__}: {exception}"
        with contextlib.suppress(Exception):  # the node may be shutting down
            with self._lock:
                if generation != self._generation:
                    return  # a failure started (or the evaluator was reset) meanwhile: not evidence any more
                verdict = self.evaluator.record(state, stamp_ns, started_ns, self._clock_ns(), plan, error)
                if plan is not None and plan.solver.success:
                    self._latest_warm_start = plan.warm_start
                standby = self.evaluator.standby_verdict is verdict
                if standby:
                    self._standby_frame, self._standby_weight, self._standby_site = frame, weight, site
                sites = self.sites
                if sites is not None and site is not None and site_tried and plan is not None:
                    sites.record(site, plan.touchdown_window is not None and plan.safe)
                report = live_report(
                    verdict,
                    standby=standby,
                    weight=weight,
                    configured_weight=self._backend.airframe.gross_weight,
                    power_fraction=self.settings.power_fraction,
                    now_ns=self._clock_ns(),
                    sites=site_values(site, plan, sites.reachable_count() if sites is not None else None),
                )
                self._publish_verdict(report)
            # its messages now, off the executor and outside the lock: the failure only publishes them
            if standby and verdict.plan is not None:
                messages = self._prepare_standby(verdict.plan, stamp_ns, frame)
                with self._lock:
                    if generation == self._generation:
                        self._standby_messages = messages

    def pause(self, failure_stamp_ns: int | None = None) -> StandbyPlan | None:
        """Drops the evaluation in flight; with a failure's stamp returns its standby plan (if any), without one
        forgets every verdict (evaluation resumes afresh)."""
        with self._lock:
            self._generation += 1
            self._job = None
            if failure_stamp_ns is None:
                self.evaluator.reset()
                if self.sites is not None:
                    self.sites.forget()
                return None
            verdict = self.evaluator.standby(failure_stamp_ns)
            if verdict is None or self._standby_weight is None:
                return None
            return StandbyPlan(
                verdict, self._standby_frame, self._standby_weight, self._standby_messages, self._standby_site
            )
