"""rclpy messages to and from plain dicts (the representation of fence_sorter.recording.samples).

Nested messages become dicts, sequences and arrays become lists of Python numbers, so a
message received over DDS compares exactly with one read back from a bag.
"""

from __future__ import annotations

import array
import importlib
from typing import Any

import numpy as np

MessageDict = dict[str, Any]


def is_message(value: Any) -> bool:
    """Return True if ``value`` is an instance of a generated rclpy message class."""
    return hasattr(type(value), "get_fields_and_field_types") and hasattr(value, "__slots__")


def msg_to_dict(msg: Any) -> MessageDict:
    """Return the dict representation of an rclpy message."""
    if not is_message(msg):
        raise TypeError(f"not an rclpy message: {type(msg).__name__}")
    return {name: _to_plain(getattr(msg, name)) for name in msg.get_fields_and_field_types()}


def _to_plain(value: Any) -> Any:
    if is_message(value):
        return msg_to_dict(value)
    if isinstance(value, (array.array, np.ndarray)):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_to_plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _message_class(slot_type: Any) -> type:
    """Return the rclpy class of a rosidl NamespacedType (e.g. geometry_msgs/msg/Point)."""
    module = importlib.import_module(".".join(slot_type.namespaces))
    return getattr(module, slot_type.name)


def dict_to_msg(msg_class: type, values: MessageDict) -> Any:
    """Build an rclpy message of ``msg_class`` from its dict representation.

    Raises:
        KeyError: ``values`` names a field that ``msg_class`` does not have.

    """
    msg = msg_class()
    fields = list(msg_class.get_fields_and_field_types())
    slot_types = dict(zip(fields, msg_class.SLOT_TYPES, strict=True))
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise KeyError(f"{msg_class.__name__} has no field(s) {', '.join(unknown)}")
    for name, value in values.items():
        current = getattr(msg, name)
        if is_message(current):
            setattr(msg, name, dict_to_msg(type(current), value))
        elif value and isinstance(value, list) and isinstance(value[0], dict):
            item_class = _message_class(slot_types[name].value_type)
            setattr(msg, name, [dict_to_msg(item_class, item) for item in value])
        else:
            setattr(msg, name, value)
    return msg
