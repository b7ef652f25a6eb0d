"""Node parameters with real rclpy: bad overrides stop the node, run-time sets are checked, unknown names warned.

Each rclpy test has its own ``Context`` (discovery OFF). The command-line side (exit codes, ``--help``) is in
``test_exit_codes.py``.
"""

from __future__ import annotations

import dataclasses
import math
import time

import pytest
import rclpy
import yaml
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from helireach_ros.core.resources import config_path
from helireach_ros.display.node import CockpitDisplay
from helireach_ros.ros.node_command_line import node_name_of, parameter_specs
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor
from helireach_ros.ros.nodes.planner_node import LandingPlannerNode
from helireach_ros.ros.nodes.recorder import McapRecorder
from helireach_ros.ros.nodes.sim_vehicle import SimVehicleNode
from helireach_ros.ros.parameter_table import parameter, table_specs
from helireach_ros.ros.parameters import (
    ParameterError,
    checked_override,
    declare_checked_parameter,
    declare_parameters,
    shared_parameter_names,
    unknown_parameter_messages,
    warn_unknown_parameters,
    warn_unknown_parameters_of_system,
)

NODE_CLASSES = (VehicleMonitor, EnvelopeStatusNode, LandingPlannerNode, SimVehicleNode, McapRecorder, CockpitDisplay)


@pytest.fixture
def context(no_ros_discovery):
    fresh = Context()
    rclpy.init(context=fresh, args=[])
    yield fresh
    rclpy.try_shutdown(context=fresh)


# --- the override rules (no node needed) --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("default", "given", "value_range", "message"),
    [
        (0.5, -5.0, (0.01, 60.0), "'stale_timeout' of helireach_monitor = -5.0 (a float) is out of range: expected "
         "a float in [0.01, 60]"),
        (0.5, "abc", (0.01, 60.0), "'stale_timeout' of helireach_monitor = 'abc' (a string): expected a float in"),
        (0.5, True, (0.01, 60.0), "(a bool): expected a float"),
        (0.5, math.nan, (0.01, 60.0), "out of range"),
        (0.5, 2**60, (0.0, 1e30), "(an integer): expected a float"),  # not exact as a float: refused
        (5, 5.0, (1, 10), "(a float): expected an integer in [1, 10]"),
        (5, 11, (1, 10), "out of range: expected an integer in [1, 10]"),
        ("odom", 3, None, "(an integer): expected a string"),
        (["/a:std_msgs/msg/Bool"], [1, 2], None, "expected an array"),
    ],
)  # fmt: skip
def test_a_bad_override_names_parameter_value_type_and_range(default, given, value_range, message):
    with pytest.raises(ParameterError, match="parameter 'stale_timeout'") as raised:
        checked_override("stale_timeout", default, given, value_range, "helireach_monitor")
    assert message in str(raised.value)


def test_an_integer_for_a_float_is_accepted_as_that_float_and_nan_only_where_the_default_is_nan():
    accepted = checked_override("stale_timeout", 0.5, 1, (0.01, 60.0))
    assert accepted == 1.0 and type(accepted) is float
    assert math.isnan(checked_override("density_altitude", math.nan, math.nan, (-1000.0, 9000.0)))
    assert checked_override("density_altitude", math.nan, 300, (-1000.0, 9000.0)) == 300.0
    with pytest.raises(ParameterError, match=r"in \[-1000, 9000\] \(or NaN\)"):
        checked_override("density_altitude", math.nan, 20000.0, (-1000.0, 9000.0))


def test_unknown_names_get_the_nearest_known_one_and_ros_and_shared_names_are_not_reported():
    declared = ["stale_timeout", "max_message_age", "rotor_joint"]
    overridden = ["stale_timout", "use_sim_time", "qos_overrides./vehicle/odometry.subscription.depth", "zzz",
                  "gross_weight", "stale_timeout"]  # fmt: skip
    messages = unknown_parameter_messages(overridden, declared)
    assert set(messages) == {"stale_timout", "zzz"}
    assert messages["stale_timout"].endswith("did you mean 'stale_timeout'?")
    assert "known: max_message_age, rotor_joint, stale_timeout" in messages["zzz"]
    assert {"airframe", "gross_weight", "density_altitude"} <= shared_parameter_names()


# --- declaration with real rclpy ----------------------------------------------------------------------------


def test_an_invalid_override_stops_a_real_node_naming_the_parameter_and_range(context):
    for value, expected in ((-5.0, "is out of range"), ("abc", "(a string)")):
        with pytest.raises(ParameterError, match=r"'stale_timeout' of helireach_monitor .*\[0\.01, 60\]") as raised:
            VehicleMonitor(context=context, parameter_overrides=[Parameter("stale_timeout", value=value)])
        assert expected in str(raised.value)
    monitor = VehicleMonitor(context=context, parameter_overrides=[Parameter("stale_timeout", value=1)])
    try:
        assert monitor.get_parameter("stale_timeout").type_ == Parameter.Type.DOUBLE
        assert monitor.get_parameter("stale_timeout").value == 1.0
    finally:
        monitor.destroy_node()


def test_every_numeric_parameter_of_every_node_has_a_range():
    for node_class in NODE_CLASSES:
        specs = parameter_specs(node_class)
        assert specs, node_class
        for spec in specs:
            numeric = isinstance(spec.default, int | float) and not isinstance(spec.default, bool)
            assert not numeric or spec.value_range is not None, (node_name_of(node_class), spec.name)


@pytest.mark.parametrize("node_class", NODE_CLASSES, ids=lambda node_class: node_class.__name__)
def test_config_nodes_yaml_gives_every_declared_parameter_its_declared_default(node_class):
    """The declarations are the one table (``--help`` reads them); config/nodes.yaml, which bringup loads first, must
    not drift from it: every key a node's section sets is declared with that default, and every declared parameter is
    set there, or named in a comment of its section (a list left to its default on purpose, e.g. the recorder's
    topics), or shared in the ``/**`` section."""
    text = config_path("nodes.yaml").read_text()
    document = yaml.safe_load(text)
    name = node_name_of(node_class)
    section = document[f"/**/{name}"]["ros__parameters"]
    section_text = text.split(f"/**/{name}:", 1)[1].split("\n/**", 1)[0]
    specs = {spec.name: spec for spec in parameter_specs(node_class)}
    for key, value in section.items():
        assert key in specs, f"{name}: config/nodes.yaml sets {key!r}, which the node does not declare"
        default = specs[key].default
        same = value == default or (isinstance(value, float) and math.isnan(value) and math.isnan(default))
        assert same, f"{name}.{key}: config/nodes.yaml {value!r}, declared default {default!r}"
    shared = set(document["/**"]["ros__parameters"])
    for key in specs:
        assert key in section or key in shared or f"# {key}:" in section_text, f"{name}.{key} not in config/nodes.yaml"


def test_a_numeric_declaration_without_a_range_is_a_programming_error(context):
    node = Node("declaring", context=context)
    try:
        with pytest.raises(TypeError, match="needs a range"):
            declare_checked_parameter(node, "period", 1.0, "a period, s")
        with pytest.raises(TypeError, match="must be read-only"):
            declare_checked_parameter(node, "altitude", math.nan, "m", (0.0, 1.0), read_only=False)
    finally:
        node.destroy_node()


def _set_through_the_parameter_service(context, target: Node, parameters: list[Parameter]) -> list:
    """What ``ros2 param set`` does: a SetParameters request from another node, answered by ``target``."""
    client_node = Node("param_client", context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(target)
    executor.add_node(client_node)
    try:
        client = AsyncParameterClient(client_node, target.get_name())
        deadline = time.monotonic() + 10.0
        while not client.services_are_ready() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        future = client.set_parameters(parameters)
        executor.spin_until_future_complete(future, timeout_sec=10.0)
        assert future.done(), "no SetParameters response"
        return list(future.result().results)
    finally:
        executor.remove_node(target)
        client_node.destroy_node()
        executor.shutdown()


def test_run_time_sets_out_of_range_or_of_read_only_parameters_are_rejected(context):
    node = Node("settable", context=context)
    try:
        declare_checked_parameter(node, "warn_margin", 20.0, "margin, ft/kt", (0.0, 1e4), read_only=False)
        declare_checked_parameter(node, "stale_timeout", 0.5, "s", (0.01, 60.0))  # read-only (the default)
        out_of_range, read_only, as_int = _set_through_the_parameter_service(
            context,
            node,
            [
                Parameter("warn_margin", value=-1.0),
                Parameter("stale_timeout", value=0.2),
                Parameter("warn_margin", value=35),  # an int for a float: converted, like at start-up
            ],
        )
        assert not out_of_range.successful and not read_only.successful and as_int.successful
        assert "read-only" in read_only.reason
        assert node.get_parameter("warn_margin").value == 35.0
        assert node.get_parameter("warn_margin").type_ == Parameter.Type.DOUBLE
        assert node.get_parameter("stale_timeout").value == 0.5
    finally:
        node.destroy_node()


def test_a_real_node_warns_about_a_misspelt_override(context):
    overrides = [Parameter("stale_timout", value=0.2), Parameter("gross_weight", value=7e4)]
    monitor = VehicleMonitor(context=context, parameter_overrides=overrides)
    try:
        assert warn_unknown_parameters(monitor) == [
            "unknown parameter 'stale_timout' (ignored); did you mean 'stale_timeout'?"
        ]
    finally:
        monitor.destroy_node()


def test_a_composed_system_warns_once_and_only_for_names_no_node_declares(context):
    # as a bare -p reaches every node: 'deadline' is the planner's (not the monitor's), 'deadlin' is no one's
    shared = [Parameter("deadline", value=0.1), Parameter("deadlin", value=0.1)]
    monitor = VehicleMonitor(context=context, parameter_overrides=shared)
    other = Node("helireach_other", context=context, parameter_overrides=shared)
    try:
        declare_checked_parameter(other, "deadline", 0.25, "s", (0.001, 60.0))
        assert warn_unknown_parameters_of_system([monitor, other]) == [
            "unknown parameter 'deadlin' (ignored); did you mean 'deadline'?"
        ]
    finally:
        monitor.destroy_node()
        other.destroy_node()


def test_a_parameter_table_declares_its_fields_in_order_and_refuses_other_fields(context):
    @dataclasses.dataclass(frozen=True)
    class Table:
        period: float = parameter(0.5, "period, s", (0.01, 10.0))
        frames: list = parameter(["odom"], "frames")
        name: str = parameter("x", "a name")

    assert [spec.name for spec in table_specs(Table)] == ["period", "frames", "name"]
    node = Node("table_node", context=context, parameter_overrides=[Parameter("period", value=2)])
    try:
        values = declare_parameters(node, Table)
        assert values == Table(period=2.0, frames=["odom"], name="x") and isinstance(values.period, float)
        assert values.frames is not Table().frames  # a list default is a fresh copy per table
        with pytest.raises(ParameterError, match="period"):
            declare_parameters(Node("table_node_2", context=context, parameter_overrides=[
                Parameter("period", value=20.0)]), Table)  # fmt: skip
    finally:
        node.destroy_node()

    @dataclasses.dataclass(frozen=True)
    class Loose:
        period: float = 0.5  # not a parameter() field: no description, no range

    with pytest.raises(TypeError, match=r"Loose\.period"):
        table_specs(Loose)
    with pytest.raises(TypeError, match="not a parameter table"):
        table_specs(dict)
