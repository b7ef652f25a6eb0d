"""Simulated vehicle node: the helicopter the helireach nodes fly in tests, the demo and at a desk.

Flies a scenario (:func:`~helireach_ros.core.flight.simulation.load_scenario`: level trim at a height and speed,
engine failure at a time, parameter mismatch, seeded sensor noise) with
:class:`~helireach_ros.core.flight.simulation.SimulatedVehicle` in real time, and publishes what a real
vehicle would: ``/vehicle/odometry``, ``/vehicle/rotor`` and ``/vehicle/engine_failure`` every
``publish_period``. After the failure it follows the latest ``/helireach/landing_trajectory``
(holding the trim controls until the first arrives; the trajectory's header stamp is its time 0).
At touchdown it publishes ``/helireach/touchdown`` (``diagnostic_msgs/DiagnosticStatus``, latched):
OK when the landing met the limits, ERROR otherwise, with descent rate, forward speed and rotor
speed. Time 0 of the scenario is the first timer tick. ``mismatch`` (a preset of
:mod:`helireach_ros.core.flight.mismatch_presets`, e.g. ``weight+5``; '' = the scenario's own) replaces the scenario's
parameter mismatch: the vehicle flies it, the planner is not told.

Run: ``python -m helireach_ros.ros.nodes.sim_vehicle --ros-args -p scenario:=demo_500ft_75kt``.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from trajectory_msgs.msg import JointTrajectory

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.flight.mismatch_presets import MISMATCH_PRESET_NAMES, apply_mismatch_preset
from helireach_ros.core.flight.simulation import ControlSchedule, SimulatedVehicle, TouchdownReport, load_scenario
from helireach_ros.core.status_contracts import TouchdownValues
from helireach_ros.core.units import FT, KT
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameter_table import parameter
from helireach_ros.ros.parameters import ParameterError, declare_parameters

__all__ = ["SimVehicleNode", "SimVehicleParameters", "main", "touchdown_status"]

_MISMATCH_CHOICES = ", ".join(MISMATCH_PRESET_NAMES)
_MAX_STEP_S = 0.5  # a stalled timer must not make the vehicle jump further than this in one go
# The trajectory subscription: reliable, volatile (a newer plan is what matters; matches latched publishers).
_TRAJECTORY_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)


def touchdown_status(report: TouchdownReport, vehicle: SimulatedVehicle, name: str) -> DiagnosticStatus:
    """The ``/helireach/touchdown`` message for a touchdown report."""
    limits = vehicle.airframe.limits
    omega0 = vehicle.nominal_airframe.nominal_rotor_speed
    touchdown = TouchdownValues(
        within_limits=report.within_limits,
        descent_rate=report.descent_rate,
        forward_speed=report.forward_speed,
        rotor_speed_pct=100.0 * report.rotor_speed / omega0,
        rotor_speed_within_limits=report.rotor_speed_within_limits,
        max_descent_rate=limits.max_descent_rate,
        max_forward_speed=limits.max_forward_speed,
        time_after_failure_s=report.time_after_failure,
        reason=report.reason,
    )
    values = {
        **touchdown.to_values(),
        "rotor_speed_rad_s": report.rotor_speed,
        "min_rotor_speed_pct": 100.0 * report.min_rotor_speed / omega0,
        "max_rotor_speed_pct": 100.0 * report.max_rotor_speed / omega0,
        "value": report.value,
        "scenario": vehicle.scenario.name,
    }
    numbers = (
        f"{report.descent_rate / FT:.1f} ft/s, {report.forward_speed / KT:.1f} kt, rotor "
        f"{100.0 * report.rotor_speed / omega0:.0f} %"
    )
    if report.within_limits:
        level, text = DiagnosticStatus.OK, f"LANDED within limits: {numbers}"
    else:
        level, text = DiagnosticStatus.ERROR, f"LANDING OUTSIDE LIMITS: {report.reason} ({numbers})"
    return rm.diagnostic_status(level, f"{name}: touchdown", text, vehicle.airframe.name, values)


@dataclass(frozen=True)
class SimVehicleParameters:
    """The simulated vehicle's parameters, SI (one table: :mod:`helireach_ros.ros.parameter_table`)."""

    scenario: str = parameter("demo_500ft_75kt", "scenario name (config/scenarios) or file")
    mismatch: str = parameter(
        "", f"model mismatch preset flown instead of the scenario's ('' = its own; {_MISMATCH_CHOICES})"
    )
    publish_period: float = parameter(0.04, "sensor publishing (and integration) period, s", (1e-3, 1.0))
    world_frame: str = parameter(rm.DEFAULT_WORLD_FRAME, "odometry frame")
    body_frame: str = parameter(rm.DEFAULT_BODY_FRAME, "vehicle frame (gravity/heading aligned)")
    rotor_joint: str = parameter(rm.ROTOR_JOINT, "rotor joint name")
    publish_engine_power: bool = parameter(True, "publish engine torque as the rotor effort")
    diagnostics_period: float = parameter(1.0, "period of /diagnostics, s", (0.05, 60.0))
    headwind: float = parameter(
        0.0, "steady wind along the track the vehicle flies in, m/s, positive against the flight", (-30.0, 30.0)
    )


class SimVehicleNode(Node):
    """Publishes a simulated vehicle's sensors and follows the landing trajectory after a failure.

    Parameters: ``scenario`` (name in config/scenarios or a file), ``mismatch`` (preset, '' = the scenario's),
    ``publish_period`` (s),
    ``world_frame``, ``body_frame``, ``rotor_joint``, ``publish_engine_power`` (rotor effort),
    ``diagnostics_period`` (s).

    Raises:
        ConfigError: the scenario cannot be loaded (a simulator without a scenario has nothing to fly).
        ParameterError: an unknown ``mismatch`` preset.
    """

    def __init__(self, **node_options: Any) -> None:
        super().__init__("helireach_sim_vehicle", **node_options)
        self.config = config = declare_parameters(self, SimVehicleParameters)
        scenario_name, mismatch = config.scenario, config.mismatch
        publish_period, diagnostics_period = config.publish_period, config.diagnostics_period
        self._world_frame, self._body_frame, self._rotor_joint = (
            config.world_frame,
            config.body_frame,
            config.rotor_joint,
        )
        self._publish_power = config.publish_engine_power
        self.scenario = load_scenario(scenario_name)
        if mismatch:
            try:
                self.scenario = apply_mismatch_preset(self.scenario, mismatch)
            except ValueError as error:
                raise ParameterError(f"parameter 'mismatch' of {self.get_name()}: {error}") from None
        airframe = load_airframe(self.scenario.airframe).with_conditions(headwind=config.headwind)
        self.vehicle = SimulatedVehicle(self.scenario, airframe)
        self._lock = threading.Lock()
        self._start_ns: int | None = None
        self._trajectories = 0
        self._ignored_trajectories = 0
        self._reported = False
        self.touchdown_message: DiagnosticStatus | None = None

        self._odometry_publisher = self.create_publisher(
            Odometry, rm.TOPIC_ODOMETRY, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._rotor_publisher = self.create_publisher(
            JointState, rm.TOPIC_ROTOR, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._failure_publisher = self.create_publisher(
            Bool, rm.TOPIC_ENGINE_FAILURE, rm.EVENT_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._touchdown_publisher = self.create_publisher(
            DiagnosticStatus, rm.TOPIC_TOUCHDOWN, rm.LATCHED_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
        )
        self.create_subscription(
            JointTrajectory,
            rm.TOPIC_LANDING_TRAJECTORY,
            self._on_trajectory,
            _TRAJECTORY_QOS,
            **rm.NO_QOS_EVENTS_SUBSCRIPTION,
        )
        self.create_timer(publish_period, self._step)
        self.create_timer(diagnostics_period, self._publish_diagnostics)
        scenario = self.scenario
        mismatch = ", ".join(f"{k} {v:+.0%}" for k, v in scenario.parameter_mismatch.items()) or "none"
        self.get_logger().info(
            f"scenario {scenario.name}: {scenario.height / FT:.0f} ft, {scenario.forward_speed / KT:.0f} kt, "
            f"engine failure at {scenario.failure_time:g} s, mismatch {mismatch}, seed {scenario.seed}"
        )

    @property
    def start_ns(self) -> int | None:
        """ROS time of scenario time 0 (None before the first tick)."""
        return self._start_ns

    @property
    def touchdown(self) -> TouchdownReport | None:
        """The touchdown report once landed."""
        return self.vehicle.touchdown

    def _on_trajectory(self, message: JointTrajectory) -> None:
        try:
            stamp_ns, times, values = rm.read_trajectory(message)
        except ValueError as error:
            self.get_logger().warning(f"ignored a landing trajectory: {error}", throttle_duration_sec=1.0)
            return
        with self._lock:
            if self._start_ns is None:
                return
            start_time = (stamp_ns - self._start_ns) * 1e-9
            if start_time < self.scenario.failure_time - 1.0:
                self._ignored_trajectories += 1  # made before this flight's failure (an old latched plan)
                return
            try:
                self.vehicle.follow(ControlSchedule(start_time, times, values))
            except ValueError as error:
                self.get_logger().warning(f"ignored a landing trajectory: {error}", throttle_duration_sec=1.0)
                return
            self._trajectories += 1

    def _step(self) -> None:
        now_ns = self.get_clock().now().nanoseconds
        with self._lock:
            if self._start_ns is None:
                self._start_ns = now_ns
            elapsed = (now_ns - self._start_ns) * 1e-9
            step = min(max(elapsed - self.vehicle.time, 0.0), _MAX_STEP_S)
            if step > 0.0:
                self.vehicle.advance(step)
            measurement = self.vehicle.measure()
            landed_now = self.vehicle.landed and not self._reported
            self._reported = self.vehicle.landed
        power = measurement.engine_power if self._publish_power else None
        self._odometry_publisher.publish(
            rm.odometry_message(
                now_ns,
                measurement.height,
                measurement.distance,
                measurement.forward_speed,
                measurement.climb_rate,
                measurement.pitch_angle,
                self._world_frame,
                self._body_frame,
            )
        )
        self._rotor_publisher.publish(rm.rotor_message(now_ns, measurement.rotor_speed, power, self._rotor_joint))
        self._failure_publisher.publish(rm.failure_flag(measurement.engine_failed))
        if landed_now and self.vehicle.touchdown is not None:
            self.touchdown_message = touchdown_status(self.vehicle.touchdown, self.vehicle, self.get_name())
            self._touchdown_publisher.publish(self.touchdown_message)
            self.get_logger().info(self.touchdown_message.message)

    def _publish_diagnostics(self) -> None:
        with self._lock:
            phase, time_s = self.vehicle.phase, self.vehicle.time
            values = {
                "phase": phase,
                "time_s": time_s,
                "trajectories_followed": self._trajectories,
                "trajectories_ignored": self._ignored_trajectories,
                "scenario": self.scenario.name,
            }
        status = rm.diagnostic_status(
            DiagnosticStatus.OK, f"{self.get_name()}: simulation", phase, self.vehicle.airframe.name, values
        )
        self._diagnostics_publisher.publish(rm.diagnostic_array(self.get_clock().now().nanoseconds, status))


def main(args: list[str] | None = None) -> None:
    """Runs the simulated vehicle until Ctrl-C or SIGTERM."""
    raise SystemExit(run_node(SimVehicleNode, args))  # 2: bad command line or parameter (one line on stderr)


if __name__ == "__main__":
    main()
