"""A file that is not what the command reads (a Rerun recording given as a bag) and an output
that is there already (``rrd``'s default ``<bag>.rrd``): exit 2, one line, nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest
from processes import run_cli


@pytest.mark.parametrize("command", [["bag", "info"], ["replay"]])
def test_a_rerun_recording_given_as_a_bag_is_named_so(command: list[str], tmp_path: Path) -> None:
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"")  # named by its suffix: no bag is read
    done = run_cli(*command, str(rrd), timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"fence-sorter {' '.join(command)}: error: {rrd}: a Rerun recording, not a bag "
        f"(view it with `fence-sorter views {rrd}`)"
    ]


def test_rrd_keeps_an_existing_default_output(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()  # no storage files: only reached once the output is allowed
    kept = tmp_path / "bag.rrd"
    kept.write_bytes(b"a recording")
    done = run_cli("rrd", str(bag), timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"fence-sorter rrd: error: {kept} exists (the default output, <bag>.rrd): give --out "
        "FILE, or --force to overwrite it"
    ]
    assert kept.read_bytes() == b"a recording"
    forced = run_cli("rrd", str(bag), "--force", timeout=120)
    assert "no storage files" in forced.stderr  # past the check: on to reading the bag
