"""keep_cpus_awake's spinners: one per CPU, pinned, at SCHED_IDLE, gone when stopped or when
their parent dies."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from processes import process_alive, wait_until

from fence_sorter.line.awake import start_spinners, stop_spinners


def _policy(pid: int) -> int:
    """The spinner's scheduling policy once it is SCHED_IDLE (the child sets it right after
    starting), or whatever it has after 5 s."""
    try:
        wait_until(lambda: os.sched_getscheduler(pid) == os.SCHED_IDLE, 5.0, "SCHED_IDLE")
    except AssertionError:
        pass
    return os.sched_getscheduler(pid)


def test_one_idle_spinner_per_cpu_pinned_and_stopped():
    cpus = set(os.sched_getaffinity(0))
    procs = start_spinners(cpus)
    try:
        assert len(procs) == len(cpus)
        for cpu, p in zip(sorted(cpus), procs, strict=True):
            assert _policy(p.pid) == os.SCHED_IDLE
            assert os.sched_getaffinity(p.pid) == {cpu}
            assert p.poll() is None
    finally:
        stop_spinners(procs)
    assert all(p.returncode is not None for p in procs)


@pytest.mark.slow
def test_spinners_die_with_their_parent():
    code = (
        "import signal, sys\n"
        "from fence_sorter.line.awake import start_spinners\n"
        "procs = start_spinners({min(__import__('os').sched_getaffinity(0))})\n"
        "print(procs[0].pid, flush=True)\n"
        "signal.pause()\n"  # until killed
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    spinner = int(parent.stdout.readline())
    assert _policy(spinner) == os.SCHED_IDLE
    parent.kill()
    parent.wait()
    wait_until(lambda: not process_alive(spinner), 10.0, f"spinner {spinner} to end")
