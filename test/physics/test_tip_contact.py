"""The fence tip inside the load: the face it presses on, and a load bigger than the tip's reach.

The tip presses on the face its normal ray (from the tip, against the fence normal) leaves the
load through: the face it indents, never a face across the load. Checked on one evaluation of the
forces (the load yawed past 45 deg against the fence, where the face most nearly facing the
fence is the far front face) and on a whole stroke of the flexible fence at 2 m/s whose tip
enters the near face of a 20 kg load that is mostly beyond it.
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


def _tip_in_near_face(relative_deg: float):
    """One evaluation at t = t1 (alpha = alpha_k, the fence at rest) of a load at rest whose near
    face (face 3, body normal (0, -1)) the stiff fence's tip indents by INDENT at the face's
    middle, the face's outward normal turned ``relative_deg`` from the fence's inward normal."""
    t1 = 0.5
    sc = Scenario(
        parcel=ParcelParams(length_a=A, width_b=B, mass=20.0, lateral_gap=0.1),
        drive=DriveParams(alpha_k=ALPHA_K, t1=t1, r_s=0.0),
        fence_length=LENGTH,
        initial_velocity=(0.0, 0.0, 0.0),
    )
    md = SortingModel(sc)
    phi = ALPHA_K - math.radians(relative_deg)
    m3 = np.array([math.sin(phi), -math.cos(phi)])  # face 3's outward normal
    tip = LENGTH * np.array([math.cos(ALPHA_K), math.sin(ALPHA_K)])
    centre = tip + (INDENT - 0.5 * B) * m3
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
