"""Forces of one state: the drive, the fence surface (21)-(32), friction (34)-(37), the contact law
(16) and the modal load (20) (:func:`evaluate`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .layout import SLOT_BORDER, SLOT_TIP


# -- drive --------------------------------------------------------------------------------------
@njit(cache=True, _nrt=False)
def drive(P, t):
    """alpha_w, rate, acceleration of the sinusoidal-velocity drive (see ``drive.py``)."""
    t1 = P[0].t1
    if t < 0.0 or t > 2.0 * t1:
        return 0.0, 0.0, 0.0
    w = math.pi / t1
    half = 0.5 * P[0].alpha_k
    return (
        half * (1.0 - math.cos(w * t)),
        half * w * math.sin(w * t),
        half * w * w * math.cos(w * t),
    )


# -- fence geometry -----------------------------------------------------------------------------
@njit(cache=True, _nrt=False)
def fence_shape(P, phi, eta, etadot, alpha, w, wdot, nodes):
    """Nodal deflections w = Phi eta, their rates, and the chord chain node positions (27)-(29)."""
    n = int(P[0].n_el)
    m = eta.shape[0]
    for i in range(2 * n):
        a = 0.0
        b = 0.0
        for j in range(m):
            a += phi[i, j] * eta[j]
            b += phi[i, j] * etadot[j]
        w[i] = a
        wdot[i] = b
    dl = P[0].dl
    cx = 0.0
    cy = 0.0
    prev = 0.0
    nodes[0, 0] = 0.0
    nodes[0, 1] = 0.0
    for k in range(n):
        wk = w[2 * k]
        ang = alpha + (wk - prev) / dl
        cx += math.cos(ang)
        cy += math.sin(ang)
        prev = wk
        nodes[k + 1, 0] = dl * cx
        nodes[k + 1, 1] = dl * cy


@njit(cache=True, _nrt=False)
def _hermite(w_a, th_a, w_b, th_b, d, inv_dl):
    slope = (w_b - w_a) * inv_dl
    p3 = (3.0 * slope - 2.0 * th_a - th_b) * inv_dl
    p4 = (th_a + th_b - 2.0 * slope) * inv_dl * inv_dl
    return w_a + d * (th_a + d * (p3 + d * p4)), th_a + d * (2.0 * p3 + 3.0 * d * p4)


@njit(cache=True, _nrt=False)
def _element(P, s):
    """Element index and offset d_N of arc s (21)-(22), clamped onto the fence."""
    n = int(P[0].n_el)
    dl = P[0].dl
    i = int(s / dl)
    if i >= n:
        i = n - 1
    if i < 0:
        i = 0
    d = s - i * dl
    if d < 0.0:
        d = 0.0
    return i, d


@njit(cache=True, _nrt=False)
def surface(P, s, alpha, rate, w, wdot, nodes):
    """(U_x, U_y, t_x, t_y, v_x, v_y): fence point at arc s, unit tangent, material velocity."""
    return _surface(P, s, alpha, math.cos(alpha), math.sin(alpha), rate, w, wdot, nodes)


@njit(cache=True, _nrt=False, inline="always")
def _surface(P, s, alpha, ca, sa, rate, w, wdot, nodes):
    """``surface`` with cos and sin of the fence angle alpha given (``evaluate`` has them)."""
    if P[0].flexible == 0.0:
        return s * ca, s * sa, ca, sa, -rate * s * sa, rate * s * ca
    i, d = _element(P, s)
    inv_dl = 1.0 / P[0].dl
    if i > 0:
        w_a, th_a, v_a, vth_a = w[2 * i - 2], w[2 * i - 1], wdot[2 * i - 2], wdot[2 * i - 1]
    else:
        w_a, th_a, v_a, vth_a = 0.0, 0.0, 0.0, 0.0
    w_s, th_s = _hermite(w_a, th_a, w[2 * i], w[2 * i + 1], d, inv_dl)
    wd_s, _ = _hermite(v_a, vth_a, wdot[2 * i], wdot[2 * i + 1], d, inv_dl)
    ang_n = alpha + ((w_s - w_a) / d if d > 0.0 else th_a)
    ux = nodes[i, 0] + d * math.cos(ang_n)
    uy = nodes[i, 1] + d * math.sin(ang_n)
    ang = alpha + th_s
    vx = -rate * uy - wd_s * sa
    vy = rate * ux + wd_s * ca
    return ux, uy, math.cos(ang), math.sin(ang), vx, vy


@njit(cache=True, _nrt=False)
def _modal_share(P, phi, s, alpha, fx, fy, modal):
    """Add the modal share of a force (fx, fy) on the fence at arc s, split by (20)."""
    transverse = -fx * math.sin(alpha) + fy * math.cos(alpha)
    i, d = _element(P, s)
    frac = d / P[0].dl
    m = modal.shape[0]
    for j in range(m):
        f = phi[2 * i, j] * transverse * frac
        if i > 0:
            f += phi[2 * i - 2, j] * transverse * (1.0 - frac)
        modal[j] += f


# -- friction -----------------------------------------------------------------------------------
@njit(cache=True, _nrt=False, inline="always")
def _fence_friction(n, slide, applied_t, mu, v_min):
    """Fence / border friction (37): Karnopp with threshold v_min."""
    limit = mu * n
    if abs(slide) > v_min:
        return -math.copysign(limit, slide)
    if limit > abs(applied_t):
        return -applied_t
    return -math.copysign(limit, applied_t)


@njit(cache=True, _nrt=False)
def _clip_force(f_cap, ax, ay):
    """The friction force that cancels the applied force (ax, ay), at most f_cap long."""
    p = math.hypot(ax, ay)
    if f_cap >= p:
        return -ax, -ay
    return -f_cap * ax / p, -f_cap * ay / p


@njit(cache=True, _nrt=False)
def stick_wrench(P, ax, ay, am):
    """Karnopp's stick branch of (34)-(36): cancel the applied wrench (ax, ay, am) inside the
    same elliptic limit surface (F/F_max)^2 + (T/T_max)^2 <= 1 the slip branch lies on; an
    applied wrench outside it is scaled radially onto it."""
    f_max = P[0].f_max
    t_max = P[0].t_max
    q = 0.0
    if f_max > 0.0:
        q += (ax * ax + ay * ay) / (f_max * f_max)
    elif ax != 0.0 or ay != 0.0:
        q = math.inf
    if t_max > 0.0:
        q += am * am / (t_max * t_max)
    elif am != 0.0:
        q = math.inf
    if q <= 1.0:
        return -ax, -ay, -am
    if math.isinf(q):
        fx, fy = _clip_force(f_max, ax, ay)
        tz = -math.copysign(min(t_max, abs(am)), am)
        return fx, fy, tz
    k = 1.0 / math.sqrt(q)
    return -k * ax, -k * ay, -k * am


@njit(cache=True, _nrt=False)
def karnopp_belt(P, ux, uy, spin, ax, ay, am):
    """Belt friction (34)-(36) in the explicit Karnopp form on the elliptic limit surface.

    Slip (|u| > v_min or |phidot| > phidot_min): the maximum-dissipation wrench on the ellipse,
    F = -F_max^2 u / n, T = -T_max^2 phidot / n with n = |(F_max |u|, T_max phidot)|. A component
    inside its window sticks: both -> ``stick_wrench``; one -> it cancels its applied part up to
    what the ellipse leaves beside the sliding one, so explicit and implicit (``implicit_belt``)
    friction bound the same set of wrenches.
    """
    f_max = P[0].f_max
    t_max = P[0].t_max
    v_o = math.hypot(ux, uy)
    norm = math.hypot(f_max * v_o, t_max * spin)
    slide_t = v_o > P[0].v_min
    slide_r = abs(spin) > P[0].phidot_min
    if not slide_t and not slide_r:
        return stick_wrench(P, ax, ay, am)
    fx = fy = tz = 0.0
    if slide_t and norm > 0.0:
        k = f_max * f_max / norm
        fx, fy = -k * ux, -k * uy
    if slide_r and norm > 0.0:
        tz = -t_max * t_max * spin / norm
    if not slide_t:
        share = tz / t_max if t_max > 0.0 else 0.0
        fx, fy = _clip_force(f_max * math.sqrt(max(0.0, 1.0 - share * share)), ax, ay)
    elif not slide_r:
        share = math.hypot(fx, fy) / f_max if f_max > 0.0 else 0.0
        cap = t_max * math.sqrt(max(0.0, 1.0 - share * share))
        tz = -math.copysign(min(cap, abs(am)), am)
    return fx, fy, tz


@njit(cache=True, _nrt=False, inline="always")
def implicit_belt(P, u0, u1, u2, w0, w1, w2, lam):
    """Belt wrench lambda with u = u* + W lambda and the elliptic law at the end velocity u.

    Stick (returns True) when the wrench -u*/W that zeroes u lies inside the limit ellipse;
    otherwise slip, lambda = -P u / sqrt(u^T P u), one scalar Newton root (see friction.py and
    :func:`belt_multiplier`).
    """
    return belt_multiplier(P, u0, u1, u2, w0, w1, w2, lam, 0.0) < 0.0


@njit(cache=True, _nrt=False, inline="always")
def belt_multiplier(P, u0, u1, u2, w0, w1, w2, lam, sigma0):
    """:func:`implicit_belt` returning the slip multiplier sigma (lambda_i = -P_i u_i /
    (sigma + W_i P_i), end velocity u_i sigma / (sigma + W_i P_i)), or -1 when the belt sticks.

    ``sigma0`` >= 0 starts the Newton iteration (a contact iteration passes its previous
    iterate's multiplier: the iterates' u* differ by the iteration's residual, so the root is
    a step or two away instead of four from sigma = 0).
    """
    fm2 = P[0].f_max * P[0].f_max
    tm2 = P[0].t_max * P[0].t_max
    l0, l1, l2 = -u0 / w0, -u1 / w1, -u2 / w2
    q = 0.0
    if fm2 > 0.0:
        q += (l0 * l0 + l1 * l1) / fm2
    elif l0 != 0.0 or l1 != 0.0:
        q = math.inf
    if tm2 > 0.0:
        q += l2 * l2 / tm2
    elif l2 != 0.0:
        q = math.inf
    if q <= 1.0:
        lam[0], lam[1], lam[2] = l0, l1, l2
        return -1.0
    a0, a1, a2 = fm2 * u0 * u0, fm2 * u1 * u1, tm2 * u2 * u2
    c0, c1, c2 = w0 * fm2, w1 * fm2, w2 * tm2
    # the multiplier sigma >= 0 is the root of q(sigma) = sum a_i / (sigma + c_i)^2 = 1 (q(0) is
    # the stick test's q > 1 here). Newton on the secular equation 1 / sqrt(q(sigma)) = 1 (More
    # and Sorensen's form: 1 / sqrt(q) is concave and increasing, exactly linear for one term),
    # so the iterates climb monotonically onto the root from sigma = 0 in a few steps (Newton on
    # q itself crept up by a factor ~1.5 per iteration: 17-25 iterations on the bench scenes).
    # From a start beyond the root (q < 1) the step lands at or below it (the tangent of a
    # concave function lies above it; clipped at 0), and the climb goes on from there; a
    # landing just past the root (round-off, e.g. from a start far beyond it) steps back.
    sigma = sigma0 if sigma0 > 0.0 else 0.0
    for _ in range(100):
        q = 0.0
        s3 = 0.0
        if a0 > 0.0:
            r = 1.0 / (sigma + c0)
            q += a0 * r * r
            s3 += a0 * r * r * r
        if a1 > 0.0:
            r = 1.0 / (sigma + c1)
            q += a1 * r * r
            s3 += a1 * r * r * r
        if a2 > 0.0:
            r = 1.0 / (sigma + c2)
            q += a2 * r * r
            s3 += a2 * r * r * r
        if abs(q - 1.0) <= 1e-14 or s3 == 0.0:
            break
        step = q * (math.sqrt(q) - 1.0) / s3
        sigma = max(sigma + step, 0.0)
        if abs(step) <= 1e-15 * sigma:
            break
    if sigma > 0.0:
        lam[0] = -fm2 * (u0 * sigma / (sigma + c0)) / sigma
        lam[1] = -fm2 * (u1 * sigma / (sigma + c1)) / sigma
        lam[2] = -tm2 * (u2 * sigma / (sigma + c2)) / sigma
    else:
        lam[0] = lam[1] = lam[2] = 0.0
    return sigma


# -- contacts -----------------------------------------------------------------------------------
@njit(cache=True, _nrt=False, inline="always")
def _fence_in_load(x, yy, c, s, corners, normals, ux, uy, tx, ty, s_arc, length):
    """Whether the fence, the line through U(s) along its tangent (tx, ty) cut to the arc range
    [0, R_z], passes through the load (C_s at (x, yy), yaw cos c, sin s): the load's interval
    on the line, from its four faces, overlaps the fence's. A corner deeper than the
    deep-penetration limit behind the fence line whose line misses the load did not get there
    through the fence surface (that contact would have been diagnosed on the way): it came
    round the tip and is on the fence's back side, not in the fence. (Shallower, it may be in
    the fence's end, as a corner sliding on after the tip has left the load through a face.)"""
    lo = -math.inf
    hi = math.inf
    for j in range(4):
        mx = c * normals[j, 0] - s * normals[j, 1]
        my = s * normals[j, 0] + c * normals[j, 1]
        qx = x + c * corners[j, 0] - s * corners[j, 1]
        qy = yy + s * corners[j, 0] + c * corners[j, 1]
        g = (ux - qx) * mx + (uy - qy) * my  # U outside face j by g
        h = tx * mx + ty * my
        if h > 0.0:
            hi = min(hi, -g / h)
        elif h < 0.0:
            lo = max(lo, -g / h)
        elif g > 0.0:
            return False
    return lo <= hi and s_arc + lo < length and s_arc + hi > 0.0


@njit(cache=True, _nrt=False, inline="always")
def _place(row, s_arc, d, d_rate, px, py, nx, ny, vsx, vsy):
    """The geometry of a contact in its slot: arc position, D, Ddot, point, normal, surface
    velocity (:func:`_add` reads them back)."""
    row.s, row.d, row.ddot = s_arc, d, d_rate
    row.px, row.py, row.nx, row.ny, row.vsx, row.vsy = px, py, nx, ny, vsx, vsy


@njit(cache=True, _nrt=False, inline="always")
def _add(model, ev, slot, tx, ty, slide, y, lam, weight):
    """The contact law (16) and friction (37) of the contact placed in ``slot`` (``_place``;
    unit tangent (tx, ty), slip velocity ``slide``) at load state y: its force into the slot and
    the resultants, and on the fence (slots below SLOT_BORDER) its modal share."""
    P, out, res = model.params, ev.contacts, ev.resultant
    row = out[slot]
    # every field read before the first store below (stores to the resultants may alias the
    # slot, so a later read would load the slot again instead of the value just placed)
    d, d_rate, px, py, nx, ny = row.d, row.ddot, row.px, row.py, row.nx, row.ny
    s_arc, vsx, vsy = row.s, row.vsx, row.vsy
    x, yy = y[0], y[1]
    mass = P[0].mass
    n_raw = P[0].b_eff * d_rate * d * d + P[0].k_p * d**4
    n = n_raw if n_raw > 0.0 else 0.0
    mu2 = P[0].mu2
    f_prev = ev.friction_prev[slot]
    if weight > 0.0 and not math.isnan(f_prev):
        # implicit (37): the friction that stops this contact's slip by the step end if it lies
        # within mu2 N, else mu2 N against the slip
        arm = (px - x) * ty - (py - yy) * tx
        w_eff = weight * (1.0 / mass + arm * arm / P[0].inertia)
        slip_free = slide - w_eff * f_prev
        limit = mu2 * n
        ft = -slip_free / w_eff
        slack = limit - abs(ft)
        if abs(ft) > limit:
            ft = -math.copysign(limit, slip_free)
    else:
        ft = _fence_friction(n, slide, lam[0] * tx + lam[1] * ty, mu2, P[0].v_min)
        slack = math.nan
    fx = n * nx + ft * tx
    fy = n * ny + ft * ty
    res[0].fx += fx
    res[0].fy += fy
    res[0].mz += (px - x) * fy - (py - yy) * fx
    res[0].energy_contact += 0.2 * P[0].k_p * d**5
    if slot < SLOT_BORDER:
        res[0].fence_n += n
        res[0].power_fence += fx * vsx + fy * vsy
        if P[0].flexible != 0.0:
            _modal_share(P, model.mode_shapes, s_arc, res[0].alpha, -fx, -fy, ev.modal)
    res[0].active_mask += float(1 << slot)
    if d > res[0].max_d:
        res[0].max_d = d
    row.active = 1.0
    row.n = n
    row.n_raw = n_raw
    row.ft = ft
    row.slack = slack


@njit(cache=True, _nrt=False)
def evaluate(model, t, accel_jump, y, lam, weight, ev):
    """All contact forces on the load at time t and state y (see the module docstring).

    ``model``: a :data:`ForceModel` (or a LoopModel). ``lam``: the belt wrench, the applied
    tangential force of (37)'s stick branch. ``weight`` > 0 (velocity change per unit
    end-of-step force over the mass) with ``ev.friction_prev`` (each slot's friction at the
    previous iterate, NaN if none) makes (37) implicit inside a step's iteration.
    ``accel_jump`` is added to the drive acceleration (a step starting on the far side of the
    jump at 2 t1). Fills the :data:`Evaluation` ``ev``: its contacts, resultant and modal force
    (the fence's generalized force including the drive's inertial load -Phi^T M_fa r
    alpha_ddot), and its fence shape.
    """
    alpha, rate, accel = drive(model.params, t)
    accel += accel_jump
    _evaluate(
        model, alpha, rate, accel, math.cos(alpha), math.sin(alpha), y, math.cos(y[2]),
        math.sin(y[2]), lam, weight, ev,
    )  # fmt: skip


@njit(cache=True, _nrt=False)
def _evaluate(model, alpha, rate, accel, ca, sa, y, c, s, lam, weight, ev):
    """:func:`evaluate` with the drive state (alpha, rate, accel), cos, sin of alpha and c, s
    = cos, sin of the yaw y[2] given: a step's iteration evaluates every iterate at the same
    time, so it computes alpha's once, and the yaw's from the first iterate's (``_turn``)."""
    P, corners, normals = model.params, model.corners, model.normals
    phi, rigid_modal = model.mode_shapes, model.rigid_modal
    out, res, modal = ev.contacts, ev.resultant, ev.modal
    w, wdot, nodes = ev.deflection, ev.deflection_rate, ev.nodes
    out.view(np.float64)[:] = 0.0
    res.view(np.float64)[:] = 0.0
    modal[:] = 0.0
    x, yy, vx, vy, om = y[0], y[1], y[3], y[4], y[5]
    m = modal.shape[0]
    res[0].alpha, res[0].rate, res[0].accel = alpha, rate, accel
    flex = P[0].flexible != 0.0
    if flex:
        fence_shape(P, phi, y[6 : 6 + m], y[6 + m : 6 + 2 * m], alpha, w, wdot, nodes)
        n_el = int(P[0].n_el)
        res[0].tip_w = w[2 * n_el - 2]
        mw = 0.0
        for k in range(n_el):
            if abs(w[2 * k]) > mw:
                mw = abs(w[2 * k])
        res[0].max_w = mw
    length = P[0].length
    use_tip = P[0].use_tip != 0.0
    reach = res[0].max_w + P[0].margin
    # corner k of the load: (x + c a_k - s b_k, y + s a_k + c b_k), recomputed where used (the
    # same arithmetic; no array allocated per evaluation)
    tip_x = tip_y = ttx = tty = vtx = vty = 0.0
    if use_tip:
        tip_x, tip_y, ttx, tty, vtx, vty = _surface(P, length, alpha, ca, sa, rate, w, wdot, nodes)
    ntx, nty = -tty, ttx
    for k in range(4):
        px = x + c * corners[k, 0] - s * corners[k, 1]
        py = yy + s * corners[k, 0] + c * corners[k, 1]
        if -px * sa + py * ca > reach:
            continue
        if flex:
            r = math.hypot(px, py)
            # arc position: the corner projected on the fence near radius r (beyond the tip:
            # on the tip's tangent, so s is continuous where a corner slides off the tip, which
            # the slide-off event R_z - s needs)
            ux, uy, tx, ty, _, _ = _surface(P, min(r, length), alpha, ca, sa, rate, w, wdot, nodes)
            s_arc = min(r, length) + (px - ux) * tx + (py - uy) * ty
        else:
            s_arc = px * ca + py * sa  # the same projection on the straight rigid fence
        if s_arc > length:
            out[k].s = s_arc  # beyond the tip: the slide-off event function is R_z - s
            continue
        if s_arc < 0.0:
            continue
        if flex:
            ux, uy, tx, ty, vux, vuy = _surface(P, s_arc, alpha, ca, sa, rate, w, wdot, nodes)
        else:  # _surface of the rigid fence, inline
            ux, uy, tx, ty = s_arc * ca, s_arc * sa, ca, sa
            vux, vuy = -rate * s_arc * sa, rate * s_arc * ca
        nx, ny = -ty, tx
        d = (ux - px) * nx + (uy - py) * ny
        if d > P[0].deep and not _fence_in_load(
            x, yy, c, s, corners, normals, ux, uy, tx, ty, s_arc, length
        ):
            continue  # deep behind the fence line, off the fence: round the tip, no contact
        vpx = vx - om * (py - yy)
        vpy = vy + om * (px - x)
        d_rate = (vux - vpx) * nx + (vuy - vpy) * ny
        out[k].gap = 1.0
        out[k].d = d
        out[k].ddot = d_rate
        out[k].n_raw = d  # negative before contact: the onset function
        if d > 0.0:
            slide = (vpx - vux) * tx + (vpy - vuy) * ty
            _place(out[k], s_arc, d, d_rate, px, py, nx, ny, vux, vuy)
            _add(model, ev, k, tx, ty, slide, y, lam, weight)
    # the fence tip inside the load (past a corner that slid off it, or pressed into a face
    # beyond the last pushing corner): it presses on the face its normal ray leaves the load
    # through (from the tip against the fence normal n: least depth / cos(n, -m) over the faces
    # with outward normal m against n), the depth is the tip's distance to that face's plane,
    # which starts from 0 as the tip enters through it; the ray leaves through a corner exactly
    # when that corner's arc is R_z, so a corner of a face along the fence sliding off hands its
    # D over to the tip on that face; the force acts along the face normal: the gradient of the
    # potential k_p D^5 / 5, zero at release. (The face merely most against n, whatever the
    # tip's position, is the far face of a load yawed past 45 deg against the fence with the
    # tip in its near face: D jumped from cm to the load's length.)
    # (Measuring the depth along the fence normal and pushing along it did work in a closed
    # elastic cycle; starting the contact only once a corner had passed the tip let it appear at
    # finite depth.)
    if use_tip:
        exit_face = -1
        ray = math.inf
        depth = 0.0
        fnx = fny = 0.0
        for k in range(4):
            nbx, nby = normals[k, 0], normals[k, 1]
            mx, my = c * nbx - s * nby, s * nbx + c * nby
            px = x + c * corners[k, 0] - s * corners[k, 1]
            py = yy + s * corners[k, 0] + c * corners[k, 1]
            inside = (px - tip_x) * mx + (py - tip_y) * my
            if inside <= 0.0:
                exit_face = -1
                break
            cos_dir = -(ntx * mx + nty * my)
            if cos_dir > 0.0 and inside < ray * cos_dir:
                ray = inside / cos_dir
                exit_face = k
                depth = inside
                fnx, fny = -mx, -my  # on the load: pushed away from the tip
        if exit_face >= 0:
            vpx = vx - om * (tip_y - yy)
            vpy = vy + om * (tip_x - x)
            d_rate = (vtx - vpx) * fnx + (vty - vpy) * fny
            ftx, fty = fny, -fnx
            slide = (vpx - vtx) * ftx + (vpy - vty) * fty
            slot = SLOT_TIP + exit_face
            out[slot].gap = 1.0
            _place(out[slot], length, depth, d_rate, tip_x, tip_y, fnx, fny, vtx, vty)
            _add(model, ev, slot, ftx, fty, slide, y, lam, weight)
    if P[0].use_border != 0.0:
        for k in range(4):
            px = x + c * corners[k, 0] - s * corners[k, 1]
            py = yy + s * corners[k, 0] + c * corners[k, 1]
            if py >= 0.0:
                continue
            vpx = vx - om * (py - yy)
            vpy = vy + om * (px - x)
            _place(out[SLOT_BORDER + k], math.nan, -py, -vpy, px, py, 0.0, 1.0, 0.0, 0.0)
            _add(model, ev, SLOT_BORDER + k, 1.0, 0.0, vpx, y, lam, weight)
    if flex:
        for j in range(m):
            modal[j] -= rigid_modal[j] * accel
    res[0].fx += P[0].ext_x
    res[0].fy += P[0].ext_y
    res[0].mz += P[0].ext_m
