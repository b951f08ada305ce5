"""Files that cannot be read: a bag with nothing readable in it, a scene or stream file of any
bytes and any nesting. Every command refuses them with exit 2 and one line, writes no output,
and never shows a traceback."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from processes import run_cli

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_MCAP = REPO / "bags" / "example_4_parcels" / "example_4_parcels_0.mcap"
MCAP_MAGIC = b"\x89MCAP0\r\n"


def _bad_bag(kind: str, tmp_path: Path) -> Path:
    """A single .mcap file of which nothing is readable."""
    path = tmp_path / f"{kind}.mcap"
    if kind == "zero-byte":
        path.write_bytes(b"")
    elif kind == "random-bytes":
        path.write_bytes(os.urandom(4096))
    elif kind == "bad-magic":
        data = EXAMPLE_MCAP.read_bytes()
        path.write_bytes(b"\x89NOPE0\r\n" + data[len(MCAP_MAGIC) :])
    elif kind == "truncated":
        # the magic and the header record, cut before the first message
        path.write_bytes(EXAMPLE_MCAP.read_bytes()[:64])
    return path


BAD_BAGS = ["zero-byte", "random-bytes", "bad-magic", "truncated"]


@pytest.mark.parametrize("kind", BAD_BAGS)
def test_nothing_readable_is_a_read_error(kind: str, tmp_path: Path) -> None:
    from fence_sorter.recording.bagread import BagReadError, read_bag

    with pytest.raises(BagReadError, match="nothing readable"):
        read_bag(_bad_bag(kind, tmp_path))
    bag = tmp_path / "bag"  # the same file as the only segment of a bag directory
    bag.mkdir()
    _bad_bag(kind, tmp_path).rename(bag / "bag_0.mcap")
    with pytest.raises(BagReadError, match="nothing readable"):
        read_bag(bag)


def test_a_bag_with_one_readable_segment_is_read(tmp_path: Path) -> None:
    """The other side of the line: a damaged segment beside an intact one is an issue, the
    intact one's messages are read."""
    from fence_sorter.recording.bagread import read_bag

    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "bag_0.mcap").write_bytes(EXAMPLE_MCAP.read_bytes())
    (bag / "bag_1.mcap").write_bytes(b"")
    contents = read_bag(bag)
    damaged = [i.file for i in contents.issues if i.file.endswith(".mcap")]
    assert contents.messages and damaged == [str(bag / "bag_1.mcap")]


@pytest.mark.slow
@pytest.mark.parametrize("kind", BAD_BAGS)
def test_rrd_of_an_unreadable_bag_exits_2_and_writes_nothing(kind: str, tmp_path: Path) -> None:
    out = tmp_path / "out.rrd"
    done = run_cli("rrd", str(_bad_bag(kind, tmp_path)), "--out", str(out), timeout=120)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "nothing readable" in done.stderr
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("command", "kind"), [("analyze", "random-bytes"), ("replay", "truncated")]
)
def test_analyze_and_replay_of_an_unreadable_bag_exit_2(
    command: str, kind: str, tmp_path: Path
) -> None:
    extra = ["--out", str(tmp_path / "out")] if command == "analyze" else []
    done = run_cli(command, str(_bad_bag(kind, tmp_path)), *extra, timeout=120)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "nothing readable" in done.stderr
    assert not (tmp_path / "out").exists()


NOT_UTF8 = b"conveyor:\n  belt_speed: \xff\xfe 1.5\n"
DEEP = "a: " + "[" * 5000 + "]" * 5000 + "\n"


@pytest.mark.parametrize(
    ("content", "named"),
    [(NOT_UTF8, r"not UTF-8 text \(byte 0xff at offset 24\)"), (DEEP, "nested too deeply")],
    ids=["not-utf8", "deep"],
)
def test_scene_and_stream_loaders_take_any_bytes(content, named: str, tmp_path: Path) -> None:
    from fence_sorter.scene import SceneError, load_scene
    from fence_sorter.stream import load_stream
    from fence_sorter.stream.model import StreamError

    data = content if isinstance(content, bytes) else content.encode()
    for name in ("scene.yaml", "stream.yaml", "manifest.csv"):
        (tmp_path / name).write_bytes(data)
    with pytest.raises(SceneError, match=named):
        load_scene(tmp_path / "scene.yaml")
    with pytest.raises(StreamError, match=named):
        load_stream(tmp_path / "stream.yaml", 2.0, count=3)
    if isinstance(content, bytes):
        with pytest.raises(StreamError, match=named):
            load_stream(tmp_path / "manifest.csv", 2.0)


@pytest.mark.slow
@pytest.mark.parametrize("option", ["--scene", "--stream"])
def test_run_refuses_unreadable_scene_and_stream_files(option: str, tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(NOT_UTF8 if option == "--scene" else DEEP.encode())
    done = run_cli("run", option, str(bad), timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fence-sorter: error: "), done.stderr
    assert "not UTF-8" in lines[0] or "nested too deeply" in lines[0]
