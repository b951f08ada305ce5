"""The Foxglove WebSocket server of fence_sorter (foxglove_ws) against Foxglove's own npm client
(@foxglove/ws-protocol, decoding with @foxglove/rosmsg2-serialization), ROS-free: CDR bytes made
by rosbags' type store go out unchanged on ros2msg/cdr channels and the npm client decodes the
same values, under either subprotocol name; a late joiner gets the latched robot description; a
client that reads gets every message handed over for it and none is dropped; one that stops
reading loses the oldest messages, and the server's count of them is exact: handed = received
+ dropped for that client; bad requests are refused with a status and counted while the server
runs on; bad addresses are refused with the option and the allowed values."""

from __future__ import annotations

import json
import os
import signal
import struct
from pathlib import Path

import pytest
import websockets
from foxglove_client import Client, client_missing
from processes import stop_process, wait_until
from websockets.sync.client import connect

from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter.visualisation.foxglove_address import AddressError, parse_address
from fence_sorter.visualisation.foxglove_live import LiveServer

needs_client = pytest.mark.skipif(client_missing() is not None, reason=str(client_missing()))

OUTCOME = "fence_sorter_msgs/msg/SortOutcome"
STRING = "std_msgs/msg/String"


def _outcome(ts, k: int):
    """A SortOutcome with distinct values per k (rosbags message object)."""
    t = ts.types
    stamp = t["builtin_interfaces/msg/Time"](sec=3 + k, nanosec=250_000_000 + k)
    header = t["std_msgs/msg/Header"](stamp=stamp, frame_id="sorter")
    return t[OUTCOME](
        header=header,
        parcel_id=100 + k,
        run_id=1000 + k,
        auth=77 + k,
        sorted=bool(k % 2),
        reason=f"reason {k}",
        reason_code=k % 7,
        peak_normal_force=1234.5678 + k / 3.0,
        peak_normal_force_stiff=2e4 / (k + 1),
        peak_normal_accel=98.25 * k,
        impact_normal_speed=1.0 / 7.0 + k,
        exit_speed_y=-0.1 * k,
        y_max=0.9,
        time_in_working_space=0.61,
        w_dop=2.4,
        a_ndop=150.0,
        impact_speed_margin=1e-3 * k,
        accel_margin=-0.5,
        drop_height=0.29,
        disputed=k == 3,
    )


def _settled(server: LiveServer) -> None:
    """Wait until each client's queue is empty and no send is under way (a message can reach
    the client before the server's send returns and counts it as sent)."""
    wait_until(
        lambda: all(
            c["queued"] == 0 and not c["in_flight"] for c in server.server.snapshot().values()
        ),
        30, "every queue sent",
    )  # fmt: skip


@pytest.fixture
def server(request):
    """A server on a free port of 127.0.0.1 (backlog: the indirect parameter, else 1024)."""
    srv = LiveServer(make_typestore(), port=0, backlog=getattr(request, "param", 1024))
    try:
        yield srv
    finally:
        srv.stop()


@pytest.mark.slow
@needs_client
def test_npm_client_decodes_what_rosbags_serialised(server: LiveServer, tmp_path: Path) -> None:
    ts = server.typestore
    server.add_topic("/sort_outcomes", OUTCOME)
    server.add_topic("/robot_description", STRING)
    urdf = '<robot name="fence_sorter"><link name="sorter"/></robot>'
    # published before any client: a late joiner gets it all the same (latched)
    server.log("/robot_description", ts.serialize_cdr(ts.types[STRING](data=urdf), STRING), 7)
    client = Client(
        f"ws://127.0.0.1:{server.port}", tmp_path / "out.jsonl",
        ["/sort_outcomes", "/robot_description"], timeout=30,
    )  # fmt: skip
    try:
        wait_until(
            lambda: sum(len(c.subscriptions) for c in server.clients.values()) == 2,
            30, "the npm client's two subscriptions",
        )  # fmt: skip
        sent = [_outcome(ts, k) for k in range(40)]
        for k, msg in enumerate(sent):
            server.log("/sort_outcomes", ts.serialize_cdr(msg, OUTCOME), 1_000_000_000 + k)
        wait_until(lambda: len(client.messages()) >= 41, 30, "41 messages at the npm client")
    finally:
        stop_process(client.proc)
    _settled(server)
    got = client.messages()
    outcomes = [m for m in got if m["topic"] == "/sort_outcomes"]
    described = [m for m in got if m["topic"] == "/robot_description"]
    assert [m["message"]["data"] for m in described] == [urdf] and described[0]["log_time"] == "7"
    assert len(outcomes) == len(sent)
    for k, (m, msg) in enumerate(zip(outcomes, sent, strict=True)):
        assert m["schema"] == OUTCOME and m["log_time"] == str(1_000_000_000 + k)
        d = m["message"]
        assert d["header"]["stamp"] == {
            "sec": msg.header.stamp.sec,
            "nanosec": msg.header.stamp.nanosec,
        }
        assert d["header"]["frame_id"] == "sorter"
        for name in (
            "parcel_id", "sorted", "reason", "reason_code", "peak_normal_force",
            "peak_normal_force_stiff", "peak_normal_accel", "impact_normal_speed",
            "exit_speed_y", "impact_speed_margin", "drop_height", "disputed",
        ):  # fmt: skip
            assert d[name] == getattr(msg, name), name  # bit for bit: the same CDR
    stats = server.stats()
    assert stats["forwarded.sort_outcomes"] == "40" and stats["resent_to_late_joiners"] == "1"
    assert stats["slow_clients"] == "0" and stats["dropped"] == "0"
    # a client that reads: every message handed over for it arrived (41: the resent latched one)
    ((client_id, handed),) = server.handed.items()
    assert handed == len(got) == 41 and stats["handed_per_client"] == f"{client_id}:41"
    assert stats["sent_per_client"] == f"{client_id}:41"
    assert stats["dropped_per_client"] == f"{client_id}:0"
    assert server.server.snapshot()[client_id]["subprotocol"] == "foxglove.sdk.v1"


@pytest.mark.slow
@needs_client
def test_the_npm_clients_own_subprotocol_name_is_served(
    server: LiveServer, tmp_path: Path
) -> None:
    """FoxgloveClient.SUPPORTED_SUBPROTOCOL (foxglove.websocket.v1): the same protocol."""
    ts = server.typestore
    server.add_topic("/robot_description", STRING)
    urdf = '<robot name="fence_sorter"/>'
    server.log("/robot_description", ts.serialize_cdr(ts.types[STRING](data=urdf), STRING), 9)
    client = Client(
        f"ws://127.0.0.1:{server.port}", tmp_path / "out.jsonl", ["/robot_description"],
        timeout=30, subprotocol="client",
    )  # fmt: skip
    try:
        wait_until(lambda: len(client.messages()) >= 1, 30, "the latched message at the client")
    finally:
        stop_process(client.proc)
    assert client.said("open foxglove.websocket.v1"), client.lines
    assert [m["message"]["data"] for m in client.messages()] == [urdf]
    ((snapshot),) = server.server.snapshot().values()
    assert snapshot["subprotocol"] == "foxglove.websocket.v1"


BACKLOG = 16


@pytest.mark.slow
@pytest.mark.parametrize("server", [BACKLOG], indirect=True)
@needs_client
def test_a_client_that_stops_reading_loses_the_oldest_messages_counted_exactly(
    server: LiveServer, tmp_path: Path
) -> None:
    """A client that stops reading while 3000 messages of 100 kB go its way: its queue of
    BACKLOG overflows and the server drops the oldest queued ones; once it reads again it gets,
    in order, what the socket's buffers held and then the newest BACKLOG (its queue). Every
    message handed over for it either arrived or was counted as dropped, exactly."""
    ts = server.typestore
    server.add_topic("/big", STRING)
    client = Client(
        f"ws://127.0.0.1:{server.port}", tmp_path / "out.jsonl", ["/big"], timeout=60, stall=True
    )
    n = 3000

    def big(k: int) -> bytes:
        return ts.serialize_cdr(ts.types[STRING](data=f"{k:05d}" + "x" * 100_000), STRING)

    def arrived() -> list[int]:
        return [int(m["message"]["data"][:5]) for m in client.messages()]

    try:
        wait_until(lambda: client.said("stalled") and server.has_clients(), 30, "a stalled client")
        # BACKLOG held per client, the socket's buffers hold a few MB: 300 MB cannot fit
        for k in range(n):
            server.log("/big", big(k), k)
        assert server.stats()["slow_clients"] == "1"
        os.kill(client.proc.pid, signal.SIGUSR2)
        # the last one in: each message before it arrived or was dropped (one queue, in order)
        wait_until(lambda: n - 1 in arrived(), 60, "the last message at the client")
        _settled(server)
    finally:
        stop_process(client.proc)
    got = arrived()
    stats = server.stats()
    assert stats["offered"] == str(n) == stats["forwarded.big"]
    ((client_id, snapshot),) = server.server.snapshot().items()
    counts = snapshot["counts"]["/big"]
    assert client.said("resumed")
    assert got == sorted(got) and len(set(got)) == len(got)  # in order, none twice
    # exact: every message handed over for this client arrived or was counted as dropped
    assert counts.handed == n == len(got) + counts.dropped
    assert counts.sent == len(got) and counts.discarded == 0
    assert counts.dropped > n // 2, f"{len(got)} of {n} arrived"
    assert stats["handed_per_client"] == f"{client_id}:{n}"
    assert stats["dropped_per_client"] == f"{client_id}:{counts.dropped}"
    assert stats["dropped"] == stats["dropped.big"] == str(counts.dropped)
    # the oldest were dropped: the newest BACKLOG (the queue) came last, as a block, and every
    # message that did not arrive is older than them
    assert got[-BACKLOG:] == list(range(n - BACKLOG, n))
    assert max(set(range(n)) - set(got)) < n - BACKLOG
    assert stats["slow_clients"] == "1"
    assert stats["slow_client_addresses"].startswith("127.0.0.1:")


def _status(ws) -> dict:
    """The next JSON message of the server that is a status."""
    while True:
        message = ws.recv(timeout=30)
        if isinstance(message, str) and json.loads(message)["op"] == "status":
            return json.loads(message)


def test_bad_requests_are_refused_and_counted_and_the_server_runs_on(server: LiveServer) -> None:
    """A plain websockets client: JSON that is not a request, an op the server does not offer,
    two subscriptions to no channel, binary data: five status errors naming what is wrong,
    ``refused_requests`` 5; then a good subscription gets its message (header as the spec
    says: opcode 1, subscription id u32 LE, log time u64 LE, the CDR bytes)."""
    ts = server.typestore
    server.add_topic("/robot_description", STRING)
    cdr = ts.serialize_cdr(ts.types[STRING](data="<robot/>"), STRING)
    server.log("/robot_description", cdr, 123_456_789_012)
    url = f"ws://127.0.0.1:{server.port}"
    with connect(url, subprotocols=["foxglove.websocket.v1"]) as ws:
        info = json.loads(ws.recv(timeout=30))
        assert info["op"] == "serverInfo" and info["capabilities"] == ["time"]
        (channel,) = json.loads(ws.recv(timeout=30))["channels"]
        assert channel["topic"] == "/robot_description" and channel["encoding"] == "cdr"
        assert channel["schemaEncoding"] == "ros2msg" and channel["schemaName"] == STRING
        ws.send("not json")
        assert "JSON object with a field op" in _status(ws)["message"]
        ws.send(json.dumps({"op": "getParameters", "parameterNames": []}))
        assert "'getParameters' is not supported" in _status(ws)["message"]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 99}]}))
        assert "not an advertised channel" in _status(ws)["message"]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 2, "channelId": [1]}]}))
        assert "not an advertised channel" in _status(ws)["message"]
        ws.send(b"\x01\x00\x00\x00\x00")
        assert _status(ws)["level"] == 2
        assert server.stats()["refused_requests"] == "5"
        sub = {"id": 7, "channelId": channel["id"]}
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [sub]}))
        frame = ws.recv(timeout=30)
    assert struct.unpack_from("<BIQ", frame) == (1, 7, 123_456_789_012)
    assert frame[13:] == cdr


def test_a_removed_topic_is_unadvertised_and_its_queue_entries_counted(
    server: LiveServer,
) -> None:
    """remove_topic: the subscribed client gets an unadvertise of the channel; per client the
    counts still add up (handed = sent + dropped + discarded + queued) and the topic can no
    longer be logged."""
    ts = server.typestore
    server.add_topic("/robot_description", STRING)
    cdr = ts.serialize_cdr(ts.types[STRING](data="<robot/>"), STRING)
    with connect(f"ws://127.0.0.1:{server.port}", subprotocols=["foxglove.sdk.v1"]) as ws:
        ws.recv(timeout=30)  # serverInfo
        (channel,) = json.loads(ws.recv(timeout=30))["channels"]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": 1}]}))
        wait_until(server.has_clients, 30, "the subscription")
        for k in range(5):
            server.log("/robot_description", cdr, k)
        server.remove_topic("/robot_description")
        frames = []
        while not frames or not isinstance(frames[-1], str):  # data, then the unadvertise
            frames.append(ws.recv(timeout=30))
    assert json.loads(frames[-1]) == {"op": "unadvertise", "channelIds": [channel["id"]]}
    assert all(struct.unpack_from("<BI", f) == (1, 3) for f in frames[:-1])
    ((snapshot),) = server.server.snapshot().values()
    counts = snapshot["counts"]["/robot_description"]
    assert counts.handed == 5 == counts.sent + counts.dropped + counts.discarded
    assert counts.sent == len(frames) - 1 and counts.dropped == 0
    with pytest.raises(KeyError, match="/robot_description"):
        server.log("/robot_description", cdr, 6)


def test_a_client_without_a_foxglove_subprotocol_is_refused(server: LiveServer) -> None:
    with pytest.raises(websockets.InvalidStatus, match="400"):
        connect(f"ws://127.0.0.1:{server.port}", subprotocols=["chat"], open_timeout=30)
    with pytest.raises(websockets.InvalidStatus, match="400"):
        connect(f"ws://127.0.0.1:{server.port}", open_timeout=30)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("8765", ("127.0.0.1", 8765)),
        ("0.0.0.0:9000", ("0.0.0.0", 9000)),
        ("localhost:1", ("localhost", 1)),
        ("[::1]:65535", ("::1", 65535)),
    ],
)
def test_addresses(text: str, expected: tuple[str, int]) -> None:
    assert parse_address(text) == expected


@pytest.mark.parametrize("text", ["0", "65536", "host:80", "8765x", "", "127.0.0.1:"])
def test_bad_addresses_name_the_option_and_range(text: str) -> None:
    with pytest.raises(AddressError, match=r"^--foxglove .*(PORT in 1-65535|IP address)"):
        parse_address(text)
