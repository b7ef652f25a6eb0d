"""Replay a helireach MCAP log onto ROS 2 topics (raw CDR, original QoS and timing) with ``/clock``.

``replay_log`` is the library call; :func:`add_playback_arguments` and :func:`run_replay` are shared by
``helireach replay`` (:mod:`helireach_ros.cli.replay`) and the ``helireach_replay`` console script (:func:`main`).

Playback rules:

* Log-time spacing is kept, divided by ``rate`` (``0`` = as fast as possible); a negative, NaN or infinite
  rate is refused (exit code 2).
* ``/clock`` (``rosgraph_msgs/Clock``, RELIABLE depth 1, which best-effort and reliable subscribers both
  match) carries the log time being played: before each message whose time is ahead of the last clock, and
  every 25 ms while waiting (rosbag2's 40 Hz), so nodes started with ``use_sim_time:=true`` run on the log's
  time, scaled by the rate. A ``--loop`` restart sends the clock back to the start.
* ``start_s`` skips the first seconds of the log (counted from its first message); the last message before that
  point of every latched (TRANSIENT_LOCAL) topic is published first, so the current status is not missing.
* Topics the log does not have are refused, naming the ones it has (exit code 2).
* Start-up: publishers wait for discovery at most :data:`DISCOVERY_WAIT_S` (``--discovery-wait``; less once
  every topic has a subscriber); the log is read lazily through its index. A subscriber that matches later (a
  loaded machine, a remote host) misses what was sent before (as with ``ros2 bag play``): raise the wait.

rclpy is imported inside the functions, so ``helireach --help`` can build the argument parser cheaply.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from typing import TYPE_CHECKING

from helireach_ros.core.mcap_log import (
    LoggedMessage,
    LoggedTopic,
    McapLogError,
    is_finished_log,
    log_damage,
    read_log,
    read_log_overview,
)

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.publisher import Publisher

__all__ = [
    "CLOCK_TOPIC",
    "DISCOVERY_WAIT_S",
    "PROGRESS_INTERVAL_S",
    "add_playback_arguments",
    "check_playback",
    "main",
    "replay_log",
    "run_replay",
]

CLOCK_TOPIC = "/clock"
DISCOVERY_WAIT_S = 0.5
PROGRESS_INTERVAL_S = 5.0
"""s of wall time between the progress lines of a replay."""
"""Longest wait for subscribers before the first message (ends early when every topic has one)."""
_MATCH_POLL_S = 0.01
_ACK_TIMEOUT_S = 1.0
_CLOCK_PERIOD_S = 0.025  # rosbag2 play's default clock frequency, 40 Hz


class _ContextShutDownError(Exception):
    """The context shut down (Ctrl-C, SIGTERM) between the check and a publish."""


def _publish(publisher: Publisher, message: object, context: Context) -> None:
    try:
        publisher.publish(message)
    except Exception:
        if context.ok():
            raise
        raise _ContextShutDownError from None


def _finite_non_negative(text: str, meaning: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value < 0.0:
        raise argparse.ArgumentTypeError(f"must be {meaning}, not {text}")
    return value


def playback_rate(text: str) -> float:
    """Parse ``--rate``: a finite factor ≥ 0 (0 = as fast as possible); ``argparse`` type function."""
    return _finite_non_negative(text, "a finite factor >= 0 (0 = as fast as possible)")


def start_offset(text: str) -> float:
    """Parse ``--start``: finite seconds ≥ 0 into the log; ``argparse`` type function."""
    return _finite_non_negative(text, "finite seconds >= 0 into the log")


def add_playback_arguments(parser: argparse.ArgumentParser) -> None:
    """The playback options (``log``, ``--rate``, ``--topics``, ``--start``, ``--loop``, ``--recover``)."""
    parser.add_argument("log", help="the .mcap file")
    parser.add_argument("--rate", type=playback_rate, default=1.0, help="speed factor >= 0; 0 = as fast as possible")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics (each must be in the log)")
    parser.add_argument("--start", type=start_offset, default=0.0, metavar="S", help="begin S seconds into the log")
    parser.add_argument("--loop", action="store_true", help="play again from --start until Ctrl-C")
    parser.add_argument(
        "--discovery-wait",
        type=lambda text: _finite_non_negative(text, "finite seconds >= 0"),
        default=DISCOVERY_WAIT_S,
        metavar="S",
        help=f"wait at most S s for every topic to have a subscriber before playing (default {DISCOVERY_WAIT_S})",
    )
    parser.add_argument(
        "--recover",
        action="store_true",
        help="play a log the recorder never closed (its complete chunks; 'helireach log recover' makes a copy)",
    )


def _print_progress(log: str, count: int, log_s: float) -> None:
    print(f"replaying {log}: {count} messages, {log_s:.1f} s of log", flush=True)


def check_playback(
    path: str | os.PathLike[str], rate: float, topics: Sequence[str] | None, start_s: float, allow_truncated: bool
) -> dict[str, LoggedTopic]:
    """Validate a replay request; return the selected topics.

    Raises:
        McapLogError: the log is unreadable (or truncated without ``allow_truncated``).
        ValueError: a bad rate or start, or topics the log does not have (the message lists the log's topics).
    """
    if not math.isfinite(rate) or rate < 0.0:
        raise ValueError(f"rate must be a finite factor >= 0 (0 = as fast as possible), not {rate}")
    if not math.isfinite(start_s) or start_s < 0.0:
        raise ValueError(f"start must be finite seconds >= 0, not {start_s}")
    logged, span_ns = read_log_overview(path, allow_truncated=allow_truncated)
    if is_finished_log(path) and (damage := log_damage(path)):  # never play part of a log without saying so
        more = f" and {len(damage) - 1} more" if len(damage) > 1 else ""
        raise McapLogError(
            f"log is damaged: {damage[0]}{more}; 'helireach log recover' salvages the intact records", path
        )
    length_s = 0.0 if span_ns is None else (span_ns[1] - span_ns[0]) * 1e-9
    if start_s > length_s:
        raise ValueError(
            f"start {start_s:g} s is past the end of {os.fspath(path)} (its messages span {length_s:.3f} s)"
        )
    missing = sorted(set(topics or ()) - set(logged))
    if missing:
        raise ValueError(
            f"not in {os.fspath(path)}: {', '.join(missing)}; the log has {', '.join(sorted(logged)) or 'no topics'}"
        )
    return {t: info for t, info in logged.items() if topics is None or t in topics}


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
    *,
    start_s: float = 0.0,
    loops: int = 1,
    publish_clock: bool = True,
    allow_truncated: bool = False,
    discovery_wait_s: float = DISCOVERY_WAIT_S,
    on_progress: Callable[[int, float], None] | None = None,
    progress_interval_s: float = PROGRESS_INTERVAL_S,
) -> int:
    """Republish logged messages as raw CDR with the QoS their publisher offered, and ``/clock``.

    Publishers created on a caller-supplied ``node`` stay alive after the call, so latched topics
    (TRANSIENT_LOCAL) still reach late subscribers until that node is destroyed; with ``node=None``
    a temporary node is created in ``context`` (which must be initialized) and destroyed at the end.
    At the end the call waits (at most ~1 s) for reliable messages to be acknowledged.

    Args:
        path: The ``.mcap`` log.
        rate: Playback speed factor; ``0`` replays as fast as possible.
        node: Node to create the publishers on.
        topics: Only replay these topics (default: all); each must be in the log.
        context: rclpy context for the temporary node (default: the global one).
        start_s: Seconds into the log to begin at.
        loops: Passes over the log (each from ``start_s``); ``0`` = until the context shuts down (``--loop``).
        publish_clock: Publish ``/clock`` with the log time.
        allow_truncated: Play a file that was never closed (its complete chunks).
        discovery_wait_s: Longest wait for every topic to have a subscriber before the first message.
        on_progress: Called with (messages published so far, log seconds played of this pass) at most every
            ``progress_interval_s`` of wall time during playback (a long replay is not silent).
        progress_interval_s: s of wall time between progress calls.

    Returns:
        The number of messages published (fewer if the context shuts down mid-replay).

    Raises:
        McapLogError: The log is unreadable or a logged type is not installed.
        ValueError: A bad rate or start, or a topic the log does not have.
    """
    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from helireach_ros.ros.nodes.recorder import import_message_type, qos_profile

    selected = check_playback(path, rate, topics, start_s, allow_truncated)
    if loops < 0:
        raise ValueError(f"loops must be >= 0 (0 = until shut down), not {loops}")
    own_node = node is None
    if node is None:
        node = rclpy.create_node("helireach_replay", context=context)
    try:
        publishers: dict[str, Publisher] = {}
        for topic, info in selected.items():
            try:
                msg_class = import_message_type(info.type_name)
            except ValueError as exc:
                raise McapLogError(f"cannot replay {topic}: {exc}", path) from exc
            publishers[topic] = node.create_publisher(msg_class, topic, qos_profile(info.qos))
        clock_publisher = (
            node.create_publisher(Clock, CLOCK_TOPIC, QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
            if publish_clock
            else None
        )

        def publish_clock_at(log_ns: int) -> None:
            if clock_publisher is not None:
                message = Clock()
                message.clock.sec, message.clock.nanosec = divmod(log_ns, 1_000_000_000)
                _publish(clock_publisher, message, node.context)

        _wait_for_subscribers(list(publishers.values()), discovery_wait_s)
        count, passes = 0, 0
        while node.context.ok() and (loops == 0 or passes < loops):
            progress = _Progress(on_progress, progress_interval_s, count)
            count += _play_once(
                read_log(path, allow_truncated=allow_truncated), publishers, publish_clock_at, rate, start_s, node,
                progress,
            )  # fmt: skip
            passes += 1
        for publisher in publishers.values():
            if node.context.ok():
                publisher.wait_for_all_acked(Duration(seconds=_ACK_TIMEOUT_S))
        return count
    finally:
        if own_node:
            node.destroy_node()


def _play_once(
    messages: Iterable[LoggedMessage],
    publishers: dict[str, Publisher],
    publish_clock_at: Callable[[int], None],
    rate: float,
    start_s: float,
    node: Node,
    progress: _Progress,
) -> int:
    """One pass over the log from ``start_s``; returns the messages published (until a shutdown)."""
    context = node.context
    count = 0
    origin_ns: int | None = None  # log time playback starts from
    wall_start = 0.0
    clock_ns = 0  # the last clock published
    started = False
    latched_before: dict[str, LoggedMessage] = {}
    try:
        for message in messages:
            if origin_ns is None:
                origin_ns = message.log_time_ns + round(start_s * 1e9)
            publisher = publishers.get(message.topic)
            if publisher is None:
                continue
            if message.log_time_ns < origin_ns:
                if message.qos.latched:
                    latched_before[message.topic] = message
                continue
            if not context.ok():
                break
            if not started:
                started = True
                wall_start = time.monotonic()
                publish_clock_at(origin_ns)
                clock_ns = origin_ns
                for earlier in latched_before.values():
                    _publish(publishers[earlier.topic], earlier.cdr, context)
                    count += 1
            if rate > 0.0:
                clock_ns = _wait_until(message.log_time_ns, origin_ns, wall_start, rate, publish_clock_at, clock_ns)
            if message.log_time_ns > clock_ns:
                publish_clock_at(message.log_time_ns)
                clock_ns = message.log_time_ns
            _publish(publisher, message.cdr, context)
            count += 1
            progress.tick(count, (message.log_time_ns - origin_ns) * 1e-9)
    except _ContextShutDownError:
        pass
    return count


class _Progress:
    """Calls back with (messages so far, log seconds played) at most every ``interval_s`` of wall time."""

    def __init__(self, callback: Callable[[int, float], None] | None, interval_s: float, before: int) -> None:
        self._callback, self._interval_s, self._before = callback, interval_s, before
        self._last = time.monotonic()

    def tick(self, count: int, log_s: float) -> None:
        if self._callback is not None and time.monotonic() - self._last >= self._interval_s:
            self._last = time.monotonic()
            self._callback(self._before + count, log_s)


def _wait_until(
    log_ns: int, origin_ns: int, wall_start: float, rate: float, publish_clock_at: Callable[[int], None], clock_ns: int
) -> int:
    """Sleep until ``log_ns`` is due, publishing the clock every 25 ms meanwhile; return the last clock sent."""
    due = wall_start + (log_ns - origin_ns) * 1e-9 / rate
    while True:
        remaining = due - time.monotonic()
        if remaining <= 0.0:
            return clock_ns
        time.sleep(min(remaining, _CLOCK_PERIOD_S))
        now_ns = origin_ns + round((time.monotonic() - wall_start) * rate * 1e9)
        if log_ns > now_ns > clock_ns:
            publish_clock_at(now_ns)
            clock_ns = now_ns


def run_replay(options: argparse.Namespace, ros_args: Sequence[str] = (), prog: str = "helireach replay") -> int:
    """Run a replay from parsed :func:`add_playback_arguments` options; returns the exit code.

    0 played, 1 unreadable log (or truncated without ``--recover``), 2 bad request (unknown topics), 130 Ctrl-C.
    """
    try:
        check_playback(options.log, options.rate, options.topics, options.start, options.recover)
    except McapLogError as exc:
        hint = "" if options.recover else " (--recover plays its complete chunks; 'helireach log recover' fixes it)"
        print(f"{prog}: {exc}{hint if 'truncated' in str(exc) else ''}", file=sys.stderr)
        return 1
    except ValueError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    if options.recover:
        from helireach_ros.core.mcap_log import is_finished_log

        if not is_finished_log(options.log):
            print(
                f"{prog}: WARNING: {options.log} was never closed (recorder killed?); playing its complete chunks "
                "only ('helireach log recover' writes a finished copy)",
                file=sys.stderr,
            )

    import rclpy
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=[prog, *ros_args])
    try:
        count = replay_log(
            options.log,
            rate=options.rate,
            topics=options.topics,
            start_s=options.start,
            loops=0 if options.loop else 1,
            allow_truncated=options.recover,
            discovery_wait_s=options.discovery_wait,
            on_progress=partial(_print_progress, options.log),
        )
        if not rclpy.ok():  # a Ctrl-C or SIGTERM shut the context down (the way a --loop ends)
            print(f"interrupted: replayed {count} messages from {options.log}")
            return 130
        print(f"replayed {count} messages from {options.log}")
        return 0
    except McapLogError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        print(f"interrupted while replaying {options.log}")
        return 130
    finally:
        rclpy.try_shutdown()


def main(argv: Sequence[str] | None = None) -> int:
    """``helireach_replay LOG.mcap [playback options] [--ros-args ...]``; returns the exit code."""
    from rclpy.utilities import remove_ros_args

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="helireach_replay", description="Replay a helireach MCAP log.")
    add_playback_arguments(parser)
    options = parser.parse_args(remove_ros_args(["helireach_replay", *argv])[1:])
    return run_replay(options, argv, prog="helireach_replay")


if __name__ == "__main__":
    sys.exit(main())
