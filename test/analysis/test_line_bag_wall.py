"""The wall-clock fields of a line summary in ``fence-sorter analyze BAG`` (ROS-free): a replay
cannot recompute them, so the analysis copies each from the live summary, nested ones
(``units_down.<unit>.downtime_wall_s``) included, and leaves them out of its comparison with
the live summary; every other field, at any depth, still counts."""

from __future__ import annotations

import copy
import math

from fence_sorter.analysis.line_bag import WALL_FIELDS, differences, wall_paths, with_live_wall


def _summary(wall: float, sim: float = 0.01) -> dict:
    down = {"downs": 1, "downtime_s": sim, "downtime_wall_s": wall, "lost_parcels": [6]}
    return {
        "sorted": 4,
        "wall_time_s": 3.0 * wall,
        "pacing": {"steps": 10},
        "units_down": {"unit_2": down, "unit_3": {**down, "downtime_wall_s": wall + 1.0}},
    }


def test_every_wall_field_is_found_at_its_depth() -> None:
    paths = wall_paths(_summary(4.9))
    # every top-level one, present or not (the live run's value or NaN goes there)
    assert [p for p in paths if len(p) == 1] == [(f,) for f in WALL_FIELDS if "." not in f]
    assert [p for p in paths if len(p) > 1] == [
        ("units_down", "unit_2", "downtime_wall_s"),
        ("units_down", "unit_3", "downtime_wall_s"),
    ]
    assert [p for p in wall_paths({"units_down": {}}) if len(p) > 1] == []


def test_the_live_wall_fields_are_copied_and_left_out_of_the_comparison() -> None:
    live = _summary(4.9)
    replayed = _summary(0.002)  # the replay's own wall clock: not the run's
    assert differences(replayed, live) == {}
    got = with_live_wall(copy.deepcopy(replayed), live)
    assert got["units_down"]["unit_2"]["downtime_wall_s"] == 4.9
    assert got["units_down"]["unit_3"]["downtime_wall_s"] == 5.9
    assert got["wall_time_s"] == live["wall_time_s"] and got["pacing"] == live["pacing"]
    assert math.isnan(got["reply_wait_max_s"])  # the live summary has none
    # without a live summary every wall field is NaN, nested ones too
    alone = with_live_wall(copy.deepcopy(replayed), None)
    assert math.isnan(alone["units_down"]["unit_2"]["downtime_wall_s"])


def test_a_sim_field_beside_a_wall_field_still_counts() -> None:
    live = _summary(4.9)
    replayed = _summary(0.002, sim=0.02)
    diff = differences(replayed, live)
    assert list(diff) == ["units_down"]
    computed, recorded = diff["units_down"]
    assert computed["unit_2"] == {"downs": 1, "downtime_s": 0.02, "lost_parcels": [6]}
    assert recorded["unit_2"]["downtime_s"] == 0.01
