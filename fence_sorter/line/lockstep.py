"""The line in lockstep (ROS-free): one owner of the clock, each unit on a side of its own.

A unit of a line must be able to run in a process, or on a host, of its own. Two state
machines split :class:`~fence_sorter.line.multi_unit.LinePlant` along that seam:

- the owner (:class:`LockstepOwner`): the induction, the recirculation and the line clock. It
  is a ``LinePlant`` whose units are :class:`RemoteUnit` stand-ins: each call the plant makes
  on a unit becomes a command on that unit's ordered stream (:class:`Command`, numbered), and
  the calls that need an answer wait for the unit's reply. Every traffic record the plant
  applies to its :class:`~fence_sorter.line.traffic.TrafficView` goes to every unit on the same
  stream, in the plant's order, so that each unit keeps a view equal to the owner's.
- a unit (:class:`UnitSide`): one :class:`~fence_sorter.line.unit.LineUnit` with its own
  ``TrafficView``. It applies its commands in sequence order (a command that arrives early
  waits for the ones before it), takes the hand-offs of its upstream link as they arrive, and
  puts out replies for the owner and hand-offs for its downstream link.

One step of the clock at time t: the owner announces and merges parcels (:class:`Scan` and
traffic records to every unit), then, in the plant's order of parcels, tells a unit that a
parcel's front reached its scan line (:class:`Deliver`; the unit routes the hand-off it got on
its upstream link and answers :class:`Delivered`); then every unit gets :class:`Step` (t, t +
dt): it checks its deadlines on its view at t, advances its simulation to t + dt and answers
:class:`Done` with the records it made. The owner applies the deadline records of every unit,
then the records of every unit's advance, in unit order (the plant's order), and only then
steps its clock. Each unit works on its own state and its own copy of the traffic, and the
order in which the owner applies the answers is the plant's: the figures of a lockstep line
equal those of ``LinePlant`` exactly (``test/line/test_lockstep.py``), whatever carries the
commands, as long as nothing is lost.

A transport carries the commands, replies and hand-offs (:class:`Links`): :class:`LocalLinks`
in one process; the line's ROS 2 nodes over DDS.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, is_dataclass

from fence_sorter.inputs import ParcelSpec
from fence_sorter.line.handoff import INDUCTION, RECIRCULATION, Failed, HandOff, Sorted
from fence_sorter.line.line_file import LineSpec
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.routing import Booking, Decision, Track
from fence_sorter.line.traffic import Announce, Hold, Left, TrafficView
from fence_sorter.line.unit import LineUnit, Record, Traffic, UnitReply

__all__ = [
    "Command",
    "Deliver",
    "Delivered",
    "Done",
    "Figures",
    "Links",
    "LocalLinks",
    "LockstepOwner",
    "RemoteUnit",
    "Report",
    "Scan",
    "StartGate",
    "Step",
    "Tick",
    "UnitSide",
    "WarmUp",
    "Warmed",
    "decode",
    "encode",
    "make_unit",
]


# -- owner -> unit ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Scan:
    """The induction scanned a parcel for a pass: its spec and the destination read."""

    parcel_id: int
    passes: int
    spec: ParcelSpec
    destination: str


@dataclass(frozen=True)
class Tick:
    """The owner's clock reached ``t`` (the views drop bookings whose strokes are over)."""

    t: float


@dataclass(frozen=True)
class Deliver:
    """The parcel's front reached the unit's scan line at ``t``: route the hand-off of this
    parcel, pass and sender that came on the upstream link."""

    parcel_id: int
    passes: int
    from_unit: int
    t: float


@dataclass(frozen=True)
class Step:
    """Check the deadlines at ``t``, then advance the simulation to ``t_next``."""

    t: float
    t_next: float


@dataclass(frozen=True)
class Report:
    """Send the unit's figures at sim time ``t``."""

    t: float


@dataclass(frozen=True)
class WarmUp:
    """Fill the planner's cache from these parcels (``LinePlant.warm_up`` on one unit)."""

    specs: tuple[ParcelSpec, ...]
    time_budget: float


@dataclass(frozen=True)
class Command:
    """One command on a unit's ordered stream; ``seq`` counts from 0 per unit."""

    seq: int
    body: object  # Scan | Tick | Deliver | Step | Report | a traffic record


# -- unit -> owner ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Delivered:
    """A unit's answer to :class:`Deliver` (the fields of a
    :class:`~fence_sorter.line.unit.UnitReply`)."""

    parcel_id: int
    refusal: str
    decision: Decision | None
    booking: Booking | None
    records: tuple[Record, ...]


@dataclass(frozen=True)
class Done:
    """A unit's answer to :class:`Step`: the records its deadlines and its advance made."""

    t: float
    deadline_records: tuple[Record, ...]
    advance_records: tuple[Record, ...]


@dataclass(frozen=True)
class Figures:
    """A unit's answer to :class:`Report`: ``LineUnit.figures`` and what the line summary
    reads beside it."""

    t: float
    figures: dict
    strokes: tuple[tuple[float, float], ...]
    max_impact_speed: float
    max_accel: float


@dataclass(frozen=True)
class Warmed:
    """A unit's answer to :class:`WarmUp`: the load classes its planner now knows."""

    classes: int


Reply = Delivered | Done | Figures | Warmed


# -- on the wire ------------------------------------------------------------------------------
def _kinds() -> dict[str, type]:
    return {
        c.__name__: c
        for c in (
            Command, Scan, Tick, Deliver, Step, Report, Delivered, Done, Figures, Announce,
            Hold, Left, Booking, HandOff, Sorted, Failed, Track, ParcelSpec, Decision, WarmUp,
            Warmed,
        )
    }  # fmt: skip


def _enc(o: object) -> object:
    if is_dataclass(o) and not isinstance(o, type):
        return {"_": type(o).__name__, **{f.name: _enc(getattr(o, f.name)) for f in fields(o)}}
    if isinstance(o, list | tuple):
        return [_enc(v) for v in o]
    if isinstance(o, dict):
        return {str(k): _enc(v) for k, v in o.items()}
    return o


def _tuples(o: object) -> object:
    return tuple(_tuples(v) for v in o) if isinstance(o, list) else o


def _dec(o: object, kinds: dict[str, type]) -> object:
    if isinstance(o, list):
        return [_dec(v, kinds) for v in o]
    if not isinstance(o, dict):
        return o
    if "_" not in o:
        return {k: _dec(v, kinds) for k, v in o.items()}
    cls = kinds[o["_"]]
    args = {}
    for f in fields(cls):
        v = _dec(o[f.name], kinds)
        args[f.name] = _tuples(v) if str(f.type).startswith("tuple") else v
    return cls(**args)


def encode(o: object) -> str:
    """A command, reply or record as JSON text: floats as Python writes them (repr: they read
    back bit for bit), inf and NaN as JSON5's Infinity and NaN, which :func:`decode` takes."""
    return json.dumps(_enc(o), separators=(",", ":"))


def decode(text: str) -> object:
    """The object :func:`encode` wrote (KeyError or TypeError on text it did not write)."""
    return _dec(json.loads(text), _kinds())


# -- a unit's side ---------------------------------------------------------------------------
def make_unit(line: LineSpec, index: int, cfg: LineRunConfig) -> LineUnit:
    """The unit ``index`` of ``line`` as the plant builds it."""
    u = line.units[index]
    return LineUnit(
        u, index, len(line.units), line.width, line.speed, line.planner, cfg.dt, cfg.guard
    )


class UnitSide:
    """One unit of a lockstep line: commands in (:meth:`on_command`), hand-offs of the
    upstream link in (:meth:`on_handoff`); each returns what the unit puts out: replies for
    the owner and :class:`~fence_sorter.line.handoff.HandOff` records for the downstream link."""

    def __init__(self, unit: LineUnit):
        self.unit = unit
        self.view = TrafficView(unit.v)
        self.next_seq = 0
        self.early: dict[int, Command] = {}  # commands ahead of the next in sequence
        self.inbox: dict[tuple[int, int, int], HandOff] = {}  # (id, passes, from) -> hand-off
        self.waiting: Deliver | None = None  # a Deliver whose hand-off has not come yet
        self.arrived = 0  # hand-offs that came on the upstream link
        self.foreign = 0  # hand-offs on the link not addressed to this unit

    @property
    def blocked(self) -> bool:
        """True while a Deliver waits for its hand-off (later commands wait behind it)."""
        return self.waiting is not None

    def on_handoff(self, h: HandOff) -> list[object]:
        if h.to_unit != self.unit.index:
            self.foreign += 1
            return []
        self.arrived += 1
        self.inbox[(h.parcel_id, h.passes, h.from_unit)] = h
        w = self.waiting
        if w is not None and (w.parcel_id, w.passes, w.from_unit) in self.inbox:
            self.waiting = None
            return [*self._deliver(w), *self._drain()]
        return []

    def on_command(self, cmd: Command) -> list[object]:
        if cmd.seq < self.next_seq or cmd.seq in self.early:
            return []  # a repeat of one already taken
        self.early[cmd.seq] = cmd
        return self._drain()

    def _drain(self) -> list[object]:
        out: list[object] = []
        while self.waiting is None and self.next_seq in self.early:
            cmd = self.early.pop(self.next_seq)
            self.next_seq += 1
            out.extend(self._apply(cmd.body))
        return out

    def _apply(self, body: object) -> list[object]:
        u = self.unit
        if isinstance(body, Scan):
            u.announce(body.parcel_id, body.passes, body.spec, body.destination)
            return []
        if isinstance(body, Tick):
            self.view.tick(body.t)
            return []
        if isinstance(body, Deliver):
            if (body.parcel_id, body.passes, body.from_unit) not in self.inbox:
                self.waiting = body
                return []
            return self._deliver(body)
        if isinstance(body, Step):
            traffic = self.view.traffic()
            late = u.deadlines(body.t, traffic)
            adv = u.advance(body.t_next, stamp=body.t)
            done = Done(body.t, tuple(late), tuple(adv))
            return [*_downstream(late), *_downstream(adv), done]
        if isinstance(body, WarmUp):
            loads = [sp.to_parcel_params() for sp in body.specs]
            return [Warmed(u.planner.warm_up(loads, time_budget=body.time_budget))]
        if isinstance(body, Report):
            return [
                Figures(
                    body.t, u.figures(body.t), tuple(u.strokes), u.max_impact_speed, u.max_accel
                )
            ]
        self.view.apply(body)  # a traffic record
        return []

    def _deliver(self, d: Deliver) -> list[object]:
        h = self.inbox.pop((d.parcel_id, d.passes, d.from_unit))
        r = self.unit.receive(h, d.t, self.view.traffic())
        reply = Delivered(h.parcel_id, r.refusal, r.decision, r.booking, tuple(r.records))
        return [*_downstream(r.records), reply]


def _downstream(records) -> list[HandOff]:
    return [r for r in records if isinstance(r, HandOff)]


# -- the transport ---------------------------------------------------------------------------
class Links:
    """What carries a lockstep line's messages: :meth:`send` a command to unit k,
    :meth:`wait` for unit k's next reply, :meth:`hand_off` a record on its link (the induction's
    to the first unit; the units send their own)."""

    def send(self, k: int, body: object) -> None:
        raise NotImplementedError

    def wait(self, k: int) -> Reply:
        raise NotImplementedError

    def hand_off(self, h: HandOff) -> None:
        raise NotImplementedError


@dataclass
class LocalLinks(Links):
    """The units' sides in this process: commands, replies and hand-offs handed over in
    memory. ``recirculation`` collects the last unit's hand-offs (the owner's end of that
    link)."""

    sides: list[UnitSide]
    seq: list[int] = field(default_factory=list)
    replies: list[list[Reply]] = field(default_factory=list)
    recirculation: list[HandOff] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.seq = [0] * len(self.sides)
        self.replies = [[] for _ in self.sides]

    def send(self, k: int, body: object) -> None:
        cmd = Command(self.seq[k], body)
        self.seq[k] += 1
        self._route(k, self.sides[k].on_command(cmd))

    def wait(self, k: int) -> Reply:
        if not self.replies[k]:
            raise RuntimeError(f"unit {k} owes no reply (blocked={self.sides[k].blocked})")
        return self.replies[k].pop(0)

    def hand_off(self, h: HandOff) -> None:
        if h.to_unit == RECIRCULATION:
            self.recirculation.append(h)
            return
        self._route(h.to_unit, self.sides[h.to_unit].on_handoff(h))

    def _route(self, k: int, out: list[object]) -> None:
        for o in out:
            if isinstance(o, HandOff):
                self.hand_off(o)
            else:
                self.replies[k].append(o)


# -- the owner -------------------------------------------------------------------------------
class StartGate:
    """The owner's start gate: the first step waits until every unit of the line, on this host
    or another, said it is ready (its writers matched their readers) and the owner's writers
    matched theirs: the commands of each unit, the induction's link to the first one."""

    def __init__(self, names: Sequence[str]):
        self.names = tuple(names)
        self.ready: set[int] = set()

    def say_ready(self, k: int) -> None:
        """Unit ``k`` said ready (an index outside the line is ignored)."""
        if 0 <= k < len(self.names):
            self.ready.add(k)

    def missing(self, commands_matched: Sequence[bool], induction_matched: bool) -> list[str]:
        """The names of the units the line still waits for, in line order (empty: open)."""
        out = [
            n
            for k, n in enumerate(self.names)
            if k not in self.ready or not commands_matched[k] or (k == 0 and not induction_matched)
        ]
        return out

    def timeout_message(self, timeout: float, missing: Sequence[str]) -> str:
        """The one line of a start that did not come within ``timeout`` [s]."""
        return (
            f"not every unit of the line answered within start_timeout {timeout:g} s; "
            f"missing: {', '.join(missing)} (started on no host, or unreachable)"
        )


class RemoteUnit:
    """The plant's stand-in for a unit on a side of its own: its calls become commands."""

    def __init__(self, unit: LineUnit, links: Links):
        self.links = links
        self.spec = unit.spec
        self.index = unit.index
        self.upstream = unit.upstream
        self.downstream = unit.downstream
        self.planner = unit.planner
        self._fig: Figures | None = None

    def announce(self, parcel_id: int, passes: int, spec=None, destination: str = "") -> None:
        self.links.send(self.index, Scan(parcel_id, passes, spec, destination))

    def receive(self, h: HandOff, t: float, traffic: Traffic | None = None) -> UnitReply:
        """The unit routes the hand-off with its own copy of the traffic (``traffic`` unused)."""
        if h.from_unit == INDUCTION:
            self.links.hand_off(h)
        self.links.send(self.index, Deliver(h.parcel_id, h.passes, h.from_unit, t))
        r = self.links.wait(self.index)
        assert isinstance(r, Delivered) and r.parcel_id == h.parcel_id, r
        return UnitReply(r.refusal, r.decision, r.booking, list(r.records))

    def report(self, t: float) -> None:
        self.links.send(self.index, Report(t))
        r = self.links.wait(self.index)
        assert isinstance(r, Figures), r
        self._fig = r

    # what the plant's summary reads (after :meth:`report`)
    def figures(self, t: float) -> dict:
        return dict(self._fig.figures)

    def _f(self, key: str):
        return self._fig.figures[key]

    received = property(lambda self: self._f("handoffs_in"))
    sent = property(lambda self: self._f("handoffs_out"))
    lost = property(lambda self: self._f("handoffs_lost"))
    refused_handoffs = property(lambda self: dict(self._f("handoffs_refused")))
    declined = property(lambda self: dict(self._f("declined")))
    intrusions = property(lambda self: self._f("swept_sector_intrusions"))
    strokes = property(lambda self: list(self._fig.strokes))
    max_impact_speed = property(lambda self: self._fig.max_impact_speed)
    max_accel = property(lambda self: self._fig.max_accel)


class _SharedView(TrafficView):
    """The owner's view: every record and tick it applies goes to every unit as well."""

    def __init__(self, speed: float, links: Links, n_units: int):
        super().__init__(speed)
        self.links = links
        self.n = n_units

    def apply(self, rec: object) -> None:
        super().apply(rec)
        for k in range(self.n):
            self.links.send(k, rec)

    def tick(self, t: float) -> None:
        super().tick(t)
        for k in range(self.n):
            self.links.send(k, Tick(t))


class LockstepOwner(LinePlant):
    """The induction, the recirculation and the clock of a line whose units run elsewhere
    (behind ``links``); :meth:`run` to the drain gives ``LinePlant``'s summary."""

    def __init__(self, line: LineSpec, cfg: LineRunConfig, links: Links):
        super().__init__(line, cfg)
        self.transport = links
        self.units = [RemoteUnit(u, links) for u in self.units]
        self.view = _SharedView(self.v, links, len(self.units))

    def step(self) -> None:
        self._announce()
        self._merge()
        self._hand_offs()
        t_next = self.t + self.cfg.dt
        for u in self.units:
            self.transport.send(u.index, Step(self.t, t_next))
        done = []
        for u in self.units:
            r = self.transport.wait(u.index)
            assert isinstance(r, Done) and r.t == self.t, r
            done.append(r)
        for u, d in zip(self.units, done, strict=True):
            for rec in d.deadline_records:
                self._on_record(u, rec)
        records: list[Record] = []
        for u, d in zip(self.units, done, strict=True):
            for rec in d.advance_records:
                records.append(rec)
                self._on_record(u, rec)
        self._close_step(t_next, records)

    def warm_up(self, time_budget: float = math.inf) -> None:
        """``LinePlant.warm_up`` on every unit's side: each warms its planner with the stream's
        first parcels (complete by default, as in process; ``time_budget`` [s] is each
        unit's)."""
        specs = tuple(p.spec for p in self.parcels[:200])
        for u in self.units:
            self.transport.send(u.index, WarmUp(specs, time_budget))
        for u in self.units:
            r = self.transport.wait(u.index)
            assert isinstance(r, Warmed), r

    def summary(self) -> dict:
        for u in self.units:
            u.report(self.t)
        return super().summary()
