"""``--foxglove [HOST:]PORT`` of ``fence-sorter run`` and ``replay``: a bad value is exit 2 with
one line naming the option and the allowed values, before any node or server starts."""

from __future__ import annotations

import socket

import pytest
from processes import run_cli


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ["run", "--parcels", "1", "--foxglove", "99999"],
            "fence-sorter: error: --foxglove must be [HOST:]PORT with PORT in 1-65535, "
            "got '99999'",
        ),
        (
            ["replay", "bags/example_4_parcels", "--foxglove", "sorter-host:8765"],
            "fence-sorter replay: error: --foxglove HOST must be an IP address or localhost, "
            "got 'sorter-host'",
        ),
    ],
)
def test_bad_foxglove_address_is_one_line_exit_2(args: list[str], expected: str) -> None:
    proc = run_cli(*args, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.strip().splitlines() == [expected]
    assert proc.stdout == ""


@pytest.mark.parametrize(
    ("command", "prefix"),
    [
        (["run", "--parcels", "1"], "fence-sorter: error: "),
        (["replay", "bags/example_4_parcels"], "fence-sorter replay: error: "),
    ],
)
def test_a_port_in_use_is_one_line_exit_2(command: list[str], prefix: str) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = run_cli(*command, "--foxglove", str(port), timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"{prefix}--foxglove 127.0.0.1:{port}: cannot listen there: Address already in use"
    ]
    assert proc.stdout == ""
