"""The fence as the load sees it: a surface point, tangent and material velocity at arc s.

Two implementations behind one small interface, so a scene builds only what it needs:
:class:`RigidFence` (stiff fence and stiff drive, sections 4.1-4.2: no FEM at all) and
:class:`FlexibleFence` (section 4.3: FEM beam (13) in modal coordinates, geometry (21)-(32)).
The fence is a line (its thickness is neglected in the contact geometry, as in (26)); the load
lies on its left side, so the surface normal n = (-t_y, t_x) points into the load.
"""

from __future__ import annotations

import math

import numpy as np

from .fence import FenceModel, contact_load, interpolate, modal_basis, point_on_fence


class RigidFence:
    """Stiff fence of length R_z on a stiff drive: the line at angle alpha_w through O."""

    flexible = False

    def __init__(self, length: float):
        self.length = length
        self.n_modes = 0
        self._c = 1.0
        self._s = 0.0
        self._rate = 0.0
        self.alpha = 0.0

    def set_state(self, alpha: float, rate: float, eta: np.ndarray, eta_dot: np.ndarray) -> None:
        self.alpha = alpha
        self._c, self._s = math.cos(alpha), math.sin(alpha)
        self._rate = rate

    def surface(self, s: float) -> tuple[float, float, float, float, float, float]:
        """(U_x, U_y, t_x, t_y, v_x, v_y) of the fence point at arc s."""
        c, si, r = self._c, self._s, self._rate
        return s * c, s * si, c, si, -r * s * si, r * s * c

    def tip(self) -> tuple[float, float]:
        return self.length * self._c, self.length * self._s

    def modal_force(self, s: float, fx: float, fy: float, out: np.ndarray) -> None:
        """A rigid fence takes the load into the drive: no generalized force."""

    def tip_deflection(self) -> float:
        return 0.0

    def max_deflection(self) -> float:
        return 0.0


class FlexibleFence:
    """Flexible fence: deflection w = Phi eta relative to the rigid line at alpha_w."""

    flexible = True

    def __init__(self, model: FenceModel, modes: int | None = None):
        self.model = model
        self.length = model.params.length
        basis = modal_basis(model, count=modes)
        self.omega = np.asarray(basis.omega, dtype=float)
        self.zeta = np.asarray(basis.zeta, dtype=float)
        self.phi = np.asarray(basis.phi, dtype=float)
        self.n_modes = self.phi.shape[1]
        # -Phi^T M_fa r alpha_ddot: modal share of the drive's inertial load
        self.rigid_modal = self.phi.T @ np.asarray(model.rigid_inertia, dtype=float)
        self.alpha = 0.0
        self._rate = 0.0
        self._w = np.zeros(model.M.shape[0])
        self._wdot = np.zeros(model.M.shape[0])
        self._c, self._s = 1.0, 0.0

    def set_state(self, alpha: float, rate: float, eta: np.ndarray, eta_dot: np.ndarray) -> None:
        self.alpha = alpha
        self._rate = rate
        self._c, self._s = math.cos(alpha), math.sin(alpha)
        self._w = self.phi @ eta
        self._wdot = self.phi @ eta_dot

    def surface(self, s: float) -> tuple[float, float, float, float, float, float]:
        ux, uy, angle = point_on_fence(self.model, self._w, self.alpha, s)
        wdot, _ = interpolate(self.model, self._wdot, s)
        r = self._rate
        # material velocity: rigid rotation about O plus the deflection rate along n_alpha
        vx = -r * uy - wdot * self._s
        vy = r * ux + wdot * self._c
        return ux, uy, math.cos(angle), math.sin(angle), vx, vy

    def tip(self) -> tuple[float, float]:
        ux, uy, _ = point_on_fence(self.model, self._w, self.alpha, self.length)
        return ux, uy

    def modal_force(self, s: float, fx: float, fy: float, out: np.ndarray) -> None:
        """Add the modal share of a force (fx, fy) on the fence at arc s, split by (20)."""
        transverse = -fx * self._s + fy * self._c  # component along the rotating normal n_alpha
        out += self.phi.T @ contact_load(self.model, s, transverse)

    def tip_deflection(self) -> float:
        return float(self._w[-2])

    def max_deflection(self) -> float:
        """Largest |w| over the nodes: bounds how far the surface leaves the rigid line."""
        return float(np.max(np.abs(self._w[0::2])))
