"""The recorder over real DDS: everything published is in the bag (SIGINT closes it cleanly),
SIGKILL leaves every closed segment readable, `fence-sorter run --bag` records a run that the
analysis matches with the live outcomes, and `fence-sorter replay` republishes it."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from processes import managed_process, run_cli, wait_until
from rosbags.rosbag2 import Reader

from fence_sorter.recording.bagread import read_bag
from fence_sorter.recording.topics import TOPIC_TYPES

pytestmark = [pytest.mark.ros, pytest.mark.slow]

CLOCKS = 1500  # /clock messages published at ~1 kHz (reliable: none may be missing)
LOADS = 300  # /load_states (best effort)
PARCELS = 10


@pytest.fixture
def ros_node(domain_id: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """An rclpy node in the test process (own context, this run's domain)."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log_test"))
    context = rclpy.Context()
    rclpy.init(
        context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO
    )
    node = rclpy.create_node("test_recording", context=context)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def start_recorder(bag: Path, env: dict[str, str], segment: float = 0.5, storage="mcap"):
    cmd = [
        sys.executable, "-m", "fence_sorter.nodes.recorder", "--ros-args",
        "-p", f"output_dir:={bag}", "-p", f"max_segment_duration:={segment}",
        "-p", "heartbeat_period:=0.2", "-p", f"storage:={storage}",
    ]  # fmt: skip
    return managed_process(cmd, env)


def publishers(node):
    from rosgraph_msgs.msg import Clock

    from fence_sorter.nodes.qos import topic_qos
    from fence_sorter_msgs.msg import LoadState, Parcel

    return (
        node.create_publisher(Clock, "/clock", topic_qos("/clock")),
        node.create_publisher(LoadState, "/load_states", topic_qos("/load_states")),
        node.create_publisher(Parcel, "/parcels", topic_qos("/parcels")),
    )


def wait_matched(node, pubs, proc, timeout=60.0) -> None:
    """Our writers see the recorder's subscriptions, and then a recorder heartbeat reports
    every publisher in its graph matched (``publishers_unmatched`` empty): a volatile message
    the recorder receives before its side has matched our writer is dropped."""

    def matched() -> bool:
        assert proc.poll() is None, proc.communicate()
        return all(p.get_subscription_count() > 0 for p in pubs)

    wait_until(matched, timeout, "the recorder's subscriptions")
    # the heartbeats are taken from here on: each was sent after our writers had matched
    wait_heartbeat(
        node, proc, lambda v: v.get("publishers_unmatched") == "", timeout,
        "the recorder to match our publishers",
    )  # fmt: skip


def publish(pubs, clocks: int, stop=None) -> int:
    from rosgraph_msgs.msg import Clock

    from fence_sorter_msgs.msg import LoadState, Parcel

    clock_pub, load_pub, parcel_pub = pubs
    sent = 0
    for k in range(clocks):
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = k // 1000, (k % 1000) * 1_000_000
        clock_pub.publish(msg)
        if k % (CLOCKS // LOADS) == 0:
            load = LoadState(parcel_id=k)
            load_pub.publish(load)
        if k % (CLOCKS // PARCELS) == 0:
            parcel_pub.publish(Parcel(parcel_id=k))
        sent += 1
        if stop is not None and stop(k):
            break
        # paced publisher: a 1 kHz /clock is the subject (the recorder closes its segments
        # and flushes on wall time, and the tests count segments and the loss at a SIGKILL)
        time.sleep(0.001)
    return sent


def clock_values(bag: Path) -> list[int]:
    return [
        m.msg.clock.sec * 1000 + m.msg.clock.nanosec // 1_000_000
        for m in read_bag(bag, ["/clock"]).messages
    ]


class Heartbeats:
    """The recorder's heartbeats (its /diagnostics status, as key: value), taken by spinning
    ``node`` (in the fixture's own context) from creation on."""

    def __init__(self, node, proc) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor

        from fence_sorter.nodes.qos import RELIABLE_QOS
        from fence_sorter.recording.topics import DIAGNOSTICS as DIAGNOSTICS_TOPIC

        self.node, self.proc, self.seen = node, proc, []
        self.sub = node.create_subscription(
            DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diag, RELIABLE_QOS
        )
        self.executor = SingleThreadedExecutor(context=node.context)
        self.executor.add_node(node)

    def _on_diag(self, msg) -> None:
        for st in msg.status:
            if "recorder" in st.name:
                self.seen.append({kv.key: kv.value for kv in st.values})

    def poll(self, timeout: float = 0.0) -> None:
        assert self.proc.poll() is None, self.proc.communicate()
        self.executor.spin_once(timeout_sec=timeout)

    def wait(self, done, timeout: float, what: str) -> dict[str, str]:
        """The first heartbeat that makes ``done`` true, spinning until one does."""
        return wait_until(
            lambda: next((v for v in self.seen if done(v)), None), timeout, what,
            lambda: self.poll(0.1),
        )  # fmt: skip

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.executor.shutdown()
        self.node.destroy_subscription(self.sub)


def wait_heartbeat(node, proc, done, timeout: float, what: str) -> dict[str, str]:
    """Spin ``node`` until a recorder heartbeat makes ``done`` true; its values."""
    beats = Heartbeats(node, proc)
    try:
        return beats.wait(done, timeout, what)
    finally:
        beats.close()


def wait_received(node, proc, counts: dict[str, int], timeout=60.0) -> None:
    """Spin ``node`` until the recorder's heartbeat reports at least ``counts`` received per
    topic ("received.clock": 1500, ...): a reliable message is only the recorder's to lose
    once it has taken it."""

    def received(values: dict[str, str]) -> bool:
        return all(int(values.get(k, -1)) >= n for k, n in counts.items())

    wait_heartbeat(node, proc, received, timeout, f"the recorder to report {counts}")


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_sigint_closes_the_bag_with_every_message(ros_node, env, tmp_path, storage):
    bag = tmp_path / "bag"
    with start_recorder(bag, env, storage=storage) as proc:
        pubs = publishers(ros_node)
        wait_matched(ros_node, pubs, proc)
        publish(pubs, CLOCKS)
        wait_received(ros_node, proc, {"received.clock": CLOCKS, "received.parcels": PARCELS})
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
        assert proc.returncode == 0, proc.communicate()
    assert not (bag / ".open").exists()
    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/clock"] == CLOCKS  # reliable: nothing lost, nothing doubled
    assert counts["/parcels"] == PARCELS
    assert counts["/load_states"] >= 0.98 * LOADS  # best effort over localhost
    assert clock_values(bag) == list(range(CLOCKS))  # in order
    if storage == "sqlite3":
        assert len(sorted(bag.glob("*.db3"))) >= 2
        return
    files = sorted(bag.glob("*.mcap"))
    assert len(files) >= 2  # 1.5 s of publishing, 0.5 s segments
    decoded = 0
    for f in files:  # schemas embedded: an independent reader decodes every message
        with f.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for schema, channel, _, msg in reader.iter_decoded_messages():
                assert schema.name == TOPIC_TYPES[channel.topic][0]
                assert msg is not None
                decoded += 1
    assert decoded == sum(counts.values())
    assert_rerun_accepts(files[0])


def assert_rerun_accepts(segment: Path) -> None:
    """`rerun mcap check` and `--full` (which decodes the header stamps as ros2_timestamp)
    pass: every topic ok, no row-order conflict between log time and stamps."""
    for full in ([], ["--full"]):
        check = subprocess.run(
            [sys.executable, "-m", "rerun", "mcap", "check", *full, str(segment)],
            capture_output=True, text=True, timeout=120,
            env={**os.environ, "RERUN_ANALYTICS_ENABLED": "false"},
        )  # fmt: skip
        assert check.returncode == 0, check.stdout + check.stderr
        assert "PROBLEM" not in check.stdout, f"{segment} {full}:\n{check.stdout}"
    assert "ros2_timestamp" in check.stdout


def test_sigkill_keeps_every_closed_segment(ros_node, env, tmp_path):
    bag = tmp_path / "bag"
    meta = bag / "metadata.yaml"

    def closed() -> tuple[int, int]:
        """(files, /clock messages in the closed segments) as metadata.yaml lists them: the
        closed segments and the open one."""
        try:
            info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
            topics = info["topics_with_message_count"]
            files = len(info["relative_file_paths"])
        except (OSError, TypeError, KeyError):
            return 0, 0
        clocks = (x["message_count"] for x in topics if x["topic_metadata"]["name"] == "/clock")
        return files, sum(clocks)

    def two_closed_segments(k: int) -> bool:
        if k % 50:
            return False
        files, clocks = closed()
        return files >= 3 and clocks >= 500

    with start_recorder(bag, env, segment=0.3) as proc:
        pubs = publishers(ros_node)
        wait_matched(ros_node, pubs, proc)
        sent = publish(pubs, 20 * CLOCKS, stop=two_closed_segments)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        assert proc.returncode == -signal.SIGKILL
    assert sent < 20 * CLOCKS
    info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
    assert len(info["relative_file_paths"]) >= 3
    with Reader(bag) as reader:  # the bag as metadata.yaml describes it is complete
        n = sum(1 for c, _, _ in reader.messages() if c.topic == "/clock")
    assert n > 0
    values = clock_values(bag)
    # what was flushed is the start of what was sent, without gaps (plus what the open
    # segment's complete chunks give back, if any)
    assert values[:n] == list(range(n))
    assert n <= sent


def test_sigkill_keeps_everything_written_before_the_last_flush(ros_node, env, tmp_path):
    """One open segment (segments of 10 min): the recorder flushes it as a complete zstd chunk
    every flush_period, so after SIGKILL the independent MCAP stream reader decodes every
    /clock the recorder had written before its last flush, without gaps; our reader recovers
    the same from the open segment. A heartbeat reports w /clock written and f flushes done;
    flush f + 2 started after that heartbeat (flush f + 1 may have been under way), so it
    holds all w: the recorder is killed once a heartbeat reports f + 2 flushes."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    bag = tmp_path / "bag"
    with start_recorder(bag, env, segment=600.0) as proc:
        pubs = publishers(ros_node)
        wait_matched(ros_node, pubs, proc)
        beats = Heartbeats(ros_node, proc)
        try:
            marks: list[dict[str, str]] = []

            def stop(k: int) -> bool:
                if k % 20:
                    return False
                beats.poll()
                if not marks:
                    marks.extend(v for v in beats.seen if int(v["written.clock"]) >= 500)
                    return False
                flushes = int(marks[0]["flushes"])  # the first heartbeat with 500 written
                return any(int(v["flushes"]) >= flushes + 2 for v in beats.seen)

            sent = publish(pubs, 100 * CLOCKS, stop=stop)
        finally:
            beats.close()
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        assert proc.returncode == -signal.SIGKILL
    assert sent < 100 * CLOCKS
    written = int(marks[0]["written.clock"])
    (segment,) = bag.glob(".open/*/*.mcap")
    values = []
    with segment.open("rb") as stream:
        reader = NonSeekingReader(stream, decoder_factories=[DecoderFactory()])
        try:  # in file order, up to the end of the last flushed chunk
            for _, channel, _, msg in reader.iter_decoded_messages(log_time_order=False):
                if channel.topic == "/clock":
                    values.append(msg.clock.sec * 1000 + msg.clock.nanosec // 1_000_000)
        except McapError:
            pass
    n = len(values)
    assert values == list(range(n))  # reliable: the start of what was sent, in order
    assert written <= n <= sent
    assert clock_values(bag) == values  # our reader recovers the open segment alike


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory) -> tuple[Path, dict]:
    """`fence-sorter run --parcels 3 --bag DIR` (about 30 s)."""
    base = tmp_path_factory.mktemp("run")
    bag = base / "bag"
    out = run_cli(
        "run", "--parcels", "3", "--bag", str(bag), "--rrd", str(base / "run.rrd"), "--json",
        "--log-dir", str(base / "logs"), timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    return bag, json.loads(out.stdout)


def test_run_bag_has_every_topic_and_consistent_counts(recorded_run):
    bag, summary = recorded_run
    contents = read_bag(bag)
    assert contents.issues == []
    counts = contents.counts()
    assert set(counts) == set(TOPIC_TYPES)
    assert counts == contents.expected_counts  # as metadata.yaml says
    assert counts["/parcels"] == 3 == summary["parcel_messages"]
    assert counts["/sort_outcomes"] == 3 == summary["outcome_messages"]
    assert counts["/fence_commands"] == summary["command_messages"]
    # a snapshot publishes /clock, /fence_state and /joint_states together; an outcome between
    # snapshots advances /clock to its stamp first. The simulator stops in order (the loop's
    # last frames published whole before its context goes), so the bag's last /clock has its
    # /joint_states too
    assert counts["/joint_states"] > 100

    def sim_ns(stamp) -> int:
        return stamp.sec * 10**9 + stamp.nanosec

    clocks = [sim_ns(m.msg.clock) for m in contents.by_topic("/clock")]
    joints = {sim_ns(m.msg.header.stamp) for m in contents.by_topic("/joint_states")}
    outcomes = contents.by_topic("/sort_outcomes")
    outcome_ns = {sim_ns(m.msg.header.stamp) for m in outcomes}
    # every other /clock is a snapshot's, from the first /joint_states on (the recorder
    # matches the simulator's publishers one by one, each at its own moment)
    snapshots = {c for c in clocks if c >= min(joints)}
    assert snapshots - joints <= outcome_ns
    assert joints <= set(clocks)
    assert clocks[-1] in joints
    assert counts["/fence_state"] >= 0.99 * counts["/joint_states"]  # best effort
    # outcomes are logged at their stamps (the recorder's sim clock has reached them)
    for m in outcomes:
        assert m.t_ns >= sim_ns(m.msg.header.stamp), (m.t_ns, m.msg.header.stamp)
        # within 2 publish periods: the recorder's executor may take the outcome after the next
        # snapshot's /clock (24-25 ms seen on a fresh clone, Jazzy and Kilted alike)
        assert m.t_ns - sim_ns(m.msg.header.stamp) < 40_000_000
    # the recorder's own account at close: everything received was written
    log = (bag.parent / "logs" / "recorder.log").read_text()
    closing = [line for line in log.splitlines() if "closed:" in line]
    assert closing, log[-2000:]
    written, received = closing[-1].split("closed: ")[1].split(" received")[0].split(" of ")
    assert int(written) == int(received) == sum(counts.values())


def test_rerun_full_check_accepts_every_segment_of_the_run(recorded_run):
    """Four nodes publish /diagnostics; the recorder runs on sim time, so log times and header
    stamps are on one clock, and StampOrder settles the races between the nodes."""
    bag, _ = recorded_run
    segments = sorted(bag.glob("*.mcap"))
    assert segments
    for segment in segments:
        assert_rerun_accepts(segment)
    contents = read_bag(bag)
    clocks = [m for m in contents.messages if m.topic == "/clock"]
    # bag time is sim time (not the system clock, ~1.7e18 ns away): a /clock message is logged
    # at about the time it carries. The recorder's clock is the newest /clock rclpy's time source
    # has taken, so it is a few ticks off while the recorder keeps up (the median), and ahead by
    # the recorder's backlog when it is starved for CPU (the bound on the largest lag)
    lags = sorted(abs(m.t_ns - (m.msg.clock.sec * 10**9 + m.msg.clock.nanosec)) for m in clocks)
    assert len(lags) > 100
    assert lags[len(lags) // 2] < 5 * 10**7 and lags[-1] < 3 * 10**9
    stamped = [m for m in contents.messages if m.topic == "/diagnostics"]
    assert {s.name for m in stamped for s in m.msg.status} >= {
        "fence_sorter/recorder", "fence_sorter/simulator", "fence_sorter/controller",
        "fence_sorter/scanner",
    }  # fmt: skip


def test_analysis_of_the_run_matches_the_live_outcomes(recorded_run, tmp_path):
    bag, summary = recorded_run
    out = run_cli("analyze", str(bag), "--json", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    s = report["summary"]
    assert s["agrees_with_live"] is True
    assert s["sorted_divert"] == summary["sorted_divert"]
    assert s["divert"] == summary["divert"]
    peaks = [p["peak_N"] for p in report["parcels"] if p["peak_N"] is not None]
    if summary["peak_force_N"] is not None:
        assert max(peaks) == pytest.approx(summary["peak_force_N"], rel=1e-12)


def test_replay_republishes_the_run(recorded_run, ros_node, env):
    from rclpy.qos import DurabilityPolicy
    from rosgraph_msgs.msg import Clock

    from fence_sorter.nodes.qos import topic_qos
    from fence_sorter.recording.topics import REPLAY_DEPTH
    from fence_sorter_msgs.msg import SortOutcome

    bag, _ = recorded_run
    counts = read_bag(bag).counts()
    clocks, outcomes = [], []
    # transient local: the replay may start before our side has matched its writers (a volatile
    # reader drops what comes before); as deep as the replay's history: a keep-last reader of
    # depth 10 overwrites what a loaded test process has not taken yet
    qos = {t: topic_qos(t, REPLAY_DEPTH) for t in ("/clock", "/sort_outcomes")}
    for q in qos.values():
        q.durability = DurabilityPolicy.TRANSIENT_LOCAL
    ros_node.create_subscription(Clock, "/clock", clocks.append, qos["/clock"])
    ros_node.create_subscription(
        SortOutcome, "/sort_outcomes", outcomes.append, qos["/sort_outcomes"]
    )
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=ros_node.context)
    executor.add_node(ros_node)
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "replay", str(bag), "--rate", "4",
           "--topics", "/clock", "/sort_outcomes", "--wait", "30"]  # fmt: skip
    spin = lambda: executor.spin_once(timeout_sec=0.05)  # noqa: E731
    with managed_process(cmd, env) as proc:
        wait_until(lambda: proc.poll() is not None, 120.0, "the replay to end", spin)
        stdout, stderr = proc.communicate()
    wait_until(
        lambda: len(clocks) >= counts["/clock"] and len(outcomes) >= counts["/sort_outcomes"],
        10.0,
        "every replayed /clock and /sort_outcomes message",
        spin,
    )
    executor.shutdown()
    assert proc.returncode == 0, stderr
    assert len(clocks) == counts["/clock"]
    assert len(outcomes) == counts["/sort_outcomes"]
    stamps = [c.clock.sec + c.clock.nanosec * 1e-9 for c in clocks]
    assert stamps == sorted(stamps)
    # paced by the bag's times at rate 4: never faster than a quarter of the bag's span (how
    # close it comes to that depends on the machine's load: a figure for a benchmark)
    bag_span = float(stdout.split(" s of bag")[0].split()[-1])
    wall = float(stdout.split(" s wall")[0].split()[-1])
    assert bag_span > 1.0 and wall >= 0.95 * bag_span / 4


def test_bag_path_never_overwrites(tmp_path, monkeypatch):
    from fence_sorter.nodes.recorder import bag_path

    assert bag_path(str(tmp_path / "new")) == tmp_path / "new"
    (tmp_path / "empty").mkdir()
    assert bag_path(str(tmp_path / "empty")) == tmp_path / "empty"
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "metadata.yaml").write_text("x")
    inside = bag_path(str(tmp_path / "used"))
    assert inside.parent == tmp_path / "used" and inside.name.startswith("run_")
    monkeypatch.setenv("ROS_HOME", str(tmp_path / "home"))
    assert bag_path("").parent == tmp_path / "home" / "bags"


def test_bad_storage_is_refused_naming_it(env, tmp_path):
    cmd = [sys.executable, "-m", "fence_sorter.nodes.recorder", "--ros-args",
           "-p", f"output_dir:={tmp_path / 'bag'}", "-p", "storage:=rosbag1"]  # fmt: skip
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode != 0
    assert "storage must be mcap or sqlite3" in out.stderr
    assert not (tmp_path / "bag").exists()


def test_a_sim_time_node_runs_against_the_replayed_clock(recorded_run, ros_node, env, tmp_path):
    """The scanner (use_sim_time) re-run on the bag's /clock publishes the same seeded stream:
    the spacing of its scan times equals the recorded one."""
    from rclpy.executors import SingleThreadedExecutor

    from fence_sorter.nodes.qos import topic_qos
    from fence_sorter_msgs.msg import Parcel

    bag, _ = recorded_run
    recorded = sorted(
        m.msg.scan_time.sec + m.msg.scan_time.nanosec * 1e-9
        for m in read_bag(bag, ["/parcels"]).messages
    )
    got: list = []
    ros_node.create_subscription(Parcel, "/parcels", got.append, topic_qos("/parcels"))
    executor = SingleThreadedExecutor(context=ros_node.context)
    executor.add_node(ros_node)
    scanner = [sys.executable, "-m", "fence_sorter.nodes.scanner", "--ros-args",
               "-p", "use_sim_time:=true", "-p", "parcels:=3", "-p", "start_gate:=test_recording",
               "-p", "start_delay:=0.5"]  # fmt: skip
    replay = [sys.executable, "-m", "fence_sorter.cli.main", "replay", str(bag), "--rate", "2",
              "--topics", "/clock", "--wait", "30"]  # fmt: skip

    def spin() -> None:
        executor.spin_once(timeout_sec=0.05)
        assert scan_proc.poll() is None, scan_proc.communicate()

    with managed_process(scanner, env) as scan_proc:
        with managed_process(replay, env) as replay_proc:
            wait_until(lambda: replay_proc.poll() is not None, 120.0, "the replay to end", spin)
            assert replay_proc.returncode == 0, replay_proc.communicate()
        # /parcels is transient local: the scanner's parcels reach us after the replay too
        wait_until(lambda: len(got) >= len(recorded), 30.0, "the scanner's parcels", spin)
    executor.shutdown()
    scans = sorted(p.scan_time.sec + p.scan_time.nanosec * 1e-9 for p in got)
    assert len(scans) == len(recorded) == 3
    # the scanner checks the scan line every 5 ms of sim time; /clock arrives every 20 ms
    spacing = [b - a for a, b in zip(scans, scans[1:], strict=False)]
    expected = [b - a for a, b in zip(recorded, recorded[1:], strict=False)]
    assert spacing == pytest.approx(expected, abs=0.05)


def test_live_rrd_of_the_run_has_every_published_frame(recorded_run):
    """`run --rrd`: the simulator's Rerun child logged every snapshot it published (the same
    snapshots as /clock), none dropped."""
    import pyarrow as pa
    import pyarrow.compute as pc
    from rerun.chunk import RrdReader

    bag, summary = recorded_run
    rrd = bag.parent / "run.rrd"
    verify = subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "verify", str(rrd)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert verify.returncode == 0, verify.stderr
    contents = read_bag(bag, ["/clock", "/joint_states"])
    snapshots = {  # the /clock of each snapshot (an outcome between them has its own)
        (m.msg.header.stamp.sec, m.msg.header.stamp.nanosec)
        for m in contents.by_topic("/joint_states")
    }
    clock_msgs = [
        m
        for m in contents.by_topic("/clock")
        if (m.msg.clock.sec, m.msg.clock.nanosec) in snapshots
    ]
    clocks = len(clock_msgs)
    first_clock = min(m.msg.clock.sec * 10**9 + m.msg.clock.nanosec for m in clock_msgs)
    rows: dict[str, int] = {}
    since_first_clock: dict[str, int] = {}  # rows at or after the first recorded /clock
    for chunk in RrdReader(rrd).stream():
        if not chunk.is_static:
            path = chunk.entity_path
            rows[path] = rows.get(path, 0) + chunk.num_rows
            t = chunk.to_record_batch().column("sim_time").cast(pa.int64())
            later = pc.sum(pc.greater_equal(t, first_clock)).as_py() or 0
            since_first_clock[path] = since_first_clock.get(path, 0) + later
    sim = summary["simulator"]
    assert int(sim["rerun_frames_dropped"]) == 0
    assert rows["/world/fence"] == rows["/world/parcels"] >= clocks
    # the top view: the same frames in 2D, and the blueprint that opens on it
    assert rows["/top/fence"] == rows["/top/parcels"] == rows["/world/parcels"]
    assert len(RrdReader(rrd).blueprints()) == 1
    # the simulator's first snapshots may go out before the recorder has matched /clock
    # (discovery takes a second or more on a loaded machine): from the first recorded /clock
    # on, every published frame is in both (a few may follow the recorder's last one)
    assert clocks <= since_first_clock["/world/fence"] <= clocks + 5
    assert rows["/events/outcomes"] == 3


def test_replay_of_a_bag_of_an_earlier_message_version(ros_node, env):
    """The committed example bag was recorded before Parcel and SortOutcome gained fields: its
    raw CDR would be misread as the current type, so those topics are republished field by
    field (the new ones at their defaults) and a current subscriber reads the bag's values."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy

    from fence_sorter.nodes.qos import topic_qos
    from fence_sorter.recording.topics import REPLAY_DEPTH
    from fence_sorter_msgs.msg import SortOutcome

    bag = Path(__file__).resolve().parents[2] / "bags" / "example_4_parcels"
    recorded = {m.msg.parcel_id: m.msg for m in read_bag(bag, ["/sort_outcomes"]).messages}
    qos = topic_qos("/sort_outcomes", REPLAY_DEPTH)
    qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    got = []
    ros_node.create_subscription(SortOutcome, "/sort_outcomes", got.append, qos)
    executor = SingleThreadedExecutor(context=ros_node.context)
    executor.add_node(ros_node)
    spin = lambda: executor.spin_once(timeout_sec=0.05)  # noqa: E731
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "replay", str(bag), "--rate", "20",
           "--topics", "/sort_outcomes", "--wait", "30"]  # fmt: skip
    with managed_process(cmd, env) as proc:
        wait_until(lambda: proc.poll() is not None, 120.0, "the replay to end", spin)
        stdout, _ = proc.communicate()
    wait_until(lambda: len(got) >= len(recorded), 10.0, "every replayed outcome", spin)
    executor.shutdown()
    assert "/sort_outcomes: recorded as another version" in stdout and "run_id" in stdout
    assert sorted(m.parcel_id for m in got) == sorted(recorded)
    for m in got:
        r = recorded[m.parcel_id]
        assert (m.sorted, m.reason_code, m.reason) == (r.sorted, r.reason_code, r.reason)
        same = m.peak_normal_force == r.peak_normal_force
        assert same or (math.isnan(m.peak_normal_force) and math.isnan(r.peak_normal_force))
        assert m.run_id == 0 and m.auth == 0
