"""Reading helireach MCAP logs: messages, topics and metadata, from finished files through the summary
index and from files a killed recorder left (no summary or footer) by scanning their completed chunks
(``allow_truncated=True``).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

from mcap.reader import SeekingReader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from helireach_ros.core.mcap_log.records import (
    MCAP_MAGIC,
    LoggedMessage,
    LoggedTopic,
    McapLogError,
    QosDescription,
)

__all__ = ["LogOverview", "read_log", "read_log_metadata", "read_log_overview", "read_log_topics"]


def _has_footer(stream: BinaryIO) -> bool:
    """Whether the file ends like a finished MCAP file (footer + closing magic)."""
    stream.seek(0, os.SEEK_END)
    if stream.tell() < 2 * len(MCAP_MAGIC):
        return False
    stream.seek(-len(MCAP_MAGIC), os.SEEK_END)
    return stream.read(len(MCAP_MAGIC)) == MCAP_MAGIC


def _open_log(path: Path) -> BinaryIO:
    try:
        stream = open(path, "rb")  # the caller closes it
    except OSError as exc:
        raise McapLogError(f"cannot open log: {exc.strerror}", path) from exc
    if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        stream.close()
        raise McapLogError("not an MCAP file (bad magic)", path)
    return stream


def _open_summary(path: Path, stream: BinaryIO, allow_truncated: bool) -> SeekingReader | None:
    """Return a seeking reader if the file is finished, None if it must be scanned sequentially."""
    try:
        if _has_footer(stream):
            stream.seek(0)
            reader = SeekingReader(stream, validate_crcs=True)
            # A finished file may legitimately have no summary section: scan it then.
            return reader if reader.get_summary() is not None else None
        problem = "no MCAP footer/summary (the recording was not closed)"
    except Exception as exc:  # the mcap library raises several types on damaged input
        problem = f"unreadable MCAP footer/summary ({exc.__class__.__name__}: {exc})"
    if not allow_truncated:
        raise McapLogError(
            f"log is truncated or corrupt: {problem}; read_log(..., allow_truncated=True) "
            "recovers the completed chunks",
            path,
        )
    return None


def _scan_records(path: Path, stream: BinaryIO, allow_truncated: bool) -> Iterator[Any]:
    """Yield records in file order; stop at (or raise on) the first incomplete or damaged one."""
    stream.seek(0)
    records = StreamReader(stream, skip_magic=False, validate_crcs=True).records
    while True:
        try:
            record = next(records)
        except StopIteration:
            return
        except Exception as exc:  # a killed writer leaves a partial record at the end
            if allow_truncated:
                return
            raise McapLogError(f"corrupt MCAP data ({exc.__class__.__name__}: {exc})", path) from exc
        yield record


class _ChannelInfo(NamedTuple):
    topic: str
    type_name: str
    qos: QosDescription


def _channel_info(path: Path, channel: Channel, schema: Schema | None) -> _ChannelInfo:
    try:
        qos = QosDescription.from_rosbag2_yaml(channel.metadata.get("offered_qos_profiles", ""))
    except ValueError as exc:
        raise McapLogError(f"channel {channel.topic}: {exc}", path) from exc
    return _ChannelInfo(channel.topic, schema.name if schema is not None else "", qos)


def read_log(path: str | os.PathLike[str], *, allow_truncated: bool = False) -> Iterator[LoggedMessage]:
    """Read every message of a log in log-time order.

    The file is checked when this is called (not only on first iteration).

    Args:
        path: The ``.mcap`` file.
        allow_truncated: Read a file that was never closed (e.g. the recorder was killed) by
            scanning it from the start: every completed chunk is returned, the incomplete tail is
            dropped. Damage inside a finished file raises either way (it is not a file that was never closed:
            :func:`~helireach_ros.core.mcap_log.recover.recover_log` salvages its intact records and says what
            was lost).

    Returns:
        An iterator of :class:`LoggedMessage`.

    Raises:
        McapLogError: The file is missing, not MCAP, truncated or corrupt (naming the file).
    """
    log_path = Path(path)
    stream = _open_log(log_path)
    try:
        reader = _open_summary(log_path, stream, allow_truncated)
    except BaseException:
        stream.close()
        raise
    if reader is None:
        return _iter_scanned(log_path, stream, allow_truncated)
    return _iter_indexed(log_path, stream, reader, allow_truncated)


def _iter_indexed(
    path: Path, stream: BinaryIO, reader: SeekingReader, allow_truncated: bool
) -> Iterator[LoggedMessage]:
    channels: dict[int, _ChannelInfo] = {}
    with stream:
        messages = reader.iter_messages(log_time_order=True)
        while True:
            try:
                item = next(messages)
            except StopIteration:
                return
            except Exception as exc:  # a finished file: damage, never a tail cut by a kill
                raise McapLogError(
                    f"damaged MCAP data ({exc.__class__.__name__}: {exc}); 'helireach log recover' salvages the "
                    "intact records and lists what was lost",
                    path,
                ) from exc
            schema, channel, message = item
            info = channels.get(channel.id)
            if info is None:
                info = channels[channel.id] = _channel_info(path, channel, schema)
            yield _logged(info, message)


def _iter_scanned(path: Path, stream: BinaryIO, allow_truncated: bool) -> Iterator[LoggedMessage]:
    schemas: dict[int, Schema] = {}
    channels: dict[int, _ChannelInfo] = {}
    collected: list[LoggedMessage] = []
    with stream:
        for record in _scan_records(path, stream, allow_truncated):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = _channel_info(path, record, schemas.get(record.schema_id))
            elif isinstance(record, Message) and record.channel_id in channels:
                collected.append(_logged(channels[record.channel_id], record))
    # Chunks are in write order, not necessarily log-time order; sort() is stable.
    collected.sort(key=lambda m: m.log_time_ns)
    yield from collected


def _logged(info: _ChannelInfo, message: Message) -> LoggedMessage:
    return LoggedMessage(
        info.topic, info.type_name, bytes(message.data), message.log_time, message.publish_time, info.qos
    )


def read_log_metadata(path: str | os.PathLike[str], *, allow_truncated: bool = False) -> dict[str, dict[str, str]]:
    """Return the MCAP metadata records of a log by name (a later record wins).

    Besides the ``helireach`` record this includes rosbag2's ``rosbag2`` record.

    Args:
        path: The ``.mcap`` file.
        allow_truncated: As for :func:`read_log`.

    Raises:
        McapLogError: The file is missing, not MCAP, truncated or corrupt.
    """
    log_path = Path(path)
    result: dict[str, dict[str, str]] = {}
    with _open_log(log_path) as stream:
        reader = _open_summary(log_path, stream, allow_truncated)
        if reader is not None:
            try:
                records: list[Metadata] = list(reader.iter_metadata())
            except Exception as exc:
                problem = f"corrupt MCAP metadata ({exc.__class__.__name__}: {exc})"
                raise McapLogError(problem, log_path) from exc
        else:
            records = [r for r in _scan_records(log_path, stream, allow_truncated) if isinstance(r, Metadata)]
    for record in records:
        result[record.name] = dict(record.metadata)
    return result


def read_log_topics(path: str | os.PathLike[str], *, allow_truncated: bool = False) -> dict[str, LoggedTopic]:
    """Return the topics of a log (type, offered QoS, message count) without reading the messages.

    Args:
        path: The ``.mcap`` file.
        allow_truncated: As for :func:`read_log` (a truncated file is scanned, so this reads it all).

    Raises:
        McapLogError: The file is missing, not MCAP, truncated or corrupt.
    """
    return _read_overview(Path(path), allow_truncated).topics


class LogOverview(NamedTuple):
    """What a log holds, without its messages.

    Attributes:
        topics: per topic: type, offered QoS, message count.
        span_ns: log times of the first and last message, ns (None for a log without messages).
    """

    topics: dict[str, LoggedTopic]
    span_ns: tuple[int, int] | None


def read_log_overview(path: str | os.PathLike[str], *, allow_truncated: bool = False) -> LogOverview:
    """The topics and the message time span of a log; args and raises as :func:`read_log_topics`."""
    return _read_overview(Path(path), allow_truncated)


def _read_overview(log_path: Path, allow_truncated: bool) -> LogOverview:
    """The topics and the message time span, from the summary or (a truncated file) by scanning the records."""
    with _open_log(log_path) as stream:
        reader = _open_summary(log_path, stream, allow_truncated)
        span: tuple[int, int] | None = None
        if reader is not None:
            summary = reader.get_summary()
            assert summary is not None  # _open_summary returns a reader only when there is one
            statistics = summary.statistics
            counts = statistics.channel_message_counts if statistics else {}
            if statistics and statistics.message_count:
                span = (statistics.message_start_time, statistics.message_end_time)
            schemas = summary.schemas
            channels = summary.channels.values()
        else:
            schemas, channel_list, counts = {}, [], {}
            for record in _scan_records(log_path, stream, allow_truncated):
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channel_list.append(record)
                elif isinstance(record, Message):
                    counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                    first, last = span or (record.log_time, record.log_time)
                    span = (min(first, record.log_time), max(last, record.log_time))
            channels = channel_list  # type: ignore[assignment]  # iterated only: values or list alike
        topics: dict[str, LoggedTopic] = {}
        for channel in channels:
            info = _channel_info(log_path, channel, schemas.get(channel.schema_id))
            topics[info.topic] = LoggedTopic(info.type_name, info.qos, counts.get(channel.id, 0))
    return LogOverview(topics, span)
