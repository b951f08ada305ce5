"""N_stiff: the peak of law (16) against a rigid wall, by RK4 and by its similarity solution (a
Chebyshev series)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

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


@njit(cache=True, _nrt=False, inline="always")
def _impact(mass, approach_speed, b_p, k_p, steps, to_peak):
    """RK4 on m D'' = -N(D, D') with ``steps`` steps over the elastic contact time estimate
    2.5074 D_max / w_n, until separation (``to_peak``: until the first step past the deepest
    compression whose force is below the peak); returns the peak refined by ``_vertex``, the
    deepest D, the time and D' where it stopped (``approach_speed`` > 0)."""
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
            return _vertex(left, peak, right), dm, t + frac * h, v_new
        if to_peak and v_new < 0.0 and f < peak:
            return _vertex(left, peak, right), dm, t + h, v_new
        d, v = d_new, v_new
        t += h
    return _vertex(left, peak, right), dm, t, v


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
    peak, dm, t, v = _impact(mass, approach_speed, b_p, k_p, steps, False)
    return peak, dm, t, -v / approach_speed


@njit(cache=True, _nrt=False)
def stiff_impact_peak_force(mass, approach_speed, b_p, k_p, steps):
    """The peak force of :func:`stiff_impact_peak` (the same RK4 steps, the same value),
    stopped at the first step past the deepest compression whose force is below the peak: with
    v = D' < 0 and N > 0, law (16) gives k D^2 > b |v| and so dN/dt = -b N D^2 / m + 2 b D v^2
    + 4 k D^3 v < -b N D^2 / m - 2 k D^3 |v| < 0, the force only falls from there (about half
    the steps of the whole impact; the loop's reductions need one per impact)."""
    if approach_speed <= 0.0:
        return 0.0
    return _impact(mass, approach_speed, b_p, k_p, steps, True)[0]


# -- N_stiff by similarity ----------------------------------------------------------------------
# m D'' = -(b_p m^0.4 D' D^2 + k_p D^4), D(0) = 0, D'(0) = w, in the units L = (m w^2 / k_p)^0.2
# of length and L / w of time, is x'' = -(c x' x^2 + x^4), x(0) = 0, x'(0) = 1, with the one
# number c = b_p k_p^-0.6 w^0.2 (the mass drops out, as for the restitution): the peak force is
# k_p L^4 F(c) = k_p^0.2 m^0.8 w^1.6 F(c). F on 0 <= c <= N_STIFF_C_MAX is a Chebyshev series in
# u = c / (1 + c) (analytic in c; the coefficients from :func:`n_stiff_coefficients`, RK4 with
# N_STIFF_FIT_STEPS steps; test_contact_friction regenerates them), so an impact costs ~30
# multiplications instead of ~400 RK4 steps (35-50 us called alone; 2 % of a stiff event).
# Beyond N_STIFF_C_MAX (very heavy damping) the peak is integrated (stiff_impact_peak_force).
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
