"""A unit of a lockstep line goes down mid-run (fence_sorter/line/lockstep.py), in process:
the unit's side is dropped with everything it was sent or owed, as a killed process is.

The line must go on: the parcels in the dead unit's strokes are lost with it and named, its
stand-in passes the other parcels on (declined ``unit_down``, so its destinations recirculate),
every link still balances and conservation stays exact; a new process of the unit rejoins at a
step boundary from the owner's traffic and sorts again. Its downtime is counted in sim time
and, on the owner's wall clock (here one the test moves), in wall time from the start of the
wait for the reply it never gave.
"""

from __future__ import annotations

import pytest

from fence_sorter.line.line_file import load_line
from fence_sorter.line.lockstep import LocalLinks, LockstepOwner, UnitDown, UnitSide, make_unit
from fence_sorter.line.multi_unit import LineRunConfig

pytestmark = pytest.mark.slow

TWO = load_line("two_units")
CFG = LineRunConfig(parcels=20, rate_pcs_h=3000.0, seed=3)
K = 1  # unit_2 (destinations B and C; B only it serves)
#: the wall clock the test gives the owner: it moves WALL_STEP [s] per step of the line, and
#: the links waited WAITED [s] for the reply of a unit that is gone before giving up
WALL_STEP, WAITED = 0.5, 3.0


class _Waiting(LocalLinks):
    def wait(self, k: int):
        try:
            return super().wait(k)
        except UnitDown as exc:
            raise UnitDown(k, str(exc), WAITED) from None


def _run(back_after: float | None) -> tuple[dict, LockstepOwner, list]:
    """Run the line; kill unit_2 when it first holds a parcel in a stroke, start a new
    process of it ``back_after`` [s] of sim time later (None: never)."""
    sides = [UnitSide(make_unit(TWO, k, CFG)) for k in range(len(TWO.units))]
    links = _Waiting(sides)
    wall = [1000.0]
    owner = LockstepOwner(TWO, CFG, links, wall_clock=lambda: wall[0])
    owner.warm_up()
    killed_at, in_stroke, new = None, [], []
    while owner.active() and owner.t < owner.limit():
        if killed_at is None:
            in_stroke = [p.pid for p in owner.live if p.stroke_unit == K]
            if in_stroke:
                killed_at = owner.t
                links.kill(K)
        elif back_after is not None and not new and owner.t >= killed_at + back_after:
            new.append(UnitSide(make_unit(TWO, K, CFG)))
            links.start_again(K, new[0])
        owner.step()
        wall[0] += WALL_STEP
    s = owner.summary()
    assert killed_at is not None
    return s, owner, [in_stroke, new]


def _accounted(s: dict) -> None:
    assert s["drained"] and s["conservation_ok"] and s["handoffs_balanced"], s
    n = s["parcels_inducted"]
    assert (
        n
        == CFG.parcels
        == (s["sorted"] + s["rejected"] + s["solver_failures"] + s["lost_with_unit"])
    )
    for link, v in s["links"].items():
        assert v["sent"] == v["received"] + sum(v["refused"].values()) + v["lost"], link


def test_a_unit_down_for_good_costs_its_parcels_in_stroke_and_the_line_drains():
    s, owner, (in_stroke, _) = _run(None)
    _accounted(s)
    down = s["units_down"]["unit_2"]
    # the parcels in its stroke when it died are lost with it, named, and no other
    assert down["lost_parcels"] == in_stroke and s["lost_with_unit"] == len(in_stroke) >= 1
    assert {owner.by_id[i].end for i in in_stroke} == {"unit_down:unit_2"}
    assert down["down_at_end"] and down["rejoins"] == 0 and down["downtime_s"] > 0
    # to the end of the run: the steps since it went down on the wall, and the wait before
    steps = round(down["downtime_s"] / CFG.dt)
    assert down["downtime_wall_s"] == WAITED + WALL_STEP * steps
    # the stand-in took every later hand-off to it and passed each on: B (served by unit_2
    # alone) is never sorted after the kill, its parcels recirculate to the reject chute
    assert down["handoffs_passed_on"] == s["declined"]["unit_down"] > 0
    assert s["units"]["unit_2"]["declined"]["unit_down"] == down["handoffs_passed_on"]
    b_late = [p for p in owner.parcels if p.destination == "B" and p.pid not in in_stroke
              and p.end != "B"]  # fmt: skip
    assert b_late and all(p.end == TWO.reject_chute for p in b_late)


def test_a_restarted_unit_rejoins_and_sorts_again():
    s, owner, (in_stroke, new) = _run(4.0)
    _accounted(s)
    down = s["units_down"]["unit_2"]
    assert down["lost_parcels"] == in_stroke and down["rejoins"] == 1
    assert not down["down_at_end"] and 4.0 <= down["downtime_s"] < 4.0 + 2 * CFG.dt
    # wall time: the wait for the reply it never gave, then the steps until it rejoined
    steps = round(down["downtime_s"] / CFG.dt)
    assert down["downtime_wall_s"] == WAITED + WALL_STEP * steps
    # the new process routed parcels announced after it rejoined and sorted some of them
    side = new[0]
    assert side.unit.received > 0 and side.unit.sorted > 0
    # its figures in the summary hold its earlier process's counts too (kept from replies)
    u2 = s["units"]["unit_2"]
    assert u2["handoffs_in"] == s["links"]["unit_1>unit_2"]["received"]
    assert u2["sorted"] >= side.unit.sorted
    # and its view started as the owner's: the tracks it holds are the owner's at the end
    assert set(side.view.tracks) == set(owner.view.tracks)
