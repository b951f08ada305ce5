"""One fence unit of a line (ROS-free): its simulation, planner, routing and counts.

A :class:`LineUnit` takes parcels entering its zone as :class:`~fence_sorter.line.handoff.
HandOff` records, routes each one (:mod:`fence_sorter.line.routing`: a stroke, or a decline
with its reason), simulates it in its :class:`~fence_sorter.line.one_fence.SortingLine` (its
own frame), and gives back records only: a :class:`~fence_sorter.line.handoff.HandOff` to its
downstream neighbour for a parcel it does not sort (at once when it declines it, with the pose
it received; after a stroke that missed, with the pose the stroke left it in), a
:class:`~fence_sorter.line.handoff.Sorted` or :class:`~fence_sorter.line.handoff.Failed` for
a parcel its stroke ended. What it needs of the rest of the line to guard a stroke is passed in
as :class:`Traffic` (the predicted tracks of the other parcels and the other units' booked
strokes), plain records as well.

The in-process line (:class:`~fence_sorter.line.multi_unit.LinePlant`) wires the units
together; a unit node runs one of them over DDS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from fence_sorter.capacity.delivered import over_plant_limits
from fence_sorter.capacity.planner import LoadRequest, Planner, PlannerConfig
from fence_sorter.codes import OutcomeCode, StartMode
from fence_sorter.inputs import ParcelSpec, StrokeCommand
from fence_sorter.line.handoff import (
    DUPLICATE,
    INDUCTION,
    NOT_FROM_UPSTREAM,
    RECIRCULATION,
    REFUSALS,
    UNKNOWN_PARCEL,
    Failed,
    HandOff,
    Sorted,
)
from fence_sorter.line.line_file import UnitSpec
from fence_sorter.line.one_fence import LineConfig, SortingLine
from fence_sorter.line.routing import (
    CHUTE_FULL,
    FENCE_BUSY,
    NO_FEASIBLE_STROKE,
    NO_READ,
    NOT_SERVED,
    PLANNING_BUDGET,
    REASONS,
    Booking,
    Decision,
    Track,
    footprint,
    guard,
    to_line,
    to_local,
)
from fence_sorter.line.types import Outcome, OverlapWarning, StrokeStarted

__all__ = [
    "ID_STRIDE", "LineUnit", "Record", "StrokeRecord", "Traffic", "UnitReply", "local_offsets",
    "track_of",
]  # fmt: skip

#: a parcel's id in a unit's simulation: line id * ID_STRIDE + pass (ids stay unique per unit)
ID_STRIDE = 16

Record = HandOff | Sorted | Failed


@dataclass(frozen=True)
class Traffic:
    """What a unit's guard must know of the rest of the line when it routes a parcel: the
    predicted tracks of the other parcels (line frame) and the booked strokes of every unit."""

    tracks: tuple[Track, ...] = ()
    bookings: tuple[Booking, ...] = ()


@dataclass
class UnitReply:
    """A unit's answer to a hand-off: refused (``refusal``, a reason of ``REFUSALS``), or taken
    with its routing decision, the booking of the stroke it commanded (None: declined or the
    simulation refused the command) and the records it sends (a declined parcel's hand-off)."""

    refusal: str = ""
    decision: Decision | None = None
    booking: Booking | None = None
    records: list[Record] = field(default_factory=list)


def track_of(h: HandOff, v: float) -> Track:
    """The ride a hand-off predicts: its pose moving on at belt speed ``v``."""
    s = h.spec
    return Track(
        h.parcel_id, s.length_a, s.width_b, s.cog_offset_x, s.cog_offset_y,
        h.x, h.y, h.yaw, h.pose_time, v,
    )  # fmt: skip


@dataclass
class _Held:
    """A parcel the unit took: the hand-off it came with and its stroke, if any."""

    handoff: HandOff
    local_id: int
    stroke: tuple[float, float] | None = None  # (R_s, t1) commanded
    planned: tuple[float, float, float] = (math.nan,) * 3  # predicted w_n, a_N, ydot
    yaw: float = 0.0  # its yaw in the unit's frame when taken [rad]


@dataclass(frozen=True)
class StrokeRecord:
    """One stroke's end, for the line's per-parcel records: the line's parcel and pass, the
    stroke (R_s, t1, alpha_k), the outcome's code and delivered figures (10)-(12) beside the
    planned ones."""

    parcel_id: int
    passes: int
    r_s: float
    t1: float
    alpha_k: float
    code: OutcomeCode
    impact_normal_speed: float  # w_n [m/s]
    peak_normal_accel: float  # a_N [m/s^2]
    exit_speed_y: float  # ydot [m/s]
    planned: tuple[float, float, float]  # w_n, a_N, ydot the planner predicted
    yaw: float  # [rad], the unit's frame


def local_offsets(
    mirrored: bool, yaw: float, cog_x: float, cog_y: float
) -> tuple[float, float, float]:
    """A parcel's yaw (already in the unit's frame) and its C_s offsets (line frame) as the
    unit's simulation takes them: the offsets in the unit's frame, and a turned parcel as the
    same rectangle with yaw in [-pi/2, pi/2] (the C_s offsets flip)."""
    cx, cy = cog_x, (-cog_y if mirrored else cog_y)
    while yaw > 0.5 * math.pi:
        yaw -= math.pi
        cx, cy = -cx, -cy
    while yaw < -0.5 * math.pi:
        yaw += math.pi
        cx, cy = -cx, -cy
    return yaw, cx, cy


class LineUnit:
    """One unit of a line: ``receive`` hand-offs, ``advance`` the sim clock, read ``figures``."""

    def __init__(
        self, spec: UnitSpec, index: int, n_units: int, width: float, speed: float,
        planner: PlannerConfig, dt: float, guard_on: bool = True,
    ):  # fmt: skip
        self.spec = spec
        self.index = index
        self.n_units = n_units
        self.width = width
        self.v = speed
        self.alpha_k = planner.alpha_k
        self.dt = dt
        self.guard_on = guard_on
        self.line = SortingLine(LineConfig.from_scenario(spec.scenario, scan_line_x=None), t0=0.0)
        self.planner = Planner(spec.scenario, planner)
        self.upstream = INDUCTION if index == 0 else index - 1
        self.downstream = RECIRCULATION if index == n_units - 1 else index + 1
        self.known: dict[int, int] = {}  # parcel id -> passes of its latest announcement
        self.announced: dict[int, tuple[ParcelSpec, str]] = {}  # parcel id -> (spec, destination)
        self.lost = 0  # hand-offs not received by their deadline (on the upstream link)
        self._due: dict[int, tuple[tuple, float]] = {}  # parcel id -> (ride, deadline)
        self.taken: set[tuple[int, int]] = set()  # (parcel id, passes) received
        self.held: dict[int, _Held] = {}  # local id -> parcel in a stroke of this unit
        self.missed_strokes: dict[int, set[tuple[float, float]]] = {}  # parcel id -> (R_s, t1)
        self.chute = 0
        self.declined: dict[str, int] = dict.fromkeys(REASONS, 0)
        self.refused_handoffs: dict[str, int] = dict.fromkeys(REFUSALS, 0)
        self.received = 0
        self.sent = 0
        self.accepted = 0
        self.sorted = 0
        self.missed = 0
        self.refused = 0  # commands the unit's simulation refused
        self.failed = 0
        self.intrusions = 0
        self.busy = 0.0  # sum of the strokes' cycles 2 t1 [s]
        self.strokes: list[tuple[float, float]] = []  # (R_s, t1) made
        self.peak_force = 0.0
        self.peak_force_stiff = 0.0
        self.max_impact_speed = 0.0
        self.max_accel = 0.0
        self.late_handoffs = 0
        self.late_past_axis = 0
        self.profile = planner.profile
        # per active limit of (10)-(12): the parcels this unit sorted over it
        self.over_limits: dict[str, list[int]] = {
            str(c): [] for c in (10, 11, 12) if c in planner.profile.active
        }
        self.stroke_records: list[StrokeRecord] = []  # every stroke's end, in order
        # (line id of the parcel found in a stroke's sector, line id of the stroke's parcel)
        self.intruded: list[tuple[int, int]] = []
        self._planned: tuple[float, float, float] = (math.nan,) * 3

    # -- records in ------------------------------------------------------------------------
    def announce(
        self, parcel_id: int, passes: int, spec: ParcelSpec | None = None, destination: str = ""
    ) -> None:
        """The induction scanned this parcel for this pass (its spec and the destination the
        scan read, as the induction's Parcel message carries them): a hand-off may follow."""
        self.known[parcel_id] = passes
        if spec is not None:
            self.announced[parcel_id] = (spec, destination)

    def deadlines(self, t: float, traffic: Traffic) -> list[HandOff]:
        """Hand-offs lost upstream: an announced parcel the traffic puts on the belt at sim
        time ``t``, riding the belt (no stroke of any unit holds it), with its front past
        this unit's fence axis (no stroke can be planned for it any more), and no hand-off
        for it received. Each is counted lost on the upstream link once (a late arrival is
        then refused as a duplicate), and passed on downstream from the line's prediction of
        its ride, so that the units after this one do not count it again."""
        out = []
        for tr in traffic.tracks:
            pid = tr.parcel_id
            passes = self.known.get(pid)
            if passes is None or (pid, passes) in self.taken or pid not in self.announced:
                continue
            if tr.free_after != math.inf:
                continue
            # when its front reaches the axis, kept per ride (a hold or a new pose changes it)
            ride = (tr.x, tr.y, tr.yaw, tr.t_ref, tr.cog_x, tr.cog_y)
            due = self._due.get(pid)
            if due is None or due[0] != ride:
                front = max(c[0] for c in tr.corners(tr.t_ref))
                due = (ride, tr.t_ref + (self.spec.position - front) / self.v)
                self._due[pid] = due
            if t <= due[1]:
                continue
            del self._due[pid]
            self.taken.add((pid, passes))
            self.lost += 1
            spec, dest = self.announced[pid]
            spec = replace(spec, cog_offset_x=tr.cog_x, cog_offset_y=tr.cog_y)
            self.sent += 1
            out.append(
                HandOff(
                    pid,
                    dest,
                    passes,
                    spec,
                    tr.x,
                    tr.y,
                    tr.yaw,
                    self.v,
                    0.0,
                    0.0,
                    tr.t_ref,
                    t,
                    self.index,
                    self.downstream,
                )  # fmt: skip
            )
        return out

    def check(self, h: HandOff) -> str:
        """The reason the unit refuses ``h`` ("" if it takes it)."""
        if self.known.get(h.parcel_id) != h.passes:
            return UNKNOWN_PARCEL
        if h.from_unit != self.upstream or h.to_unit != self.index:
            return NOT_FROM_UPSTREAM
        if (h.parcel_id, h.passes) in self.taken:
            return DUPLICATE
        return ""

    def receive(self, h: HandOff, t: float, traffic: Traffic = Traffic()) -> UnitReply:
        """Take the parcel of ``h`` at sim time ``t`` (its front at or past the unit's scan
        line), route it and put it into the unit's simulation; or refuse the hand-off."""
        why = self.check(h)
        if why:
            self.refused_handoffs[why] += 1
            return UnitReply(refusal=why)
        self.taken.add((h.parcel_id, h.passes))
        self._due.pop(h.parcel_id, None)
        self.received += 1
        track = track_of(h, self.v)
        front = max(c[0] for c in track.corners(t))
        late = front > self.spec.zone[0] + self.v * self.dt + 1e-9
        if not late:
            # the exact crossing of the scan line (within the last step)
            front_ref = max(c[0] for c in track.corners(track.t_ref))
            t_c = track.t_ref + (self.spec.zone[0] - front_ref) / self.v
            spec = self._local_spec(h, track, min(max(t_c, t - self.dt), t), False)
        else:
            spec = self._local_spec(h, track, t, divert=False)
            self.late_handoffs += 1
            if front > self.spec.position:
                self.late_past_axis += 1
        decision, cmd, booking = self._route(h, track, spec, t, traffic)
        if cmd is not None:
            spec = replace(spec, divert=True)
        self.line.add_parcel(spec, t=t)
        reply = UnitReply(decision=decision)
        if cmd is None:
            self.declined[decision.reason] += 1
            reply.records.append(self._pass_on(h, t))
            return reply
        res = self.line.command(cmd, t=t)
        if res.accepted:
            self.accepted += 1
            self.held[spec.parcel_id] = _Held(
                h, spec.parcel_id, (cmd.r_s, cmd.t1), self._planned, spec.yaw
            )
            reply.booking = booking
        else:
            self.refused += 1
            self.declined[FENCE_BUSY if res.code == "fence_busy" else NO_FEASIBLE_STROKE] += 1
            reply.records.append(self._pass_on(h, t))
        return reply

    # -- routing ---------------------------------------------------------------------------
    def _local_spec(self, h: HandOff, tr: Track, t: float, divert: bool) -> ParcelSpec:
        """The parcel as the unit's simulation sees it at time t (unit frame)."""
        u = self.spec
        x, y, yaw = to_local(u.position, u.mirrored, self.width, tr.x + self.v * (t - tr.t_ref),
                             tr.y, tr.yaw)  # fmt: skip
        yaw, cx, cy = local_offsets(u.mirrored, yaw, tr.cog_x, tr.cog_y)
        pts = footprint(tr.length_a, tr.width_b, cx, cy, x, y, yaw)
        front = max(c[0] for c in pts)
        fw = max(c[1] for c in pts) - min(c[1] for c in pts)
        gap = min(max(min(c[1] for c in pts), 0.0), max(self.width - fw, 0.0))
        return replace(
            h.spec,
            parcel_id=h.parcel_id * ID_STRIDE + h.passes,
            cog_offset_x=cx,
            cog_offset_y=cy,
            lateral_gap=gap,
            yaw=yaw,
            divert=divert,
            scan_time=t,
            scan_position_x=front,
        )

    def _route(
        self, h: HandOff, track: Track, spec: ParcelSpec, t: float, traffic: Traffic
    ) -> tuple[Decision, StrokeCommand | None, Booking | None]:
        us = self.spec
        if h.no_read:
            return Decision(False, NO_READ), None, None
        if h.destination not in us.destinations:
            return Decision(False, NOT_SERVED), None, None
        if us.chute_capacity is not None and self.chute >= us.chute_capacity:
            return Decision(False, CHUTE_FULL), None, None
        req = LoadRequest(spec.parcel_id, spec.to_parcel_params(), spec.scan_time,
                          spec.scan_position_x)  # fmt: skip
        others = [tr for tr in traffic.tracks if tr.parcel_id != h.parcel_id]
        missed = self.missed_strokes.get(h.parcel_id, set())
        refusals: list[Decision] = []

        def booking(start: float, end: float) -> Booking:
            return Booking(
                self.index, h.parcel_id, start, end, self.alpha_k,
                self.line.config.length, us.position, us.mirrored,
            )  # fmt: skip

        def clear(ev, start: float, end: float) -> bool:
            """A feasible stroke the unit may make: not one that missed this parcel on an
            earlier pass, and (guard) none another parcel would be struck by; the planner
            passes a refused one over for its next feasible one."""
            if (ev.r_s, ev.t1) in missed:
                return False
            if not self.guard_on:
                return True
            d = guard(booking(start, end), track, others, list(traffic.bookings), self.width)
            if not d.accepted:
                refusals.append(d)
            return d.accepted

        plan = self.planner.plan(req, t, commit=False, accept=clear)
        if not plan.feasible:
            if refusals:
                return refusals[0], None, None
            if plan.budget_ran_out:
                code = PLANNING_BUDGET
            else:
                code = FENCE_BUSY if "fence busy" in plan.reason else NO_FEASIBLE_STROKE
            return Decision(False, code, plan.reason), None, None
        ev = plan.evaluation
        self.planner.busy_until = plan.end_time
        self._planned = (ev.impact_speed, ev.peak_accel, ev.exit_speed)
        cmd = StrokeCommand(spec.parcel_id, StartMode.AT_RS, ev.r_s, 0.0, ev.t1, self.alpha_k)
        return Decision(True), cmd, booking(plan.start_time, plan.end_time)

    # -- records out -----------------------------------------------------------------------
    def _pass_on(self, h: HandOff, t: float) -> HandOff:
        """The hand-off downstream of a parcel the unit left untouched: the pose it came with."""
        self.sent += 1
        return replace(h, t=t, from_unit=self.index, to_unit=self.downstream)

    def _after_stroke(self, held: _Held, t: float) -> HandOff:
        """The hand-off downstream of a parcel its stroke did not sort: the pose the stroke
        left it in, riding on at belt speed."""
        h = held.handoff
        lp = self.line.parcels.get(held.local_id)
        self.sent += 1
        if lp is None:
            return replace(h, t=t, from_unit=self.index, to_unit=self.downstream)
        u = self.spec
        x, y, yaw = to_line(u.position, u.mirrored, self.width, *lp.pose(t))
        cy = -lp.spec.cog_offset_y if u.mirrored else lp.spec.cog_offset_y
        spec = replace(h.spec, cog_offset_x=lp.spec.cog_offset_x, cog_offset_y=cy)
        return replace(
            h, spec=spec, x=x, y=y, yaw=yaw, vx=self.v, vy=0.0, yaw_rate=0.0, pose_time=t, t=t,
            from_unit=self.index, to_unit=self.downstream,
        )  # fmt: skip

    def _on_outcome(self, ev: Outcome, t: float) -> Record | None:
        held = self.held.pop(ev.parcel_id, None)
        if held is None:  # a parcel the unit declined left its zone
            return None
        h = held.handoff
        if held.stroke is not None:
            self.stroke_records.append(
                StrokeRecord(
                    h.parcel_id,
                    h.passes,
                    *held.stroke,
                    self.alpha_k,
                    ev.code,
                    ev.impact_normal_speed,
                    ev.peak_normal_accel,
                    ev.exit_speed_y,
                    held.planned,
                    held.yaw,
                )  # fmt: skip
            )
        if ev.code in (OutcomeCode.SORTED, OutcomeCode.MISSED) and math.isfinite(
            ev.peak_normal_force
        ):
            self.peak_force = max(self.peak_force, ev.peak_normal_force)
            self.peak_force_stiff = max(self.peak_force_stiff, ev.peak_normal_force_stiff)
            self.max_impact_speed = max(self.max_impact_speed, ev.impact_normal_speed)
            self.max_accel = max(self.max_accel, ev.peak_normal_accel)
        if ev.code is OutcomeCode.SORTED:
            figures = {
                "impact_normal_speed": ev.impact_normal_speed,
                "peak_normal_accel": ev.peak_normal_accel,
                "exit_speed_y": ev.exit_speed_y,
            }
            for c in over_plant_limits(figures, self.profile):
                self.over_limits[str(c)].append(h.parcel_id)
            self.sorted += 1
            self.chute += 1
            ok = h.destination in self.spec.destinations
            chute = h.destination if ok else f"wrong:{self.index}"
            return Sorted(h.parcel_id, self.index, chute, t)
        if ev.code is OutcomeCode.SOLVER_FAILURE:
            self.failed += 1
            return Failed(h.parcel_id, self.index, t, ev.reason)
        if ev.code is OutcomeCode.MISSED:
            self.missed += 1
            if held.stroke is not None:  # not that stroke again on a later pass
                self.missed_strokes.setdefault(h.parcel_id, set()).add(held.stroke)
        return self._after_stroke(held, t)

    def advance(self, t: float, stamp: float | None = None) -> list[Record]:
        """Step the unit's simulation to sim time ``t``; the records its strokes' ends send,
        stamped ``stamp`` (default ``t``; the in-process line stamps them with its clock's
        time during the step, the step's start)."""
        out: list[Record] = []
        at = t if stamp is None else stamp
        for ev in self.line.advance(t):
            if isinstance(ev, Outcome):
                rec = self._on_outcome(ev, at)
                if rec is not None:
                    out.append(rec)
            elif isinstance(ev, OverlapWarning):
                self.intrusions += 1
                self.intruded.append(
                    (ev.other_parcel_id // ID_STRIDE, ev.stroke_parcel_id // ID_STRIDE)
                )
            elif isinstance(ev, StrokeStarted):
                self.busy += 2.0 * ev.t1
                self.strokes.append((ev.r_s, ev.t1))
        return out

    # -- figures ---------------------------------------------------------------------------
    def figures(self, t: float) -> dict:
        """The unit's counts and extremes at sim time ``t`` (the line summary's per-unit part)."""
        u = self.spec
        return {
            "side": u.side,
            "position_m": u.position,
            "destinations": list(u.destinations),
            "handoffs_in": self.received,
            "handoffs_out": self.sent,
            "handoffs_refused": dict(self.refused_handoffs),
            "handoffs_lost": self.lost,
            "late_handoffs": self.late_handoffs,
            "late_handoffs_past_axis": self.late_past_axis,
            "strokes": self.accepted,
            "sorted": self.sorted,
            "missed": self.missed,
            "commands_refused": self.refused,
            "solver_failures": self.failed,
            "declined": dict(self.declined),
            "swept_sector_intrusions": self.intrusions,
            "utilisation": self.busy / t if t > 0 else 0.0,
            "peak_normal_force_N": self.peak_force,
            "peak_normal_force_stiff_N": self.peak_force_stiff,
            "max_impact_speed_m_s": self.max_impact_speed,
            "max_normal_accel_m_s2": self.max_accel,
            "over_limits": {c: list(ids) for c, ids in self.over_limits.items()},
        }

    def in_stroke(self, parcel_id: int) -> bool:
        """True while a stroke of this unit holds the line's parcel ``parcel_id``."""
        return any(hd.handoff.parcel_id == parcel_id for hd in self.held.values())
