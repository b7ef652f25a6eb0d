"""Live reachability: "if the engine failed now, could we land?" answered continuously from the measured state.

Before any failure the planner evaluates, at ``rate_hz``, the landing NLP from the latest valid measured state
with the engine assumed to fail at that instant: the state is the measured one (descent rate, speed, rotor
speed, height) with the engine power replaced by what is left after the failure,

.. math:: P_0 = \\text{power\\_fraction} \\cdot P_{\\text{measured}},

decaying with the engine time constant as in every plan (``power_fraction`` 0 = total power loss, the
default). Each evaluation is warm-started from the previous live solution (the state moves little between
two evaluations), and is a full :meth:`~helireach_ros.core.planning.planner.LandingPlanner.plan`: solve, independent
replay, classification. A warm solve that is not ``safe`` is solved again cold (:func:`solve_with_cold_check`):
a warm start can lead IPOPT to a local optimum whose replay fails (measured: warm plans at 120 kt, ~480 ft
that skim the ground, where the cold plan lands), and the cold answer is what ``helireach plan`` gives. The
verdict is the cold plan if that is replay-verified safe, else the warm one: never safe without a verified
plan, and equal to ``helireach plan`` wherever that finds a safe landing.

When the latest live verdict is ``safe`` (replay-verified), its plan is the **standby plan**: when the engine
fails, a standby made from a state at most ``standby_max_age_s`` older than the failure is published at once,
flagged ``standby``, before the planner re-plans from the state at the failure. A newer verdict that is not safe
withdraws the standby.

A verdict is evidence about one state at one time: :meth:`LiveVerdict.is_current` says whether it still is
(its state not older than ``max_verdict_age_s``). Pure policy, no threads, no ROS: times are passed in (ns).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.planning.planner import ControlFunctionWarmStart, LandingPlan, WarmStart

__all__ = [
    "WARM_START_NEIGHBOURHOOD",
    "LiveEvaluator",
    "LiveSettings",
    "LiveVerdict",
    "failure_now_state",
    "solve_with_cold_check",
]

AnyWarmStart = WarmStart | ControlFunctionWarmStart | None
"""A solve's start: a previous solution, a stored plan's control function (the envelope's), or cold."""


@dataclass(frozen=True)
class LiveSettings:
    """The live evaluation's policy (planner node parameters of the same names).

    Attributes:
        rate_hz: evaluations per second (at most; one at a time).
        power_fraction: engine power left after the assumed failure, as a fraction of the measured power.
        max_state_age_s: a state older than this when an evaluation starts is not evaluated, s.
        max_verdict_age_s: a verdict whose state is older than this is no longer evidence, s.
        standby_max_age_s: the standby plan is used only if its state is at most this much older than the
            failure, s.
    """

    rate_hz: float = 5.0
    power_fraction: float = 0.0
    max_state_age_s: float = 0.3
    max_verdict_age_s: float = 1.0
    standby_max_age_s: float = 0.3

    def __post_init__(self) -> None:
        for name in ("rate_hz", "max_state_age_s", "max_verdict_age_s", "standby_max_age_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if not 0.0 <= self.power_fraction <= 1.0:
            raise ValueError(f"power_fraction must lie in [0, 1], got {self.power_fraction!r}")

    @property
    def period_ns(self) -> int:
        """Time between two evaluations, ns."""
        return int(1e9 / self.rate_hz)


@dataclass(frozen=True)
class LiveVerdict:
    """One live evaluation.

    Attributes:
        status: the plan's status (``safe``, ``unsafe``, ``unverified``, ``failed``) or ``error`` (the solve
            raised: a refused state, a dead solver worker; ``reason`` says which).
        value: the NLP value J (≤ 0: a safe landing reachable), NaN without a plan.
        state: the evaluated state (y, v, Ω, h, z, P₀), SI.
        state_stamp_ns: stamp of the measurement it comes from.
        evaluated_at_ns: when the evaluation finished.
        solve_time_ms: wall time of the evaluation (solve + replay + transport), ms.
        plan: the plan (None for ``error``).
        reason: why there is no plan, for ``error``.
    """

    status: str
    value: float
    state: np.ndarray
    state_stamp_ns: int
    evaluated_at_ns: int
    solve_time_ms: float
    plan: LandingPlan | None = None
    reason: str = ""

    @property
    def safe(self) -> bool:
        """The landing from this state is reachable and the replay confirmed it."""
        return self.status == "safe" and self.plan is not None and self.plan.safe

    def state_age_s(self, now_ns: int) -> float:
        """How old the evaluated state is at ``now_ns``, s."""
        return (now_ns - self.state_stamp_ns) * 1e-9

    def is_current(self, now_ns: int, settings: LiveSettings) -> bool:
        """Whether the verdict still speaks for the aircraft: its state at most ``max_verdict_age_s`` old."""
        return 0.0 <= self.state_age_s(now_ns) <= settings.max_verdict_age_s


def solve_with_cold_check(
    solve: Callable[[np.ndarray, AnyWarmStart], LandingPlan], state: np.ndarray, warm_start: AnyWarmStart
) -> LandingPlan:
    """A warm solve, and a cold one if the warm plan is not safe. The cold plan wins if it is safe, or if the warm
    solve did not converge and the cold one did (a failed solve is no answer; an unsafe cold plan is one)."""
    plan = solve(state, warm_start)
    if warm_start is None or plan.safe:
        return plan
    cold = solve(state, None)
    return cold if cold.safe or (cold.solver.success and not plan.solver.success) else plan


def failure_now_state(measured_state: np.ndarray, power_fraction: float) -> np.ndarray:
    """The state if the engine failed at the measurement: the measured state with P₀ = fraction × measured P."""
    state = np.array(measured_state, dtype=float).reshape(-1)
    if state.shape != (6,):
        raise ValueError(f"a helicopter state has 6 components, got shape {state.shape}")
    state[StateIndex.ENGINE_POWER] = power_fraction * max(state[StateIndex.ENGINE_POWER], 0.0)
    return state


# (descent rate m/s, forward speed m/s, height m): the largest change from the previous live solution's state for
# which it is the warm start. At 5 Hz a flying aircraft changes far less; a bigger jump (a log replayed from
# elsewhere, a sensor reset) starts cold or from the envelope, because a far warm start ends in worse local optima
# (measured: warm from 20 ft / 90 kt, the plan from 600 ft / 20 kt had J = -0.21; cold, J = -0.36).
WARM_START_NEIGHBOURHOOD = np.array([5.0, 10.0, 30.0])
_NEIGHBOURHOOD_COMPONENTS = [StateIndex.DESCENT_RATE, StateIndex.FORWARD_SPEED, StateIndex.HEIGHT]


class LiveEvaluator:
    """Schedules live evaluations, warm-starts each from the last, and keeps the standby plan.

    Blocking use: :meth:`evaluate`. With a solver pool (asynchronous): :meth:`prepare`, submit the solve,
    then :meth:`record` with its plan or error.

    Args:
        settings: the policy.
        solve: ``solve(state, warm_start) -> LandingPlan`` for :meth:`evaluate` (in process, or through a
            solver pool); may raise ``ValueError``/``RuntimeError``, which become an ``error`` verdict.
    """

    def __init__(
        self, settings: LiveSettings, solve: Callable[[np.ndarray, AnyWarmStart], LandingPlan] | None = None
    ) -> None:
        self.settings = settings
        self._solve = solve
        self.latest: LiveVerdict | None = None
        self.standby_verdict: LiveVerdict | None = None
        self._warm_start: WarmStart | None = None
        self._warm_state: np.ndarray | None = None
        self._last_started_ns: int | None = None
        self.evaluations = 0
        self.errors = 0
        self.clock_jumps_back = 0  # times ``now`` came before the last evaluation's start (sim time restarted)

    @property
    def has_warm_start(self) -> bool:
        """There is a previous live solution to start from (see :meth:`warm_start_applies`)."""
        return self._warm_start is not None

    def warm_start_applies(self, measured_state: np.ndarray) -> bool:
        """The evaluation of ``measured_state`` starts from the previous live solution: there is one, and it was
        made from a state within :data:`WARM_START_NEIGHBOURHOOD` of this one (a fallback is then not needed)."""
        if self._warm_start is None or self._warm_state is None:
            return False
        change = np.abs(
            np.asarray(measured_state, dtype=float).reshape(-1)[_NEIGHBOURHOOD_COMPONENTS]
            - self._warm_state[_NEIGHBOURHOOD_COMPONENTS]
        )
        return bool(np.all(change <= WARM_START_NEIGHBOURHOOD))

    def due(self, now_ns: int) -> bool:
        """Whether the next evaluation is due (one per period). A clock that went back (a replay's sim time
        restarting) restarts the schedule rather than pausing the evaluation until it catches up; it is counted."""
        if self._last_started_ns is not None and now_ns < self._last_started_ns:
            self.clock_jumps_back += 1
            self._last_started_ns = None
        return self._last_started_ns is None or now_ns - self._last_started_ns >= self.settings.period_ns

    def prepare(
        self, measured_state: np.ndarray, state_stamp_ns: int, now_ns: int, fallback_warm_start: AnyWarmStart = None
    ) -> tuple[np.ndarray, AnyWarmStart] | None:
        """Starts an evaluation: (the engine-fails-now state, the warm start), or None if the state is too old.

        Args:
            measured_state: (y, v, Ω, h, z, P_measured), SI.
            state_stamp_ns: its stamp.
            now_ns: now (the evaluation's start; the schedule counts from here).
            fallback_warm_start: used when there is no previous live solution (e.g. the envelope's nearest plan).
        """
        self._last_started_ns = now_ns
        if (now_ns - state_stamp_ns) * 1e-9 > self.settings.max_state_age_s:
            return None
        warm_start = self._warm_start if self.warm_start_applies(measured_state) else fallback_warm_start
        return failure_now_state(measured_state, self.settings.power_fraction), warm_start

    def record(
        self,
        state: np.ndarray,
        state_stamp_ns: int,
        started_ns: int,
        finished_ns: int,
        plan: LandingPlan | None,
        error: str = "",
    ) -> LiveVerdict:
        """Ends an evaluation with its plan (or the error that replaced it) and updates warm start and standby."""
        elapsed_ms = (finished_ns - started_ns) * 1e-6
        if plan is None:
            self.errors += 1
            verdict = LiveVerdict("error", math.nan, state, state_stamp_ns, finished_ns, elapsed_ms, None, error)
            self._warm_start = None
        else:
            self.evaluations += 1
            verdict = LiveVerdict(plan.status, plan.value, state, state_stamp_ns, finished_ns, elapsed_ms, plan)
            # Only a converged solution is a good start for the next one (a failed solve's iterate may be anywhere).
            self._warm_start = plan.warm_start if plan.solver.success else None
            self._warm_state = np.array(state, dtype=float).reshape(-1)
        self.latest = verdict
        # The standby is the latest verdict or nothing: an older safe plan after a newer unsafe verdict
        # would answer for a state the aircraft has left.
        self.standby_verdict = verdict if verdict.safe else None
        return verdict

    def evaluate(
        self,
        measured_state: np.ndarray,
        state_stamp_ns: int,
        now_ns: int,
        clock_ns: Callable[[], int],
        fallback_warm_start: AnyWarmStart = None,
    ) -> LiveVerdict | None:
        """One evaluation, blocking: :meth:`prepare`, the solve, :meth:`record` (None if the state is too old)."""
        if self._solve is None:
            raise RuntimeError("this evaluator has no solve function: use prepare() and record()")
        prepared = self.prepare(measured_state, state_stamp_ns, now_ns, fallback_warm_start)
        if prepared is None:
            return None
        state, warm_start = prepared
        try:
            plan, error = solve_with_cold_check(self._solve, state, warm_start), ""
        except (ValueError, RuntimeError) as exception:
            plan, error = None, f"{type(exception).__name__}: {exception}"
        return self.record(state, state_stamp_ns, now_ns, clock_ns(), plan, error)

    def standby(self, failure_stamp_ns: int) -> LiveVerdict | None:
        """The standby plan for a failure at ``failure_stamp_ns``: the latest safe live verdict, if fresh enough.

        Fresh enough: its state is at most ``standby_max_age_s`` older than the failure (and not after it).
        """
        verdict = self.standby_verdict
        if verdict is None:
            return None
        age_s = (failure_stamp_ns - verdict.state_stamp_ns) * 1e-9
        return verdict if 0.0 <= age_s <= self.settings.standby_max_age_s else None

    def reset(self) -> None:
        """Forgets every verdict and the warm start (e.g. after a failure episode or an airframe change)."""
        self.latest = None
        self.standby_verdict = None
        self._warm_start = None
        self._last_started_ns = None
