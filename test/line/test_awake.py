"""keep_cpus_awake's spinners: one per CPU, pinned, at SCHED_IDLE, gone when stopped or when
their parent dies."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from fence_sorter.line.awake import start_spinners, stop_spinners


def _policy(pid: int) -> int:
    for _ in range(100):  # the child sets its policy right after starting
        if os.sched_getscheduler(pid) == os.SCHED_IDLE:
            break
        time.sleep(0.05)
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


def test_spinners_die_with_their_parent():
    code = (
        "import sys, time\n"
        "from fence_sorter.line.awake import start_spinners\n"
        "procs = start_spinners({min(__import__('os').sched_getaffinity(0))})\n"
        "print(procs[0].pid, flush=True)\n"
        "time.sleep(60)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    spinner = int(parent.stdout.readline())
    assert _policy(spinner) == os.SCHED_IDLE
    parent.kill()
    parent.wait()
    for _ in range(100):
        try:
            os.kill(spinner, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        raise AssertionError(f"spinner {spinner} outlived its parent")
