"""The observer of the solve loop: the reductions of a run at each accepted point
(:func:`observe`: sorting and exit speed, impacts with N_stiff, peak N, tip deflection, depth,
y_max, stages, the energy audit, the recorded series) and its divergence checks
(:func:`diverged`). A module of its own, apart from the step control, because they serve every
source of points: the compiled loop calls them per accepted step, the SciPy baselines from
Python on their own points (``Stepper.observe``), so every scheme's result is reduced alike.

Stages E1-E4 (paper section 2, appendix; ``fence_sorter.codes.Stage``) are classified from the
active contact set by :func:`classify_code`, not integrated as separate equations. The contact
slots (``forces.evaluate``, one row each): corners 0-3 against the fence surface (E1's oblique
strike (13), (23)-(33)); the fence tip inside the load after a penetrating corner slid past it,
slots 4-7 (E2's contact point kept on the fence until it passes R_z, (21)); corners against the
fence-side border wall y0 = 0, slots 8-11 (E3, (50)-(56)). A face along the fence (E2) is a face
whose two corners (or a corner and the fence tip) both touch the fence, or a single contact
with the face within ``FLUSH_ANGLE`` of the fence tangent: that contact pair holds it flush, the
moment the paper's E2 (46) imposes by slaving phi to the fence."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fence_sorter.codes import Stage

from .impact import n_stiff
from .layout import (
    DIAG_DEEP,
    DIAG_NONE,
    DIAG_NONFINITE,
    DIAG_SPEED,
    N_SLOTS,
    SLOT_BORDER,
    SLOT_TIP,
)

# stages: the values of fence_sorter.codes.Stage (plain ints: Numba freezes them as constants)
STAGE_CODE_ON_BELT = int(Stage.ON_BELT)
STAGE_CODE_E1 = int(Stage.E1)
STAGE_CODE_E2 = int(Stage.E2)
STAGE_CODE_E3 = int(Stage.E3)
STAGE_CODE_E4 = int(Stage.E4)
STAGE_CODE_SORTED = int(Stage.SORTED)


# a single contact whose face lies this close to the fence tangent holds it flush: E2 [rad]
FLUSH_ANGLE = math.radians(2.0)


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
    """Stage E1-E4 (or on_belt before the first touch) from the contact slots ``out``: E3 with
    a corner on the border wall, E2 with the fence tip inside the load, both corners of one face
    on the fence, or a single corner whose face lies within ``flush`` of the fence tangent
    (that face's contact pair holds it flush, the moment the paper's E2 (46) imposes by slaving
    phi to the fence), E1 another single corner, E4 no contact after one; codes STAGE_CODE_*."""
    n_corners = 0
    first = -1
    for k in range(4):
        if out[k].active != 0.0:
            n_corners += 1
            if first < 0:
                first = k
    tip = False
    for k in range(SLOT_TIP, SLOT_BORDER):
        if out[k].active != 0.0:
            tip = True
    border = False
    for k in range(SLOT_BORDER, N_SLOTS):
        if out[k].active != 0.0:
            border = True
    if n_corners == 0 and not tip:
        return STAGE_CODE_E4 if touched else STAGE_CODE_ON_BELT
    if border:
        return STAGE_CODE_E3
    if tip:
        return STAGE_CODE_E2
    for k in range(4):
        if out[k].active != 0.0 and out[(k + 1) % 4].active != 0.0:
            return STAGE_CODE_E2
    tangent_angle = math.atan2(out[first].nx, -out[first].ny)
    for face in (first, (first - 1) % 4):
        face_angle = phi + math.atan2(normals[face, 0], -normals[face, 1])
        if abs(_remainder(face_angle - tangent_angle, math.pi)) < flush:
            return STAGE_CODE_E2
    return STAGE_CODE_E1


@njit(cache=True, _nrt=False)
def parabola_peak(t0, n0, t1, n1, t2, n2):
    """Vertex value of the parabola through three points with n1 >= n0, n2 (else n1), at most
    n1 + max(n1 - n0, n1 - n2).

    Equally spaced, the vertex lies at most a quarter of that above n1; the cap binds only for
    very uneven spacing, where the vertex is an extrapolation: three points 1 ns and 1 ms apart
    on a force chattering by 1 N in 900 N put it at 3.4e6 N."""
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
    return min(n1 + b * d + c * d * d, n1 + max(n1 - n0, n1 - n2))


@njit(cache=True, _nrt=False)
def _audit(figures, t, r):
    """Update the energy audit (``result.EnergyAudit``) with the balance r at t."""
    if not math.isfinite(r):
        figures[0].max_res = r
        figures[0].min_res = r
        return
    if not math.isfinite(figures[0].max_res):
        return
    if r > figures[0].max_res:
        figures[0].max_res = r
        figures[0].t_max = t
    if r < figures[0].min_res:
        figures[0].min_res = r
        figures[0].t_min = t
    if r < figures[0].run_min:
        figures[0].run_min = r
        figures[0].t_run_min = t
    if r - figures[0].run_min > figures[0].max_rise:
        figures[0].max_rise = r - figures[0].run_min
        figures[0].t_rise0 = figures[0].t_run_min
        figures[0].t_rise1 = t


@njit(cache=True, _nrt=False)
def observe(
    params, normals, settings, counters, figures, times, states, belt_wrench, contacts, resultants,
    impacts, stages, record, i, on_belt,
):  # fmt: skip
    """The reductions of a run at the accepted point in state row i: sorting (C_s crossing
    y0 = s, exit speed interpolated), impacts (a fence contact after none, N_stiff at its w_n),
    peak N (with the parabola through the last three points when the contact set held), tip
    deflection, depth, y_max, stages, the energy audit and the recorded series; returns
    (stop, on_belt). The SciPy baselines call it from Python on their own points."""
    t = times[i]
    y = states[i]
    res = resultants[i]
    out = contacts[i]
    mass = params[0].mass
    vx, vy, om = y[3], y[4], y[5]
    energy = 0.5 * mass * (vx * vx + vy * vy) + 0.5 * params[0].inertia * om * om
    energy += res[0].energy_contact
    power = res[0].power_fence + params[0].ext_x * vx + params[0].ext_y * vy + params[0].ext_m * om
    if on_belt:
        power += belt_wrench[i, 0] * params[0].belt
    width = settings[0].width
    if counters[0].first != 0:
        counters[0].first = 0
        figures[0].e0 = energy
        figures[0].flow = abs(energy)
        figures[0].y_max = y[1]
    else:
        h = t - figures[0].prev_t
        figures[0].work += 0.5 * h * (power + figures[0].prev_power)
        figures[0].flow += 0.5 * h * (abs(power) + abs(figures[0].prev_power))
        _audit(figures, t, energy - figures[0].e0 - figures[0].work)
        py1 = figures[0].prev_y[1]
        if y[1] >= width > py1 and counters[0].sorted == 0:
            frac = (width - py1) / (y[1] - py1)
            figures[0].exit_speed = figures[0].prev_y[4] + frac * (vy - figures[0].prev_y[4])
            counters[0].sorted = 1
    mask = int(res[0].active_mask)
    fence_on = (mask & 0xFF) != 0
    if fence_on and counters[0].had_fence == 0:
        counters[0].touched = 1
        w_n = -math.inf
        for k in range(SLOT_BORDER):
            if out[k].active != 0.0:
                v = out[k].ddot
                if math.isnan(v) or math.isnan(w_n):
                    w_n = math.nan
                elif v > w_n:
                    w_n = v
        if math.isnan(figures[0].impact_speed):
            figures[0].impact_speed = w_n
        peak = n_stiff(mass, w_n, settings[0].b_p, settings[0].k_p)
        n_imp = counters[0].n_impacts
        impacts[n_imp, 0] = t
        impacts[n_imp, 1] = w_n
        impacts[n_imp, 2] = peak
        counters[0].n_impacts = n_imp + 1
    counters[0].had_fence = 1 if fence_on else 0
    n = res[0].fence_n
    if n > figures[0].peak_n:
        figures[0].peak_n = n
    n1, n2 = figures[0].last_n1, figures[0].last_n2
    smooth = counters[0].last_mask0 == counters[0].last_mask1 and counters[0].last_mask1 == mask
    counters[0].last_mask0 = counters[0].last_mask1
    counters[0].last_mask1 = mask
    if smooth and n2 > n1 and n2 >= n and n1 > 0.0:
        peak = parabola_peak(figures[0].last_t1, n1, figures[0].last_t2, n2, t, n)
        if peak > figures[0].peak_n:
            figures[0].peak_n = peak
    figures[0].last_n1, figures[0].last_n2 = n2, n
    figures[0].last_t1, figures[0].last_t2 = figures[0].last_t2, t
    tip = abs(res[0].tip_w)
    if tip > figures[0].peak_tip:
        figures[0].peak_tip = tip
    if res[0].max_d > figures[0].max_depth:
        figures[0].max_depth = res[0].max_d
    if y[1] > figures[0].y_max:
        figures[0].y_max = y[1]
    sorted_ = counters[0].sorted != 0
    if mask != counters[0].mask or (sorted_ and counters[0].stage != STAGE_CODE_SORTED):
        counters[0].mask = mask
        if sorted_:
            stage = STAGE_CODE_SORTED
        else:
            stage = classify_code(out, normals, y[2], counters[0].touched != 0, settings[0].flush)
        if stage != counters[0].stage:
            counters[0].stage = stage
            n_stg = counters[0].n_stages
            stages[n_stg, 0] = t
            stages[n_stg, 1] = stage
            counters[0].n_stages = n_stg + 1
    if settings[0].record != 0.0:
        n_rec = counters[0].n_rec
        point = record[n_rec]
        point.t = t
        point.t_fence = t
        point.t_forces = t
        point.t_stage = t
        for k in range(6):
            point.y[k] = y[k]
        point.alpha = res[0].alpha
        point.tip_w = res[0].tip_w
        point.fence_n = res[0].fence_n
        point.max_d = res[0].max_d
        point.stage = counters[0].stage
        counters[0].n_rec = n_rec + 1
    figures[0].prev_t = t
    for k in range(6):
        figures[0].prev_y[k] = y[k]
    figures[0].prev_power = power
    return sorted_ and settings[0].stop_sorted != 0.0, on_belt and not sorted_


@njit(cache=True, _nrt=False)
def diverged(params, settings, figures, t, y, res):
    """Divergence checks at an accepted point: a DIAG_* code (non-finite state, deep
    penetration, runaway speed; time and value left in figures)."""
    total = 0.0
    for k in range(y.shape[0]):
        total += y[k]
    figures[0].diag_t = t
    if not math.isfinite(total):
        return DIAG_NONFINITE
    if res[0].max_d > settings[0].deep:
        figures[0].diag_v = res[0].max_d
        return DIAG_DEEP
    speed = math.hypot(y[3], y[4])
    if speed > settings[0].speed_limit:
        figures[0].diag_v = speed
        return DIAG_SPEED
    return DIAG_NONE
