"""A line's hand-off through fence_sorter_msgs/HandOff: rclpy's serialisation (what goes over
DDS) read back by rosbags' deserialiser (what a bag reader sees), and rclpy's own round trip
back to the line's record."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from fence_sorter.inputs import ParcelSpec
from fence_sorter.line.handoff import INDUCTION, RECIRCULATION, HandOff
from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.nodes.convert import handoff_from_msg, handoff_to_msg
from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter_msgs.msg import HandOff as HandOffMsg

pytestmark = pytest.mark.ros


def records() -> list[HandOff]:
    """Hand-offs with values that are not short decimals: a parcel of the two_units stream,
    turned and moving off the belt's kinematics, from each kind of sender to each receiver."""
    plant = LinePlant(load_line("two_units"), LineRunConfig(parcels=1, seed=4))
    spec = replace(plant.parcels[0].spec, cog_offset_x=0.0312, cog_offset_y=-0.0177)
    base = HandOff(
        parcel_id=spec.parcel_id, destination="C", passes=1, spec=spec, x=7.123456789012345,
        y=0.31415926535, yaw=-2.7182818, vx=0.987654321, vy=-0.0123456789, yaw_rate=0.4142,
        pose_time=12.345678901234567, t=12.355, from_unit=0, to_unit=1,
    )  # fmt: skip
    return [
        base,
        replace(base, from_unit=INDUCTION, to_unit=0, destination="", passes=0),
        replace(base, from_unit=1, to_unit=RECIRCULATION, passes=2),
    ]


def expected_fields(h: HandOff) -> dict:
    s = h.spec
    return {
        "from_unit": h.from_unit, "to_unit": h.to_unit, "x": h.x, "y": h.y, "yaw": h.yaw,
        "vx": h.vx, "vy": h.vy, "yaw_rate": h.yaw_rate, "pose_time": h.pose_time,
        "parcel_id": h.parcel_id, "destination": h.destination, "passes": h.passes,
        "length_a": s.length_a, "width_b": s.width_b, "height": s.height, "mass": s.mass,
        "cog_offset_x": s.cog_offset_x, "cog_offset_y": s.cog_offset_y,
    }  # fmt: skip


@pytest.mark.parametrize("h", records(), ids=["unit>unit", "induction>unit", "unit>recirc"])
def test_rclpy_bytes_read_by_rosbags_equal_the_record(h: HandOff) -> None:
    data = serialize_message(handoff_to_msg(h, run_id=77))
    ts = make_typestore()
    msg = ts.deserialize_cdr(data, "fence_sorter_msgs/msg/HandOff")
    p = msg.parcel
    got = {
        "from_unit": msg.from_unit, "to_unit": msg.to_unit, "x": msg.x, "y": msg.y,
        "yaw": msg.yaw, "vx": msg.vx, "vy": msg.vy, "yaw_rate": msg.yaw_rate,
        "pose_time": msg.pose_time, "parcel_id": p.parcel_id, "destination": p.destination,
        "passes": p.passes, "length_a": p.length_a, "width_b": p.width_b, "height": p.height,
        "mass": p.mass, "cog_offset_x": p.cog_offset_x, "cog_offset_y": p.cog_offset_y,
    }  # fmt: skip
    assert got == expected_fields(h)  # bit-exact floats
    assert msg.run_id == 77 and p.run_id == 77
    assert msg.header.frame_id == "line"
    stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
    assert stamp == pytest.approx(h.t, abs=1e-9)


@pytest.mark.parametrize("h", records(), ids=["unit>unit", "induction>unit", "unit>recirc"])
def test_the_record_survives_rclpy_both_ways(h: HandOff) -> None:
    msg = deserialize_message(serialize_message(handoff_to_msg(h)), HandOffMsg)
    back = handoff_from_msg(msg)
    # times travel as builtin Time (ns) in the header and the parcel's scan time; the stream's
    # arrival time is the induction's, not carried
    assert back.t == pytest.approx(h.t, abs=1e-9)
    assert back.spec.scan_time == pytest.approx(h.spec.scan_time, abs=1e-9)
    same = {f.name for f in fields(ParcelSpec)} - {"scan_time", "arrival_time"}
    for name in same:
        a, b = getattr(back.spec, name), getattr(h.spec, name)
        assert a == b or (math.isnan(a) and math.isnan(b)), name
    assert replace(back, t=h.t, spec=h.spec) == h
    assert back.no_read == (h.destination == "")
