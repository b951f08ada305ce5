"""A line's units as objects that talk only through records (fence_sorter/line/unit.py).

The in-process line (LinePlant) is the wiring of LineUnit objects; it must give the figures
the line gave before it was split into them, every hand-off must be counted at both ends of
its link, and a unit must refuse a hand-off it cannot take, counting it with a reason.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from fence_sorter.line.handoff import (
    DUPLICATE,
    INDUCTION,
    NOT_FROM_UPSTREAM,
    RECIRCULATION,
    UNKNOWN_PARCEL,
    HandOff,
    Sorted,
)
from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.routing import NOT_SERVED
from fence_sorter.line.unit import LineUnit, Traffic, track_of

TWO = load_line("two_units")

#: main's LinePlant at 6dd615c (before the split into LineUnit objects): the fields below of
#: ``LinePlant(load_line(LINE), LineRunConfig(**CONFIG)).run()`` for each case of CASES, with
#: that commit's module (``git show 6dd615c:fence_sorter/line/multi_unit.py``, written to a
#: file of its own and loaded by path with importlib beside the current package); the
#: throughput in and out are not among them: they are counted over the steady window
#: (``LinePlant.steady_window``), which these 40-parcel runs, shorter than a loop cycle of
#: induction, do not have
MAIN = {'four': {'sorted': 40,
          'sorted_per_destination': {'D1': 4,
                                     'D2': 3,
                                     'D3': 6,
                                     'D4': 6,
                                     'D5': 2,
                                     'D6': 5,
                                     'D7': 5,
                                     'D8': 9},
          'rejected': 0,
          'inductions': 49,
          'recirculated': 9,
          'no_read': 1,
          'handoffs': 144,
          'declined': {'sector_occupied': 8, 'no_read': 4, 'not_served': 92},
          'swept_sector_intrusions': 0,
          'induction_hold_s': 12.720308667724744,
          'sim_time_s': 93.20000000001077,
          'units': {'unit_1': {'strokes': 7,
                               'sorted': 7,
                               'missed': 0,
                               'late_handoffs': 0,
                               'declined': {'sector_occupied': 1,
                                            'no_read': 1,
                                            'not_served': 40},
                               'swept_sector_intrusions': 0,
                               'utilisation': 0.04935622317595995,
                               'peak_normal_force_N': 1331.7894206844624,
                               'max_impact_speed_m_s': 2.3567755459485675},
                    'unit_2': {'strokes': 12,
                               'sorted': 12,
                               'missed': 0,
                               'late_handoffs': 0,
                               'declined': {'sector_occupied': 3,
                                            'no_read': 1,
                                            'not_served': 26},
                               'swept_sector_intrusions': 0,
                               'utilisation': 0.09656652360513904,
                               'peak_normal_force_N': 787.3078226053514,
                               'max_impact_speed_m_s': 2.24360018974293},
                    'unit_3': {'strokes': 7,
                               'sorted': 7,
                               'missed': 0,
                               'late_handoffs': 0,
                               'declined': {'sector_occupied': 1,
                                            'no_read': 1,
                                            'not_served': 21},
                               'swept_sector_intrusions': 0,
                               'utilisation': 0.04077253218883649,
                               'peak_normal_force_N': 831.2394795041049,
                               'max_impact_speed_m_s': 2.377073008192796},
                    'unit_4': {'strokes': 14,
                               'sorted': 14,
                               'missed': 0,
                               'late_handoffs': 0,
                               'declined': {'sector_occupied': 3,
                                            'no_read': 1,
                                            'not_served': 5},
                               'swept_sector_intrusions': 0,
                               'utilisation': 0.12660944206007121,
                               'peak_normal_force_N': 1595.2814853293041,
                               'max_impact_speed_m_s': 2.1455277992247352}}},
 'two_guard': {'sorted': 28,
               'sorted_per_destination': {'A': 9, 'B': 13, 'C': 6},
               'rejected': 12,
               'inductions': 67,
               'recirculated': 27,
               'no_read': 4,
               'handoffs': 122,
               'declined': {'sector_occupied': 42, 'no_read': 8, 'not_served': 44},
               'swept_sector_intrusions': 0,
               'induction_hold_s': 30.898674338511643,
               'sim_time_s': 113.06000000002093,
               'units': {'unit_1': {'strokes': 12,
                                    'sorted': 12,
                                    'missed': 0,
                                    'late_handoffs': 0,
                                    'declined': {'sector_occupied': 24,
                                                 'no_read': 4,
                                                 'not_served': 27},
                                    'swept_sector_intrusions': 0,
                                    'utilisation': 0.09375552803819245,
                                    'peak_normal_force_N': 1218.4914966310994,
                                    'max_impact_speed_m_s': 2.3620753276111044},
                         'unit_2': {'strokes': 16,
                                    'sorted': 16,
                                    'missed': 0,
                                    'late_handoffs': 0,
                                    'declined': {'sector_occupied': 18,
                                                 'no_read': 4,
                                                 'not_served': 17},
                                    'swept_sector_intrusions': 0,
                                    'utilisation': 0.14505572262512792,
                                    'peak_normal_force_N': 1093.3279009983278,
                                    'max_impact_speed_m_s': 2.3920980752649372}}},
 'two_noguard': {'sorted': 40,
                 'sorted_per_destination': {'A': 15, 'B': 18, 'C': 7},
                 'rejected': 0,
                 'inductions': 41,
                 'recirculated': 1,
                 'no_read': 1,
                 'handoffs': 60,
                 'declined': {'no_read': 2, 'not_served': 18},
                 'swept_sector_intrusions': 22,
                 'induction_hold_s': 0.0,
                 'sim_time_s': 58.89999999999685,
                 'units': {'unit_1': {'strokes': 22,
                                      'sorted': 22,
                                      'missed': 0,
                                      'late_handoffs': 0,
                                      'declined': {'no_read': 1, 'not_served': 18},
                                      'swept_sector_intrusions': 18,
                                      'utilisation': 0.3463497453310881,
                                      'peak_normal_force_N': 1218.4914966310994,
                                      'max_impact_speed_m_s': 2.3620753276111044},
                           'unit_2': {'strokes': 18,
                                      'sorted': 18,
                                      'missed': 0,
                                      'late_handoffs': 0,
                                      'declined': {'no_read': 1},
                                      'swept_sector_intrusions': 4,
                                      'utilisation': 0.3157894736842274,
                                      'peak_normal_force_N': 1343.9472122625466,
                                      'max_impact_speed_m_s': 2.3746811489386257}}}}  # fmt: skip
CASES = {
    "four": ("four_units", dict(parcels=40, rate_pcs_h=6000.0, seed=2)),
    "two_guard": ("two_units", dict(parcels=40, rate_pcs_h=3000.0, seed=3)),
    "two_noguard": ("two_units", dict(parcels=40, rate_pcs_h=3000.0, seed=3, guard=False)),
}
#: the line files' values at 6dd615c where they changed since (four_units: merge_gap 2 m)
THEN = {"four": {"merge_gap": 2.0}}


def pick(summary: dict, like: dict) -> dict:
    """The fields of ``summary`` that ``like`` has (declines: the reasons that occurred)."""
    out = {}
    for k, v in like.items():
        got = summary[k]
        if k == "declined":
            got = {r: n for r, n in got.items() if n}
        out[k] = pick(got, v) if isinstance(v, dict) and k != "declined" else got
    return out


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_the_wired_units_give_main_s_figures(case):
    """Same line, stream and seed: the split line's summary equals main's, exactly (strokes,
    missed strokes whose disturbed pose went downstream, declines, forces, times)."""
    name, cfg = CASES[case]
    line = replace(load_line(name), **THEN.get(case, {}))
    s = LinePlant(line, LineRunConfig(**cfg)).run()
    assert pick(s, MAIN[case]) == MAIN[case]


@pytest.mark.slow
def test_every_handoff_is_counted_at_both_ends():
    """After the drain every link's sent == received, none refused or lost, and the counts
    are the parcels' own: the first unit got one hand-off per induction, the recirculation one
    per parcel that went round (or was rejected at the belt's end)."""
    plant = LinePlant(TWO, LineRunConfig(parcels=40, rate_pcs_h=3000.0, seed=3))
    s = plant.run()
    links = s["links"]
    assert list(links) == ["induction>unit_1", "unit_1>unit_2", "unit_2>recirculation"]
    for v in links.values():
        assert v["sent"] == v["received"] and v["lost"] == 0
        assert sum(v["refused"].values()) == 0
    assert s["handoffs_balanced"]
    assert links["induction>unit_1"]["received"] == s["inductions"]
    ends = sum(p.passes for p in plant.parcels)  # each pass ended at the belt's end
    assert links["unit_2>recirculation"]["received"] == ends
    assert s["handoffs"] == sum(v["received"] for k, v in links.items() if "recirc" not in k)
    # unit_1 passes on what it does not sort
    u1 = s["units"]["unit_1"]
    assert u1["handoffs_out"] == u1["handoffs_in"] - u1["sorted"] - u1["solver_failures"]


def unit(index: int, guard_on: bool = True) -> LineUnit:
    u = TWO.units[index]
    return LineUnit(u, index, len(TWO.units), TWO.width, TWO.speed, TWO.planner, 0.01, guard_on)


def handoff(pid: int, dest: str, frm: int, to: int, t: float, front_x: float) -> HandOff:
    """A parcel of the stream with its front at X = ``front_x`` at time t, on the belt at v."""
    plant = LinePlant(TWO, LineRunConfig(parcels=1, seed=1))
    p = plant.parcels[0]
    spec = replace(p.spec, parcel_id=pid, yaw=0.0, cog_offset_x=0.0, cog_offset_y=0.0)
    x = front_x - 0.5 * spec.length_a
    y = spec.lateral_gap + 0.5 * spec.width_b
    return HandOff(pid, dest, 0, spec, x, y, 0.0, TWO.speed, 0.0, 0.0, t, t, frm, to)


def test_a_unit_refuses_handoffs_it_cannot_take_and_counts_them():
    u = unit(1)
    h = handoff(5, "B", 0, 1, 4.0, TWO.units[1].zone[0])
    r = u.receive(h, 4.0)
    assert r.refusal == UNKNOWN_PARCEL  # the induction never announced parcel 5
    u.announce(5, 0)
    assert u.receive(replace(h, from_unit=INDUCTION), 4.0).refusal == NOT_FROM_UPSTREAM
    assert u.receive(replace(h, passes=1), 4.0).refusal == UNKNOWN_PARCEL  # not that pass
    assert u.receive(replace(h, to_unit=0), 4.0).refusal == NOT_FROM_UPSTREAM
    assert not u.line.parcels and u.received == 0
    assert u.receive(h, 4.0).refusal == ""
    assert u.receive(h, 4.0).refusal == DUPLICATE
    assert u.refused_handoffs == {UNKNOWN_PARCEL: 2, NOT_FROM_UPSTREAM: 2, DUPLICATE: 1}
    assert u.received == 1 and len(u.line.parcels) == 1


def test_a_declined_parcel_goes_on_with_the_pose_it_came_with():
    """Destination A is not unit_2's: declined ``not_served`` and handed to the recirculation
    at once, with the pose and velocity it came with (the unit did not touch it), while the
    unit's simulation carries it through its zone."""
    u = unit(1)
    u.announce(7, 0)
    h = handoff(7, "A", 0, 1, 6.0, TWO.units[1].zone[0])
    r = u.receive(h, 6.0)
    assert r.decision.reason == NOT_SERVED and r.booking is None
    [out] = r.records
    assert (out.from_unit, out.to_unit, out.t) == (1, RECIRCULATION, 6.0)
    assert (out.x, out.y, out.yaw, out.vx, out.vy, out.yaw_rate, out.pose_time) == (
        h.x, h.y, h.yaw, h.vx, h.vy, h.yaw_rate, h.pose_time,
    )  # fmt: skip
    assert u.sent == 1 and u.declined[NOT_SERVED] == 1
    # the unit's simulation has it where the record puts it (mirrored unit: y0 = s - Y)
    lp = u.line.parcels[7 * 16]
    x0, y0, _ = lp.pose(6.5)
    tr = track_of(h, TWO.speed)
    assert x0 + TWO.units[1].position == pytest.approx(tr.x + TWO.speed * 0.5, abs=1e-9)
    assert TWO.width - y0 == pytest.approx(tr.y, abs=1e-9)


@pytest.mark.slow
def test_a_unit_sorts_a_parcel_of_its_destination_from_records_alone():
    """unit_1 alone, fed one hand-off for destination A at its scan line: it books a stroke
    (start after the hand-off, end 2 t1 later), and stepping its clock gives one Sorted record
    into chute A, with the stroke's peak force in its figures."""
    u = unit(0)
    u.announce(3, 0)
    h = handoff(3, "A", INDUCTION, 0, 1.0, TWO.units[0].zone[0])
    r = u.receive(h, 1.0)
    assert r.decision.accepted, r.decision
    b = r.booking
    assert 1.0 <= b.t_start < b.t_end and b.unit == 0 and b.parcel_id == 3
    out = []
    t = 1.0
    while not out and t < 10.0:
        t = round(t + 0.01, 2)
        out += u.advance(t)
    [rec] = out
    assert isinstance(rec, Sorted) and rec.chute == "A" and rec.unit == 0
    assert b.t_start < rec.t <= b.t_end + 1.0  # during the stroke or its settling
    f = u.figures(t)
    assert f["sorted"] == 1 and f["strokes"] == 1 and math.isfinite(f["peak_normal_force_N"])
    assert f["peak_normal_force_N"] > 0.0 and u.chute == 1


def _picture(tracks, bookings) -> tuple[dict, set]:
    cols = ("x", "y", "yaw", "t_ref", "cog_x", "cog_y", "free_after", "free_until")
    return (
        {tr.parcel_id: tuple(getattr(tr, c) for c in cols) for tr in tracks},
        set(bookings),
    )


@pytest.mark.slow
def test_the_traffic_kept_from_records_is_the_line_s_own():
    """At every hand-off the traffic a unit is given (kept by a TrafficView from the records
    of the induction, the units and the belt's end alone) holds the same tracks, poses and
    free times bit for bit, and the same booked strokes, as the line's own state."""
    checked = []

    class Checked(LinePlant):
        def _deliver(self, p, u):
            view = self.view.traffic()
            assert _picture(view.tracks, view.bookings) == _picture(
                self._live_tracks(), self.bookings
            )
            checked.append(len(view.tracks))
            super()._deliver(p, u)

    plant = Checked(TWO, LineRunConfig(parcels=40, rate_pcs_h=3000.0, seed=3))
    s = plant.run()
    assert s["drained"] and plant.records_ignored == 0
    assert len(checked) == s["handoffs"] and max(checked) > 1
    assert not plant.view.tracks and not plant.view.stroking  # everything left the traffic


def test_a_handoff_not_received_by_its_deadline_is_counted_lost_once():
    """unit_2 knows parcel 9 (announced) but gets no hand-off: while the traffic puts its
    front before unit_2's fence axis nothing happens; once past it, the unit counts one
    hand-off lost on its upstream link and sends the parcel on from the predicted ride; a
    hand-off arriving after that is refused as a duplicate."""
    u = unit(1)
    h = handoff(9, "B", 0, 1, 0.0, 0.0)  # front at X = 0 at t = 0, riding at v
    u.announce(9, 0, h.spec, "B")
    tr = track_of(h, TWO.speed)
    axis_t = TWO.units[1].position / TWO.speed  # its front reaches the axis
    traffic = Traffic((tr,))
    assert u.deadlines(axis_t - 0.01, traffic) == [] and u.lost == 0
    [out] = u.deadlines(axis_t + 0.01, traffic)
    assert u.lost == 1 and u.sent == 1 and u.received == 0
    assert (out.parcel_id, out.destination, out.from_unit, out.to_unit) == (9, "B", 1, -2)
    assert (out.x, out.y, out.yaw, out.pose_time) == (tr.x, tr.y, tr.yaw, tr.t_ref)
    assert u.deadlines(axis_t + 1.0, traffic) == []  # once
    assert u.receive(h, axis_t + 1.0).refusal == DUPLICATE
    # a parcel in a stroke upstream (its ride not predicted) is not overdue
    u.announce(10, 0, h.spec, "B")
    busy = replace(track_of(replace(h, parcel_id=10), TWO.speed), free_after=0.5)
    assert u.deadlines(axis_t + 1.0, Traffic((busy,))) == []


@pytest.mark.slow
def test_a_handoff_lost_on_a_link_is_counted_there_and_the_parcel_is_not_lost():
    """The wiring drops unit_1's hand-off of one parcel for unit_2 (destination B, unit_2's):
    unit_2 counts it lost on unit_1>unit_2 and no other link counts anything lost; the
    parcel goes round and ends sorted or rejected like every other: conservation exact."""
    plant = LinePlant(TWO, LineRunConfig(parcels=12, rate_pcs_h=2000.0, seed=3))
    victim = next(p for p in plant.parcels if p.destination == "B")
    plant.drop.add((victim.pid, 0))
    s = plant.run()
    assert not plant.drop  # it was dropped
    links = s["links"]
    assert links["unit_1>unit_2"]["lost"] == 1
    assert links["unit_1>unit_2"]["sent"] == links["unit_1>unit_2"]["received"] + 1
    assert sum(v["lost"] for v in links.values()) == 1
    assert s["handoffs_balanced"] and s["units"]["unit_2"]["handoffs_lost"] == 1
    assert s["drained"] and s["conservation_ok"] and s["sorted_wrong_destination"] == 0
    assert victim.passes >= 1 and victim.state in ("sorted", "rejected")
    assert victim.end in ("B", TWO.reject_chute)
