"""What a landing plan means for the crew: its status level and one line of text.

Levels follow ``diagnostic_msgs/DiagnosticStatus`` by name (the ROS layer maps them to bytes):

| plan | rotor speed | level | text starts with |
|---|---|---|---|
| safe (value ≤ 0 and replay lands within limits) | measured | OK | ``SAFE:`` |
| safe | assumed nominal (not measured) | WARN | ``SAFE if the rotor speed is nominal`` |
| unverified (value ≤ 0, replay fails) | any | WARN | ``NOT VERIFIED:`` |
| unsafe (value > 0) | any | ERROR | ``UNSAFE:`` |
"""

from __future__ import annotations

from enum import StrEnum
from typing import Any

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.units import FT, KT

__all__ = ["PlanStatus", "plan_verdict"]


class PlanStatus(StrEnum):
    """What the solve and its independent replay say of a landing plan (a str: ``"safe"`` etc. on the wire)."""

    SAFE = "safe"  # NLP value ≤ 0 and the replay lands within limits: the only status that is evidence
    UNSAFE = "unsafe"  # value > 0: no landing within limits exists in the model, the plan is the best effort
    UNVERIFIED = "unverified"  # value ≤ 0 but the replay does not land within limits
    FAILED = "failed"  # the solver did not converge: nothing is known


def plan_verdict(plan: Any, rotor_source: str) -> tuple[str, str]:
    """(level name ``"OK"``/``"WARN"``/``"ERROR"``, text) of a converged landing plan.

    Args:
        plan: a :class:`~helireach_ros.core.planning.planner.LandingPlan` (its replay's touchdown state is reported).
        rotor_source: ``"measured"`` or how the initial rotor speed was otherwise obtained.
    """
    touchdown = plan.replay.touchdown_state
    summary = (
        f"land in {plan.time_to_land:.1f} s at {touchdown[StateIndex.DESCENT_RATE] / FT:.1f} ft/s, "
        f"{plan.touchdown_ground_speed / KT:.1f} kt "
        f"(value {plan.value:+.2f})"
    )
    if plan.safe and rotor_source == "measured":
        return "OK", f"SAFE: {summary}"
    if plan.safe:
        return "WARN", f"SAFE if the rotor speed is nominal (not measured): {summary}"
    if plan.status == PlanStatus.UNVERIFIED:
        return "WARN", f"NOT VERIFIED: the replay does not land within limits; {summary}"
    return "ERROR", f"UNSAFE: no safe landing, best effort; {summary}"
