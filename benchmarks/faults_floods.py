"""The fault campaign's floods (see :mod:`benchmarks.faults`): the flooding child process,
the forged parcel and command messages, and one flood trial against a run."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.faults_processes import start_watched
from benchmarks.runs import finish, last_json

#: a run id no run of the suite draws in practice: the flooding "other run"
FOREIGN_RUN = 999


# -- floods ----------------------------------------------------------------------------------
def flood_main(argv: list[str]) -> int:
    """``python -m benchmarks.faults flood TOPIC --domain N [--rate R]
    [--seconds S]``: publish another run's messages at R per second for S s; print the count
    sent as JSON."""
    ap = argparse.ArgumentParser(prog="faults flood")
    ap.add_argument("topic", choices=("/parcels", "/fence_commands"))
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--rate", type=float, default=5000.0)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--first-id", type=int, default=1)
    ap.add_argument("--ids", type=int, default=20, help="ids cycle over first-id + [0, ids)")
    a = ap.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy  # lazy: rclpy (0.25 s), only where ROS runs
    from rclpy.signals import SignalHandlerOptions

    from fence_sorter.nodes.qos import INPUT_QOS  # lazy: loads rclpy
    from fence_sorter_msgs.msg import FenceCommand, Parcel

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=a.domain, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("fence_sorter_flood", context=ctx)
    kind = Parcel if a.topic == "/parcels" else FenceCommand
    pub = node.create_publisher(kind, a.topic, INPUT_QOS)
    end = time.monotonic() + 10.0
    while pub.get_subscription_count() < 2 and time.monotonic() < end:
        time.sleep(0.05)
    subscribers = pub.get_subscription_count()
    n = int(round(a.rate * a.seconds))
    sent = failed = 0
    error = ""
    t0 = time.monotonic()
    for i in range(n):
        due = t0 + i / a.rate
        delay = due - time.monotonic()
        if delay > 0.001:
            time.sleep(delay)
        pid = a.first_id + i % a.ids
        if kind is Parcel:
            msg = parcel_msg(pid, run_id=FOREIGN_RUN, scan_position_x=-3.0)
        else:
            msg = command_msg(pid, FOREIGN_RUN, feasible=False, reason="forged by a flood")
        try:
            pub.publish(msg)
            sent += 1
        except Exception as exc:  # the middleware refused it (a keep-all reader's back-pressure)
            failed += 1
            error = f"{type(exc).__name__}: {exc}"
    wall = time.monotonic() - t0
    # every subscriber has it before the participant goes (its writer's history goes with it)
    from rclpy.duration import Duration  # lazy: rclpy (0.25 s), only where ROS runs

    acked = pub.wait_for_all_acked(Duration(seconds=30))
    print(
        json.dumps(
            {
                "sent": sent,
                "publish_failed": failed,
                "all_acked": acked,
                "error": error[:200],
                "wall_s": wall,
                "subscribers": subscribers,
            }
        )
    )
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
    return 0


def parcel_msg(pid: int, run_id: int = 0, scan_time: float = 0.0, **fields):
    """A plausible Parcel (0.3 x 0.2 m, 3 kg, to divert) with ``fields`` changed."""
    from fence_sorter.nodes.convert import sec_to_time  # lazy: loads ROS messages
    from fence_sorter_msgs.msg import Parcel

    msg = Parcel()
    msg.header.frame_id = "sorter"
    msg.parcel_id, msg.run_id = pid, run_id
    msg.length_a, msg.width_b, msg.height, msg.mass = 0.3, 0.2, 0.2, 3.0
    msg.lateral_gap, msg.yaw = 0.1, 0.0
    msg.mu_belt = msg.mu_fence = math.nan
    msg.divert = True
    msg.scan_time = sec_to_time(scan_time)
    msg.header.stamp = msg.scan_time
    msg.scan_position_x = -3.0
    for k, v in fields.items():
        setattr(msg, k, v)
    return msg


def command_msg(pid: int, run_id: int, **fields):
    """A FenceCommand (R_s 0.4 m, t1 0.35 s, alpha_k 40 deg, feasible) with ``fields``."""
    from fence_sorter_msgs.msg import FenceCommand  # lazy: ROS messages, only where ROS runs

    msg = FenceCommand()
    msg.header.frame_id = "sorter"
    msg.parcel_id, msg.run_id = pid, run_id
    msg.r_s, msg.t1, msg.alpha_k, msg.feasible = 0.4, 0.35, math.radians(40.0), True
    for k, v in fields.items():
        setattr(msg, k, v)
    return msg


@dataclass
class FloodTrial:
    topic: str
    sent: int
    publish_failed: int
    exit_code: int | None
    summary: dict = field(default_factory=dict)
    leftovers: int = 0
    traceback: bool = False


def flood_trial(topic: str, workdir: Path, rate: float, seconds: float) -> FloodTrial:
    """A 20-parcel run with a flood on ``topic`` 3 s after its nodes are up."""
    err_path = workdir / f"flood-{topic.strip('/')}.log"
    err = open(err_path, "w+")  # noqa: SIM115 (read while the run writes it)
    proc, watch = start_watched(
        ("run", "--parcels", "20", "--json"), workdir, subprocess.PIPE, err, text=True
    )
    domain = None
    end = time.monotonic() + 300.0
    while time.monotonic() < end and proc.poll() is None:
        text = err_path.read_text(errors="replace")
        m = re.search(r"ROS domain (\d+)", text)
        domain = int(m.group(1)) if m else None
        if domain is not None and "running" in text:
            break
        time.sleep(0.2)
    sent = failed = 0
    if domain is not None and proc.poll() is None:
        time.sleep(3.0)
        flood = subprocess.run(
            [
                sys.executable,
                "-m",
                "benchmarks.faults",
                "flood",
                topic,
                "--domain",
                str(domain),
                "--rate",
                str(rate),
                "--seconds",
                str(seconds),
            ],
            capture_output=True,
            text=True,
            timeout=300.0,
        )
        try:
            report = json.loads(flood.stdout.strip().splitlines()[-1])
            sent, failed = report["sent"], report["publish_failed"]
        except (IndexError, ValueError, KeyError):
            sent = -1
            (workdir / "flood-error.log").write_text(flood.stdout + flood.stderr)
    out = finish(proc)
    time.sleep(1.0)
    watch.poll()
    watch.done.set()
    left = watch.alive()
    watch.kill_alive()
    err.close()
    summary = last_json(out)
    text = err_path.read_text(errors="replace") + out
    return FloodTrial(
        topic, sent, failed, proc.returncode, summary, len(left), "Traceback" in text
    )
