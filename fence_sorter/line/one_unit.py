"""The single unit's swept-sector guard (ROS-free): the line's guard
(:func:`fence_sorter.line.routing.guard`) fed with what one controller knows.

The controller of the one-fence line knows every parcel scanned so far (its
:class:`~fence_sorter.inputs.ParcelSpec`: scan time, scan line position, sizes, lateral gap,
yaw) and the strokes it commanded. :class:`UnitTraffic` keeps them as the line's
:class:`~fence_sorter.line.routing.Track` and :class:`~fence_sorter.line.routing.Booking`
records in the unit's frame O x0 y0 (the line frame of a unit at X = 0, not mirrored), so a
stroke is guarded by the very code the line's units run:

- a parcel riding the belt is predicted kinematically (C_s as the line places it at its scan,
  moving at v);
- a parcel with a commanded stroke may leave the belt's kinematics from that stroke's start on
  (the line's band, :class:`~fence_sorter.line.routing.Track`); a stroke after it on the same
  fence finds it sorted, as its stroke was planned to do ((8) with a reserve): the one fence
  strikes one parcel at a time, so that stroke ended first (the planner's fence-busy window);
- the parcels not yet scanned are one more track (:func:`unscanned`): the belt upstream of the
  scan line at the time of the decision, across its whole width. A stroke is only ever
  accepted when no parcel, scanned or not, can enter its sector while it runs; deciding late
  (:func:`decision_time`) keeps that region far from the sector.
"""

from __future__ import annotations

import math

from fence_sorter.capacity.planner import LoadRequest, Plan, Planner, PlannerConfig
from fence_sorter.inputs import ParcelSpec
from fence_sorter.line.routing import (
    NO_FEASIBLE_STROKE,
    SECTOR_OCCUPIED,
    SETTLE_SLACK,
    Booking,
    Decision,
    Track,
    footprint,
    guard,
)
from fence_sorter.physics.simulate import Scenario

__all__ = [
    "UNSCANNED", "UnitTraffic", "decision_time", "decline_reason", "track_of_spec", "unscanned"
]  # fmt: skip

#: the parcel id of the region of parcels not yet scanned
UNSCANNED = -1
#: length of that region upstream of the scan line [m] (any belt ahead of the scanner)
UNSCANNED_LENGTH = 1000.0
#: a parcel scanned up to this long before a decision may not have reached the controller yet
#: (the middleware's delivery): the region of the parcels not scanned starts that far on [s]
IN_FLIGHT = 0.1
#: sim time between the decision on a parcel and its earliest admissible stroke start, beyond
#: the planner's start margin: the planning itself and the command's delivery [s]
DECISION_LEAD = 0.3


def track_of_spec(spec: ParcelSpec, v: float) -> Track:
    """The ride of a scanned parcel: C_s placed as the line places it (front at
    ``scan_position_x``, lowest point at ``lateral_gap``, at ``scan_time``), moving at v."""
    pts = footprint(
        spec.length_a, spec.width_b, spec.cog_offset_x, spec.cog_offset_y, 0.0, 0.0, spec.yaw
    )
    x = spec.scan_position_x - max(c[0] for c in pts)
    y = spec.lateral_gap - min(c[1] for c in pts)
    return Track(
        int(spec.parcel_id), spec.length_a, spec.width_b, spec.cog_offset_x,
        spec.cog_offset_y, x, y, spec.yaw, spec.scan_time, v,
    )  # fmt: skip


def unscanned(scan_line_x: float, t: float, width: float, v: float) -> Track:
    """The parcels not yet scanned at time ``t``: the whole belt width upstream of the scan
    line then, riding at v."""
    return Track(
        UNSCANNED, UNSCANNED_LENGTH, width, 0.0, 0.0,
        scan_line_x - 0.5 * UNSCANNED_LENGTH, 0.5 * width, 0.0, t, v,
    )  # fmt: skip


def decision_time(spec: ParcelSpec, v: float, config: PlannerConfig) -> float:
    """When to plan a parcel: as late as its earliest stroke (front at ``r_s_min``) still
    allows, so that as many parcels behind it as can be are scanned by then."""
    earliest = spec.scan_time + (config.r_s_min - spec.scan_position_x) / v
    return earliest - config.start_margin - DECISION_LEAD


def decline_reason(plan: Plan) -> str:
    """The reason code of a plan without a stroke: the guard's, or no feasible stroke."""
    return SECTOR_OCCUPIED if plan.reason.startswith(SECTOR_OCCUPIED) else NO_FEASIBLE_STROKE


class UnitTraffic:
    """The tracks of the scanned parcels and the commanded strokes of one fence unit.

    ``length``: R_z of the fence; ``width``: belt width s; ``v``: belt speed;
    ``scan_line_x``: the scan line (unit frame); the most downstream scan position seen
    counts if it lies further on."""

    def __init__(self, length: float, width: float, v: float, scan_line_x: float):
        self.length = length
        self.width = width
        self.v = v
        self.scan_line_x = scan_line_x
        self.tracks: dict[int, Track] = {}
        self.bookings: list[Booking] = []
        self.ends: dict[int, float] = {}  # parcel id -> end of its commanded stroke [s]

    @classmethod
    def of_scenario(cls, sc: Scenario, scan_line_x: float) -> UnitTraffic:
        """The traffic of a scene's fence and belt."""
        length = sc.fence.length if sc.fence is not None else sc.fence_length
        return cls(length, sc.conveyor.width, sc.conveyor.belt_speed, scan_line_x)

    def scanned(self, spec: ParcelSpec) -> None:
        """A parcel was scanned (to divert or not): its predicted ride."""
        self.tracks[int(spec.parcel_id)] = track_of_spec(spec, self.v)
        self.scan_line_x = max(self.scan_line_x, spec.scan_position_x)

    def booking(self, parcel_id: int, start: float, end: float, alpha_k: float) -> Booking:
        return Booking(0, parcel_id, start, end, alpha_k, self.length, 0.0, False)

    def guard(
        self, parcel_id: int, start: float, end: float, alpha_k: float, now: float
    ) -> Decision:
        """The line's guard for a stroke of ``parcel_id`` over [start, end] decided at sim
        time ``now``: the other scanned parcels and those not scanned by ``now`` (less
        ``IN_FLIGHT``)."""
        own = self.tracks[parcel_id]
        others = [
            tr
            for pid, tr in self.tracks.items()
            if pid != parcel_id and self.ends.get(pid, math.inf) > start
        ]
        others.append(unscanned(self.scan_line_x, now - IN_FLIGHT, self.width, self.v))
        cand = self.booking(parcel_id, start, end, alpha_k)
        return guard(cand, own, others, self.bookings, self.width)

    def plan(self, planner: Planner, req: LoadRequest, now: float, **options) -> Plan:
        """The planner's first feasible stroke the guard accepts (``commit=False``); none
        accepted: the plan's reason names the guard (``sector_occupied: ...``) and the
        parcels of the first stroke it refused. ``options``: the planner's own (its
        ``deadline``)."""
        if req.parcel_id not in self.tracks:  # past the fence's reach: no stroke to guard
            return planner.plan(req, now, commit=False, **options)
        alpha_k = planner.config.alpha_k
        refusals: list[tuple[Decision, float, float, float, float]] = []

        def clear(ev, start: float, end: float) -> bool:
            d = self.guard(req.parcel_id, start, end, alpha_k, now)
            if not d.accepted:
                refusals.append((d, ev.r_s, ev.t1, start, end))
            return d.accepted

        plan = planner.plan(req, now, commit=False, accept=clear, **options)
        if not plan.feasible and refusals:
            plan = self._second_search(planner, req, now, clear, options) or plan
        if not plan.feasible and refusals:
            d, r_s, t1, start, end = refusals[0]
            who = ", ".join("not yet scanned" if i == UNSCANNED else str(i) for i in d.intruders)
            plan.reason = (
                f"{SECTOR_OCCUPIED}: parcel(s) {who} in the swept sector of the stroke "
                f"R_s = {r_s:g} m, t1 = {t1:g} s [{start:.3f}, {end:.3f}] s"
                + (f" ({len(refusals)} strokes refused)" if len(refusals) > 1 else "")
            )
        return plan

    def _second_search(self, planner: Planner, req: LoadRequest, now: float, clear, options):
        """The planner's search again over the admissible candidates whose times alone the
        guard accepts (its search probes a few candidates, spread over all of them); the
        planner's hints stay those of the physics alone. None if none is feasible."""
        alpha_k = planner.config.alpha_k
        by_start: dict[float, list[float]] = {}
        for r_s, t1 in planner.admissible(req, now):
            by_start.setdefault(r_s, []).append(t1)
        clear_times = set()
        for r_s, t1s in by_start.items():
            start = req.scan_time + (r_s - req.scan_position_x) / planner.v
            for t1 in sorted(t1s):  # a longer stroke from the same start sweeps a superset
                if not self.guard(req.parcel_id, start, start + 2.0 * t1, alpha_k, now).accepted:
                    break
                clear_times.add((r_s, t1))
        if not clear_times:
            return None
        saved, chosen = planner.candidate_list, dict(planner.chosen)
        planner.candidate_list = [c for c in saved if c in clear_times]  # W_t order kept
        try:
            plan = planner.plan(req, now, commit=False, accept=clear, **options)
        finally:
            planner.candidate_list, planner.chosen = saved, chosen
        return plan if plan.feasible else None

    def book(self, parcel_id: int, start: float, end: float, alpha_k: float) -> None:
        """A stroke was commanded: its parcel may leave the belt from ``start`` on."""
        self.bookings.append(self.booking(parcel_id, start, end, alpha_k))
        self.ends[parcel_id] = end
        tr = self.tracks[parcel_id]
        tr.free_after = start
        tr.free_until = end + SETTLE_SLACK

    def prune(self, t: float) -> None:
        """Forget what can no longer reach a sector at or after ``t``: a track whose region
        is downstream of the fence's reach, a booking whose stroke is over."""
        self.tracks = {
            pid: tr
            for pid, tr in self.tracks.items()
            if min(x for x, _ in tr.region(t, t, self.width)) <= self.length
        }
        self.ends = {pid: e for pid, e in self.ends.items() if pid in self.tracks or e > t}
        self.bookings = [b for b in self.bookings if b.t_end > t]
