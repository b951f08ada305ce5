"""TF and the robot description of a recorded run, read back with the independent MCAP reader
(mcap + mcap_ros2, not our reader): every parcel frame on /tf is its /load_states pose, the
fence frame is the /joint_states angle, /tf_static holds the URDF's fixed joints and
/robot_description is the URDF with the scene's geometry."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from processes import run_cli

pytestmark = [pytest.mark.ros, pytest.mark.slow]

PARCELS = 3
TOLERANCE = 1e-9  # m and rad: the frames carry the very numbers of the state messages


def _stamp(header) -> int:
    return header.stamp.sec * 10**9 + header.stamp.nanosec


@pytest.fixture(scope="module")
def bag_messages(tmp_path_factory) -> dict[str, list]:
    """`fence-sorter run --parcels 3 --rtf 2 --bag DIR`, every message decoded by mcap_ros2."""
    base = tmp_path_factory.mktemp("tf_run")
    bag = base / "bag"
    out = run_cli(
        "run", "--parcels", str(PARCELS), "--rtf", "2", "--bag", str(bag),
        "--log-dir", str(base / "logs"), timeout=400,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    messages: dict[str, list] = defaultdict(list)
    segments = sorted(Path(bag).glob("*.mcap"))
    assert segments
    for segment in segments:
        with segment.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages():
                messages[channel.topic].append(msg)
    return messages


def test_parcel_frames_are_the_load_poses(bag_messages):
    loads = {
        (_stamp(m.header), m.parcel_id): m.pose for m in bag_messages["/load_states"]
    }  # best effort (and /tf keep-last): a few may be missing, the matched ones agree exactly
    frames = {}
    for msg in bag_messages["/tf"]:
        for tr in msg.transforms:
            assert tr.header.frame_id == "sorter"
            if tr.child_frame_id.startswith("parcel_"):
                frames[(_stamp(tr.header), int(tr.child_frame_id[7:]))] = tr.transform
    matched = [key for key in loads if key in frames]
    assert len(matched) >= 0.9 * len(loads) > 50
    assert {pid for _, pid in frames} == {pid for _, pid in loads}
    assert len({pid for _, pid in frames}) == PARCELS
    for key in matched:
        pose, tr = loads[key], frames[key]
        assert abs(tr.translation.x - pose.position.x) <= TOLERANCE
        assert abs(tr.translation.y - pose.position.y) <= TOLERANCE
        assert abs(tr.translation.z - pose.position.z) <= TOLERANCE
        q, r = pose.orientation, tr.rotation
        assert max(abs(q.x - r.x), abs(q.y - r.y), abs(q.z - r.z), abs(q.w - r.w)) <= TOLERANCE
    # the parcels move along the belt: the frames are not one pose repeated
    xs = [frames[k].translation.x for k in matched]
    assert max(xs) - min(xs) > 1.0


def test_fence_frame_is_the_joint_angle(bag_messages):
    joints = {_stamp(m.header): m for m in bag_messages["/joint_states"]}
    fence = {
        _stamp(tr.header): tr.transform.rotation
        for msg in bag_messages["/tf"]
        for tr in msg.transforms
        if tr.child_frame_id == "fence"
    }
    matched = [t for t in joints if t in fence]
    assert len(matched) >= 0.9 * len(joints) > 100
    swung = 0
    for t in matched:
        joint = joints[t]
        assert joint.name == ["fence_drive"]
        q = fence[t]
        assert abs(q.x) + abs(q.y) <= TOLERANCE  # a rotation about z only
        angle = 2.0 * math.atan2(q.z, q.w)
        assert abs(angle - joint.position[0]) <= TOLERANCE
        swung += joint.position[0] > 0.1
    assert swung > 0  # the strokes of the divert parcels are in it


def test_static_frames_and_robot_description(bag_messages):
    (description,) = bag_messages["/robot_description"]
    robot = ET.fromstring(description.data)
    joints = {j.get("name"): j for j in robot.iter("joint")}
    assert joints["fence_drive"].get("type") == "revolute"
    assert joints["fence_drive"].find("axis").get("xyz") == "0 0 1"
    fixed = {n for n, j in joints.items() if j.get("type") == "fixed"}
    (static,) = bag_messages["/tf_static"]
    children = {tr.child_frame_id: tr.transform.translation for tr in static.transforms}
    assert set(children) == {joints[n].find("child").get("link") for n in fixed}
    assert {"belt", "chute", "scan_line"} <= set(children)
    # impact_flexible: belt width s = 0.7 m (belt centre line at s/2), fence R_z = 1.2 m
    assert children["belt"].y == pytest.approx(0.35, abs=1e-12)
    assert children["scan_line"].x == pytest.approx(-3.0, abs=1e-12)
    fence_box = robot.find("link[@name='fence']/visual/geometry/box").get("size").split()
    assert float(fence_box[0]) == pytest.approx(1.2, abs=1e-12)
