"""MCAP flight logs in the layout ``ros2 bag record`` (rosbag2, Jazzy) writes — without ROS.

The file is a plain MCAP file with header profile ``ros2``. Each topic gets a schema named
``pkg/msg/Type`` (encoding ``ros2msg``: the root ``.msg`` text followed by every dependency, each
once, after an 80-character ``=`` line and ``MSG: pkg/Type``) and a channel (message encoding
``cdr``, metadata ``offered_qos_profiles`` and ``topic_type_hash``). Messages are the rmw CDR bytes
exactly as received. Like rosbag2 the writer also stores a ``rosbag2`` metadata record holding the
bag metadata (version 9): without it ``ros2 bag play`` parses ``offered_qos_profiles`` with the
pre-Jazzy integer enums and rejects the file.

Crash safety: data is chunked, and everything the MCAP writer emits (a completed chunk and its
message index) is handed to the operating system immediately. A recorder killed with SIGKILL leaves
a file without summary/footer whose completed chunks :func:`read_log` recovers with
``allow_truncated=True``. ``mcap.reader.make_reader(...).iter_messages()`` raises ``McapError`` on
such a file (its seeking reader starts from the footer); ``mcap.reader.NonSeekingReader`` reads it
up to the incomplete tail.

This module must not import rclpy: it is used by offline tools and tests.
"""

from __future__ import annotations

import json
import os
import re
import sys
import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO, NamedTuple

import yaml
from mcap.reader import SeekingReader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

__all__ = [
    "LoggedMessage",
    "LoggedTopic",
    "McapLogError",
    "McapLogWriter",
    "QosDescription",
    "message_definition",
    "read_log",
    "read_log_metadata",
    "read_log_topics",
    "type_description_hash",
]

#: Metadata record name rosbag2 reads its bag metadata from (``rosbag2_storage_mcap``).
ROSBAG2_METADATA_NAME = "rosbag2"
#: rosbag2 bag metadata version written by Jazzy (9: QoS enums serialized as strings).
ROSBAG2_METADATA_VERSION = 9

_MCAP_MAGIC = b"\x89MCAP0\r\n"
# rmw's RMW_DURATION_INFINITE as rosbag2 serializes it ({sec, nsec}); Fast DDS reports it for the
# deadline, lifespan and liveliness lease of a default publisher.
_INFINITE_DURATION = {"sec": 9223372036, "nsec": 854775807}
_INT64_MAX = 2**63 - 1
_COMPRESSION = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD}
# rmw's policy enums: pre-Jazzy bags (metadata version <= 8) store the integer values.
_RMW_RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
_RMW_DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
_RMW_HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
_DEFAULT_DEPTH = 10  # rosbag2's default history depth when a profile does not carry one


class McapLogError(RuntimeError):
    """A log file cannot be written or read (truncated, corrupt, unknown type...).

    Attributes:
        path: The file concerned, when there is one.
    """

    def __init__(self, message: str, path: str | os.PathLike[str] | None = None) -> None:
        self.path = None if path is None else os.fspath(path)
        super().__init__(f"{self.path}: {message}" if self.path is not None else message)


@dataclass(frozen=True)
class QosDescription:
    """The QoS policies of a topic that matter for matching and latching.

    Attributes:
        reliability: ``"reliable"`` or ``"best_effort"``.
        durability: ``"volatile"`` or ``"transient_local"`` (latched).
        depth: KEEP_LAST history depth (> 0).
    """

    reliability: str = "reliable"
    durability: str = "volatile"
    depth: int = _DEFAULT_DEPTH

    def __post_init__(self) -> None:
        if self.reliability not in ("reliable", "best_effort"):
            raise ValueError(f"reliability must be 'reliable' or 'best_effort', not {self.reliability!r}")
        if self.durability not in ("volatile", "transient_local"):
            raise ValueError(f"durability must be 'volatile' or 'transient_local', not {self.durability!r}")
        if isinstance(self.depth, bool) or not isinstance(self.depth, int) or self.depth < 1:
            raise ValueError(f"depth must be a positive int, not {self.depth!r}")

    @property
    def latched(self) -> bool:
        """Whether late subscribers receive the last messages (TRANSIENT_LOCAL durability)."""
        return self.durability == "transient_local"

    def to_rosbag2_dict(self) -> dict[str, Any]:
        """Return one profile with the keys and value spellings of rosbag2_storage (Jazzy)."""
        return {
            "history": "keep_last",
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": dict(_INFINITE_DURATION),
            "lifespan": dict(_INFINITE_DURATION),
            "liveliness": "automatic",
            "liveliness_lease_duration": dict(_INFINITE_DURATION),
            "avoid_ros_namespace_conventions": False,
        }

    def to_rosbag2_yaml(self) -> str:
        """Return the ``offered_qos_profiles`` YAML list (one profile) as rosbag2 writes it."""
        # yaml-cpp's Dump (used by rosbag2) emits block style without a trailing newline.
        return yaml.safe_dump([self.to_rosbag2_dict()], sort_keys=False, default_flow_style=False).rstrip("\n")

    @classmethod
    def from_rosbag2_yaml(cls, text: str) -> QosDescription:
        """Parse an ``offered_qos_profiles`` value (YAML list) written by rosbag2 or this module.

        The first profile is used (rosbag2 lists one per publisher). Both the Jazzy string enums
        and the older integer enums are accepted. A profile without a usable KEEP_LAST depth (rmw
        does not report the history of a remote publisher) gets rosbag2's default depth of 10.

        Args:
            text: The YAML text; empty means "no profile" and gives the defaults.

        Returns:
            The description of the first profile.

        Raises:
            ValueError: The text is not a list of QoS profiles or names an unknown policy.
        """
        try:
            profiles = yaml.safe_load(text) if text.strip() else []
        except yaml.YAMLError as exc:
            raise ValueError(f"offered_qos_profiles is not valid YAML: {exc}") from exc
        if profiles is None:
            profiles = []
        if not isinstance(profiles, list) or not all(isinstance(p, dict) for p in profiles):
            raise ValueError(f"offered_qos_profiles must be a YAML list of mappings, got {text!r}")
        if not profiles:
            return cls()
        profile = profiles[0]
        history = _policy(profile.get("history", "keep_last"), _RMW_HISTORY)
        depth = profile.get("depth", 0)
        if history != "keep_last" or not isinstance(depth, int) or depth < 1:
            depth = _DEFAULT_DEPTH
        # Collapse rmw's other values onto the two that matter: system default and unknown are
        # RELIABLE/VOLATILE in every Tier-1 rmw; "best available" turns into the stronger policy.
        reliability = _policy(profile.get("reliability", "reliable"), _RMW_RELIABILITY)
        durability = _policy(profile.get("durability", "volatile"), _RMW_DURABILITY)
        return cls(
            reliability="best_effort" if reliability == "best_effort" else "reliable",
            durability="transient_local" if durability in ("transient_local", "best_available") else "volatile",
            depth=depth,
        )


def _policy(value: object, names: Mapping[int, str]) -> str:
    if isinstance(value, int) and not isinstance(value, bool):
        if value not in names:
            raise ValueError(f"unsupported QoS policy value {value}")
        return names[value]
    text = str(value).lower()
    if text not in names.values():
        raise ValueError(f"unsupported QoS policy value {value!r}")
    return text


class LoggedMessage(NamedTuple):
    """One message read back from a log.

    Attributes:
        topic: Topic name.
        type_name: ``pkg/msg/Type``.
        cdr: The serialized message, as rmw delivered it.
        log_time_ns: Receive time (recorder clock), ns since the epoch.
        publish_time_ns: Publish time reported by the middleware, ns since the epoch.
        qos: The QoS the publisher offered.
    """

    topic: str
    type_name: str
    cdr: bytes
    log_time_ns: int
    publish_time_ns: int
    qos: QosDescription


class LoggedTopic(NamedTuple):
    """A topic present in a log.

    Attributes:
        type_name: ``pkg/msg/Type``.
        qos: The QoS the publisher offered.
        message_count: Messages logged on the topic.
    """

    type_name: str
    qos: QosDescription
    message_count: int


# --- message definitions, the way rosbag2's LocalMessageDefinitionSource builds them -------------

# Field types in a .msg file ("foo_msgs/Bar" in "foo_msgs/Bar[] bar"); same pattern as rosbag2.
_MSG_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_IDL_INCLUDE = re.compile(r"(?:^|\n)#include\s+(?:\"|<)([a-zA-Z0-9_/]+)\.idl(?:\"|>)")
_TYPE_NAME = re.compile(r"^([a-zA-Z][a-zA-Z0-9_]*)/(?:([a-zA-Z][a-zA-Z0-9_]*)/)?([a-zA-Z][a-zA-Z0-9_]*)$")
_PRIMITIVES = frozenset(
    "bool byte char float32 float64 int8 uint8 int16 uint16 int32 uint32 int64 uint64 string".split()
)
_DELIMITER = "=" * 80 + "\n"


def _share_dirs(package: str) -> list[Path]:
    """Candidate ``share/<package>`` directories: AMENT_PREFIX_PATH first, then this interpreter's."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    # A plain venv has no AMENT_PREFIX_PATH; the message wheels install into <venv>/share.
    prefixes += [sys.prefix, sys.base_prefix]
    seen: list[Path] = []
    for prefix in prefixes:
        candidate = Path(prefix, "share", package)
        if candidate not in seen:
            seen.append(candidate)
    return seen


def _interface_file(type_name: str, extension: str) -> Path | None:
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise McapLogError(f"type name {type_name!r} is not of the form pkg/msg/Type or pkg/Type")
    package, namespace, name = match.group(1), match.group(2) or "msg", match.group(3)
    for share in _share_dirs(package):
        candidate = share / namespace / f"{name}{extension}"
        if candidate.is_file():
            return candidate
    return None


def _full_text(root: str, fmt: str) -> str:
    """Concatenate the root definition and its dependencies depth-first (sorted, each once)."""
    extension = ".msg" if fmt == "MSG" else ".idl"
    seen: set[str] = set()

    def load(type_name: str) -> str:
        path = _interface_file(type_name, extension)
        if path is None:
            raise FileNotFoundError(type_name)
        # Byte-exact like rosbag2 (no newline translation).
        return path.read_bytes().decode("utf-8")

    def dependencies(type_name: str, text: str) -> list[str]:
        if fmt == "IDL":
            return sorted(set(_IDL_INCLUDE.findall(text)))
        package = type_name.split("/", 1)[0]
        deps = {
            field if "/" in field else f"{package}/{field}"
            for field in _MSG_FIELD_TYPE.findall(text)
            if field not in _PRIMITIVES
        }
        return sorted(deps)

    def append(type_name: str, depth: int) -> str:
        if depth <= 0:
            raise McapLogError(f"message definition of {root} nests too deeply")
        text = load(type_name)
        result = text
        for dep in dependencies(type_name, text):
            if dep not in seen:
                seen.add(dep)
                result += "\n" + _DELIMITER + f"{fmt}: {dep}\n" + append(dep, depth - 1)
        return result

    text = append(root, 50)
    return text if fmt == "MSG" else _DELIMITER + f"IDL: {root}\n" + text


def message_definition(type_name: str) -> tuple[str, str]:
    """Build the schema text ``ros2 bag record`` stores for a message type.

    Args:
        type_name: ``pkg/msg/Type``.

    Returns:
        ``(encoding, text)``: ``("ros2msg", ...)`` from the ``.msg`` files, or ``("ros2idl", ...)``
        when only ``.idl`` files are installed (rosbag2's fallback).

    Raises:
        McapLogError: Neither ``.msg`` nor ``.idl`` definitions are found for the type or one of
            its dependencies.
    """
    for fmt, encoding in (("MSG", "ros2msg"), ("IDL", "ros2idl")):
        try:
            return encoding, _full_text(type_name, fmt)
        except FileNotFoundError as exc:
            missing = str(exc)
    searched = ", ".join(str(p) for p in _share_dirs(type_name.split("/", 1)[0]))
    raise McapLogError(f"no .msg/.idl definition found for {missing} (needed by {type_name}); searched {searched}")


def type_description_hash(type_name: str) -> str:
    """Return the ``RIHS01_...`` type hash from ``share/<pkg>/msg/<Type>.json``, or ``""``.

    Args:
        type_name: ``pkg/msg/Type``.
    """
    path = _interface_file(type_name, ".json")
    if path is None:
        return ""
    try:
        hashes = json.loads(path.read_text(encoding="utf-8")).get("type_hashes", [])
    except (OSError, ValueError):
        return ""
    for entry in hashes:
        if entry.get("type_name") == type_name:
            return str(entry.get("hash_string", ""))
    return ""


# --- writer ----------------------------------------------------------------------------------------


@dataclass
class _Topic:
    channel_id: int
    type_name: str
    qos: QosDescription
    type_hash: str
    message_count: int = 0


class McapLogWriter:
    """Write a rosbag2-compatible MCAP log; thread-safe, crash-tolerant.

    Use as a context manager; :meth:`close` (also run by ``__exit__``, even on error) writes the
    summary and index. Until then, every completed chunk is already in the operating system's hands.

    Args:
        path: File to create (overwritten if it exists).
        metadata: Key/value pairs stored as a ``helireach`` metadata record and as rosbag2's
            ``custom_data``.
        chunk_size: Uncompressed bytes after which a chunk is completed and written out.
        compression: Chunk compression: ``"none"`` (rosbag2's default), ``"lz4"`` or ``"zstd"``
            (both ship as dependencies of the ``mcap`` wheel).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        metadata: Mapping[str, str] | None = None,
        chunk_size: int = 64 * 1024,
        compression: str = "none",
    ) -> None:
        if compression not in _COMPRESSION:
            raise ValueError(f"compression must be one of {sorted(_COMPRESSION)}, not {compression!r}")
        if chunk_size < 1:
            raise ValueError(f"chunk_size must be positive, not {chunk_size}")
        self._path = Path(path)
        self._lock = threading.Lock()
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
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
            self._writer.start(profile="ros2", library=f"helireach_ros.mcap_log; {LIBRARY_IDENTIFIER}")
            # rosbag2 writes its metadata at open too, so a killed recording still identifies itself.
            self._write_rosbag2_metadata()
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

    def add_topic(self, topic: str, type_name: str, qos: QosDescription) -> int:
        """Register a topic (schema + channel); idempotent for the same type.

        Args:
            topic: Fully qualified topic name.
            type_name: ``pkg/msg/Type``.
            qos: The QoS the publisher offers (stored as ``offered_qos_profiles``).

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
                encoding, text = message_definition(type_name)
                schema_id = self._writer.register_schema(type_name, encoding, text.encode("utf-8"))
                self._schemas[type_name] = schema_id
            type_hash = type_description_hash(type_name)
            channel_id = self._writer.register_channel(
                topic,
                "cdr",
                schema_id,
                {"offered_qos_profiles": qos.to_rosbag2_yaml(), "topic_type_hash": type_hash},
            )
            self._topics[topic] = _Topic(channel_id, type_name, qos, type_hash)
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
            self._writer.add_message(entry.channel_id, log_time_ns, bytes(cdr), publish)
            entry.message_count += 1
            self._message_count += 1
            self._start_ns = log_time_ns if self._start_ns is None else min(self._start_ns, log_time_ns)
            self._end_ns = max(self._end_ns, log_time_ns)
            # Nothing reaches the file object until a chunk completes; pass that on at once.
            self._sync()

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
            writer_flush = getattr(self._writer, "flush", None)  # mcap >= 1.3
            if writer_flush is not None:
                writer_flush()
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

    def _write_rosbag2_metadata(self) -> None:
        start = self._start_ns if self._start_ns is not None else _INT64_MAX
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


def _has_footer(stream: BinaryIO) -> bool:
    """Whether the file ends like a finished MCAP file (footer + closing magic)."""
    stream.seek(0, os.SEEK_END)
    if stream.tell() < 2 * len(_MCAP_MAGIC):
        return False
    stream.seek(-len(_MCAP_MAGIC), os.SEEK_END)
    return stream.read(len(_MCAP_MAGIC)) == _MCAP_MAGIC


def _open_log(path: Path) -> BinaryIO:
    try:
        stream = open(path, "rb")  # the caller closes it
    except OSError as exc:
        raise McapLogError(f"cannot open log: {exc.strerror}", path) from exc
    if stream.read(len(_MCAP_MAGIC)) != _MCAP_MAGIC:
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
            dropped. Damage inside a finished file ends the iteration early instead of raising.

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
            except Exception as exc:
                if allow_truncated:
                    return
                raise McapLogError(f"corrupt MCAP data ({exc.__class__.__name__}: {exc})", path) from exc
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
    log_path = Path(path)
    with _open_log(log_path) as stream:
        reader = _open_summary(log_path, stream, allow_truncated)
        if reader is not None:
            summary = reader.get_summary()
            assert summary is not None  # _open_summary returns a reader only when there is one
            counts = summary.statistics.channel_message_counts if summary.statistics else {}
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
            channels = channel_list
        topics: dict[str, LoggedTopic] = {}
        for channel in channels:
            info = _channel_info(log_path, channel, schemas.get(channel.schema_id))
            topics[info.topic] = LoggedTopic(info.type_name, info.qos, counts.get(channel.id, 0))
    return topics
