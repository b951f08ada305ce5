"""`fence-sorter views` refuses bad input before any browser starts: exit 2 and one line
naming the argument and what it may be."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "bags" / "example_4_parcels.rrd"


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["/nonexistent.rrd"], "rrd /nonexistent.rrd: no such .rrd file"),
        ([str(EXAMPLE), "--mid", "-3"], "--mid -3.0: outside 0.00.."),
    ],
)
def test_bad_views_input_exits_2_with_one_line(args: list[str], says: str, tmp_path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", "views", *args, "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert says in lines[0]
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize("content", [b"", b"not a recording\n"])
def test_a_file_that_is_no_recording_exits_2_with_one_line(content: bytes, tmp_path) -> None:
    fake = tmp_path / "fake.rrd"
    fake.write_bytes(content)
    out = subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", "views", str(fake), "--out",
         str(tmp_path / "views")],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert lines[0].startswith(f"fence-sorter views: error: rrd {fake}: not a Rerun recording")
    assert not (tmp_path / "views").exists()
