"""The fence root moment a run's gauge measures against the calibration's replay of the same
parcel and stroke (ROS-free; the run over DDS: test/ros/test_sensors_run.py).

The run's path: the line's adaptive solve, its state at the simulator's 250 Hz publication, the
sensors node's interpolation to the gauge's 1 kHz. The replay's: a fixed-step trapezoidal solve
(calibration/replay.py). Both read M = k w_tip; they must agree to well within the gauge's noise
level (camera60: 2 N m), through the stroke and the fence's ring-down after it, or the fit reads
their difference as physics."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fence_sorter.calibration.replay import ParcelEvent, replay, root_moment_factor
from fence_sorter.calibration.sensors import SensorStream, load_sensors
from fence_sorter.codes import StartMode
from fence_sorter.inputs import ParcelSpec, StrokeCommand
from fence_sorter.line.one_fence import LineConfig, SortingLine
from fence_sorter.physics.drive import drive_state
from fence_sorter.physics.params import DriveParams
from fence_sorter.runner.job import MAX_STATE_RATE
from fence_sorter.scene import load_scene

pytestmark = pytest.mark.slow

T1, ALPHA_K = 0.35, math.radians(40.0)
DRIVE = DriveParams(alpha_k=ALPHA_K, t1=T1, r_s=0.42)


@pytest.mark.parametrize(("mass", "gap"), [(15.0, 0.25), (4.0, 0.1)])
def test_the_runs_gauge_follows_the_replay_through_stroke_and_ring_down(mass, gap):
    sc = load_scene("impact_flexible").scenario
    line = SortingLine(LineConfig.from_scenario(sc))
    spec = ParcelSpec(1, mass=mass, lateral_gap=gap, divert=True, scan_position_x=-1.0)
    line.add_parcel(spec)
    t_start = 1.42  # the front from -1 m to R_s = 0.42 m at 1 m/s
    cmd = StrokeCommand(1, StartMode.AT_TIME, start_time=t_start, t1=T1, alpha_k=ALPHA_K)
    assert line.command(cmd).accepted
    gauge_cfg = load_sensors("camera60")
    sigma = gauge_cfg.strain.noise
    noiseless = replace(gauge_cfg, strain=replace(gauge_cfg.strain, noise=0.0))
    factor = root_moment_factor(sc)
    rate = MAX_STATE_RATE  # the simulator's state in a run with a 1 kHz gauge
    stream = SensorStream(noiseless, 1, factor, 3.0 / rate)
    gt, gm = [], []
    for k in range(1, int(3.0 * rate) + 1):
        line.advance(k / rate)
        f = line.snapshot().fence
        # the published drive angle is the prescribed drive's (no interpolation between steps)
        assert f.drive_angle == drive_state(DRIVE, k / rate - t_start).alpha
        _, (tt, mm) = stream.fence_state(k / rate, f.drive_angle, f.drive_rate, f.tip_deflection)
        gt.append(tt)
        gm.append(mm)
    gt, gm = np.concatenate(gt), np.concatenate(gm)
    ev = ParcelEvent(1, spec.to_parcel_params(), ALPHA_K, T1, 0.42, t_start)
    tr = replay(sc, ev)
    sel = (gt >= t_start) & (gt < t_start + ev.t_end)
    tau = gt[sel] - t_start
    ref = tr.moment_at(tau)
    d = gm[sel] - ref
    ring = tau > 2.0 * T1
    # a loaded fence (peaks of hundreds of N m) and a ring-down that is not at rest
    assert np.abs(ref).max() > 50.0 * sigma and np.abs(ref[ring]).max() > 5.0 * sigma
    # the mismatch adds at most 12 % to the gauge's noise (in quadrature: sigma / 2), and no
    # sample is off by more than two noise levels
    assert np.sqrt(np.mean(d**2)) < 0.5 * sigma
    assert np.abs(d).max() < 2.0 * sigma
    assert np.sqrt(np.mean(d[ring] ** 2)) < 0.5 * sigma
