"""The fault campaign's freezes and full disk (see :mod:`benchmarks.faults`): a run whose
pacing loop or controller is stopped for a while, and one recording into a full file system."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from benchmarks.faults_processes import ProcessWatch, start_watched

# -- freezes and a full disk -------------------------------------------------------------------
#: the freeze cases: what is stopped (SIGSTOP, then SIGCONT) or filled up
FREEZES = ("pacing loop", "controller", "disk full")
#: the scan spacing of a freeze run's parcels [s] (every one to divert when the controller is
#: stopped, at rtf 1): the first decision time in a stop of stop_s is decided at least
#: stop_s - FREEZE_SPACING late
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
    "decision_lateness_max_s",
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
    # a parcel every FREEZE_SPACING (every other one to divert, every one when the controller
    # is stopped: its decision times then come every FREEZE_SPACING): a 3 s stop has some
    stream = workdir / f"{d.name}.csv"
    rows = ["parcel_id,arrival_time,length_a,width_b,height,mass,lateral_gap,divert"]
    rows += [
        f"{i},{FREEZE_SPACING * (i - 1):.2f},0.30,0.25,0.2,4.0,0.1,"
        f"{str(case == 'controller' or i % 2 == 1).lower()}"
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
            proc, watch = start_watched(argv, workdir, subprocess.PIPE, err, text=True)
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
        "limits": summary.get("limits"),
        "swept_sector_intrusions": summary.get("swept_sector_intrusions"),
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
        c, waited = row["controller"], row["stop_s"] - FREEZE_SPACING
        if "decision_lateness_max_s" in c:  # decided at decision time: late by the stop
            seen = float(c["decision_lateness_max_s"] or 0) >= waited
        else:  # a row of a controller that planned at reception
            seen = float(c.get("latency_from_send_max_ms") or 0) >= 1e3 * waited
        late = int(c.get("late_no_command") or 0)
        return ok and row["exit_code"] in (0, 3) and (seen or late > 0)
    return ok and row["exit_code"] == 5 and bool(row["recording_failed"] and row["recording_told"])
