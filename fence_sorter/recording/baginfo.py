"""What ``ros2 bag info`` shows about a bag, without ROS: files, size, storage, duration, start
and end, message counts per topic with types, compression, and the health of each segment.

Each storage file is inspected on its own: an MCAP file through its summary (statistics, chunk
indexes) when it has one, else read as a stream up to its first damaged record
(:mod:`fence_sorter.recording.bagread`); a sqlite3 file through rosbags. A segment that is
missing, empty, unclosed or damaged is named with what is wrong, and the counts of the others
stand. metadata.yaml's declared counts are compared with the counts found.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import yaml
from rosbags.rosbag2 import Reader

from fence_sorter.recording.bagread import (
    STORAGE_SUFFIXES,
    BagIssue,
    BagReadError,
    bag_files,
    not_a_bag,
    recover_mcap,
)
from fence_sorter.recording.writer import STAGING_DIR


@dataclass
class SegmentInfo:
    """One storage file: size, messages, time span, chunk compression and its health."""

    file: str
    size: int
    messages: int = 0
    start_ns: int | None = None
    end_ns: int | None = None
    compression: str = ""  # MCAP chunk compression ("zstd", "lz4"; "" none)
    health: str = "ok"  # "ok", or what is wrong (and how much was still read)
    counts: dict[str, int] = field(default_factory=dict)


@dataclass
class BagInfo:
    """The bag as ``ros2 bag info`` describes it, plus per-segment health."""

    path: str
    storage: str
    size: int
    segments: list[SegmentInfo]
    types: dict[str, str]  # topic -> type
    counts: dict[str, int]  # topic -> messages found
    declared_counts: dict[str, int]  # topic -> metadata.yaml's count
    compression_format: str  # metadata.yaml's (rosbag2 file/message compression)
    compression_mode: str
    issues: list[str]

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    @property
    def start_ns(self) -> int | None:
        starts = [s.start_ns for s in self.segments if s.start_ns is not None]
        return min(starts) if starts else None

    @property
    def end_ns(self) -> int | None:
        ends = [s.end_ns for s in self.segments if s.end_ns is not None]
        return max(ends) if ends else None

    @property
    def duration_ns(self) -> int:
        start, end = self.start_ns, self.end_ns
        return 0 if start is None or end is None else end - start

    @property
    def healthy(self) -> bool:
        return not self.issues and all(s.health == "ok" for s in self.segments)

    def to_json(self) -> dict:
        out = asdict(self)
        out.update(
            messages=self.messages,
            start_ns=self.start_ns,
            end_ns=self.end_ns,
            duration_ns=self.duration_ns,
            healthy=self.healthy,
        )
        return out


def _mcap_segment(path: Path, types: dict[str, str]) -> SegmentInfo:
    from mcap.reader import make_reader  # lazy: mcap (40 ms), only to read a bag's chunks

    seg = SegmentInfo(str(path), path.stat().st_size)
    if seg.size == 0:
        seg.health = "empty file (0 bytes)"
        return seg
    summary = None
    try:
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
    except Exception as exc:  # damaged footer or summary: read it as a stream below
        seg.health = f"summary unreadable ({type(exc).__name__})"
    if summary is not None and summary.statistics is not None:
        stats = summary.statistics
        schemas = summary.schemas
        for cid, channel in summary.channels.items():
            if channel.schema_id in schemas:
                types[channel.topic] = schemas[channel.schema_id].name
            n = stats.channel_message_counts.get(cid, 0)
            if n:
                seg.counts[channel.topic] = seg.counts.get(channel.topic, 0) + n
        seg.messages = stats.message_count
        if stats.message_count:
            seg.start_ns, seg.end_ns = stats.message_start_time, stats.message_end_time
        seg.compression = ",".join(sorted({c.compression for c in summary.chunk_indexes})) or ""
        return seg
    rec = recover_mcap(path)
    types.update(rec.types)
    seg.counts = dict(Counter(topic for topic, _, _, _ in rec.records))
    seg.messages = rec.recovered
    if rec.records:
        stamps = [t for _, _, t, _ in rec.records]
        seg.start_ns, seg.end_ns = min(stamps), max(stamps)
    seg.health = f"{rec.problem}; {rec.recovered} messages recovered"
    return seg


def _sqlite_segment(path: Path, types: dict[str, str]) -> SegmentInfo:
    seg = SegmentInfo(str(path), path.stat().st_size)
    try:
        with Reader(path) as reader:
            for c in reader.connections:
                types[c.topic] = c.msgtype
            counts: Counter[str] = Counter()
            stamps = []
            for c, t, _ in reader.messages():
                counts[c.topic] += 1
                stamps.append(t)
    except Exception as exc:
        seg.health = f"unreadable: {type(exc).__name__}: {exc}"
        return seg
    seg.counts, seg.messages = dict(counts), len(stamps)
    if stamps:
        seg.start_ns, seg.end_ns = min(stamps), max(stamps)
    return seg


def bag_info(path: Path | str) -> BagInfo:
    """Inspect a bag directory (or one storage file).

    Raises:
        BagReadError: the path is neither a bag directory nor a storage file.
    """
    path = Path(path)
    issues: list[BagIssue] = []
    declared: dict[str, int] = {}
    meta: dict = {}
    if path.is_file() and path.suffix in STORAGE_SUFFIXES:
        files = [path]
    elif path.is_dir():
        files, declared = bag_files(path, issues)
        staging = path / STAGING_DIR
        if staging.is_dir():
            for f in sorted(staging.glob("*/*.mcap")):
                files.append(f)
                issues.append(BagIssue(str(f), "segment left open by the recorder"))
        if not files:
            raise BagReadError(f"{path}: no storage files (.mcap/.db3) in the bag directory")
        try:
            doc = yaml.safe_load((path / "metadata.yaml").read_text(encoding="utf-8"))
            meta = doc["rosbag2_bagfile_information"]
        except Exception:  # reported by bag_files already
            meta = {}
    else:
        raise not_a_bag(path)
    types: dict[str, str] = {}
    segments = [
        _mcap_segment(f, types) if f.suffix == ".mcap" else _sqlite_segment(f, types)
        for f in files
    ]
    counts: Counter[str] = Counter()
    for seg in segments:
        counts.update(seg.counts)
    for topic, n in declared.items():
        if counts.get(topic, 0) != n:
            issues.append(
                BagIssue(
                    str(path / "metadata.yaml"),
                    f"declares {n} messages on {topic}, {counts.get(topic, 0)} found",
                )
            )
    for topic in declared:
        counts.setdefault(topic, 0)
    storage = str(meta.get("storage_identifier") or files[0].suffix.lstrip(".")).replace(
        "db3", "sqlite3"
    )
    return BagInfo(
        path=str(path),
        storage=storage,
        size=sum(s.size for s in segments),
        segments=segments,
        types=types,
        counts=dict(sorted(counts.items())),
        declared_counts=declared,
        compression_format=str(meta.get("compression_format") or ""),
        compression_mode=str(meta.get("compression_mode") or ""),
        issues=[str(i) for i in issues],
    )


def _time(ns: int | None) -> str:
    if ns is None:
        return "-"
    when = datetime.fromtimestamp(ns / 1e9, tz=UTC).strftime("%b %d %Y %H:%M:%S")
    return f"{when}.{ns % 1_000_000_000:09d} ({ns / 1e9:.9f})"


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{n} B"
        n /= 1024
    return f"{n} B"


def format_info(info: BagInfo) -> str:
    """The text of ``fence-sorter bag info``, laid out as ``ros2 bag info``'s."""
    chunk = ",".join(sorted({s.compression for s in info.segments if s.compression})) or "none"
    lines = [
        f"Files:             {Path(info.segments[0].file).name}",
        *(f"                   {Path(s.file).name}" for s in info.segments[1:]),
        f"Bag size:          {_size(info.size)}",
        f"Storage id:        {info.storage}",
        f"Duration:          {info.duration_ns / 1e9:.9f}s",
        f"Start:             {_time(info.start_ns)}",
        f"End:               {_time(info.end_ns)}",
        f"Messages:          {info.messages}",
        f"Compression:       {info.compression_format or 'none'}"
        f" (mode {info.compression_mode or 'none'}); MCAP chunks: {chunk}",
    ]
    width = max((len(t) for t in info.counts), default=0)
    for i, (topic, n) in enumerate(info.counts.items()):
        head = "Topic information: " if i == 0 else "                   "
        lines.append(
            f"{head}Topic: {topic:<{width}} | Type: {info.types.get(topic, '?')} | Count: {n}"
            " | Serialization Format: cdr"
        )
    lines.append("Segments:")
    for s in info.segments:
        span = f"{s.start_ns / 1e9:.3f}-{s.end_ns / 1e9:.3f} s" if s.start_ns is not None else "-"
        lines.append(
            f"  {Path(s.file).name}: {_size(s.size)}, {s.messages} messages, {span}, "
            f"chunks {s.compression or 'uncompressed'}: {s.health}"
        )
    lines.extend(f"Issue: {text}" for text in info.issues)
    return "\n".join(lines)
