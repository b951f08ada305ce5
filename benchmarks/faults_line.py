"""The fault campaign's line faults (see :mod:`benchmarks.faults`): a line of two units whose
link, unit or host fails mid-run.

- **link cut**: two_units split over two network namespaces joined by a veth pair (host A:
  the owner and unit_1, host B: unit_2, ``fence-sorter run --line --units ... --interface
  --peers``); once the line runs, host A's end of the veth goes down for ``CUT_S`` s
  (``ip link set ... down``, then ``up``). In lockstep the owner's clock waits for unit_2's
  replies, so hand-offs arrive late and none is lost: the summary must equal ``line-sim``'s
  for the seed.
- **unit kill**: ``fence-sorter run --line two_units`` on one host; once the line runs,
  unit_2's process is killed (SIGKILL). The runner starts it again, the owner takes it for
  down (the new process says ready with a token of its own), passes its hand-offs on and lets
  the new process rejoin; every parcel must be accounted for, and the new process sort again.
- **host kill**: as the link cut, but every process of host B is killed (SIGKILL): host A's
  owner goes on without unit_2 (it does not answer within ``reply_timeout``) and says what was
  lost; and every process of host A killed instead: host B's runner, without its owner, ends
  with exit status 3 and one line (its unit found no command for ``owner_timeout``).

Each trial returns a row (a dict) with the summaries and exit statuses; :func:`line_met` says
whether it met its target. The two-host trials need root and ``ip`` (a row ``not_run`` with
the reason otherwise).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

from benchmarks.faults_processes import fence_sorter_cmd
from benchmarks.netns import NotRunnable, in_ns, ip, ns_pids, two_hosts

#: the line, stream and seed of every trial
LINE, PARCELS, SEED = "two_units", 12, 3
#: how long the link is cut [s]
CUT_S = 2.0
#: wall time from the line's start (the owner's log says it runs) to the fault [s]
FAULT_AFTER_S = 1.0
#: the cases, in the order the campaign runs them
LINE_CASES = ("link cut", "unit kill", "host kill", "owner host kill")
#: the summary's fields that are the wall clock's, not the line's
WALL = ("wall_time_s", "real_time_factor", "restarts", "log_dir")
RUNS = "every unit is ready: the line runs"


def _kill_ns(ns: str) -> int:
    """SIGKILL every process of a namespace (a host that dies at once); how many."""
    pids = ns_pids(ns)
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    return len(pids)


def _line_cmd(ns: str | None, *args: str) -> list[str]:
    cmd = fence_sorter_cmd(
        "run", "--line", LINE, "--parcels", str(PARCELS), "--seed", str(SEED), "--json",
        "--timeout", "600", *args,
    )  # fmt: skip
    return cmd if ns is None else in_ns(ns, cmd)


def _start(cmd: list[str], workdir: Path, name: str) -> tuple[subprocess.Popen, Path]:
    err = workdir / f"{name}.err"
    with open(err, "w") as f:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=f, text=True, cwd=workdir,
            start_new_session=True,
        )  # fmt: skip
    return proc, err


def _wait_running(log: Path, procs: list[subprocess.Popen], timeout: float = 300.0) -> bool:
    """Until the owner's log says the line runs (False: a process ended first, or timeout)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and all(p.poll() is None for p in procs):
        try:
            if RUNS in log.read_text(errors="replace"):
                return True
        except OSError:
            pass
        time.sleep(0.1)
    return False


def _finish(proc: subprocess.Popen, err: Path, timeout: float = 600.0) -> dict:
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    text = err.read_text(errors="replace")
    summary = next((json.loads(x) for x in reversed(out.splitlines()) if x.startswith("{")), {})
    last = [x for x in text.splitlines() if x.strip()]
    return {
        "exit_code": proc.returncode,
        "summary": summary,
        "last_line": last[-1] if last else "",
        "traceback": "Traceback" in text,
    }


def line_sim_reference() -> dict:
    """``fence-sorter line-sim`` of the trials' line, parcels and seed."""
    out = subprocess.run(
        fence_sorter_cmd("line-sim", LINE, "--parcels", str(PARCELS), "--seed", str(SEED),
                         "--json"),
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(out.stdout)


def _timeouts(reply: float | None, owner: float | None, owner_here: bool) -> list[str]:
    """The options of ``run --line`` for the owner's wait for a reply and the units' wait for
    a command (None: the default)."""
    args = []
    if reply is not None and owner_here:
        args += ["--reply-timeout", repr(reply)]
    if owner is not None:
        args += ["--owner-timeout", repr(owner)]
    return args


def _two_host_trial(
    case: str, workdir: Path, reply: float | None = None, owner: float | None = None
) -> dict:
    row: dict = {"case": case}
    d = Path(tempfile.mkdtemp(prefix="line-fault-", dir=workdir))
    domain = str(150 + int(uuid.uuid4().hex[:4], 16) % 50)
    with two_hosts() as h:
        side_b, err_b = _start(
            _line_cmd(h.b, "--units", "2", "--no-owner", "--domain", domain,
                      "--interface", h.addr_b, "--peers", h.addr_a,
                      *_timeouts(reply, owner, False)),
            d, "b",
        )  # fmt: skip
        side_a, err_a = _start(
            _line_cmd(h.a, "--units", "1", "--domain", domain, "--interface", h.addr_a,
                      "--peers", h.addr_b, "--log-dir", str(d / "logs_a"),
                      *_timeouts(reply, owner, True)),
            d, "a",
        )  # fmt: skip
        try:
            running = _wait_running(d / "logs_a" / "line_owner.log", [side_a, side_b])
            row["fault_mid_run"] = False
            if running:
                time.sleep(FAULT_AFTER_S)
                if case == "link cut":
                    ip("-n", h.a, "link", "set", h.dev_a, "down")
                    time.sleep(CUT_S)
                    ip("-n", h.a, "link", "set", h.dev_a, "up")
                    row["fault_mid_run"] = side_a.poll() is None
                elif case == "host kill":
                    row["fault_mid_run"] = side_a.poll() is None
                    row["killed"] = _kill_ns(h.b)
                else:  # the owner's host
                    row["fault_mid_run"] = side_b.poll() is None
                    row["killed"] = _kill_ns(h.a)
            row["a"] = _finish(side_a, err_a)
            row["b"] = _finish(side_b, err_b)
        finally:
            for ns in (h.a, h.b):
                _kill_ns(ns)
    return row


def _unit_kill_trial(workdir: Path) -> dict:
    row: dict = {"case": "unit kill"}
    d = Path(tempfile.mkdtemp(prefix="line-fault-", dir=workdir))
    proc, err = _start(_line_cmd(None, "--log-dir", str(d / "logs")), d, "run")
    try:
        row["fault_mid_run"] = False
        if _wait_running(d / "logs" / "line_owner.log", [proc]):
            time.sleep(FAULT_AFTER_S)
            pid = _unit_pid(proc.pid, 1)
            if pid is not None and proc.poll() is None:
                os.kill(pid, signal.SIGKILL)
                row["fault_mid_run"] = True
        row["a"] = _finish(proc, err)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return row


def _unit_pid(root: int, index: int) -> int | None:
    """The pid of the ``line_unit`` process of unit ``index`` under the run ``root``."""
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{name}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        text = [c.decode(errors="replace") for c in cmd]
        if f"unit_index:={index}" in text and _descends(int(name), root):
            return int(name)
    return None


def _descends(pid: int, root: int) -> bool:
    while pid > 1:
        if pid == root:
            return True
        try:
            stat = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
        except OSError:
            return False
        pid = int(stat[1])
    return False


def line_trial(
    case: str,
    workdir: Path,
    reply_timeout: float | None = None,
    owner_timeout: float | None = None,
) -> dict:
    """One trial of ``case`` (one of LINE_CASES); a row ``not_run`` with the reason where it
    cannot run here. ``reply_timeout``, ``owner_timeout``: ``run --line``'s
    ``--reply-timeout`` (the owner's host) and ``--owner-timeout`` (both hosts) of a
    two-host trial (None: the defaults)."""
    try:
        if case == "unit kill":
            return _unit_kill_trial(workdir)
        return _two_host_trial(case, workdir, reply_timeout, owner_timeout)
    except NotRunnable as exc:
        return {"case": case, "not_run": str(exc)}


def accounted(s: dict) -> bool:
    """A line summary whose every parcel is accounted for: drained, conservation exact (the
    parcels lost with a unit counted), every link balanced."""
    return bool(s.get("drained") and s.get("conservation_ok") and s.get("handoffs_balanced"))


def line_met(row: dict, ref: dict | None = None) -> bool:
    """A line fault row's target (``ref``: ``line-sim``'s summary, for the link cut)."""
    if "not_run" in row or not row.get("fault_mid_run"):
        return False
    a = row["a"]
    if a["traceback"]:
        return False
    s = a["summary"]
    if row["case"] == "link cut":
        same = ref is None or all(s.get(k) == v for k, v in ref.items() if k not in WALL)
        return a["exit_code"] == 0 == row["b"]["exit_code"] and accounted(s) and same
    if row["case"] == "unit kill":
        down = s.get("units_down", {}).get("unit_2", {})
        return (
            a["exit_code"] == 0 and accounted(s) and s.get("restarts", {}).get("unit_2") == 1
            and down.get("rejoins") == 1 and (down.get("sorted_by_last_process") or 0) > 0
        )  # fmt: skip
    if row["case"] == "host kill":
        down = s.get("units_down", {}).get("unit_2", {})
        return a["exit_code"] == 0 and accounted(s) and bool(down.get("down_at_end"))
    b = row["b"]
    return b["exit_code"] == 3 and "no command from the line's owner" in b["last_line"]


if __name__ == "__main__":  # one trial by hand: python -m benchmarks.faults_line CASE
    print(json.dumps(line_trial(sys.argv[1], Path(tempfile.mkdtemp())), indent=1))
