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
from dataclasses import dataclass, field, replace

import numpy as np

from fence_sorter.capacity.formulas import stroke_capacity
from fence_sorter.capacity.planner import LoadRequest, Planner
from fence_sorter.codes import OutcomeCode, StartMode
from fence_sorter.inputs import ParcelSpec, StrokeCommand
from fence_sorter.line.line_file import UNIT_LEAD, LineSpec, UnitSpec
from fence_sorter.line.one_fence import LineConfig, SortingLine
from fence_sorter.line.routing import (
    CHUTE_FULL,
    FENCE_BUSY,
    NO_FEASIBLE_STROKE,
    NO_READ,
    NOT_SERVED,
    REASONS,
    SETTLE_SLACK,
    Booking,
    Decision,
    Track,
    footprint,
    guard,
    to_line,
    to_local,
    track_hits_sector,
)
from fence_sorter.line.types import Outcome, OverlapWarning, StrokeStarted
from fence_sorter.stream.model import generate

__all__ = ["LinePlant", "LineRunConfig", "run_line"]

#: a parcel's id in a unit's simulation: line id * ID_STRIDE + pass (ids stay unique per unit)
ID_STRIDE = 16


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
    inducted_at: float = math.nan  # its first induction [s], after the holds
    sorted_at: float = math.nan  # when its stroke's outcome said sorted [s]
    inducted_last: float = math.nan  # its latest induction [s]
    passes: int = 0  # completed passes
    no_read: bool = False  # this pass
    ever_no_read: bool = False
    # new (not yet announced) | scheduled (announced, front not yet at the induction) | belt |
    # loop | sorted | rejected | failed
    state: str = "new"
    track: Track | None = None
    next_unit: int = 0
    stroke_unit: int | None = None  # unit with a booked or running stroke for it
    stroke: tuple[int, float, float] | None = None  # (unit, R_s, t1) of that stroke
    missed: set[tuple[int, float, float]] = field(default_factory=set)  # strokes that missed it
    return_time: float = math.nan
    end: str = ""  # chute or reject it ended in

    @property
    def local_id(self) -> int:
        return self.pid * ID_STRIDE + self.passes


@dataclass
class _Unit:
    spec: UnitSpec
    index: int
    line: SortingLine
    planner: Planner
    chute: int = 0
    declined: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REASONS, 0))
    accepted: int = 0
    sorted: int = 0
    missed: int = 0
    refused: int = 0  # commands the unit's simulation refused
    failed: int = 0
    intrusions: int = 0
    busy: float = 0.0  # sum of the strokes' cycles 2 t1 [s]
    strokes: list[tuple[float, float]] = field(default_factory=list)  # (R_s, t1) made
    peak_force: float = 0.0
    peak_force_stiff: float = 0.0
    max_impact_speed: float = 0.0
    max_accel: float = 0.0
    handoffs_in: int = 0
    late_handoffs: int = 0
    late_past_axis: int = 0


class LinePlant:
    """The line's state and clock; :meth:`run` to the drain, :meth:`summary` for the figures."""

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
        self.live: list[_LP] = []  # announced and not yet ended (sorted, rejected, failed)
        self.by_local: dict[int, _LP] = {}
        self.units = [self._make_unit(i, u) for i, u in enumerate(line.units)]
        self.bookings: list[Booking] = []
        self._next_new = 0  # index of the next stream parcel to announce
        self.horizon = self._horizon()
        self.inductions = 0
        self.merges_waited = 0.0  # summed waiting time of returning parcels at the merge [s]
        self.hold = 0.0  # the induction's summed hold of the stream for returning parcels [s]
        self.handoffs = 0
        self.wall = 0.0

    # -- set-up ----------------------------------------------------------------------------
    def _make_unit(self, i: int, u: UnitSpec) -> _Unit:
        cfg = LineConfig.from_scenario(u.scenario, scan_line_x=None)
        planner = Planner(u.scenario, self.spec.planner)
        return _Unit(u, i, SortingLine(cfg, t0=0.0), planner)

    def _horizon(self) -> float:
        """How far ahead a stroke can be booked: from a unit's scan line to the end of the
        latest stroke the planner may choose [s]; new parcels are announced this early."""
        pc = self.spec.planner
        return (UNIT_LEAD + pc.r_s_max) / self.v + 2.0 * pc.t1_max + 1.0

    def warm_up(self, time_budget: float = 10.0) -> None:
        """Fill each planner's cache from the stream's parcels (and load the JIT)."""
        loads = [p.spec.to_parcel_params() for p in self.parcels[:200]]
        for u in self.units:
            u.planner.warm_up(loads, time_budget=time_budget / max(len(self.units), 1))

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
        if math.isnan(p.inducted_at):
            p.inducted_at = t
        p.inducted_last = t
        self.inductions += 1

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
            self.hold += delay
            self.merges_waited += self.t - p.return_time
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
        self.hold += delay

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
    def _local_spec(self, p: _LP, u: UnitSpec, t: float, divert: bool) -> ParcelSpec:
        """The parcel as the unit's simulation sees it at time t (unit frame)."""
        tr = p.track
        x, y, yaw = to_local(u.position, u.mirrored, self.width, tr.x + self.v * (t - tr.t_ref),
                             tr.y, tr.yaw)  # fmt: skip
        cx, cy = tr.cog_x, (-tr.cog_y if u.mirrored else tr.cog_y)
        # a turned parcel: the same rectangle with yaw in [-pi/2, pi/2] (C_s offsets flip)
        while yaw > 0.5 * math.pi:
            yaw -= math.pi
            cx, cy = -cx, -cy
        while yaw < -0.5 * math.pi:
            yaw += math.pi
            cx, cy = -cx, -cy
        pts = footprint(tr.length_a, tr.width_b, cx, cy, x, y, yaw)
        front = max(c[0] for c in pts)
        fw = max(c[1] for c in pts) - min(c[1] for c in pts)
        gap = min(max(min(c[1] for c in pts), 0.0), max(self.width - fw, 0.0))
        return replace(
            p.spec,
            parcel_id=p.local_id,
            cog_offset_x=cx,
            cog_offset_y=cy,
            lateral_gap=gap,
            yaw=yaw,
            divert=divert,
            scan_time=t,
            scan_position_x=front,
        )

    def _route(self, p: _LP, u: _Unit, spec: ParcelSpec) -> tuple[Decision, StrokeCommand | None]:
        us = u.spec
        if p.no_read:
            return Decision(False, NO_READ), None
        if p.destination not in us.destinations:
            return Decision(False, NOT_SERVED), None
        if us.chute_capacity is not None and u.chute >= us.chute_capacity:
            return Decision(False, CHUTE_FULL), None
        req = LoadRequest(spec.parcel_id, spec.to_parcel_params(), spec.scan_time,
                          spec.scan_position_x)  # fmt: skip
        alpha_k = self.spec.planner.alpha_k
        others = [tr for tr in self._live_tracks() if tr.parcel_id != p.pid]
        refusals: list[Decision] = []

        def booking(start: float, end: float) -> Booking:
            return Booking(
                u.index, p.pid, start, end, alpha_k,
                u.line.config.length, us.position, us.mirrored,
            )  # fmt: skip

        def clear(ev, start: float, end: float) -> bool:
            """A feasible stroke the unit may make: not one that missed this parcel on an
            earlier pass, and (guard) none another parcel would be struck by; the planner
            passes a refused one over for its next feasible one."""
            if (u.index, ev.r_s, ev.t1) in p.missed:
                return False
            if not self.cfg.guard:
                return True
            d = guard(booking(start, end), p.track, others, self.bookings, self.width)
            if not d.accepted:
                refusals.append(d)
            return d.accepted

        plan = u.planner.plan(req, self.t, commit=False, accept=clear)
        if not plan.feasible:
            if refusals:
                return refusals[0], None
            code = FENCE_BUSY if "fence busy" in plan.reason else NO_FEASIBLE_STROKE
            return Decision(False, code, plan.reason), None
        ev = plan.evaluation
        self.bookings.append(booking(plan.start_time, plan.end_time))
        u.planner.busy_until = plan.end_time
        p.track.free_after = plan.start_time
        p.track.free_until = plan.end_time + SETTLE_SLACK
        p.stroke = (u.index, ev.r_s, ev.t1)
        cmd = StrokeCommand(spec.parcel_id, StartMode.AT_RS, ev.r_s, 0.0, ev.t1, alpha_k)
        return Decision(True), cmd

    def _hand_off(self, p: _LP, u: _Unit, late: bool) -> None:
        spec = self._local_spec(p, u.spec, self.t, divert=False)
        if not late:
            # the exact crossing of the scan line (within the last step)
            t_c = p.track.t_ref + (u.spec.zone[0] - (self._front(p.track, p.track.t_ref))) / self.v
            spec = self._local_spec(p, u.spec, min(max(t_c, self.t - self.cfg.dt), self.t), False)
        else:
            u.late_handoffs += 1
            if self._front(p.track, self.t) > u.spec.position:
                u.late_past_axis += 1
        decision, cmd = self._route(p, u, spec)
        if cmd is not None:
            spec = replace(spec, divert=True)
        u.line.add_parcel(spec, t=self.t)
        self.by_local[spec.parcel_id] = p
        u.handoffs_in += 1
        self.handoffs += 1
        p.next_unit = u.index + 1
        if cmd is None:
            u.declined[decision.reason] += 1
            return
        res = u.line.command(cmd, t=self.t)
        if res.accepted:
            u.accepted += 1
            p.stroke_unit = u.index
        else:
            u.refused += 1
            u.declined[FENCE_BUSY if res.code == "fence_busy" else NO_FEASIBLE_STROKE] += 1
            p.track.free_after = p.track.free_until = math.inf
            self.bookings = [b for b in self.bookings if b.parcel_id != p.pid]

    def _hand_offs(self) -> None:
        for p in self.live:
            if (
                p.state == "scheduled"
                and p.track.t_ref <= self.t
                and self._front(p.track, self.t) >= 0.0
            ):
                p.state = "belt"
            if p.state != "belt" or p.stroke_unit is not None:
                continue
            while p.next_unit < len(self.units):
                u = self.units[p.next_unit]
                front = self._front(p.track, self.t)
                if front < u.spec.zone[0]:
                    break
                late = front > u.spec.zone[0] + self.v * self.cfg.dt + 1e-9
                self._hand_off(p, u, late)
                if p.stroke_unit is not None:
                    break

    # -- unit events -----------------------------------------------------------------------
    def _on_outcome(self, u: _Unit, ev: Outcome) -> None:
        p = self.by_local.get(ev.parcel_id)
        if p is None or p.stroke_unit != u.index or p.state != "belt":
            return
        p.stroke_unit = None
        self.bookings = [b for b in self.bookings if b.parcel_id != p.pid]
        if ev.code is OutcomeCode.SORTED:
            p.state = "sorted"
            p.sorted_at = self.t
            p.end = p.destination if p.destination in u.spec.destinations else f"wrong:{u.index}"
            p.track = None
            u.sorted += 1
            u.chute += 1
        elif ev.code is OutcomeCode.SOLVER_FAILURE:
            p.state = "failed"
            p.track = None
            u.failed += 1
        else:
            if ev.code is OutcomeCode.MISSED:
                u.missed += 1
                if p.stroke is not None:  # not that stroke again on a later pass
                    p.missed.add(p.stroke)
            lp = u.line.parcels.get(ev.parcel_id)
            if lp is not None:  # rides on with the pose its stroke left it in
                x, y, yaw = to_line(u.spec.position, u.spec.mirrored, self.width,
                                    *lp.pose(self.t))  # fmt: skip
                cy = -lp.spec.cog_offset_y if u.spec.mirrored else lp.spec.cog_offset_y
                p.track = replace(
                    p.track, x=x, y=y, yaw=yaw, t_ref=self.t, cog_x=lp.spec.cog_offset_x,
                    cog_y=cy, free_after=math.inf, free_until=math.inf,
                )  # fmt: skip
            else:
                p.track.free_after = p.track.free_until = math.inf
        if ev.code in (OutcomeCode.SORTED, OutcomeCode.MISSED) and math.isfinite(
            ev.peak_normal_force
        ):
            u.peak_force = max(u.peak_force, ev.peak_normal_force)
            u.peak_force_stiff = max(u.peak_force_stiff, ev.peak_normal_force_stiff)
            u.max_impact_speed = max(u.max_impact_speed, ev.impact_normal_speed)
            u.max_accel = max(u.max_accel, ev.peak_normal_accel)

    def _leave_belt(self) -> None:
        for p in self.live:
            if p.state != "belt" or p.stroke_unit is not None:
                continue
            if self._rear(p.track, self.t) < self.spec.length:
                continue
            p.passes += 1
            p.track = None
            if p.passes >= self.spec.max_passes:
                p.state = "rejected"
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
        t_next = self.t + self.cfg.dt
        for u in self.units:
            for ev in u.line.advance(t_next):
                if isinstance(ev, Outcome):
                    self._on_outcome(u, ev)
                elif isinstance(ev, OverlapWarning):
                    u.intrusions += 1
                elif isinstance(ev, StrokeStarted):
                    u.busy += 2.0 * ev.t1
                    u.strokes.append((ev.r_s, ev.t1))
        self.t = t_next
        self._leave_belt()
        self.live = [p for p in self.live if p.state not in ("sorted", "rejected", "failed")]
        running = {p.pid for p in self.live if p.stroke_unit is not None}
        self.bookings = [b for b in self.bookings if b.t_end > self.t or b.parcel_id in running]

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
        # throughput in: parcels per hour over the span of their first inductions (after the
        # holds for returning parcels), widened by one mean pitch; out: sorts per hour while
        # the induction ran, that window shifted by the median induction-to-sort time of the
        # sorted parcels (a finite stream's recirculated tail, sorted
        # after the induction stopped, is left out: in steady state it is sorted in the
        # window as well); the induction-to-sort time is the sorting pass's
        firsts = [p.inducted_at for p in ps if not math.isnan(p.inducted_at)]
        throughput_in = _per_hour(firsts)
        delays = sorted(p.sorted_at - p.inducted_last for p in ps if p.state == "sorted")
        if delays and len(firsts) > 1 and throughput_in > 0:
            lag = delays[len(delays) // 2]
            window = len(firsts) * 3600.0 / throughput_in
            w0 = min(firsts) + lag
            out = sum(w0 <= p.sorted_at < w0 + window for p in ps if p.state == "sorted")
            throughput_out = 3600.0 * out / window
        else:
            throughput_out = math.nan
        prof = self.spec.planner.profile
        units = {}
        for u in self.units:
            units[u.spec.name] = {
                "side": u.spec.side,
                "position_m": u.spec.position,
                "destinations": list(u.spec.destinations),
                "handoffs_in": u.handoffs_in,
                "late_handoffs": u.late_handoffs,
                "late_handoffs_past_axis": u.late_past_axis,
                "strokes": u.accepted,
                "sorted": u.sorted,
                "missed": u.missed,
                "commands_refused": u.refused,
                "solver_failures": u.failed,
                "declined": dict(u.declined),
                "swept_sector_intrusions": u.intrusions,
                "utilisation": u.busy / self.t if self.t > 0 else 0.0,
                "peak_normal_force_N": u.peak_force,
                "peak_normal_force_stiff_N": u.peak_force_stiff,
                "max_impact_speed_m_s": u.max_impact_speed,
                "max_normal_accel_m_s2": u.max_accel,
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
            "handoffs": self.handoffs,
            "declined": {r: sum(u.declined[r] for u in self.units) for r in REASONS},
            "throughput_in_pcs_h": throughput_in,
            "throughput_out_pcs_h": throughput_out,
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

    def unit_capacity(self, u: _Unit) -> float:
        """W_t (1) with Delta_c (2) of the unit's median stroke (by scraping time t_z) and the
        stream's median parcel length [pcs/h]; NaN before its first stroke."""
        if not u.strokes:
            return math.nan
        tz = sorted(u.strokes, key=lambda st: 2.0 * st[1] + abs(st[0]) / self.v)
        r_s, t1 = tz[len(tz) // 2]
        a = float(np.median([p.spec.length_a for p in self.parcels]))
        return stroke_capacity(self.v, t1, r_s, a, self.spec.planner.pitch_gap)


def _per_hour(times: list[float]) -> float:
    """Events per hour over the span of ``times`` widened by one mean interval (NaN if < 2)."""
    if len(times) < 2:
        return math.nan
    span = max(times) - min(times)
    window = span * len(times) / (len(times) - 1)
    return 3600.0 * len(times) / window if window > 0 else math.nan


def run_line(line: LineSpec, cfg: LineRunConfig = LineRunConfig(), warm: bool = True) -> dict:
    plant = LinePlant(line, cfg)
    if warm:
        plant.warm_up()
    return plant.run()
