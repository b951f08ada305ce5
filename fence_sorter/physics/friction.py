"""Belt friction, coupled sliding and spinning (34)-(36), Karnopp stick; fence friction (37).

The paper's coupled law (after its ref. 6) is an elliptic limit surface: with c = F_max v_o and
d = T_max |phidot| the slip wrench is F = -F_max^2 v / sqrt(c^2 + d^2), T = -T_max^2 phidot /
sqrt(c^2 + d^2), so (|F| / F_max)^2 + (T / T_max)^2 = 1 and the wrench is parallel to the scaled
velocity (F_max^2 v, T_max^2 phidot). Below the Karnopp thresholds v_min, phidot_min the belt holds
the load with the wrench that cancels the applied one, saturated at F_max, T_max.

A fixed step cannot stay inside a 1e-6 m/s window (numerics notes): the time stepper therefore uses
:func:`implicit_belt_wrench`, the same law solved at the end of the step (stick makes the relative
velocity exactly zero when the needed wrench lies inside the limit ellipse), and
:func:`karnopp_belt_wrench` for the explicit evaluation and the stick branch.
"""

from __future__ import annotations

import math


def _corner_integral(a: float, b: float) -> float:
    """int_0^a int_0^b sqrt(x^2 + y^2) dy dx for a, b >= 0."""
    if a <= 0.0 or b <= 0.0:
        return 0.0
    r = math.hypot(a, b)
    return (2.0 * a * b * r + a**3 * math.log((b + r) / a) + b**3 * math.log((a + r) / b)) / 6.0


def polar_distance_integral(x1: float, x2: float, y1: float, y2: float) -> float:
    """int over [x1, x2] x [y1, y2] of the distance to the origin (closed form, any signs)."""
    total = 0.0
    for x, sx in ((x2, 1.0), (x1, -1.0)):
        for y, sy in ((y2, 1.0), (y1, -1.0)):
            sign = sx * sy * math.copysign(1.0, x) * math.copysign(1.0, y)
            total += sign * _corner_integral(abs(x), abs(y))
    return total


def max_spin_torque(
    length_a: float, width_b: float, cog_x: float, cog_y: float, mu: float, mass: float, g: float
) -> float:
    """T_max: friction torque about C_s for pure spin, uniform pressure m g / (A B) (our choice).

    T_max = mu (m g / (A B)) * int_footprint |rho| dA with rho measured from C_s, which sits at
    (cog_x, cog_y) from the geometric centre. For a square of side a about its centre this is
    mu m g a (sqrt(2) + asinh(1)) / 6 = 0.3826 mu m g a.
    """
    x1, x2 = -0.5 * length_a - cog_x, 0.5 * length_a - cog_x
    y1, y2 = -0.5 * width_b - cog_y, 0.5 * width_b - cog_y
    mean_radius = polar_distance_integral(x1, x2, y1, y2) / (length_a * width_b)
    return mu * mass * g * mean_radius


def karnopp_belt_wrench(
    ux: float,
    uy: float,
    spin: float,
    applied_x: float,
    applied_y: float,
    applied_torque: float,
    f_max: float,
    t_max: float,
    v_min: float,
    phidot_min: float,
) -> tuple[float, float, float]:
    """Belt friction on the load (34)-(36), explicit Karnopp form.

    (ux, uy): velocity of C_s relative to the belt; spin: phidot; applied: the other forces and
    torque on the load (the paper's P_ext, T_ext with opposite sign convention: here the friction
    that sticks is minus the applied wrench). Returns (F_x, F_y, T).
    """
    v_o = math.hypot(ux, uy)
    # slip wrench = -(F_max^2 v, T_max^2 phidot) / sqrt(c^2 + d^2), the form (34)-(36) reduces to
    norm = math.hypot(f_max * v_o, t_max * spin)
    if v_o > v_min:
        k = f_max * f_max / norm if norm > 0.0 else 0.0
        fx, fy = -k * ux, -k * uy
    else:
        p = math.hypot(applied_x, applied_y)
        if f_max > p:
            fx, fy = -applied_x, -applied_y
        else:
            fx, fy = -f_max * applied_x / p, -f_max * applied_y / p
    if abs(spin) > phidot_min:
        torque = -t_max * t_max * spin / norm if norm > 0.0 else 0.0
    elif t_max > abs(applied_torque):
        torque = -applied_torque
    else:
        torque = -math.copysign(t_max, applied_torque)
    return fx, fy, torque


def implicit_belt_wrench(
    u_star: tuple[float, float, float],
    weights: tuple[float, float, float],
    f_max: float,
    t_max: float,
) -> tuple[tuple[float, float, float], tuple[float, float, float], bool]:
    """Belt wrench lambda solving u = u* + W lambda with the elliptic law at the end velocity u.

    u*: relative generalized velocity (ux, uy, phidot) the step reaches without this wrench;
    W: velocity change per unit wrench (h/2m, h/2m, h/2I for the trapezoidal rule). Stick when the
    wrench -u*/W that zeroes u lies inside the ellipse (Fx^2 + Fy^2)/F_max^2 + T^2/T_max^2 <= 1;
    otherwise slip with lambda = -P u / sqrt(u^T P u), P = diag(F_max^2, F_max^2, T_max^2), solved
    in closed form up to one scalar root (Newton on a convex, decreasing function). Returns
    (lambda, u, stuck).
    """
    lam0 = [-u_star[k] / weights[k] for k in range(3)]
    limits = (f_max * f_max, f_max * f_max, t_max * t_max)
    q = 0.0
    for k in range(3):
        if limits[k] > 0.0:
            q += lam0[k] * lam0[k] / limits[k]
        elif lam0[k] != 0.0:
            q = math.inf
    if q <= 1.0:
        return (lam0[0], lam0[1], lam0[2]), (0.0, 0.0, 0.0), True
    a = [limits[k] * u_star[k] * u_star[k] for k in range(3)]
    c = [weights[k] * limits[k] for k in range(3)]
    sigma = 0.0
    for _ in range(100):
        psi = -1.0
        dpsi = 0.0
        for k in range(3):
            if a[k] > 0.0:
                den = sigma + c[k]
                psi += a[k] / (den * den)
                dpsi -= 2.0 * a[k] / (den * den * den)
        if psi <= 1e-14 or dpsi == 0.0:
            break
        step = -psi / dpsi
        sigma += step
        if step <= 1e-15 * max(sigma, 1e-300):
            break
    u = tuple(u_star[k] * sigma / (sigma + c[k]) if sigma + c[k] > 0 else 0.0 for k in range(3))
    lam = tuple(-limits[k] * u[k] / sigma if sigma > 0 else 0.0 for k in range(3))
    return lam, u, False


def fence_friction(
    normal_force: float, slide_speed: float, applied_tangential: float, mu: float, v_min: float
) -> float:
    """Fence (or border) friction along the tangent (37): Karnopp with threshold v_min.

    Returns the tangential force on the load, opposing the sliding speed; below v_min it cancels
    the applied tangential force up to mu N.
    """
    limit = mu * normal_force
    if abs(slide_speed) > v_min:
        return -math.copysign(limit, slide_speed)
    if limit > abs(applied_tangential):
        return -applied_tangential
    return -math.copysign(limit, applied_tangential)
