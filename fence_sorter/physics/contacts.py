"""Motion stages E1-E4 from the active contact set (paper section 2, appendix).

The contacts themselves are evaluated in ``kernel.evaluate`` (one row per contact slot):

- ``corner`` slots 0-3: a load corner against the fence surface: E1's oblique strike (13),
  (23)-(33); the arc position starts from R = |O C_j| (23) and is refined by one projection onto
  the deflected fence, and D is the normal distance of C_j behind the fence surface at U (26).
- ``tip`` slots 4-7: the fence tip inside the load after a penetrating corner slid past it (the
  paper keeps E2's contact point C on the fence until it passes R_z, (21)); D is measured from
  the tip along the fence normal, continuous with the corner's D.
- ``border`` slots 8-11: a load corner against the fence-side border wall y0 = 0, D = -y_C2 (56),
  kinetic friction mu2 (E3, (50)-(55)).

Stages are classified from the active set, not integrated as separate equations: a face along
the fence (E2) is a face whose two corners (or corner and the fence tip) both touch the fence, or
a single contact with the face within ``FLUSH_ANGLE`` of the fence tangent; that face's contact
pair holds it flush, the moment the paper's E2 (46) imposes by slaving phi to the fence.
"""

from __future__ import annotations

import math

import numpy as np

from . import kernel as K

FLUSH_ANGLE = math.radians(2.0)

STAGE_ON_BELT = "on_belt"
STAGE_E1 = "E1"
STAGE_E2 = "E2"
STAGE_E3 = "E3"
STAGE_E4 = "E4"
STAGE_SORTED = "sorted"


def classify(out: np.ndarray, face_normals: np.ndarray, phi: float, touched: bool) -> str:
    """Stage E1-E4 (or on_belt before the first touch) from the kernel's contact slots."""
    active = out[:, K.C_ACTIVE] != 0.0
    corners = [k for k in range(4) if active[k]]
    tip = bool(active[K.SLOT_TIP : K.SLOT_BORDER].any())
    border = bool(active[K.SLOT_BORDER :].any())
    if not corners and not tip:
        return STAGE_E4 if touched else STAGE_ON_BELT
    if border:
        return STAGE_E3
    if tip:
        return STAGE_E2
    if any((k + 1) % 4 in corners for k in corners):  # both corners of one face on the fence
        return STAGE_E2
    # single corner: is one of its faces (nearly) along the fence tangent?
    row = out[corners[0]]
    tangent_angle = math.atan2(row[K.C_NX], -row[K.C_NY])  # n = (-t_y, t_x)
    for face in (corners[0], (corners[0] - 1) % 4):
        nbx, nby = face_normals[face]
        face_angle = phi + math.atan2(nbx, -nby)
        diff = math.remainder(face_angle - tangent_angle, math.pi)
        if abs(diff) < FLUSH_ANGLE:
            return STAGE_E2
    return STAGE_E1
