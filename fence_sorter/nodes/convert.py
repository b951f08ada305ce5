"""Conversions at the ROS edge: messages to and from plain dicts and the line's dataclasses.

Dicts (the representation of fence_sorter.recording.samples): nested messages become dicts,
sequences and arrays become lists of Python numbers, so a message received over DDS compares
exactly with one read back from a bag.

Line dataclasses (:mod:`fence_sorter.line`): ``parcel_from_msg``/``parcel_to_msg``,
``command_from_msg``/``command_to_msg``, ``outcome_to_msg``/``outcome_from_msg``,
``handoff_to_msg``/``handoff_from_msg`` (a line's hand-offs) and the state
messages of a :class:`~fence_sorter.line.LineSnapshot` (FenceState, JointState, LoadState,
MarkerArray). Times are sim seconds (float) below this layer; SI units throughout.
"""

from __future__ import annotations

import array
import importlib
import math
from dataclasses import replace
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Quaternion, Vector3
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from fence_sorter.capacity.constraints import ConstraintProfile, damage_risk
from fence_sorter.codes import StartMode
from fence_sorter.inputs import ParcelSpec, StrokeCommand
from fence_sorter.line.handoff import HandOff
from fence_sorter.line.types import (
    EventTrace,
    FenceSnapshot,
    LineSnapshot,
    Outcome,
    OutcomeCode,
    ParcelSnapshot,
)
from fence_sorter.physics.params import ContactParams
from fence_sorter.stamps import time_to_sec
from fence_sorter.visualisation.frames import unit_chute
from fence_sorter_msgs.msg import (
    FenceCommand,
    FenceState,
    LoadState,
    Parcel,
    SortEvent,
    SortOutcome,
)
from fence_sorter_msgs.msg import (
    HandOff as HandOffMsg,
)

MessageDict = dict[str, Any]


def is_message(value: Any) -> bool:
    """Return True if ``value`` is an instance of a generated rclpy message class."""
    return hasattr(type(value), "get_fields_and_field_types") and hasattr(value, "__slots__")


def msg_to_dict(msg: Any) -> MessageDict:
    """Return the dict representation of an rclpy message."""
    if not is_message(msg):
        raise TypeError(f"not an rclpy message: {type(msg).__name__}")
    return {name: _to_plain(getattr(msg, name)) for name in msg.get_fields_and_field_types()}


def _to_plain(value: Any) -> Any:
    if is_message(value):
        return msg_to_dict(value)
    if isinstance(value, (array.array, np.ndarray)):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_to_plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _message_class(slot_type: Any) -> type:
    """Return the rclpy class of a rosidl NamespacedType (e.g. geometry_msgs/msg/Point)."""
    module = importlib.import_module(".".join(slot_type.namespaces))
    return getattr(module, slot_type.name)


def dict_to_msg(msg_class: type, values: MessageDict) -> Any:
    """Build an rclpy message of ``msg_class`` from its dict representation.

    Raises:
        KeyError: ``values`` names a field that ``msg_class`` does not have.

    """
    msg = msg_class()
    fields = list(msg_class.get_fields_and_field_types())
    slot_types = dict(zip(fields, msg_class.SLOT_TYPES, strict=True))
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise KeyError(f"{msg_class.__name__} has no field(s) {', '.join(unknown)}")
    for name, value in values.items():
        current = getattr(msg, name)
        if is_message(current):
            setattr(msg, name, dict_to_msg(type(current), value))
        elif value and isinstance(value, list) and isinstance(value[0], dict):
            item_class = _message_class(slot_types[name].value_type)
            setattr(msg, name, [dict_to_msg(item_class, item) for item in value])
        else:
            setattr(msg, name, value)
    return msg


# -- line dataclasses <-> fence_sorter messages ------------------------------------------------
FRAME_ID = "sorter"
JOINT_NAME = "fence_drive"
#: the damage limits of an outcome when the node is given none (the paper's (10), (11))
DEFAULT_LIMITS = ConstraintProfile()


def sec_to_time(t: float) -> Time:
    """Seconds (>= 0) -> builtin_interfaces/Time (rounded to the nanosecond)."""
    ns = max(round(t * 1e9), 0)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(t: float, frame_id: str = FRAME_ID) -> Header:
    return Header(stamp=sec_to_time(t), frame_id=frame_id)


def clock_msg(t: float) -> Clock:
    return Clock(clock=sec_to_time(t))


def parcel_from_msg(msg: Parcel) -> ParcelSpec:
    """fence_sorter_msgs/Parcel -> ParcelSpec (no checks: see fence_sorter.inputs)."""
    return ParcelSpec(
        parcel_id=int(msg.parcel_id),
        length_a=float(msg.length_a),
        width_b=float(msg.width_b),
        height=float(msg.height),
        mass=float(msg.mass),
        cog_offset_x=float(msg.cog_offset_x),
        cog_offset_y=float(msg.cog_offset_y),
        lateral_gap=float(msg.lateral_gap),
        yaw=float(msg.yaw),
        mu_belt=float(msg.mu_belt),
        mu_fence=float(msg.mu_fence),
        divert=bool(msg.divert),
        scan_time=time_to_sec(msg.scan_time),
        scan_position_x=float(msg.scan_position_x),
    )


def parcel_to_msg(
    p: ParcelSpec,
    frame_id: str = FRAME_ID,
    run_id: int = 0,
    destination: str = "",
    passes: int = 0,
) -> Parcel:
    """ParcelSpec -> fence_sorter_msgs/Parcel of run ``run_id`` stamped with its scan time
    (``destination`` and ``passes``: a line's parcel; empty and 0 on one fence)."""
    return Parcel(
        header=header(p.scan_time, frame_id),
        parcel_id=int(p.parcel_id),
        run_id=int(run_id),
        length_a=float(p.length_a),
        width_b=float(p.width_b),
        height=float(p.height),
        mass=float(p.mass),
        cog_offset_x=float(p.cog_offset_x),
        cog_offset_y=float(p.cog_offset_y),
        lateral_gap=float(p.lateral_gap),
        yaw=float(p.yaw),
        mu_belt=float(p.mu_belt),
        mu_fence=float(p.mu_fence),
        divert=bool(p.divert),
        scan_time=sec_to_time(p.scan_time),
        scan_position_x=float(p.scan_position_x),
        destination=str(destination),
        passes=int(passes),
    )


#: frame of a line's hand-offs (fence_sorter.line.line_file: x from the induction scan line)
LINE_FRAME_ID = "line"


def handoff_to_msg(h: HandOff, run_id: int = 0) -> HandOffMsg:
    """A line's HandOff record -> fence_sorter_msgs/HandOff stamped with the hand-off's sim
    time; the pose time travels as float64, so the receiver predicts the same ride."""
    return HandOffMsg(
        header=header(h.t, LINE_FRAME_ID),
        run_id=int(run_id),
        parcel=parcel_to_msg(
            replace(h.spec, parcel_id=h.parcel_id),
            LINE_FRAME_ID,
            run_id,
            h.destination,
            h.passes,
        ),
        from_unit=int(h.from_unit),
        to_unit=int(h.to_unit),
        x=float(h.x),
        y=float(h.y),
        yaw=float(h.yaw),
        vx=float(h.vx),
        vy=float(h.vy),
        yaw_rate=float(h.yaw_rate),
        pose_time=float(h.pose_time),
    )


def handoff_from_msg(msg: HandOffMsg) -> HandOff:
    """fence_sorter_msgs/HandOff -> the line's HandOff record (no checks: the receiving unit
    refuses one it cannot take, :meth:`fence_sorter.line.unit.LineUnit.check`)."""
    spec = parcel_from_msg(msg.parcel)
    return HandOff(
        parcel_id=spec.parcel_id,
        destination=str(msg.parcel.destination),
        passes=int(msg.parcel.passes),
        spec=spec,
        x=float(msg.x),
        y=float(msg.y),
        yaw=float(msg.yaw),
        vx=float(msg.vx),
        vy=float(msg.vy),
        yaw_rate=float(msg.yaw_rate),
        pose_time=float(msg.pose_time),
        t=time_to_sec(msg.header.stamp),
        from_unit=int(msg.from_unit),
        to_unit=int(msg.to_unit),
    )


def command_from_msg(msg: FenceCommand) -> StrokeCommand:
    """fence_sorter_msgs/FenceCommand -> StrokeCommand (predicted figures are not needed)."""
    mode = int(msg.start_mode)
    return StrokeCommand(
        parcel_id=int(msg.parcel_id),
        start_mode=StartMode(mode) if mode in (0, 1) else mode,
        r_s=float(msg.r_s),
        start_time=time_to_sec(msg.start_time),
        t1=float(msg.t1),
        alpha_k=float(msg.alpha_k),
        feasible=bool(msg.feasible),
        reason=str(msg.reason),
    )


def command_to_msg(
    cmd: StrokeCommand,
    stamp: float,
    predicted: dict[str, float] | None = None,
    frame_id: str = FRAME_ID,
    run_id: int = 0,
) -> FenceCommand:
    """StrokeCommand -> FenceCommand of run ``run_id``; ``predicted`` fills the predicted_*
    fields by their names without the prefix (capacity_pcs_h, impact_speed, peak_accel,
    exit_speed, peak_force)."""
    msg = FenceCommand(
        header=header(stamp, frame_id),
        parcel_id=int(cmd.parcel_id),
        run_id=int(run_id),
        start_mode=int(cmd.start_mode),
        r_s=float(cmd.r_s),
        start_time=sec_to_time(cmd.start_time),
        t1=float(cmd.t1),
        alpha_k=float(cmd.alpha_k),
        feasible=bool(cmd.feasible),
        reason=str(cmd.reason),
    )
    for key, value in (predicted or {}).items():
        setattr(msg, f"predicted_{key}", float(value))
    return msg


def outcome_to_msg(
    o: Outcome, frame_id: str = FRAME_ID, limits: ConstraintProfile = DEFAULT_LIMITS
) -> SortOutcome:
    """Outcome -> SortOutcome with its damage risk against ``limits`` (w_dop, a_Ndop; NaN
    figures stay NaN: the parcel met no stroke)."""
    risk = damage_risk(o.impact_normal_speed, o.peak_normal_accel, limits)
    return SortOutcome(
        header=header(o.t, frame_id),
        parcel_id=int(o.parcel_id),
        sorted=o.sorted,
        reason=o.reason,
        reason_code=int(o.code),
        peak_normal_force=float(o.peak_normal_force),
        peak_normal_force_stiff=float(o.peak_normal_force_stiff),
        peak_normal_accel=float(o.peak_normal_accel),
        impact_normal_speed=float(o.impact_normal_speed),
        exit_speed_y=float(o.exit_speed_y),
        y_max=float(o.y_max),
        time_in_working_space=float(o.time_in_working_space),
        w_dop=float(limits.w_dop),
        a_ndop=float(limits.a_ndop),
        impact_speed_margin=float(risk.impact_speed_margin),
        accel_margin=float(risk.accel_margin),
        drop_height=float(risk.drop_height),
    )


#: SortEvent's per-step arrays and the EventTrace columns they come from
EVENT_STEP_FIELDS = (
    "t", "normal_force", "deformation", "deformation_rate", "tip_deflection", "drive_angle",
    "x", "y", "yaw", "vx", "vy", "yaw_rate",
)  # fmt: skip


def event_to_msg(e: EventTrace, frame_id: str = FRAME_ID) -> SortEvent:
    """EventTrace -> SortEvent: the per-step arrays as they are, a_N = N / m_p, and the
    N_stiff course of every impact (:func:`fence_sorter.physics.contact.stiff_course`)."""
    msg = SortEvent(header=header(e.t, frame_id), parcel_id=int(e.parcel_id), mass=e.mass)
    msg.start_time = sec_to_time(e.start_time)
    for name in EVENT_STEP_FIELDS:
        setattr(msg, name, np.ascontiguousarray(e.column(name), dtype=np.float64))
    msg.normal_accel = np.ascontiguousarray(e.column("normal_force") / e.mass)
    msg.stage = e.column("stage").astype(np.uint8)
    msg.contact_set = e.column("contact_set").astype(np.uint32)
    msg.impact_t = np.ascontiguousarray(e.impacts[:, 0])
    msg.impact_speed = np.ascontiguousarray(e.impacts[:, 1])
    msg.impact_force_stiff = np.ascontiguousarray(e.impacts[:, 2])
    contact = ContactParams(b_p=e.b_p, k_p=e.k_p)
    # scipy.integrate (~0.5 s) on first use: every node imports this module, few call this
    from fence_sorter.physics.contact import stiff_course  # lazy: scipy.integrate, ~0.3 s

    courses = [stiff_course(e.mass, w_n, contact, t0) for t0, w_n, _ in e.impacts]
    msg.stiff_t = np.concatenate([c[0] for c in courses]) if courses else np.zeros(0)
    msg.stiff_force = np.concatenate([c[1] for c in courses]) if courses else np.zeros(0)
    return msg


def outcome_from_msg(msg: SortOutcome) -> Outcome:
    """SortOutcome -> Outcome (for summaries of a run)."""
    return Outcome(
        parcel_id=int(msg.parcel_id),
        t=time_to_sec(msg.header.stamp),
        code=OutcomeCode(int(msg.reason_code)),
        reason=str(msg.reason),
        peak_normal_force=float(msg.peak_normal_force),
        peak_normal_force_stiff=float(msg.peak_normal_force_stiff),
        peak_normal_accel=float(msg.peak_normal_accel),
        impact_normal_speed=float(msg.impact_normal_speed),
        exit_speed_y=float(msg.exit_speed_y),
        y_max=float(msg.y_max),
        time_in_working_space=float(msg.time_in_working_space),
    )


def _stamp(msg_header: Header, t: float, frame_id: str) -> None:
    """Set a header in place (cheaper than building a new Header and Time)."""
    ns = max(round(t * 1e9), 0)
    stamp = msg_header.stamp
    stamp.sec = ns // 1_000_000_000
    stamp.nanosec = ns % 1_000_000_000
    msg_header.frame_id = frame_id


def fill_clock(msg: Clock, t: float) -> Clock:
    """Set a Clock message in place to sim time ``t``."""
    ns = max(round(t * 1e9), 0)
    msg.clock.sec = ns // 1_000_000_000
    msg.clock.nanosec = ns % 1_000_000_000
    return msg


def fill_fence_state(
    msg: FenceState, f: FenceSnapshot, t: float, frame_id: str = FRAME_ID
) -> FenceState:
    """Set a FenceState in place from a fence snapshot (the node reuses one message: publish
    serialises it at once)."""
    _stamp(msg.header, t, frame_id)
    msg.drive_angle = float(f.drive_angle)
    msg.drive_rate = float(f.drive_rate)
    msg.drive_accel = float(f.drive_accel)
    msg.node_s = f.node_s
    msg.node_x = f.node_x
    msg.node_y = f.node_y
    msg.deflection = f.deflection
    msg.rotation = f.rotation
    msg.tip_deflection = float(f.tip_deflection)
    return msg


def fence_state_to_msg(f: FenceSnapshot, t: float, frame_id: str = FRAME_ID) -> FenceState:
    return fill_fence_state(FenceState(), f, t, frame_id)


def fill_joint_state(msg: JointState, f: FenceSnapshot, t: float) -> JointState:
    """The drive as sensor_msgs/JointState ``fence_drive``: alpha_w and its rate (effort left
    empty: the model does not compute the drive torque)."""
    _stamp(msg.header, t, "")
    msg.name = [JOINT_NAME]
    msg.position = [float(f.drive_angle)]
    msg.velocity = [float(f.drive_rate)]
    return msg


def joint_state_to_msg(f: FenceSnapshot, t: float) -> JointState:
    return fill_joint_state(JointState(), f, t)


def _yaw_quaternion(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))


def fill_load_state(
    msg: LoadState, p: ParcelSnapshot, t: float, frame_id: str = FRAME_ID
) -> LoadState:
    """Set a LoadState in place from a parcel snapshot (C_s pose, yaw quaternion, twist)."""
    _stamp(msg.header, t, frame_id)
    msg.parcel_id = int(p.parcel_id)
    msg.stage = int(p.stage)
    pos, q = msg.pose.position, msg.pose.orientation
    pos.x, pos.y, pos.z = float(p.x), float(p.y), 0.0
    q.x, q.y, q.z, q.w = 0.0, 0.0, math.sin(0.5 * p.yaw), math.cos(0.5 * p.yaw)
    lin, ang = msg.twist.linear, msg.twist.angular
    lin.x, lin.y, lin.z = float(p.vx), float(p.vy), 0.0
    ang.x, ang.y, ang.z = 0.0, 0.0, float(p.yaw_rate)
    msg.contact_normal_force = float(p.contact_normal_force)
    msg.contact_normal_force_stiff = float(p.contact_normal_force_stiff)
    msg.deformation = float(p.deformation)
    msg.deformation_rate = float(p.deformation_rate)
    cp = msg.contact_point  # NaN x, y, z while the parcel has no fence contact (LoadState.msg)
    cp.x, cp.y = float(p.contact_point[0]), float(p.contact_point[1])
    cp.z = 0.0 if math.isfinite(cp.x) else math.nan
    return msg


def load_state_to_msg(p: ParcelSnapshot, t: float, frame_id: str = FRAME_ID) -> LoadState:
    return fill_load_state(LoadState(), p, t, frame_id)


def _color(r: float, g: float, b: float, a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=r, g=g, b=b, a=a)


class MarkerBuilder:
    """RViz/Foxglove markers of the line: belt, borders, chute, the fence (LINE_STRIP through
    its nodes, deflection included) and one CUBE per parcel with its id as text above it.

    Marker objects are kept and updated in place between calls (building ~10 nested messages
    per parcel each time costs milliseconds); markers of parcels that left the line are sent
    once with action DELETE.
    """

    def __init__(self, belt_width: float, belt_x: tuple[float, float], frame_id: str = FRAME_ID):
        self.frame_id = frame_id
        x0, x1 = belt_x
        belt = self._new("belt", 0, Marker.CUBE)
        belt.pose.position = Point(x=0.5 * (x0 + x1), y=0.5 * belt_width, z=-0.01)
        belt.scale = Vector3(x=x1 - x0, y=belt_width, z=0.02)
        belt.color = _color(0.25, 0.25, 0.25)
        border = self._new("border", 0, Marker.LINE_LIST)
        border.scale.x = 0.01
        border.color = _color(0.8, 0.8, 0.2)
        border.points = [
            Point(x=x0, y=0.0, z=0.0),
            Point(x=x1, y=0.0, z=0.0),
            Point(x=x0, y=belt_width, z=0.0),
            Point(x=x1, y=belt_width, z=0.0),
        ]
        chute = self._new("chute", 0, Marker.CUBE)
        cx, cy, length, depth = unit_chute(belt_width)
        chute.pose.position = Point(x=cx, y=cy, z=-0.05)
        chute.scale = Vector3(x=length, y=depth, z=0.02)
        chute.color = _color(0.2, 0.4, 0.8, 0.6)
        self.fence = self._new("fence", 0, Marker.LINE_STRIP)
        self.fence.scale.x = 0.02
        self.fence.color = _color(0.9, 0.3, 0.1)
        self.static = [belt, border, chute, self.fence]
        self.parcels: dict[int, tuple[Marker, Marker]] = {}

    def _new(self, ns: str, mid: int, kind: int) -> Marker:
        m = Marker(ns=ns, id=mid, type=kind, action=Marker.ADD)
        m.header.frame_id = self.frame_id
        m.pose.orientation.w = 1.0
        return m

    def build(self, snap: LineSnapshot) -> MarkerArray:
        t = snap.t
        out = list(self.static)
        self.fence.points = [
            Point(x=float(x), y=float(y), z=0.05)
            for x, y in zip(snap.fence.node_x, snap.fence.node_y, strict=True)
        ]
        seen = set()
        for p in snap.parcels:
            pid = int(p.parcel_id)
            seen.add(pid)
            pair = self.parcels.get(pid)
            if pair is None:
                cube = self._new("parcels", pid % 2**31, Marker.CUBE)
                cube.scale = Vector3(x=p.length_a, y=p.width_b, z=p.height)
                cube.color = _color(0.9, 0.6, 0.2) if p.divert else _color(0.6, 0.6, 0.6)
                label = self._new("parcel_ids", pid % 2**31, Marker.TEXT_VIEW_FACING)
                label.scale.z = 0.1
                label.color = _color(1.0, 1.0, 1.0)
                label.text = str(pid)
                pair = self.parcels[pid] = (cube, label)
            cube, label = pair
            # the cube is centred on the footprint's centre, not on C_s
            n = max(len(p.corners), 1)
            cx = sum(c[0] for c in p.corners) / n
            cy = sum(c[1] for c in p.corners) / n
            pos = cube.pose.position
            pos.x, pos.y, pos.z = float(cx), float(cy), 0.5 * p.height
            q = cube.pose.orientation
            q.z, q.w = math.sin(0.5 * p.yaw), math.cos(0.5 * p.yaw)
            pos = label.pose.position
            pos.x, pos.y, pos.z = float(cx), float(cy), p.height + 0.1
            out += pair
        for pid in [pid for pid in self.parcels if pid not in seen]:
            for m in self.parcels.pop(pid):
                m.action = Marker.DELETE
                out.append(m)
        for m in out:
            _stamp(m.header, t, self.frame_id)
        return MarkerArray(markers=out)


def markers_to_msg(
    snap: LineSnapshot,
    belt_width: float,
    belt_x: tuple[float, float],
    frame_id: str = FRAME_ID,
) -> MarkerArray:
    """The markers of one snapshot (see :class:`MarkerBuilder`, which the node keeps)."""
    return MarkerBuilder(belt_width, belt_x, frame_id).build(snap)
