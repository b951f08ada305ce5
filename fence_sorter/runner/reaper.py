"""Watchdog of a run: ``python -m fence_sorter.runner.reaper FD``.

Reads process group ids (one per line) from pipe FD, written by the runner as it starts each
node. When the pipe ends without a ``done`` line (the runner died, SIGKILL included), every
process of those groups gets SIGKILL, the real-time ones first. It runs in a process group of its
own, so a Ctrl-C at the terminal reaches the runner, not this process.
"""

from __future__ import annotations

import os
import signal
import sys

from fence_sorter.runner.processes import kill_groups, leftovers, wait_until


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    fd = int(argv[0])
    pgids: list[int] = []
    buffer, done = b"", False
    while chunk := os.read(fd, 4096):
        buffer += chunk
        *lines, buffer = buffer.split(b"\n")
        for line in lines:
            if line == b"done":
                done = True
            elif line.strip():
                pgids.append(int(line))
    if not done:
        kill_groups(pgids)
        wait_until(lambda: not leftovers(pgids), 5.0)
        kill_groups(pgids)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
