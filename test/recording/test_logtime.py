"""Bag log times against header stamps: StampOrder keeps them in one order per topic, which is
what `rerun mcap check --full` requires (and the naive reception times fail it)."""

from __future__ import annotations

import os
import random
import subprocess
import sys
from pathlib import Path

import pytest

from fence_sorter.recording.logtime import StampOrder, header_stamp_ns, starts_with_header
from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter.recording.topics import TOPIC_TYPES
from fence_sorter.recording.writer import SegmentedBagWriter

DIAG = "diagnostic_msgs/msg/DiagnosticArray"
MS = 1_000_000


@pytest.fixture(scope="module")
def typestore():
    return make_typestore()


def diagnostics(typestore, stamp_ns: int, name: str) -> bytes:
    """A DiagnosticArray with one status, stamped ``stamp_ns``, as CDR."""
    T = typestore.types
    msg = T[DIAG](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](
                sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000
            ),
            frame_id="",
        ),
        status=[
            T["diagnostic_msgs/msg/DiagnosticStatus"](
                level=0, name=name, message="ok", hardware_id="", values=[]
            )
        ],
    )
    return bytes(typestore.serialize_cdr(msg, DIAG))


def race(n_rounds: int = 40, seed: int = 3) -> list[tuple[int, int, str]]:
    """(reception, stamp, node) of /diagnostics from four nodes on a 10 ms sim clock: each node
    stamps with the tick it has seen (0 to 3 ticks behind: busy, or /clock not processed yet),
    and the recorder receives in a shuffled order within a few ms, on its own tick."""
    rng = random.Random(seed)
    out = []
    for k in range(n_rounds):
        tick = 1000 + 50 * k  # [ms], heartbeats of all nodes near the same tick
        batch = [(tick - 10 * rng.randint(0, 3), f"node{j}") for j in range(4)]
        rng.shuffle(batch)
        for i, (stamp, node) in enumerate(batch):
            received = tick + 10 * (i // 2)  # the recorder's clock moves on within the batch
            out.append((received * MS, stamp * MS, node))
    return out


def pairs_agree(rows: list[tuple[int, int]]) -> bool:
    """Rerun's rule: lex-sort by (log time, stamp); every column then non-decreasing."""
    rows = sorted(rows)
    return all(a[1] <= b[1] for a, b in zip(rows, rows[1:], strict=False))


@pytest.mark.slow
def test_header_topics_and_stamp_bytes(typestore):
    headed = {t for t, (m, _) in TOPIC_TYPES.items() if starts_with_header(typestore, m)}
    # TFMessage and String carry no header of their own (a TFMessage's transforms each do)
    headless = {"/clock", "/scan_progress", "/markers", "/tf", "/tf_static", "/robot_description"}
    assert headed == set(TOPIC_TYPES) - headless
    data = diagnostics(typestore, 12_345_678_901, "x")
    assert header_stamp_ns(data) == 12_345_678_901
    big_endian = b"\x00\x00\x00\x00" + (12).to_bytes(4, "big") + (345).to_bytes(4, "big")
    assert header_stamp_ns(big_endian) == 12 * 10**9 + 345
    assert header_stamp_ns(b"\x00\x01\x00") is None  # too short
    assert header_stamp_ns(b"\x00\x07" + bytes(12)) is None  # not XCDR1


def test_in_order_stamps_keep_the_reception_time(typestore):
    order = StampOrder()
    for k in range(100):
        received = 5_000 * MS + 7 * k * MS
        data = diagnostics(typestore, received - 3 * MS, "a")
        assert order.log_time("/diagnostics", received, data) == received
    assert order.adjusted == 0


def test_out_of_order_stamps_get_log_times_in_stamp_order(typestore):
    events = race()
    naive = [(received, stamp) for received, stamp, _ in events]
    assert not pairs_agree(naive)  # the race is real: reception order is not stamp order
    order = StampOrder()
    logged = []
    for received, stamp, node in events:
        t = order.log_time("/diagnostics", received, diagnostics(typestore, stamp, node))
        assert t <= received  # never logged after it arrived ...
        assert received - t <= 30 * MS  # ... and moved back by at most the race (3 ticks)
        logged.append((t, stamp))
    assert pairs_agree(logged)
    assert 0 < order.adjusted < len(events)
    # topics are independent: another topic's stamps do not move this one's log times
    assert order.log_time("/other", 1, diagnostics(typestore, 10**12, "b")) == 1


def test_a_stamp_on_another_clock_keeps_its_reception_time(typestore):
    """A recorder on system time with sim-time publishers: the recorder's own heartbeats are
    stamped ~1.8e18 ns, the others ~10 s. Nothing collapses onto the first heartbeat."""
    order = StampOrder()
    wall = 1_795_000_000 * 10**9
    for k in range(20):
        received = wall + k * 500 * MS
        own = diagnostics(typestore, received - MS, "recorder")
        sim = diagnostics(typestore, 10**10 + k * 500 * MS, "controller")
        assert order.log_time("/diagnostics", received, own) == received
        assert order.log_time("/diagnostics", received + MS, sim) == received + MS
    assert order.adjusted == 0
    with pytest.raises(ValueError, match="tolerance_ns must be >= 0"):
        StampOrder(tolerance_ns=-1)


def test_a_zero_stamp_received_late_joins_the_zero_stamps(typestore):
    """A sim-time node's heartbeat sent before its first /clock is stamped 0; received 1.74 s
    into the run (CI once had one), it is logged before every message stamped later, not at
    its reception (Rerun's --full check saw a row-order conflict)."""
    order = StampOrder()
    rows = [(order.log_time("/diagnostics", 0, diagnostics(typestore, 0, "recorder")), 0)]
    for k in range(1, 4):  # controller heartbeats on the sim clock: (log time, stamp)
        t = k * 400 * MS
        rows.append((order.log_time("/diagnostics", t, diagnostics(typestore, t, "c")), t))
    late = order.log_time("/diagnostics", 1740 * MS, diagnostics(typestore, 0, "scanner"))
    assert late == 400 * MS and order.adjusted == 1  # the first message stamped after it
    assert pairs_agree([*rows, (late, 0)])
    assert not pairs_agree([*rows, (1740 * MS, 0)])  # at its reception time: the conflict


def test_window_is_bounded(typestore):
    order = StampOrder(window=10)
    for k in range(100):
        order.log_time("/d", k * MS, diagnostics(typestore, k * MS, "a"))
    assert len(order._topics["/d"].stamps) <= 20
    with pytest.raises(ValueError, match="window must be >= 1"):
        StampOrder(window=0)


def rerun_check_full(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "rerun", "mcap", "check", "--full", str(path)],
        capture_output=True, text=True, timeout=120,
        env={**os.environ, "RERUN_ANALYTICS_ENABLED": "false"},
    )  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("ordered", [False, True])
def test_rerun_full_check_on_a_racing_diagnostics_topic(tmp_path, typestore, ordered):
    """The same race written with reception times (Rerun reports the /diagnostics row-order
    conflict) and with StampOrder's log times (Rerun accepts it)."""
    pytest.importorskip("rerun")
    bag = tmp_path / "bag"
    order = StampOrder()
    with SegmentedBagWriter(bag, typestore=typestore, max_segment_duration=3600) as writer:
        handle = writer.add_topic("/diagnostics", DIAG)
        for received, stamp, node in race():
            data = diagnostics(typestore, stamp, node)
            t = order.log_time("/diagnostics", received, data) if ordered else received
            writer.write(handle, t, data)
    (segment,) = sorted(bag.glob("*.mcap"))
    out = rerun_check_full(segment)
    assert out.returncode == 0, out.stderr
    line = next(x for x in out.stdout.splitlines() if "/diagnostics" in x)
    assert "ros2_timestamp" in out.stdout  # the header stamps were decoded
    if ordered:
        assert line.split()[0] == "ok", out.stdout
    else:
        assert line.split()[0] == "PROBLEM" and "row-order conflict" in line, out.stdout


def test_settle_buffer_releases_held_messages_in_log_time_order():
    """A message logged before one received ahead of it (StampOrder moved it) is released
    first once the earliest has been held the settle time; ties keep their arrival order."""
    from fence_sorter.recording.logtime import SettleBuffer

    now = [0.0]
    held = SettleBuffer(0.2, clock=lambda: now[0])
    held.push(100, "a")
    held.push(120, "b")
    now[0] = 0.1
    held.push(110, "moved")  # logged between a and b, arrived after b
    held.push(120, "c")
    assert list(held.ready()) == []  # the earliest is held 0.1 s of 0.2
    now[0] = 0.25
    assert list(held.ready()) == [(100, "a")]
    now[0] = 0.35
    assert list(held.ready()) == [(110, "moved"), (120, "b"), (120, "c")]
    held.push(90, "late")
    assert list(held.ready(everything=True)) == [(90, "late")]
    assert len(held) == 0
