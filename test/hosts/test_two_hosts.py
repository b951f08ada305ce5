"""A run on one host seen from another: two network namespaces joined by a veth pair.

Each namespace is a host (its own interfaces and loopback; nothing but UDP over the link joins
them). The run (``fence-sorter run --interface B --peers A``) starts in host B; a participant
in host A (test/hosts/listener.py, real rclpy on the profile of fence_sorter.runner.transport)
finds it by unicast discovery and takes its /parcels and /sort_outcomes. Checked: host A
receives every parcel and every outcome of the run, equal to the run's own summary, and every
UDP socket of the run's processes is bound to B's link address (no 0.0.0.0, no loopback).
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import uuid
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.hosts]

REPO = Path(__file__).resolve().parents[2]
LISTENER = REPO / "test" / "hosts" / "listener.py"
PARCELS = 4


def _udp_binds(ns: str, pids: set[int] | None = None) -> set[str]:
    """Local addresses of the UDP sockets of python processes in ``ns``."""
    out = subprocess.run(
        ["ip", "netns", "exec", ns, "ss", "-ulpnH"], capture_output=True, text=True
    ).stdout
    found = set()
    for line in out.splitlines():
        if "python" in line:
            found.add(line.split()[3].rsplit(":", 1)[0])
    return found


def test_a_run_on_one_host_is_seen_whole_from_another(two_hosts, tmp_path: Path) -> None:
    a, addr_a, b, addr_b = two_hosts.a, two_hosts.addr_a, two_hosts.b, two_hosts.addr_b
    domain = 150 + int(uuid.uuid4().hex[:4], 16) % 50
    listener = subprocess.Popen(
        ["ip", "netns", "exec", a, sys.executable, str(LISTENER), "--domain", str(domain),
         "--interface", addr_a, "--peers", addr_b, "--outcomes", str(PARCELS),
         "--timeout", "300"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
    )  # fmt: skip
    assert listener.stderr.readline().strip() == "listening"
    binds: set[str] = set()
    done = threading.Event()

    def watch() -> None:
        while not done.wait(0.2):
            binds.update(_udp_binds(b))

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        run = subprocess.run(
            ["ip", "netns", "exec", b, sys.executable, "-m", "fence_sorter.cli.main", "run",
             "--parcels", str(PARCELS), "--domain", str(domain), "--interface", addr_b,
             "--peers", addr_a, "--json"],
            capture_output=True, text=True, timeout=600, cwd=tmp_path,
        )  # fmt: skip
    finally:
        done.set()
        watcher.join()
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout)
    out, err = listener.communicate(timeout=330)
    assert listener.returncode == 0, err[-3000:]
    got = json.loads(out.strip().splitlines()[-1])
    # every parcel and every outcome of the run crossed the link, as the run has them
    assert sorted(got["parcels"]) == [r["parcel_id"] for r in summary["parcels"]]
    codes = {name: code for code, name in enumerate(
        ["SORTED", "NOT_DIVERTED", "NO_FEASIBLE_COMMAND", "NO_COMMAND", "MISSED", "REJECTED",
         "SOLVER_FAILURE", "NO_STROKE_IN_BUDGET"])}  # fmt: skip
    assert sorted(map(tuple, got["outcomes"])) == [
        (r["parcel_id"], codes[r["outcome"]]) for r in summary["parcels"]
    ]
    # the run's sockets: on B's link address only
    assert binds == {addr_b}, binds
