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

A unit that stops answering (its process or its host is gone: :meth:`Links.wait` raises
:class:`UnitDown`) is down, and the line goes on without it: the parcels in its strokes are
lost with it (``lost_with_unit``, each named with its unit); its stand-in takes the hand-offs
meant for it, declines each ``unit_down`` and passes it on to the next unit on the unit's own
link (:meth:`Links.forward`), so that its destinations recirculate. A new process of the unit
(:meth:`Links.rejoining`) rejoins at the start of a step: its command stream starts again with
a :class:`Snapshot` of the owner's traffic and clock, and it routes the parcels announced from
then on (the stand-in keeps the ones announced before). The counts of a unit's earlier
processes are kept from their replies, so that every link still balances.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, is_dataclass, replace

from fence_sorter.inputs import ParcelSpec
from fence_sorter.line.handoff import (
    INDUCTION,
    RECIRCULATION,
    REFUSALS,
    Failed,
    HandOff,
    Sorted,
)
from fence_sorter.line.line_file import LineSpec
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.routing import UNIT_DOWN, Booking, Decision, Track
from fence_sorter.line.traffic import Announce, Hold, Left, TrafficView
from fence_sorter.line.unit import LineUnit, Record, Traffic, UnitReply

__all__ = [
    "EXIT_OWNER_GONE",
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
    "Snapshot",
    "StartGate",
    "Step",
    "Tick",
    "UnitDown",
    "UnitSide",
    "WarmUp",
    "Warmed",
    "answered",
    "decode",
    "encode",
    "join_batch",
    "split_batch",
    "make_unit",
]


#: the exit status of a unit's process (and of a runner without the owner) whose owner fell
#: silent: no command for the unit's ``owner_timeout`` once the line ran
EXIT_OWNER_GONE = 3


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
class Snapshot:
    """A new process of a unit rejoins the line at ``t``: the owner's traffic (tracks, booked
    strokes, parcels in a stroke) to start its view from, and its clock."""

    t: float
    tracks: tuple[Track, ...]
    bookings: tuple[Booking, ...]
    stroking: tuple[int, ...]


@dataclass(frozen=True)
class Command:
    """One command on a unit's ordered stream; ``seq`` counts from 0 per unit."""

    seq: int
    body: object  # Scan | Tick | Deliver | Step | Report | WarmUp | Snapshot | a record


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
            Warmed, Snapshot,
        )
    }  # fmt: skip


#: a dataclass's field names, and which of them are tuples, per class (read once: encode and
#: decode run for every command and reply of every step)
_FIELDS: dict[type, tuple[tuple[str, bool], ...]] = {}
_PLAIN = (float, int, str, bool, type(None))


def _fields(cls: type) -> tuple[tuple[str, bool], ...]:
    f = _FIELDS.get(cls)
    if f is None:
        f = _FIELDS[cls] = tuple((x.name, str(x.type).startswith("tuple")) for x in fields(cls))
    return f


def _enc(o: object) -> object:
    if type(o) in _PLAIN:
        return o
    if is_dataclass(o) and not isinstance(o, type):
        return {"_": type(o).__name__, **{n: _enc(getattr(o, n)) for n, _ in _fields(type(o))}}
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
    for name, is_tuple in _fields(cls):
        v = _dec(o[name], kinds)
        args[name] = _tuples(v) if is_tuple else v
    return cls(**args)


def encode(o: object) -> str:
    """A command, reply or record as JSON text: floats as Python writes them (repr: they read
    back bit for bit), inf and NaN as JSON5's Infinity and NaN, which :func:`decode` takes."""
    return json.dumps(_enc(o), separators=(",", ":"))


def decode(text: str) -> object:
    """The object :func:`encode` wrote (KeyError or TypeError on text it did not write)."""
    return _dec(json.loads(text), _KINDS)


_KINDS = _kinds()
#: how a Delivered reply starts on the wire (a reader that wants only those)
DELIVERED_PREFIX = encode(Delivered(0, "", None, None, ())).partition('"parcel_id"')[0]


def answered(body: object) -> bool:
    """True for a command the unit answers (the owner then waits for the reply): a transport
    may hold a unit's other commands back and send them in one batch with the next one it
    answers, which keeps their order and changes nothing the unit does (it applies them in
    sequence order, and only a command it answers makes it put anything out)."""
    return isinstance(body, Deliver | Step | Report | WarmUp)


def join_batch(texts: Sequence[str]) -> str:
    """Encoded commands in one message, in order, one a line (:func:`encode` writes no raw
    newline)."""
    return "\n".join(texts)


def split_batch(text: str) -> list[str]:
    """The encoded commands of a message :func:`join_batch` wrote (one command: itself)."""
    return text.split("\n")


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
        self.last: object = None  # the body of the last command applied

    @property
    def reported(self) -> bool:
        """True once the last command applied is the owner's :class:`Report`: the line is
        over only after it (the owner's ``end`` follows its reports)."""
        return isinstance(self.last, Report)

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
            self.last = cmd.body
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
        if isinstance(body, Snapshot):  # a new process of the unit rejoins the line
            self.view.tracks = {tr.parcel_id: replace(tr) for tr in body.tracks}
            self.view.bookings = list(body.bookings)
            self.view.stroking = set(body.stroking)
            u.advance(body.t)  # an empty simulation: its clock jumps to the line's
            return []
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

    def forward(self, h: HandOff) -> None:
        """A hand-off on the downstream link of unit ``h.from_unit``, sent by the owner for
        that unit while it is down."""
        raise NotImplementedError

    def rejoining(self) -> list[int]:
        """The units that are down and whose new process is ready to rejoin (none by
        default)."""
        return []

    def restart(self, k: int) -> None:
        """Unit ``k``'s command stream starts again (from 0; replies still queued are
        dropped)."""

    def left_over(self, k: int) -> list[Reply]:
        """Unit ``k``'s replies received and not taken (none asked for them), taken now."""
        return []


class UnitDown(RuntimeError):
    """:meth:`Links.wait`: unit ``k`` stopped answering (its process or host is gone);
    ``waited``: the wall time [s] the links waited for its reply before giving up."""

    def __init__(self, k: int, why: str, waited: float = 0.0):
        super().__init__(why)
        self.k = k
        self.waited = waited


@dataclass
class LocalLinks(Links):
    """The units' sides in this process: commands, replies and hand-offs handed over in
    memory. ``recirculation`` collects the last unit's hand-offs (the owner's end of that
    link)."""

    sides: list[UnitSide | None]
    seq: list[int] = field(default_factory=list)
    replies: list[list[Reply]] = field(default_factory=list)
    recirculation: list[HandOff] = field(default_factory=list)
    #: new sides of killed units, waiting to rejoin (unit index -> side)
    fresh: dict[int, UnitSide] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.seq = [0] * len(self.sides)
        self.replies = [[] for _ in self.sides]

    def kill(self, k: int) -> None:
        """Unit ``k``'s process is gone: what it was sent or owed is lost with it."""
        self.sides[k] = None
        self.replies[k].clear()

    def start_again(self, k: int, side: UnitSide) -> None:
        """A new process of unit ``k`` is ready: it rejoins at the owner's next step."""
        self.fresh[k] = side

    def send(self, k: int, body: object) -> None:
        cmd = Command(self.seq[k], body)
        self.seq[k] += 1
        side = self.sides[k]
        if side is not None:
            self._route(k, side.on_command(cmd))

    def wait(self, k: int) -> Reply:
        if not self.replies[k]:
            side = self.sides[k]
            if side is None:
                raise UnitDown(k, f"unit {k} is gone")
            raise RuntimeError(f"unit {k} owes no reply (blocked={side.blocked})")
        return self.replies[k].pop(0)

    def left_over(self, k: int) -> list[Reply]:
        out, self.replies[k] = self.replies[k], []
        return out

    def hand_off(self, h: HandOff) -> None:
        if h.to_unit == RECIRCULATION:
            self.recirculation.append(h)
            return
        side = self.sides[h.to_unit]
        if side is not None:
            self._route(h.to_unit, side.on_handoff(h))

    def forward(self, h: HandOff) -> None:
        self.hand_off(h)

    def rejoining(self) -> list[int]:
        return sorted(self.fresh)

    def restart(self, k: int) -> None:
        self.sides[k] = self.fresh.pop(k)
        self.seq[k] = 0
        self.replies[k].clear()

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


@dataclass
class _Tally:
    """The link counts of one process of a unit, kept from its replies."""

    handoffs_in: int = 0
    handoffs_out: int = 0
    handoffs_lost: int = 0
    sorted: int = 0
    refused: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REFUSALS, 0))

    def add(self, o: _Tally) -> None:
        self.handoffs_in += o.handoffs_in
        self.handoffs_out += o.handoffs_out
        self.handoffs_lost += o.handoffs_lost
        self.sorted += o.sorted
        for k, v in o.refused.items():
            self.refused[k] += v


class RemoteUnit:
    """The plant's stand-in for a unit on a side of its own: its calls become commands; while
    the unit is down it declines the unit's hand-offs ``unit_down`` and passes them on."""

    def __init__(self, unit: LineUnit, links: Links):
        self.links = links
        self.spec = unit.spec
        self.index = unit.index
        self.upstream = unit.upstream
        self.downstream = unit.downstream
        self.planner = unit.planner
        self.blank = unit  # never used: the figures of a unit that is down at the end
        self._fig: Figures | None = None
        self._t = 0.0
        self.down = False
        self.why = ""  # why it went down, the latest time
        self.down_at = math.nan  # sim time it went down, the latest time [s]
        self.downtime = 0.0  # sim time it was down, rejoins aside [s]
        # wall time [s, the owner's wall_clock] from the start of the wait for the reply it
        # never gave, the latest time; and its wall time down, rejoins aside
        self.down_wall_at = math.nan
        self.downtime_wall = 0.0
        self.downs = 0
        self.rejoins = 0
        self.lost_parcels: list[int] = []  # parcels in its strokes when it went down
        self.known: set[tuple[int, int]] | None = None  # (id, pass) announced to its process
        self.tally = _Tally()  # its process's counts, from its replies
        self.banked = _Tally()  # the counts of its earlier processes
        self.stood_in = 0  # hand-offs the stand-in took and passed on for it
        #: replies on its link the owner did not ask for (another kind, another parcel or
        #: step, or left over at the end): refused, never taken for the unit's answer
        self.replies_refused: list[str] = []
        self.on_down: Callable[[RemoteUnit, str, float], None] = lambda u, why, waited: None

    def answer(self, kind: type, asked: Callable[[object], bool] = lambda r: True) -> Reply:
        """The unit's reply of ``kind`` that ``asked`` accepts; every other reply on its link
        before it is refused and counted (UnitDown as :meth:`Links.wait`)."""
        while True:
            r = self.links.wait(self.index)
            if isinstance(r, kind) and asked(r):
                return r
            self.refuse(r)

    def refuse(self, r: object) -> None:
        what = type(r).__name__
        about = getattr(r, "parcel_id", getattr(r, "t", None))
        self.replies_refused.append(what if about is None else f"{what} {about}")

    def announce(self, parcel_id: int, passes: int, spec=None, destination: str = "") -> None:
        if self.down:
            return
        if self.known is not None:
            self.known.add((parcel_id, passes))
        self.links.send(self.index, Scan(parcel_id, passes, spec, destination))

    def receive(self, h: HandOff, t: float, traffic: Traffic | None = None) -> UnitReply:
        """The unit routes the hand-off with its own copy of the traffic (``traffic`` unused);
        while it is down, or for a parcel announced before its process rejoined, the
        stand-in passes it on (:meth:`stand_in`)."""
        if not self.down and (self.known is None or (h.parcel_id, h.passes) in self.known):
            try:
                if h.from_unit == INDUCTION:
                    self.links.hand_off(h)
                self.links.send(self.index, Deliver(h.parcel_id, h.passes, h.from_unit, t))
                r = self.answer(Delivered, lambda r: r.parcel_id == h.parcel_id)
            except UnitDown as exc:
                self.on_down(self, str(exc), exc.waited)
            else:
                self.count(r)
                return UnitReply(r.refusal, r.decision, r.booking, list(r.records))
        return self.stand_in(h, t)

    def stand_in(self, h: HandOff, t: float) -> UnitReply:
        """Take ``h`` for the unit, decline it ``unit_down`` and pass it on, as the unit
        passes on a parcel it declines (the pose it came with), on the unit's own link."""
        self.stood_in += 1
        out = replace(h, t=t, from_unit=self.index, to_unit=self.downstream)
        self.links.forward(out)
        return UnitReply(decision=Decision(False, UNIT_DOWN), records=[out])

    def count(self, r: object) -> None:
        """Count a reply's hand-offs and sorts (what a process that dies takes with it)."""
        c = self.tally
        if isinstance(r, Delivered):
            if r.refusal:
                c.refused[r.refusal] += 1
            else:
                c.handoffs_in += 1
            recs, late = r.records, ()
        elif isinstance(r, Done):
            recs, late = (*r.deadline_records, *r.advance_records), r.deadline_records
        else:
            return
        c.handoffs_out += sum(isinstance(x, HandOff) for x in recs)
        c.handoffs_lost += sum(isinstance(x, HandOff) for x in late)
        c.sorted += sum(isinstance(x, Sorted) for x in recs)

    def report(self, t: float) -> None:
        self._fig, self._t = None, t
        if self.down:
            return
        self.links.send(self.index, Report(t))
        try:
            r = self.answer(Figures, lambda r: r.t == t)
        except UnitDown as exc:
            self.on_down(self, str(exc), exc.waited)
            return
        self._fig = r
        for left in self.links.left_over(self.index):  # answers to nothing the owner asked
            self.refuse(left)

    # what the plant's summary reads (after :meth:`report`): the unit's process's figures,
    # plus the counts of its earlier processes and of its stand-in
    def figures(self, t: float) -> dict:
        f = dict(self._fig.figures) if self._fig is not None else self.blank.figures(t)
        b = self.banked
        f["handoffs_in"] += b.handoffs_in + self.stood_in
        f["handoffs_out"] += b.handoffs_out + self.stood_in
        f["handoffs_lost"] += b.handoffs_lost
        f["sorted"] += b.sorted
        f["handoffs_refused"] = {k: v + b.refused[k] for k, v in f["handoffs_refused"].items()}
        f["declined"] = {**f["declined"], UNIT_DOWN: f["declined"][UNIT_DOWN] + self.stood_in}
        return f

    def _f(self, key: str):
        return self.figures(self._t)[key]

    received = property(lambda self: self._f("handoffs_in"))
    sent = property(lambda self: self._f("handoffs_out"))
    lost = property(lambda self: self._f("handoffs_lost"))
    refused_handoffs = property(lambda self: dict(self._f("handoffs_refused")))
    declined = property(lambda self: dict(self._f("declined")))
    intrusions = property(lambda self: self._f("swept_sector_intrusions"))
    strokes = property(lambda self: list(self._fig.strokes) if self._fig else [])
    max_impact_speed = property(lambda self: self._fig.max_impact_speed if self._fig else 0.0)
    max_accel = property(lambda self: self._fig.max_accel if self._fig else 0.0)


class _SharedView(TrafficView):
    """The owner's view: every record and tick it applies goes to every unit that is up."""

    def __init__(self, speed: float, links: Links, units: list[RemoteUnit]):
        super().__init__(speed)
        self.links = links
        self.units = units

    def apply(self, rec: object) -> None:
        super().apply(rec)
        for u in self.units:
            if not u.down:
                self.links.send(u.index, rec)

    def tick(self, t: float) -> None:
        super().tick(t)
        for u in self.units:
            if not u.down:
                self.links.send(u.index, Tick(t))


class LockstepOwner(LinePlant):
    """The induction, the recirculation and the clock of a line whose units run elsewhere
    (behind ``links``); :meth:`run` to the drain gives ``LinePlant``'s summary, with the units
    that went down (``units_down``) and the parcels lost with them (``lost_with_unit``).
    ``wall_clock`` [s] times how long a unit was down on the wall (``downtime_wall_s``)."""

    def __init__(
        self,
        line: LineSpec,
        cfg: LineRunConfig,
        links: Links,
        wall_clock: Callable[[], float] = time.monotonic,
    ):
        super().__init__(line, cfg)
        self.transport = links
        self.wall_clock = wall_clock
        self.units = [RemoteUnit(u, links) for u in self.units]
        for u in self.units:
            u.on_down = self._unit_down
        self.view = _SharedView(self.v, links, self.units)

    def _unit_down(self, u: RemoteUnit, why: str, waited: float = 0.0) -> None:
        """Unit ``u`` is down: the parcels in its strokes are lost with it (each leaves every
        other unit's traffic as a failed one), its counts so far are kept. Its wall downtime
        counts from the start of the wait for the reply it never gave (``waited`` [s] ago)."""
        if u.down:
            return
        u.down, u.why, u.down_at, u.downs = True, why, self.t, u.downs + 1
        u.down_wall_at = self.wall_clock() - waited
        u.banked.add(u.tally)
        u.tally = _Tally()
        for p in self.live:
            if p.stroke_unit != u.index or p.state != "belt":
                continue
            p.state, p.end = "lost", f"{UNIT_DOWN}:{u.spec.name}"
            p.stroke_unit, p.track, p.pending = None, None, None
            u.lost_parcels.append(p.pid)
            self.bookings = [b for b in self.bookings if b.parcel_id != p.pid]
            self.view.apply(Failed(p.pid, u.index, self.t, UNIT_DOWN))
        self.live = [p for p in self.live if p.state != "lost"]

    def _rejoin(self, u: RemoteUnit) -> None:
        """A new process of ``u`` rejoins now, at the start of a step: its stream starts again
        with the owner's traffic; it routes the parcels announced from now on."""
        if not u.down:  # its new process says the old one is gone
            self._unit_down(u, "a new process of it started")
        self.transport.restart(u.index)
        u.down, u.known = False, set()
        u.downtime += self.t - u.down_at
        u.downtime_wall += self.wall_clock() - u.down_wall_at
        u.rejoins += 1
        v = self.view
        snap = Snapshot(self.t, tuple(v.tracks.values()), tuple(v.bookings), tuple(v.stroking))
        self.transport.send(u.index, snap)

    def _wait(self, u: RemoteUnit, t: float) -> Done:
        if not u.down:
            try:
                r = u.answer(Done, lambda r: r.t == t)
            except UnitDown as exc:
                self._unit_down(u, str(exc), exc.waited)
            else:
                u.count(r)
                return r
        return Done(t, (), ())

    def step(self) -> None:
        for k in self.transport.rejoining():
            self._rejoin(self.units[k])
        self._announce()
        self._merge()
        self._hand_offs()
        t_next = self.t + self.cfg.dt
        t = self.t
        for u in self.units:
            if not u.down:
                self.transport.send(u.index, Step(t, t_next))
        done = [self._wait(u, t) for u in self.units]
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
            try:
                u.answer(Warmed)
            except UnitDown as exc:
                self._unit_down(u, str(exc), exc.waited)

    def summary(self) -> dict:
        for u in self.units:
            u.report(self.t)
        s = super().summary()
        lost = [p for p in self.parcels if p.state == "lost"]
        ended = s["sorted"] + s["rejected"] + s["solver_failures"] + s["still_on_line"]
        s["lost_with_unit"] = len(lost)
        s["replies_refused"] = {
            u.spec.name: list(u.replies_refused) for u in self.units if u.replies_refused
        }
        s["conservation_ok"] = s["parcels_inducted"] == ended + len(lost)
        now = self.wall_clock()
        s["units_down"] = {
            u.spec.name: {
                "downs": u.downs,
                "rejoins": u.rejoins,
                "down_at_end": u.down,
                "why": u.why,
                # down in sim time: small after a restart, the clock waits for the unit's
                # reply until its new process says ready
                "downtime_s": u.downtime + (self.t - u.down_at if u.down else 0.0),
                # down in wall time: from the start of the owner's wait for the reply it never
                # gave to its new process's rejoin (or to the end of the run)
                "downtime_wall_s": u.downtime_wall + (now - u.down_wall_at if u.down else 0.0),
                "lost_parcels": list(u.lost_parcels),
                "handoffs_passed_on": u.stood_in,
                # what its latest process (after the latest rejoin) sorted; None: down
                "sorted_by_last_process": (
                    u._fig.figures["sorted"] if u._fig is not None and u.rejoins else None
                ),
            }
            for u in self.units
            if u.downs
        }
        return s
