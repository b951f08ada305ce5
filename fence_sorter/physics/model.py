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
from .scenario import RECORDABLE, Scenario, per_scenario

__all__ = ["RECORDABLE", "Scenario", "SortingModel"]


class SortingModel:
    """The parts one scenario needs, packed once for the kernel: no FEM for a stiff fence, only
    the modes ``fence_modes`` keeps, no border contact for a load that cannot reach the border,
    no time series nobody asked for."""

    sc: Scenario
    body: ParcelBody
    corners: np.ndarray  # the load's corners relative to C_s [m]
    normals: np.ndarray  # its face normals
    initial: tuple[float, float, float]  # initial pose (C_s, yaw)
    mass: float
    inertia: float
    belt: float  # belt speed [m/s]
    flexible: bool
    fem: object | None  # the fence's FEM (flexible)
    omega: np.ndarray  # kept modes' angular frequencies [rad/s] (empty: stiff fence)
    zeta: np.ndarray
    phi: np.ndarray
    rigid_modal: np.ndarray
    n_el: int
    n_modes: int
    n_state: int
    use_border: bool
    P: np.ndarray  # packed parameters (kernel.pack)
    speed_limit: float  # runaway-speed diagnosis [m/s]
    deep: float  # deep-penetration diagnosis [m]
    parts: tuple[str, ...]

    def __init__(self, sc: Scenario):
        # every attribute is a function of the (frozen) scenario: packed once per scenario
        # (``_packed``); the arrays are shared by the models of the scenario, so nothing may
        # write to them (a caller changing a part assigns its own copy of ``P``)
        self.__dict__.update(_packed(sc))

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


@per_scenario
def _packed(sc: Scenario) -> dict:
    """The attributes of a :class:`SortingModel` of ``sc``: the parts the scenario needs packed
    for the kernel (no FEM for a stiff fence, no border contact for a load that cannot reach it,
    only the modes ``fence_modes`` keeps, no time series nobody asked for). Computed once per
    scenario (repeated events of one scene: the optimiser, the line, the benchmarks); the arrays
    are shared, so nothing may write to them."""
    d: dict = {"sc": sc}
    body, d["corners"], d["normals"], d["initial"], reach = _load_geometry(
        sc.parcel, sc.conveyor, sc.drive.r_s
    )
    d["body"] = body
    d["mass"] = mass = body.mass
    d["inertia"] = body.inertia
    d["belt"] = belt = sc.conveyor.belt_speed
    d["flexible"] = flexible = sc.fence is not None
    if flexible:
        fem, d["omega"], d["zeta"], d["phi"], d["rigid_modal"] = _fence_modes(
            sc.fence, sc.fence_modes
        )
        d["fem"] = fem
        d["n_el"] = n_el = int(sc.fence.elements)
        dl = fem.dl
    else:
        d["fem"] = None
        d["omega"] = d["zeta"] = d["rigid_modal"] = _NO_MODES
        d["phi"] = _NO_PHI
        d["n_el"] = n_el = 0
        dl = 0.0
    d["n_modes"] = n_modes = len(d["omega"])
    d["n_state"] = 6 + 2 * n_modes
    y0 = d["initial"][1]
    steep = sc.drive.alpha_k > math.atan2(1.0, max(sc.contact.mu_fence, 1e-12))
    d["use_border"] = use_border = y0 - reach < 1e-3 or steep
    d["deep"] = deep = sc.contact.deep_penetration * min(body.length_a, body.width_b)
    d["P"] = K.pack(
        alpha_k=sc.drive.alpha_k,
        t1=sc.drive.t1,
        mass=mass,
        inertia=body.inertia,
        f_max=body.f_max,
        t_max=body.t_max,
        b_p=sc.contact.b_p,
        k_p=sc.contact.k_p,
        mu2=sc.contact.mu_fence,
        v_min=sc.contact.v_min,
        phidot_min=sc.contact.phidot_min,
        length=sc.length,
        dl=dl,
        n_el=n_el,
        use_border=use_border,
        use_tip=True,
        flexible=flexible,
        belt=belt,
        external=sc.external_wrench,
        deep=deep,
    )
    tip_speed = peak_rate(sc.drive) * sc.length
    d["speed_limit"] = 20.0 * (belt + tip_speed) + 10.0
    parts = ["load", "belt_friction", "fence_contact", "stiff_reference"]
    parts.append("fem_fence" if flexible else "rigid_fence")
    if use_border:
        parts.append("border_contact")
    parts.extend(f"record:{r}" for r in sc.record)
    d["parts"] = tuple(parts)
    return d


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
