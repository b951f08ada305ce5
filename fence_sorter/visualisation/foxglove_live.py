"""ROS messages to the Foxglove app over the Foxglove WebSocket protocol (foxglove-sdk), ROS-free.

One channel per topic with schema encoding ``ros2msg`` (the .msg text with its dependencies,
as rosbag2 embeds it: ``typestore.generate_msgdef``) and message encoding ``cdr``: a message
goes out as the CDR bytes it came in (a raw rclpy subscription, a bag), never re-serialised.
The node (:mod:`fence_sorter.nodes.foxglove_bridge`) and ``fence-sorter replay --foxglove``
feed a :class:`LiveServer`.

Late joiners: the last message of each topic in :data:`LATCHED` is sent again to a client
when it subscribes (as a transient-local subscription would get it), so the app's 3D panel
gets the robot description, the static frames and the markers whenever it connects.

Slow clients: the server holds ``backlog`` outgoing messages per client and drops the oldest
beyond it. foxglove-sdk 0.30 counts those drops nowhere it shows: its only sign is a log record
"outbox for client ADDR full", at most one every 30 s for the whole process, without a count
(``send_lossy`` in its Rust source). :class:`LiveServer` counts those reports (``slow_clients``,
a lower bound of the clients that lost messages) and counts exactly what it sees itself: the
messages handed to the server for each subscribed client (``handed``, per client id: what the
client receives when nothing is dropped, so handed minus received is what the server dropped
for it), in all (``forwarded``) and sent again to late joiners (``resent``).
docs/guide/foxglove.md says what that does and does not measure.
"""

from __future__ import annotations

import logging
import re
import threading
from collections import Counter
from dataclasses import dataclass, field

import foxglove
from foxglove.websocket import Capability, ServerListener

from fence_sorter.recording.topics import MARKERS, ROBOT_DESCRIPTION, TF_STATIC
from fence_sorter.visualisation.foxglove_address import DEFAULT_HOST

#: foxglove-sdk's own default of outgoing messages held per client
DEFAULT_BACKLOG = 1024
#: topics whose last message a new subscriber gets at once
LATCHED = (ROBOT_DESCRIPTION, TF_STATIC, MARKERS)
#: the SDK's logger that reports a full client outbox (one record per 30 s per process)
SDK_DROP_LOGGER = "foxglove.websocket.connected_client.send_lossy"
_OUTBOX_FULL = re.compile(r"outbox for client (\S+) full")


def message_definition(typestore, msgtype: str) -> str:
    """The ``ros2msg`` schema of ``msgtype``: its .msg text, then each dependency after a line
    of 80 '=' and ``MSG: pkg/msg/Type`` (what rosbag2 writes into MCAP)."""
    text, _ = typestore.generate_msgdef(msgtype, ros_version=2)
    return text


@dataclass
class ClientStats:
    """What the server knows of one client."""

    subscriptions: set[str] = field(default_factory=set)


class _DropReports(logging.Handler):
    """Counts the SDK's reports of a full client outbox."""

    def __init__(self, server: LiveServer) -> None:
        super().__init__(logging.DEBUG)
        self.server = server

    def emit(self, record: logging.LogRecord) -> None:
        match = _OUTBOX_FULL.search(record.getMessage())
        if match:
            self.server.on_outbox_full(match.group(1))


class _Listener(ServerListener):
    def __init__(self, server: LiveServer) -> None:
        self.server = server

    def on_subscribe(self, client, channel) -> None:
        self.server.on_subscribe(client.id, channel.topic)

    def on_unsubscribe(self, client, channel) -> None:
        self.server.on_unsubscribe(client.id, channel.topic)


_SDK_LOGGING = threading.Lock()
_sdk_logging_on = False


def _forward_sdk_logs() -> None:
    """Route the SDK's log records into Python logging (once per process; INFO and up)."""
    global _sdk_logging_on
    with _SDK_LOGGING:
        if _sdk_logging_on:
            return
        root = logging.getLogger()
        if not root.handlers:  # the SDK would call logging.basicConfig otherwise
            handler = logging.StreamHandler()
            handler.setLevel(logging.WARNING)
            root.addHandler(handler)
        # the drop reports are INFO records: enabled on their logger whatever the root's level
        # (the SDK asks Python's logging whether a level is enabled before it sends a record)
        logging.getLogger(SDK_DROP_LOGGER).setLevel(logging.INFO)
        foxglove.set_log_level("INFO")
        _sdk_logging_on = True


class LiveServer:
    """A Foxglove WebSocket server with one ``ros2msg``/``cdr`` channel per topic.

    ``add_topic`` before or while clients are connected; ``log`` the CDR bytes of a message
    with its log time [ns]; ``broadcast_time`` the sim time [ns] (the app's current time).
    Thread-safe for ``log`` from one thread and the SDK's callbacks from its own.
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
        self.clients: dict[int, ClientStats] = {}
        self.forwarded: Counter = Counter()  # topic -> messages handed over with a subscriber
        self.offered: Counter = Counter()  # topic -> every message given to log()
        self.resent: Counter = Counter()  # topic -> latched messages sent to a late joiner
        self.slow_clients: Counter = Counter()  # client address -> overflows reported
        self.handed: Counter = Counter()  # client id -> messages handed over for it
        self._last: dict[str, tuple[bytes, int]] = {}
        self._channels: dict[str, foxglove.Channel] = {}
        _forward_sdk_logs()
        self._reports = _DropReports(self)
        logging.getLogger(SDK_DROP_LOGGER).addHandler(self._reports)
        self.context = foxglove.Context()
        self.server = foxglove.start_server(
            name=name,
            host=host,
            port=port,
            capabilities=[Capability.Time],
            server_listener=_Listener(self),
            context=self.context,
            message_backlog_size=self.backlog,
        )
        self.host = host
        self.port = self.server.port

    # -- channels ---------------------------------------------------------------------------
    def add_topic(self, topic: str, msgtype: str, msgdef: str | None = None) -> None:
        """A channel for ``topic`` carrying ``msgtype`` (pkg/msg/Name) as ros2msg/cdr; its
        schema ``msgdef`` (a bag's embedded definition), else the type store's."""
        if topic in self._channels:
            return
        schema = foxglove.Schema(
            name=msgtype,
            encoding="ros2msg",
            data=(msgdef or message_definition(self.typestore, msgtype)).encode(),
        )
        self._channels[topic] = foxglove.Channel(
            topic, schema=schema, message_encoding="cdr", context=self.context
        )

    @property
    def topics(self) -> list[str]:
        return list(self._channels)

    def log(self, topic: str, data: bytes, t_ns: int) -> None:
        """Send one message (CDR bytes as received) to every client subscribed to ``topic``."""
        channel = self._channels[topic]
        data = bytes(data)
        self.offered[topic] += 1
        if topic in LATCHED:
            with self._lock:
                self._last[topic] = (data, t_ns)
        if channel.has_sinks():
            channel.log(data, log_time=t_ns)
            self.forwarded[topic] += 1
            with self._lock:
                for client_id, stats in self.clients.items():
                    if topic in stats.subscriptions:
                        self.handed[client_id] += 1

    def broadcast_time(self, t_ns: int) -> None:
        """The server's time [ns] (sim time): the app's current time for TF and plots."""
        self.server.broadcast_time(int(t_ns))

    # -- clients ------------------------------------------------------------------------------
    def on_subscribe(self, client_id: int, topic: str) -> None:
        with self._lock:
            self.clients.setdefault(client_id, ClientStats()).subscriptions.add(topic)
            last = self._last.get(topic)
        if last is not None:
            self._channels[topic].log(last[0], log_time=last[1], sink_id=client_id)
            self.resent[topic] += 1
            with self._lock:
                self.handed[client_id] += 1

    def on_unsubscribe(self, client_id: int, topic: str) -> None:
        with self._lock:
            stats = self.clients.get(client_id)
            if stats is not None:
                stats.subscriptions.discard(topic)
                if not stats.subscriptions:
                    del self.clients[client_id]

    def has_clients(self) -> bool:
        """A client is subscribed to a channel."""
        with self._lock:
            return bool(self.clients)

    def on_outbox_full(self, address: str) -> None:
        self.slow_clients[address] += 1

    def stats(self) -> dict[str, str]:
        """Key/value figures of the server (the node's /diagnostics)."""
        with self._lock:
            clients = len(self.clients)
            subscriptions = sum(len(c.subscriptions) for c in self.clients.values())
            handed = " ".join(f"{c}:{n}" for c, n in sorted(self.handed.items()))
        values = {
            "address": f"{self.host}:{self.port}",
            "clients": str(clients),
            "subscriptions": str(subscriptions),
            "client_backlog": str(self.backlog),
            "offered": str(sum(self.offered.values())),
            "forwarded": str(sum(self.forwarded.values())),
            "resent_to_late_joiners": str(sum(self.resent.values())),
            # per client id (connected or gone): messages handed to the server for it
            "handed_per_client": handed,
            # clients whose outbox overflowed as the SDK reports them (the oldest messages
            # dropped; at most one report per 30 s for the whole process, without a count)
            "slow_clients": str(len(self.slow_clients)),
            "slow_client_addresses": " ".join(sorted(self.slow_clients)),
        }
        for topic in self._channels:
            values[f"forwarded{topic.replace('/', '.')}"] = str(self.forwarded[topic])
        return values

    def stop(self) -> None:
        logging.getLogger(SDK_DROP_LOGGER).removeHandler(self._reports)
        self.server.stop()
