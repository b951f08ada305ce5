"""``python -m benchmarks.peers``: bad arguments are one line naming the argument, exit 2."""

from __future__ import annotations

import os
import subprocess
import sys

from benchmarks import REPO


def peers(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, "-m", "benchmarks.peers", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO,
        env=env,
    )


def test_bad_rounds_and_rungs_exit_2_with_one_line() -> None:
    r = peers("--rounds", "0")
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "benchmarks.peers: error: --rounds must be at least 1, got 0"
    ]
    r = peers("--rung", "cyrk:LSODA:tight")
    assert r.returncode == 2
    (line,) = r.stderr.strip().splitlines()
    assert "--rung 'cyrk:LSODA:tight' is not method:rtol" in line
    r = peers("--rung", "cyrk:Euler:1e-3")
    assert r.returncode == 2
    (line,) = r.stderr.strip().splitlines()
    assert "cyrk:Euler" in line and "cyrk:LSODA" in line
