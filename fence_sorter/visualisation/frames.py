"""The plain frames the Rerun views are drawn from (no ROS, no Rerun): what does not move
(:class:`SceneGeometry`), the fence (:class:`FenceFrame`) and the parcels (:class:`ParcelFrame`)
at one instant, made from the line's snapshots (:func:`frames_from_snapshot`, live) or from a
recorded bag (:func:`scene_from_bag`, :func:`bag_frames`).

Frame "sorter" (REP-103, z up): x0 along the belt, y0 across it towards the chute [m].
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from fence_sorter.recording import topics
from fence_sorter.stamps import time_to_sec


@dataclass(frozen=True)
class SceneGeometry:
    """What does not move: belt width s and x range, chute box, scan line [m]."""

    belt_width: float
    belt_x: tuple[float, float] = (-3.0, 3.0)
    chute: tuple[float, float, float, float] | None = None  # centre x, y, size x, y
    scan_line_x: float | None = None


#: a unit's chute as the views draw it, in the unit's frame: from the fence axis (x0 = 0)
#: CHUTE_LENGTH downstream, from the far belt border (y0 = s) CHUTE_DEPTH outwards [m]
CHUTE_LENGTH = 1.5
CHUTE_DEPTH = 0.6


def unit_chute(belt_width: float) -> tuple[float, float, float, float]:
    """A unit's chute box (centre x, y, size x, y) in its frame [m]."""
    return (0.5 * CHUTE_LENGTH, belt_width + 0.5 * CHUTE_DEPTH, CHUTE_LENGTH, CHUTE_DEPTH)


@dataclass(frozen=True)
class FenceFrame:
    alpha: float  # alpha_w [rad]
    node_x: np.ndarray  # [m]
    node_y: np.ndarray
    tip_deflection: float  # [m]


@dataclass(frozen=True)
class ParcelFrame:
    parcel_id: int
    x: float  # C_s [m]
    y: float
    yaw: float  # [rad]
    vx: float  # [m/s]
    vy: float
    center_x: float  # centre of the box (not C_s) [m]
    center_y: float
    length_a: float
    width_b: float
    height: float
    n: float = 0.0  # contact normal force N [N]
    n_stiff: float = 0.0  # N_stiff [N]
    contact_x: float = math.nan  # contact point [m]
    contact_y: float = math.nan
    divert: bool = False
    stage: int = 0


def frames_from_snapshot(snap) -> tuple[FenceFrame, list[ParcelFrame]]:
    """FenceFrame and ParcelFrames of a :class:`fence_sorter.line.LineSnapshot`."""
    f = snap.fence
    fence = FenceFrame(float(f.drive_angle), f.node_x, f.node_y, float(f.tip_deflection))
    parcels = []
    for p in snap.parcels:
        n = max(len(p.corners), 1)
        cx = sum(c[0] for c in p.corners) / n if p.corners else p.x
        cy = sum(c[1] for c in p.corners) / n if p.corners else p.y
        parcels.append(
            ParcelFrame(
                int(p.parcel_id), p.x, p.y, p.yaw, p.vx, p.vy, cx, cy, p.length_a, p.width_b,
                p.height, p.contact_normal_force, p.contact_normal_force_stiff,
                p.contact_point[0], p.contact_point[1], bool(p.divert), int(p.stage),
            )
        )  # fmt: skip
    return fence, parcels


def scene_from_bag(contents) -> SceneGeometry:
    """Belt, chute (from /markers) and scan line (from /parcels) as the bag shows them."""
    from fence_sorter.analysis.run import DEFAULT_BELT_WIDTH  # lazy: loads rosbags

    width, belt_x, chute = DEFAULT_BELT_WIDTH, (-3.0, 3.0), None
    for m in contents.by_topic(topics.MARKERS):
        for mk in m.msg.markers:
            if mk.ns == "belt":
                width = float(mk.scale.y)
                belt_x = (mk.pose.position.x - 0.5 * mk.scale.x,
                          mk.pose.position.x + 0.5 * mk.scale.x)  # fmt: skip
            elif mk.ns == "chute":
                chute = (mk.pose.position.x, mk.pose.position.y, mk.scale.x, mk.scale.y)
        break
    scans = [m.msg.scan_position_x for m in contents.by_topic(topics.PARCELS)]
    scan_x = float(np.median(scans)) if scans else None
    return SceneGeometry(width, belt_x, chute, scan_x)


def bag_frames(contents) -> Iterable[tuple[float, FenceFrame | None, list[ParcelFrame]]]:
    """(t, fence, parcels) per published snapshot of a recorded run, in sim-time order."""
    specs = {m.msg.parcel_id: m.msg for m in contents.by_topic(topics.PARCELS)}
    loads: dict[float, list] = {}
    for m in contents.by_topic(topics.LOAD_STATES):
        loads.setdefault(round(time_to_sec(m.msg.header.stamp), 9), []).append(m.msg)
    fences = {
        round(time_to_sec(m.msg.header.stamp), 9): m.msg
        for m in contents.by_topic(topics.FENCE_STATE)
    }
    for t in sorted(set(loads) | set(fences)):
        fm = fences.get(t)
        fence = (
            FenceFrame(fm.drive_angle, np.asarray(fm.node_x), np.asarray(fm.node_y),
                       fm.tip_deflection)
            if fm is not None
            else None
        )  # fmt: skip
        parcels = []
        for s in loads.get(t, []):
            spec = specs.get(s.parcel_id)
            a = spec.length_a if spec else 0.4
            b = spec.width_b if spec else 0.3
            h = spec.height if spec else 0.3
            xp = spec.cog_offset_x if spec else 0.0
            yp = spec.cog_offset_y if spec else 0.0
            q = s.pose.orientation
            yaw = 2.0 * math.atan2(q.z, q.w)
            c, sn = math.cos(yaw), math.sin(yaw)
            x, y = s.pose.position.x, s.pose.position.y
            parcels.append(
                ParcelFrame(
                    int(s.parcel_id), x, y, yaw, s.twist.linear.x, s.twist.linear.y,
                    x - c * xp + sn * yp, y - sn * xp - c * yp, a, b, h,
                    s.contact_normal_force, s.contact_normal_force_stiff,
                    s.contact_point.x, s.contact_point.y,
                    bool(spec.divert) if spec else False, int(s.stage),
                )
            )  # fmt: skip
        yield t, fence, parcels
