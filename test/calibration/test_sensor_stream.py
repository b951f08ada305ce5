"""The sensors of a run (SensorStream, ROS-free): fed a known motion state by state as the
simulator publishes it, they sample at their rates with the configured noise, dropouts, frame
offset and latency, and count every sample they do not publish."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from fence_sorter.calibration.sensors import (
    SensorStream,
    camera_to_sorter,
    geometric_centre,
    load_sensors,
)

V = 2.0  # belt speed [m/s]
COG = (0.02, -0.01)


def _truth(t):
    """A parcel riding the belt, drifting and turning; the drive swinging; the fence ringing."""
    x, y, yaw = -1.5 + V * t, 0.3 + 0.1 * np.sin(5.0 * t), 0.2 * np.sin(3.0 * t)
    alpha = 0.3 * np.sin(8.0 * t)
    tip = 1e-3 * np.sin(2 * math.pi * 20.0 * t)
    return x, y, yaw, alpha, tip


def _rates(t):
    return V, 0.5 * np.cos(5.0 * t), 0.6 * np.cos(3.0 * t), 2.4 * np.cos(8.0 * t)


def _run(cfg, seed=3, dt=1e-3, t_end=1.6, skip=(), factor=1000.0):
    s = SensorStream(cfg, seed, factor, max_gap=0.01)
    s.parcel(7, *COG)
    enc, gauge, frames = [], [], []
    for k in range(int(round(t_end / dt)) + 1):
        if k in skip:
            continue
        t = k * dt
        x, y, yaw, alpha, tip = _truth(t)
        vx, vy, wz, rate = _rates(t)
        (et, ea), (st, sm) = s.fence_state(t, alpha, rate, tip)
        enc += list(zip(et, ea, strict=True))
        gauge += list(zip(st, sm, strict=True))
        s.parcel_state(7, t, (x, y, yaw), (vx, vy, wz))
        frames += [(s.clock, f) for f in s.release()]
    return s, np.array(enc), np.array(gauge), frames


def test_rates_noise_offset_dropout_and_latency():
    cfg = load_sensors("camera60")
    s, enc, gauge, frames = _run(cfg)
    # every instant k / rate in (0, 1.6] once (the gauge's last state interval waits for the
    # state after it)
    assert np.allclose(enc[:, 0], np.arange(1, 801) / 500.0)
    assert np.allclose(gauge[:, 0], np.arange(1, 1600) / 1000.0)
    d_enc = enc[:, 1] - _truth(enc[:, 0])[3]
    assert abs(np.std(d_enc) / cfg.encoder.noise - 1.0) < 0.15 and abs(np.mean(d_enc)) < 2e-5
    d_str = gauge[:, 1] - 1000.0 * _truth(gauge[:, 0])[4]
    assert abs(np.std(d_str) / cfg.strain.noise - 1.0) < 0.1
    cam = cfg.camera
    t = np.array([f.t for _, f in frames])
    cx = np.array([f.x for _, f in frames])
    cy = np.array([f.y for _, f in frames])
    cyaw = np.array([f.yaw for _, f in frames])
    x, y, yaw = camera_to_sorter(cam.offset, cx, cy, cyaw)
    tx, ty, tyaw, _, _ = _truth(t)
    gx, gy = geometric_centre(tx, ty, tyaw, *COG)
    err = np.concatenate([x - gx, y - gy])
    assert abs(np.std(err) / cam.noise_position - 1.0) < 0.2
    assert abs(np.std(yaw - tyaw) / cam.noise_yaw - 1.0) < 0.25
    # frames on the camera's instants, in view once the centre passes x = -1 m (t = 0.26 s)
    assert np.allclose(t * cam.rate, np.round(t * cam.rate))
    assert t.min() >= 0.26 - 1e-9
    seen = s.counts["camera_frames_in_view"]
    assert seen == len(range(math.ceil(0.26 * 60), math.floor(1.6 * 60) + 1))
    assert s.counts["camera_dropped_dropout"] + len(frames) + len(s._pending) == seen
    assert 0.0 < s.counts["camera_dropped_dropout"] / seen < 0.15
    # released once the state clock reached capture + latency, not a state sample later
    lag = np.array([c - f.t for c, f in frames])
    assert s.delay_range == (lag.min(), lag.max())
    assert lag.min() >= cam.latency - 1e-9 and lag.max() <= cam.latency + 1e-3 + 1e-9
    # the same seed and states: the same samples
    _, enc2, _, frames2 = _run(cfg)
    assert np.array_equal(enc, enc2) and [f for _, f in frames] == [f for _, f in frames2]


def test_gaps_and_unknown_parcels_are_counted_not_sampled():
    cfg = load_sensors("ideal")
    cfg = replace(cfg, camera=replace(cfg.camera, latency=0.0))
    skip = set(range(400, 430))  # 60 ms without state: longer than max_gap
    s, enc, gauge, frames = _run(cfg, skip=skip, dt=2e-3)
    # the instants in (0.798, 0.860] s: 62 at 1 kHz (encoder, gauge), 8 at 120 Hz (camera);
    # the gauge's too in the state intervals either side, whose cubic's stencil spans the gap
    assert s.counts["encoder_dropped_state_gap"] == 62
    assert s.counts["strain_dropped_state_gap"] == 62 + 2 + 2
    assert s.counts["camera_dropped_state_gap"] == 8
    assert not np.any((enc[:, 0] > 0.7985) & (enc[:, 0] <= 0.86))
    # noise-free: the samples are the truth, Hermite-interpolated between states 2 ms apart
    # (the gauge by its cubic through four states, the first interval's through three: the
    # 20 Hz ringing within (omega h)^3 / 15.6 = 1e-3 of its amplitude)
    assert np.max(np.abs(enc[:, 1] - _truth(enc[:, 0])[3])) < 1e-7
    assert np.max(np.abs(gauge[:, 1] - 1000.0 * _truth(gauge[:, 0])[4])) < 1.05e-3
    t = np.array([f.t for _, f in frames])
    poses = (np.array([getattr(f, k) for _, f in frames]) for k in ("x", "y", "yaw"))
    x, _, _ = camera_to_sorter(cfg.camera.offset, *poses)
    gx, _ = geometric_centre(*_truth(t)[:3], *COG)
    assert np.max(np.abs(x - gx)) < 1e-7
    # a parcel without its /parcels message is not guessed at: counted
    s2 = SensorStream(replace(cfg, camera=replace(cfg.camera, rate=60.0)), 0, None, 0.01)
    for k in range(400):
        s2.parcel_state(9, k * 1e-3, (-0.5 + V * k * 1e-3, 0.3, 0.0), (V, 0.0, 0.0))
    assert s2.counts["camera_dropped_unknown_parcel"] == 23 and not s2.release()
    # out of order: refused and counted
    s2.parcel_state(9, 0.1, (0.0, 0.3, 0.0), (V, 0.0, 0.0))
    assert s2.counts["states_dropped_out_of_order"] == 1
    # a stiff fence: no gauge samples
    assert s2.strain is None and s2.fence_state(0.0, 0.0, 0.0, 1.0)[1][0].size == 0
