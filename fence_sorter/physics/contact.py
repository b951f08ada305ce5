"""Contact law (16) and the stiff-obstacle reference N_stiff (Fig. 11c, 12c).

N = b_p m_p^0.4 Ddot D^2 + k_p D^4 for D > 0 (modified nonlinear Kelvin model), clipped at
N >= 0 (no adhesion: late in restitution the damping term would pull). N_stiff is the same load
(mass m_p) and the same law against an immobile, undeformable obstacle of infinite mass, starting
at the normal approach speed w_n the real contact had at its onset: the drop test the paper's
limits w_dop and a_Ndop come from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from .params import ContactParams

#: b = 0 contact time factor: 2 int_0^1 dx / sqrt(1 - x^5) = 2 sqrt(pi) G(6/5) / G(7/10) = 2.5074
ELASTIC_DURATION_FACTOR = 2.0 * math.sqrt(math.pi) * math.gamma(1.2) / math.gamma(0.7)


def normal_force(d: float, d_rate: float, mass: float, contact: ContactParams) -> float:
    """Contact law (16), clipped at 0; D and Ddot positive into the load."""
    if d <= 0.0:
        return 0.0
    n = contact.b_p * mass**0.4 * d_rate * d * d + contact.k_p * d**4
    return n if n > 0.0 else 0.0


@dataclass(frozen=True)
class StiffImpact:
    """Normal impact of mass m at speed w_n on a rigid wall with law (16)."""

    approach_speed: float  # w_n [m/s]
    time: np.ndarray  # [s] from contact onset
    force: np.ndarray  # N_stiff(t) [N]
    peak_force: float  # [N]
    max_deformation: float  # [m]
    duration: float  # [s] until N returns to 0
    restitution: float  # rebound speed / approach speed
    damping_work: float  # [J] dissipated by the damping term, incl. the clamp's effect


def stiff_impact(
    mass: float,
    approach_speed: float,
    contact: ContactParams,
    samples: int = 400,
    max_spacing: float = math.inf,
) -> StiffImpact:
    """Solve m Dddot = -N(D, Ddot), D(0) = 0, Ddot(0) = w_n until the load separates; the
    course on ``samples`` points, more where they would lie more than ``max_spacing`` apart.

    Tight tolerances (rtol 1e-10) make the reference independent of the caller's step size.
    With b_p = 0: D_max = (5 m w_n^2 / (2 k_p))^(1/5) and the contact lasts 2.5074 D_max / w_n.
    """
    if approach_speed <= 0.0:
        z = np.zeros(1)
        return StiffImpact(approach_speed, z, z, 0.0, 0.0, 0.0, 1.0, 0.0)
    b = contact.b_p * mass**0.4
    k = contact.k_p

    def rhs(_t, y):
        d, dd = y[0], y[1]
        n = b * dd * d * d + k * d**4 if d > 0.0 else 0.0
        n = max(n, 0.0)
        return [dd, -n / mass]

    def separated(_t, y):
        return y[0]

    separated.terminal = True
    separated.direction = -1
    d_el = (5.0 * mass * approach_speed**2 / (2.0 * k)) ** 0.2
    horizon = 50.0 * d_el / approach_speed
    sol = solve_ivp(
        rhs,
        (0.0, horizon),
        [0.0, approach_speed],
        method="DOP853",
        rtol=1e-10,
        atol=1e-14,
        events=separated,
        dense_output=True,
        first_step=d_el / approach_speed * 1e-3,
    )
    t_sep = float(sol.t_events[0][0]) if len(sol.t_events[0]) else float(sol.t[-1])
    if math.isfinite(max_spacing):
        samples = max(samples, math.ceil(t_sep / max_spacing) + 1)
    t = np.linspace(0.0, t_sep, samples)
    y = sol.sol(t)
    d = np.maximum(y[0], 0.0)
    force = np.maximum(b * y[1] * d * d + k * d**4, 0.0)
    force[0] = 0.0
    rebound = float(-sol.sol(t_sep)[1])
    restitution = rebound / approach_speed
    damping_work = 0.5 * mass * (approach_speed**2 - rebound**2)
    i_max = int(np.argmax(force))
    # refine the peak on the dense output
    lo, hi = t[max(i_max - 1, 0)], t[min(i_max + 1, samples - 1)]
    tt = np.linspace(lo, hi, 201)
    yy = sol.sol(tt)
    dd = np.maximum(yy[0], 0.0)
    peak = float(np.max(np.maximum(b * yy[1] * dd * dd + k * dd**4, 0.0)))
    i_d = int(np.argmax(d))
    td = np.linspace(t[max(i_d - 1, 0)], t[min(i_d + 1, samples - 1)], 201)
    d_max = float(np.max(sol.sol(td)[0]))
    return StiffImpact(
        approach_speed=approach_speed,
        time=t,
        force=force,
        peak_force=peak,
        max_deformation=d_max,
        duration=t_sep,
        restitution=restitution,
        damping_work=damping_work,
    )


#: fewest points of :func:`stiff_course` per impact, and their largest spacing [s] (4 kHz)
STIFF_COURSE_POINTS = 200
STIFF_COURSE_DT = 2.5e-4


def stiff_course(
    mass: float, approach_speed: float, contact: ContactParams, onset: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """N_stiff(t) through one impact (Fig. 11c, 12c): times from ``onset`` [s] and forces [N]
    of :func:`stiff_impact` on at least STIFF_COURSE_POINTS points at most STIFF_COURSE_DT
    apart (a slow, long impact gets more), ending with the force back at 0."""
    imp = stiff_impact(mass, approach_speed, contact, STIFF_COURSE_POINTS, STIFF_COURSE_DT)
    return onset + imp.time, imp.force


def elastic_impact_closed_form(mass: float, approach_speed: float, k_p: float) -> dict:
    """b_p = 0 closed forms: maximum deformation, peak force and contact duration."""
    d_max = (5.0 * mass * approach_speed**2 / (2.0 * k_p)) ** 0.2
    return {
        "max_deformation": d_max,
        "peak_force": k_p * d_max**4,
        "duration": ELASTIC_DURATION_FACTOR * d_max / approach_speed,
    }
