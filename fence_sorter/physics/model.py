"""The model of one sorting event packed from the scenario a user describes.

:class:`Scenario` (``scenario.py``, imported here too) holds everything one event needs (the
scene loader builds it from YAML); :class:`SortingModel` packs the parts a scenario needs into
the compiled kernel's arrays (no FEM for a stiff fence, no border contact for a load that cannot
reach it, only the modes kept by ``fence.modes``, no time series nobody asked for).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from . import kernel as K
from .drive import peak_rate
from .fence import build_fence, modal_basis
from .params import ConveyorParams, FenceParams, ParcelParams
from .parcel import ParcelBody, initial_pose, parcel_body
from .scenario import RECORDABLE, Scenario

__all__ = ["RECORDABLE", "Scenario", "SortingModel"]


class SortingModel:
    """The parts one scenario needs, packed once for the kernel: no FEM for a stiff fence, only
    the modes ``fence_modes`` keeps, no border contact for a load that cannot reach the border,
    no time series nobody asked for."""

    def __init__(self, sc: Scenario):
        self.sc = sc
        self.body: ParcelBody
        self.body, self.corners, self.normals, self.initial, reach = _load_geometry(
            sc.parcel, sc.conveyor, sc.drive.r_s
        )
        self.mass = self.body.mass
        self.inertia = self.body.inertia
        self.belt = sc.conveyor.belt_speed
        self.flexible = sc.fence is not None
        if self.flexible:
            fem, self.omega, self.zeta, self.phi, self.rigid_modal = _fence_modes(
                sc.fence, sc.fence_modes
            )
            self.fem = fem
            self.n_el = int(sc.fence.elements)
            dl = fem.dl
        else:
            self.fem = None
            self.omega = self.zeta = self.rigid_modal = _NO_MODES
            self.phi = _NO_PHI
            self.n_el = 0
            dl = 0.0
        self.n_modes = len(self.omega)
        self.n_state = 6 + 2 * self.n_modes
        y0 = self.initial[1]
        steep = sc.drive.alpha_k > math.atan2(1.0, max(sc.contact.mu_fence, 1e-12))
        self.use_border = y0 - reach < 1e-3 or steep
        self.P = K.pack(
            alpha_k=sc.drive.alpha_k,
            t1=sc.drive.t1,
            mass=self.mass,
            inertia=self.inertia,
            f_max=self.body.f_max,
            t_max=self.body.t_max,
            b_p=sc.contact.b_p,
            k_p=sc.contact.k_p,
            mu2=sc.contact.mu_fence,
            v_min=sc.contact.v_min,
            phidot_min=sc.contact.phidot_min,
            length=sc.length,
            dl=dl,
            n_el=self.n_el,
            use_border=self.use_border,
            use_tip=True,
            flexible=self.flexible,
            belt=self.belt,
            external=sc.external_wrench,
        )
        tip_speed = peak_rate(sc.drive) * sc.length
        self.speed_limit = 20.0 * (self.belt + tip_speed) + 10.0
        self.deep = sc.contact.deep_penetration * min(self.body.length_a, self.body.width_b)
        parts = ["load", "belt_friction", "fence_contact", "stiff_reference"]
        parts.append("fem_fence" if self.flexible else "rigid_fence")
        if self.use_border:
            parts.append("border_contact")
        parts.extend(f"record:{r}" for r in sc.record)
        self.parts = tuple(parts)

    def initial_state(self) -> np.ndarray:
        """[x, y, phi, vx, vy, phidot, eta, etadot] at t = 0 (fence at rest)."""
        y = np.zeros(self.n_state)
        y[:3] = self.initial
        v = self.sc.initial_velocity
        y[3:6] = v if v is not None else (self.belt, 0.0, 0.0)
        return y

    def kinetic_energy(self, y: np.ndarray) -> float:
        return 0.5 * self.mass * (y[3] ** 2 + y[4] ** 2) + 0.5 * self.inertia * y[5] ** 2


_NO_MODES = np.zeros(0)  # a stiff fence's (empty) modal arrays, shared
_NO_PHI = np.zeros((2, 0))


@functools.lru_cache(maxsize=64)
def _load_geometry(parcel: ParcelParams, conveyor: ConveyorParams, r_s: float):
    """The load's body, corner and face-normal arrays, initial pose (C_s, yaw) and reach (the
    largest corner distance from C_s): pure functions of frozen parameters, shared by every model
    of the same load (the optimiser and the line build a model per event for the same parcels;
    on a cold cache these few NumPy and dataclass calls cost ~0.13 ms of a stiff event). The
    arrays are shared, so nothing may write to them (the kernels only read)."""
    body = parcel_body(parcel, conveyor)
    corners = np.array(body.corners, dtype=float)
    normals = np.array(body.face_normals, dtype=float)
    pose = initial_pose(body, r_s, parcel.lateral_gap, parcel.yaw)
    reach = max(math.hypot(bx, by) for bx, by in body.corners)
    return body, corners, normals, pose, reach


@functools.lru_cache(maxsize=16)
def _fence_modes(fence: FenceParams, count: int | None):
    """FEM and modal basis of a fence (shared by every model of the same fence: the line and
    the controller build one model per stroke, and the eigen-solve costs 0.5-3 ms). The arrays
    are shared, so nothing may write to them."""
    fem = build_fence(fence)
    basis = modal_basis(fem, count=count)
    phi = np.ascontiguousarray(basis.phi, dtype=float)
    return (
        fem,
        np.ascontiguousarray(basis.omega, dtype=float),
        np.ascontiguousarray(basis.zeta, dtype=float),
        phi,
        np.ascontiguousarray(phi.T @ fem.rigid_inertia),
    )
