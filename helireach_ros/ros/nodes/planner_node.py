"""Planner node: on an engine failure, plan the landing, publish it, and keep re-planning down to the ground.

Startup builds the NLP once (:func:`~helireach_ros.core.planner.get_planner`) and solves one warm-up landing
so the first real solve pays no first-call costs. It loads the envelope (for warm starts and fallbacks)
when it was computed for the same airframe, planner settings and total power loss.

On a failure event (``/helireach/failure_event``) the node takes the latest canonical state
(``/helireach/state`` + ``/helireach/rotor_state``), solves warm-started from the envelope's nearest
stored plan, and publishes the trajectory (``/helireach/landing_trajectory``), the predicted path
(``/helireach/landing_path``) and the plan status (``/helireach/plan_status``), all latched, stamped
with the state's stamp. Only a plan whose NLP value is ≤ 0 *and* whose independent replay lands
within limits is called safe.

If no plan is out ``deadline`` seconds after the failure event (the solve is slow or failed), a
fallback is published, flagged ``fallback=true``: the nearest envelope plan's controls from now on
(its cell's status is reported), or without an envelope a standard autorotation entry (steady
autorotation controls at the current speed). A later converged solve replaces it.

While the descent lasts (down to ``replan_min_height``, while the current plan has more than
``replan_min_remaining`` seconds to go) the node re-plans every ``replan_period`` seconds from the
current state, warm-started from its previous plan (closed loop). A re-plan that fails keeps the
current plan. Solves run on the node's own solver thread, one at a time (a re-plan is skipped while a
solve is still running); callbacks only hand work to it. So whatever executor spins the node, even a
single-threaded one, state reception, the deadline's fallback and status publishing go on during a
solve (CasADi releases the GIL while IPOPT and CVODES run).

Run: ``python -m helireach_ros.ros.nodes.planner_node`` (or the ``helireach_planner`` console script).
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.failure_episode import FailureEpisode, PublishedPlan
from helireach_ros.core.fallback import FallbackPlan, fallback_plan
from helireach_ros.core.model import clip_rotor_speed_noise
from helireach_ros.core.plan_verdict import plan_verdict
from helireach_ros.core.replanning import plan_time_remaining, replanning_ends
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameters import declare_aircraft, declare_checked_parameter

__all__ = ["LandingPlannerNode", "main"]

_PLAN_HISTORY = 200  # published plans kept for inspection (demo, tests)
_ROTOR_NOISE_TOLERANCE = 0.01  # fraction of Ω₀ a measured rotor speed may lie outside its limits as noise


class LandingPlannerNode(Node):
    """Plans landings after engine failures and re-plans during the descent.

    Parameters: ``airframe``, ``gross_weight`` (N, 0 = the airframe file's), ``density_altitude`` (m, NaN = the
    file's), ``planner_settings`` (file, '' = config/planner.yaml), ``envelope_file``
    ('' = the shipped one, ``none`` = no envelope), ``deadline`` (s), ``replan_period`` (s, 0 = off),
    ``replan_min_height`` (m), ``replan_min_remaining`` (s), ``state_timeout`` (s),
    ``assume_total_power_loss``, ``warm_up``, ``world_frame``, ``rotor_joint``, ``diagnostics_period``.
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_planner", **node_options)
        declare = partial(declare_checked_parameter, self)
        load_aircraft = declare_aircraft(self)
        settings_file = declare("planner_settings", "", "planner settings file ('' = config/planner.yaml)")
        envelope_file = declare("envelope_file", "", "envelope for warm starts/fallbacks ('' = shipped, 'none' = off)")
        self._deadline = declare("deadline", 0.25, "fallback if no plan this long after the failure, s", (0.001, 60.0))
        self._replan_period = declare("replan_period", 0.25, "closed-loop re-planning period, s (0 = off)", (0.0, 60.0))
        self._replan_min_height = declare("replan_min_height", 0.5, "no re-planning below this height, m", (0.0, 1e3))
        self._replan_min_remaining = declare(
            "replan_min_remaining", 0.3, "no re-planning when the plan has less time left, s", (0.0, 60.0)
        )
        self._state_timeout = declare("state_timeout", 0.5, "older states are not planned from, s", (0.01, 60.0))
        self._assume_total_power_loss = declare(
            "assume_total_power_loss", True, "plan with zero engine power (else the measured power)"
        )
        warm_up = declare("warm_up", True, "solve one landing at startup (first-call costs)")
        self._world_frame = declare("world_frame", rm.DEFAULT_WORLD_FRAME, "frame of the landing path")
        self._rotor_joint = declare("rotor_joint", rm.ROTOR_JOINT, "JointState joint of the main rotor")
        diagnostics_period = declare("diagnostics_period", 1.0, "period of /diagnostics, s", (0.05, 60.0))

        self._lock = threading.Lock()  # latest state, failure bookkeeping
        self._publish_lock = threading.Lock()  # one plan decision/publication at a time
        self._odometry: tuple[rm.OdometryReading, int, str] | None = None
        self._rotor: tuple[rm.RotorReading, int] | None = None
        self._failure: FailureEpisode | None = None
        self._failure_count = 0
        self.published_plans: list[PublishedPlan] = []

        self.planner: Any | None = None
        self.envelope: Any | None = None
        self._setup_error = ""
        try:
            self._setup_core(load_aircraft, settings_file, envelope_file, warm_up)
        except Exception as error:  # a broken airframe/settings file: say so on every channel, keep running
            self._setup_error = f"{type(error).__name__}: {error}"
            self.get_logger().error(f"planner not configured, no plans will be made: {self._setup_error}")

        # One solve at a time, off the executor: a slow solve must not hold up the deadline or the inputs.
        self._solver_thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="helireach_solver")
        self._solve_job: Future | None = None
        self._trajectory_publisher = self.create_publisher(
            JointTrajectory, rm.TOPIC_LANDING_TRAJECTORY, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._path_publisher = self.create_publisher(
            PathMsg, rm.TOPIC_LANDING_PATH, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._status_publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_PLAN_STATUS, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self.create_subscription(
            Odometry, rm.TOPIC_STATE, self._on_state, rm.SENSOR_QOS, **rm.NO_QOS_EVENTS_SUBSCRIPTION
        )
        self.create_subscription(
            JointState, rm.TOPIC_ROTOR_STATE, self._on_rotor, rm.SENSOR_QOS, **rm.NO_QOS_EVENTS_SUBSCRIPTION
        )
        self.create_subscription(
            Header,
            rm.TOPIC_FAILURE_EVENT,
            self._on_failure_event,
            rm.EVENT_QOS,
            **rm.NO_QOS_EVENTS_SUBSCRIPTION,
        )
        # A periodic check, never cancelled or reset from the solver thread (cancelling a timer that the
        # executor is about to fire raises inside the executor). Every half deadline:
        # the fallback goes out within 1.5 deadlines without waking the executor needlessly.
        self.create_timer(max(self._deadline / 2.0, 0.005), self._on_deadline)
        if self._replan_period > 0.0:
            self.create_timer(self._replan_period, self._on_replan_timer)
        self.create_timer(diagnostics_period, self._publish_diagnostics)

    # -- startup -----------------------------------------------------------------------------------------------
    def _setup_core(
        self, load_aircraft: Callable[[], Any], settings_file: str, envelope_file: str, warm_up: bool
    ) -> None:
        """Loads airframe, settings and envelope, builds the NLP (once) and warms it up."""
        from helireach_ros.core.model import initial_state_after_failure
        from helireach_ros.core.planner import get_planner
        from helireach_ros.core.settings import load_settings

        started = time.perf_counter()
        # Today's weight and density altitude change the model, hence the NLP and which envelope matches
        # (one made for other conditions is refused: cold starts, autorotation-entry fallback).
        self.airframe = load_aircraft()
        self.settings = load_settings(settings_file or None)
        self.planner = get_planner(self.airframe, self.settings)
        self.envelope, self._envelope_note = self._load_envelope(envelope_file)
        self.warm_up_ms = math.nan
        if warm_up:
            state = initial_state_after_failure(self.airframe, 500.0 * FT, 75.0 * KT)
            stored = self.envelope.nearest_plan(state.height, state.forward_speed) if self.envelope else None
            warm_up_started = time.perf_counter()
            self.planner.plan(state, stored.warm_start if stored else None)
            self.warm_up_ms = 1e3 * (time.perf_counter() - warm_up_started)
        self.startup_s = time.perf_counter() - started
        self.get_logger().info(
            f"planner ready for {self.airframe.name} ({self.settings.method}, {self.settings.intervals} intervals) "
            f"in {self.startup_s:.2f} s; {self._envelope_note}"
        )

    def _load_envelope(self, path: str) -> tuple[Any | None, str]:
        if path.strip().lower() == "none":
            return None, "no envelope (disabled): cold starts, autorotation-entry fallback"
        try:
            from helireach_ros.core.envelope.data import default_envelope_path, load_envelope

            resolved = path or str(default_envelope_path())
            envelope = load_envelope(resolved, self.airframe, self.settings, 0.0)
            return envelope, f"envelope {envelope.envelope_id} for warm starts and fallbacks"
        except Exception as error:  # missing or mismatched: plan cold, fall back to the autorotation entry
            note = f"envelope not usable ({type(error).__name__}: {error}): cold starts, autorotation-entry fallback"
            self.get_logger().warning(note)
            return None, note

    # -- inputs ------------------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _on_state(self, message: Odometry) -> None:
        reading = rm.read_odometry(message)
        if rm.state_problems(rm.StateLimits(), odometry=reading):
            return  # the monitor filters; a direct publisher's garbage is ignored here too
        with self._lock:
            self._odometry = (reading, self._now_ns(), message.child_frame_id or rm.DEFAULT_BODY_FRAME)

    def _on_rotor(self, message: JointState) -> None:
        try:
            reading = rm.read_rotor(message, self._rotor_joint)
        except ValueError:
            return
        if rm.state_problems(rm.StateLimits(), rotor=reading):
            return
        with self._lock:
            self._rotor = (reading, self._now_ns())

    def current_state(self) -> tuple[np.ndarray, int, str, str] | None:
        """(state y, v, Ω, h, z, P; its stamp ns; vehicle frame; rotor-speed source), or None without a fresh state.

        Without a fresh rotor speed Ω₀ is assumed (the source says so; re-plans are then skipped). Ω within
        1 % of Ω₀ outside the rotor limits is clipped to them (sensor noise); farther out it is kept.
        """
        now_ns = self._now_ns()
        timeout_ns = self._state_timeout * 1e9
        with self._lock:
            odometry, rotor = self._odometry, self._rotor
        if odometry is None or now_ns - odometry[1] > timeout_ns:
            return None
        reading, _, frame = odometry
        if rotor is not None and now_ns - rotor[1] <= timeout_ns:
            rotor_speed, source = rotor[0].rotor_speed, "measured"
            power = rotor[0].engine_power
        else:
            rotor_speed, source, power = self.airframe.nominal_rotor_speed, "assumed_nominal", None
        if self._assume_total_power_loss or power is None:
            power = 0.0
        rotor_speed = clip_rotor_speed_noise(self.airframe, rotor_speed, _ROTOR_NOISE_TOLERANCE)
        return rm.helicopter_state(reading, rotor_speed, power), reading.stamp_ns, frame, source

    # -- the failure --------------------------------------------------------------------------------------------
    def _on_failure_event(self, message: Header) -> None:
        now_ns = self._now_ns()
        with self._lock:
            self._failure_count += 1
            failure = FailureEpisode(self._failure_count, rm.stamp_nanoseconds(message.stamp), now_ns)
            self._failure = failure
        self.get_logger().warning(f"engine failure #{failure.failure_id}: planning the landing")
        if self.planner is None:
            self._publish_status_only(failure, f"planner not configured ({self._setup_error})")
            return
        self._submit(self._plan_initial, failure, queue=True)

    # -- the solver thread ---------------------------------------------------------------------------------------
    def _submit(self, job: Callable[..., None], *args: Any, queue: bool = False) -> bool:
        """Runs ``job(*args)`` on the solver thread; without ``queue`` only if no solve is pending or running."""
        with self._lock:
            if not queue and self._solve_job is not None and not self._solve_job.done():
                return False
            try:
                self._solve_job = self._solver_thread.submit(self._run_job, job, *args)
            except RuntimeError:  # the node is being destroyed
                return False
        return True

    def _run_job(self, job: Callable[..., None], *args: Any) -> None:
        try:
            job(*args)
        except Exception as error:  # an unexpected error must not silently end planning for this failure
            with contextlib.suppress(Exception):  # the context may already be shut down
                self.get_logger().error(f"planning step {job.__name__} failed: {type(error).__name__}: {error}")

    @property
    def solving(self) -> bool:
        """A solve is pending or running on the solver thread."""
        with self._lock:
            return self._solve_job is not None and not self._solve_job.done()

    def destroy_node(self) -> None:
        """Lets a running solve finish (queued ones are dropped), then destroys the node."""
        self._solver_thread.shutdown(wait=True, cancel_futures=True)
        super().destroy_node()

    def _plan_initial(self, failure: FailureEpisode, retry: bool = False) -> None:
        """The first plan of a failure, warm-started from the envelope's nearest stored plan.

        ``retry``: called again because no converged plan is out yet; a fallback already out is not repeated.
        """
        current = self.current_state()
        if current is None:
            self._publish_status_only(failure, "no valid vehicle state at the failure: waiting for one")
            return
        state, stamp_ns, frame, rotor_source = current
        stored = self.envelope.nearest_plan(state[3], state[1]) if self.envelope is not None else None
        warm_start, source = (stored.warm_start, "envelope") if stored is not None else (None, "none")
        plan, error = self._solve(state, warm_start)
        if plan is None or not plan.solver.success:
            reason = error or f"solver {plan.solver.status}"
            self.get_logger().error(f"failure #{failure.failure_id}: no converged plan ({reason})")
            if not (retry and failure.published):
                self._publish_fallback(failure, state, stamp_ns, reason)
            return
        self._publish_plan(failure, plan, stamp_ns, frame, source, rotor_source, replan=False)

    def _solve(self, state: np.ndarray, warm_start: Any) -> tuple[Any | None, str]:
        try:
            return self.planner.plan(state, warm_start), ""
        except (ValueError, RuntimeError) as error:
            return None, f"{type(error).__name__}: {error}"

    def _on_deadline(self) -> None:
        with self._lock:
            failure = self._failure
            if failure is None or failure.published or failure.deadline_handled:
                return
            if self._now_ns() - failure.event_received_ns < self._deadline * 1e9:
                return
            failure.deadline_handled = True
        current = self.current_state()
        if current is None:
            self._publish_status_only(failure, f"no plan within {self._deadline:g} s and no valid state")
            return
        state, stamp_ns, _, _ = current
        self._publish_fallback(failure, state, stamp_ns, f"no plan within the {self._deadline:g} s deadline")

    def _on_replan_timer(self) -> None:
        with self._lock:
            failure = self._failure
        if failure is None or not failure.active or self.planner is None:
            return
        if not failure.published or failure.current is None or failure.current.fallback:
            self._submit(self._plan_initial, failure, True)  # still no converged plan for this failure: keep trying
            return
        self._submit(self._replan, failure)

    def _replan(self, failure: FailureEpisode) -> None:
        """One closed-loop re-plan from the current state, warm-started from the current plan."""
        if not failure.active or failure is not self._failure:
            return
        current = self.current_state()
        if current is None:
            return
        state, stamp_ns, frame, rotor_source = current
        if rotor_source != "measured":
            return  # re-planning with an assumed rotor speed could be worse than the current plan
        previous = failure.current
        remaining = plan_time_remaining(previous.plan.time_to_land, (stamp_ns - previous.stamp_ns) * 1e-9)
        if replanning_ends(state[3], remaining, self._replan_min_height, self._replan_min_remaining):
            failure.active = False
            self.get_logger().info(
                f"failure #{failure.failure_id}: closed loop ends at {state[3]:.2f} m, {remaining:.2f} s to go "
                f"({failure.replans} re-plans, {failure.replans_failed} failed)"
            )
            return
        plan, error = self._solve(state, previous.plan.warm_start)
        if plan is None or not plan.solver.success:
            failure.replans_failed += 1
            reason = error or f"solver {plan.solver.status}"
            self.get_logger().warning(f"re-plan failed ({reason}); keeping the current plan", throttle_duration_sec=1.0)
            return
        failure.replans += 1
        self._publish_plan(failure, plan, stamp_ns, frame, "previous_plan", rotor_source, replan=True)

    # -- fallbacks -----------------------------------------------------------------------------------------------
    def fallback_plan(self, state: np.ndarray) -> FallbackPlan:
        """The best available controls without a converged solve (:func:`helireach_ros.core.fallback.fallback_plan`)."""
        return fallback_plan(state, self.airframe, self.settings, self.envelope)

    def _publish_fallback(self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int, reason: str) -> None:
        try:
            fallback = self.fallback_plan(state)
        except Exception as error:  # the last resort must not take the node down
            self._publish_status_only(failure, f"{reason}; no fallback available ({error})")
            return
        with self._publish_lock:
            if failure is not self._failure or (failure.current is not None and not failure.current.fallback):
                return  # a newer failure or a converged plan came first
            now_ns = self._now_ns()
            record = PublishedPlan(
                failure.failure_id,
                failure.replans,
                stamp_ns,
                fallback,
                True,
                (now_ns - failure.event_received_ns) * 1e-6,
                now_ns,
                "none",
            )
            self._trajectory_publisher.publish(rm.trajectory_message(fallback, stamp_ns))
            values = {
                "status": "fallback",
                "safe": False,
                "verified": False,
                "fallback": True,
                "fallback_kind": fallback.kind,
                "fallback_source_status": fallback.source_status,
                "reason": reason,
                "time_to_land_s": fallback.time_to_land,
                "latency_ms": record.latency_ms,
                **self._common_values(failure, state, stamp_ns),
            }
            self._status_publisher.publish(
                rm.diagnostic_status(
                    DiagnosticStatus.WARN,
                    f"{self.get_name()}: landing plan",
                    f"FALLBACK (not verified): {fallback.description}; {reason}",
                    self.airframe.name,
                    values,
                )
            )
            self._remember(failure, record)
        self.get_logger().warning(f"failure #{failure.failure_id}: published fallback {fallback.description}")

    # -- publishing ----------------------------------------------------------------------------------------------
    def _common_values(self, failure: FailureEpisode, state: np.ndarray, stamp_ns: int) -> dict[str, Any]:
        return {
            "failure_id": failure.failure_id,
            "failure_stamp_ns": failure.event_stamp_ns,
            "state_stamp_ns": stamp_ns,
            "initial_descent_rate_m_s": state[0],
            "initial_forward_speed_m_s": state[1],
            "initial_rotor_speed_rad_s": state[2],
            "initial_height_m": state[3],
            "initial_distance_m": state[4],
            "initial_engine_power_w": state[5],
            "airframe": self.airframe.name,
            "gross_weight_n": self.airframe.gross_weight,
            "density_altitude_m": self.airframe.density_altitude,
            "envelope_id": self.envelope.envelope_id if self.envelope is not None else "",
        }

    def _publish_plan(
        self,
        failure: FailureEpisode,
        plan: Any,
        stamp_ns: int,
        frame: str,
        warm_source: str,
        rotor_source: str,
        replan: bool,
    ) -> None:
        """Publishes a converged plan (safe, unverified or unsafe) as trajectory, path and status."""
        with self._publish_lock:
            if failure is not self._failure:
                return  # a newer failure superseded this one while solving
            now_ns = self._now_ns()
            late = not replan and failure.published
            reference_ns = failure.event_received_ns if not replan else stamp_ns
            record = PublishedPlan(
                failure.failure_id,
                failure.replans,
                stamp_ns,
                plan,
                False,
                (now_ns - reference_ns) * 1e-6,
                now_ns,
                warm_source,
            )
            self._trajectory_publisher.publish(rm.trajectory_message(plan, stamp_ns, frame))
            self._path_publisher.publish(
                rm.path_message(plan.times, plan.states, stamp_ns, self._world_frame, plan.controls[1])
            )
            values = {
                **rm.plan_status_values(plan),
                "warm_start": warm_source,
                "replan_index": failure.replans if replan else 0,
                "late": late,
                "latency_ms": record.latency_ms,
                "rotor_speed_source": rotor_source,
                **self._common_values(failure, plan.initial_state, stamp_ns),
            }
            level_name, text = plan_verdict(plan, rotor_source)
            level = rm.DIAGNOSTIC_LEVELS[level_name]
            self._status_publisher.publish(
                rm.diagnostic_status(level, f"{self.get_name()}: landing plan", text, self.airframe.name, values)
            )
            self._remember(failure, record)
        if not replan:
            self.get_logger().info(f"failure #{failure.failure_id}: {text} ({record.latency_ms:.0f} ms)")

    def _publish_status_only(self, failure: FailureEpisode, text: str) -> None:
        self.get_logger().error(f"failure #{failure.failure_id}: {text}")
        hardware_id = self.airframe.name if self.planner is not None else "helireach"
        values = {
            "status": "none",
            "safe": False,
            "verified": False,
            "fallback": False,
            "reason": text,
            "failure_id": failure.failure_id,
        }
        with self._publish_lock:
            if failure is self._failure and not failure.published:
                self._status_publisher.publish(
                    rm.diagnostic_status(
                        DiagnosticStatus.ERROR,
                        f"{self.get_name()}: landing plan",
                        f"NO PLAN: {text}",
                        hardware_id,
                        values,
                    )
                )

    def _remember(self, failure: FailureEpisode, record: PublishedPlan) -> None:
        failure.remember(record)
        self.published_plans.append(record)
        del self.published_plans[:-_PLAN_HISTORY]

    # -- diagnostics ---------------------------------------------------------------------------------------------
    @property
    def failure_active(self) -> bool:
        """A failure is being handled and the closed loop has not ended."""
        with self._lock:
            return self._failure is not None and self._failure.active

    def _publish_diagnostics(self) -> None:
        with self._lock:
            failure = self._failure
        if self.planner is None:
            status = rm.diagnostic_status(
                DiagnosticStatus.ERROR,
                f"{self.get_name()}: planner",
                f"not configured: {self._setup_error}",
                "helireach",
            )
            self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), status))
            return
        values: dict[str, Any] = {
            "airframe": self.airframe.name,
            "method": self.settings.method,
            "startup_s": self.startup_s,
            "warm_up_ms": self.warm_up_ms,
            "envelope": self._envelope_note,
            "failures": self._failure_count,
            "solving": self.solving,
        }
        if failure is not None:
            values.update(failure_active=failure.active, replans=failure.replans, replans_failed=failure.replans_failed)
            if failure.current is not None:
                values["last_latency_ms"] = failure.current.latency_ms
        level = DiagnosticStatus.OK if self.envelope is not None else DiagnosticStatus.WARN
        text = "ready" if self.envelope is not None else "ready without an envelope (cold starts)"
        status = rm.diagnostic_status(level, f"{self.get_name()}: planner", text, self.airframe.name, values)
        self._diagnostics_publisher.publish(rm.diagnostic_array(self._now_ns(), status))


def main(args: list[str] | None = None) -> None:
    """Runs the planner node until Ctrl-C or SIGTERM."""
    run_node(LandingPlannerNode, args)


if __name__ == "__main__":
    main()
