"""Contact detection and forces between the load, the fence and the border (paper appendix).

One evaluation gives every active contact of the load with the law (16) and friction (37):

- ``corner``: a load corner against the fence surface: E1's oblique strike (13), (23)-(33); the
  arc position starts from R = |O C_j| (23) and is refined by one projection onto the deflected
  fence, and D is the normal distance of C_j behind the fence surface at U (26).
- ``tip``: the fence tip inside the load after a penetrating corner has slid past it: the face
  still lies on the fence (the paper keeps E2's contact point C on the fence until it passes R_z,
  (21)); D is measured from the tip along the fence normal, continuous with the corner's D.
- ``border``: a load corner against the fence-side border wall y0 = 0, D = -y_C2 (56), kinetic
  friction mu2 (E3, (50)-(55)).

Stages are classified from the active set (E1-E4), not integrated as separate equations: a face
along the fence (E2) is a face whose two corners (or corner and the fence tip) both touch the
fence, or a single contact with the face within ``FLUSH_ANGLE`` of the fence tangent; that face's
contact pair holds it flush, the moment the paper's E2 (46) imposes by slaving phi to the fence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .contact import normal_force
from .friction import fence_friction
from .params import ContactParams
from .parcel import ParcelBody

FLUSH_ANGLE = math.radians(2.0)

STAGE_ON_BELT = "on_belt"
STAGE_E1 = "E1"
STAGE_E2 = "E2"
STAGE_E3 = "E3"
STAGE_E4 = "E4"
STAGE_SORTED = "sorted"


@dataclass(slots=True)
class Contact:
    kind: str  # "corner", "tip" or "border"
    index: int  # corner index (corner, border) or face index (tip)
    s: float  # arc position on the fence [m] (nan for the border)
    depth: float  # D [m]
    depth_rate: float  # Ddot [m/s]
    normal_force: float  # N [N]
    friction_force: float  # along the contact tangent [N]
    px: float  # contact point [m]
    py: float
    nx: float  # unit normal of the force on the load
    ny: float


@dataclass(slots=True)
class Evaluation:
    fx: float = 0.0  # resultant of contact forces on the load [N]
    fy: float = 0.0
    mz: float = 0.0  # their moment about C_s [N m]
    fence_normal: float = 0.0  # sum of N over fence contacts [N]
    max_depth: float = 0.0  # deepest D of any contact [m]
    contacts: list[Contact] = field(default_factory=list)
    gaps: dict = field(default_factory=dict)  # (kind, index) -> (D, Ddot) of fence candidates
    modal: np.ndarray | None = None  # generalized modal force on the fence


def evaluate(
    body: ParcelBody,
    contact: ContactParams,
    fence,
    state: tuple[float, float, float, float, float, float],
    belt_wrench: tuple[float, float, float],
    *,
    use_border: bool,
    use_tip: bool,
    modal_out: np.ndarray | None,
    implicit_weight: float | None = None,
    prev_friction: dict | None = None,
) -> Evaluation:
    """Contact forces on the load in ``state`` = (x, y, phi, vx, vy, phidot) against ``fence``.

    ``belt_wrench`` (the belt friction in force) supplies the applied tangential force of the
    Karnopp stick branch of (37). ``modal_out`` (zeroed here) receives the fence's share.

    Inside a time step's iteration, ``implicit_weight`` (velocity change per unit end-of-step
    force over the mass, h/2 for the trapezoidal rule) and ``prev_friction`` (each contact's
    friction at the previous iterate, keyed (kind, index)) make (37) implicit: the friction that
    stops the contact's slip by the end of the step is used if it lies within mu2 N (stick),
    otherwise mu2 N against the slip. The explicit sign flip would never let the iteration
    converge while a contact point's slip passes through zero.
    """
    x, y, phi, vx, vy, om = state
    ev = Evaluation()
    if modal_out is not None:
        modal_out[:] = 0.0
        ev.modal = modal_out
    c, s = math.cos(phi), math.sin(phi)
    corners = [(x + c * bx - s * by, y + s * bx + c * by) for bx, by in body.corners]
    length = fence.length
    mass = body.mass
    mu2 = contact.mu_fence
    v_min = contact.v_min
    lam_x, lam_y = belt_wrench[0], belt_wrench[1]
    ca, sa = math.cos(fence.alpha), math.sin(fence.alpha)
    reach = fence.max_deflection() + 0.05  # wide enough that the gap before an onset is known

    inv_mass, inv_inertia = 1.0 / mass, 1.0 / body.inertia

    def add(kind, index, s_arc, d, d_rate, px, py, nx, ny, tx, ty, slide, on_fence):
        n = normal_force(d, d_rate, mass, contact)
        f_prev = prev_friction.get((kind, index)) if prev_friction is not None else None
        if implicit_weight is not None and f_prev is not None:
            arm = (px - x) * ty - (py - y) * tx
            w_eff = implicit_weight * (inv_mass + arm * arm * inv_inertia)
            slip_free = slide - w_eff * f_prev  # the slip without this contact's friction
            limit = mu2 * n
            ft = -slip_free / w_eff
            if abs(ft) > limit:
                ft = -math.copysign(limit, slip_free)
        else:
            applied_t = lam_x * tx + lam_y * ty
            ft = fence_friction(n, slide, applied_t, mu2, v_min)
        fx = n * nx + ft * tx
        fy = n * ny + ft * ty
        ev.fx += fx
        ev.fy += fy
        ev.mz += (px - x) * fy - (py - y) * fx
        if on_fence:
            ev.fence_normal += n
            if modal_out is not None:
                fence.modal_force(s_arc, -fx, -fy, modal_out)
        ev.max_depth = max(ev.max_depth, d)
        ev.contacts.append(Contact(kind, index, s_arc, d, d_rate, n, ft, px, py, nx, ny))

    # corners against the fence surface
    tip_x, tip_y, ttx, tty, vtx, vty = fence.surface(length) if use_tip else (0,) * 6
    ntx, nty = -tty, ttx
    passed = [False] * 4
    for k, (px, py) in enumerate(corners):
        # cheap reject: well in front of the rigid line, beyond any deflection
        if -px * sa + py * ca > reach:
            continue
        r = math.hypot(px, py)
        if r > length:
            s_arc = r
        else:
            ux, uy, tx, ty, vux, vuy = fence.surface(r)
            s_arc = r + (px - ux) * tx + (py - uy) * ty
        if s_arc > length:
            # beyond the tip: behind the fence's extension, the tip contact takes over
            passed[k] = use_tip and (tip_x - px) * ntx + (tip_y - py) * nty > 0.0
            continue
        if s_arc < 0.0:
            continue
        ux, uy, tx, ty, vux, vuy = fence.surface(s_arc)
        nx, ny = -ty, tx
        d = (ux - px) * nx + (uy - py) * ny
        vpx = vx - om * (py - y)
        vpy = vy + om * (px - x)
        d_rate = (vux - vpx) * nx + (vuy - vpy) * ny
        ev.gaps[("corner", k)] = (d, d_rate)
        if d > 0.0:
            slide = (vpx - vux) * tx + (vpy - vuy) * ty
            add("corner", k, s_arc, d, d_rate, px, py, nx, ny, tx, ty, slide, True)

    # the fence tip inside the load, continuing a corner that slid past it: D is the depth of
    # the load behind the tip along the fence normal (a ray from the tip), so it equals the
    # corner's D at the moment the corner passes the tip and the force stays continuous
    if use_tip and any(passed):
        depth = math.inf
        exit_face = -1
        for k in range(4):
            nbx, nby = body.face_normals[k]
            mx, my = c * nbx - s * nby, s * nbx + c * nby
            cx_, cy_ = corners[k]
            inside = (cx_ - tip_x) * mx + (cy_ - tip_y) * my
            if inside <= 0.0:
                exit_face = -1
                break
            cos_dir = -(ntx * mx + nty * my)
            if cos_dir > 1e-12:
                lam = inside / cos_dir
                if lam < depth:
                    depth, exit_face = lam, k
        if exit_face >= 0 and (passed[exit_face] or passed[(exit_face + 1) % 4]):
            vpx = vx - om * (tip_y - y)
            vpy = vy + om * (tip_x - x)
            d_rate = (vtx - vpx) * ntx + (vty - vpy) * nty
            slide = (vpx - vtx) * ttx + (vpy - vty) * tty
            ev.gaps[("tip", exit_face)] = (depth, d_rate)
            add(
                "tip",
                exit_face,
                length,
                depth,
                d_rate,
                tip_x,
                tip_y,
                ntx,
                nty,
                ttx,
                tty,
                slide,
                True,
            )

    # corners against the border wall y0 = 0
    if use_border:
        for k, (px, py) in enumerate(corners):
            if py >= 0.0:
                continue
            vpx = vx - om * (py - y)
            vpy = vy + om * (px - x)
            add("border", k, math.nan, -py, -vpy, px, py, 0.0, 1.0, 1.0, 0.0, vpx, False)
    return ev


def classify(ev: Evaluation, body: ParcelBody, phi: float, touched: bool) -> str:
    """Stage E1-E4 (or on_belt before the first touch) from the active contact set."""
    fence_contacts = [ct for ct in ev.contacts if ct.kind != "border"]
    border = any(ct.kind == "border" for ct in ev.contacts)
    if not fence_contacts:
        return STAGE_E4 if touched else STAGE_ON_BELT
    if border:
        return STAGE_E3
    if any(ct.kind == "tip" for ct in fence_contacts):
        return STAGE_E2
    corners = {ct.index for ct in fence_contacts}
    if any((k + 1) % 4 in corners for k in corners):  # both corners of one face on the fence
        return STAGE_E2
    # single corner: is one of its faces (nearly) along the fence tangent?
    ct = fence_contacts[0]
    tangent_angle = math.atan2(ct.nx, -ct.ny)  # n = (-t_y, t_x)
    for face in (ct.index, (ct.index - 1) % 4):
        nbx, nby = body.face_normals[face]
        face_angle = phi + math.atan2(nbx, -nby)
        diff = math.remainder(face_angle - tangent_angle, math.pi)
        if abs(diff) < FLUSH_ANGLE:
            return STAGE_E2
    return STAGE_E1
