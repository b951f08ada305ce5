"""The line summary of a line's bag (``fence-sorter run --line LINE --bag DIR``), from the bag
alone (ROS-free).

A line over DDS is a :class:`~fence_sorter.line.lockstep.LockstepOwner` (induction,
recirculation, clock) and units that answer its commands; the summary is the owner's state
after the drain, and every input of that state is on the wire: the owner's set-up
(/line/setup: the line file's text, parcels, seed, rate, guard, clock step, warm-up) and every
reply of every unit (/<unit>/replies). :func:`analyze_line_bag` replays the owner on the
recorded replies (:class:`BagLinks`): the same code the live owner ran, fed the same answers,
so it computes the same summary, every count and float bit for bit. The wall-clock fields
(``wall_time_s``, ``real_time_factor``, ``reply_wait_max_s``, ``pacing``: the paced clock's
deadline counts, ``handoff_latency``: the hand-offs' transit, and each unit's
``units_down.<unit>.downtime_wall_s``) are the live run's, read from /line/summary (NaN when the
bag has no summary).

Two checks say that the bag holds the whole run: each command the replayed owner sends must be
the one the bag holds under the same number on /<unit>/commands (text equal), and the computed
summary must equal the live one of /line/summary field by field.
"""

from __future__ import annotations

import json
import math
import re
import tempfile
from collections import defaultdict, deque
from dataclasses import dataclass, field, fields
from pathlib import Path

from fence_sorter.inputs import ParcelSpec
from fence_sorter.jsonsafe import json_safe
from fence_sorter.line.handoff import HandOff
from fence_sorter.line.line_file import LineSpec, load_line
from fence_sorter.line.lockstep import (
    Command,
    Deliver,
    Delivered,
    Done,
    Figures,
    Links,
    LockstepOwner,
    Report,
    Step,
    UnitSide,
    Warmed,
    WarmUp,
    decode,
    encode,
    make_unit,
    split_batch,
)
from fence_sorter.line.multi_unit import LineRunConfig
from fence_sorter.recording.bagread import BagContents, read_bag
from fence_sorter.recording.topics import (
    LINE_INDUCTION,
    LINE_SETUP,
    LINE_SUMMARY,
    line_unit_topics,
)
from fence_sorter.stamps import time_to_sec

#: the summary's wall-clock fields: the live run's (the replay's own wall time is not the run's);
#: a field inside a field as its keys joined by dots, ``*`` for every key at that level
WALL_FIELDS = (
    "wall_time_s",
    "real_time_factor",
    "reply_wait_max_s",
    "pacing",
    "handoff_latency",
    "units_down.*.downtime_wall_s",
)
_SEQ = re.compile(r'^\{"_":"Command","seq":(\d+),')


class LineBagError(ValueError):
    """A bag that is no line bag, or misses what the replay needs (one line)."""


@dataclass
class LineBagReport:
    summary: dict
    live: dict | None  # /line/summary, the run's own
    differences: dict[str, tuple]  # field -> (computed, live), wall-clock fields aside
    commands_checked: int
    commands_differing: list[str] = field(default_factory=list)  # "<unit> seq N", first ones
    issues: list[str] = field(default_factory=list)  # the bag's own (bagread)

    @property
    def agrees_with_live(self) -> bool | None:
        return None if self.live is None else not self.differences

    @property
    def ok(self) -> bool:
        return (
            not self.issues and not self.commands_differing and self.agrees_with_live is not False
        )


class BagLinks(Links):
    """The units' side of a lockstep line as the bag recorded it: :meth:`wait` returns the
    recorded reply to the command just sent (a Deliver's by parcel, a Step's by time), and
    every command sent is compared with the recorded one of the same number."""

    def __init__(self, names: list[str], commands: list[dict[int, str]], replies: list[list]):
        self.names = names
        self.commands = commands
        self.seq = [0] * len(names)
        self.expect: list[deque] = [deque() for _ in names]
        self.delivered: list[dict[int, deque]] = [defaultdict(deque) for _ in names]
        self.done: list[dict[float, Done]] = [{} for _ in names]
        self.other: list[dict[type, deque]] = [defaultdict(deque) for _ in names]
        for k, rs in enumerate(replies):
            for r in rs:
                if isinstance(r, Delivered):
                    self.delivered[k][r.parcel_id].append(r)
                elif isinstance(r, Done):
                    self.done[k][r.t] = r
                else:
                    self.other[k][type(r)].append(r)
        self.checked = 0
        self.differing: list[str] = []

    def send(self, k: int, body: object) -> None:
        seq = self.seq[k]
        self.seq[k] += 1
        self.checked += 1
        if self.commands[k].get(seq) != encode(Command(seq, body)) and len(self.differing) < 10:
            self.differing.append(f"{self.names[k]} seq {seq}")
        if isinstance(body, Deliver):
            self.expect[k].append((Delivered, body.parcel_id, seq))
        elif isinstance(body, Step):
            self.expect[k].append((Done, body.t, seq))
        elif isinstance(body, Report):
            self.expect[k].append((Figures, None, seq))
        elif isinstance(body, WarmUp):
            self.expect[k].append((Warmed, None, seq))

    def wait(self, k: int):
        kind, key, seq = self.expect[k].popleft()
        if kind is Delivered:
            found = self.delivered[k].get(key)
            reply = found.popleft() if found else None
        elif kind is Done:
            reply = self.done[k].pop(key, None)
        else:
            found = self.other[k].get(kind)
            reply = found.popleft() if found else None
        if reply is None:
            raise LineBagError(
                f"the bag has no reply of {self.names[k]} to its command {seq} "
                f"({kind.__name__} missing on {line_unit_topics(self.names[k])[1]})"
            )
        return reply

    def hand_off(self, h: HandOff) -> None:
        """The induction's hand-off: on /line/handoffs in the bag; the replay needs none."""


def _texts(bag: BagContents, topic: str) -> list[str]:
    return [str(m.msg.data) for m in bag.by_topic(topic)]


def _config(d: dict) -> LineRunConfig:
    known = {f.name for f in fields(LineRunConfig)}
    return LineRunConfig(**{k: v for k, v in d.items() if k in known})


def is_line_bag(bag: BagContents) -> bool:
    return bool(bag.by_topic(LINE_SETUP))


@dataclass
class LineRecords:
    """What a line's bag holds for a replay: the line (from the recorded file text), the run's
    configuration, each unit's recorded commands (by number) and replies (decoded)."""

    line: LineSpec
    cfg: LineRunConfig
    warm_up: bool
    commands: list[dict[int, str]]
    replies: list[list]
    upstream: list[list[HandOff]]  # the hand-offs recorded on each unit's upstream link

    @property
    def names(self) -> list[str]:
        return [u.name for u in self.line.units]


def line_records(bag: BagContents) -> LineRecords:
    """The records of a line's bag; LineBagError when it holds no /line/setup."""
    setups = _texts(bag, LINE_SETUP)
    if not setups:
        raise LineBagError(f"{bag.path}: no {LINE_SETUP} in the bag: not a line's bag")
    setup = json.loads(setups[-1])
    with tempfile.TemporaryDirectory(prefix="fence_sorter_line_bag_") as tmp:
        path = Path(tmp) / setup["line_file"]
        path.write_text(setup["line_text"], encoding="utf-8")
        line = load_line(path)
    commands: list[dict[int, str]] = []
    replies: list[list] = []
    upstream: list[list[HandOff]] = []
    for k, u in enumerate(line.units):
        link = LINE_INDUCTION if k == 0 else line_unit_topics(line.units[k - 1].name)[2]
        upstream.append([handoff_from_bag(m.msg) for m in bag.by_topic(link)])
        topic_cmd, topic_rep, _ = line_unit_topics(u.name)
        cmds = {}
        for text in (t for msg in _texts(bag, topic_cmd) for t in split_batch(msg)):
            m = _SEQ.match(text)
            if m:
                cmds[int(m.group(1))] = text
        commands.append(cmds)
        replies.append([decode(t) for t in _texts(bag, topic_rep) if t.startswith("{")])
    return LineRecords(
        line, _config(setup["config"]), bool(setup.get("warm_up", True)), commands, replies,
        upstream,
    )  # fmt: skip


def handoff_from_bag(msg) -> HandOff:
    """A recorded fence_sorter_msgs/HandOff (as rosbags decodes it) -> the line's HandOff
    record, field for field as a unit takes it off the wire (``nodes.convert.handoff_from_msg``:
    the parcel's arrival time does not travel)."""
    p = msg.parcel
    spec = ParcelSpec(
        parcel_id=int(p.parcel_id), length_a=float(p.length_a), width_b=float(p.width_b),
        height=float(p.height), mass=float(p.mass), cog_offset_x=float(p.cog_offset_x),
        cog_offset_y=float(p.cog_offset_y), lateral_gap=float(p.lateral_gap),
        yaw=float(p.yaw), mu_belt=float(p.mu_belt), mu_fence=float(p.mu_fence),
        divert=bool(p.divert), scan_time=time_to_sec(p.scan_time),
        scan_position_x=float(p.scan_position_x),
    )  # fmt: skip
    return HandOff(
        parcel_id=spec.parcel_id, destination=str(p.destination), passes=int(p.passes),
        spec=spec, x=float(msg.x), y=float(msg.y), yaw=float(msg.yaw), vx=float(msg.vx),
        vy=float(msg.vy), yaw_rate=float(msg.yaw_rate), pose_time=float(msg.pose_time),
        t=time_to_sec(msg.header.stamp), from_unit=int(msg.from_unit),
        to_unit=int(msg.to_unit),
    )  # fmt: skip


class ResimLinks(BagLinks):
    """:class:`BagLinks` that also feed every recorded command to a unit simulated here
    (:class:`~fence_sorter.line.lockstep.UnitSide`), with the hand-offs recorded on its
    upstream link, and compare each reply it makes with the recorded one (as text): the
    units' states as the run had them, for a view."""

    def __init__(self, records: LineRecords):
        super().__init__(records.names, records.commands, records.replies)
        cfg = records.cfg
        self.sides = [UnitSide(make_unit(records.line, k, cfg)) for k in range(len(self.names))]
        for side, handoffs in zip(self.sides, records.upstream, strict=True):
            for h in handoffs:  # as they came on the unit's upstream link
                side.on_handoff(h)
        self.produced: list[deque] = [deque() for _ in self.names]
        self.resim_checked = 0
        self.resim_differing: list[str] = []

    def send(self, k: int, body: object) -> None:
        seq = self.seq[k]
        super().send(k, body)
        text = self.commands[k].get(seq)
        self._route(k, self.sides[k].on_command(decode(text) if text else Command(seq, body)))

    def _route(self, k: int, out: list) -> None:
        """Unit k's replies kept for :meth:`wait`; its hand-offs are the recorded ones the
        next unit already has."""
        self.produced[k].extend(o for o in out if not isinstance(o, HandOff))

    def wait(self, k: int):
        reply = super().wait(k)
        mine = self.produced[k].popleft() if self.produced[k] else None
        self.resim_checked += 1
        if (mine is None or encode(mine) != encode(reply)) and len(self.resim_differing) < 10:
            self.resim_differing.append(f"{self.names[k]} {type(reply).__name__}")
        return reply


def replay(
    records: LineRecords, links: BagLinks, observers: tuple = ()
) -> tuple[dict, LockstepOwner]:
    """The owner run to the drain on ``links``: its summary (wall-clock fields 0) and itself.
    With :class:`ResimLinks` each unit stand-in gets ``line``, its simulated unit's
    :class:`~fence_sorter.line.one_fence.SortingLine` (what a view samples)."""
    owner = LockstepOwner(records.line, records.cfg, links)
    if isinstance(links, ResimLinks):
        for remote, side in zip(owner.units, links.sides, strict=True):
            remote.line = side.unit.line
    owner.observers.extend(observers)
    if records.warm_up:
        owner.warm_up()
    while owner.active() and owner.t < owner.limit():
        owner.step()
    owner.wall = 0.0
    return owner.summary(), owner


def replay_summary(bag: BagContents) -> tuple[dict, BagLinks]:
    """The owner replayed on the bag's replies: its summary (wall-clock fields 0) and the
    links (with the command check). LineBagError names what is missing."""
    records = line_records(bag)
    links = BagLinks(records.names, records.commands, records.replies)
    summary, _ = replay(records, links)
    return summary, links


def _json(v: object) -> object:
    """A summary value as its JSON text reads back (NaN and inf as None, tuples as lists)."""
    return json.loads(json.dumps(json_safe(v)))


def wall_paths(summary: dict) -> list[tuple[str, ...]]:
    """The keys to every wall-clock field (WALL_FIELDS) that ``summary`` holds, or, at its
    top level, could hold."""
    out: list[tuple[str, ...]] = []
    for name in WALL_FIELDS:
        *head, last = name.split(".")
        level: list[tuple[tuple[str, ...], dict]] = [((), summary)]
        for part in head:
            level = [
                ((*keys, k), v[k])
                for keys, v in level
                for k in (list(v) if part == "*" else [part])
                if isinstance(v.get(k), dict)
            ]
        out += [(*keys, last) for keys, v in level if not head or last in v]
    return out


def _at(d: dict, keys: tuple[str, ...], default: object = math.nan) -> object:
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def _without_wall(summary: dict) -> dict:
    """A JSON copy of ``summary`` without its wall-clock fields."""
    out = _json(summary)
    for keys in wall_paths(out):
        parent = _at(out, keys[:-1], None)
        if isinstance(parent, dict):
            parent.pop(keys[-1], None)
    return out


def with_live_wall(summary: dict, live: dict | None) -> dict:
    """``summary`` (changed in place) with each of its wall-clock fields set to the live run's
    (NaN where the live summary has none, or there is none)."""
    for keys in wall_paths(summary):
        value = _at(live, keys) if live is not None else math.nan
        _at(summary, keys[:-1])[keys[-1]] = value
    return summary


def differences(computed: dict, live: dict) -> dict[str, tuple]:
    """Top-level field -> (computed, live) of every field whose JSON differs, the wall-clock
    fields (WALL_FIELDS, at any depth) left out."""
    a_all, b_all = _without_wall(computed), _without_wall(live)
    out = {}
    for k in sorted(set(a_all) | set(b_all)):
        a, b = a_all.get(k), b_all.get(k)
        if a != b:
            out[k] = (a, b)
    return out


def analyze_line_bag(path: Path | str) -> LineBagReport:
    """Read a line's bag and compute its line summary (see the module); BagReadError when
    nothing can be read, LineBagError when it is no line bag or misses a reply."""
    bag = read_bag(path)
    try:
        summary, links = replay_summary(bag)
    except LineBagError as exc:
        if not bag.issues:
            raise
        more = f" and {len(bag.issues) - 1} more problems" if len(bag.issues) > 1 else ""
        raise LineBagError(f"{exc}; the bag: {bag.issues[0]}{more}") from None
    lives = _texts(bag, LINE_SUMMARY)
    live = json.loads(lives[-1]) if lives else None
    return LineBagReport(
        summary=with_live_wall(summary, live),
        live=live,
        differences=differences(summary, live) if live is not None else {},
        commands_checked=links.checked,
        commands_differing=links.differing,
        issues=[str(i) for i in bag.issues],
    )


def looks_like_line_bag(path: Path | str) -> bool:
    """True if the bag holds a line's set-up (/line/setup): from metadata.yaml when the bag
    is a directory with one, else from the storage file's messages."""
    path = Path(path)
    meta = path / "metadata.yaml"
    if path.is_dir() and meta.is_file():
        try:
            return f"name: {LINE_SETUP}\n" in meta.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            return False
    try:
        return is_line_bag(read_bag(path, topics=[LINE_SETUP]))
    except Exception:  # not a bag at all: the single-unit analysis says why
        return False
