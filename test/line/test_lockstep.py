"""The line in lockstep (fence_sorter/line/lockstep.py): an owner of the clock and units that
each keep their own state and their own copy of the traffic, talking by commands, replies
and hand-offs only.

Whatever carries the messages, the lockstep line must give the in-process line's figures
exactly, count every hand-off at both ends of its link, and keep each unit's traffic equal to
the owner's; a unit must apply its commands in their order however they arrive.
"""

from __future__ import annotations

import random

import pytest

from fence_sorter.line.handoff import HandOff
from fence_sorter.line.line_file import load_line
from fence_sorter.line.lockstep import (
    Command,
    Deliver,
    Delivered,
    Done,
    LocalLinks,
    LockstepOwner,
    Scan,
    Step,
    UnitSide,
    make_unit,
)
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig

TWO = load_line("two_units")
#: the summary's fields that are the wall clock's, not the line's
WALL = ("wall_time_s", "real_time_factor")


def _line(cfg: LineRunConfig, links_cls=LocalLinks):
    sides = [UnitSide(make_unit(TWO, k, cfg)) for k in range(len(TWO.units))]
    links = links_cls(sides)
    return LockstepOwner(TWO, cfg, links), sides, links


def _same(a: dict, b: dict) -> dict:
    return {k: (a[k], b.get(k)) for k in a if k not in WALL and a[k] != b.get(k)}


@pytest.mark.slow
@pytest.mark.parametrize(
    "cfg",
    [
        LineRunConfig(parcels=40, rate_pcs_h=3000.0, seed=3),
        LineRunConfig(parcels=40, rate_pcs_h=3000.0, seed=3, guard=False),
    ],
    ids=["guard", "no_guard"],
)
def test_the_lockstep_line_gives_the_in_process_figures_exactly(cfg):
    """Same line, stream and seed: every field of the summary (strokes, declines per reason,
    forces, link counts, throughput) equals LinePlant's; the run drained with conservation
    exact and every hand-off received at the other end of its link."""
    ref = LinePlant(TWO, cfg).run()
    owner, sides, links = _line(cfg)
    got = owner.run()
    assert _same(ref, got) == {}
    assert got["drained"] and got["conservation_ok"] and got["handoffs_balanced"]
    for v in got["links"].values():
        assert v["sent"] == v["received"] and v["lost"] == 0
    # each unit took on its link exactly the hand-offs it was sent (none left over), and the
    # recirculation got one per parcel that reached the belt's end
    for k, side in enumerate(sides):
        name = TWO.units[k].name
        assert side.arrived == got["units"][name]["handoffs_in"] and not side.inbox
        assert not side.blocked and not side.early
    assert len(links.recirculation) == got["links"]["unit_2>recirculation"]["received"]


@pytest.mark.slow
def test_every_unit_keeps_the_owner_s_traffic():
    """At every delivery the routing unit's own TrafficView (kept from the records on its
    command stream) holds the same tracks and bookings as the owner's, field by field."""
    checked = []

    class Checked(UnitSide):
        def _deliver(self, d):
            mine = self.view.traffic()
            theirs = owner.view.traffic()
            assert [vars(t) for t in mine.tracks] == [vars(t) for t in theirs.tracks]
            assert mine.bookings == theirs.bookings
            checked.append(len(mine.tracks))
            return super()._deliver(d)

    cfg = LineRunConfig(parcels=20, rate_pcs_h=3000.0, seed=3)
    sides = [Checked(make_unit(TWO, k, cfg)) for k in range(len(TWO.units))]
    owner = LockstepOwner(TWO, cfg, LocalLinks(sides))
    s = owner.run()
    assert len(checked) == s["handoffs"] and max(checked) > 1


class ShuffledLinks(LocalLinks):
    """Commands reach a unit in batches whose order is shuffled (a transport that does not
    keep order between messages): the unit must still apply them in sequence."""

    def __init__(self, sides):
        super().__init__(sides)
        self.rng = random.Random(5)
        self.pending: list[list[Command]] = [[] for _ in sides]

    def send(self, k, body):
        self.pending[k].append(Command(self.seq[k], body))
        self.seq[k] += 1
        if isinstance(body, Deliver | Step) or len(self.pending[k]) > 6:
            self.flush(k)

    def flush(self, k):
        batch, self.pending[k] = self.pending[k], []
        self.rng.shuffle(batch)
        for cmd in batch:
            self._route(k, self.sides[k].on_command(cmd))

    def wait(self, k):
        self.flush(k)
        return super().wait(k)

    def hand_off(self, h):
        for k in range(len(self.sides)):
            self.flush(k)
        super().hand_off(h)


@pytest.mark.slow
def test_commands_out_of_order_give_the_same_line():
    """Commands shuffled on their way (numbered, buffered by the unit until their turn):
    the summary is the in-order one."""
    cfg = LineRunConfig(parcels=12, rate_pcs_h=2000.0, seed=3)
    ref = LinePlant(TWO, cfg).run()
    owner, sides, _ = _line(cfg, ShuffledLinks)
    assert _same(ref, owner.run()) == {}


def test_a_deliver_waits_for_its_handoff_and_the_commands_behind_it_wait_too():
    """A Deliver that comes before its hand-off blocks the unit's stream: the Step behind it
    is not applied until the hand-off arrives; then both answer, in order."""
    cfg = LineRunConfig(parcels=1, seed=1)
    plant = LinePlant(TWO, cfg)
    p = plant.parcels[0]
    side = UnitSide(make_unit(TWO, 0, cfg))
    track = plant._track_at_induction(p, 0.0)
    t = 2.0 / TWO.speed  # its front at the unit's scan line (2 m ahead of X = 0... of the axis)
    h = HandOff(
        p.pid, p.destination, 0, p.spec, track.x, track.y, track.yaw, TWO.speed, 0.0, 0.0,
        track.t_ref, t, -1, 0,
    )  # fmt: skip
    assert side.on_command(Command(0, Scan(p.pid, 0, p.spec, p.destination))) == []
    assert side.on_command(Command(1, Deliver(p.pid, 0, -1, t))) == []
    assert side.blocked
    assert side.on_command(Command(2, Step(t, t + cfg.dt))) == []  # waits behind the Deliver
    out = side.on_handoff(h)
    replies = [o for o in out if not isinstance(o, HandOff)]
    assert [type(r) for r in replies] == [Delivered, Done]
    assert replies[0].parcel_id == p.pid and replies[0].refusal == ""
    assert replies[1].t == t and side.unit.received == 1 and side.arrived == 1
    # a repeated command is ignored
    assert side.on_command(Command(2, Step(t, t + cfg.dt))) == []
