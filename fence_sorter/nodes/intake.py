"""What a node takes in on /parcels and /fence_commands, counted where it is dropped (ROS-free).

Every message a subscription callback gets passes :meth:`TopicIntake.admit` first:

- a message of another run (its ``run_id`` is not this run's, when the node has one) is
  refused and counted as ``foreign``: it never reaches the line, the planner or the figures;
- a message with the run's id whose sender's tag does not verify under the run's key (when
  the node has one: :mod:`fence_sorter.provenance`) is refused and counted as
  ``foreign_source``: an insider with the run's id reaches no further than a foreign run, and
  before the rate limit, so a forged flood spends none of the real sender's tokens;
- beyond the topic's rate (a token bucket on the steady clock: ``rate`` messages per second,
  bursts up to ``burst``) a message is refused and counted as ``rate_limited``, so a flood
  cannot starve the node's real work (the simulator's forwarding and publishing, the
  controller's planning);
- messages the middleware lost before the callback (rclpy's message-lost QoS event, where the
  RMW provides it) are added as ``lost``.

The counters go to /diagnostics as ``<topic>.<counter>`` (``parcels.foreign``, ...).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import fields

#: default rate limit of /parcels and /fence_commands per node [messages/s], and the burst: far
#: above any stream (2400 parcels/h is 0.7/s; unpaced at 30x real time about 20/s), far below
#: a flood (thousands per second)
INPUT_RATE = 200.0
INPUT_BURST = 400.0


class TokenBucket:
    """``rate`` tokens per second up to ``burst``; :meth:`take` spends one if there is one."""

    def __init__(
        self, rate: float, burst: float, clock: Callable[[], float] = time.monotonic
    ) -> None:
        if not (rate > 0.0 and burst >= 1.0):
            raise ValueError(
                f"rate must be in (0, inf) /s and burst in [1, inf), got {rate}, {burst}"
            )
        self.rate, self.burst, self.clock = rate, burst, clock
        self.tokens = burst
        self.t = clock()

    def take(self) -> bool:
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
        self.t = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


class TopicIntake:
    """Admission and drop counters of one input topic of one node."""

    COUNTERS = ("received", "accepted", "foreign", "foreign_source", "rate_limited", "lost")

    def __init__(
        self,
        name: str,
        run_id: int,
        rate: float = INPUT_RATE,
        burst: float = INPUT_BURST,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.name = name
        self.run_id = int(run_id)
        self.bucket = TokenBucket(rate, burst, clock)
        self.received = self.accepted = self.foreign = self.foreign_source = 0
        self.rate_limited = self.lost = 0

    def admit(self, msg_run_id: int, authentic: Callable[[], bool] | None = None) -> bool:
        """True: take the message; False: it is refused (and counted). ``authentic``: checks
        the sender's tag (called only for a message with the run's id)."""
        self.received += 1
        if self.run_id and int(msg_run_id) != self.run_id:
            self.foreign += 1
            return False
        if authentic is not None and not authentic():
            self.foreign_source += 1
            return False
        if not self.bucket.take():
            self.rate_limited += 1
            return False
        self.accepted += 1
        return True

    def on_message_lost(self, info) -> None:
        """rclpy's message-lost event (rmw_message_lost_status_t): count what it says."""
        self.lost += int(getattr(info, "total_count_change", 1))

    @property
    def dropped(self) -> int:
        """Messages that got no further than this intake."""
        return self.foreign + self.foreign_source + self.rate_limited + self.lost

    def values(self) -> dict[str, str]:
        return {f"{self.name}.{k}": str(getattr(self, k)) for k in self.COUNTERS}


def spec_fingerprint(spec) -> tuple[str, ...]:
    """A parcel spec's fields as text, NaN equal to NaN (``mu_*`` NaN: the scene's value)."""
    return tuple(repr(getattr(spec, f.name)) for f in fields(spec))


class ParcelRegistry:
    """The first accepted message of every parcel id, and what a later one for the same id is.

    ``duplicate``: the same spec again (harmless, refused and counted); ``conflict``: another
    spec for a known id. Two authentic messages that disagree cannot both be the parcel on the
    belt: the first one stays (its stroke may be under way), the id is kept in ``disputed``,
    named on /diagnostics and flagged in its outcome, and the run does not end clean.
    """

    def __init__(self) -> None:
        self.specs: dict[int, tuple[str, ...]] = {}
        self.duplicates = 0
        self.conflicts = 0
        self.disputed: set[int] = set()

    def register(self, spec) -> str:
        """``new`` (now known), ``duplicate`` or ``conflict`` for a parcel spec."""
        pid = int(spec.parcel_id)
        known = self.specs.get(pid)
        if known is None:
            self.specs[pid] = spec_fingerprint(spec)
            return "new"
        if known == spec_fingerprint(spec):
            self.duplicates += 1
            return "duplicate"
        self.conflicts += 1
        self.disputed.add(pid)
        return "conflict"

    def values(self, prefix: str = "parcels") -> dict[str, str]:
        """Counters for /diagnostics: duplicates, conflicts and the disputed ids."""
        return {
            f"{prefix}.duplicate": str(self.duplicates),
            f"{prefix}.conflict": str(self.conflicts),
            f"{prefix}.disputed_ids": ",".join(str(i) for i in sorted(self.disputed)),
        }
