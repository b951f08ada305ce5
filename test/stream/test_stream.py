"""Parcel streams: seeded random draws from a config, CSV manifests, errors naming the field."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from fence_sorter.stream import (
    StreamConfig,
    StreamError,
    generate,
    load_stream,
    read_manifest,
)

REPO = Path(__file__).resolve().parents[2]


def cfg(**stream) -> StreamConfig:
    base = {
        "seed": 1,
        "rate_pcs_h": 2400.0,
        "parcel": {
            "length_a": {"dist": "uniform", "low": 0.2, "high": 0.5},
            "width_b": 0.3,
            "height": 0.2,
            "mass": {"dist": "lognormal", "median": 4.0, "sigma": 0.5, "low": 1.0, "high": 9.0},
            "lateral_gap": {"dist": "uniform", "low": 0.0, "high": 1.0},
        },
    }
    base.update(stream)
    return StreamConfig.from_mapping({"stream": base}, "test.yaml")


def test_default_stream_is_2400_per_hour_and_seeded() -> None:
    c = StreamConfig.from_yaml(REPO / "config" / "streams" / "default.yaml")
    a = generate(c, 1.0, count=50)
    b = generate(c, 1.0, count=50)
    assert a == b  # same seed, same stream
    assert generate(c, 1.0, count=50, seed=7) != a
    heads = [q.arrival_time - p.arrival_time for p, q in zip(a, a[1:], strict=False)]
    assert heads == pytest.approx([1.5] * 49)  # 3600 / 2400 s
    assert len({p.parcel_id for p in a}) == 50
    assert 0.2 < sum(p.divert for p in a) / 50 < 0.8


def test_draws_stay_in_range_and_on_the_belt() -> None:
    stream = generate(cfg(), 1.5, duration=60.0)
    assert stream and all(p.arrival_time <= 60.0 for p in stream)
    for p in stream:
        assert 0.2 <= p.length_a <= 0.5 and 1.0 <= p.mass <= 9.0
        assert 0.0 <= p.lateral_gap and p.lateral_gap + p.width_b <= 0.7 + 1e-12


def test_min_gap_spaces_long_parcels() -> None:
    stream = generate(cfg(rate_pcs_h=100000.0, min_gap=0.3), 1.0, count=20)
    for p, q in zip(stream, stream[1:], strict=False):
        assert q.arrival_time - p.arrival_time >= (p.length_a + 0.3) / 1.0 - 1e-9


def test_gap_spacing_and_poisson() -> None:
    gap = cfg(rate_pcs_h=None, gap={"dist": "uniform", "low": 0.5, "high": 0.5})
    s = generate(gap, 2.0, count=5)
    for p, q in zip(s, s[1:], strict=False):
        assert q.arrival_time - p.arrival_time == pytest.approx((p.length_a + 0.5) / 2.0)
    poisson = generate(cfg(headway="poisson", min_gap=0.0), 1.0, count=400)
    mean = poisson[-1].arrival_time / 399
    assert mean == pytest.approx(1.5, rel=0.2)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"rate_pcs_h": -5.0}, r"stream.rate_pcs_h must be in \(0, 1e\+06\]"),
        ({"divert_share": 1.5}, r"stream.divert_share must be in \[0, 1\]"),
        ({"headway": "bursty"}, r"stream.headway must be one of regular, poisson"),
        ({"colour": "red"}, r"stream.colour is not a known key"),
        ({"parcel": {"length_a": 0.3}}, r"stream.parcel.width_b is required"),
        (
            {
                "parcel": {
                    "length_a": {"dist": "uniform", "low": 1, "high": 0},
                    "width_b": 0.1,
                    "height": 0.1,
                    "mass": 1,
                }
            },
            r"stream.parcel.length_a: uniform low \(1\) must not exceed high",
        ),
        (
            {"parcel": {"length_a": 0.3, "width_b": 0.1, "height": 0.1, "mass": -2.0}},
            r"stream test.yaml: parcel 1.mass must be in \[0.01, 500\] kg",
        ),
    ],
)
def test_bad_config_names_the_field(change, match) -> None:
    with pytest.raises(StreamError, match=match):
        generate(cfg(**change), 1.0, count=3)


def test_manifest_example_reads(tmp_path: Path) -> None:
    parcels = read_manifest(REPO / "config" / "streams" / "example_manifest.csv")
    assert [p.parcel_id for p in parcels] == [1, 2, 3, 4, 5, 6]
    assert parcels[2].yaw == pytest.approx(math.radians(2.0))
    assert math.isnan(parcels[0].mu_belt) and parcels[3].mu_belt == pytest.approx(0.6)
    assert [p.divert for p in parcels] == [True, False, True, True, False, True]
    cut = load_stream(REPO / "config" / "streams" / "example_manifest.csv", 1.0, count=2)
    assert len(cut) == 2


@pytest.mark.parametrize(
    ("rows", "match"),
    [
        ("1,0.0,0.4,0.3,0.3,abc,true", r"line 3 column 'mass': cannot read 'abc'"),
        ("1,0.0,0.4,0.3,0.3,-1,true", r"line 3 column 'mass'.*must be in \[0.01, 500\]"),
        ("1,0.0,0.4,0.3,0.3,5,maybe", r"line 3 column 'divert'"),
        ("1,0.0,0.4,0.9,0.3,5,true", r"line 3.*exceeds the belt width"),
        (
            "1,0.0,0.4,0.3,0.3,5,true\n1,1.0,0.4,0.3,0.3,5,true",
            r"line 4 column 'parcel_id': duplicate",
        ),
        ("1,0.0,0.4,0.3", r"line 3: 4 fields, the header has 7"),
    ],
)
def test_bad_manifest_names_line_and_column(tmp_path: Path, rows: str, match: str) -> None:
    f = tmp_path / "m.csv"
    f.write_text("# comment\nparcel_id,arrival_time,length_a,width_b,height,mass,divert\n" + rows)
    with pytest.raises(StreamError, match=match) as info:
        read_manifest(f)
    assert str(f) in str(info.value)


def test_unknown_stream_file() -> None:
    with pytest.raises(StreamError, match="nope: file not found"):
        load_stream("nope", 1.0, count=1)


@pytest.mark.parametrize("given", ["/nonexistent/s.yaml", "/nonexistent/s", "sub/s.yaml"])
def test_a_missing_stream_path_is_named_as_given(given: str) -> None:
    with pytest.raises(StreamError) as info:
        load_stream(given, 1.0, count=1)
    assert str(info.value) == f"stream {given}: file not found"


def test_a_missing_stream_name_names_its_config_file() -> None:
    with pytest.raises(StreamError) as info:
        load_stream("nope", 1.0, count=1)
    assert str(info.value) == "stream nope: file not found (nor config/streams/nope.yaml)"


def test_config_yaml_roundtrip_rejects_missing_stream_key(tmp_path: Path) -> None:
    f = tmp_path / "s.yaml"
    f.write_text(yaml.safe_dump({"parcels": {}}))
    with pytest.raises(StreamError, match="must contain a 'stream:' mapping"):
        StreamConfig.from_yaml(f)


def test_at_rate_replaces_a_gap_spacing_and_keeps_the_mix() -> None:
    """A gap-spaced stream at 600 pcs/h: regular 6 s headways (above any (A + min_gap) / v),
    the same parcels as drawn with the gap (a constant gap draws no random number)."""
    gapped = cfg(rate_pcs_h=None, gap=0.5)
    timed = gapped.at_rate(600.0)
    assert timed.gap is None and timed.rate_pcs_h == 600.0
    a, b = generate(gapped, 1.0, count=5), generate(timed, 1.0, count=5)
    times = [s.arrival_time for s in b]
    assert [t1 - t0 for t0, t1 in zip(times, times[1:], strict=False)] == pytest.approx([6.0] * 4)
    assert [(s.length_a, s.mass) for s in a] == [(s.length_a, s.mass) for s in b]
    with pytest.raises(StreamError, match=r"rate must be in \(0, inf\) pcs/h"):
        gapped.at_rate(0.0)
