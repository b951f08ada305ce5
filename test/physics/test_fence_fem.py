"""Fence beam FEM against closed forms (cantilever theory, quadrature); ROS-free and fast."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
import scipy.optimize

from fence_sorter.physics.fence import (
    FenceParams,
    build_fence,
    contact_load,
    element_at,
    interpolate,
    modal_basis,
    natural_frequencies,
    node_positions,
    point_on_fence,
    static_tip_deflection,
)

P_TIP = 100.0  # N


def uniform(n: int, **kw) -> FenceParams:
    return FenceParams(profile="uniform", elements=n, **kw)


def section(p: FenceParams) -> tuple[float, float]:
    """(A, I) of the root section."""
    return p.height * p.root_thickness, p.height * p.root_thickness**3 / 12.0


def h_profile(p: FenceParams, s):
    """Constant-strength thickness h1 sqrt(1 - s/R_z), written independently of the module."""
    return p.root_thickness * np.sqrt(1.0 - np.asarray(s) / p.length)


def piecewise_h(p: FenceParams, s: float) -> float:
    """Section thickness at s when each element takes h at its own midpoint."""
    dl = p.length / p.elements
    k = min(int(s // dl), p.elements - 1)
    return float(h_profile(p, (k + 0.5) * dl))


def fitted_order(ns, errors) -> float:
    """Least-squares slope of log(error) against log(1/n)."""
    return float(np.polyfit(np.log(1.0 / np.asarray(ns, float)), np.log(errors), 1)[0])


@pytest.fixture(scope="module")
def beta_l() -> np.ndarray:
    """Roots of the clamped-free characteristic equation cos(bL) cosh(bL) + 1 = 0."""

    def char(x):
        return math.cos(x) * math.cosh(x) + 1.0

    roots = np.array(
        [scipy.optimize.brentq(char, a, b, xtol=1e-15) for a, b in ((1, 3), (4, 6), (7, 9))]
    )
    np.testing.assert_allclose(roots, [1.8751, 4.6941, 7.8548], atol=6e-5)
    return roots


def exact_cantilever_hz(p: FenceParams, beta_l: np.ndarray) -> np.ndarray:
    area, inertia = section(p)
    return (
        (beta_l / p.length) ** 2
        / (2 * math.pi)
        * math.sqrt(p.youngs_modulus * inertia / (p.density * area))
    )


# --------------------------------------------------------------------------- frequencies


def test_uniform_frequencies_match_cantilever_theory(beta_l):
    p = uniform(20)
    f = natural_frequencies(build_fence(p), 3)
    rel = np.abs(f / exact_cantilever_hz(p, beta_l) - 1.0)
    assert np.all(rel < 1e-3), rel
    # Also against the 5-digit beta_n L values quoted in the model notes.
    quoted = exact_cantilever_hz(p, np.array([1.8751, 4.6941, 7.8548]))
    assert np.all(np.abs(f / quoted - 1.0) < 1e-3)


def test_uniform_frequencies_converge_with_order_about_four(beta_l):
    ns = (4, 8, 16)
    errs = (
        np.array([natural_frequencies(build_fence(uniform(n)), 3) for n in ns])
        / exact_cantilever_hz(uniform(4), beta_l)
        - 1.0
    )
    assert np.all(errs > 0.0), "consistent mass gives upper bounds on the frequencies"
    assert np.all(np.diff(errs, axis=0) < 0.0), errs
    orders = [fitted_order(ns, errs[:, j]) for j in range(3)]
    # Measured (4, 8, 16 elements): 3.98, 3.92, 3.80 for modes 1, 2, 3.
    assert min(orders) > 3.0, f"fitted frequency convergence orders {orders}"


# --------------------------------------------------------------------------- statics


@pytest.mark.parametrize("n", [1, 3, 10])
def test_uniform_static_tip_deflection_is_exact(n):
    p = uniform(n)
    _, inertia = section(p)
    exact = P_TIP * p.length**3 / (3.0 * p.youngs_modulus * inertia)
    assert static_tip_deflection(build_fence(p), P_TIP) == pytest.approx(exact, rel=1e-9)


@pytest.mark.parametrize("n", [1, 4, 7])
def test_tapered_static_tip_matches_quadrature_of_piecewise_section(n):
    """Cubic elements are nodally exact for a tip load and element-wise constant EI."""
    p = FenceParams(elements=n)
    L, E, z = p.length, p.youngs_modulus, p.height
    dl = L / n
    total = 0.0
    for k in range(n):
        inertia = z * piecewise_h(p, (k + 0.5) * dl) ** 3 / 12.0
        val, _ = scipy.integrate.quad(
            lambda s, ei=E * inertia: P_TIP * (L - s) ** 2 / ei, k * dl, (k + 1) * dl
        )
        total += val
    assert static_tip_deflection(build_fence(p), P_TIP) == pytest.approx(total, rel=1e-9)


def test_tapered_static_tip_converges_to_constant_strength_closed_form():
    p0 = FenceParams()
    _, i1 = section(p0)
    exact = (2.0 / 3.0) * P_TIP * p0.length**3 / (p0.youngs_modulus * i1)
    ns = (5, 10, 20, 40)
    errs = np.array(
        [
            abs(static_tip_deflection(build_fence(FenceParams(elements=n)), P_TIP) / exact - 1.0)
            for n in ns
        ]
    )
    assert np.all(np.diff(errs) < 0.0), errs
    order = fitted_order(ns, errs)
    # Measured fitted order 1.44 over 5..40 elements (pairwise 1.41, 1.44, 1.46, tending to
    # 1.5: the last element, where h -> 0 at the tip, dominates and its error scales as
    # dl^1.5). Relative error 5.0e-2, 1.9e-2, 7.0e-3, 2.5e-3 at n_E = 5, 10, 20, 40.
    assert order > 1.3, f"fitted order of tapered tip deflection {order:.3f}, errors {errs}"
    assert errs[-1] < 5e-3


# --------------------------------------------------------------------------- mass, inertia


@pytest.mark.slow
@pytest.mark.parametrize("n", [1, 6, 25])
def test_mass_is_integral_of_piecewise_section(n):
    p = FenceParams(elements=n)
    dl = p.length / n
    integral = sum(
        scipy.integrate.quad(
            lambda s: p.density * p.height * piecewise_h(p, s), k * dl, (k + 1) * dl
        )[0]
        for k in range(n)
    )
    assert build_fence(p).mass() == pytest.approx(integral, rel=1e-12)
    # And it tends to the exact taper mass (2/3) rho z h1 R_z.
    exact = (2.0 / 3.0) * p.density * p.height * p.root_thickness * p.length
    assert build_fence(FenceParams(elements=200)).mass() == pytest.approx(exact, rel=1e-3)


def test_mass_uniform():
    p = uniform(7)
    expected = p.density * p.height * p.root_thickness * p.length
    assert build_fence(p).mass() == pytest.approx(expected, rel=1e-12)


def test_matrices_symmetric_positive_definite():
    model = build_fence(FenceParams(elements=9))
    for a in (model.M, model.K, model.C):
        assert np.allclose(a, a.T, rtol=0, atol=1e-12 * np.abs(a).max())
        assert np.all(np.linalg.eigvalsh(a) > 0.0)


@pytest.mark.parametrize("n", [1, 5, 12])
def test_rigid_inertia_quasi_static_root_acceleration(n):
    """Constant root angular acceleration: load q(s) = -rho A s alpha_ddot on the cantilever."""
    p = uniform(n)
    area, inertia = section(p)
    alpha_ddot = 3.7  # rad/s^2
    model = build_fence(p)
    w = np.linalg.solve(model.K, -model.rigid_inertia * alpha_ddot)
    q0 = p.density * area * p.length * alpha_ddot
    exact = -11.0 * q0 * p.length**4 / (120.0 * p.youngs_modulus * inertia)
    assert w[-2] == pytest.approx(exact, rel=1e-9)


def test_rigid_inertia_quasi_static_tapered_matches_virtual_work():
    """Tapered fence, constant root acceleration: tip deflection by the unit-load method,
    integral M(s) (L - s) / (E I(s)) ds with M(s) = integral_s^L q(t) (t - s) dt and
    q(t) = -rho S(t) t alpha_ddot (piecewise section). Cubic elements with element-wise
    constant EI and consistent loads are nodally exact, so this holds at any mesh."""
    p = FenceParams(elements=4)
    L, E, rho, z = p.length, p.youngs_modulus, p.density, p.height
    dl = L / p.elements
    alpha_ddot = -2.0
    edges = [k * dl for k in range(p.elements + 1)]

    def q(t):
        return -rho * z * piecewise_h(p, t) * t * alpha_ddot

    def moment(s):
        return scipy.integrate.quad(lambda t: q(t) * (t - s), s, L, points=edges[1:-1])[0]

    exact = sum(
        scipy.integrate.quad(
            lambda s: moment(s) * (L - s) / (E * z * piecewise_h(p, s) ** 3 / 12.0),
            edges[k],
            edges[k + 1],
        )[0]
        for k in range(p.elements)
    )
    model = build_fence(p)
    w = np.linalg.solve(model.K, -model.rigid_inertia * alpha_ddot)
    assert w[-2] == pytest.approx(exact, rel=1e-9)


# --------------------------------------------------------------------------- damping


def test_rayleigh_damping_ratios():
    p = FenceParams(elements=12, damping_ratio=0.05)
    model = build_fence(p)
    lam, phi = scipy.linalg.eigh(model.K, model.M)
    omega = np.sqrt(lam)
    c_modal = phi.T @ model.C @ phi
    zeta = np.diag(c_modal) / (2.0 * omega)
    np.testing.assert_allclose(zeta[:2], 0.05, rtol=1e-9)
    assert np.all(zeta[2:] > 0.05)
    off = c_modal - np.diag(np.diag(c_modal))
    assert np.abs(off).max() < 1e-9 * np.abs(np.diag(c_modal)).max()
    basis = modal_basis(model, count=5)
    np.testing.assert_allclose(basis.zeta, zeta[:5], rtol=1e-9)
    np.testing.assert_allclose(basis.phi.T @ model.M @ basis.phi, np.eye(5), atol=1e-10)


def test_modal_basis_selection():
    model = build_fence(FenceParams(elements=10))
    f = natural_frequencies(model, model.n_dof)
    assert np.all(np.diff(f) > 0)
    b = modal_basis(model, f_max_hz=0.5 * (f[2] + f[3]))
    assert b.phi.shape == (model.n_dof, 3)
    assert modal_basis(model, count=6, f_max_hz=1e9).omega.shape == (6,)
    with pytest.raises(ValueError, match="below the first frequency"):
        modal_basis(model, f_max_hz=0.5 * f[0])


# --------------------------------------------------------------------------- interpolation


def test_interpolate_reproduces_nodes_and_cubics():
    p = FenceParams(elements=6)
    model = build_fence(p)
    c2, c3 = 0.013, -0.0071  # w = c2 s^2 + c3 s^3 satisfies the clamp w(0) = w'(0) = 0
    s_nodes = model.node_s[1:]
    w_free = np.empty(model.n_dof)
    w_free[0::2] = c2 * s_nodes**2 + c3 * s_nodes**3
    w_free[1::2] = 2 * c2 * s_nodes + 3 * c3 * s_nodes**2
    for k, s in enumerate(model.node_s):
        w, th = interpolate(model, w_free, float(s))
        ref = (0.0, 0.0) if k == 0 else (w_free[2 * k - 2], w_free[2 * k - 1])
        assert (w, th) == pytest.approx(ref, abs=1e-15)
    for s in np.linspace(0.0, p.length, 37):
        w, th = interpolate(model, w_free, float(s))
        assert w == pytest.approx(c2 * s**2 + c3 * s**3, abs=1e-15)
        assert th == pytest.approx(2 * c2 * s + 3 * c3 * s**2, abs=1e-14)


def test_element_at_and_beyond_tip():
    model = build_fence(FenceParams(elements=10))
    dl = model.dl
    assert element_at(model, 0.0) == (0, 0.0)
    i, d = element_at(model, 3.4 * dl)
    assert i == 3 and d == pytest.approx(0.4 * dl, abs=1e-15)
    i, d = element_at(model, 1.2)
    assert i == 9 and d == pytest.approx(dl, abs=1e-15)
    with pytest.raises(ValueError, match=r"outside the fence .*beyond the tip"):
        element_at(model, 1.2 + 1e-9)
    for bad in (-1e-9, float("nan")):
        with pytest.raises(ValueError, match="outside the fence"):
            element_at(model, bad)


def test_contact_load_split():
    model = build_fence(FenceParams(elements=5))
    dl = model.dl
    q = contact_load(model, 2.25 * dl, 80.0)
    assert q.sum() == pytest.approx(80.0, abs=1e-12)
    assert q[2] == pytest.approx(80.0 * 0.75) and q[4] == pytest.approx(80.0 * 0.25)
    assert np.count_nonzero(q) == 2 and np.all(q[1::2] == 0.0)
    # First element: the root node's share goes into the clamp.
    q = contact_load(model, 0.3 * dl, 80.0)
    assert q.sum() == pytest.approx(80.0 * 0.3) and q[0] == pytest.approx(24.0)
    # Tip: all on the tip translation; out= buffer reused and cleared.
    buf = np.full(model.n_dof, 9.0)
    q = contact_load(model, 1.2, -10.0, out=buf)
    assert q is buf and q[-2] == pytest.approx(-10.0) and np.count_nonzero(q) == 1


# --------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("alpha", [0.0, 0.3, -1.1, 2.5])
def test_point_on_fence_rigid_line(alpha):
    model = build_fence(FenceParams(elements=8))
    zero = np.zeros(model.n_dof)
    for s in np.linspace(0.0, 1.2, 23):
        x, y, ang = point_on_fence(model, zero, alpha, float(s))
        assert x == pytest.approx(s * math.cos(alpha), abs=1e-15)
        assert y == pytest.approx(s * math.sin(alpha), abs=1e-15)
        assert ang == alpha
    x, y = node_positions(model, zero, alpha)
    np.testing.assert_allclose(x, model.node_s * math.cos(alpha), atol=1e-15)
    np.testing.assert_allclose(y, model.node_s * math.sin(alpha), atol=1e-15)


def test_point_on_fence_consistent_with_chords():
    """Deflected fence: U at nodes equals the chain of chords (27)-(29); a linear w = delta s
    beyond the first element is a rigid line at alpha + delta, chords and all (30)."""
    model = build_fence(FenceParams(elements=8))
    rng = np.random.default_rng(1)
    w_free = rng.normal(scale=0.02, size=model.n_dof)
    x, y = node_positions(model, w_free, 0.4)
    for k, s in enumerate(model.node_s):
        u = point_on_fence(model, w_free, 0.4, float(s))
        assert u[:2] == pytest.approx((x[k], y[k]), abs=1e-14)
    delta, alpha = 0.05, 0.2
    w_lin = np.empty(model.n_dof)
    w_lin[0::2] = delta * model.node_s[1:]
    w_lin[1::2] = delta
    ang1 = alpha + delta * 1.0  # chord angles beyond element 0
    xs, ys = node_positions(model, w_lin, alpha)
    x1, y1 = xs[1], ys[1]
    for s in np.linspace(model.dl, 1.2, 11):
        xu, yu, au = point_on_fence(model, w_lin, alpha, float(s))
        assert xu == pytest.approx(x1 + (s - model.dl) * math.cos(ang1), abs=1e-14)
        assert yu == pytest.approx(y1 + (s - model.dl) * math.sin(ang1), abs=1e-14)
        assert au == pytest.approx(ang1, abs=1e-14)


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    "field, value",
    [
        ("elements", 0),
        ("elements", 201),
        ("elements", 2.5),
        ("length", 0.0),
        ("length", float("nan")),
        ("height", -0.1),
        ("root_thickness", 0.0),
        ("youngs_modulus", 0.0),
        ("poisson_ratio", 0.5),
        ("density", -1.0),
        ("damping_ratio", 1.0),
        ("profile", "parabolic"),
    ],
)
def test_validate_names_field(field, value):
    p = FenceParams(**{field: value})
    with pytest.raises(ValueError, match=rf"fence\.{field} must be"):
        p.validate()
    with pytest.raises(ValueError, match=rf"fence\.{field}"):
        build_fence(p)


def test_defaults_valid_and_model_readonly():
    p = FenceParams()
    p.validate()
    assert p.shear_modulus == pytest.approx(3.0e9 / 2.78)
    model = build_fence(p)
    with pytest.raises(ValueError):
        model.K[0, 0] = 1.0
