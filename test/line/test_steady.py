"""A line run's steady state (fence_sorter/line/steady.py): the cohort first inducted in the
window, inducted against offered, and the saturated flag with where the queue forms.

The first tests build the parcels' times by hand (closed forms); the last ones run four_units
briefly far above and far below what its induction can take."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.steady import (
    QUEUES,
    SATURATION_GROWTH,
    growth,
    steady_state,
    steady_window,
)


def parcel(arrival: float, inducted: float, state: str = "sorted", ended: float = math.nan):
    sorted_at = ended if state == "sorted" else math.nan
    return SimpleNamespace(
        arrival=arrival, inducted_at=inducted, state=state, sorted_at=sorted_at, ended_at=ended
    )


def test_growth_is_the_least_squares_slope() -> None:
    assert growth([0.0, 1.0, 2.0, 3.0], [1.0, 1.5, 2.0, 2.5]) == pytest.approx(0.5)
    assert growth([0.0, 1.0, 2.0], [4.0, 4.0, 4.0]) == 0.0
    assert math.isnan(growth([0.0, 1.0], [0.0, 1.0]))  # under 3 points
    assert math.isnan(growth([2.0, 2.0, 2.0], [0.0, 1.0, 2.0]))  # no spread


def test_an_induction_slower_than_the_stream_is_saturated_at_its_hold() -> None:
    """Arrivals every 1 s (3600 pcs/h offered), inductions every 1.5 s: each parcel waits
    0.5 s longer than the one before (growth 0.5 s/s); over the window [10, 60) the cohort is
    the parcels first inducted at 10.5 ... 58.5 s, 33 of them in 50 s."""
    n, fill = 41, 10.0
    ps = [parcel(float(i), 1.5 * i, ended=1.5 * i + 5.0) for i in range(n)]
    w = steady_window(ps, fill)
    assert (w["start_s"], w["end_s"], w["first_inductions"]) == (10.0, 60.0, 33)
    holds = [(1.5 * i, "min_gap", 0.5) for i in range(n)]
    st = steady_state(ps, w, 3600.0, holds, [])
    assert st["induction_delay_growth"] == pytest.approx(0.5)
    assert st["saturated"] and st["queue_at"] == [QUEUES[0]]
    assert st["inducted_pcs_h"] == pytest.approx(33 * 3600.0 / 50.0)
    assert st["inducted_over_offered"] == pytest.approx(33 / 50.0)
    assert st["hold_s"] == {"min_gap": pytest.approx(0.5 * 33), "returning": 0.0}


def test_the_cohort_s_out_over_in_is_its_sorted_share_and_at_most_one() -> None:
    """Inducted as they arrive (no queue): not saturated, inducted = offered over the window;
    the cohort's fate is read at the end of the run, whatever the window's end."""
    states = ["sorted", "sorted", "rejected", "sorted", "failed", "loop", "sorted", "belt"]
    ps = [parcel(2.0 * i, 2.0 * i, states[i % len(states)], 2.0 * i + 3.0) for i in range(40)]
    w = steady_window(ps, 10.0)  # [10, 78): parcels 5 ... 38
    st = steady_state(ps, w, 1800.0, [], [])
    assert not st["saturated"] and st["queue_at"] == [] and st["induction_delay_growth"] == 0.0
    cohort = [states[i % len(states)] for i in range(5, 39)]
    c = st["cohort"]
    assert c["inducted"] == 34 == w["first_inductions"]
    assert c["sorted"] == cohort.count("sorted") == w["cohort_sorted"]
    assert (c["rejected"], c["failed"]) == (cohort.count("rejected"), cohort.count("failed"))
    assert c["on_line"] == cohort.count("loop") + cohort.count("belt")
    assert st["out_over_in"] == c["sorted"] / 34 <= 1.0
    assert st["sorted_pcs_h"] == pytest.approx(c["sorted"] * 3600.0 / 68.0)
    assert st["inducted_over_offered"] == pytest.approx(34 * 3600.0 / 68.0 / 1800.0)


def test_returning_parcels_waiting_longer_and_longer_saturate_the_merge() -> None:
    ps = [parcel(float(i), float(i)) for i in range(30)]
    w = steady_window(ps, 5.0)
    merges = [(5.0 + i, 2.0 * SATURATION_GROWTH * i) for i in range(20)]
    st = steady_state(ps, w, 3600.0, [], merges)
    assert st["merge_wait_growth"] == pytest.approx(2.0 * SATURATION_GROWTH)
    assert st["saturated"] and st["queue_at"] == [QUEUES[2]]
    assert st["merge_wait_s"] == pytest.approx(sum(x for t, x in merges if t < 29.0))


FOUR = load_line("four_units")


@pytest.mark.slow
def test_far_above_capacity_four_units_is_saturated_at_its_gapping_induction() -> None:
    """6000 pcs/h (a 1.2 m pitch) against four_units' induction.min_gap 1.5 m: every new parcel
    is held to the gap, its wait grows; what goes in is bounded by the gap, a pitch at least
    the shortest parcel (0.2 m) + 1.5 m at 2 m/s: 4235 pcs/h, less than offered."""
    cfg = LineRunConfig(parcels=12, rate_pcs_h=6000.0, seed=5, max_time=14.0)
    st = LinePlant(FOUR, cfg).run()["steady"]
    assert st["offered_pcs_h"] == pytest.approx(6000.0)
    assert st["saturated"] and st["queue_at"] == ["induction hold (min_gap)"]
    assert st["induction_delay_growth"] > SATURATION_GROWTH
    assert st["inducted_pcs_h"] <= 3600.0 * FOUR.speed / (0.2 + FOUR.min_gap)
    assert st["inducted_over_offered"] < 1.0


@pytest.mark.slow
def test_far_below_capacity_four_units_is_not_saturated() -> None:
    """600 pcs/h (a 12 m pitch): no hold, every parcel inducted as it arrives."""
    cfg = LineRunConfig(parcels=5, rate_pcs_h=600.0, seed=5, max_time=30.0)
    s = LinePlant(FOUR, cfg).run()
    st = s["steady"]
    assert not st["saturated"] and st["queue_at"] == []
    assert st["induction_delay_growth"] == 0.0
    assert st["inducted_pcs_h"] == pytest.approx(600.0) == st["offered_pcs_h"]
    assert s["induction_hold_s"] == 0.0
