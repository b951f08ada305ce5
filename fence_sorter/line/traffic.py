"""The line's traffic rebuilt from records alone (ROS-free): what a unit's guard must know.

A unit's swept-sector guard needs the predicted tracks of every other parcel on the line and
every unit's booked strokes (:class:`~fence_sorter.line.unit.Traffic`). A
:class:`TrafficView` keeps them from the records the line's parts publish, so that a unit in a
process or on a host of its own can keep its own copy:

- :class:`Announce` (the induction): a parcel's predicted ride for a pass, from when the
  induction knows it (the stream is drawn ahead) until it leaves the belt;
- :class:`Hold` (the induction): it held parcels not yet inducted by a delay;
- :class:`~fence_sorter.line.routing.Booking` (a unit): a stroke booked for a parcel; from its
  start on the parcel may leave the belt's kinematics;
- :class:`~fence_sorter.line.handoff.HandOff` (a unit): after a stroke that did not sort the
  parcel, its new pose (the stroke's booking ends); a hand-off passing a parcel on untouched
  leaves its ride as it was;
- :class:`~fence_sorter.line.handoff.Sorted`, :class:`~fence_sorter.line.handoff.Failed`
  (a unit) and :class:`Left` (the belt's end): the parcel leaves the traffic;
- the clock: a booking whose stroke is over and whose parcel is no longer in a stroke is
  dropped at each step's end (:meth:`TrafficView.tick`).

The in-process line feeds one view with every record it makes and gives its units the view's
traffic, so that its figures are those of records alone (``test/line/test_line_unit.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from fence_sorter.line.handoff import Failed, HandOff, Sorted
from fence_sorter.line.routing import SETTLE_SLACK, Booking, Track
from fence_sorter.line.unit import Traffic, track_of

__all__ = ["Announce", "Hold", "Left", "TrafficView"]


@dataclass(frozen=True)
class Announce:
    """The induction's prediction of a parcel's ride for a pass (line frame)."""

    parcel_id: int
    passes: int
    track: Track


@dataclass(frozen=True)
class Hold:
    """The induction held these parcels (not yet inducted) by ``delay`` [s]."""

    parcel_ids: tuple[int, ...]
    delay: float


@dataclass(frozen=True)
class Left:
    """The parcel left the belt at its end (to the recirculation or the reject chute)."""

    parcel_id: int


class TrafficView:
    """The tracks and booked strokes of a line, kept from its records (:meth:`apply`)."""

    def __init__(self, speed: float):
        self.v = speed
        self.tracks: dict[int, Track] = {}
        self.bookings: list[Booking] = []
        self.stroking: set[int] = set()  # parcels with a booked or running stroke
        self.applied = 0

    def apply(self, rec: object) -> None:
        self.applied += 1
        if isinstance(rec, Announce):
            self.tracks[rec.parcel_id] = replace(rec.track)
        elif isinstance(rec, Hold):
            for pid in rec.parcel_ids:
                self.tracks[pid].t_ref += rec.delay
        elif isinstance(rec, Booking):
            self.bookings.append(rec)
            self.stroking.add(rec.parcel_id)
            tr = self.tracks[rec.parcel_id]
            tr.free_after = rec.t_start
            tr.free_until = rec.t_end + SETTLE_SLACK
        elif isinstance(rec, HandOff | Sorted | Failed):
            if rec.parcel_id in self.stroking:  # its stroke is over
                self.stroking.discard(rec.parcel_id)
                self.bookings = [b for b in self.bookings if b.parcel_id != rec.parcel_id]
            if isinstance(rec, HandOff):
                self.tracks[rec.parcel_id] = track_of(rec, self.v)
            else:
                self.tracks.pop(rec.parcel_id, None)
        elif isinstance(rec, Left):
            self.tracks.pop(rec.parcel_id, None)
        else:
            raise TypeError(f"not a traffic record: {type(rec).__name__}")

    def tick(self, t: float) -> None:
        """The clock reached ``t``: drop the bookings whose strokes are over."""
        self.bookings = [b for b in self.bookings if b.t_end > t or b.parcel_id in self.stroking]

    def traffic(self) -> Traffic:
        return Traffic(tuple(self.tracks.values()), tuple(self.bookings))
