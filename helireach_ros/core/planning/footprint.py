"""The reachable footprint: the nearest and the farthest touchdown a safe landing can reach from a state.

A plan answers *whether* and *how* to land; its touchdown point is wherever its optimum puts it. The footprint
answers *where*: two more landing NLPs from the same state, the same dynamics, limits and flyability, whose objective
is the touchdown distance instead of the touchdown cost,

.. math:: z_{near} = \\min_{T, u(\\cdot)} z(T) - z(0), \\qquad z_{far} = \\max_{T, u(\\cdot)} z(T) - z(0)
          \\quad \\text{subject to} \\quad J(x(T)) \\le -m,

with m the settings' ``footprint_margin`` (an end rides no limit: 5 % inside the nearest touchdown limit by default;
:class:`~helireach_ros.core.ocp.settings.PlannerSettings`). Tierney & Langelaan (2010) plan an autorotation to a
designated touchdown point; the footprint is the range of points such a plan can be asked for. Each end is a
:class:`~helireach_ros.core.planning.planner.LandingPlan` like any other: it counts only when the independent replay
lands it within limits (``safe``), and its distance is the *replayed* touchdown's.

Both NLPs are non-convex: each end is solved from every warm start given and cold, and the most extreme verified
landing is kept (measured at 500 ft / 75 kt: cold, the nearest end's replay breaks a limit where the end warm-started
from the touchdown-cost plan lands). Only the two ends are verified: a touchdown between them is very likely
reachable (the controls vary continuously) but is not evidence until its own plan is replayed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.ocp.settings import PlannerSettings
from helireach_ros.core.planning.planner import LandingPlan, WarmStart, get_planner

__all__ = ["ReachableFootprint", "SiteReachability", "reachable_footprint", "touchdown_distance"]


class SiteReachability(StrEnum):
    """What the footprint says of a landing site."""

    REACHABLE = "reachable"  # it overlaps the footprint between two verified ends
    NOT_REACHABLE = "not_reachable"  # it lies beyond a verified end
    UNKNOWN = "unknown"  # an end the site would need is not verified


def touchdown_distance(plan: LandingPlan) -> float:
    """The replayed touchdown's distance from the plan's start, m (NaN for a plan that was not replayed)."""
    return float(plan.replay.touchdown_state[StateIndex.DISTANCE] - plan.initial_state[StateIndex.DISTANCE])


@dataclass(frozen=True)
class ReachableFootprint:
    """The two ends of the reachable footprint from one state.

    Attributes:
        nearest: the verified landing with the shortest touchdown distance (None: none verified).
        farthest: the verified landing with the longest (None: none verified).
        tried: every plan solved for either end, in order (the evidence of a missing end).
    """

    nearest: LandingPlan | None
    farthest: LandingPlan | None
    tried: tuple[LandingPlan, ...]

    @property
    def reachable(self) -> bool:
        """Both ends are replay-verified landings."""
        return self.nearest is not None and self.farthest is not None

    @property
    def nearest_m(self) -> float:
        """m from the start (NaN without a verified nearest end)."""
        return touchdown_distance(self.nearest) if self.nearest is not None else math.nan

    @property
    def farthest_m(self) -> float:
        """m from the start (NaN without a verified farthest end)."""
        return touchdown_distance(self.farthest) if self.farthest is not None else math.nan

    def covers(self, start_m: float, end_m: float) -> bool:
        """Whether [start_m, end_m] (a site along the track, m from the state) overlaps the footprint (both ends
        verified)."""
        return self.site_reachability(start_m, end_m) is SiteReachability.REACHABLE

    def site_reachability(self, start_m: float, end_m: float) -> SiteReachability:
        """Whether a site can be reached, as far as the verified ends tell: beyond a verified end it cannot
        (within the model); where an end is missing, the footprint does not know (a site plan may still land)."""
        if self.farthest is not None and start_m > self.farthest_m:
            return SiteReachability.NOT_REACHABLE
        if self.nearest is not None and end_m < self.nearest_m:
            return SiteReachability.NOT_REACHABLE
        return SiteReachability.REACHABLE if self.reachable else SiteReachability.UNKNOWN


def reachable_footprint(
    state: np.ndarray,
    airframe: Airframe,
    settings: PlannerSettings,
    *,
    warm_starts: Sequence[WarmStart] = (),
) -> ReachableFootprint:
    """The footprint from ``state`` (y, v, Ω, h, z, P; SI) for the flyable method of ``settings``.

    Args:
        warm_starts: solutions to start each end from (e.g. the touchdown-cost plan's); a cold solve is tried too.

    Raises:
        ValueError: a state the planner refuses, or settings whose method is not flyable.
    """
    tried: list[LandingPlan] = []
    ends: dict[str, LandingPlan | None] = {}
    for objective in ("nearest_touchdown", "farthest_touchdown"):
        planner = get_planner(airframe, settings.replace(objective=objective))
        plans = [planner.plan(state, warm_start) for warm_start in (*warm_starts, None)]
        tried += plans
        verified = [plan for plan in plans if plan.safe]
        pick = min if objective == "nearest_touchdown" else max
        ends[objective] = pick(verified, key=touchdown_distance) if verified else None
    return ReachableFootprint(ends["nearest_touchdown"], ends["farthest_touchdown"], tuple(tried))
