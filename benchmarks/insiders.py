"""Insiders: an adversary on the run's own domain with the run's own id (the fault campaign's
``insiders`` section, ``python -m benchmarks faults --cases insiders``).

The run id is public (any /parcels message carries it), so the insider learns it from the
first real parcel and then, in a process of its own:

- **duplicates**: publishes the next ``count`` parcel ids with the run's id just ahead of the
  scanner, other size and mass, ``divert: false``;
- **flood**: publishes parcels with the run's id and new ids at ``rate`` per second for
  ``seconds`` s;
- **clock**: publishes /clock jumping ``jump`` s ahead of the run's sim time at 1 kHz for
  ``seconds`` s;
- **outcomes**: answers each parcel it sees on /parcels at once with a SORTED outcome of the
  run's id (peak force 1 N, impact 0.01 m/s) and a /diagnostics status in the simulator's
  name with figures of its own, ``count`` parcels long.

What the suite must do (docs/design/security.md, docs/reports/reliability.md): refuse every
forgery as ``foreign_source`` (it has no tag under the run's key), sort every real divert parcel as
planned, keep forgeries out of the figures, name them (and a foreign /clock publisher) in the
summary and exit 4, never 0.
"""

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

from benchmarks import REPO
from benchmarks.runs import finish, last_json
from fence_sorter.inputs import ParcelSpec

KINDS = ("duplicates", "flood", "clock", "outcomes")
#: the trials of the fault campaign's section (the forged outcomes are test/ros/test_insiders.py's)
CAMPAIGN_KINDS = ("duplicates", "flood", "clock")
#: ids of the flood's parcels start here (far above any stream of the suite)
FLOOD_FIRST_ID = 1_000_000
#: a parcel with the run's id but another spec: bigger, heavier, not to divert
FORGED_SPEC = {"length_a": 0.6, "width_b": 0.45, "height": 0.3, "mass": 20.0, "divert": False}


def insider_main(argv: list[str]) -> int:
    """``python -m benchmarks.insiders KIND --domain N [--count C] [--rate R] [--subscribers K]
    [--seconds S] [--jump J]``: act as the insider KIND; print what it sent as JSON."""
    ap = argparse.ArgumentParser(prog="insiders")
    ap.add_argument("kind", choices=KINDS)
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--rate", type=float, default=5000.0)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--jump", type=float, default=6.7e7)
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument(
        "--subscribers",
        type=int,
        default=3,
        help="readers of /parcels to match before forging (simulator, controller, monitor)",
    )
    a = ap.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy  # lazy: rclpy (0.25 s), only where ROS runs
    from rclpy.duration import Duration  # lazy: rclpy
    from rclpy.executors import SingleThreadedExecutor  # lazy: rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy  # lazy: rclpy
    from rclpy.signals import SignalHandlerOptions  # lazy: rclpy
    from rosgraph_msgs.msg import Clock  # lazy: ROS message

    from fence_sorter.nodes.convert import parcel_to_msg, sec_to_time  # lazy: ROS messages
    from fence_sorter.nodes.qos import INPUT_QOS  # lazy: rclpy
    from fence_sorter_msgs.msg import Parcel  # lazy: ROS message

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=a.domain, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("fence_sorter_insider", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    seen: dict[str, float] = {"run_id": 0, "last_id": 0, "sim": 0.0}

    def on_parcel(msg) -> None:
        if not seen["run_id"]:
            seen["run_id"] = int(msg.run_id)  # read off the wire
        seen["last_id"] = max(seen["last_id"], int(msg.parcel_id))

    def on_clock(msg) -> None:
        t = msg.clock.sec + 1e-9 * msg.clock.nanosec
        if t < seen["sim"] + 1e6:  # not our own jumped clock
            seen["sim"] = max(seen["sim"], t)

    node.create_subscription(Parcel, "/parcels", on_parcel, INPUT_QOS)
    if a.kind == "clock":  # on the graph from the start, silent until the first parcel
        pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=10))
    node.create_subscription(
        Clock, "/clock", on_clock, QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    )
    end = time.monotonic() + a.timeout
    while not seen["run_id"] and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    report: dict = {"kind": a.kind, "run_id": int(seen["run_id"]), "sent": 0}
    if not seen["run_id"]:
        report["error"] = "no parcel of the run seen"
        print(json.dumps(report))
        rclpy.try_shutdown(context=ctx)
        return 1
    run_id = int(seen["run_id"])
    if a.kind == "outcomes":
        return _forge_outcomes(node, executor, ctx, a, seen, report)
    if a.kind == "clock":
        # until the run's simulator and this process have found each other: a clock no node
        # has discovered reaches nobody and cannot be named
        wait = time.monotonic() + 30.0
        while time.monotonic() < wait and not any(
            e.node_name == "simulator" for e in node.get_publishers_info_by_topic("/run_clock")
        ):
            executor.spin_once(timeout_sec=0.05)
        msg = Clock()
        t0 = time.monotonic()
        n = int(a.seconds * 1000)
        for i in range(n):
            executor.spin_once(timeout_sec=0.0)
            msg.clock = sec_to_time(seen["sim"] + a.jump)
            pub.publish(msg)
            report["sent"] += 1
            delay = t0 + (i + 1) / 1000.0 - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        report["jump_s"] = a.jump
    else:
        pub = node.create_publisher(Parcel, "/parcels", INPUT_QOS)
        wait = time.monotonic() + 30.0
        # its own reader of /parcels (the run id) is matched too
        while pub.get_subscription_count() < a.subscribers + 1 and time.monotonic() < wait:
            executor.spin_once(timeout_sec=0.05)
        report["subscribers"] = pub.get_subscription_count() - 1
        if a.kind == "duplicates":
            first = int(seen["last_id"]) + 1
            ids = list(range(first, first + a.count))
            for pid in ids:  # ahead of the scanner: the real ones come 1-2 s apart
                spec = ParcelSpec(pid, scan_time=seen["sim"], scan_position_x=-3.0, **FORGED_SPEC)
                pub.publish(parcel_to_msg(spec, run_id=run_id))
                report["sent"] += 1
            report["forged_ids"] = ids
        else:
            n = int(round(a.rate * a.seconds))
            t0 = time.monotonic()
            for i in range(n):
                delay = t0 + i / a.rate - time.monotonic()
                if delay > 0.001:
                    time.sleep(delay)
                if i % 500 == 0:
                    executor.spin_once(timeout_sec=0.0)
                spec = ParcelSpec(
                    FLOOD_FIRST_ID + i,
                    lateral_gap=0.1,
                    divert=True,
                    scan_time=seen["sim"],
                    scan_position_x=-3.0,
                )
                pub.publish(parcel_to_msg(spec, run_id=run_id))
                report["sent"] += 1
            report["wall_s"] = time.monotonic() - t0
        report["all_acked"] = pub.wait_for_all_acked(Duration(seconds=30))
    print(json.dumps(report))
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
    return 0


def _forge_outcomes(node, executor, ctx, a, seen: dict, report: dict) -> int:
    """The ``outcomes`` insider: a SORTED outcome for each parcel as soon as it is scanned and
    a simulator status of its own, ``a.count`` parcels long."""
    import rclpy  # lazy: rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # lazy: ROS
    from rclpy.duration import Duration  # lazy: rclpy

    from fence_sorter.nodes.qos import topic_qos  # lazy: rclpy
    from fence_sorter_msgs.msg import SortOutcome  # lazy: ROS message

    outcomes = node.create_publisher(SortOutcome, "/sort_outcomes", topic_qos("/sort_outcomes"))
    diagnostics = node.create_publisher(DiagnosticArray, "/diagnostics", topic_qos("/diagnostics"))
    answered: set[int] = set()
    end = time.monotonic() + a.timeout
    report["forged_ids"] = []
    while len(answered) < a.count and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)
        for pid in range(1, int(seen["last_id"]) + 1):
            if pid in answered:
                continue
            answered.add(pid)
            msg = SortOutcome(parcel_id=pid, run_id=int(seen["run_id"]), sorted=True)
            msg.reason = "sorted"
            msg.peak_normal_force = msg.peak_normal_force_stiff = 1.0
            msg.impact_normal_speed, msg.peak_normal_accel, msg.exit_speed_y = 0.01, 0.1, 0.5
            outcomes.publish(msg)
            report["sent"] += 1
            report["forged_ids"].append(pid)
            status = DiagnosticStatus(name="fence_sorter/simulator", message="ok")
            status.values = [KeyValue(key="overlap_warnings", value="0")]
            diagnostics.publish(DiagnosticArray(status=[status]))
            report["statuses"] = report.get("statuses", 0) + 1
    report["all_acked"] = outcomes.wait_for_all_acked(Duration(seconds=30))
    print(json.dumps(report))
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
    return 0


@dataclass
class InsiderTrial:
    kind: str
    exit_code: int | None
    message: str
    insider: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)


def insider_trial(
    kind: str, workdir: Path, parcels: int = 12, rtf: float = 1.0, **insider: float
) -> InsiderTrial:
    """``fence-sorter run --parcels N --rtf R --json`` with the insider ``kind`` on its domain
    from the first parcel on."""
    err_path = workdir / f"insider-{kind}.log"
    with open(err_path, "w+") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "fence_sorter.cli.main", "run", "--parcels", str(parcels)]
            + ["--rtf", f"{rtf:g}", "--json"],
            stdout=subprocess.PIPE,
            stderr=err,
            text=True,
            start_new_session=True,
            cwd=workdir,
        )
        domain = None
        end = time.monotonic() + 300.0
        while domain is None and time.monotonic() < end and proc.poll() is None:
            m = re.search(r"ROS domain (\d+)", err_path.read_text(errors="replace"))
            domain = int(m.group(1)) if m else None
            time.sleep(0.1)
        report: dict = {}
        if domain is not None:
            args = [f"--{k}={v}" for k, v in insider.items()]
            done = subprocess.run(
                [sys.executable, "-m", __name__, kind, "--domain", str(domain), *args],
                cwd=REPO,  # where python -m finds benchmarks/
                capture_output=True,
                text=True,
                timeout=300.0,
            )
            try:
                report = json.loads(done.stdout.strip().splitlines()[-1])
            except (IndexError, ValueError):
                report = {"error": (done.stdout + done.stderr)[-2000:]}
        out = finish(proc)
    text = err_path.read_text(errors="replace").strip().splitlines()
    return InsiderTrial(kind, proc.returncode, text[-1] if text else "", report, last_json(out))


def refused(summary: dict, node: str, topic: str = "parcels") -> int:
    """A node's ``<topic>.foreign_source`` count from the run's summary."""
    return int(summary.get("dropped", {}).get(node, {}).get(f"{topic}.foreign_source", 0))


def trial_row(t: InsiderTrial) -> dict:
    """The campaign's figures of one trial."""
    s = t.summary
    sim = s.get("simulator", {})
    misses = float(sim.get("deadline_misses", "nan") or "nan")
    cycles = float(sim.get("cycles", "nan") or "nan")
    lost = s.get("divert_not_sorted", [])
    return {
        "case": t.kind,
        "sent": t.insider.get("sent", -1),
        "exit": t.exit_code,
        "parcels": f"{s.get('parcels_seen', 0)} of {s.get('parcels_expected', 0)}",
        "real_divert_not_sorted": ", ".join(f"{r['parcel_id']} {r['why']}" for r in lost)
        or "none",
        "refused_simulator": refused(s, "simulator"),
        "refused_controller": refused(s, "controller"),
        "forged_in_figures": s.get("outcomes_outside_stream", 0),
        "foreign_named": "; ".join(
            f"{k}: {', '.join(v)}" for k, v in s.get("foreign_publishers", {}).items()
        )
        or ", ".join(str(i) for i in s.get("forged_parcel_ids", []))
        or "-",
        "deadline_miss_pct": 100.0 * misses / cycles if cycles > 0 else math.nan,
        "sim_time_s": s.get("sim_time_s", math.nan),
    }


def row_ok(row: dict) -> bool:
    """The targets of one trial: exit 4, no real divert parcel lost, nothing forged in the
    figures, something named; the flood also < 0.5 % deadline misses."""
    return (
        row["exit"] == 4
        and row["real_divert_not_sorted"] == "none"
        and row["forged_in_figures"] == 0
        and row["foreign_named"] != "-"
        and not (row["case"] == "flood" and row["deadline_miss_pct"] >= 0.5)
    )


def section(workdir: Path, progress=print) -> dict:
    """The trials of :data:`CAMPAIGN_KINDS` as the campaign's ``insiders`` section."""
    rows = []
    for kind in CAMPAIGN_KINDS:
        t = insider_trial(kind, workdir, parcels=20)
        row = trial_row(t)
        rows.append(row)
        progress(f"insider {kind}: exit {t.exit_code}, {row['real_divert_not_sorted']} lost")
    return {"rows": rows}


def insiders_md(sec: dict, meta_lines: list[str]) -> list[str]:
    """docs/reports/reliability.md's section (``meta_lines``: the command, commit and machine)."""
    lines = [
        "## Insiders (the run's own id on the run's own domain)",
        "",
        *meta_lines,
        "A process on the run's domain reads the run id off /parcels and forges, during a "
        "20-parcel run at rtf 1: the next 10 parcel ids just ahead of the scanner (other size "
        "and mass, not to divert), a flood of 5000 parcels/s for 2 s with new ids, or a second "
        "/clock 6.7e7 s ahead for 2 s. Target: exit 4, every real divert parcel sorted as "
        "planned, no forgery in the figures, the forgery named; during the flood, deadline misses "
        "< 0.5 % (the pacing loop runs in a process of its own, which the flood does not reach).",
        "",
        "| case | sent | exit | parcels | real divert not sorted | refused (simulator) "
        "| refused (controller) | forged in figures | named | deadline misses | sim time |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in sec.get("rows", []):
        lines.append(
            f"| {r['case']} | {r['sent']} | {r['exit']} | {r['parcels']} | "
            f"{r['real_divert_not_sorted']} | {r['refused_simulator']} | "
            f"{r['refused_controller']} | {r['forged_in_figures']} | {r['foreign_named']} | "
            f"{r['deadline_miss_pct']:.3f} % | {r['sim_time_s']:.1f} s |"
        )
    return [*lines, ""]


if __name__ == "__main__":
    raise SystemExit(insider_main(sys.argv[1:]))
