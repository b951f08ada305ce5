"""A measured bag's parcels as the fit sees them: each parcel's samples from its stroke start,
the camera frame aligned to the sorter's, the twin's prediction at those samples, and the
errors of a calibration (bad input: exit 2; a failed fit: exit 3)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fence_sorter.physics.params import SolverParams
from fence_sorter.physics.parcel import initial_pose, parcel_body
from fence_sorter.physics.simulate import Scenario

from .bag import MeasuredBag
from .replay import ParcelEvent, replay
from .sensors import geometric_centre

#: seconds before a stroke where the root moment is read as the gauge's noise
PRE_WINDOW = 0.5
#: after a stroke's cycle, how long the fence rings down before a root moment reads it at rest
#: [s] (the line's solver.settle_time: a run's fence follows its stroke's solve that long)
RING_DOWN = SolverParams().settle_time


class CalibrationInputError(ValueError):
    """Bad input to a calibration (exit 2): the message names what is wrong."""


class FitError(RuntimeError):
    """The fit failed: a replay diverged or the optimiser did not converge (exit 3)."""


@dataclass
class EventData:
    """One parcel's measured samples, sorter frame, times from its stroke start [s]."""

    ev: ParcelEvent
    cam_tau: np.ndarray
    cam_x: np.ndarray
    cam_y: np.ndarray
    cam_yaw: np.ndarray
    str_tau: np.ndarray
    str_m: np.ndarray


def pre_stroke_centre(base: Scenario, ev: ParcelEvent, tau: np.ndarray):
    """Geometric centre and yaw of a parcel riding the belt before its stroke (tau <= 0)."""
    body = parcel_body(ev.parcel, base.conveyor)
    xc, yc, yaw = initial_pose(body, ev.r_s, ev.parcel.lateral_gap, ev.parcel.yaw)
    x0, y0 = geometric_centre(xc, yc, yaw, ev.parcel.cog_offset_x, ev.parcel.cog_offset_y)
    v = base.conveyor.belt_speed
    return x0 + v * tau, np.full_like(tau, y0), np.full_like(tau, yaw)


def align_camera(base: Scenario, mb: MeasuredBag) -> tuple[tuple[float, float, float], float]:
    """The camera frame in the sorter frame (x, y, yaw) from the pre-stroke poses (Kabsch), and
    the RMS distance left [m]."""
    m = mb.m
    src, dst = [], []
    for ev in mb.events:
        sel = (m.cam_id == ev.parcel_id) & (m.cam_t < ev.t_start)
        if not sel.any():
            continue
        px, py, _ = pre_stroke_centre(base, ev, m.cam_t[sel] - ev.t_start)
        src.append(np.column_stack([m.cam_x[sel], m.cam_y[sel]]))
        dst.append(np.column_stack([px, py]))
    if not src or sum(len(s) for s in src) < 3:
        raise CalibrationInputError(
            f"{mb.path}: the camera sees fewer than 3 parcel poses before the strokes start; "
            "the camera frame cannot be aligned"
        )
    a, b = np.concatenate(src), np.concatenate(dst)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    h = (a - ca).T @ (b - cb)
    theta = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    d = cb - rot @ ca
    rms = float(np.sqrt(np.mean(np.sum((a @ rot.T + d - b) ** 2, axis=1))))
    return (float(d[0]), float(d[1]), theta), rms


def event_data(mb: MeasuredBag, ring_down: float = RING_DOWN) -> list[EventData]:
    """Each parcel's samples (camera frame), times from its stroke start, to its replay's end.

    The root moment's window is what its replay explains with the fence at rest before the
    stroke: from PRE_WINDOW before the stroke, but not within ``ring_down`` after the previous
    stroke's cycle (the fence still rings; a run's line follows it for solver.settle_time), and
    up to the next stroke's start (whose solve starts with the fence at rest).
    """
    m = mb.m
    out = []
    events = sorted(mb.events, key=lambda e: e.t_start)
    for ev in mb.events:
        k = events.index(ev)
        sel = m.cam_id == ev.parcel_id
        tau = m.cam_t[sel] - ev.t_start
        keep = tau < ev.t_end - 1e-6
        lo, hi = ev.t_start - PRE_WINDOW, ev.t_start + ev.t_end - 1e-6
        if k > 0:
            prev = events[k - 1]
            lo = max(lo, prev.t_start + 2.0 * prev.t1 + ring_down)
        if k + 1 < len(events):
            hi = min(hi, events[k + 1].t_start - 1e-6)
        ssel = (m.str_t >= lo) & (m.str_t < hi)
        out.append(
            EventData(
                ev,
                tau[keep],
                m.cam_x[sel][keep],
                m.cam_y[sel][keep],
                m.cam_yaw[sel][keep],
                m.str_t[ssel] - ev.t_start,
                m.str_moment[ssel],
            )
        )
    return out


def predict(base: Scenario, ed: EventData, values: dict[str, float]):
    """The twin's replay sampled where this parcel was measured: x, y, yaw, moment."""
    tr = replay(base, ed.ev, values)
    x, y, yaw = tr.pose_at(ed.cam_tau)
    return x, y, yaw, tr.moment_at(ed.str_tau)
