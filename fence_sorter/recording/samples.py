"""Messages as plain values, and sample messages with every field set (for round-trip checks).

A message is represented as a plain ``dict`` {field: value}: nested messages are dicts,
sequences and arrays are lists, numbers are Python ``int``/``float``. The same representation
is produced from rosbags objects here and from rclpy messages in
:mod:`fence_sorter.nodes.convert`, so a message can be compared exactly across DDS, rosbags and
the independent ``mcap_ros2`` decoder.

:func:`sample_values` walks the field definitions registered from ``msg_defs/`` and gives every
field a value different from its default, so adding a field to a .msg file adds it to every
round-trip test without touching the tests.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

MessageDict = dict[str, Any]

_NUMPY_DTYPES = {
    "bool": np.bool_,
    "byte": np.uint8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}
_INT_TYPES = {"byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64"}
_INT_TYPES |= {"uint64"}
SEQUENCE_SAMPLE_LENGTH = 3


class _Counter:
    """Hands out 1, 2, 3, ... so that every field of a sample gets its own value."""

    def __init__(self, start: int) -> None:
        self.value = start

    def next(self) -> int:
        self.value += 1
        return self.value


def _base_sample(typename: str, field: str, counter: _Counter) -> Any:
    k = counter.next()
    if typename == "bool":
        return True
    if typename in _INT_TYPES:
        # in range of every integer type, never 0; the seed (k // 1000) shifts it, so a message
        # of integers alone differs between seeds too
        return (k + k // 1000) % 100 + 1
    if typename == "float32":
        return k + 0.25  # exactly representable in float32
    if typename == "float64":
        return k * 1.1 + 1.0 / 3.0  # not a short decimal: checks bit-exact transport
    if typename == "string":
        return f"{field}-{k}"
    raise ValueError(f"field {field!r}: no sample value for base type {typename!r}")


def _field_sample(typestore: Typestore, field: str, desc: tuple, counter: _Counter) -> Any:
    nodetype, detail = desc
    if nodetype == Nodetype.BASE:
        return _base_sample(detail[0], field, counter)
    if nodetype == Nodetype.NAME:
        return _sample(typestore, detail, counter)
    if nodetype == Nodetype.ARRAY:
        subdesc, size = detail
        return [_field_sample(typestore, field, subdesc, counter) for _ in range(size)]
    if nodetype == Nodetype.SEQUENCE:
        subdesc, bound = detail
        length = min(SEQUENCE_SAMPLE_LENGTH, bound) if bound else SEQUENCE_SAMPLE_LENGTH
        return [_field_sample(typestore, field, subdesc, counter) for _ in range(length)]
    raise ValueError(f"field {field!r}: unknown node type {nodetype!r}")


def _sample(typestore: Typestore, msgtype: str, counter: _Counter) -> MessageDict:
    _, fields = typestore.fielddefs[msgtype]
    return {name: _field_sample(typestore, name, desc, counter) for name, desc in fields}


def sample_values(typestore: Typestore, msgtype: str, seed: int = 0) -> MessageDict:
    """Return a message of ``msgtype`` as a dict with every field set to a non-default value.

    Different ``seed`` values give different samples; equal seeds give equal samples.
    """
    if msgtype not in typestore.fielddefs:
        raise KeyError(f"type {msgtype!r} is not registered in the type store")
    return _sample(typestore, msgtype, _Counter(seed * 1000))


def _to_rosbags_field(typestore: Typestore, desc: tuple, value: Any) -> Any:
    nodetype, detail = desc
    if nodetype == Nodetype.BASE:
        return value
    if nodetype == Nodetype.NAME:
        return to_rosbags(typestore, detail, value)
    subdesc, _ = detail
    subtype, subdetail = subdesc
    if subtype == Nodetype.BASE and subdetail[0] in _NUMPY_DTYPES:
        return np.array(value, dtype=_NUMPY_DTYPES[subdetail[0]])
    return [_to_rosbags_field(typestore, subdesc, item) for item in value]


def to_rosbags(typestore: Typestore, msgtype: str, values: MessageDict) -> Any:
    """Build the rosbags message object of ``msgtype`` from its dict representation."""
    _, fields = typestore.fielddefs[msgtype]
    names = {name for name, _ in fields}
    unknown = sorted(set(values) - names)
    if unknown:
        raise KeyError(f"{msgtype} has no field(s) {', '.join(unknown)}")
    missing = sorted(names - set(values))
    if missing:
        raise KeyError(f"{msgtype}: value(s) missing for {', '.join(missing)}")
    kwargs = {name: _to_rosbags_field(typestore, desc, values[name]) for name, desc in fields}
    return typestore.types[msgtype](**kwargs)


def _from_rosbags_field(typestore: Typestore, desc: tuple, value: Any) -> Any:
    nodetype, detail = desc
    if nodetype == Nodetype.BASE:
        return value.item() if isinstance(value, np.generic) else value
    if nodetype == Nodetype.NAME:
        return from_rosbags(typestore, value)
    subdesc, _ = detail
    if isinstance(value, np.ndarray):
        return value.tolist()
    return [_from_rosbags_field(typestore, subdesc, item) for item in value]


def from_rosbags(typestore: Typestore, message: Any) -> MessageDict:
    """Return the dict representation of a rosbags message object."""
    msgtype = message.__msgtype__
    _, fields = typestore.fielddefs[msgtype]
    return {
        name: _from_rosbags_field(typestore, desc, getattr(message, name)) for name, desc in fields
    }


def from_mcap_ros2(message: Any) -> MessageDict:
    """Return the dict representation of a message decoded by ``mcap_ros2``.

    mcap_ros2 decodes into dynamic objects exposing ``__slots__``; numeric sequences may come
    as lists or tuples.
    """
    result: MessageDict = {}
    for name in message.__slots__:
        value = getattr(message, name)
        result[name] = _plain(value)
    return result


def _plain(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):  # mcap_ros2 decodes uint8[]/byte[] as bytes
        return list(value)
    if hasattr(value, "__slots__") and not isinstance(value, str):
        return from_mcap_ros2(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def diff_values(expected: Any, actual: Any, path: str = "") -> list[str]:
    """Return the field paths where ``actual`` differs from ``expected`` (exact comparison)."""
    where = path or "<message>"
    if isinstance(expected, dict) and isinstance(actual, dict):
        diffs: list[str] = []
        for key in sorted(set(expected) | set(actual)):
            sub = f"{path}.{key}" if path else key
            if key not in actual:
                diffs.append(f"{sub}: missing")
            elif key not in expected:
                diffs.append(f"{sub}: unexpected")
            else:
                diffs.extend(diff_values(expected[key], actual[key], sub))
        return diffs
    if isinstance(expected, list) and isinstance(actual, list):
        if len(expected) != len(actual):
            return [f"{where}: length {len(actual)} != {len(expected)}"]
        diffs = []
        for index, (exp, act) in enumerate(zip(expected, actual, strict=True)):
            diffs.extend(diff_values(exp, act, f"{path}[{index}]"))
        return diffs
    if type(expected) is not type(actual) or expected != actual:
        return [f"{where}: {actual!r} != {expected!r}"]
    return []
