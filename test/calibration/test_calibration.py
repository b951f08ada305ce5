"""Calibration from measured bags: emulator statistics, recovery of known truth, identifiability
flags and the commands' bad-input exits."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from fence_sorter.calibration.bag import read_measured_bag, write_measured_bag
from fence_sorter.calibration.emulate import draw_events, emulate, emulate_bag, truth_tracks
from fence_sorter.calibration.fit import calibrate
from fence_sorter.calibration.replay import with_values
from fence_sorter.calibration.sensors import (
    SensorConfigError,
    load_sensors,
    sorter_to_camera,
)
from fence_sorter.cli.main import main
from fence_sorter.recording.topics import CAMERA_POSES, DRIVE_ENCODER, FENCE_ROOT_MOMENT
from fence_sorter.scene import load_scene

TRUTH = {"mu_belt": 0.55, "mu_fence": 0.40, "k_p": 2.4e9, "b_p": 4.0e5}


def _truth_scene(name: str, **extra):
    base = load_scene(name).scenario
    return base, with_values(base, {**TRUTH, **extra})


def test_sensor_file_errors_name_the_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {rate: 0.5}\n")
    with pytest.raises(SensorConfigError, match=r"camera.rate must be in \[1, 1000\] Hz"):
        load_sensors(bad)
    bad.write_text("camera: {fps: 30}\n")
    with pytest.raises(SensorConfigError, match="camera.fps is not a known key"):
        load_sensors(bad)
    with pytest.raises(SensorConfigError, match="no such file"):
        load_sensors("no_such_sensors")


def test_emulated_sensors_have_the_configured_statistics(tmp_path):
    """Camera at 60 Hz: dropouts near 5 %, 2 mm noise about the truth, the frame offset and
    latency as configured; the same seed gives the same samples; the bag reads back equal
    with our reader and with the mcap library."""
    _, truth = _truth_scene("positioned_stiff")
    cfg = load_sensors("camera60")
    events = draw_events(truth, "default", 8, seed=4)
    tracks = truth_tracks(truth, events, workers=1)
    m = emulate(truth, cfg, stream="default", count=8, seed=4, workers=1)[1]
    m2 = emulate(truth, cfg, stream="default", count=8, seed=4, workers=1)[1]
    assert np.array_equal(m.cam_x, m2.cam_x) and np.array_equal(m.enc_angle, m2.enc_angle)
    assert m.str_t.size == 0  # a stiff fence has no strain gauge reading
    noise, frames, kept = [], 0, 0
    for ev, tr in zip(events, tracks, strict=True):
        sel = m.cam_id == ev.parcel_id
        tau = m.cam_t[sel] - ev.t_start
        # frames on the 60 Hz grid
        assert np.allclose(m.cam_t[sel] * 60.0, np.round(m.cam_t[sel] * 60.0), atol=1e-6)
        x, y, yaw = tr.pose_at(tau)
        cx, cy, _ = sorter_to_camera(cfg.camera.offset, x, y, yaw)
        noise.extend(m.cam_x[sel] - cx)
        noise.extend(m.cam_y[sel] - cy)
        span = np.arange(math.ceil(tau.min() * 60), math.floor(tau.max() * 60) + 1)
        frames += span.size
        kept += sel.sum()
    noise = np.array(noise)
    # sample std of n Gaussian values: relative spread 1/sqrt(2n); 5 sigma bounds
    n = noise.size
    assert abs(noise.std() / 2e-3 - 1.0) < 5.0 / math.sqrt(2 * n)
    assert abs(noise.mean()) < 5 * 2e-3 / math.sqrt(n)
    drop = 1.0 - kept / frames
    assert abs(drop - 0.05) < 5 * math.sqrt(0.05 * 0.95 / frames) + 2.0 / frames
    path = write_measured_bag(tmp_path / "bag", events, m)
    mb = read_measured_bag(path)
    assert np.allclose(mb.m.cam_x, m.cam_x, atol=1e-12)
    assert mb.m.cam_latency == pytest.approx(cfg.camera.latency, abs=1e-6)
    for got, ev in zip(mb.events, events, strict=True):
        assert got.t_start == pytest.approx(ev.t_start, abs=1e-4)  # from the 500 Hz encoder
        assert got.alpha_k == pytest.approx(ev.alpha_k, rel=1e-3)
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    counts: dict[str, int] = {}
    with next(path.glob("*.mcap")).open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == CAMERA_POSES:
                assert decoded.header.frame_id == "camera"
    assert counts[CAMERA_POSES] == m.cam_t.size
    assert counts[DRIVE_ENCODER] == m.enc_t.size
    assert FENCE_ROOT_MOMENT not in counts


def test_noise_free_bag_recovers_every_parameter(tmp_path):
    """Ideal sensors on the flexible fence: five parameters, three parcels, each recovered
    within 1e-3 relative from a prior 10-40 % off; validate with the truth scene predicts the
    measured figures exactly."""
    base, truth = _truth_scene("impact_flexible")
    truth = with_values(truth, {"fence.damping_ratio": 0.08})
    bag = emulate_bag(
        tmp_path / "ideal",
        truth,
        load_sensors("ideal"),
        scene_name="x",
        stream="default",
        count=3,
        seed=1,
    )
    mb = read_measured_bag(bag)
    names = ["mu_belt", "mu_fence", "k_p", "b_p", "fence.damping_ratio"]
    res = calibrate(base, mb, names)
    want = {**TRUTH, "fence.damping_ratio": 0.08}
    for e in res.estimates:
        assert e.verdict == "identified", e
        assert e.value == pytest.approx(want[e.name], rel=1e-3), e.name
    assert res.camera_offset == pytest.approx(load_sensors("ideal").camera.offset, abs=1e-5)


def test_contact_damping_from_25hz_poses_of_border_parcels_is_flagged(tmp_path, capsys):
    """Parcels lying at the border meet the fence without impact: 25 Hz poses fix the fence
    friction and the contact stiffness but not the contact damping b_p, which is flagged, given
    no number and left at the scene's value in the calibrated scene."""
    base = load_scene("arbitrary_stiff").scenario
    want = {"mu_fence": 0.40, "k_p": 2.4e9, "b_p": 4.0e5}
    truth = with_values(base, want)
    bag = emulate_bag(
        tmp_path / "b25", truth, load_sensors("camera25"), scene_name="x", stream="border",
        count=4, seed=5,
    )  # fmt: skip
    argv = ["calibrate", str(bag), "--scene", "arbitrary_stiff", "--fit", "mu_fence,k_p,b_p",
            "--json", "--no-progress", "--out", str(tmp_path / "out")]  # fmt: skip
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    est = {e["name"]: e for e in out["estimates"]}
    assert est["b_p"]["verdict"] == "not identifiable" and est["b_p"]["value"] is None
    assert "95 % interval spans a factor" in est["b_p"]["why"]
    for name in ("mu_fence", "k_p"):
        assert est[name]["verdict"] == "identified"
        lo, hi = est[name]["ci95"]
        assert lo < want[name] < hi, name
    scene = load_scene(tmp_path / "out" / "arbitrary_stiff_calibrated.yaml").scenario
    assert scene.contact.mu_fence == pytest.approx(est["mu_fence"]["value"], rel=1e-5)
    assert scene.contact.b_p == base.contact.b_p  # not identified: the prior stays
    assert (tmp_path / "out" / "residuals.png").stat().st_size > 10_000


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    d = tmp_path_factory.mktemp("cal")
    _, truth = _truth_scene("positioned_stiff")
    return emulate_bag(
        d / "two",
        truth,
        load_sensors("camera60"),
        scene_name="positioned_stiff",
        stream="default",
        count=2,
        seed=2,
    )


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_bag_without_measured_topics_exits_2(capsys):
    code = main(
        ["calibrate", "bags/example_4_parcels", "--scene", "impact_flexible", "--fit", "k_p"]
    )
    assert code == 2
    assert f"topic {DRIVE_ENCODER}" in _err_line(capsys)


def test_too_few_parcels_exits_2(small_bag, capsys):
    code = main(["calibrate", str(small_bag), "--fit", "k_p", "--no-progress"])
    assert code == 2
    line = _err_line(capsys)
    assert "2 parcels" in line and "at least 3" in line


@pytest.mark.parametrize(
    "fit, words",
    [
        ("fence.damping_ratio", "has a stiff fence, no fence.damping_ratio"),
        ("mu_chute", "not a fit parameter; allowed: mu_belt"),
    ],
)
def test_parameter_the_scene_lacks_exits_2(small_bag, capsys, fit, words):
    code = main(["calibrate", str(small_bag), "--fit", fit, "--no-progress"])
    assert code == 2
    assert words in _err_line(capsys)


def _three_stiff_parcels(path, truth):
    """A camera60 bag of three parcels on ``truth``, a positioned_stiff scene."""
    return emulate_bag(
        path, truth, load_sensors("camera60"), scene_name="positioned_stiff", stream="default",
        count=3, seed=2,
    )  # fmt: skip


def test_fit_that_does_not_converge_exits_3(tmp_path, capsys):
    _, truth = _truth_scene("positioned_stiff")
    bag = _three_stiff_parcels(tmp_path / "b", truth)
    code = main(
        ["calibrate", str(bag), "--fit", "mu_belt,k_p", "--max-evaluations", "1", "--no-progress"]
    )
    assert code == 3
    assert "did not converge in" in _err_line(capsys)


def test_a_twin_that_does_not_fit_the_machine_fails_unless_its_scatter_is_accepted(
    tmp_path, capsys
):
    """The machine's fence friction is 0.6 where the twin has 0.35 and the fit may not move
    it: no basin brings the camera poses to their noise, so the fit fails (exit 3) naming
    their scatter; with --max-pose-scatter above it the fit is reported with that scatter
    (and a belt friction the model error has biased beyond its interval), and fitting the
    fence friction too brings the scatter back to the camera's noise."""
    _, truth = _truth_scene("positioned_stiff", mu_fence=0.6)
    bag = _three_stiff_parcels(tmp_path / "m", truth)
    args = ["calibrate", str(bag), "--fit", "mu_belt,k_p", "--no-progress", "--json"]
    assert main(args) == 3
    line = _err_line(capsys)
    m = re.search(r"scattering ([\d.]+) times their noise .*--max-pose-scatter 1\.41", line)
    assert m, line
    scatter = float(m.group(1))
    assert scatter > 2.0
    assert main([*args, "--max-pose-scatter", "1000"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["pose_scatter"] == pytest.approx(scatter, rel=0.05)
    lo, hi = {e["name"]: e for e in out["estimates"]}["mu_belt"]["ci95"]
    assert not lo < 0.55 < hi  # the model error biases the belt friction beyond its interval
    assert main([*args[:3], "mu_belt,mu_fence,k_p", *args[4:]]) == 0
    out = json.loads(capsys.readouterr().out)
    assert 0.7 < out["pose_scatter"] < 1.3
    est = {e["name"]: e for e in out["estimates"]}
    lo, hi = est["mu_fence"]["ci95"]
    assert lo < 0.6 < hi


@pytest.mark.parametrize(
    ("option", "value"),
    [("--max-pose-scatter", "0.9"), ("--max-pose-scatter", "nan"), ("--max-ci-factor", "1"),
     ("--max-evaluations", "0"), ("--starts", "0")],
)  # fmt: skip
def test_bad_fit_options_exit_2_naming_the_option(capsys, option, value):
    code = main(["calibrate", "no_such_bag", "--fit", "k_p", option, value])
    assert code == 2
    assert option in _err_line(capsys)


def test_validate_with_the_truth_scene_predicts_the_measured_figures(tmp_path, capsys):
    """Noise-free poses: the truth scene predicts each parcel's figures as measured; a scene
    with a slipperier belt predicts a different y_max."""
    base, truth = _truth_scene("positioned_stiff")
    bag = emulate_bag(
        tmp_path / "v",
        truth,
        load_sensors("ideal"),
        scene_name="positioned_stiff",
        stream="default",
        count=3,
        seed=6,
    )
    scene = tmp_path / "truth.yaml"
    from fence_sorter.calibration.report import write_scene

    write_scene(load_scene("positioned_stiff").source_path, TRUTH, scene, "truth")
    assert main(["validate", str(bag), "--scene", str(scene), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["summary"]["sorted_agree"] == 3
    assert out["summary"]["y_max"]["max_abs_error"] < 1e-6
    sets = ["--set", "conveyor.mu_belt=0.3"]
    assert main(["validate", str(bag), "--scene", str(scene), *sets, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["summary"]["y_max"]["max_abs_error"] > 1e-3


def test_bootstrap_intervals_agree_with_the_jacobian(tmp_path):
    """The parametric bootstrap's percentile interval of the fence friction has the width of
    the Jacobian's 95 % interval (8 refits: within a factor 2.5) and overlaps it."""
    base = load_scene("arbitrary_stiff").scenario
    truth = with_values(base, {"mu_fence": 0.40})
    bag = emulate_bag(
        tmp_path / "boot", truth, load_sensors("camera60"), scene_name="x", stream="default",
        count=3, seed=8,
    )  # fmt: skip
    res = calibrate(base, read_measured_bag(bag), ["mu_fence"], bootstrap=8, seed=1)
    (e,) = res.estimates
    assert e.ci95[0] < 0.40 < e.ci95[1]
    jac_width = e.ci95[1] - e.ci95[0]
    boot_width = e.bootstrap_ci95[1] - e.bootstrap_ci95[0]
    assert 1 / 2.5 < boot_width / jac_width < 2.5
    assert e.bootstrap_ci95[0] < e.ci95[1] and e.ci95[0] < e.bootstrap_ci95[1]
