"""Where a CDR message's content ends, read from its ``ros2msg`` schema: so the log keeps the message and not the
bytes that the serializer leaves after it.

The ROS 2 Fast-DDS type support sizes a message's buffer with an alignment pad for every *empty* sequence whose
elements would need one (a ``float64[]`` after its 4-byte length, for one), but the Fast-CDR serializer rightly
writes no pad for an empty sequence (eProsima/Fast-CDR#6; XCDR1, OMG CORBA 3.3 §9.3). The serialized message
therefore ends with up to 4 uninitialised bytes per empty sequence: ``rclpy.serialization.serialize_message(
std_msgs.msg.Float64MultiArray())`` returns 20 bytes of which the last 4 are left over, and every
``trajectory_msgs/JointTrajectory`` of a landing plan (``velocities``, ``accelerations`` and ``effort`` empty)
carries 12 such bytes per point. Readers that stop at the content (rclpy, ``mcap-ros2-support``, Foxglove) do not
notice; ``rosbags``, which checks that the whole buffer is consumed, refuses the message ("CDR message size
mismatch"), and the log stores stray heap bytes.

:func:`cdr_extent` walks the CDR (XCDR1, as ROS 2 writes it: a 4-byte encapsulation header, then each primitive
aligned to its size, at most 8, from the byte after the header; a sequence is a ``uint32`` count and its elements;
a string a ``uint32`` length including the NUL and its bytes) guided by the schema text that the log stores for
the channel (:func:`~helireach_ros.core.mcap_log.schemas.message_definition`).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

__all__ = ["CdrLayout", "CdrLayoutError", "cdr_extent", "parse_ros2msg_layout"]

_PRIMITIVE_SIZES = {
    "bool": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1,
    "int16": 2, "uint16": 2,
    "int32": 4, "uint32": 4, "float32": 4,
    "int64": 8, "uint64": 8, "float64": 8,
}  # fmt: skip
_ENCAPSULATION_HEADER = 4
_SECTION_DELIMITER = "\n" + "=" * 80 + "\n"
_FIELD_TYPE = re.compile(r"^(?P<base>[A-Za-z][A-Za-z0-9_/]*)(?:<=\d+)?(?P<array>\[(?P<bound><=)?(?P<size>\d*)\])?$")
_FIELD_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


class CdrLayoutError(ValueError):
    """A schema this module cannot lay out, or a message that does not fit its schema."""


@dataclass(frozen=True)
class _Field:
    base: str  # a primitive, "string", or a message type's full name (pkg/Type)
    sequence: bool  # unbounded or bounded sequence: a uint32 count first
    fixed_length: int | None  # fixed-size array: this many elements, no count


@dataclass(frozen=True)
class CdrLayout:
    """Every message type of one schema as its list of fields (constants dropped).

    Attributes:
        root: the full name of the message type (``pkg/Type``).
        types: field lists by full type name, the root's included.
    """

    root: str
    types: dict[str, tuple[_Field, ...]]


def _short_name(type_name: str) -> str:
    """``pkg/msg/Type`` and ``pkg/Type`` → ``pkg/Type``."""
    parts = type_name.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) >= 2 else type_name


def _parse_fields(text: str, package: str) -> tuple[_Field, ...]:
    fields = []
    for raw_line in text.splitlines():
        line = raw_line.split("#", 1)[0].strip()
        if not line:
            continue
        type_token, _, rest = line.partition(" ")
        name = _FIELD_NAME.match(rest.strip())
        if name is None:
            raise CdrLayoutError(f"cannot read the field line {raw_line!r}")
        if rest.strip()[name.end() :].lstrip().startswith("="):
            continue  # a constant: not serialized
        match = _FIELD_TYPE.match(type_token)
        if match is None:
            raise CdrLayoutError(f"cannot read the field type {type_token!r}")
        base = match.group("base")
        if base == "wstring":
            raise CdrLayoutError("wstring fields are not laid out")
        if base not in _PRIMITIVE_SIZES and base != "string":
            base = _short_name(base) if "/" in base else f"{package}/{base}"
        array = match.group("array") is not None
        sequence = array and (match.group("bound") is not None or match.group("size") == "")
        fixed_length = int(match.group("size")) if array and not sequence else None
        fields.append(_Field(base, sequence, fixed_length))
    return tuple(fields)


def parse_ros2msg_layout(type_name: str, schema_text: str) -> CdrLayout:
    """Lay out a ``ros2msg`` schema: the root's ``.msg`` text, then ``MSG: pkg/Type`` sections of its dependencies.

    Raises:
        CdrLayoutError: a line or a type that cannot be read, or a field of a type without a section.
    """
    sections = schema_text.split(_SECTION_DELIMITER)
    root = _short_name(type_name)
    types = {root: _parse_fields(sections[0], root.split("/")[0])}
    for section in sections[1:]:
        header, _, body = section.partition("\n")
        if not header.startswith("MSG: "):
            raise CdrLayoutError(f"unexpected schema section header {header!r}")
        name = _short_name(header[len("MSG: ") :].strip())
        types[name] = _parse_fields(body, name.split("/")[0])
    for fields in types.values():
        for field in fields:
            if field.base not in _PRIMITIVE_SIZES and field.base != "string" and field.base not in types:
                raise CdrLayoutError(f"the schema has no definition of {field.base}")
    return CdrLayout(root, types)


class _Cursor:
    def __init__(self, data: bytes, little_endian: bool) -> None:
        self.data = data
        self.offset = _ENCAPSULATION_HEADER
        self.count_format = "<I" if little_endian else ">I"

    def align(self, size: int) -> None:
        body = self.offset - _ENCAPSULATION_HEADER
        self.offset += -body % min(size, 8)

    def skip(self, size: int) -> None:
        self.offset += size
        if self.offset > len(self.data):
            raise CdrLayoutError(f"the message ends at byte {len(self.data)}, its content goes on to {self.offset}")

    def count(self) -> int:
        self.align(4)
        start = self.offset
        self.skip(4)
        return int(struct.unpack_from(self.count_format, self.data, start)[0])


def _walk_element(layout: CdrLayout, base: str, cursor: _Cursor, depth: int) -> None:
    if base in _PRIMITIVE_SIZES:
        size = _PRIMITIVE_SIZES[base]
        cursor.align(size)
        cursor.skip(size)
    elif base == "string":
        cursor.skip(cursor.count())
    else:
        _walk_message(layout, base, cursor, depth + 1)


def _walk_field(layout: CdrLayout, field: _Field, cursor: _Cursor, depth: int) -> None:
    if field.sequence:
        elements = cursor.count()
    elif field.fixed_length is not None:
        elements = field.fixed_length
    else:
        _walk_element(layout, field.base, cursor, depth)
        return
    if elements and field.base in _PRIMITIVE_SIZES:  # no alignment for an empty sequence (Fast-CDR#6)
        size = _PRIMITIVE_SIZES[field.base]
        cursor.align(size)
        cursor.skip(size * elements)
        return
    for _ in range(elements):
        _walk_element(layout, field.base, cursor, depth)


def _walk_message(layout: CdrLayout, type_name: str, cursor: _Cursor, depth: int) -> None:
    if depth > 64:
        raise CdrLayoutError(f"{layout.root} nests deeper than 64 levels")
    fields = layout.types[type_name]
    if not fields:  # an empty message is serialized as one uint8 (rosidl's structure_needs_at_least_one_member)
        cursor.skip(1)
    for field in fields:
        _walk_field(layout, field, cursor, depth)


def cdr_extent(layout: CdrLayout, data: bytes) -> int:
    """The number of bytes of ``data`` (a CDR message with its encapsulation header) that its content takes.

    Raises:
        CdrLayoutError: the data is shorter than its content, or not plain CDR (XCDR1).
    """
    if len(data) < _ENCAPSULATION_HEADER or data[0] != 0 or data[1] not in (0, 1):
        raise CdrLayoutError("not a plain CDR message (encapsulation header 00 00 or 00 01)")
    cursor = _Cursor(data, little_endian=data[1] == 1)
    _walk_message(layout, layout.root, cursor, 0)
    return cursor.offset
