"""A line of fence units without ROS: conservation, destinations, recirculation, the guard.

Line: config/lines/two_units.yaml (unit_1 right serving A and C, unit_2 mirrored on the left
serving B and C; 2 passes, then the reject chute), the default stream.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from fence_sorter.line.handoff import Failed, Sorted
from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.routing import NO_READ, REASONS
from fence_sorter.line.unit import track_of

LINE = load_line("two_units")


def run(line=LINE, **kw) -> tuple[LinePlant, dict]:
    plant = LinePlant(line, LineRunConfig(**kw))
    return plant, plant.run()


def check_books(plant: LinePlant, s: dict) -> None:
    """Every parcel ends in exactly one place; the summary's counts are the parcels' own."""
    n = s["parcels_inducted"]
    assert s["drained"] and s["still_on_line"] == 0
    assert s["conservation_ok"]
    assert n == s["sorted"] + s["rejected"] + s["solver_failures"]
    ends = [p.end for p in plant.parcels]
    assert all(ends), "a parcel without an end"
    assert s["sorted_wrong_destination"] == 0
    assert sum(s["sorted_per_destination"].values()) == s["sorted"]
    # a sorted parcel left through a unit that serves its destination
    for p in plant.parcels:
        if p.state == "sorted":
            assert p.end == p.destination
    units = s["units"].values()
    assert sum(u["sorted"] for u in units) == s["sorted"]
    assert sum(u["strokes"] for u in units) == s["sorted"] + sum(
        u["missed"] + u["solver_failures"] for u in units
    )
    # passes: a rejected parcel made max_passes, the others at most that many
    for p in plant.parcels:
        if p.state == "rejected":
            assert p.passes == LINE.max_passes
        else:
            assert p.passes < LINE.max_passes


@pytest.mark.slow
def test_dense_stream_with_the_guard():
    """3000 pcs/h on two units: every parcel accounted for, none in a swept sector."""
    plant, s = run(parcels=40, rate_pcs_h=3000.0, seed=3)
    check_books(plant, s)
    assert s["swept_sector_intrusions"] == 0
    assert s["sorted"] > 0
    # a parcel that went round again was inducted again
    assert s["inductions"] == sum(p.passes + (p.state != "rejected") for p in plant.parcels)


@pytest.mark.slow
def test_without_the_guard_parcels_lie_in_the_sector():
    """The same stream with the guard off: the simulation finds parcels in swept sectors."""
    plant, s = run(parcels=40, rate_pcs_h=3000.0, seed=3, guard=False)
    check_books(plant, s)
    assert s["declined"]["sector_occupied"] == 0
    assert s["swept_sector_intrusions"] > 0


@pytest.mark.slow
def test_all_no_reads_go_round_then_to_the_reject_chute():
    """No-read share 1: no unit diverts, every parcel makes max_passes passes (inducted that
    many times) and ends in the reject chute."""
    line = replace(LINE, no_read_share=1.0)
    plant, s = run(line, parcels=6, rate_pcs_h=1200.0, seed=5)
    check_books(plant, s)
    n = s["parcels_inducted"]
    assert s["rejected"] == n and s["sorted"] == 0
    assert s["inductions"] == n * line.max_passes
    assert all(p.end == line.reject_chute for p in plant.parcels)
    for u in s["units"].values():
        assert u["declined"][NO_READ] == n * line.max_passes
        assert u["strokes"] == 0
        assert set(u["declined"]) == set(REASONS)
    # a returning parcel waits the loop's transit time at least: the run lasts that long
    assert s["sim_time_s"] > (line.max_passes - 1) * line.transit_time


@pytest.mark.slow
def test_four_units_at_6000_per_hour():
    """The shipped four-unit line at 6000 pcs/h (a short run): conservation exact, no wrong
    destination, no parcel in a swept sector, every hand-off received by its unit, none after
    the parcel reached the unit's fence."""
    plant, s = run(load_line("four_units"), parcels=30, rate_pcs_h=6000.0, seed=11)
    assert s["drained"] and s["conservation_ok"]
    assert s["sorted_wrong_destination"] == 0
    assert s["swept_sector_intrusions"] == 0
    units = s["units"].values()
    assert sum(u["handoffs_in"] for u in units) == s["handoffs"]
    assert all(u["late_handoffs_past_axis"] == 0 for u in units)
    # every parcel met every unit on each of its passes up to where it was sorted
    assert s["handoffs"] >= s["inductions"]


@pytest.mark.slow
def test_cli_json(capsys):
    import json

    from fence_sorter.cli.main import main

    code = main(["line-sim", "two_units", "--parcels", "8", "--rate", "1500", "--json"])
    s = json.loads(capsys.readouterr().out)
    assert code == 0
    assert s["parcels_inducted"] == 8 and s["conservation_ok"] and s["drained"]
    assert set(s["units"]) == {"unit_1", "unit_2"}
    assert s["handoffs_balanced"]
    assert s["links"]["induction>unit_1"]["received"] == s["inductions"]


@pytest.mark.parametrize("unit", [0, 1])
@pytest.mark.parametrize("yaw", [0.3, -1.4, 2.0])
def test_a_unit_sees_the_parcel_where_the_line_has_it(unit, yaw):
    """The hand-off pose: the unit's ParcelSpec (front, lateral gap, yaw, C_s offsets in its
    frame, mirrored on the left) rebuilds the parcel's footprint exactly where the line frame
    has it, for a turned parcel (yaw beyond +-90 deg folds back with its C_s offsets)."""
    from fence_sorter.line.routing import to_line
    from fence_sorter.physics.params import ConveyorParams
    from fence_sorter.physics.parcel import initial_pose, parcel_body, world_corners

    plant = LinePlant(LINE, LineRunConfig(parcels=2, seed=1))
    p = plant.parcels[0]
    p.spec = replace(p.spec, cog_offset_x=0.04, cog_offset_y=-0.03)
    tr = plant._track_at_induction(p, 0.0)
    p.track = replace(tr, x=7.3, y=0.33, yaw=yaw, cog_x=0.04, cog_y=-0.03)
    u = LINE.units[unit]
    h = plant._induction_handoff(p)
    spec = plant.units[unit]._local_spec(h, track_of(h, plant.v), 0.5, divert=False)
    body = parcel_body(spec.to_parcel_params(), ConveyorParams())
    x, y, phi = initial_pose(body, spec.scan_position_x, spec.lateral_gap, spec.yaw)
    got = sorted(
        to_line(u.position, u.mirrored, LINE.width, cx, cy, 0.0)[:2]
        for cx, cy in world_corners(body, x, y, phi)
    )
    want = sorted(p.track.corners(0.5))
    flat = [c for pt in got for c in pt]
    assert flat == pytest.approx([c for pt in want for c in pt], abs=1e-9)
    assert abs(spec.yaw) <= 0.5 * math.pi


@pytest.mark.slow
def test_a_returning_parcel_merges_with_its_gap_and_the_stream_keeps_its_order():
    """At 4000 pcs/h the stream's own gaps are shorter than the four-unit line's merge gap, so
    a returning parcel merges only when the induction holds the new parcels behind it: at every
    merge each other parcel's footprint is at least merge_gap away, and the stream's parcels
    reach the induction in their order with their drawn spacing or more."""
    line = load_line("four_units")
    plant = LinePlant(line, LineRunConfig(parcels=40, rate_pcs_h=4000.0, seed=2))
    merges: list[float] = []
    induct = plant._induct

    def recorded(p, t):
        if p.passes > 0:  # a returning parcel: its front at X = 0 now
            cand = plant._track_at_induction(p, t)
            lo, hi = plant._rear(cand, t), plant._front(cand, t)
            for q in plant.live:
                if q is p or q.track is None or q.state not in ("scheduled", "belt"):
                    continue
                r, f = plant._rear(q.track, t), plant._front(q.track, t)
                merges.append(r - hi if r >= hi else (lo - f if f <= lo else -1.0))
        induct(p, t)

    plant._induct = recorded
    s = plant.run()
    assert s["drained"] and s["conservation_ok"] and s["swept_sector_intrusions"] == 0
    assert merges and s["induction_hold_s"] > 0.0
    assert min(merges) >= line.merge_gap - 1e-9
    firsts = [p.inducted_at for p in plant.parcels]
    drawn = [p.arrival for p in plant.parcels]
    for i in range(1, len(firsts)):
        assert firsts[i] - firsts[i - 1] >= drawn[i] - drawn[i - 1] - 1e-9
    assert s["induction_rate_pcs_h"] < 4000.0  # the holds took induction capacity


@pytest.mark.slow
def test_below_the_knee_every_readable_parcel_is_sorted():
    """four_units at 2000 pcs/h, half its units' W_t: the parcels out are the parcels in, less
    the no-reads that stayed unread on every pass (within 2 %)."""
    plant = LinePlant(load_line("four_units"), LineRunConfig(parcels=100, rate_pcs_h=2000.0))
    plant.warm_up()  # as run_line does: the planners' caches filled from the stream
    s = plant.run()
    assert s["drained"] and s["conservation_ok"] and s["swept_sector_intrusions"] == 0
    unread = sum(p.state == "rejected" and p.ever_no_read for p in plant.parcels)
    assert s["sorted"] >= 0.98 * (s["parcels_inducted"] - unread), s


@pytest.mark.slow
def test_a_gapping_induction_meters_a_dense_stream_to_its_gap():
    """two_units with min_gap 1.5 m at 6000 pcs/h (a pitch shorter than that gap): every new
    parcel reaches the induction with its front at least 1.5 m behind every parcel's rear, in
    the stream's order, and the rate in is what the gap allows, not what was offered."""
    line = replace(LINE, min_gap=1.5)
    plant = LinePlant(line, LineRunConfig(parcels=20, rate_pcs_h=6000.0, seed=4))
    gaps: list[float] = []
    induct = plant._induct

    def recorded(p, t):
        if p.passes == 0:
            others = [q.track for q in plant.live if q is not p and q.track is not None
                      and q.state in ("scheduled", "belt")]  # fmt: skip
            # every parcel past the induction line (its front at X > 0) is ahead of this one
            gaps.extend(plant._rear(tr, t) for tr in others if plant._front(tr, t) > 0.0)
        induct(p, t)

    plant._induct = recorded
    s = plant.run()
    check_books(plant, s)
    assert gaps and min(gaps) >= 1.5 - 1e-9
    firsts = [p.inducted_at for p in plant.parcels]
    assert firsts == sorted(firsts)
    longest = max(p.spec.length_a for p in plant.parcels)  # pitch <= longest parcel + gap
    assert s["induction_rate_pcs_h"] < 6000.0 * 0.9
    assert s["induction_rate_pcs_h"] >= 3600.0 * LINE.speed / (longest + 1.5) * 0.5


@pytest.mark.slow
def test_over_the_steady_window_sorts_are_first_inductions_less_open_ones_plus_earlier():
    """two_units, 60 s of induction at 2000 pcs/h: the steady window starts one loop cycle
    (belt length / v + transit time) after the first parcel's first induction and ends at the
    last one's; the summary's counts over it equal those read off the run by an observer of
    the units' records and the parcels' states, and obey, exactly, sorts = first inductions -
    still on the line at its end - rejected or failed in it + sorted in it from before it; the
    window's parcels sorted by the end of the run are counted as the records say."""
    plant = LinePlant(LINE, LineRunConfig(duration=60.0, rate_pcs_h=2000.0, seed=3))
    first: dict[int, float] = {}  # the time its front crossed X = 0, from its track
    sorted_at: dict[int, float] = {}
    ended: dict[int, float] = {}

    def observe(pl: LinePlant, records: list) -> None:
        for rec in records:
            if isinstance(rec, Sorted | Failed):
                ended[rec.parcel_id] = rec.t
            if isinstance(rec, Sorted):
                sorted_at[rec.parcel_id] = rec.t
        for p in pl.parcels:
            if p.state == "rejected" and p.pid not in ended:
                ended[p.pid] = pl.t
            if p.passes == 0 and p.state == "belt" and p.pid not in first:
                tr = p.track
                first[p.pid] = tr.t_ref - pl._front(tr, tr.t_ref) / tr.v

    plant.observers.append(observe)
    s = plant.run()
    check_books(plant, s)
    assert plant.records_ignored == 0
    w = s["steady_window"]
    assert w["fill_s"] == LINE.length / LINE.speed + LINE.transit_time
    assert w["start_s"] == pytest.approx(min(first.values()) + w["fill_s"], abs=1e-9)
    assert w["end_s"] == pytest.approx(max(first.values()), abs=1e-9)
    a, b = w["start_s"], w["end_s"]
    new = [pid for pid, t in first.items() if a <= t < b]
    seen = {
        "first_inductions": len(new),
        "sorts": sum(a <= t < b for t in sorted_at.values()),
        "still_on_line": sum(ended.get(pid, math.inf) >= b for pid in new),
        "ended_unsorted": sum(
            pid not in sorted_at and ended.get(pid, math.inf) < b for pid in new
        ),
        "from_before": sum(first[pid] < a and a <= t < b for pid, t in sorted_at.items()),
        "cohort_sorted": sum(pid in sorted_at for pid in new),  # after the drain
    }
    assert {k: w[k] for k in seen} == seen
    assert seen["first_inductions"] > 10 and seen["from_before"] > 0 and seen["still_on_line"] > 0
    assert w["sorts"] == (
        w["first_inductions"] - w["still_on_line"] - w["ended_unsorted"] + w["from_before"]
    )
    hours = (b - a) / 3600.0
    # throughput is the cohort's: its parcels in, and those of them sorted, per hour of it
    assert s["throughput_in_pcs_h"] == w["first_inductions"] / hours
    assert s["throughput_out_pcs_h"] == seen["cohort_sorted"] / hours
    st = s["steady"]
    assert st["cohort"]["inducted"] == len(new) and st["cohort"]["sorted"] == len(
        [pid for pid in new if pid in sorted_at]
    )
    assert st["out_over_in"] == seen["cohort_sorted"] / len(new) <= 1.0
    assert st["offered_pcs_h"] == s["rate_in_pcs_h"]
    assert st["inducted_over_offered"] == s["throughput_in_pcs_h"] / s["rate_in_pcs_h"]


@pytest.mark.slow
def test_each_unit_names_the_sorted_parcels_over_a_limit_and_the_line_is_not_clean():
    """The units judge what each stroke delivered (w_n, a_N, ydot of its outcome) against the
    limits (10)-(12): here judged against tighter limits than planned for, so that some sorted
    parcels go over; the lists equal the outcomes' own figures, and the line is not clean."""
    from fence_sorter.capacity.constraints import ConstraintProfile
    from fence_sorter.line.multi_unit import line_problems
    from fence_sorter.line.types import Outcome

    plant = LinePlant(LINE, LineRunConfig(parcels=12, seed=3))
    judged = ConstraintProfile(w_dop=1.8, a_ndop=120.0, ydot_dop=1.2)
    seen: list[Outcome] = []
    for u in plant.units:
        u.profile = judged
        advance = u.line.advance

        def spy(t, advance=advance):
            events = advance(t)
            seen.extend(e for e in events if isinstance(e, Outcome))
            return events

        u.line.advance = spy
    s = plant.run()
    check_books(plant, s)
    by_local = {e.parcel_id: e for e in seen if e.code.name == "SORTED"}
    assert len(by_local) == s["sorted"] > 0
    expected = {"10": set(), "11": set(), "12": set()}
    for e in by_local.values():
        for c, value, limit in (
            ("10", e.impact_normal_speed, judged.w_dop),
            ("11", e.peak_normal_accel, judged.a_ndop),
            ("12", e.exit_speed_y, judged.ydot_dop),
        ):
            if value > limit:
                expected[c].add(e.parcel_id)
    got = {c: set(ids) for c, ids in s["parcels_over_limits"].items()}
    assert {c: len(ids) for c, ids in got.items()} == {c: len(v) for c, v in expected.items()}
    assert any(got.values())
    assert sum(len(u["over_limits"]["10"]) for u in s["units"].values()) == len(got["10"])
    problems = line_problems(s)
    assert [p for p in problems if "sorted parcels over it" in p]
