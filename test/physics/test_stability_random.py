"""The random stability campaign: its events lie in the documented space, are reproduced from
(seed, index) alone, and a sample of them solves without a failure."""

from __future__ import annotations

import argparse
import math

from benchmarks.commands import stability_random as command
from fence_sorter.verification import stability_random as R


def test_events_lie_in_the_space_and_fit_the_belt():
    sp = R.SPACE
    r_s = set(R._grid(*sp.r_s))
    t1 = set(R._grid(*sp.t1))
    assert min(r_s) == -0.4 and max(r_s) == 1.0 and len(r_s) == 8
    assert min(t1) == 0.2 and max(t1) == 1.5 and len(t1) == 14
    events = [R.draw_event(7, i) for i in range(300)]
    for ev in events:
        assert sp.mass[0] <= ev.mass <= sp.mass[1]
        assert sp.side[0] <= ev.length_a <= sp.side[1] and sp.side[0] <= ev.width_b <= sp.side[1]
        assert abs(ev.yaw_deg) <= sp.yaw_deg
        assert abs(ev.cog_x) <= 0.5 * ev.length_a and abs(ev.cog_y) <= 0.5 * ev.width_b
        assert sp.belt_speed[0] <= ev.belt_speed <= sp.belt_speed[1]
        assert ev.r_s in r_s and ev.t1 in t1 and ev.alpha_k_deg in sp.alpha_k_deg
        parcel = ev.parcel()
        assert ev.lateral_gap >= 0.0
        assert ev.lateral_gap + parcel.footprint_width() <= sp.belt_width + 1e-12
        parcel.validate(belt_width=sp.belt_width)
    # every fence and settings kind is drawn, and the grid's ends are reached
    assert {e.fence for e in events} == set(sp.fences)
    assert {e.solver for e in events} == set(sp.solvers)
    assert {e.r_s for e in events} == r_s


def test_an_event_is_reproduced_from_seed_and_index_alone():
    assert R.draw_event(11, 16) == R.draw_event(11, 16)
    assert R.draw_event(11, 16) != R.draw_event(11, 17)
    assert R.draw_event(11, 16) != R.draw_event(12, 16)


def test_a_sample_of_events_solves_within_the_penetration_limit():
    """50 events in process (seed 2024): none fails, every solve's D stays below the solver's
    deep-penetration limit contact.deep_penetration x min(A, B)."""
    outcomes = R.run_chunk(2024, range(50))
    s = R.summarise(outcomes)
    assert s["events"] == 50
    assert s["failures"] == 0, s["regions"]
    assert s["solved"] == 50
    assert all(o["d_ratio"] < 1.0 for o in outcomes)
    assert 0.0 < s["max_d"] < 0.5 * R.SPACE.side[1]
    assert math.isfinite(s["max_peak_n"])


def test_the_command_refuses_bad_arguments(capsys):
    for field, value in (("events", 0), ("seed", -1), ("workers", 0)):
        args = argparse.Namespace(events=10, seed=1, workers=None, out="")
        setattr(args, field, value)
        assert command.run(args) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--{field} must be in" in err
