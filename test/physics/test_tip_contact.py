"""The fence's end: the face the tip presses on, and loads beyond the tip's reach.

The tip presses on the face its normal ray (from the tip, against the fence normal) leaves the
load through: the face it indents, never a face across the load. A corner behind the fence line
touches the fence only while the fence passes through the load; a corner that came round the
tip is on the fence's back side. Checked on single evaluations of the forces and on whole
strokes at 2 m/s of loads mostly beyond the tip when the stroke starts.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fence_sorter.physics import kernel as K
from fence_sorter.physics.params import DriveParams, ParcelParams
from fence_sorter.physics.simulate import Scenario, SortingModel, simulate
from fence_sorter.scene import load_scene

ALPHA_K = math.radians(40.0)
LENGTH = 1.2  # R_z [m]
A, B = 0.56, 0.48  # load sides [m]
INDENT = 0.02  # the tip's depth behind the near face [m]


def _evaluate_at_rest(centre, phi: float, length_a: float = A, width_b: float = B):
    """One evaluation at t = t1 (alpha = alpha_k, the stiff fence at rest) of a load at rest
    with C_s at ``centre`` and yaw ``phi``: (scenario, evaluation)."""
    t1 = 0.5
    sc = Scenario(
        parcel=ParcelParams(length_a=length_a, width_b=width_b, mass=20.0, lateral_gap=0.1),
        drive=DriveParams(alpha_k=ALPHA_K, t1=t1, r_s=0.0),
        fence_length=LENGTH,
        initial_velocity=(0.0, 0.0, 0.0),
    )
    md = SortingModel(sc)
    y = np.zeros(md.n_state)
    y[:3] = centre[0], centre[1], phi
    force_model = K.ForceModel(
        md.P, md.corners, md.normals, md.phi, md.rigid_modal, md.omega, md.zeta
    )
    ev = K.Evaluation(
        K.zero_slots(),
        K.zero_result(),
        np.zeros(0),
        np.zeros(2),
        np.zeros(2),
        np.zeros((1, 2)),
        np.full(K.N_SLOTS, math.nan),
        np.zeros(3),
    )
    K.evaluate(force_model, t1, 0.0, y, np.zeros(3), 0.0, ev)
    return sc, ev


def _tip_in_near_face(relative_deg: float):
    """One evaluation of a load at rest whose near face (face 3, body normal (0, -1)) the stiff
    fence's tip indents by INDENT at the face's middle, the face's outward normal turned
    ``relative_deg`` from the fence's inward normal."""
    phi = ALPHA_K - math.radians(relative_deg)
    m3 = np.array([math.sin(phi), -math.cos(phi)])  # face 3's outward normal
    tip = LENGTH * np.array([math.cos(ALPHA_K), math.sin(ALPHA_K)])
    sc, ev = _evaluate_at_rest(tip + (INDENT - 0.5 * B) * m3, phi)
    return sc, ev, m3


@pytest.mark.parametrize("relative_deg", [10.0, 44.0, 46.0, 60.0])
def test_the_tip_presses_on_the_face_it_indents_at_any_yaw(relative_deg):
    """Near face turned 10-60 deg against the fence (past 45 deg the far front face faces the
    fence more): the only contact is the tip on the near face, D = INDENT, N = k_p D^4 (at
    rest: no damping), pushing the load along the face's inward normal."""
    sc, ev, m3 = _tip_in_near_face(relative_deg)
    out, res = ev.contacts, ev.resultant
    active = [k for k in range(K.N_SLOTS) if out[k]["active"] != 0.0]
    assert active == [K.SLOT_TIP + 3]
    row = out[K.SLOT_TIP + 3]
    assert row["d"] == pytest.approx(INDENT, abs=1e-12)
    assert row["n"] == pytest.approx(sc.contact.k_p * INDENT**4, rel=1e-9)
    assert (row["nx"], row["ny"]) == pytest.approx((-m3[0], -m3[1]), abs=1e-12)
    assert res[0]["fence_n"] == pytest.approx(sc.contact.k_p * INDENT**4, rel=1e-9)


# A 20.3 kg load of a mixed stream (0.56 x 0.48 m) under the stroke R_s = 1.0 m, t1 = 0.5-0.7 s
# on the flexible PA6 fence at belt speed 2 m/s: the load is mostly beyond the tip's reach when
# the stroke starts, the tip enters its near face and turns it past 45 deg against the fence
BIG_LOAD = ParcelParams(
    length_a=0.5629,
    width_b=0.4801,
    height=0.12,
    mass=20.2568,
    cog_offset_x=0.0110,
    cog_offset_y=-0.0142,
    lateral_gap=0.1604,
    yaw=-0.02437,
)


@pytest.mark.parametrize("t1", [0.5, 0.6, 0.7])
def test_a_load_beyond_the_tip_is_pushed_with_bounded_penetration(t1):
    """The solve succeeds and the fence sorts the load. Law (16) with b = 0 bounds the
    penetration of a load meeting the fence at speed v0 by D_max = (5 m v0^2 / (2 k_p))^(1/5);
    with v0 the belt speed plus the tip's peak speed (the fastest closing possible) D stays
    below it and N below k_p D_max^4."""
    base = load_scene("impact_flexible").scenario
    sc = replace(
        base,
        conveyor=replace(base.conveyor, belt_speed=2.0),
        parcel=BIG_LOAD,
        drive=replace(base.drive, r_s=1.0, t1=t1),
        record=(),
    )
    r = simulate(sc)
    assert r.success, r.diagnosis
    assert r.sorted
    tip_speed = math.pi * sc.drive.alpha_k / (2.0 * t1) * sc.fence.length
    v0 = sc.conveyor.belt_speed + tip_speed
    d_max = (5.0 * BIG_LOAD.mass * v0**2 / (2.0 * sc.contact.k_p)) ** 0.2
    assert 0.0 < r.max_penetration < d_max
    assert 0.0 < r.peak_contact_force < sc.contact.k_p * d_max**4


def test_a_corner_round_the_tip_does_not_touch_the_fence():
    """A 0.3 x 0.4 m load beyond the tip, unyawed, its rear fence-side corner 0.2 m behind the
    fence line (deeper than the deep-penetration limit 0.5 x 0.3 m) and 1 cm inside the arc
    range, as a spinning load swings it round the tip: its rear face meets the fence line
    0.261 m above the corner, 0.158 m beyond the tip, so the fence does not reach the load and
    nothing touches (the corner alone would have D = 0.2 m, N = k_p D^4 = 2.8e6 N)."""
    a, b, depth = 0.3, 0.4, 0.2
    t = np.array([math.cos(ALPHA_K), math.sin(ALPHA_K)])
    n = np.array([-math.sin(ALPHA_K), math.cos(ALPHA_K)])
    corner = (LENGTH - 0.01) * t - depth * n
    _, ev = _evaluate_at_rest(corner + np.array([0.5 * a, 0.5 * b]), 0.0, a, b)
    out, res = ev.contacts, ev.resultant
    assert [k for k in range(K.N_SLOTS) if out[k]["active"] != 0.0] == []
    assert res[0]["fence_n"] == 0.0 and res[0]["fx"] == 0.0 and res[0]["fy"] == 0.0
    # the same corner 1 cm in front of the fence line instead: the load straddles the fence
    # and the corner is a candidate ahead of its onset (D = -1 cm)
    _, ev = _evaluate_at_rest(
        corner + (depth + 0.01) * n + np.array([0.5 * a, 0.5 * b]), 0.0, a, b
    )
    rear = ev.contacts[3]
    assert rear["gap"] == 1.0 and rear["d"] == pytest.approx(-0.01, abs=1e-12)


# A 19 kg, 0.22 x 0.23 m load with C_s 0.11 m ahead of its centre under R_s = 1.0 m, t1 = 0.2 s,
# alpha_k = 40 deg on the flexible fence at 2.23 m/s: the tip flings it into a spin at
# 25 rad/s beyond the tip, and a corner swings round the tip behind the fence line
SPUN_LOAD = ParcelParams(
    length_a=0.21886,
    width_b=0.22512,
    height=0.2,
    mass=19.0726,
    cog_offset_x=0.10915,
    cog_offset_y=0.010696,
    lateral_gap=0.14264,
    yaw=math.radians(7.78375),
)


def test_a_load_spun_round_the_tip_is_sorted_with_bounded_penetration():
    base = load_scene("impact_flexible").scenario
    sc = replace(
        base,
        conveyor=replace(base.conveyor, belt_speed=2.2344),
        parcel=SPUN_LOAD,
        drive=replace(base.drive, r_s=1.0, t1=0.2),
        record=(),
    )
    r = simulate(sc)
    assert r.success, r.diagnosis
    assert r.sorted
    tip_speed = math.pi * sc.drive.alpha_k / (2.0 * sc.drive.t1) * sc.fence.length
    v0 = sc.conveyor.belt_speed + tip_speed
    d_max = (5.0 * SPUN_LOAD.mass * v0**2 / (2.0 * sc.contact.k_p)) ** 0.2
    assert 0.0 < r.max_penetration < d_max
    assert 0.0 < r.peak_contact_force < sc.contact.k_p * d_max**4
