"""The records a line's parts exchange (ROS-free): hand-offs, sorted outcomes, link counts.

A unit of a line (:class:`~fence_sorter.line.unit.LineUnit`) talks to the rest of the line only
through these plain records, so that it can run in the same process as the others
(:class:`~fence_sorter.line.multi_unit.LinePlant`) or in a process of its own with the records
carried over DDS (the HandOff message of ``msg_defs/msg``):

- :class:`HandOff`: a parcel enters a unit's zone (from the induction or the upstream unit) or
  leaves it (to the next unit, or to the recirculation after the last unit). It carries what the
  receiver needs to simulate and route the parcel: its line-frame spec, its destination (empty on
  a no-read pass), its pass, its pose and velocity at a sim time, and who sent it to whom.
- :class:`Sorted`: a unit's stroke put the parcel into the unit's chute.
- :class:`Failed`: the unit's simulation could not finish the parcel's stroke (solver failure).

A unit refuses a hand-off for a parcel it never heard of (the induction announces every pass of
every parcel), one from anyone but its upstream neighbour, and a second one for the same pass,
counting each under a reason of :data:`REFUSALS`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fence_sorter.inputs import ParcelSpec

__all__ = [
    "INDUCTION",
    "RECIRCULATION",
    "REFUSALS",
    "Failed",
    "HandOff",
    "LinkCounts",
    "Sorted",
    "link_name",
]

#: the sender index of the induction (the upstream neighbour of the first unit)
INDUCTION = -1
#: the receiver index of the recirculation loop (the downstream neighbour of the last unit)
RECIRCULATION = -2

#: why a unit refuses a hand-off
UNKNOWN_PARCEL = "unknown_parcel"
NOT_FROM_UPSTREAM = "not_from_upstream"
DUPLICATE = "duplicate"
REFUSALS = (UNKNOWN_PARCEL, NOT_FROM_UPSTREAM, DUPLICATE)


@dataclass(frozen=True)
class HandOff:
    """A parcel handed from one part of the line to the next (line frame, SI).

    ``spec`` is the parcel's spec with its centre-of-gravity offsets as they are now (a stroke
    may have turned it over); (x, y, yaw) is the pose of C_s at ``pose_time``, and it moves on
    with (vx, vy, yaw_rate) (on the belt: (v, 0, 0)); ``t`` is the sim time of the hand-off."""

    parcel_id: int  # the line's id
    destination: str  # "" on a no-read pass: no unit can know it
    passes: int  # passes completed before this one (0: the first)
    spec: ParcelSpec
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float
    pose_time: float
    t: float
    from_unit: int  # INDUCTION, or the sender's unit index
    to_unit: int  # the receiver's unit index, or RECIRCULATION

    @property
    def no_read(self) -> bool:
        return self.destination == ""


@dataclass(frozen=True)
class Sorted:
    """A parcel a unit's stroke put into its chute (``chute``: the destination the unit
    serves, ``wrong:<unit index>`` if the unit does not serve the parcel's destination)."""

    parcel_id: int
    unit: int
    chute: str
    t: float


@dataclass(frozen=True)
class Failed:
    """A parcel whose stroke the unit's simulation could not finish."""

    parcel_id: int
    unit: int
    t: float
    detail: str = ""


def link_name(from_unit: int, to_unit: int, names: list[str]) -> str:
    """``induction>unit_1``, ``unit_1>unit_2``, ``unit_2>recirculation``."""

    def name(i: int) -> str:
        if i == INDUCTION:
            return "induction"
        if i == RECIRCULATION:
            return "recirculation"
        return names[i]

    return f"{name(from_unit)}>{name(to_unit)}"


@dataclass
class LinkCounts:
    """Hand-offs counted at both ends of each link (``link_name``): sent by the upstream part,
    received by the downstream one, refused by it (per reason), lost (not received within the
    deadline, counted by the side that noticed)."""

    sent: dict[str, int] = field(default_factory=dict)
    received: dict[str, int] = field(default_factory=dict)
    refused: dict[str, dict[str, int]] = field(default_factory=dict)
    lost: dict[str, int] = field(default_factory=dict)

    def count_sent(self, link: str) -> None:
        self.sent[link] = self.sent.get(link, 0) + 1

    def count_received(self, link: str) -> None:
        self.received[link] = self.received.get(link, 0) + 1

    def count_refused(self, link: str, reason: str) -> None:
        per = self.refused.setdefault(link, dict.fromkeys(REFUSALS, 0))
        per[reason] += 1

    def table(self) -> dict[str, dict]:
        links = list(dict.fromkeys([*self.sent, *self.received, *self.refused, *self.lost]))
        return {
            k: {
                "sent": self.sent.get(k, 0),
                "received": self.received.get(k, 0),
                "refused": dict(self.refused.get(k, dict.fromkeys(REFUSALS, 0))),
                "lost": self.lost.get(k, 0),
            }
            for k in links
        }

    def balanced(self) -> bool:
        """Every hand-off sent was received (or refused, or counted lost)."""
        t = self.table()
        return all(
            v["sent"] == v["received"] + sum(v["refused"].values()) + v["lost"] for v in t.values()
        )
