"""Recovering a log that was never closed (recorder killed, power cut) into a finished, indexed file.

A killed recorder leaves header, helireach metadata and every completed chunk (with its message
index) but no summary, footer or ``rosbag2`` metadata record, so mcap's seeking reader, ``ros2 bag``
and ``rosbags`` refuse it. :func:`recover_log` scans the file from the start, keeps the channels,
schemas, metadata and every message of every complete record, and writes them with
:class:`~helireach_ros.core.mcap_log.writer.McapLogWriter` into a new file: log-time order, one
``helireach`` record (the last one written wins, as for the readers), exactly one ``rosbag2`` record,
summary and index.

A *finished* file with damaged records (a flipped bit, bytes overwritten: the chunk's CRC no longer matches) is
salvaged the same way, record by record: every intact record is kept, and each damaged one is reported with what it
held as far as it can be known (a chunk's time span from its header, its topics from the summary's chunk index). An
intact finished file has nothing to recover. :func:`log_damage` lists the damage without writing anything, so a
reader can refuse to play part of a log silently.

What is lost: the incomplete record at the end of the file (usually nothing, because a chunk reaches
the file in one write; a truncated copy can end inside one, whose time span is reported when its header
survived) and what the writer still held in memory, the open chunk: at most ``max_chunk_age`` plus the
recorder's check period of messages (docs/guides/failure-handling.md, "Logs"). The report cannot count those (they never
reached the disk); it gives the recovered span so the caller can compare it with the kill time.
"""

from __future__ import annotations

import io
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.exceptions import EndOfFile
from mcap.records import Channel, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from helireach_ros.core.mcap_log.reader import _has_footer, _open_log, _open_summary
from helireach_ros.core.mcap_log.records import MCAP_MAGIC, ROSBAG2_METADATA_NAME, McapLogError, QosDescription
from helireach_ros.core.mcap_log.writer import McapLogWriter

__all__ = ["RecoveryReport", "default_recovered_path", "is_finished_log", "log_damage", "recover_log"]

_CHUNK_OPCODE = 0x06
_DATA_END_OPCODE = 0x0F
_RECORD_PREFIX = struct.Struct("<BQ")  # opcode, record length
_CHUNK_TIMES = struct.Struct("<QQ")  # message_start_time, message_end_time (the chunk record's first fields)
_HELIREACH = "helireach"


@dataclass(frozen=True)
class RecoveryReport:
    """What :func:`recover_log` kept and dropped.

    Attributes:
        source: The damaged file.
        output: The finished file written.
        messages: Messages recovered.
        topics: Channels recovered (topic names, sorted).
        start_ns, end_ns: Log time of the first and last recovered message (ns since the epoch; 0 without any).
        dropped_bytes: Bytes of the incomplete record at the end of the file (0 if the file ends on a record).
        dropped_span_ns: ``(start, end)`` log times of an incomplete chunk whose header survived, else None.
        skipped_channels: Channels dropped because their schema is missing (topic names).
        damaged: One line per damaged record skipped inside the file (what it held, as far as it can be known).
    """

    source: Path
    output: Path
    messages: int
    topics: tuple[str, ...]
    start_ns: int
    end_ns: int
    dropped_bytes: int
    dropped_span_ns: tuple[int, int] | None
    skipped_channels: tuple[str, ...] = ()
    damaged: tuple[str, ...] = ()

    @property
    def duration_s(self) -> float:
        """Recovered time span, s."""
        return (self.end_ns - self.start_ns) * 1e-9

    def describe(self) -> str:
        """A few human-readable lines: what was recovered, what was lost."""
        lines = [
            f"recovered {self.messages} messages on {len(self.topics)} topics, {self.duration_s:.3f} s of log time "
            f"(last message at {self.end_ns * 1e-9:.3f} s since the epoch) into {self.output}"
        ]
        lines += [f"lost: {damage}" for damage in self.damaged]
        if self.dropped_bytes:
            span = ""
            if self.dropped_span_ns is not None:
                start, end = self.dropped_span_ns
                span = f", messages from {start * 1e-9:.3f} to {end * 1e-9:.3f} s since the epoch"
            lines.append(f"lost: an incomplete record of {self.dropped_bytes} bytes at the end of the file{span}")
        if not self.damaged:
            lines.append("lost: whatever the recorder had not yet written to disk (its open chunk; at most ~1 s)")
        if self.skipped_channels:
            lines.append(f"skipped (no schema): {', '.join(self.skipped_channels)}")
        return "\n".join(lines)


def default_recovered_path(path: str | os.PathLike[str]) -> Path:
    """``run.mcap`` → ``run.recovered.mcap`` beside it."""
    source = Path(path)
    return source.with_name(f"{source.stem}.recovered{source.suffix or '.mcap'}")


def is_finished_log(path: str | os.PathLike[str]) -> bool:
    """Whether the file ends with an MCAP footer (it was closed); raises McapLogError if it is not MCAP."""
    with _open_log(Path(path)) as stream:
        return _has_footer(stream)


def log_damage(path: str | os.PathLike[str]) -> list[str]:
    """The damaged records inside a log (one line each, naming what they held); empty for an intact file. The
    incomplete last record of a file that was never closed is not damage (:func:`recover_log` reports it)."""
    source = Path(path)
    with _open_log(source) as stream:
        return [damage for damage, _ in _salvage(source, stream) if damage]


def _top_level_records(stream: BinaryIO) -> Iterator[tuple[int, int, bytes]]:
    """(offset, opcode, the record's bytes) of each complete top-level record of the data section."""
    stream.seek(0, os.SEEK_END)
    size = stream.tell()
    offset = len(MCAP_MAGIC)
    while offset + _RECORD_PREFIX.size <= size:
        stream.seek(offset)
        opcode, length = _RECORD_PREFIX.unpack(stream.read(_RECORD_PREFIX.size))
        end = offset + _RECORD_PREFIX.size + length
        if end > size:
            return  # the incomplete tail (_incomplete_tail reports it)
        stream.seek(offset)
        yield offset, opcode, stream.read(end - offset)
        if opcode == _DATA_END_OPCODE:
            return  # the summary follows: copies of what the data section held
        offset = end


def _salvage(path: Path, stream: BinaryIO) -> Iterator[tuple[str, list[Any]]]:
    """Per top-level record: ('' and its records) when intact, (what was lost, []) when damaged."""
    topics_by_chunk = _chunk_topics(path, stream)
    for offset, opcode, data in _top_level_records(stream):
        try:
            records = list(_records_of(data))
        except Exception as exc:  # the mcap library raises several types on damaged input
            yield _describe_damage(offset, opcode, data, topics_by_chunk.get(offset), exc), []
            continue
        yield "", records


def _records_of(data: bytes) -> Iterator[Any]:
    """The records of one top-level record (a chunk's messages and index records, or the record itself); raises on
    damage (a chunk's CRC, a record cut short)."""
    buffer = io.BytesIO(data)
    records = StreamReader(buffer, skip_magic=True, validate_crcs=True).records
    while True:
        try:
            record = next(records)
        except StopIteration:
            return
        except EndOfFile:
            if buffer.tell() == len(data):
                return  # the record was read whole; the buffer just ends (no footer follows)
            raise
        yield record
        if isinstance(record, DataEnd):
            return


def _describe_damage(offset: int, opcode: int, data: bytes, topics: list[str] | None, error: Exception) -> str:
    what = f"a damaged record at byte {offset} ({error.__class__.__name__}: {error})"
    if opcode != _CHUNK_OPCODE:
        return what
    span = ""
    if len(data) >= _RECORD_PREFIX.size + _CHUNK_TIMES.size:
        start, end = _CHUNK_TIMES.unpack_from(data, _RECORD_PREFIX.size)
        span = f", messages from {start * 1e-9:.3f} to {end * 1e-9:.3f} s since the epoch"
    held = f" on {', '.join(topics)}" if topics else ""
    return f"a damaged chunk at byte {offset}{span}{held} ({error.__class__.__name__}: {error})"


def _chunk_topics(path: Path, stream: BinaryIO) -> dict[int, list[str]]:
    """Topics per chunk offset from a finished file's summary (its chunk indexes); empty when there is none."""
    try:
        reader = _open_summary(path, stream, allow_truncated=True)
        summary = reader.get_summary() if reader is not None else None
    except Exception:  # a damaged summary: the damage is then reported without topics
        return {}
    if summary is None:
        return {}
    return {
        index.chunk_start_offset: sorted(
            summary.channels[channel_id].topic
            for channel_id in index.message_index_offsets
            if channel_id in summary.channels
        )
        for index in summary.chunk_indexes
    }


def _incomplete_tail(stream: BinaryIO) -> tuple[int, tuple[int, int] | None]:
    """Walk the top-level records; return (bytes of the incomplete last record, its chunk time span if readable)."""
    stream.seek(0, os.SEEK_END)
    size = stream.tell()
    offset = len(MCAP_MAGIC)
    while offset < size:
        stream.seek(offset)
        prefix = stream.read(_RECORD_PREFIX.size)
        if len(prefix) < _RECORD_PREFIX.size:
            return size - offset, None
        opcode, length = _RECORD_PREFIX.unpack(prefix)
        end = offset + _RECORD_PREFIX.size + length
        if end > size:
            times = stream.read(_CHUNK_TIMES.size)
            span = _CHUNK_TIMES.unpack(times) if opcode == _CHUNK_OPCODE and len(times) == _CHUNK_TIMES.size else None
            return size - offset, span
        offset = end
    return 0, None


def recover_log(
    path: str | os.PathLike[str], output: str | os.PathLike[str] | None = None, *, overwrite: bool = False
) -> RecoveryReport:
    """Rewrite a log that was never closed, or a finished one with damaged records, into a finished, indexed file.

    Args:
        path: The killed recorder's ``.mcap``, or a damaged finished one.
        output: Where to write (default :func:`default_recovered_path`); must differ from ``path``.
        overwrite: Replace an existing ``output``.

    Returns:
        The :class:`RecoveryReport`.

    Raises:
        McapLogError: ``path`` is missing, not MCAP, finished and intact (nothing to recover), or holds no channel;
            ``output`` is ``path`` or exists (without ``overwrite``), or cannot be written.
    """
    source = Path(path)
    target = Path(output) if output is not None else default_recovered_path(source)
    with _open_log(source) as stream:
        salvaged = list(_salvage(source, stream))
        damaged = tuple(damage for damage, _ in salvaged if damage)
        if _has_footer(stream) and not damaged:
            raise McapLogError("log is finished (it has a footer) and intact; nothing to recover", source)
        if target.resolve() == source.resolve():
            raise McapLogError("recovery must write a new file, not the one it reads", target)
        if target.exists() and not overwrite:
            raise McapLogError("output exists (pass overwrite=True / --force to replace it)", target)
        dropped_bytes, dropped_span = (0, None) if _has_footer(stream) else _incomplete_tail(stream)
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        metadata: dict[str, dict[str, str]] = {}
        messages: list[Message] = []
        for record in (record for _, records in salvaged for record in records):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Metadata):
                metadata[record.name] = dict(record.metadata)  # a later record wins, as for read_log_metadata
            elif isinstance(record, Message):
                messages.append(record)
    if not channels:
        raise McapLogError("no channel survived: nothing to recover", source)
    messages.sort(key=lambda m: m.log_time)  # chunks are in write order; sort() is stable
    skipped = sorted(c.topic for c in channels.values() if c.schema_id not in schemas)
    kept = {cid: c for cid, c in channels.items() if c.schema_id in schemas}
    count = 0
    with McapLogWriter(target, metadata=metadata.get(_HELIREACH), max_chunk_age=None) as writer:
        for name, values in metadata.items():
            if name not in (_HELIREACH, ROSBAG2_METADATA_NAME):  # the writer writes both itself
                writer.add_metadata(name, values)
        for channel in kept.values():
            schema = schemas[channel.schema_id]
            try:
                qos = QosDescription.from_rosbag2_yaml(channel.metadata.get("offered_qos_profiles", ""))
            except ValueError as exc:
                raise McapLogError(f"channel {channel.topic}: {exc}", source) from exc
            writer.add_topic(
                channel.topic,
                schema.name,
                qos,
                definition=(schema.encoding, bytes(schema.data)),
                type_hash=channel.metadata.get("topic_type_hash", ""),
            )
        for message in messages:
            kept_channel = kept.get(message.channel_id)
            if kept_channel is not None:
                writer.write(kept_channel.topic, message.data, message.log_time, message.publish_time)
                count += 1
    recovered = [m for m in messages if m.channel_id in kept]
    return RecoveryReport(
        source=source,
        output=target,
        messages=count,
        topics=tuple(sorted(c.topic for c in kept.values())),
        start_ns=recovered[0].log_time if recovered else 0,
        end_ns=recovered[-1].log_time if recovered else 0,
        dropped_bytes=dropped_bytes,
        dropped_span_ns=dropped_span,
        skipped_channels=tuple(skipped),
        damaged=damaged,
    )
