"""The line's per-parcel records (fence_sorter/line/parcel_log.py, ``line-sim --parcels-out``):
one row per parcel whose decisions, stroke, delivered figures and end are the run's own."""

from __future__ import annotations

import csv
import json
from collections import Counter

import pytest

from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.cli.main import main
from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.parcel_log import COLUMNS, parcel_rows
from fence_sorter.line.types import Outcome
from fence_sorter.line.unit import ID_STRIDE

LINE = load_line("two_units")


@pytest.mark.slow
def test_each_row_is_the_parcel_s_decisions_stroke_figures_and_end() -> None:
    """two_units, 12 parcels: the rows' ends are the summary's counts; a sorted parcel's last
    decision is its stroke unit's ``booked>sorted``, its w_n, a_N and ydot are that stroke's
    outcome, its margins the figure less the limit its unit judged against (tighter here
    than planned, so that some go over), and its limits over are the unit's lists."""
    plant = LinePlant(LINE, LineRunConfig(parcels=12, seed=3))
    judged = ConstraintProfile(w_dop=1.8, a_ndop=120.0, ydot_dop=1.2)
    seen: dict[int, Outcome] = {}
    for u in plant.units:
        u.profile = judged
        advance = u.line.advance

        def spy(t, advance=advance):
            events = advance(t)
            seen.update((e.parcel_id, e) for e in events if isinstance(e, Outcome))
            return events

        u.line.advance = spy
    s = plant.run()
    rows = parcel_rows(plant)
    assert [r["parcel_id"] for r in rows] == [p.pid for p in plant.parcels]
    assert all(list(r) == COLUMNS for r in rows)
    states = Counter(r["state"] for r in rows)
    assert states == Counter({"sorted": s["sorted"], "rejected": s["rejected"]})
    assert sum(r["recirculations"] > 0 for r in rows) == s["recirculated"]
    over = {c: set() for c in ("10", "11", "12")}
    for u in s["units"].values():
        for c, ids in u["over_limits"].items():
            over[c] |= set(ids)
    for r, p in zip(rows, plant.parcels, strict=True):
        passes = r["decisions"].split(" | ")
        assert len(passes) == r["recirculations"] + 1
        for group in passes:  # the units saw it in the line's order
            names = [d.split("=")[0] for d in group.split()]
            assert names == sorted(names)
        if r["state"] == "rejected":
            assert r["chute"] == LINE.reject_chute and "booked>sorted" not in r["decisions"]
            continue
        assert r["chute"] == r["destination"]
        assert passes[-1].split()[-1] == f"{r['stroke_unit']}=booked>sorted"
        assert r["stroke_outcome"] == "sorted"
        e = seen[p.pid * ID_STRIDE + p.passes]
        assert (
            r["delivered_impact_speed_mps"], r["delivered_accel_mps2"],
            r["delivered_exit_speed_mps"],
        ) == (e.impact_normal_speed, e.peak_normal_accel, e.exit_speed_y)  # fmt: skip
        assert r["margin_10_mps"] == e.impact_normal_speed - judged.w_dop
        assert r["margin_11_mps2"] == e.peak_normal_accel - judged.a_ndop
        assert r["margin_12_mps"] == e.exit_speed_y - judged.ydot_dop
        assert {str(c) for c in r["over_limits"] if c != 7} == {
            c for c, ids in over.items() if p.pid in ids
        }
        assert 0.0 < r["r_s_m"] and 0.0 < r["t1_s"]
    assert any(r["over_limits"] for r in rows)


@pytest.mark.slow
def test_line_sim_writes_the_rows_as_csv_and_under_parcels_in_its_json(tmp_path, capsys) -> None:
    out = tmp_path / "parcels.csv"
    argv = ["line-sim", "two_units", "--parcels", "4", "--seed", "3"]
    code = main([*argv, "--parcels-out", str(out), "--json", "--with-parcels"])
    s = json.loads(capsys.readouterr().out)
    assert code == 0
    with out.open() as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == COLUMNS and len(table) == 4 == len(s["parcels"])
    for row, rec in zip(table, s["parcels"], strict=True):
        assert int(row["parcel_id"]) == rec["parcel_id"]
        assert (row["state"], row["decisions"]) == (rec["state"], rec["decisions"])
    assert sum(r["state"] == "sorted" for r in s["parcels"]) == s["sorted"]


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--parcels-out", "x.txt"], "--parcels-out must be a FILE.csv or FILE.parquet"),
        (["--parcels-out", "/no/such/dir/x.csv"], "in an existing directory"),
        (["--with-parcels"], "--with-parcels goes with --json only"),
    ],
)
def test_a_bad_parcel_option_exits_2_naming_it(args, expected, capsys) -> None:
    assert main(["line-sim", "two_units", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err
