"""Pacing and speed of the simulator node with publishing: ``python -m
benchmarks.simulator_bench --rtf 1 --sim 60`` (``--rtf 0``: unpaced).

Runs :class:`SimulatorNode` in this process (its own pacing thread, the executor in another
thread, every topic published over DDS on an isolated domain) fed with a 2400 parcels/h stream:
one 15 kg 0.4 x 0.3 m parcel every 1.5 s at 1 m/s, scanned at x0 = -2 m, every other one
diverted with its stroke command (R_s 0.42 m, t1 0.35 s, alpha_k 40 deg) handed over with it.
Prints achieved real-time factor, cycle lateness and work percentiles, deadline misses and the
outcomes. The stream is handed to the node's inbox directly (no scanner/controller processes):
it measures the simulator alone.
"""

from __future__ import annotations

import argparse
import math
import os
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

from fence_sorter.inputs import ParcelSpec, StrokeCommand
from fence_sorter.nodes import convert
from fence_sorter.nodes.simulator import SimulatorNode

SPACING = 1.5  # s between parcels at 1 m/s: 2400 parcels/h
KEYS = (
    "cycles",
    "deadline_misses",
    "catch_up_slips",
    "cycle_lateness_p50_ms",
    "cycle_lateness_p99_ms",
    "cycle_lateness_p99_9_ms",
    "cycle_lateness_max_ms",
    "cycle_work_p50_ms",
    "cycle_work_p99_ms",
    "cycle_work_p99_9_ms",
    "cycle_work_max_ms",
    "outcomes.SORTED",
    "outcomes.NOT_DIVERTED",
    "outcomes.NO_COMMAND",
    "outcomes.MISSED",
    "overlap_warnings",
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rtf", type=float, default=1.0, help="real_time_factor (0: unpaced)")
    ap.add_argument("--sim", type=float, default=60.0, help="sim time to run [s]")
    ap.add_argument("-p", action="append", default=[], help="extra node parameter k:=v")
    a = ap.parse_args(argv)
    # a domain of its own (the test runs use 100-199), localhost only
    os.environ.setdefault("ROS_DOMAIN_ID", str(229))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    # its parcels are "scanned" at x0 = -2 m
    params = [f"real_time_factor:={a.rtf}", "heartbeat_period:=60.0", "scan_line_x:=-2.0", *a.p]
    rclpy.init(args=["--ros-args", *[x for p in params for x in ("-p", p)]])
    node = SimulatorNode()
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()

    def feed() -> None:
        i = 0
        while not node._stopping:
            ts = SPACING * i
            if node.sim_time >= ts:
                spec = ParcelSpec(
                    i + 1,
                    length_a=0.4,
                    width_b=0.3,
                    height=0.3,
                    mass=15.0,
                    lateral_gap=0.25,
                    divert=i % 2 == 0,
                    scan_time=ts,
                    scan_position_x=-2.0,
                )
                node._on_parcel(convert.parcel_to_msg(spec))
                if spec.divert:
                    cmd = StrokeCommand(i + 1, r_s=0.42, t1=0.35, alpha_k=math.radians(40.0))
                    node._on_command(convert.command_to_msg(cmd, ts))
                i += 1
            time.sleep(0.002)

    load0 = os.getloadavg()[0]
    wall0 = time.perf_counter()
    node.start()
    threading.Thread(target=feed, daemon=True).start()
    while node.sim_time < a.sim and node.loop_error is None:
        time.sleep(0.05)
    wall = time.perf_counter() - wall0
    node.stop()
    values = {kv.key: kv.value for kv in node.heartbeat_status().values}
    print(
        f"rtf target {a.rtf:g}: {node.sim_time:.2f} s sim in {wall:.2f} s wall -> achieved RTF "
        f"{node.sim_time / wall:.2f} (load average {load0:.2f} -> {os.getloadavg()[0]:.2f}, "
        f"{os.cpu_count()} CPUs)"
    )
    for key in KEYS:
        print(f"  {key:24s} {values.get(key, '0')}")
    cycles = int(values.get("cycles", "0"))
    if cycles:
        print(f"  {'miss share':24s} {100.0 * int(values['deadline_misses']) / cycles:.3f} %")
    # the executor thread may sit in a wait: leave without joining it
    os._exit(1 if node.loop_error else 0)


if __name__ == "__main__":
    raise SystemExit(main())
