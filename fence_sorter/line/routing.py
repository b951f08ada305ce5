"""Routing on a line of fence units, with the swept-sector guard (ROS-free, plain functions).

A unit takes a parcel at its scan line and either plans a stroke for it (the controller's
:class:`~fence_sorter.capacity.planner.Planner`) or declines it with a reason code
(:data:`REASONS`). The guard declines a stroke when any other parcel would lie in the fence's
swept sector (radius R_z about the axis, angles 0 to alpha_k, frame of the unit) at any time of
the stroke [t_start, t_start + 2 t1], predicted from the belt kinematics: a parcel riding the
belt translates at v, so the region it covers over an interval is the convex hull of its
footprint at both ends, and that hull is tested against the sector
(:func:`fence_sorter.line.sector.in_swept_sector`). A parcel with a stroke of its own ahead may
leave the belt's kinematics from that stroke's start on; from then it is predicted as a band
across the whole belt over the length its footprint can reach. A stroke whose own parcel, if it
is not sorted, would reach into the sector of another unit's booked stroke is declined too.

Frames: "line" (X along the belt from the induction scan line, Y from the right border) and
each unit's local frame O x0 y0 (:mod:`fence_sorter.line.line_file`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from fence_sorter.line.sector import OVERLAP_TOL, in_swept_sector

__all__ = [
    "REASONS",
    "Booking",
    "Decision",
    "Track",
    "convex_hull",
    "footprint",
    "guard",
    "to_local",
    "to_line",
    "track_hits_sector",
]

#: reason codes of a declined parcel
NO_FEASIBLE_STROKE = "no_feasible_stroke"
FENCE_BUSY = "fence_busy"
SECTOR_OCCUPIED = "sector_occupied"
CHUTE_FULL = "chute_full"
NO_READ = "no_read"
NOT_SERVED = "not_served"
#: the unit is down (its process or host is gone): the line's owner passes the parcel on for it
UNIT_DOWN = "unit_down"
#: the planner's cap of evaluations came with candidates left unverified
PLANNING_BUDGET = "planning_budget"
#: after its stroke a parcel left on the belt rides at v again within this time [s] (the
#: solve's settle time, 0.5 s by default, and a reserve)
SETTLE_SLACK = 1.5
REASONS = (
    NO_FEASIBLE_STROKE, FENCE_BUSY, SECTOR_OCCUPIED, CHUTE_FULL, NO_READ, NOT_SERVED, UNIT_DOWN,
    PLANNING_BUDGET,
)  # fmt: skip


def footprint(
    length_a: float, width_b: float, cog_x: float, cog_y: float, x: float, y: float, yaw: float
) -> list[tuple[float, float]]:
    """Corners of a parcel with C_s at (x, y) and yaw (as physics.parcel.world_corners)."""
    c, s = math.cos(yaw), math.sin(yaw)
    geo = (
        (0.5 * length_a, -0.5 * width_b),
        (0.5 * length_a, 0.5 * width_b),
        (-0.5 * length_a, 0.5 * width_b),
        (-0.5 * length_a, -0.5 * width_b),
    )
    out = []
    for gx, gy in geo:
        bx, by = gx - cog_x, gy - cog_y
        out.append((x + c * bx - s * by, y + s * bx + c * by))
    return out


def to_local(
    position: float, mirrored: bool, width: float, x: float, y: float, yaw: float
) -> tuple[float, float, float]:
    """A line pose (X, Y, yaw) in a unit's frame (axis at X = position, mirrored on the left)."""
    if mirrored:
        return x - position, width - y, -yaw
    return x - position, y, yaw


def to_line(
    position: float, mirrored: bool, width: float, x: float, y: float, yaw: float
) -> tuple[float, float, float]:
    """A unit-frame pose in the line frame (the inverse of :func:`to_local`)."""
    if mirrored:
        return x + position, width - y, -yaw
    return x + position, y, yaw


def unit_origin(
    position: float, mirrored: bool, width: float
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """A unit's frame in the line frame as a rigid transform: origin (x, y, z) [m] and
    fixed-axis (roll, pitch, yaw) [rad]. A right unit's frame is the line's moved to the axis
    (position, 0); a left one's is half a turn about X at (position, s): in the belt plane the
    map of :func:`to_line` (Y = s - y, yaw negated), its z pointing down (a mirror is no
    rotation; the turn is the rotation that agrees with it on the belt)."""
    if mirrored:
        return (position, width, 0.0), (math.pi, 0.0, 0.0)
    return (position, 0.0, 0.0), (0.0, 0.0, 0.0)


def convex_hull(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Convex hull, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(set(points))
    if len(pts) <= 2:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple[float, float]] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


@dataclass
class Track:
    """A parcel's predicted ride in the line frame: C_s at (x, y) at ``t_ref``, moving at v.

    From ``free_after`` on (the start of a stroke booked for it) its pose is not predicted: a
    band across the belt from its rear at that time to its front at belt speed, widened by
    its half diagonal (it may turn); from ``free_until`` on (its stroke and the settling after
    it are over) the band's rear moves at v again."""

    parcel_id: int
    length_a: float
    width_b: float
    cog_x: float
    cog_y: float
    x: float
    y: float
    yaw: float
    t_ref: float
    v: float
    free_after: float = math.inf
    free_until: float = math.inf  # from then on it rides at v again (at the latest)

    def corners(self, t: float) -> list[tuple[float, float]]:
        return footprint(
            self.length_a, self.width_b, self.cog_x, self.cog_y,
            self.x + self.v * (t - self.t_ref), self.y, self.yaw,
        )  # fmt: skip

    def region(self, t0: float, t1: float, width: float) -> list[tuple[float, float]]:
        """A convex polygon (line frame) holding the parcel over [t0, t1]."""
        if t1 <= self.free_after:
            return convex_hull(self.corners(t0) + self.corners(t1))
        ta = min(t0, self.free_after)
        diag = math.hypot(self.length_a, self.width_b)
        xs0 = [c[0] for c in self.corners(ta)]
        xs1 = [c[0] for c in self.corners(t1)]
        lo = min(xs0) - diag + self.v * max(0.0, t0 - self.free_until)
        hi = max(xs1) + diag
        return [(lo, 0.0), (hi, 0.0), (hi, width), (lo, width)]


@dataclass(frozen=True)
class Booking:
    """A unit's booked stroke: its sector (unit frame) and time [t_start, t_end]."""

    unit: int
    parcel_id: int
    t_start: float
    t_end: float
    alpha_k: float
    length: float  # R_z [m]
    position: float
    mirrored: bool


@dataclass
class Decision:
    """A unit's answer for a parcel: a stroke (accepted) or a declined reason code."""

    accepted: bool
    reason: str = ""
    detail: str = ""
    intruders: list[int] = field(default_factory=list)


def track_hits_sector(
    track: Track, booking: Booking, width: float, tol: float = OVERLAP_TOL
) -> bool:
    """True if the parcel would lie in the booking's swept sector at any time of its stroke."""
    poly = track.region(booking.t_start, booking.t_end, width)
    local = [to_local(booking.position, booking.mirrored, width, x, y, 0.0)[:2] for x, y in poly]
    if booking.mirrored:
        local.reverse()  # keep the winding after the mirror
    return in_swept_sector(local, booking.length, booking.alpha_k, tol)


def guard(
    candidate: Booking,
    own: Track,
    tracks: list[Track],
    bookings: list[Booking],
    width: float,
) -> Decision:
    """The swept-sector guard for a candidate stroke of ``own``: accepted, or declined
    ``sector_occupied`` naming the parcels that would intrude (in the candidate's sector, or
    ``own`` in another booked stroke's sector should its stroke leave it on the belt)."""
    hits = [
        t.parcel_id
        for t in tracks
        if t.parcel_id != own.parcel_id and track_hits_sector(t, candidate, width)
    ]
    if hits:
        return Decision(
            False,
            SECTOR_OCCUPIED,
            f"parcel(s) {', '.join(map(str, hits))} in the swept sector during the stroke "
            f"[{candidate.t_start:.3f}, {candidate.t_end:.3f}] s",
            hits,
        )
    after = Track(
        **{
            **own.__dict__,
            "free_after": candidate.t_start,
            "free_until": candidate.t_end + SETTLE_SLACK,
        }
    )
    for b in bookings:
        if b.unit == candidate.unit or b.parcel_id == own.parcel_id:
            continue
        if b.t_end <= candidate.t_start:
            continue
        if track_hits_sector(after, b, width):
            return Decision(
                False,
                SECTOR_OCCUPIED,
                f"if not sorted, the parcel could reach the sector of unit {b.unit + 1}'s stroke "
                f"for parcel {b.parcel_id} [{b.t_start:.3f}, {b.t_end:.3f}] s",
                [b.parcel_id],
            )
    return Decision(True)
