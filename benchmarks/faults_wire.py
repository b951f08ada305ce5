"""The fault campaign's wire cases (see :mod:`benchmarks.faults`): malformed and hostile
parcels and commands published one by one to a controller and a simulator of one run."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from benchmarks.faults_floods import FOREIGN_RUN, command_msg, parcel_msg
from fence_sorter.resources import data_path
from fence_sorter.runner.monitor import Monitor
from fence_sorter.runner.processes import (
    ProcessGroup,
    leftovers,
    node_command,
    node_env,
)

#: the run id of the wire case's nodes
WIRE_RUN = 4242


# -- the wire ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class WireCase:
    """One message to a controller and a simulator of run WIRE_RUN and where it must be
    counted: ``node`` and the diagnostics key that must rise by one."""

    name: str
    topic: str  # "parcels" | "commands"
    fields: dict
    counters: tuple[tuple[str, str], ...]  # (node, key)
    target: int = 0  # commands: the parcel they are for (published first, valid)


def wire_cases() -> list[WireCase]:
    nan, inf = math.nan, math.inf
    both = (("controller", "rejected_parcels.{}"), ("simulator", "bad_parcels.{}"))

    def p(name, key, **f):
        return WireCase(name, "parcels", f, tuple((n, k.format(key)) for n, k in both))

    def c(name, key, target, **f):
        return WireCase(name, "commands", f, (("simulator", f"commands_rejected.{key}"),), target)

    return [
        p("mass NaN", "non_finite", mass=nan),
        p("mass -1 kg", "mass", mass=-1.0),
        p("mass 1e6 kg", "mass", mass=1e6),
        p("length_a 0", "size", length_a=0.0),
        p("length_a 10 m", "size", length_a=10.0),
        p("height NaN", "non_finite", height=nan),
        p("cog_offset_x 1 m", "cog_offset", cog_offset_x=1.0),
        p("yaw 3 rad", "yaw", yaw=3.0),
        p("mu_belt 5", "friction", mu_belt=5.0),
        p("mu_fence 5", "friction", mu_fence=5.0),
        p("mu_fence -1", "friction", mu_fence=-1.0),
        p("mu_belt inf", "non_finite", mu_belt=inf),
        p("lateral_gap -0.1 m", "lateral_gap", lateral_gap=-0.1),
        p("wider than the belt", "wider_than_belt", width_b=0.65),
        p("scan_time 1e5 s ahead", "scan_time", scan_time_offset=1e5),
        p("scan_time 11 s behind", "scan_time", scan_time_offset=-11.0),
        p("scan_position_x 1e9 m", "scan_position", scan_position_x=1e9),
        p("scan_position_x 1 m (off the scan line)", "scan_position", scan_position_x=1.0),
        p("scan_position_x NaN", "non_finite", scan_position_x=nan),
        WireCase(
            "another run's parcel",
            "parcels",
            {"run_id": FOREIGN_RUN},
            (("controller", "parcels.foreign"), ("simulator", "parcels.foreign")),
        ),
        c("t1 10 s (a 20 s stroke)", "outside_window", 301, t1=10.0),
        c("t1 20 s", "invalid", 302, t1=20.0),
        c("t1 NaN", "invalid", 303, t1=nan),
        c("alpha_k 0", "invalid", 304, alpha_k=0.0),
        c("R_s 9 m", "invalid", 305, r_s=9.0),
        c("start_mode 7", "invalid", 306, start_mode=7),
        c("start_time 1e5 s ahead (AT_TIME)", "invalid", 307, start_mode=1, start_offset=1e5),
        c("unknown parcel_id", "unknown_parcel", 0, parcel_id=999_999),
        c("a second command for a parcel", "duplicate", 308, repeat=True),
        WireCase(
            "another run's feasible:false for a real parcel",
            "commands",
            {"run_id": FOREIGN_RUN, "feasible": False, "reason": "forged"},
            (("simulator", "commands.foreign"),),
            309,
        ),
    ]


@dataclass
class WireResult:
    case: WireCase
    counted: dict[str, int]  # "node key" -> rise
    ok: bool


def run_wire(workdir: Path, domain: int, progress=print) -> tuple[list[WireResult], dict]:
    """Start a controller and a simulator of run WIRE_RUN and send each wire case."""
    from fence_sorter.nodes.convert import sec_to_time  # lazy: loads ROS messages
    from fence_sorter.nodes.qos import INPUT_QOS
    from fence_sorter_msgs.msg import FenceCommand, Parcel

    env = node_env(domain, workdir / "wire-ros")
    group = ProcessGroup(env, workdir / "wire-logs")
    monitor = Monitor(domain, name="fence_sorter_faults", run_id=WIRE_RUN)
    rec = monitor.records

    def args(node: str, *extra: str) -> list[str]:
        out = ["--params-file", str(data_path("config", f"{node}.yaml"))]
        for o in ("heartbeat_period:=0.2", f"run_id:={WIRE_RUN}", *extra):
            out += ["-p", o]
        return out

    def wait(pred, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            monitor.spin_for(0.05)
            if pred():
                return True
        return False

    def beat(node: str) -> dict:
        return rec.diagnostics.get(f"fence_sorter/{node}", {})

    results: list[WireResult] = []
    extra: dict = {}
    try:
        # the controller listens only to the scan line itself: the command cases' parcels
        # (scanned 0.3 m upstream of it) are the simulator's alone, so no real command races
        # the hostile ones
        group.start(
            "controller",
            node_command(
                "controller",
                args(
                    "controller",
                    "use_sim_time:=true",
                    "warmup_parcels:=0",
                    "scan_line_tolerance:=0.1",
                ),
            ),
        )
        group.start("simulator", node_command("simulator", args("simulator")))
        up = wait(lambda: beat("controller").get("listening") == "true" and beat("simulator"), 180)
        if not up:
            raise RuntimeError("controller and simulator did not come up within 180 s")
        ppub = monitor.node.create_publisher(Parcel, "/parcels", INPUT_QOS)
        cpub = monitor.node.create_publisher(FenceCommand, "/fence_commands", INPUT_QOS)
        wait(lambda: ppub.get_subscription_count() >= 3 and cpub.get_subscription_count() >= 2, 30)
        wait(lambda: rec.sim_time > 12.0, 60)  # a scan time 11 s back is still >= 0
        next_id = 201
        for case in wire_cases():
            before = {f"{n} {k}": int(beat(n).get(k, "0")) for n, k in case.counters}
            now = rec.sim_time
            f = dict(case.fields)
            if case.topic == "parcels":
                offset = f.pop("scan_time_offset", 0.0)
                run_id = f.pop("run_id", WIRE_RUN)
                ppub.publish(parcel_msg(next_id, run_id, now + offset, **f))
                next_id += 1
            else:
                repeat = f.pop("repeat", False)
                start_offset = f.pop("start_offset", None)
                if case.target:
                    target = parcel_msg(case.target, WIRE_RUN, now, scan_position_x=-3.3)
                    ppub.publish(target)
                    monitor.spin_for(0.3)
                if start_offset is not None:
                    f["start_time"] = sec_to_time(now + start_offset)
                pid = f.pop("parcel_id", case.target)
                run_id = f.pop("run_id", WIRE_RUN)
                if repeat:
                    cpub.publish(command_msg(pid, WIRE_RUN))
                cpub.publish(command_msg(pid, run_id, **f))

            def risen(counters=case.counters, before=before) -> bool:
                return all(int(beat(n).get(k, "0")) >= before[f"{n} {k}"] + 1 for n, k in counters)

            ok = wait(risen, 10.0)
            counted = {
                key: int(beat(key.split()[0]).get(key.split()[1], "0")) - v
                for key, v in before.items()
            }
            alive = all(n.proc.poll() is None for n in group.nodes.values())
            results.append(WireResult(case, counted, ok and alive))
            progress(f"wire  {case.name:45s} {'refused, counted' if ok else 'NOT COUNTED'}")
        extra["controller"] = dict(beat("controller"))
        extra["simulator"] = dict(beat("simulator"))
        extra["alive"] = all(n.proc.poll() is None for n in group.nodes.values())
    finally:
        codes = group.stop(("controller", "simulator"))
        extra["exit_codes"] = codes
        extra["leftovers"] = len(leftovers(group.pgids))
        monitor.close()
    return results, extra
