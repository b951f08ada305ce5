"""``fence-sorter run --interface/--peers``: a bad value exits 2 with one line naming the option,
before any node starts."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    "args, says",
    [
        (
            ["--interface", "10.254.254.254", "--peers", "10.1.1.1"],
            "--interface: 10.254.254.254 is not an address of this host",
        ),
        (["--interface", "127.0.0.1", "--peers", "x"], "--peers: 'x' is not an IPv4 address"),
        (
            ["--interface", "127.0.0.1", "--peers", "127.0.0.1"],
            "--peers: 127.0.0.1 is this host's --interface",
        ),
        (
            ["--interface", "224.0.0.1", "--peers", "10.1.1.1"],
            "--interface: 224.0.0.1 must be one host's unicast address",
        ),
        (["--interface", "127.0.0.1"], "--interface and --peers go together"),
    ],
)
def test_bad_transport_exits_2_naming_the_option(args, says) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", "run", "--parcels", "2", *args],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], lines
