"""Node processes of a run (ROS-free): isolated environment, process groups, clean stop.

Every node runs in its own process group (setsid), so stopping a node also ends anything it
started; :func:`leftovers` scans /proc for processes still in those groups (no orphans).
Nothing outlives the run: each node gets SIGKILL when the runner dies (PR_SET_PDEATHSIG), and a
watchdog process (:mod:`fence_sorter.runner.reaper`) kills every group of the run when the
runner ends without saying it is done (SIGKILL of the runner included).
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import IO

from fence_sorter.affinity import keep_on
from fence_sorter.resources import checkout_root, data_path
from fence_sorter.rosdistro import set_profile

#: Domain ids of `fence-sorter run`'s automatic choice (the tests use 100..199); Fast DDS's
#: default ports allow 0..232 (ROS_DOMAIN_ID, --domain)
RUN_DOMAIN_RANGE = (201, 232)
DOMAIN_LIMITS = (0, 232)
#: Fast DDS's well-known ports (RTPS 9.6.1.1): the metatraffic unicast port of participant p in
#: domain d is PORT_BASE + DOMAIN_GAIN d + 10 + 2 p; a participant alive on this host holds it
PORT_BASE, DOMAIN_GAIN = 7400, 250
#: participants per domain whose ports are probed (a run has at most six)
PROBED_PARTICIPANTS = 12
#: the transports of every process of a run: shared memory and loopback UDP only
FASTDDS_PROFILE = data_path("config", "fastdds_localhost.xml")


#: Stop escalation at the end of a run, node by node: (signal, seconds to wait for the group).
STOP_SEQUENCE = ((signal.SIGINT, 10.0), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0))
#: An interrupted run stops every node at once within this many seconds: SIGINT, SIGTERM after
#: half of it, SIGKILL (real-time processes first) after three quarters
INTERRUPT_BUDGET = 4.0
#: Signals that stop a run; held while a node is being started, so none is half-registered
STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})
_PR_SET_PDEATHSIG = 1
_LIBC = ctypes.CDLL(None, use_errno=True)


class DomainError(ValueError):
    """The ROS domain asked for is out of range or in use on this host (one line)."""


def domain_ports(domain: int, participants: int = PROBED_PARTICIPANTS) -> list[int]:
    """The metatraffic unicast ports of ``domain``'s first participants."""
    base = PORT_BASE + DOMAIN_GAIN * domain + 10
    return [base + 2 * p for p in range(participants)]


def domain_in_use(domain: int) -> list[int]:
    """Ports of ``domain`` that a process on this host holds (Fast DDS binds them exclusively;
    a wildcard bind conflicts with a bind on any address)."""
    taken = []
    for port in domain_ports(domain):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind(("0.0.0.0", port))
            except OSError as exc:
                if exc.errno == errno.EADDRINUSE:
                    taken.append(port)
    return taken


def check_domain(domain: int, what: str = "--domain") -> int:
    """``domain`` if it is a ROS domain id the default ports allow (DOMAIN_LIMITS), else
    DomainError naming ``what`` and the range."""
    lo, hi = DOMAIN_LIMITS
    if not lo <= domain <= hi:
        raise DomainError(f"{what} must be in [{lo}, {hi}], got {domain}")
    return domain


def choose_domain(requested: int | None = None, env: Mapping[str, str] | None = None) -> int:
    """The ROS domain of a run: ``requested`` (--domain), else ROS_DOMAIN_ID if set, else the
    first free one of RUN_DOMAIN_RANGE from one derived from the process id. An asked-for
    domain that another participant on this host uses is refused (DomainError)."""
    env = os.environ if env is None else env
    lo, hi = DOMAIN_LIMITS
    if requested is None and env.get("ROS_DOMAIN_ID", "").strip():
        what, text = "ROS_DOMAIN_ID", env["ROS_DOMAIN_ID"].strip()
        try:
            requested = int(text)
        except ValueError:
            raise DomainError(f"{what} must be an integer in [{lo}, {hi}], got {text!r}") from None
    else:
        what = "--domain"
    if requested is not None:
        check_domain(requested, what)
        taken = domain_in_use(requested)
        if taken:
            raise DomainError(
                f"{what} {requested}: the ROS domain is in use on this host (UDP port "
                f"{taken[0]} held by another participant); choose another domain"
            )
        return requested
    first = run_domain_id()
    lo, hi = RUN_DOMAIN_RANGE
    for k in range(hi - lo + 1):
        domain = lo + (first - lo + k) % (hi - lo + 1)
        if not domain_in_use(domain):
            return domain
    raise DomainError(f"every ROS domain in [{lo}, {hi}] is in use on this host; use --domain")


def run_domain_id(pid: int | None = None) -> int:
    """The first domain the automatic choice tries, derived from the process id."""
    lo, hi = RUN_DOMAIN_RANGE
    return lo + (os.getpid() if pid is None else pid) % (hi - lo + 1)


def node_env(
    domain_id: int,
    log_dir: Path,
    extra: Mapping[str, str] | None = None,
    profile: Path = FASTDDS_PROFILE,
) -> dict[str, str]:
    """os.environ plus isolation: own domain, the run's transports (``profile``, under the
    variable the installed Fast DDS reads: FASTDDS_PROFILE, shared memory and loopback UDP,
    or a run across hosts' from fence_sorter.runner.transport), rcl logs in ``log_dir``."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    # rmw_fastrtps's LOCALHOST range adds a UDP transport of its own, with sockets on every
    # interface (0.0.0.0 and the host's address in `ss -lnuap`); with the profile's transports
    # alone (SUBNET: the rmw adds none) discovery and data stay on this host all the same
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    set_profile(env, str(profile))
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
    cmd: list[str] = field(default_factory=list)

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
        """``cpus``: the CPUs every node process may run on once :meth:`confine` is called
        (None: as this process)."""
        self.env = dict(env)
        self.cpus = cpus
        self.confined = False  # the start-up may use every CPU (the loop runs after it)
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.nodes: dict[str, NodeProcess] = {}
        self.pgids: list[int] = []
        self.reaper: Reaper | None = None
        self.restarts: dict[str, int] = {}

    def start(self, name: str, cmd: Sequence[str]) -> NodeProcess:
        """Start node ``name``: own process group (setsid), SIGKILL when this process dies,
        watched by the reaper; SIGINT/SIGTERM held until it is registered (so a stop finds
        it)."""
        if self.reaper is None:
            self.reaper = Reaper(self.env)
        log_path = self.log_dir / f"{name}.log"
        log = open(log_path, "a", buffering=1)  # noqa: SIM115 (closed in stop)
        held = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
        try:
            proc = subprocess.Popen(
                list(cmd),
                env=self.env,
                start_new_session=True,
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                preexec_fn=_die_with_parent(os.getpid(), held),
            )
            node = NodeProcess(name, proc, log_path, log, list(cmd))
            self.nodes[name] = node
            self.pgids.append(proc.pid)
            self.reaper.watch(proc.pid)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)
        if self.confined:  # before the interpreter starts any thread (inherited)
            keep_on(proc.pid, self.cpus)
        return node

    def confine(self) -> None:
        """Keep every node process (each of its threads; not its children, which place
        themselves) on :attr:`cpus` from now on, and every node started later."""
        self.confined = True
        for node in self.nodes.values():
            if node.proc.poll() is None:
                keep_on(node.proc.pid, self.cpus)

    def restart(self, name: str) -> NodeProcess:
        """End whatever is left of node ``name``'s group and start it again (same command,
        log appended); counted in :attr:`restarts`."""
        old = self.nodes[name]
        self.stop_one(name)
        if old.log is not None and not old.log.closed:
            old.log.close()
        self.restarts[name] = self.restarts.get(name, 0) + 1
        return self.start(name, old.cmd)

    def dead(self) -> list[NodeProcess]:
        """Nodes that exited on their own."""
        return [n for n in self.nodes.values() if n.proc.poll() is not None]

    def stop_one(self, name: str, urgent: Callable[[], bool] = lambda: False) -> int | None:
        """Stop one node (and its group) with escalation; return its exit code. Returns early
        (None) once ``urgent()`` is true: the caller then stops everything at once."""
        node = self.nodes[name]
        for sig, timeout in STOP_SEQUENCE:
            if node.proc.poll() is None:
                _killpg(node.pgid, sig)
                if not wait_until(lambda: node.proc.poll() is not None or urgent(), timeout):
                    continue
                if urgent() and node.proc.poll() is None:
                    return None
            # the leader is gone; end whatever is left of its group
            if not leftovers([node.pgid]):
                break
            _killpg(node.pgid, signal.SIGKILL)
        return node.proc.returncode

    def stop(
        self, order: Sequence[str] | None = None, urgent: Callable[[], bool] = lambda: False
    ) -> dict[str, int | None]:
        """Stop every node (``order`` first, then the rest), one after the other so the later
        ones (the recorder) see the earlier ones' last messages; once ``urgent()`` is true
        (another Ctrl-C), :meth:`kill` the rest at once. Return exit codes by name."""
        names = list(order or []) + [n for n in self.nodes if n not in (order or [])]
        for n in names:
            if n not in self.nodes:
                continue
            if urgent():
                break
            self.stop_one(n, urgent)
        return self.kill()

    def kill(self, budget: float = INTERRUPT_BUDGET) -> dict[str, int | None]:
        """End every node still running at once within ``budget`` s: SIGINT, then SIGTERM,
        then SIGKILL of the real-time processes and of every group; reap; say done to the
        reaper. Return exit codes by name."""
        start = time.monotonic()
        for sig, at in ((signal.SIGINT, 0.0), (signal.SIGTERM, 0.5), (signal.SIGKILL, 0.75)):
            live = [n for n in self.nodes.values() if n.proc.poll() is None or leftovers([n.pgid])]
            if not live:
                break
            time.sleep(max(0.0, start + at * budget - time.monotonic()))
            pgids = [n.pgid for n in live]
            if sig == signal.SIGKILL:
                kill_groups(pgids)
            else:
                for pgid in realtime_first(pgids):
                    _killpg(pgid, sig)
            wait_until(
                partial(_all_ended, live),
                max(0.0, budget * (0.5 if sig == signal.SIGINT else 0.25)),
            )
        kill_groups(self.pgids)  # nothing may be left, whatever a group still holds
        for node in self.nodes.values():
            try:
                node.proc.wait(timeout=budget)
            except subprocess.TimeoutExpired:
                pass
            if node.log is not None and not node.log.closed:
                node.log.close()
        if self.reaper is not None and not leftovers(self.pgids):
            self.reaper.done()
        return {name: node.proc.returncode for name, node in self.nodes.items()}


class Reaper:
    """A watchdog process (own process group, no signals from the terminal) that SIGKILLs every
    process group it was told about when this process ends without calling :meth:`done`:
    the nodes' children (the pacing worker, the Rerun child) do not die with the runner by
    PR_SET_PDEATHSIG, their group does."""

    def __init__(self, env: Mapping[str, str]):
        read, self._write = os.pipe()
        os.set_inheritable(read, True)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fence_sorter.runner.reaper", str(read)],
            env=dict(env),
            start_new_session=True,
            pass_fds=(read,),
            stdin=subprocess.DEVNULL,
        )
        os.close(read)

    def watch(self, pgid: int) -> None:
        os.write(self._write, f"{pgid}\n".encode())

    def done(self) -> None:
        """Every group has ended: the reaper exits without killing anything."""
        if self._write < 0:
            return
        try:
            os.write(self._write, b"done\n")
        finally:
            os.close(self._write)
            self._write = -1
        try:
            self.proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def _die_with_parent(parent: int, mask: set[int]) -> Callable[[], None]:
    """preexec_fn of a node: SIGKILL when ``parent`` dies (also if it died before this ran),
    and the signal mask of before the start (the stop signals are held during it)."""

    def setup() -> None:
        _LIBC.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)

    return setup


def realtime(pid: int) -> bool:
    """Whether ``pid`` runs under a real-time policy (SCHED_FIFO or SCHED_RR)."""
    try:
        return os.sched_getscheduler(pid) in (os.SCHED_FIFO, os.SCHED_RR)
    except OSError:
        return False


def realtime_first(pgids: Sequence[int]) -> list[int]:
    """``pgids`` with the groups holding a real-time process first (they can starve the rest
    of the machine of CPU while the others stop)."""
    rt = {_pgid_of(pid) for pid in leftovers(pgids) if realtime(pid)}
    return sorted(pgids, key=lambda g: g not in rt)


def kill_groups(pgids: Sequence[int]) -> None:
    """SIGKILL every process of ``pgids``: the real-time ones first, then each group."""
    for pid in leftovers(pgids):
        if realtime(pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
    for pgid in pgids:
        _killpg(pgid, signal.SIGKILL)


def _all_ended(nodes: Sequence[NodeProcess]) -> bool:
    return all(n.proc.poll() is not None for n in nodes) and not leftovers([n.pgid for n in nodes])


def _pgid_of(pid: int) -> int:
    try:
        return os.getpgid(pid)
    except OSError:
        return -1


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


def tagged(key: str, value: str) -> list[int]:
    """Pids of live processes whose environment has ``key=value``: every process a run
    started inherits the runner's environment, whatever process group it moved to, so a
    tag set for one run finds all of them (the leftover count of a fault campaign)."""
    wanted = f"{key}={value}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if wanted in (entry / "environ").read_bytes().split(b"\0"):
                state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
                if state != "Z":
                    found.append(int(entry.name))
        except (OSError, IndexError):
            continue
    return found


#: where Fast DDS keeps its shared-memory ports and segments (Linux)
SHM_DIR = Path("/dev/shm")
#: Fast DDS's shared-memory files: ports, segments, their lock files, the ports' semaphores
_SHM_FILE = re.compile(r"^(sem\.)?(fastdds|fastrtps)_(port\d{1,5}|[0-9a-z]{16})(_el|_sl|_mutex)?$")
#: a file this young may belong to a participant that is still creating it [s]
SHM_GRACE = 5.0


def clean_shm(directory: Path = SHM_DIR) -> list[str]:
    """Remove the shared-memory files of Fast DDS that no live process uses (a participant
    killed with SIGKILL cannot remove its own): a file that no process maps or holds open and
    that nobody holds a lock on (a lock file ``<name>_el``/``_sl`` is flock-ed while its
    owner lives, as ``fastdds shm clean`` tests it); files younger than SHM_GRACE stay.
    Where the processes cannot be read, only a free lock file tells, and it takes its port
    or segment and the port's semaphore with it. Returns the names removed."""
    try:
        names = sorted(n for n in os.listdir(directory) if _SHM_FILE.match(n))
    except OSError:
        return []
    in_use = _files_in_use(directory)
    removed = []
    for name in names:
        path = directory / name
        is_lock = name.endswith(("_el", "_sl"))
        if (in_use is None and not is_lock) or (in_use is not None and str(path) in in_use):
            continue
        try:
            if time.time() - path.stat().st_mtime < SHM_GRACE:
                continue
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # a live owner holds its lock
        except OSError:
            continue
        finally:
            os.close(fd)
        victims = [name]
        if is_lock and in_use is None:
            victims = [name[:-3], name, f"sem.{name[:-3]}_mutex"]
        for victim in victims:
            try:
                (directory / victim).unlink()
                removed.append(victim)
            except FileNotFoundError:
                pass
    return removed


def _files_in_use(directory: Path) -> set[str] | None:
    """Paths under ``directory`` that a live process maps or holds open (/proc); None if
    /proc cannot be read at all."""
    prefix = str(directory) + "/"
    found: set[str] = set()
    try:
        entries = list(Path("/proc").iterdir())
    except OSError:
        return None
    for entry in entries:
        if not entry.name.isdigit():
            continue
        try:
            for line in (entry / "maps").read_text().splitlines():
                at = line.find(prefix)
                if at >= 0:
                    found.add(line[at:].removesuffix(" (deleted)"))
            for fd in (entry / "fd").iterdir():
                try:
                    target = os.readlink(fd)
                except OSError:
                    continue
                if target.startswith(prefix):
                    found.add(target)
        except (FileNotFoundError, ProcessLookupError):
            continue  # the process ended meanwhile
        except PermissionError:
            # another user's process: it cannot open this user's files read-write as Fast
            # DDS does (they are 0644), so it uses none of the files this user may remove
            continue
    return found
