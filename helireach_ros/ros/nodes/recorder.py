"""Flight recorder node: logs helireach topics as raw CDR into a rosbag2-compatible MCAP file.

Messages are never deserialized (``raw=True`` subscriptions). Like ``ros2 bag record``, a topic is
subscribed once a publisher for it is discovered, with a request QoS adapted to what the publishers
offer (RELIABLE only if all offer it, TRANSIENT_LOCAL only if all offer it), so the recorder
connects to best-effort and volatile publishers and still receives the current value of latched
topics such as ``/helireach/safety_status`` even when it starts after their publisher. The QoS the
publisher offers is stored with the topic, so a replay keeps latched topics latched.

Discovery gap: a topic is subscribed only once its publisher is discovered (as ``ros2 bag record``), so
messages a publisher in *another process* sends before discovery completes (typically 0.1–0.5 s after
both exist) are not recorded: start the recorder first. The composed bringup creates it first and waits
(:meth:`McapRecorder.wait_until_recording`) before anything spins.

Metadata: every recorder writes the ``helireach`` record itself (:mod:`helireach_ros.core.mcap_log.run_metadata`):
airframe and conditions from the shared ``airframe``/``gross_weight``/``density_altitude`` parameters, the
``planner_settings`` file, then the envelope id and the planner's aircraft as ``/helireach/safety_status`` and
``/helireach/plan_status`` report them, so ``helireach replay --compare`` works on a multi-process run's log.

Loss bound: the open chunk is written out once its oldest message has waited ``flush_period`` (0.5 s),
checked at every message and every ``flush_period / 2``, so no message waits in memory longer than
0.75 s plus executor latency and a SIGKILL loses under 1 s of messages (docs/guides/failure-handling.md, "Logs").

Run: ``python -m helireach_ros.ros.nodes.recorder --ros-args -p log_dir:=/tmp/logs``. SIGINT/SIGTERM end
spinning and the file is finished (summary and index written).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rclpy.topic_endpoint_info import TopicEndpointInfo

from helireach_ros import __version__
from helireach_ros.core.mcap_log import McapLogError, McapLogWriter, QosDescription
from helireach_ros.core.mcap_log.run_metadata import aircraft_metadata, status_metadata_updates
from helireach_ros.ros import messages as rm
from helireach_ros.ros.executors import run_node
from helireach_ros.ros.parameter_table import parameter
from helireach_ros.ros.parameters import declare_aircraft, declare_parameters
from helireach_ros.ros.qos import QosWatch

__all__ = [
    "DEFAULT_TOPICS",
    "McapRecorder",
    "RecorderParameters",
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
_MATCH_POLL_S = 0.01
# Status topics whose values the metadata adopts (run_metadata.status_metadata_updates).
_METADATA_SOURCES = {rm.TOPIC_SAFETY_STATUS: "safety_status", rm.TOPIC_PLAN_STATUS: "plan_status"}
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


@dataclass(frozen=True)
class RecorderParameters:
    """The recorder's own parameters (one table: :mod:`helireach_ros.ros.parameter_table`); the aircraft's
    (``airframe``, ``gross_weight``, ``density_altitude``, for the log's metadata) come from ``declare_aircraft``."""

    log_dir: str = parameter("~/.helireach/logs", "Directory for the .mcap logs.")
    topics: list = parameter(list(DEFAULT_TOPICS), "Recorded topics as /topic:pkg/msg/Type.")
    chunk_size: int = parameter(64 * 1024, "Uncompressed bytes per MCAP chunk.", (1024, 1 << 30))
    flush_period: float = parameter(
        0.5, "Longest wait of a message in memory, s (bounds loss on a hard kill); 0 = off.", (0.0, 60.0)
    )
    max_message_bytes: int = parameter(
        1 << 20,
        "Messages larger than this are not written (counted per topic in the log's metadata), bytes; 0 = any.",
        (0, 1 << 31),
    )
    planner_settings: str = parameter("", "planner settings file for the metadata ('' = config/planner.yaml)")


class McapRecorder(Node):
    """Record topics into ``<log_dir>/helireach_<UTC yyyymmdd_HHMMSS>_<pid>.mcap``.

    Parameters (read-only): ``log_dir`` (``~`` expanded), ``topics`` (``/topic:pkg/msg/Type``),
    ``chunk_size`` (bytes per MCAP chunk), ``flush_period`` (longest wait of a message in the open chunk, s,
    which bounds what a hard kill loses; 0 = size only), the shared ``airframe``, ``gross_weight``,
    ``density_altitude`` and ``planner_settings`` (file, '' = config/planner.yaml) for the metadata.

    Args:
        metadata: Merged over what the recorder knows itself into the log's ``helireach`` metadata record
            (e.g. the scenario, or the composed planner's values).
        **kwargs: Passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``...).
    """

    def __init__(self, metadata: Mapping[str, str] | None = None, **kwargs: Any) -> None:
        super().__init__("helireach_recorder", **kwargs)
        self._closed = False
        self.config = config = declare_parameters(self, RecorderParameters)
        load_aircraft = declare_aircraft(self)
        log_dir, entries, chunk_size, flush_period = (
            config.log_dir,
            config.topics,
            config.chunk_size,
            config.flush_period,
        )
        self._max_message_bytes, settings_file = config.max_message_bytes, config.planner_settings
        self._pending = _parse_topics(entries)
        directory = Path(os.path.expandvars(os.path.expanduser(log_dir)))
        directory.mkdir(parents=True, exist_ok=True)
        known = {**self._own_metadata(load_aircraft, settings_file), **(metadata or {})}
        max_chunk_age = flush_period if flush_period > 0 else None
        self._writer = McapLogWriter(
            _new_log_path(directory), metadata=known, chunk_size=chunk_size, max_chunk_age=max_chunk_age
        )
        self._subscriptions_by_topic: dict[str, Subscription] = {}
        # One incompatible-QoS handler per subscription (an ERROR line: that publisher's messages are not logged),
        # not rclpy's default two: each is a waitable the composed system's executor re-adds on every wait.
        self._qos_watch = QosWatch(self, publish=False)
        self._warned_types: set[str] = set()
        self._unreadable_status: set[str] = set()
        self._oversized: dict[str, int] = {}  # topic -> messages not written for their size
        self._discovery_timer: Timer | None = self.create_timer(_DISCOVERY_PERIOD_S, self._discover)
        self._flush_timer = self.create_timer(flush_period / 2, self._writer.flush_stale) if flush_period > 0 else None
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

    @property
    def metadata(self) -> dict[str, str]:
        """The log's current ``helireach`` metadata."""
        return self._writer.metadata

    def update_metadata(self, values: Mapping[str, str]) -> None:
        """Merge values into the log's ``helireach`` metadata (a change writes the record again)."""
        if not self._closed:
            self._writer.update_metadata(values)

    def wait_until_recording(self, timeout_s: float) -> bool:
        """Subscribe to every topic that has a publisher now and wait until each subscription has matched them all.

        For the composed system before it spins (nothing is published yet), and for tests; bounded by ``timeout_s``.

        Returns:
            Whether every discovered publisher of a recorded topic is matched.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            self._discover()
            if self._all_matched() or time.monotonic() >= deadline:
                return self._all_matched()
            time.sleep(_MATCH_POLL_S)

    def _all_matched(self) -> bool:
        for topic, (type_name, _) in self._pending.items():
            if any(p.topic_type == type_name for p in self.get_publishers_info_by_topic(topic)):
                return False  # a publisher the next _discover() subscribes to
        for topic, subscription in self._subscriptions_by_topic.items():
            if subscription.get_publisher_count() < self.count_publishers(topic):
                return False
        return True

    def _own_metadata(self, load_aircraft: Any, settings_file: str) -> dict[str, str]:
        """What this recorder knows by itself: software, command, aircraft and planner settings from its parameters."""
        from helireach_ros.core.ocp.settings import load_settings

        values = {"software_version": __version__, "command": " ".join(sys.argv) or "helireach_recorder"}
        try:
            values.update(aircraft_metadata(load_aircraft(), load_settings(settings_file or None)))
        except Exception as exc:  # a broken file must not stop the recorder; the log then says less
            self.get_logger().error(f"log metadata without airframe/planner settings: {exc}")
        return values

    def close(self) -> None:
        """Finish the log file (summary and index); idempotent."""
        if self._closed:
            return
        self._closed = True
        for timer in (self._discovery_timer, self._flush_timer):
            if timer is not None:
                timer.cancel()
        if self._oversized:  # the final counts (the metadata record written last wins)
            self._writer.update_metadata({"oversized_dropped": self._oversized_summary()})
        self._writer.close()
        self.get_logger().info(f"wrote {self._writer.message_count} messages to {self.log_path}")

    def destroy_node(self) -> None:
        """Finish the log, then destroy the node."""
        self.close()
        super().destroy_node()

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
            self._subscriptions_by_topic[topic] = self._qos_watch.create_subscription(
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

    @property
    def oversized_counts(self) -> dict[str, int]:
        """Messages not written because they exceeded ``max_message_bytes``, per topic."""
        return dict(self._oversized)

    def _skip_oversized(self, topic: str, size: int) -> None:
        """A message over the bound is counted, said once per topic, and named in the log's metadata, so the log
        says what it lacks (a flood of 1.7 MB messages wrote 400 MB in 11 s)."""
        count = self._oversized.get(topic, 0) + 1
        self._oversized[topic] = count
        if count == 1:
            self.get_logger().warning(
                f"{topic}: a message of {size} bytes exceeds max_message_bytes {self._max_message_bytes}; messages "
                "this large are not written (counted in the log's metadata as oversized_dropped)"
            )
        if count == 1 or count % 100 == 0:
            with contextlib.suppress(McapLogError):  # racing close(): the log is already finished
                self._writer.update_metadata({"oversized_dropped": self._oversized_summary()})

    def _oversized_summary(self) -> str:
        return " ".join(f"{name}:{count}" for name, count in sorted(self._oversized.items()))

    def _on_message(self, topic: str, data: bytes, info: Mapping[str, Any] | None = None) -> None:
        log_time = self.get_clock().now().nanoseconds
        source = info.get("source_timestamp") if isinstance(info, Mapping) else None
        if 0 < self._max_message_bytes < len(data):
            self._skip_oversized(topic, len(data))
            return
        try:
            self._writer.write(topic, data, log_time, source or log_time)
            source_kind = _METADATA_SOURCES.get(topic)
            if source_kind is not None:
                self._adopt_status(topic, source_kind, data)
        except McapLogError:
            # A callback racing close() (a stop signal, another executor thread): the log is already finished.
            if not self._writer.closed:
                raise

    def _adopt_status(self, topic: str, source_kind: str, data: bytes) -> None:
        """Take the envelope id / the planner's aircraft from a status message into the metadata."""
        try:
            values = rm.status_values(deserialize_message(data, DiagnosticStatus))
        except Exception as exc:  # a foreign publisher's bad bytes are still recorded; only the metadata skips them
            if topic not in self._unreadable_status:
                self._unreadable_status.add(topic)
                self.get_logger().warning(f"{topic}: cannot read status values for the metadata: {exc}")
            return
        updates = status_metadata_updates(self._writer.metadata, values, source_kind)
        if updates:
            self._writer.update_metadata(updates)


def main(args: list[str] | None = None) -> None:
    """Run the recorder until SIGINT/SIGTERM, then finish the log (destroying the node closes it)."""
    raise SystemExit(run_node(McapRecorder, args))  # 2: bad command line or parameter (one line on stderr)


if __name__ == "__main__":
    main()
