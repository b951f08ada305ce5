"""`fence-sorter bag info` (the stand-in for `ros2 bag info`) against the independent MCAP
reader: counts, types, start, end and duration of bags/example_4_parcels, and a damaged
segment named while the others are still counted. ROS-free."""

from __future__ import annotations

import json
import shutil
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader

from fence_sorter.recording.baginfo import bag_info, format_info
from fence_sorter.testing import run_cli

pytestmark = pytest.mark.slow  # bag readers and the CLI in a process: seconds each

EXAMPLE = Path(__file__).resolve().parents[2] / "bags" / "example_4_parcels"


def independent_counts(bag: Path) -> tuple[Counter, dict[str, str], list[int]]:
    """Per-topic counts, types and log times, every message iterated by the mcap package."""
    counts: Counter[str] = Counter()
    types: dict[str, str] = {}
    times: list[int] = []
    for segment in sorted(bag.glob("*.mcap")):
        with segment.open("rb") as stream:
            for schema, channel, message in make_reader(stream).iter_messages():
                counts[channel.topic] += 1
                types[channel.topic] = schema.name
                times.append(message.log_time)
    return counts, types, times


def test_example_bag_info_matches_the_independent_reader():
    counts, types, times = independent_counts(EXAMPLE)
    out = run_cli("bag", "info", str(EXAMPLE), "--json")
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    assert info["counts"] == dict(counts)
    assert info["types"] == types
    assert info["messages"] == sum(counts.values()) == 3758
    assert info["start_ns"] == min(times)
    assert info["end_ns"] == max(times)
    assert info["duration_ns"] == max(times) - min(times)
    assert info["storage"] == "mcap"
    assert [Path(s["file"]).name for s in info["segments"]] == [
        f"example_4_parcels_{i}.mcap" for i in range(3)
    ]
    assert all(s["health"] == "ok" for s in info["segments"])
    assert info["healthy"] is True
    text = run_cli("bag", "info", str(EXAMPLE)).stdout
    assert f"Messages:          {sum(counts.values())}" in text
    assert "Topic: /parcels        | Type: fence_sorter_msgs/msg/Parcel | Count: 4" in text


def test_a_truncated_segment_is_named_and_the_others_counted(tmp_path):
    bag = tmp_path / "bag"
    shutil.copytree(EXAMPLE, bag)
    damaged = bag / "example_4_parcels_1.mcap"
    data = damaged.read_bytes()
    damaged.write_bytes(data[:850239])  # its one chunk whole, summary and footer cut off
    whole = bag_info(EXAMPLE)
    info = bag_info(bag)
    assert not info.healthy
    seg = {Path(s.file).name: s for s in info.segments}
    assert seg["example_4_parcels_0.mcap"].health == "ok"
    assert seg["example_4_parcels_2.mcap"].health == "ok"
    bad = seg["example_4_parcels_1.mcap"]
    assert "truncated" in bad.health and "2699 messages recovered" in bad.health
    assert bad.messages == 2699  # the chunk holds every message of the segment
    assert info.counts == whole.counts
    # cut inside the chunk: the segment's messages are lost, the others still counted
    damaged.write_bytes(data[:400000])
    info = bag_info(bag)
    bad = next(s for s in info.segments if s.file == str(damaged))
    assert "truncated" in bad.health and bad.messages == 0
    assert info.messages == whole.messages - 2699
    assert any("declares 828 messages on /clock" in issue for issue in info.issues)
    assert "example_4_parcels_1.mcap" in format_info(info)
    assert run_cli("bag", "info", str(bag)).returncode == 1


def test_not_a_bag_exits_2(tmp_path):
    out = run_cli("bag", "info", str(tmp_path / "nothing"))
    assert out.returncode == 2
    assert "no such bag" in out.stderr


def test_counts_include_topics_declared_but_absent(tmp_path):
    bag = tmp_path / "bag"
    shutil.copytree(EXAMPLE, bag)
    (bag / "example_4_parcels_2.mcap").unlink()
    info = bag_info(bag).to_json()
    assert set(info["counts"]) == set(bag_info(EXAMPLE).counts)
    assert any("listed in metadata.yaml but missing" in issue for issue in info["issues"])
