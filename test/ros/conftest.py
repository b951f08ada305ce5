"""Fixtures of the ROS tests shared across modules."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from processes import run_cli


@pytest.fixture(scope="session")
def line_run_two_units(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """One ``fence-sorter run --line two_units --parcels 10 --seed 3 --json --bag DIR --rrd
    DIR.rrd`` for the line's run tests (test_line_run.py) and its bag's (test_line_bag.py):
    the bag directory (the run's view beside it, ``bag.with_suffix(".rrd")``) and the finished
    command (its exit status not checked here)."""
    base = tmp_path_factory.mktemp("line_run")
    bag = base / "bag"
    proc = run_cli(
        "run", "--line", "two_units", "--parcels", "10", "--seed", "3", "--json",
        "--bag", str(bag), "--rrd", str(base / "bag.rrd"), "--log-dir", str(base / "logs"),
        timeout=600,
    )  # fmt: skip
    return bag, proc
