"""One-step maps: the trapezoidal step implicit in the contact forces and belt friction (Newton or
Anderson), and the generalized-alpha step."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .control import resolves_stick
from .forces import (
    _evaluate,
    _modal_share,
    belt_multiplier,
    drive,
    evaluate,
    implicit_belt,
    stick_wrench,
)
from .layout import (
    N_SLOTS,
    SLOT_BORDER,
    SLOT_TIP,
)

# -- one-step maps ------------------------------------------------------------------------------
STEP_OK = 0
STEP_REJECTED = 1  # iteration did not converge (or a non-finite trial): halve and retry
STEP_FORCED = 2  # not converged but taken (the caller asked: a tiny step over a switch)


def trapezoidal_work_shape(m: int) -> tuple[int, int]:
    """Shape of the workspace ``trapezoidal_step`` needs for m modes."""
    return (11, 6 + 2 * m)


@njit(cache=True, _nrt=False, inline="always")
def _turn(c, s, d):
    """cos, sin of phi + d from c, s = cos, sin of phi, for |d| <= 1e-4 (a step's iterates
    differ in yaw by far less): Taylor series of cos d, sin d to d^4, d^5 (the next terms are
    < 1e-27), one libm sincos less per evaluation; equal to it within a few ulp."""
    d2 = d * d
    cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0))
    sd = d * (1.0 - d2 * ((1.0 / 6.0) - d2 * (1.0 / 120.0)))
    return c * cd - s * sd, s * cd + c * sd


@njit(cache=True, _nrt=False, inline="always")
def _friction_prev(out, prev):
    for k in range(N_SLOTS):
        prev[k] = out[k].ft if out[k].active != 0.0 else math.nan


# the contact iteration of a stiff fence by Newton (``_newton_load``); False: the Anderson-
# accelerated fixed point alone, as for a flexible fence (tests compare the two)
NEWTON = True


@njit(cache=True, _nrt=False, inline="always")
def _newton_load(P, out, y1, g_new, hh, im0, im2, rate, sigma, u0, u1, u2):
    """Turn the fixed-point update of the load, G(y1), into a Newton update: solve
    (I - dG/dy) delta = G(y1) - y1 and set g_new <- y1 + delta (load rows only).

    G: v_new = Phi(v*), v* = v0 + hh M^-1 (F0 + lambda0 + Q(q, v)), q_new = q0 + hh (v0 + v_new),
    with Q the contacts' generalized force and Phi the belt's implicit slip map. Each contact
    pushes N = b D' D^2 + k_p D^4 along J = (n, r x n) with friction ft along T = (t, r x t)
    (sliding: ft = +-mu2 N; sticking: ft = f_prev - slide / w_eff, a Newton step on the slip
    already, left out); dD/dq = dD'/dv = -J^T, and dD'/dq, dJ/dq, dT/dq from the contact's
    geometry: a corner on the rigid fence or the border (D' = rate s - v_p . n, so dD'/dq =
    rate T + omega (r . n) e_phi; J, T turn with phi through r) or the fence tip in a face of the
    load (the face normal turns with phi; dD'/dq = omega (n_y, -n_x, 0) + slide e_phi). With
    delta_q = hh delta_v + (r_q - hh r_v) this is the 3 x 3 system
    (I + DPhi hh M^-1 [sum (J + s T)(c J - hh b D^2 dD'/dq)^T - hh (N dJ/dq + ft dT/dq)]) dv = r_v
    with c = hh (4 k_p D^3 + 2 b D D') + b D^2, s = ft / N sliding (0 sticking) and, slipping on
    the belt (``sigma`` > 0, u = v* - belt), DPhi = diag(sigma / (sigma + c_i)) + g h^T
    (c_i = W_i P_i, g_i = u_i c_i / (sigma + c_i)^2, h_i = P_i u_i / (sigma + c_i)^2 / s3),
    identity off the belt. This is the exact Jacobian of G (to the finite-difference check's
    1e-9), so the iteration converges quadratically.
    """
    b = P[0].b_eff
    kp = P[0].k_p
    mu2 = P[0].mu2
    x, y, vx, vy, om = y1[0], y1[1], y1[3], y1[4], y1[5]
    m00 = m11 = m22 = 0.0
    m01 = m02 = m10 = m12 = m20 = m21 = 0.0
    active = False
    for k in range(N_SLOTS):
        row = out[k]
        if row.active == 0.0:
            continue
        nn = row.n
        if nn <= 0.0:
            continue
        d = row.d
        c = hh * (4.0 * kp * d * d * d + 2.0 * b * d * row.ddot) + b * d * d
        if c <= 0.0:
            continue
        active = True
        nx, ny = row.nx, row.ny
        tx, ty = ny, -nx
        rx, ry = row.px - x, row.py - y
        j2 = rx * ny - ry * nx
        t2 = rx * ty - ry * tx
        u0_, u1_, u2_ = nx, ny, j2
        ft = row.ft
        if ft != 0.0 and abs(ft) >= mu2 * nn * (1.0 - 1e-12):
            sf = ft / nn
            u0_ += sf * tx
            u1_ += sf * ty
            u2_ += sf * t2
        cd = hh * b * d * d
        # e: hh (dN/dq hh + dN/dv)-like row (with the sign of -dQ/dy); geo: -hh^2 (N dJ/dq +
        # ft dT/dq) per column
        e0, e1, e2 = c * nx, c * ny, c * j2
        if SLOT_TIP <= k < SLOT_BORDER:  # the fence tip in a face: the face normal turns
            vpx, vpy = vx - om * ry, vy + om * rx
            slide = (vpx - row.vsx) * tx + (vpy - row.vsy) * ty
            e0 -= cd * om * ny
            e1 += cd * om * nx
            e2 -= cd * slide
            g0x = g1x = g0y = g1y = 0.0
            g2x = -nn * ny + ft * nx
            g2y = nn * nx + ft * ny
            g0p = -nn * tx + ft * nx
            g1p = -nn * ty + ft * ny
            g2p = -nn * t2 + ft * j2
        else:  # a corner on the rigid fence (rate: its angular speed) or on the border (0)
            rate_k = rate if k < SLOT_TIP else 0.0
            rn = rx * nx + ry * ny
            e0 -= cd * rate_k * tx
            e1 -= cd * rate_k * ty
            e2 -= cd * (rate_k * t2 + om * rn)
            g0x = g1x = g0y = g1y = g2x = g2y = g0p = g1p = 0.0
            g2p = -nn * rn - ft * (rx * tx + ry * ty)
        a0, a1, a2 = hh * im0, hh * im0, hh * im2
        m00 += a0 * (u0_ * e0 - hh * g0x)
        m01 += a0 * (u0_ * e1 - hh * g0y)
        m02 += a0 * (u0_ * e2 - hh * g0p)
        m10 += a1 * (u1_ * e0 - hh * g1x)
        m11 += a1 * (u1_ * e1 - hh * g1y)
        m12 += a1 * (u1_ * e2 - hh * g1p)
        m20 += a2 * (u2_ * e0 - hh * g2x)
        m21 += a2 * (u2_ * e1 - hh * g2y)
        m22 += a2 * (u2_ * e2 - hh * g2p)
    if not active:
        return False
    if sigma > 0.0:
        # slipping on the belt: M <- DPhi M (M here is the contact part, I + M the matrix)
        fm2 = P[0].f_max * P[0].f_max
        tm2 = P[0].t_max * P[0].t_max
        c0, c1, c2 = hh * im0 * fm2, hh * im0 * fm2, hh * im2 * tm2
        i0, i1, i2 = 1.0 / (sigma + c0), 1.0 / (sigma + c1), 1.0 / (sigma + c2)
        s3 = fm2 * (u0 * u0 * i0 * i0 * i0 + u1 * u1 * i1 * i1 * i1) + tm2 * u2 * u2 * i2**3
        if s3 > 0.0:
            g0, g1, g2 = u0 * c0 * i0 * i0, u1 * c1 * i1 * i1, u2 * c2 * i2 * i2
            h0, h1, h2 = fm2 * u0 * i0 * i0 / s3, fm2 * u1 * i1 * i1 / s3, tm2 * u2 * i2 * i2 / s3
            d0, d1, d2 = sigma * i0, sigma * i1, sigma * i2
            k0 = h0 * m00 + h1 * m10 + h2 * m20
            k1 = h0 * m01 + h1 * m11 + h2 * m21
            k2 = h0 * m02 + h1 * m12 + h2 * m22
            m00, m01, m02 = d0 * m00 + g0 * k0, d0 * m01 + g0 * k1, d0 * m02 + g0 * k2
            m10, m11, m12 = d1 * m10 + g1 * k0, d1 * m11 + g1 * k1, d1 * m12 + g1 * k2
            m20, m21, m22 = d2 * m20 + g2 * k0, d2 * m21 + g2 * k1, d2 * m22 + g2 * k2
    m00 += 1.0
    m11 += 1.0
    m22 += 1.0
    r0, r1, r2 = g_new[3] - y1[3], g_new[4] - y1[4], g_new[5] - y1[5]
    e0 = g_new[0] - y1[0] - hh * r0
    e1 = g_new[1] - y1[1] - hh * r1
    e2 = g_new[2] - y1[2] - hh * r2
    c00 = m11 * m22 - m12 * m21
    c01 = m12 * m20 - m10 * m22
    c02 = m10 * m21 - m11 * m20
    det = m00 * c00 + m01 * c01 + m02 * c02
    if not (det > 1e-12):
        return False
    inv = 1.0 / det
    d0 = (c00 * r0 + (m02 * m21 - m01 * m22) * r1 + (m01 * m12 - m02 * m11) * r2) * inv
    d1 = (c01 * r0 + (m00 * m22 - m02 * m20) * r1 + (m02 * m10 - m00 * m12) * r2) * inv
    d2 = (c02 * r0 + (m01 * m20 - m00 * m21) * r1 + (m00 * m11 - m01 * m10) * r2) * inv
    g_new[3], g_new[4], g_new[5] = y1[3] + d0, y1[4] + d1, y1[5] + d2
    g_new[0] = y1[0] + hh * d0 + e0
    g_new[1] = y1[1] + hh * d1 + e1
    g_new[2] = y1[2] + hh * d2 + e2
    return True


@njit(cache=True, _nrt=False)
def trapezoidal_step(model, props, h, h_prev, t, y0, start, modal_prev, jump, on_belt, force, y1,
                     end, work):  # fmt: skip
    """One step of the trapezoidal rule, implicit in the contact forces and belt friction.

    Load: q1 = q0 + h/2 (v0 + v1), v1 = v0 + h/2 M^-1 (F0 + F1 + lambda1), iterated on F1 until
    the update is within ``tol``: Newton with the contacts' stiffness on a stiff fence
    (``_newton_load``), an Anderson-accelerated fixed point with the fence's modes; lambda1
    solves the belt law at the step end (stick exact; its multiplier warm-started from the
    previous iterate's). Fence: each mode
    propagated exactly for a modal force quadratic over the step, through the previous point's
    force ``modal_prev`` a step ``h_prev`` earlier, or linear (h_prev = 0: the start, after an
    event or a drive breakpoint, a fixed step): ``props`` = (A | g2, G0, G1) from Van Loan's
    matrix exponential. The exact modes then carry the force's curvature, an O(h^3) error of
    a linear force that the load's error estimate does not see; the contact iteration is
    unchanged, the curvature's share of f1 folded into G1. ``model``: a :data:`LoopModel`
    (settings: ``tol``, ``max_iter``); ``start``: the :data:`Evaluation` at the step start
    (y0's forces and belt wrench); ``jump``: the drive's acceleration jump at t.
    Returns STEP_OK, STEP_REJECTED or STEP_FORCED; the end-of-step forces are left in ``end``
    (an :data:`Evaluation`: its contacts, resultant and modal force, the belt wrench the
    stick wrench when stuck).

    Stick forces are constraint forces, and the trapezoidal rule rings on them (F1 = 2 F - F0,
    alternating step to step); like the belt's stick wrench, a fence or border contact that
    sticks at both ends of the step stores a force free of the ring as its end force
    (``_unring_stick``). Where ``control.resolves_stick``: the iteration converges the load's
    velocities to ``tol`` [m/s] as well, and that end force is extrapolated to second order.
    """
    P, phi, rigid_modal = model.params, model.mode_shapes, model.rigid_modal
    settings = model.settings
    f0, lam0, modal0, out0 = start.resultant, start.belt, start.modal, start.contacts
    out, res, modal1, lam1 = end.contacts, end.resultant, end.modal, end.belt
    prev = end.friction_prev
    tol, max_iter = settings[0].tol, int(settings[0].max_iter)
    a_mat, g0, g1 = props
    m = modal0.shape[0]
    resolve_stick = resolves_stick(settings, model.omega.shape[0])
    t1 = t + h
    im0 = 1.0 / P[0].mass
    im2 = 1.0 / P[0].inertia
    belt = P[0].belt
    hh = 0.5 * h
    fs0, fs1, fs2 = f0[0].fx + lam0[0], f0[0].fy + lam0[1], f0[0].mz + lam0[2]
    vn0 = y0[3] + h * fs0 * im0
    vn1 = y0[4] + h * fs1 * im0
    vn2 = y0[5] + h * fs2 * im2
    y1[0] = y0[0] + hh * (y0[3] + vn0)
    y1[1] = y0[1] + hh * (y0[4] + vn1)
    y1[2] = y0[2] + hh * (y0[5] + vn2)
    y1[3], y1[4], y1[5] = vn0, vn1, vn2
    n = 6 + 2 * m
    # one workspace (rows of n) instead of eight arrays per step: the modal base (rows 0-1,
    # first m), the Anderson history df, dg (rows 2-3, 4-5, zeroed: 0 * dg enters the update
    # before it is filled) and the vectors wts, g_new, f_prev, g_prev, f_cur (rows 6-10);
    # row views, no reshape (Numba's reshape is a library call)
    base0 = work[0]
    base1 = work[1]
    df = work[2:4]
    dg = work[4:6]
    df[:, :] = 0.0
    dg[:, :] = 0.0
    wts = work[6]
    g_new = work[7]
    f_prev = work[8]
    g_prev = work[9]
    f_cur = work[10]
    phi_scale = 0.0
    # the modal base and f1's coefficient (row 0-1 entries m..2m-1): f(s) = f0 + (f1 - f0) s / h
    # + kappa s (s - h), kappa = ((f1 - f0) / h - (f0 - f_prev) / h_prev) / (h + h_prev)
    k1 = k0 = 0.0
    if h_prev > 0.0:
        k1 = 1.0 / (h * (h + h_prev))
        k0 = 1.0 / (h_prev * (h + h_prev))
    for j in range(m):
        fm = modal0[j] - rigid_modal[j] * jump
        e0 = y0[6 + j]
        e1 = y0[6 + m + j]
        curv = -k1 * fm - k0 * (fm - modal_prev[j]) if h_prev > 0.0 else 0.0
        base0[j] = (
            a_mat[j, 0, 0] * e0 + a_mat[j, 0, 1] * e1 + g0[j, 0] * fm + a_mat[j, 0, 2] * curv
        )
        base1[j] = (
            a_mat[j, 1, 0] * e0 + a_mat[j, 1, 1] * e1 + g0[j, 1] * fm + a_mat[j, 1, 2] * curv
        )
        base0[m + j] = g1[j, 0] + k1 * a_mat[j, 0, 2]
        base1[m + j] = g1[j, 1] + k1 * a_mat[j, 1, 2]
        y1[6 + j] = base0[j] + base0[m + j] * fm
        y1[6 + m + j] = base1[j] + base1[m + j] * fm
    if m > 0:
        for i in range(phi.shape[0]):
            for j in range(m):
                if abs(phi[i, j]) > phi_scale:
                    phi_scale = abs(phi[i, j])
    alpha1, rate1, accel1 = drive(P, t1)
    ca1 = math.cos(alpha1)
    sa1 = math.sin(alpha1)
    for k in range(N_SLOTS):
        prev[k] = math.nan
    stuck = False
    sigma = 0.0  # the belt's slip multiplier at the last iterate (-1: stuck)
    lam1[0] = lam1[1] = lam1[2] = 0.0
    converged = False
    iterations = 0
    # Anderson acceleration (depth 2) of the fixed point x = G(x) on (q, v, eta, etadot): the
    # contact couples the load to the fence's modal deflection so tightly that the plain
    # iteration contracts slowly (often > 10 iterations per step on a flexible fence)
    for k in range(3):
        wts[k] = 1.0
        wts[3 + k] = h
    for j in range(m):
        wts[6 + j] = phi_scale
        wts[6 + m + j] = h * phi_scale
    # depth-2 history: rows 0 (latest) and 1 of df, dg: the differences of f and G between
    # iterates
    depth = 0
    accelerate = True
    fn_old = 0.0
    ph_ref = c_ref = s_ref = 0.0  # the yaw of the step's first iterate and its cos, sin
    for _ in range(max_iter):
        iterations += 1
        if iterations == 1 or abs(y1[2] - ph_ref) > 1e-4:
            ph_ref = y1[2]
            c_ref = math.cos(ph_ref)
            s_ref = math.sin(ph_ref)
            c1, s1 = c_ref, s_ref
        else:
            c1, s1 = _turn(c_ref, s_ref, y1[2] - ph_ref)
        _evaluate(model, alpha1, rate1, accel1, ca1, sa1, y1, c1, s1, lam0, hh, end)
        _friction_prev(out, prev)
        if not (
            math.isfinite(res[0].fx) and math.isfinite(res[0].fy) and math.isfinite(res[0].mz)
        ):
            return STEP_REJECTED
        vf0 = y0[3] + hh * (f0[0].fx + lam0[0] + res[0].fx) * im0
        vf1 = y0[4] + hh * (f0[0].fy + lam0[1] + res[0].fy) * im0
        vf2 = y0[5] + hh * (f0[0].mz + lam0[2] + res[0].mz) * im2
        if on_belt:
            w0, w1, w2 = hh * im0, hh * im0, hh * im2
            sigma = belt_multiplier(P, vf0 - belt, vf1, vf2, w0, w1, w2, lam1, sigma)
            stuck = sigma < 0.0
            vi0 = vf0 + w0 * lam1[0]
            vi1 = vf1 + w1 * lam1[1]
            vi2 = vf2 + w2 * lam1[2]
            if stuck:
                vi0 = belt
        else:
            vi0, vi1, vi2 = vf0, vf1, vf2
        q0 = y0[0] + hh * (y0[3] + vi0)
        q1 = y0[1] + hh * (y0[4] + vi1)
        q2 = y0[2] + hh * (y0[5] + vi2)
        err = abs(q0 - y1[0]) + h * abs(vi0 - y1[3])
        err = max(err, abs(q1 - y1[1]) + h * abs(vi1 - y1[4]))
        err = max(err, abs(q2 - y1[2]) + h * abs(vi2 - y1[5]))
        if resolve_stick:  # the velocities to tol [m/s] as well
            err = max(err, abs(vi0 - y1[3]), abs(vi1 - y1[4]), abs(vi2 - y1[5]))
        g_new[0], g_new[1], g_new[2], g_new[3], g_new[4], g_new[5] = q0, q1, q2, vi0, vi1, vi2
        for j in range(m):
            z0 = base0[j] + base0[m + j] * modal1[j]
            g_new[6 + j] = z0
            g_new[6 + m + j] = base1[j] + base1[m + j] * modal1[j]
            err = max(err, abs(z0 - y1[6 + j]) * phi_scale)
        if err <= tol:
            for k in range(n):
                y1[k] = g_new[k]
            converged = True
            break
        # a stiff fence (no modes): Newton with the contacts' stiffness (the Anderson history
        # is not needed then); a stuck belt holds v1 fixed, where the plain update is exact
        slip = sigma if on_belt else 0.0
        if (
            NEWTON
            and m == 0
            and not stuck
            and _newton_load(P, out, y1, g_new, hh, im0, im2, rate1, slip, vf0 - belt, vf1, vf2)
        ):
            for k in range(n):
                y1[k] = g_new[k]
            continue
        # Anderson step on the scaled residual f = G(x) - x over the last two differences
        # (least squares); a residual that grows (a friction or contact switch inside the
        # iteration: G is not smooth there) turns it off
        fn = 0.0
        for k in range(n):
            f_cur[k] = (g_new[k] - y1[k]) * wts[k]
            fn += f_cur[k] * f_cur[k]
        if depth > 0 and fn > fn_old:
            accelerate = False
        fn_old = fn
        if depth > 0:
            for k in range(n):
                df[1, k] = df[0, k]
                dg[1, k] = dg[0, k]
                df[0, k] = f_cur[k] - f_prev[k]
                dg[0, k] = g_new[k] - g_prev[k]
        g0 = 0.0
        g1_ = 0.0
        if accelerate and depth > 0:
            a00 = a01 = a11 = b0 = b1 = 0.0
            for k in range(n):
                a00 += df[0, k] * df[0, k]
                b0 += df[0, k] * f_cur[k]
                if depth > 1:
                    a01 += df[0, k] * df[1, k]
                    a11 += df[1, k] * df[1, k]
                    b1 += df[1, k] * f_cur[k]
            det = a00 * a11 - a01 * a01
            if depth > 1 and det > 1e-12 * a00 * a11 and a11 > 0.0:
                g0 = (b0 * a11 - b1 * a01) / det
                g1_ = (a00 * b1 - a01 * b0) / det
            elif a00 > 0.0:
                g0 = b0 / a00
        for k in range(n):
            f_prev[k] = f_cur[k]
            g_prev[k] = g_new[k]
            y1[k] = g_new[k] - g0 * dg[0, k] - g1_ * dg[1, k]
        depth = min(depth + 1, 2)
    if not converged and not force:
        return STEP_REJECTED
    # converged: the forces of the last iterate (within tol of y1: an O(dN/dD tol) difference,
    # tol = 1e-9 m) end the step, as any fixed-point solve stops on its last evaluation; one
    # evaluation less per step (positioned_stiff 914 -> 712 per event). A single iteration
    # evaluated its friction without a previous iterate (prev = nan: the first guess of the
    # stick/slip branch), so that step is evaluated again at its end as before, unless no
    # contact acted at the iterate and no fence corner was within 10 tol of the fence: its
    # forces do not depend on the state then (the same end state to round-off), and only the
    # corners' D, Ddot, s (event values) are left at the iterate, within the tolerance
    again = not converged
    if converged and iterations < 2:
        again = res[0].active_mask != 0.0
        for k in range(SLOT_TIP):
            if out[k].gap != 0.0 and out[k].d > -10.0 * tol:
                again = True
    if again:
        if abs(y1[2] - ph_ref) > 1e-4:
            c1, s1 = math.cos(y1[2]), math.sin(y1[2])
        else:
            c1, s1 = _turn(c_ref, s_ref, y1[2] - ph_ref)
        _evaluate(model, alpha1, rate1, accel1, ca1, sa1, y1, c1, s1, lam0, hh, end)
    _unring_stick(P, phi, out0, out, res, modal1, y1[0], y1[1], h, h_prev, resolve_stick)
    if stuck:
        lam1[0], lam1[1], lam1[2] = stick_wrench(P, res[0].fx, res[0].fy, res[0].mz)
    res[0].iterations = iterations
    return STEP_OK if converged else STEP_FORCED


@njit(cache=True, _nrt=False)
def _unring_stick(P, phi, out0, out, res, modal, x, y, h, h_prev, extrapolate):
    """Replace the end friction of contacts that stick at both step ends by the stick force
    estimated from the step means (impulse / h, free of the ring): the mean itself, or with
    ``extrapolate`` and a previous step of h_prev > 0 that stuck at both ends too, the line
    through the two means at the step end (second order; the mean lags by h / 2)."""
    mu2 = P[0].mu2
    for k in range(N_SLOTS):
        if out[k].active == 0.0 or out0[k].active == 0.0:
            continue
        ft1, ft0 = out[k].ft, out0[k].ft
        if abs(ft1) >= mu2 * out[k].n * (1.0 - 1e-9):
            continue
        if abs(ft0) >= mu2 * out0[k].n * (1.0 - 1e-9):
            continue
        mean = 0.5 * (ft0 + ft1)
        out[k].fmean = mean
        stick = mean
        mean0 = out0[k].fmean
        if extrapolate and h_prev > 0.0 and mean0 != 0.0:
            stick = mean + (mean - mean0) * h / (h + h_prev)
        shift_friction(P, phi, out, res, modal, x, y, k, stick - ft1)


@njit(cache=True, _nrt=False)
def shift_friction(P, phi, out, res, modal, x, y, k, d):
    """Add d to slot k's friction force and to the resultants it enters."""
    tx, ty = out[k].ny, -out[k].nx  # n = (-t_y, t_x)
    dfx, dfy = d * tx, d * ty
    res[0].fx += dfx
    res[0].fy += dfy
    res[0].mz += (out[k].px - x) * dfy - (out[k].py - y) * dfx
    if k < SLOT_BORDER:
        res[0].power_fence += dfx * out[k].vsx + dfy * out[k].vsy
        if P[0].flexible != 0.0:
            _modal_share(P, phi, out[k].s, res[0].alpha, -dfx, -dfy, modal)
    out[k].ft += d


@njit(cache=True, _nrt=False, inline="always")
def _newmark(h, beta, gamma, m, y0, acc0, acc1, y1):
    """Newmark's update of the end state y1 from y0 and the accelerations acc0, acc1 of the
    second-order DOFs (x, y, phi, eta_1..m)."""
    for i in range(3 + m):
        if i < 3:
            qi, vi = i, 3 + i
        else:
            qi, vi = 6 + (i - 3), 6 + m + (i - 3)
        y1[qi] = y0[qi] + h * y0[vi] + h * h * ((0.5 - beta) * acc0[i] + beta * acc1[i])
        y1[vi] = y0[vi] + h * ((1.0 - gamma) * acc0[i] + gamma * acc1[i])


@njit(cache=True, _nrt=True)
def generalized_alpha_step(model, h, t, y0, acc0, start, on_belt, force, y1, acc1, end, ya):
    """One step of the generalized-alpha method (Chung and Hulbert 1993) on load and modes.

    M a_{n+1-am} = F(q_{n+1-af}, v_{n+1-af}, t_{n+1-af}) with Newmark updates; ``coef`` =
    (alpha_m, alpha_f, beta, gamma) from rho_inf. The modal equations are linear and solved in
    closed form for the contact force of the current iterate; the contact forces are iterated
    to ``tol`` (fixed point: the contact is soft). Belt friction is resolved at the step end
    like a constraint (stick holds u = 0 exactly), with the velocity weight h gamma /
    ((1 - alpha_m) m). ``acc0``/``acc1``: the algorithmic accelerations of (x, y, phi, eta_1..m).
    ``model``: a :data:`LoopModel` (settings: ``alpha_coefficients``, ``tol``, ``max_iter``);
    ``start``/``end``: the :data:`Evaluation` of the step start (its belt wrench) and of the
    step end (filled: forces and belt wrench); ``ya``: scratch, the state at the alpha point.
    """
    P, phi, omega, zeta, settings = (
        model.params, model.mode_shapes, model.omega, model.zeta, model.settings,
    )  # fmt: skip
    coef = settings[0].alpha_coefficients
    tol, max_iter = settings[0].tol, int(settings[0].max_iter)
    lam0, lam1, out, res, modal1 = start.belt, end.belt, end.contacts, end.resultant, end.modal
    prev = end.friction_prev
    am, af, beta, gamma = coef[0], coef[1], coef[2], coef[3]
    m = omega.shape[0]
    nd = 3 + m  # second-order DOFs: x, y, phi, eta
    t_a = t + (1.0 - af) * h
    im = np.empty(3)
    im[0] = im[1] = 1.0 / P[0].mass
    im[2] = 1.0 / P[0].inertia
    belt = P[0].belt
    # predictor: a_{n+1} = a_n
    for i in range(nd):
        acc1[i] = acc0[i]
    phi_scale = 0.0
    for i in range(phi.shape[0]):
        for j in range(m):
            if abs(phi[i, j]) > phi_scale:
                phi_scale = abs(phi[i, j])
    for k in range(N_SLOTS):
        prev[k] = math.nan
    stuck = False
    lam1[0], lam1[1], lam1[2] = lam0[0], lam0[1], lam0[2]
    wv = h * gamma / (1.0 - am)  # end velocity per unit (force / mass) at the alpha point
    converged = False
    for it in range(max_iter + 1):
        # Newmark update of the end state from acc1
        _newmark(h, beta, gamma, m, y0, acc0, acc1, y1)
        for i in range(6 + 2 * m):
            ya[i] = (1.0 - af) * y1[i] + af * y0[i]
        # t_a lies inside the step, where the drive's acceleration is already the new one
        evaluate(model, t_a, 0.0, ya, lam1, (1.0 - af) * wv, end)
        _friction_prev(out, prev)
        if not (
            math.isfinite(res[0].fx) and math.isfinite(res[0].fy) and math.isfinite(res[0].mz)
        ):
            return STEP_REJECTED
        if it == max_iter:
            break
        err = 0.0
        # load: (1 - am) a1 + am a0 = (F + lambda_a) / M with the belt wrench at the alpha
        # point lambda_a = (1 - af) lambda1 + af lambda0, lambda1 from the end-velocity law
        # (stick is exact at the step end); applying lambda1 itself at the alpha point made
        # the scheme first order under sliding friction
        fa0, fa1, fa2 = res[0].fx, res[0].fy, res[0].mz
        vs0 = y0[3] + h * (1.0 - gamma) * acc0[0] + wv * (fa0 * im[0] - am * acc0[0])
        vs1 = y0[4] + h * (1.0 - gamma) * acc0[1] + wv * (fa1 * im[1] - am * acc0[1])
        vs2 = y0[5] + h * (1.0 - gamma) * acc0[2] + wv * (fa2 * im[2] - am * acc0[2])
        if on_belt:
            wl = wv * (1.0 - af)
            stuck = implicit_belt(
                P,
                vs0 + wv * af * lam0[0] * im[0] - belt,
                vs1 + wv * af * lam0[1] * im[1],
                vs2 + wv * af * lam0[2] * im[2],
                wl * im[0],
                wl * im[1],
                wl * im[2],
                lam1,
            )
            fa = (
                fa0 + (1.0 - af) * lam1[0] + af * lam0[0],
                fa1 + (1.0 - af) * lam1[1] + af * lam0[1],
                fa2 + (1.0 - af) * lam1[2] + af * lam0[2],
            )
        else:
            lam1[0] = lam1[1] = lam1[2] = 0.0
            stuck = False
            fa = (fa0, fa1, fa2)
        for i in range(3):
            a_new = (fa[i] * im[i] - am * acc0[i]) / (1.0 - am)
            err = max(err, h * h * abs(a_new - acc1[i]))
            acc1[i] = a_new
        # modes: (1-am) a1 + am a0 + 2 zeta omega v_a + omega^2 q_a = f_a, linear in a1
        for j in range(m):
            om_j, ze_j = omega[j], zeta[j]
            e0, ed0, a0j = y0[6 + j], y0[6 + m + j], acc0[3 + j]
            q_pred = e0 + h * ed0 + h * h * (0.5 - beta) * a0j
            v_pred = ed0 + h * (1.0 - gamma) * a0j
            rhs = (
                modal1[j]
                - am * a0j
                - 2.0 * ze_j * om_j * ((1.0 - af) * v_pred + af * ed0)
                - om_j * om_j * ((1.0 - af) * q_pred + af * e0)
            )
            lhs = (
                (1.0 - am)
                + 2.0 * ze_j * om_j * (1.0 - af) * h * gamma
                + om_j * om_j * (1.0 - af) * h * h * beta
            )
            a_new = rhs / lhs
            err = max(err, h * h * beta * abs(a_new - acc1[3 + j]) * phi_scale)
            acc1[3 + j] = a_new
        if err <= tol and it > 0:
            converged = True
            # final Newmark update with the converged accelerations
            _newmark(h, beta, gamma, m, y0, acc0, acc1, y1)
            if on_belt and stuck:
                y1[3] = belt
            break
    if not converged and not force:
        return STEP_REJECTED
    # end-of-step forces (for recording, events and the next step's explicit quantities)
    evaluate(model, t + h, 0.0, y1, lam1, 0.0, end)
    if stuck:
        lam1[0], lam1[1], lam1[2] = stick_wrench(P, res[0].fx, res[0].fy, res[0].mz)
    return STEP_OK if converged else STEP_FORCED
