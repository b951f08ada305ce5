"""``fence-sorter run --line two_units`` as the user starts it, with a listener of the test's
own on the line's domain that the line waits for: the owner is held (SIGSTOP) from its start
until the listener has matched its topics, so the listener sees the line from its first step.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from processes import stop_process, wait_until

from fence_sorter.runner.processes import tagged

REPO = Path(__file__).resolve().parents[2]
TAG = "FENCE_SORTER_TEST_LINE_KILL"
#: the line, its stream and the pace of its clock (real-time factor)
LINE, PARCELS, SEED, RATE, RTF = "two_units", 6, 3, 4000, 2


def run_pid(tag: str, *words: str) -> int | None:
    """The pid of the run's process whose command line holds every one of ``words`` (None:
    none yet)."""
    for pid in tagged(TAG, tag):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if all(w.encode() in cmd for w in words):
            return pid
    return None


@contextmanager
def held_line_run(
    tmp_path: Path, listener: Callable[[int, str], object], matched: Callable[[object], bool]
) -> Iterator[tuple[subprocess.Popen, object, Path]]:
    """The run (``--json``; a unit's new process and the owner wait up to a minute for each
    other), ``listener(domain, tag)`` made while its owner is held and ``matched(listener)``
    awaited before the owner goes on; yields (process, listener, stderr file). On the way
    out the owner is let go, the listener closed (``close()``) and the run stopped."""
    tag = uuid.uuid4().hex
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env[TAG] = tag
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--line", LINE, "--parcels",
           str(PARCELS), "--seed", str(SEED), "--rate", str(RATE), "--rtf", str(RTF), "--json",
           "--log-dir", str(tmp_path / "logs"), "--reply-timeout", "60",
           "--owner-timeout", "90"]  # fmt: skip
    err_file = tmp_path / "stderr.txt"
    made, held = None, None
    with err_file.open("w") as err_out:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=err_out, text=True, cwd=REPO, env=env,
            start_new_session=True,
        )  # fmt: skip
        try:
            # the runner says its domain once it checked that no other participant uses it
            found = wait_until(
                lambda: (
                    re.search(r"ROS domain (\d+)", err_file.read_text()) or proc.poll() is not None
                ),
                120.0,
                "the runner's domain",
            )
            assert proc.poll() is None, err_file.read_text()
            owner = wait_until(
                lambda: run_pid(tag, "fence_sorter.nodes.line_owner"), 60.0, "the owner's process"
            )
            os.kill(owner, signal.SIGSTOP)
            held = owner
            made = listener(int(found.group(1)), tag)
            wait_until(lambda: matched(made), 120.0, "the listener matched")
            os.kill(owner, signal.SIGCONT)
            held = None
            yield proc, made, err_file
        finally:
            if held is not None:
                os.kill(held, signal.SIGCONT)
            if made is not None:
                made.close()
            stop_process(proc)
