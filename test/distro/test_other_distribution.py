"""The other ROS 2 distribution: set up from scratch beside the default one, then the ROS
tests on it.

The suite runs on Jazzy (LTS) by default and on Kilted with ``FENCE_SORTER_ROS_DISTRO=kilted``
(scripts/bootstrap.sh: its own pinned wheel set, venv ``.venv-kilted`` and build directory
``.build/kilted``; docs/guide/install.md). ``make test`` runs everything on the distribution of its
venv and, through this test, the set-up and ``pytest test/ros`` on the other one in a child
process, so CI (which runs ``make test`` alone) covers both: every node, message, bag and
DDS path runs on each distribution (the quick ROS tests and the slow ones of ``OTHER_SLOW``);
the command-line tests (``test/cli``: argument checks, summaries and verdicts, the same
Python on both) run on the default one. On the other one the fault-injection tests (marker
``faults``: killed and restarted nodes, floods, a full disk) are left out but for the signal
tests of ``test_shutdown.py``: they test the runner's and the nodes' own logic, the same on
both, while signal handling is the distribution's rclpy. A
failure shows the child's output. ``pytest -m "not distro"`` leaves it out. The colcon
install test runs on the default distribution only (docs/guide/install.md: what the other leg
costs).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from fence_sorter.rosdistro import ros_distribution

pytestmark = [pytest.mark.distro, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
#: the distribution that is not the one this test runs on
OTHER = {"jazzy": "kilted", "kilted": "jazzy"}
#: the slow ROS tests run on the other distribution too: the node suite end to end, every
#: message through DDS, the recorder's bags, the nodes one by one, the line over DDS (equal
#: to line-sim) and the signal tests; the other slow ones (views, bags of lines, the CLI
#: clients) run the same Python on the same paths and are left to the default distribution
OTHER_SLOW = (
    "test/ros/test_suite_e2e.py",
    "test/ros/test_dds_roundtrip.py",
    "test/ros/test_recording.py",
    "test/ros/test_nodes.py",
    "test/ros/test_line_run.py",
    "test/ros/test_shutdown.py",
)
#: the other distribution's set-up (a first one: download and message build) [s]
BOOTSTRAP_TIMEOUT = 1800.0
#: its ROS tests [s]
TESTS_TIMEOUT = 3600.0
#: the child's output shown on a failure [characters]
TAIL = 12000


def other_env(distro: str) -> dict[str, str]:
    """This environment without the current venv, for the other distribution's scripts."""
    env = dict(os.environ)
    venv = env.pop("VIRTUAL_ENV", None)
    for var in ("FENCE_SORTER_VENV", "PYTHONPATH", "PYTHONHOME", "ROS_DISTRO"):
        env.pop(var, None)
    for var in [v for v in env if v.startswith("_ROS_WHEELS")]:
        env.pop(var, None)
    if venv:
        env["PATH"] = os.pathsep.join(
            p for p in env.get("PATH", "").split(os.pathsep) if p != f"{venv}/bin"
        )
    # the ros-wheels bootstrapper put this venv's libraries on LD_LIBRARY_PATH: the other
    # venv's libraries have the same names
    env["LD_LIBRARY_PATH"] = os.pathsep.join(
        p
        for p in env.get("LD_LIBRARY_PATH", "").split(os.pathsep)
        if p and not p.startswith(sys.prefix)
    )
    env["AMENT_PREFIX_PATH"] = ""
    env["FENCE_SORTER_ROS_DISTRO"] = distro
    return env


def run_in(distro: str, script: str, timeout: float) -> subprocess.CompletedProcess:
    """``script`` (bash) in the checkout with the other distribution's environment."""
    return subprocess.run(
        ["bash", "-c", script],
        cwd=REPO,
        env=other_env(distro),
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
    )


def shown(proc: subprocess.CompletedProcess) -> str:
    return f"exit {proc.returncode}\n{(proc.stdout + proc.stderr)[-TAIL:]}"


def test_the_other_distribution_sets_up_and_passes_the_ros_tests() -> None:
    current = ros_distribution()
    assert current in OTHER, f"this venv runs ROS 2 {current!r}, not one of {sorted(OTHER)}"
    distro = OTHER[current]
    setup = run_in(distro, "bash scripts/bootstrap.sh", BOOTSTRAP_TIMEOUT)
    assert setup.returncode == 0, shown(setup)

    check = run_in(distro, "source scripts/env.sh && fence-sorter check", 120.0)
    assert check.returncode == 0, shown(check)
    line = next(ln for ln in check.stdout.splitlines() if ln.startswith("OK   ros 2:"))
    assert f"OK   ros 2: {distro}, Fast DDS " in line, line
    venv = REPO / (".venv" if distro == "jazzy" else f".venv-{distro}")
    assert (venv / ".fence_sorter_ros_distro").read_text().strip() == distro

    tests = run_in(
        distro,
        "source scripts/env.sh && pytest -q -p no:cacheprovider -m 'not faults and not slow'"
        f" test/ros && pytest -q -p no:cacheprovider -m 'not faults' {' '.join(OTHER_SLOW)}",
        TESTS_TIMEOUT,
    )
    assert tests.returncode == 0, shown(tests)
    assert " passed" in tests.stdout.splitlines()[-1], shown(tests)
