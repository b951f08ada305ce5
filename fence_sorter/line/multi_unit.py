"""A line of fence units run without ROS: induction, units, recirculation, the line summary.

Every unit is a :class:`~fence_sorter.line.one_fence.SortingLine` in its own frame (its strokes are
the single-unit line's sorting events, stepped as sim time passes) with its own planner
(:class:`~fence_sorter.capacity.planner.Planner`). A parcel is handed to a unit when its front
crosses the unit's scan line (2 m before the fence axis): the unit routes it
(:mod:`fence_sorter.line.routing`), then it rides through the unit's zone. A parcel a unit did
not divert rides on with the pose it left the unit with (a missed stroke's disturbed pose is
what the next unit gets); a parcel still in a stroke is handed on when the stroke ends. At the
belt's end an unsorted parcel enters the recirculation loop and, after the transit time, merges
at the induction with ``merge_gap`` on both sides: the parcels on the belt must leave that gap,
and the induction holds the stream's new parcels back to make it behind (a returning parcel
has priority, as on loop sorters; the stream's own spacing is kept). With the guard it merges
only where neither it nor a held parcel reaches into a booked stroke's sector. After
``max_passes`` it goes to the reject chute. No-reads are drawn per pass at the induction scan.

Each unit's simulation checks the fence's swept sector at every step of the line clock
(``dt``) during every stroke and reports each parcel found in it once per stroke
(:class:`~fence_sorter.line.types.OverlapWarning`): the intrusions of the summary.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from fence_sorter.capacity.formulas import stroke_capacity
from fence_sorter.inputs import ParcelSpec
from fence_sorter.line.handoff import (
    INDUCTION,
    RECIRCULATION,
    Failed,
    HandOff,
    LinkCounts,
    Sorted,
    link_name,
)
from fence_sorter.line.line_file import UNIT_LEAD, LineSpec
from fence_sorter.line.parcel_log import ParcelLog
from fence_sorter.line.routing import (
    REASONS,
    SETTLE_SLACK,
    Booking,
    Track,
    footprint,
    track_hits_sector,
)
from fence_sorter.line.steady import per_hour, steady_state
from fence_sorter.line.steady import steady_window as _steady_window
from fence_sorter.line.traffic import Announce, Hold, Left, TrafficView
from fence_sorter.line.unit import LineUnit, Record, track_of
from fence_sorter.stream.model import generate

__all__ = ["LinePlant", "LineRunConfig", "run_line"]


@dataclass(frozen=True)
class LineRunConfig:
    parcels: int | None = 100  # parcels of the stream (or duration)
    duration: float | None = None  # [s] of induction
    rate_pcs_h: float | None = None  # None: the stream's rate
    seed: int | None = None
    guard: bool = True
    dt: float = 0.01  # line clock step: units advance and check their sectors [s]
    max_time: float | None = None  # stop (undrained) at this sim time [s]


@dataclass
class _LP:
    """A parcel of the line."""

    pid: int
    spec: ParcelSpec  # sizes, mass; cog_offset_y, yaw, lateral_gap in the line frame
    destination: str
    arrival: float  # the stream's first induction [s], before any hold
    inducted_at: float = math.nan  # its first induction: its front crossed X = 0 [s]
    sorted_at: float = math.nan  # when its stroke's outcome said sorted [s]
    ended_at: float = math.nan  # when it was sorted, rejected or failed [s]
    passes: int = 0  # completed passes
    no_read: bool = False  # this pass
    ever_no_read: bool = False
    # new (not yet announced) | scheduled (announced, front not yet at the induction) | belt |
    # loop | sorted | rejected | failed
    state: str = "new"
    track: Track | None = None  # the line's prediction of its ride, from its latest hand-off
    next_unit: int = 0  # the unit its pending hand-off goes to
    pending: HandOff | None = None  # the hand-off sent for it and not yet received
    stroke_unit: int | None = None  # unit with a booked or running stroke for it
    return_time: float = math.nan
    end: str = ""  # chute or reject it ended in


class LinePlant:
    """The line's state and clock; :meth:`run` to the drain, :meth:`summary` for the figures.

    The units are :class:`~fence_sorter.line.unit.LineUnit` objects; the plant is the
    induction, the recirculation and the wiring between them: it delivers each unit's
    hand-offs to the next one when the parcel's front reaches that unit's scan line, and keeps
    the line's predicted tracks and booked strokes (the :class:`~fence_sorter.line.unit.
    Traffic` a unit's guard is given)."""

    def __init__(self, line: LineSpec, cfg: LineRunConfig = LineRunConfig()):
        self.spec = line
        self.cfg = cfg
        self.v = line.speed
        self.width = line.width
        self.t = 0.0
        self.rng = np.random.default_rng(
            (line.stream.seed if cfg.seed is None else cfg.seed) + 7919
        )
        stream = line.stream
        if cfg.rate_pcs_h is not None:
            stream = replace(stream, rate_pcs_h=float(cfg.rate_pcs_h), gap=None)
        specs = generate(
            stream, self.v, count=cfg.parcels if cfg.duration is None else None,
            duration=cfg.duration, seed=cfg.seed,
        )  # fmt: skip
        dests = list(line.destinations)
        shares = np.array([line.destinations[d] for d in dests])
        self.parcels: list[_LP] = []
        for s in specs:
            d = dests[int(self.rng.choice(len(dests), p=shares / shares.sum()))]
            self.parcels.append(_LP(s.parcel_id, s, d, s.arrival_time))
        self.by_id = {p.pid: p for p in self.parcels}
        self.live: list[_LP] = []  # announced and not yet ended (sorted, rejected, failed)
        self.units = [
            LineUnit(u, i, len(line.units), self.width, self.v, line.planner, cfg.dt, cfg.guard)
            for i, u in enumerate(line.units)
        ]
        self.names = [u.name for u in line.units]
        self.log = ParcelLog(self.names)  # what each unit decided, per parcel and pass
        self.bookings: list[Booking] = []
        self.view = TrafficView(self.v)  # the traffic the units are given: records alone
        self._next_new = 0  # index of the next stream parcel to announce
        self.horizon = self._horizon()
        self.inductions = 0
        self.merges_waited = 0.0  # summed waiting time of returning parcels at the merge [s]
        self.hold = 0.0  # the induction's summed hold of the stream for returning parcels [s]
        # (sim time, "min_gap" | "returning", seconds) of each hold of the stream, and
        # (return time, wait [s]) of each returning parcel merged: the queues' growth
        self.holds: list[tuple[float, str, float]] = []
        self.merges: list[tuple[float, float]] = []
        self.handoffs = 0
        self.induction_sent = 0  # hand-offs the induction sent to the first unit
        self.recirculation_received = 0  # hand-offs the recirculation took from the last unit
        self.recirculation_lost = 0  # parcels that reached it without their hand-off
        self.records_ignored = 0  # records for a parcel not in the sender's stroke
        #: fault injection: hand-offs (parcel id, sender index) the wiring drops, once each
        self.drop: set[tuple[int, int]] = set()
        self.wall = 0.0
        #: called after every step of the line clock with the plant and the records the units'
        #: simulations sent in it (a view samples the line)
        self.observers: list[Callable[[LinePlant, list[Record]], None]] = []

    # -- set-up ----------------------------------------------------------------------------
    def _horizon(self) -> float:
        """How far ahead a stroke can be booked: from a unit's scan line to the end of the
        latest stroke the planner may choose [s]; new parcels are announced this early."""
        pc = self.spec.planner
        return (UNIT_LEAD + pc.r_s_max) / self.v + 2.0 * pc.t1_max + 1.0

    def warm_up(self, time_budget: float = math.inf) -> None:
        """Fill each planner's cache from the stream's parcels (and load the JIT). Complete
        by default (about 1.2 s a unit for 200 parcels), so the line's figures do not depend
        on how busy the machine was while it warmed up; ``time_budget`` [s] is each unit's."""
        loads = [p.spec.to_parcel_params() for p in self.parcels[:200]]
        for u in self.units:
            u.planner.warm_up(loads, time_budget=time_budget)

    # -- tracks ----------------------------------------------------------------------------
    def _track_at_induction(self, p: _LP, t: float) -> Track:
        """The ride of a parcel whose front crosses X = 0 at time t."""
        s = p.spec
        pts = footprint(s.length_a, s.width_b, s.cog_offset_x, s.cog_offset_y, 0.0, 0.0, s.yaw)
        x = -max(c[0] for c in pts)
        y = s.lateral_gap - min(c[1] for c in pts)
        return Track(
            p.pid, s.length_a, s.width_b, s.cog_offset_x, s.cog_offset_y, x, y, s.yaw, t, self.v
        )

    def _front(self, tr: Track, t: float) -> float:
        return max(c[0] for c in tr.corners(t))

    def _rear(self, tr: Track, t: float) -> float:
        return min(c[0] for c in tr.corners(t))

    def _live_tracks(self) -> list[Track]:
        return [p.track for p in self.live if p.state in ("scheduled", "belt") and p.track]

    # -- induction -------------------------------------------------------------------------
    def _induct(self, p: _LP, t: float) -> None:
        p.track = self._track_at_induction(p, t)
        p.state = "scheduled"
        p.next_unit = 0
        p.no_read = bool(self.rng.random() < self.spec.no_read_share)
        p.ever_no_read |= p.no_read
        self.inductions += 1
        for u in self.units:
            u.announce(p.pid, p.passes, p.spec, "" if p.no_read else p.destination)
        self.view.apply(Announce(p.pid, p.passes, p.track))

    def _announce(self) -> None:
        while (
            self._next_new < len(self.parcels)
            and self.parcels[self._next_new].arrival + self.hold <= self.t + self.horizon
        ):
            p = self.parcels[self._next_new]
            at = p.arrival + self.hold
            if self.spec.min_gap > 0.0:  # a gapping induction holds it behind the one ahead
                gap = min(
                    (self._rear(q.track, at) for q in self.live if q.track is not None
                     and q.state in ("scheduled", "belt")),
                    default=math.inf,
                )  # fmt: skip
                if gap < self.spec.min_gap:
                    self.hold += (self.spec.min_gap - gap) / self.v
                    self.holds.append((self.t, "min_gap", (self.spec.min_gap - gap) / self.v))
                    at = p.arrival + self.hold
            self.live.append(p)
            self._induct(p, at)
            self._next_new += 1

    def _merge(self) -> None:
        """Returning parcels whose loop transit is over merge at X = 0 (:meth:`_merge_hold`)."""
        waiting = sorted(
            (p for p in self.live if p.state == "loop" and p.return_time <= self.t),
            key=lambda p: p.return_time,
        )
        for p in waiting:
            cand = self._track_at_induction(p, self.t)
            held = self._merge_hold(cand)
            if held is None:
                # not yet: the induction holds the stream for one clock step, so that no new
                # parcel takes the gap the returning one waits for
                self._hold_stream(self.cfg.dt)
                break
            delay, tracks = held
            for tr in tracks:
                tr.t_ref += delay
            self.view.apply(Hold(tuple(tr.parcel_id for tr in tracks), delay))
            self.hold += delay
            self.holds.append((self.t, "returning", delay))
            self.merges_waited += self.t - p.return_time
            self.merges.append((p.return_time, self.t - p.return_time))
            self._induct(p, self.t)

    def _holdable(self) -> list[Track]:
        """The tracks of the stream's parcels announced but not yet at X = 0."""
        return [
            p.track
            for p in self.live
            if p.state == "scheduled" and p.passes == 0 and self._front(p.track, self.t) < 0.0
        ]

    def _hold_stream(self, delay: float) -> None:
        """Hold the stream's parcels not yet inducted by ``delay`` [s], unless (guard) one of
        them would then reach into a booked stroke's sector."""
        tracks = self._holdable()
        if self.cfg.guard:
            live = [b for b in self.bookings if b.t_end > self.t]
            for tr in tracks:
                moved = replace(tr, t_ref=tr.t_ref + delay)
                if any(track_hits_sector(moved, b, self.width) for b in live):
                    return
        for tr in tracks:
            tr.t_ref += delay
        self.view.apply(Hold(tuple(tr.parcel_id for tr in tracks), delay))
        self.hold += delay
        self.holds.append((self.t, "returning", delay))

    def _merge_hold(self, cand: Track) -> tuple[float, list[Track]] | None:
        """How long the induction must hold the stream's parcels not yet at X = 0 (and which)
        so that ``cand``, with its front at X = 0 now, has ``merge_gap`` to every parcel; None
        if a parcel already on the belt is too close, or (guard) the merged or a held parcel
        would reach into a booked stroke's sector."""
        t, gap = self.t, self.spec.merge_gap
        lo, hi = self._rear(cand, t), self._front(cand, t)
        held = self._holdable()
        ids = {tr.parcel_id for tr in held}
        for p in self.live:
            tr = p.track
            if tr is None or p.state not in ("scheduled", "belt") or p.pid in ids:
                continue
            if self._rear(tr, t) < hi + gap and lo - gap < self._front(tr, t):
                return None
        behind = max((self._front(tr, t) for tr in held), default=-math.inf)
        delay = max(0.0, (behind - (lo - gap)) / self.v) if held else 0.0
        if not self.cfg.guard:
            return delay, held
        live = [b for b in self.bookings if b.t_end > t]
        if any(track_hits_sector(cand, b, self.width) for b in live):
            return None
        for tr in held:
            moved = replace(tr, t_ref=tr.t_ref + delay)
            if any(track_hits_sector(moved, b, self.width) for b in live):
                return None
        return delay, held

    # -- hand-offs -------------------------------------------------------------------------
    def _induction_handoff(self, p: _LP) -> HandOff:
        """The induction's hand-off of a parcel to the first unit (its scan result: no
        destination on a no-read pass)."""
        tr = p.track
        self.induction_sent += 1
        return HandOff(
            p.pid, "" if p.no_read else p.destination, p.passes,
            replace(p.spec, cog_offset_x=tr.cog_x, cog_offset_y=tr.cog_y),
            tr.x, tr.y, tr.yaw, self.v, 0.0, 0.0, tr.t_ref, self.t, INDUCTION, 0,
        )  # fmt: skip

    def _deliver(self, p: _LP, u: LineUnit) -> None:
        key = (p.pid, p.pending.from_unit)
        if key in self.drop:  # lost on the way: the unit never gets it
            self.drop.discard(key)
            p.pending = None
            p.next_unit = u.index + 1
            return
        reply = u.receive(p.pending, self.t, self.view.traffic())
        self.handoffs += 1
        reason = reply.decision.reason if reply.decision is not None else ""
        booked = reply.booking is not None
        self.log.decided(p.pid, p.passes, u.index, reply.refusal, reason, booked)
        p.pending = None
        p.next_unit = u.index + 1
        if reply.booking is not None:
            self.bookings.append(reply.booking)
            self.view.apply(reply.booking)
            p.track.free_after = reply.booking.t_start
            p.track.free_until = reply.booking.t_end + SETTLE_SLACK
            p.stroke_unit = u.index
        for rec in reply.records:
            self._on_record(u, rec)

    def _hand_offs(self) -> None:
        for p in self.live:
            if (
                p.state == "scheduled"
                and p.track.t_ref <= self.t
                and self._front(p.track, self.t) >= 0.0
            ):
                p.state = "belt"
                if p.passes == 0:  # its front crossed X = 0 at t_ref (after every hold)
                    p.inducted_at = p.track.t_ref
            if p.state != "belt" or p.stroke_unit is not None:
                continue
            while p.next_unit < len(self.units):
                u = self.units[p.next_unit]
                front = self._front(p.track, self.t)
                if front < u.spec.zone[0]:
                    break
                if p.next_unit == 0 and p.pending is None:
                    p.pending = self._induction_handoff(p)
                if p.pending is None:  # lost on its way: the unit's deadline sends it on
                    break
                self._deliver(p, u)
                if p.stroke_unit is not None:
                    break

    # -- unit records ----------------------------------------------------------------------
    def _on_record(self, u: LineUnit, rec: Record) -> None:
        self.view.apply(rec)
        p = self.by_id.get(rec.parcel_id)
        if p is None or p.state != "belt":
            self.records_ignored += 1
            return
        in_stroke = p.stroke_unit == u.index
        if p.stroke_unit is not None:
            if p.stroke_unit != u.index:
                self.records_ignored += 1
                return
            p.stroke_unit = None
            self.bookings = [b for b in self.bookings if b.parcel_id != p.pid]
        self.log.record(p.pid, p.passes, u.index, rec, in_stroke)
        if isinstance(rec, Sorted):
            p.state = "sorted"
            p.sorted_at = p.ended_at = rec.t
            p.end = owner_chute(u.spec.destinations, u.index, p.destination, rec.chute)
            p.track = None
        elif isinstance(rec, Failed):
            p.state = "failed"
            p.ended_at = rec.t
            p.track = None
        else:  # rides on from the pose it left the unit with
            p.track = track_of(rec, self.v)
            p.pending = rec

    def _leave_belt(self) -> None:
        for p in self.live:
            if p.state != "belt" or p.stroke_unit is not None:
                continue
            if self._rear(p.track, self.t) < self.spec.length:
                continue
            if p.pending is not None and p.pending.to_unit == RECIRCULATION:
                self.recirculation_received += 1
            else:  # the last unit's hand-off never came: lost on that link
                self.recirculation_lost += 1
            p.pending = None
            self.view.apply(Left(p.pid))
            p.passes += 1
            p.track = None
            if p.passes >= self.spec.max_passes:
                p.state = "rejected"
                p.ended_at = self.t
                p.end = self.spec.reject_chute
            else:
                p.state = "loop"
                p.return_time = self.t + self.spec.transit_time

    # -- clock -----------------------------------------------------------------------------
    def active(self) -> bool:
        return self._next_new < len(self.parcels) or bool(self.live)

    def step(self) -> None:
        self._announce()
        self._merge()
        self._hand_offs()
        traffic = self.view.traffic()
        for u in self.units:
            for rec in u.deadlines(self.t, traffic):
                self._on_record(u, rec)
        t_next = self.t + self.cfg.dt
        records: list[Record] = []
        for u in self.units:
            for rec in u.advance(t_next, stamp=self.t):
                records.append(rec)
                self._on_record(u, rec)
        self._close_step(t_next, records)

    def _close_step(self, t_next: float, records: list[Record]) -> None:
        """The end of a step of the line clock, once every unit has advanced to ``t_next``:
        parcels off the belt, the finished ones and bookings forgotten, the observers told."""
        self.t = t_next
        self._leave_belt()
        self.live = [p for p in self.live if p.state not in ("sorted", "rejected", "failed")]
        running = {p.pid for p in self.live if p.stroke_unit is not None}
        self.bookings = [b for b in self.bookings if b.t_end > self.t or b.parcel_id in running]
        self.view.tick(self.t)
        for observe in self.observers:
            observe(self, records)

    def limit(self) -> float:
        """Sim time the run stops at, drained or not: ``cfg.max_time``, else a bound on the
        drain after the last parcel's arrival (moved on by the induction's holds)."""
        if self.cfg.max_time is not None:
            return self.cfg.max_time
        last = self.parcels[-1].arrival if self.parcels else 0.0
        loop = self.spec.length / self.v + self.spec.transit_time + 60.0
        return last + self.hold + self.spec.max_passes * loop + 60.0

    def run(self) -> dict:
        wall0 = time.perf_counter()
        while self.active() and self.t < self.limit():
            self.step()
        self.wall = time.perf_counter() - wall0
        return self.summary()

    # -- figures ---------------------------------------------------------------------------
    def summary(self) -> dict:
        ps = self.parcels
        n = len(ps)
        count = {s: sum(p.state == s for p in ps) for s in ("sorted", "rejected", "failed")}
        on_line = sum(p.state in ("new", "scheduled", "belt", "loop") for p in ps)
        wrong = sum(p.end.startswith("wrong:") for p in ps)
        per_dest = {d: sum(p.end == d for p in ps) for d in self.spec.destinations}
        ended = [p for p in ps if p.state in ("sorted", "rejected", "failed")]
        # parcels that went round the loop at least once (a rejected one: before its last pass)
        recirculated = sum(p.passes >= (2 if p.state == "rejected" else 1) for p in ps)
        span = (ps[-1].arrival - ps[0].arrival) if n > 1 else 0.0
        window = span + (span / (n - 1) if n > 1 else 0.0)
        rate = (lambda k: 3600.0 * k / window) if window > 0 else (lambda k: math.nan)
        firsts = [p.inducted_at for p in ps if not math.isnan(p.inducted_at)]
        steady = self.steady_window()
        # the cohort first inducted in the window: its sorted / inducted is at most 1
        st = steady_state(ps, steady, rate(n), self.holds, self.merges)
        throughput_in = st["inducted_pcs_h"] if steady is not None else math.nan
        throughput_out = st["sorted_pcs_h"]
        prof = self.spec.planner.profile
        units = {}
        for u in self.units:
            units[u.spec.name] = {
                **u.figures(self.t),
                "impact_speed_margin_m_s": prof.w_dop - u.max_impact_speed,
                "accel_margin_m_s2": prof.a_ndop - u.max_accel,
                "capacity_bound_pcs_h": self.unit_capacity(u),
            }
        return {
            "line": self.spec.name,
            "guard": self.cfg.guard,
            "rate_in_pcs_h": rate(n),
            "parcels_inducted": n,
            "inductions": self.inductions,
            "sorted": count["sorted"],
            "sorted_per_destination": per_dest,
            "sorted_wrong_destination": wrong,
            "sort_rate": count["sorted"] / n if n else math.nan,
            "recirculated": recirculated,
            "recirculation_share": recirculated / n if n else math.nan,
            "passes_per_parcel": (
                sum(p.passes + (p.state != "rejected") for p in ended) / len(ended)
                if ended
                else math.nan
            ),  # fmt: skip
            "rejected": count["rejected"],
            "no_read": sum(p.ever_no_read for p in ps),
            "solver_failures": count["failed"],
            "swept_sector_intrusions": sum(u.intrusions for u in self.units),
            "parcels_over_limits": over_limits(units.values()),
            "handoffs": self.handoffs,
            "links": self.links().table(),
            "handoffs_balanced": self.links().balanced(),
            "declined": {r: sum(u.declined[r] for u in self.units) for r in REASONS},
            "induction_rate_pcs_h": per_hour(firsts),
            "throughput_in_pcs_h": throughput_in,
            "throughput_out_pcs_h": throughput_out,
            "steady_window": steady,
            "steady": st,
            "merge_wait_mean_s": self.merges_waited / max(self.inductions - n, 1),
            "induction_hold_s": self.hold,
            "still_on_line": on_line,
            "conservation_ok": n
            == count["sorted"] + count["rejected"] + count["failed"] + on_line,
            "drained": on_line == 0,
            "sim_time_s": self.t,
            "wall_time_s": self.wall,
            "real_time_factor": self.t / self.wall if self.wall > 0 else math.nan,
            "units": units,
        }

    def loop_cycle(self) -> float:
        """One loop cycle [s]: a parcel's ride along the belt (length / v) and the loop back."""
        return self.spec.length / self.v + self.spec.transit_time

    def steady_window(self) -> dict | None:
        """The steady-state window of the run and its counts (:func:`~fence_sorter.line.
        steady.steady_window`), as users of sortation lines measure throughput: from one loop
        cycle after the first parcel's first induction to the last parcel's first induction.
        None when the induction ran no longer than a loop cycle (no steady state)."""
        return _steady_window(self.parcels, self.loop_cycle())

    def links(self) -> LinkCounts:
        """Hand-offs per link, counted at both ends (the units count their own); a hand-off
        still pending for a parcel on the line is neither received nor lost yet."""
        lc = LinkCounts()
        first = link_name(INDUCTION, 0, self.names)
        lc.sent[first] = self.induction_sent
        for u in self.units:
            up = link_name(u.upstream, u.index, self.names)
            lc.received[up] = u.received
            lc.refused[up] = dict(u.refused_handoffs)
            lc.lost[up] = u.lost
            lc.sent[link_name(u.index, u.downstream, self.names)] = u.sent
        last = link_name(len(self.units) - 1, RECIRCULATION, self.names)
        lc.received[last] = self.recirculation_received
        lc.lost[last] = self.recirculation_lost
        return lc

    def unit_capacity(self, u: LineUnit) -> float:
        """W_t (1) with Delta_c (2) of the unit's median stroke (by scraping time t_z) and the
        stream's median parcel length [pcs/h]; NaN before its first stroke."""
        if not u.strokes:
            return math.nan
        tz = sorted(u.strokes, key=lambda st: 2.0 * st[1] + abs(st[0]) / self.v)
        r_s, t1 = tz[len(tz) // 2]
        a = float(np.median([p.spec.length_a for p in self.parcels]))
        return stroke_capacity(self.v, t1, r_s, a, self.spec.planner.pitch_gap)


def owner_chute(served: tuple[str, ...], unit: int, destination: str, chute: str) -> str:
    """Where a parcel a unit says it sorted into ``chute`` went, as the owner knows it: that
    chute when it is the parcel's destination (the owner's, not the one its hand-off carried)
    and the unit serves it; else ``wrong:<unit>`` (a unit misled by a hand-off of another
    destination, or one that says so itself)."""
    return chute if chute == destination and chute in served else f"wrong:{unit}"


def line_problems(s: dict) -> list[str]:
    """What keeps a line summary from being clean, one phrase each (empty: clean): not
    drained, conservation violated, a wrong destination, hand-offs unbalanced, (guard on) a
    swept-sector intrusion, a failed event, a sorted parcel over a limit of (10)-(12), a
    reply on a unit's link that answers nothing the owner asked (refused: a forgery or a
    confused process)."""
    out = []
    if not s["drained"]:
        out.append(f"{s['still_on_line']} parcels still on the line")
    if not s["conservation_ok"]:
        out.append("conservation violated")
    if s["sorted_wrong_destination"]:
        out.append(f"{s['sorted_wrong_destination']} parcels sorted to a wrong destination")
    if not s["handoffs_balanced"]:
        out.append("hand-offs sent and received differ")
    if s["guard"] and s["swept_sector_intrusions"]:
        out.append(f"{s['swept_sector_intrusions']} swept-sector intrusions")
    if s["solver_failures"]:
        out.append(f"{s['solver_failures']} failed events")
    for c, ids in s.get("parcels_over_limits", {}).items():
        if ids:
            out.append(f"({c}) {len(ids)} sorted parcels over it {ids[:20]}")
    for name, refused in s.get("replies_refused", {}).items():
        out.append(f"{name}: {len(refused)} replies the owner did not ask for {refused[:5]}")
    return out


def over_limits(units) -> dict[str, list[int]]:
    """Per active limit of (10)-(12): the parcels sorted over it, on any unit (the units'
    ``over_limits`` figures merged)."""
    out: dict[str, set[int]] = {}
    for u in units:
        for c, ids in u["over_limits"].items():
            out.setdefault(c, set()).update(ids)
    return {c: sorted(ids) for c, ids in sorted(out.items(), key=lambda kv: int(kv[0]))}


def run_line(line: LineSpec, cfg: LineRunConfig = LineRunConfig(), warm: bool = True) -> dict:
    plant = LinePlant(line, cfg)
    if warm:
        plant.warm_up()
    return plant.run()
