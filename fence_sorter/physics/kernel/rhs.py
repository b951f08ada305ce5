"""The model's ODE form with explicit Karnopp friction (:func:`rhs`), which the SciPy baselines
integrate."""

from __future__ import annotations

import math

from numba import njit

from .forces import evaluate, karnopp_belt
from .layout import N_SLOTS


# -- right-hand side for ODE solvers (scipy.integrate baselines) --------------------------------
@njit(cache=True, _nrt=False)
def rhs(model, t, y, on_belt, dy, ev):
    """dy/dt of the full model with explicit Karnopp friction (34)-(37), the form an ODE solver
    integrates: the same forces as the steppers, no implicit friction. ``model``: a
    :data:`ForceModel` (or a LoopModel); ``ev``: the :data:`Evaluation` it fills, with the belt
    wrench. The fence friction's stick branch sees no belt wrench (it would need the belt
    friction it feeds): it matters only inside the 1e-6 m/s window."""
    P, omega, zeta = model.params, model.omega, model.zeta
    prev, lam, modal, res = ev.friction_prev, ev.belt, ev.modal, ev.resultant
    m = omega.shape[0]
    for k in range(N_SLOTS):
        prev[k] = math.nan
    lam[0] = lam[1] = lam[2] = 0.0
    evaluate(model, t, 0.0, y, lam, 0.0, ev)
    fx, fy, mz = res[0].fx, res[0].fy, res[0].mz
    if on_belt:
        bx, by, bz = karnopp_belt(P, y[3] - P[0].belt, y[4], y[5], fx, fy, mz)
        fx += bx
        fy += by
        mz += bz
        lam[0], lam[1], lam[2] = bx, by, bz
    dy[0], dy[1], dy[2] = y[3], y[4], y[5]
    dy[3] = fx / P[0].mass
    dy[4] = fy / P[0].mass
    dy[5] = mz / P[0].inertia
    for j in range(m):
        e, ed = y[6 + j], y[6 + m + j]
        dy[6 + j] = ed
        dy[6 + m + j] = modal[j] - omega[j] * omega[j] * e - 2.0 * zeta[j] * omega[j] * ed
