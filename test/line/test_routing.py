"""The swept-sector guard: closed-form geometry of a parcel riding into the sector of a stroke.

A stroke at alpha_k sweeps the sector r < R_z, 0 < angle < alpha_k about the fence axis. A
parcel on the belt at lateral gap g (its lowest edge at y0 = g, yaw 0) first touches the sector
with its front corner (x_f, g), when atan2(g, x_f) < alpha_k, i.e. x_f > g / tan(alpha_k); the
guard must find exactly that within the interval of the stroke.
"""

from __future__ import annotations

import math

import pytest

from fence_sorter.line.routing import (
    SECTOR_OCCUPIED,
    Booking,
    Track,
    convex_hull,
    guard,
    to_line,
    to_local,
    track_hits_sector,
)

W = 0.7  # belt width [m]
V = 1.0  # belt speed [m/s]
R_Z = 1.2
ALPHA = math.radians(40.0)
POS = 5.0  # fence axis at X = 5 m


def riding(pid: int, front_x: float, gap: float, t: float = 0.0, a=0.4, b=0.3) -> Track:
    """A parcel (yaw 0, C_s centred) with its front at X = front_x, lowest edge at Y = gap."""
    return Track(pid, a, b, 0.0, 0.0, front_x - 0.5 * a, gap + 0.5 * b, 0.0, t, V)


def booking(t0: float, t1: float, mirrored=False, unit=0, pid=99) -> Booking:
    return Booking(unit, pid, t0, t1, ALPHA, R_Z, POS, mirrored)


def test_clearly_inside_and_outside():
    inside = riding(1, POS + 0.8, 0.1)  # front 0.8 m past the axis, close to the border
    assert track_hits_sector(inside, booking(0.0, 0.1), W)
    far = riding(2, POS - 3.0, 0.1)  # 3 m upstream, a 1 s stroke: 1 m of travel
    assert not track_hits_sector(far, booking(0.0, 1.0), W)
    gone = riding(3, POS + R_Z + 0.5 + 0.4, 0.1)  # rear 0.5 m beyond the fence tip
    assert not track_hits_sector(gone, booking(0.0, 1.0), W)


@pytest.mark.parametrize("gap", [0.05, 0.2, 0.35])
def test_entering_during_the_stroke(gap):
    """Front at X = POS - 0.5 at t = 0, stroke [0, T]: it enters iff 0.5 + V T exceeds the
    closed-form threshold g / tan(alpha_k) (beyond the 1 mm tolerance)."""
    x_star = gap / math.tan(ALPHA)
    tr = riding(1, POS - 0.5, gap)
    t_enter = (0.5 + x_star) / V
    assert not track_hits_sector(tr, booking(0.0, t_enter - 0.01), W)
    assert track_hits_sector(tr, booking(0.0, t_enter + 0.01), W)
    # the same stroke later in time: the parcel has passed in front of the axis already
    assert track_hits_sector(tr, booking(t_enter + 0.2, t_enter + 0.3), W)


def test_mirrored_unit_is_the_mirror_image():
    """On the left border the same parcel, mirrored across the belt's centre, gives the same
    answers as on the right."""
    gap = 0.2
    x_star = gap / math.tan(ALPHA)
    t_enter = (0.5 + x_star) / V
    right = riding(1, POS - 0.5, gap)
    left = riding(1, POS - 0.5, W - gap - 0.3)  # its upper edge 0.2 m from the left border
    for t_end, hit in ((t_enter - 0.01, False), (t_enter + 0.01, True)):
        assert track_hits_sector(right, booking(0.0, t_end), W) is hit
        assert track_hits_sector(left, booking(0.0, t_end, mirrored=True), W) is hit
    # the parcel near the right border lies in no left-side sector over the same time
    assert not track_hits_sector(riding(1, POS + 0.3, 0.0), booking(0.0, 0.01, mirrored=True), W)


def test_frames_round_trip():
    for mirrored in (False, True):
        pose = to_local(POS, mirrored, W, 6.1, 0.2, 0.3)
        assert to_line(POS, mirrored, W, *pose) == pytest.approx((6.1, 0.2, 0.3))
    assert to_local(POS, True, W, 6.1, 0.2, 0.3) == pytest.approx((1.1, 0.5, -0.3))


def test_hull_of_a_translated_rectangle():
    a = [(0, 0), (1, 0), (1, 1), (0, 1)]
    b = [(x + 2, y) for x, y in a]
    assert sorted(convex_hull(a + b)) == sorted([(0, 0), (3, 0), (3, 1), (0, 1)])


def test_guard_names_the_intruder_and_the_own_parcel_is_exempt():
    own = riding(1, POS + 0.3, 0.2)
    other = riding(2, POS - 0.45, 0.2)  # enters 0.1 + 0.24 m later
    cand = booking(0.0, 0.7, pid=1)
    d = guard(cand, own, [own, other], [], W)
    assert not d.accepted and d.reason == SECTOR_OCCUPIED and d.intruders == [2]
    assert guard(booking(0.0, 0.2, pid=1), own, [own, other], [], W).accepted


def test_guard_own_parcel_against_a_downstream_booking():
    """A parcel that may stay on the belt after its own stroke (from its start on: a band
    across the belt) must not be able to reach another unit's booked stroke."""
    own = riding(1, POS - 0.2, 0.2)
    cand = booking(0.0, 0.8, unit=0, pid=1)
    down = Booking(1, 7, 4.5, 5.3, ALPHA, R_Z, POS + 5.0, True)  # 5 m on, left side
    d = guard(cand, own, [own], [down], W)
    assert not d.accepted and d.intruders == [7]
    later = Booking(1, 7, 12.0, 12.8, ALPHA, R_Z, POS + 5.0, True)  # long after it passed
    assert guard(cand, own, [own], [later], W).accepted
