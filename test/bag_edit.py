"""A bag rewritten with some of its messages dropped or edited: the damaged bags the analysis
tests read (one MCAP file, each topic with the definition embedded in the source bag)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class BagMessage:
    """One message of the source bag, as ``drop`` sees it."""

    topic: str
    t_ns: int
    msg: object


def rewrite_bag(
    src: Path,
    dst: Path,
    drop: Callable[[BagMessage], bool] | None = None,
    topic: str | None = None,
    edit: Callable[[object], object] | None = None,
) -> int:
    """``src`` written into ``dst`` without the messages ``drop`` is true for and with each
    message of ``topic`` replaced by ``edit(message)``; the number dropped."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    dropped = 0
    writer = Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP)
    with AnyReader([src]) as reader, writer as w:
        out = {}
        for c in reader.connections:
            if c.topic not in out:
                out[c.topic] = w.add_connection(
                    c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest
                )
        for c, t_ns, raw in reader.messages():
            if drop is not None or c.topic == topic:
                msg = reader.deserialize(raw, c.msgtype)
                if drop is not None and drop(BagMessage(c.topic, t_ns, msg)):
                    dropped += 1
                    continue
                if edit is not None and c.topic == topic:
                    raw = reader.typestore.serialize_cdr(edit(msg), c.msgtype)
            w.write(out[c.topic], t_ns, raw)
    return dropped
