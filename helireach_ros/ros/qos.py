"""QoS of the helireach endpoints: incompatible-QoS events become an ERROR on ``/diagnostics``.

Every helireach node creates its input subscriptions (and the outputs it owns) through one
:class:`QosWatch`, which registers only the ``incompatible_qos`` event callback (not rclpy's default set:
each event handler is a waitable the executor polls, see ``NO_QOS_EVENTS_SUBSCRIPTION``). An event is
logged as an ERROR at once and published as the status ``<node>: QoS`` on ``/diagnostics``
(:mod:`helireach_ros.core.policies.qos_problems` says when a problem ends); the status goes out every period,
OK when there is no problem, so its absence is visible too.

What can still be incompatible once inputs subscribe BEST_EFFORT, VOLATILE (``SENSOR_QOS``)? Nothing on the
requested side: best effort is the weakest reliability and volatile the weakest durability, and the
subscription requests no deadline (infinite) and automatic liveliness with an infinite lease, so every
publisher's offer satisfies it. What remains: inputs that must stay strict (the failure event, RELIABLE;
latched topics, TRANSIENT_LOCAL) against a weaker publisher, and outputs against a subscriber that requests
more than is offered (RELIABLE from a best-effort publisher, TRANSIENT_LOCAL from a volatile one, a finite
deadline, manual liveliness). A publisher of another *type* is no QoS event (and not reported here).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from functools import partial
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSCompatibility, QoSPolicyKind, QoSProfile, qos_check_compatible

from helireach_ros.core.policies.qos_problems import INPUT, OUTPUT, QosProblemLog
from helireach_ros.ros import messages as rm

__all__ = ["QOS_STATUS_SUFFIX", "QosWatch", "drop_parameter_event_handlers", "input_problems_of"]

QOS_STATUS_SUFFIX = ": QoS"
"""Every node's QoS status on ``/diagnostics`` is named ``<node name>: QoS``."""
_INPUT_PROBLEMS_KEY = "input_problems"


def _policy_name(kind: Any) -> str:
    try:
        return QoSPolicyKind(int(kind)).name
    except ValueError:  # a policy kind newer than this rclpy
        return str(kind)


def input_problems_of(status: DiagnosticStatus) -> str:
    """The input problems a ``<node>: QoS`` status reports ('' for none or another kind of status)."""
    if not status.name.endswith(QOS_STATUS_SUFFIX):
        return ""
    return rm.status_values(status).get(_INPUT_PROBLEMS_KEY, "")


class QosWatch:
    """Creates a node's endpoints with an incompatible-QoS callback and reports their problems.

    Args:
        node: the node. period_s: how often the ``<node>: QoS`` status is published (and problems rechecked).
        hold_s: a problem lasts at least this long after its last event.
        publish: False for a node that publishes nothing (the display): events are only logged (ERROR).
    """

    def __init__(self, node: Node, period_s: float = 1.0, hold_s: float = 2.0, publish: bool = True) -> None:
        self._node = node
        self._lock = threading.Lock()
        self._log = QosProblemLog(hold_s)
        self._qos: dict[tuple[str, str], QoSProfile] = {}
        self._publisher = None
        if publish:
            self._publisher = node.create_publisher(
                DiagnosticArray, rm.TOPIC_DIAGNOSTICS, rm.STREAM_QOS, **rm.NO_QOS_EVENTS_PUBLISHER
            )
            node.create_timer(period_s, self.publish)

    # -- endpoints ---------------------------------------------------------------------------------------------
    def create_subscription(self, message_type: type, topic: str, callback: Callable, qos: QoSProfile, **kwargs):
        """``node.create_subscription`` with an incompatible-QoS callback (an input)."""
        self._qos[(topic, INPUT)] = qos
        events = SubscriptionEventCallbacks(
            incompatible_qos=partial(self._on_incompatible, topic, INPUT), use_default_callbacks=False
        )
        return self._node.create_subscription(message_type, topic, callback, qos, event_callbacks=events, **kwargs)

    def create_publisher(self, message_type: type, topic: str, qos: QoSProfile, **kwargs):
        """``node.create_publisher`` with an incompatible-QoS callback (an output)."""
        self._qos[(topic, OUTPUT)] = qos
        events = PublisherEventCallbacks(
            incompatible_qos=partial(self._on_incompatible, topic, OUTPUT), use_default_callbacks=False
        )
        return self._node.create_publisher(message_type, topic, qos, event_callbacks=events, **kwargs)

    # -- problems ----------------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self._node.get_clock().now().nanoseconds

    def _on_incompatible(self, topic: str, side: str, info: Any) -> None:
        with self._lock:
            problem = self._log.report(
                topic, side, _policy_name(info.last_policy_kind), self._now_ns(), int(info.total_count_change)
            )
        self._node.get_logger().error(f"incompatible QoS: {problem.text}")
        self.publish()

    def _still_incompatible(self, topic: str, side: str) -> bool:
        """Whether the graph still lists an endpoint on ``topic`` that cannot match ours."""
        ours = self._qos[(topic, side)]
        if side == INPUT:
            pairs = [(info.qos_profile, ours) for info in self._node.get_publishers_info_by_topic(topic)]
        else:
            pairs = [(ours, info.qos_profile) for info in self._node.get_subscriptions_info_by_topic(topic)]
        return any(qos_check_compatible(offer, request)[0] == QoSCompatibility.ERROR for offer, request in pairs)

    def input_problems(self) -> list[str]:
        """The open input problems of this node, one line each."""
        with self._lock:
            return [problem.text for problem in self._log.problems(INPUT)]

    def status(self) -> DiagnosticStatus:
        """The ``<node>: QoS`` status: ERROR naming each topic and policy, or OK."""
        now_ns = self._now_ns()
        with self._lock:
            ended = self._log.resolve(now_ns, self._still_incompatible)
            problems, total = self._log.problems(), self._log.total_events
        for problem in ended:
            self._node.get_logger().info(f"QoS problem over: {problem.topic} ({problem.side})")
        texts = {side: [p.text for p in problems if p.side == side] for side in (INPUT, OUTPUT)}
        level = DiagnosticStatus.ERROR if problems else DiagnosticStatus.OK
        message = "; ".join(p.text for p in problems) if problems else "no incompatible QoS"
        values = {
            _INPUT_PROBLEMS_KEY: "; ".join(texts[INPUT]),
            "output_problems": "; ".join(texts[OUTPUT]),
            "incompatible_qos_events": total,
        }
        for problem in problems:
            values[f"policy {problem.side} {problem.topic}"] = problem.policy
        return rm.diagnostic_status(level, f"{self._node.get_name()}{QOS_STATUS_SUFFIX}", message, "helireach", values)

    def publish(self) -> None:
        """Publishes the status on ``/diagnostics`` (the timer does every period; events at once)."""
        if self._publisher is not None:
            self._publisher.publish(rm.diagnostic_array(self._now_ns(), self.status()))


def drop_parameter_event_handlers(node: Node) -> int:
    """Removes rclpy's default QoS-event handlers from ``node``'s own ``/parameter_events`` publisher.

    rclpy creates that publisher in every node with the default event callbacks: two waitables per node that the
    single-threaded executor re-adds to its wait set on every wake-up (12 of the composed system's 41; each costs
    ~15 µs of Python per wait, and the failure path crosses three waits). Nothing here depends on them: they only
    log an incompatible subscriber of parameter events. Uses the publisher's public ``event_handlers`` and the
    node's ``remove_waitable``; the publisher is destroyed normally later. Returns how many were removed.
    """
    removed = 0
    for publisher in list(node.publishers):
        if publisher.topic_name != "/parameter_events" or not publisher.event_handlers:
            continue
        handlers: list[Any] = list(publisher.event_handlers)  # type: ignore[call-overload]  # a list, typed as one
        for handler in handlers:
            node.remove_waitable(handler)
            handler.destroy()
            removed += 1
        publisher.event_handlers = []  # type: ignore[assignment]  # destroy_publisher() destroys what is left
    return removed

