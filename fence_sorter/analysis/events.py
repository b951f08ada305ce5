"""Sorting events at the solver's resolution (/sort_events, SortEvent) as arrays, their peaks,
and the damage risk of every parcel.

A SortEvent holds every accepted step of one stroke's solve up to the parcel's outcome, so the
figures the simulator published on /sort_outcomes follow from it again: peak N is the largest N
of the steps or, where three steps around a local maximum share one contact set, the vertex of
the parabola through them (the rule of the solve loop's reductions, ``kernel.observe``); peak
a_N = peak N / m_p; peak N_stiff the largest of the impacts' N_stiff; w_n the first impact's
normal speed. The N_stiff course (Fig. 11c, 12c) is in the message, on its own time grid.
Times here are sim time [s]; SI units throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fence_sorter.capacity.constraints import ConstraintProfile, damage_risk
from fence_sorter.stamps import time_to_sec

NAN = math.nan
#: the event's peaks must match the live outcome's within this (analyze's check)
EVENT_PEAK_RTOL = 0.005


def _arr(values, dtype=float) -> np.ndarray:
    return np.asarray(values, dtype=dtype)


@dataclass
class SortEventData:
    """One SortEvent as arrays; ``t``, ``impact_t`` and ``stiff_t`` in sim time [s]."""

    parcel_id: int
    t_outcome: float
    start_time: float
    mass: float
    t: np.ndarray
    stage: np.ndarray
    contact_set: np.ndarray
    normal_force: np.ndarray  # N [N]
    normal_accel: np.ndarray  # a_N [m/s^2]
    deformation: np.ndarray  # D [m]
    tip_deflection: np.ndarray  # [m]
    drive_angle: np.ndarray  # [rad]
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    impact_t: np.ndarray
    impact_speed: np.ndarray  # w_n [m/s]
    impact_force_stiff: np.ndarray  # [N]
    stiff_t: np.ndarray
    stiff_force: np.ndarray  # N_stiff [N]

    @classmethod
    def from_msg(cls, msg) -> SortEventData:
        """From a SortEvent (rclpy or rosbags message: the same field names)."""
        t0 = time_to_sec(msg.start_time)
        return cls(
            int(msg.parcel_id), time_to_sec(msg.header.stamp), t0, float(msg.mass),
            t0 + _arr(msg.t), _arr(msg.stage, np.uint8), _arr(msg.contact_set, np.int64),
            _arr(msg.normal_force), _arr(msg.normal_accel), _arr(msg.deformation),
            _arr(msg.tip_deflection), _arr(msg.drive_angle), _arr(msg.x), _arr(msg.y),
            _arr(msg.yaw), _arr(msg.vx), _arr(msg.vy), t0 + _arr(msg.impact_t),
            _arr(msg.impact_speed), _arr(msg.impact_force_stiff), t0 + _arr(msg.stiff_t),
            _arr(msg.stiff_force),
        )  # fmt: skip

    @property
    def steps(self) -> int:
        return int(self.t.size)

    def impact_window(self, k: int = 0) -> tuple[float, float] | None:
        """[onset, end] of impact ``k`` [s]: until both N and N_stiff are back at 0."""
        if k >= self.impact_t.size:
            return None
        t0 = float(self.impact_t[k])
        t_next = float(self.impact_t[k + 1]) if k + 1 < self.impact_t.size else math.inf
        after = (self.t > t0) & (self.t < t_next) & (self.normal_force <= 0.0)
        t_n = float(self.t[after][0]) if np.any(after) else float(self.t[-1])
        stiff = self.stiff_t[(self.stiff_t >= t0) & (self.stiff_t < t_next)]
        t_s = float(stiff[-1]) if stiff.size else t0
        return t0, max(t_n, t_s)


def refined_peak(t: np.ndarray, n: np.ndarray, contact_set: np.ndarray) -> float:
    """Largest N of the steps, or the vertex of the parabola through three steps around a
    local maximum that share one contact set (N is smooth there), whichever is larger."""
    if n.size == 0:
        return NAN
    peak = max(float(np.max(n)), 0.0)
    if n.size < 3:
        return peak
    n0, n1, n2 = n[:-2], n[1:-1], n[2:]
    same = (contact_set[:-2] == contact_set[1:-1]) & (contact_set[1:-1] == contact_set[2:])
    for i in np.flatnonzero(same & (n1 > n0) & (n1 >= n2) & (n0 > 0.0)):
        peak = max(peak, _parabola_peak(t[i], n0[i], t[i + 1], n1[i], t[i + 2], n2[i]))
    return peak


def _parabola_peak(t0, n0, t1, n1, t2, n2) -> float:
    """Vertex value of the parabola through three points with n1 >= n0, n2 (else n1), as
    :func:`fence_sorter.physics.kernel.parabola_peak`."""
    d0, d2 = t0 - t1, t2 - t1
    if d0 >= 0.0 or d2 <= 0.0:
        return float(n1)
    c = ((n0 - n1) / d0 - (n2 - n1) / d2) / (d0 - d2)
    b = (n0 - n1) / d0 - c * d0
    if c >= 0.0:
        return float(n1)
    d = -b / (2.0 * c)
    if not d0 <= d <= d2:
        return float(n1)
    return float(n1 + b * d + c * d * d)


def event_figures(ev: SortEventData) -> dict:
    """The live outcome's figures re-derived from one event (NaN where it has no contact)."""
    touched = ev.impact_t.size > 0
    peak_n = refined_peak(ev.t, ev.normal_force, ev.contact_set) if ev.steps else NAN
    return {
        "steps": ev.steps,
        "peak_normal_force": peak_n,
        "peak_normal_force_stiff": float(np.max(ev.impact_force_stiff)) if touched else 0.0,
        "peak_normal_accel": peak_n / ev.mass if ev.mass > 0 else NAN,
        "impact_normal_speed": float(ev.impact_speed[0]) if touched else NAN,
        "peak_tip_deflection": float(np.max(np.abs(ev.tip_deflection))) if ev.steps else NAN,
    }


def check_event(figures: dict, outcome: dict) -> list[str]:
    """Where an event's peaks differ from the live outcome's by more than EVENT_PEAK_RTOL."""
    out = []
    for key in ("peak_normal_force", "peak_normal_force_stiff", "impact_normal_speed"):
        ev, live = figures[key], outcome[key]
        if not (math.isfinite(live) or math.isfinite(ev)):
            continue
        if not (math.isfinite(ev) and math.isfinite(live)) or abs(ev - live) > (
            EVENT_PEAK_RTOL * abs(live) + 1e-9
        ):
            out.append(f"event {key} {ev:.6g}, live {live:.6g}")
    return out


def risk_of(outcome: dict) -> dict:
    """Damage risk of a live outcome: its limits (the paper's when the bag predates them), the
    margins and the drop height from the closed forms of
    :func:`fence_sorter.capacity.constraints.damage_risk`."""
    w_dop = outcome.get("w_dop", NAN)
    a_ndop = outcome.get("a_ndop", NAN)
    default = ConstraintProfile()
    limits = ConstraintProfile(
        w_dop=w_dop if w_dop > 0 else default.w_dop,
        a_ndop=a_ndop if a_ndop > 0 else default.a_ndop,
    )
    r = damage_risk(outcome["impact_normal_speed"], outcome["peak_normal_accel"], limits)
    return {
        "w_dop": limits.w_dop,
        "a_ndop": limits.a_ndop,
        "impact_speed_margin": r.impact_speed_margin,
        "accel_margin": r.accel_margin,
        "drop_height": r.drop_height,
    }


def risk_summary(rows: list[dict], worst: int = 3) -> dict:
    """Share of the parcels with an impact over each limit, and the worst parcels (smallest
    margin of the two); failed events (``failed`` rows) are not physics and left out."""
    hit = [
        r for r in rows if not r.get("failed") and math.isfinite(r.get("impact_speed_margin", NAN))
    ]
    over_w = [r["parcel_id"] for r in hit if r["impact_speed_margin"] < 0.0]
    over_a = [r["parcel_id"] for r in hit if r["accel_margin"] < 0.0]
    ranked = sorted(hit, key=lambda r: min(r["impact_speed_margin"], r["accel_margin"]))
    return {
        "parcels_with_impact": len(hit),
        "share_over_w_dop": len(over_w) / len(hit) if hit else NAN,
        "share_over_a_ndop": len(over_a) / len(hit) if hit else NAN,
        "parcels_over_w_dop": over_w,
        "parcels_over_a_ndop": over_a,
        "worst_parcels": [
            {
                "parcel_id": r["parcel_id"],
                "impact_speed_margin": r["impact_speed_margin"],
                "accel_margin": r["accel_margin"],
                "drop_height_m": r["drop_height_m"],
            }
            for r in ranked[:worst]
        ],
    }
