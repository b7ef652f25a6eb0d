"""Dataclasses of numpy arrays as bytes, and back, without pickle.

The solver process (:mod:`helireach_ros.core.workers.solver_pool`) sends landing plans and requests over a pipe.
Pickle would execute whatever a corrupted or foreign byte stream says; this codec writes a JSON header
(name, dtype, shape of each array) followed by the arrays' raw bytes, and refuses object dtypes, so the
bytes can only ever become numeric, boolean or text arrays, and the arrays only the dataclass the reader
asks for. (An ``.npz`` archive read with ``allow_pickle=False`` would be as safe, but its zip framing costs
~3 ms per plan; this costs ~0.1 ms.)

A dataclass is flattened field by field into named arrays (``"replay.touchdown_state"``). Supported field
values: numpy arrays, ``float``/``int``/``bool``/``str``, ``tuple[str, ...]`` (a text array), ``tuple[float, ...]``,
nested dataclasses, ``dict[str, float]`` (stored as ``<name>.__keys__``/``<name>.__values__``) and ``None``
(stored as the marker ``<name>.__none__``). Decoding follows the reader's type hints, so bytes written for another
class (a missing field) raise :class:`ValueError`.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import struct
import types
import typing
from typing import Any, TypeVar

import numpy as np

__all__ = ["decode_dataclass", "encode_dataclass"]

T = TypeVar("T")

_NONE, _KEYS, _VALUES = "__none__", "__keys__", "__values__"
_HEADER_LENGTH = struct.Struct("<I")


def _flatten(value: Any, prefix: str, arrays: dict[str, np.ndarray]) -> None:
    if value is None:
        arrays[f"{prefix}.{_NONE}"] = np.array(True)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            _flatten(getattr(value, field.name), f"{prefix}.{field.name}" if prefix else field.name, arrays)
    elif isinstance(value, dict):
        arrays[f"{prefix}.{_KEYS}"] = np.array([str(key) for key in value], dtype=str)
        arrays[f"{prefix}.{_VALUES}"] = np.array([float(item) for item in value.values()], dtype=float)
    elif isinstance(value, np.ndarray | bool | int | float | str | np.generic):
        arrays[prefix] = np.asarray(value)
    elif isinstance(value, tuple) and all(isinstance(item, str) for item in value):
        arrays[prefix] = np.array(value, dtype=str).reshape(-1)
    elif isinstance(value, tuple) and all(isinstance(item, int | float | np.number) for item in value):
        arrays[prefix] = np.array(value, dtype=float).reshape(-1)
    else:
        raise TypeError(f"{prefix}: cannot encode a {type(value).__name__}")


def encode_dataclass(value: Any) -> bytes:
    """The dataclass instance ``value`` as bytes: a 4-byte header length, the JSON header, the raw arrays."""
    if not (dataclasses.is_dataclass(value) and not isinstance(value, type)):
        raise TypeError(f"expected a dataclass instance, got {type(value).__name__}")
    arrays: dict[str, np.ndarray] = {}
    _flatten(value, "", arrays)
    header, chunks = [], []
    for name, array in arrays.items():
        header.append([name, array.dtype.str, list(array.shape)])
        chunks.append(array.tobytes(order="C"))
    encoded_header = json.dumps(header, separators=(",", ":")).encode()
    return b"".join([_HEADER_LENGTH.pack(len(encoded_header)), encoded_header, *chunks])


def _read_arrays(data: bytes) -> dict[str, np.ndarray]:
    (length,) = _HEADER_LENGTH.unpack_from(data, 0)
    header = json.loads(data[_HEADER_LENGTH.size : _HEADER_LENGTH.size + length])
    offset = _HEADER_LENGTH.size + length
    arrays = {}
    for name, dtype_text, shape in header:
        dtype = np.dtype(dtype_text)
        if dtype.hasobject or dtype.kind not in "biufcU":
            raise ValueError(f"{name}: dtype {dtype_text!r} is not allowed")
        count = int(np.prod(shape, dtype=np.int64))
        size = count * dtype.itemsize
        if offset + size > len(data):
            raise ValueError(f"{name}: truncated")
        arrays[str(name)] = np.frombuffer(data, dtype, count, offset).reshape(tuple(shape))
        offset += size
    if offset != len(data):
        raise ValueError("trailing bytes after the last array")
    return arrays


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _optional_inner(hint: Any) -> tuple[Any, bool]:
    """(the non-None type, whether None is allowed) of a type hint."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        arguments = [argument for argument in typing.get_args(hint) if argument is not type(None)]
        return (arguments[0] if len(arguments) == 1 else Any), len(arguments) < len(typing.get_args(hint))
    return hint, False


def _build(hint: Any, prefix: str, arrays: Any) -> Any:
    hint, optional = _optional_inner(hint)
    if f"{prefix}.{_NONE}" in arrays:
        if not optional:
            raise ValueError(f"{prefix}: None where a value is required")
        return None
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        hints = _type_hints(hint)
        values = {
            field.name: _build(hints[field.name], f"{prefix}.{field.name}" if prefix else field.name, arrays)
            for field in dataclasses.fields(hint)
        }
        return hint(**values)
    origin = typing.get_origin(hint) or hint
    if origin is dict:
        keys, items = arrays.get(f"{prefix}.{_KEYS}"), arrays.get(f"{prefix}.{_VALUES}")
        if keys is None or items is None:
            raise ValueError(f"{prefix}: missing in the archive")
        return {str(key): float(item) for key, item in zip(keys, items, strict=True)}
    if prefix not in arrays:
        raise ValueError(f"{prefix}: missing in the archive")
    array = arrays[prefix]
    if origin is np.ndarray:
        return np.array(array)
    if origin is tuple:
        if array.ndim == 1 and array.dtype.kind == "U":
            return tuple(str(item) for item in array)
        if array.ndim == 1 and array.dtype.kind == "f":  # a tuple of numbers (e.g. a landing site's ends)
            return tuple(float(item) for item in array)
        raise ValueError(f"{prefix}: expected a tuple of text or numbers, got {array.dtype} {array.shape}")
    if origin in (bool, int, float, str):
        if array.shape != ():
            raise ValueError(f"{prefix}: expected a scalar, got shape {array.shape}")
        return origin(array.item())
    return np.array(array) if array.shape else array.item()


def decode_dataclass(cls: type[T], data: bytes) -> T:
    """Rebuilds an instance of the dataclass ``cls`` from :func:`encode_dataclass` bytes.

    Raises:
        ValueError: the bytes are not such an encoding, or lack (or mistype) a field of ``cls``.
    """
    try:
        arrays = _read_arrays(data)
    except (ValueError, TypeError, struct.error, json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"not an encoded {cls.__name__}: {error}") from error
    return _build(cls, "", arrays)
