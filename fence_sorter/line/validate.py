"""Checks of incoming parcels and commands: plain functions raising errors that name the field.

The simulator node counts rejections per :attr:`InputError.key` and logs the message; the
ranges follow :class:`fence_sorter.physics.params.ParcelParams` so an accepted parcel always
builds a valid physics Scenario.
"""

from __future__ import annotations

import math
from collections.abc import Container

from fence_sorter.physics.params import ParcelParams

from .types import ParcelSpec, StartMode, StrokeCommand

#: reason keys reported in diagnostics (one counter each)
PARCEL_REASONS = (
    "non_finite",
    "mass",
    "size",
    "cog_offset",
    "lateral_gap",
    "yaw",
    "friction",
    "wider_than_belt",
    "duplicate_id",
)


class InputError(ValueError):
    """A parcel or command field is invalid; ``key`` is its diagnostics category."""

    def __init__(self, key: str, field: str, message: str):
        super().__init__(message)
        self.key = key
        self.field = field


def _range(key: str, field: str, value: float, lo: float, hi: float, unit: str, lo_open=False):
    ok = (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise InputError(
            key, field, f"{field} must be in {bracket}{lo:g}, {hi:g}] {unit}, got {value!r}"
        )


FLOAT_FIELDS = (
    "length_a",
    "width_b",
    "height",
    "mass",
    "cog_offset_x",
    "cog_offset_y",
    "lateral_gap",
    "yaw",
    "scan_time",
    "scan_position_x",
)


def validate_parcel(p: ParcelSpec, belt_width: float, known_ids: Container[int] = ()) -> None:
    """Raise :class:`InputError` naming the field and its allowed range, or return.

    NaN/Inf anywhere (except mu_belt/mu_fence, where NaN means "configured default"), mass
    <= 0 or beyond 500 kg, sizes outside [5 mm, 3 m], C_s outside the footprint, yaw outside
    [-pi/2, pi/2], a footprint wider than the belt (Delta_s + B > s at yaw 0), a known id.
    """
    for name in FLOAT_FIELDS:
        value = getattr(p, name)
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError("non_finite", name, f"{name} must be a finite number, got {value!r}")
    for name in ("mu_belt", "mu_fence"):
        value = getattr(p, name)
        if math.isinf(value):
            raise InputError("non_finite", name, f"{name} must be finite or NaN, got {value!r}")
        if not math.isnan(value):
            _range("friction", name, value, 0.0, 2.0, "(NaN: configured default)")
    _range("mass", "mass", p.mass, 0.01, 500.0, "kg")
    for name in ("length_a", "width_b", "height"):
        _range("size", name, getattr(p, name), 0.005, 3.0, "m")
    _range("cog_offset", "cog_offset_x", abs(p.cog_offset_x), 0.0, 0.5 * p.length_a, "m (|x_p|)")
    _range("cog_offset", "cog_offset_y", abs(p.cog_offset_y), 0.0, 0.5 * p.width_b, "m (|y_p|)")
    _range("yaw", "yaw", p.yaw, -0.5 * math.pi, 0.5 * math.pi, "rad")
    _range("lateral_gap", "lateral_gap", p.lateral_gap, 0.0, belt_width, "m")
    width = physics_parcel(p).footprint_width()
    if p.lateral_gap + width > belt_width + 1e-12:
        raise InputError(
            "wider_than_belt",
            "width_b",
            f"lateral_gap + footprint width across the belt (width_b at yaw 0) "
            f"({p.lateral_gap:g} + {width:.4g} m) exceeds the belt "
            f"width s = {belt_width:g} m; lateral_gap must be in "
            f"[0, {max(belt_width - width, 0.0):.4g}] m for this parcel",
        )
    if p.parcel_id in known_ids:
        raise InputError(
            "duplicate_id", "parcel_id", f"parcel_id {p.parcel_id} is already on the line"
        )


def physics_parcel(p: ParcelSpec) -> ParcelParams:
    """The physics core's ParcelParams of a parcel spec."""
    return ParcelParams(
        length_a=float(p.length_a),
        width_b=float(p.width_b),
        height=float(p.height),
        mass=float(p.mass),
        cog_offset_x=float(p.cog_offset_x),
        cog_offset_y=float(p.cog_offset_y),
        lateral_gap=float(p.lateral_gap),
        yaw=float(p.yaw),
    )


def validate_command(c: StrokeCommand, r_s_range: tuple[float, float]) -> None:
    """Raise :class:`InputError` (key ``invalid``) for a feasible command with bad numbers."""
    if not c.feasible:
        return
    for name in ("r_s", "start_time", "t1", "alpha_k"):
        value = getattr(c, name)
        if not math.isfinite(value):
            raise InputError("invalid", name, f"{name} must be a finite number, got {value!r}")
    if c.start_mode not in (StartMode.AT_RS, StartMode.AT_TIME):
        raise InputError(
            "invalid", "start_mode", f"start_mode must be 0 or 1, got {c.start_mode!r}"
        )
    _range("invalid", "t1", c.t1, 0.02, 10.0, "s")
    _range("invalid", "alpha_k", c.alpha_k, 0.0, 0.5 * math.pi, "rad", lo_open=True)
    if c.start_mode == StartMode.AT_RS:
        _range("invalid", "r_s", c.r_s, r_s_range[0], r_s_range[1], "m (paper range (3))")
