"""`fence-sorter bag info` (the stand-in for `ros2 bag info`) against the independent MCAP
reader: counts, types, start, end and duration of bags/example_4_parcels, and a damaged
segment named while the others are still counted. ROS-free."""

from __future__ import annotations

import io
import json
import re
import shutil
from collections import Counter
from pathlib import Path

import pytest
import yaml
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from processes import run_cli

from fence_sorter.recording.baginfo import bag_info, format_info

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
    # and the recorder's own metadata.yaml, written when it closed the bag
    metadata = yaml.safe_load((EXAMPLE / "metadata.yaml").read_text())
    recorded = metadata["rosbag2_bagfile_information"]["message_count"]
    assert info["messages"] == sum(counts.values()) == recorded
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
    parcels = r"Topic: /parcels +\| Type: fence_sorter_msgs/msg/Parcel \| Count: (\d+) "
    assert int(re.search(parcels, text).group(1)) == counts["/parcels"] == 4


def recoverable(data: bytes) -> tuple[int, Counter]:
    """Messages (and per-topic counts) the mcap package's streaming reader takes from a
    possibly truncated segment before it ends: what a reader can still recover."""
    total, per_topic, channels = 0, Counter(), {}
    try:
        for record in StreamReader(io.BytesIO(data)).records:
            if isinstance(record, Channel):
                channels[record.id] = record.topic
            elif isinstance(record, Message):
                total += 1
                per_topic[channels[record.channel_id]] += 1
    except EndOfFile:
        pass
    return total, per_topic


def test_a_truncated_segment_is_named_and_the_others_counted(tmp_path):
    bag = tmp_path / "bag"
    shutil.copytree(EXAMPLE, bag)
    damaged = bag / "example_4_parcels_1.mcap"
    data = damaged.read_bytes()
    whole = bag_info(EXAMPLE)
    segment_total = next(s.messages for s in whole.segments if s.file.endswith(damaged.name))
    # summary and footer cut off (the footer's summary_start): every chunk still whole
    summary_start = int.from_bytes(data[-28:-20], "little")
    damaged.write_bytes(data[:summary_start])
    assert recoverable(data[:summary_start])[0] == segment_total
    info = bag_info(bag)
    assert not info.healthy
    seg = {Path(s.file).name: s for s in info.segments}
    assert seg["example_4_parcels_0.mcap"].health == "ok"
    assert seg["example_4_parcels_2.mcap"].health == "ok"
    bad = seg["example_4_parcels_1.mcap"]
    assert "truncated" in bad.health and f"{segment_total} messages recovered" in bad.health
    assert bad.messages == segment_total
    assert info.counts == whole.counts
    # cut in the middle: the chunks before the cut are recovered (chunks are flushed every
    # 0.5 s), as many as the independent streaming reader recovers, the others still counted
    cut = data[: len(data) // 2]
    damaged.write_bytes(cut)
    recovered, per_topic = recoverable(cut)
    assert 0 < recovered < segment_total
    info = bag_info(bag)
    bad = next(s for s in info.segments if s.file == str(damaged))
    assert "truncated" in bad.health and bad.messages == recovered
    assert info.messages == whole.messages - segment_total + recovered
    clock = whole.counts["/clock"]
    found = clock - recoverable(data)[1]["/clock"] + per_topic["/clock"]
    assert any(f"declares {clock} messages on /clock, {found} found" in i for i in info.issues)
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


def test_bag_info_analyze_and_rrd_recover_the_same_from_a_truncated_segment(tmp_path):
    """One reader (bagread.recover_mcap) behind all three tools: for a segment cut in the
    middle each reports the messages the independent streaming reader recovers, whatever
    topics it then keeps (analyze reads only its own)."""
    bag = tmp_path / "bag"
    shutil.copytree(EXAMPLE, bag)
    damaged = bag / "example_4_parcels_1.mcap"
    cut = damaged.read_bytes()[: damaged.stat().st_size // 2]
    damaged.write_bytes(cut)
    expected, per_topic = recoverable(cut)
    assert 0 < expected and len(per_topic) > 1

    info = run_cli("bag", "info", str(bag), "--json")
    assert info.returncode == 1
    seg = next(s for s in json.loads(info.stdout)["segments"] if s["file"] == str(damaged))
    assert seg["messages"] == expected and f"; {expected} messages recovered" in seg["health"]

    analyze = run_cli("analyze", str(bag), "--json", "--no-plots")
    assert analyze.returncode == 1
    issues = [i for i in json.loads(analyze.stdout)["issues"] if i["file"] == str(damaged)]
    assert [i["recovered"] for i in issues if "truncated" in i["problem"]] == [expected]

    rrd = run_cli("rrd", str(bag), "--out", str(tmp_path / "b.rrd"))
    assert rrd.returncode == 1
    line = next(ln for ln in rrd.stderr.splitlines() if damaged.name in ln and "truncated" in ln)
    assert line.endswith(f"({expected} messages recovered)")
    assert f"({expected} messages recovered)" in analyze.stderr
