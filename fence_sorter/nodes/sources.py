"""The run's key in a node: tags on what it sends, checks on what it takes in, a pinned clock.

:mod:`fence_sorter.provenance` says why (the run id is public, the key is not). Here the rclpy
side: :func:`sign` and :func:`authentic` on fence_sorter_msgs messages with an ``auth`` field
(the tag covers :func:`fence_sorter.provenance.message_payload`), :class:`PinnedClock`,
which takes a node's sim time from /run_clock under the key instead of /clock, and
:class:`SourceWatch`, which names the other publishers of a topic from the graph.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from diagnostic_msgs.msg import KeyValue
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from fence_sorter import provenance
from fence_sorter.recording.topics import RUN_CLOCK
from fence_sorter_msgs.msg import RunClock


def sign(msg, key: bytes | None):
    """Put the tag of ``msg`` under ``key`` into ``msg.auth`` (nothing without a key)."""
    if key is not None:
        msg.auth = provenance.tag(key, provenance.message_payload(msg))
    return msg


def authentic(msg, key: bytes | None) -> bool:
    """True when ``msg.auth`` is its tag under ``key``; every message is, without a key."""
    if key is None:
        return True
    given = int(msg.auth)
    return bool(given) and provenance.verify(key, provenance.message_payload(msg), given)


def _level(status) -> int:
    level = status.level
    return int.from_bytes(level, "little") if isinstance(level, bytes) else int(level)


def _status_payload(stamp, status) -> bytes:
    return provenance.status_payload(
        stamp.sec,
        stamp.nanosec,
        status.name,
        status.message,
        _level(status),
        [(kv.key, kv.value) for kv in status.values],
    )


#: the heartbeat value naming the node process's start (ns, wall clock): statuses of one
#: node are ordered by (start, stamp), so a restart is not taken for a replay
STARTED_KEY = "started_ns"


def status_order(stamp: float, status) -> tuple[int, float]:
    """Where a node's status stands among its others: (its process's start, its stamp)."""
    started = [kv.value for kv in status.values if kv.key == STARTED_KEY]
    return (int(started[0]) if started and started[0].isdigit() else 0, stamp)


def sign_diagnostics(msg, key: bytes | None):
    """Append to each status of a DiagnosticArray its tag under ``key`` (the KeyValue
    :data:`fence_sorter.provenance.STATUS_TAG_KEY`; nothing without a key)."""
    if key is not None:
        for status in msg.status:
            text = str(provenance.tag(key, _status_payload(msg.header.stamp, status)))
            status.values.append(KeyValue(key=provenance.STATUS_TAG_KEY, value=text))
    return msg


def status_authentic(stamp, status, key: bytes) -> bool:
    """True when a status carries the tag of its content (and its array's ``stamp``)."""
    given = [kv.value for kv in status.values if kv.key == provenance.STATUS_TAG_KEY]
    if len(given) != 1 or not given[0].isdigit():
        return False
    return provenance.verify(key, _status_payload(stamp, status), int(given[0]) % 2**64)


def clock_authentic(msg, key: bytes) -> bool:
    """True when a RunClock message's tag verifies under ``key``."""
    payload = provenance.clock_payload(msg.clock.sec, msg.clock.nanosec, msg.run_id)
    return provenance.verify(key, payload, int(msg.auth))


def sign_clock(msg, key: bytes):
    """Tag a RunClock message (its time and run id) under ``key``."""
    msg.auth = provenance.tag(
        key, provenance.clock_payload(msg.clock.sec, msg.clock.nanosec, msg.run_id)
    )
    return msg


class PinnedClock:
    """A node's sim time from /run_clock messages that verify under the run's key.

    rclpy's TimeSource takes /clock from anyone on the domain; this replaces its subscription
    (same QoS: best effort, depth 1) with one to /run_clock that hands only authentic, not
    older messages on to the TimeSource. A second /clock publisher then moves no node's time;
    it is named from the graph (:class:`SourceWatch`) instead.
    """

    COUNTERS = ("accepted", "foreign_source", "stale")
    #: the node's time is behind the run's once no clock message was taken for this long [s]
    #: (a callback kept the executor busy; the run's clock ticks every few ms of wall time)
    BEHIND_AFTER = 0.05
    #: ... unless none came for this long [s]: the run's clock is paused or has ended
    PAUSED_AFTER = 1.0

    def __init__(self, node, key: bytes) -> None:
        self.key = key
        self.accepted = self.foreign_source = self.stale = 0
        self._last = -1
        self._taken_at = -math.inf  # time.monotonic() of the last message taken
        #: called once with the next message taken (a heartbeat held back until then)
        self.on_next: Callable[[], object] | None = None
        self._clock = Clock()
        self._time_source = node._time_source  # rclpy's, attached to the node's clock
        if self._time_source._clock_sub is not None:
            node.destroy_subscription(self._time_source._clock_sub)
        self._time_source._clock_sub = node.create_subscription(
            RunClock,
            RUN_CLOCK,
            self.on_run_clock,
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
        )

    def on_run_clock(self, msg) -> None:
        if not clock_authentic(msg, self.key):
            self.foreign_source += 1
            return
        t = int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec)
        if t < self._last:  # a replayed, older message of the run's clock
            self.stale += 1
            return
        self._last = t
        self.accepted += 1
        self._clock.clock = msg.clock
        self._time_source.clock_callback(self._clock)
        self._taken_at = time.monotonic()
        if self.on_next is not None:
            call, self.on_next = self.on_next, None
            call()

    def behind(self, now: float) -> bool:
        """Whether the node's time lags the run's clock (``now``: time.monotonic()): running,
        but no message taken for BEHIND_AFTER (a heartbeat stamped now would be stamped before
        other nodes' heartbeats already sent)."""
        return self._last > 0 and self.BEHIND_AFTER < now - self._taken_at < self.PAUSED_AFTER

    def values(self) -> dict[str, str]:
        return {f"run_clock.{k}": str(getattr(self, k)) for k in self.COUNTERS}


#: the node name of a graph endpoint whose node has not announced itself (yet)
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"
#: an endpoint without a node name is named only after this long [s]: a new node's endpoints
#: reach the graph before its name does (a raw DDS writer never names itself)
UNNAMED_GRACE = 3.0


def endpoint_name(info) -> str:
    """``namespace/node`` of a graph endpoint, with the first bytes of its GID."""
    ns = info.node_namespace.rstrip("/")
    gid = bytes(info.endpoint_gid[:8]).hex()
    return f"{ns}/{info.node_name} (gid {gid})"


class SourceWatch:
    """The publishers of some topics that are not the node that owns each, from the graph.

    ``owners``: (topic, owner node name) pairs; an owner is matched in the watching node's
    namespace. A named foreign publisher is kept at once, an unnamed one once it has stayed
    unnamed for :data:`UNNAMED_GRACE` (a node of the run in the middle of its start-up is not
    taken for an intruder) or has left the graph before it got a name (a node of the run never
    does). What is found stays found (``foreign``): a second /clock that published for 2 s is
    still named at the end of the run.
    """

    def __init__(self, owners: tuple[tuple[str, str], ...]) -> None:
        self.owners = owners
        self.foreign: dict[str, set[str]] = {topic: set() for topic, _ in owners}
        #: GID -> (first seen [s], topic, name) of the endpoints seen only unnamed so far
        self._unnamed: dict[bytes, tuple[float, str, str]] = {}

    def poll(self, node, now: float) -> dict[str, list[str]]:
        """Look at the graph once (``now``: a steady clock [s]); the newly found, by topic."""
        ns = node.get_namespace().rstrip("/")
        new: dict[str, list[str]] = {}

        def found(topic: str, name: str) -> None:
            if name not in self.foreign[topic]:
                self.foreign[topic].add(name)
                new.setdefault(topic, []).append(name)

        present: set[bytes] = set()
        for topic, owner in self.owners:
            for e in node.get_publishers_info_by_topic(topic):
                gid = bytes(e.endpoint_gid)
                present.add(gid)
                if e.node_name == owner and e.node_namespace.rstrip("/") == ns:
                    self._unnamed.pop(gid, None)
                    continue
                if e.node_name == UNKNOWN_NODE:
                    since, _, _ = self._unnamed.setdefault(gid, (now, topic, endpoint_name(e)))
                    if now - since < UNNAMED_GRACE:
                        continue
                else:
                    self._unnamed.pop(gid, None)
                found(topic, endpoint_name(e))
        for gid in [g for g in self._unnamed if g not in present]:
            _, topic, name = self._unnamed.pop(gid)  # left the graph before it had a name
            found(topic, name)
        return new

    def values(self) -> dict[str, str]:
        return {f"foreign_publishers.{k}": "; ".join(sorted(v)) for k, v in self.foreign.items()}
