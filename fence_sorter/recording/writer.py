"""Segmented rosbag2 writer (no ROS): a bag that survives SIGKILL up to its last flush.

A bag is a directory with ``metadata.yaml`` and storage files ``<name>_<i>.mcap`` (or ``.db3``),
as ``ros2 bag record --max-bag-size/--max-bag-duration`` lays it out. Each segment is written by
a rosbags :class:`~rosbags.rosbag2.Writer` in a staging directory ``<bag>/.open/`` and moved
into the bag, complete (MCAP summary and index, message definitions embedded), when it reaches
``max_segment_bytes`` or ``max_segment_duration`` or the bag is closed. ``metadata.yaml`` is
rewritten atomically (write to a temporary file, fsync, rename) after every segment, so at any
moment it is valid and lists exactly the closed segments. Within the open segment the messages
go out as MCAP chunks (zstd-compressed by default) closed and flushed to the file at least every
``flush_period`` seconds (sqlite3: a commit), so a writer killed with SIGKILL loses the messages
of the last ``flush_period`` at most: the open segment is left in ``.open/``, where
:mod:`fence_sorter.recording.bagread` (and any MCAP stream reader) reads its complete chunks.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from rosbags.interfaces import Qos
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.typesys.store import Typestore

from fence_sorter.recording.msgtypes import make_typestore

#: rosbag2 metadata version written (rosbags 0.11 writes 8 or 9).
BAG_VERSION = 9
STAGING_DIR = ".open"
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
SUFFIXES = {"mcap": ".mcap", "sqlite3": ".db3"}
DEFAULT_MAX_SEGMENT_BYTES = 64 * 2**20
DEFAULT_MAX_SEGMENT_DURATION = 10.0  # [s] of writer clock
#: the open chunk is closed and flushed to the file at least this often [s] of writer clock
DEFAULT_FLUSH_PERIOD = 0.5
#: MCAP chunk compression: zstd (default) or none
COMPRESSIONS = ("zstd", "none")


class BagWriteError(RuntimeError):
    """The bag cannot be created or written (the message names the path)."""


@dataclass
class TopicRecord:
    """A topic of the bag: type, offered QoS and message counts."""

    topic: str
    msgtype: str
    qos: tuple[Qos, ...] = ()
    count: int = 0  # messages written to closed and open segments
    closed_count: int = 0  # messages in closed segments


@dataclass
class SegmentInfo:
    """A closed segment as listed in metadata.yaml."""

    path: str
    start_ns: int
    duration_ns: int
    message_count: int
    size_bytes: int


@dataclass
class _OpenSegment:
    index: int
    name: str
    writer: Writer
    connections: dict[int, object] = field(default_factory=dict)  # topic index -> Connection
    opened_at: float = 0.0
    flushed_at: float = 0.0
    bytes: int = 0
    count: int = 0


class SegmentedBagWriter:
    """Write CDR messages into a rosbag2 bag split into bounded, self-contained segments.

    ``path`` must not exist or be an empty directory. ``storage`` is ``mcap`` (default) or
    ``sqlite3``. A segment is closed when its payload reaches ``max_segment_bytes`` or when it
    has been open ``max_segment_duration`` seconds of ``clock``; its pending messages are
    flushed to the file every ``flush_period`` seconds (both checked on every write and by
    :meth:`poll`). ``compression``: MCAP chunks zstd-compressed (``zstd``) or not (``none``).
    Not thread-safe: one thread writes.
    """

    def __init__(
        self,
        path: Path | str,
        *,
        storage: str = "mcap",
        typestore: Typestore | None = None,
        max_segment_bytes: int = DEFAULT_MAX_SEGMENT_BYTES,
        max_segment_duration: float = DEFAULT_MAX_SEGMENT_DURATION,
        flush_period: float = DEFAULT_FLUSH_PERIOD,
        compression: str = "zstd",
        custom_data: dict[str, str] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if storage not in STORAGES:
            raise BagWriteError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
        if not max_segment_bytes > 0:
            raise BagWriteError(f"max_segment_bytes must be > 0, got {max_segment_bytes}")
        if not max_segment_duration > 0:
            raise BagWriteError(f"max_segment_duration must be > 0 s, got {max_segment_duration}")
        if not flush_period > 0:
            raise BagWriteError(f"flush_period must be > 0 s, got {flush_period}")
        if compression not in COMPRESSIONS:
            raise BagWriteError(
                f"compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}"
            )
        self.path = Path(path)
        self.storage = storage
        self.typestore = typestore if typestore is not None else make_typestore()
        self.max_segment_bytes = int(max_segment_bytes)
        self.max_segment_duration = float(max_segment_duration)
        self.flush_period = float(flush_period)
        self.compression = compression if storage == "mcap" else "none"
        self.flushes = 0
        self.custom_data = dict(custom_data or {})
        self.clock = clock
        self.topics: list[TopicRecord] = []
        self.segments: list[SegmentInfo] = []
        self._by_topic: dict[str, int] = {}
        self._open: _OpenSegment | None = None
        self._next_index = 0
        self._is_open = False
        self.bytes_written = 0
        #: the newest timestamp handed to :meth:`write`, and the newest one a reader finds in
        #: the files (flushed or in a closed segment) [ns]; None before any
        self.last_ns: int | None = None
        self.durable_ns: int | None = None

    # -- lifecycle -----------------------------------------------------------------------------
    def open(self) -> SegmentedBagWriter:
        """Create the bag directory and an empty, valid metadata.yaml."""
        if self.path.exists():
            if not self.path.is_dir():
                raise BagWriteError(f"{self.path}: exists and is not a directory")
            if any(self.path.iterdir()):
                raise BagWriteError(f"{self.path}: directory not empty, not overwriting a bag")
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            (self.path / STAGING_DIR).mkdir(exist_ok=True)
        except OSError as exc:
            raise BagWriteError(f"{self.path}: cannot create the bag directory: {exc}") from exc
        self._is_open = True
        self._write_metadata()
        return self

    def __enter__(self) -> SegmentedBagWriter:
        return self.open()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def name(self) -> str:
        return self.path.name

    def add_topic(self, topic: str, msgtype: str, qos: Sequence[Qos] = ()) -> int:
        """Register a topic; return its handle for :meth:`write`. Idempotent per topic."""
        self._check_open()
        if topic in self._by_topic:
            known = self.topics[self._by_topic[topic]]
            if known.msgtype != msgtype:
                raise BagWriteError(
                    f"{self.path}: topic {topic} already recorded as {known.msgtype}, "
                    f"not {msgtype}"
                )
            return self._by_topic[topic]
        if msgtype not in self.typestore.fielddefs:
            raise BagWriteError(f"{self.path}: topic {topic}: unknown message type {msgtype}")
        handle = len(self.topics)
        self.topics.append(TopicRecord(topic, msgtype, tuple(qos)))
        self._by_topic[topic] = handle
        if self._open is not None:
            self._connect(self._open, handle)
        return handle

    def write(self, handle: int, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Write one serialised (CDR) message of topic ``handle`` stamped ``timestamp_ns``."""
        self._check_open()
        seg = self._open or self._start_segment()
        seg.writer.write(seg.connections[handle], int(timestamp_ns), data)
        size = len(data)
        seg.bytes += size
        seg.count += 1
        self.bytes_written += size
        self.topics[handle].count += 1
        if self.last_ns is None or timestamp_ns > self.last_ns:
            self.last_ns = int(timestamp_ns)
        if seg.bytes >= self.max_segment_bytes:
            self.rotate()
        else:
            self.poll()

    def poll(self) -> None:
        """Close the open segment if it has been open longer than max_segment_duration, else
        flush it if its last flush is flush_period ago."""
        seg = self._open
        if seg is None or not seg.count:
            return
        now = self.clock()
        if now - seg.opened_at >= self.max_segment_duration:
            self.rotate()
        elif now - seg.flushed_at >= self.flush_period:
            self.flush()

    def flush(self) -> None:
        """Write the open segment's pending messages to its file: the open MCAP chunk is
        closed (a complete, indexed chunk record) and the file flushed; sqlite3 commits. A
        process killed afterwards leaves them readable."""
        seg = self._open
        if seg is None:
            return
        seg.flushed_at = self.clock()
        storage = seg.writer.storage
        try:
            if self.storage == "mcap":
                if storage.chunk.msgs:  # schemas and channels go with the first messages
                    storage.close_chunk()
                storage.bio.flush()
            else:
                storage.conn.commit()
        except OSError as exc:
            raise BagWriteError(f"{self.path}: cannot flush segment {seg.name}: {exc}") from exc
        self.flushes += 1
        self.durable_ns = self.last_ns

    def rotate(self) -> None:
        """Close the open segment (if it holds messages) and list it in metadata.yaml."""
        seg, self._open = self._open, None
        if seg is None:
            return
        staged = self.path / STAGING_DIR / seg.name
        if seg.count == 0:
            seg.writer.close()
            shutil.rmtree(staged, ignore_errors=True)
            return
        writer = seg.writer
        start = writer.min_timestamp
        duration = max(0, writer.max_timestamp - writer.min_timestamp)
        counts = dict(writer.counts)
        try:
            writer.close()
            src = staged / f"{seg.name}{SUFFIXES[self.storage]}"
            _fsync_file(src)
            dst = self.path / src.name
            os.replace(src, dst)
            _fsync_dir(self.path)
            shutil.rmtree(staged, ignore_errors=True)
        except OSError as exc:
            raise BagWriteError(f"{self.path}: cannot close segment {seg.name}: {exc}") from exc
        for handle, conn in seg.connections.items():
            self.topics[handle].closed_count += counts.get(conn.id, 0)
        self.segments.append(SegmentInfo(dst.name, start, duration, seg.count, dst.stat().st_size))
        self.durable_ns = self.last_ns
        self._write_metadata()

    def close(self) -> None:
        """Close the open segment and write the final metadata.yaml."""
        if not self._is_open:
            return
        self.rotate()
        self._is_open = False
        shutil.rmtree(self.path / STAGING_DIR, ignore_errors=True)
        self._write_metadata()

    # -- internals -----------------------------------------------------------------------------
    def _check_open(self) -> None:
        if not self._is_open:
            raise BagWriteError(f"{self.path}: bag is not open")

    def _start_segment(self) -> _OpenSegment:
        name = f"{self.name}_{self._next_index}"
        self._next_index += 1
        plugin = STORAGES[self.storage]
        writer = Writer(self.path / STAGING_DIR / name, version=BAG_VERSION, storage_plugin=plugin)
        if self.compression == "zstd":  # chunk compression inside the MCAP file
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            writer.open()
        except Exception as exc:
            raise BagWriteError(f"{self.path}: cannot open segment {name}: {exc}") from exc
        for key, value in self.custom_data.items():
            writer.set_custom_data(key, value)
        now = self.clock()
        seg = _OpenSegment(self._next_index - 1, name, writer, opened_at=now, flushed_at=now)
        for handle in range(len(self.topics)):
            self._connect(seg, handle)
        self._open = seg
        return seg

    def _connect(self, seg: _OpenSegment, handle: int) -> None:
        rec = self.topics[handle]
        seg.connections[handle] = seg.writer.add_connection(
            rec.topic, rec.msgtype, typestore=self.typestore, offered_qos_profiles=list(rec.qos)
        )

    def metadata(self) -> dict:
        """The rosbag2 metadata of the closed segments (the content of metadata.yaml)."""
        start = min((s.start_ns for s in self.segments), default=0)
        end = max((s.start_ns + s.duration_ns for s in self.segments), default=0)
        return {
            "rosbag2_bagfile_information": {
                "version": BAG_VERSION,
                "storage_identifier": self.storage,
                "relative_file_paths": [s.path for s in self.segments],
                "duration": {"nanoseconds": max(end - start, 0)},
                "starting_time": {"nanoseconds_since_epoch": start},
                "message_count": sum(s.message_count for s in self.segments),
                "topics_with_message_count": [
                    {
                        "topic_metadata": {
                            "name": t.topic,
                            "type": t.msgtype,
                            "serialization_format": "cdr",
                            "offered_qos_profiles": dump_qos_v9(list(t.qos)),
                            "type_description_hash": self.typestore.hash_rihs01(t.msgtype),
                        },
                        "message_count": t.closed_count,
                    }
                    for t in self.topics
                ],
                "compression_format": "",
                "compression_mode": "",
                "files": [
                    {
                        "path": s.path,
                        "starting_time": {"nanoseconds_since_epoch": s.start_ns},
                        "duration": {"nanoseconds": s.duration_ns},
                        "message_count": s.message_count,
                    }
                    for s in self.segments
                ],
                "custom_data": self.custom_data or None,
                "ros_distro": "rosbags",
            }
        }

    def _write_metadata(self) -> None:
        target = self.path / "metadata.yaml"
        tmp = target.with_suffix(".yaml.tmp")
        try:
            with tmp.open("w", encoding="utf-8") as out:
                yaml.safe_dump(self.metadata(), out, default_flow_style=False, sort_keys=False)
                out.flush()
                os.fsync(out.fileno())
            os.replace(tmp, target)
        except OSError as exc:
            raise BagWriteError(f"{target}: cannot write: {exc}") from exc


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
