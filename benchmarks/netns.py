"""Two hosts on this machine: two network namespaces joined by a veth pair.

Used by the two-host tests (test/hosts), the fault campaign's line faults and ``line-scale
--hosts 2``. Each namespace has its own interfaces, addresses and loopback, so Fast DDS in
one sees the other as another host and reaches it only by UDP over the veth; both share this
machine's kernel (one clock: a DDS source timestamp taken in one namespace and a reception
time taken in the other are on the same clock), its file system and /dev/shm. Needs root and
the ``ip`` command; :class:`NotRunnable` (one line: why) otherwise.

:func:`link_counters` reads a veth end's byte and packet counters (``ip -n NS -j -s link
show DEV``): what crossed the link, independently of DDS.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass


class NotRunnable(RuntimeError):
    """Two hosts cannot be made here (one line: why)."""


@dataclass(frozen=True)
class Hosts:
    a: str  # network namespace of host A
    addr_a: str  # A's address on the link
    dev_a: str  # A's end of the veth pair
    b: str
    addr_b: str
    dev_b: str


def ip(*args: str) -> None:
    """``ip ARGS``; CalledProcessError (with ``ip``'s stderr) when it fails."""
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


def why_not() -> str | None:
    """Why two hosts cannot be made here (None: root and ``ip`` are there)."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        return "two hosts need root and the ip command (network namespaces, veth)"
    return None


@contextmanager
def two_hosts() -> Iterator[Hosts]:
    """Two network namespaces joined by a veth pair, each end up with an address of one /24
    (and each namespace's loopback up); both namespaces removed afterwards."""
    why = why_not()
    if why is not None:
        raise NotRunnable(why)
    tag = uuid.uuid4().hex[:6]
    net = 100 + int(tag, 16) % 150
    h = Hosts(f"fs{tag}a", f"10.{net}.77.1", f"v{tag}a", f"fs{tag}b", f"10.{net}.77.2", f"v{tag}b")
    try:
        try:
            ip("netns", "add", h.a)
            ip("netns", "add", h.b)
            ip("link", "add", h.dev_a, "type", "veth", "peer", "name", h.dev_b)
            for ns, dev, addr in ((h.a, h.dev_a, h.addr_a), (h.b, h.dev_b, h.addr_b)):
                ip("link", "set", dev, "netns", ns)
                ip("-n", ns, "addr", "add", f"{addr}/24", "dev", dev)
                ip("-n", ns, "link", "set", dev, "up")
                ip("-n", ns, "link", "set", "lo", "up")
        except subprocess.CalledProcessError as exc:
            why = exc.stderr.strip()
            raise NotRunnable(f"network namespaces not available here: {why}") from None
        yield h
    finally:
        for ns in (h.a, h.b):  # the veth pair goes with its namespaces
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def in_ns(ns: str, cmd: list[str]) -> list[str]:
    """``cmd`` run in the network namespace ``ns``."""
    return ["ip", "netns", "exec", ns, *cmd]


def ns_pids(ns: str) -> list[int]:
    """The processes of the network namespace ``ns``."""
    out = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def fastdds_shm(ns: str) -> set[str]:
    """The Fast DDS files under /dev/shm (``fastrtps_*``) that the processes of the network
    namespace ``ns`` map or hold open now."""
    found: set[str] = set()
    for pid in ns_pids(ns):
        try:
            with open(f"/proc/{pid}/maps") as f:
                found.update(w for line in f for w in line.split()[5:] if _fastdds_file(w))
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:  # the process ended meanwhile
            continue
        for fd in fds:
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if _fastdds_file(target):
                found.add(target)
    return found


def _fastdds_file(path: str) -> bool:
    return path.startswith("/dev/shm/fastrtps_")


def link_counters(ns: str, dev: str) -> dict[str, int]:
    """The kernel's counters of ``dev`` in ``ns``: ``rx_bytes``, ``rx_packets``, ``tx_bytes``,
    ``tx_packets`` (bytes of the Ethernet frames, headers included)."""
    out = subprocess.run(
        ["ip", "-n", ns, "-j", "-s", "link", "show", dev],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    stats = json.loads(out)[0]["stats64"]
    return {f"{d}_{k}": int(stats[d][k]) for d in ("rx", "tx") for k in ("bytes", "packets")}


def grown(before: dict[str, int], after: dict[str, int]) -> dict[str, int]:
    """How much each counter of :func:`link_counters` grew from ``before`` to ``after``."""
    return {k: after[k] - before[k] for k in before}


def wait_both(
    first: subprocess.Popen, second: subprocess.Popen, first_timeout: float, second_timeout: float
) -> tuple[str, str, str, str]:
    """Both hosts' commands' (stdout, stderr): the first waited for up to ``first_timeout``,
    then the second (which ends with the line) up to ``second_timeout`` [s]; neither is left
    running."""
    try:
        out_1, err_1 = first.communicate(timeout=first_timeout)
        out_2, err_2 = second.communicate(timeout=second_timeout)
    finally:
        for p in (first, second):
            if p.poll() is None:
                p.kill()
                p.wait()
    return out_1, err_1, out_2, err_2
