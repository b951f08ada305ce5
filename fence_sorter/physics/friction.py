"""Belt friction, coupled sliding and spinning (34)-(36), Karnopp stick; fence friction (37).

The paper's coupled law (after its ref. 6) is an elliptic limit surface: with c = F_max v_o and
d = T_max |phidot| the slip wrench is F = -F_max^2 v / sqrt(c^2 + d^2), T = -T_max^2 phidot /
sqrt(c^2 + d^2), so (|F| / F_max)^2 + (T / T_max)^2 = 1 and the wrench is parallel to the scaled
velocity (F_max^2 v, T_max^2 phidot). Below the Karnopp thresholds v_min, phidot_min the belt holds
the load with the wrench that cancels the applied one, saturated at F_max, T_max.

A fixed step cannot stay inside a 1e-6 m/s window (numerics notes): the steppers therefore solve
the same law at the end of the step (:func:`implicit_belt_wrench`: stick makes the relative
velocity exactly zero when the needed wrench lies inside the limit ellipse); the ODE right-hand
side of the SciPy baselines uses the explicit form (:func:`karnopp_belt_wrench`). Both are the
compiled kernel's functions; this module gives them a plain-float interface and computes T_max.
"""

from __future__ import annotations

import math

import numpy as np

from . import kernel as K


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


def _limits(f_max: float, t_max: float, v_min: float = 0.0, phidot_min: float = 0.0):
    p = np.zeros(1, K.PARAMS)
    p["f_max"], p["t_max"], p["v_min"], p["phidot_min"] = f_max, t_max, v_min, phidot_min
    return p


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
    """Belt friction on the load (34)-(36), explicit Karnopp form (``kernel.karnopp_belt``).

    (ux, uy): velocity of C_s relative to the belt; spin: phidot; applied: the other forces and
    torque on the load (the paper's P_ext, T_ext with opposite sign convention: here the friction
    that sticks is minus the applied wrench). Returns (F_x, F_y, T).
    """
    p = _limits(f_max, t_max, v_min, phidot_min)
    return K.karnopp_belt(p, ux, uy, spin, applied_x, applied_y, applied_torque)


def implicit_belt_wrench(
    u_star: tuple[float, float, float],
    weights: tuple[float, float, float],
    f_max: float,
    t_max: float,
) -> tuple[tuple[float, float, float], tuple[float, float, float], bool]:
    """Belt wrench lambda solving u = u* + W lambda with the elliptic law at the end velocity u
    (``kernel.implicit_belt``, what the steppers use).

    u*: relative generalized velocity (ux, uy, phidot) the step reaches without this wrench;
    W: velocity change per unit wrench (h/2m, h/2m, h/2I for the trapezoidal rule). Stick when the
    wrench -u*/W that zeroes u lies inside the ellipse (Fx^2 + Fy^2)/F_max^2 + T^2/T_max^2 <= 1;
    otherwise slip with lambda = -P u / sqrt(u^T P u), P = diag(F_max^2, F_max^2, T_max^2), solved
    in closed form up to one scalar root. Returns (lambda, u, stuck).
    """
    lam = np.zeros(3)
    stuck = K.implicit_belt(_limits(f_max, t_max), *u_star, *weights, lam)
    if stuck:
        return (lam[0], lam[1], lam[2]), (0.0, 0.0, 0.0), True
    u = tuple(u_star[k] + weights[k] * lam[k] for k in range(3))
    return (lam[0], lam[1], lam[2]), u, False
