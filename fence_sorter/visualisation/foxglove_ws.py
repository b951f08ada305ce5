"""A Foxglove WebSocket protocol server that counts every message it drops, per client and channel.

The protocol (``foxglove.websocket.v1``, and ``foxglove.sdk.v1``, the same messages under the
name foxglove-sdk gives them; the client offers one, the server answers with it): on connection
the server sends ``serverInfo`` (capability ``time``) and an ``advertise`` of its channels; a
client sends ``subscribe`` / ``unsubscribe`` (JSON); the server sends each message of a
subscribed channel as a binary ``messageData`` frame (opcode 0x01, subscription id u32 LE, log
time u64 LE [ns], the payload) and its time as a binary ``time`` frame (opcode 0x02, u64 LE
[ns]). Everything else a client sends is refused with a ``status`` error and counted.

Flow control, the reason this module exists: each client has a queue of at most ``backlog``
messages of our own. :meth:`WsServer.publish` (any thread) puts a message into the queue of each
subscribed client; when the queue is full, its oldest message is dropped and counted there,
the only place a message is ever dropped for a slow client. One writer task per client takes
the messages in order and awaits the socket's send (websockets' ``send`` waits until the
transport's buffer is below its high-water mark), so the socket's buffers push back on the
writer and the queue is the only thing that overflows. Per client and channel:
``handed = sent + dropped + discarded + queued + in_flight`` at every moment, where
``discarded`` are the messages still queued when the client unsubscribed or went away.
Server time is a value, not a stream: a client gets the newest one, and a time not yet sent
when a newer one comes is replaced (``time_replaced``). JSON replies (serverInfo, advertise,
status) go before data and are never dropped; a client that lets ``backlog`` of them pile up
is disconnected.
"""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import struct
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import websockets
from websockets.asyncio.server import ServerConnection, serve

#: subprotocols a client may offer; the first one it offers of these is the connection's
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
MESSAGE_DATA = 0x01
TIME = 0x02
_DATA_HEADER = struct.Struct("<BIQ")
_TIME = struct.Struct("<BQ")
#: the largest subscription id (u32)
MAX_SUBSCRIPTION_ID = 2**32 - 1
STATUS_ERROR = 2

log = logging.getLogger(__name__)


class ServeError(RuntimeError):
    """The server cannot listen (one line: the address and the reason)."""


@dataclass
class ChannelCounts:
    """Messages of one channel for one client [count]."""

    handed: int = 0  # put into the client's queue
    sent: int = 0  # written to its socket (the send returned)
    dropped: int = 0  # the oldest of a full queue, dropped for a newer one
    discarded: int = 0  # still queued when it unsubscribed or the connection ended


@dataclass
class _Channel:
    id: int
    topic: str
    advert: dict


@dataclass
class Client:
    """One connection: its subscriptions, queue and counts (guarded by the server's lock)."""

    id: int
    address: str
    subprotocol: str
    subscriptions: dict[str, int] = field(default_factory=dict)  # topic -> subscription id
    counts: dict[str, ChannelCounts] = field(default_factory=dict)  # topic -> counts
    queue: deque = field(default_factory=deque)  # (topic, subscription id, log time, bytes)
    control: deque = field(default_factory=deque)  # JSON texts, never dropped
    time_ns: int | None = None  # the newest server time not yet sent
    time_replaced: int = 0
    in_flight: str | None = None  # topic of the message being sent
    refused: int = 0  # requests refused (bad JSON, unknown op, bad subscription)
    connected: bool = True
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    wake_pending: bool = False
    connection: ServerConnection | None = None

    def count(self, topic: str) -> ChannelCounts:
        counts = self.counts.get(topic)
        if counts is None:
            counts = self.counts[topic] = ChannelCounts()
        return counts


class WsServer:
    """The server on its own asyncio loop in a daemon thread; every public method is
    thread-safe. ``on_subscribe(client_id, topic)`` runs on the loop after a subscription is
    accepted (a latched message can be sent with :meth:`send_to` from there)."""

    def __init__(
        self,
        host: str,
        port: int,
        backlog: int,
        name: str = "fence_sorter",
        on_subscribe: Callable[[int, str], None] | None = None,
    ) -> None:
        if backlog < 1:
            raise ValueError(f"backlog: must be in [1, inf), got {backlog}")
        self.backlog = int(backlog)
        self.name = name
        self.on_subscribe = on_subscribe
        self.session_id = str(time.time_ns())
        self._lock = threading.Lock()
        self._channels: dict[str, _Channel] = {}
        self._next_channel = 1
        self._next_client = 1
        self.clients: dict[int, Client] = {}  # every client, connected or gone
        self._sock = _listen(host, port)
        self.host = host
        self.port = int(self._sock.getsockname()[1])
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, name="foxglove-ws", daemon=True)
        self._thread.start()
        if not self._ready.wait(30.0):
            raise ServeError(f"{host}:{port}: the server did not start within 30 s")

    # -- the loop ---------------------------------------------------------------------------
    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._loop.run_until_complete(self._start())
        self._ready.set()
        self._loop.run_forever()

    async def _start(self) -> None:
        self._server = await serve(
            self._handler,
            sock=self._sock,
            subprotocols=list(SUBPROTOCOLS),
            compression=None,  # payloads go as they are (the SDK does not deflate either)
            ping_interval=None,  # a client that pauses its reading stays connected
            max_size=2**20,  # client requests are small JSON
            close_timeout=2.0,  # a stalled client cannot hold the node's stop for long
            server_header=None,
        )

    async def _handler(self, ws: ServerConnection) -> None:
        host, port = ws.remote_address[:2]
        with self._lock:
            client = Client(self._next_client, f"{host}:{port}", ws.subprotocol or "")
            client.connection = ws
            self._next_client += 1
            self.clients[client.id] = client
            info = {"op": "serverInfo", "name": self.name, "capabilities": ["time"],
                    "supportedEncodings": [], "metadata": {},
                    "sessionId": self.session_id}  # fmt: skip
            client.control.append(json.dumps(info))
            adverts = [c.advert for c in self._channels.values()]
            if adverts:
                client.control.append(json.dumps({"op": "advertise", "channels": adverts}))
        writer = asyncio.create_task(self._write(ws, client))
        try:
            async for message in ws:
                self._request(client, message)
        except websockets.ConnectionClosed:
            pass
        finally:
            writer.cancel()
            try:
                await writer
            except asyncio.CancelledError:
                pass
            with self._lock:
                self._disconnect(client)

    async def _write(self, ws: ServerConnection, client: Client) -> None:
        """Control texts first, then the newest time, then the queue in order; each send
        awaited (the socket's flow control)."""
        while True:
            with self._lock:
                topic, frame = None, None
                if client.control:
                    frame = client.control.popleft()
                elif client.time_ns is not None:
                    frame = _TIME.pack(TIME, client.time_ns)
                    client.time_ns = None
                elif client.queue:
                    topic, sub_id, t_ns, data = client.queue.popleft()
                    frame = _DATA_HEADER.pack(MESSAGE_DATA, sub_id, t_ns) + data
                    client.in_flight = topic
                else:
                    client.wake.clear()
                    client.wake_pending = False
            if frame is None:
                await client.wake.wait()
                continue
            try:
                await ws.send(frame)
            except BaseException:  # the connection ended (closed, or the writer cancelled)
                if topic is not None:
                    with self._lock:
                        client.in_flight = None
                        client.count(topic).discarded += 1
                if isinstance(sys.exc_info()[1], websockets.ConnectionClosed):
                    return
                raise
            if topic is not None:
                with self._lock:
                    client.in_flight = None
                    client.count(topic).sent += 1
            # a send that finished at once gives the loop no turn: let the reader in
            await asyncio.sleep(0)

    def _wake(self, client: Client) -> None:
        """Wake the client's writer (lock held)."""
        if not client.wake_pending:
            client.wake_pending = True
            self._loop.call_soon_threadsafe(client.wake.set)

    def _disconnect(self, client: Client) -> None:
        """The connection ended: what is still queued is discarded (lock held)."""
        client.connected = False
        for topic, *_ in client.queue:
            client.count(topic).discarded += 1
        client.queue.clear()
        client.control.clear()
        client.subscriptions.clear()
        client.connection = None

    # -- client requests ----------------------------------------------------------------------
    def _request(self, client: Client, message: str | bytes) -> None:
        accepted: list[str] = []
        with self._lock:
            error = self._apply(client, message, accepted)
            if error is not None:
                client.refused += 1
                self._control(client, {"op": "status", "level": STATUS_ERROR, "message": error})
        if self.on_subscribe is not None:
            for topic in accepted:
                self.on_subscribe(client.id, topic)

    def _apply(self, client: Client, message: str | bytes, accepted: list[str]) -> str | None:
        """Apply one request (lock held); the reason it is refused, or None."""
        if isinstance(message, bytes):
            return "binary messages are not accepted (no clientPublish or services capability)"
        try:
            request = json.loads(message)
            op = request["op"]
        except (ValueError, TypeError, KeyError, RecursionError):
            return "a request must be a JSON object with a field op"
        if op == "subscribe":
            return self._subscribe(client, request.get("subscriptions"), accepted)
        if op == "unsubscribe":
            return self._unsubscribe(client, request.get("subscriptionIds"))
        return f"op {op!r} is not supported (capabilities: time)"

    def _subscribe(self, client: Client, subs, accepted: list[str]) -> str | None:
        if not isinstance(subs, list):
            return "subscribe: subscriptions must be a list of {id, channelId}"
        by_id = {c.id: c for c in self._channels.values()}
        errors = []
        for sub in subs:
            sub_id = sub.get("id") if isinstance(sub, dict) else None
            channel_id = sub.get("channelId") if isinstance(sub, dict) else None
            channel = by_id.get(channel_id) if isinstance(channel_id, int) else None
            if not isinstance(sub_id, int) or not 0 <= sub_id <= MAX_SUBSCRIPTION_ID:
                errors.append(f"subscribe: id must be an integer in [0, {MAX_SUBSCRIPTION_ID}]")
            elif channel is None:
                errors.append(f"subscribe: channelId of {sub!r} is not an advertised channel")
            elif sub_id in client.subscriptions.values():
                errors.append(f"subscribe: id {sub_id} is in use")
            elif channel.topic in client.subscriptions:
                errors.append(f"subscribe: channel {channel.id} is subscribed already")
            else:
                client.subscriptions[channel.topic] = sub_id
                client.count(channel.topic)
                accepted.append(channel.topic)
        return "; ".join(errors) or None

    def _unsubscribe(self, client: Client, ids) -> str | None:
        if not isinstance(ids, list):
            return "unsubscribe: subscriptionIds must be a list of integers"
        errors = []
        for sub_id in ids:
            topics = [t for t, s in client.subscriptions.items() if s == sub_id]
            if not topics:
                errors.append(f"unsubscribe: no subscription {sub_id!r}")
                continue
            self._drop_subscription(client, topics[0])
        return "; ".join(errors) or None

    def _drop_subscription(self, client: Client, topic: str) -> None:
        """End the subscription to ``topic``; its queued messages are discarded (lock held)."""
        del client.subscriptions[topic]
        kept = deque(item for item in client.queue if item[0] != topic)
        client.count(topic).discarded += len(client.queue) - len(kept)
        client.queue = kept

    def _control(self, client: Client, message: dict) -> None:
        """A JSON message for the client (lock held); a client that lets ``backlog`` of them
        pile up unread is disconnected."""
        if not client.connected:
            return
        if len(client.control) >= self.backlog:
            log.warning("client %s: %d replies unread, disconnected", client.address,
                        len(client.control))  # fmt: skip
            self._loop.call_soon_threadsafe(self._close_client, client)
            return
        client.control.append(json.dumps(message))
        self._wake(client)

    def _close_client(self, client: Client) -> None:
        if client.connection is not None:
            self._loop.create_task(client.connection.close(1008, "replies piled up unread"))

    # -- channels and messages ----------------------------------------------------------------
    def add_channel(
        self, topic: str, encoding: str, schema_name: str, schema_encoding: str, schema: str
    ) -> int:
        """Advertise a channel (to the connected clients, and to each new one); its id."""
        with self._lock:
            channel = self._channels.get(topic)
            if channel is not None:
                return channel.id
            advert = {"id": self._next_channel, "topic": topic, "encoding": encoding,
                      "schemaName": schema_name, "schemaEncoding": schema_encoding,
                      "schema": schema}  # fmt: skip
            channel = self._channels[topic] = _Channel(self._next_channel, topic, advert)
            self._next_channel += 1
            for client in self.clients.values():
                self._control(client, {"op": "advertise", "channels": [advert]})
            return channel.id

    def remove_channel(self, topic: str) -> None:
        """Unadvertise a channel; its subscriptions end, their queued messages discarded."""
        with self._lock:
            channel = self._channels.pop(topic, None)
            if channel is None:
                return
            for client in self.clients.values():
                if topic in client.subscriptions:
                    self._drop_subscription(client, topic)
                self._control(client, {"op": "unadvertise", "channelIds": [channel.id]})

    @property
    def topics(self) -> list[str]:
        with self._lock:
            return list(self._channels)

    def publish(self, topic: str, data: bytes, t_ns: int) -> int:
        """Queue one message for every client subscribed to ``topic``; how many."""
        n = 0
        with self._lock:
            for client in self.clients.values():
                sub_id = client.subscriptions.get(topic)
                if sub_id is not None:
                    self._enqueue(client, topic, sub_id, data, t_ns)
                    n += 1
        return n

    def send_to(self, client_id: int, topic: str, data: bytes, t_ns: int) -> bool:
        """Queue one message for one client if it is subscribed to ``topic``."""
        with self._lock:
            client = self.clients.get(client_id)
            sub_id = None if client is None else client.subscriptions.get(topic)
            if sub_id is None:
                return False
            self._enqueue(client, topic, sub_id, data, t_ns)
            return True

    def _enqueue(self, client: Client, topic: str, sub_id: int, data: bytes, t_ns: int) -> None:
        """The one place a message is dropped for a slow client, and counted (lock held)."""
        if len(client.queue) >= self.backlog:
            oldest = client.queue.popleft()
            client.count(oldest[0]).dropped += 1
        client.queue.append((topic, sub_id, int(t_ns), data))
        client.count(topic).handed += 1
        self._wake(client)

    def broadcast_time(self, t_ns: int) -> None:
        """The server's time [ns] to every connected client (the newest replaces one unsent)."""
        with self._lock:
            for client in self.clients.values():
                if client.connected:
                    if client.time_ns is not None:
                        client.time_replaced += 1
                    client.time_ns = int(t_ns)
                    self._wake(client)

    # -- figures --------------------------------------------------------------------------
    def snapshot(self) -> dict[int, dict]:
        """Per client id (connected or gone): address, connected, subscriptions (topics),
        queued, in_flight, refused, time_replaced and counts (topic -> ChannelCounts copy)."""
        with self._lock:
            return {
                c.id: {
                    "address": c.address,
                    "subprotocol": c.subprotocol,
                    "connected": c.connected,
                    "subscriptions": set(c.subscriptions),
                    "queued": len(c.queue),
                    "in_flight": c.in_flight is not None,
                    "refused": c.refused,
                    "time_replaced": c.time_replaced,
                    "counts": {t: ChannelCounts(**vars(n)) for t, n in c.counts.items()},
                }
                for c in self.clients.values()
            }

    # -- stop -----------------------------------------------------------------------------
    def stop(self, flush_s: float = 2.0) -> None:
        """Give each client up to ``flush_s`` [s] to take what is queued for it, then close
        every connection and the listening socket."""
        if not self._thread.is_alive():
            return
        future = asyncio.run_coroutine_threadsafe(self._stop(flush_s), self._loop)
        try:
            future.result(flush_s + 15.0)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(15.0)
            if not self._thread.is_alive():
                self._loop.close()

    async def _stop(self, flush_s: float) -> None:
        deadline = self._loop.time() + flush_s
        while self._loop.time() < deadline:
            with self._lock:
                busy = any(
                    c.connected and (c.queue or c.control or c.in_flight is not None)
                    for c in self.clients.values()
                )
            if not busy:
                break
            await asyncio.sleep(0.01)
        self._server.close()
        await self._server.wait_closed()


def _listen(host: str, port: int) -> socket.socket:
    """A listening TCP socket on the first address ``host`` resolves to (as foxglove-sdk)."""
    try:
        family, kind, proto, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )[0]
        sock = socket.socket(family, kind, proto)
    except OSError as exc:
        raise ServeError(f"{host}:{port}: {exc}") from None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(128)
    except OSError as exc:
        sock.close()
        raise ServeError(f"{host}:{port}: {exc.strerror or exc}") from None
    sock.setblocking(False)
    return sock
