"""Full-rate sorting events of a real 20-parcel run (`fence-sorter run --bag --rrd`, unpaced):
the bag's /sort_events reproduce the live /sort_outcomes peaks for every parcel, every outcome
carries its damage margins and drop height as the closed forms give them, `analyze` draws
Fig. 11c/12c and the damage-risk plot from the bag, and the live Rerun recording and the one
made from the bag (`fence-sorter rrd`) hold the same full-rate curves."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from processes import run_cli

from fence_sorter.analysis import analyze_bag
from fence_sorter.analysis.events import EVENT_PEAK_RTOL, SortEventData
from fence_sorter.recording.bagread import read_bag
from fence_sorter.visualisation import rerun_log as rl

pytestmark = [pytest.mark.ros, pytest.mark.slow]

PARCELS = 20
G = 9.81  # the drop height's gravity [m/s^2]
W_DOP, A_NDOP = 2.4, 300.0  # the simulator's default limits, (10) and (11)


@pytest.fixture(scope="module")
def run20(tmp_path_factory) -> tuple[Path, dict]:
    """`fence-sorter run --parcels 20 --rtf 0 --bag DIR --rrd FILE` (about 40 s)."""
    base = tmp_path_factory.mktemp("run20")
    out = run_cli(
        "run", "--parcels", str(PARCELS), "--rtf", "0", "--bag", str(base / "bag"),
        "--rrd", str(base / "live.rrd"), "--json", "--log-dir", str(base / "logs"),
        timeout=400,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    return base, json.loads(out.stdout)


def live_outcomes(bag: Path) -> dict[int, object]:
    return {int(m.msg.parcel_id): m.msg for m in read_bag(bag, ["/sort_outcomes"]).messages}


def test_event_peaks_from_the_bag_match_the_live_outcomes(run20):
    base, summary = run20
    bag = base / "bag"
    outcomes = live_outcomes(bag)
    assert len(outcomes) == PARCELS == summary["outcome_messages"]
    events = {
        int(m.msg.parcel_id): SortEventData.from_msg(m.msg)
        for m in read_bag(bag, ["/sort_events"]).messages
    }
    stroked = {pid for pid, o in outcomes.items() if math.isfinite(o.peak_normal_force)}
    assert stroked and set(events) == stroked  # one event per stroke, none for the others
    report = analyze_bag(bag)
    rows = {r["parcel_id"]: r for r in report.rows}
    for pid in stroked:
        o, row, ev = outcomes[pid], rows[pid], events[pid]
        assert row["event_steps"] == ev.steps > 20
        assert np.all(np.diff(ev.t) > 0)  # every accepted step, in order
        assert ev.t[0] == pytest.approx(ev.start_time)  # from the stroke start
        for key, live in (
            ("event_peak_N", o.peak_normal_force),
            ("event_peak_N_stiff", o.peak_normal_force_stiff),
            ("event_peak_accel_mps2", o.peak_normal_accel),
            ("event_impact_speed_mps", o.impact_normal_speed),
        ):
            assert abs(row[key] - live) <= EVENT_PEAK_RTOL * abs(live), (pid, key)
        if o.sorted:  # the event ends at the step where C_s crossed y0 = s
            assert ev.y[-1] >= row["y_max_m"] - 1e-9 and ev.y[-2] < report.summary["belt_width_m"]
        # the N_stiff course: sampled above 2 kHz through each impact, peaking at its N_stiff
        for k, t0 in enumerate(ev.impact_t):
            course = (ev.stiff_t >= t0) & (ev.stiff_t <= t0 + 1.0)
            if k + 1 < ev.impact_t.size:
                course &= ev.stiff_t < ev.impact_t[k + 1]
            assert np.max(np.diff(ev.stiff_t[course])) <= 2.5e-4 + 1e-12  # >= 4 kHz
            peak = np.max(ev.stiff_force[course])
            assert peak == pytest.approx(ev.impact_force_stiff[k], rel=5e-3)
    assert report.summary["sort_events"] == len(stroked)


def test_outcome_margins_are_the_closed_forms(run20):
    base, _ = run20
    outcomes = live_outcomes(base / "bag")
    hit = [o for o in outcomes.values() if math.isfinite(o.impact_normal_speed)]
    assert hit
    for o in outcomes.values():
        assert (o.w_dop, o.a_ndop) == (W_DOP, A_NDOP)
    for o in hit:
        w, a = o.impact_normal_speed, o.peak_normal_accel
        assert o.impact_speed_margin == pytest.approx(1.0 - w / W_DOP, rel=1e-12)
        assert o.accel_margin == pytest.approx(1.0 - a / A_NDOP, rel=1e-12)
        assert o.drop_height == pytest.approx(w * w / (2.0 * G), rel=1e-12)
        # a free fall from that height lands at the impact's normal speed
        assert math.sqrt(2.0 * G * o.drop_height) == pytest.approx(w, rel=1e-12)
    for o in outcomes.values():
        if not math.isfinite(o.peak_normal_force):  # no stroke: no figure, no margin
            assert math.isnan(o.impact_speed_margin) and math.isnan(o.drop_height)


def test_analyze_draws_the_impact_and_the_damage_risk(run20, tmp_path):
    base, _ = run20
    report = analyze_bag(base / "bag", tmp_path)
    risk = report.summary["damage_risk"]
    hit = [r for r in report.rows if math.isfinite(r["impact_speed_margin"])]
    assert risk["parcels_with_impact"] == len(hit) > 0
    over_w = [r["parcel_id"] for r in hit if r["impact_speed_margin"] < 0]
    assert risk["parcels_over_w_dop"] == over_w
    assert risk["share_over_w_dop"] == pytest.approx(len(over_w) / len(hit))
    worst = min(hit, key=lambda r: min(r["impact_speed_margin"], r["accel_margin"]))
    assert risk["worst_parcels"][0]["parcel_id"] == worst["parcel_id"]
    for r in hit:
        assert f"impact_{r['parcel_id']}.png" in report.files
        assert r["drop_height_m"] == pytest.approx(r["impact_speed_mps"] ** 2 / (2 * G))
    assert (tmp_path / "damage_risk.png").stat().st_size > 10_000
    events_ok = [r for r in hit if not any("event" in d for d in r["disagreements"].split("; "))]
    assert events_ok == hit


def scalar_series(path: Path, prefix: str) -> dict[str, list[tuple[int, float]]]:
    """(sim time [ns], value) per entity under ``prefix``, read with Rerun's RrdReader."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for chunk in RrdReader(path).stream():
        if chunk.is_static or not chunk.entity_path.startswith(prefix):
            continue
        batch = chunk.to_record_batch()
        cols = [c for c in batch.schema.names if c.endswith("Scalars:scalars")]
        if not cols:
            continue
        t = batch.column("sim_time").cast(pa.int64()).to_pylist()
        v = [x[0] for x in batch.column(cols[0]).to_pylist()]
        out.setdefault(chunk.entity_path, []).extend(zip(t, v, strict=True))
    return {k: sorted(v) for k, v in out.items()}


def assert_same_in_time_order(series: list[tuple[int, float]], values) -> None:
    """``series`` (time [ns], value) pairs sorted as read back equal ``values`` in their step
    order; steps closer than the 1 ns of Rerun's time column (a located event's step can be
    1e-11 s) share a time, and within such a group the order is the value's, not the step's."""
    values = list(values)
    assert len(series) == len(values)
    i = 0
    while i < len(series):
        j = i
        while j < len(series) and series[j][0] == series[i][0]:
            j += 1
        assert sorted(v for _, v in series[i:j]) == sorted(values[i:j]), (i, series[i][0])
        i = j


def test_live_rerun_and_the_bag_show_the_same_event_curves(run20, tmp_path):
    base, _ = run20
    bag_rrd = tmp_path / "bag.rrd"
    res = run_cli("rrd", str(base / "bag"), "--out", str(bag_rrd))
    assert res.returncode == 0, res.stderr
    live = scalar_series(base / "live.rrd", "/plots/")
    from_bag = scalar_series(bag_rrd, "/plots/")
    events = {int(m.msg.parcel_id): m.msg for m in read_bag(base / "bag", ["/sort_events"])
              .messages}  # fmt: skip
    assert events
    for pid, ev in events.items():
        for entity, n in (
            (f"/plots/contact/{pid}/N_steps", len(ev.t)),
            (f"/plots/contact/{pid}/N_stiff_course", len(ev.stiff_t)),
            (f"/plots/fence/tip_deflection/steps/{pid}", len(ev.t)),
        ):
            assert len(live[entity]) == n == len(from_bag[entity]), entity
            assert live[entity] == from_bag[entity], entity
        assert_same_in_time_order(  # plotted in kN
            from_bag[f"/plots/contact/{pid}/N_steps"],
            np.asarray(ev.normal_force, dtype=float) / rl.FORCE_PLOT_UNIT,
        )
    damage = scalar_series(base / "live.rrd", "/damage/")
    assert len(damage["/damage/w_n/value"]) == len(events)
    assert {v for _, v in damage["/damage/w_n/limit"]} == {W_DOP}
