"""Constraints (7)-(12) of section 3 as margins (<= 0 feasible) from one simulated stroke.

(7)  (A - R_s) / v - t1 <= 0          the load front is in the working space within t1 [s]
(8)  -y_k + s <= 0                     C_s reaches the chute edge y0 = s [m]
(9)  -T_g <= 0                         the fence catches the load before it escapes [m]
(10) w_n - w_dop <= 0                  impact speed [m/s]
(11) a_N - a_Ndop <= 0                 acceleration exerted by the fence [m/s^2]
(12) ydot - ydot_dop <= 0              exit speed towards the chute [m/s]

T_g (9) is not defined in closed form by the paper; we take, at the first contact onset t_c,
the distance along x0 from the load's rear edge to the fence tip, x_tip(t_c) - x_rear(t_c)
(the load still rides the belt until t_c); a load the fence never touches gets
T_g = R_z - x_rear(t_end) (negative once the rear has passed the tip).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from fence_sorter.physics.params import GRAVITY, ParameterError, ParcelParams, check_range

CONSTRAINT_IDS = (7, 8, 9, 10, 11, 12)
CONSTRAINT_TEXT = {
    7: "(7) working time: (A - R_s)/v - t1 <= 0 [s]",
    8: "(8) push-off: s - y_k <= 0 [m]",
    9: "(9) catch before escape: -T_g <= 0 [m]",
    10: "(10) impact speed: w_n - w_dop <= 0 [m/s]",
    11: "(11) acceleration: a_N - a_Ndop <= 0 [m/s^2]",
    12: "(12) exit speed: ydot - ydot_dop <= 0 [m/s]",
}


@dataclass(frozen=True)
class ConstraintProfile:
    """Limits of (10)-(12) and the constraints that count (paper values by default)."""

    w_dop: float = 2.4  # [m/s], free fall from 0.3 m
    a_ndop: float = 300.0  # [m/s^2]
    ydot_dop: float = 2.5  # [m/s]
    active: tuple[int, ...] = CONSTRAINT_IDS

    def validate(self, prefix: str = "constraints") -> ConstraintProfile:
        """Raise ParameterError naming the field and its range; return self."""
        check_range(f"{prefix}.w_dop", self.w_dop, 0.0, 100.0, lo_open=True, unit="m/s")
        check_range(f"{prefix}.a_ndop", self.a_ndop, 0.0, 1e5, lo_open=True, unit="m/s^2")
        check_range(f"{prefix}.ydot_dop", self.ydot_dop, 0.0, 100.0, lo_open=True, unit="m/s")
        bad = [c for c in self.active if c not in CONSTRAINT_IDS]
        if bad or len(set(self.active)) != len(self.active):
            raise ParameterError(
                f"{prefix}.active must be distinct constraint numbers from "
                f"{list(CONSTRAINT_IDS)}, got {list(self.active)}"
            )
        return self

    @classmethod
    def from_mapping(cls, data: Mapping, prefix: str = "constraints") -> ConstraintProfile:
        """Build from a config mapping (keys w_dop, a_ndop, ydot_dop, active); validated."""
        allowed = ("w_dop", "a_ndop", "ydot_dop", "active")
        unknown = [k for k in data if k not in allowed]
        if unknown:
            raise ParameterError(
                f"{prefix}.{unknown[0]} is not a known key; allowed: {', '.join(allowed)}"
            )
        kwargs = {}
        for key in ("w_dop", "a_ndop", "ydot_dop"):
            if key in data:
                kwargs[key] = _number(f"{prefix}.{key}", data[key])
        if "active" in data:
            active = data["active"]
            if not isinstance(active, (list, tuple)) or not all(
                isinstance(c, int) and not isinstance(c, bool) for c in active
            ):
                raise ParameterError(
                    f"{prefix}.active must be a list of constraint numbers from "
                    f"{list(CONSTRAINT_IDS)}, got {active!r}"
                )
            kwargs["active"] = tuple(active)
        return cls(**kwargs).validate(prefix)


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{name} must be a number, got {value!r}")
    return float(value)


def drive_angle(alpha_k: float, t1: float, t: float) -> float:
    """alpha_w(t): sinusoidal-velocity stroke out over t1 and back over t2 = t1 [rad]."""
    if t <= 0.0:
        return 0.0
    if t <= t1:
        return 0.5 * alpha_k * (1.0 - math.cos(math.pi * t / t1))
    if t <= 2.0 * t1:
        return 0.5 * alpha_k * (1.0 - math.cos(math.pi * (2.0 * t1 - t) / t1))
    return 0.0


def footprint_length(parcel: ParcelParams) -> float:
    """Extent of the yawed load along the belt [m] (A for phi = 0)."""
    c, s = abs(math.cos(parcel.yaw)), abs(math.sin(parcel.yaw))
    return parcel.length_a * c + parcel.width_b * s


def margin_working_time(a: float, r_s: float, v: float, t1: float) -> float:
    """(7): (A - R_s)/v - t1 [s]; analytic, no simulation needed."""
    return (a - r_s) / v - t1


def margins(
    result,
    parcel: ParcelParams,
    *,
    r_s: float,
    t1: float,
    alpha_k: float,
    v: float,
    belt_width: float,
    fence_length: float,
    profile: ConstraintProfile,
) -> dict[int, float]:
    """Margins of (7)-(12) for one simulated stroke (a SimulationResult); <= 0 is feasible.

    (12) is NaN when the load never crossed y0 = s (no exit speed); (8) is then violated.
    """
    a = footprint_length(parcel)
    out = {7: margin_working_time(a, r_s, v, t1)}
    y_k = result.y_max if math.isfinite(result.y_max) else -math.inf
    out[8] = belt_width - y_k
    if result.impacts:
        t_c = result.impacts[0][0]
        x_rear = r_s - a + v * t_c
        x_tip = fence_length * math.cos(drive_angle(alpha_k, t1, t_c))
        t_g = x_tip - x_rear
    else:
        t_g = fence_length - (r_s - a + v * result.sim_time)
    out[9] = -t_g
    w_n = result.impact_normal_speed if math.isfinite(result.impact_normal_speed) else 0.0
    out[10] = w_n - profile.w_dop
    out[11] = result.peak_normal_accel - profile.a_ndop
    out[12] = result.exit_speed_y - profile.ydot_dop if result.sorted else math.nan
    return {k: float(v) for k, v in out.items()}


def violated(margin: Mapping[int, float], active: Iterable[int]) -> tuple[int, ...]:
    """Active constraints whose margin is > 0 (or NaN, except (12) of an unsorted load)."""
    bad = []
    for c in active:
        m = margin.get(c, math.nan)
        if c == 12 and math.isnan(m):
            continue  # no exit speed: the load was not pushed off, which (8) reports
        if not m <= 0.0:
            bad.append(c)
    return tuple(bad)


@dataclass(frozen=True)
class DamageRisk:
    """How close one impact came to the drop-test limits of (10) and (11).

    A margin is the share of the limit left, 1 - value / limit: 0 at the limit, < 0 over it
    (-0.5: 50 % over). ``drop_height`` h = w_n^2 / (2 g) is the height
    of the free fall that hits the ground at the impact's normal speed w_n (the drop test the
    limits come from: w_dop = 2.4 m/s is h = 0.294 m). NaN where the figure is NaN (no
    stroke, or no contact).
    """

    impact_speed_margin: float  # 1 - w_n / w_dop [-]
    accel_margin: float  # 1 - a_N / a_Ndop [-]
    drop_height: float  # [m]


def damage_risk(impact_speed: float, peak_accel: float, profile: ConstraintProfile) -> DamageRisk:
    """Margins of an impact at normal speed w_n with peak acceleration a_N (NaN: no stroke)
    against ``profile``'s w_dop and a_Ndop, and its equivalent drop height."""
    return DamageRisk(
        1.0 - impact_speed / profile.w_dop,
        1.0 - peak_accel / profile.a_ndop,
        impact_speed * impact_speed / (2.0 * GRAVITY),
    )
