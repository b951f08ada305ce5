"""End to end: `fence-sorter run` starts simulator, scanner and controller as separate processes
over DDS; a short stream (some to divert, some not): every divert parcel is SORTED, every other
NOT_DIVERTED, the outcomes are published, the nodes exit cleanly and leave no process behind."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from processes import run_cli

from fence_sorter.runner.processes import leftovers

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
