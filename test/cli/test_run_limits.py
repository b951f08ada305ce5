"""The run's account of the paper's limits on the plant (runner.summary with
capacity.delivered): a sorted parcel over (7), (10), (11) or (12), a failed event or a
swept-sector intrusion makes the run not clean (exit 7) and is named by parcel; failed events
never enter the peak figures; each parcel's stroke, mass and sizes are in the summary."""

from __future__ import annotations

import math

import pytest

from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.capacity.delivered import ROW_COLUMNS
from fence_sorter.runner.job import BadInput, controller_limits
from fence_sorter.runner.monitor import Records
from fence_sorter.runner.summary import EXIT_LIMITS, format_summary, summarise, verdict

BELT = 2.0  # [m/s]


def outcome(name: str, sorted_: bool, w_n: float, a_n: float, ydot: float, n: float) -> dict:
    return {
        "sorted": sorted_,
        "reason": name.lower(),
        "reason_code": 0,
        "reason_name": name,
        "time": 1.0,
        "peak_normal_force": n,
        "peak_normal_force_stiff": 2.0 * n,
        "peak_normal_accel": a_n,
        "impact_normal_speed": w_n,
        "exit_speed_y": ydot,
    }


def command(r_s: float, t1: float, w_n: float, a_n: float, ydot: float) -> dict:
    return {
        "feasible": True,
        "reason": "",
        "r_s": r_s,
        "t1": t1,
        "alpha_k": math.radians(40.0),
        "stamp": 0.5,
        "received_sim": 0.5,
        "predicted_capacity_pcs_h": 3000.0,
        "predicted_peak_accel": a_n,
        "predicted_impact_speed": w_n,
        "predicted_exit_speed": ydot,
    }


def records() -> Records:
    """Three divert parcels: 1 within every limit, 2 over (12) by 0.59 m/s (planned within),
    3 a failed event with a non-physical 4.1e7 N."""
    r = Records()
    for pid, (a, b, m) in {1: (0.3, 0.2, 5.0), 2: (0.6, 0.4, 10.0), 3: (0.5, 0.5, 25.0)}.items():
        r.parcels[pid] = {
            "scan_time": float(pid),
            "scan_position_x": -3.0,
            "divert": True,
            "length_a": a,
            "width_b": b,
            "yaw": 0.0,
            "mass": m,
        }
        r.commands[pid] = command(0.2, 0.4, 2.0, 100.0, 2.2)
    r.outcomes = {
        1: outcome("SORTED", True, 2.1, 120.0, 2.3, 800.0),
        2: outcome("SORTED", True, 2.2, 150.0, 3.09, 900.0),
        3: outcome("SOLVER_FAILURE", False, 9.0, 2.0e6, math.nan, 4.1e7),
    }
    return r


def test_a_sorted_parcel_over_a_limit_and_a_failed_event_exit_7_by_parcel() -> None:
    s = summarise(records(), BELT, [1, 2, 3], [1, 2, 3], ConstraintProfile())
    lim = s["limits"]
    assert lim["over_limit"] == {"7": [], "10": [], "11": [], "12": [2]}
    worst = lim["worst_excess"]["12"]
    assert worst["parcel_id"] == 2
    assert worst["delivered"] == 3.09 and worst["planned"] == 2.2 and worst["limit"] == 2.5
    assert worst["excess"] == pytest.approx(0.59)
    assert lim["failed_events"] == [3] and not lim["clean"]
    code, why = verdict(s)
    assert code == EXIT_LIMITS
    assert "(12) 1 sorted parcels over it [2]" in why and "1 failed events [3]" in why
    text = format_summary(s)
    assert "limits" in text and "[2]" in text


def test_failed_events_never_enter_the_peak_figures() -> None:
    s = summarise(records(), BELT, [1, 2, 3], [1, 2, 3], ConstraintProfile())
    assert s["peak_force_N"] == 900.0
    assert s["peak_force_stiff_N"] == 1800.0
    assert s["peak_accel_mps2"] == 150.0
    assert s["peak_impact_speed_mps"] == 2.2


def test_each_parcel_carries_its_stroke_its_sizes_and_planned_against_delivered() -> None:
    s = summarise(records(), BELT, [1, 2, 3], [1, 2, 3], ConstraintProfile())
    rows = {r["parcel_id"]: r for r in s["delivered"]}
    assert set(ROW_COLUMNS) <= set(rows[2])
    row = rows[2]
    assert (row["mass_kg"], row["length_a_m"], row["width_b_m"]) == (10.0, 0.6, 0.4)
    assert (row["r_s_m"], row["t1_s"]) == (0.2, 0.4)
    assert row["alpha_k_rad"] == pytest.approx(math.radians(40.0))
    assert (row["planned_exit_speed_mps"], row["delivered_exit_speed_mps"]) == (2.2, 3.09)
    # (7): (A - R_s)/v - t1 = (0.6 - 0.2)/2 - 0.4 = -0.2 s, met
    assert row["margin_7_s"] == pytest.approx(-0.2)
    assert rows[3]["failed"] and math.isnan(rows[3]["margin_10_mps"])


def test_working_time_7_is_judged_from_the_stroke_and_the_yawed_extent() -> None:
    r = records()
    r.outcomes = {pid: r.outcomes[1] for pid in (1, 2, 3)}
    r.parcels[2]["yaw"] = math.radians(30.0)
    r.commands[2] = {**r.commands[2], "r_s": -0.4, "t1": 0.2}
    s = summarise(r, BELT, [1, 2, 3], [1, 2, 3], ConstraintProfile())
    extent = 0.6 * math.cos(math.radians(30.0)) + 0.4 * math.sin(math.radians(30.0))
    row = next(x for x in s["delivered"] if x["parcel_id"] == 2)
    assert row["margin_7_s"] == pytest.approx((extent + 0.4) / BELT - 0.2)
    assert s["limits"]["over_limit"]["7"] == [2]


def test_inactive_limits_and_unsorted_parcels_do_not_count() -> None:
    r = records()
    r.outcomes[3] = outcome("MISSED", False, 3.0, 500.0, math.nan, 3000.0)
    s = summarise(r, BELT, [1, 2, 3], [1, 2, 3], ConstraintProfile(active=(7, 8, 9, 10, 11)))
    assert s["limits"]["clean"] and verdict(s) is None
    assert "12" not in s["limits"]["over_limit"]
    # the missed parcel was not sorted: its impact is a peak figure, not a sorted excess
    assert s["peak_impact_speed_mps"] == 3.0


def test_a_swept_sector_intrusion_is_not_clean() -> None:
    r = records()
    r.outcomes = {pid: r.outcomes[1] for pid in (1, 2, 3)}
    r.diagnostics["fence_sorter/simulator"] = {"overlap_warnings": "38"}
    s = summarise(r, BELT, [1, 2, 3], [1, 2, 3], ConstraintProfile())
    assert s["swept_sector_intrusions"] == 38 and s["limits"]["clean"]
    code, why = verdict(s)
    assert code == EXIT_LIMITS and "38 swept-sector intrusions" in why


def test_the_run_is_judged_against_the_controllers_limits() -> None:
    assert controller_limits({}) == ConstraintProfile(2.4, 300.0, 2.5, (7, 8, 9, 10, 11, 12))
    assert controller_limits({"ydot_dop": 3.5, "active_constraints": [7, 10]}) == (
        ConstraintProfile(2.4, 300.0, 3.5, (7, 10))
    )
    with pytest.raises(BadInput, match=r"controller\.w_dop must be in"):
        controller_limits({"w_dop": -1.0})
