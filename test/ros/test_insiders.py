"""Insiders on the run's own domain with the run's own id (benchmarks.insiders):
forged duplicates just ahead of the scanner, a flood of new ids, a second /clock jumping ahead.

Each is a real ``fence-sorter run`` (its nodes in their own processes over DDS) with the insider
in another process that reads the run id off /parcels. The run's key refuses every forgery
(``foreign_source``), so the real parcels keep their planned outcomes and the figures hold only
the run's stream; the summary names the forgery and the run exits 4, never 0.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.insiders import InsiderTrial, insider_trial, refused

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.faults]

PARCELS = 8
#: outcomes a real divert parcel may have when the run went as planned: sorted, or the
#: controller found no stroke (its own plan); not NO_COMMAND, REJECTED or no outcome
PLANNED = {"SORTED", "NO_FEASIBLE_COMMAND"}


def real_parcels_as_planned(t: InsiderTrial) -> None:
    s = t.summary
    assert s["parcels_expected"] == PARCELS and s["parcels_seen"] == PARCELS, t.message
    rows = s["parcels"]
    assert [r["parcel_id"] for r in rows] == list(range(1, PARCELS + 1))
    assert all(r["outcome"] in PLANNED for r in rows if r["divert"]), rows
    assert s["outcomes_outside_stream"] == 0 and s["disputed"] == []
    # the nodes took exactly the stream's parcels
    for node in ("simulator", "controller"):
        assert s[node]["parcels.accepted"] == str(PARCELS), (node, s[node])


def test_forged_duplicates_are_refused_and_named(tmp_path: Path) -> None:
    t = insider_trial("duplicates", tmp_path, parcels=PARCELS, count=5)
    forged = t.insider["forged_ids"]
    assert len(forged) == 5 and t.insider["sent"] == 5
    real_parcels_as_planned(t)
    s = t.summary
    assert refused(s, "simulator") == 5 and refused(s, "controller") == 5
    # the ids it forged that the stream has (the next ones after the last it saw)
    of_the_run = [i for i in forged if i <= PARCELS]
    assert of_the_run and s["forged_parcel_ids"] == of_the_run
    assert "fence_sorter_insider" in "".join(s["foreign_publishers"]["/parcels"])
    assert t.exit_code == 4 and f"forging parcel ids {of_the_run}" in t.message


def test_an_insider_flood_reaches_neither_the_line_nor_the_figures(tmp_path: Path) -> None:
    t = insider_trial("flood", tmp_path, parcels=PARCELS, rate=5000.0, seconds=1.0)
    sent = t.insider["sent"]
    assert sent == 5000
    real_parcels_as_planned(t)
    s = t.summary
    for node in ("simulator", "controller"):
        taken = int(s["dropped"].get(node, {}).get("parcels.lost", 0)) + refused(s, node)
        assert taken == sent, (node, s["dropped"])  # every forgery refused (or lost), none taken
    assert s["forged_parcel_messages"] == sent
    assert t.exit_code == 4 and f"{sent} parcels and 0 commands with the run's id" in t.message


def test_a_second_clock_moves_no_node_and_is_named(tmp_path: Path) -> None:
    t = insider_trial("clock", tmp_path, parcels=PARCELS, seconds=2.0, jump=6.7e7)
    assert t.insider["sent"] == 2000
    real_parcels_as_planned(t)
    s = t.summary
    assert s["sim_time_s"] < 1000.0  # the scanner's progress never jumped with it
    assert "scan_time" not in "".join(s["dropped"].get("simulator", {}))
    assert s["controller"]["rejected_parcels"] == "0", s["controller"]
    # the intruder by name (under load it may also be named once as an endpoint whose node's
    # name had not arrived for 3 s)
    named = s["foreign_publishers"]["/clock"]
    assert any("fence_sorter_insider" in n for n in named), named
    assert t.exit_code == 4 and "publishers of /clock that are not the run's" in t.message


def test_forged_outcomes_and_statuses_are_refused_and_the_figures_are_the_runs(
    tmp_path: Path,
) -> None:
    """An insider answers each scanned parcel at once with SORTED, 1 N, 0.01 m/s, and speaks
    for the simulator on /diagnostics: every one refused; the real outcomes stand."""
    t = insider_trial("outcomes", tmp_path, parcels=PARCELS, count=PARCELS)
    assert t.insider["sent"] == PARCELS and t.insider["forged_ids"] == list(
        range(1, PARCELS + 1)
    ), t.insider
    real_parcels_as_planned(t)
    s = t.summary
    assert s["forged_outcome_messages"] == PARCELS
    assert s["forged_outcome_ids"] == list(range(1, PARCELS + 1))
    assert s["forged_diagnostics"]["fence_sorter/simulator"] == t.insider["statuses"]
    # the figures are the simulator's: not the insider's 1 N and 0.01 m/s
    assert s["peak_force_N"] > 100.0 and s["peak_impact_speed_mps"] > 0.5
    assert s["outcome_messages"] == PARCELS
    assert any("fence_sorter_insider" in n for n in s["foreign_publishers"]["/sort_outcomes"])
    assert t.exit_code == 4
    assert f"{PARCELS} outcomes with the run's id that its key does not vouch for" in t.message
