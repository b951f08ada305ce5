"""The scanner's start gate by node name, over DDS: three extra subscribers on every suite topic
join before the recorder, and the stream still waits for the recorder; the bag then holds every
parcel, command and outcome of the stream (read back by our reader and by the independent
MCAP reader) and `fence-sorter analyze` finds it complete."""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from processes import run_cli

from fence_sorter.recording.bagread import read_bag
from fence_sorter.runner.processes import ProcessGroup, leftovers, node_command

from .test_faults import ros_args, wait

pytestmark = pytest.mark.ros

EXTRA = 3  # extra subscribers on every suite topic

#: EXTRA nodes in one process, each subscribed to every suite topic with a volatile profile
#: (as `ros2 topic echo` would be), printing "ready" once they exist
LISTENERS = textwrap.dedent(
    """
    import sys
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from fence_sorter.nodes.qos import profile
    from fence_sorter.nodes.recorder import message_class
    from fence_sorter.recording.topics import TOPICS, QosSpec

    rclpy.init()
    executor = SingleThreadedExecutor()
    for i in range(int(sys.argv[1])):
        node = rclpy.create_node(f"extra_listener_{i}")
        for t in TOPICS.values():
            qos = profile(QosSpec(reliable=t.qos.reliable, depth=10))
            node.create_subscription(message_class(t.msgtype), t.name, lambda m: None, qos)
        executor.add_node(node)
    print("ready", flush=True)
    try:
        executor.spin()
    except BaseException:
        pass
    """
)


def test_stream_waits_for_the_recorder_by_name(domain_id, env, tmp_path: Path) -> None:
    from fence_sorter.runner.monitor import Monitor

    rows = ["parcel_id,arrival_time,length_a,width_b,height,mass,lateral_gap,divert"]
    rows += [
        f"{i},{2.5 * (i - 1):.1f},0.30,0.25,0.2,4.0,0.1,{str(i != 3).lower()}"
        for i in (1, 2, 3, 4)
    ]
    manifest = tmp_path / "stream.csv"
    manifest.write_text("\n".join(rows) + "\n")
    bag = tmp_path / "bag"
    group = ProcessGroup(env, tmp_path / "logs")
    monitor = Monitor(domain_id, name="test_gate_monitor")
    rec = monitor.records
    try:
        ctrl = ros_args("controller", f"warmup_stream:={manifest}", "use_sim_time:=true")
        group.start("controller", node_command("controller", ctrl))
        group.start("simulator", node_command("simulator", ros_args("simulator")))
        wait(
            monitor,
            lambda: rec.diagnostics.get("fence_sorter/controller", {}).get("listening") == "true",
            120,
            "the controller to listen",
        )
        group.start("listeners", [sys.executable, "-c", LISTENERS, str(EXTRA)])

        def extra_subscribers() -> int:
            infos = monitor.node.get_subscriptions_info_by_topic("/parcels")
            return sum(i.node_name.startswith("extra_listener_") for i in infos)

        wait(monitor, lambda: extra_subscribers() == EXTRA, 60, "the extra subscribers")
        gate = f"start_gate:=simulator,controller,recorder,{monitor.node.get_name()}"
        scan = ros_args("scanner", f"stream:={manifest}", "parcels:=4", gate)
        group.start("scanner", node_command("scanner", scan))
        # the scanner runs and reports that it waits for the recorder alone, with /parcels
        # matched by the simulator, the controller, the monitor and the extra subscribers: a
        # count of subscribers would have opened the gate
        beats = rec.diagnostics_history.setdefault("fence_sorter/scanner", [])
        wait(
            monitor,
            lambda: (
                len([b for b in beats if b.get("start_gate_missing", "").startswith("rec")]) >= 8
            ),
            60,
            "the scanner to wait for the recorder",
        )
        waiting = [b for b in beats if b.get("start_gate_missing", "")]
        assert all(b["parcels_published"] == "0" for b in waiting)
        assert all(
            {x.split(":")[0] for x in b["start_gate_missing"].split()} == {"recorder"}
            for b in waiting[-4:]
        )
        assert rec.parcels == {}
        sim_beats = rec.diagnostics_history["fence_sorter/simulator"]
        assert float(sim_beats[-1]["sim_time_s"]) > 1.0  # sim time runs meanwhile
        recorder = ros_args("recorder", f"output_dir:={bag}", "use_sim_time:=true")
        group.start("recorder", node_command("recorder", recorder))
        wait(monitor, lambda: len(rec.outcomes) == 4, 180, "the four outcomes")
        assert beats[-1]["start_gate_missing"] == ""
    finally:
        codes = {}
        for name in ("scanner", "controller", "simulator", "listeners", "recorder"):
            if name in group.nodes:
                codes[name] = group.stop_one(name)
        assert leftovers(group.pgids) == []
        monitor.close()
    assert codes["recorder"] == 0, codes
    contents = read_bag(bag)
    assert contents.issues == []
    ids = {1, 2, 3, 4}
    assert {m.msg.parcel_id for m in contents.by_topic("/parcels")} == ids
    assert {m.msg.parcel_id for m in contents.by_topic("/sort_outcomes")} == ids
    assert {m.msg.parcel_id for m in contents.by_topic("/fence_commands")} == {1, 2, 4}
    assert len(contents.by_topic("/parcels")) == 4  # once each: no history replayed twice

    # the gate waits for the recorder's heartbeat to report every publisher matched, so the
    # volatile state topics are recorded from before the first scan, not from their matching
    def stamp(m) -> float:
        return m.sec + 1e-9 * m.nanosec

    first_clock = min(stamp(m.msg.clock) for m in contents.by_topic("/clock"))
    first_scan = min(stamp(m.msg.scan_time) for m in contents.by_topic("/parcels"))
    assert first_clock < first_scan
    assert min(stamp(m.msg.header.stamp) for m in contents.by_topic("/joint_states")) < first_scan
    decoded = 0
    for f in sorted(bag.glob("*.mcap")):  # the independent reader decodes the same messages
        with f.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            decoded += sum(1 for *_, msg in reader.iter_decoded_messages() if msg is not None)
    assert decoded == len(contents.messages)
    out = run_cli("analyze", str(bag), "--json", "--no-plots")
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)["summary"]
    assert summary["parcels_scanned"] == 4 and summary["divert"] == 3
    assert summary["outcomes_without_parcel"] == [] == summary["commands_without_parcel"]
