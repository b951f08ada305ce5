"""Text inputs (scenes, streams, manifests) read from whatever bytes a file holds: a file that
is not UTF-8 or a YAML document nested deeper than the parser can follow is a one-line
:class:`TextInputError`, never a traceback."""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path
from typing import Any

import yaml


class TextInputError(ValueError):
    """A text input that cannot be read (the message names why, without the file)."""


def read_text(path: Path) -> str:
    """The UTF-8 text of ``path``."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise TextInputError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise TextInputError(
            f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})"
        ) from None


def keyed_mapping(data: Any, key: str, allowed: Collection[str]) -> dict:
    """``data`` as a mapping (None: an empty one) whose keys are all in ``allowed``; else a
    TextInputError naming ``key`` (``key.k`` for an unknown key k) and the allowed keys."""
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise TextInputError(f"{key} must be a mapping, got {type(data).__name__} {data!r}")
    for k in data:
        if k not in allowed:
            raise TextInputError(
                f"{key}.{k} is not a known key; allowed keys: {', '.join(allowed)}"
            )
    return data


def load_yaml(text: str) -> Any:
    """The YAML document ``text`` (yaml.safe_load)."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise TextInputError(f"YAML syntax error: {' '.join(str(exc).split())}") from None
    except RecursionError:
        raise TextInputError("YAML nested too deeply to read") from None
