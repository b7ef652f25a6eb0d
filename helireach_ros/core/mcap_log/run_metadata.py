"""The ``helireach`` metadata record of a run log: what a recorder can know, and how it learns the rest.

``helireach replay --compare`` re-runs the planner from a log, so the log must say which aircraft and
settings the plans were made with: ``airframe`` (name), ``airframe_digest``, ``gross_weight_n``,
``density_altitude_m``, ``planner_settings`` (JSON of the settings dataclass), ``envelope_id``, plus
``software_version`` and ``command``. Any recorder, composed or standalone, builds the first values from
the shared aircraft parameters and the planner settings file (:func:`aircraft_metadata`) and then adopts
what the nodes report as their status values arrive (:func:`status_metadata_updates`): the envelope id
of ``/helireach/safety_status``, and the planner's own airframe and conditions from
``/helireach/plan_status``. When the planner reports another aircraft than the recorder's parameters
name, the recorder's digest describes the wrong file, so it is cleared (a comparison then checks the
name and conditions only) and never left claiming a match it has not seen.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from typing import Any

__all__ = ["aircraft_metadata", "status_metadata_updates"]

_CONDITION_KEYS = ("gross_weight_n", "density_altitude_m")


def aircraft_metadata(airframe: Any, settings: Any) -> dict[str, str]:
    """Metadata describing an :class:`~helireach_ros.core.aircraft.airframe.Airframe` and ``PlannerSettings``."""
    return {
        "airframe": airframe.name,
        "airframe_digest": airframe.digest(),
        "gross_weight_n": repr(float(airframe.gross_weight)),
        "density_altitude_m": repr(float(airframe.density_altitude)),
        "planner_settings": json.dumps(dataclasses.asdict(settings), sort_keys=True),
    }


def _same_number(a: str | None, b: str | None) -> bool:
    try:
        x, y = float(a or "nan"), float(b or "nan")
    except ValueError:
        return a == b
    return math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12)


def status_metadata_updates(current: Mapping[str, str], values: Mapping[str, str], source: str) -> dict[str, str]:
    """The metadata changes a status message implies (empty when it adds nothing).

    Args:
        current: The metadata so far.
        values: The status message's key/values.
        source: ``"safety_status"`` (envelope status node) or ``"plan_status"`` (planner).

    Rules: ``envelope_id`` comes from the safety status (the envelope the SAFE/UNSAFE status is read off);
    a plan status with an ``airframe`` sets the airframe and its conditions to the planner's, and clears
    ``airframe_digest`` if they differ from the current ones (the digest was computed for the other aircraft).
    """
    updates: dict[str, str] = {}
    if source == "safety_status":
        envelope_id = values.get("envelope_id", "")
        if envelope_id and envelope_id != current.get("envelope_id"):
            updates["envelope_id"] = envelope_id
    elif source == "plan_status" and values.get("airframe"):
        planner = {"airframe": values["airframe"], **{k: values[k] for k in _CONDITION_KEYS if k in values}}
        differs = planner["airframe"] != current.get("airframe") or not all(
            _same_number(planner[k], current.get(k)) for k in _CONDITION_KEYS if k in planner
        )
        if differs:
            updates.update(planner)
            if current.get("airframe_digest"):
                updates["airframe_digest"] = ""
        if values.get("envelope_id") and not current.get("envelope_id"):
            updates["envelope_id"] = values["envelope_id"]
    return updates
