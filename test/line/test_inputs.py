"""The one validation of parcels and commands (fence_sorter.inputs), shared by the stream
loaders, the controller and the simulator's line, and the hostile inputs it must refuse:
a scan_time 1e5 s ahead (planned, it would book the fence until t = 1e5 s), scan_position_x = 1e9,
mu_fence = 5, a 20 s stroke, commands outside their parcel's window."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from fence_sorter.inputs import (
    PARCEL_REASONS,
    SCAN_TIME_AHEAD,
    SCAN_TIME_PAST,
    InputError,
    ParcelSpec,
    StrokeCommand,
    validate_command,
    validate_parcel,
)
from fence_sorter.line import LineConfig, SortingLine
from fence_sorter.nodes.intake import TokenBucket, TopicIntake
from fence_sorter.scene import load_scene
from fence_sorter.stream import StreamError, load_stream

BELT = 0.7
GOOD = ParcelSpec(
    7, length_a=0.4, width_b=0.3, mass=5.0, lateral_gap=0.1, divert=True, scan_time=20.0,
    scan_position_x=-3.0,
)  # fmt: skip


@pytest.mark.parametrize(
    ("change", "key", "field", "allowed"),
    [
        ({"scan_time": 20.0 + 1e5}, "scan_time", "scan_time", "[10, 22] s"),
        ({"scan_time": 5.0}, "scan_time", "scan_time", "[10, 22] s"),
        ({"scan_position_x": 1e9}, "scan_position", "scan_position_x", "[-100, 100] m"),
        ({"scan_position_x": 1.0}, "scan_position", "scan_position_x", "[-3.5, -2.5] m"),
        ({"mu_fence": 5.0}, "friction", "mu_fence", "[0, 2]"),
        ({"mu_belt": -0.1}, "friction", "mu_belt", "[0, 2]"),
        ({"mu_belt": math.inf}, "non_finite", "mu_belt", "finite or NaN"),
        ({"mass": math.nan}, "non_finite", "mass", "finite"),
        ({"mass": 0.0}, "mass", "mass", "[0.01, 500] kg"),
        ({"mass": 501.0}, "mass", "mass", "[0.01, 500] kg"),
        ({"length_a": 3.5}, "size", "length_a", "[0.005, 3] m"),
        ({"height": 0.001}, "size", "height", "[0.005, 3] m"),
        ({"cog_offset_x": 0.3}, "cog_offset", "cog_offset_x", "[0, 0.2] m"),
        ({"yaw": 2.0}, "yaw", "yaw", "[-1.5708, 1.5708] rad"),
        ({"lateral_gap": -0.1}, "lateral_gap", "lateral_gap", "[0, 0.7] m"),
        ({"width_b": 0.65}, "wider_than_belt", "width_b", "[0, 0.05] m"),
        ({"parcel_id": -1}, "parcel_id", "parcel_id", "[0, 4294967295]"),
        ({"parcel_id": 2**32}, "parcel_id", "parcel_id", "[0, 4294967295]"),
        ({"arrival_time": -1.0}, "arrival_time", "arrival_time", "[0, 1e+07] s"),
    ],
)
def test_every_field_has_a_range_named_in_the_error(change, key, field, allowed) -> None:
    with pytest.raises(InputError) as err:
        validate_parcel(replace(GOOD, **change), BELT, now=20.0, scan_line_x=-3.0)
    assert err.value.key == key and err.value.field == field
    assert key in PARCEL_REASONS
    assert allowed in str(err.value), str(err.value)


def test_a_good_parcel_and_the_edges_of_the_scan_time_window_pass() -> None:
    validate_parcel(GOOD, BELT, now=20.0, scan_line_x=-3.0)
    validate_parcel(replace(GOOD, scan_time=20.0 - SCAN_TIME_PAST), BELT, now=20.0)
    validate_parcel(replace(GOOD, scan_time=20.0 + SCAN_TIME_AHEAD), BELT, now=20.0)
    validate_parcel(replace(GOOD, mu_belt=math.nan, mu_fence=2.0), BELT)
    with pytest.raises(InputError, match="already known") as err:
        validate_parcel(GOOD, BELT, known_ids={7})
    assert err.value.key == "duplicate_id"


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"t1": 20.0}, "t1"),
        ({"t1": math.nan}, "t1"),
        ({"alpha_k": 0.0}, "alpha_k"),
        ({"r_s": 3.0}, "r_s"),
        ({"start_mode": 7}, "start_mode"),
        ({"parcel_id": -3}, "parcel_id"),
        ({"parcel_id": -3, "feasible": False}, "parcel_id"),
    ],
)
def test_a_command_with_bad_numbers_is_refused(change, field) -> None:
    with pytest.raises(InputError) as err:
        validate_command(replace(StrokeCommand(1, r_s=0.4, t1=0.35), **change), (-0.5, 2.0))
    assert err.value.key == "invalid" and err.value.field == field


def line(**kw) -> SortingLine:
    sc = load_scene("impact_flexible").scenario
    return SortingLine(LineConfig.from_scenario(sc, **kw))


def test_the_line_refuses_a_parcel_scanned_far_ahead_or_away_from_the_scan_line() -> None:
    ln = line(scan_line_x=-3.0)
    with pytest.raises(InputError) as err:  # it would hold the fence until t = 1e5 s
        ln.add_parcel(replace(GOOD, parcel_id=1, scan_time=1e5), 0.0)
    assert err.value.key == "scan_time"
    with pytest.raises(InputError) as err:
        ln.add_parcel(replace(GOOD, parcel_id=2, scan_time=0.0, scan_position_x=1e9), 0.0)
    assert err.value.key == "scan_position"
    with pytest.raises(InputError) as err:
        ln.add_parcel(replace(GOOD, parcel_id=3, scan_time=0.0, mu_fence=5.0), 0.0)
    assert err.value.key == "friction"
    assert ln.parcels == {}


def test_a_stroke_that_outlasts_its_parcel_on_the_line_is_refused() -> None:
    """Front at -3 m at t = 0, belt 1 m/s, A = 0.4 m: the rear passes line_end_x = 3 m at
    t = 6.4 s. A stroke at R_s = 0.4 m starts at t = 3.4 s: t1 = 10 s (a 20 s stroke) would
    book the fence to t = 23.4 s; t1 up to 3.0 s keeps its working motion on the parcel."""
    ln = line(scan_line_x=-3.0)
    ln.add_parcel(replace(GOOD, parcel_id=1, scan_time=0.0), 0.0)
    res = ln.command(StrokeCommand(1, r_s=0.4, t1=10.0))
    assert not res.accepted and res.code == "outside_window"
    assert "t1 must be in [0.02, 3] s" in res.reason, res.reason
    assert ln.command(StrokeCommand(1, r_s=0.4, t1=0.35)).accepted


def test_stream_files_are_checked_by_the_same_validation(tmp_path) -> None:
    f = tmp_path / "m.csv"
    f.write_text(
        "parcel_id,arrival_time,length_a,width_b,height,mass,mu_fence,divert\n"
        "1,0,0.4,0.3,0.2,5,5,true\n"
    )
    match = r"line 2 column 'mu_fence': mu_fence must be in \[0, 2\]"
    with pytest.raises(StreamError, match=match):
        load_stream(f, 1.0)
    stream = load_stream("default", 1.0, count=5)
    assert all(isinstance(s, ParcelSpec) for s in stream)
    for s in stream:
        validate_parcel(s, BELT)


def test_token_bucket_refuses_and_counts_the_excess() -> None:
    t = [0.0]
    intake = TopicIntake("parcels", run_id=5, rate=10.0, burst=20.0, clock=lambda: t[0])
    admitted = sum(intake.admit(5) for _ in range(5000))  # a flood in no time
    assert admitted == 20 and intake.rate_limited == 4980
    t[0] = 1.0  # one second later: 10 more tokens
    assert sum(intake.admit(5) for _ in range(100)) == 10
    assert not intake.admit(6) and intake.foreign == 1  # another run's: never the bucket's
    assert intake.received == 5101 and intake.accepted == 30
    assert intake.received == intake.accepted + intake.foreign + intake.rate_limited
    with pytest.raises(ValueError, match="rate must be in"):
        TokenBucket(0.0, 1.0)
