"""The load as a planar rigid rectangle with an offset centre of gravity (paper Fig. 2, (17)-(19)).

Body frame: origin at C_s, x_b along A (the belt direction at phi = 0), y_b along B. Corners are
numbered counter-clockwise from the front corner on the fence side: 0 front/fence side,
1 front/chute side, 2 rear/chute side, 3 rear/fence side; face k joins corners k and k+1
(0 front, 1 chute side, 2 rear, 3 fence side). The paper's r_Cj and gamma_j (17)-(18) are the
polar coordinates of these corner vectors; we keep the vectors instead of the angles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .friction import max_spin_torque
from .params import ConveyorParams, ParcelParams


@dataclass(frozen=True)
class ParcelBody:
    mass: float  # m_p [kg]
    inertia: float  # I_p about C_s [kg m^2]
    corners: tuple[tuple[float, float], ...]  # body-frame corner vectors from C_s [m]
    face_normals: tuple[tuple[float, float], ...]  # body-frame outward normals of faces 0..3
    f_max: float  # mu1 m g [N]
    t_max: float  # pure-spin friction torque about C_s [N m]
    length_a: float
    width_b: float


def parcel_body(parcel: ParcelParams, conveyor: ConveyorParams) -> ParcelBody:
    """Mass properties, corner vectors and belt friction limits of a parcel."""
    a, b = parcel.length_a, parcel.width_b
    xp, yp = parcel.cog_offset_x, parcel.cog_offset_y
    m = parcel.mass
    inertia = m * (a * a + b * b) / 12.0 + m * (xp * xp + yp * yp)
    geo = ((0.5 * a, -0.5 * b), (0.5 * a, 0.5 * b), (-0.5 * a, 0.5 * b), (-0.5 * a, -0.5 * b))
    corners = tuple((cx - xp, cy - yp) for cx, cy in geo)
    normals = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
    f_max = conveyor.mu_belt * m * conveyor.gravity
    t_max = max_spin_torque(a, b, xp, yp, conveyor.mu_belt, m, conveyor.gravity)
    return ParcelBody(m, inertia, corners, normals, f_max, t_max, a, b)


def world_corners(body: ParcelBody, x: float, y: float, phi: float) -> list[tuple[float, float]]:
    """Corner positions in frame O x0 y0 for C_s at (x, y) and yaw phi."""
    c, s = math.cos(phi), math.sin(phi)
    return [(x + c * bx - s * by, y + s * bx + c * by) for bx, by in body.corners]


def initial_pose(
    body: ParcelBody, front_x: float, lateral_gap: float, yaw: float
) -> tuple[float, float, float]:
    """C_s with the load front at x0 = front_x and its lowest point at y0 = lateral_gap."""
    pts = world_corners(body, 0.0, 0.0, yaw)
    x = front_x - max(p[0] for p in pts)
    y = lateral_gap - min(p[1] for p in pts)
    return x, y, yaw
