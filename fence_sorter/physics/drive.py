"""Fence drive with sinusoidal angular velocity (paper section 2; model notes "Drive").

Working motion over t1 and return motion over t2 = t1 in one formula:
alpha_w(tau) = (alpha_k / 2) (1 - cos(pi tau / t1)) for 0 <= tau <= 2 t1, so the angular velocity
is a sine arch peaking at pi alpha_k / (2 t1) mid-stroke and the fence is back at 0 at tau = 2 t1.
The drive is "stiff": root angle, rate and acceleration are prescribed exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .params import DriveParams


@dataclass(frozen=True)
class DriveState:
    alpha: float  # alpha_w [rad]
    rate: float  # [rad/s]
    accel: float  # [rad/s^2]


def drive_state(drive: DriveParams, t: float) -> DriveState:
    """Root angle, rate and acceleration at time t (the drive starts at t = 0).

    The acceleration jumps at t = 0 (to alpha_k pi^2 / (2 t1^2)) and at t = 2 t1 (back to 0);
    at those instants this returns the value inside the motion (right limit at 0, left limit at
    2 t1); a time step starting at 2 t1 uses :func:`accel_jump_at` to take the right limit.
    """
    t1 = drive.t1
    if t < 0.0 or t > 2.0 * t1:
        return DriveState(0.0, 0.0, 0.0)
    w = math.pi / t1
    half = 0.5 * drive.alpha_k
    return DriveState(
        half * (1.0 - math.cos(w * t)), half * w * math.sin(w * t), half * w * w * math.cos(w * t)
    )


def accel_jump_at(drive: DriveParams, t: float) -> float:
    """Right minus left limit of the drive acceleration at t (nonzero only at the end, 2 t1)."""
    if abs(t - 2.0 * drive.t1) <= 1e-12:
        return -0.5 * drive.alpha_k * (math.pi / drive.t1) ** 2
    return 0.0


def breakpoints(drive: DriveParams) -> tuple[float, float, float]:
    """Times where the drive's acceleration jumps (start, end of work, end of return)."""
    return (0.0, drive.t1, 2.0 * drive.t1)


def peak_rate(drive: DriveParams) -> float:
    """Peak angular velocity pi alpha_k / (2 t1) [rad/s]."""
    return math.pi * drive.alpha_k / (2.0 * drive.t1)
