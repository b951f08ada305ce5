"""ROS messages to the Foxglove app over the Foxglove WebSocket protocol, ROS-free.

One channel per topic with schema encoding ``ros2msg`` (the .msg text with its dependencies,
as rosbag2 embeds it: ``typestore.generate_msgdef``) and message encoding ``cdr``: a message
goes out as the CDR bytes it came in (a raw rclpy subscription, a bag), never re-serialised.
The node (:mod:`fence_sorter.nodes.foxglove_bridge`) and ``fence-sorter replay --foxglove``
feed a :class:`LiveServer`; the protocol and the per-client queues are
:mod:`fence_sorter.visualisation.foxglove_ws`.

Late joiners: the last message of each topic in :data:`LATCHED` is sent again to a client
when it subscribes (as a transient-local subscription would get it), so the app's 3D panel
gets the robot description, the static frames and the markers whenever it connects.

Slow clients: each client has a queue of ``backlog`` messages; beyond it the oldest is
dropped and counted, per client and channel. :meth:`LiveServer.stats` has, per client id,
the messages handed to its queue, sent to its socket, dropped for it and discarded (queued
when it left), so handed = sent + dropped + discarded + queued, exactly.
docs/guide/foxglove.md says what that does and does not measure.
"""

from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass, field

from fence_sorter.recording.topics import MARKERS, ROBOT_DESCRIPTION, TF_STATIC
from fence_sorter.visualisation.foxglove_address import DEFAULT_HOST
from fence_sorter.visualisation.foxglove_ws import ServeError, WsServer

#: outgoing messages held per client (foxglove-sdk's default message backlog)
DEFAULT_BACKLOG = 1024
#: topics whose last message a new subscriber gets at once
LATCHED = (ROBOT_DESCRIPTION, TF_STATIC, MARKERS)

__all__ = ["DEFAULT_BACKLOG", "LATCHED", "LiveServer", "ServeError", "message_definition"]


def message_definition(typestore, msgtype: str) -> str:
    """The ``ros2msg`` schema of ``msgtype``: its .msg text, then each dependency after a line
    of 80 '=' and ``MSG: pkg/msg/Type`` (what rosbag2 writes into MCAP)."""
    text, _ = typestore.generate_msgdef(msgtype, ros_version=2)
    return text


@dataclass
class ClientStats:
    """The subscriptions of one connected client."""

    subscriptions: set[str] = field(default_factory=set)


class LiveServer:
    """A Foxglove WebSocket server with one ``ros2msg``/``cdr`` channel per topic.

    ``add_topic`` before or while clients are connected; ``log`` the CDR bytes of a message
    with its log time [ns]; ``broadcast_time`` the sim time [ns] (the app's current time).
    Thread-safe: ``log`` from any thread, the server's own loop in another.
    """

    def __init__(
        self,
        typestore,
        host: str = DEFAULT_HOST,
        port: int = 0,
        backlog: int = DEFAULT_BACKLOG,
        name: str = "fence_sorter",
    ) -> None:
        self.typestore = typestore
        self.backlog = int(backlog)
        self._lock = threading.Lock()
        self.forwarded: Counter = Counter()  # topic -> messages queued for a subscriber
        self.offered: Counter = Counter()  # topic -> every message given to log()
        self.resent: Counter = Counter()  # topic -> latched messages sent to a late joiner
        self._last: dict[str, tuple[bytes, int]] = {}
        self._topics: set[str] = set()
        self.server = WsServer(host, port, self.backlog, name, on_subscribe=self.on_subscribe)
        self.host = host
        self.port = self.server.port

    # -- channels ---------------------------------------------------------------------------
    def add_topic(self, topic: str, msgtype: str, msgdef: str | None = None) -> None:
        """A channel for ``topic`` carrying ``msgtype`` (pkg/msg/Name) as ros2msg/cdr; its
        schema ``msgdef`` (a bag's embedded definition), else the type store's."""
        schema = msgdef or message_definition(self.typestore, msgtype)
        self.server.add_channel(topic, "cdr", msgtype, "ros2msg", schema)
        self._topics.add(topic)

    def remove_topic(self, topic: str) -> None:
        """Unadvertise ``topic``'s channel."""
        self.server.remove_channel(topic)
        self._topics.discard(topic)
        with self._lock:
            self._last.pop(topic, None)

    @property
    def topics(self) -> list[str]:
        return self.server.topics

    def log(self, topic: str, data: bytes, t_ns: int) -> None:
        """Send one message (CDR bytes as received) to every client subscribed to ``topic``."""
        if topic not in self._topics:
            raise KeyError(f"{topic} has no channel (add_topic first)")
        data = bytes(data)
        self.offered[topic] += 1
        if topic in LATCHED:
            with self._lock:
                self._last[topic] = (data, t_ns)
        if self.server.publish(topic, data, t_ns):
            self.forwarded[topic] += 1

    def broadcast_time(self, t_ns: int) -> None:
        """The server's time [ns] (sim time): the app's current time for TF and plots."""
        self.server.broadcast_time(int(t_ns))

    # -- clients ------------------------------------------------------------------------------
    def on_subscribe(self, client_id: int, topic: str) -> None:
        """A client subscribed to ``topic``: the latched message again, for it alone."""
        with self._lock:
            last = self._last.get(topic)
        if last is not None and self.server.send_to(client_id, topic, last[0], last[1]):
            self.resent[topic] += 1

    @property
    def clients(self) -> dict[int, ClientStats]:
        """Connected clients with a subscription, by id."""
        return {
            cid: ClientStats(set(c["subscriptions"]))
            for cid, c in self.server.snapshot().items()
            if c["connected"] and c["subscriptions"]
        }

    def has_clients(self) -> bool:
        """A client is subscribed to a channel."""
        return bool(self.clients)

    def _per_client(self, what: str) -> Counter:
        return Counter(
            {
                cid: sum(getattr(n, what) for n in c["counts"].values())
                for cid, c in self.server.snapshot().items()
            }
        )

    @property
    def handed(self) -> Counter:
        """Client id (connected or gone) -> messages queued for it."""
        return self._per_client("handed")

    @property
    def dropped(self) -> Counter:
        """Client id -> messages dropped for it (its queue was full)."""
        return self._per_client("dropped")

    @property
    def slow_clients(self) -> dict[int, str]:
        """Clients that lost messages to a full queue: id -> address."""
        snapshot = self.server.snapshot()
        return {
            cid: c["address"]
            for cid, c in snapshot.items()
            if any(n.dropped for n in c["counts"].values())
        }

    def stats(self) -> dict[str, str]:
        """Key/value figures of the server (the node's /diagnostics)."""
        snapshot = self.server.snapshot()
        connected = {cid: c for cid, c in snapshot.items() if c["connected"]}

        def per_client(what: str) -> str:
            return " ".join(
                f"{cid}:{sum(getattr(n, what) for n in c['counts'].values())}"
                for cid, c in sorted(snapshot.items())
                if c["counts"]
            )

        dropped_by_topic: Counter = Counter()
        for c in snapshot.values():
            for topic, n in c["counts"].items():
                dropped_by_topic[topic] += n.dropped
        slow = {cid: c["address"] for cid, c in snapshot.items()
                if any(n.dropped for n in c["counts"].values())}  # fmt: skip
        values = {
            "address": f"{self.host}:{self.port}",
            "clients": str(sum(1 for c in connected.values() if c["subscriptions"])),
            "connections": str(len(connected)),
            "subscriptions": str(sum(len(c["subscriptions"]) for c in connected.values())),
            "client_backlog": str(self.backlog),
            "offered": str(sum(self.offered.values())),
            "forwarded": str(sum(self.forwarded.values())),
            "resent_to_late_joiners": str(sum(self.resent.values())),
            # per client id with a subscription (connected or gone), ID:N
            "handed_per_client": per_client("handed"),
            "sent_per_client": per_client("sent"),
            "dropped_per_client": per_client("dropped"),
            "discarded_per_client": per_client("discarded"),
            "queued_per_client": " ".join(
                f"{cid}:{c['queued'] + int(c['in_flight'])}"
                for cid, c in sorted(connected.items())
                if c["counts"]
            ),
            "dropped": str(sum(dropped_by_topic.values())),
            "slow_clients": str(len(slow)),
            "slow_client_addresses": " ".join(sorted(slow.values())),
            "refused_requests": str(sum(c["refused"] for c in snapshot.values())),
            "time_replaced": str(sum(c["time_replaced"] for c in snapshot.values())),
        }
        for topic in self.topics:
            values[f"forwarded{topic.replace('/', '.')}"] = str(self.forwarded[topic])
        for topic, n in sorted(dropped_by_topic.items()):
            values[f"dropped{topic.replace('/', '.')}"] = str(n)
        return values

    def stop(self) -> None:
        self.server.stop()
