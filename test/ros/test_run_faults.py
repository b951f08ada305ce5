"""`fence-sorter run` under a fault and as seen from the host: the controller killed mid-run is
restarted by the runner and the run goes on to every outcome; every UDP socket of the run is
on the loopback interface; a clean run leaves no log directory behind."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from fence_sorter.runner.processes import tagged, wait_until

pytestmark = [pytest.mark.ros, pytest.mark.faults, pytest.mark.slow]

TAG = "FENCE_SORTER_TEST_RUN"
REPO = Path(__file__).resolve().parents[2]
PARCELS = 10


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _pids(tag: str, module: str) -> set[int]:
    return {pid for pid in tagged(TAG, tag) if module in _cmdline(pid)}


def _udp_binds(pids: set[int]) -> list[tuple[str, int]]:
    """(local address, pid) of every UDP socket ``ss -lnuap`` lists for ``pids``."""
    out = subprocess.run(["ss", "-lnuap"], capture_output=True, text=True, check=True).stdout
    binds = []
    for line in out.splitlines()[1:]:
        fields = line.split()
        if len(fields) < 5:
            continue
        local = fields[3]
        for pid in re.findall(r"pid=(\d+)", line):
            if int(pid) in pids:
                binds.append((local, int(pid)))
    return binds


def _loopback(address: str) -> bool:
    """A loopback address, or a multicast group (a group is no interface: Fast DDS joins it
    on the allowed interfaces only, here loopback; shared memory carries the discovery)."""
    host = address.rsplit(":", 1)[0].strip("[]").split("%")[0]
    first = int(host.split(".")[0]) if host[:1].isdigit() else 0
    return host.startswith("127.") or host == "::1" or 224 <= first <= 239


def test_controller_killed_mid_run_is_restarted_and_the_run_goes_on(tmp_path: Path) -> None:
    rows = ["parcel_id,arrival_time,length_a,width_b,height,mass,lateral_gap,divert"]
    rows += [f"{i},{2.5 * (i - 1):.1f},0.30,0.25,0.2,4.0,0.1,true" for i in range(1, 11)]
    manifest = tmp_path / "stream.csv"
    manifest.write_text("\n".join(rows) + "\n")
    tag = uuid.uuid4().hex
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env[TAG] = tag
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--stream", str(manifest)]
    cmd += ["--rtf", "2", "--json"]
    err_file = tmp_path / "stderr.txt"
    with err_file.open("w") as err_out:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=err_out, text=True, cwd=REPO, env=env
        )
        try:
            assert wait_until(
                lambda: "; running" in err_file.read_text() or proc.poll() is not None, 240.0
            )
            assert proc.poll() is None, err_file.read_text()
            # every UDP socket of every process of the run is on loopback (DDS included)
            run_pids = set(tagged(TAG, tag))
            binds = _udp_binds(run_pids)
            assert binds, "ss lists no UDP socket of the run"
            assert [b for b in binds if not _loopback(b[0])] == [], binds
            first = _pids(tag, "fence_sorter.nodes.controller")
            assert len(first) == 1
            os.kill(first.pop(), signal.SIGKILL)
            out, _ = proc.communicate(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    err = err_file.read_text()
    assert proc.returncode == 0, err
    s = json.loads(out)
    assert s["controller_restarts"] == 1
    assert "controller exited with status -9; restarting it (1 of at most 3)" in err
    # every parcel has its outcome: those that reached R_s while no controller listened are
    # NO_COMMAND (the simulator's side, test/ros/test_faults.py), the new controller planned
    # the others
    assert s["outcomes"] == PARCELS, s["by_reason"]
    assert set(s["by_reason"]) <= {"SORTED", "NO_COMMAND"} and s["by_reason"].get("SORTED")
    # a clean run removes its temporary log directory
    logs = re.search(r"logs (\S+)", err).group(1)
    assert s["log_dir"] is None and not Path(logs).exists()
    assert wait_until(lambda: not tagged(TAG, tag), 10.0)


def test_a_pacing_loop_stopped_3_s_misses_every_deadline_it_did_not_run(tmp_path: Path) -> None:
    """SIGSTOP of the loop process for 3 s at 1 kHz: about 3000 deadline misses (each cycle
    not run), not the handful of late wake-ups; the line resumes and every divert parcel is
    sorted as planned."""
    from benchmarks.faults import freeze_met, freeze_trial

    row = freeze_trial("pacing loop", tmp_path, stop_s=3.0)
    assert row["stopped_pid_found"], row
    sim = {k: float(v) for k, v in row["simulator"].items()}
    # the stop is at least 3 s of missed deadlines (the machine's own misses come on top)
    assert 2990 <= sim["deadline_misses"] <= sim["cycles"]
    assert sim["cycle_lateness_max_ms"] >= 2990.0
    assert sim["deadline_misses"] >= sim["cycle_lateness_max_ms"] - 10.0
    assert row["exit_code"] == 0, row
    assert row["sorted_divert"] == row["divert"] > 0, (row["by_reason"], row["missed_examples"])
    assert freeze_met(row)


def test_a_controller_stopped_3_s_decides_late_and_no_verdict_is_wrong(tmp_path: Path) -> None:
    """SIGSTOP of the controller for 3 s at rtf 1 with a parcel to divert scanned every 1.5 s:
    the first decision time in the stop is decided at least 3 - 1.5 s late, and only from the
    run's time (never from the sim time the node had when it stopped: a stroke planned from it
    starts in the past). Every divert parcel has an outcome; nothing over a limit, no
    intrusion (exit 0, or 3 for parcels it could not plan in time)."""
    from benchmarks.faults import FREEZE_SPACING, freeze_met, freeze_trial

    row = freeze_trial("controller", tmp_path, stop_s=3.0)
    assert row["stopped_pid_found"], row
    late = float(row["controller"]["decision_lateness_max_s"])
    assert late >= 3.0 - FREEZE_SPACING, row["controller"]
    assert row["swept_sector_intrusions"] == 0 and row["limits"]["clean"], row["limits"]
    assert not row["divert_without_outcome"] and row["exit_code"] in (0, 3), row
    assert freeze_met(row)


def test_a_full_disk_is_reported_when_it_happens_and_the_run_exits_5(tmp_path: Path) -> None:
    """Recording into a 256 KiB tmpfs (mounted here, as root): the recorder's write fails
    with ENOSPC; the runner says so at once with the sim time where the bag ends, the run goes
    on unrecorded to every outcome, the summary names it and the exit status is 5. The bag
    left on the full disk ends where the recorder said (read back from a copy)."""
    from benchmarks.faults import freeze_met, freeze_trial
    from fence_sorter.recording.bagread import read_bag

    row = freeze_trial("disk full", tmp_path)
    if "not_run" in row:
        pytest.skip(f"cannot mount a tmpfs here: {row['not_run']}")
    rec = row["recording_failed"]
    assert row["exit_code"] == 5, row
    assert rec and "No space left on device" in rec["error"], rec
    assert row["recording_told"].startswith(
        f"recorder: writing the bag failed at sim time {rec['failed_at_sim_s']:.2f} s"
    )
    assert (
        f"the bag holds every message up to sim time {rec['bag_ends_sim_s']:.2f} s"
        in row["recording_told"]
    )
    assert 0.0 < rec["bag_ends_sim_s"] <= rec["failed_at_sim_s"]
    assert rec["messages_not_written"] > 0
    assert not row["divert_without_outcome"] and row["sorted_divert"] == row["divert"]
    last = max(m.t_ns for m in read_bag(row["bag_copy"]).messages) * 1e-9
    # every message up to the last flush is there; a chunk the failing write completed before
    # the disk filled may hold later ones, never later than the failure
    assert rec["bag_ends_sim_s"] - 2e-3 <= last <= rec["failed_at_sim_s"] + 2e-3
    assert freeze_met(row)
