"""The plain functions under the scanner and controller nodes (message types, no DDS)."""

from __future__ import annotations

import math

import pytest

from fence_sorter.capacity.planner import Plan

pytestmark = pytest.mark.ros


def parcel_msg(**fields):
    from fence_sorter_msgs.msg import Parcel

    msg = Parcel()
    msg.parcel_id = 7
    msg.length_a, msg.width_b, msg.height, msg.mass = 0.4, 0.3, 0.2, 5.0
    msg.lateral_gap = 0.1
    msg.mu_belt = msg.mu_fence = math.nan
    msg.divert = True
    msg.scan_time.sec, msg.scan_time.nanosec = 12, 500_000_000
    msg.scan_position_x = -3.0
    for k, v in fields.items():
        setattr(msg, k, v)
    return msg


def test_parcel_message_to_request() -> None:
    from fence_sorter.nodes.controller import request_from_spec
    from fence_sorter.nodes.convert import parcel_from_msg

    req = request_from_spec(parcel_from_msg(parcel_msg()))
    assert req.parcel_id == 7 and req.scan_time == pytest.approx(12.5)
    assert req.parcel.mass == 5.0 and math.isnan(req.mu_belt)


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        ({"length_a": math.nan}, "length_a must be a finite number"),
        ({"scan_position_x": math.inf}, "scan_position_x must be a finite number"),
        ({"mass": -1.0}, r"mass must be in \[0.01, 500\] kg"),
        ({"width_b": 0.9}, "exceeds the belt"),
        ({"mu_fence": 5.0}, r"mu_fence must be in \[0, 2\]"),
        ({"scan_position_x": 1e9}, r"scan_position_x must be in \[-100, 100\] m"),
    ],
)
def test_malformed_parcel_message_is_rejected_naming_the_field(fields, match) -> None:
    """The controller's path: message -> ParcelSpec -> the one validation."""
    from fence_sorter.inputs import InputError, validate_parcel
    from fence_sorter.nodes.convert import parcel_from_msg

    with pytest.raises(InputError, match=match):
        validate_parcel(parcel_from_msg(parcel_msg(**fields)), 0.7, now=12.5)


def test_infeasible_plan_becomes_a_command_with_its_reason() -> None:
    from fence_sorter.nodes.controller import fill_command
    from fence_sorter_msgs.msg import FenceCommand

    cmd = FenceCommand()
    plan = Plan(7, False, None, math.nan, math.nan, "(11) acceleration violated by 12")
    fill_command(cmd, plan, alpha_k=0.7)
    assert cmd.parcel_id == 7 and not cmd.feasible and cmd.start_mode == cmd.START_AT_RS
    assert cmd.reason.startswith("(11)") and math.isnan(cmd.r_s) and math.isnan(cmd.t1)


def test_rate_estimate_follows_sim_over_wall_time() -> None:
    from fence_sorter.nodes.controller import RateEstimate

    est = RateEstimate(window=2.0)
    assert est.update(0.0, 100.0) == 1.0  # nothing to tell yet
    for k in range(1, 41):
        value = est.update(0.1 * k, 100.0 + 5.0 * k)  # 50 sim s per wall s
    assert value == pytest.approx(50.0)


def test_scanner_publishes_what_has_crossed_the_line() -> None:
    from fence_sorter.nodes.scanner import due, fill_parcel
    from fence_sorter.stream import ParcelSpec
    from fence_sorter_msgs.msg import Parcel

    stream = [
        ParcelSpec(i, 0.4, 0.3, 0.2, 5.0, divert=True, arrival_time=1.5 * (i - 1))
        for i in (1, 2, 3)
    ]
    assert due(stream, 0, t0=10.0, now=9.9) == 0
    assert due(stream, 0, t0=10.0, now=11.5) == 2  # 10.0 and 11.5 are due
    assert due(stream, 2, t0=10.0, now=20.0) == 3
    msg = Parcel()
    fill_parcel(msg, stream[1], 11.5, -3.0, "sorter", run_id=42)
    assert msg.scan_time.sec == 11 and msg.scan_time.nanosec == 500_000_000
    assert msg.scan_position_x == -3.0 and msg.parcel_id == 2 and msg.header.frame_id == "sorter"
    assert msg.run_id == 42
