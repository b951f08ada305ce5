"""Stopping `fence-sorter run` cannot orphan a process: any number of SIGINT/SIGTERM at any
moment (start-up included) end every process of the run with exit 130 and no traceback, and a
SIGKILLed runner takes its nodes, the pacing worker and the Rerun child with it.

Every process of a run inherits the runner's environment, so a tag set there finds them all
(:func:`fence_sorter.runner.processes.tagged`), whatever group they are in."""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from fence_sorter.runner.processes import SHM_DIR, SHM_GRACE, clean_shm, tagged, wait_until

pytestmark = [pytest.mark.ros, pytest.mark.faults, pytest.mark.slow]

TAG = "FENCE_SORTER_TEST_RUN"
REPO = Path(__file__).resolve().parents[2]


def _start_run(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, str]:
    """`fence-sorter run ARGS` with setsid (as from a terminal), tagged."""
    tag = uuid.uuid4().hex
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env[TAG] = tag
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", *args]
    cmd += ["--json", "--log-dir", str(tmp_path / "logs")]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=env,
        start_new_session=True,
    )
    return proc, tag


def _cmdlines(tag: str) -> list[str]:
    out = []
    for pid in tagged(TAG, tag):
        try:
            out.append(Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode())
        except OSError:
            pass
    return out


def _running(tag: str, module: str) -> bool:
    return any(module in c for c in _cmdlines(tag))


def _loop_running(tag: str) -> bool:
    """The pacing loop's process (forked from the simulator's: named, not in its cmdline)."""
    from fence_sorter.line.worker import PROCESS_NAME  # lazy: numba, through the line

    for pid in tagged(TAG, tag):
        try:
            if Path(f"/proc/{pid}/comm").read_text().strip() == PROCESS_NAME:
                return True
        except OSError:
            pass
    return False


def _finish(proc: subprocess.Popen, tag: str) -> tuple[str, str]:
    try:
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    # the processes of the run end with it; poll: the kernel reaps a killed group in a moment
    assert wait_until(lambda: not tagged(TAG, tag), 10.0), _cmdlines(tag)
    return out, err


# When the signals come: the runner's own start-up (imports, before any node), while the
# nodes start (controller warming up), and while the stream runs (every node up)
MOMENTS = {
    "start-up": lambda proc: _catches_sigterm(proc.pid),
    "nodes starting": lambda proc: _running(proc.tag, "fence_sorter.nodes.controller"),
    "running": lambda proc: _running(proc.tag, "fence_sorter.nodes.scanner"),
}


def _catches_sigterm(pid: int) -> bool:
    """The command's main() has run: it handles SIGTERM (the interpreter leaves it default;
    a signal in the interpreter's own start-up, before any of our code, is Python's)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = next(line for line in status.splitlines() if line.startswith("SigCgt:"))
    return bool(int(caught.split()[1], 16) & (1 << (signal.SIGTERM - 1)))


@pytest.mark.parametrize(
    ("moment", "signals"),
    [
        ("start-up", [signal.SIGINT, signal.SIGINT]),
        ("nodes starting", [signal.SIGINT, signal.SIGINT, signal.SIGINT]),
        ("running", [signal.SIGTERM, signal.SIGINT, signal.SIGTERM]),
    ],
    ids=["start-up-2xINT", "starting-3xINT", "running-TERM-INT-TERM"],
)
def test_interrupted_run_ends_every_process(tmp_path: Path, moment: str, signals: list) -> None:
    proc, tag = _start_run(tmp_path, "--parcels", "40", "--rrd", str(tmp_path / "r.rrd"))
    try:
        proc.tag = tag
        assert wait_until(lambda: MOMENTS[moment](proc) or proc.poll() is not None, 180.0, 0.01)
        assert proc.poll() is None, proc.communicate()
        for k, sig in enumerate(signals):
            proc.send_signal(sig)
            # the second one lands while the first stop is on its way
            wait_until(lambda: proc.poll() is not None, 0.1 * (k + 1))
    finally:
        out, err = _finish(proc, tag)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    if moment != "start-up":
        import json

        summary = json.loads(out)
        assert summary["message"].startswith("interrupted")
        assert summary["leftover_processes"] == []


@pytest.mark.parametrize(
    ("moment", "signals"),
    [
        ("units starting", [signal.SIGINT, signal.SIGINT]),
        ("running", [signal.SIGTERM, signal.SIGINT, signal.SIGTERM]),
    ],
    ids=["starting-2xINT", "running-TERM-INT-TERM"],
)
def test_interrupted_line_run_ends_every_process(
    tmp_path: Path, moment: str, signals: list
) -> None:
    """`run --line`: the owner and every unit process end with the runner, exit 130."""
    proc, tag = _start_run(tmp_path, "--line", "two_units", "--parcels", "200")
    started = {
        "units starting": lambda: _running(tag, "fence_sorter.nodes.line_unit"),
        "running": lambda: (
            _running(tag, "fence_sorter.nodes.line_owner")
            and sum("fence_sorter.nodes.line_unit" in c for c in _cmdlines(tag)) == 2
        ),
    }[moment]
    try:
        assert wait_until(lambda: started() or proc.poll() is not None, 180.0, 0.01)
        assert proc.poll() is None, proc.communicate()
        for k, sig in enumerate(signals):
            proc.send_signal(sig)
            wait_until(lambda: proc.poll() is not None, 0.1 * (k + 1))
    finally:
        _, err = _finish(proc, tag)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert "interrupted" in err, err


def test_killed_runner_takes_every_process_with_it(tmp_path: Path) -> None:
    """SIGKILL of the runner itself (no handler can run): the nodes die by their parent-death
    signal, the pacing worker and the Rerun child with their groups (the reaper)."""
    proc, tag = _start_run(tmp_path, "--parcels", "40", "--rrd", str(tmp_path / "r.rrd"))
    try:
        rerun = "fence_sorter.visualisation.rerun_live"
        assert wait_until(
            lambda: (_loop_running(tag) and _running(tag, rerun)) or proc.poll() is not None,
            180.0,
        )
        assert _running(tag, rerun), _cmdlines(tag)
        assert _loop_running(tag)
        assert proc.poll() is None
        proc.send_signal(signal.SIGKILL)
    finally:
        _finish(proc, tag)
    assert proc.returncode == -signal.SIGKILL
    # the killed participants' shared-memory files stay in /dev/shm until the next start
    # cleans them: afterwards every Fast DDS lock file left there is held by a live process
    clean_shm()
    for lock in SHM_DIR.glob("fastdds_*_[es]l"):
        try:
            if time.time() - lock.stat().st_mtime < SHM_GRACE:
                continue  # another program's participant may be creating it right now
            fd = os.open(lock, os.O_RDONLY)
        except FileNotFoundError:
            continue
        try:
            with pytest.raises(BlockingIOError):
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        finally:
            os.close(fd)
