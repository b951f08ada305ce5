"""Register the fence_sorter_msgs message definitions with rosbags (no ROS needed).

The .msg files in ``msg_defs/msg/`` are the one source of truth: the interface package
fence_sorter_msgs is built from them by rosidl, and the rosbags type store is filled from the
very same files, so bags written here and messages sent over DDS agree field by field.

Where the .msg files are looked up, first hit wins:

1. ``$FENCE_SORTER_MSG_DIR`` if set (a directory holding the .msg files);
2. the source checkout: ``<repo>/msg_defs/msg`` next to this package (editable install);
3. installed: ``<prefix>/share/fence_sorter_msgs/msg`` for every prefix on
   ``$AMENT_PREFIX_PATH``, then ``sys.prefix`` (the interface package installs them there).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from fence_sorter.resources import checkout_root

if TYPE_CHECKING:
    from rosbags.interfaces.typing import Typesdict

MSG_PACKAGE = "fence_sorter_msgs"
MSG_DIR_ENV = "FENCE_SORTER_MSG_DIR"
#: The ROS distribution whose standard message definitions the type store starts from.
TYPESTORE_STORE = Stores.ROS2_KILTED


class MsgDefsError(RuntimeError):
    """The fence_sorter_msgs definitions cannot be found, parsed or registered."""


class MsgDefsNotFoundError(MsgDefsError, FileNotFoundError):
    """No directory with the fence_sorter_msgs .msg files was found."""


def msgtype_name(stem: str) -> str:
    """Return the full ROS 2 type name of a message, e.g. 'fence_sorter_msgs/msg/Parcel'."""
    return f"{MSG_PACKAGE}/msg/{stem}"


def _has_msg_files(directory: Path) -> bool:
    return directory.is_dir() and any(directory.glob("*.msg"))


def candidate_msg_dirs() -> list[Path]:
    """Return the directories searched for .msg files, in search order."""
    candidates: list[Path] = []
    override = os.environ.get(MSG_DIR_ENV)
    if override:
        candidates.append(Path(override))
    root = checkout_root()
    if root is not None:
        candidates.append(root / "msg_defs" / "msg")
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    for prefix in prefixes:
        directory = Path(prefix) / "share" / MSG_PACKAGE / "msg"
        if directory not in candidates:
            candidates.append(directory)
    return candidates


def find_msg_dir() -> Path:
    """Return the directory holding the fence_sorter_msgs .msg files.

    Raises:
        MsgDefsNotFoundError: ``$FENCE_SORTER_MSG_DIR`` is set but holds no .msg file, or no
            candidate directory holds any.

    """
    override = os.environ.get(MSG_DIR_ENV)
    if override:
        directory = Path(override)
        if not _has_msg_files(directory):
            raise MsgDefsNotFoundError(f"${MSG_DIR_ENV}={override} holds no .msg file")
        return directory
    for directory in candidate_msg_dirs():
        if _has_msg_files(directory):
            return directory
    searched = ", ".join(str(d) for d in candidate_msg_dirs())
    raise MsgDefsNotFoundError(
        f"no {MSG_PACKAGE} .msg files found (searched: {searched}); run scripts/bootstrap.sh "
        f"or set ${MSG_DIR_ENV}"
    )


def msg_files(msg_dir: Path | None = None) -> dict[str, Path]:
    """Return {full type name: .msg path} for every message definition, sorted by name."""
    directory = find_msg_dir() if msg_dir is None else msg_dir
    files = sorted(directory.glob("*.msg"))
    if not files:
        raise MsgDefsNotFoundError(f"{directory} holds no .msg file")
    return {msgtype_name(path.stem): path for path in files}


def message_names(msg_dir: Path | None = None) -> list[str]:
    """Return the short names of all fence_sorter_msgs messages, e.g. ['FenceCommand', ...]."""
    return [name.rsplit("/", 1)[1] for name in msg_files(msg_dir)]


def load_types(msg_dir: Path | None = None) -> Typesdict:
    """Parse every .msg file into a rosbags types dictionary {type name: parse tree}.

    Raises:
        MsgDefsError: a .msg file cannot be read or parsed (the message names the file).

    """
    types: Typesdict = {}
    for name, path in msg_files(msg_dir).items():
        try:
            text = path.read_text(encoding="utf-8")
            types.update(get_types_from_msg(text, name))
        except (OSError, UnicodeDecodeError) as exc:
            raise MsgDefsError(f"cannot read {path}: {exc}") from exc
        except Exception as exc:  # rosbags raises its own parser errors
            raise MsgDefsError(f"cannot parse {path} as {name}: {exc}") from exc
    return types


def register_types(typestore: Typestore, msg_dir: Path | None = None) -> list[str]:
    """Register the fence_sorter_msgs types in ``typestore``; return the registered names.

    Raises:
        MsgDefsError: a definition cannot be parsed or clashes with one already registered.

    """
    types = load_types(msg_dir)
    try:
        typestore.register(types)
    except Exception as exc:
        raise MsgDefsError(f"cannot register {MSG_PACKAGE} types: {exc}") from exc
    missing = sorted(set(types) - set(typestore.fielddefs))
    if missing:
        raise MsgDefsError(f"types not registered: {', '.join(missing)}")
    return sorted(types)


def make_typestore(msg_dir: Path | None = None) -> Typestore:
    """Return a ROS 2 Kilted type store with the fence_sorter_msgs types registered."""
    typestore = get_typestore(TYPESTORE_STORE)
    register_types(typestore, msg_dir)
    return typestore


def field_names(typestore: Typestore, msgtype: str) -> list[str]:
    """Return the field names of ``msgtype`` in definition order (constants excluded)."""
    try:
        _, fields = typestore.fielddefs[msgtype]
    except KeyError:
        raise MsgDefsError(f"type {msgtype!r} is not registered") from None
    return [name for name, _ in fields]
