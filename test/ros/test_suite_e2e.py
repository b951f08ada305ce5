"""End to end: `fence-sorter run` starts simulator, scanner and controller as separate processes
over DDS; a short stream (some to divert, some not): every divert parcel is SORTED, every other
NOT_DIVERTED, the outcomes are published, the nodes exit cleanly and leave no process behind."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from fence_sorter.runner.processes import leftovers
from fence_sorter.testing import run_cli, wait_until

pytestmark = [pytest.mark.ros, pytest.mark.slow]

MANIFEST = """parcel_id,arrival_time,length_a,width_b,height,mass,lateral_gap,yaw_deg,divert
11,0.0,0.40,0.30,0.30,8.0,0.10,0.0,true
12,2.5,0.30,0.20,0.20,3.0,0.00,0.0,false
13,5.0,0.25,0.25,0.15,2.0,0.20,2.0,true
14,7.5,0.50,0.30,0.40,15.0,0.05,0.0,true
15,10.0,0.20,0.15,0.10,1.0,0.30,-3.0,false
"""


def test_short_stream_end_to_end(tmp_path: Path, env: dict[str, str]) -> None:
    manifest = tmp_path / "short.csv"
    manifest.write_text(MANIFEST)
    proc = run_cli(
        "run",
        "--stream",
        str(manifest),
        "--rtf",
        "2",
        "--json",
        "--log-dir",
        str(tmp_path / "logs"),
        timeout=85,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    s = json.loads(proc.stdout)
    assert s["exit"] == 0 and s["parcels_expected"] == 5 and s["parcels_seen"] == 5
    assert s["outcomes"] == 5 and s["outcome_messages"] == 5  # exactly one outcome per parcel
    assert s["by_reason"] == {"SORTED": 3, "NOT_DIVERTED": 2}, s["missed_examples"]
    assert s["sorted_divert"] == 3 and s["wrongly_sorted"] == []
    assert s["commands"] == 3 and s["infeasible_commands"] == 0 and s["commands_late"] == 0
    assert s["command_min_lead_s"] > 0.0
    assert s["peak_force_N"] > 0.0
    assert all(code == 0 for code in s["exit_codes"].values()), s["exit_codes"]
    assert set(s["exit_codes"]) == {"simulator", "scanner", "controller"}
    assert s["leftover_processes"] == [] and leftovers(s["process_groups"]) == []
    assert s["controller"]["commands"] == "3" and s["controller"]["rejected_parcels"] == "0"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_interrupted_run_stops_every_node(tmp_path: Path, sig: int) -> None:
    """Ctrl-C (or SIGTERM) in the middle of a run: exit 130, a summary, no process left."""
    repo = Path(__file__).resolve().parents[2]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(repo), env.get("PYTHONPATH")]))
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--parcels", "40", "--json"]
    err_file = tmp_path / "stderr.txt"
    with err_file.open("w") as err_out:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=err_out, text=True, cwd=repo, env=env
        )
        try:
            # mid-run: the nodes are up and the stream is flowing
            wait_until(
                lambda: "; running" in err_file.read_text() or proc.poll() is not None,
                120.0,
                "the run's nodes to be up",
            )
            assert proc.poll() is None, err_file.read_text()
            proc.send_signal(sig)
            out, _ = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
    err = err_file.read_text()
    assert proc.returncode == 130, err
    s = json.loads(out)
    assert s["message"].startswith("interrupted")
    assert len(s["process_groups"]) == 3 and leftovers(s["process_groups"]) == []
