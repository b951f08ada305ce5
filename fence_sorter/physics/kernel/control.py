"""Step control of the solve loop: exact modal propagators, Milne's error estimate, event
functions, the contact-oscillation cap."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .layout import (
    N_SLOTS,
    SLOT_BORDER,
    SLOT_TIP,
)


# -- exact modal propagation --------------------------------------------------------------------
@njit(cache=True, _nrt=False)
def _mm(a, b, out):
    n = a.shape[0]
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for k in range(n):
                acc += a[i, k] * b[k, j]
            out[i, j] = acc


@njit(cache=True, _nrt=False)
def _expm(a, result, term, tmp):
    """result = exp(a) of a small square matrix: scaling and squaring with an 18-term Taylor
    series (allocation-free: this runs for every mode at every new step size)."""
    n = a.shape[0]
    norm = 0.0
    for i in range(n):
        row = 0.0
        for j in range(n):
            row += abs(a[i, j])
        norm = max(norm, row)
    sq = 0
    while norm > 0.5:
        norm *= 0.5
        sq += 1
    scale = 0.5**sq
    for i in range(n):
        for j in range(n):
            v = 1.0 if i == j else 0.0
            term[i, j] = v
            result[i, j] = v
    for k in range(1, 19):
        _mm(term, a, tmp)
        f = scale / k
        small = 0.0
        for i in range(n):
            for j in range(n):
                term[i, j] = tmp[i, j] * f
                result[i, j] += term[i, j]
                small = max(small, abs(term[i, j]))
        if small < 1e-18:
            break
    for _ in range(sq):
        _mm(result, result, tmp)
        for i in range(n):
            for j in range(n):
                result[i, j] = tmp[i, j]


@njit(cache=True, _nrt=True)
def modal_propagators(omega, zeta, h, a_out, g0_out, g1_out):
    """Exact one-step maps of the damped modes eta'' + 2 zeta omega eta' + omega^2 eta = f(t)
    for f quadratic over the step (Van Loan's augmented matrix exponential, the force and its
    first two derivatives as three more states): z1 = A z0 + g0 f0 + g1 f1 + g2 kappa with
    z = (eta, eta'), f(s) = f0 + (f1 - f0) s / h + kappa s (s - h); g2 is column 2 of a_out
    (kappa = 0: the force linear over the step)."""
    base = np.zeros((5, 5))
    e = np.empty((5, 5))
    term = np.empty((5, 5))
    tmp = np.empty((5, 5))
    for j in range(omega.shape[0]):
        base[0, 1] = h
        base[1, 0] = -(omega[j] ** 2) * h
        base[1, 1] = -2.0 * zeta[j] * omega[j] * h
        base[1, 2] = h
        base[2, 3] = h
        base[3, 4] = h
        _expm(base, e, term, tmp)
        for r in range(2):
            a_out[j, r, 0] = e[r, 0]
            a_out[j, r, 1] = e[r, 1]
            # the responses to f = s and f = s^2 / 2: s (s - h) = 2 (s^2 / 2) - h s
            a_out[j, r, 2] = 2.0 * e[r, 4] - h * e[r, 3]
            g0_out[j, r] = e[r, 2] - e[r, 3] / h
            g1_out[j, r] = e[r, 3] / h


RTOL_DEFAULT = 1e-4  # solver.rtol's default: its local error tolerance is rtol itself


@njit(cache=True, _nrt=False)
def tolerance_scale(rtol):
    """(rtol / RTOL_DEFAULT)^(1/2) below the default rtol, else 1: the factor on the local error
    tolerance (atol, rtol) of Milne's test on a flexible fence (tolerance proportionality).

    A second-order scheme whose local error per step is held at tol has a global error of
    ~tol^(2/3): from rtol 1e-4 to 1e-7 that is 100x only in the limit, and the peak force of an
    impact, set by the steps near it, gains less. Holding the local error at
    rtol (rtol / 1e-4)^(1/2) makes the global error fall about as rtol while the default is
    unchanged. On a stiff fence it needs the fence friction's stick resolved
    (:func:`resolves_stick`)."""
    if rtol >= RTOL_DEFAULT:
        return 1.0
    return math.sqrt(rtol / RTOL_DEFAULT)


@njit(cache=True, _nrt=False)
def resolves_stick(settings, m):
    """Whether the adaptive scheme resolves the fence friction's stick on a stiff fence: below
    the default rtol. Then its stick/slip switches are events (``first_event``'s
    ``friction``), the contact iteration converges the load's velocities to
    ``solver.tolerance`` [m/s] (its |dq| + h |dv| test alone leaves a velocity error up to
    tol / h and a force error ~ m tol / h^2 at the short steps around a switch), and a contact
    sticking at both ends of a step ends it at the stick force extrapolated from the step
    means (``steps._unring_stick``). See docs/design/numerics.md, "Convergence of the adaptive
    scheme with rtol"."""
    return settings[0].adaptive != 0.0 and m == 0 and settings[0].rtol < RTOL_DEFAULT


@njit(cache=True, _nrt=False)
def milne_error(y0, acc0, y1, prev_v, prev_a, r, h, atol, rtol, v_ref, om_ref):
    """Scaled local error of a trapezoidal step y0 -> y1 on the load's state: Milne's device,
    corrector minus variable-step AB2 (r > 0) or Euler (r = 0) predictor, each component over
    atol + rtol * its block magnitude. With history (r = h / h_prev > 0) TR's local error is
    -h^3 y'''/12, the AB2 predictor's h^3 y''' (1/6 + 1/(4r)), so the error is r/(3(r+1)) times
    corrector minus predictor (order 3); without (the start, after an event or a drive
    breakpoint) the Euler predictor gives the conservative order-2 estimate. The block
    magnitudes: position |r| or 1 m, yaw |phi| or 1 rad, velocity |v| or the belt speed, yaw
    rate |phidot| or belt / load size, so a component passing through zero does not shrink the
    tolerance to atol."""
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
EVENT_STICK = 4  # mu N - |f_stick|: a pushing corner's fence friction switches stick <-> slip


@njit(cache=True, _nrt=False)
def event_value(P, out, slot, kind):
    """The event function of ``kind`` for ``slot`` at a point (nan where it is not defined)."""
    if kind == EVENT_STICK:
        return out[slot].slack if out[slot].active != 0.0 else math.nan
    if kind == EVENT_SLIDE_OFF:
        s_arc = out[slot].s
        return P[0].length - s_arc if s_arc > 0.0 else math.nan
    if out[slot].gap == 0.0:
        return math.nan
    return out[slot].d if kind == EVENT_ONSET else out[slot].n_raw


@njit(cache=True, _nrt=False)
def first_event(P, out_a, out_b, friction):
    """The fence slot whose event function changes sign first between two points, or -1.

    A slot without force at a can start one (onset; the function is D), a slot with force can
    lose it (release or the N >= 0 clamp engaging; the function is the law (16) unclipped), and
    a pushing corner can slide past the fence tip (the function is R_z - s); with ``friction``
    a pushing corner's fence friction can switch between slip and stick (the function is
    mu N - |the implicit stick force|, ``slack``); only functions defined at both points
    count. The first is estimated by linear interpolation.
    Returns (slot, kind, g_a, g_b).
    """
    best = -1
    best_fr = 2.0
    kind_best = EVENT_ONSET
    ga_best = gb_best = 0.0
    for k in range(SLOT_BORDER):
        active = out_a[k].active != 0.0
        kind = EVENT_RELEASE if active else EVENT_ONSET
        if active and k < SLOT_TIP and out_b[k].gap == 0.0:
            kind = EVENT_SLIDE_OFF
        ga = event_value(P, out_a, k, kind)
        gb = event_value(P, out_b, k, kind)
        if friction and kind == EVENT_RELEASE and not (ga > 0.0) != (gb > 0.0):
            kind = EVENT_STICK
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
        if out[k].gap == 0.0 or out[k].active != 0.0:
            continue
        d = out[k].d
        rate = out[k].ddot
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
    mass = P[0].mass
    k = P[0].k_p
    b = P[0].b_eff
    for s in range(N_SLOTS):
        if out[s].active == 0.0:
            continue
        d = out[s].d
        if not d > 0.0:
            continue
        stiff = 4.0 * k * d**3 + 2.0 * b * d * out[s].ddot
        if not stiff > 0.0:
            continue
        if b * d * d < 2.0 * OSC_ZETA * math.sqrt(stiff * mass):
            h = OSC_PHASE * math.sqrt(rtol) / math.sqrt(stiff / mass)
            if h < best:
                best = h
    return best


@njit(cache=True, _nrt=False)
def flexible_contact_step(out, h_nom, scale):
    """Longest adaptive step while the load pushes a flexible fence: dt_max times
    ``tolerance_scale(rtol)`` (dt_max at the default rtol).

    The fence's modes are propagated exactly for their force quadratic over the step, and
    Milne's estimate on the load does not see the error of that force between points: in a
    slow push (slide_flexible's first 0.1 s) the load's error allows steps of dt_max whose
    error on the fence sets the peak force's (4.9e-5 at any rtol). A step held to
    dt_max (rtol / 1e-4)^(1/2) makes it fall with rtol; inf without a fence contact."""
    for k in range(SLOT_BORDER):
        if out[k].active != 0.0:
            return h_nom * scale
    return math.inf


#: the module's constants and compiled functions, re-exported by the package
__all__ = [
    n
    for n, v in tuple(globals().items())
    if not n.startswith("_") and (isinstance(v, int | float) or hasattr(v, "py_func"))
]
