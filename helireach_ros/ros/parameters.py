"""Node parameters: declared with a descriptor (description, range, read-only) and validated.

Every helireach node declares its parameters through :func:`declare_checked_parameter`; the aircraft
parameters shared by the planner and the envelope status node come from :func:`declare_aircraft`.

Rules (nav2 style, stricter than rclpy's defaults):

- **Every numeric parameter has a range**; a declaration without one is a programming error.
- **A bad override stops the node** at start-up: :class:`ParameterError` names the node, the parameter,
  the given value and its type, the expected type and the allowed range (``run_node`` turns it into one
  line on stderr and exit code 2). A safety node running on a default the operator did not ask for would
  be optimistic about its own configuration.
- **An integer for a float parameter is accepted** and converted (``-p stale_timeout:=1`` arrives as an
  INTEGER; ``1`` and ``1.0`` mean the same number, and every int a command line can carry below 2⁵³ is
  exact as a float), at start-up and at run time (a pre-set callback converts it before rclpy's type
  check). Every other type mismatch (a string, a bool, a float for an int parameter) is refused.
- **At run time** rclpy refuses a set outside the descriptor's range and any set of a read-only parameter.
- **Unknown overrides** (a name given to the node that it never declared) are warned about with the nearest
  declared name (:func:`warn_unknown_parameters`); ROS's own parameters (``use_sim_time``,
  ``qos_overrides.*``, ...) and the shared ``/**`` aircraft parameters of ``config/nodes.yaml`` are not.
"""

from __future__ import annotations

import difflib
import math
import weakref
from collections.abc import Callable, Collection, Iterable, Sequence
from functools import lru_cache, partial
from typing import Any, TypeVar

import yaml
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from helireach_ros.core.aircraft.airframe import MAX_WIND
from helireach_ros.core.resources import config_path

_Table = TypeVar("_Table")

__all__ = [
    "ROS_OWN_PARAMETERS",
    "ROS_OWN_PARAMETER_PREFIXES",
    "ParameterError",
    "checked_override",
    "declare_aircraft",
    "declare_checked_parameter",
    "declare_parameters",
    "shared_parameter_names",
    "unknown_parameter_messages",
    "warn_unknown_parameters",
    "warn_unknown_parameters_of_system",
]

ROS_OWN_PARAMETERS = frozenset({"use_sim_time", "start_type_description_service", "start_parameter_event_publisher"})
"""Parameters rclpy declares (or may be given) on every node: never reported as unknown."""
ROS_OWN_PARAMETER_PREFIXES = ("qos_overrides.",)
"""Prefixes of ROS's own parameter families (QoS overrides)."""

_LARGEST_EXACT_INT = 2**53  # every int up to this magnitude is exactly representable as a float
_INT_TO_FLOAT_NODES: weakref.WeakSet[Node] = weakref.WeakSet()  # nodes with the run-time conversion installed


class ParameterError(ValueError):
    """A parameter override the node cannot use (wrong type, out of range): the node must not start."""


def _type_name(value: Any) -> str:
    return {bool: "a bool", int: "an integer", float: "a float", str: "a string"}.get(type(value), "an array")


def _range_text(value_range: tuple[float, float] | None, default: Any) -> str:
    if value_range is None:
        return ""
    low, high = value_range
    text = f" in [{low:g}, {high:g}]"
    return f"{text} (or NaN)" if isinstance(default, float) and math.isnan(default) else text


def checked_override(
    name: str, default: Any, value: Any, value_range: tuple[float, float] | None = None, node_name: str = ""
) -> Any:
    """The value a parameter takes from an override, or a :class:`ParameterError` saying why it cannot.

    Types follow the default's: an integer for a float parameter is converted (module docstring); any other
    mismatch is an error. Numbers must lie in ``value_range`` (inclusive); NaN only where the default is NaN
    (it then means "not given", e.g. ``density_altitude``).

    Args:
        name: the parameter.
        default: its declared default (sets the type).
        value: the override (a Python value as rclpy parses ``-p name:=value`` or a parameter file).
        value_range: ``(low, high)`` for numbers.
        node_name: for the message.

    Returns:
        The value to declare (a float for an integer given to a float parameter).
    """
    expected = _type_name(default)
    of_node = f" of {node_name}" if node_name else ""
    given = f"parameter {name!r}{of_node} = {value!r} ({_type_name(value)})"
    wanted = f"expected {expected}{_range_text(value_range, default)}"
    if isinstance(default, float) and type(value) is int and abs(value) <= _LARGEST_EXACT_INT:
        value = float(value)
    if isinstance(default, list | tuple):
        if isinstance(value, str | bool | int | float) or Parameter.Type.from_parameter_value(
            list(value)
        ) != Parameter.Type.from_parameter_value(list(default)):
            element_names: dict[type, str] = {bool: "bools", int: "integers", float: "floats", str: "strings"}
            elements = element_names.get(type(default[0]), "values") if default else "values"
            raise ParameterError(f"{given}: {wanted} of {elements} (non-empty)")
        return value
    if type(value) is not type(default):
        raise ParameterError(f"{given}: {wanted}")
    if value_range is not None:
        low, high = value_range
        nan_allowed = isinstance(default, float) and math.isnan(default) and math.isnan(value)
        if not nan_allowed and not low <= value <= high:
            raise ParameterError(f"{given} is out of range: {wanted}")
    return value


def _convert_ints_for_floats(node: Node, parameters: list[Parameter]) -> list[Parameter]:
    """Pre-set callback: an INTEGER set on a DOUBLE parameter becomes the same DOUBLE (run-time twin of
    :func:`checked_override`); rclpy then checks ranges and read-only as usual."""
    converted = []
    for parameter in parameters:
        if (
            parameter.type_ == Parameter.Type.INTEGER
            and node.has_parameter(parameter.name)
            and node.describe_parameter(parameter.name).type == Parameter.Type.DOUBLE.value
            and abs(parameter.value) <= _LARGEST_EXACT_INT
        ):
            parameter = Parameter(parameter.name, Parameter.Type.DOUBLE, float(parameter.value))
        converted.append(parameter)
    return converted


def declare_checked_parameter(
    node: Node,
    name: str,
    default: Any,
    description: str,
    value_range: tuple[float, float] | None = None,
    read_only: bool = True,
) -> Any:
    """Declares a parameter with a descriptor (and range) and returns its value.

    Args:
        node: the node declaring it.
        name: the parameter's name.
        default: its default; sets its type.
        description: what it is, with its unit.
        value_range: ``(low, high)``, inclusive; required for numbers (ints and floats), refused for bools.
            With a NaN default ("not given") the range is checked at start-up only and the parameter must be
            read-only (rclpy's range descriptor cannot say "NaN or in range").
        read_only: refuse run-time sets.

    Raises:
        ParameterError: the override is of the wrong type or out of range (the node must not start).
        TypeError: a declaration against the rules above (a programming error).
    """
    numeric = isinstance(default, int | float) and not isinstance(default, bool)
    if value_range is not None and not numeric:
        raise TypeError(f"parameter {name!r}: only numeric parameters have a range")
    if numeric and value_range is None:
        raise TypeError(f"parameter {name!r}: a numeric parameter needs a range")
    nan_default = isinstance(default, float) and math.isnan(default)
    if nan_default and not read_only:
        raise TypeError(f"parameter {name!r}: a NaN default with a range must be read-only")
    descriptor = ParameterDescriptor(description=description, read_only=read_only)
    if value_range is None:
        pass  # not numeric: no range (checked above)
    elif isinstance(default, int):
        descriptor.integer_range = [IntegerRange(from_value=int(value_range[0]), to_value=int(value_range[1]), step=1)]
    elif not nan_default:
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=float(value_range[0]), to_value=float(value_range[1]))
        ]
    if nan_default:
        descriptor.additional_constraints = f"NaN or{_range_text(value_range, 0.0)}"
    value = default
    # rclpy keeps the node's overrides (parameter files, -p, parameter_overrides) only in this attribute
    override = node._parameter_overrides.get(name)
    if override is not None:
        value = checked_override(name, default, override.value, value_range, node.get_name())
    if not read_only and node not in _INT_TO_FLOAT_NODES:
        _INT_TO_FLOAT_NODES.add(node)
        node.add_pre_set_parameters_callback(partial(_convert_ints_for_floats, node))
    return node.declare_parameter(name, value, descriptor, ignore_override=True).value


def declare_parameters(node: Node, table: type[_Table]) -> _Table:
    """Declares every parameter of a table (:mod:`helireach_ros.ros.parameter_table`) in field order with
    :func:`declare_checked_parameter`, and returns the table filled with the values.

    Raises:
        ParameterError: an override of the wrong type or out of range (the node must not start).
    """
    from helireach_ros.ros.parameter_table import table_specs

    values = {
        spec.name: declare_checked_parameter(
            node, spec.name, spec.default, spec.description, spec.value_range, read_only=spec.read_only
        )
        for spec in table_specs(table)
    }
    return table(**values)


@lru_cache(maxsize=1)
def shared_parameter_names() -> frozenset[str]:
    """The parameters of the ``/**`` section of ``config/nodes.yaml`` (given to every node, used by some)."""
    document = yaml.safe_load(config_path("nodes.yaml").read_text()) or {}
    return frozenset((document.get("/**") or {}).get("ros__parameters") or {})


def _is_ros_own(name: str) -> bool:
    return name in ROS_OWN_PARAMETERS or name.startswith(ROS_OWN_PARAMETER_PREFIXES)


def unknown_parameter_messages(
    overridden: Iterable[str], declared: Collection[str], also_known: Collection[str] = ()
) -> dict[str, str]:
    """A message for each overridden name that is not declared, with the nearest declared name if any.

    Args:
        overridden: the names the node was given (parameter files, ``-p``, constructor overrides).
        declared: the names the node declared.
        also_known: further names not to report and to suggest (e.g. declared by another node of a composed
            system, which a bare ``-p`` reaches as well). ROS's own parameters and :func:`shared_parameter_names`
            are never reported.

    Returns:
        Unknown name -> message, e.g. ``"unknown parameter 'stale_timout' (ignored); did you mean
        'stale_timeout'?"``, in name order.
    """
    known = sorted((set(declared) | set(also_known)) - {name for name in also_known if _is_ros_own(name)})
    messages = {}
    for name in sorted(set(overridden)):
        if name in known or name in shared_parameter_names() or _is_ros_own(name):
            continue
        nearest = difflib.get_close_matches(name, known, n=1)
        hint = f"; did you mean {nearest[0]!r}?" if nearest else f"; known: {', '.join(known)}"
        messages[name] = f"unknown parameter {name!r} (ignored){hint}"
    return messages


def warn_unknown_parameters(node: Node, also_known: Collection[str] = ()) -> list[str]:
    """Logs a WARN for each override the node did not declare (call after it declared its parameters).

    Returns:
        The messages logged.
    """
    messages = list(_unknown_overrides(node, also_known).values())
    for message in messages:
        node.get_logger().warning(message)
    return messages


def _unknown_overrides(node: Node, also_known: Collection[str]) -> dict[str, str]:
    # rclpy has no public accessor for the declared names or the overrides; both attributes are stable since Foxy
    declared = [name for name in node._parameters if not _is_ros_own(name)]
    return unknown_parameter_messages(node._parameter_overrides, declared, also_known)


def declare_aircraft(node: Node) -> Callable[[], Any]:
    """Declares the aircraft parameters shared by the planner and the envelope status node.

    ``airframe`` (name or file), ``gross_weight`` (N, 0 = the airframe file's), ``density_altitude``
    (m, NaN = the file's) and ``headwind`` (m/s, 0 = calm): config/nodes.yaml keeps them in its ``/**`` section so
    one bare ``-p gross_weight:=…`` sets them for every node, and the plans and the status describe the same
    aircraft.

    Returns:
        A function loading that :class:`~helireach_ros.core.aircraft.airframe.Airframe` (raises ``ConfigError`` on a bad
        file or out-of-range conditions), so each node decides what a broken configuration means for it.
    """
    declare = partial(declare_checked_parameter, node)
    name = declare("airframe", "uh60a_class", "airframe name or file")
    gross_weight = declare("gross_weight", 0.0, "today's gross weight, N (0 = the airframe file's)", (0.0, 1e7))
    density_altitude = declare(
        "density_altitude", math.nan, "today's density altitude, m (NaN = the file's)", (-1000.0, 9000.0)
    )
    headwind = declare(
        "headwind", 0.0, "today's steady wind along the track, m/s, positive against the flight (< 0: tailwind)",
        (-MAX_WIND, MAX_WIND),
    )  # fmt: skip

    def load() -> Any:
        from helireach_ros.core.aircraft.airframe import load_airframe

        return load_airframe(name).with_conditions(
            gross_weight or None, None if math.isnan(density_altitude) else density_altitude, headwind
        )

    return load


def warn_unknown_parameters_of_system(nodes: Sequence[Node]) -> list[str]:
    """:func:`warn_unknown_parameters` for nodes composed in one process (``helireach bringup``).

    A bare ``-p name:=value`` reaches every node, so a name counts as unknown only when no node of the system
    declared it (a misspelling addressed to one node but declared by another is therefore not reported).

    Returns:
        Every message logged.
    """
    declared_anywhere = {name for node in nodes for name in node._parameters}
    logged: dict[str, str] = {}
    for node in nodes:  # a bare -p reaches every node: say it once, from the first node that got it
        for name, message in _unknown_overrides(node, declared_anywhere).items():
            if name not in logged:
                node.get_logger().warning(message)
                logged[name] = message
    return list(logged.values())
