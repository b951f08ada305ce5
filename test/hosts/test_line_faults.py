"""Faults of a line split over two hosts (two network namespaces joined by a veth pair): the
campaign's cases "link cut", "host kill" and "owner host kill" (benchmarks/faults_line.py).

Host A runs the owner of two_units and unit_1, host B unit_2 (``--no-owner``). Checked:

- the link down for 2 s mid-run: the lockstep clock waits, hand-offs arrive late and none is
  lost; both hosts exit 0 and A's summary equals ``line-sim``'s for the seed;
- every process of host B killed: A's owner goes on without unit_2 (no answer within
  ``reply_timeout``), drains the line with every parcel accounted for and names what was lost;
- every process of host A killed: B's runner ends with exit status 3 and one line (its unit
  got no command for ``owner_timeout``) instead of waiting until ``--timeout``.

The two kills run with ``--reply-timeout REPLY_S`` and ``--owner-timeout OWNER_S`` (defaults
10 s and 20 s): a dead host is found as surely, sooner (the owner's longest wait for a reply
that came, the planners' warm-up included, was 0.16 s in the case "host kill" of
docs/reports/reliability.md); the summary and the last line name the timeout that fired.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.faults_line import PARCELS, WALL, line_met, line_sim_reference, line_trial

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.hosts, pytest.mark.faults]

#: the owner's wait for a reply and the units' wait for a command in the kill cases [s]
REPLY_S, OWNER_S = 4.0, 8.0


def _trial(case: str, tmp_path: Path, **timeouts: float) -> dict:
    row = line_trial(case, tmp_path, **timeouts)
    if "not_run" in row:
        pytest.skip(row["not_run"])
    assert row["fault_mid_run"], row
    return row


def _accounted(s: dict) -> None:
    assert s["drained"] and s["conservation_ok"] and s["handoffs_balanced"], s
    assert (
        PARCELS
        == s["parcels_inducted"]
        == (s["sorted"] + s["rejected"] + s["solver_failures"] + s["lost_with_unit"])
    )
    for link, v in s["links"].items():
        assert v["sent"] == v["received"] + sum(v["refused"].values()) + v["lost"], link


def test_a_link_cut_of_2_s_delays_the_line_and_loses_nothing(tmp_path: Path) -> None:
    row = _trial("link cut", tmp_path)
    a, b = row["a"], row["b"]
    assert a["exit_code"] == 0, a["last_line"]
    assert b["exit_code"] == 0, b["last_line"]
    s = a["summary"]
    _accounted(s)
    assert s["lost_with_unit"] == 0 and s["units_down"] == {}
    ref = line_sim_reference()
    assert {k: (v, s.get(k)) for k, v in ref.items() if k not in WALL and s.get(k) != v} == {}
    across = s["links"]["unit_1>unit_2"]
    assert across["sent"] == across["received"] > 0 and across["lost"] == 0
    assert line_met(row, ref)


def test_host_b_killed_the_owner_s_host_goes_on_and_says_what_was_lost(tmp_path: Path) -> None:
    row = _trial("host kill", tmp_path, reply_timeout=REPLY_S, owner_timeout=OWNER_S)
    a = row["a"]
    assert row["killed"] > 0 and a["exit_code"] == 0 and not a["traceback"], a["last_line"]
    s = a["summary"]
    _accounted(s)
    down = s["units_down"]["unit_2"]
    assert down["down_at_end"] and down["rejoins"] == 0 and down["downs"] == 1, down
    assert f"within reply_timeout {REPLY_S:g} s" in down["why"], down["why"]
    assert len(down["lost_parcels"]) == s["lost_with_unit"]
    # from the moment it went down, its hand-offs were passed on for it: B (unit_2's alone)
    # is sorted no more, every parcel still ended somewhere
    assert s["units"]["unit_2"]["declined"]["unit_down"] == down["handoffs_passed_on"] > 0
    assert line_met(row)


def test_host_a_killed_the_other_host_ends_with_exit_3(tmp_path: Path) -> None:
    row = _trial("owner host kill", tmp_path, reply_timeout=REPLY_S, owner_timeout=OWNER_S)
    b = row["b"]
    assert row["killed"] > 0 and not b["traceback"]
    assert b["exit_code"] == 3, b
    assert "no command from the line's owner" in b["last_line"], b["last_line"]
    assert f"(owner_timeout {OWNER_S:g} s)" in b["last_line"], b["last_line"]
    assert line_met(row)
