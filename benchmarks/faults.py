"""The fault-injection campaign of the node suite: the faults of issue 16, injected again and
counted, written to docs/reports/reliability.md (``python -m benchmarks faults``).

Cases:

- **interrupts**: ``fence-sorter run --parcels 20`` started with setsid (as from a terminal);
  the first SIGINT to its process group at a random moment in [0, 30] s, then 1-4 more at
  random gaps of 0-0.5 s (2-5 in all). Every process the run started is tracked (its
  descendants, polled every 0.1 s); figures: exit status, seconds from the first signal to
  the exit, processes still alive 1 s after the exit, tracebacks.
- **floods**: during ``fence-sorter run --parcels 20 --json``, another process publishes
  5000 messages/s for 2 s on /parcels (another run's plausible parcels with the run's own
  ids) or /fence_commands (forged ``feasible: false`` for them); figures: messages sent,
  taken, refused and lost per node, divert parcels without an outcome, deadline misses.
- **wire**: malformed and hostile parcels and commands published one by one to a controller
  and a simulator of one run; each must be refused and counted under its reason while both
  nodes run on.
- **bad input**: files, scenes, streams and parameters given to the command line; each must
  exit with its status and one line, no traceback.
- **insiders**: forged duplicates, a flood and a second /clock with the run's own id
  (:mod:`benchmarks.insiders`).
- **freezes**: a run whose pacing loop or controller is stopped (SIGSTOP) for 3 s, and one
  recording into a full file system (a small tmpfs); the stop must show in the figures, the
  full disk be reported when it happens (exit status 5).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

from benchmarks import insiders
from benchmarks.runs import finish, last_json
from fence_sorter.resources import data_path
from fence_sorter.runner.monitor import Monitor
from fence_sorter.runner.processes import (
    ProcessGroup,
    leftovers,
    node_command,
    node_env,
    run_domain_id,
)
from fence_sorter.verification.machine import git_revision, machine_info

#: the run id of the wire case's nodes
WIRE_RUN = 4242
#: a run id no run of the suite draws in practice: the flooding "other run"
FOREIGN_RUN = 999


# -- processes -------------------------------------------------------------------------------
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


# -- interrupts ------------------------------------------------------------------------------
@dataclass
class InterruptTrial:
    first_signal_s: float
    signals: int
    exit_code: int | None
    exit_after_s: float  # from the first signal
    leftovers: int
    traceback: bool
    leftover_names: str = ""


def _names(pids: list[int]) -> str:
    """The leftovers' executables, e.g. "simulator, python (2)"."""
    names = Counter()
    for pid in pids:
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        words = [Path(a.decode(errors="replace")).name for a in argv if a]
        mod = next((w for w in words if w.startswith("fence_sorter.")), None)
        names[
            mod
            or (
                words[1]
                if len(words) > 1 and words[0].startswith("python")
                else words[0]
                if words
                else "?"
            )
        ] += 1
    return ", ".join(f"{n}" + (f" ({c})" if c > 1 else "") for n, c in sorted(names.items()))


def interrupt_trial(rng: random.Random, workdir: Path, parcels: int = 20) -> InterruptTrial:
    """One run interrupted by 2-5 SIGINTs (see the module docstring)."""
    log = workdir / f"interrupt-{time.time_ns()}.log"
    with open(log, "w") as out:
        proc = subprocess.Popen(
            fence_sorter_cmd("run", "--parcels", str(parcels)),
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            cwd=workdir,
        )
    watch = ProcessWatch(proc.pid)
    watch.start()
    first = rng.uniform(0.0, 30.0)
    n = rng.randint(2, 5)
    t0 = time.monotonic()
    while time.monotonic() - t0 < first and proc.poll() is None:
        time.sleep(0.01)
    t_sig = time.monotonic()
    sent = 0
    for i in range(n):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, signal.SIGINT)
            sent += 1
        except ProcessLookupError:
            break
        if i < n - 1:
            time.sleep(rng.uniform(0.0, 0.5))
    try:
        proc.wait(timeout=60.0)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    exit_after = time.monotonic() - t_sig
    time.sleep(1.0)
    watch.poll()
    watch.done.set()
    left = watch.alive()
    names = _names(left)
    watch.kill_alive()
    text = log.read_text(errors="replace")
    return InterruptTrial(
        round(first, 2), sent, proc.returncode, exit_after, len(left), "Traceback" in text, names
    )


# -- floods ----------------------------------------------------------------------------------
def flood_main(argv: list[str]) -> int:
    """``python -m benchmarks.faults flood TOPIC --domain N [--rate R]
    [--seconds S]``: publish another run's messages at R per second for S s; print the count
    sent as JSON."""
    ap = argparse.ArgumentParser(prog="faults flood")
    ap.add_argument("topic", choices=("/parcels", "/fence_commands"))
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--rate", type=float, default=5000.0)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--first-id", type=int, default=1)
    ap.add_argument("--ids", type=int, default=20, help="ids cycle over first-id + [0, ids)")
    a = ap.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy  # lazy: rclpy (0.25 s), only where ROS runs
    from rclpy.signals import SignalHandlerOptions

    from fence_sorter.nodes.qos import INPUT_QOS  # lazy: loads rclpy
    from fence_sorter_msgs.msg import FenceCommand, Parcel

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=a.domain, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("fence_sorter_flood", context=ctx)
    kind = Parcel if a.topic == "/parcels" else FenceCommand
    pub = node.create_publisher(kind, a.topic, INPUT_QOS)
    end = time.monotonic() + 10.0
    while pub.get_subscription_count() < 2 and time.monotonic() < end:
        time.sleep(0.05)
    subscribers = pub.get_subscription_count()
    n = int(round(a.rate * a.seconds))
    sent = failed = 0
    error = ""
    t0 = time.monotonic()
    for i in range(n):
        due = t0 + i / a.rate
        delay = due - time.monotonic()
        if delay > 0.001:
            time.sleep(delay)
        pid = a.first_id + i % a.ids
        if kind is Parcel:
            msg = parcel_msg(pid, run_id=FOREIGN_RUN, scan_position_x=-3.0)
        else:
            msg = command_msg(pid, FOREIGN_RUN, feasible=False, reason="forged by a flood")
        try:
            pub.publish(msg)
            sent += 1
        except Exception as exc:  # the middleware refused it (a keep-all reader's back-pressure)
            failed += 1
            error = f"{type(exc).__name__}: {exc}"
    wall = time.monotonic() - t0
    # every subscriber has it before the participant goes (its writer's history goes with it)
    from rclpy.duration import Duration  # lazy: rclpy (0.25 s), only where ROS runs

    acked = pub.wait_for_all_acked(Duration(seconds=30))
    print(
        json.dumps(
            {
                "sent": sent,
                "publish_failed": failed,
                "all_acked": acked,
                "error": error[:200],
                "wall_s": wall,
                "subscribers": subscribers,
            }
        )
    )
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
    return 0


def parcel_msg(pid: int, run_id: int = 0, scan_time: float = 0.0, **fields):
    """A plausible Parcel (0.3 x 0.2 m, 3 kg, to divert) with ``fields`` changed."""
    from fence_sorter.nodes.convert import sec_to_time  # lazy: loads ROS messages
    from fence_sorter_msgs.msg import Parcel

    msg = Parcel()
    msg.header.frame_id = "sorter"
    msg.parcel_id, msg.run_id = pid, run_id
    msg.length_a, msg.width_b, msg.height, msg.mass = 0.3, 0.2, 0.2, 3.0
    msg.lateral_gap, msg.yaw = 0.1, 0.0
    msg.mu_belt = msg.mu_fence = math.nan
    msg.divert = True
    msg.scan_time = sec_to_time(scan_time)
    msg.header.stamp = msg.scan_time
    msg.scan_position_x = -3.0
    for k, v in fields.items():
        setattr(msg, k, v)
    return msg


def command_msg(pid: int, run_id: int, **fields):
    """A FenceCommand (R_s 0.4 m, t1 0.35 s, alpha_k 40 deg, feasible) with ``fields``."""
    from fence_sorter_msgs.msg import FenceCommand  # lazy: ROS messages, only where ROS runs

    msg = FenceCommand()
    msg.header.frame_id = "sorter"
    msg.parcel_id, msg.run_id = pid, run_id
    msg.r_s, msg.t1, msg.alpha_k, msg.feasible = 0.4, 0.35, math.radians(40.0), True
    for k, v in fields.items():
        setattr(msg, k, v)
    return msg


@dataclass
class FloodTrial:
    topic: str
    sent: int
    publish_failed: int
    exit_code: int | None
    summary: dict = field(default_factory=dict)
    leftovers: int = 0
    traceback: bool = False


def flood_trial(topic: str, workdir: Path, rate: float, seconds: float) -> FloodTrial:
    """A 20-parcel run with a flood on ``topic`` 3 s after its nodes are up."""
    err_path = workdir / f"flood-{topic.strip('/')}.log"
    err = open(err_path, "w+")  # noqa: SIM115 (read while the run writes it)
    proc = subprocess.Popen(
        fence_sorter_cmd("run", "--parcels", "20", "--json"),
        stdout=subprocess.PIPE,
        stderr=err,
        text=True,
        start_new_session=True,
        cwd=workdir,
    )
    watch = ProcessWatch(proc.pid)
    watch.start()
    domain = None
    end = time.monotonic() + 300.0
    while time.monotonic() < end and proc.poll() is None:
        text = err_path.read_text(errors="replace")
        m = re.search(r"ROS domain (\d+)", text)
        domain = int(m.group(1)) if m else None
        if domain is not None and "running" in text:
            break
        time.sleep(0.2)
    sent = failed = 0
    if domain is not None and proc.poll() is None:
        time.sleep(3.0)
        flood = subprocess.run(
            [
                sys.executable,
                "-m",
                "benchmarks.faults",
                "flood",
                topic,
                "--domain",
                str(domain),
                "--rate",
                str(rate),
                "--seconds",
                str(seconds),
            ],
            capture_output=True,
            text=True,
            timeout=300.0,
        )
        try:
            report = json.loads(flood.stdout.strip().splitlines()[-1])
            sent, failed = report["sent"], report["publish_failed"]
        except (IndexError, ValueError, KeyError):
            sent = -1
            (workdir / "flood-error.log").write_text(flood.stdout + flood.stderr)
    out = finish(proc)
    time.sleep(1.0)
    watch.poll()
    watch.done.set()
    left = watch.alive()
    watch.kill_alive()
    err.close()
    summary = last_json(out)
    text = err_path.read_text(errors="replace") + out
    return FloodTrial(
        topic, sent, failed, proc.returncode, summary, len(left), "Traceback" in text
    )


# -- freezes and a full disk -------------------------------------------------------------------
#: the freeze cases: what is stopped (SIGSTOP, then SIGCONT) or filled up
FREEZES = ("pacing loop", "controller", "disk full")
#: the scan spacing of a freeze run's parcels [s]: the first parcel scanned during a stop of
#: stop_s waits at least stop_s - FREEZE_SPACING for the stopped controller
FREEZE_SPACING = 1.5
#: size of the file system a disk-full run records into (the bag of 12 parcels needs ~1 MB)
FULL_DISK = "256k"
#: what a freeze row keeps of the simulator's and the controller's figures
FREEZE_SIM_KEYS = ("cycles", "deadline_misses", "catch_up_slips", "cycle_lateness_max_ms")
FREEZE_CONTROLLER_KEYS = (
    "latency_p99_ms",
    "latency_max_ms",
    "latency_from_send_p99_ms",
    "latency_from_send_max_ms",
    "late_no_command",
)


def _descendant(watch: ProcessWatch, match) -> int | None:
    """The first process seen under ``watch`` whose (comm, cmdline) ``match`` accepts."""
    watch.poll()
    for pid, _ in sorted(watch.seen):
        try:
            comm = Path(f"/proc/{pid}/comm").read_text().strip()
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if match(comm, cmd):
            return pid
    return None


def freeze_trial(case: str, workdir: Path, stop_s: float = 3.0, parcels: int = 12) -> dict:
    """``fence-sorter run`` of ``parcels`` parcels 1.5 s apart with the pacing loop or the
    controller stopped (SIGSTOP) for ``stop_s`` 4 s after the run's nodes are up, or (``disk
    full``) recording into a tmpfs of FULL_DISK mounted for it (root only; else not run, with
    the reason)."""
    d = Path(tempfile.mkdtemp(prefix="freeze-", dir=workdir))
    # a parcel every FREEZE_SPACING (every other one to divert): a 3 s stop has parcels in it
    stream = workdir / f"{d.name}.csv"
    rows = ["parcel_id,arrival_time,length_a,width_b,height,mass,lateral_gap,divert"]
    rows += [
        f"{i},{FREEZE_SPACING * (i - 1):.2f},0.30,0.25,0.2,4.0,0.1,{str(i % 2 == 1).lower()}"
        for i in range(1, parcels + 1)
    ]
    stream.write_text("\n".join(rows) + "\n")
    argv = ["run", "--stream", str(stream), "--json"]
    row: dict = {"case": case, "stop_s": stop_s if case != "disk full" else 0.0}
    if case == "disk full":
        mount = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={FULL_DISK}", "tmpfs", str(d)],
            capture_output=True,
            text=True,
        )
        if mount.returncode != 0:
            return {**row, "not_run": mount.stderr.strip() or "mount failed"}
        argv += ["--bag", str(d / "bag")]
    err_path = workdir / f"freeze-{time.time_ns()}.log"
    try:
        with open(err_path, "w") as err:
            proc = subprocess.Popen(
                fence_sorter_cmd(*argv),
                stdout=subprocess.PIPE,
                stderr=err,
                text=True,
                start_new_session=True,
                cwd=workdir,
            )
            watch = ProcessWatch(proc.pid)
            watch.start()
            end = time.monotonic() + 300.0
            while time.monotonic() < end and proc.poll() is None:
                if "; running" in err_path.read_text(errors="replace"):
                    break
                time.sleep(0.2)
            if case != "disk full" and proc.poll() is None:
                time.sleep(4.0)
                pid = _descendant(
                    watch,
                    (lambda comm, cmd: comm == "fs-line-worker")
                    if case == "pacing loop"
                    else (lambda comm, cmd: "fence_sorter.nodes.controller" in cmd),
                )
                row["stopped_pid_found"] = pid is not None
                if pid is not None:
                    os.kill(pid, signal.SIGSTOP)
                    time.sleep(stop_s)
                    os.kill(pid, signal.SIGCONT)
            try:
                out, _ = proc.communicate(timeout=600.0)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                out, _ = proc.communicate()
            time.sleep(1.0)
            watch.poll()
            watch.done.set()
            left = watch.alive()
            watch.kill_alive()
        if case == "disk full":  # what the full disk holds, kept for a reader
            shutil.copytree(d / "bag", workdir / f"{d.name}-bag", dirs_exist_ok=True)
            row["bag_copy"] = str(workdir / f"{d.name}-bag")
    finally:
        if case == "disk full":
            subprocess.run(["umount", "-l", str(d)], capture_output=True)
    summary = next((json.loads(x) for x in reversed(out.splitlines()) if x.startswith("{")), {})
    text = err_path.read_text(errors="replace")
    sim, ctrl = summary.get("simulator", {}), summary.get("controller", {})
    told = re.search(r"recorder: writing the bag failed at sim time .*", text)
    return {
        **row,
        "exit_code": proc.returncode,
        "leftovers": len(left),
        "traceback": "Traceback" in text + out,
        "divert": summary.get("divert"),
        "sorted_divert": summary.get("sorted_divert"),
        "divert_without_outcome": summary.get("divert_without_outcome"),
        "by_reason": summary.get("by_reason"),
        "missed_examples": summary.get("missed_examples"),
        "dropped": summary.get("dropped"),
        "recording_failed": summary.get("recording_failed"),
        "recording_told": told.group(0) if told else "",
        "simulator": {k: sim.get(k) for k in FREEZE_SIM_KEYS},
        "controller": {k: ctrl.get(k) for k in FREEZE_CONTROLLER_KEYS},
    }


def freeze_met(row: dict) -> bool:
    """A freeze row's target: the stop or the full disk shows in the figures, the run names
    it and leaves nothing behind; every divert parcel has its outcome (a stopped loop only
    delays the line; parcels a stopped controller cannot plan in time are NO_COMMAND)."""
    if "not_run" in row:
        return False
    ok = row["leftovers"] == 0 and not row["traceback"] and not row["divert_without_outcome"]
    if row["case"] == "pacing loop":
        misses = float(row["simulator"].get("deadline_misses") or 0)
        return ok and misses >= 0.9 * row["stop_s"] * 1000.0 and row["exit_code"] == 0
    if row["case"] == "controller":
        c = row["controller"]
        waited = 1e3 * (row["stop_s"] - FREEZE_SPACING)
        seen = float(c.get("latency_from_send_max_ms") or 0) >= waited
        late = int(c.get("late_no_command") or 0)
        return ok and row["exit_code"] in (0, 3) and (seen or late > 0)
    return ok and row["exit_code"] == 5 and bool(row["recording_failed"] and row["recording_told"])


# -- the wire ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class WireCase:
    """One message to a controller and a simulator of run WIRE_RUN and where it must be
    counted: ``node`` and the diagnostics key that must rise by one."""

    name: str
    topic: str  # "parcels" | "commands"
    fields: dict
    counters: tuple[tuple[str, str], ...]  # (node, key)
    target: int = 0  # commands: the parcel they are for (published first, valid)


def wire_cases() -> list[WireCase]:
    nan, inf = math.nan, math.inf
    both = (("controller", "rejected_parcels.{}"), ("simulator", "bad_parcels.{}"))

    def p(name, key, **f):
        return WireCase(name, "parcels", f, tuple((n, k.format(key)) for n, k in both))

    def c(name, key, target, **f):
        return WireCase(name, "commands", f, (("simulator", f"commands_rejected.{key}"),), target)

    return [
        p("mass NaN", "non_finite", mass=nan),
        p("mass -1 kg", "mass", mass=-1.0),
        p("mass 1e6 kg", "mass", mass=1e6),
        p("length_a 0", "size", length_a=0.0),
        p("length_a 10 m", "size", length_a=10.0),
        p("height NaN", "non_finite", height=nan),
        p("cog_offset_x 1 m", "cog_offset", cog_offset_x=1.0),
        p("yaw 3 rad", "yaw", yaw=3.0),
        p("mu_belt 5", "friction", mu_belt=5.0),
        p("mu_fence 5", "friction", mu_fence=5.0),
        p("mu_fence -1", "friction", mu_fence=-1.0),
        p("mu_belt inf", "non_finite", mu_belt=inf),
        p("lateral_gap -0.1 m", "lateral_gap", lateral_gap=-0.1),
        p("wider than the belt", "wider_than_belt", width_b=0.65),
        p("scan_time 1e5 s ahead", "scan_time", scan_time_offset=1e5),
        p("scan_time 11 s behind", "scan_time", scan_time_offset=-11.0),
        p("scan_position_x 1e9 m", "scan_position", scan_position_x=1e9),
        p("scan_position_x 1 m (off the scan line)", "scan_position", scan_position_x=1.0),
        p("scan_position_x NaN", "non_finite", scan_position_x=nan),
        WireCase(
            "another run's parcel",
            "parcels",
            {"run_id": FOREIGN_RUN},
            (("controller", "parcels.foreign"), ("simulator", "parcels.foreign")),
        ),
        c("t1 10 s (a 20 s stroke)", "outside_window", 301, t1=10.0),
        c("t1 20 s", "invalid", 302, t1=20.0),
        c("t1 NaN", "invalid", 303, t1=nan),
        c("alpha_k 0", "invalid", 304, alpha_k=0.0),
        c("R_s 9 m", "invalid", 305, r_s=9.0),
        c("start_mode 7", "invalid", 306, start_mode=7),
        c("start_time 1e5 s ahead (AT_TIME)", "invalid", 307, start_mode=1, start_offset=1e5),
        c("unknown parcel_id", "unknown_parcel", 0, parcel_id=999_999),
        c("a second command for a parcel", "duplicate", 308, repeat=True),
        WireCase(
            "another run's feasible:false for a real parcel",
            "commands",
            {"run_id": FOREIGN_RUN, "feasible": False, "reason": "forged"},
            (("simulator", "commands.foreign"),),
            309,
        ),
    ]


@dataclass
class WireResult:
    case: WireCase
    counted: dict[str, int]  # "node key" -> rise
    ok: bool


def run_wire(workdir: Path, domain: int, progress=print) -> tuple[list[WireResult], dict]:
    """Start a controller and a simulator of run WIRE_RUN and send each wire case."""
    from fence_sorter.nodes.convert import sec_to_time  # lazy: loads ROS messages
    from fence_sorter.nodes.qos import INPUT_QOS
    from fence_sorter_msgs.msg import FenceCommand, Parcel

    env = node_env(domain, workdir / "wire-ros")
    group = ProcessGroup(env, workdir / "wire-logs")
    monitor = Monitor(domain, name="fence_sorter_faults", run_id=WIRE_RUN)
    rec = monitor.records

    def args(node: str, *extra: str) -> list[str]:
        out = ["--params-file", str(data_path("config", f"{node}.yaml"))]
        for o in ("heartbeat_period:=0.2", f"run_id:={WIRE_RUN}", *extra):
            out += ["-p", o]
        return out

    def wait(pred, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            monitor.spin_for(0.05)
            if pred():
                return True
        return False

    def beat(node: str) -> dict:
        return rec.diagnostics.get(f"fence_sorter/{node}", {})

    results: list[WireResult] = []
    extra: dict = {}
    try:
        # the controller listens only to the scan line itself: the command cases' parcels
        # (scanned 0.3 m upstream of it) are the simulator's alone, so no real command races
        # the hostile ones
        group.start(
            "controller",
            node_command(
                "controller",
                args(
                    "controller",
                    "use_sim_time:=true",
                    "warmup_parcels:=0",
                    "scan_line_tolerance:=0.1",
                ),
            ),
        )
        group.start("simulator", node_command("simulator", args("simulator")))
        up = wait(lambda: beat("controller").get("listening") == "true" and beat("simulator"), 180)
        if not up:
            raise RuntimeError("controller and simulator did not come up within 180 s")
        ppub = monitor.node.create_publisher(Parcel, "/parcels", INPUT_QOS)
        cpub = monitor.node.create_publisher(FenceCommand, "/fence_commands", INPUT_QOS)
        wait(lambda: ppub.get_subscription_count() >= 3 and cpub.get_subscription_count() >= 2, 30)
        wait(lambda: rec.sim_time > 12.0, 60)  # a scan time 11 s back is still >= 0
        next_id = 201
        for case in wire_cases():
            before = {f"{n} {k}": int(beat(n).get(k, "0")) for n, k in case.counters}
            now = rec.sim_time
            f = dict(case.fields)
            if case.topic == "parcels":
                offset = f.pop("scan_time_offset", 0.0)
                run_id = f.pop("run_id", WIRE_RUN)
                ppub.publish(parcel_msg(next_id, run_id, now + offset, **f))
                next_id += 1
            else:
                repeat = f.pop("repeat", False)
                start_offset = f.pop("start_offset", None)
                if case.target:
                    target = parcel_msg(case.target, WIRE_RUN, now, scan_position_x=-3.3)
                    ppub.publish(target)
                    monitor.spin_for(0.3)
                if start_offset is not None:
                    f["start_time"] = sec_to_time(now + start_offset)
                pid = f.pop("parcel_id", case.target)
                run_id = f.pop("run_id", WIRE_RUN)
                if repeat:
                    cpub.publish(command_msg(pid, WIRE_RUN))
                cpub.publish(command_msg(pid, run_id, **f))

            def risen(counters=case.counters, before=before) -> bool:
                return all(int(beat(n).get(k, "0")) >= before[f"{n} {k}"] + 1 for n, k in counters)

            ok = wait(risen, 10.0)
            counted = {
                key: int(beat(key.split()[0]).get(key.split()[1], "0")) - v
                for key, v in before.items()
            }
            alive = all(n.proc.poll() is None for n in group.nodes.values())
            results.append(WireResult(case, counted, ok and alive))
            progress(f"wire  {case.name:45s} {'refused, counted' if ok else 'NOT COUNTED'}")
        extra["controller"] = dict(beat("controller"))
        extra["simulator"] = dict(beat("simulator"))
        extra["alive"] = all(n.proc.poll() is None for n in group.nodes.values())
    finally:
        codes = group.stop(("controller", "simulator"))
        extra["exit_codes"] = codes
        extra["leftovers"] = len(leftovers(group.pgids))
        monitor.close()
    return results, extra


# -- bad input at the command line -----------------------------------------------------------
@dataclass(frozen=True)
class CliCase:
    category: str  # files | scenes | streams | parameters
    name: str
    argv: tuple[str, ...]  # {dir} is the case's scratch directory
    files: dict = field(default_factory=dict)  # name -> bytes
    expected: int = 2


def _nested(depth: int) -> bytes:
    return ("[" * depth + "]" * depth).encode()


def cli_cases() -> list[CliCase]:
    scene_ok = data_path("config", "scenes", "impact_flexible.yaml").read_bytes()
    run = ("run", "--parcels", "1", "--rtf", "0", "--timeout", "120")
    csv_head = b"parcel_id,arrival_time,length_a,width_b,height,mass,divert\n"

    def scene(name: str, data: bytes) -> CliCase:
        return CliCase("scenes", name, (*run, "--scene", "{dir}/s.yaml"), {"s.yaml": data})

    def stream(name: str, data: bytes, ext: str = "csv") -> CliCase:
        return CliCase("streams", name, (*run, "--stream", f"{{dir}}/m.{ext}"), {f"m.{ext}": data})

    def param(name: str, *argv: str) -> CliCase:
        return CliCase("parameters", name, (*run, *argv))

    junk = bytes(random.Random(7).getrandbits(8) for _ in range(4096))
    return [
        scene("non-UTF-8 scene", b"\xff\xfe\x00conveyor: {belt_speed: 1}\n"),
        scene("deeply nested scene", _nested(5000)),
        scene("empty scene", b""),
        scene("scene is a list", b"- 1\n- 2\n"),
        scene("unknown key", scene_ok + b"\nbogus_key: 1\n"),
        scene("negative belt speed", scene_ok.replace(b"belt_speed: 1.0", b"belt_speed: -1.0")),
        scene("random bytes", junk),
        CliCase("scenes", "missing scene file", (*run, "--scene", "{dir}/none.yaml")),
        stream("mass not a number", csv_head + b"1,0,0.4,0.3,0.2,x,true\n"),
        stream("negative mass", csv_head + b"1,0,0.4,0.3,0.2,-5,true\n"),
        stream("duplicate parcel id", csv_head + b"1,0,0.4,0.3,0.2,5,true\n1,2,0.4,0.3,0.2,5,y\n"),
        stream("unknown column", b"parcel_id,colour\n1,red\n"),
        stream("missing column", b"parcel_id,arrival_time\n1,0\n"),
        stream("empty manifest", b""),
        stream("non-UTF-8 manifest", b"\xff\xfe" + csv_head),
        stream("wider than the belt", csv_head + b"1,0,0.4,0.9,0.2,5,true\n"),
        stream(
            "mu_fence 5",
            csv_head.replace(b",divert", b",mu_fence,divert") + b"1,0,0.4,0.3,0.2,5,5,1\n",
        ),
        stream("rate 0 in a stream config", b"stream:\n  rate_pcs_h: 0\n  parcel: {}\n", "yaml"),
        stream("deeply nested stream config", _nested(5000), "yaml"),
        stream("unknown distribution", b"stream:\n  parcel:\n    mass: {dist: zipf}\n", "yaml"),
        param("--param without NODE:", "--param", "a_ndop=150"),
        param("--param unknown node", "--param", "planner:a_ndop=150"),
        param("--param unknown key", "--param", "controller:no_such_key=1"),
        param("--param out of range", "--param", "controller:a_ndop=-5"),
        param("--param wrong type", "--param", "simulator:real_time_factor=fast"),
        param("--param loop_cpu 99", "--param", "simulator:loop_cpu=99"),
        param("--rtf -1", "--rtf", "-1"),
        CliCase("parameters", "--parcels 0", ("run", "--parcels", "0")),
        CliCase("parameters", "--duration -5", ("run", "--duration", "-5")),
        CliCase("parameters", "--seed -1", ("run", "--parcels", "1", "--seed", "-1")),
        CliCase("parameters", "--rrd into a missing directory", (*run, "--rrd", "{dir}/no/x.rrd")),
        CliCase("files", "analyze: zero-byte .mcap", ("analyze", "{dir}/b"), {"b/b_0.mcap": b""}),
        CliCase("files", "analyze: random bytes", ("analyze", "{dir}/b"), {"b/b_0.mcap": junk}),
        CliCase(
            "files",
            "analyze: bad magic",
            ("analyze", "{dir}/b"),
            {"b/b_0.mcap": b"\x89XCAP0\r\n" + junk},
        ),
        CliCase("files", "analyze: missing bag", ("analyze", "{dir}/nothing")),
        CliCase(
            "files",
            "rrd: random bytes",
            ("rrd", "{dir}/b", "--out", "{dir}/o.rrd"),
            {"b/b_0.mcap": junk},
        ),
        CliCase(
            "files",
            "rrd: zero-byte .mcap",
            ("rrd", "{dir}/b", "--out", "{dir}/o.rrd"),
            {"b/b_0.mcap": b""},
        ),
    ]


@dataclass
class CliResult:
    case: CliCase
    code: int | None
    traceback: bool
    line: str  # the last line on stderr
    output_written: bool
    ok: bool


def run_cli_case(case: CliCase, workdir: Path) -> CliResult:
    d = Path(tempfile.mkdtemp(prefix="case-", dir=workdir))
    for name, data in case.files.items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_bytes(data)
    argv = [a.replace("{dir}", str(d)) for a in case.argv]
    try:
        proc = subprocess.run(
            fence_sorter_cmd(*argv), capture_output=True, text=True, timeout=300.0, cwd=d
        )
        code, out, err = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired as exc:
        code, out, err = None, str(exc.stdout or ""), str(exc.stderr or "")
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    written = (d / "o.rrd").exists()
    tb = "Traceback" in out + err
    ok = code == case.expected and not tb and bool(lines) and not written
    return CliResult(case, code, tb, lines[-1] if lines else "", written, ok)


# -- the report -------------------------------------------------------------------------------
def _pct(a: float, b: float) -> str:
    return f"{100.0 * a / b:.3f} %" if b else "n/a"


def _intake(summary: dict, node: str, topic: str) -> dict[str, int]:
    diag = summary.get(node, {})
    return {
        k: int(float(diag.get(f"{topic}.{k}", "0") or 0))
        for k in ("received", "accepted", "foreign", "rate_limited", "lost")
    }


#: what the report keeps of a flood run's summary
FLOOD_SUMMARY_KEYS = (
    "parcel_messages",
    "command_messages",
    "divert_without_outcome",
    "sorted_divert",
    "divert",
    "foreign_parcel_messages",
    "foreign_command_messages",
)


def flood_row(f: FloodTrial) -> dict:
    s = f.summary
    keep = {k: s.get(k) for k in FLOOD_SUMMARY_KEYS}
    for node in ("simulator", "controller"):
        diag = s.get(node, {})
        keep[node] = {
            k: v
            for k, v in diag.items()
            if k in ("cycles", "deadline_misses") or k.startswith(("parcels.", "commands."))
        }
    return {
        "topic": f.topic,
        "sent": f.sent,
        "publish_failed": f.publish_failed,
        "exit_code": f.exit_code,
        "leftovers": f.leftovers,
        "traceback": f.traceback,
        "summary": keep,
    }


def wire_row(r: WireResult) -> dict:
    return {"name": r.case.name, "topic": r.case.topic, "counted": r.counted, "ok": r.ok}


def cli_row(r: CliResult) -> dict:
    argv = r.case.argv
    return {
        "category": r.case.category,
        "name": r.case.name,
        "command": " ".join(argv[:1] + tuple(a for a in argv[1:] if "{dir}" not in a)),
        "code": r.code,
        "traceback": r.traceback,
        "line": r.line,
        "ok": r.ok,
    }


def _meta_lines(meta: dict) -> list[str]:
    return [
        f"Command `{meta['command']}` at commit {meta['commit']}, {meta['date']} "
        f"({meta['machine']}), {meta['wall_s']:.0f} s of wall time.",
        "",
    ]


def _interrupts_md(sec: dict) -> list[str]:
    rows = sec["rows"]
    within = sum(1 for t in rows if t["exit_after_s"] <= 5.0)
    L = [
        "## Repeated Ctrl-C",
        "",
        *_meta_lines(sec["meta"]),
        "`fence-sorter run --parcels 20` started with setsid (its own process group, as "
        "from a terminal); the first SIGINT to its process group at a random moment in "
        "[0, 30] s, then more at random gaps of 0-0.5 s "
        "(2-5 in all; fewer when the run was out before the next). Leftovers: processes the "
        "run started (its descendants, polled every 0.1 s) still alive 1 s after it exited. "
        "Exit status -2: the run ended by the signal's default action (a signal in the "
        "interpreter's start-up, before the run's handler exists). Target: 0 leftovers, every "
        "trial out within 5 s.",
        "",
        f"**{len(rows)} trials: {within} exited within 5 s, "
        f"{sum(t['leftovers'] for t in rows)} leftover processes in all, "
        f"{sum(t['traceback'] for t in rows)} with a traceback.**",
        "",
        "| trial | first signal [s] | signals | exit status | exit after [s] | leftovers "
        "| traceback |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for i, t in enumerate(rows, 1):
        names = f" ({t['leftover_names']})" if t["leftover_names"] else ""
        L.append(
            f"| {i} | {t['first_signal_s']:.2f} | {t['signals']} | {t['exit_code']} | "
            f"{t['exit_after_s']:.2f} | {t['leftovers']}{names} | "
            f"{'yes' if t['traceback'] else 'no'} |"
        )
    return [*L, ""]


def _floods_md(sec: dict) -> list[str]:
    L = [
        "## Floods",
        "",
        *_meta_lines(sec["meta"]),
        "During `fence-sorter run --parcels 20 --json`, 3 s after its nodes are up, another "
        "process publishes on the run's domain for 2 s at 5000 messages/s: another run's "
        "plausible parcels with the run's own ids (1-20) on /parcels, or forged "
        "`feasible: false` commands for them on /fence_commands. Received, taken, foreign, "
        "rate-limited, lost: each node's own counters (`<topic>.*` on /diagnostics; lost is "
        "the middleware's message-lost event). Refused at publish: the flooding publisher's "
        "calls the middleware refused. Targets: 0 real divert parcels without an outcome, "
        "every refused or dropped message counted, deadline misses < 0.5 %.",
        "",
        "| flood on | sent | refused at publish | node | received | taken | foreign "
        "(refused) | rate-limited | lost | not counted | divert parcels without outcome "
        "| sorted / to divert | deadline misses | exit status | leftovers |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- "
        "| --- | --- |",
    ]
    for f in sec["rows"]:
        s = f["summary"]
        topic = "parcels" if f["topic"] == "/parcels" else "commands"
        sim = s.get("simulator", {})
        cycles = float(sim.get("cycles", "0") or 0)
        misses = float(sim.get("deadline_misses", "0") or 0)
        own = s.get("parcel_messages" if topic == "parcels" else "command_messages") or 0
        for node in ["simulator"] + (["controller"] if topic == "parcels" else []):
            c = _intake(s, node, topic)
            uncounted = f["sent"] + own - c["received"] - c["lost"]
            L.append(
                f"| {f['topic']} | {f['sent']} | {f['publish_failed']} | {node} | "
                f"{c['received']} | {c['accepted']} | {c['foreign']} | {c['rate_limited']} | "
                f"{c['lost']} | {uncounted} | {len(s.get('divert_without_outcome') or [])} | "
                f"{s.get('sorted_divert')} / {s.get('divert')} | "
                f"{int(misses)} of {int(cycles)} ({_pct(misses, cycles)}) | {f['exit_code']} | "
                f"{f['leftovers']} |"
            )
    foreign = "; ".join(
        f"{f['topic']}: {f['summary'].get('foreign_parcel_messages')} parcels, "
        f"{f['summary'].get('foreign_command_messages')} commands"
        for f in sec["rows"]
    )
    return [
        *L,
        "",
        "Not counted = sent + the run's own messages on the topic - received - lost, per node "
        "(0: every message reached the node's intake or was counted lost). The flood lands in "
        "the simulator's ROS process; its pacing loop is a process of its own (no ROS), so "
        "the deadline misses above are the loop's under the flood. The run's monitor counted "
        f"the foreign messages apart ({foreign}); exit status 4: foreign traffic seen "
        "(README).",
        "",
    ]


def _wire_md(sec: dict) -> list[str]:
    rows, extra = sec["rows"], sec.get("extra", {})
    L = [
        "## Hostile and malformed messages",
        "",
        *_meta_lines(sec["meta"]),
        f"Published one by one to a controller and a simulator of run {WIRE_RUN}; each must "
        "raise its counter by one on the node(s) named while both run on. The commands' "
        "parcels are scanned 0.3 m upstream of the scan line, inside the simulator's tolerance "
        "and outside the controller's, so no real command races them.",
        "",
        *([f"**Not run: {extra['error']}**", ""] if "error" in extra else []),
        f"**{sum(r['ok'] for r in rows)} of {len(rows)} refused and counted; nodes alive at "
        f"the end: {extra.get('alive')}; exit statuses {extra.get('exit_codes')}; leftover "
        f"processes {extra.get('leftovers')}.**",
        "",
        "| message | topic | counted as | rise | result |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        L.append(
            f"| {r['name']} | /{r['topic']} | {', '.join(r['counted'])} | "
            f"{', '.join(str(v) for v in r['counted'].values())} | "
            f"{'refused, counted' if r['ok'] else 'NOT COUNTED'} |"
        )
    return [*L, ""]


def _cli_md(sec: dict) -> list[str]:
    rows = sec["rows"]
    L = [
        "## Bad input at the command line",
        "",
        *_meta_lines(sec["meta"]),
        "Each must exit with its status (2: bad input) with one line naming what is wrong, no "
        "traceback and no output file.",
        "",
        f"**{sum(r['ok'] for r in rows)} of {len(rows)} as required; tracebacks: "
        f"{sum(r['traceback'] for r in rows)}; silently accepted (exit 0): "
        f"{sum(r['code'] == 0 for r in rows)}.**",
        "",
        "| kind | input | command | exit status | traceback | last line | result |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        line = r["line"].replace("|", "\\|")
        line = line if len(line) <= 140 else line[:137] + "..."
        L.append(
            f"| {r['category']} | {r['name']} | `{r['command']}` | {r['code']} | "
            f"{'yes' if r['traceback'] else 'no'} | {line} | {'ok' if r['ok'] else 'FAILED'} |"
        )
    return [*L, ""]


def _insiders_md(sec: dict) -> list[str]:
    return insiders.insiders_md(sec, _meta_lines(sec["meta"]))


def _freezes_md(sec: dict) -> list[str]:
    L = [
        "## Freezes and a full disk",
        "",
        *_meta_lines(sec["meta"]),
        "`fence-sorter run --json` of 12 parcels scanned 1.5 s apart (every other one to "
        "divert); 4 s after its nodes are up, the pacing loop "
        "(the process `fs-line-worker`) or the controller is stopped with SIGSTOP for 3 s and "
        f"continued; or the run records (`--bag`) into a tmpfs of {FULL_DISK} mounted for "
        "it. Deadline misses count every cycle a stalled loop did not run; the controller's "
        "latency runs from the parcel's reception by the middleware (`latency_*`) and from "
        "its publication by the scanner (`latency_from_send_*`: a process stopped as a whole "
        "receives late, so only this one covers the stop). Targets: the stop or the full disk "
        "in the figures, every divert parcel with an outcome, a full disk reported when it "
        "happens with the sim time where the bag ends, exit status 5 (README), no leftovers.",
        "",
        "| case | exit status | sorted / to divert | outcomes | deadline misses | lateness "
        "max [ms] | controller latency p99 / max [ms] | from send p99 / max [ms] | recording "
        "| result |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sec["rows"]:
        if "not_run" in r:
            L.append(f"| {r['case']} | not run: {r['not_run']} | | | | | | | | FAILED |")
            continue
        sim, c = r["simulator"], r["controller"]
        rec = r["recording_failed"]
        rec_text = (
            f"failed at sim {rec['failed_at_sim_s']:.2f} s, bag ends at "
            f"{rec['bag_ends_sim_s']:.2f} s, {rec['messages_not_written']} not written"
            if rec
            else "-"
        )
        L.append(
            f"| {r['case']} | {r['exit_code']} | {r['sorted_divert']} / {r['divert']} | "
            f"{', '.join(f'{k} {v}' for k, v in sorted((r['by_reason'] or {}).items()))} | "
            f"{sim.get('deadline_misses')} of {sim.get('cycles')} | "
            f"{sim.get('cycle_lateness_max_ms')} | {c.get('latency_p99_ms')} / "
            f"{c.get('latency_max_ms')} | {c.get('latency_from_send_p99_ms')} / "
            f"{c.get('latency_from_send_max_ms')} | {rec_text} | "
            f"{'ok' if freeze_met(r) else 'FAILED'} |"
        )
    return [*L, ""]


SECTIONS = {
    "interrupts": _interrupts_md,
    "floods": _floods_md,
    "insiders": _insiders_md,
    "wire": _wire_md,
    "cli": _cli_md,
    "freezes": _freezes_md,
}


def render_report(data: dict, json_name: str = "reliability.json") -> str:
    """The markdown report of ``data`` (section -> {meta, rows[, extra]}) alone."""
    L = [
        "# Reliability: the fault-injection campaign",
        "",
        "`python -m benchmarks faults` (benchmarks/faults.py) injects the faults below "
        "into the node suite and counts what it refused, dropped and sorted; every figure "
        f"comes from the run named in its section (data: {json_name}).",
        "",
    ]
    for name, render in SECTIONS.items():
        if name in data:
            L += render(data[name])
    n_wire = len(data.get("wire", {}).get("rows", []))
    n_cli = len(data.get("cli", {}).get("rows", []))
    L += [
        f"Bad-input table: {n_wire + n_cli} entries ({n_wire} on the wire, {n_cli} at the "
        "command line).",
        "",
    ]
    return "\n".join(L)


def write_report(path: Path, data: dict) -> None:
    """The report ``path`` (markdown) rendered from ``data``, and the data beside it as JSON
    (a later run of some cases replaces only their sections)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_report(data, path.with_suffix(".json").name))
    path.with_suffix(".json").write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")


def verdicts(data: dict) -> dict[str, bool]:
    """Whether each section met its target."""
    out = {}
    if "wire" in data:
        out["wire"] = bool(data["wire"]["rows"]) and all(r["ok"] for r in data["wire"]["rows"])
    if "cli" in data:
        out["cli"] = all(r["ok"] for r in data["cli"]["rows"])
    if "interrupts" in data:
        out["interrupts"] = all(
            t["leftovers"] == 0 and t["exit_after_s"] <= 5.0 for t in data["interrupts"]["rows"]
        )
    if "insiders" in data:
        out["insiders"] = all(insiders.row_ok(r) for r in data["insiders"]["rows"])
    if "freezes" in data:
        out["freezes"] = all(freeze_met(r) for r in data["freezes"]["rows"])
    if "floods" in data:
        out["floods"] = all(
            not f["summary"].get("divert_without_outcome") and f["leftovers"] == 0
            for f in data["floods"]["rows"]
        )
    return out


def campaign(
    out: Path,
    trials: int = 20,
    seed: int = 16,
    which: tuple[str, ...] = tuple(SECTIONS),
    rate: float = 5000.0,
    seconds: float = 2.0,
    progress=print,
) -> dict[str, bool]:
    """Run the cases named in ``which``, replace their sections of the report ``out`` (the
    others are kept from its JSON) and return whether each section met its target."""
    rng = random.Random(seed)
    workdir = Path(tempfile.mkdtemp(prefix="fence_sorter_faults_"))
    try:
        data = json.loads(out.with_suffix(".json").read_text())
    except (OSError, ValueError):
        data = {}
    info = machine_info()
    machine = ", ".join(info[k] for k in ("cpu", "cores", "memory"))

    def meta(name: str, wall0: float) -> dict:
        argv = ["nice", "-n", "10", "python", "-m", "benchmarks", "faults", "--cases", name]
        if name == "interrupts":
            argv += ["--trials", str(trials), "--seed", str(seed)]
        return {
            "command": shlex.join(argv),
            "commit": git_revision(),
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "machine": machine,
            "wall_s": time.monotonic() - wall0,
        }

    if "wire" in which:
        wall0 = time.monotonic()
        try:
            wire, extra = run_wire(workdir, run_domain_id(), progress)
        except RuntimeError as exc:  # the nodes did not come up: reported, not a traceback
            wire, extra = [], {"error": str(exc)}
        data["wire"] = {"rows": [wire_row(r) for r in wire], "extra": extra}
        data["wire"]["meta"] = meta("wire", wall0)
    if "cli" in which:
        wall0 = time.monotonic()
        rows = []
        for case in cli_cases():
            r = run_cli_case(case, workdir)
            rows.append(cli_row(r))
            progress(
                f"cli   {case.category:10s} {case.name:40s} exit {r.code} "
                + ("ok" if r.ok else "FAILED")
            )
        data["cli"] = {"rows": rows, "meta": meta("cli", wall0)}
    if "floods" in which:
        wall0 = time.monotonic()
        rows = []
        for topic in ("/parcels", "/fence_commands"):
            f = flood_trial(topic, workdir, rate, seconds)
            rows.append(flood_row(f))
            progress(f"flood {topic}: sent {f.sent}, exit {f.exit_code}, leftovers {f.leftovers}")
        data["floods"] = {"rows": rows, "meta": meta("floods", wall0)}
    if "insiders" in which:
        wall0 = time.monotonic()
        data["insiders"] = insiders.section(workdir, progress)
        data["insiders"]["meta"] = meta("insiders", wall0)
    if "freezes" in which:
        wall0 = time.monotonic()
        rows = [freeze_trial(case, workdir) for case in FREEZES]
        for r in rows:
            progress(f"freeze {r['case']}: exit {r.get('exit_code')}, met {freeze_met(r)}")
        data["freezes"] = {"rows": rows, "meta": meta("freezes", wall0)}
    if "interrupts" in which:
        wall0 = time.monotonic()
        rows = []
        for i in range(trials):
            t = interrupt_trial(rng, workdir)
            rows.append(asdict(t))
            progress(
                f"ctrl-c {i + 1:2d}: first at {t.first_signal_s:5.2f} s, {t.signals} signals, "
                f"exit {t.exit_code} after {t.exit_after_s:.2f} s, leftovers {t.leftovers} "
                f"{t.leftover_names}"
            )
        data["interrupts"] = {"rows": rows, "meta": meta("interrupts", wall0)}
    write_report(out, data)
    return verdicts({k: v for k, v in data.items() if k in which})


def main(argv: list[str] | None = None) -> int:
    """The flooding child process of the campaign (the campaign itself is ``python -m
    benchmarks faults``)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["flood"]:
        return flood_main(argv[1:])
    print(
        "faults: error: the first argument must be 'flood' (the campaign is "
        "`python -m benchmarks faults`)",
        file=sys.stderr,
    )
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
