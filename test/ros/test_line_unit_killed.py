"""A unit's process of ``fence-sorter run --line`` killed mid-run (SIGKILL): the fault case
"unit kill" of the campaign (benchmarks/faults_line.py).

The line must go on: the runner starts the unit again (counted in ``restarts``), the owner
takes the old process for down when the new one says ready with its own token, passes the
unit's hand-offs on meanwhile and lets the new process rejoin at a step. Checked: exit 0,
conservation exact with the parcels lost with the unit counted and named, every link
balanced at both ends, the unit down once and back once, its new process sorting again.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.faults_line import PARCELS, line_met, line_trial

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.faults]


def test_a_killed_unit_is_restarted_and_rejoins_and_nothing_is_silently_lost(
    tmp_path: Path,
) -> None:
    row = line_trial("unit kill", tmp_path)
    assert row["fault_mid_run"], row
    a = row["a"]
    assert a["exit_code"] == 0 and not a["traceback"], a["last_line"]
    s = a["summary"]
    assert s["drained"] and s["conservation_ok"] and s["handoffs_balanced"], s
    assert (
        PARCELS
        == s["parcels_inducted"]
        == (s["sorted"] + s["rejected"] + s["solver_failures"] + s["lost_with_unit"])
    )
    assert s["restarts"] == {"unit_1": 0, "unit_2": 1}
    down = s["units_down"]["unit_2"]
    assert down["downs"] == 1 == down["rejoins"] and not down["down_at_end"], down
    assert len(down["lost_parcels"]) == s["lost_with_unit"] and "unit_1" not in s["units_down"]
    # every hand-off on every link counted at both ends (the dead process's counts kept)
    for link, v in s["links"].items():
        assert v["sent"] == v["received"] + sum(v["refused"].values()) + v["lost"], link
    # the stand-in's hand-offs are the unit's declines `unit_down`
    assert s["units"]["unit_2"]["declined"]["unit_down"] == down["handoffs_passed_on"]
    # the new process routed the parcels announced after it rejoined and sorted again
    assert down["sorted_by_last_process"] > 0
    assert line_met(row)
