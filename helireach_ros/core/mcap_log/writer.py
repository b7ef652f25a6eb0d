"""MCAP flight logs in the layout ``ros2 bag record`` (rosbag2, Jazzy) writes — without ROS.

The file is a plain MCAP file with header profile ``ros2``. Each topic gets a schema named
``pkg/msg/Type`` (encoding ``ros2msg``: the root ``.msg`` text followed by every dependency, each
once, after an 80-character ``=`` line and ``MSG: pkg/Type``) and a channel (message encoding
``cdr``, metadata ``offered_qos_profiles`` and ``topic_type_hash``). Messages are the rmw CDR bytes
as received, cut at the end of their content: the ROS 2 serializer leaves uninitialised bytes after a message with
empty sequences, which ``rosbags`` refuses (:mod:`~helireach_ros.core.mcap_log.cdr_extent`). Like rosbag2 the
writer also stores a ``rosbag2`` metadata record holding the
bag metadata (version 9): without it ``ros2 bag play`` parses ``offered_qos_profiles`` with the
pre-Jazzy integer enums and rejects the file. As ``rosbag2_storage_mcap`` does (its
``update_metadata`` runs once, when the bag is closed), that record is written exactly once, at
:meth:`McapLogWriter.close`, with the final duration and counts. A file that was never closed is still
identifiable: its header says profile ``ros2`` and the ``helireach`` record (airframe, envelope,
version...) is written at open; :func:`~helireach_ros.core.mcap_log.recover.recover_log` adds the
``rosbag2`` record when it rewrites such a file.

Crash safety: data is chunked, and everything the MCAP writer emits (a completed chunk and its
message index) is handed to the operating system immediately. A chunk is completed when it reaches
``chunk_size`` bytes or, at the next write or :meth:`McapLogWriter.flush_stale` call, once its oldest
message has waited ``max_chunk_age`` seconds (monotonic time), so a SIGKILL loses only the messages of
the open chunk: those received during the last ``max_chunk_age`` plus the caller's
:meth:`~McapLogWriter.flush_stale` period (the recorder: 0.5 s + 0.25 s, under the 1 s bound).
A recorder killed with SIGKILL leaves a file without summary/footer whose completed chunks
:func:`read_log` recovers with ``allow_truncated=True`` and ``recover_log`` rewrites into a finished,
indexed file. ``mcap.reader.make_reader(...).iter_messages()`` raises ``McapError`` on the killed
file (its seeking reader starts from the footer); ``mcap.reader.NonSeekingReader`` reads it up to the
incomplete tail.

This module must not import rclpy: it is used by offline tools and tests.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

import yaml
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

from helireach_ros.core.mcap_log.cdr_extent import CdrLayout, CdrLayoutError, cdr_extent, parse_ros2msg_layout
from helireach_ros.core.mcap_log.records import (
    INT64_MAX,
    ROSBAG2_METADATA_NAME,
    ROSBAG2_METADATA_VERSION,
    McapLogError,
    QosDescription,
)
from helireach_ros.core.mcap_log.schemas import message_definition, type_description_hash

__all__ = ["McapLogWriter"]

_COMPRESSION = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD}


@dataclass
class _Topic:
    channel_id: int
    type_name: str
    qos: QosDescription
    type_hash: str
    layout: CdrLayout | None  # None: a schema this package cannot lay out; its messages are kept whole
    message_count: int = 0


def _layout(type_name: str, definition: tuple[str, bytes]) -> CdrLayout | None:
    """The CDR layout of a ``ros2msg`` schema; None for other encodings or a schema it cannot read."""
    encoding, text = definition
    if encoding != "ros2msg":
        return None
    try:
        return parse_ros2msg_layout(type_name, text.decode("utf-8"))
    except (CdrLayoutError, UnicodeDecodeError):
        return None


def _content(layout: CdrLayout | None, cdr: bytes) -> bytes:
    """``cdr`` up to the end of its content, padded to 4 bytes as a DDS payload is; whole when it cannot be laid out
    (a malformed message is kept as it came, for whoever reads the log to judge)."""
    if layout is None:
        return cdr
    try:
        extent = cdr_extent(layout, cdr)
    except CdrLayoutError:
        return cdr
    return cdr[: -(-extent // 4) * 4]  # the 4-byte padding of a DDS payload is standard; readers accept it


class McapLogWriter:
    """Write a rosbag2-compatible MCAP log; thread-safe, crash-tolerant.

    Use as a context manager; :meth:`close` (also run by ``__exit__``, even on error) writes the
    summary and index. Until then, every completed chunk is already in the operating system's hands.

    Args:
        path: File to create (overwritten if it exists).
        metadata: Key/value pairs stored as a ``helireach`` metadata record and as rosbag2's
            ``custom_data``.
        chunk_size: Uncompressed bytes after which a chunk is completed and written out.
        max_chunk_age: Seconds (monotonic) after which the open chunk is completed at the next
            :meth:`write` or :meth:`flush_stale`, which bounds what a hard kill loses; ``None`` = size only.
        compression: Chunk compression: ``"none"`` (rosbag2's default), ``"lz4"`` or ``"zstd"``
            (both ship as dependencies of the ``mcap`` wheel).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        metadata: Mapping[str, str] | None = None,
        chunk_size: int = 64 * 1024,
        compression: str = "none",
        max_chunk_age: float | None = 0.5,
    ) -> None:
        if compression not in _COMPRESSION:
            raise ValueError(f"compression must be one of {sorted(_COMPRESSION)}, not {compression!r}")
        if chunk_size < 1:
            raise ValueError(f"chunk_size must be positive, not {chunk_size}")
        if max_chunk_age is not None and not (max_chunk_age > 0.0 and max_chunk_age < float("inf")):
            raise ValueError(f"max_chunk_age must be a positive number of seconds or None, not {max_chunk_age!r}")
        if max_chunk_age is not None and not hasattr(Writer, "flush"):
            raise ValueError("max_chunk_age needs mcap >= 1.3 (Writer.flush); this mcap cannot bound the loss")
        self._max_chunk_age = max_chunk_age
        self._chunk_opened_at: float | None = None  # monotonic time of the open chunk's first message
        self._path = Path(path)
        self._lock = threading.Lock()
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
        self._layouts: dict[str, CdrLayout | None] = {}
        self._custom = {str(k): str(v) for k, v in (metadata or {}).items()}
        self._start_ns: int | None = None
        self._end_ns = 0
        self._message_count = 0
        self._closed = False
        try:
            self._file: BinaryIO = open(self._path, "wb")  # closed in close()
        except OSError as exc:
            raise McapLogError(f"cannot create log: {exc.strerror}", path) from exc
        try:
            self._writer = Writer(self._file, chunk_size=chunk_size, compression=_COMPRESSION[compression])
            self._writer.start(profile="ros2", library=f"helireach_ros.core.mcap_log; {LIBRARY_IDENTIFIER}")
            # The rosbag2 record waits for close() (exactly one, with the final counts); the helireach
            # record goes first so that a killed recording still identifies itself.
            if self._custom:
                self._writer.add_metadata("helireach", dict(self._custom))
            self._sync()
        except BaseException:
            self._file.close()
            raise

    @property
    def path(self) -> Path:
        """The file being written."""
        return self._path

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._message_count

    def __enter__(self) -> McapLogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def metadata(self) -> dict[str, str]:
        """The current ``helireach`` metadata (a copy)."""
        with self._lock:
            return dict(self._custom)

    def add_topic(
        self,
        topic: str,
        type_name: str,
        qos: QosDescription,
        definition: tuple[str, bytes] | None = None,
        type_hash: str | None = None,
    ) -> int:
        """Register a topic (schema + channel); idempotent for the same type.

        Args:
            topic: Fully qualified topic name.
            type_name: ``pkg/msg/Type``.
            qos: The QoS the publisher offers (stored as ``offered_qos_profiles``).
            definition: ``(schema encoding, schema data)`` to store instead of the installed definition
                (recovery copies a log's own schemas).
            type_hash: ``RIHS01_...`` to store instead of the installed type's hash.

        Returns:
            The MCAP channel id.

        Raises:
            McapLogError: The writer is closed, the topic exists with another type, or the message
                definition cannot be found.
        """
        with self._lock:
            self._check_open()
            existing = self._topics.get(topic)
            if existing is not None:
                if existing.type_name != type_name:
                    raise McapLogError(
                        f"topic {topic} already logged as {existing.type_name}, not {type_name}", self._path
                    )
                return existing.channel_id
            schema_id = self._schemas.get(type_name)
            if schema_id is None:
                if definition is None:
                    encoding, text = message_definition(type_name)
                    definition = (encoding, text.encode("utf-8"))
                schema_id = self._writer.register_schema(type_name, definition[0], definition[1])
                self._schemas[type_name] = schema_id
                self._layouts[type_name] = _layout(type_name, definition)
            if type_hash is None:
                type_hash = type_description_hash(type_name)
            channel_id = self._writer.register_channel(
                topic,
                "cdr",
                schema_id,
                {"offered_qos_profiles": qos.to_rosbag2_yaml(), "topic_type_hash": type_hash},
            )
            self._topics[topic] = _Topic(channel_id, type_name, qos, type_hash, self._layouts[type_name])
            self._sync()
            return channel_id

    def write(self, topic: str, cdr: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Append one serialized message.

        Args:
            topic: A topic registered with :meth:`add_topic`.
            cdr: The CDR bytes (e.g. from a ``raw=True`` subscription).
            log_time_ns: Receive time, ns since the epoch.
            publish_time_ns: Publish time; defaults to ``log_time_ns``.

        Raises:
            McapLogError: The writer is closed or the topic is unknown.
        """
        publish = log_time_ns if publish_time_ns is None else publish_time_ns
        with self._lock:
            self._check_open()
            entry = self._topics.get(topic)
            if entry is None:
                raise McapLogError(f"topic {topic} was not added with add_topic()", self._path)
            position = self._file.tell()
            self._writer.add_message(entry.channel_id, log_time_ns, _content(entry.layout, bytes(cdr)), publish)
            entry.message_count += 1
            self._message_count += 1
            self._start_ns = log_time_ns if self._start_ns is None else min(self._start_ns, log_time_ns)
            self._end_ns = max(self._end_ns, log_time_ns)
            now = time.monotonic()
            if self._file.tell() != position:  # the size limit completed the chunk, this message included
                self._chunk_opened_at = None
            elif self._chunk_opened_at is None:
                self._chunk_opened_at = now
            elif self._chunk_is_stale(now):
                self._complete_chunk()
            # Nothing reaches the file object until a chunk completes; pass that on at once.
            self._sync()

    def flush_stale(self) -> bool:
        """Complete the open chunk if its oldest message has waited ``max_chunk_age``; call periodically.

        Returns:
            Whether a chunk was completed.
        """
        with self._lock:
            if self._closed or not self._chunk_is_stale(time.monotonic()):
                return False
            self._complete_chunk()
            self._sync()
            return True

    def update_metadata(self, data: Mapping[str, str]) -> bool:
        """Merge values into the ``helireach`` metadata; a change writes the whole record again.

        Readers take the last ``helireach`` record (each is complete), so a killed file holds what was
        known when it was killed; the ``rosbag2`` record's ``custom_data`` (at close) holds the final values.

        Returns:
            Whether anything changed.

        Raises:
            McapLogError: The writer is closed.
        """
        with self._lock:
            self._check_open()
            merged = {**self._custom, **{str(k): str(v) for k, v in data.items()}}
            if merged == self._custom:
                return False
            self._custom = merged
            self._writer.add_metadata("helireach", dict(merged))
            self._sync()
            return True

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write an MCAP metadata record (e.g. ``helireach``: airframe, envelope, version, scenario).

        Raises:
            McapLogError: The writer is closed.
        """
        with self._lock:
            self._check_open()
            self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
            self._sync()

    def flush(self) -> None:
        """Complete the chunk in progress and hand it to the OS (bounds loss on a hard kill).

        Small chunks compress worse; call this periodically (e.g. once a second), not per message.
        """
        with self._lock:
            if self._closed:
                return
            self._complete_chunk()
            self._sync()

    def close(self) -> None:
        """Write the final rosbag2 metadata, summary and index, and close the file; idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._write_rosbag2_metadata()
                self._writer.finish()
            finally:
                self._file.close()

    # Callers hold self._lock (or are the constructor).
    def _check_open(self) -> None:
        if self._closed:
            raise McapLogError("log is closed", self._path)

    def _sync(self) -> None:
        self._file.flush()

    def _chunk_is_stale(self, now: float) -> bool:
        opened = self._chunk_opened_at
        return self._max_chunk_age is not None and opened is not None and now - opened >= self._max_chunk_age

    def _complete_chunk(self) -> None:
        writer_flush = getattr(self._writer, "flush", None)  # mcap >= 1.3
        if writer_flush is not None:
            writer_flush()
        self._chunk_opened_at = None

    def _write_rosbag2_metadata(self) -> None:
        start = self._start_ns if self._start_ns is not None else INT64_MAX
        duration = 0 if self._start_ns is None else self._end_ns - self._start_ns
        name = self._path.name
        bag = {
            "version": ROSBAG2_METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self._message_count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": topic,
                        "type": entry.type_name,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": entry.qos.to_rosbag2_yaml(),
                        "type_description_hash": entry.type_hash,
                    },
                    "message_count": entry.message_count,
                }
                for topic, entry in self._topics.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [name],
            "files": [
                {
                    "path": name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": self._message_count,
                }
            ],
            "custom_data": dict(self._custom),
            "ros_distro": os.environ.get("ROS_DISTRO", "jazzy"),
        }
        serialized = yaml.safe_dump(bag, sort_keys=False, default_flow_style=False)
        self._writer.add_metadata(ROSBAG2_METADATA_NAME, {"serialized_metadata": serialized})


# --- reader ----------------------------------------------------------------------------------------
