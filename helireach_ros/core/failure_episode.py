"""One engine failure as the planner handles it: the episode and the plans published for it.

An episode starts with a failure event and collects every plan published for it (the first plan,
a fallback, the closed-loop re-plans). It stays ``active`` while the closed loop re-plans; the
re-planning policy (:mod:`helireach_ros.core.replanning`) ends it near the ground.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["FailureEpisode", "PublishedPlan"]


@dataclass
class PublishedPlan:
    """A plan as published: the core plan (or fallback), its stamp and bookkeeping.

    Attributes:
        failure_id: the episode it belongs to.
        replan_index: re-plans made in the episode before this one.
        stamp_ns: stamp of the state it starts from (its t = 0).
        plan: a :class:`~helireach_ros.core.planner.LandingPlan` or :class:`~helireach_ros.core.fallback.FallbackPlan`.
        fallback: whether it is a fallback (never safe).
        latency_ms: from the failure event's receipt (first plan) or the state's stamp (re-plan) to publication.
        published_at_ns: when it was published.
        warm_start_source: ``"envelope"``, ``"previous_plan"`` or ``"none"``.
    """

    failure_id: int
    replan_index: int
    stamp_ns: int
    plan: Any
    fallback: bool
    latency_ms: float
    published_at_ns: int
    warm_start_source: str


@dataclass
class FailureEpisode:
    """One engine failure being handled (mutable bookkeeping, guarded by its owner's lock)."""

    failure_id: int
    event_stamp_ns: int
    event_received_ns: int
    active: bool = True
    published: bool = False
    current: PublishedPlan | None = None
    replans: int = 0
    replans_failed: int = 0
    deadline_handled: bool = False
    history: list[PublishedPlan] = field(default_factory=list)

    def remember(self, record: PublishedPlan) -> None:
        """Records a published plan as the episode's current one."""
        self.published = True
        self.current = record
        self.history.append(record)
