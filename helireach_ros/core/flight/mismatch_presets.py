"""Named model mismatches the simulated vehicle can fly (``helireach demo --mismatch NAME``).

Each preset is a ``parameter_mismatch`` of :class:`~helireach_ros.core.flight.simulation.Scenario` (true value = the
airframe file's × (1 + fraction)), i.e. what the vehicle is and the planner does not know:

==============  ==================================================================================================
``none``        the planner's own model
``drag+5``      blade profile drag and both drag areas +5 % (the ``demo_500ft_75kt`` scenario's own mismatch)
``weight+5``    5 % heavier than the airframe file says (the issue's unknown weight)
``weight-5``    5 % lighter
``heavy+draggy`` the uncertainty set's corner: gross weight, drag areas and c_d at their high ends
``light+clean`` the opposite corner: all four at their low ends
==============  ==================================================================================================

The corners are read from the uncertainty set (``config/uncertainty.yaml``), so they follow the file.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the names alone are imported at once: a command line lists them without loading the model
    from helireach_ros.core.flight.simulation import Scenario
    from helireach_ros.core.flight.uncertainty import UncertaintySet

__all__ = ["MISMATCH_PRESET_NAMES", "apply_mismatch_preset", "mismatch_preset"]

MISMATCH_PRESET_NAMES = ("none", "drag+5", "weight+5", "weight-5", "heavy+draggy", "light+clean")
"""The presets, in the order the command line lists them."""

_DRAG = ("blade_drag_coefficient", "horizontal_drag_area", "vertical_drag_area")
_FIXED: dict[str, dict[str, float]] = {
    "none": {},
    "drag+5": dict.fromkeys(_DRAG, 0.05),
    "weight+5": {"gross_weight": 0.05},
    "weight-5": {"gross_weight": -0.05},
}
_CORNERS = {"heavy+draggy": "high", "light+clean": "low"}  # preset -> end of each range of ("gross_weight", *_DRAG)


def mismatch_preset(name: str, uncertainty: UncertaintySet | None = None) -> dict[str, float]:
    """The parameter mismatch of a preset (a fresh dict).

    Args:
        name: one of :data:`MISMATCH_PRESET_NAMES`.
        uncertainty: the set the corners come from (default: ``config/uncertainty.yaml``).

    Raises:
        ValueError: an unknown name, or a set without the corner's ranges.
    """
    if name in _FIXED:
        return dict(_FIXED[name])
    if name not in _CORNERS:
        raise ValueError(f"unknown mismatch preset {name!r} (one of {', '.join(MISMATCH_PRESET_NAMES)})")
    if uncertainty is None:
        from helireach_ros.core.flight.uncertainty import load_uncertainty_set

        uncertainty = load_uncertainty_set()
    ranges = uncertainty.ranges()
    missing = [parameter for parameter in ("gross_weight", *_DRAG) if parameter not in ranges]
    if missing:
        raise ValueError(f"mismatch preset {name!r}: the uncertainty set has no range for {', '.join(missing)}")
    end = _CORNERS[name]
    return {parameter: getattr(ranges[parameter], end) for parameter in ("gross_weight", *_DRAG)}


def apply_mismatch_preset(scenario: Scenario, name: str, uncertainty: UncertaintySet | None = None) -> Scenario:
    """``scenario`` flying preset ``name`` instead of its own mismatch; the name says so (``<scenario>:<preset>``)."""
    mismatch: Mapping[str, float] = mismatch_preset(name, uncertainty)
    return dataclasses.replace(
        scenario,
        name=f"{scenario.name}:{name}",
        description=f"{scenario.description} (mismatch preset {name})",
        parameter_mismatch=mismatch,
    )
