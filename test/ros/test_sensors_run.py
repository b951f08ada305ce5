"""`fence-sorter run --sensors FILE --bag DIR`: the sensors node (a separate process over DDS)
publishes the measured topics from the simulator's state and the recorder records them with the
truth. The bag holds the encoder, camera and strain gauge at the configured rates, with the
configured noise about the truth recorded in the same bag (/fence_state, /load_states), the
configured dropout share, camera frame and latency, and `fence-sorter calibrate` fits it."""

from __future__ import annotations

import json
import math
from dataclasses import asdict

import numpy as np
import pytest
from processes import run_cli

from fence_sorter.calibration.bag import read_measured_bag
from fence_sorter.calibration.events import event_data, predict
from fence_sorter.calibration.replay import root_moment_factor
from fence_sorter.calibration.sensors import (
    camera_to_sorter,
    geometric_centre,
    in_view,
    load_sensors,
)
from fence_sorter.recording.bagread import read_bag
from fence_sorter.recording.topics import (
    CAMERA_POSES,
    DIAGNOSTICS,
    DRIVE_ENCODER,
    FENCE_ROOT_MOMENT,
    FENCE_STATE,
    LOAD_STATES,
    PARCELS,
)
from fence_sorter.scene import load_scene

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SCENE = "impact_flexible"
#: four parcels to divert, 1.5 s apart: four strokes
MANIFEST = """parcel_id,arrival_time,length_a,width_b,height,mass,lateral_gap,yaw_deg,divert
1,0.0,0.40,0.30,0.30,8.0,0.10,0.0,true
2,1.5,0.30,0.20,0.20,3.0,0.05,0.0,true
3,3.0,0.25,0.25,0.15,2.0,0.15,2.0,true
4,4.5,0.50,0.30,0.40,15.0,0.05,0.0,true
"""
#: rates a loaded 2-core machine records without loss (the state then runs at 250 Hz)
SENSORS = """name: test250
encoder: {rate: 250.0, noise: 2.0e-4}
camera:
  rate: 50.0
  noise_position: 3.0e-3
  noise_yaw_deg: 1.0
  dropout: 0.1
  latency: 0.05
  offset: {x: 0.3, y: -0.1, yaw_deg: 2.0}
  field_of_view: {x: [-1.0, 2.0], y: [-0.1, 0.8]}
strain: {rate: 250.0, noise: 2.0}
"""


def _t(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One paced run (rtf 1) with the sensors, recorded."""
    tmp = tmp_path_factory.mktemp("sensors_run")
    (tmp / "m.csv").write_text(MANIFEST)
    (tmp / "s.yaml").write_text(SENSORS)
    bag = tmp / "bag"
    proc = run_cli(
        "run",
        "--scene",
        SCENE,
        "--stream",
        str(tmp / "m.csv"),
        "--rtf",
        "1",
        "--sensors",
        str(tmp / "s.yaml"),
        "--bag",
        str(bag),
        "--json",
        "--log-dir",
        str(tmp / "logs"),
        timeout=240,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = json.loads(proc.stdout)
    contents = read_bag(
        bag,
        [
            DRIVE_ENCODER,
            CAMERA_POSES,
            FENCE_ROOT_MOMENT,
            FENCE_STATE,
            LOAD_STATES,
            PARCELS,
            DIAGNOSTICS,
        ],
    )
    diag = None
    for m in contents.by_topic(DIAGNOSTICS):
        for status in m.msg.status:
            if status.name == "fence_sorter/sensors":
                diag = {kv.key: kv.value for kv in status.values}
    assert diag is not None, "no /diagnostics of the sensors node in the bag"
    return {
        "bag": bag,
        "summary": summary,
        "bag_contents": contents,
        "diag": diag,
        "cfg": load_sensors(tmp / "s.yaml"),
        "tmp": tmp,
    }


def test_encoder_and_gauge_rates_and_noise_about_the_recorded_truth(run):
    s, b, diag, cfg = run["summary"], run["bag_contents"], run["diag"], run["cfg"]
    assert s["by_reason"] == {"SORTED": 4} and set(s["exit_codes"]) >= {"sensors", "recorder"}
    assert s["sensors"]["sensors"] == "test250"  # the node's figures in the run's summary
    fence = b.by_topic(FENCE_STATE)
    tf = np.array([_t(m.msg.header.stamp) for m in fence])
    # the simulator's state at the sensors' highest rate (250 Hz of sim time)
    assert np.median(np.diff(tf)) == pytest.approx(1.0 / 250.0, rel=1e-3)
    alpha = np.array([m.msg.drive_angle for m in fence])
    moment = root_moment_factor(load_scene(SCENE).scenario) * np.array(
        [m.msg.tip_deflection for m in fence]
    )
    for topic, rate, noise, value, truth, key in (
        (DRIVE_ENCODER, cfg.encoder.rate, cfg.encoder.noise, "position", alpha, "encoder"),
        (FENCE_ROOT_MOMENT, cfg.strain.rate, cfg.strain.noise, "torque", moment, "strain"),
    ):
        msgs = b.by_topic(topic)
        t = np.array([_t(m.msg.header.stamp) for m in msgs])
        # stamped on the sensor's instants k / rate, each once; up to the fence-state clock of
        # the node's last heartbeat none missing but those it counted (/load_states may run
        # ahead of /fence_state: the overall state clock is not the fence samples' clock)
        k = np.round(t * rate)
        assert np.max(np.abs(t * rate - k)) < 1e-5 and np.all(np.diff(k) >= 1)
        # the gauge's samples wait for the state after their interval (4 ms)
        clock = float(diag["fence_clock_s"]) - (0.004 if key == "strain" else 0.0)
        upto = int((t <= clock + 1e-9).sum())
        gaps = int(diag[f"{key}_dropped_state_gap"])
        missing = math.floor(clock * rate + 1e-6) - k[0] + 1 - upto
        assert 0 <= missing <= gaps, topic
        # what the node published before the recorder matched it (the run's first moments,
        # before any parcel) is not in the bag: at most 2 s of it
        assert 0 <= int(diag[f"{key}_published"]) - upto <= 2.0 * rate, topic
        # states the node did not get (a loaded machine): few, and counted
        assert gaps <= 0.1 * len(k), f"{topic}: {gaps} samples lost to state gaps"
        if value == "position":
            measured = np.array([m.msg.position[0] for m in msgs])
        else:
            measured = np.array([m.msg.wrench.torque.z for m in msgs])
        # the truth at the same instants: the recorded state (the same 250 Hz instants)
        sel = (t >= tf[0]) & (t <= tf[-1])
        err = measured[sel] - np.interp(t[sel], tf, truth)
        assert np.std(err) == pytest.approx(noise, rel=0.15), topic
        assert abs(np.mean(err)) < 5.0 * noise / math.sqrt(err.size), topic


def test_camera_noise_frame_offset_dropouts_and_latency(run):
    b, diag, cfg = run["bag_contents"], run["diag"], run["cfg"]
    cam = cfg.camera
    cog = {m.msg.parcel_id: (m.msg.cog_offset_x, m.msg.cog_offset_y) for m in b.by_topic(PARCELS)}
    states: dict[int, list] = {}
    for m in b.by_topic(LOAD_STATES):
        q = m.msg.pose.orientation
        states.setdefault(m.msg.parcel_id, []).append(
            (
                _t(m.msg.header.stamp),
                m.msg.pose.position.x,
                m.msg.pose.position.y,
                2.0 * math.atan2(q.z, q.w),
            )
        )
    frames = b.by_topic(CAMERA_POSES)
    assert {m.msg.header.frame_id for m in frames} == {"camera"}
    err_xy, err_yaw, published, in_view_count = [], [], 0, 0
    for pid, rows in states.items():
        tr = np.array(rows)
        mine = [m for m in frames if m.msg.parcel_id == pid]
        t = np.array([_t(m.msg.header.stamp) for m in mine])
        # stamped with the capture instant k / rate (not capture + latency)
        assert np.max(np.abs(t * cam.rate - np.round(t * cam.rate))) < 1e-5
        cx = np.array([m.msg.pose.position.x for m in mine])
        cy = np.array([m.msg.pose.position.y for m in mine])
        cyaw = np.array([2.0 * math.atan2(m.msg.pose.orientation.z, m.msg.pose.orientation.w)
                         for m in mine])  # fmt: skip
        x, y, yaw = camera_to_sorter(cam.offset, cx, cy, cyaw)
        tx, ty, tyaw = (np.interp(t, tr[:, 0], tr[:, k]) for k in (1, 2, 3))
        gx, gy = geometric_centre(tx, ty, tyaw, *cog[pid])
        err_xy += [x - gx, y - gy]
        err_yaw.append(yaw - tyaw)
        # the instants the truth puts the parcel in view
        grid = np.arange(math.floor(tr[0, 0] * cam.rate) + 1, math.floor(tr[-1, 0] * cam.rate) + 1)
        tg = grid / cam.rate
        gx, gy = geometric_centre(
            *(np.interp(tg, tr[:, 0], tr[:, k]) for k in (1, 2, 3)), *cog[pid]
        )
        in_view_count += int(in_view(cam, gx, gy).sum())
        published += len(mine)
    exy, eyaw = np.concatenate(err_xy), np.concatenate(err_yaw)
    # robust spread (the recorded truth is linear between 4 ms states; impacts bend it)
    sigma = 1.4826 * np.median(np.abs(exy - np.median(exy)))
    assert sigma == pytest.approx(cam.noise_position, rel=0.2)
    assert abs(np.median(exy)) < 1e-3  # the configured camera frame, undone, leaves no offset
    assert 1.4826 * np.median(np.abs(eyaw)) == pytest.approx(cam.noise_yaw, rel=0.25)
    # dropouts: the frames in view, less those counted as lost to state gaps, less published
    lost = int(diag["camera_dropped_state_gap"])
    clock = float(diag["state_clock_s"])
    share = 1.0 - published / (in_view_count - lost)
    # enough frames for the figures; the frames lost to state gaps are counted, and how many
    # there are is a figure of the machine's load (a node that falls behind /load_states,
    # about 1000 messages/s with four parcels in view, loses stretches of its history: 75 of
    # 331 frames on a CI machine), so the bound only says most frames were measured
    assert published > 150 and lost <= 0.5 * in_view_count, (published, lost, in_view_count)
    assert 0.04 < share < 0.18, (share, published, in_view_count, lost)
    # released by the heartbeat: due (capture + latency) by the state clock, and measured
    # from a load state the node had: every parcel's state up to the load clock's previous
    # instant (4 ms earlier) surely, the states of the load clock's own instant perhaps not
    # all (the heartbeat may fall between two parcels' states of one instant)
    load = float(diag["load_clock_s"])
    due = [_t(m.msg.header.stamp) for m in frames]
    due = np.array([tc for tc in due if tc + cam.latency <= clock + 1e-9])
    surely, perhaps = int((due <= load - 0.004 + 1e-9).sum()), int((due <= load + 1e-9).sum())
    assert surely <= int(diag["camera_published"]) <= perhaps
    # latency: a frame goes out once the state stream reaches its capture + latency, at the
    # first state past it (states 4 ms apart)
    assert cam.latency <= float(diag["camera_delay_min_s"]) <= cam.latency + 0.004 + 1e-6
    assert float(diag["camera_delay_max_s"]) >= float(diag["camera_delay_min_s"])


def test_the_gauge_is_the_replays_of_the_runs_parcels_plus_its_noise(run):
    """The run's root moment (the line's solve, its 250 Hz state, the sensors node) against the
    calibration's replays of the same parcels and strokes (fixed-step trapezoid) over each
    parcel's window, ring-down included: what is left is the gauge's noise, no bias, and the
    two models' difference adds at most sigma / 2 in quadrature."""
    base = load_scene(SCENE).scenario
    sigma = run["cfg"].strain.noise
    mb = read_measured_bag(run["bag"])
    res, peaks = [], []
    for ed in event_data(mb, base.solver.settle_time):
        *_, moment = predict(base, ed, {})
        res.append(ed.str_m - moment)
        peaks.append(np.abs(moment).max())
    r = np.concatenate(res)
    assert len(peaks) == 4 and min(peaks) > 10.0 * sigma  # every stroke loads the fence
    assert sigma * 0.9 < np.sqrt(np.mean(r**2)) < sigma * math.hypot(1.0, 0.5)
    assert abs(np.mean(r)) < 5.0 * sigma / math.sqrt(r.size)


def test_the_bag_carries_the_truth_and_calibrate_fits_it(run):
    mb = read_measured_bag(run["bag"])
    truth = mb.truth
    base = load_scene(SCENE).scenario
    assert truth["scene"] == SCENE and truth["source"] == "fence-sorter run"
    assert truth["values"]["mu_fence"] == base.contact.mu_fence
    assert truth["sensors_spec"] == json.loads(json.dumps(asdict(run["cfg"])))
    assert len(mb.events) == 4
    out = run["tmp"] / "cal"
    proc = run_cli(
        "calibrate",
        str(run["bag"]),
        "--fit",
        "mu_fence",
        "--scene",
        SCENE,
        "--out",
        str(out),
        "--json",
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    (est,) = res["estimates"]
    assert est["verdict"] == "identified"
    # within 5 %; the 95 % interval holds the truth on about 95 % of run bags
    # (docs/guide/calibration.md, run bags), so on this one bag it is not asserted
    assert est["value"] == pytest.approx(truth["values"]["mu_fence"], rel=0.05), est
    lo, hi = est["ci95"]
    assert lo < est["value"] < hi and hi / lo < 1.2, est
    cam = run["cfg"].camera
    off = res["camera_offset"]
    assert off["x_m"] == pytest.approx(cam.offset[0], abs=3e-3)
    assert off["y_m"] == pytest.approx(cam.offset[1], abs=3e-3)
    assert math.radians(off["yaw_deg"]) == pytest.approx(cam.offset[2], abs=math.radians(0.2))
    assert res["noise_sigma"]["position_m"] == pytest.approx(cam.noise_position, rel=0.2)
    assert res["encoder_rms_rad"] == pytest.approx(run["cfg"].encoder.noise, rel=0.2)


def test_a_bad_sensors_file_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {rate: 5000}\n")
    proc = run_cli("run", "--sensors", str(bad), timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "camera.rate must be in [1, 1000] Hz, got 5000" in lines[0]


def test_the_sensors_node_exits_2_naming_the_bad_key(tmp_path, env):
    import subprocess
    import sys

    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {dropout: 1.5}\n")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "fence_sorter.nodes.sensors",
            "--ros-args",
            "-p",
            f"sensors:={bad}",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last == "sensors: sensors bad.yaml: camera.dropout must be in [0, 0.9], got 1.5"


def test_the_mcap_library_reads_the_measured_topics_alike(run):
    """An independent reader (mcap + mcap_ros2) over every segment of the run's bag: the
    measured topics with our reader's counts, stamps and values."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    b = run["bag_contents"]
    topics = [DRIVE_ENCODER, CAMERA_POSES, FENCE_ROOT_MOMENT]
    seen: dict[str, list] = {t: [] for t in topics}
    for segment in sorted(run["bag"].glob("*.mcap")):
        with segment.open("rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, channel, message, decoded in reader.iter_decoded_messages(topics=topics):
                seen[channel.topic].append((message.log_time, _t(decoded.header.stamp), decoded))
    for topic in topics:
        ours = sorted((m.t_ns, _t(m.msg.header.stamp)) for m in b.by_topic(topic))
        theirs = sorted((t_ns, stamp) for t_ns, stamp, _ in seen[topic])
        assert len(theirs) == len(ours) > 0 and theirs == ours, topic
    poses = {(_t(m.msg.header.stamp), m.msg.parcel_id): m.msg.pose.position.x
             for m in b.by_topic(CAMERA_POSES)}  # fmt: skip
    assert all(
        poses[(stamp, d.parcel_id)] == d.pose.position.x for _, stamp, d in seen[CAMERA_POSES]
    )
