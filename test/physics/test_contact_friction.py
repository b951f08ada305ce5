"""Closed-form checks of the contact law (16), the stiff-obstacle reference and belt friction."""

import math
from dataclasses import replace

import numpy as np
import pytest

from fence_sorter.physics import kernel as K
from fence_sorter.physics.contact import elastic_impact_closed_form, stiff_impact
from fence_sorter.physics.friction import (
    implicit_belt_wrench,
    karnopp_belt_wrench,
    max_spin_torque,
    polar_distance_integral,
)
from fence_sorter.physics.params import (
    ContactParams,
    ConveyorParams,
    DriveParams,
    ParcelParams,
    SolverParams,
)
from fence_sorter.physics.simulate import Scenario, simulate

G = 9.81


def test_elastic_impact_matches_closed_form():
    """b_p = 0: D_max = (5 m v^2 / 2k)^(1/5), F_max = k D_max^4, duration 2.5074 D_max / v."""
    contact = ContactParams(b_p=0.0)
    for mass, v0 in ((15.0, 2.43), (0.5, 1.0), (60.0, 0.3)):
        imp = stiff_impact(mass, v0, contact)
        ref = elastic_impact_closed_form(mass, v0, contact.k_p)
        assert imp.max_deformation == pytest.approx(ref["max_deformation"], rel=1e-5)
        assert imp.peak_force == pytest.approx(ref["peak_force"], rel=1e-4)
        assert imp.duration == pytest.approx(ref["duration"], rel=1e-4)
        assert imp.restitution == pytest.approx(1.0, abs=1e-7)


def test_damped_impact_dissipates_exactly_the_damping_work():
    """Restitution < 1, and the kinetic energy lost equals the work of N - k D^4."""
    contact = ContactParams()
    mass, v0 = 15.0, 2.43
    imp = stiff_impact(mass, v0, contact, samples=20001)
    assert 0.0 < imp.restitution < 1.0
    # rebuild D(t) and Ddot(t) from the force history alone (Newton: m Dddot = -N)
    t, n = imp.time, imp.force
    dd = v0 - np.concatenate(([0.0], np.cumsum(0.5 * (n[1:] + n[:-1]) * np.diff(t)))) / mass
    d = np.concatenate(([0.0], np.cumsum(0.5 * (dd[1:] + dd[:-1]) * np.diff(t))))
    dissipative = (n - contact.k_p * np.maximum(d, 0.0) ** 4) * dd
    work = np.sum(0.5 * (dissipative[1:] + dissipative[:-1]) * np.diff(t))
    lost = 0.5 * mass * v0**2 * (1.0 - imp.restitution**2)
    assert work == pytest.approx(lost, rel=2e-3)


def test_restitution_is_mass_independent_and_duration_scales_as_m_to_one_fifth():
    """With b_p m^0.4 the coefficient of restitution depends on b v^0.2 / k^0.6 only."""
    contact = ContactParams()
    light, heavy = stiff_impact(1.0, 2.0, contact), stiff_impact(32.0, 2.0, contact)
    assert light.restitution == pytest.approx(heavy.restitution, rel=1e-6)
    assert heavy.duration / light.duration == pytest.approx(32.0**0.2, rel=1e-5)


@pytest.mark.parametrize("b_p", [0.0, 3.3e5, 3.3e6])
def test_observer_n_stiff_matches_the_dop853_impact(b_p):
    """The observers' N_stiff (``kernel.n_stiff``: the similarity form inside its range, RK4
    with N_STIFF_STEPS steps and the parabola vertex beyond it) agrees with the DOP853 solve at
    rtol 1e-10 to 3e-7 over masses 0.1-60 kg and approach speeds 1e-4-20 m/s (b_p = 3.3e6 at
    0.01-20 m/s lies beyond N_STIFF_C_MAX: the RK4 branch)."""
    contact = ContactParams(b_p=b_p)
    worst = 0.0
    for mass, v0 in ((0.1, 0.05), (0.1, 20.0), (1.0, 1.5), (5.0, 0.01), (5.0, 3.0), (60.0, 1e-4)):
        ref = stiff_impact(mass, v0, contact, samples=4001).peak_force
        fast = K.n_stiff(mass, v0, b_p, contact.k_p)
        worst = max(worst, abs(fast / ref - 1.0))
    assert worst < 3e-7


def test_n_stiff_similarity_form_matches_the_integrated_impact():
    """Law (16) against a rigid wall scales to x'' = -(c x' x^2 + x^4) with c = b_p k_p^-0.6
    w^0.2: the Chebyshev series of the scaled peak gives the RK4 peak at N_STIFF_FIT_STEPS steps
    to 1e-8 for any mass, speed and stiffness with c inside its range (up to N_STIFF_C_MAX), and
    its coefficients are the ones n_stiff_coefficients() computes."""
    np.testing.assert_allclose(K.n_stiff_coefficients(), K._N_STIFF_CHEBYSHEV, rtol=0, atol=1e-12)
    inside = 0
    for mass in (0.1, 5.0, 60.0):
        for speed in (1e-10, 1.5e-6, 1e-3, 0.3, 1.85, 20.0):
            for b_p in (0.0, 3.3e4, 3.3e5, 3.3e6):
                for k_p in (1e6, 1.72e9, 1.72e12):
                    c = b_p * k_p**-0.6 * speed**0.2
                    fast = K.n_stiff(mass, speed, b_p, k_p)
                    rk4 = K.stiff_impact_peak_force(mass, speed, b_p, k_p, K.N_STIFF_FIT_STEPS)
                    if c <= K.N_STIFF_C_MAX:
                        inside += 1
                        assert fast == pytest.approx(rk4, rel=1e-8, abs=0.0)
                    else:  # the RK4 branch
                        assert fast == K.stiff_impact_peak_force(
                            mass, speed, b_p, k_p, K.N_STIFF_STEPS
                        )
    assert inside > 100
    # undamped closed form: D_max = (5 m w^2 / (2 k))^0.2, N = k D_max^4
    for mass, speed in ((0.1, 1e-6), (5.0, 2.0), (60.0, 20.0)):
        d_max = (5.0 * mass * speed**2 / (2.0 * 1.72e9)) ** 0.2
        assert K.n_stiff(mass, speed, 0.0, 1.72e9) == pytest.approx(1.72e9 * d_max**4, rel=1e-9)
    assert K.n_stiff(1.0, 0.0, 3.3e5, 1.72e9) == 0.0
    assert K.n_stiff(1.0, -1.0, 3.3e5, 1.72e9) == 0.0


def test_pure_spin_torque_of_a_square_and_rectangle_integral():
    # square of side a about its centre: mu m g a (sqrt 2 + asinh 1) / 6
    assert max_spin_torque(0.3, 0.3, 0.0, 0.0, 0.5, 2.0, G) == pytest.approx(
        0.5 * 2.0 * G * 0.3 * (math.sqrt(2.0) + math.asinh(1.0)) / 6.0, rel=1e-12
    )
    # off-centre rectangle against a midpoint-rule quadrature
    xs = np.linspace(-0.3, 0.5, 2001)[:-1] + 0.4 / 2000
    ys = np.linspace(-0.1, 0.25, 2001)[:-1] + 0.35 / 4000
    xx, yy = np.meshgrid(xs, ys)
    quad = np.hypot(xx, yy).mean() * 0.8 * 0.35
    assert polar_distance_integral(-0.3, 0.5, -0.1, 0.25) == pytest.approx(quad, rel=1e-5)


@pytest.mark.slow
def test_coupled_slip_wrench_lies_on_the_limit_ellipse():
    f_max, t_max = 10.0, 1.0
    fx, fy, t = karnopp_belt_wrench(0.3, -0.4, 2.0, 0, 0, 0, f_max, t_max, 1e-6, 1e-6)
    assert (fx**2 + fy**2) / f_max**2 + t**2 / t_max**2 == pytest.approx(1.0, rel=1e-12)
    assert fx < 0 < fy and t < 0  # opposes the relative velocity and the spin
    lam, u, stuck = implicit_belt_wrench((1.0, 0.5, 2.0), (1e-4, 1e-4, 1e-3), f_max, t_max)
    assert not stuck
    assert (lam[0] ** 2 + lam[1] ** 2) / f_max**2 + lam[2] ** 2 / t_max**2 == pytest.approx(1.0)
    # the wrench follows the explicit law at the end velocity u
    ref = karnopp_belt_wrench(u[0], u[1], u[2], 0, 0, 0, f_max, t_max, 1e-6, 1e-6)
    assert lam == pytest.approx(ref, rel=1e-9)


def test_explicit_stick_uses_the_same_ellipse_as_slip_and_the_implicit_law():
    """The Karnopp stick branch holds any applied wrench inside the limit ellipse and scales one
    outside it onto the ellipse (a box |F| <= F_max, |T| <= T_max would let SciPy's explicit
    rhs hold wrenches the implicit steppers let slip)."""
    f_max, t_max = 10.0, 1.0
    inside = karnopp_belt_wrench(0, 0, 0, 6.0, 0.0, 0.7, f_max, t_max, 1e-6, 1e-6)
    assert inside == pytest.approx((-6.0, 0.0, -0.7))
    fx, fy, t = karnopp_belt_wrench(0, 0, 0, 8.0, 0.0, 0.8, f_max, t_max, 1e-6, 1e-6)
    assert (fx**2 + fy**2) / f_max**2 + t**2 / t_max**2 == pytest.approx(1.0, rel=1e-12)
    assert fx / -8.0 == pytest.approx(t / -0.8)  # radial scaling: the same direction
    # the implicit law sticks exactly on the same set: inside -> stuck, outside -> slip
    w = (1e-4, 1e-4, 1e-3)
    for applied, stuck_expected in (((6.0, 0.0, 0.7), True), ((8.0, 0.0, 0.8), False)):
        u_star = tuple(-applied[k] * w[k] for k in range(3))  # the velocity lambda must cancel
        _, _, stuck = implicit_belt_wrench(u_star, w, f_max, t_max)
        assert stuck is stuck_expected
    # translation sticking while the load spins: the force left is what the ellipse allows
    fx, fy, t = karnopp_belt_wrench(0, 0, 2.0, 9.0, 0.0, 0.0, f_max, t_max, 1e-6, 1e-6)
    assert t == pytest.approx(-t_max) and fx == pytest.approx(0.0, abs=1e-9)


def _free_parcel(**kw) -> Scenario:
    """A parcel far upstream of the fence: only the belt acts on it."""
    base = dict(
        conveyor=ConveyorParams(belt_speed=1.5, mu_belt=0.5),
        parcel=ParcelParams(length_a=0.3, width_b=0.3, mass=4.0, lateral_gap=0.2),
        record=("trajectory",),
    )
    base.update(kw)
    return Scenario(
        **base,
        drive=DriveParams(r_s=-3.0, t1=0.3),
        solver=SolverParams(method="trapezoidal", t_end=0.6, dt=1e-3),
    )


@pytest.mark.parametrize("dt", [1e-3, 2.5e-4])
def test_parcel_at_rest_reaches_belt_speed_in_coulomb_time(dt):
    """Slip lasts v / (mu g) over v^2 / (2 mu g), then the parcel sticks exactly."""
    sc = _free_parcel(initial_velocity=(0.0, 0.0, 0.0))
    sc = replace(sc, solver=replace(sc.solver, dt=dt))
    r = simulate(sc)
    t, vx, x = r.series["t"], r.series["vx"], r.series["x"]
    v, mu = 1.5, 0.5
    t_slip = v / (mu * G)
    i = int(np.argmax(vx >= v - 1e-12))
    assert abs(t[i] - t_slip) <= dt  # reaches belt speed within one step of Coulomb's time
    slip = (x[i] - x[0]) - v * t[i]  # displacement relative to the belt
    assert slip == pytest.approx(-(v**2) / (2 * mu * G), rel=2 * dt / t_slip)
    assert np.all(np.abs(vx[i:] - v) < 1e-12)  # and then sticks exactly
    np.testing.assert_allclose(vx[:i], mu * G * t[:i], atol=1e-9)


def test_lateral_slide_decays_in_coulomb_time():
    vy0 = 0.8
    r = simulate(_free_parcel(initial_velocity=(1.5, vy0, 0.0)))
    t, vy = r.series["t"], r.series["vy"]
    i = int(np.argmax(np.abs(vy) < 1e-12))
    assert abs(t[i] - vy0 / (0.5 * G)) <= 1e-3


def test_stick_holds_under_a_sub_threshold_push_and_slips_above():
    f_max = 0.5 * 4.0 * G
    held = simulate(_free_parcel(external_wrench=(0.0, 0.6 * f_max, 0.0)))
    assert np.all(held.series["vy"] == 0.0)
    assert np.all(held.series["vx"] == 1.5)
    pushed = simulate(_free_parcel(external_wrench=(0.0, 1.4 * f_max, 0.0)))
    t, vy = pushed.series["t"], pushed.series["vy"]
    # sliding across the belt at (1.4 - 1) F_max / m
    np.testing.assert_allclose(vy, 0.4 * 0.5 * G * t, rtol=1e-9, atol=1e-12)


def test_pure_spin_decays_at_t_max_over_inertia():
    omega0 = 3.0
    r = simulate(_free_parcel(initial_velocity=(1.5, 0.0, omega0)))
    t, om = r.series["t"], r.series["phidot"]
    inertia = 4.0 * (0.3**2 + 0.3**2) / 12.0
    t_max = 0.5 * 4.0 * G * 0.3 * (math.sqrt(2.0) + math.asinh(1.0)) / 6.0
    t_stop = omega0 * inertia / t_max
    i = int(np.argmax(om == 0.0))
    assert abs(t[i] - t_stop) <= 1e-3
    np.testing.assert_allclose(om[:i], omega0 - t_max / inertia * t[:i], atol=1e-9)
    assert np.all(r.series["vx"] == 1.5)  # no sliding is induced


def test_elastic_bounce_off_the_border_conserves_energy():
    """b_p = 0, mu1 = mu2 = 0: the parcel hits the border wall and leaves at the same speed."""
    sc = _free_parcel(
        initial_velocity=(1.5, -0.7, 0.0),
        conveyor=ConveyorParams(belt_speed=1.5, mu_belt=0.0),
        contact=ContactParams(b_p=0.0, mu_fence=0.0),
        parcel=ParcelParams(length_a=0.3, width_b=0.3, mass=4.0, lateral_gap=0.05),
    )
    for dt in (5e-4, 1e-4):
        r = simulate(replace(sc, solver=replace(sc.solver, dt=dt, t_end=0.3)))
        vy = r.series["vy"]
        assert vy[-1] == pytest.approx(0.7, rel=1e-6)
        assert r.series["y"].min() < 0.15  # its lower face went into the wall
        assert r.series["vx"][-1] == pytest.approx(1.5, abs=1e-12)


def test_damped_bounce_off_the_border_loses_energy():
    sc = _free_parcel(
        initial_velocity=(1.5, -0.7, 0.0),
        conveyor=ConveyorParams(belt_speed=1.5, mu_belt=0.0),
        contact=ContactParams(mu_fence=0.0),
        parcel=ParcelParams(length_a=0.3, width_b=0.3, mass=4.0, lateral_gap=0.05),
    )
    r = simulate(replace(sc, solver=replace(sc.solver, dt=2e-4, t_end=0.3)))
    e = r.series["vy"][-1] / 0.7
    assert 0.0 < e < 1.0
