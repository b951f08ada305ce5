"""Measured bags: write the emulated sensors' samples, read a bag's measured topics back.

A measured bag carries the topics of :data:`fence_sorter.recording.topics.MEASURED_TOPICS`
(drive encoder, camera poses, optionally the fence root moment) plus the scanner's ``/parcels``
and the controller's ``/fence_commands``. An emulated bag also carries the truth it was made
from in its metadata's ``custom_data`` (key :data:`TRUTH_KEY`), for benchmarks; a calibration
never reads it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import yaml
from scipy.optimize import least_squares

from fence_sorter.codes import StartMode
from fence_sorter.physics.params import ParcelParams
from fence_sorter.recording.bagread import BagReadError, read_bag
from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter.recording.topics import (
    CAMERA_POSES,
    DRIVE_ENCODER,
    FENCE_COMMANDS,
    FENCE_ROOT_MOMENT,
    MEASURED_TOPICS,
    PARCELS,
    TOPIC_TYPES,
)
from fence_sorter.recording.writer import SegmentedBagWriter
from fence_sorter.stamps import time_to_sec

from .replay import ParcelEvent
from .sensors import Measurements, drive_angle

TRUTH_KEY = "fence_sorter.calibration_truth"
DRIVE_JOINT = "fence_drive"
#: the scanner sees a parcel this long before its stroke starts [s]
SCAN_LEAD = 1.0
BAG_TOPICS = {**TOPIC_TYPES, **MEASURED_TOPICS}
#: the fields Parcel messages and ParcelParams share (same names, SI units)
PARCEL_FIELDS = tuple(f.name for f in fields(ParcelParams))


class MeasuredBagError(ValueError):
    """A bag lacks what a calibration needs (the message names the topic)."""


def _stamp(ts, t: float):
    sec, nanosec = divmod(int(round(t * 1e9)), 10**9)
    return ts.types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nanosec))


def _header(ts, t: float, frame: str):
    return ts.types["std_msgs/msg/Header"](stamp=_stamp(ts, t), frame_id=frame)


def encoder_msg(ts, t: float, alpha_w: float):
    """The drive encoder's sample: JointState of joint ``fence_drive`` stamped ``t``."""
    T = ts.types
    return T["sensor_msgs/msg/JointState"](
        header=_header(ts, t, "sorter"),
        name=[DRIVE_JOINT],
        position=np.array([alpha_w]),
        velocity=np.zeros(0),
        effort=np.zeros(0),
    )


def camera_msg(ts, t: float, parcel_id: int, x: float, y: float, yaw: float):
    """The camera's pose of a parcel: LoadState in frame ``camera`` stamped with the capture
    time; geometric centre and yaw, every other field NaN (not measured)."""
    T = ts.types
    vec, point = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Point"]
    return T["fence_sorter_msgs/msg/LoadState"](
        header=_header(ts, t, "camera"),
        parcel_id=int(parcel_id),
        stage=0,
        pose=T["geometry_msgs/msg/Pose"](
            position=point(x=float(x), y=float(y), z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
            ),
        ),
        twist=T["geometry_msgs/msg/Twist"](
            linear=vec(x=math.nan, y=math.nan, z=0.0), angular=vec(x=0.0, y=0.0, z=math.nan)
        ),
        contact_normal_force=math.nan,
        contact_normal_force_stiff=math.nan,
        deformation=math.nan,
        deformation_rate=math.nan,
        contact_point=point(x=math.nan, y=math.nan, z=math.nan),
    )


def moment_msg(ts, t: float, moment: float):
    """The strain gauge's sample: WrenchStamped in frame ``fence_root``, torque.z [N m]."""
    T = ts.types
    vec = T["geometry_msgs/msg/Vector3"]
    return T["geometry_msgs/msg/WrenchStamped"](
        header=_header(ts, t, "fence_root"),
        wrench=T["geometry_msgs/msg/Wrench"](
            force=vec(x=0.0, y=0.0, z=0.0), torque=vec(x=0.0, y=0.0, z=float(moment))
        ),
    )


def write_measured_bag(
    path: Path | str, events: list[ParcelEvent], m: Measurements, truth: dict | None = None
) -> Path:
    """Write the measured topics and each event's parcel and command into a bag at ``path``."""
    ts = make_typestore()
    T = ts.types
    msgs: list[tuple[float, str, object]] = []
    for ev in events:
        p = ev.parcel
        t_scan = ev.t_start - SCAN_LEAD
        parcel = T["fence_sorter_msgs/msg/Parcel"](
            header=_header(ts, t_scan, "sorter"),
            parcel_id=ev.parcel_id,
            run_id=0,
            auth=0,  # unsigned: a measured bag is no run of the suite
            **{f: getattr(p, f) for f in PARCEL_FIELDS},
            mu_belt=math.nan,
            mu_fence=math.nan,
            divert=True,
            scan_time=_stamp(ts, t_scan),
            scan_position_x=-3.0,
            destination="",
            passes=0,
        )
        cmd = T["fence_sorter_msgs/msg/FenceCommand"](
            header=_header(ts, t_scan, "sorter"),
            parcel_id=ev.parcel_id,
            run_id=0,
            auth=0,  # unsigned: a measured bag is no run of the suite
            start_mode=int(StartMode.AT_TIME),
            r_s=ev.r_s,
            start_time=_stamp(ts, ev.t_start),
            t1=ev.t1,
            alpha_k=ev.alpha_k,
            predicted_capacity_pcs_h=math.nan,
            predicted_impact_speed=math.nan,
            predicted_peak_accel=math.nan,
            predicted_exit_speed=math.nan,
            predicted_peak_force=math.nan,
            feasible=True,
            reason="",
        )
        msgs.append((t_scan, PARCELS, parcel))
        msgs.append((t_scan, FENCE_COMMANDS, cmd))
    for t, a in zip(m.enc_t, m.enc_angle, strict=True):
        msgs.append((t, DRIVE_ENCODER, encoder_msg(ts, t, a)))
    for t, pid, x, y, yaw in zip(m.cam_t, m.cam_id, m.cam_x, m.cam_y, m.cam_yaw, strict=True):
        msgs.append((t + m.cam_latency, CAMERA_POSES, camera_msg(ts, t, int(pid), x, y, yaw)))
    for t, mz in zip(m.str_t, m.str_moment, strict=True):
        msgs.append((t, FENCE_ROOT_MOMENT, moment_msg(ts, t, mz)))
    msgs.sort(key=lambda item: item[0])
    custom = {TRUTH_KEY: json.dumps(truth)} if truth is not None else None
    writer = SegmentedBagWriter(path, custom_data=custom, clock=lambda: 0.0)
    with writer:
        handles = {}
        for _, topic, _ in msgs:
            if topic not in handles:
                handles[topic] = writer.add_topic(topic, BAG_TOPICS[topic][0])
        for t, topic, msg in msgs:
            data = ts.serialize_cdr(msg, BAG_TOPICS[topic][0])
            writer.write(handles[topic], int(round(t * 1e9)), data)
    return Path(path)


def fit_stroke(
    enc_t: np.ndarray, enc_angle: np.ndarray, alpha_k: float, t1: float, t_start: float
) -> tuple[float, float, float]:
    """(t_start, alpha_k, t1) of a stroke from the encoder samples around the commanded one:
    least squares of the sinusoidal drive law against the measured angle."""
    sel = (enc_t >= t_start - 0.3) & (enc_t <= t_start + 2.0 * t1 + 0.3)
    tt, aa = enc_t[sel], enc_angle[sel]
    if tt.size < 10:
        return t_start, alpha_k, t1

    def resid(p):
        tau = tt - p[0]
        inside = (tau >= 0.0) & (tau <= 2.0 * p[2])
        f = np.zeros_like(tt)
        f[inside] = 0.5 * p[1] * (1.0 - np.cos(math.pi * tau[inside] / p[2]))
        return f - aa

    sol = least_squares(resid, [t_start, alpha_k, t1], x_scale=[1e-3, alpha_k, t1], xtol=1e-12)
    return float(sol.x[0]), float(sol.x[1]), float(sol.x[2])


@dataclass
class MeasuredBag:
    path: Path
    events: list[ParcelEvent]
    m: Measurements  # camera samples in the camera frame
    truth: dict | None
    has_strain: bool
    encoder_rms: float  # RMS of the encoder about the fitted strokes [rad]


def read_custom_data(path: Path) -> dict:
    meta = path / "metadata.yaml"
    try:
        info = yaml.safe_load(meta.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        return dict(info.get("custom_data") or {})
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return {}


def read_measured_bag(path: Path | str) -> MeasuredBag:
    """The events and measured samples of a bag.

    Raises:
        BagReadError: not a bag.
        MeasuredBagError: a needed topic is missing or empty (the message names it).
    """
    path = Path(path)
    wanted = [PARCELS, FENCE_COMMANDS, DRIVE_ENCODER, CAMERA_POSES, FENCE_ROOT_MOMENT]
    bag = read_bag(path, wanted)
    counts = bag.counts()
    for topic in (PARCELS, FENCE_COMMANDS, DRIVE_ENCODER, CAMERA_POSES):
        if not counts.get(topic):
            raise MeasuredBagError(
                f"{path}: topic {topic} ({BAG_TOPICS[topic][0]}) is missing or empty; a "
                f"calibration needs {', '.join(wanted[:4])}"
            )
    m = Measurements()
    enc = bag.by_topic(DRIVE_ENCODER)
    m.enc_t = np.array([time_to_sec(x.msg.header.stamp) for x in enc])
    m.enc_angle = np.array([float(x.msg.position[0]) for x in enc])
    cam = bag.by_topic(CAMERA_POSES)
    m.cam_t = np.array([time_to_sec(x.msg.header.stamp) for x in cam])
    m.cam_id = np.array([int(x.msg.parcel_id) for x in cam], dtype=np.int64)
    m.cam_x = np.array([x.msg.pose.position.x for x in cam])
    m.cam_y = np.array([x.msg.pose.position.y for x in cam])
    m.cam_yaw = np.array(
        [2.0 * math.atan2(x.msg.pose.orientation.z, x.msg.pose.orientation.w) for x in cam]
    )
    m.cam_latency = float(np.median([x.t_ns * 1e-9 for x in cam] - m.cam_t))
    strain = bag.by_topic(FENCE_ROOT_MOMENT)
    m.str_t = np.array([time_to_sec(x.msg.header.stamp) for x in strain])
    m.str_moment = np.array([x.msg.wrench.torque.z for x in strain])
    parcels = {int(x.msg.parcel_id): x.msg for x in bag.by_topic(PARCELS)}
    events = []
    for c in bag.by_topic(FENCE_COMMANDS):
        cmd = c.msg
        pid = int(cmd.parcel_id)
        p = parcels.get(pid)
        if p is None or not cmd.feasible:
            continue
        start = time_to_sec(cmd.start_time)
        t0, ak, t1 = fit_stroke(m.enc_t, m.enc_angle, cmd.alpha_k, cmd.t1, start)
        parcel = ParcelParams(**{f: float(getattr(p, f)) for f in PARCEL_FIELDS})
        events.append(ParcelEvent(pid, parcel, ak, t1, cmd.r_s, t0))
    events.sort(key=lambda e: e.t_start)
    # encoder residual about the fitted strokes: what the sinusoidal law leaves unexplained
    rms = float(np.sqrt(np.mean((drive_angle(events, m.enc_t) - m.enc_angle) ** 2)))
    truth_text = read_custom_data(path).get(TRUTH_KEY) if path.is_dir() else None
    truth = json.loads(truth_text) if truth_text else None
    return MeasuredBag(path, events, m, truth, bool(m.str_t.size), rms)


__all__ = [
    "BagReadError",
    "MeasuredBag",
    "MeasuredBagError",
    "TRUTH_KEY",
    "fit_stroke",
    "read_measured_bag",
    "write_measured_bag",
]
