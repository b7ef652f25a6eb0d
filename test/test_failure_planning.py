"""The planner's failure steps, live scheduling, readings and solver thread without ROS (core/workers/:
failure_planning.py, live_scheduling.py, solver_thread.py; core/policies/vehicle_readings.py): real solves (IPOPT, in
process) on a fake clock, published into a sink that records what the node would publish."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from typing import Any

import numpy as np
import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import StateIndex
from helireach_ros.core.estimation.disturbance import DisturbanceSettings
from helireach_ros.core.ocp.settings import load_settings
from helireach_ros.core.policies.failure_episode import FailureEpisode, PublishedPlan
from helireach_ros.core.policies.landing_supervisor import LandingSupervisor, SupervisorSettings
from helireach_ros.core.policies.live_reachability import LiveSettings
from helireach_ros.core.policies.plan_status import StatusReport
from helireach_ros.core.policies.vehicle_readings import (
    CurrentState,
    LatestReadings,
    OdometryReading,
    RotorReading,
    RotorSource,
)
from helireach_ros.core.units import FT, KT
from helireach_ros.core.workers.failure_planning import FailurePlanner
from helireach_ros.core.workers.live_scheduling import LiveScheduler
from helireach_ros.core.workers.planner_backend import BackendSettings, PlannerBackend
from helireach_ros.core.workers.solver_thread import SolverThread

MAX_AGE_NS = 500_000_000
HEIGHT, SPEED = 500 * FT, 75 * KT


class Clock:
    """A clock that moves only when told."""

    def __init__(self) -> None:
        self.now_ns = 10_000_000_000

    def __call__(self) -> int:
        return self.now_ns

    def advance(self, seconds: float) -> None:
        self.now_ns += int(seconds * 1e9)


class RecordingSink:
    """What the planner node does with a FailurePlanner's publications, recorded instead of sent."""

    def __init__(self, supervisor: LandingSupervisor, clock: Clock) -> None:
        self.supervisor = supervisor
        self.clock = clock
        self.plans: list[tuple[Any, CurrentState, str, bool, bool]] = []
        self.fallbacks: list[tuple[int, str]] = []
        self.no_plans: list[str] = []
        self.robust: list[tuple[int, int, int]] = []
        self.reports: list[tuple[str, str]] = []

    def publish_plan(
        self, failure: FailureEpisode, plan: Any, current: CurrentState, warm_source: str, *, replan: bool,
        robust_pending: bool = False,
    ) -> None:  # fmt: skip
        with self.supervisor.publication(failure, fallback=False) as allowed:
            if allowed:
                record = PublishedPlan(failure.failure_id, failure.replans, current.stamp_ns, plan, False, 0.0,
                                       self.clock(), warm_source)  # fmt: skip
                self.supervisor.remember(failure, record)
                self.plans.append((plan, current, warm_source, replan, robust_pending))

    def publish_fallback(self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int, reason: str) -> None:
        self.fallbacks.append((stamp_ns, reason))

    def publish_no_plan(self, failure: FailureEpisode, text: str) -> None:
        self.no_plans.append(text)

    def robust_pending(self, key: tuple[int, int, int]) -> None:
        self.robust.append(key)

    def report(self, level: str, text: str, throttle_s: float = 0.0) -> None:
        self.reports.append((level, text))


@pytest.fixture(scope="module")
def backend() -> PlannerBackend:
    settings = BackendSettings(solver_workers=0, warm_up=False)
    return PlannerBackend(load_airframe("uh60a_class"), load_settings(), settings, lambda *report: None)


def _feed(
    readings: LatestReadings, clock: Clock, height: float, speed: float, *, climb_rate: float = -5.0,
    rotor_speed: float | None = None, rotor: bool = True,
) -> None:  # fmt: skip
    """Readings stamped and received now (Ω₀ unless ``rotor_speed``; no rotor reading without ``rotor``)."""
    readings.add_odometry(OdometryReading(clock(), height, 0.0, speed, climb_rate), clock(), "base_link")
    if rotor:
        omega = readings.airframe.nominal_rotor_speed if rotor_speed is None else rotor_speed
        readings.add_rotor(RotorReading(clock(), omega, None), clock())


def _planner(
    backend: PlannerBackend | None, clock: Clock, *, disturbance: DisturbanceSettings | None = None
) -> tuple[FailurePlanner, RecordingSink, LatestReadings]:
    airframe = backend.airframe if backend is not None else load_airframe("uh60a_class")
    supervisor = LandingSupervisor(SupervisorSettings(deadline=0.25))
    readings = LatestReadings(airframe, MAX_AGE_NS, "base_link")
    sink = RecordingSink(supervisor, clock)
    planner = FailurePlanner(
        backend, "" if backend is not None else "ValueError: broken airframe", supervisor, readings, sink, clock,
        zero_power=True, disturbance=disturbance,
    )  # fmt: skip
    return planner, sink, readings


def test_the_failure_steps_load_without_ros() -> None:
    modules = "helireach_ros.core.workers.failure_planning, helireach_ros.core.workers.live_scheduling"
    code = f"import sys, {modules}; sys.exit('rclpy' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_the_latest_readings_make_the_state_to_plan_from_and_say_where_the_rotor_speed_came_from() -> None:
    clock = Clock()
    airframe = load_airframe("uh60a_class")
    readings = LatestReadings(airframe, MAX_AGE_NS, "base_link")
    assert readings.current(clock(), zero_power=True) is None  # nothing yet
    odometry = OdometryReading(clock(), HEIGHT, 3.0, SPEED, -2.0)
    assert readings.add_odometry(odometry, clock(), "")
    assert not readings.add_odometry(odometry._replace(height=float("nan")), clock(), "other")  # ignored
    current = readings.current(clock(), zero_power=True)
    assert current is not None and current.frame == "base_link" and current.rotor_source is RotorSource.ASSUMED_NOMINAL
    assert current.state[StateIndex.ROTOR_SPEED] == airframe.nominal_rotor_speed
    assert (current.state[StateIndex.HEIGHT], current.state[StateIndex.DESCENT_RATE]) == (HEIGHT, 2.0)
    omega0 = airframe.nominal_rotor_speed
    just_below = airframe.limits.min_rotor_speed_ratio * omega0 - 0.005 * omega0  # noise across the floor: clipped
    sample = readings.add_rotor(RotorReading(clock(), just_below, 1.0e6), clock())
    assert sample is not None and sample.rotor_speed == just_below and sample.engine_power == 1.0e6
    measured = readings.current(clock(), zero_power=False)
    assert measured is not None and measured.rotor_source is RotorSource.MEASURED
    assert measured.state[StateIndex.ROTOR_SPEED] == airframe.limits.min_rotor_speed_ratio * omega0
    assert measured.state[StateIndex.ENGINE_POWER] == 1.0e6
    assert readings.current(clock(), zero_power=True).state[StateIndex.ENGINE_POWER] == 0.0  # type: ignore[union-attr]
    clock.advance(0.3)
    assert readings.add_rotor(RotorReading(clock(), omega0, None), clock()) is not None  # odometry 0.3 s old: fresh
    clock.advance(0.3)
    assert readings.add_rotor(RotorReading(clock(), omega0, None), clock()) is None  # 0.6 s: no weight sample
    assert readings.current(clock(), zero_power=True) is None  # the odometry is stale


def test_the_solver_thread_skips_a_step_while_one_runs_queues_a_first_plan_and_reports_a_crash() -> None:
    errors: list[str] = []
    thread = SolverThread(errors.append)
    release, ran = threading.Event(), []

    def slow() -> None:
        release.wait(10.0)
        ran.append("slow")

    def broken() -> None:
        raise RuntimeError("boom")

    assert thread.submit(slow) and thread.busy
    assert not thread.submit(ran.append, "skipped")  # a re-plan tick while a solve runs
    assert thread.submit(ran.append, "queued", queue=True)  # a failure's first plan always runs
    assert thread.submit(broken, queue=True)
    release.set()
    deadline = time.monotonic() + 10.0
    while thread.busy and time.monotonic() < deadline:
        time.sleep(0.01)
    thread.shutdown()
    assert ran == ["slow", "queued"] and not thread.busy
    assert errors == ["planning step broken failed: RuntimeError: boom"]
    assert not thread.submit(ran.append, "late")  # shut down: refused, not raised


def test_a_failure_is_planned_from_the_envelope_then_re_planned_down_to_the_closed_loops_end(backend) -> None:
    clock = Clock()
    planner, sink, readings = _planner(backend, clock, disturbance=DisturbanceSettings())
    _feed(readings, clock, HEIGHT, SPEED)
    failure = planner.supervisor.start_failure(clock(), clock())
    assert failure is not None
    planner.fix_weight(None)
    assert planner.episode_weight.gross_weight == backend.airframe.gross_weight
    planner.first_plan(failure)
    assert len(sink.plans) == 1 and not sink.no_plans and not sink.fallbacks
    plan, _, source, replan, robust = sink.plans[0]
    assert plan.safe and plan.verified and source == "envelope" and not replan and not robust
    assert failure.disturbance is not None  # started after the first plan went out
    # a re-plan 0.25 s on, from the state the plan predicts (the same aircraft as the model)
    clock.advance(0.25)
    predicted = [float(np.interp(0.25, plan.times, component)) for component in plan.states]
    height = predicted[StateIndex.HEIGHT]
    _feed(
        readings, clock, height, predicted[StateIndex.FORWARD_SPEED], climb_rate=-predicted[StateIndex.DESCENT_RATE],
        rotor_speed=predicted[StateIndex.ROTOR_SPEED],
    )  # fmt: skip
    planner.replan(failure)
    assert len(sink.plans) == 2 and sink.plans[1][2] == "previous_plan" and sink.plans[1][3]
    assert failure.replans == 1
    # without a fresh rotor reading the re-plan pauses (the current plan is kept) and says so
    clock.advance(0.6)
    readings.add_odometry(OdometryReading(clock(), height - 10.0, 0.0, SPEED, -5.0), clock(), "base_link")
    planner.replan(failure)
    assert len(sink.plans) == 2 and failure.replans_skipped_no_rotor == 1
    assert sink.reports[-1][0] == "warning" and "re-planning paused" in sink.reports[-1][1]
    # near the ground the closed loop ends
    _feed(readings, clock, 0.2, 2.0)
    planner.replan(failure)
    assert not failure.active and "closed loop ends" in sink.reports[-1][1]
    planner.replan(failure)  # nothing more
    assert len(sink.plans) == 2


def test_without_a_state_or_a_solver_a_failure_gets_a_status_and_the_deadline_a_fallback(backend) -> None:
    clock = Clock()
    planner, sink, readings = _planner(backend, clock)
    failure = planner.supervisor.start_failure(clock(), clock())
    assert failure is not None
    planner.first_plan(failure)
    assert sink.no_plans == ["no valid vehicle state at the failure: waiting for one"] and not sink.plans
    planner.deadline()  # not yet due
    assert not sink.fallbacks
    clock.advance(0.3)
    planner.deadline()  # due, no state
    assert sink.no_plans[-1] == "no plan within 0.25 s and no valid state"
    planner.deadline()  # once per failure
    assert len(sink.no_plans) == 2
    # a second failure with a state: the deadline's fallback goes out for the state
    second = planner.supervisor.start_failure(clock() + 1, clock())
    assert second is not None
    _feed(readings, clock, HEIGHT, SPEED)
    clock.advance(0.3)
    _feed(readings, clock, HEIGHT, SPEED)
    planner.deadline()
    assert sink.fallbacks == [(clock(), "no plan within the 0.25 s deadline")]


def test_a_planner_that_is_not_configured_answers_every_step_with_its_reason() -> None:
    clock = Clock()
    planner, sink, readings = _planner(None, clock)
    _feed(readings, clock, HEIGHT, SPEED)
    failure = planner.supervisor.start_failure(clock(), clock())
    assert failure is not None
    planner.fix_weight(None)  # nothing to fix
    planner.first_plan(failure)
    not_configured = "planner not configured (ValueError: broken airframe)"
    assert sink.reports == [("error", f"failure #1: no converged plan ({not_configured})")]
    assert sink.no_plans == [f"{not_configured}; no fallback available ({not_configured})"]
    report = planner.health_report(None, solving=False, solve_timeout_s=3.0)
    assert report == StatusReport("ERROR", "not configured: ValueError: broken airframe", {})


def test_live_evaluation_runs_on_the_solver_thread_and_hands_the_failure_its_standby(backend) -> None:
    clock = Clock()
    readings = LatestReadings(backend.airframe, MAX_AGE_NS, "base_link")
    thread = SolverThread(lambda line: pytest.fail(line))
    verdicts: list[StatusReport] = []
    prepared: list[tuple[int, str]] = []
    live = LiveScheduler(
        LiveSettings(rate_hz=5.0), backend, thread, clock, verdicts.append,
        lambda plan, stamp_ns, frame: prepared.append((stamp_ns, frame)) or f"messages@{stamp_ns}",
    )  # fmt: skip
    _feed(readings, clock, HEIGHT, SPEED, rotor=False)
    live.tick(readings.current(clock(), zero_power=False))  # an assumed rotor speed: no verdict from it
    _feed(readings, clock, HEIGHT, SPEED)
    stamp_ns = clock()
    live.tick(readings.current(clock(), zero_power=False))
    thread.shutdown()  # waits for the evaluation
    assert len(verdicts) == 1 and verdicts[0].level == "OK" and verdicts[0].values["standby"] is True
    assert prepared == [(stamp_ns, "base_link")] and live.standby_messages == f"messages@{stamp_ns}"
    assert live.latest_weight is not None and live.latest_weight.gross_weight == backend.airframe.gross_weight
    standby = live.pause(stamp_ns + 100_000_000)  # a failure 0.1 s after the state
    assert standby is not None and standby.verdict.state_stamp_ns == stamp_ns and standby.frame == "base_link"
    assert standby.messages == f"messages@{stamp_ns}"
    assert live.pause(stamp_ns + 10 * 1_000_000_000) is None  # a failure long after: too old to stand by
    live.pause()  # the episode ended: every verdict forgotten
    assert live.evaluator.latest is None and live.pause(stamp_ns + 100_000_000) is None


def test_without_a_standby_on_the_site_the_first_plan_lands_anywhere_then_the_sites_plan_follows() -> None:
    """The deadline is met by the compiled anywhere NLP; the site's plan from the same state replaces it when verified;
    a site found unreachable is not tried by the next re-plans but every few."""
    from helireach_ros.core.policies.landing_sites import SITE_RETRY_EVERY, SiteSelection, parse_landing_sites

    airframe, settings = load_airframe("uh60a_class"), load_settings()
    backend = PlannerBackend(
        airframe, settings, BackendSettings(solver_workers=0, warm_up=False, site_planning=True), lambda *report: None
    )
    clock = Clock()
    supervisor = LandingSupervisor(SupervisorSettings(deadline=0.25))
    readings = LatestReadings(airframe, MAX_AGE_NS, "base_link")
    sink = RecordingSink(supervisor, clock)
    sites = SiteSelection(parse_landing_sites(["beyond:740:800", "far:5000:5100"]), "beyond")
    planner = FailurePlanner(
        backend, "", supervisor, readings, sink, clock, zero_power=True, disturbance=None, sites=sites
    )  # fmt: skip
    _feed(readings, clock, HEIGHT, SPEED)  # along-track distance 0: the site is 740-800 m ahead (anywhere: ~720 m)
    failure = supervisor.start_failure(clock(), clock())
    assert failure is not None
    planner.fix_weight(None)
    planner.fix_site(None)  # no standby plan
    planner.first_plan(failure)
    assert [plan.touchdown_window is not None for plan, *_ in sink.plans] == [False, True]
    anywhere, on_site = sink.plans[0][0], sink.plans[1][0]
    assert anywhere.safe and on_site.safe and sites.reachability(sites.sites[0]) is True
    assert planner.site_values(on_site)["on_site"] is True
    # the crew's far site: not reachable, the first plan lands anywhere and the site's attempt is not published
    crew_far = SiteSelection(sites.sites, "far")
    planner = FailurePlanner(
        backend, "", supervisor, readings, sink, clock, zero_power=True, disturbance=None, sites=crew_far
    )  # fmt: skip
    clock.advance(1.0)
    _feed(readings, clock, HEIGHT, SPEED)
    failure = supervisor.start_failure(clock(), clock())
    assert failure is not None
    planner.fix_site(None)
    published = len(sink.plans)
    planner.first_plan(failure)
    assert len(sink.plans) == published + 1 and sink.plans[-1][0].touchdown_window is None
    assert crew_far.reachability(crew_far.sites[1]) is False
    assert [crew_far.worth_trying(crew_far.sites[1]) for _ in range(SITE_RETRY_EVERY)][-1]  # every fifth solve
