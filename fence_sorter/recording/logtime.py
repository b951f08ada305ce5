"""Bag log times that agree with the header stamps on every topic (no ROS).

A rosbag2 log time is the recorder's clock when the message arrived. On a topic with several
publishers (``/diagnostics``: every node) one message can arrive after another that was stamped
later (its node had not processed the newest ``/clock`` yet, or was busy), so ordering the topic
by log time and by ``header.stamp`` disagree. Rerun's ``rerun mcap check --full`` reports that
as a row-order conflict: it lex-sorts each topic's rows by ``message_log_time``,
``message_publish_time`` and ``ros2_timestamp`` (the header stamp) and requires every one of them
to come out non-decreasing.

:class:`StampOrder` keeps, per topic whose messages begin with a ``std_msgs/Header``, the
(stamp, log time) pairs written so far and gives a new message the reception time clamped into
``[lo, hi]``: ``lo`` the log time of the latest message stamped no later, ``hi`` that of the
earliest message stamped later. Log time is then a non-decreasing function of the stamp on every
topic. A message whose stamp is not older than any before it (every single-publisher topic)
keeps its reception time exactly; an out-of-order one is logged at the log time of the first
message stamped after it (earlier than its reception by the size of the race). Only messages
stamped within ``tolerance`` of their reception take part: a stamp on another clock (a
sim-time node recorded by a recorder on system time) keeps its reception time and moves no
other message, so a misconfigured clock costs the check, never the timing of the bag. A zero
stamp always takes part: it comes from a sim-time node whose clock has not started yet (a
scanner's first heartbeat before its first /clock, received seconds into the run), and is
logged before every message stamped later.
"""

from __future__ import annotations

import heapq
import itertools
import struct
import time
from bisect import bisect_right
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from rosbags.typesys.store import Typestore

HEADER_TYPE = "std_msgs/msg/Header"
#: (stamp, log time) pairs kept per topic; a message stamped before all of them (more than this
#: many messages late) is logged at the oldest kept pair's log time
DEFAULT_WINDOW = 4096
#: a stamp further than this from the reception time is on another clock [ns] (a node's sim
#: clock lags by the length of its busiest callback, times the real-time factor)
DEFAULT_TOLERANCE_NS = 5_000_000_000
_LE = struct.Struct("<iI")
_BE = struct.Struct(">iI")


def starts_with_header(typestore: Typestore, msgtype: str) -> bool:
    """Whether ``msgtype``'s first field is a ``std_msgs/Header`` (its stamp is what Rerun reads
    as ``ros2_timestamp``)."""
    try:
        _, fields = typestore.fielddefs[msgtype]
    except KeyError:
        return False
    if not fields:
        return False
    _, (_, ref) = fields[0]
    return ref == HEADER_TYPE


def header_stamp_ns(data: bytes | memoryview) -> int | None:
    """``header.stamp`` [ns] of a CDR message that starts with a Header (XCDR1, either byte
    order); None for another encapsulation or a message too short to hold a stamp."""
    if len(data) < 12 or data[0] != 0:
        return None
    if data[1] == 1:
        sec, nanosec = _LE.unpack_from(data, 4)
    elif data[1] == 0:
        sec, nanosec = _BE.unpack_from(data, 4)
    else:
        return None
    return sec * 1_000_000_000 + nanosec


@dataclass
class _Pairs:
    stamps: list[int] = field(default_factory=list)  # sorted
    logs: list[int] = field(default_factory=list)  # non-decreasing, as the stamps


@dataclass
class StampOrder:
    """Log times per topic that never disagree with the header stamps (see the module doc).

    ``window`` (stamp, log time) pairs are kept per topic; stamps more than ``tolerance_ns``
    from their reception time are left alone. Not thread-safe: the writer thread owns it.
    """

    window: int = DEFAULT_WINDOW
    tolerance_ns: int = DEFAULT_TOLERANCE_NS
    _topics: dict[object, _Pairs] = field(default_factory=dict)
    adjusted: int = 0  # messages logged before their reception time (out of stamp order)

    def __post_init__(self) -> None:
        if self.window < 1:
            raise ValueError(f"StampOrder: window must be >= 1, got {self.window}")
        if self.tolerance_ns < 0:
            raise ValueError(f"StampOrder: tolerance_ns must be >= 0, got {self.tolerance_ns}")

    def log_time(self, topic: object, received_ns: int, data: bytes | memoryview) -> int:
        """Log time [ns] of a message of ``topic`` (a topic whose type starts with a Header)
        received at ``received_ns``; the message is remembered."""
        stamp = header_stamp_ns(data)
        # a zero stamp is a sim-time node whose clock has not started (no /clock yet): it
        # takes part whatever its distance, so it is logged before every later stamp
        if stamp is None or (stamp != 0 and abs(stamp - received_ns) > self.tolerance_ns):
            return received_ns
        pairs = self._topics.setdefault(topic, _Pairs())
        stamps, logs = pairs.stamps, pairs.logs
        if not stamps or stamp >= stamps[-1]:  # in order: the common case
            t = max(received_ns, logs[-1]) if logs else received_ns
            stamps.append(stamp)
            logs.append(t)
        else:
            i = bisect_right(stamps, stamp)  # stamps[:i] <= stamp < stamps[i:]
            t = min(max(received_ns, logs[i - 1]) if i else received_ns, logs[i])
            if t < received_ns:
                self.adjusted += 1
            stamps.insert(i, stamp)
            logs.insert(i, t)
        if len(stamps) > 2 * self.window:
            del stamps[: -self.window], logs[: -self.window]
        return t


class SettleBuffer:
    """Messages held ``settle`` seconds of ``clock`` and released in log-time order.

    A message that :class:`StampOrder` logs before messages received ahead of it is written
    before them as long as it arrives within ``settle`` of them, so the bag's chunks (flushed
    every fraction of a second) follow log time: ``rerun mcap check`` reports a topic whose
    chunks overlap out of order. Ties keep their arrival order.
    """

    def __init__(self, settle: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.settle = float(settle)
        self.clock = clock
        self._heap: list[tuple[int, int, float, object]] = []
        self._seq = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, log_ns: int, item: object) -> None:
        heapq.heappush(self._heap, (log_ns, next(self._seq), self.clock(), item))

    def ready(self, everything: bool = False) -> Iterator[tuple[int, object]]:
        """(log time, item) in log-time order while the earliest has been held ``settle``
        (``everything``: all of them)."""
        heap, now = self._heap, self.clock()
        while heap and (everything or now - heap[0][2] >= self.settle):
            log_ns, _, _, item = heapq.heappop(heap)
            yield log_ns, item
