"""A run's isolation without ROS: its domain (--domain, ROS_DOMAIN_ID, else a free one; a
domain another participant on this host uses is refused), the node logs it leaves (none after
a clean run) and the shared-memory files of killed participants (cleaned at the next start)."""

from __future__ import annotations

import fcntl
import os
import socket
import time
from pathlib import Path

import pytest
from processes import run_cli

from fence_sorter.runner.processes import (
    RUN_DOMAIN_RANGE,
    DomainError,
    choose_domain,
    clean_shm,
    domain_in_use,
    domain_ports,
)


@pytest.fixture
def occupied():
    """A UDP socket on a domain's first participant port, as a Fast DDS participant holds it
    (returns the domain)."""
    sockets = []

    def take(domain: int, participant: int = 0) -> int:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", domain_ports(domain)[participant]))
        sockets.append(sock)
        return domain

    yield take
    for sock in sockets:
        sock.close()


def _free_domain(start: int) -> int:
    return next(d for d in range(start, 233) if not domain_in_use(d))


def test_domain_asked_for_is_used_or_refused_when_taken(occupied) -> None:
    free = _free_domain(150)
    assert choose_domain(free, env={}) == free
    assert choose_domain(None, env={"ROS_DOMAIN_ID": str(free)}) == free
    taken = occupied(_free_domain(free + 1), participant=3)
    with pytest.raises(DomainError, match=f"--domain {taken}: the ROS domain is in use"):
        choose_domain(taken, env={})
    with pytest.raises(DomainError, match=f"ROS_DOMAIN_ID {taken}: the ROS domain is in use"):
        choose_domain(None, env={"ROS_DOMAIN_ID": str(taken)})
    with pytest.raises(DomainError, match=r"--domain must be in \[0, 232\], got 233"):
        choose_domain(233, env={})
    with pytest.raises(DomainError, match="ROS_DOMAIN_ID must be an integer"):
        choose_domain(None, env={"ROS_DOMAIN_ID": "eleven"})


def test_automatic_domain_skips_the_taken_ones(occupied, monkeypatch) -> None:
    lo, hi = RUN_DOMAIN_RANGE
    first = _free_domain(lo)
    monkeypatch.setattr("fence_sorter.runner.processes.run_domain_id", lambda: first)
    assert choose_domain(None, env={}) == first
    occupied(first)
    chosen = choose_domain(None, env={})
    assert chosen != first and lo <= chosen <= hi and not domain_in_use(chosen)


@pytest.mark.slow
def test_run_exits_2_when_its_domain_is_taken(occupied) -> None:
    taken = occupied(_free_domain(160))
    done = run_cli("run", "--parcels", "1", "--domain", str(taken), timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert lines == [
        f"fence-sorter: error: --domain {taken}: the ROS domain is in use on this host "
        f"(UDP port {domain_ports(taken)[0]} held by another participant); choose another domain"
    ]


def _leftover(directory: Path, base: str, age: float = 60.0) -> list[Path]:
    files = [directory / base, directory / f"{base}_el", directory / f"sem.{base}_mutex"]
    for f in files:
        f.write_bytes(b"x")
        os.utime(f, (time.time() - age, time.time() - age))
    return files


def test_shared_memory_of_dead_participants_is_cleaned(tmp_path: Path) -> None:
    dead_port = _leftover(tmp_path, "fastdds_port7413")
    dead_segment = _leftover(tmp_path, "fastdds_0123456789abcdef")
    orphan = _leftover(tmp_path, "fastdds_port7419")[::2]  # its lock file already gone
    (tmp_path / "fastdds_port7419_el").unlink()
    live_port = _leftover(tmp_path, "fastdds_port7415")
    young = _leftover(tmp_path, "fastdds_port7417", age=0.0)  # maybe being created
    other = tmp_path / "not_fast_dds_el"
    other.write_bytes(b"x")
    # a live owner maps its port and semaphore and holds its lock file open and locked
    held = [open(f, "ab") for f in live_port]  # noqa: SIM115
    try:
        fcntl.flock(held[1], fcntl.LOCK_SH)
        removed = clean_shm(tmp_path)
    finally:
        for h in held:
            h.close()
    assert sorted(removed) == sorted(f.name for f in dead_port + dead_segment + orphan)
    assert all(not f.exists() for f in dead_port + dead_segment + orphan)
    assert all(f.exists() for f in live_port + young + [other])
