"""Landing solves in worker processes: no GIL shared with a busy ROS executor, a hung solve can be killed.

CasADi re-takes the GIL between IPOPT iterations and around every CVODES call of the replay, so a solve in
the same process as a busy rclpy executor waits for it (measured: one busy Python thread makes the same solve
3.9× slower). A :class:`SolverPool` runs :meth:`~helireach_ros.core.planning.planner.LandingPlanner.plan` (solve +
independent replay + classification, exactly as in process) in ``workers`` processes of their own, each with
the NLP built once and warmed up.

- **Wire format.** Requests and plans cross the pipe as numpy arrays (:mod:`helireach_ros.core.array_codec`),
  never as pickles: the parent only ever decodes arrays into the dataclasses it expects.
- **Priorities.** Jobs are served lowest ``priority`` first (:data:`PRIORITY_FAILURE` before
  :data:`PRIORITY_LIVE`), first come first served within one priority. With two or more workers, low-priority
  jobs never occupy the last free worker, so a failure plan never waits for a live evaluation.
- **Supervision.** A worker that dies (any exit) or does not answer within the job's ``timeout_s`` is killed
  and restarted in the background (a worker that has to build the NLP of a job's weight says so, and gets
  :attr:`SolverPoolSettings.build_timeout_s` for the build before the job's own timeout starts); the job's future
  fails with :class:`SolverWorkerError` at once (within one supervision tick, :data:`SUPERVISION_PERIOD_S`, of the
  death or the timeout), and the caller falls back as it would after a failed solve. :attr:`SolverPool.restarts`
  counts restarts for diagnostics.
- **Start method.** ``forkserver`` (or ``spawn``), never ``fork``: the parent runs rclpy's threads.
- **Gross weight**. A request may name the gross weight to plan for (NaN: the airframe's). A worker
  builds that weight's NLP at the first request for it (:func:`~helireach_ros.core.planning.planner.get_planner` caches
  up to 16 per process; the compiled-NLP cache is keyed by the NLP's hash, so a new weight runs on plain CasADi
  functions) and keeps it (the airframe's and the 15 most recent others). The pool records which weights each worker
  holds (:meth:`SolverPool.ready_weights`). A failure job goes to an idle worker that holds its weight; a live job to
  one that lacks it, so the workers build a new weight one after the other before any failure. Before a failure only one
  live job runs at a time and it runs on a worker lacking the weight whenever one is idle, so a weight one ready worker
  holds finds that worker idle at the failure: no NLP is built in the failure path. A worker restarted after it had
  reported ready builds (and warms up) every weight its predecessor held before it reports ready, so a restart does not
  put an NLP build in front of the next failure job (a build takes seconds, longer than a failure job's timeout); one
  that died before it was ready is restarted with the airframe's weight only, so an NLP whose build kills its worker
  does not restart for ever.
"""

from __future__ import annotations

import heapq
import itertools
import math
import multiprocessing
import os
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeoutError
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.array_codec import decode_dataclass, encode_dataclass
from helireach_ros.core.ocp.settings import FOOTPRINT_OBJECTIVES, PlannerSettings
from helireach_ros.core.planning.planner import ControlFunctionWarmStart, LandingPlan, WarmStart

__all__ = [
    "PRIORITY_FAILURE",
    "PRIORITY_LIVE",
    "QUEUE_WAIT_LIMIT_S",
    "SUPERVISION_PERIOD_S",
    "SolverPool",
    "SolverPoolSettings",
    "SolverWorkerError",
]

PRIORITY_FAILURE = 0
"""Priority of a plan after an engine failure (served first)."""
PRIORITY_LIVE = 10
"""Priority of a live evaluation before any failure."""
SUPERVISION_PERIOD_S = 0.01
"""How often the dispatcher checks for hung workers when nothing else wakes it, s."""
QUEUE_WAIT_LIMIT_S = 60.0
"""Longest :meth:`SolverPool.plan` waits for a worker to take its job (a restart takes a few seconds), s."""

_READY = b"ready"
_BUILDING = b"building"  # the worker builds the NLP of a job's weight (build_timeout_s applies)
_BUILT = b"built"  # ... and has built it: the job's solve starts now
_HELD_WEIGHTS = 15  # a worker keeps the NLPs of this many recent weights besides the airframe's (get_planner: 16)
_STOP = b"stop"


class SolverWorkerError(RuntimeError):
    """A solve did not come back: its worker died or hung (it was killed and is being restarted)."""


@dataclass(frozen=True)
class SolverPoolSettings:
    """How the pool runs.

    Attributes:
        workers: worker processes (≥ 1; each holds one NLP, ~100 MB).
        start_method: ``"forkserver"`` or ``"spawn"`` (``fork`` is refused: the parent may run threads).
        warm_up: each worker solves one landing before it reports ready (first-call costs).
        default_timeout_s: a job's timeout when the caller gives none, s.
        build_timeout_s: longest a worker may take to build the NLP of a gross weight it does not hold yet before
            the job's own timeout starts, s (a build on plain CasADi functions takes seconds; a job's timeout is
            sized for a solve).
        site_planning: each worker also builds (and warms up) the landing-site NLP of every weight it holds, so that
            a job with a touchdown window builds nothing (the settings' method must be ``flyable``).
        footprint: each worker also builds (and warms up) the reachable footprint's two NLPs (nearest and farthest
            touchdown) of the airframe's weight, so that a footprint job builds nothing (``flyable`` too).
    """

    workers: int = 2
    start_method: str = "forkserver"
    warm_up: bool = True
    default_timeout_s: float = 5.0
    build_timeout_s: float = 120.0
    site_planning: bool = False
    footprint: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.workers, int) or self.workers < 1:
            raise ValueError(f"workers must be an integer >= 1, got {self.workers!r}")
        if self.start_method not in ("forkserver", "spawn"):
            raise ValueError(f"start_method must be 'forkserver' or 'spawn', got {self.start_method!r}")
        for name in ("default_timeout_s", "build_timeout_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be > 0, got {value!r}")


@dataclass(frozen=True)
class _SolveRequest:
    state: np.ndarray
    warm_start: WarmStart | None
    cold_check: bool
    initial_control: np.ndarray | None = None
    reaction_delay_s: float | None = None
    gross_weight: float = math.nan  # N; NaN = the worker's airframe's
    disturbance: np.ndarray | None = None  # (d_y, d_v, d_Ω); None = the model as it is
    stored_controls: ControlFunctionWarmStart | None = None  # a stored plan to warm-start from (not warm_start)
    touchdown_window: np.ndarray | None = None  # (start, end) m from the state: land on this site, else anywhere
    objective: str = ""  # a footprint end's objective ('' = the settings', or the site's with a touchdown window)

    @property
    def start(self) -> WarmStart | ControlFunctionWarmStart | None:
        return self.warm_start if self.warm_start is not None else self.stored_controls


@dataclass(frozen=True)
class _SolveReply:
    plan: LandingPlan | None
    error: str


def _worker_main(
    connection: Connection,
    airframe: Airframe,
    settings: PlannerSettings,
    warm_up: bool,
    gross_weights: tuple[float, ...] = (),
    site_planning: bool = False,
    footprint: bool = False,
) -> None:
    """A worker: builds the NLP (and one for each of ``gross_weights``, N; with ``site_planning`` the landing-site NLP
    of each too; with ``footprint`` the footprint ends' NLPs of the airframe's weight), warms them up, then answers
    requests until told to stop or the pipe closes."""
    from helireach_ros.core.aircraft.model import initial_state_after_failure
    from helireach_ros.core.planning.planner import get_planner
    from helireach_ros.core.policies.landing_sites import plan_site_or_anywhere

    held: dict[tuple[float, str], None] = {}  # the recent (weight, objective) NLPs, oldest first: get_planner's cache

    def planner_for(gross_weight: float, objective: str = "", announce: bool = False) -> Any:
        """The NLP of a weight (NaN: the airframe's) and an objective ('' = the settings'): built at its first
        request, then cached."""
        weight = airframe.gross_weight if math.isnan(gross_weight) else gross_weight
        building = (weight, objective) not in held
        if building and announce:
            connection.send_bytes(_BUILDING)
        model = airframe if weight == airframe.gross_weight else airframe.with_conditions(gross_weight=weight)
        built = get_planner(model, settings.replace(objective=objective) if objective else settings)
        held.pop((weight, objective), None)
        held[(weight, objective)] = None
        while len(held) > 2 * (_HELD_WEIGHTS + 1):
            held.pop(next(iter(held)))
        if building and announce:
            connection.send_bytes(_BUILT)
        return built

    warm_up_state = initial_state_after_failure(airframe, 150.0, 38.0)
    for gross_weight in (math.nan, *gross_weights):
        built = planner_for(gross_weight)
        if warm_up:
            plan = built.plan(warm_up_state)
        if site_planning:
            site_built = planner_for(gross_weight, "site")
            if warm_up:  # a site around the touchdown-cost plan's touchdown
                distance = float(plan.replay.touchdown_state[StateIndex.DISTANCE] - warm_up_state.distance)
                site_built.plan(warm_up_state, touchdown_window=(distance - 30.0, distance + 30.0))
        if footprint and math.isnan(gross_weight):
            for objective in FOOTPRINT_OBJECTIVES:
                end = planner_for(gross_weight, objective)
                if warm_up:
                    end.plan(warm_up_state, plan.warm_start)
    connection.send_bytes(_READY)
    while True:
        try:
            data = connection.recv_bytes()
        except (EOFError, OSError):
            return
        if data == _STOP:
            return
        try:
            request = decode_dataclass(_SolveRequest, data)
            anywhere_planner = planner_for(request.gross_weight, request.objective, announce=True)
            window, site_planner = None, None
            if request.touchdown_window is not None:
                window = (float(request.touchdown_window[0]), float(request.touchdown_window[1]))
                site_planner = planner_for(request.gross_weight, "site", announce=True)
            plan = plan_site_or_anywhere(
                anywhere_planner, site_planner, request.state, request.start, window, cold_check=request.cold_check,
                initial_control=request.initial_control, reaction_delay_s=request.reaction_delay_s,
                disturbance=request.disturbance,
            )  # fmt: skip
            reply = _SolveReply(plan, "")
        except (ValueError, RuntimeError) as error:
            reply = _SolveReply(None, f"{type(error).__name__}: {error}")
        connection.send_bytes(encode_dataclass(reply))


@dataclass
class _Job:
    payload: bytes
    future: Future
    timeout_s: float
    priority: int
    started: float = 0.0  # when the solve's clock started (assigned, or its NLP built), monotonic s
    gross_weight: float = math.nan
    building: bool = False  # its worker said it builds the NLP of its weight (build_timeout_s applies)

    def deadline(self, build_timeout_s: float) -> float:
        """When the worker running this job is deemed hung, monotonic s."""
        return self.started + (build_timeout_s if self.building else self.timeout_s)


class _Worker:
    """One worker process and the parent's end of its pipe."""

    def __init__(
        self,
        context: Any,
        airframe: Airframe,
        settings: PlannerSettings,
        warm_up: bool,
        gross_weights: tuple[float, ...] = (),
        site_planning: bool = False,
        footprint: bool = False,
    ) -> None:
        self.connection, child = context.Pipe(duplex=True)
        extra = tuple(weight for weight in gross_weights if weight != airframe.gross_weight)[-_HELD_WEIGHTS:]
        self.process = context.Process(
            target=_worker_main,
            args=(child, airframe, settings, warm_up, extra, site_planning, footprint),
            name="helireach_solver",
            daemon=True,
        )
        self.process.start()
        child.close()
        self.ready = False
        self.job: _Job | None = None
        self._airframe_weight = airframe.gross_weight
        self._recent = dict.fromkeys(extra)  # the other weights it holds, oldest first (as the worker's own record)
        self._lock = threading.Lock()

    @property
    def weights(self) -> set[float]:
        """Gross weights whose NLPs this worker holds, N."""
        with self._lock:
            return {self._airframe_weight, *self._recent}

    @property
    def recent_weights(self) -> tuple[float, ...]:
        """The weights other than the airframe's it holds, oldest first (what a replacement builds)."""
        with self._lock:
            return tuple(self._recent)

    def hold(self, gross_weight: float) -> None:
        """Records that the worker built or used the NLP of ``gross_weight`` (N), as the worker records it."""
        if gross_weight == self._airframe_weight:
            return
        with self._lock:
            self._recent.pop(gross_weight, None)
            self._recent[gross_weight] = None
            while len(self._recent) > _HELD_WEIGHTS:
                self._recent.pop(next(iter(self._recent)))

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join(timeout=5.0)
        self.connection.close()


class SolverPool:
    """Landing solves in worker processes (see the module docstring).

    Args:
        airframe: the airframe every worker plans for.
        settings: planner settings (default: the ``verified`` method).
        pool_settings: workers, start method, warm-up, default timeout.
    """

    def __init__(
        self,
        airframe: Airframe,
        settings: PlannerSettings | None = None,
        pool_settings: SolverPoolSettings | None = None,
    ) -> None:
        self.airframe = airframe
        self.settings = settings or PlannerSettings()
        self.pool_settings = pool_settings or SolverPoolSettings()
        self._context = multiprocessing.get_context(self.pool_settings.start_method)
        if self.pool_settings.start_method == "forkserver":
            self._context.set_forkserver_preload(["helireach_ros.core.workers.solver_pool"])
        self._lock = threading.Lock()
        self._queue: list[tuple[int, int, _Job]] = []
        self._sequence = itertools.count()
        self._closed = False
        self.restarts = 0
        self.last_error = ""
        self._wake_reader, self._wake_writer = os.pipe()
        self._workers = [self._start_worker() for _ in range(self.pool_settings.workers)]
        self._dispatcher = threading.Thread(target=self._dispatch, name="helireach_solver_pool", daemon=True)
        self._dispatcher.start()

    # -- public ----------------------------------------------------------------------------------------------
    def submit(
        self,
        state: np.ndarray,
        warm_start: WarmStart | ControlFunctionWarmStart | None = None,
        *,
        priority: int = PRIORITY_FAILURE,
        timeout_s: float | None = None,
        cold_check: bool = False,
        initial_control: np.ndarray | None = None,
        reaction_delay_s: float | None = None,
        gross_weight: float | None = None,
        disturbance: np.ndarray | None = None,
        touchdown_window: tuple[float, float] | None = None,
        objective: str = "",
    ) -> Future:
        """Queues a solve; the future gives the :class:`~helireach_ros.core.planning.planner.LandingPlan`.

        ``touchdown_window`` (start, end; m of touchdown distance from ``state``): land on that site, or anywhere if no
        site plan is safe (:func:`~helireach_ros.core.policies.landing_sites.solve_site_or_anywhere`; the plan's own
        ``touchdown_window`` says which it is). Needs :attr:`SolverPoolSettings.site_planning`, so no NLP is built
        for it in a job. ``objective``: a footprint end's (``nearest_touchdown``, ``farthest_touchdown``; needs
        :attr:`SolverPoolSettings.footprint`), '' for the settings'.

        ``initial_control``, ``reaction_delay_s`` and ``disturbance`` are passed to
        :meth:`~helireach_ros.core.planning.planner.LandingPlanner.plan` (None: its defaults). ``gross_weight`` (N, None
        = the pool's airframe's): plan for the airframe at that weight (module docstring).

        ``cold_check``: a warm plan that is not safe is solved again cold in the worker
        (:func:`~helireach_ros.core.policies.live_reachability.solve_with_cold_check`). The future raises
        :class:`ValueError` for a state the planner refuses, and :class:`SolverWorkerError` when the worker
        died or did not answer within ``timeout_s`` (counted from when a worker took the job).
        """
        future: Future = Future()
        control = None if initial_control is None else np.asarray(initial_control, dtype=float).reshape(-1)
        delay = None if reaction_delay_s is None else float(reaction_delay_s)
        weight = self.airframe.gross_weight if gross_weight is None else float(gross_weight)
        disturbance = None if disturbance is None else np.asarray(disturbance, dtype=float).reshape(-1)
        stored = warm_start if isinstance(warm_start, ControlFunctionWarmStart) else None
        solver_warm_start = None if isinstance(warm_start, ControlFunctionWarmStart) else warm_start
        if touchdown_window is not None and not self.pool_settings.site_planning:
            raise ValueError("a touchdown window needs a pool built with site_planning")
        if objective and (objective not in FOOTPRINT_OBJECTIVES or not self.pool_settings.footprint):
            raise ValueError(f"objective {objective!r}: only a footprint end's, in a pool built with footprint")
        if objective and touchdown_window is not None:
            raise ValueError("a footprint end has no touchdown window")
        window = None if touchdown_window is None else np.asarray(touchdown_window, dtype=float).reshape(2)
        request = _SolveRequest(
            np.asarray(state, dtype=float).reshape(-1), solver_warm_start, cold_check, control, delay, weight,
            disturbance, stored, window, objective,
        )  # fmt: skip
        payload = encode_dataclass(request)
        job = _Job(payload, future, timeout_s or self.pool_settings.default_timeout_s, priority, gross_weight=weight)
        with self._lock:
            if self._closed:
                raise RuntimeError("the solver pool is closed")
            heapq.heappush(self._queue, (priority, next(self._sequence), job))
        self._wake()
        return future

    def plan(
        self,
        state: np.ndarray,
        warm_start: WarmStart | ControlFunctionWarmStart | None = None,
        *,
        priority: int = PRIORITY_FAILURE,
        timeout_s: float | None = None,
        **request: Any,
    ) -> LandingPlan:
        """Solves and waits: :meth:`submit` (``request``: its keyword arguments) then the result.

        The wait is bounded (the job's timeout plus :data:`QUEUE_WAIT_LIMIT_S` in the queue, e.g. while a worker
        restarts): beyond it :class:`SolverWorkerError`, so a caller never waits for ever.
        """
        timeout = timeout_s or self.pool_settings.default_timeout_s
        future = self.submit(state, warm_start, priority=priority, timeout_s=timeout, **request)
        try:
            return future.result(timeout=timeout + QUEUE_WAIT_LIMIT_S)
        except FutureTimeoutError:
            future.cancel()
            raise SolverWorkerError(f"no worker answered within {timeout + QUEUE_WAIT_LIMIT_S:g} s") from None

    def wait_ready(self, timeout_s: float, count: int = 1) -> bool:
        """Waits until at least ``count`` workers are ready (NLP built, warmed up); returns whether they are."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.ready_workers >= count:
                return True
            time.sleep(0.01)
        return self.ready_workers >= count

    @property
    def ready_workers(self) -> int:
        """Workers that have built their NLP and can take a job."""
        with self._lock:
            return sum(worker.ready and worker.process.is_alive() for worker in self._workers)

    def ready_weights(self, every: bool = False) -> set[float]:
        """Gross weights (N) some ready worker holds the NLP of (``every``: every ready worker): a failure job for
        one of them goes to a worker that holds it (module docstring). The airframe's weight when none is ready."""
        with self._lock:
            held = [worker.weights for worker in self._workers if worker.ready and worker.process.is_alive()]
        if not held:
            return {self.airframe.gross_weight}
        return set.intersection(*held) if every else set.union(*held)

    @property
    def busy_workers(self) -> int:
        """Workers solving now."""
        with self._lock:
            return sum(worker.job is not None for worker in self._workers)

    def worker_pids(self) -> list[int]:
        """The workers' process ids (e.g. for a test that kills one)."""
        with self._lock:
            return [worker.process.pid for worker in self._workers if worker.process.pid is not None]

    def close(self) -> None:
        """Stops the workers (queued and running jobs fail with :class:`SolverWorkerError`)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._wake()
        self._dispatcher.join(timeout=10.0)
        os.close(self._wake_reader)
        os.close(self._wake_writer)

    def __enter__(self) -> SolverPool:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- dispatcher thread -----------------------------------------------------------------------------------
    def _start_worker(self, gross_weights: tuple[float, ...] = ()) -> _Worker:
        return _Worker(
            self._context,
            self.airframe,
            self.settings,
            self.pool_settings.warm_up,
            gross_weights,
            self.pool_settings.site_planning,
            self.pool_settings.footprint,
        )

    def _wake(self) -> None:
        try:
            os.write(self._wake_writer, b"x")
        except OSError:
            pass

    def _assign(self) -> None:
        """Hands queued jobs to idle ready workers, keeping one worker free of low-priority work."""
        with self._lock:
            idle = [
                worker for worker in self._workers if worker.ready and worker.job is None and worker.process.is_alive()
            ]
            busy_low = sum(
                1 for worker in self._workers if worker.job is not None and worker.job.priority > PRIORITY_FAILURE
            )
            while idle and self._queue:
                priority = self._queue[0][0]
                if priority > PRIORITY_FAILURE and len(self._workers) > 1 and busy_low >= len(self._workers) - 1:
                    break
                _, _, job = heapq.heappop(self._queue)
                if not job.future.set_running_or_notify_cancel():
                    continue
                worker = self._pick(idle, job)
                idle.remove(worker)
                job.started = time.monotonic()
                worker.job = job
                busy_low += priority > PRIORITY_FAILURE
                try:
                    worker.connection.send_bytes(job.payload)
                except OSError:
                    pass  # a dead worker: its sentinel fails the job on the next pass

    @staticmethod
    def _pick(idle: list[_Worker], job: _Job) -> _Worker:
        """The idle worker for a job: a failure job one that holds its weight (no NLP built in the failure path),
        a live job one that lacks it (so every worker builds a new weight before a failure); else the last."""
        wants_weight = job.priority <= PRIORITY_FAILURE
        matching = [worker for worker in idle if (job.gross_weight in worker.weights) == wants_weight]
        return (matching or idle)[-1]

    def _replace(self, worker: _Worker, reason: str) -> None:
        """Kills a dead or hung worker, fails its job, starts a new one (ready later, in the background) holding the
        weights the old one held if it had been ready (module docstring)."""
        job = worker.job
        inherited = worker.recent_weights if worker.ready else ()
        worker.job = None
        worker.kill()
        self.restarts += 1
        self.last_error = reason
        if job is not None:
            job.future.set_exception(SolverWorkerError(f"{reason}; the worker was restarted"))
        if not self._closed:
            replacement = self._start_worker(inherited)
            with self._lock:
                self._workers[self._workers.index(worker)] = replacement

    def _dispatch(self) -> None:
        while True:
            try:
                if self._dispatch_once():
                    return
            except Exception as error:  # the supervisor must outlive any surprise (e.g. no process can be started)
                self.last_error = f"solver pool dispatcher: {type(error).__name__}: {error}"
                time.sleep(0.1)

    def _dispatch_once(self) -> bool:
        """One pass: serve answers, deaths and time-outs, hand out jobs, wait. True when the pool is closed."""
        with self._lock:
            closed = self._closed
        if closed:
            self._stop_all()
            return True
        with self._lock:
            workers = list(self._workers)
        now = time.monotonic()
        for worker in workers:  # answers, deaths and time-outs first: a dead worker gets no new job
            self._service(worker, now)
        self._assign()
        with self._lock:
            workers = list(self._workers)
        waitables: list[Any] = [self._wake_reader]
        for worker in workers:
            waitables += [worker.connection, worker.process.sentinel]
        for ready in wait(waitables, timeout=SUPERVISION_PERIOD_S):
            if ready == self._wake_reader:
                os.read(self._wake_reader, 4096)
        return False

    def _service(self, worker: _Worker, now: float) -> None:
        """Reads a worker's answer, or replaces it when it died or its job timed out."""
        try:
            has_data = worker.connection.poll()
        except (OSError, EOFError):
            has_data = False
        if has_data:
            try:
                data = worker.connection.recv_bytes()
            except (EOFError, OSError):
                data = None
            if data == _READY:
                with self._lock:
                    worker.ready = True
                return
            if data in (_BUILDING, _BUILT):
                if worker.job is not None:  # the job's clock restarts: for the build, then for the solve
                    worker.job.started, worker.job.building = time.monotonic(), data == _BUILDING
                    if data == _BUILT:
                        worker.hold(worker.job.gross_weight)
                return
            if data is not None and worker.job is not None:
                job, worker.job = worker.job, None
                try:
                    reply = decode_dataclass(_SolveReply, data)
                except ValueError as error:
                    job.future.set_exception(SolverWorkerError(f"unreadable answer from the worker: {error}"))
                    return
                if reply.plan is None:
                    job.future.set_exception(ValueError(reply.error))
                else:
                    worker.hold(job.gross_weight)
                    job.future.set_result(reply.plan)
                return
        if not worker.process.is_alive():
            self._replace(worker, f"solver worker {worker.process.pid} died (exit code {worker.process.exitcode})")
        elif worker.job is not None and now > worker.job.deadline(self.pool_settings.build_timeout_s):
            limit = f"{worker.job.timeout_s:g} s"
            if worker.job.building:
                limit = f"{self.pool_settings.build_timeout_s:g} s building the NLP of its weight"
            self._replace(worker, f"solver worker {worker.process.pid} gave no answer within {limit}")

    def _stop_all(self) -> None:
        with self._lock:
            queued = [job for _, _, job in self._queue]
            self._queue.clear()
            workers = list(self._workers)
        for job in queued:
            if not job.future.done():
                job.future.set_exception(SolverWorkerError("the solver pool was closed"))
        for worker in workers:
            if worker.job is not None and not worker.job.future.done():
                worker.job.future.set_exception(SolverWorkerError("the solver pool was closed"))
            try:
                worker.connection.send_bytes(_STOP)
            except OSError:
                pass
        for worker in workers:
            worker.process.join(timeout=2.0)
            worker.kill()
