"""Flexible fence of the rotary active fence sorter: a tapered PA6 cantilever as beam FEM.

The fence (paper section 4.3, Fig. 14) is an Euler-Bernoulli beam bending in the plane of the
belt, clamped at its root to the drive, which turns it by a prescribed angle alpha_w(t). It is
cut into n_E two-node elements of length dl = R_z / n_E; each node carries a transverse
translation and a rotation. Element i has the constant section S_i = z h_i, I_i = z h_i^3 / 12,
with h_i taken at the element midpoint from the constant-bending-strength profile
h(s) = h1 sqrt(1 - s / R_z) (or h1 for the uniform profile). Element matrices are the standard
4x4 cubic Hermite stiffness and consistent mass matrices. SI units throughout.

Floating-frame formulation
--------------------------
The paper writes the fence in absolute node coordinates, M_b q'' + B_b q' + K_b q = Q, eq. (13),
with q3(k) = s_k alpha_w + w_k (translation of node k) and q5(k) = alpha_w + theta_k (rotation),
and the root driven, q5(1) = alpha_w. Splitting q = r alpha_w + w, where r = [s_k, 1] per node is
the rigid-rotation shape (unit alpha_w), and using K r = 0 (a rigid rotation does not strain the
beam), the free rows of (13) become the equation integrated here:

    M w'' + C w' + K w = Q - M_fa r alpha_w'',        w_1 = theta_1 = 0 (clamped root),

where M, C, K act on the free DOFs [w_2, theta_2, w_3, theta_3, ...], M_fa are the free rows of
the full mass matrix (all columns) and ``rigid_inertia = M_fa r`` is the inertia load of the
rigid rotation. Damping C = a0 M + a1 K is Rayleigh damping of the RELATIVE motion, tuned to
``damping_ratio`` on modes 1 and 2 (the paper's material damping zeta, value not given), so the
prescribed rigid rotation itself is not damped. The model is linear in w: centrifugal
stiffening, Coriolis coupling and axial foreshortening are neglected (small at the fence's
angular speeds), and so are shear deformation (G is reported only) and gravity (out of plane).

Contact geometry follows the paper: the element holding arc position s is (21)-(22), the contact
force is split between that element's two node translations by (20), the deflection inside the
element is the cubic Hermite polynomial (31)-(32) (which reproduces the linear rigid part s alpha_w
exactly, so interpolating w is the same as interpolating q3), and the deformed fence is a chain
of chords of constant length dl with angles (29), giving the contact point U by (27), (28), (30).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from .params import FenceParams  # defined with the other parameters; imported from here too

__all__ = [
    "FenceModel",
    "FenceParams",
    "ModalBasis",
    "build_fence",
    "contact_load",
    "element_at",
    "interpolate",
    "modal_basis",
    "natural_frequencies",
    "node_positions",
    "point_on_fence",
    "static_tip_deflection",
]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class FenceModel:
    """Assembled clamped-free fence model; build with :func:`build_fence`. Arrays are read-only.

    ``eq=False``: models compare by identity (array fields have no scalar equality).
    """

    params: FenceParams
    dl: float  # element length R_z / n_E [m]
    node_s: np.ndarray  # (n_E+1,) arc positions of the nodes [m]
    thickness: np.ndarray  # (n_E,) element (midpoint) thickness [m]
    M: np.ndarray  # (2n_E, 2n_E) free-DOF consistent mass [kg, kg m, kg m^2]
    C: np.ndarray  # (2n_E, 2n_E) Rayleigh damping of the relative motion
    K: np.ndarray  # (2n_E, 2n_E) free-DOF stiffness
    rigid_inertia: np.ndarray  # (2n_E,) M_fa r; the forcing is -rigid_inertia * alpha_ddot
    rayleigh: tuple[float, float]  # (a0 [1/s], a1 [s])
    # Derived caches for the hot paths (not constructor arguments).
    _n: int = field(init=False, repr=False)
    _inv_dl: float = field(init=False, repr=False)
    _length: float = field(init=False, repr=False)
    _omega: np.ndarray = field(init=False, repr=False)
    _phi: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n = len(self.thickness)
        set_ = object.__setattr__
        set_(self, "_n", n)
        set_(self, "_inv_dl", 1.0 / self.dl)
        set_(self, "_length", float(self.node_s[-1]))
        lam, phi = scipy.linalg.eigh(self.K, self.M)  # phi^T M phi = I
        # Deterministic sign: tip translation of every mode positive (or tip rotation if zero).
        tip = np.where(np.abs(phi[-2]) > 1e-12 * np.abs(phi).max(axis=0), phi[-2], phi[-1])
        phi = phi * np.where(tip < 0.0, -1.0, 1.0)
        set_(self, "_omega", _readonly(np.sqrt(np.clip(lam, 0.0, None))))
        set_(self, "_phi", _readonly(phi))

    @property
    def n_dof(self) -> int:
        """Number of free DOFs, 2 n_E."""
        return 2 * self._n

    def mass(self) -> float:
        """Total beam mass sum(rho_b z h_i dl) [kg]."""
        p = self.params
        return float(p.density * p.height * self.dl * self.thickness.sum())


@dataclass(frozen=True, eq=False)
class ModalBasis:
    """Clamped-free modes: omega [rad/s], Rayleigh zeta per mode, phi mass-normalised (2n_E, m)."""

    omega: np.ndarray
    zeta: np.ndarray
    phi: np.ndarray

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self.omega / (2.0 * math.pi)


def _element_thickness(p: FenceParams, node_s: np.ndarray) -> np.ndarray:
    if p.profile == "uniform":
        return np.full(p.elements, float(p.root_thickness))
    mid = 0.5 * (node_s[:-1] + node_s[1:])
    return p.root_thickness * np.sqrt(1.0 - mid / p.length)


def build_fence(params: FenceParams) -> FenceModel:
    """Validate ``params`` and assemble M, K, C and the rigid-rotation inertia load."""
    params.validate()
    n = int(params.elements)
    L = float(params.length)
    dl = L / n
    node_s = np.linspace(0.0, L, n + 1)
    h = _element_thickness(params, node_s)
    area = params.height * h
    inertia = params.height * h**3 / 12.0

    le, le2 = dl, dl * dl
    k_unit = np.array(
        [[12.0, 6 * le, -12.0, 6 * le], [6 * le, 4 * le2, -6 * le, 2 * le2],
         [-12.0, -6 * le, 12.0, -6 * le], [6 * le, 2 * le2, -6 * le, 4 * le2]]
    ) / le**3  # fmt: skip
    m_unit = np.array(
        [[156.0, 22 * le, 54.0, -13 * le], [22 * le, 4 * le2, 13 * le, -3 * le2],
         [54.0, 13 * le, 156.0, -22 * le], [-13 * le, -3 * le2, -22 * le, 4 * le2]]
    ) * (le / 420.0)  # fmt: skip

    nd = 2 * (n + 1)
    m_full = np.zeros((nd, nd))
    k_full = np.zeros((nd, nd))
    for e in range(n):
        sl = slice(2 * e, 2 * e + 4)
        k_full[sl, sl] += params.youngs_modulus * inertia[e] * k_unit
        m_full[sl, sl] += params.density * area[e] * m_unit

    r = np.zeros(nd)  # rigid rotation by unit alpha_w: translation s_k, rotation 1
    r[0::2] = node_s
    r[1::2] = 1.0
    rigid_inertia = m_full[2:, :] @ r

    M = m_full[2:, 2:]
    K = k_full[2:, 2:]
    # Rayleigh coefficients from the two lowest clamped-free modes (for n_E = 1 these are
    # the only two). zeta(omega) = a0 / (2 omega) + a1 omega / 2.
    lam = scipy.linalg.eigh(K, M, eigvals_only=True, subset_by_index=[0, 1])
    w1, w2 = np.sqrt(lam)
    zeta = params.damping_ratio
    a0 = float(2.0 * zeta * w1 * w2 / (w1 + w2))
    a1 = float(2.0 * zeta / (w1 + w2))
    C = a0 * M + a1 * K

    return FenceModel(
        params=params,
        dl=dl,
        node_s=_readonly(node_s),
        thickness=_readonly(h),
        M=_readonly(M),
        C=_readonly(C),
        K=_readonly(K),
        rigid_inertia=_readonly(rigid_inertia),
        rayleigh=(a0, a1),
    )


def natural_frequencies(model: FenceModel, count: int) -> np.ndarray:
    """Lowest ``count`` undamped clamped-free natural frequencies [Hz], ascending."""
    if not 1 <= count <= model.n_dof:
        raise ValueError(f"count must be in [1, {model.n_dof}], got {count}")
    return model._omega[:count] / (2.0 * math.pi)


def modal_basis(
    model: FenceModel, count: int | None = None, f_max_hz: float | None = None
) -> ModalBasis:
    """Lowest modes for modal truncation: all, the first ``count``, those up to ``f_max_hz``,
    or (both given) the first ``count`` of those up to ``f_max_hz``.

    phi is mass-normalised (phi^T M phi = I) with the tip translation positive; zeta is the
    Rayleigh modal damping a0 / (2 omega) + a1 omega / 2 (C is diagonal in this basis).
    """
    m = model.n_dof
    if count is not None:
        if not 1 <= count <= model.n_dof:
            raise ValueError(f"count must be in [1, {model.n_dof}], got {count}")
        m = count
    if f_max_hz is not None:
        m = min(m, int(np.searchsorted(model._omega, 2.0 * math.pi * f_max_hz, side="right")))
        if m == 0:
            f1 = model._omega[0] / (2.0 * math.pi)
            raise ValueError(f"f_max_hz={f_max_hz} is below the first frequency {f1:.4g} Hz")
    omega = model._omega[:m]
    a0, a1 = model.rayleigh
    return ModalBasis(
        omega=_readonly(omega),
        zeta=_readonly(a0 / (2.0 * omega) + 0.5 * a1 * omega),
        phi=_readonly(model._phi[:, :m]),
    )


def static_tip_deflection(model: FenceModel, tip_load: float) -> float:
    """Tip translation [m] solving K w = Q with ``tip_load`` [N] on the tip translation DOF."""
    q = np.zeros(model.n_dof)
    q[-2] = tip_load
    return float(scipy.linalg.solve(model.K, q, assume_a="pos")[-2])


def element_at(model: FenceModel, s: float) -> tuple[int, float]:
    """Element holding arc position ``s`` [m] per (21)-(22): 0-based index i and offset d_N.

    The tip itself (s = R_z) belongs to the last element with d_N = dl; beyond it, (21)
    gives "error": ValueError.
    """
    if not 0.0 <= s <= model._length:  # also rejects NaN
        where = "beyond the tip, eq. (21)" if s > model._length else "not on the fence"
        raise ValueError(
            f"arc position s={s!r} m is outside the fence [0, {model._length:g}] m ({where})"
        )
    i = int(s * model._inv_dl)
    if i >= model._n:
        i = model._n - 1
    d = s - i * model.dl
    return i, max(0.0, d)


def _nodal(model: FenceModel, w_free: np.ndarray, i: int) -> tuple[float, float, float, float]:
    if len(w_free) != 2 * model._n:
        raise ValueError(f"w_free must have {2 * model._n} entries, got {len(w_free)}")
    if i == 0:
        return 0.0, 0.0, w_free.item(0), w_free.item(1)
    k = 2 * i
    return w_free.item(k - 2), w_free.item(k - 1), w_free.item(k), w_free.item(k + 1)


def _hermite(w_a, th_a, w_b, th_b, d, dl, inv_dl):
    # Coefficients p of (31)-(32) from q3(0), q5(0), q3(dl), q5(dl) within the element.
    slope = (w_b - w_a) * inv_dl
    p3 = (3.0 * slope - 2.0 * th_a - th_b) * inv_dl
    p4 = (th_a + th_b - 2.0 * slope) * inv_dl * inv_dl
    w = w_a + d * (th_a + d * (p3 + d * p4))
    th = th_a + d * (2.0 * p3 + 3.0 * d * p4)
    return w, th


def interpolate(model: FenceModel, w_free: np.ndarray, s: float) -> tuple[float, float]:
    """Relative deflection w(s) [m] and rotation theta(s) [rad] by the cubic (31)-(32)."""
    i, d = element_at(model, s)
    w_a, th_a, w_b, th_b = _nodal(model, w_free, i)
    return _hermite(w_a, th_a, w_b, th_b, d, model.dl, model._inv_dl)


def contact_load(
    model: FenceModel, s: float, force: float, out: np.ndarray | None = None
) -> np.ndarray:
    """Free-DOF generalized force (2n_E,) of a transverse ``force`` [N] at arc ``s``, per (20).

    Node i gets force (1 - d_N/dl), node i+1 force d_N/dl, both on translations; the root
    node's share goes into the clamp and is dropped. ``out``, if given, is zeroed and filled.
    """
    i, d = element_at(model, s)
    if out is None:
        out = np.zeros(2 * model._n)
    else:
        out[:] = 0.0
    frac = d * model._inv_dl
    if i > 0:
        out[2 * i - 2] = force * (1.0 - frac)
    out[2 * i] = force * frac
    return out


def node_positions(
    model: FenceModel, w_free: np.ndarray, alpha_w: float
) -> tuple[np.ndarray, np.ndarray]:
    """Node coordinates (x, y), each (n_E+1,), in the frame Ox0y0 on the rotation axis.

    Chain of chords of constant length dl (Fig. 15): chord k has the angle
    vartheta_k = alpha_w + (w_{k+1} - w_k) / dl, the absolute form of (29).
    """
    w = np.empty(model._n + 1)
    w[0] = 0.0
    w[1:] = w_free[0::2]
    ang = alpha_w + np.diff(w) * model._inv_dl
    x = np.empty_like(w)
    y = np.empty_like(w)
    x[0] = y[0] = 0.0
    np.cumsum(model.dl * np.cos(ang), out=x[1:])
    np.cumsum(model.dl * np.sin(ang), out=y[1:])
    return x, y


def point_on_fence(
    model: FenceModel, w_free: np.ndarray, alpha_w: float, s: float
) -> tuple[float, float, float]:
    """Fence point U at arc ``s`` and the fence angle q5(N) = alpha_w + theta(s) [rad].

    U = node i + d_N (cos, sin)(vartheta_N) by (27)-(28), with the chord angles (29) and
    vartheta_N = alpha_w + (w(s) - w_i) / d_N by (30) (its limit alpha_w + theta_i at d_N = 0).
    """
    i, d = element_at(model, s)
    if len(w_free) != 2 * model._n:
        raise ValueError(f"w_free must have {2 * model._n} entries, got {len(w_free)}")
    wl = w_free[: 2 * i + 2].tolist()  # Python floats: cheaper than NumPy for these few values
    w_a, th_a = (wl[2 * i - 2], wl[2 * i - 1]) if i > 0 else (0.0, 0.0)
    inv_dl = model._inv_dl
    w_s, th_s = _hermite(w_a, th_a, wl[2 * i], wl[2 * i + 1], d, model.dl, inv_dl)
    # Sum of the first i chords (27)-(28); a short Python loop beats NumPy for small arrays.
    cos, sin = math.cos, math.sin
    cx = cy = prev = 0.0
    for wk in wl[0 : 2 * i : 2]:
        a = alpha_w + (wk - prev) * inv_dl
        cx += cos(a)
        cy += sin(a)
        prev = wk
    ang_n = alpha_w + ((w_s - w_a) / d if d > 0.0 else th_a)
    x = model.dl * cx + d * math.cos(ang_n)
    y = model.dl * cy + d * math.sin(ang_n)
    return x, y, alpha_w + th_s
