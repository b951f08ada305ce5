"""Sweeps of Figs. 3-10: resume, CSV rows, definitions, and the controller's decision table.

ROS-free and fast: the sweep machinery runs on a stand-in objective (W_t (1)-(2) of a stroke
chosen in closed form), never on the optimiser itself.
"""

from __future__ import annotations

import argparse
import math
import shutil
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import pytest

from benchmarks import cli as cli_main
from benchmarks.paper import sweep as sw
from benchmarks.paper import sweep_defs as sd
from benchmarks.paper import sweep_rows as sr
from benchmarks.paper.points import point
from fence_sorter.capacity import LoadRequest, Planner, PlannerConfig
from fence_sorter.capacity.decision_table import DecisionTable, build_table, write_table
from fence_sorter.capacity.formulas import pitch
from fence_sorter.physics.params import ParameterError
from fence_sorter.scene import load_scene


class SyncExecutor(Executor):
    """Runs each job in submit (a KeyboardInterrupt there is the user's Ctrl-C)."""

    def submit(self, fn, /, *args, **kwargs) -> Future:
        fut: Future = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except Exception as exc:
            fut.set_exception(exc)
        return fut


def stand_in(inputs) -> dict:
    """A stroke in closed form: v = 2.5 m/s, R_s = 0, t1 so that (11) is met by a_N ~ 1/t1^2;
    W_t and Delta_c from (1)-(2) (Delta = 0), the margins from the same figures."""
    v, r_s = 2.5, 0.0
    alpha = math.radians(inputs["alpha_k_deg"])
    t1 = max(0.1, math.sqrt(40.0 * alpha / inputs["a_ndop"]))
    a_max = inputs["load_length"]
    delta_c = pitch(v, t1, r_s, a_max, 0.0)
    accel = 40.0 * alpha / t1**2
    return sr.result_row(
        inputs,
        {
            "feasible": True,
            "X": {"R_s": r_s, "v": v, "t1": t1, "R_z": 1.2},
            "W_t": 3600.0 * v / delta_c,
            "Delta_c": delta_c,
            "active": [11],
            "margins": {"7": (a_max - r_s) / v - t1, "8": -0.2, "11": accel - inputs["a_ndop"]},
            "infeasible": "",
            "evaluations": 17,
            "wall_time": 0.0,
        },
    )


def fake_sweep(solve=stand_in) -> sd.SweepDef:
    pts = tuple(
        point(case="positioned", alpha_k_deg=a, a_ndop=an, constraints="7 8 11")
        for an in (15.0, 300.0)
        for a in (20.0, 40.0, 60.0)
    )
    return sd.SweepDef(
        "fake", "Fig. X", "stand-in", "fake", pts, "alpha_k_deg", "alpha_k [deg]", "a_ndop",
        "a_Ndop", (sd.P_T1, sd.P_WT), solve=solve,
    )  # fmt: skip


def _strip(rows):
    """Rows as their CSV cells (NaN == NaN there), wall time left out."""
    return [sr.format_row({**r, "wall_time": 0.0}) for r in rows]


# -- resume ------------------------------------------------------------------------------------
def test_interrupted_sweep_resumes_without_repeating_or_duplicating(tmp_path) -> None:
    calls: list[str] = []

    def counted(inputs):
        calls.append(sr.point_key(inputs))
        if len(calls) == 3:  # Ctrl-C while the third point is being solved
            raise KeyboardInterrupt
        return stand_in(inputs)

    full = sw.run_sweep(fake_sweep(), tmp_path / "ref", SyncExecutor(), progress=False)
    with pytest.raises(KeyboardInterrupt):
        sw.run_sweep(fake_sweep(counted), tmp_path, SyncExecutor(), progress=False)
    assert len(sr.read_rows(tmp_path / "fake.csv")) == 2  # the two finished points were kept
    rows = sw.run_sweep(fake_sweep(counted), tmp_path, SyncExecutor(), progress=False)
    keys = [r["key"] for r in sr.read_rows(tmp_path / "fake.csv")]
    assert len(keys) == len(set(keys)) == 6  # no duplicate rows
    assert len(calls) == 3 + 4  # the rerun solved only the 4 open points (3rd one again)
    assert _strip(rows) == _strip(full)  # same final table, in point order
    # a third run has nothing left to do
    again = sw.run_sweep(fake_sweep(counted), tmp_path, SyncExecutor(), progress=False)
    assert len(calls) == 7 and _strip(again) == _strip(full)


def test_chunked_parallel_run_and_a_line_cut_mid_write(tmp_path) -> None:
    with ThreadPoolExecutor(2) as ex:
        first = sw.run_sweep(fake_sweep(), tmp_path, ex, progress=False, max_points=4)
        assert len(first) == 4
        path = tmp_path / "fake.csv"
        text = path.read_text()
        path.write_text(text[: text.rstrip("\n").rfind("\n") + 1] + text.splitlines()[-1][:25])
        assert len(sr.read_rows(path)) == 3  # the cut row does not count
        rows = sw.run_sweep(fake_sweep(), tmp_path, ex, progress=False)
    assert len(rows) == 6 and len(sr.read_rows(path)) == 6
    assert path.read_text().count("\n") == 7  # header + 6 rows, the cut line is gone
    ref = sw.run_sweep(fake_sweep(), tmp_path / "ref", SyncExecutor(), progress=False)
    assert _strip(rows) == _strip(ref)


def test_resume_false_starts_afresh(tmp_path) -> None:
    sw.run_sweep(fake_sweep(), tmp_path, SyncExecutor(), progress=False)
    calls = []

    def counted(inputs):
        calls.append(1)
        return stand_in(inputs)

    sw.run_sweep(fake_sweep(counted), tmp_path, SyncExecutor(), resume=False, progress=False)
    assert len(calls) == 6 and len(sr.read_rows(tmp_path / "fake.csv")) == 6


def test_a_failing_point_is_reported_and_the_others_saved(tmp_path) -> None:
    def flaky(inputs):
        if inputs["alpha_k_deg"] == 40.0 and inputs["a_ndop"] == 15.0:
            raise ValueError("no optimum")
        return stand_in(inputs)

    with pytest.raises(sw.SweepError, match="1 point.*no optimum"):
        sw.run_sweep(fake_sweep(flaky), tmp_path, SyncExecutor(), progress=False)
    assert len(sr.read_rows(tmp_path / "fake.csv")) == 5
    assert len(sw.run_sweep(fake_sweep(), tmp_path, SyncExecutor(), progress=False)) == 6


# -- rows --------------------------------------------------------------------------------------
def test_csv_rows_round_trip_exactly(tmp_path) -> None:
    inputs = point(case="arbitrary", alpha_k_deg=35.0, w_dop=1.981, fixed="R_s=0.0 R_z=1.4")
    row = {"key": sr.point_key(inputs), **inputs, **stand_in(inputs)}
    row.update(
        feasible=False,
        t1=0.1 + 0.2,  # not a short decimal
        m12=math.nan,
        infeasible='(8) push-off: s - y_k <= 0 [m] violated by 0.05, "quoted"; (10) too',
    )
    with sr.RowWriter(tmp_path / "r.csv") as w:
        w.write(row)
    (back,) = sr.read_rows(tmp_path / "r.csv")
    assert set(back) == set(row)
    for k, v in row.items():
        if isinstance(v, float) and math.isnan(v):
            assert math.isnan(back[k]), k
        else:
            assert back[k] == v and type(back[k]) is type(v), k


def test_result_row_derives_the_figures_from_1_2_and_the_margins() -> None:
    inputs = point(case="positioned", a_ndop=150.0, load_length=0.7)
    row = sr.result_row(
        inputs,
        {
            "feasible": True,
            "X": {"R_s": 0.4, "v": 2.0, "t1": 0.5, "R_z": 1.0},
            "W_t": 3600.0 * 2.0 / 2.2,
            "Delta_c": 2.2,
            "active": [11, 7],
            "margins": {"7": -0.35, "11": -12.5, "12": 3.5},
        },
    )
    # t_z = 2 t1 + |R_s| / v = 1.2 s; Delta = Delta_c - A_max; a_N = margin + a_Ndop
    assert row["t_z"] == pytest.approx(1.2)
    assert row["Delta"] == pytest.approx(2.2 - 0.7)
    assert row["accel"] == pytest.approx(137.5)
    assert row["exit_speed"] == pytest.approx(6.0)  # ydot_dop 2.5 + 3.5
    assert math.isnan(row["impact_speed"]) and math.isnan(row["m9"])  # (10), (9) not given
    assert row["active"] == "11 7"


# -- definitions -------------------------------------------------------------------------------
def test_definitions_follow_the_paper() -> None:
    fig6, fig7 = sd.get_sweep("fig6"), sd.get_sweep("fig7")
    for fig, cons in ((fig6, "7 8 11"), (fig7, "7 8 11 12")):
        assert len(fig.points) == 36
        assert sorted({p["alpha_k_deg"] for p in fig.points}) == list(range(20, 61, 5))
        assert len({p["a_ndop"] for p in fig.points}) == 4
        assert {(p["case"], p["constraints"], p["load_length"], p["load_width"])
                for p in fig.points} == {("positioned", cons, 0.7, 0.1)}  # fmt: skip
    keys = {sr.point_key(p) for p in fig6.points + fig7.points}
    assert len(keys) == 72  # the benchmark's 72 optima
    (fig4,) = {(p["alpha_k_deg"], p["w_dop"], p["fixed"], p["case"]) for p in
               sd.get_sweep("fig4").points}  # fmt: skip
    assert fig4 == (40.0, 2.4, "R_s=0.0 R_z=1.4", "arbitrary")
    assert {p["constraints"] for p in sd.get_sweep("fig3").points} == {"7 8 9 10"}
    # free falls from 0.1, 0.2, 0.3 (the paper's 2.4 m/s) and 0.5 m
    assert sd.W_DOP_LEVELS == (1.4, 2.0, 2.4, 3.1)
    lengths = {p["load_length"] for p in sd.get_sweep("fig10").points}
    assert {0.1, 1.2} <= lengths
    assert sd.get_sweep("fig9").run == "fig8"
    assert sw.parse_names("all") == [f"fig{i}" for i in range(3, 11)]


def test_nesting_check_flags_a_tighter_problem_with_a_higher_optimum() -> None:
    def rows_of(name):
        out = []
        for inputs in sd.get_sweep(name).points:
            row = stand_in(inputs)  # W_t grows with a_Ndop (t1 ~ a_Ndop^-1/2)
            if name == "fig7" and inputs["alpha_k_deg"] == 30.0 and inputs["a_ndop"] == 150.0:
                row["W_t"] *= 1.2  # with (12) on top, 20 % above the optimum without it
            out.append({**inputs, **row})
        return out

    pairs, bad = sw.nesting_violations(rows_of)
    assert pairs == 36 + 24 + 9 * 3 + 6 * 2 + 2 * (9 * 3) + 2 * (6 * 3)  # 189
    # the raised point beats fig6's at the same inputs (not yet fig7's own a_Ndop 300 one)
    assert bad == [
        "fig7 vs fig6 at alpha_k_deg 30, a_ndop 150: tighter "
        f"{rows_of('fig7')[2 * 9 + 2]['W_t']:.0f} > looser "
        f"{rows_of('fig6')[2 * 9 + 2]['W_t']:.0f} pcs/h",
    ]


def test_bad_sweep_name_exits_2_naming_the_allowed_names(capsys) -> None:
    args = argparse.Namespace(sweep="fig2", out=None, resume=True, workers=None, scheduler=None)
    assert sw.main(args) == 2
    err = capsys.readouterr().err
    assert "fig2" in err and "fig3" in err and "fig10" in err and "decision-table" in err


def test_plot_has_the_panels(tmp_path) -> None:
    rows = sw.run_sweep(fake_sweep(), tmp_path, SyncExecutor(), progress=False)
    png = sw.plot_sweep(fake_sweep(), rows, tmp_path / "fake.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# -- decision table ----------------------------------------------------------------------------
def test_finishing_the_decision_sweep_writes_the_table(tmp_path) -> None:
    rows, entries = _decision_rows(tmp_path, 2.0)
    fake = sd.SweepDef(
        "decision-table", "controller", "", "decision-fake", tuple(point(case=r["case"],
        load_length=r["load_length"], fixed=r["fixed"], constraints=r["constraints"])
        for r in rows), "load_length", "A", "case", "placement", (sd.P_T1,),
    )  # fmt: skip
    lines = sw.finish(fake, tmp_path, tmp_path / "table.yaml")
    assert lines[-1].endswith("4 load classes -> " + str(tmp_path / "table.yaml"))
    table = DecisionTable.load(tmp_path / "table.yaml")
    assert table.belt_speed == 2.0 and len(table.entries) == 4
    assert (tmp_path / "decision-table.png").exists()


def _decision_rows(tmp_path, v: float):
    """A small fake decision sweep CSV: positioned and arbitrary loads of 0.4 and 0.7 m."""
    entries = {
        ("positioned", 0.4): (0.1, 0.45),
        ("positioned", 0.7): (0.3, 0.55),  # off the planner's grid (R_s by 0.2 m)
        ("arbitrary", 0.4): (0.0, 0.65),
        ("arbitrary", 0.7): (-0.1, 0.85),
    }

    def solve(inputs):
        r_s, t1 = entries[(inputs["case"], inputs["load_length"])]
        d = pitch(v, t1, r_s, inputs["load_length"], 0.0)
        return sr.result_row(
            inputs,
            {
                "feasible": True,
                "X": {"R_s": r_s, "v": v, "t1": t1, "R_z": 1.2},
                "W_t": 3600 * v / d,
                "Delta_c": d,
                "margins": {},
            },
        )

    pts = tuple(
        point(case=c, load_length=a, fixed=f"v={v!r} R_z=1.2", constraints="7 8 9 10 11 12")
        for c, a in entries
    )
    fake = sd.SweepDef(
        "decision-fake", "controller", "", "decision-fake", pts, "load_length", "A", "case",
        "placement", (sd.P_T1,), solve=solve,
    )  # fmt: skip
    return sw.run_sweep(fake, tmp_path, SyncExecutor(), progress=False), entries


def test_decision_table_gives_the_planner_its_first_candidate(tmp_path) -> None:
    base = load_scene("positioned_stiff").scenario  # belt 2.0 m/s, stiff fence 1.2 m
    rows, entries = _decision_rows(tmp_path, base.conveyor.belt_speed)
    table = build_table(rows, source="fake")
    path = write_table(table, tmp_path / "decision_table.yaml")
    assert DecisionTable.load(path).lookup(0.5, 0.0, 0.0) == entries[("positioned", 0.7)]
    cfg = PlannerConfig.from_mapping({"decision_table": str(path)})
    planner = Planner(base, cfg)
    p = base.parcel  # 0.7 x 0.1 m at the border: positioned, A = 0.7 m
    plan = planner.plan(LoadRequest(1, p, 0.0, -3.0), now=0.0)
    assert (plan.tried[0].r_s, plan.tried[0].t1) == entries[("positioned", 0.7)]
    # a 0.3 m load 0.3 m off the border: the arbitrary class of the shortest A >= 0.3 m
    q = replace(p, length_a=0.3, lateral_gap=0.3, cog_offset_x=0.0, cog_offset_y=0.0)
    plan = planner.plan(LoadRequest(2, q, 5.0, -3.0), now=5.0)
    assert (plan.tried[0].r_s, plan.tried[0].t1) == entries[("arbitrary", 0.4)]
    # without a table the first candidate is the grid's best-W_t one
    plain = Planner(base, PlannerConfig()).plan(LoadRequest(1, p, 0.0, -3.0), now=0.0)
    assert (plain.tried[0].r_s, plain.tried[0].t1) != entries[("positioned", 0.7)]


def test_decision_table_for_another_belt_speed_or_a_bad_file_is_refused(tmp_path) -> None:
    base = load_scene("positioned_stiff").scenario
    rows, _ = _decision_rows(tmp_path, 1.0)
    path = write_table(build_table(rows), tmp_path / "t.yaml")
    with pytest.raises(ParameterError, match="decision_table.*belt speed 1 m/s"):
        Planner(base, PlannerConfig(decision_table=str(path)))
    (tmp_path / "bad.yaml").write_text("decision_table: {alpha_k_deg: 40}\n")
    with pytest.raises(ParameterError, match="not a decision table"):
        Planner(base, PlannerConfig(decision_table=str(tmp_path / "bad.yaml")))
    with pytest.raises(ParameterError, match="decision_table must be a file path"):
        PlannerConfig.from_mapping({"decision_table": 3})


# -- nesting repair ----------------------------------------------------------------------------
def _write_run(path, name, lower=None, factor=1.0):
    """The stand-in optima of sweep ``name`` as its CSV; the point ``lower`` (inputs subset)
    with W_t scaled by ``factor`` (an optimiser miss)."""
    with sr.RowWriter(path / f"{sd.get_sweep(name).run}.csv") as w:
        for inputs in sd.get_sweep(name).points:
            row = stand_in(inputs)
            if lower and all(inputs[k] == v for k, v in lower.items()):
                row["W_t"] *= factor
            w.write({"key": sr.point_key(inputs), **inputs, **row})


def test_nesting_repair_restarts_the_looser_problem_from_the_tighter_optimum(
    tmp_path, monkeypatch
) -> None:
    """fig6 (no (12)) at alpha_k 30 deg, a_Ndop 150 missed its optimum by half, below fig7's
    (with (12)) and below its own tighter a_Ndop 50 neighbour. The repair re-solves it once,
    starting from both tighter optima, appends the row naming them, and then nothing is out
    of order; a second repair does nothing."""
    miss = {"alpha_k_deg": 30.0, "a_ndop": 150.0}
    _write_run(tmp_path, "fig6", miss, 0.5)
    _write_run(tmp_path, "fig7")
    calls = []

    def solve_point(inputs, starts=(), started_from=""):
        calls.append((dict(inputs), list(starts), started_from))
        return {**stand_in(inputs), "started_from": started_from}  # the true optimum

    monkeypatch.setattr(sw, "solve_point", solve_point)

    def rows_of(name):
        return sw._order(sd.get_sweep(name), sr.read_rows(sw._csv(tmp_path, name)))

    assert len(sw.nesting_violations(rows_of)[1]) == 2
    # a repair of other runs leaves fig6 alone (a --sweep fig7 does not rewrite fig6.csv)
    assert sw.repair_nesting(tmp_path, SyncExecutor(), runs={"fig7"}) == (0, set())
    assert calls == []
    solved, changed = sw.repair_nesting(tmp_path, SyncExecutor(), runs={"fig6", "fig7"})
    assert (solved, changed) == (1, {"fig6"})
    ((inputs, starts, started_from),) = calls
    assert {k: inputs[k] for k in miss} == miss and inputs["constraints"] == sd.C_POS
    tight = {
        r["key"]: r
        for name, a_ndop in (("fig7", 150.0), ("fig6", 50.0))
        for r in rows_of(name)
        if r["alpha_k_deg"] == 30.0 and r["a_ndop"] == a_ndop
    }
    assert sorted(started_from.split()) == sorted(tight)
    assert sorted(s["t1"] for s in starts) == sorted(r["t1"] for r in tight.values())
    assert sw.nesting_violations(rows_of)[1] == []
    fixed = [r for r in rows_of("fig6") if r["alpha_k_deg"] == 30.0 and r["a_ndop"] == 150.0]
    assert fixed[0]["started_from"] == started_from
    assert sw.repair_nesting(tmp_path, SyncExecutor()) == (0, set())


def test_a_csv_from_before_started_from_is_read_and_migrated(tmp_path) -> None:
    _write_run(tmp_path, "fig6")
    path = tmp_path / "fig6.csv"
    lines = path.read_text().splitlines()
    old = "\n".join(line.rsplit(",", 1)[0] for line in lines) + "\n"  # drop the last column
    path.write_text(old)
    rows = sr.read_rows(path)
    assert len(rows) == len(sd.get_sweep("fig6").points)
    assert all(r["started_from"] == "" for r in rows)
    assert path.read_text() == old  # reading alone changes nothing
    assert _strip(sr.read_rows(path, repair=True)) == _strip(rows)
    assert path.read_text().splitlines()[0].split(",") == list(sr.COLUMNS)
    assert _strip(sr.read_rows(path)) == _strip(rows)


@pytest.mark.slow
def test_infeasible_points_are_drawn_apart_from_every_value(tmp_path, monkeypatch) -> None:
    """decision-table.csv has points with no feasible optimum; R_s = 0 would be a real value,
    so their crosses sit in a band above every value (axes coordinates), none at y = 0."""
    from pathlib import Path

    from matplotlib.figure import Figure

    figures = []
    save = Figure.savefig

    def keep(fig, *args, **kwargs):
        figures.append(fig)
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    sweep = sd.get_sweep("decision-table")
    csv = Path(__file__).resolve().parents[2] / "docs" / "reports" / "paper" / "decision-table.csv"
    rows = sw._order(sweep, sr.read_rows(csv))
    infeasible = sum(not r["feasible"] for r in rows)
    assert infeasible > 0
    sw.plot_sweep(sweep, rows, tmp_path / "table.png")
    (fig,) = figures
    panels = [ax for ax in fig.axes if ax.has_data()]
    assert len(panels) == len(sweep.panels)
    for ax in panels:
        lo, hi = ax.get_ylim()
        band = lo + (hi - lo) * (1.0 - sw.INFEASIBLE_BAND)
        crosses = [ln for ln in ax.lines if ln.get_marker() == "x"]
        assert sum(len(ln.get_xdata()) for ln in crosses) == infeasible
        for ln in crosses:
            assert ln.get_transform() != ax.transData
            assert set(ln.get_ydata()) == {1.0 - 0.5 * sw.INFEASIBLE_BAND}
        values = [y for ln in ax.lines if ln.get_marker() == "o" for y in ln.get_ydata()]
        finite = [y for y in values if math.isfinite(y)]
        assert finite and max(finite) < band and min(finite) >= lo
    title = fig.texts[0].get_text() if fig.texts else fig._suptitle.get_text()
    assert "controller: controller" not in title and title.startswith("Decision table")


@pytest.mark.slow
def test_plots_only_redraws_from_the_saved_results(tmp_path, capsys):
    """`python -m benchmarks paper-sweep NAME --plots-only --out DIR`: the figure from the
    committed CSV, nothing solved; a missing CSV is exit 2 naming it."""
    paper = Path(__file__).resolve().parents[2] / "docs" / "reports" / "paper"
    shutil.copy(paper / "fig8.csv", tmp_path / "fig8.csv")
    argv = ["paper-sweep", "fig9", "--plots-only", "--out", str(tmp_path)]
    assert cli_main.main(argv) == 0
    assert (tmp_path / "fig9.png").stat().st_size > 10_000
    assert not (tmp_path / "fig8.png").exists()  # only what was asked for
    assert cli_main.main(["paper-sweep", "fig6", "--plots-only", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fig6.csv" in err[0]
    assert cli_main.main(["paper-sweep", "fig99", "--out", str(tmp_path)]) == 2
    assert "fig99" in capsys.readouterr().err
