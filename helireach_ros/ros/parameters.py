"""Node parameters: declared with a descriptor (description, range, read-only) and validated.

Every helireach node declares its parameters through :func:`declare_checked_parameter`; the aircraft
parameters shared by the planner and the envelope status node come from :func:`declare_aircraft`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.node import Node

__all__ = ["declare_aircraft", "declare_checked_parameter"]


def declare_checked_parameter(
    node: Node,
    name: str,
    default: Any,
    description: str,
    value_range: tuple[float, float] | None = None,
    read_only: bool = True,
) -> Any:
    """Declares a parameter with a descriptor (and range); a bad override is logged and the default used.

    A broken parameter file must not stop a safety node: the error names the parameter, the rejected
    value and the default that applies instead.
    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only)
    if value_range is not None and isinstance(default, bool):
        raise TypeError("a boolean parameter has no range")
    if value_range is not None and isinstance(default, int):
        descriptor.integer_range = [IntegerRange(from_value=int(value_range[0]), to_value=int(value_range[1]), step=1)]
    elif value_range is not None:
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=float(value_range[0]), to_value=float(value_range[1]))
        ]
    try:
        return node.declare_parameter(name, default, descriptor).value
    except ParameterException as error:
        node.get_logger().error(f"parameter {name!r} rejected ({error}); using the default {default!r}")
        return node.declare_parameter(name, default, descriptor, ignore_override=True).value


def declare_aircraft(node: Node) -> Callable[[], Any]:
    """Declares the aircraft parameters shared by the planner and the envelope status node.

    ``airframe`` (name or file), ``gross_weight`` (N, 0 = the airframe file's) and ``density_altitude``
    (m, NaN = the file's): config/nodes.yaml keeps them in its ``/**`` section so one bare
    ``-p gross_weight:=…`` sets them for every node, and the plans and the status describe the same aircraft.

    Returns:
        A function loading that :class:`~helireach_ros.core.airframe.Airframe` (raises ``ConfigError`` on a bad
        file or out-of-range conditions), so each node decides what a broken configuration means for it.
    """
    declare = partial(declare_checked_parameter, node)
    name = declare("airframe", "uh60a_class", "airframe name or file")
    gross_weight = declare("gross_weight", 0.0, "today's gross weight, N (0 = the airframe file's)", (0.0, 1e7))
    density_altitude = declare("density_altitude", math.nan, "today's density altitude, m (NaN = the file's)")

    def load() -> Any:
        from helireach_ros.core.airframe import load_airframe

        return load_airframe(name).with_conditions(
            gross_weight or None, None if math.isnan(density_altitude) else density_altitude
        )

    return load
