"""Node processes of a run (ROS-free): isolated environment, process groups, clean stop.

Every node runs in its own session/process group, so stopping a node also ends anything it
started; :func:`leftovers` scans /proc for processes still in those groups (no orphans).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from fence_sorter.resources import checkout_root

#: Domain ids of `fence-sorter run` (the tests use 100..199); Fast DDS accepts up to 232.
RUN_DOMAIN_RANGE = (201, 232)
#: Stop escalation: (signal, seconds to wait for the group to end).
STOP_SEQUENCE = ((signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0))


def run_domain_id(pid: int | None = None) -> int:
    """A ROS_DOMAIN_ID for this run, derived from the process id."""
    lo, hi = RUN_DOMAIN_RANGE
    return lo + (os.getpid() if pid is None else pid) % (hi - lo + 1)


def node_env(
    domain_id: int, log_dir: Path, extra: Mapping[str, str] | None = None
) -> dict[str, str]:
    """os.environ plus isolation: own domain, localhost discovery, rcl logs in ``log_dir``."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_LOG_DIR"] = str(log_dir)
    env["PYTHONUNBUFFERED"] = "1"
    env.pop("RMW_IMPLEMENTATION", None)
    repo = checkout_root()  # None in an install: its PYTHONPATH finds the package already
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [repo and str(repo), env.get("PYTHONPATH")]))
    if extra:
        env.update(extra)
    return env


def node_command(name: str, ros_args: Sequence[str] = ()) -> list[str]:
    """Command line of node ``name`` (fence_sorter.nodes.<name>) with --ros-args."""
    cmd = [sys.executable, "-m", f"fence_sorter.nodes.{name}"]
    if ros_args:
        cmd += ["--ros-args", *ros_args]
    return cmd


@dataclass
class NodeProcess:
    name: str
    proc: subprocess.Popen
    log_path: Path
    log: IO = field(repr=False, default=None)

    @property
    def pgid(self) -> int:
        return self.proc.pid

    def tail(self, lines: int = 15) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


class ProcessGroup:
    """The node processes of one run; :meth:`stop` ends them all, in order, with escalation."""

    def __init__(self, env: Mapping[str, str], log_dir: Path, cpus: set[int] | None = None):
        """``cpus``: the CPUs every node process may run on (None: as this process)."""
        self.env = dict(env)
        self.cpus = cpus
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.nodes: dict[str, NodeProcess] = {}
        self.pgids: list[int] = []

    def start(self, name: str, cmd: Sequence[str]) -> NodeProcess:
        log_path = self.log_dir / f"{name}.log"
        log = open(log_path, "a", buffering=1)  # noqa: SIM115 (closed in stop)
        proc = subprocess.Popen(
            list(cmd),
            env=self.env,
            start_new_session=True,
            stdout=log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
        )
        if self.cpus is not None:  # before the interpreter starts any thread (inherited)
            try:
                os.sched_setaffinity(proc.pid, self.cpus)
            except OSError:
                pass
        node = NodeProcess(name, proc, log_path, log)
        self.nodes[name] = node
        self.pgids.append(proc.pid)
        return node

    def dead(self) -> list[NodeProcess]:
        """Nodes that exited on their own."""
        return [n for n in self.nodes.values() if n.proc.poll() is not None]

    def stop_one(self, name: str) -> int | None:
        """Stop one node (and its group) with escalation; return its exit code."""
        node = self.nodes[name]
        for sig, timeout in STOP_SEQUENCE:
            if node.proc.poll() is None:
                _killpg(node.pgid, sig)
                try:
                    node.proc.wait(timeout=timeout)
                except subprocess.TimeoutExpired:
                    continue
            # the leader is gone; end whatever is left of its group
            if not leftovers([node.pgid]):
                break
            _killpg(node.pgid, signal.SIGKILL)
        if node.log is not None and not node.log.closed:
            node.log.close()
        return node.proc.returncode

    def stop(self, order: Sequence[str] | None = None) -> dict[str, int | None]:
        """Stop every node (``order`` first, then the rest); return exit codes by name."""
        names = list(order or []) + [n for n in self.nodes if n not in (order or [])]
        return {n: self.stop_one(n) for n in names if n in self.nodes}


def _killpg(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def leftovers(pgids: Sequence[int]) -> list[int]:
    """Pids of live (non-zombie) processes whose process group is one of ``pgids`` (/proc)."""
    wanted = set(pgids)
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # pid (comm) state ppid pgrp ...; comm may contain spaces or parentheses
        rest = stat[stat.rfind(")") + 2 :].split()
        if len(rest) >= 3 and int(rest[2]) in wanted and rest[0] != "Z":
            found.append(int(entry.name))
    return found


def wait_until(predicate, timeout: float, step: float = 0.05) -> bool:
    """Poll ``predicate`` until true or ``timeout`` s passed."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return bool(predicate())
