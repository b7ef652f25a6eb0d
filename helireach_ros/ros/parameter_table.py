"""A node's parameters as one table: a frozen dataclass whose fields are the parameters.

Each field is made with :func:`parameter` (default, description with its unit, range, read-only), so the one class
gives everything that used to be written three times: the declarations
(:func:`~helireach_ros.ros.parameters.declare_parameters` declares every field in order, with its descriptor and
checks, and returns the class filled with the values, typed for the type checker), the ``--help`` text
(:func:`~helireach_ros.ros.node_command_line.parameter_specs` reads the class through :func:`table_specs`), and the
check of ``config/nodes.yaml`` (``test/test_parameters.py``). ROS-free: the help text needs no rclpy.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

__all__ = ["ParameterSpec", "parameter", "table_specs"]

_SPEC = "helireach_parameter"  # the field metadata key of a parameter's description, range and read-only flag


@dataclass(frozen=True)
class ParameterSpec:
    """One declared parameter as the help text shows it (values as Python objects, or source text)."""

    name: str
    default: Any
    description: str
    value_range: Any = None
    read_only: bool = True


def parameter(
    default: Any, description: str, value_range: tuple[float, float] | None = None, *, read_only: bool = True
) -> Any:
    """A parameter field of a table: its default (which sets its type), description, inclusive range (numbers only,
    required for them) and whether run-time sets are refused."""
    metadata = {_SPEC: (description, value_range, read_only)}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def table_specs(table: type) -> list[ParameterSpec]:
    """The parameters of a table class, in field order.

    Raises:
        TypeError: ``table`` is not a dataclass, or a field is not made with :func:`parameter`.
    """
    if not dataclasses.is_dataclass(table):
        raise TypeError(f"{table!r} is not a parameter table (a dataclass of parameter() fields)")
    specs = []
    for item in dataclasses.fields(table):
        if _SPEC not in item.metadata:
            raise TypeError(f"{table.__name__}.{item.name} is not a parameter() field")
        description, value_range, read_only = item.metadata[_SPEC]
        if item.default_factory is not dataclasses.MISSING:  # a list's
            default = item.default_factory()
        else:
            default = item.default
        specs.append(ParameterSpec(item.name, default, description, value_range, read_only))
    return specs
