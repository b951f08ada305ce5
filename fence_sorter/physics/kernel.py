"""Compiled force evaluation and one-step maps of the sorting model (Numba).

This module is the one implementation of the forces of one sorting event: the fence surface
(21)-(32), the contact law (16) with fence and border friction (37), belt friction (34)-(36) and
the fence's modal load (20). Everything works on flat float arrays so that Numba compiles it:

- ``P``: packed scalar parameters (indices ``P_*`` below), built by :func:`pack`;
- ``y``: the state [x, y, phi, vx, vy, phidot, eta_1..m, etadot_1..m] (C_s over ground, yaw,
  their rates, then the fence's modal coordinates and rates; m = 0 for a stiff fence);
- ``out``: one row per contact slot (0-3 corner k on the fence, 4-7 the fence tip in face k,
  8-11 corner k on the border wall) with the columns ``C_*``;
- ``res``: the resultant and a few scalars (indices ``R_*``).

Why compiled: the pure-Python stepper ran impact_flexible at 2.4x real time; the accuracy and
speed targets (75x real time) need the force evaluation in the 1-10 us range, which only a
compiled kernel reaches (docs/benchmarks.md measures the same code with and without the JIT).
Setting NUMBA_DISABLE_JIT=1 runs exactly this code as plain Python.

Compiled without Numba's reference counting (``_nrt=False``, as Numba compiles its own hot
helpers): every array here is allocated by the caller, and with NRT each call of a kernel
function and each view (``Y[a]``, ``out[slot]``) paid an atomic incref/decref per array, 139,000
per positioned_stiff event, half its run time (perf; counted with gdb on NRT_incref/decref).
The two functions that allocate (``modal_propagators``, ``generalized_alpha_step``) say
``_nrt=True`` explicitly: a callee otherwise inherits the flag of whoever compiles it first.

The small helpers of the contact iteration (``_add``, ``_surface``, ``_fence_friction``,
``implicit_belt``, ``belt_multiplier``, ``_friction_prev``, ``_newton_load``) are inlined into
their callers by Numba (``inline="always"``): a call passes every array as ~7-9 machine words,
and the profile showed the callers pushing ~150 words per ``_evaluate`` call and dozens per
``_add`` (same arithmetic, bitwise the same results; compiled loop 5-12 % faster,
docs/numerics.md).

The time-stepping schemes built on it (trapezoidal, generalized-alpha) are ``*_step`` functions
here. The control loop (events, step size, stages, recording) exists twice: :func:`solve` at the
end of this module runs it compiled (``solver.engine = compiled``, the default, driven by
``engine.py``), ``integrators.Integrator`` in Python (``solver.engine = python``, the
soft-real-time line, generalized-alpha); test/physics/test_engine.py checks they agree.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# -- packed parameters --------------------------------------------------------------------------
P_ALPHA_K = 0  # alpha_k [rad]
P_T1 = 1  # t1 [s]
P_MASS = 2  # m_p [kg]
P_INERTIA = 3  # I_p about C_s [kg m^2]
P_FMAX = 4  # mu1 m g [N]
P_TMAX = 5  # pure-spin torque [N m]
P_BEFF = 6  # b_p m_p^0.4
P_KP = 7  # k_p [N/m^4]
P_MU2 = 8  # fence / border friction
P_VMIN = 9  # Karnopp threshold [m/s]
P_PHIDOT_MIN = 10  # [rad/s]
P_LENGTH = 11  # R_z [m]
P_DL = 12  # element length [m] (flexible)
P_NEL = 13  # elements (flexible)
P_USE_BORDER = 14
P_USE_TIP = 15
P_FLEX = 16
P_BELT = 17  # belt speed [m/s]
P_EXT_X = 18  # external wrench on the load
P_EXT_Y = 19
P_EXT_M = 20
P_MARGIN = 21  # cheap-reject margin beyond the deflection [m]
N_PARAMS = 22

# -- contact slot columns -----------------------------------------------------------------------
C_ACTIVE = 0  # 1: force acting (D > 0)
C_GAP = 1  # 1: a fence candidate whose D and Ddot are known (for onset/release location)
C_S = 2  # arc position [m]
C_D = 3  # D [m]
C_DDOT = 4  # Ddot [m/s]
C_N = 5  # N [N] (clipped >= 0)
C_NRAW = 6  # the law (16) before the clip (negative: adhesion the clip removes)
C_FT = 7  # tangential friction force on the load [N]
C_PX = 8  # contact point
C_PY = 9
C_NX = 10  # unit normal of the force on the load
C_NY = 11
C_VSX = 12  # surface velocity at the contact point (0 for the border)
C_VSY = 13
N_COLS = 14
N_SLOTS = 12
SLOT_TIP = 4
SLOT_BORDER = 8

# -- results ------------------------------------------------------------------------------------
R_FX = 0  # contact resultant plus external wrench on the load (belt friction excluded)
R_FY = 1
R_MZ = 2
R_FENCE_N = 3  # sum of N over fence contacts [N]
R_MAX_D = 4  # deepest D [m]
R_POWER_FENCE = 5  # power of the fence contact forces at the fence surface velocity [W]
R_ALPHA = 6  # alpha_w [rad]
R_RATE = 7
R_ACCEL = 8
R_TIP_W = 9  # tip deflection [m]
R_MAX_W = 10  # largest nodal |w| [m]
R_ENERGY_CONTACT = 11  # potential of the k_p D^4 springs, sum k D^5 / 5 [J]
R_ACTIVE_MASK = 12  # bit k set: slot k carries a force
R_ITERATIONS = 13  # contact iterations the step that produced this point took
N_RES = 14


def pack(
    *,
    alpha_k,
    t1,
    mass,
    inertia,
    f_max,
    t_max,
    b_p,
    k_p,
    mu2,
    v_min,
    phidot_min,
    length,
    dl,
    n_el,
    use_border,
    use_tip,
    flexible,
    belt,
    external,
    margin=0.05,
) -> np.ndarray:
    """The packed parameter vector ``P`` (SI units)."""
    # filled as a list, one array at the end (a NumPy item assignment per field costs ~1 us on
    # a cold cache; a model is built per event)
    p = [0.0] * N_PARAMS
    p[P_ALPHA_K], p[P_T1] = alpha_k, t1
    p[P_MASS], p[P_INERTIA], p[P_FMAX], p[P_TMAX] = mass, inertia, f_max, t_max
    p[P_BEFF], p[P_KP], p[P_MU2] = b_p * mass**0.4, k_p, mu2
    p[P_VMIN], p[P_PHIDOT_MIN] = v_min, phidot_min
    p[P_LENGTH], p[P_DL], p[P_NEL] = length, dl, n_el
    p[P_USE_BORDER], p[P_USE_TIP], p[P_FLEX] = float(use_border), float(use_tip), float(flexible)
    p[P_BELT] = belt
    p[P_EXT_X], p[P_EXT_Y], p[P_EXT_M] = external
    p[P_MARGIN] = margin
    return np.array(p, dtype=float)


# -- drive --------------------------------------------------------------------------------------
@njit(cache=True, _nrt=False)
def drive(P, t):
    """alpha_w, rate, acceleration of the sinusoidal-velocity drive (see ``drive.py``)."""
    t1 = P[P_T1]
    if t < 0.0 or t > 2.0 * t1:
        return 0.0, 0.0, 0.0
    w = math.pi / t1
    half = 0.5 * P[P_ALPHA_K]
    return (
        half * (1.0 - math.cos(w * t)),
        half * w * math.sin(w * t),
        half * w * w * math.cos(w * t),
    )


# -- fence geometry -----------------------------------------------------------------------------
@njit(cache=True, _nrt=False)
def fence_shape(P, phi, eta, etadot, alpha, w, wdot, nodes):
    """Nodal deflections w = Phi eta, their rates, and the chord chain node positions (27)-(29)."""
    n = int(P[P_NEL])
    m = eta.shape[0]
    for i in range(2 * n):
        a = 0.0
        b = 0.0
        for j in range(m):
            a += phi[i, j] * eta[j]
            b += phi[i, j] * etadot[j]
        w[i] = a
        wdot[i] = b
    dl = P[P_DL]
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
    n = int(P[P_NEL])
    dl = P[P_DL]
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
    if P[P_FLEX] == 0.0:
        return s * ca, s * sa, ca, sa, -rate * s * sa, rate * s * ca
    i, d = _element(P, s)
    inv_dl = 1.0 / P[P_DL]
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
    frac = d / P[P_DL]
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
    f_max = P[P_FMAX]
    t_max = P[P_TMAX]
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
    f_max = P[P_FMAX]
    t_max = P[P_TMAX]
    v_o = math.hypot(ux, uy)
    norm = math.hypot(f_max * v_o, t_max * spin)
    slide_t = v_o > P[P_VMIN]
    slide_r = abs(spin) > P[P_PHIDOT_MIN]
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
    fm2 = P[P_FMAX] * P[P_FMAX]
    tm2 = P[P_TMAX] * P[P_TMAX]
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
def _add(
    P,
    phi,
    out,
    res,
    modal,
    slot,
    s_arc,
    d,
    d_rate,
    px,
    py,
    nx,
    ny,
    tx,
    ty,
    slide,
    vsx,
    vsy,
    x,
    y,
    lam_x,
    lam_y,
    weight,
    prev,
    on_fence,
    alpha,
):
    mass = P[P_MASS]
    n_raw = P[P_BEFF] * d_rate * d * d + P[P_KP] * d**4
    n = n_raw if n_raw > 0.0 else 0.0
    mu2 = P[P_MU2]
    f_prev = prev[slot]
    if weight > 0.0 and not math.isnan(f_prev):
        # implicit (37): the friction that stops this contact's slip by the step end if it lies
        # within mu2 N, else mu2 N against the slip
        arm = (px - x) * ty - (py - y) * tx
        w_eff = weight * (1.0 / mass + arm * arm / P[P_INERTIA])
        slip_free = slide - w_eff * f_prev
        limit = mu2 * n
        ft = -slip_free / w_eff
        if abs(ft) > limit:
            ft = -math.copysign(limit, slip_free)
    else:
        ft = _fence_friction(n, slide, lam_x * tx + lam_y * ty, mu2, P[P_VMIN])
    fx = n * nx + ft * tx
    fy = n * ny + ft * ty
    res[R_FX] += fx
    res[R_FY] += fy
    res[R_MZ] += (px - x) * fy - (py - y) * fx
    res[R_ENERGY_CONTACT] += 0.2 * P[P_KP] * d**5
    if on_fence:
        res[R_FENCE_N] += n
        res[R_POWER_FENCE] += fx * vsx + fy * vsy
        if P[P_FLEX] != 0.0:
            _modal_share(P, phi, s_arc, alpha, -fx, -fy, modal)
    res[R_ACTIVE_MASK] += float(1 << slot)
    if d > res[R_MAX_D]:
        res[R_MAX_D] = d
    row = out[slot]
    row[C_ACTIVE] = 1.0
    row[C_S] = s_arc
    row[C_D] = d
    row[C_DDOT] = d_rate
    row[C_N] = n
    row[C_NRAW] = n_raw
    row[C_FT] = ft
    row[C_PX] = px
    row[C_PY] = py
    row[C_NX] = nx
    row[C_NY] = ny
    row[C_VSX] = vsx
    row[C_VSY] = vsy


@njit(cache=True, _nrt=False)
def evaluate(
    P,
    corners,
    normals,
    phi,
    rigid_modal,
    t,
    accel_jump,
    y,
    lam,
    weight,
    prev,
    out,
    res,
    modal,
    w,
    wdot,
    nodes,
):
    """All contact forces on the load at time t and state y (see the module docstring).

    ``lam``: the belt wrench, the applied tangential force of (37)'s stick branch. ``weight``
    > 0 (velocity change per unit end-of-step force over the mass) with ``prev`` (each slot's
    friction at the previous iterate, NaN if none) makes (37) implicit inside a step's
    iteration. ``accel_jump`` is added to the drive acceleration (a step starting on the far
    side of the jump at 2 t1). Fills ``out``, ``res`` and ``modal`` (the fence's generalized
    force including the drive's inertial load -Phi^T M_fa r alpha_ddot).
    """
    alpha, rate, accel = drive(P, t)
    accel += accel_jump
    _evaluate(
        P, corners, normals, phi, rigid_modal, alpha, rate, accel, math.cos(alpha),
        math.sin(alpha), y, math.cos(y[2]), math.sin(y[2]), lam, weight, prev, out, res, modal,
        w, wdot, nodes,
    )  # fmt: skip


@njit(cache=True, _nrt=False)
def _evaluate(
    P, corners, normals, phi, rigid_modal, alpha, rate, accel, ca, sa, y, c, s, lam, weight, prev,
    out, res, modal, w, wdot, nodes,
):  # fmt: skip
    """:func:`evaluate` with the drive state (alpha, rate, accel), cos, sin of alpha and c, s
    = cos, sin of the yaw y[2] given: a step's iteration evaluates every iterate at the same
    time, so it computes alpha's once, and the yaw's from the first iterate's (``_turn``)."""
    out[:, :] = 0.0
    res[:] = 0.0
    modal[:] = 0.0
    x, yy, vx, vy, om = y[0], y[1], y[3], y[4], y[5]
    m = modal.shape[0]
    res[R_ALPHA], res[R_RATE], res[R_ACCEL] = alpha, rate, accel
    flex = P[P_FLEX] != 0.0
    if flex:
        fence_shape(P, phi, y[6 : 6 + m], y[6 + m : 6 + 2 * m], alpha, w, wdot, nodes)
        n_el = int(P[P_NEL])
        res[R_TIP_W] = w[2 * n_el - 2]
        mw = 0.0
        for k in range(n_el):
            if abs(w[2 * k]) > mw:
                mw = abs(w[2 * k])
        res[R_MAX_W] = mw
    length = P[P_LENGTH]
    use_tip = P[P_USE_TIP] != 0.0
    reach = res[R_MAX_W] + P[P_MARGIN]
    lam_x, lam_y = lam[0], lam[1]
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
            out[k, C_S] = s_arc  # beyond the tip: the slide-off event function is R_z - s
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
        vpx = vx - om * (py - yy)
        vpy = vy + om * (px - x)
        d_rate = (vux - vpx) * nx + (vuy - vpy) * ny
        out[k, C_GAP] = 1.0
        out[k, C_D] = d
        out[k, C_DDOT] = d_rate
        out[k, C_NRAW] = d  # negative before contact: the onset function
        if d > 0.0:
            slide = (vpx - vux) * tx + (vpy - vuy) * ty
            _add(
                P,
                phi,
                out,
                res,
                modal,
                k,
                s_arc,
                d,
                d_rate,
                px,
                py,
                nx,
                ny,
                tx,
                ty,
                slide,
                vux,
                vuy,
                x,
                yy,
                lam_x,
                lam_y,
                weight,
                prev,
                True,
                alpha,
            )
    # the fence tip inside the load (past a corner that slid off it, or pressed into a face
    # beyond the last pushing corner): it presses on the face that faces the fence (outward
    # normal most against the fence normal), the depth is the tip's distance to that face's
    # plane, which starts from 0 as the tip enters through it and equals the corner's D when a
    # corner of a face along the fence slides off (continuous hand-over), and the force acts
    # along the face normal: the gradient of the potential k_p D^5 / 5, zero at release.
    # (Measuring the depth along the fence normal and pushing along it did work in a closed
    # elastic cycle; starting the contact only once a corner had passed the tip let it appear at
    # finite depth.)
    if use_tip:
        exit_face = -1
        facing = -math.inf
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
            if cos_dir > facing:
                facing = cos_dir
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
            out[slot, C_GAP] = 1.0
            _add(
                P,
                phi,
                out,
                res,
                modal,
                slot,
                length,
                depth,
                d_rate,
                tip_x,
                tip_y,
                fnx,
                fny,
                ftx,
                fty,
                slide,
                vtx,
                vty,
                x,
                yy,
                lam_x,
                lam_y,
                weight,
                prev,
                True,
                alpha,
            )
    if P[P_USE_BORDER] != 0.0:
        for k in range(4):
            px = x + c * corners[k, 0] - s * corners[k, 1]
            py = yy + s * corners[k, 0] + c * corners[k, 1]
            if py >= 0.0:
                continue
            vpx = vx - om * (py - yy)
            vpy = vy + om * (px - x)
            _add(
                P,
                phi,
                out,
                res,
                modal,
                SLOT_BORDER + k,
                math.nan,
                -py,
                -vpy,
                px,
                py,
                0.0,
                1.0,
                1.0,
                0.0,
                vpx,
                0.0,
                0.0,
                x,
                yy,
                lam_x,
                lam_y,
                weight,
                prev,
                False,
                alpha,
            )
    if flex:
        for j in range(m):
            modal[j] -= rigid_modal[j] * accel
    res[R_FX] += P[P_EXT_X]
    res[R_FY] += P[P_EXT_Y]
    res[R_MZ] += P[P_EXT_M]


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
        prev[k] = out[k, C_FT] if out[k, C_ACTIVE] != 0.0 else math.nan


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
    b = P[P_BEFF]
    kp = P[P_KP]
    mu2 = P[P_MU2]
    x, y, vx, vy, om = y1[0], y1[1], y1[3], y1[4], y1[5]
    m00 = m11 = m22 = 0.0
    m01 = m02 = m10 = m12 = m20 = m21 = 0.0
    active = False
    for k in range(N_SLOTS):
        row = out[k]
        if row[C_ACTIVE] == 0.0:
            continue
        nn = row[C_N]
        if nn <= 0.0:
            continue
        d = row[C_D]
        c = hh * (4.0 * kp * d * d * d + 2.0 * b * d * row[C_DDOT]) + b * d * d
        if c <= 0.0:
            continue
        active = True
        nx, ny = row[C_NX], row[C_NY]
        tx, ty = ny, -nx
        rx, ry = row[C_PX] - x, row[C_PY] - y
        j2 = rx * ny - ry * nx
        t2 = rx * ty - ry * tx
        u0_, u1_, u2_ = nx, ny, j2
        ft = row[C_FT]
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
            slide = (vpx - row[C_VSX]) * tx + (vpy - row[C_VSY]) * ty
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
        fm2 = P[P_FMAX] * P[P_FMAX]
        tm2 = P[P_TMAX] * P[P_TMAX]
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
def trapezoidal_step(
    P,
    corners,
    normals,
    phi,
    rigid_modal,
    props,
    h,
    t,
    y0,
    f0,
    lam0,
    modal0,
    out0,
    jump,
    on_belt,
    tol,
    max_iter,
    force,
    y1,
    lam1,
    out,
    res,
    modal1,
    w,
    wdot,
    nodes,
    prev,
    work,
):
    """One step of the trapezoidal rule, implicit in the contact forces and belt friction.

    Load: q1 = q0 + h/2 (v0 + v1), v1 = v0 + h/2 M^-1 (F0 + F1 + lambda1), iterated on F1 until
    the update is within ``tol``: Newton with the contacts' stiffness on a stiff fence
    (``_newton_load``), an Anderson-accelerated fixed point with the fence's modes; lambda1
    solves the belt law at the step end (stick exact; its multiplier warm-started from the
    previous iterate's). Fence: each mode
    propagated exactly for a modal force linear over the step (``props`` = (A, G0, G1) from
    Van Loan's matrix exponential). ``f0``/``lam0``/``modal0``: forces at the step start.
    Returns STEP_OK, STEP_REJECTED or STEP_FORCED; the end-of-step forces are left in out/res/
    modal1 and the belt wrench in lam1 (the stick wrench when stuck).

    Stick forces are constraint forces, and the trapezoidal rule rings on them (F1 = 2 F - F0,
    alternating step to step); like the belt's stick wrench, a fence or border contact that
    sticks at both ends of the step stores the mean (F0 + F1) / 2 as its end force (``out0``:
    the contacts at the step start), which removes the ringing mode.
    """
    a_mat, g0, g1 = props
    m = modal0.shape[0]
    t1 = t + h
    im0 = 1.0 / P[P_MASS]
    im2 = 1.0 / P[P_INERTIA]
    belt = P[P_BELT]
    hh = 0.5 * h
    fs0, fs1, fs2 = f0[0] + lam0[0], f0[1] + lam0[1], f0[2] + lam0[2]
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
    for j in range(m):
        fm = modal0[j] - rigid_modal[j] * jump
        e0 = y0[6 + j]
        e1 = y0[6 + m + j]
        base0[j] = a_mat[j, 0, 0] * e0 + a_mat[j, 0, 1] * e1 + g0[j, 0] * fm
        base1[j] = a_mat[j, 1, 0] * e0 + a_mat[j, 1, 1] * e1 + g0[j, 1] * fm
        y1[6 + j] = base0[j] + g1[j, 0] * fm
        y1[6 + m + j] = base1[j] + g1[j, 1] * fm
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
        _evaluate(
            P, corners, normals, phi, rigid_modal, alpha1, rate1, accel1, ca1, sa1, y1, c1, s1,
            lam0, hh, prev, out, res, modal1, w, wdot, nodes,
        )  # fmt: skip
        _friction_prev(out, prev)
        if not (
            math.isfinite(res[R_FX]) and math.isfinite(res[R_FY]) and math.isfinite(res[R_MZ])
        ):
            return STEP_REJECTED
        vf0 = y0[3] + hh * (f0[0] + lam0[0] + res[R_FX]) * im0
        vf1 = y0[4] + hh * (f0[1] + lam0[1] + res[R_FY]) * im0
        vf2 = y0[5] + hh * (f0[2] + lam0[2] + res[R_MZ]) * im2
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
        g_new[0], g_new[1], g_new[2], g_new[3], g_new[4], g_new[5] = q0, q1, q2, vi0, vi1, vi2
        for j in range(m):
            z0 = base0[j] + g1[j, 0] * modal1[j]
            g_new[6 + j] = z0
            g_new[6 + m + j] = base1[j] + g1[j, 1] * modal1[j]
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
        again = res[R_ACTIVE_MASK] != 0.0
        for k in range(SLOT_TIP):
            if out[k, C_GAP] != 0.0 and out[k, C_D] > -10.0 * tol:
                again = True
    if again:
        if abs(y1[2] - ph_ref) > 1e-4:
            c1, s1 = math.cos(y1[2]), math.sin(y1[2])
        else:
            c1, s1 = _turn(c_ref, s_ref, y1[2] - ph_ref)
        _evaluate(
            P, corners, normals, phi, rigid_modal, alpha1, rate1, accel1, ca1, sa1, y1, c1, s1,
            lam0, hh, prev, out, res, modal1, w, wdot, nodes,
        )  # fmt: skip
    _unring_stick(P, phi, out0, out, res, modal1, y1[0], y1[1])
    if stuck:
        lam1[0], lam1[1], lam1[2] = stick_wrench(P, res[R_FX], res[R_FY], res[R_MZ])
    res[R_ITERATIONS] = iterations
    return STEP_OK if converged else STEP_FORCED


@njit(cache=True, _nrt=False)
def _unring_stick(P, phi, out0, out, res, modal, x, y):
    """Replace the end friction of contacts that stick at both step ends by the step mean."""
    mu2 = P[P_MU2]
    for k in range(N_SLOTS):
        if out[k, C_ACTIVE] == 0.0 or out0[k, C_ACTIVE] == 0.0:
            continue
        ft1, ft0 = out[k, C_FT], out0[k, C_FT]
        if abs(ft1) >= mu2 * out[k, C_N] * (1.0 - 1e-9):
            continue
        if abs(ft0) >= mu2 * out0[k, C_N] * (1.0 - 1e-9):
            continue
        d = 0.5 * (ft0 + ft1) - ft1
        tx, ty = out[k, C_NY], -out[k, C_NX]  # n = (-t_y, t_x)
        dfx, dfy = d * tx, d * ty
        res[R_FX] += dfx
        res[R_FY] += dfy
        res[R_MZ] += (out[k, C_PX] - x) * dfy - (out[k, C_PY] - y) * dfx
        if k < SLOT_BORDER:
            res[R_POWER_FENCE] += dfx * out[k, C_VSX] + dfy * out[k, C_VSY]
            if P[P_FLEX] != 0.0:
                _modal_share(P, phi, out[k, C_S], res[R_ALPHA], -dfx, -dfy, modal)
        out[k, C_FT] += d


@njit(cache=True, _nrt=True)
def generalized_alpha_step(
    P,
    corners,
    normals,
    phi,
    rigid_modal,
    omega,
    zeta,
    coef,
    h,
    t,
    y0,
    acc0,
    lam0,
    on_belt,
    tol,
    max_iter,
    force,
    y1,
    acc1,
    lam1,
    out,
    res,
    modal1,
    w,
    wdot,
    nodes,
    prev,
    ya,
):
    """One step of the generalized-alpha method (Chung and Hulbert 1993) on load and modes.

    M a_{n+1-am} = F(q_{n+1-af}, v_{n+1-af}, t_{n+1-af}) with Newmark updates; ``coef`` =
    (alpha_m, alpha_f, beta, gamma) from rho_inf. The modal equations are linear and solved in
    closed form for the contact force of the current iterate; the contact forces are iterated
    to ``tol`` (fixed point: the contact is soft). Belt friction is resolved at the step end
    like a constraint (stick holds u = 0 exactly), with the velocity weight h gamma /
    ((1 - alpha_m) m). ``acc0``/``acc1``: the algorithmic accelerations of (x, y, phi, eta_1..m).
    """
    am, af, beta, gamma = coef[0], coef[1], coef[2], coef[3]
    m = omega.shape[0]
    nd = 3 + m  # second-order DOFs: x, y, phi, eta
    t_a = t + (1.0 - af) * h
    im = np.empty(3)
    im[0] = im[1] = 1.0 / P[P_MASS]
    im[2] = 1.0 / P[P_INERTIA]
    belt = P[P_BELT]
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
        for i in range(nd):
            if i < 3:
                qi, vi = i, 3 + i
            else:
                qi, vi = 6 + (i - 3), 6 + m + (i - 3)
            y1[qi] = y0[qi] + h * y0[vi] + h * h * ((0.5 - beta) * acc0[i] + beta * acc1[i])
            y1[vi] = y0[vi] + h * ((1.0 - gamma) * acc0[i] + gamma * acc1[i])
        for i in range(6 + 2 * m):
            ya[i] = (1.0 - af) * y1[i] + af * y0[i]
        # t_a lies inside the step, where the drive's acceleration is already the new one
        evaluate(
            P,
            corners,
            normals,
            phi,
            rigid_modal,
            t_a,
            0.0,
            ya,
            lam1,
            (1.0 - af) * wv,
            prev,
            out,
            res,
            modal1,
            w,
            wdot,
            nodes,
        )
        _friction_prev(out, prev)
        if not (
            math.isfinite(res[R_FX]) and math.isfinite(res[R_FY]) and math.isfinite(res[R_MZ])
        ):
            return STEP_REJECTED
        if it == max_iter:
            break
        err = 0.0
        # load: (1 - am) a1 + am a0 = (F + lambda_a) / M with the belt wrench at the alpha
        # point lambda_a = (1 - af) lambda1 + af lambda0, lambda1 from the end-velocity law
        # (stick is exact at the step end); applying lambda1 itself at the alpha point made
        # the scheme first order under sliding friction
        fa0, fa1, fa2 = res[R_FX], res[R_FY], res[R_MZ]
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
            for i in range(nd):
                if i < 3:
                    qi, vi = i, 3 + i
                else:
                    qi, vi = 6 + (i - 3), 6 + m + (i - 3)
                y1[qi] = y0[qi] + h * y0[vi] + h * h * ((0.5 - beta) * acc0[i] + beta * acc1[i])
                y1[vi] = y0[vi] + h * ((1.0 - gamma) * acc0[i] + gamma * acc1[i])
            if on_belt and stuck:
                y1[3] = belt
            break
    if not converged and not force:
        return STEP_REJECTED
    # end-of-step forces (for recording, events and the next step's explicit quantities)
    evaluate(
        P,
        corners,
        normals,
        phi,
        rigid_modal,
        t + h,
        0.0,
        y1,
        lam1,
        0.0,
        prev,
        out,
        res,
        modal1,
        w,
        wdot,
        nodes,
    )
    if stuck:
        lam1[0], lam1[1], lam1[2] = stick_wrench(P, res[R_FX], res[R_FY], res[R_MZ])
    return STEP_OK if converged else STEP_FORCED


# -- right-hand side for ODE solvers (scipy.integrate baselines) --------------------------------
@njit(cache=True, _nrt=False)
def rhs(
    P,
    corners,
    normals,
    phi,
    rigid_modal,
    omega,
    zeta,
    t,
    y,
    on_belt,
    dy,
    out,
    res,
    modal,
    w,
    wdot,
    nodes,
    prev,
    lam,
):
    """dy/dt of the full model with explicit Karnopp friction (34)-(37), the form an ODE solver
    integrates: the same forces as the steppers, no implicit friction. The fence friction's
    stick branch sees no belt wrench (it would need the belt friction it feeds): it matters only
    inside the 1e-6 m/s window."""
    m = omega.shape[0]
    for k in range(N_SLOTS):
        prev[k] = math.nan
    lam[0] = lam[1] = lam[2] = 0.0
    evaluate(
        P,
        corners,
        normals,
        phi,
        rigid_modal,
        t,
        0.0,
        y,
        lam,
        0.0,
        prev,
        out,
        res,
        modal,
        w,
        wdot,
        nodes,
    )
    fx, fy, mz = res[R_FX], res[R_FY], res[R_MZ]
    if on_belt:
        bx, by, bz = karnopp_belt(P, y[3] - P[P_BELT], y[4], y[5], fx, fy, mz)
        fx += bx
        fy += by
        mz += bz
        lam[0], lam[1], lam[2] = bx, by, bz
    dy[0], dy[1], dy[2] = y[3], y[4], y[5]
    dy[3] = fx / P[P_MASS]
    dy[4] = fy / P[P_MASS]
    dy[5] = mz / P[P_INERTIA]
    for j in range(m):
        e, ed = y[6 + j], y[6 + m + j]
        dy[6 + j] = ed
        dy[6 + m + j] = modal[j] - omega[j] * omega[j] * e - 2.0 * zeta[j] * omega[j] * ed


N_STIFF_STEPS = 800  # RK4 steps per elastic contact time of the N_stiff solve (error < 2e-7)


@njit(cache=True, _nrt=False)
def _impact_rk4(b, k_p, mass, h, d, v):
    """One RK4 step of m D'' = -N(D, D') (law (16), rigid wall) from (D, D'); returns the new
    D, D' and N there."""
    k1d, k1v = v, -_law(b, k_p, d, v) / mass
    k2d, k2v = v + 0.5 * h * k1v, -_law(b, k_p, d + 0.5 * h * k1d, v + 0.5 * h * k1v) / mass
    k3d, k3v = v + 0.5 * h * k2v, -_law(b, k_p, d + 0.5 * h * k2d, v + 0.5 * h * k2v) / mass
    k4d, k4v = v + h * k3v, -_law(b, k_p, d + h * k3d, v + h * k3v) / mass
    d_new = d + h / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d)
    v_new = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    return d_new, v_new, _law(b, k_p, d_new, v_new)


@njit(cache=True, _nrt=False)
def _vertex(left, peak, right):
    """The largest force of an impact from its largest RK4 point and the points either side
    (equal steps): the vertex of the parabola through them (the discrete maximum alone is off
    by O(h^2), the vertex by O(h^3))."""
    curvature = left - 2.0 * peak + right
    if right >= 0.0 and curvature < 0.0:
        return peak - (right - left) ** 2 / (8.0 * curvature)
    return peak


@njit(cache=True, _nrt=False)
def stiff_impact_peak(mass, approach_speed, b_p, k_p, steps):
    """Peak force, max deformation, duration and restitution of law (16) against a rigid wall.

    Classical RK4 on m D'' = -N(D, D') with ``steps`` steps over the elastic contact time
    estimate 2.5074 D_max / w_n, continued until separation, the peak refined by ``_vertex``;
    used on the hot path (one call per impact) with N_STIFF_STEPS, checked against the DOP853
    reference in ``contact.stiff_impact`` (test_contact_friction).
    """
    if approach_speed <= 0.0:
        return 0.0, 0.0, 0.0, 1.0
    b = b_p * mass**0.4
    d_max = (5.0 * mass * approach_speed**2 / (2.0 * k_p)) ** 0.2
    h = 2.5074 * d_max / approach_speed / steps
    d, v = 0.0, approach_speed
    t = 0.0
    peak = 0.0
    f_prev = 0.0
    left = 0.0
    right = -1.0
    dm = 0.0
    for _ in range(100 * steps):
        d_new, v_new, f = _impact_rk4(b, k_p, mass, h, d, v)
        if f > peak:
            peak, left, right = f, f_prev, -1.0
        elif right < 0.0:
            right = f
        f_prev = f
        if d_new > dm:
            dm = d_new
        if d_new <= 0.0 or (f <= 0.0 and v_new < 0.0):
            # separation inside the step: interpolate the time linearly on D
            frac = d / (d - d_new) if d_new <= 0.0 and d > d_new else 1.0
            return _vertex(left, peak, right), dm, t + frac * h, -v_new / approach_speed
        d, v = d_new, v_new
        t += h
    return _vertex(left, peak, right), dm, t, -v / approach_speed


@njit(cache=True, _nrt=False)
def stiff_impact_peak_force(mass, approach_speed, b_p, k_p, steps):
    """The peak force of :func:`stiff_impact_peak` (the same RK4 steps, the same value),
    stopped at the first step past the deepest compression whose force is below the peak: with
    v = D' < 0 and N > 0, law (16) gives k D^2 > b |v| and so dN/dt = -b N D^2 / m + 2 b D v^2
    + 4 k D^3 v < -b N D^2 / m - 2 k D^3 |v| < 0, the force only falls from there (about half
    the steps of the whole impact; the observer needs one per impact)."""
    if approach_speed <= 0.0:
        return 0.0
    b = b_p * mass**0.4
    d_max = (5.0 * mass * approach_speed**2 / (2.0 * k_p)) ** 0.2
    h = 2.5074 * d_max / approach_speed / steps
    d, v = 0.0, approach_speed
    peak = 0.0
    f_prev = 0.0
    left = 0.0
    right = -1.0
    for _ in range(100 * steps):
        d_new, v_new, f = _impact_rk4(b, k_p, mass, h, d, v)
        if f > peak:
            peak, left, right = f, f_prev, -1.0
        elif right < 0.0:
            right = f
        f_prev = f
        if d_new <= 0.0 or (f <= 0.0 and v_new < 0.0) or (v_new < 0.0 and f < peak):
            return _vertex(left, peak, right)
        d, v = d_new, v_new
    return _vertex(left, peak, right)


# -- N_stiff by similarity ----------------------------------------------------------------------
# m D'' = -(b_p m^0.4 D' D^2 + k_p D^4), D(0) = 0, D'(0) = w, in the units L = (m w^2 / k_p)^0.2
# of length and L / w of time, is x'' = -(c x' x^2 + x^4), x(0) = 0, x'(0) = 1, with the one
# number c = b_p k_p^-0.6 w^0.2 (the mass drops out, as for the restitution): the peak force is
# k_p L^4 F(c) = k_p^0.2 m^0.8 w^1.6 F(c). F on 0 <= c <= N_STIFF_C_MAX is a Chebyshev series in
# u = c / (1 + c) (analytic in c; the coefficients from :func:`n_stiff_coefficients`, RK4 with
# N_STIFF_FIT_STEPS steps; test_contact_friction regenerates them), so an impact costs ~30
# multiplications instead of ~400 RK4 steps (35-50 us called alone; 2 % of a stiff event).
# Beyond N_STIFF_C_MAX (very heavy damping) the observers integrate as before.
N_STIFF_C_MAX = 8.0
N_STIFF_DEGREE = 32
N_STIFF_FIT_STEPS = 6400
_N_STIFF_U_MAX = N_STIFF_C_MAX / (1.0 + N_STIFF_C_MAX)
# fmt: off
_N_STIFF_CHEBYSHEV = np.array(
    [
        1.5554757593385624, -0.4205364602231864, 0.163410278640157,
        0.07628446294153268, 0.023038267648361973, 0.006262350184889399,
        0.0022496929134455863, 0.0012914207777662123, 0.0007969650324095932,
        0.0004140015127320261, 0.0001750995754789114, 6.453354856189959e-05,
        2.570144973444279e-05, 1.3686072416488254e-05, 8.307537813544449e-06,
        4.513426921648466e-06, 2.0171617082347932e-06, 7.668398337324058e-07,
        3.020033611266874e-07, 1.60863873957959e-07, 1.0208111377705045e-07,
        5.80980643067472e-08, 2.6490328924317702e-08, 9.783380065298214e-09,
        3.593093383324961e-09, 1.9423418399752963e-09, 1.3565004830114047e-09,
        8.322065183241046e-10, 3.9646992632164747e-10, 1.5478337513340296e-10,
        6.819654993000146e-11, 4.6600354504186704e-11, 2.909811474516753e-11,
    ]
)
# fmt: on


def n_stiff_coefficients(steps: int = N_STIFF_FIT_STEPS) -> np.ndarray:
    """The Chebyshev coefficients of F(u) (see above): the scaled impact (m = k_p = w = 1,
    b_p = c) solved by :func:`stiff_impact_peak_force` at the Chebyshev nodes of u."""
    n = N_STIFF_DEGREE + 1
    x = np.cos(np.pi * (np.arange(n) + 0.5) / n)
    u = 0.5 * (x + 1.0) * _N_STIFF_U_MAX
    values = [stiff_impact_peak_force(1.0, 1.0, ui / (1.0 - ui), 1.0, steps) for ui in u]
    return np.polynomial.chebyshev.chebfit(x, np.array(values), N_STIFF_DEGREE)


@njit(cache=True, _nrt=False)
def n_stiff(mass, approach_speed, b_p, k_p):
    """N_stiff of an impact at normal speed ``approach_speed`` (law (16) against a rigid wall):
    the similarity form above; :func:`stiff_impact_peak_force` with N_STIFF_STEPS outside its
    range (c > N_STIFF_C_MAX, k_p <= 0, a speed that is not finite)."""
    if approach_speed <= 0.0:
        return 0.0
    c = b_p * k_p**-0.6 * approach_speed**0.2 if k_p > 0.0 else math.inf
    if not (c >= 0.0 and c <= N_STIFF_C_MAX and approach_speed < math.inf):
        return stiff_impact_peak_force(mass, approach_speed, b_p, k_p, N_STIFF_STEPS)
    x = 2.0 * (c / (1.0 + c)) / _N_STIFF_U_MAX - 1.0
    # Clenshaw's recurrence
    b1 = 0.0
    b2 = 0.0
    for j in range(N_STIFF_DEGREE, 0, -1):
        b1, b2 = 2.0 * x * b1 - b2 + _N_STIFF_CHEBYSHEV[j], b1
    f = x * b1 - b2 + _N_STIFF_CHEBYSHEV[0]
    return k_p**0.2 * mass**0.8 * approach_speed**1.6 * f


@njit(cache=True, _nrt=False)
def _law(b, k, d, v):
    if d <= 0.0:
        return 0.0
    n = b * v * d * d + k * d**4
    return n if n > 0.0 else 0.0


# -- exact modal propagation --------------------------------------------------------------------
@njit(cache=True, _nrt=False)
def _mm4(a, b, out):
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for k in range(4):
                acc += a[i, k] * b[k, j]
            out[i, j] = acc


@njit(cache=True, _nrt=False)
def _expm4(a, result, term, tmp):
    """result = exp(a) of a 4x4 matrix: scaling and squaring with an 18-term Taylor series
    (allocation-free: this runs for every mode at every new step size)."""
    norm = 0.0
    for i in range(4):
        row = 0.0
        for j in range(4):
            row += abs(a[i, j])
        norm = max(norm, row)
    sq = 0
    while norm > 0.5:
        norm *= 0.5
        sq += 1
    scale = 0.5**sq
    for i in range(4):
        for j in range(4):
            v = 1.0 if i == j else 0.0
            term[i, j] = v
            result[i, j] = v
    for k in range(1, 19):
        _mm4(term, a, tmp)
        f = scale / k
        small = 0.0
        for i in range(4):
            for j in range(4):
                term[i, j] = tmp[i, j] * f
                result[i, j] += term[i, j]
                small = max(small, abs(term[i, j]))
        if small < 1e-18:
            break
    for _ in range(sq):
        _mm4(result, result, tmp)
        for i in range(4):
            for j in range(4):
                result[i, j] = tmp[i, j]


@njit(cache=True, _nrt=True)
def modal_propagators(omega, zeta, h, a_out, g0_out, g1_out):
    """Exact one-step maps of the damped modes eta'' + 2 zeta omega eta' + omega^2 eta = f(t)
    for f linear over the step (Van Loan's augmented matrix exponential):
    z1 = A z0 + g0 f0 + g1 f1 with z = (eta, eta')."""
    base = np.zeros((4, 4))
    e = np.empty((4, 4))
    term = np.empty((4, 4))
    tmp = np.empty((4, 4))
    for j in range(omega.shape[0]):
        base[0, 1] = h
        base[1, 0] = -(omega[j] ** 2) * h
        base[1, 1] = -2.0 * zeta[j] * omega[j] * h
        base[1, 2] = h
        base[2, 3] = h
        _expm4(base, e, term, tmp)
        for r in range(2):
            a_out[j, r, 0] = e[r, 0]
            a_out[j, r, 1] = e[r, 1]
            g0_out[j, r] = e[r, 2] - e[r, 3] / h
            g1_out[j, r] = e[r, 3] / h


@njit(cache=True, _nrt=False)
def milne_error(y0, acc0, y1, prev_v, prev_a, r, h, atol, rtol, v_ref, om_ref):
    """Scaled local error of a trapezoidal step y0 -> y1 on the load's state: Milne's device
    (see ``integrators._local_error``), corrector minus variable-step AB2 (r > 0) or Euler
    (r = 0) predictor, each component over atol + rtol * its block magnitude."""
    if r > 0.0:
        c1, c2 = 1.0 + 0.5 * r, 0.5 * r
        fac = r / (3.0 * (r + 1.0))
    else:
        c1, c2, fac = 1.0, 0.0, 1.0
    pos = atol + rtol * max(math.hypot(y1[0], y1[1]), 1.0)
    ang = atol + rtol * max(abs(y1[2]), 1.0)
    vel = atol + rtol * max(math.hypot(y1[3], y1[4]), v_ref)
    rot = atol + rtol * max(abs(y1[5]), om_ref)
    err = 0.0
    for k in range(3):
        sq = ang if k == 2 else pos
        sv = rot if k == 2 else vel
        qp = y0[k] + h * (c1 * y0[3 + k] - c2 * prev_v[k])
        vp = y0[3 + k] + h * (c1 * acc0[k] - c2 * prev_a[k])
        err = max(err, abs(y1[k] - qp) / sq, abs(y1[3 + k] - vp) / sv)
    return fac * err


EVENT_ONSET = 0  # event function D: a separated candidate starts to push
EVENT_RELEASE = 1  # the law (16) unclipped: the force falls to zero (or the clip engages)
EVENT_SLIDE_OFF = 2  # R_z - s: a pushing corner slides past the fence tip


@njit(cache=True, _nrt=False)
def event_value(P, out, slot, kind):
    """The event function of ``kind`` for ``slot`` at a point (nan where it is not defined)."""
    if kind == EVENT_SLIDE_OFF:
        s_arc = out[slot, C_S]
        return P[P_LENGTH] - s_arc if s_arc > 0.0 else math.nan
    if out[slot, C_GAP] == 0.0:
        return math.nan
    return out[slot, C_D] if kind == EVENT_ONSET else out[slot, C_NRAW]


@njit(cache=True, _nrt=False)
def first_event(P, out_a, out_b):
    """The fence slot whose event function changes sign first between two points, or -1.

    A slot without force at a can start one (onset; the function is D), a slot with force can
    lose it (release or the N >= 0 clamp engaging; the function is the law (16) unclipped), and
    a pushing corner can slide past the fence tip (the function is R_z - s); only functions
    defined at both points count. The first is estimated by linear interpolation.
    Returns (slot, kind, g_a, g_b).
    """
    best = -1
    best_fr = 2.0
    kind_best = EVENT_ONSET
    ga_best = gb_best = 0.0
    for k in range(SLOT_BORDER):
        active = out_a[k, C_ACTIVE] != 0.0
        kind = EVENT_RELEASE if active else EVENT_ONSET
        if active and k < SLOT_TIP and out_b[k, C_GAP] == 0.0:
            kind = EVENT_SLIDE_OFF
        ga = event_value(P, out_a, k, kind)
        gb = event_value(P, out_b, k, kind)
        if math.isnan(ga) or math.isnan(gb) or (ga > 0.0) == (gb > 0.0):
            continue
        fr = ga / (ga - gb)
        if fr < best_fr:
            best_fr = fr
            best = k
            kind_best = kind
            ga_best, gb_best = ga, gb
    return best, kind_best, ga_best, gb_best


@njit(cache=True, _nrt=False)
def time_to_contact(out):
    """Shortest time until a separated fence candidate closes its gap at its present closing
    speed, min over slots of -D / Ddot (D < 0, Ddot > 0); inf if none approaches. An adaptive
    step no longer than this cannot jump over a contact shorter than one step (grazing), since
    the onset then shows as a sign change of D within the step."""
    best = math.inf
    for k in range(SLOT_BORDER):
        if out[k, C_GAP] == 0.0 or out[k, C_ACTIVE] != 0.0:
            continue
        d = out[k, C_D]
        rate = out[k, C_DDOT]
        if d < 0.0 and rate > 0.0:
            ttc = -d / rate
            if ttc < best:
                best = ttc
    return best


OSC_ZETA = 0.02  # a contact damped less than this has its oscillation resolved by the step
OSC_PHASE = 10.0  # ... to omega h <= OSC_PHASE sqrt(rtol)


@njit(cache=True, _nrt=False)
def oscillation_step(P, out, rtol):
    """Longest adaptive step for a lightly damped contact oscillation, min over active slots.

    Law (16) linearised at (D, D'): stiffness 4 k_p D^3 + 2 b D D', damping b D^2 (b = b_p
    m^0.4), on the load's mass: omega and the damping ratio zeta. The trapezoidal rule neither
    damps an oscillation nor keeps its phase (lag (omega h)^2 / 12 per radian) and Milne's
    estimate on the load's position (scaled by 1 m) does not see a rattle of mm amplitude, so a
    contact with zeta < OSC_ZETA (k_p x1000 on a stiff fence: zeta ~ 0.003, rattling at 26 Hz
    for the whole push) gets omega h <= OSC_PHASE sqrt(rtol). At the paper's k_p a pushing
    contact has zeta 0.1-0.4; below OSC_ZETA only at the first touch (N < 0.1-50 N), where
    omega h < 0.04 stays far inside the cap: the bench scenes never meet it. inf if no slot
    qualifies."""
    best = math.inf
    mass = P[P_MASS]
    k = P[P_KP]
    b = P[P_BEFF]
    for s in range(N_SLOTS):
        if out[s, C_ACTIVE] == 0.0:
            continue
        d = out[s, C_D]
        if not d > 0.0:
            continue
        stiff = 4.0 * k * d**3 + 2.0 * b * d * out[s, C_DDOT]
        if not stiff > 0.0:
            continue
        if b * d * d < 2.0 * OSC_ZETA * math.sqrt(stiff * mass):
            h = OSC_PHASE * math.sqrt(rtol) / math.sqrt(stiff / mass)
            if h < best:
                best = h
    return best


# -- the compiled solve loop --------------------------------------------------------------------
# ``integrators.Integrator.stepping`` (adaptive and fixed-step trapezoidal) and the reductions of
# ``result.Observer`` as one compiled loop over flat arrays; ``engine.py`` builds the arrays,
# calls :func:`solve` in chunks (wall-time limit, growing the output buffers) and turns the
# figures into a ``SimulationResult``. It lives in this module so that Numba's on-disk cache of
# the loop is invalidated with the kernels it inlines (the cache only tracks the defining file).
# It is the same algorithm step for step: test/physics/test_engine.py checks both loops agree.

EVENT_TOL = 1e-10  # a located onset's step ends with 0 < D <= EVENT_TOL [m]
EVENT_SORT = 3  # C_s crossing the sorting line y0 = s (belt friction ends there)

# states: rows of T, Y, LAM, OUT, RES, MODAL, ACC; cur and trial swap, loc and before are fixed
S_LOC = 2
S_BEFORE = 3
N_STATES = 4

# configuration ``cfg``
G_H_NOM = 0  # dt_max (adaptive) or dt (fixed step) [s]
G_T_END = 1
G_DT = 2  # first adaptive step [s]
G_MIN_DT = 3
G_TOL = 4  # contact iteration tolerance
G_MAX_ITER = 5
G_ATOL = 6
G_RTOL = 7
G_V_REF = 8
G_OM_REF = 9
G_WIDTH = 10  # s [m]
G_ADAPTIVE = 11
G_STOP_SORTED = 12
G_RECORD = 13
G_BP = 14  # b_p, k_p of the stiff reference (stiff_impact_peak)
G_KP = 15
G_DEEP = 16
G_SPEED_LIMIT = 17
G_VMIN = 18
G_PHIDOT_MIN = 19
G_UP = 20  # 2^(1/4)
G_DOWN = 21  # 2^(-1/4)
G_FLUSH = 22  # contacts.FLUSH_ANGLE [rad]
N_CFG = 23

# integer control ``ctl``
I_CUR = 0
I_TRIAL = 1
I_STARTED = 2
I_DONE = 3
I_DIAG = 4  # DIAG_*
I_STEPS = 5
I_REJECTED = 6
I_FORCED = 7
I_EVENTS = 8
I_NEXT_BREAK = 9
I_CLEAN = 10
I_ON_BELT = 11
I_STOP = 12
I_SORTED = 13  # observer
I_TOUCHED = 14
I_HAD_FENCE = 15
I_FIRST = 16
I_MASK = 17
I_STAGE = 18
I_LAST_MASK0 = 19
I_LAST_MASK1 = 20
I_N_IMPACTS = 21
I_N_STAGES = 22
I_N_REC = 23
I_N_PROPS = 24  # entries of the propagator cache in use
I_N_TRACE = 25  # rows of the trace in use
N_CTL = 26

# float control ``fc``
F_H = 0
F_H_CAP = 1
F_H_PREV = 2
F_PREV_V = 3  # 3 values
F_PREV_A = 6  # 3 values
F_EXIT_SPEED = 9  # observer
F_IMPACT_SPEED = 10
F_PEAK_N = 11
F_PEAK_TIP = 12
F_MAX_DEPTH = 13
F_Y_MAX = 14
F_PREV_T = 15
F_PREV_Y = 16  # 6 values
F_PREV_POWER = 22
F_WORK = 23
F_LAST_N1 = 24
F_LAST_N2 = 25
F_LAST_T1 = 26
F_LAST_T2 = 27
F_MAX_RES = 28  # energy audit (result.EnergyAudit)
F_MIN_RES = 29
F_FLOW = 30
F_E0 = 31
F_T_MAX = 32
F_T_MIN = 33
F_MAX_RISE = 34
F_T_RISE0 = 35
F_T_RISE1 = 36
F_RUN_MIN = 37
F_T_RUN_MIN = 38
F_DIAG_T = 39  # where a diagnosis was made, and its value (D or speed)
F_DIAG_V = 40
N_FC = 41

# diagnoses and stop reasons
DIAG_NONE = 0
DIAG_NONFINITE = 1
DIAG_DEEP = 2
DIAG_SPEED = 3
DIAG_MIN_DT = 4
SOLVE_DONE = 0
SOLVE_PAUSED = 1  # attempt budget used up (the caller checks the wall-time limit)
SOLVE_GROW = 2  # an output buffer is full
SOLVE_REACHED = 3  # the accepted time reached t_target
SOLVE_TRACED = 4  # the trace is full (the caller replays and empties it)

# stages (contacts.STAGE_*, in this order) and the recorded row
STAGE_CODE_ON_BELT = 0
STAGE_CODE_E1 = 1
STAGE_CODE_E2 = 2
STAGE_CODE_E3 = 3
STAGE_CODE_E4 = 4
STAGE_CODE_SORTED = 5
REC_T = 0
REC_Y = 1  # x, y, phi, vx, vy, phidot
REC_ALPHA = 7
REC_TIP_W = 8
REC_FENCE_N = 9
REC_MAX_D = 10
REC_STAGE = 11
# the time again, once per series group that has its own time array (fence, forces, stages), so
# each recorded array is a row of REC of its own
REC_T_FENCE = 12
REC_T_FORCES = 13
REC_T_STAGE = 14
N_REC_COLS = 15
N_PROP_CACHE = 256
# a trace row: an accepted point as the Python observer sees it (``integrators.State``) and the
# on_belt flag it was observed with: [t, on_belt, y, lam, out (row-major), res, modal, acc]
TR_T = 0
TR_ON_BELT = 1
TR_Y = 2


def trace_width(n_state, m):
    """Columns of a trace row for a model with n_state states and m modes."""
    return 2 + n_state + 3 + N_SLOTS * N_COLS + N_RES + m + 3 + m


@njit(cache=True, _nrt=False)
def _remainder(x, y):
    """IEEE remainder of x by y > 0 (CPython's ``math.remainder``, exact like it)."""
    absx = abs(x)
    m = np.fmod(absx, y)
    c = y - m
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:
        r = m - 2.0 * np.fmod(0.5 * (absx - m), y)
    return math.copysign(1.0, x) * r


@njit(cache=True, _nrt=False)
def classify_code(out, normals, phi, touched, flush):
    """``contacts.classify`` on the stage codes STAGE_CODE_*."""
    n_corners = 0
    first = -1
    for k in range(4):
        if out[k, C_ACTIVE] != 0.0:
            n_corners += 1
            if first < 0:
                first = k
    tip = False
    for k in range(SLOT_TIP, SLOT_BORDER):
        if out[k, C_ACTIVE] != 0.0:
            tip = True
    border = False
    for k in range(SLOT_BORDER, N_SLOTS):
        if out[k, C_ACTIVE] != 0.0:
            border = True
    if n_corners == 0 and not tip:
        return STAGE_CODE_E4 if touched else STAGE_CODE_ON_BELT
    if border:
        return STAGE_CODE_E3
    if tip:
        return STAGE_CODE_E2
    for k in range(4):
        if out[k, C_ACTIVE] != 0.0 and out[(k + 1) % 4, C_ACTIVE] != 0.0:
            return STAGE_CODE_E2
    tangent_angle = math.atan2(out[first, C_NX], -out[first, C_NY])
    for face in (first, (first - 1) % 4):
        face_angle = phi + math.atan2(normals[face, 0], -normals[face, 1])
        if abs(_remainder(face_angle - tangent_angle, math.pi)) < flush:
            return STAGE_CODE_E2
    return STAGE_CODE_E1


@njit(cache=True, _nrt=False)
def parabola_peak(t0, n0, t1, n1, t2, n2):
    """Vertex value of the parabola through three points with n1 >= n0, n2 (else n1)."""
    d0, d2 = t0 - t1, t2 - t1
    if d0 >= 0.0 or d2 <= 0.0:
        return n1
    c = ((n0 - n1) / d0 - (n2 - n1) / d2) / (d0 - d2)
    b = (n0 - n1) / d0 - c * d0
    if c >= 0.0:
        return n1
    d = -b / (2.0 * c)
    if not d0 <= d <= d2:
        return n1
    return n1 + b * d + c * d * d


@njit(cache=True, _nrt=False)
def _copy_row(A, dst, src):
    for k in range(A.shape[1]):
        A[dst, k] = A[src, k]


@njit(cache=True, _nrt=False)
def _copy_state(T, Y, LAM, OUT, RES, MODAL, ACC, dst, src):
    T[dst] = T[src]
    _copy_row(Y, dst, src)
    _copy_row(LAM, dst, src)
    for r in range(N_SLOTS):
        for c in range(N_COLS):
            OUT[dst, r, c] = OUT[src, r, c]
    _copy_row(RES, dst, src)
    _copy_row(MODAL, dst, src)
    _copy_row(ACC, dst, src)


@njit(cache=True, _nrt=False)
def _propagator_slot(omega, zeta, h, ctl, PK, PA, PG0, PG1):
    """Row of the exact modal maps for step h in the cache (computed on a miss; the cache is
    emptied when full, like ``integrators.Propagators``)."""
    if omega.shape[0] == 0:
        return 0
    n = ctl[I_N_PROPS]
    for i in range(n):
        if PK[i] == h:
            return i
    if n >= PK.shape[0]:
        n = 0
    modal_propagators(omega, zeta, h, PA[n], PG0[n], PG1[n])
    PK[n] = h
    ctl[I_N_PROPS] = n + 1
    return n


@njit(cache=True, _nrt=False)
def _jump_at(P, t):
    if abs(t - 2.0 * P[P_T1]) <= 1e-12:
        return -0.5 * P[P_ALPHA_K] * (math.pi / P[P_T1]) ** 2
    return 0.0


@njit(cache=True, _nrt=False)
def _snap(h_nom, h):
    """``Integrator._snap``: round a step down onto the ladder dt_max 2^(-k/4)."""
    if h == h_nom:  # k = 0 (most steps: no log2 and pow calls)
        return h_nom
    k = math.ceil(4.0 * math.log2(h_nom / h) - 1e-9)
    return h_nom * 2.0 ** (-k / 4.0)


@njit(cache=True, _nrt=False)
def _trap(
    P, corners, normals, phi, rigid_modal, omega, zeta, cfg, ctl, T, Y, LAM, OUT, RES, MODAL, ACC,
    w, wdot, nodes, prev, work, PK, PA, PG0, PG1, h, a, b, jump, on_belt, force,
):  # fmt: skip
    """``Scheme.step`` of the trapezoidal scheme from state row a into row b."""
    k = _propagator_slot(omega, zeta, h, ctl, PK, PA, PG0, PG1)
    status = trapezoidal_step(
        P, corners, normals, phi, rigid_modal, (PA[k], PG0[k], PG1[k]), h, T[a], Y[a], RES[a],
        LAM[a], MODAL[a], OUT[a], jump, on_belt, cfg[G_TOL], int(cfg[G_MAX_ITER]), force, Y[b],
        LAM[b], OUT[b], RES[b], MODAL[b], w, wdot, nodes, prev, work,
    )  # fmt: skip
    if status != STEP_REJECTED:
        ACC[b, 0] = (RES[b, 0] + LAM[b, 0]) / P[P_MASS]
        ACC[b, 1] = (RES[b, 1] + LAM[b, 1]) / P[P_MASS]
        ACC[b, 2] = (RES[b, 2] + LAM[b, 2]) / P[P_INERTIA]
    T[b] = T[a] + h
    return status


@njit(cache=True, _nrt=False)
def _locate(
    P, corners, normals, phi, rigid_modal, omega, zeta, cfg, ctl, T, Y, LAM, OUT, RES, MODAL, ACC,
    w, wdot, nodes, prev, work, PK, PA, PG0, PG1, h, on_belt, slot, kind, g0, g1,
):  # fmt: skip
    """``Integrator._locate``: Illinois regula falsi onto the event; the located trial is left
    in the trial row; returns the step taken."""
    a = ctl[I_CUR]
    trial = ctl[I_TRIAL]
    onset = kind == EVENT_ONSET
    sign0 = g0 > 0.0
    lo = 0.0
    hi, g_hi = h, g1
    jump = _jump_at(P, T[a])
    best = 0.0
    have_best = False
    tol = cfg[G_TOL]
    keep_before = kind == EVENT_SLIDE_OFF and g0 > tol
    cross = kind == EVENT_SLIDE_OFF and not keep_before
    sort = kind == EVENT_SORT
    g_lo = g0
    before = 0.0
    have_before = False
    f_lo, f_hi, last = g0, g1, 0
    lo_prev, g_lo_prev = 0.0, g0  # the lo end before the last (Integrator._locate)
    for _ in range(60):
        if hi - lo <= 1e-7 * h or (onset and g_hi <= EVENT_TOL):
            break
        if (have_before and g_lo <= tol) or ((cross or sort) and have_best and -g_hi <= tol):
            break
        h_loc = lo + (hi - lo) * (f_lo / (f_lo - f_hi))
        if cross and last == 0:
            h_loc = min(2.0 * h_loc, hi)  # the tip is within tol: step just past it
        else:
            h_loc = min(max(h_loc, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
        if keep_before and last == -1 and g_lo_prev > g_lo:
            h_sec = lo + (g_lo - 0.5 * tol) * (lo - lo_prev) / (g_lo_prev - g_lo)
            if lo < h_sec < hi:
                h_loc = h_sec
        st = _trap(
            P, corners, normals, phi, rigid_modal, omega, zeta, cfg, ctl, T, Y, LAM, OUT, RES,
            MODAL, ACC, w, wdot, nodes, prev, work, PK, PA, PG0, PG1, h_loc, a, S_LOC, jump,
            on_belt, False,
        )  # fmt: skip
        if st == STEP_REJECTED:
            break
        if kind == EVENT_SORT:
            g = cfg[G_WIDTH] - Y[S_LOC, 1]
        else:
            g = event_value(P, OUT[S_LOC], slot, kind)
        if math.isnan(g):
            break
        if (g > 0.0) != sign0:
            hi, g_hi, f_hi = h_loc, g, g
            if last == 1:
                f_lo *= 0.5
            last = 1
            best = h_loc
            have_best = True
            _copy_state(T, Y, LAM, OUT, RES, MODAL, ACC, trial, S_LOC)
        else:
            lo_prev, g_lo_prev = lo, g_lo
            lo, g_lo, f_lo = h_loc, g, g
            if last == -1:
                f_hi *= 0.5
            last = -1
            if keep_before:
                before = h_loc
                have_before = True
                _copy_state(T, Y, LAM, OUT, RES, MODAL, ACC, S_BEFORE, S_LOC)
    ctl[I_EVENTS] += 1
    if have_before:
        _copy_state(T, Y, LAM, OUT, RES, MODAL, ACC, trial, S_BEFORE)
        return before
    return best if have_best else h


@njit(cache=True, _nrt=False)
def _audit(fc, t, r):
    """``result.EnergyAudit.update``."""
    if not math.isfinite(r):
        fc[F_MAX_RES] = r
        fc[F_MIN_RES] = r
        return
    if not math.isfinite(fc[F_MAX_RES]):
        return
    if r > fc[F_MAX_RES]:
        fc[F_MAX_RES] = r
        fc[F_T_MAX] = t
    if r < fc[F_MIN_RES]:
        fc[F_MIN_RES] = r
        fc[F_T_MIN] = t
    if r < fc[F_RUN_MIN]:
        fc[F_RUN_MIN] = r
        fc[F_T_RUN_MIN] = t
    if r - fc[F_RUN_MIN] > fc[F_MAX_RISE]:
        fc[F_MAX_RISE] = r - fc[F_RUN_MIN]
        fc[F_T_RISE0] = fc[F_T_RUN_MIN]
        fc[F_T_RISE1] = t


@njit(cache=True, _nrt=False)
def _observe(P, normals, cfg, ctl, fc, T, Y, LAM, OUT, RES, IMP, STG, REC, i, on_belt):
    """``result.Observer.__call__`` at state row i; returns (stop, on_belt)."""
    t = T[i]
    y = Y[i]
    res = RES[i]
    out = OUT[i]
    mass = P[P_MASS]
    vx, vy, om = y[3], y[4], y[5]
    energy = 0.5 * mass * (vx * vx + vy * vy) + 0.5 * P[P_INERTIA] * om * om
    energy += res[R_ENERGY_CONTACT]
    power = res[R_POWER_FENCE] + P[P_EXT_X] * vx + P[P_EXT_Y] * vy + P[P_EXT_M] * om
    if on_belt:
        power += LAM[i, 0] * P[P_BELT]
    width = cfg[G_WIDTH]
    if ctl[I_FIRST] != 0:
        ctl[I_FIRST] = 0
        fc[F_E0] = energy
        fc[F_FLOW] = abs(energy)
        fc[F_Y_MAX] = y[1]
    else:
        h = t - fc[F_PREV_T]
        fc[F_WORK] += 0.5 * h * (power + fc[F_PREV_POWER])
        fc[F_FLOW] += 0.5 * h * (abs(power) + abs(fc[F_PREV_POWER]))
        _audit(fc, t, energy - fc[F_E0] - fc[F_WORK])
        py1 = fc[F_PREV_Y + 1]
        if y[1] >= width > py1 and ctl[I_SORTED] == 0:
            frac = (width - py1) / (y[1] - py1)
            fc[F_EXIT_SPEED] = fc[F_PREV_Y + 4] + frac * (vy - fc[F_PREV_Y + 4])
            ctl[I_SORTED] = 1
    mask = int(res[R_ACTIVE_MASK])
    fence_on = (mask & 0xFF) != 0
    if fence_on and ctl[I_HAD_FENCE] == 0:
        ctl[I_TOUCHED] = 1
        w_n = -math.inf
        for k in range(SLOT_BORDER):
            if out[k, C_ACTIVE] != 0.0:
                v = out[k, C_DDOT]
                if math.isnan(v) or math.isnan(w_n):
                    w_n = math.nan
                elif v > w_n:
                    w_n = v
        if math.isnan(fc[F_IMPACT_SPEED]):
            fc[F_IMPACT_SPEED] = w_n
        peak = n_stiff(mass, w_n, cfg[G_BP], cfg[G_KP])
        n_imp = ctl[I_N_IMPACTS]
        IMP[n_imp, 0] = t
        IMP[n_imp, 1] = w_n
        IMP[n_imp, 2] = peak
        ctl[I_N_IMPACTS] = n_imp + 1
    ctl[I_HAD_FENCE] = 1 if fence_on else 0
    n = res[R_FENCE_N]
    if n > fc[F_PEAK_N]:
        fc[F_PEAK_N] = n
    n1, n2 = fc[F_LAST_N1], fc[F_LAST_N2]
    smooth = ctl[I_LAST_MASK0] == ctl[I_LAST_MASK1] and ctl[I_LAST_MASK1] == mask
    ctl[I_LAST_MASK0] = ctl[I_LAST_MASK1]
    ctl[I_LAST_MASK1] = mask
    if smooth and n2 > n1 and n2 >= n and n1 > 0.0:
        peak = parabola_peak(fc[F_LAST_T1], n1, fc[F_LAST_T2], n2, t, n)
        if peak > fc[F_PEAK_N]:
            fc[F_PEAK_N] = peak
    fc[F_LAST_N1], fc[F_LAST_N2] = n2, n
    fc[F_LAST_T1], fc[F_LAST_T2] = fc[F_LAST_T2], t
    tip = abs(res[R_TIP_W])
    if tip > fc[F_PEAK_TIP]:
        fc[F_PEAK_TIP] = tip
    if res[R_MAX_D] > fc[F_MAX_DEPTH]:
        fc[F_MAX_DEPTH] = res[R_MAX_D]
    if y[1] > fc[F_Y_MAX]:
        fc[F_Y_MAX] = y[1]
    sorted_ = ctl[I_SORTED] != 0
    if mask != ctl[I_MASK] or (sorted_ and ctl[I_STAGE] != STAGE_CODE_SORTED):
        ctl[I_MASK] = mask
        if sorted_:
            stage = STAGE_CODE_SORTED
        else:
            stage = classify_code(out, normals, y[2], ctl[I_TOUCHED] != 0, cfg[G_FLUSH])
        if stage != ctl[I_STAGE]:
            ctl[I_STAGE] = stage
            n_stg = ctl[I_N_STAGES]
            STG[n_stg, 0] = t
            STG[n_stg, 1] = stage
            ctl[I_N_STAGES] = n_stg + 1
    if cfg[G_RECORD] != 0.0:
        n_rec = ctl[I_N_REC]
        REC[REC_T, n_rec] = t
        REC[REC_T_FENCE, n_rec] = t
        REC[REC_T_FORCES, n_rec] = t
        REC[REC_T_STAGE, n_rec] = t
        for k in range(6):
            REC[REC_Y + k, n_rec] = y[k]
        REC[REC_ALPHA, n_rec] = res[R_ALPHA]
        REC[REC_TIP_W, n_rec] = res[R_TIP_W]
        REC[REC_FENCE_N, n_rec] = res[R_FENCE_N]
        REC[REC_MAX_D, n_rec] = res[R_MAX_D]
        REC[REC_STAGE, n_rec] = ctl[I_STAGE]
        ctl[I_N_REC] = n_rec + 1
    fc[F_PREV_T] = t
    for k in range(6):
        fc[F_PREV_Y + k] = y[k]
    fc[F_PREV_POWER] = power
    return sorted_ and cfg[G_STOP_SORTED] != 0.0, on_belt and not sorted_


@njit(cache=True, _nrt=False)
def _trace(ctl, TR, T, Y, LAM, OUT, RES, MODAL, ACC, i, on_belt):
    """Append state row i and the on_belt flag it is observed with to the trace (if kept)."""
    if TR.shape[0] == 0:
        return
    row = TR[ctl[I_N_TRACE]]
    ctl[I_N_TRACE] += 1
    row[TR_T] = T[i]
    row[TR_ON_BELT] = 1.0 if on_belt else 0.0
    k = TR_Y
    for v in Y[i]:
        row[k] = v
        k += 1
    for v in LAM[i]:
        row[k] = v
        k += 1
    for r in range(N_SLOTS):
        for c in range(N_COLS):
            row[k] = OUT[i, r, c]
            k += 1
    for v in RES[i]:
        row[k] = v
        k += 1
    for v in MODAL[i]:
        row[k] = v
        k += 1
    for v in ACC[i]:
        row[k] = v
        k += 1


@njit(cache=True, _nrt=False)
def _diverged(P, cfg, fc, t, y, res):
    """``Integrator._diverged``: a DIAG_* code (value and time left in fc)."""
    total = 0.0
    for k in range(y.shape[0]):
        total += y[k]
    fc[F_DIAG_T] = t
    if not math.isfinite(total):
        return DIAG_NONFINITE
    if res[R_MAX_D] > cfg[G_DEEP]:
        fc[F_DIAG_V] = res[R_MAX_D]
        return DIAG_DEEP
    speed = math.hypot(y[3], y[4])
    if speed > cfg[G_SPEED_LIMIT]:
        fc[F_DIAG_V] = speed
        return DIAG_SPEED
    return DIAG_NONE


@njit(cache=True, _nrt=False)
def solve(
    P, corners, normals, phi, rigid_modal, omega, zeta, cfg, breaks, ctl, fc, T, Y, LAM, OUT, RES,
    MODAL, ACC, w, wdot, nodes, prev, work, PK, PA, PG0, PG1, IMP, STG, REC, TR, max_attempts,
    t_target,
):  # fmt: skip
    """Run the solve loop (``Integrator.stepping`` with ``Observer``) from where ``ctl``/``fc``
    left it: until it ends (SOLVE_DONE, the diagnosis in ctl[I_DIAG]), ``max_attempts`` step
    attempts (SOLVE_PAUSED), an output buffer (IMP, STG rows; REC columns, one row per
    recorded quantity REC_*) without a free entry (SOLVE_GROW),
    the accepted time reaching ``t_target`` (SOLVE_REACHED) or a full trace (SOLVE_TRACED: ``TR``
    with rows keeps every observed point for a Python observer, ``integrators.Integrator``; no
    rows, no trace). Row 0 of Y holds the initial state on the first call, which zeroes the
    other state rows and the scratch arrays."""
    adaptive = cfg[G_ADAPTIVE] != 0.0
    h_nom = cfg[G_H_NOM]
    min_dt = cfg[G_MIN_DT]
    width = cfg[G_WIDTH]
    m = omega.shape[0]
    if ctl[I_STARTED] == 0:
        # Scheme.initialize: forces at t = 0, belt wrench by Karnopp, accelerations
        ctl[I_STARTED] = 1
        a = ctl[I_CUR]
        # the state rows other than the initial state, and the scratch arrays, start at zero
        # (the caller may pass arrays of an earlier solve: engine reuses them)
        T[:] = 0.0
        for i in range(Y.shape[0]):
            if i != a:
                Y[i, :] = 0.0
        LAM[:, :] = 0.0
        OUT[:, :, :] = 0.0
        RES[:, :] = 0.0
        MODAL[:, :] = 0.0
        ACC[:, :] = 0.0
        w[:] = 0.0
        wdot[:] = 0.0
        nodes[:, :] = 0.0
        work[:, :] = 0.0
        for k in range(N_SLOTS):
            prev[k] = math.nan
        evaluate(
            P, corners, normals, phi, rigid_modal, T[a], 0.0, Y[a], LAM[a], 0.0, prev, OUT[a],
            RES[a], MODAL[a], w, wdot, nodes,
        )  # fmt: skip
        y, r = Y[a], RES[a]
        bx, by, bz = karnopp_belt(P, y[3] - P[P_BELT], y[4], y[5], r[0], r[1], r[2])
        LAM[a, 0], LAM[a, 1], LAM[a, 2] = bx, by, bz
        if math.hypot(y[3] - P[P_BELT], y[4]) <= cfg[G_VMIN] and abs(y[5]) <= cfg[G_PHIDOT_MIN]:
            bx, by, bz = stick_wrench(P, r[0], r[1], r[2])
            LAM[a, 0], LAM[a, 1], LAM[a, 2] = bx, by, bz
        ACC[a, 0] = (r[0] + LAM[a, 0]) / P[P_MASS]
        ACC[a, 1] = (r[1] + LAM[a, 1]) / P[P_MASS]
        ACC[a, 2] = (r[2] + LAM[a, 2]) / P[P_INERTIA]
        for j in range(m):
            ACC[a, 3 + j] = (
                MODAL[a, j] - omega[j] ** 2 * y[6 + j] - 2.0 * zeta[j] * omega[j] * y[6 + m + j]
            )
        _trace(ctl, TR, T, Y, LAM, OUT, RES, MODAL, ACC, a, True)
        stop, on_belt = _observe(
            P, normals, cfg, ctl, fc, T, Y, LAM, OUT, RES, IMP, STG, REC, a, True
        )
        ctl[I_STOP] = 1 if stop else 0
        ctl[I_ON_BELT] = 1 if on_belt else 0
        fc[F_H] = h_nom if not adaptive else min(h_nom, cfg[G_DT])
        fc[F_H_CAP] = h_nom
        fc[F_H_PREV] = 0.0
    attempts = 0
    while True:
        a = ctl[I_CUR]
        b = ctl[I_TRIAL]
        if ctl[I_STOP] != 0 or not T[a] < cfg[G_T_END] - 1e-12:
            ctl[I_DONE] = 1
            return SOLVE_DONE
        if T[a] >= t_target - 1e-12:
            return SOLVE_REACHED
        if attempts >= max_attempts:
            return SOLVE_PAUSED
        if (
            ctl[I_N_IMPACTS] >= IMP.shape[0]
            or ctl[I_N_STAGES] >= STG.shape[0]
            or ctl[I_N_REC] >= REC.shape[1]
        ):
            return SOLVE_GROW
        if TR.shape[0] > 0 and ctl[I_N_TRACE] >= TR.shape[0]:
            return SOLVE_TRACED
        attempts += 1
        on_belt = ctl[I_ON_BELT] != 0
        nb = ctl[I_NEXT_BREAK]
        while breaks[nb] <= T[a] + 1e-12:
            nb += 1
        ctl[I_NEXT_BREAK] = nb
        to_break = breaks[nb] - T[a]
        h_try = min(fc[F_H], to_break)
        if adaptive:
            cap = min(time_to_contact(OUT[a]), oscillation_step(P, OUT[a], cfg[G_RTOL]))
            h_try = min(h_try, max(cap, 10.0 * min_dt))
            tiny = h_try <= 4.0 * min_dt
        else:
            tiny = h_try <= 1e-3 * h_nom
        status = _trap(
            P, corners, normals, phi, rigid_modal, omega, zeta, cfg, ctl, T, Y, LAM, OUT, RES,
            MODAL, ACC, w, wdot, nodes, prev, work, PK, PA, PG0, PG1, h_try, a, b,
            _jump_at(P, T[a]), on_belt, tiny,
        )  # fmt: skip
        if status == STEP_REJECTED:
            ctl[I_REJECTED] += 1
            fc[F_H] = h_try / 2.0
            fc[F_H_CAP] = h_try * cfg[G_DOWN]
            ctl[I_CLEAN] = 0
            if fc[F_H] < min_dt:
                ctl[I_DIAG] = DIAG_MIN_DT
                fc[F_DIAG_T] = T[a]
                ctl[I_DONE] = 1
                return SOLVE_DONE
            continue
        if status == STEP_FORCED:
            ctl[I_FORCED] += 1
        h_taken = h_try
        slot, kind, g0, g1 = first_event(P, OUT[a], OUT[b])
        if slot < 0 and on_belt and Y[a, 1] < width <= Y[b, 1]:
            slot, kind, g0, g1 = -1, EVENT_SORT, width - Y[a, 1], width - Y[b, 1]
        located = False
        if (slot >= 0 or kind == EVENT_SORT) and h_try > 1e-9:
            h_taken = _locate(
                P, corners, normals, phi, rigid_modal, omega, zeta, cfg, ctl, T, Y, LAM, OUT,
                RES, MODAL, ACC, w, wdot, nodes, prev, work, PK, PA, PG0, PG1, h_try, on_belt,
                slot, kind, g0, g1,
            )  # fmt: skip
            located = True
        if adaptive:
            h_prev = fc[F_H_PREV]
            r = h_taken / h_prev if h_prev > 0.0 else 0.0
            err = milne_error(
                Y[a], ACC[a], Y[b], fc[F_PREV_V : F_PREV_V + 3], fc[F_PREV_A : F_PREV_A + 3], r,
                h_taken, cfg[G_ATOL], cfg[G_RTOL], cfg[G_V_REF], cfg[G_OM_REF],
            )  # fmt: skip
            order = 3.0 if r > 0.0 else 2.0
            if err > 1.0 and h_taken > 4.0 * min_dt:
                ctl[I_REJECTED] += 1
                fc[F_H] = _snap(h_nom, h_taken * max(0.2, 0.9 * err ** (-1.0 / order)))
                continue
            if not located:
                ctl[I_CLEAN] += 1
                if ctl[I_CLEAN] >= 4 and fc[F_H_CAP] < h_nom:
                    fc[F_H_CAP] = fc[F_H_CAP] * cfg[G_UP]
                    ctl[I_CLEAN] = 0
                cap = min(h_nom, fc[F_H_CAP])
                # h_taken grow >= cap when err <= (0.9 h_taken / cap)^order (and cap <= 4
                # h_taken); with a 1 % margin for pow's rounding that decides without the pow
                # call (most steps: at the cap with a small error); the same step otherwise
                ratio = 0.9 * h_taken / cap
                bound = ratio * ratio * ratio if order == 3.0 else ratio * ratio
                if cap <= 4.0 * h_taken and err <= 0.99 * bound:
                    h_next = cap
                else:
                    grow = min(4.0, 0.9 * max(err, 1e-12) ** (-1.0 / order))
                    h_next = min(cap, h_taken * grow)
                fc[F_H] = _snap(h_nom, h_next)
        else:
            fc[F_H] = min(h_nom, 2.0 * h_try)
        # accept
        for k in range(3):
            fc[F_PREV_V + k] = Y[a, 3 + k]
            fc[F_PREV_A + k] = ACC[a, k]
        fc[F_H_PREV] = h_taken
        if located or abs(T[a] + h_taken - breaks[nb]) <= 1e-12:
            fc[F_H_PREV] = 0.0
        ctl[I_CUR] = b
        ctl[I_TRIAL] = a
        a = b
        ctl[I_STEPS] += 1
        _trace(ctl, TR, T, Y, LAM, OUT, RES, MODAL, ACC, a, on_belt)
        stop, on_belt = _observe(
            P, normals, cfg, ctl, fc, T, Y, LAM, OUT, RES, IMP, STG, REC, a, on_belt
        )
        ctl[I_STOP] = 1 if stop else 0
        ctl[I_ON_BELT] = 1 if on_belt else 0
        diag = _diverged(P, cfg, fc, T[a], Y[a], RES[a])
        if diag != DIAG_NONE:
            ctl[I_DIAG] = diag
            ctl[I_DONE] = 1
            return SOLVE_DONE
