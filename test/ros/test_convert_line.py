"""Converters between the line's dataclasses and fence_sorter messages (no DDS): round trips
keep every field; state messages carry the snapshot's numbers in frame sorter."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_parcel_command_outcome_round_trips():
    from fence_sorter.line import Outcome, OutcomeCode, ParcelSpec, StartMode, StrokeCommand
    from fence_sorter.nodes import convert

    p = ParcelSpec(
        42, 0.5, 0.25, 0.2, 7.5, -0.1, 0.05, 0.12, 0.3, math.nan, 0.4, True, 12.345678901, -3.0
    )
    back = convert.parcel_from_msg(convert.parcel_to_msg(p))
    assert math.isnan(back.mu_belt)
    assert back == ParcelSpec(**{**p.__dict__, "mu_belt": back.mu_belt})
    assert back.scan_time == pytest.approx(p.scan_time, abs=1e-9)

    c = StrokeCommand(42, StartMode.AT_TIME, 0.3, 15.25, 0.4, math.radians(35.0), False, "why")
    msg = convert.command_to_msg(c, 11.0, {"impact_speed": 2.1, "capacity_pcs_h": 2700.0})
    assert msg.predicted_impact_speed == 2.1 and msg.predicted_capacity_pcs_h == 2700.0
    assert convert.command_from_msg(msg) == c

    o = Outcome(42, 16.5, OutcomeCode.SORTED, "sorted", 700.0, 1600.0, 140.0, 2.3, 1.9, 0.75, 0.8)
    m = convert.outcome_to_msg(o)
    assert m.sorted and m.reason_code == 0 and m.header.frame_id == "sorter"
    assert convert.outcome_from_msg(m) == o


def test_state_messages_from_a_snapshot():
    from fence_sorter.line import LineConfig, ParcelSpec, SortingLine, StrokeCommand
    from fence_sorter.nodes import convert
    from fence_sorter.scene import load_scene

    line = SortingLine(LineConfig.from_scenario(load_scene("impact_flexible").scenario))
    line.add_parcel(ParcelSpec(1, mass=15.0, lateral_gap=0.25, divert=True, scan_position_x=-1))
    line.command(StrokeCommand(1, r_s=0.42, t1=0.35, alpha_k=math.radians(40.0)))
    for k in range(1, 801):
        line.advance(0.002 * k)  # 1.6 s: mid-stroke
    snap = line.snapshot()
    f = convert.fence_state_to_msg(snap.fence, snap.t)
    assert f.drive_angle == snap.fence.drive_angle > 0.0
    np.testing.assert_array_equal(np.asarray(f.node_y), snap.fence.node_y)
    assert f.header.stamp.sec == 1 and f.header.stamp.nanosec == 600_000_000
    j = convert.joint_state_to_msg(snap.fence, snap.t)
    assert list(j.name) == ["fence_drive"] and list(j.position) == [snap.fence.drive_angle]
    p = snap.parcels[0]
    ls = convert.load_state_to_msg(p, snap.t)
    assert (ls.pose.position.x, ls.pose.position.y) == (p.x, p.y)
    assert 2.0 * math.atan2(ls.pose.orientation.z, ls.pose.orientation.w) == pytest.approx(p.yaw)
    assert ls.stage == int(p.stage) and ls.twist.linear.y == p.vy
    markers = convert.markers_to_msg(snap, 0.7, (-3.0, 3.0)).markers
    fence = next(m for m in markers if m.ns == "fence")
    assert len(fence.points) == 11 and fence.points[-1].y == pytest.approx(snap.fence.node_y[-1])
    assert [m.text for m in markers if m.ns == "parcel_ids"] == ["1"]


def test_code_enums_match_the_generated_message_constants():
    """fence_sorter.codes is the one Python copy of the messages' integer codes."""
    from fence_sorter.codes import OutcomeCode, Stage, StartMode, code_name
    from fence_sorter_msgs.msg import FenceCommand, LoadState, SortOutcome

    for code in OutcomeCode:
        assert getattr(SortOutcome, code.name) == code
    for stage in Stage:
        assert getattr(LoadState, f"STAGE_{stage.name}") == stage
    for mode in StartMode:
        assert getattr(FenceCommand, f"START_{mode.name}") == mode
    # every constant of the messages has its enum member
    n_out = [
        k for k in dir(SortOutcome) if k.isupper() and isinstance(getattr(SortOutcome, k), int)
    ]
    assert len(n_out) == len(OutcomeCode)
    assert code_name(OutcomeCode, 0) == "SORTED" and code_name(OutcomeCode, 99) == "CODE_99"
