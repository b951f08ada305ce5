"""The line in lockstep (fence_sorter/line/lockstep.py): an owner of the clock and units that
each keep their own state and their own copy of the traffic, talking by commands, replies
and hand-offs only.

Whatever carries the messages, the lockstep line must give the in-process line's figures
exactly, count every hand-off at both ends of its link, and keep each unit's traffic equal to
the owner's; a unit must apply its commands in their order however they arrive.
"""

from __future__ import annotations

import math
import random
from dataclasses import replace

import pytest

from fence_sorter.line.handoff import HandOff, Sorted
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
    answered,
    decode,
    encode,
    join_batch,
    make_unit,
    split_batch,
)
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.traffic import Announce, Hold

TWO = load_line("two_units")
#: the summary's fields that are the wall clock's, not the line's
WALL = ("wall_time_s", "real_time_factor")


def _line(cfg: LineRunConfig, links_cls=LocalLinks):
    sides = [UnitSide(make_unit(TWO, k, cfg)) for k in range(len(TWO.units))]
    links = links_cls(sides)
    return LockstepOwner(TWO, cfg, links), sides, links


def _equal(x: object, y: object) -> bool:
    """Equal, a NaN equal to a NaN (the throughput of a run with no steady window)."""
    both_nan = isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y)
    return both_nan or x == y


def _same(a: dict, b: dict) -> dict:
    return {k: (a[k], b.get(k)) for k in a if k not in WALL and not _equal(a[k], b.get(k))}


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


class WireLinks(LocalLinks):
    """Every command, reply and hand-off goes through encode/decode (JSON text) on its way."""

    def send(self, k, body):
        super().send(k, decode(encode(body)))

    def hand_off(self, h):
        super().hand_off(decode(encode(h)))

    def _route(self, k, out):
        super()._route(k, [decode(encode(o)) for o in out])


@pytest.mark.slow
def test_the_line_through_its_wire_format_gives_the_same_figures():
    """Every message written as JSON text and read back (what the line's nodes send over DDS):
    the summary equals LinePlant's exactly, so no float lost a bit on the way."""
    cfg = LineRunConfig(parcels=12, rate_pcs_h=2000.0, seed=3)
    ref = LinePlant(TWO, cfg).run()
    owner, _, _ = _line(cfg, WireLinks)
    assert _same(ref, owner.run()) == {}


class BatchLinks(LocalLinks):
    """What the line's owner node does: a unit's commands held back until one it answers, then
    all of them in one message (join_batch), which the unit splits and reads one by one."""

    def __init__(self, sides):
        super().__init__(sides)
        self.held = [[] for _ in sides]
        self.messages = [[] for _ in sides]  # each message: the bodies it carried

    def send(self, k, body):
        self.held[k].append(encode(Command(self.seq[k], body)))
        self.seq[k] += 1
        if answered(body):
            text = join_batch(self.held[k])
            self.held[k] = []
            cmds = [decode(t) for t in split_batch(text)]
            self.messages[k].append([c.body for c in cmds])
            for cmd in cmds:
                self._route(k, self.sides[k].on_command(cmd))


@pytest.mark.slow
def test_commands_batched_up_to_the_one_answered_give_the_same_figures():
    """A unit's commands sent in batches, each ending with a command it answers (a step's
    Tick, traffic records and Step in one message): the summary equals LinePlant's exactly,
    every message ends with its only answered command, and no command is left unsent."""
    cfg = LineRunConfig(parcels=12, rate_pcs_h=2000.0, seed=3)
    ref = LinePlant(TWO, cfg).run()
    owner, _, links = _line(cfg, BatchLinks)
    assert _same(ref, owner.run()) == {}
    for k, msgs in enumerate(links.messages):
        assert [sum(map(answered, m)) for m in msgs] == [1] * len(msgs)
        assert all(answered(m[-1]) for m in msgs)
        assert sum(map(len, msgs)) == links.seq[k] and links.held[k] == []
        # a step of the clock is one message, not one per command: Ticks ride with Steps
        steps = sum(isinstance(b, Step) for m in msgs for b in m)
        assert len(msgs) < sum(map(len, msgs)) and steps <= len(msgs)


def test_a_batch_splits_into_the_commands_it_joined():
    """Texts with newlines escaped by JSON (a destination named with one) come back whole."""
    plant = LinePlant(TWO, LineRunConfig(parcels=1, seed=4))
    p = plant.parcels[0]
    texts = [
        encode(Command(0, Scan(p.pid, 0, p.spec, "A\nB"))),
        encode(Command(1, Step(0.0, 0.01))),
    ]
    assert split_batch(join_batch(texts)) == texts
    assert decode(split_batch(join_batch(texts))[0]).body.destination == "A\nB"
    assert split_batch(texts[1]) == [texts[1]]


def test_the_wire_format_reads_back_bit_for_bit():
    """A hand-off with values that are not short decimals, inf and NaN fields, tuples of
    records: decode(encode(x)) == x, field by field (NaN compared as NaN)."""
    plant = LinePlant(TWO, LineRunConfig(parcels=1, seed=4))
    p = plant.parcels[0]
    h = HandOff(
        p.pid, "C", 1, p.spec, 7.123456789012345, 0.1 + 0.2, -2.7182818, 0.987654321, 0.0,
        0.0, 12.345678901234567, 12.355, 0, 1,
    )  # fmt: skip
    tr = plant._track_at_induction(p, 1.0 / 3.0)
    done = Done(1.0 / 3.0, (h,), (Sorted(3, 1, "B", 2.0),))
    for o in (h, Announce(3, 0, tr), done, Hold((1, 2), 0.01)):
        back = decode(encode(o))
        assert type(back) is type(o)
        assert repr(back) == repr(o)  # NaN fields (mu_belt) included
    assert decode(encode(tr)).free_after == math.inf


def test_the_owner_s_observers_see_every_step_and_the_units_records():
    """A view's hook on the owner (LinePlant.observers): called once per step of the clock,
    with the records the units' simulations sent in it, as on LinePlant."""
    cfg = LineRunConfig(parcels=3, rate_pcs_h=2000.0, seed=3)

    def watch(plant):
        seen = []
        plant.observers.append(lambda pl, recs: seen.append((pl.t, list(recs))))
        plant.run()
        return seen

    ref = watch(LinePlant(TWO, cfg))
    owner, _, _ = _line(cfg)
    got = watch(owner)
    assert [t for t, _ in got] == [t for t, _ in ref] and len(got) > 100
    assert [recs for _, recs in got] == [recs for _, recs in ref]
    assert any(recs for _, recs in got)


class ForgedLinks(LocalLinks):
    """An insider on the units' reply links: before unit 0's real answer it slips in a reply
    of another kind, another step or another parcel (``mismatched``), or one that matches
    what the owner waits for but carries nothing (``matching``: a Done of the right step with
    no records, or a Delivered of the right parcel declining it)."""

    def __init__(self, sides, matching: bool):
        super().__init__(sides)
        self.matching = matching
        self.forged = 0

    def wait(self, k):
        real = super().wait(k)
        if k != 0 or self.forged >= 3:
            return real
        if self.matching and isinstance(real, Done):
            fake = Done(real.t, (), ())
        elif self.matching:
            return real
        else:
            fake = Done(-1.0, (), ()) if self.forged % 2 else Delivered(-7, "", None, None, ())
        self.forged += 1
        self.replies[k].insert(0, real)  # the real answer comes after the forged one
        return fake


@pytest.mark.slow
def test_a_reply_the_owner_did_not_ask_for_is_refused_and_named_never_asserted():
    """Forged replies on a unit's link never kill the owner. Those that answer nothing asked
    are refused and counted, and the line's figures equal the undisturbed line's; one that
    matches a question takes the real answer's place, which is then refused as unasked: the
    line is not clean (line_problems names the unit), so a changed figure never passes."""
    from fence_sorter.line.multi_unit import line_problems

    cfg = LineRunConfig(parcels=10, rate_pcs_h=2000.0, seed=3)
    ref = LinePlant(TWO, cfg).run()
    assert not line_problems(ref)
    name = TWO.units[0].name
    for matching in (False, True):
        owner, _, links = _line(cfg, lambda sides, m=matching: ForgedLinks(sides, m))
        got = owner.run()
        assert links.forged == 3
        assert len(got["replies_refused"][name]) == 3, got["replies_refused"]
        problems = line_problems(got)
        assert any(p.startswith(f"{name}: 3 replies the owner did not ask for") for p in problems)
        if not matching:
            assert _same(ref, got) == {}


class RedirectedLinks(LocalLinks):
    """An insider on unit_2's upstream link: every hand-off of a parcel to A (which unit_2
    does not serve) arrives there as one to B (which it does)."""

    def __init__(self, sides):
        super().__init__(sides)
        self.redirected: set[int] = set()

    def _route(self, k, out):
        def redirect(o):
            if isinstance(o, HandOff) and o.to_unit == 1 and o.destination == "A":
                self.redirected.add(o.parcel_id)
                return replace(o, destination="B")
            return o

        super()._route(k, [redirect(o) for o in out])


@pytest.mark.slow
def test_a_parcel_sorted_on_a_redirected_hand_off_counts_as_a_wrong_destination():
    """The owner judges a Sorted record by the destination it knows, not by the one the
    hand-off carried: the parcels to A that unit_2 sorted into B on forged hand-offs are
    sorted to a wrong destination, and the line is not clean."""
    from fence_sorter.line.multi_unit import line_problems

    cfg = LineRunConfig(parcels=30, rate_pcs_h=3000.0, seed=3)
    owner, _, links = _line(cfg, RedirectedLinks)
    got = owner.run()
    misled = [p.pid for p in owner.parcels if p.pid in links.redirected and p.end == "wrong:1"]
    assert misled and got["sorted_wrong_destination"] >= len(misled)
    assert got["sorted_per_destination"]["B"] + len(misled) <= got["sorted"]
    assert any("sorted to a wrong destination" in p for p in line_problems(got))
