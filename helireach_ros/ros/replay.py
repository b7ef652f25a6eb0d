"""Replay a helireach MCAP log onto ROS 2 topics (raw CDR, original QoS and timing).

``replay_log`` is the library call (the ``helireach replay`` subcommand uses it); ``main`` is the
small ``helireach-replay LOG.mcap [--rate X] [--topics ...]`` command line.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Sequence

import rclpy
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.utilities import remove_ros_args

from helireach_ros.core.mcap_log import McapLogError, read_log, read_log_topics
from helireach_ros.ros.nodes.recorder import import_message_type, qos_profile

__all__ = ["main", "replay_log"]

_MATCH_TIMEOUT_S = 2.0
_MATCH_POLL_S = 0.02
_ACK_TIMEOUT_S = 1.0


def _wait_for_subscribers(publishers: Sequence[Publisher], timeout_s: float) -> None:
    """Give discovery a bounded chance to match every publisher before anything is sent."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and any(p.get_subscription_count() == 0 for p in publishers):
        time.sleep(_MATCH_POLL_S)


def replay_log(
    path: str | os.PathLike[str],
    rate: float = 1.0,
    node: Node | None = None,
    topics: list[str] | None = None,
    context: Context | None = None,
) -> int:
    """Republish every logged message as raw CDR with the QoS its publisher offered.

    The original spacing of log times is kept, divided by ``rate``. Before the first message the
    call waits (at most ~2 s) for each topic to have a subscriber; at the end it waits (at most
    ~1 s) for reliable messages to be acknowledged.

    Publishers created on a caller-supplied ``node`` stay alive after the call, so latched topics
    (TRANSIENT_LOCAL) still reach late subscribers until that node is destroyed; with ``node=None``
    a temporary node is created in ``context`` (which must be initialized) and destroyed at the end.

    Args:
        path: The ``.mcap`` log.
        rate: Playback speed factor; ``<= 0`` or infinite replays as fast as possible.
        node: Node to create the publishers on.
        topics: Only replay these topics (default: all).
        context: rclpy context for the temporary node (default: the global one).

    Returns:
        The number of messages published (fewer if the context shuts down mid-replay).

    Raises:
        McapLogError: The log is unreadable or a logged type is not installed.
    """
    logged = read_log_topics(path)
    selected = {t: info for t, info in logged.items() if topics is None or t in topics}
    own_node = node is None
    if node is None:
        node = rclpy.create_node("helireach_replay", context=context)
    try:
        missing = sorted(set(topics or ()) - set(logged))
        if missing:
            node.get_logger().warning(f"not in {os.fspath(path)}: {', '.join(missing)}")
        publishers: dict[str, Publisher] = {}
        for topic, info in selected.items():
            try:
                msg_class = import_message_type(info.type_name)
            except ValueError as exc:
                raise McapLogError(f"cannot replay {topic}: {exc}", path) from exc
            publishers[topic] = node.create_publisher(msg_class, topic, qos_profile(info.qos))
        _wait_for_subscribers(list(publishers.values()), _MATCH_TIMEOUT_S)
        count = _publish_timed(path, publishers, rate, node.context)
        for publisher in publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=_ACK_TIMEOUT_S))
        return count
    finally:
        if own_node:
            node.destroy_node()


def _publish_timed(
    path: str | os.PathLike[str], publishers: dict[str, Publisher], rate: float, context: Context
) -> int:
    paced = rate > 0 and math.isfinite(rate)
    count = 0
    first_log_ns: int | None = None
    start = time.monotonic()
    for message in read_log(path):
        publisher = publishers.get(message.topic)
        if publisher is None:
            continue
        if not context.ok():
            break
        if first_log_ns is None:
            first_log_ns = message.log_time_ns
            start = time.monotonic()
        if paced:
            delay = (message.log_time_ns - first_log_ns) / 1e9 / rate - (time.monotonic() - start)
            if delay > 0:
                time.sleep(delay)
        publisher.publish(message.cdr)
        count += 1
    return count


def main(argv: Sequence[str] | None = None) -> int:
    """``helireach-replay LOG.mcap [--rate X] [--topics T ...] [--ros-args ...]``; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="helireach-replay", description="Replay a helireach MCAP log.")
    parser.add_argument("log", help="the .mcap file")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor; 0 = as fast as possible")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    options = parser.parse_args(remove_ros_args(["helireach-replay", *argv])[1:])
    rclpy.init(args=["helireach-replay", *argv])
    try:
        count = replay_log(options.log, rate=options.rate, topics=options.topics)
        print(f"replayed {count} messages from {options.log}")
        return 0
    except McapLogError as exc:
        print(f"helireach-replay: {exc}", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
