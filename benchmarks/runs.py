"""A `fence-sorter run` a campaign started: wait for it and read its summary."""

from __future__ import annotations

import json
import os
import signal
import subprocess


def finish(proc: subprocess.Popen, timeout: float = 600.0) -> str:
    """The run's standard output once it has exited; its process group is killed after
    ``timeout`` s."""
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    return out


def last_json(out: str) -> dict:
    """The last line of ``out`` that is a JSON object (``--json``'s summary), else {}."""
    for line in reversed(out.strip().splitlines()):
        try:
            value = json.loads(line)
        except ValueError:
            continue
        if isinstance(value, dict):
            return value
    return {}
