"""The closed-loop re-planning policy shared by the planner node and the lock-step closed loop.

After the first plan, the planner re-plans every ``replan_period`` from the current state, warm-started
from its previous plan, until the vehicle is below ``min_height`` or the current plan has less than
``min_remaining`` seconds to go (a re-plan that close to the ground would arrive after touchdown).
"""

from __future__ import annotations

__all__ = ["plan_time_remaining", "replanning_ends"]


def plan_time_remaining(time_to_land: float, elapsed: float) -> float:
    """Seconds the current plan still has to go: its time to land less the time since its state, s."""
    return time_to_land - elapsed


def replanning_ends(height: float, remaining: float, min_height: float, min_remaining: float) -> bool:
    """Whether the closed loop stops re-planning: below ``min_height`` (m) or under ``min_remaining`` (s) to go."""
    return height < min_height or remaining < min_remaining
