"""CPU affinity of a process (ROS-free): the run's nodes and the simulator's helpers."""

from __future__ import annotations

import os


def keep_on(pid: int, cpus: set[int] | None) -> None:
    """Every thread of process ``pid`` on ``cpus`` (None: left as it is); a process or thread
    that has just ended is passed over."""
    if cpus is None:
        return
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return
    for tid in tids:
        try:
            os.sched_setaffinity(int(tid), cpus)
        except OSError:
            pass
