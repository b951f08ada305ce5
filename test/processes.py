"""Building blocks for tests that start fence_sorter processes (nodes, CLI) over real DDS.

Each process gets its own process group, so a test can always end it and everything it
started (no orphan processes), and an environment that keeps test runs apart: one
ROS_DOMAIN_ID per run, discovery limited to this machine, rcl logs in a temporary directory.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TypeVar

from fence_sorter.runner.processes import node_env

T = TypeVar("T")

#: Fast DDS accepts domain ids 0..232; stay away from 0 (the default) and 1..99.
DOMAIN_ID_RANGE = (100, 200)


def wait_until(
    predicate: Callable[[], T],
    timeout: float,
    what: str,
    poll: Callable[[], object] | None = None,
    interval: float = 0.01,
) -> T:
    """Return ``predicate()``'s first truthy value, polled until ``timeout`` seconds have
    passed; then fail with an AssertionError naming ``what`` was awaited.

    ``poll`` does the work between two checks (for example ``lambda: rclpy.spin_once(node,
    timeout_sec=0.05)``); without it the wait is ``interval`` seconds. Tests wait on a
    condition this way, never sleep for a guessed time and then assert."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        if poll is not None:
            poll()
        else:
            time.sleep(interval)


def process_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (a zombie not yet reaped counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def run_domain_id() -> int:
    """Return a ROS_DOMAIN_ID for this test run (derived from the process id)."""
    low, high = DOMAIN_ID_RANGE
    return low + os.getpid() % (high - low)


def ros_env(
    domain_id: int, log_dir: Path, extra: Mapping[str, str] | None = None
) -> dict[str, str]:
    """Return os.environ plus the isolation settings for a child process (the same as
    ``fence-sorter run`` gives its nodes: :func:`fence_sorter.runner.processes.node_env`)."""
    return node_env(domain_id, log_dir, extra)


def venv_executable(name: str) -> str:
    """Return the path of console script ``name`` next to this interpreter."""
    return str(Path(sys.executable).parent / name)


def stop_process(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> None:
    """End ``proc`` and its process group: ``sig`` first, SIGKILL if it lingers."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pass
    # Whatever is left of the group (children of the child), and the child itself.
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    if proc.poll() is None:
        proc.wait(timeout=timeout)


@contextmanager
def managed_process(
    cmd: Sequence[str], env: Mapping[str, str], **popen_kwargs: object
) -> Iterator[subprocess.Popen]:
    """Start ``cmd`` in its own process group; always end the group on exit of the block."""
    proc = subprocess.Popen(
        list(cmd),
        env=dict(env),
        start_new_session=True,
        stdout=popen_kwargs.pop("stdout", subprocess.PIPE),
        stderr=popen_kwargs.pop("stderr", subprocess.PIPE),
        text=True,
        **popen_kwargs,
    )
    try:
        yield proc
    finally:
        stop_process(proc)
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


def run_cli(
    *args: str, timeout: float = 600.0, module: str = "fence_sorter.cli.main"
) -> subprocess.CompletedProcess:
    """``fence-sorter ARGS`` as a separate process run from the checkout (``module``
    ``benchmarks``: ``python -m benchmarks ARGS``, the campaigns)."""
    repo = Path(__file__).resolve().parents[1]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(repo), env.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=repo,
        env=env,
    )
