"""Sensor emulator core (no ROS): what a real sorter's sensors would measure of the twin.

A sensors file (``config/sensors/*.yaml``) describes three instruments:

- ``encoder``: the fence drive angle alpha_w (sensor_msgs/JointState), ``rate`` [Hz] and
  ``noise`` [rad] (standard deviation, Gaussian).
- ``camera``: an overhead camera's pose of each parcel's geometric centre and yaw (LoadState in
  frame ``camera``), ``rate`` [Hz], ``noise_position`` [m], ``noise_yaw`` [rad], ``dropout``
  (probability a frame loses the parcel), ``latency`` [s] (bag time = capture stamp + latency),
  ``offset`` (the camera frame in the sorter frame: ``x``, ``y`` [m], ``yaw_deg``) and
  ``field_of_view`` (``x``, ``y`` ranges in the sorter frame [m] where the parcel is seen).
- ``strain`` (optional, flexible fence only): the fence root's bending moment
  (geometry_msgs/WrenchStamped, torque.z [N m]), ``rate`` [Hz], ``noise`` [N m].

:func:`measure` turns the twin's truth (one :class:`TruthEvent` per parcel: its stroke start in
bag time and the replayed track) into :class:`Measurements` with one seeded generator, so truth
and noise are reproducible. Every emitter (the bag writer of ``fence-sorter emulate``) uses
this one function, so every path yields the same measured samples.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from fence_sorter.physics.dense import hermite
from fence_sorter.physics.params import ParameterError
from fence_sorter.resources import find_data
from fence_sorter.textinput import TextInputError, keyed_mapping


class SensorConfigError(ParameterError):
    """A sensors file is invalid; the message names the file and the dotted key."""


@dataclass(frozen=True)
class EncoderSpec:
    rate: float = 500.0  # [Hz]
    noise: float = 1e-4  # [rad]


@dataclass(frozen=True)
class CameraSpec:
    rate: float = 60.0  # [Hz]
    noise_position: float = 2e-3  # [m]
    noise_yaw: float = math.radians(0.5)  # [rad]
    dropout: float = 0.05  # probability a frame misses the parcel
    latency: float = 0.03  # [s] capture stamp -> bag time
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # camera frame in sorter (x, y, yaw)
    fov_x: tuple[float, float] = (-1.0, 2.0)  # [m] sorter frame
    fov_y: tuple[float, float] = (-0.1, 0.8)  # [m] sorter frame


@dataclass(frozen=True)
class StrainSpec:
    rate: float = 1000.0  # [Hz]
    noise: float = 1.0  # [N m]


@dataclass(frozen=True)
class SensorConfig:
    name: str = "default"
    encoder: EncoderSpec = EncoderSpec()
    camera: CameraSpec = CameraSpec()
    strain: StrainSpec | None = None


_RANGES = {
    "encoder.rate": (1.0, 1e5, "Hz"),
    "encoder.noise": (0.0, 0.1, "rad"),
    "camera.rate": (1.0, 1000.0, "Hz"),
    "camera.noise_position": (0.0, 0.1, "m"),
    "camera.noise_yaw": (0.0, 0.5, "rad"),
    "camera.dropout": (0.0, 0.9, ""),
    "camera.latency": (0.0, 1.0, "s"),
    "strain.rate": (1.0, 1e5, "Hz"),
    "strain.noise": (0.0, 1e4, "N m"),
}
_KEYS = {
    "encoder": ("rate", "noise"),
    "camera": (
        "rate",
        "noise_position",
        "noise_yaw_deg",
        "dropout",
        "latency",
        "offset",
        "field_of_view",
    ),
    "strain": ("rate", "noise"),
}


def resolve_sensors(path_or_name: str | Path) -> Path:
    """A sensors file by path, or by name under config/sensors/ (checkout or share)."""
    found = find_data("config/sensors", path_or_name, (".yaml", ".yml"))
    if found is None:
        raise SensorConfigError(
            f"sensors {path_or_name}: no such file (nor config/sensors/{path_or_name}.yaml)"
        )
    return found


def _number(src: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise SensorConfigError(
                f"sensors {src}: {key} must be a number, got {value!r}"
            ) from None
    lo, hi, unit = _RANGES.get(key, (-math.inf, math.inf, ""))
    if not (math.isfinite(value) and lo <= value <= hi):
        raise SensorConfigError(
            f"sensors {src}: {key} must be in [{lo:g}, {hi:g}] {unit}".rstrip()
            + f", got {value!r}"
        )
    return float(value)


def _pair(src: str, key: str, value) -> tuple[float, float]:
    if not (isinstance(value, list | tuple) and len(value) == 2):
        raise SensorConfigError(f"sensors {src}: {key} must be a list [low, high], got {value!r}")
    lo, hi = (_number(src, key, v) for v in value)
    if not lo < hi:
        raise SensorConfigError(f"sensors {src}: {key} must have low < high, got {value!r}")
    return lo, hi


def load_sensors(path_or_name: str | Path) -> SensorConfig:
    """Load and check a sensors file; SensorConfigError names the key and its range."""
    path = resolve_sensors(path_or_name)
    src = path.name
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except (OSError, yaml.YAMLError) as exc:
        detail = " ".join(str(exc).split())
        raise SensorConfigError(f"sensors {src}: cannot read: {detail}") from None
    if not isinstance(raw, dict):
        raise SensorConfigError(f"sensors {src}: the top level must be a mapping")
    for k in raw:
        if k not in (*_KEYS, "name", "description"):
            raise SensorConfigError(
                f"sensors {src}: {k} is not a known key; allowed: name, description, "
                + ", ".join(_KEYS)
            )
    sections = {}
    for sec, keys in _KEYS.items():
        data = raw.get(sec)
        if data is None:
            continue
        try:
            sections[sec] = keyed_mapping(data, sec, keys)
        except TextInputError as exc:
            raise SensorConfigError(f"sensors {src}: {exc}") from None
    enc = sections.get("encoder", {})
    encoder = EncoderSpec(
        **{k: _number(src, f"encoder.{k}", v) for k, v in enc.items()},
    )
    cam = dict(sections.get("camera", {}))
    kw = {}
    for k in ("rate", "noise_position", "dropout", "latency"):
        if k in cam:
            kw[k] = _number(src, f"camera.{k}", cam[k])
    if "noise_yaw_deg" in cam:
        kw["noise_yaw"] = math.radians(_number(src, "camera.noise_yaw_deg", cam["noise_yaw_deg"]))
        _number(src, "camera.noise_yaw", kw["noise_yaw"])
    if "offset" in cam:
        off = cam["offset"]
        if not isinstance(off, dict) or set(off) - {"x", "y", "yaw_deg"}:
            raise SensorConfigError(
                f"sensors {src}: camera.offset must be a mapping of x, y [m] and yaw_deg"
            )
        kw["offset"] = (
            _number(src, "camera.offset.x", off.get("x", 0.0)),
            _number(src, "camera.offset.y", off.get("y", 0.0)),
            math.radians(_number(src, "camera.offset.yaw_deg", off.get("yaw_deg", 0.0))),
        )
    if "field_of_view" in cam:
        fov = cam["field_of_view"]
        if not isinstance(fov, dict) or set(fov) - {"x", "y"}:
            raise SensorConfigError(
                f"sensors {src}: camera.field_of_view must be a mapping of x and y ranges [m]"
            )
        if "x" in fov:
            kw["fov_x"] = _pair(src, "camera.field_of_view.x", fov["x"])
        if "y" in fov:
            kw["fov_y"] = _pair(src, "camera.field_of_view.y", fov["y"])
    strain = None
    if "strain" in sections:
        strain = StrainSpec(
            **{k: _number(src, f"strain.{k}", v) for k, v in sections["strain"].items()}
        )
    return SensorConfig(
        name=str(raw.get("name", path.stem)),
        encoder=encoder,
        camera=CameraSpec(**kw),
        strain=strain,
    )


# -- frames ------------------------------------------------------------------------------------
def sorter_to_camera(offset, x, y, yaw):
    """Sorter-frame pose -> camera frame, the camera frame lying at ``offset`` (x, y, yaw)."""
    ox, oy, oyaw = offset
    c, s = math.cos(oyaw), math.sin(oyaw)
    dx, dy = np.asarray(x) - ox, np.asarray(y) - oy
    return c * dx + s * dy, -s * dx + c * dy, np.asarray(yaw) - oyaw


def camera_to_sorter(offset, x, y, yaw):
    """Camera-frame pose -> sorter frame (inverse of :func:`sorter_to_camera`)."""
    ox, oy, oyaw = offset
    c, s = math.cos(oyaw), math.sin(oyaw)
    x, y = np.asarray(x), np.asarray(y)
    return ox + c * x - s * y, oy + s * x + c * y, np.asarray(yaw) + oyaw


# -- truth and measurements --------------------------------------------------------------------
@dataclass
class Track:
    """A parcel's replayed motion (times from its stroke start, s) and the fence's.

    ``x``, ``y`` the geometric centre [m] and ``yaw`` [rad], sorter frame; ``moment`` the fence
    root bending moment [N m] on ``t_fence`` (empty for a stiff fence).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    t_fence: np.ndarray
    moment: np.ndarray
    t_end: float

    def pose_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (
            np.interp(t, self.t, self.x),
            np.interp(t, self.t, self.y),
            np.interp(t, self.t, self.yaw),
        )

    def moment_at(self, t: np.ndarray) -> np.ndarray:
        if not len(self.t_fence):
            return np.zeros_like(t)
        return np.interp(t, self.t_fence, self.moment, left=0.0)


@dataclass
class TruthEvent:
    parcel_id: int
    t_start: float  # stroke start in bag time [s]
    alpha_k: float
    t1: float
    track: Track


@dataclass
class Measurements:
    """The measured samples of a bag, in bag time (stamps are capture times)."""

    enc_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    enc_angle: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cam_t: np.ndarray = field(default_factory=lambda: np.zeros(0))  # capture stamp
    cam_id: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    cam_x: np.ndarray = field(default_factory=lambda: np.zeros(0))  # camera frame
    cam_y: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cam_yaw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cam_latency: float = 0.0
    str_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    str_moment: np.ndarray = field(default_factory=lambda: np.zeros(0))


def drive_angle(events, t: np.ndarray) -> np.ndarray:
    """alpha_w at bag times ``t`` from the strokes of ``events`` (anything with ``t_start``,
    ``alpha_k``, ``t1``; 0 between strokes)."""
    out = np.zeros_like(t)
    for ev in events:
        tau = t - ev.t_start
        inside = (tau >= 0.0) & (tau <= 2.0 * ev.t1)
        out[inside] = 0.5 * ev.alpha_k * (1.0 - np.cos(math.pi * tau[inside] / ev.t1))
    return out


def grid(t0: float, t1: float, rate: float) -> np.ndarray:
    """The sample instants k / rate of a sensor in [t0, t1] (every sensor samples on the
    multiples of its period, in bag time)."""
    n0, n1 = math.ceil(t0 * rate), math.floor(t1 * rate)
    return np.arange(n0, n1 + 1) / rate


def encoder_readings(enc: EncoderSpec, rng: np.random.Generator, angle) -> np.ndarray:
    """The encoder's readings of the true drive angles ``angle`` [rad]: plus Gaussian noise."""
    angle = np.asarray(angle, dtype=float)
    return angle + rng.normal(0.0, 1.0, angle.size) * enc.noise


def in_view(cam: CameraSpec, x, y) -> np.ndarray:
    """Whether a geometric centre (sorter frame) lies inside the camera's field of view."""
    x, y = np.asarray(x), np.asarray(y)
    return (x >= cam.fov_x[0]) & (x <= cam.fov_x[1]) & (y >= cam.fov_y[0]) & (y <= cam.fov_y[1])


def camera_frames(cam: CameraSpec, rng: np.random.Generator, x, y, yaw):
    """One parcel's frames as the camera sees them, from its true geometric centre and yaw
    (sorter frame): the frames it lies in the field of view, minus the dropped ones (probability
    ``dropout`` each), in the camera frame, plus Gaussian noise.

    Returns (seen, kept, cx, cy, cyaw): ``seen``, ``kept`` boolean masks over the frames (kept:
    seen and not dropped), the measured poses of the kept frames.
    """
    x, y, yaw = (np.asarray(v, dtype=float) for v in (x, y, yaw))
    seen = in_view(cam, x, y)
    kept = seen & (rng.random(x.size) >= cam.dropout)
    n = int(kept.sum())
    cx, cy, cyaw = sorter_to_camera(cam.offset, x[kept], y[kept], yaw[kept])
    cx = cx + rng.normal(0.0, 1.0, n) * cam.noise_position
    cy = cy + rng.normal(0.0, 1.0, n) * cam.noise_position
    cyaw = cyaw + rng.normal(0.0, 1.0, n) * cam.noise_yaw
    return seen, kept, cx, cy, cyaw


def strain_readings(strain: StrainSpec, rng: np.random.Generator, moment) -> np.ndarray:
    """The strain gauge's readings of the true root moments ``moment`` [N m]: plus noise."""
    moment = np.asarray(moment, dtype=float)
    return moment + rng.normal(0.0, 1.0, moment.size) * strain.noise


def geometric_centre(x, y, yaw, cog_offset_x: float, cog_offset_y: float):
    """A parcel's geometric centre from its centre of gravity C_s (x, y) and yaw: C_s - R(yaw)
    (x_p, y_p), the point a camera sees."""
    c, s = np.cos(yaw), np.sin(yaw)
    return (
        x - (c * cog_offset_x - s * cog_offset_y),
        y - (s * cog_offset_x + c * cog_offset_y),
    )


def measure(
    events: list[TruthEvent], cfg: SensorConfig, seed: int, pre_time: float, t_bag_end: float
) -> Measurements:
    """Sample the truth as the sensors of ``cfg`` would, with one seeded generator.

    Encoder: every 1/rate from 0 to ``t_bag_end``. Camera: every frame in which a parcel lies
    inside the field of view from ``pre_time`` before its stroke to the end of its track, minus
    the dropped frames. Strain: every 1/rate over the same window as the camera's.
    """
    rng = np.random.default_rng(seed)
    m = Measurements(cam_latency=cfg.camera.latency)
    m.enc_t = grid(0.0, t_bag_end, cfg.encoder.rate)
    m.enc_angle = encoder_readings(cfg.encoder, rng, drive_angle(events, m.enc_t))
    cam = cfg.camera
    ts, ids, xs, ys, yaws = [], [], [], [], []
    for ev in events:
        tt = grid(ev.t_start - pre_time, ev.t_start + ev.track.t_end, cam.rate)
        _, kept, cx, cy, cyaw = camera_frames(cam, rng, *ev.track.pose_at(tt - ev.t_start))
        ts.append(tt[kept])
        ids.append(np.full(cx.size, ev.parcel_id, dtype=np.int64))
        xs.append(cx)
        ys.append(cy)
        yaws.append(cyaw)
    if events:
        m.cam_t, m.cam_id = np.concatenate(ts), np.concatenate(ids)
        m.cam_x, m.cam_y, m.cam_yaw = np.concatenate(xs), np.concatenate(ys), np.concatenate(yaws)
    if cfg.strain is not None and any(len(ev.track.t_fence) for ev in events):
        st, sm = [], []
        for ev in events:
            tt = grid(ev.t_start - pre_time, ev.t_start + ev.track.t_end, cfg.strain.rate)
            st.append(tt)
            sm.append(ev.track.moment_at(tt - ev.t_start))
        m.str_t = np.concatenate(st)
        m.str_moment = strain_readings(cfg.strain, rng, np.concatenate(sm))
    return m


# -- the sensors of a run ----------------------------------------------------------------------
def _instants(t0: float, t1: float, rate: float) -> np.ndarray:
    """The sample instants k / rate with floor(t0 rate) < k <= floor(t1 rate): consecutive
    intervals (t0, t1] of a state stream yield each instant once."""
    return np.arange(math.floor(t0 * rate) + 1, math.floor(t1 * rate) + 1) / rate


@dataclass(frozen=True)
class CameraFrame:
    """One measured pose: capture stamp [s], parcel, geometric centre and yaw (camera frame)."""

    t: float
    parcel_id: int
    x: float
    y: float
    yaw: float


#: what :class:`SensorStream` counts: samples published, and samples dropped by cause
STREAM_COUNTERS = (
    "encoder_published",
    "encoder_dropped_state_gap",
    "camera_frames_in_view",
    "camera_published",
    "camera_dropped_dropout",
    "camera_dropped_state_gap",
    "camera_dropped_overload",
    "camera_dropped_unknown_parcel",
    "strain_published",
    "strain_dropped_state_gap",
    "states_dropped_out_of_order",
)


class SensorStream:
    """The sensors of ``cfg`` fed with the twin's state as a run publishes it (the sensors
    node, :mod:`fence_sorter.nodes.sensors`), with the noise and dropout model of
    :func:`measure`.

    Each sensor samples at its instants k / rate. Between two consecutive states of the same
    source (the fence; one parcel) the truth is interpolated: the drive angle and a parcel's
    centre of gravity and yaw by cubic Hermite interpolation with their rates, the root moment
    (no rate in the state) by the cubic through the four states around the sample, one state
    interval later. Across a gap longer than ``max_gap`` (a run sets it to 1.5 state periods: a
    lost state is never bridged) no sample is taken and the missed instants are counted
    (``*_dropped_state_gap``), the gauge's also where its cubic's stencil spans such a gap.
    Camera frames are held until the state clock reaches capture + latency (:meth:`release`);
    beyond ``max_pending`` held frames a new frame is dropped and counted
    (``camera_dropped_overload``). Three generators (encoder, camera, strain) spawned from
    ``seed``. ``moment_factor``: root moment per tip deflection [N m / m] (None: a stiff
    fence, no gauge).
    """

    def __init__(
        self,
        cfg: SensorConfig,
        seed: int,
        moment_factor: float | None,
        max_gap: float,
        max_pending: int = 10000,
    ) -> None:
        self.cfg = cfg
        self.strain = cfg.strain if moment_factor is not None else None
        self.moment_factor = moment_factor
        self.max_gap = float(max_gap)
        self.max_pending = int(max_pending)
        rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)]
        self.rng_encoder, self.rng_camera, self.rng_strain = rngs
        self.counts: dict[str, int] = dict.fromkeys(STREAM_COUNTERS, 0)
        self._fence: list[tuple[float, ...]] = []  # the last states: t, alpha, rate, moment
        self._poses: dict[int, tuple[float, ...]] = {}  # t, x, y, yaw, vx, vy, yaw rate
        self._cog: dict[int, tuple[float, float]] = {}
        self._pending: list[tuple[float, int, CameraFrame]] = []  # heap of (due, seq, frame)
        self._seq = 0
        self.clock = -math.inf  # the newest state stamp [s]
        # the newest stamp of each state stream: the two topics arrive independently, so
        # each sensor's published count is a function of its own stream's clock
        self.fence_clock = -math.inf
        self.load_clock = -math.inf
        #: shortest and longest delay of a released frame: state clock - capture time [s]
        self.delay_range = (math.inf, -math.inf)

    def parcel(self, parcel_id: int, cog_offset_x: float, cog_offset_y: float) -> None:
        """A scanned parcel: its centre of gravity offset, to place its geometric centre."""
        self._cog[int(parcel_id)] = (float(cog_offset_x), float(cog_offset_y))

    def _span(self, prev_t: float, t: float, rate: float, gap_key: str) -> np.ndarray | None:
        tt = _instants(prev_t, t, rate)
        if t - prev_t > self.max_gap:
            self.counts[gap_key] += tt.size
            return None
        return tt

    def fence_state(self, t: float, alpha_w: float, rate: float, tip_deflection: float):
        """The fence at ``t`` (drive angle and rate, tip deflection): the encoder's samples
        (times, angles) since the previous fence state, and the gauge's (times, moments) one
        state interval behind (its cubic interpolation needs the state after it)."""
        self.clock = max(self.clock, t)
        self.fence_clock = max(self.fence_clock, t)
        moment = self.moment_factor * tip_deflection if self.moment_factor is not None else 0.0
        hist, empty = self._fence, (np.zeros(0), np.zeros(0))
        if hist and t <= hist[-1][0]:
            self.counts["states_dropped_out_of_order"] += 1
            return empty, empty
        hist.append((t, alpha_w, rate, moment))
        if len(hist) > 4:
            hist.pop(0)
        if len(hist) < 2:
            return empty, empty
        prev = hist[-2]
        enc = empty
        tt = self._span(prev[0], t, self.cfg.encoder.rate, "encoder_dropped_state_gap")
        if tt is not None and tt.size:
            true = hermite(tt, prev[0], t, prev[1], alpha_w, prev[2], rate)
            enc = (tt, encoder_readings(self.cfg.encoder, self.rng_encoder, true))
            self.counts["encoder_published"] += tt.size
        gauge = empty
        if self.strain is not None and len(hist) >= 3:
            gauge = self._gauge(hist)
        return enc, gauge

    def _gauge(self, hist: list[tuple[float, ...]]):
        """The gauge's samples in the interval before the newest state: the root moment by the
        cubic through the four states around it (two each side), so a ringing fence is
        followed between states. Where a state of that stencil is missing (a neighbour more
        than ``max_gap`` away) the samples are dropped and counted: a cubic or a line across
        a lost state misses an impact by several noise levels."""
        a, b = hist[-3], hist[-2]
        tt = self._span(a[0], b[0], self.strain.rate, "strain_dropped_state_gap")
        if tt is None or not tt.size:
            return np.zeros(0), np.zeros(0)
        pts = hist[-4:] if len(hist) == 4 else hist[-3:]
        if any(q[0] - p[0] > self.max_gap for p, q in zip(pts, pts[1:], strict=False)):
            self.counts["strain_dropped_state_gap"] += tt.size
            return np.zeros(0), np.zeros(0)
        ts, ms = [p[0] for p in pts], [p[3] for p in pts]
        true = sum(
            ms[i] * np.prod([(tt - ts[j]) / (ts[i] - ts[j]) for j in range(len(ts)) if j != i],
                            axis=0)
            for i in range(len(ts))
        )  # fmt: skip
        self.counts["strain_published"] += tt.size
        return tt, strain_readings(self.strain, self.rng_strain, true)

    def parcel_state(self, parcel_id: int, t: float, pose, velocity) -> None:
        """A parcel's centre of gravity and yaw ``pose`` (x, y, yaw) and their rates
        ``velocity`` at ``t`` (sorter frame): the camera's frames since its previous state are
        measured and held for their latency."""
        self.clock = max(self.clock, t)
        self.load_clock = max(self.load_clock, t)
        pid = int(parcel_id)
        cam = self.cfg.camera
        prev = self._poses.get(pid)
        if prev is not None and t <= prev[0]:
            self.counts["states_dropped_out_of_order"] += 1
            return
        state = (float(t), *map(float, pose), *map(float, velocity))
        self._poses[pid] = state
        if prev is None:
            return
        tt = _instants(prev[0], t, cam.rate)
        if not tt.size:
            return
        x, y, yaw = (hermite(tt, prev[0], t, prev[k], state[k], prev[k + 3], state[k + 3])
                     for k in (1, 2, 3))  # fmt: skip
        cog = self._cog.get(pid)
        gx, gy = geometric_centre(x, y, yaw, *(cog or (0.0, 0.0)))
        if t - prev[0] > self.max_gap:
            self.counts["camera_dropped_state_gap"] += int(in_view(cam, gx, gy).sum())
            return
        if cog is None:
            self.counts["camera_dropped_unknown_parcel"] += int(in_view(cam, gx, gy).sum())
            return
        seen, kept, cx, cy, cyaw = camera_frames(cam, self.rng_camera, gx, gy, yaw)
        self.counts["camera_frames_in_view"] += int(seen.sum())
        self.counts["camera_dropped_dropout"] += int((seen & ~kept).sum())
        for t_k, x_k, y_k, yaw_k in zip(tt[kept], cx, cy, cyaw, strict=True):
            if len(self._pending) >= self.max_pending:
                self.counts["camera_dropped_overload"] += 1
                continue
            frame = CameraFrame(float(t_k), pid, float(x_k), float(y_k), float(yaw_k))
            heapq.heappush(self._pending, (frame.t + cam.latency, self._seq, frame))
            self._seq += 1

    def release(self) -> list[CameraFrame]:
        """The held frames whose capture + latency the state clock has reached, in order."""
        out = []
        while self._pending and self._pending[0][0] <= self.clock + 1e-9:
            out.append(heapq.heappop(self._pending)[2])
        if out:
            lo, hi = self.delay_range
            delays = [self.clock - f.t for f in out]
            self.delay_range = (min(lo, *delays), max(hi, *delays))
        self.counts["camera_published"] += len(out)
        return out

    def forget_before(self, t: float) -> None:
        """Drop the parcels whose last state is older than ``t`` (they left the line)."""
        for pid in [p for p, s in self._poses.items() if s[0] < t]:
            del self._poses[pid]
            self._cog.pop(pid, None)
