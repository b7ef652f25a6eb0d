"""Incompatible-QoS problems of one node's endpoints: when one starts, what it says, and when it is over.

The middleware reports an incompatibility once, when it discovers a remote endpoint that cannot be matched
(``requested_incompatible_qos`` on a subscription, ``offered_incompatible_qos`` on a publisher); it reports
nothing when that endpoint goes away. So a problem starts with the event and ends only when a check of the
graph finds no incompatible endpoint on that topic any more, and not before ``hold_s`` after the last event
(discovery data may lag the event). Until then it is an ERROR: no data flows between the two endpoints.

* An **input** problem (a subscription of this node cannot hear a publisher) means this node may be
  missing data it needs: the safety status is never SAFE while a helireach node reports one.
* An **output** problem (a subscriber requests what this publisher does not offer, e.g. TRANSIENT_LOCAL
  or RELIABLE from a volatile/best-effort topic, or a deadline) means that subscriber gets nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["INPUT", "OUTPUT", "QosProblem", "QosProblemLog"]

INPUT = "input"
OUTPUT = "output"


@dataclass(frozen=True)
class QosProblem:
    """One topic of this node with an incompatible remote endpoint.

    Attributes:
        topic: the topic. side: :data:`INPUT` (our subscription) or :data:`OUTPUT` (our publisher).
        policy: the last incompatible policy the middleware named (``RELIABILITY``, ``DURABILITY``,
            ``DEADLINE``, ``LIVELINESS``, ...). events: incompatible endpoints seen so far on it.
        last_event_ns: local time of the last event.
    """

    topic: str
    side: str
    policy: str
    events: int
    last_event_ns: int

    @property
    def text(self) -> str:
        """One line for people: topic, side and policy."""
        if self.side == INPUT:
            return f"{self.topic}: a publisher offers incompatible {self.policy} (its messages are not received)"
        return f"{self.topic}: a subscriber requests {self.policy} this node does not offer (it gets nothing)"


class QosProblemLog:
    """The open problems of one node, keyed by (topic, side). Not thread-safe: callers hold their lock."""

    def __init__(self, hold_s: float = 2.0) -> None:
        self._hold_ns = round(hold_s * 1e9)
        self._problems: dict[tuple[str, str], QosProblem] = {}
        self.total_events = 0

    def report(self, topic: str, side: str, policy: str, now_ns: int, new_events: int = 1) -> QosProblem:
        """Records an incompatible-QoS event; returns the (new or updated) problem."""
        previous = self._problems.get((topic, side))
        events = (previous.events if previous else 0) + max(new_events, 1)
        problem = QosProblem(topic, side, policy, events, now_ns)
        self._problems[(topic, side)] = problem
        self.total_events += max(new_events, 1)
        return problem

    def resolve(self, now_ns: int, still_incompatible: Callable[[str, str], bool]) -> list[QosProblem]:
        """Ends the problems held for ``hold_s`` whose topic no longer has an incompatible endpoint.

        Args:
            still_incompatible: (topic, side) → whether the graph still lists an incompatible endpoint.

        Returns:
            The problems that ended.
        """
        ended = [
            problem
            for problem in self._problems.values()
            if now_ns - problem.last_event_ns >= self._hold_ns and not still_incompatible(problem.topic, problem.side)
        ]
        for problem in ended:
            del self._problems[(problem.topic, problem.side)]
        return ended

    def problems(self, side: str | None = None) -> list[QosProblem]:
        """The open problems (of one side, or all), sorted by topic."""
        return sorted(
            (problem for problem in self._problems.values() if side is None or problem.side == side),
            key=lambda problem: (problem.side, problem.topic),
        )
