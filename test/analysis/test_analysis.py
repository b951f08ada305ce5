"""Analysis and Rerun views of a recorded run, without ROS: the committed example bag (recorded
with `fence-sorter run --parcels 4 --bag bags/example_4_parcels`), damaged copies of it, and
the Rerun logger driven by the line's snapshots."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from collections import Counter
from dataclasses import astuple
from pathlib import Path

import numpy as np
import pytest
from bag_edit import rewrite_bag
from processes import run_cli

from fence_sorter.analysis import analyze_bag
from fence_sorter.analysis.run import (
    Series,
    check_row,
    crossing,
    load_run,
    parcel_table,
    sampled_exit_speed,
)
from fence_sorter.recording.bagread import read_bag
from fence_sorter.stamps import time_to_sec
from fence_sorter.visualisation import rerun_layout as layout
from fence_sorter.visualisation import rerun_log as rl

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "bags" / "example_4_parcels"


@pytest.fixture(scope="module")
def example() -> Path:
    assert (EXAMPLE / "metadata.yaml").is_file(), f"{EXAMPLE} missing"
    return EXAMPLE


@pytest.mark.slow
def test_example_bag_analysis_agrees_with_the_live_outcomes(example, tmp_path):
    report = analyze_bag(example, tmp_path)
    assert report.issues == []
    s = report.summary
    live = {m.msg.parcel_id: m.msg for m in read_bag(example, ["/sort_outcomes"]).messages}
    scanned = read_bag(example, ["/parcels"]).messages
    assert len(report.rows) == len(scanned) == len(live) >= 3
    for row in report.rows:
        o = live[row["parcel_id"]]
        assert row["sorted"] == o.sorted
        assert row["sampled_sorted"] == o.sorted  # derived from the states alone
        assert row["agrees"] is True, row["disagreements"]
        if o.sorted:
            assert row["sampled_exit_speed_mps"] == pytest.approx(o.exit_speed_y, rel=0.06)
            assert row["sampled_peak_N_stiff"] <= o.peak_normal_force_stiff * 1.001
    assert s["agrees_with_live"] is True
    assert s["sorted_divert"] == sum(1 for o in live.values() if o.sorted)
    assert s["divert"] >= s["sorted_divert"] > 0
    assert 0 < s["throughput_pcs_h"] < 20000
    names = set(report.files)
    assert {"parcels.csv", "analysis.json", "trajectories.png"} <= names
    stroked = [o for o in live.values() if math.isfinite(o.peak_normal_force)]
    assert sum(1 for n in names if n.startswith("parcel_")) == len(stroked) > 0
    csv_lines = (tmp_path / "parcels.csv").read_text().splitlines()
    assert len(csv_lines) == 1 + len(live)
    assert csv_lines[0].startswith("parcel_id,divert,sorted,reason")
    data = json.loads((tmp_path / "analysis.json").read_text())
    assert data["summary"]["agrees_with_live"] is True


@pytest.mark.slow
def test_analyze_cli_json_and_exit_codes(example, tmp_path):
    out = run_cli("analyze", str(example), "--json", "--no-plots", "--out", str(tmp_path / "a"))
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    ids = [p["parcel_id"] for p in data["parcels"]]
    assert ids == sorted(ids) and len(ids) == len(read_bag(example, ["/parcels"]).messages)
    assert all(p["agrees"] is True for p in data["parcels"])
    bad = run_cli("analyze", str(tmp_path / "nope"))
    assert bad.returncode == 2 and "nope: no such bag" in bad.stderr


@pytest.mark.slow
def test_truncated_bag_reports_the_file_and_analyses_the_rest(example, tmp_path):
    bag = tmp_path / "bag"
    shutil.copytree(example, bag)
    segs = sorted(bag.glob("*.mcap"))
    assert len(segs) >= 2, "the example bag should have several segments"
    last = segs[-1]
    last.write_bytes(last.read_bytes()[:200])  # cut inside its first chunk
    out = run_cli("analyze", str(bag), "--no-plots", "--out", str(tmp_path / "a"))
    assert out.returncode == 1
    assert f"{last}: damaged or truncated at byte" in out.stderr
    assert "BAG PROBLEM" in out.stdout and "SORTED" in out.stdout  # still a table
    full = read_bag(example).counts()
    part = read_bag(bag).counts()
    assert 0 < sum(part.values()) < sum(full.values())


def test_outcome_without_its_parcel_message_is_flagged(example, tmp_path):
    """The bag lost parcel 1's /parcels message (the scanner started before the recorder was
    matched): its outcome and its command have no parcel. analyze names it and exits 1, where
    it used to report 2 of 2 diverted and 2400 pcs/h with exit 0."""
    bag = tmp_path / "lost_parcel_1"
    assert rewrite_bag(example, bag, lambda m: m.topic == "/parcels" and m.msg.parcel_id == 1)
    assert 1 not in {m.msg.parcel_id for m in read_bag(bag, ["/parcels"]).messages}
    assert 1 in {m.msg.parcel_id for m in read_bag(bag, ["/sort_outcomes"]).messages}
    out = run_cli("analyze", str(bag), "--json", "--no-plots")
    assert out.returncode == 1, out.stderr
    summary = json.loads(out.stdout)["summary"]
    assert summary["outcomes_without_parcel"] == [1]
    assert summary["commands_without_parcel"] == [1]
    assert "outcome of parcel(s) [1] without their /parcels message" in out.stderr
    assert "command of parcel(s) [1] without their /parcels message" in out.stderr
    text = run_cli("analyze", str(bag), "--no-plots")
    assert text.returncode == 1 and "INCOMPLETE: outcome of parcel(s) [1]" in text.stdout
    # the whole bag: nothing flagged
    whole = json.loads(run_cli("analyze", str(example), "--json", "--no-plots").stdout)
    assert whole["summary"]["outcomes_without_parcel"] == []
    assert whole["summary"]["commands_without_parcel"] == []


def test_crossing_is_extrapolated_from_the_last_samples():
    t = np.array([0.0, 0.01, 0.02])
    vy = np.array([1.2, 1.1, 1.0])
    y = np.array([0.67, 0.681, 0.691])
    z = np.zeros(3)
    s = Series(t, z, z, y, z, z, vy, z, z, z, z)
    tc, v = crossing(s, 0.7, 0.01)
    # 0.009 m at 1 m/s, decelerating at 10 m/s^2: tau = (v - sqrt(v^2 - 2 a d)) / a
    tau = (1.0 - math.sqrt(1.0 - 2.0 * 10.0 * 0.009)) / 10.0
    assert tc == pytest.approx(0.02 + tau)
    assert v == pytest.approx(1.0 - 10.0 * tau)
    # 0.109 m away: it stops after v^2 / (2 a) = 0.05 m, whatever the window
    assert crossing(s, 0.8, 0.01, math.inf) is None
    # 0.029 m away: it crosses after 0.035 s, past the next snapshot (0.01 s) and half a period
    assert crossing(s, 0.72, 0.01) is None


def _samples(period: float, y_last: float, vy_last: float, ay: float, n: int = 2) -> Series:
    """Samples every ``period`` of a parcel at constant lateral acceleration ``ay`` whose last
    one is at (y_last, vy_last)."""
    t = period * np.arange(n, dtype=float)
    tau = t - t[-1]
    z = np.zeros(n)
    y = y_last + vy_last * tau + 0.5 * ay * tau**2
    return Series(t, z + 2, z, y, z, z, vy_last + ay * tau, z, z, z, z)


def test_a_parcel_the_fence_pushes_over_the_edge_crosses_at_its_acceleration():
    """Hit between two samples (at rest on the belt, then 1 m/s: 50 m/s^2, a_N within
    a_Ndop = 300 m/s^2), the parcel 0.025 m from y0 = s crosses while the fence still pushes
    it: at tau = (sqrt(v^2 + 2 a d) - v) / a, before the next snapshot, faster than 1 m/s."""
    period, d, a = 0.02, 0.025, 50.0
    s = _samples(period, 0.7 - d, 1.0, a)
    tc, v = crossing(s, 0.7, period)
    tau = (math.sqrt(1.0 + 2.0 * a * d) - 1.0) / a
    assert tc == pytest.approx(s.t[-1] + tau) and tau < period
    assert v == pytest.approx(1.0 + a * tau) and v == pytest.approx(math.sqrt(1.0 + 2 * a * d))


def test_an_exit_speed_extrapolated_from_a_pushed_sample_is_not_a_measurement():
    """The crossing of a parcel whose last sample the fence still pushes (N > 0) is found, but
    its exit speed is not taken from it: the push up to the release is not in the states. A
    released last sample (N = 0) or a sample past the edge gives it."""
    period, d, a = 0.02, 0.025, 50.0
    s = _samples(period, 0.7 - d, 1.0, a)
    cross = crossing(s, 0.7, period)
    assert cross is not None
    assert sampled_exit_speed(s, cross, 0.7) == pytest.approx(cross[1])  # released: N = 0
    s.n[-1] = 150.0
    assert math.isnan(sampled_exit_speed(s, cross, 0.7))
    past = _samples(period, 0.71, 1.0, a, n=3)  # the last sample is past the edge
    past.n[:] = 150.0
    cross = crossing(past, 0.7, period)
    assert sampled_exit_speed(past, cross, 0.7) == pytest.approx(cross[1])


def test_a_skipped_snapshot_widens_the_window_of_the_crossing():
    """Released, sliding on the belt (a_y = -5 m/s^2 of friction), the parcel crosses 1.8
    periods after its last sample; the snapshot after it went out 2 periods later (one
    skipped), so it left the line in between."""
    period = 0.02
    tau = 1.8 * period
    d = 1.0 * tau - 0.5 * 5.0 * tau**2
    s = _samples(period, 0.7 - d, 1.0, -5.0, n=4)
    assert crossing(s, 0.7, period) is None  # no snapshot skipped: it would have been seen
    tc, v = crossing(s, 0.7, period, s.t[-1] + 2 * period)
    assert tc == pytest.approx(s.t[-1] + tau) and v == pytest.approx(1.0 - 5.0 * tau)


#: the topics load_run reads
RUN_TOPICS = [
    "/parcels", "/fence_commands", "/sort_outcomes", "/sort_events", "/load_states",
    "/fence_state", "/markers", "/diagnostics",
]  # fmt: skip


def test_a_snapshot_skipped_before_the_crossing_leaves_the_parcel_sorted(example):
    """The example run without its snapshot at 9.02 s, the last with parcel 1 on the line
    (15 ms before it crossed y0 = s), as a paced loop that slips skips one: the parcel left the
    line between its sample at 9.00 s and the next snapshot at 9.04 s, and decelerating on the
    belt from there it crosses 35 ms on, inside that window; the states say sorted, as live."""
    t_skipped = 9_020_000_000
    contents = read_bag(example, RUN_TOPICS)
    contents.messages = [m for m in contents.messages if m.t_ns != t_skipped]
    run = load_run(contents)
    assert run.series[1].t[-1] == pytest.approx(9.0)
    row = next(r for r in parcel_table(run) if r["parcel_id"] == 1)
    assert row["sampled_sorted"] and row["sorted"], row["disagreements"]
    assert row["agrees"], row["disagreements"]


def test_check_row_flags_contradictions():
    outcome = dict(
        sorted=True, peak_normal_force=300.0, peak_normal_force_stiff=700.0,
        peak_normal_accel=100.0, exit_speed_y=1.0, time_in_working_space=1.0,
    )  # fmt: skip
    row = dict(
        samples=10, sampled_sorted=True, sampled_peak_N=200.0, sampled_peak_N_stiff=700.0,
        sampled_peak_accel_mps2=50.0, sampled_exit_speed_mps=1.01, sampled_time_in_ws_s=1.005,
    )  # fmt: skip
    assert check_row(row, outcome, 0.01) == []
    assert len(check_row({**row, "sampled_sorted": False}, outcome, 0.01)) == 1
    assert "exceeds the live peak" in check_row({**row, "sampled_peak_N": 400.0}, outcome, 0.01)[0]
    assert "exit speed" in check_row({**row, "sampled_exit_speed_mps": 1.3}, outcome, 0.01)[0]
    assert (
        "time in working space"
        in check_row({**row, "sampled_time_in_ws_s": 1.1}, outcome, 0.01)[0]
    )


# -- Rerun ---------------------------------------------------------------------------------------
def rrd_rows(path: Path) -> tuple[Counter, Counter]:
    """(rows per entity on the timeline, static entities) read back with Rerun's RrdReader."""
    from rerun.chunk import RrdReader

    rows, static = Counter(), Counter()
    for chunk in RrdReader(path).stream():
        (static if chunk.is_static else rows)[chunk.entity_path] += chunk.num_rows
    return rows, static


TOP_MOVING = ("/top/fence", "/top/parcels", "/top/contact_forces")


def blueprint_views(path: Path) -> dict[str, tuple[str, dict | None]]:
    """The default blueprint stored in an .rrd: view name -> (kind, 2D visual bounds)."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    (store,) = reader.blueprints()
    views: dict[str, dict] = {}
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        key = chunk.entity_path.split("/")[2] if chunk.entity_path.startswith("/view/") else None
        if key is None:
            continue
        for column in batch.schema.names:
            if column.startswith(("ViewBlueprint:", "VisualBounds2D:")):
                views.setdefault(key, {})[column] = batch.column(column).to_pylist()[0]
    out = {}
    for v in views.values():
        if "ViewBlueprint:display_name" in v:
            bounds = v.get("VisualBounds2D:range")
            out[v["ViewBlueprint:display_name"][0]] = (
                v["ViewBlueprint:class_identifier"][0],
                v["ViewBlueprint:space_origin"][0],
                bounds[0] if bounds else None,
            )
    return out


def blueprint_axes(path: Path) -> dict[str, dict[str, object]]:
    """Per time-series view name: its TimeAxis link and view range, its ScalarAxis range and
    whether it shows a legend, as stored."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    (store,) = reader.blueprints()
    names, link, y_range, x_range, legend = {}, {}, {}, {}, {}
    for chunk in reader.stream(store=store):
        parts = chunk.entity_path.split("/")
        if len(parts) < 3 or parts[1] != "view":
            continue
        batch = chunk.to_record_batch()
        cols = batch.schema.names
        if "ViewBlueprint:display_name" in cols:
            names[parts[2]] = batch.column("ViewBlueprint:display_name").to_pylist()[0][0]
        if "TimeAxis:link" in cols:
            link[parts[2]] = batch.column("TimeAxis:link").to_pylist()[0][0]
        if "TimeAxis:view_range" in cols:
            x_range[parts[2]] = batch.column("TimeAxis:view_range").to_pylist()[0][0]
        if "PlotLegend:visible" in cols:
            legend[parts[2]] = batch.column("PlotLegend:visible").to_pylist()[0][0]
        if "ScalarAxis:range" in cols:
            y_range[parts[2]] = batch.column("ScalarAxis:range").to_pylist()[0][0]
    return {
        "time_link": {names[k]: v for k, v in link.items()},
        "y_range": {names[k]: v for k, v in y_range.items()},
        "x_range": {names[k]: v for k, v in x_range.items()},
        "legend": {names[k]: v for k, v in legend.items()},
    }


@pytest.mark.slow
def test_damage_colours_and_the_logged_event(tmp_path):
    """A parcel's outline keeps the outcome scheme's colour (to divert) once its event is
    logged; its damage margin (green with room to spare, red over a limit) colours its damage
    mark; the event's curves go in at full rate."""
    from fence_sorter.analysis.events import SortEventData
    from fence_sorter.visualisation.rerun_log import (
        MARGIN_COLORS,
        MARGIN_RANGE,
        ParcelFrame,
        RerunLogger,
        SceneGeometry,
        margin_color,
        open_recording,
    )

    assert margin_color(MARGIN_RANGE[0] - 1.0) == MARGIN_COLORS[0]
    assert margin_color(MARGIN_RANGE[1] + 1.0) == MARGIN_COLORS[-1]
    mid = 0.5 * (MARGIN_RANGE[0] + MARGIN_RANGE[1])
    assert margin_color(mid) == MARGIN_COLORS[1]
    out = tmp_path / "event.rrd"
    logger = RerunLogger(open_recording(out), SceneGeometry(0.7))
    frame = ParcelFrame(3, 0, 0, 0, 0, 0, 0, 0, 0.4, 0.3, 0.3, divert=True)
    before = logger._color(frame)
    t = np.linspace(1.0, 1.2, 101)
    ev = SortEventData(
        3, 1.3, 1.0, 15.0, t, np.zeros(101, np.uint8), np.ones(101, np.int64),
        np.sin(np.pi * (t - 1.0) / 0.2), t, t, t, t, t, t, t, t, t, np.array([1.0]),
        np.array([2.0]), np.array([5.0]), t[:50], t[:50],
    )  # fmt: skip
    risk = {"w_dop": 2.4, "a_ndop": 300.0, "impact_speed_margin": -0.2, "accel_margin": 0.5,
            "drop_height": 0.2}  # fmt: skip
    logger.log_event(ev, risk)
    assert before == logger._color(frame) == rl.PARCEL_COLORS["to divert"]
    assert logger._risk_marks[3][0] == margin_color(-0.2)
    logger.close()
    rows, static = rrd_rows(out)
    assert rows["/plots/contact/3/N_steps"] == 101 == rows["/plots/fence/tip_deflection/steps/3"]
    assert rows["/plots/contact/3/N_stiff_course"] == 50
    assert rows["/damage/w_n/value"] == rows["/damage/a_N/limit"] == 1
    assert rows["/top/damage_risk"] == rows["/top/damage_risk_labels"] == 1  # its mark
    assert rows["/risk/w_n"] == rows["/risk/a_N"] == rows["/risk/parcels"] == 1  # the chart


def test_top_view_footprints_are_the_rotated_boxes():
    from fence_sorter.visualisation.rerun_log import ParcelFrame, _footprints

    def parcel(yaw):
        return ParcelFrame(1, 0, 0, yaw, 0, 0, 1.0, 0.5, 0.4, 0.3, 0.2)

    flat, turned = _footprints([parcel(0.0), parcel(math.pi / 2)])
    for fp in (flat, turned):
        assert np.allclose(fp[0], fp[-1])  # closed
        x, y = fp[:, 0], fp[:, 1]
        area = 0.5 * abs(np.dot(x[:-1], y[1:]) - np.dot(x[1:], y[:-1]))
        assert area == pytest.approx(0.4 * 0.3)  # a x b
        assert np.allclose(fp[:-1].mean(axis=0), (1.0, -0.5))  # centre, y negated (view)
    assert np.ptp(flat[:, 0]) == pytest.approx(0.4) and np.ptp(flat[:, 1]) == pytest.approx(0.3)
    assert np.ptp(turned[:, 0]) == pytest.approx(0.3)  # a quarter turn swaps the extents
    yaw = 0.3  # yaw counter-clockwise in the sorter frame: clockwise with y negated
    (fp,) = _footprints([parcel(yaw)])
    edge = fp[1] - fp[0]  # from the (+a/2, +b/2) corner to (-a/2, +b/2): along -a
    assert math.atan2(-edge[1], -edge[0]) == pytest.approx(-yaw)
    assert _footprints([]).shape == (0, 5, 2)


@pytest.mark.slow
def test_rerun_full_check_accepts_the_example_bag(example):
    """The committed bag as Rerun's MCAP loader sees it: every topic ok, header stamps
    (ros2_timestamp) decoded and in the same order as the log times."""
    import os

    for segment in sorted(example.glob("*.mcap")):
        out = subprocess.run(
            [sys.executable, "-m", "rerun", "mcap", "check", "--full", str(segment)],
            capture_output=True, text=True, timeout=120,
            env={**os.environ, "RERUN_ANALYTICS_ENABLED": "false"},
        )  # fmt: skip
        assert out.returncode == 0, out.stderr
        assert "ros2_timestamp" in out.stdout
        table = [x for x in out.stdout.splitlines() if x.startswith(("ok", "PROBLEM"))]
        assert table and all(x.startswith("ok") for x in table), out.stdout


@pytest.mark.slow
def test_rrd_from_the_example_bag(example, tmp_path):
    out = tmp_path / "run.rrd"
    res = run_cli("rrd", str(example), "--out", str(out))
    assert res.returncode == 0, res.stderr
    verify = subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "verify", str(out)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert verify.returncode == 0, verify.stderr
    contents = read_bag(example)
    counts = contents.counts()
    rows, static = rrd_rows(out)
    # the scene up to the last outcome (the fence at rest right after it), and a last frame
    # at that instant: the recorder's later fence states are left out
    t_end = max(time_to_sec(m.msg.header.stamp) for m in contents.by_topic("/sort_outcomes"))
    states = sorted((time_to_sec(m.msg.header.stamp), m.msg.drive_angle)
                    for m in contents.by_topic("/fence_state"))  # fmt: skip
    assert abs(next(a for t, a in states if t > t_end)) < 1e-3
    frames = sum(t <= t_end for t, _ in states) + 1
    assert frames < counts["/fence_state"]
    for entity in ("/world/fence", "/world/parcels", "/world/contact_forces",
                   "/plots/fence/tip_deflection", "/plots/fence/alpha_w"):  # fmt: skip
        assert rows[entity] == frames, entity
    assert {"/world/conveyor/belt", "/world/chute", "/world/scan_line"} <= set(static)
    for entity in TOP_MOVING:  # the top view's 2D entities, one row per frame as the 3D ones
        assert rows[entity] == frames, entity
    assert {"/top/conveyor/belt", "/top/conveyor/borders", "/top/chute", "/top/scan_line"} <= set(
        static
    )
    views = blueprint_views(out)
    kinds = sorted(kind for kind, _, _ in views.values())
    assert kinds == ["2D", "2D", "3D"] + ["TimeSeries"] * 7, views
    # alpha_w and the tip deflection on plots of their own, with units; every plot shows the
    # whole timeline (one range for all: one instant at one x position), no legend
    by_origin = {v[1]: n for n, v in views.items()}
    assert "[cm]" in by_origin["plots/fence/tip_deflection"]
    assert by_origin["plots/fence/alpha_w"] == "drive angle alpha_w [rad]"
    axes = blueprint_axes(out)
    plots = sorted(n for n, v in views.items() if v[0] == "TimeSeries")
    assert sorted(axes["time_link"]) == plots == sorted(axes["x_range"])
    assert set(axes["time_link"].values()) == {1}  # LinkAxis.Independent: its own view_range
    # from the first instant to 3 % past the last (the cursor at the end drawn whole)
    end = round((1.0 + layout.TIME_END_MARGIN) * t_end * 1e9)
    assert all(r["start"] is None and abs(r["end"] - end) <= 1 for r in axes["x_range"].values())
    assert axes["legend"] == dict.fromkeys(plots, False)
    # fixed y ranges with single-digit tick labels on every time series plot (one plot area)
    assert axes["y_range"] == {
        by_origin["damage/w_n"]: list(layout.DAMAGE_SPEED_AXIS),
        by_origin["damage/a_N"]: list(layout.DAMAGE_ACCEL_AXIS),
        by_origin["damage/N"]: list(layout.DAMAGE_FORCE_AXIS),
        by_origin["plots/contact"]: list(rl.CONTACT_AXIS),
        by_origin["plots/fence/tip_deflection"]: list(rl.DEFLECTION_AXIS),
        by_origin["plots/fence/alpha_w"]: list(rl.ALPHA_AXIS),
        by_origin["plots/speed"]: list(rl.SPEED_AXIS),
    }
    for lo, hi in axes["y_range"].values():  # whole-number ticks from 0 to at most 9
        assert -1.0 < lo < 0.0 and 2.0 <= hi < 10.0, (lo, hi)
    kind, origin, bounds = views[layout.TOP_VIEW_NAME]
    assert (kind, origin) == ("2D", "top")
    # framed on the bag's scene: belt x -3 .. 3 m, chute up to y0 = 1.3 m (view y = -1.3)
    (x0, x1), (y0, y1) = bounds["x_range"], bounds["y_range"]
    assert x0 < -3.0 and x1 > 3.0 and y0 < -1.3 and 0.0 < y1
    per_parcel = Counter(m.msg.parcel_id for m in contents.by_topic("/load_states"))
    for pid, n in per_parcel.items():
        assert rows[f"/plots/speed/{pid}"] == n
    contact = Counter(
        m.msg.parcel_id for m in contents.by_topic("/load_states") if 1 <= m.msg.stage <= 4
    )
    for pid, n in contact.items():
        assert rows[f"/plots/contact/{pid}/N"] == n == rows[f"/plots/contact/{pid}/N_stiff"]
    assert rows["/events/outcomes"] == counts["/sort_outcomes"]


@pytest.mark.slow
def test_logger_from_line_snapshots(tmp_path):
    from fence_sorter.line import LineConfig, ParcelSpec, SortingLine, StrokeCommand
    from fence_sorter.scene import load_scene
    from fence_sorter.visualisation.rerun_log import (
        RerunLogger,
        SceneGeometry,
        frames_from_snapshot,
        open_recording,
    )

    line = SortingLine(LineConfig.from_scenario(load_scene("impact_flexible").scenario))
    line.add_parcel(ParcelSpec(7, lateral_gap=0.25, divert=True, scan_position_x=-1.0))
    line.add_parcel(ParcelSpec(8, lateral_gap=0.1, divert=False, scan_position_x=-2.5))
    line.command(StrokeCommand(7, r_s=0.42, t1=0.35, alpha_k=math.radians(40.0)))
    out = tmp_path / "live.rrd"
    logger = RerunLogger(open_recording(out), SceneGeometry(0.7, (-3.0, 3.0), None, -3.0))
    frames = 0
    for k in range(1, 101):  # 2 s at 50 Hz
        line.advance(0.02 * k)
        fence, parcels = frames_from_snapshot(line.snapshot())
        logger.log_frame(line.t, fence, parcels)
        frames += 1
    logger.close()
    rows, static = rrd_rows(out)
    assert rows["/world/fence"] == rows["/world/parcels"] == frames
    assert all(rows[e] == frames for e in TOP_MOVING)
    assert rows["/plots/speed/8"] == frames  # parcel 8 stays on the belt the whole time
    assert 0 < rows["/plots/contact/7/N"] < frames  # only while the fence works on it
    assert "/world/chute" not in static and "/world/scan_line" in static
    assert "/top/chute" not in static and "/top/scan_line" in static


@pytest.mark.slow
def test_rerun_child_process_logs_what_the_loop_offers(tmp_path):
    from fence_sorter.line import LineConfig, ParcelSpec, SortingLine
    from fence_sorter.scene import load_scene
    from fence_sorter.visualisation.rerun_live import RerunProcess, pack_snapshot, unpack_frame
    from fence_sorter.visualisation.rerun_log import SceneGeometry, frames_from_snapshot

    line = SortingLine(LineConfig.from_scenario(load_scene("impact_flexible").scenario))
    line.add_parcel(ParcelSpec(5, lateral_gap=0.1, divert=True, scan_position_x=-2.5))
    line.advance(0.1)
    snap = line.snapshot()
    t, fence, parcels = unpack_frame(pack_snapshot(snap)[5:])  # past the 5-byte header
    ref_fence, ref_parcels = frames_from_snapshot(snap)
    assert t == snap.t and len(parcels) == len(ref_parcels) == 1
    np.testing.assert_equal(astuple(parcels[0]), astuple(ref_parcels[0]))  # NaN == NaN here
    assert np.array_equal(fence.node_x, ref_fence.node_x)
    out = tmp_path / "child.rrd"
    scene = SceneGeometry(0.7, (-3.0, 3.0), (0.75, 1.0, 1.5, 0.6), -3.0)
    proc = RerunProcess(scene, out, lossless=True)
    for k in range(2, 42):
        line.advance(0.05 * k)
        for _ in range(1000 if k == 2 else 1):  # ~300 kB at once, beyond the pipe: waits
            proc.offer(line.snapshot())
    proc.event(line.t, "parcel 5: test", ok=False)
    assert proc.close() == 0
    assert proc.sent == 1040 and proc.dropped == 0
    rows, static = rrd_rows(out)
    assert rows["/world/parcels"] == rows["/plots/speed/5"] == 1039
    assert all(rows[e] == 1039 for e in TOP_MOVING)
    assert blueprint_views(out)[layout.TOP_VIEW_NAME][:2] == ("2D", "top")
    assert rows["/events/outcomes"] == 1
    assert "/world/chute" in static


def test_damage_marks_and_the_3d_eye_frame_the_scene():
    """The top view's damage marks sit in a grid under the belt, one label width apart, none
    on another, the first rows inside the view's bounds; the 3D eye looks at the middle of
    belt and chute from the fence side, from above, farther than the belt is long (the
    browser test's 3D screenshot shows the whole belt)."""

    scene = rl.SceneGeometry(0.7, (-3.0, 3.0), (0.5, 1.0, 1.6, 0.6), -3.0)
    n = rl.RISK_MARKS_PER_ROW * rl.RISK_ROWS_FRAMED
    marks = np.array([rl.risk_mark_position(scene, k) for k in range(n + 5)])
    assert len({tuple(m) for m in marks}) == len(marks)
    step = (scene.belt_x[1] - scene.belt_x[0]) / rl.RISK_MARKS_PER_ROW
    first_row = marks[: rl.RISK_MARKS_PER_ROW, 0]
    assert np.allclose(np.diff(first_row), step) and np.all(marks[:, 1] > 0.0)  # under the belt
    (x0, x1), (y0, y1) = rl.top_view_bounds(scene)
    inside = marks[:n]
    assert np.all((inside[:, 0] > x0) & (inside[:, 0] + step < x1 + 1e-9) & (inside[:, 1] < y1))
    target = np.array(rl.camera_target(scene))
    eye = np.array(rl.camera_position(scene))
    assert target[0] == pytest.approx(0.0) and target[1] == pytest.approx(0.65)  # y 0 .. 1.3
    assert eye[1] < 0.0 < eye[2]
    distance = np.linalg.norm(eye - target)
    assert distance > scene.belt_x[1] - scene.belt_x[0]
