"""The two hosts of the ``hosts`` tests: two network namespaces joined by a veth pair (root and
the ``ip`` command needed; skipped with the reason otherwise)."""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid

import pytest


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture
def two_hosts():
    """(netns A, address A, netns B, address B), removed afterwards."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("two hosts need root and the ip command (network namespaces, veth)")
    tag = uuid.uuid4().hex[:6]
    a, b = f"fs{tag}a", f"fs{tag}b"
    net = 100 + int(tag, 16) % 150
    addr_a, addr_b = f"10.{net}.77.1", f"10.{net}.77.2"
    try:
        _ip("netns", "add", a)
        _ip("netns", "add", b)
        _ip("link", "add", f"v{tag}a", "type", "veth", "peer", "name", f"v{tag}b")
        for ns, dev, addr in ((a, f"v{tag}a", addr_a), (b, f"v{tag}b", addr_b)):
            _ip("link", "set", dev, "netns", ns)
            _ip("-n", ns, "addr", "add", f"{addr}/24", "dev", dev)
            _ip("-n", ns, "link", "set", dev, "up")
            _ip("-n", ns, "link", "set", "lo", "up")
    except subprocess.CalledProcessError as exc:
        pytest.skip(f"network namespaces not available here: {exc.stderr.strip()}")
    try:
        yield a, addr_a, b, addr_b
    finally:
        for ns in (a, b):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
