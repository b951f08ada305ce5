"""The processes of the fault campaign (see :mod:`benchmarks.faults`): every descendant of a
run seen while it runs (:class:`ProcessWatch`), and the ``fence-sorter`` command line."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence
from pathlib import Path


def _ppid_starttime(pid: int) -> tuple[int, int] | None:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
            rest = f.read().rpartition(")")[2].split()
    except OSError:
        return None
    return int(rest[1]), int(rest[19])  # ppid, starttime


class ProcessWatch(threading.Thread):
    """Every descendant of ``root`` seen while it runs (pid and start time, so a reused pid
    is not mistaken for it), polled every ``period`` s."""

    def __init__(self, root: int, period: float = 0.1):
        super().__init__(daemon=True)
        self.root, self.period = root, period
        self.seen: set[tuple[int, int]] = set()
        self.done = threading.Event()

    def poll(self) -> None:
        children: dict[int, list[tuple[int, int]]] = {}
        for name in os.listdir("/proc"):
            if name.isdigit():
                info = _ppid_starttime(int(name))
                if info is not None:
                    children.setdefault(info[0], []).append((int(name), info[1]))
        todo = [self.root]
        while todo:
            for pid, start in children.get(todo.pop(), []):
                if (pid, start) not in self.seen:
                    self.seen.add((pid, start))
                todo.append(pid)

    def run(self) -> None:
        while not self.done.is_set():
            self.poll()
            self.done.wait(self.period)

    def alive(self) -> list[int]:
        """The descendants seen that still run (zombies of a live parent count as gone)."""
        out = []
        for pid, start in self.seen:
            info = _ppid_starttime(pid)
            if info is not None and info[1] == start:
                try:
                    state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
                except OSError:
                    continue
                if state != "Z":
                    out.append(pid)
        return sorted(out)

    def kill_alive(self) -> None:
        for pid in self.alive():
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass


def fence_sorter_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "fence_sorter.cli.main", *args]


def start_watched(
    args: Sequence[str], workdir: Path, stdout, stderr, text: bool = False
) -> tuple[subprocess.Popen, ProcessWatch]:
    """``fence-sorter ARGS`` started in ``workdir`` in a session of its own (as from a
    terminal), and the watch of its descendants, running."""
    proc = subprocess.Popen(
        fence_sorter_cmd(*args),
        stdout=stdout,
        stderr=stderr,
        text=text,
        start_new_session=True,
        cwd=workdir,
    )
    watch = ProcessWatch(proc.pid)
    watch.start()
    return proc, watch
