"""What enters the line from outside: scanned parcels and stroke commands, and their one check.

:class:`ParcelSpec` is the one plain-data parcel of every layer (a stream's parcel, the
scanner's /parcels message, the controller's and the simulator's input); :class:`StrokeCommand`
the fence command. :func:`validate_parcel` and :func:`validate_command` are the one validation
of both, shared by the stream loaders, the controller and the simulator's line: each raises
:class:`InputError` naming the field and its allowed range, and its ``key`` is the counter the
nodes report on /diagnostics. ROS-free and light (no physics import beyond the parameter
dataclasses), so the stream loader and the nodes use the very same checks.

Frame "sorter" (the paper's O x0 y0), SI units, angles in rad, times in sim seconds.
"""

from __future__ import annotations

import math
from collections.abc import Container
from dataclasses import dataclass, fields

from fence_sorter.codes import StartMode
from fence_sorter.physics.params import ParcelParams

NAN = math.nan

#: parcel ids are uint32 on the wire
PARCEL_ID_MAX = 2**32 - 1
#: a parcel's scan_time may lie this far behind the receiver's clock [s] (a parcel scanned
#: earlier than this has long left the line at any belt speed of the scenes)
SCAN_TIME_PAST = 10.0
#: ... and this far ahead of it [s] (the scanner follows the simulator's /clock, so a real
#: parcel is never ahead by more than a message's delay)
SCAN_TIME_AHEAD = 2.0
#: scan_position_x may lie this far from the scan line [m]
SCAN_LINE_TOLERANCE = 0.5
#: absolute bound of any position along the belt [m]
POSITION_LIMIT = 100.0
#: longest stream [s] (arrival_time)
ARRIVAL_TIME_MAX = 1e7

#: reason keys of rejected parcels (one diagnostics counter each)
PARCEL_REASONS = (
    "non_finite",
    "parcel_id",
    "mass",
    "size",
    "cog_offset",
    "lateral_gap",
    "yaw",
    "friction",
    "wider_than_belt",
    "duplicate_id",
    "scan_time",
    "scan_position",
    "arrival_time",
)


@dataclass(frozen=True)
class ParcelSpec:
    """A parcel: a stream's entry and a scanned parcel (fence_sorter_msgs/Parcel).

    ``mu_belt``/``mu_fence`` NaN: the scene's mu1 / mu2. ``scan_position_x`` is the front's x0
    at ``scan_time`` (sim time [s]); the belt carries the front on at speed v.
    ``arrival_time``: in a stream, when the front crosses the scan line, s after its start.
    """

    parcel_id: int
    length_a: float = 0.4  # A [m]
    width_b: float = 0.3  # B [m]
    height: float = 0.3  # [m] (visuals only)
    mass: float = 15.0  # m_p [kg]
    cog_offset_x: float = 0.0  # x_p [m]
    cog_offset_y: float = 0.0  # y_p [m]
    lateral_gap: float = 0.0  # Delta_s [m]
    yaw: float = 0.0  # phi [rad]
    mu_belt: float = NAN
    mu_fence: float = NAN
    divert: bool = False
    scan_time: float = 0.0  # [s]
    scan_position_x: float = -2.0  # [m]
    arrival_time: float = 0.0  # [s] after the stream start

    def to_parcel_params(self) -> ParcelParams:
        """The physics core's ParcelParams of this parcel."""
        return ParcelParams(
            length_a=float(self.length_a),
            width_b=float(self.width_b),
            height=float(self.height),
            mass=float(self.mass),
            cog_offset_x=float(self.cog_offset_x),
            cog_offset_y=float(self.cog_offset_y),
            lateral_gap=float(self.lateral_gap),
            yaw=float(self.yaw),
        )


@dataclass(frozen=True)
class StrokeCommand:
    """A fence stroke for one parcel (fence_sorter_msgs/FenceCommand without header/predictions).

    ``feasible`` False: the controller found no stroke meeting the constraints; ``reason`` says
    why and the parcel passes unsorted (outcome NO_FEASIBLE_COMMAND).
    """

    parcel_id: int
    start_mode: StartMode = StartMode.AT_RS
    r_s: float = 0.0  # R_s [m] (AT_RS)
    start_time: float = 0.0  # [s] (AT_TIME)
    t1: float = 0.5  # working time [s]
    alpha_k: float = math.radians(40.0)  # [rad]
    feasible: bool = True
    reason: str = ""


class InputError(ValueError):
    """A parcel or command field is invalid; ``key`` is its diagnostics category."""

    def __init__(self, key: str, field: str, message: str):
        super().__init__(message)
        self.key = key
        self.field = field


def check_range(key: str, field: str, value, lo: float, hi: float, unit: str, lo_open=False):
    """Raise InputError unless lo <= value <= hi (lo < value with ``lo_open``)."""
    ok = (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise InputError(
            key, field, f"{field} must be in {bracket}{lo:g}, {hi:g}] {unit}, got {value!r}"
        )


#: the fields that must be finite numbers (mu_belt/mu_fence may be NaN: the scene's value)
FLOAT_FIELDS = tuple(
    f.name for f in fields(ParcelSpec) if f.type == "float" and not f.name.startswith("mu_")
)


def validate_parcel(
    p: ParcelSpec,
    belt_width: float,
    known_ids: Container[int] = (),
    *,
    now: float | None = None,
    scan_line_x: float | None = None,
    scan_line_tolerance: float = SCAN_LINE_TOLERANCE,
) -> None:
    """Raise :class:`InputError` naming the field and its allowed range, or return.

    Every field has a range: parcel_id a uint32; NaN/Inf nowhere (except mu_belt/mu_fence,
    where NaN means "the scene's value"); mass in [0.01, 500] kg; sizes in [5 mm, 3 m]; C_s
    inside the footprint; yaw in [-pi/2, pi/2]; mu in [0, 2]; the footprint within the belt
    (Delta_s + footprint width <= s); arrival_time in [0, 1e7] s; scan_position_x within
    +-100 m. With ``now`` (the receiver's sim time), scan_time in [now - SCAN_TIME_PAST,
    now + SCAN_TIME_AHEAD]; with ``scan_line_x``, scan_position_x within
    ``scan_line_tolerance`` of it. A parcel_id in ``known_ids`` is a duplicate.
    """
    pid = p.parcel_id
    if isinstance(pid, bool) or not isinstance(pid, int) or not 0 <= pid <= PARCEL_ID_MAX:
        raise InputError(
            "parcel_id", "parcel_id", f"parcel_id must be in [0, {PARCEL_ID_MAX}], got {pid!r}"
        )
    for name in FLOAT_FIELDS:
        value = getattr(p, name)
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError("non_finite", name, f"{name} must be a finite number, got {value!r}")
    for name in ("mu_belt", "mu_fence"):
        value = getattr(p, name)
        if not isinstance(value, (int, float)) or math.isinf(value):
            raise InputError("non_finite", name, f"{name} must be finite or NaN, got {value!r}")
        if not math.isnan(value):
            check_range("friction", name, value, 0.0, 2.0, "(NaN: the scene's value)")
    check_range("mass", "mass", p.mass, 0.01, 500.0, "kg")
    for name in ("length_a", "width_b", "height"):
        check_range("size", name, getattr(p, name), 0.005, 3.0, "m")
    check_range("cog_offset", "cog_offset_x", abs(p.cog_offset_x), 0.0, 0.5 * p.length_a, "m")
    check_range("cog_offset", "cog_offset_y", abs(p.cog_offset_y), 0.0, 0.5 * p.width_b, "m")
    check_range("yaw", "yaw", p.yaw, -0.5 * math.pi, 0.5 * math.pi, "rad")
    check_range("lateral_gap", "lateral_gap", p.lateral_gap, 0.0, belt_width, "m")
    width = p.to_parcel_params().footprint_width()
    if p.lateral_gap + width > belt_width + 1e-12:
        raise InputError(
            "wider_than_belt",
            "width_b",
            f"lateral_gap + footprint width across the belt (width_b at yaw 0) "
            f"({p.lateral_gap:g} + {width:.4g} m) exceeds the belt "
            f"width s = {belt_width:g} m; lateral_gap must be in "
            f"[0, {max(belt_width - width, 0.0):.4g}] m for this parcel",
        )
    check_range("arrival_time", "arrival_time", p.arrival_time, 0.0, ARRIVAL_TIME_MAX, "s")
    check_range(
        "scan_position", "scan_position_x", p.scan_position_x, -POSITION_LIMIT, POSITION_LIMIT, "m"
    )
    if scan_line_x is not None:
        check_range(
            "scan_position",
            "scan_position_x",
            p.scan_position_x,
            scan_line_x - scan_line_tolerance,
            scan_line_x + scan_line_tolerance,
            f"m (the scan line x0 = {scan_line_x:g} m +- {scan_line_tolerance:g} m)",
        )
    if now is not None:
        check_range(
            "scan_time",
            "scan_time",
            p.scan_time,
            now - SCAN_TIME_PAST,
            now + SCAN_TIME_AHEAD,
            f"s (now t = {now:.3f} s -{SCAN_TIME_PAST:g}/+{SCAN_TIME_AHEAD:g} s)",
        )
    if pid in known_ids:
        raise InputError("duplicate_id", "parcel_id", f"parcel_id {pid} is already known")


def validate_command(c: StrokeCommand, r_s_range: tuple[float, float]) -> None:
    """Raise :class:`InputError` (key ``invalid``) for a command with bad numbers.

    parcel_id a uint32; a feasible command: start_mode AT_RS or AT_TIME, t1 in [0.02, 10] s,
    alpha_k in (0, pi/2] rad, R_s (AT_RS) in the line's range (3), start_time finite. Whether
    the stroke fits its parcel's window is the line's check (it knows the parcel).
    """
    pid = c.parcel_id
    if isinstance(pid, bool) or not isinstance(pid, int) or not 0 <= pid <= PARCEL_ID_MAX:
        raise InputError(
            "invalid", "parcel_id", f"parcel_id must be in [0, {PARCEL_ID_MAX}], got {pid!r}"
        )
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
    check_range("invalid", "t1", c.t1, 0.02, 10.0, "s")
    check_range("invalid", "alpha_k", c.alpha_k, 0.0, 0.5 * math.pi, "rad", lo_open=True)
    if c.start_mode == StartMode.AT_RS:
        check_range("invalid", "r_s", c.r_s, r_s_range[0], r_s_range[1], "m (paper range (3))")
