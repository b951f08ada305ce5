"""Read a recorded bag file by file, and say precisely what could not be read (no ROS).

:func:`read_bag` accepts a bag directory (``metadata.yaml`` plus ``*.mcap``/``*.db3`` segments,
as written by :class:`~fence_sorter.recording.writer.SegmentedBagWriter` or ``ros2 bag``) or one
storage file. Every file is read on its own, so a missing, truncated or corrupted segment costs
only its own messages: the problem is reported as a :class:`BagIssue` naming the file, and the
other segments are read. An MCAP file without its summary (a writer killed before it closed the
file, or a truncated copy) is read record by record up to the first damaged byte. A segment left
open in ``<bag>/.open/`` by a killed recorder is recovered the same way and reported.

Messages are decoded with the message definitions embedded in each file (not with
``msg_defs/``), so a bag is readable on its own.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from fence_sorter.recording.writer import STAGING_DIR

STORAGE_SUFFIXES = (".mcap", ".db3")


class BagReadError(RuntimeError):
    """Nothing at all could be read from the bag (the message names the path and why)."""


@dataclass(frozen=True)
class BagIssue:
    """A problem with one file of the bag; ``recovered`` messages were still read from it."""

    file: str
    problem: str
    recovered: int = 0

    def __str__(self) -> str:
        tail = f" ({self.recovered} messages recovered)" if self.recovered else ""
        return f"{self.file}: {self.problem}{tail}"


@dataclass(frozen=True)
class BagMessage:
    """One decoded message: topic, type, bag timestamp [ns] and the rosbags message object."""

    topic: str
    msgtype: str
    t_ns: int
    msg: Any
    raw: bytes


@dataclass
class BagContents:
    """Everything readable from a bag, in file order then log-time order within each file."""

    path: Path
    messages: list[BagMessage] = field(default_factory=list)
    issues: list[BagIssue] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    types: dict[str, str] = field(default_factory=dict)  # topic -> msgtype
    msgdefs: dict[str, str] = field(default_factory=dict)  # msgtype -> embedded definition
    expected_counts: dict[str, int] = field(default_factory=dict)  # topic -> from metadata

    def by_topic(self, topic: str) -> list[BagMessage]:
        return [m for m in self.messages if m.topic == topic]

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for m in self.messages:
            out[m.topic] = out.get(m.topic, 0) + 1
        return out


def _segment_key(path: Path) -> tuple[int, str]:
    match = re.search(r"_(\d+)$", path.stem)
    return (int(match.group(1)) if match else -1, path.name)


def bag_files(path: Path, issues: list[BagIssue]) -> tuple[list[Path], dict[str, int]]:
    """The storage files of a bag directory (metadata order) and the per-topic counts it
    declares; problems with metadata.yaml or missing files go to ``issues``."""
    meta_path = path / "metadata.yaml"
    on_disk = sorted((p for p in path.iterdir() if p.suffix in STORAGE_SUFFIXES), key=_segment_key)
    listed: list[Path] | None = None
    counts: dict[str, int] = {}
    if not meta_path.is_file():
        issues.append(BagIssue(str(meta_path), "missing: reading the storage files found"))
    else:
        try:
            text = meta_path.read_text(encoding="utf-8")
            info = yaml.safe_load(text)["rosbag2_bagfile_information"]
            listed = [path / Path(str(name)).name for name in info["relative_file_paths"]]
            for item in info.get("topics_with_message_count") or []:
                counts[str(item["topic_metadata"]["name"])] = int(item["message_count"])
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            issues.append(BagIssue(str(meta_path), f"unreadable YAML ({exc}); using files found"))
        except (KeyError, TypeError, ValueError) as exc:
            issues.append(
                BagIssue(
                    str(meta_path),
                    f"not rosbag2 metadata (missing or bad {exc}); using files found",
                )
            )
    if listed is None:
        return on_disk, counts
    for p in listed:
        if not p.is_file():
            issues.append(BagIssue(str(p), "listed in metadata.yaml but missing"))
    extra = [p for p in on_disk if p not in listed]
    for p in extra:
        issues.append(BagIssue(str(p), "not listed in metadata.yaml (read anyway)"))
    return [p for p in listed if p.is_file()] + extra, counts


def _typestore_for(defs: dict[str, str], issues: list[BagIssue], file: str) -> Typestore:
    """A type store filled only from the definitions embedded in the bag."""
    store = get_typestore(Stores.EMPTY)
    for msgtype, text in defs.items():
        try:
            store.register(get_types_from_msg(text, msgtype))
        except Exception as exc:  # rosbags raises its own parser and clash errors
            issues.append(BagIssue(file, f"embedded definition of {msgtype} unusable: {exc}"))
    return store


def _decode_into(
    out: BagContents,
    records: Iterable[tuple[str, str, int, bytes]],
    store: Typestore,
    file: str,
    topics: set[str] | None,
) -> int:
    bad: dict[str, tuple[int, str]] = {}
    n = 0
    for topic, msgtype, t_ns, data in records:
        if topics is not None and topic not in topics:
            continue
        try:
            msg = store.deserialize_cdr(bytes(data), msgtype)
        except Exception as exc:
            count, first = bad.get(topic, (0, f"{type(exc).__name__}: {exc}"))
            bad[topic] = (count + 1, first)
            continue
        out.messages.append(BagMessage(topic, msgtype, int(t_ns), msg, bytes(data)))
        n += 1
    for topic, (count, first) in bad.items():
        out.issues.append(BagIssue(file, f"{count} messages on {topic} do not decode ({first})"))
    return n


def _read_with_rosbags(path: Path) -> tuple[dict[str, str], dict[str, str], list]:
    """All records of one storage file through rosbags (needs an intact, closed file)."""
    with Reader(path) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        defs = {c.msgtype: c.msgdef.data for c in reader.connections if c.msgdef.data}
        records = [(c.topic, c.msgtype, t, bytes(d)) for c, t, d in reader.messages()]
    return types, defs, records


@dataclass
class Recovered:
    """What one damaged MCAP segment yields (:func:`recover_mcap`): its topics' types, the
    embedded definitions, every message record read (topic, type, log time, CDR bytes) and
    what is wrong with the file. ``recovered`` is what every tool reports for the segment
    (``bag info``, ``analyze``, ``rrd``): all its records, whatever a reader then keeps."""

    types: dict[str, str]
    defs: dict[str, str]
    records: list
    problem: str

    @property
    def recovered(self) -> int:
        return len(self.records)


def recover_mcap(path: Path) -> Recovered:
    """The one reader of a damaged or unclosed MCAP segment: its records read as a stream up
    to the first damaged record."""
    # lazy: mcap (40 ms), only to read a bag's chunks
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    records: list = []
    problem = "ends without summary/footer (not closed: writer killed or file truncated)"
    with path.open("rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    ch = channels.get(record.channel_id)
                    sc = schemas.get(ch.schema_id) if ch else None
                    if ch is None or sc is None:
                        continue
                    records.append((ch.topic, sc.name, record.log_time, record.data))
            problem = "summary unreadable, records read as a stream"
        except Exception as exc:
            problem = (
                f"damaged or truncated at byte {stream.tell()} of {path.stat().st_size} "
                f"({type(exc).__name__}: {str(exc) or 'unexpected end of file'}); read up to there"
            )
    types = {
        ch.topic: schemas[ch.schema_id].name for ch in channels.values() if ch.schema_id in schemas
    }
    defs = {s.name: s.data.decode("utf-8", "replace") for s in schemas.values()}
    return Recovered(types, defs, records, problem)


def read_file_into(out: BagContents, path: Path, topics: set[str] | None = None) -> None:
    """Read one storage file into ``out``; problems become issues naming the file (a damaged
    MCAP segment's with the count of :func:`recover_mcap`, as ``bag info`` reports it)."""
    file = str(path)
    out.files.append(file)
    recovered = None
    try:
        if path.stat().st_size == 0:
            out.issues.append(BagIssue(file, "empty file (0 bytes)"))
            return
        types, defs, records = _read_with_rosbags(path)
    except Exception as exc:
        if path.suffix != ".mcap":
            out.issues.append(BagIssue(file, f"unreadable: {type(exc).__name__}: {exc}"))
            return
        recovered = recover_mcap(path)
        types, defs, records = recovered.types, recovered.defs, recovered.records
    out.types.update(types)
    for msgtype, text in defs.items():
        out.msgdefs.setdefault(msgtype, text)
    store = _typestore_for(defs, out.issues, file)
    _decode_into(out, records, store, file, topics)
    if recovered is not None:
        out.issues.append(BagIssue(file, recovered.problem, recovered=recovered.recovered))


def not_a_bag(path: Path) -> BagReadError:
    """The error for a path that is neither a bag directory nor a storage file: missing, a
    Rerun recording (pointed to `fence-sorter views`) or another file."""
    if not path.exists():
        return BagReadError(f"{path}: no such bag (directory or .mcap/.db3 file)")
    if path.suffix == ".rrd":
        return BagReadError(
            f"{path}: a Rerun recording, not a bag (view it with `fence-sorter views {path}`)"
        )
    return BagReadError(f"{path}: not a bag (expected a directory, .mcap or .db3 file)")


def read_bag(path: Path | str, topics: Iterable[str] | None = None) -> BagContents:
    """Read every readable message of a bag directory or storage file.

    Raises:
        BagReadError: the path does not exist or is neither a bag directory nor a storage file.

    """
    path = Path(path)
    wanted = set(topics) if topics is not None else None
    out = BagContents(path)
    if path.is_file():
        if path.suffix not in STORAGE_SUFFIXES:
            raise not_a_bag(path)
        read_file_into(out, path, wanted)
        return _readable(out)
    if not path.is_dir():
        raise not_a_bag(path)
    files, out.expected_counts = bag_files(path, out.issues)
    staging = path / STAGING_DIR
    unclosed = sorted(staging.glob("*/*.mcap")) if staging.is_dir() else []
    if not files and not unclosed:
        raise BagReadError(f"{path}: no storage files (.mcap/.db3) in the bag directory")
    for f in files:
        read_file_into(out, f, wanted)
    for f in unclosed:
        before = len(out.issues)
        read_file_into(out, f, wanted)
        if len(out.issues) == before:
            out.issues.append(BagIssue(str(f), "segment left open by the recorder (read)"))
    return _readable(out)


def _readable(out: BagContents) -> BagContents:
    """``out`` if anything of it could be read; BagReadError naming the first problem when
    no message was read and no storage file read cleanly (a clean bag with no messages is
    readable)."""
    damaged = {issue.file for issue in out.issues}
    if not out.messages and all(f in damaged for f in out.files):
        problems = [i for i in out.issues if i.file in damaged and i.file in out.files]
        first = problems[0] if problems else out.issues[0]
        more = f" (and {len(out.issues) - 1} more problems)" if len(out.issues) > 1 else ""
        raise BagReadError(f"{out.path}: nothing readable: {first}{more}")
    return out
