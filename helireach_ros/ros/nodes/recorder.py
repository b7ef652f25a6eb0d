"""Flight recorder node: logs helireach topics as raw CDR into a rosbag2-compatible MCAP file.

Messages are never deserialized (``raw=True`` subscriptions). Like ``ros2 bag record``, a topic is
subscribed once a publisher for it is discovered, with a request QoS adapted to what the publishers
offer (RELIABLE only if all offer it, TRANSIENT_LOCAL only if all offer it), so the recorder
connects to best-effort and volatile publishers and still receives the current value of latched
topics such as ``/helireach/safety_status`` even when it starts after their publisher. The QoS the
publisher offers is stored with the topic, so a replay keeps latched topics latched.

Run: ``python -m helireach_ros.ros.nodes.recorder --ros-args -p log_dir:=/tmp/logs``. SIGINT/SIGTERM end
spinning and the file is finished (summary and index written).
"""

from __future__ import annotations

import importlib
import os
import time
from collections.abc import Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rclpy.topic_endpoint_info import TopicEndpointInfo

from helireach_ros.core.mcap_log import McapLogError, McapLogWriter, QosDescription
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node

__all__ = [
    "DEFAULT_TOPICS",
    "McapRecorder",
    "documented_qos",
    "import_message_type",
    "main",
    "qos_profile",
]

#: ``topic:pkg/msg/Type`` entries recorded when the ``topics`` parameter is not set: every topic of the
#: contract table (:data:`helireach_ros.ros.messages.TOPICS`, documented in msg_docs/).
DEFAULT_TOPICS: tuple[str, ...] = tuple(f"{spec.name}:{spec.type_name}" for spec in rm.TOPICS.values())

_DEFAULT_QOS = QosDescription("reliable", "volatile", 10)
_DISCOVERY_PERIOD_S = 0.1  # rosbag2 polls the graph at the same rate
_MIN_SUBSCRIPTION_DEPTH = 100  # a recorder should absorb bursts rather than drop


def documented_qos(topic: str) -> QosDescription:
    """Return the documented publisher QoS of a topic (the contract table; RELIABLE, VOLATILE, depth 10 else)."""
    spec = rm.TOPICS.get(topic)
    if spec is None:
        return _DEFAULT_QOS
    reliable = spec.qos.reliability == ReliabilityPolicy.RELIABLE
    latched = spec.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
    return QosDescription(
        "reliable" if reliable else "best_effort", "transient_local" if latched else "volatile", spec.qos.depth
    )


def qos_profile(qos: QosDescription) -> QoSProfile:
    """Convert a :class:`QosDescription` to an rclpy ``QoSProfile`` (KEEP_LAST)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=qos.depth,
        reliability=ReliabilityPolicy.RELIABLE if qos.reliability == "reliable" else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.latched else DurabilityPolicy.VOLATILE,
    )


def import_message_type(type_name: str) -> type:
    """Import the Python class of ``pkg/msg/Type``.

    Raises:
        ValueError: The name is malformed or the type is not installed.
    """
    parts = type_name.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"message type must look like pkg/msg/Type, not {type_name!r}")
    package, namespace, name = parts
    try:
        return getattr(importlib.import_module(f"{package}.{namespace}"), name)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"message type {type_name} is not installed: {exc}") from exc


def _parse_topics(entries: Sequence[str]) -> dict[str, tuple[str, type]]:
    topics: dict[str, tuple[str, type]] = {}
    for entry in entries:
        topic, sep, type_name = entry.strip().partition(":")
        if not sep or not topic or not type_name:
            raise ValueError(f"topics entry {entry!r} is not of the form /topic:pkg/msg/Type")
        topics[topic] = (type_name, import_message_type(type_name))
    return topics


def _new_log_path(log_dir: Path) -> Path:
    stem = f"helireach_{time.strftime('%Y%m%d_%H%M%S', time.gmtime())}_{os.getpid()}"
    path = log_dir / f"{stem}.mcap"
    suffix = 1
    while path.exists():  # a second recorder in this process within the same second
        path = log_dir / f"{stem}_{suffix}.mcap"
        suffix += 1
    return path


def _offered_qos(topic: str, publishers: Sequence[TopicEndpointInfo]) -> QosDescription:
    """Describe what the (first) publisher offers; rmw does not report its history depth."""
    documented = documented_qos(topic)
    if not publishers:
        return documented
    profile = publishers[0].qos_profile
    depth = profile.depth if profile.history == HistoryPolicy.KEEP_LAST and profile.depth > 0 else documented.depth
    return QosDescription(
        reliability="reliable" if profile.reliability == ReliabilityPolicy.RELIABLE else "best_effort",
        durability="transient_local" if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL else "volatile",
        depth=depth,
    )


def _request_qos(topic: str, publishers: Sequence[TopicEndpointInfo]) -> QoSProfile:
    """A subscription QoS compatible with every publisher (rosbag2's adapt_request_to_offers)."""
    reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
    latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
    return qos_profile(
        QosDescription(
            reliability="reliable" if reliable else "best_effort",
            durability="transient_local" if latched else "volatile",
            depth=max(documented_qos(topic).depth, _MIN_SUBSCRIPTION_DEPTH),
        )
    )


class McapRecorder(Node):
    """Record topics into ``<log_dir>/helireach_<UTC yyyymmdd_HHMMSS>_<pid>.mcap``.

    Parameters (read-only): ``log_dir`` (``~`` expanded), ``topics`` (``/topic:pkg/msg/Type``),
    ``chunk_size`` (bytes per MCAP chunk), ``flush_period`` (seconds between forced chunk ends, which
    bounds what a hard kill loses; 0 disables).

    Args:
        metadata: Stored as the log's ``helireach`` metadata record (airframe, envelope id,
            software version, scenario...).
        **kwargs: Passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``...).
    """

    def __init__(self, metadata: Mapping[str, str] | None = None, **kwargs: Any) -> None:
        super().__init__("helireach_recorder", **kwargs)
        self._closed = False
        log_dir = self._declare("log_dir", "~/.helireach/logs", "Directory for the .mcap logs.")
        entries = self._declare("topics", list(DEFAULT_TOPICS), "Recorded topics as /topic:pkg/msg/Type.")
        chunk_size = self._declare("chunk_size", 64 * 1024, "Uncompressed bytes per MCAP chunk.")
        flush_period = self._declare(
            "flush_period", 1.0, "Seconds between forced chunk ends (bounds loss on a hard kill); 0 = off."
        )
        self._pending = _parse_topics(entries)
        directory = Path(os.path.expandvars(os.path.expanduser(log_dir)))
        directory.mkdir(parents=True, exist_ok=True)
        self._writer = McapLogWriter(_new_log_path(directory), metadata=metadata, chunk_size=chunk_size)
        self._subscriptions_by_topic: dict[str, Subscription] = {}
        self._warned_types: set[str] = set()
        self._discovery_timer: Timer | None = self.create_timer(_DISCOVERY_PERIOD_S, self._discover)
        self._flush_timer = self.create_timer(flush_period, self._writer.flush) if flush_period > 0 else None
        self.get_logger().info(f"recording {len(self._pending)} topics to {self.log_path}")
        self._discover()

    @property
    def log_path(self) -> Path:
        """The file being written."""
        return self._writer.path

    @property
    def message_count(self) -> int:
        """Messages recorded so far."""
        return self._writer.message_count

    @property
    def recorded_topics(self) -> list[str]:
        """Topics subscribed so far (a publisher has been discovered)."""
        return sorted(self._subscriptions_by_topic)

    def close(self) -> None:
        """Finish the log file (summary and index); idempotent."""
        if self._closed:
            return
        self._closed = True
        for timer in (self._discovery_timer, self._flush_timer):
            if timer is not None:
                timer.cancel()
        self._writer.close()
        self.get_logger().info(f"wrote {self._writer.message_count} messages to {self.log_path}")

    def destroy_node(self) -> None:
        """Finish the log, then destroy the node."""
        self.close()
        super().destroy_node()

    def _declare(self, name: str, default: Any, description: str) -> Any:
        descriptor = ParameterDescriptor(description=description, read_only=True)
        return self.declare_parameter(name, default, descriptor).value

    def _discover(self) -> None:
        """Subscribe to every pending topic that now has a publisher of the configured type."""
        if self._closed:
            return
        for topic, (type_name, msg_class) in list(self._pending.items()):
            offers = self.get_publishers_info_by_topic(topic)
            publishers = [p for p in offers if p.topic_type == type_name]
            if not publishers:
                self._warn_other_types(topic, type_name, offers)
                continue
            del self._pending[topic]
            try:
                self._writer.add_topic(topic, type_name, _offered_qos(topic, publishers))
            except McapLogError as exc:
                self.get_logger().error(f"not recording {topic}: {exc}")
                continue
            self._subscriptions_by_topic[topic] = self.create_subscription(
                msg_class, topic, partial(self._on_message, topic), _request_qos(topic, publishers), raw=True
            )
        if not self._pending and self._discovery_timer is not None:
            self._discovery_timer.cancel()
            self._discovery_timer = None

    def _warn_other_types(self, topic: str, type_name: str, offers: Sequence[TopicEndpointInfo]) -> None:
        other = {p.topic_type for p in offers} - {type_name}
        if other and topic not in self._warned_types:
            self._warned_types.add(topic)
            self.get_logger().warning(f"{topic} is published as {sorted(other)}, expected {type_name}")

    def _on_message(self, topic: str, data: bytes, info: Mapping[str, Any] | None = None) -> None:
        log_time = self.get_clock().now().nanoseconds
        source = info.get("source_timestamp") if isinstance(info, Mapping) else None
        try:
            self._writer.write(topic, data, log_time, source or log_time)
        except McapLogError:
            # A callback racing close() (a stop signal, another executor thread): the log is already finished.
            if not self._writer.closed:
                raise


def main(args: list[str] | None = None) -> None:
    """Run the recorder until SIGINT/SIGTERM, then finish the log (destroying the node closes it)."""
    run_node(McapRecorder, args)


if __name__ == "__main__":
    main()
