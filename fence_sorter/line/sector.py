"""The fence's swept sector (ROS-free, plain geometry): whether a parcel's footprint reaches
into the sector the fence sweeps in a stroke, in the unit's frame O x0 y0 (axis at the origin,
radius R_z, angles 0 to alpha_k). The one-fence line reports such a parcel as an
:class:`~fence_sorter.line.types.OverlapWarning`; the multi-unit line's guard declines a stroke
for it (:mod:`fence_sorter.line.routing`)."""

from __future__ import annotations

import math

#: a parcel corner this far inside the swept sector counts as overlapping [m]
OVERLAP_TOL = 1e-3


def in_swept_sector(
    corners: list[tuple[float, float]], length: float, alpha_k: float, tol: float = OVERLAP_TOL
) -> bool:
    """True if the convex polygon ``corners`` reaches into the sector the fence sweeps
    (radius R_z about the axis, angles 0 to alpha_k) deeper than ``tol``."""

    def inside_sector(x: float, y: float) -> bool:
        r = math.hypot(x, y)
        if r >= length - tol or r < tol:
            return False
        ang = math.atan2(y, x)
        return tol / r < ang < alpha_k - tol / r

    xs = [c[0] for c in corners]
    ys = [c[1] for c in corners]
    y_top = length * (math.sin(alpha_k) if alpha_k < 0.5 * math.pi else 1.0)
    x_low = length * min(math.cos(alpha_k), 0.0)
    if min(xs) > length or max(xs) < x_low or min(ys) > y_top or max(ys) < tol:
        return False  # bounding boxes apart
    if any(inside_sector(x, y) for x, y in corners):
        return True
    # sector sample points (radii and arc, slightly inside) inside the polygon
    pts = []
    for k in range(1, 17):
        r = (length - 2 * tol) * k / 16
        pts.append((r * math.cos(2 * tol / r), r * math.sin(2 * tol / r)))
        pts.append((r * math.cos(alpha_k - 2 * tol / r), r * math.sin(alpha_k - 2 * tol / r)))
        a = alpha_k * k / 17
        pts.append(((length - 2 * tol) * math.cos(a), (length - 2 * tol) * math.sin(a)))
    return any(_in_convex(corners, x, y) for x, y in pts)


def _in_convex(poly: list[tuple[float, float]], x: float, y: float) -> bool:
    sign = 0.0
    n = len(poly)
    for i in range(n):
        x0, y0 = poly[i]
        x1, y1 = poly[(i + 1) % n]
        cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
        if cross == 0.0:
            continue
        if sign == 0.0:
            sign = cross
        elif (cross > 0) != (sign > 0):
            return False
    return True
