"""The run's key: tags on parcels, commands and the run clock (fence_sorter.provenance,
nodes/sources.py), and the registry that tells a duplicate from a conflict (nodes/intake.py).

A tag made in one process verifies in another (the payload is the message's values, not its
CDR bytes, whose padding is uninitialised), any changed field or another key fails it, and an
unsigned message fails under a key."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from fence_sorter import provenance
from fence_sorter.inputs import ParcelSpec
from fence_sorter.nodes.intake import ParcelRegistry, TopicIntake

pytestmark = pytest.mark.ros

KEY = bytes(range(32))
OTHER = bytes(range(1, 33))
#: the parcel of these tests, built the same way here and in a child process
PARCEL = (
    "from fence_sorter.inputs import ParcelSpec\n"
    "from fence_sorter.nodes.convert import parcel_to_msg\n"
    "spec = ParcelSpec(7, 0.4, 0.3, 0.2, 5.0, lateral_gap=0.1, divert=True, scan_time=12.5)\n"
    "msg = parcel_to_msg(spec, run_id=99)\n"
)


def parcel():
    scope: dict = {}
    exec(PARCEL, scope)
    return scope["msg"]


def test_a_tag_made_in_another_process_verifies_here() -> None:
    from fence_sorter.nodes.sources import authentic

    code = PARCEL + (
        "from fence_sorter.nodes.sources import sign\n"
        f"print(sign(msg, bytes.fromhex('{KEY.hex()}')).auth)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    msg = parcel()
    msg.auth = int(out.split()[-1])
    assert authentic(msg, KEY)
    assert not authentic(msg, OTHER)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("mass", 5.000000000000001),  # one ulp: the payload is exact
        ("divert", False),
        ("parcel_id", 8),
        ("run_id", 98),
        ("mu_belt", 0.5),  # NaN (the scene's) -> a value
        ("lateral_gap", -0.0),
    ],
)
def test_any_changed_field_fails_the_tag(field: str, value) -> None:
    from fence_sorter.nodes.sources import authentic, sign

    msg = sign(parcel(), KEY)
    assert authentic(msg, KEY)
    setattr(msg, field, value)
    assert not authentic(msg, KEY)


def test_nested_fields_are_covered_and_unsigned_messages_fail() -> None:
    from fence_sorter.nodes.sources import authentic, sign

    msg = sign(parcel(), KEY)
    msg.scan_time.nanosec += 1
    assert not authentic(msg, KEY)
    unsigned = parcel()
    assert unsigned.auth == 0 and not authentic(unsigned, KEY)
    assert authentic(unsigned, None)  # a node without a key checks run ids only


def test_commands_and_the_run_clock_are_tagged() -> None:
    from fence_sorter.nodes.sources import authentic, clock_authentic, sign, sign_clock
    from fence_sorter_msgs.msg import FenceCommand, RunClock

    cmd = FenceCommand(parcel_id=3, run_id=99, t1=0.3, predicted_peak_force=math.nan)
    assert authentic(sign(cmd, KEY), KEY)
    cmd.feasible = not cmd.feasible
    assert not authentic(cmd, KEY)
    tick = RunClock(run_id=99)
    tick.clock.sec, tick.clock.nanosec = 12, 345
    assert clock_authentic(sign_clock(tick, KEY), KEY)
    tick.clock.sec = 67_000_000  # a forged jump
    assert not clock_authentic(tick, KEY)


def test_run_key_from_the_environment() -> None:
    key = provenance.new_run_key()
    assert provenance.run_key({provenance.RUN_KEY_ENV: key}) == bytes.fromhex(key)
    assert provenance.run_key({}) is None
    with pytest.raises(ValueError, match="FENCE_SORTER_RUN_KEY must be 64 hex digits"):
        provenance.run_key({provenance.RUN_KEY_ENV: "abc"})


def test_intake_refuses_a_forgery_before_the_rate_limit() -> None:
    """A flood with the run's id but no valid tag spends none of the tokens: the real
    sender's messages after it are all taken."""
    intake = TopicIntake("parcels", run_id=99, rate=1.0, burst=2.0, clock=lambda: 0.0)
    for _ in range(1000):
        assert not intake.admit(99, lambda: False)
    assert intake.admit(99, lambda: True) and intake.admit(99, lambda: True)
    assert not intake.admit(99, lambda: True)  # the third real one meets the rate limit
    assert (intake.foreign_source, intake.accepted, intake.rate_limited) == (1000, 2, 1)
    assert not intake.admit(98, lambda: True) and intake.foreign == 1
    assert intake.dropped == 1000 + 1 + 1


def test_registry_tells_a_duplicate_from_a_conflict() -> None:
    reg = ParcelRegistry()
    spec = ParcelSpec(4, 0.4, 0.3, 0.2, 5.0, lateral_gap=0.1, divert=True)  # mu NaN
    assert reg.register(spec) == "new"
    assert reg.register(ParcelSpec(4, 0.4, 0.3, 0.2, 5.0, lateral_gap=0.1, divert=True)) == (
        "duplicate"
    )
    forged = ParcelSpec(4, 0.6, 0.4, 0.2, 20.0, lateral_gap=0.1, divert=False)
    assert reg.register(forged) == "conflict"
    assert reg.values() == {
        "parcels.duplicate": "1",
        "parcels.conflict": "1",
        "parcels.disputed_ids": "4",
    }


class Endpoint:
    def __init__(self, node: str, gid: int, ns: str = "/") -> None:
        self.node_name, self.node_namespace = node, ns
        self.endpoint_gid = [1, 15, 120, 253, gid, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]


class Graph:
    """A node's view of the graph: the publishers of each topic."""

    def __init__(self) -> None:
        self.publishers: dict[str, list[Endpoint]] = {}

    def get_namespace(self) -> str:
        return "/"

    def get_publishers_info_by_topic(self, topic: str) -> list[Endpoint]:
        return self.publishers.get(topic, [])


def test_source_watch_names_intruders_not_a_node_of_the_run_starting_up() -> None:
    from fence_sorter.nodes.sources import UNKNOWN_NODE, UNNAMED_GRACE, SourceWatch

    graph, watch = Graph(), SourceWatch((("/clock", "simulator"), ("/parcels", "scanner")))
    graph.publishers["/clock"] = [Endpoint("simulator", 1)]
    graph.publishers["/parcels"] = [Endpoint(UNKNOWN_NODE, 2, ns="_NODE_NAMESPACE_UNKNOWN_")]
    assert watch.poll(graph, 0.0) == {}  # the scanner's endpoint, before its name arrives
    graph.publishers["/parcels"] = [Endpoint("scanner", 2)]
    assert watch.poll(graph, 1.0) == {}
    graph.publishers["/clock"].append(Endpoint("intruder", 3))
    assert watch.poll(graph, 1.2) == {"/clock": ["/intruder (gid 010f78fd03000000)"]}
    graph.publishers["/clock"] = [Endpoint("simulator", 1)]  # the intruder has gone: still named
    raw = Endpoint(UNKNOWN_NODE, 4, ns="_NODE_NAMESPACE_UNKNOWN_")  # a raw DDS writer
    graph.publishers["/parcels"].append(raw)
    assert watch.poll(graph, 2.0) == {}
    assert watch.poll(graph, 2.0 + UNNAMED_GRACE) == {
        "/parcels": ["_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_ (gid 010f78fd04000000)"]
    }
    assert watch.values()["foreign_publishers./clock"] == "/intruder (gid 010f78fd03000000)"


def test_source_watch_names_an_unnamed_publisher_that_left_before_its_grace() -> None:
    from fence_sorter.nodes.sources import UNKNOWN_NODE, SourceWatch

    graph, watch = Graph(), SourceWatch((("/parcels", "scanner"),))
    graph.publishers["/parcels"] = [Endpoint("scanner", 2)]
    short = Endpoint(UNKNOWN_NODE, 5, ns="_NODE_NAMESPACE_UNKNOWN_")  # published and left
    graph.publishers["/parcels"].append(short)
    assert watch.poll(graph, 0.0) == {}
    graph.publishers["/parcels"] = [Endpoint("scanner", 2)]
    assert watch.poll(graph, 0.1) == {
        "/parcels": ["_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_ (gid 010f78fd05000000)"]
    }
    # a node of the run whose name arrives after its endpoint is never named
    late = Endpoint(UNKNOWN_NODE, 6, ns="_NODE_NAMESPACE_UNKNOWN_")
    graph.publishers["/parcels"] = [late]
    assert watch.poll(graph, 1.0) == {}
    graph.publishers["/parcels"] = [Endpoint("scanner", 6)]
    assert watch.poll(graph, 1.1) == {}
    graph.publishers["/parcels"] = []
    assert watch.poll(graph, 1.2) == {}


def test_outcomes_and_statuses_are_tagged() -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from fence_sorter.nodes.sources import authentic, sign, sign_diagnostics, status_authentic
    from fence_sorter_msgs.msg import SortOutcome

    out = sign(SortOutcome(parcel_id=3, run_id=99, sorted=True, peak_normal_force=812.5), KEY)
    assert authentic(out, KEY) and not authentic(out, OTHER)
    out.peak_normal_force = 1.0
    assert not authentic(out, KEY)
    status = DiagnosticStatus(name="fence_sorter/simulator", message="running")
    status.values = [KeyValue(key="overlap_warnings", value="0")]
    array = DiagnosticArray(status=[status])
    array.header.stamp.sec = 12
    sign_diagnostics(array, KEY)
    assert status.values[-1].key == provenance.STATUS_TAG_KEY
    assert status_authentic(array.header.stamp, status, KEY)
    assert not status_authentic(array.header.stamp, status, OTHER)
    array.header.stamp.sec = 13  # the same status under another stamp: not its tag
    assert not status_authentic(array.header.stamp, status, KEY)
    array.header.stamp.sec = 12
    status.values[0].value = "5"
    assert not status_authentic(array.header.stamp, status, KEY)


def test_a_restarted_node_is_not_a_replay_but_an_older_status_of_one_process_is() -> None:
    """Statuses of one node are ordered by (process start, stamp): a restarted node stamps from
    sim time 0 until its clock arrives and is taken; an older status of the same process, or
    any status of the process before, is counted stale and left out."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from fence_sorter.nodes.sources import STARTED_KEY, sign_diagnostics
    from fence_sorter.runner.monitor import Monitor

    def status(started: int, sec: int, taken: str) -> DiagnosticArray:
        s = DiagnosticStatus(name="fence_sorter/controller", message="running")
        s.values = [KeyValue(key=STARTED_KEY, value=str(started)), KeyValue(key="n", value=taken)]
        array = DiagnosticArray(status=[s])
        array.header.stamp.sec = sec
        return sign_diagnostics(array, KEY)

    monitor = Monitor(0, name="test_restart_monitor", run_key=KEY)
    try:
        feed = [(100, 5, "a5"), (100, 3, "a3"), (200, 0, "b0"), (100, 6, "a6"), (200, 7, "b7")]
        for started, sec, taken in feed:
            monitor._on_diag(status(started, sec, taken))
        r = monitor.records
        assert [h["n"] for h in r.diagnostics_history["fence_sorter/controller"]] == [
            "a5",
            "b0",
            "b7",
        ]
        assert r.stale_diagnostics == 2 and not r.forged_diagnostics
    finally:
        monitor.close()


def test_a_change_of_parameters_needs_its_tag_a_fresh_sequence_and_the_same_values() -> None:
    changes = [("a_ndop", 150.0)]
    auth = provenance.change_auth(KEY, "/controller", 7, changes)
    refusal = provenance.change_refusal
    assert refusal(KEY, "/controller", 0, auth, changes) == ""
    assert "needs the run's key" in refusal(KEY, "/controller", 0, None, changes)
    assert "a replay" in refusal(KEY, "/controller", 7, auth, changes)
    assert "does not verify" in refusal(KEY, "/controller", 0, auth, [("a_ndop", 1e-6)])
    assert "does not verify" in refusal(KEY, "/unit_2/controller", 0, auth, changes)
    assert "does not verify" in refusal(OTHER, "/controller", 0, auth, changes)
    assert "must be SEQ:TAG" in refusal(KEY, "/controller", 0, "7", changes)


def test_a_node_whose_time_lags_the_run_clock_holds_its_heartbeat_back() -> None:
    """Behind: the run's clock is running but the node took no message of it for longer than a
    tick (a long callback); not behind before the clock starts or once it has paused."""
    from fence_sorter.nodes.sources import PinnedClock

    clock = PinnedClock.__new__(PinnedClock)
    clock._last, clock._taken_at = -1, -math.inf
    assert not clock.behind(10.0)  # no clock yet: heartbeats stamped 0 announce the node
    clock._last, clock._taken_at = 5_000_000_000, 10.0
    assert not clock.behind(10.0 + 0.5 * PinnedClock.BEHIND_AFTER)
    assert clock.behind(10.0 + 2.0 * PinnedClock.BEHIND_AFTER)
    assert not clock.behind(10.0 + 1.5 * PinnedClock.PAUSED_AFTER)  # paused: beat on
