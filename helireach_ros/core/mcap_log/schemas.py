"""Message schemas for the log: each type's ``.msg`` (or ``.idl``) text with its dependencies, as rosbag2
stores them (encoding ``ros2msg``), and the type-description hash, read from the installed interface files.
No ROS import: the message wheels install their interface files under ``<prefix>/share``.
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

from helireach_ros.core.mcap_log.records import McapLogError

__all__ = ["message_definition", "type_description_hash"]

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
