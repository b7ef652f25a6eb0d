"""Bringup: the helireach nodes composed in one process under one executor.

There is no ``ros2 launch`` with the PyPI wheels; this is the ros2/examples ``composed.py`` pattern.
:func:`build_system` initialises a context with ``config/nodes.yaml`` (then the user's parameter
files, which win), creates the MCAP recorder first, then the monitor, envelope status and planner
nodes, optionally the simulated vehicle and any extra nodes (e.g. the cockpit display), and waits (at
most 2 s) until the recorder has matched every publisher, so the log starts with the vehicle's first
message; the recorder's metadata names the airframe, envelope, software version and scenario. One
single-threaded executor spins them all by default (:mod:`helireach_ros.ros.executors`), serving them in the
order of :attr:`HelireachSystem.nodes` (the failure path first, the recorder last); the planner solves on its own
thread, so no callback blocks the others. Once the executor runs its first callbacks, the ``helireach_bringup``
node publishes the latched ``/helireach/ready`` status (OK, naming the nodes) and ``helireach bringup`` prints
``helireach bringup: ready``: from then on every message a matched subscription receives is processed (a vehicle
waits for it, and for its own publishers to be matched, before it starts publishing). At shutdown it turns STALE.

``helireach bringup [--params-file F] [--with-sim] [--executor KIND]`` (:func:`run_bringup`) spins
until Ctrl-C or SIGTERM and then finishes the log. Each node also has its own console script for
multi-process use.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from helireach_ros import __version__
from helireach_ros.core.mcap_log.run_metadata import aircraft_metadata
from helireach_ros.core.resources import config_path
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import DEFAULT_EXECUTOR, create_executor
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode
from helireach_ros.ros.nodes.recorder import McapRecorder
from helireach_ros.ros.nodes.sim_vehicle import SimVehicleNode
from helireach_ros.ros.parameters import warn_unknown_parameters_of_system
from helireach_ros.ros.qos import drop_parameter_event_handlers

__all__ = [
    "DEFAULT_EXECUTOR",
    "DEFAULT_PARAMETERS",
    "HelireachSystem",
    "ReadinessAnnouncer",
    "build_system",
    "ros_arguments",
    "run_bringup",
]

DEFAULT_PARAMETERS = "nodes.yaml"
"""The node parameter file in ``config/``, loaded before the user's."""
_DRAIN_S = 0.3  # after a stop signal: run the callbacks already queued before finishing the log
_READY_NODE_NAME = "helireach_bringup"
_RECORDER_MATCH_TIMEOUT_S = 2.0  # bound on waiting for the recorder's subscriptions to match (in-process: ms)


def ros_arguments(params_files: Sequence[str | os.PathLike[str]] = (), ros_args: Sequence[str] = ()) -> list[str]:
    """Command-line arguments for ``rclpy.init``: the default parameters, then the user's (last wins)."""
    arguments = ["helireach", "--ros-args", "--params-file", str(config_path(DEFAULT_PARAMETERS))]
    for path in params_files:
        if not Path(path).is_file():
            raise FileNotFoundError(f"parameter file {str(path)!r} not found")
        arguments += ["--params-file", str(path)]
    return [*arguments, *ros_args, "--"]


class ReadinessAnnouncer(Node):
    """Publishes the latched ``/helireach/ready`` status the first time the executor runs its callbacks: the proof
    that the composed nodes are spinning, which their construction is not (a planner is built seconds before the
    executor starts: a vehicle that began publishing at "planner ready" lost its first messages).

    Args:
        node_names: the composed nodes, named in the status.
        values: further values of the status (the log path, the executor kind).
        on_ready: called once, from the executor, after the status is published.
    """

    def __init__(
        self,
        *,
        node_names: Sequence[str],
        values: Mapping[str, str],
        on_ready: Callable[[], None] | None = None,
        **node_options,
    ) -> None:
        super().__init__(_READY_NODE_NAME, **node_options)
        self._node_names = list(node_names)
        self._values = {"nodes": " ".join(self._node_names), "software_version": __version__, **values}
        self._on_ready = on_ready
        self._publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_READY, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )  # no QoS-event waitables: the executor re-adds each at every wait
        self._timer = self.create_timer(0.01, self._announce)
        self.ready = False

    def _status(self, level: bytes, message: str) -> DiagnosticStatus:
        return rm.diagnostic_status(level, f"{_READY_NODE_NAME}: ready", message, _READY_NODE_NAME, self._values)

    def _announce(self) -> None:
        self._timer.cancel()
        if self.ready:
            return
        self.ready = True
        self._publisher.publish(self._status(DiagnosticStatus.OK, f"ready: {', '.join(self._node_names)} spinning"))
        if self._on_ready is not None:
            self._on_ready()

    def announce_stopping(self) -> None:
        """Turns the latched status STALE: the nodes no longer process messages."""
        with contextlib.suppress(Exception):  # the context may already be shut down
            self._publisher.publish(self._status(DiagnosticStatus.STALE, "stopping: messages are no longer processed"))


@dataclass
class HelireachSystem:
    """The composed nodes, their executor and context."""

    context: Context
    executor: Executor
    monitor: VehicleMonitor
    envelope_status: EnvelopeStatusNode
    planner: LandingPlannerNode
    sim: SimVehicleNode | None = None
    recorder: McapRecorder | None = None
    extra: list[Node] = field(default_factory=list)
    readiness: ReadinessAnnouncer | None = None
    _closed: bool = False
    _signals: list[int] = field(default_factory=list)

    @property
    def nodes(self) -> list[Node]:
        """Every node, in the order the executor serves them after a wait: the failure path (monitor, planner),
        the trajectory's consumers (simulated vehicle, extra nodes), the safety status, the recorder last."""
        nodes: list[Node] = [self.monitor, self.planner]
        nodes += [self.sim] if self.sim is not None else []
        nodes += self.extra
        nodes += [self.envelope_status]
        nodes += [self.recorder] if self.recorder is not None else []
        nodes += [self.readiness] if self.readiness is not None else []
        return nodes

    @property
    def log_path(self) -> Path | None:
        """The MCAP log being written (None without a recorder)."""
        return self.recorder.log_path if self.recorder is not None else None

    def spin_until(self, condition: Callable[[], bool], timeout_s: float, step_s: float = 0.05) -> bool:
        """Spins until ``condition()`` holds, the timeout passes or a stop was requested; returns the condition."""
        deadline = time.monotonic() + timeout_s
        while self.context.ok() and not self.stop_requested and not condition():
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                break
            self.executor.spin_once(timeout_sec=min(step_s, remaining))
        return condition()

    @property
    def stop_requested(self) -> bool:
        """A SIGINT/SIGTERM arrived while :meth:`stop_on_signals` was active."""
        return bool(self._signals)

    @contextlib.contextmanager
    def stop_on_signals(self) -> Iterator[None]:
        """Within this block SIGINT and SIGTERM only request a stop (:attr:`stop_requested`).

        rclpy's own handlers would shut the context down at once; this way the spinning code ends its
        loop (the executor wakes at least every ``step_s``) and the log is drained and finished.
        """
        if threading.current_thread() is not threading.main_thread():
            yield  # Python delivers signals to the main thread only
            return
        previous = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)}
        for number in previous:
            signal.signal(number, lambda number, _frame: self._signals.append(number))
        try:
            yield
        finally:
            for number, handler in previous.items():
                signal.signal(number, handler)

    def drain(self, duration_s: float = _DRAIN_S) -> None:
        """Runs the callbacks already queued (e.g. the recorder's copy of the last plan) for a short while."""
        deadline = time.monotonic() + duration_s
        while self.context.ok() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.05, max(deadline - time.monotonic(), 0.0)))

    def spin_until_signal(self) -> None:
        """Spins until SIGINT or SIGTERM (or the context shuts down), then drains."""
        with self.stop_on_signals():
            self.spin_until(lambda: False, math.inf, step_s=0.1)
            self.drain()

    def shutdown(self) -> None:
        """Finishes the log, destroys the nodes, shuts the executor and context down; idempotent."""
        if self._closed:
            return
        self._closed = True
        if self.readiness is not None:
            self.readiness.announce_stopping()
        if self.recorder is not None:
            self.recorder.close()  # first: the file is complete whatever happens next
        for node in self.nodes:
            self.executor.remove_node(node)  # no callback may start on a node being destroyed
        self.executor.shutdown(timeout_sec=5.0)
        for node in self.nodes:
            node.destroy_node()
        if self.context.ok():
            rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> HelireachSystem:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.shutdown()


def _recorder_metadata(
    planner: LandingPlannerNode, status: EnvelopeStatusNode, sim: SimVehicleNode | None, command: str
) -> dict[str, str]:
    metadata = {
        "software_version": __version__,
        "command": command,
        "airframe": getattr(getattr(planner, "airframe", None), "name", "unknown"),
        "envelope_id": status.envelope.envelope_id if status.envelope is not None else "",
        "airframe_digest": "",
        "planner_settings": "",
    }
    if getattr(planner, "planner", None) is not None:  # configured: the model and settings it plans with
        metadata.update(aircraft_metadata(planner.airframe, planner.settings))
    if sim is not None:
        metadata["scenario"] = sim.scenario.name
        metadata["scenario_json"] = json.dumps(sim.scenario.as_dict(), sort_keys=True)
    return metadata


def build_system(
    params_files: Sequence[str | os.PathLike[str]] = (),
    with_sim: bool = False,
    record: bool = True,
    log_dir: str | os.PathLike[str] | None = None,
    scenario: str | None = None,
    extra_nodes: Sequence[Callable[..., Node]] = (),
    context: Context | None = None,
    ros_args: Sequence[str] = (),
    executor: str = DEFAULT_EXECUTOR,
    command: str = "helireach bringup",
    on_ready: Callable[[], None] | None = None,
) -> HelireachSystem:
    """Creates the composed system (not yet spinning).

    Args:
        params_files: parameter YAML files applied after ``config/nodes.yaml``.
        with_sim: add the simulated vehicle.
        record: add the MCAP recorder.
        log_dir: the recorder's folder (overrides the parameter files).
        scenario: the simulated vehicle's scenario (overrides the parameter files).
        extra_nodes: factories called with the node options (``context=...``), e.g. the display class.
        context: a fresh context to initialise (default: a new one).
        ros_args: further ROS arguments (e.g. ``["-p", "helireach_planner:deadline:=0.1"]``).
        executor: the executor kind (:data:`~helireach_ros.ros.executors.EXECUTOR_KINDS`).
        command: recorded in the log's metadata.
        on_ready: called from the executor once ``/helireach/ready`` is published (:class:`ReadinessAnnouncer`).
    """
    context = context if context is not None else Context()
    # No rclpy signal handlers: they would shut the context down before the log is drained and finished
    # (HelireachSystem.spin_until_signal handles SIGINT/SIGTERM instead).
    rclpy.init(
        args=ros_arguments(params_files, ros_args), context=context, signal_handler_options=SignalHandlerOptions.NO
    )
    created: list[Node] = []
    try:
        recorder = None
        if record:  # first, so that it can subscribe to each publisher as it appears
            overrides = [Parameter("log_dir", value=str(log_dir))] if log_dir is not None else []
            recorder = McapRecorder(metadata={"command": command}, context=context, parameter_overrides=overrides)
            created.append(recorder)
        monitor = VehicleMonitor(context=context)
        created.append(monitor)
        envelope_status = EnvelopeStatusNode(context=context)
        created.append(envelope_status)
        planner = LandingPlannerNode(context=context)
        created.append(planner)
        sim = None
        if with_sim:
            overrides = [Parameter("scenario", value=scenario)] if scenario else []
            sim = SimVehicleNode(context=context, parameter_overrides=overrides)
            created.append(sim)
        extra = []
        for factory in extra_nodes:
            extra.append(factory(context=context))
            created.append(extra[-1])
        readiness = ReadinessAnnouncer(
            node_names=[node.get_name() for node in created],
            values={"log_path": str(recorder.log_path) if recorder is not None else "", "executor": executor},
            on_ready=on_ready,
            context=context,
        )
        created.append(readiness)
        if recorder is not None:
            recorder.update_metadata(
                _recorder_metadata(planner, envelope_status, sim, command)
            )
            # Nothing spins yet: every message the vehicle publishes from the first on is recorded.
            recorder.wait_until_recording(_RECORDER_MATCH_TIMEOUT_S)
        spinner = create_executor(executor, context)
    except BaseException:
        for node in reversed(created):
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        raise
    system = HelireachSystem(context, spinner, monitor, envelope_status, planner, sim, recorder, extra, readiness)
    for node in system.nodes:
        drop_parameter_event_handlers(node)
        spinner.add_node(node)
    warn_unknown_parameters_of_system(system.nodes)  # a misspelt -p is otherwise silently ignored
    return system


def run_bringup(
    params_files: Sequence[str | os.PathLike[str]] = (),
    with_sim: bool = False,
    log_dir: str | os.PathLike[str] | None = None,
    scenario: str | None = None,
    record: bool = True,
    extra_nodes: Sequence[Callable[..., Node]] = (),
    ros_args: Sequence[str] = (),
    executor: str = DEFAULT_EXECUTOR,
) -> int:
    """``helireach bringup``: runs the system until Ctrl-C or SIGTERM; returns the exit code."""
    system = build_system(
        params_files,
        with_sim=with_sim,
        record=record,
        log_dir=log_dir,
        scenario=scenario,
        extra_nodes=extra_nodes,
        ros_args=ros_args,
        executor=executor,
        on_ready=lambda: print("helireach bringup: ready", flush=True),
    )
    if system.log_path is not None:
        print(f"helireach bringup: logging to {system.log_path}", flush=True)
    for node in system.extra:
        if hasattr(node, "url"):
            print(f"helireach bringup: cockpit display at {node.url}", flush=True)
    try:
        system.spin_until_signal()
    finally:
        system.shutdown()
    if system.log_path is not None:
        print(f"helireach bringup: log written to {system.log_path}", flush=True)
    return 0
