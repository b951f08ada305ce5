"""SegmentedBagWriter and read_bag without ROS: segments, metadata, storages, damage, SIGKILL."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from fence_sorter.recording.bagread import BagReadError, read_bag
from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter.recording.samples import (
    diff_values,
    from_mcap_ros2,
    from_rosbags,
    sample_values,
    to_rosbags,
)
from fence_sorter.recording.topics import TOPIC_TYPES
from fence_sorter.recording.writer import STAGING_DIR, BagWriteError, SegmentedBagWriter

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def typestore():
    return make_typestore()


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def write_suite(path: Path, typestore, storage: str = "mcap", per_topic: int = 4, **kw):
    """Every suite topic with ``per_topic`` sample messages; a segment closes after 1 s of the
    fake clock, which advances 1 s per round of messages (a segment per round)."""
    clock = FakeClock()
    expected: dict[str, list] = {}
    with SegmentedBagWriter(
        path, storage=storage, typestore=typestore, max_segment_duration=1.0, clock=clock, **kw
    ) as writer:
        handles = {t: writer.add_topic(t, m) for t, (m, _) in TOPIC_TYPES.items()}
        stamp = 1_000_000_000
        for k in range(per_topic):
            for topic, (msgtype, _) in TOPIC_TYPES.items():
                values = sample_values(typestore, msgtype, seed=k + 1)
                data = typestore.serialize_cdr(to_rosbags(typestore, msgtype, values), msgtype)
                writer.write(handles[topic], stamp, data)
                expected.setdefault(topic, []).append(values)
                stamp += 1_000_000
            clock.t += 1.0
        segments = len(writer.segments)
    return expected, segments


@pytest.mark.slow
def test_segments_rotate_by_duration_and_every_one_is_a_complete_bag(tmp_path, typestore):
    bag = tmp_path / "bag"
    expected, closed_before_close = write_suite(bag, typestore)
    assert closed_before_close == 3  # the 4th round is closed by close()
    files = sorted(bag.glob("*.mcap"))
    assert [f.name for f in files] == [f"bag_{i}.mcap" for i in range(4)]
    assert not (bag / STAGING_DIR).exists()
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == [f.name for f in files]
    assert meta["message_count"] == 4 * len(TOPIC_TYPES)
    got: dict[str, list] = {}
    with Reader(bag) as reader:
        for conn, _, raw in reader.messages():
            msg = typestore.deserialize_cdr(raw, conn.msgtype)
            got.setdefault(conn.topic, []).append(from_rosbags(typestore, msg))
    assert diff_values(expected, got) == []
    for f in files:  # each segment on its own
        with Reader(f) as reader:
            assert reader.message_count > 0


@pytest.mark.slow
def test_segments_rotate_by_size(tmp_path, typestore):
    bag = tmp_path / "bag"
    write_suite(bag, typestore, max_segment_bytes=2000)
    sizes = [
        f["message_count"]
        for f in yaml.safe_load((bag / "metadata.yaml").read_text())[
            "rosbag2_bagfile_information"
        ]["files"]
    ]
    assert len(sizes) > 4 and sum(sizes) == 4 * len(TOPIC_TYPES)


@pytest.mark.slow
def test_independent_mcap_reader_decodes_the_embedded_schemas(tmp_path, typestore):
    bag = tmp_path / "bag"
    expected, _ = write_suite(bag, typestore)
    got: dict[str, list] = {}
    for f in sorted(bag.glob("*.mcap")):
        with f.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for schema, channel, _, decoded in reader.iter_decoded_messages():
                assert schema.encoding == "ros2msg"
                assert schema.name == TOPIC_TYPES[channel.topic][0]
                got.setdefault(channel.topic, []).append(from_mcap_ros2(decoded))
    assert diff_values(expected, got) == []


@pytest.mark.slow
def test_sqlite3_storage(tmp_path, typestore):
    bag = tmp_path / "bag"
    expected, _ = write_suite(bag, typestore, storage="sqlite3")
    assert sorted(p.suffix for p in bag.iterdir()) == [".db3"] * 4 + [".yaml"]
    contents = read_bag(bag)
    assert contents.issues == []
    assert contents.counts() == {t: 4 for t in TOPIC_TYPES}


@pytest.mark.slow
def test_metadata_is_valid_while_the_bag_is_open(tmp_path, typestore):
    clock = FakeClock()
    writer = SegmentedBagWriter(
        tmp_path / "bag", typestore=typestore, max_segment_duration=1.0, clock=clock
    ).open()
    h = writer.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    msg = to_rosbags(typestore, "rosgraph_msgs/msg/Clock", {"clock": {"sec": 1, "nanosec": 2}})
    data = typestore.serialize_cdr(msg, "rosgraph_msgs/msg/Clock")
    with Reader(tmp_path / "bag") as reader:  # empty but valid
        assert reader.message_count == 0
    for k in range(25):
        clock.t = k * 0.125  # exact in binary
        writer.write(h, 10**9 + k, data)
    # segments close after the writes at 1.0 s and 2.125 s: 9 + 9 closed, 7 still open
    assert [s.message_count for s in writer.segments] == [9, 9]
    with Reader(tmp_path / "bag") as reader:
        assert reader.message_count == 18 == sum(1 for _ in reader.messages())
    writer.close()
    with Reader(tmp_path / "bag") as reader:
        assert reader.message_count == 25


def test_bad_arguments_name_the_problem(tmp_path, typestore):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    with pytest.raises(BagWriteError, match="not empty"):
        SegmentedBagWriter(tmp_path / "full", typestore=typestore).open()
    with pytest.raises(BagWriteError, match="storage must be"):
        SegmentedBagWriter(tmp_path / "b", storage="rosbag1", typestore=typestore)
    writer = SegmentedBagWriter(tmp_path / "b", typestore=typestore).open()
    with pytest.raises(BagWriteError, match="unknown message type"):
        writer.add_topic("/x", "nope_msgs/msg/Nope")
    writer.close()


# -- damage -------------------------------------------------------------------------------------
@pytest.fixture
def suite_bag(tmp_path, typestore) -> Path:
    bag = tmp_path / "bag"
    write_suite(bag, typestore, per_topic=8)
    return bag


@pytest.mark.slow
def test_truncated_segment_is_named_and_the_rest_is_read(suite_bag):
    seg = suite_bag / "bag_2.mcap"
    data = seg.read_bytes()
    seg.write_bytes(data[: len(data) - 200])  # footer and part of the summary gone
    contents = read_bag(suite_bag)
    assert len(contents.issues) == 1
    issue = contents.issues[0]
    assert issue.file == str(seg)
    assert "summary" in issue.problem or "truncated" in issue.problem
    # the segment's chunk is intact: every message is still recovered
    assert sum(contents.counts().values()) == 8 * len(TOPIC_TYPES)
    assert issue.recovered > 0


@pytest.mark.slow
def test_corrupted_and_missing_segments(suite_bag):
    seg = suite_bag / "bag_1.mcap"
    data = bytearray(seg.read_bytes())
    data[40:120] = b"\xff" * 80  # inside the first record after the header
    seg.write_bytes(bytes(data))
    (suite_bag / "bag_3.mcap").unlink()
    contents = read_bag(suite_bag)
    problems = {Path(i.file).name: i.problem for i in contents.issues}
    assert "bag_1.mcap" in problems and "damaged or truncated at byte" in problems["bag_1.mcap"]
    assert problems["bag_3.mcap"] == "listed in metadata.yaml but missing"
    total = 8 * len(TOPIC_TYPES)
    assert 0 < sum(contents.counts().values()) < total


@pytest.mark.slow
def test_garbage_metadata_and_no_bag(tmp_path, suite_bag):
    (suite_bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [1, 2\n")
    contents = read_bag(suite_bag)
    assert contents.issues[0].file.endswith("metadata.yaml")
    assert "YAML" in contents.issues[0].problem
    assert sum(contents.counts().values()) == 8 * len(TOPIC_TYPES)
    with pytest.raises(BagReadError, match="no such bag"):
        read_bag(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagReadError, match="no storage files"):
        read_bag(tmp_path / "empty")
    (tmp_path / "x.txt").write_text("x")
    with pytest.raises(BagReadError, match="not a bag"):
        read_bag(tmp_path / "x.txt")


KILLED_WRITER = textwrap.dedent(
    """
    import sys
    from fence_sorter.recording.msgtypes import make_typestore
    from fence_sorter.recording.samples import sample_values, to_rosbags
    from fence_sorter.recording.writer import SegmentedBagWriter
    ts = make_typestore()
    t = "fence_sorter_msgs/msg/LoadState"
    data = ts.serialize_cdr(to_rosbags(ts, t, sample_values(ts, t)), t)
    k = 0
    # the writer's clock counts writes (0.5 ms each): a segment every 400 writes, whatever
    # the machine's speed
    w = SegmentedBagWriter(
        sys.argv[1], typestore=ts, max_segment_duration=0.2, clock=lambda: k * 5e-4
    ).open()
    h = w.add_topic("/load_states", t)
    while True:
        w.write(h, 10**9 + k, data)
        k += 1
        if k % 100 == 0:
            print(k, len(w.segments), flush=True)
    """
)


@pytest.mark.slow
def test_sigkill_leaves_every_closed_segment_readable(tmp_path):
    bag = tmp_path / "bag"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED_WRITER, str(bag)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        segments = 0
        deadline = time.monotonic() + 60.0
        while segments < 3 and time.monotonic() < deadline:
            line = proc.stdout.readline()
            assert line, "writer died"
            segments = int(line.split()[1])
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    listed = meta["relative_file_paths"]
    assert len(listed) >= 3
    with Reader(bag) as reader:  # rosbags accepts the bag as the metadata describes it
        n = sum(1 for _ in reader.messages())
    assert n == meta["message_count"] > 0
    contents = read_bag(bag)
    # the open segment is reported (possibly nothing recoverable from it), never fatal
    assert all(STAGING_DIR in i.file for i in contents.issues)
    assert contents.counts()["/load_states"] >= n


@pytest.mark.slow
def test_rerun_accepts_the_bag(tmp_path, typestore):
    if shutil.which("rerun") is None and not _has_rerun():
        pytest.skip("rerun-sdk not installed")
    bag = tmp_path / "bag"
    write_suite(bag, typestore, per_topic=2)
    for f, full in [(f, full) for f in sorted(bag.glob("*.mcap")) for full in ([], ["--full"])]:
        out = subprocess.run(
            [sys.executable, "-m", "rerun", "mcap", "check", *full, str(f)],
            capture_output=True,
            text=True,
            timeout=120,
            env=dict(os.environ, RERUN_ANALYTICS_ENABLED="false"),
        )
        assert out.returncode == 0, out.stderr + out.stdout
        for topic in TOPIC_TYPES:
            if f"{topic} " in out.stdout:
                line = next(x for x in out.stdout.splitlines() if f"{topic} " in x)
                assert line.split()[0] == "ok", line


def _has_rerun() -> bool:
    try:
        import rerun  # noqa: F401
    except ImportError:
        return False
    return True


def _open_segment_messages(bag: Path) -> list[tuple[str, int]]:
    """(topic, log time) of what the independent MCAP stream reader decodes from the open
    segment (a file without its summary: read up to its last complete record)."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    (segment,) = (bag / STAGING_DIR).glob("*/*.mcap")
    out = []
    with segment.open("rb") as stream:
        reader = NonSeekingReader(stream, decoder_factories=[DecoderFactory()])
        try:
            # in file order: a time-ordered read collects the whole file first
            for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
                assert decoded is not None
                out.append((channel.topic, message.log_time))
        except (McapError, EOFError):  # the end of what was flushed
            pass
    return out


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_open_segment_is_flushed_every_flush_period(tmp_path, typestore, compression):
    """Pending messages reach the file as a complete chunk once flush_period has passed on the
    writer's clock, compressed as asked; the independent reader decodes them from the open
    segment while the writer still holds it."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    clock = FakeClock()
    bag = tmp_path / "bag"
    writer = SegmentedBagWriter(
        bag, typestore=typestore, clock=clock, flush_period=0.5, compression=compression
    ).open()
    msgtype = TOPIC_TYPES["/clock"][0]
    handle = writer.add_topic("/clock", msgtype)
    data = typestore.serialize_cdr(
        to_rosbags(typestore, msgtype, sample_values(typestore, msgtype, seed=1)), msgtype
    )
    for k in range(10):
        writer.write(handle, k, data)
    assert _open_segment_messages(bag) == []  # nothing flushed yet: 0 s of writer clock
    clock.t = 0.5
    writer.poll()
    assert _open_segment_messages(bag) == [("/clock", k) for k in range(10)]
    for k in range(10, 15):
        writer.write(handle, k, data)
    clock.t = 0.9
    writer.poll()  # 0.4 s since the last flush: pending
    assert len(_open_segment_messages(bag)) == 10
    clock.t = 1.0
    writer.write(handle, 15, data)  # a write checks the period too
    assert _open_segment_messages(bag) == [("/clock", k) for k in range(16)]
    assert writer.flushes == 2
    (segment,) = (bag / STAGING_DIR).glob("*/*.mcap")
    chunks = []
    with segment.open("rb") as stream:
        try:
            for record in StreamReader(stream, emit_chunks=True).records:
                chunks += [record] if isinstance(record, Chunk) else []
        except EndOfFile:  # no footer: the segment is still open
            pass
    assert len(chunks) == 2
    assert {c.compression for c in chunks} == {"zstd" if compression == "zstd" else ""}
    writer.close()
    with Reader(bag) as reader:
        assert sum(1 for _ in reader.messages()) == 16


def test_zstd_chunks_are_smaller_and_decode_the_same(tmp_path, typestore):
    sizes, decoded = {}, {}
    for compression in ("zstd", "none"):
        bag = tmp_path / compression
        write_suite(bag, typestore, per_topic=20, compression=compression)
        sizes[compression] = sum(f.stat().st_size for f in bag.glob("*.mcap"))
        decoded[compression] = read_bag(bag).messages
        for f in sorted(bag.glob("*.mcap")):
            with f.open("rb") as stream:
                reader = make_reader(stream, decoder_factories=[DecoderFactory()])
                summary = reader.get_summary()
                assert {c.compression for c in summary.chunk_indexes} == {
                    "zstd" if compression == "zstd" else ""
                }
                assert all(m is not None for *_, m in reader.iter_decoded_messages())
    assert sizes["zstd"] < sizes["none"]
    assert [(m.topic, m.t_ns, m.raw) for m in decoded["zstd"]] == [
        (m.topic, m.t_ns, m.raw) for m in decoded["none"]
    ]
