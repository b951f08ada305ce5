"""The owner of a line over DDS: induction, recirculation and the lockstep clock.

A :class:`~fence_sorter.line.lockstep.LockstepOwner` whose units are ``line_unit`` nodes (one
per namespace ``/<unit name>``, on this host or another). It waits until every unit says it is
ready (its writers matched), then runs the line to the drain: each unit's commands go on
``/<unit name>/commands`` (in batches: the commands up to one the unit answers in one
message), its answers come on ``/<unit name>/replies``, the induction's
hand-offs go on ``/line/handoffs`` and the last unit's come back on its ``handoffs`` topic (the
recirculation's end of that link). Each step of the line clock is published on /clock. At the
end it writes the line summary (``LinePlant.summary``, JSON) to ``summary`` (or stdout) and
exits: 0 on a drained line whose hand-offs balance and whose parcels are all accounted for, 1
otherwise, 2 on a bad line file or parameter.

A unit that does not answer within ``reply_timeout``, or whose new process says ``ready``
(each process of a unit says it with a token of its own), is down: the line goes on without it
(:class:`~fence_sorter.line.lockstep.LockstepOwner`); the owner passes its hand-offs on for it
on the unit's own ``handoffs`` topic, and a new process of it rejoins at the next step.

The plant's loop runs in the main thread; rclpy spins in a thread of its own and hands the
replies over through one queue per unit.
"""

from __future__ import annotations

import json
import queue
import sys
import threading
import time
from collections.abc import Sequence

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from fence_sorter.jsonsafe import json_safe
from fence_sorter.line.handoff import RECIRCULATION, HandOff
from fence_sorter.line.line_file import load_line
from fence_sorter.line.lockstep import (
    Command,
    Links,
    LockstepOwner,
    StartGate,
    UnitDown,
    answered,
    decode,
    encode,
    join_batch,
)
from fence_sorter.line.multi_unit import LineRunConfig, line_problems
from fence_sorter.line.pacing import PacedSteps
from fence_sorter.nodes.base import FenceSorterNode
from fence_sorter.nodes.convert import handoff_from_msg, handoff_to_msg
from fence_sorter.nodes.line_record import (
    RecorderGate,
    publish_setup,
    publish_summary,
    summary_publisher,
)
from fence_sorter.nodes.line_unit import (
    COMMAND_QOS,
    END,
    INDUCTION_TOPIC,
    LINE_QOS,
    READY,
    TRANSIT,
    TRANSIT_QOS,
    handoff_latency_ns,
    handoff_topic,
    with_info,
)
from fence_sorter.nodes.parameters import LINE_OWNER_PARAMETERS
from fence_sorter.nodes.qos import CLOCK_QOS
from fence_sorter.nodes.tf_publisher import LineTfPublisher
from fence_sorter.recording.topics import CLOCK
from fence_sorter_msgs.msg import HandOff as HandOffMsg


class UnitSilent(RuntimeError):
    """Not every unit of the line said ready within ``start_timeout`` (one line)."""


class LineOwnerNode(FenceSorterNode, Links):
    NODE_NAME = "line_owner"
    STATUS = "running the line"
    PARAMETERS = LINE_OWNER_PARAMETERS
    PINNED_CLOCK = False

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        p = self.parameter_values()
        self.line = load_line(p["line"])
        self.cfg = LineRunConfig(
            parcels=int(p["parcels"]) if float(p["duration"]) == 0.0 else None,
            duration=float(p["duration"]) or None,
            rate_pcs_h=float(p["rate"]) or None,
            seed=None if int(p["seed"]) < 0 else int(p["seed"]),
            guard=bool(p["guard"]),
            dt=float(p["dt"]),
        )
        self.rtf = float(p["real_time_factor"])
        self.reply_timeout = float(p["reply_timeout"])
        self.start_timeout = float(p["start_timeout"])
        self.summary_path = str(p["summary"])
        self.warm = bool(p["warm_up"])
        names = [u.name for u in self.line.units]
        self.seq = [0] * len(names)
        # each unit's encoded commands not sent yet: they go in one message with the next
        # command the unit answers (lockstep.answered)
        self.batch: list[list[str]] = [[] for _ in names]
        self.inbox: list[queue.Queue] = [queue.Queue() for _ in names]
        self.gate = StartGate(names)
        self.token: list[str | None] = [None] * len(names)  # the process each unit runs in
        self.fresh: dict[int, str] = {}  # unit -> token of a new process of it, said ready
        self._poll = threading.Event()  # never set: a bounded wait between checks
        self.induction_published = 0
        self.recirculation_arrived = 0
        self.bad_messages = 0
        self.reply_wait_max = 0.0  # the longest wait for a unit's reply [s, wall]
        # hand-off transit times [ns]: each unit's upstream link (on /<unit>/transit at the
        # end), the recirculation's (measured here)
        self.latency_ns: list[list[int] | None] = [None] * len(names)
        self.recirculation_latency_ns: list[int] = []
        self.commands = [
            self.create_publisher(String, f"/{n}/commands", COMMAND_QOS) for n in names
        ]
        for k, n in enumerate(names):
            self.create_subscription(
                String, f"/{n}/replies", lambda m, k=k: self._on_reply(k, m), LINE_QOS
            )
            self.create_subscription(
                String, f"/{n}/{TRANSIT}", lambda m, k=k: self._on_transit(k, m), TRANSIT_QOS
            )
        self.induction = self.create_publisher(HandOffMsg, INDUCTION_TOPIC, LINE_QOS)
        # a unit's downstream link, for the hand-offs the owner passes on while it is down
        self.stand_in = [
            self.create_publisher(HandOffMsg, handoff_topic(n), LINE_QOS) for n in names
        ]
        self.create_subscription(
            HandOffMsg, handoff_topic(names[-1]), with_info(self._on_recirculation), LINE_QOS
        )
        self.clock = self.create_publisher(Clock, CLOCK, CLOCK_QOS)
        self.owner = LockstepOwner(self.line, self.cfg, self)
        # --bag: the gate waits for the recorder too; the summary goes on /line/summary
        self.recorder_gate = RecorderGate(self, names) if p["recorder"] else None
        self.summary_pub = summary_publisher(self)
        self.setup_pub = publish_setup(self, self.line.source_path, self.cfg, self.warm)
        self.tf = LineTfPublisher(self, self.line)  # every unit's frames and URDF

    # -- rclpy callbacks (the spin thread) ------------------------------------------------------
    def _on_reply(self, k: int, msg: String) -> None:
        if msg.data.startswith(READY):
            token = msg.data[len(READY) :]
            if self.token[k] is None:
                self.token[k] = token
                self.gate.say_ready(k)
            elif token != self.token[k]:
                self.fresh[k] = token
            return
        try:
            self.inbox[k].put(decode(msg.data))
        except (KeyError, TypeError, ValueError):
            self.bad_messages += 1

    def _on_transit(self, k: int, msg: String) -> None:
        try:
            self.latency_ns[k] = [int(v) for v in json.loads(msg.data)]
        except (TypeError, ValueError):
            self.bad_messages += 1

    def _on_recirculation(self, msg: HandOffMsg, info) -> None:
        self.recirculation_latency_ns.append(handoff_latency_ns(info))
        if handoff_from_msg(msg).to_unit == RECIRCULATION:
            self.recirculation_arrived += 1
        else:
            self.bad_messages += 1

    # -- Links (the plant's thread) -------------------------------------------------------------
    def send(self, k: int, body: object) -> None:
        """Unit k's next command; held back until the next one it answers, with which it goes
        in one message (a step's Tick, traffic records and Step: one message, not three)."""
        self.batch[k].append(encode(Command(self.seq[k], body)))
        self.seq[k] += 1
        if answered(body):
            self._flush(k)

    def _flush(self, k: int) -> None:
        if self.batch[k]:
            self.commands[k].publish(String(data=join_batch(self.batch[k])))
            self.batch[k].clear()

    def wait(self, k: int):
        """Unit k's next reply; UnitDown when none comes within ``reply_timeout`` or a new
        process of the unit said ready (the one the owner waits for is gone)."""
        self._flush(k)
        name = self.line.units[k].name
        t0 = time.monotonic()
        end = t0 + self.reply_timeout
        while True:
            if k in self.fresh:
                waited = time.monotonic() - t0
                raise UnitDown(k, f"{name}: a new process of it started", waited)
            try:
                r = self.inbox[k].get(timeout=0.05)
            except queue.Empty:
                pass
            else:
                self.reply_wait_max = max(self.reply_wait_max, time.monotonic() - t0)
                return r
            if time.monotonic() >= end:
                why = (
                    f"{name} did not answer command {self.seq[k] - 1} within reply_timeout "
                    f"{self.reply_timeout:g} s"
                )
                self.get_logger().error(f"{why}: the line goes on without it")
                raise UnitDown(k, why, time.monotonic() - t0)

    def left_over(self, k: int) -> list:
        out = []
        while not self.inbox[k].empty():
            out.append(self.inbox[k].get_nowait())
        return out

    def hand_off(self, h: HandOff) -> None:
        self.induction.publish(handoff_to_msg(h))
        self.induction_published += 1

    def forward(self, h: HandOff) -> None:
        self.stand_in[h.from_unit].publish(handoff_to_msg(h))

    def rejoining(self) -> list[int]:
        return sorted(self.fresh)

    def restart(self, k: int) -> None:
        self.token[k] = self.fresh.pop(k)
        self.seq[k] = 0
        self.batch[k].clear()  # the earlier process's commands
        while not self.inbox[k].empty():
            self.inbox[k].get_nowait()
        self.get_logger().info(f"{self.line.units[k].name} rejoins the line")

    # -- the run --------------------------------------------------------------------------------
    def wait_ready(self) -> None:
        """The start gate: until every unit said ready and every writer of the owner has
        matched its reader, wherever the units run; bounded by ``start_timeout``."""
        end = time.monotonic() + self.start_timeout
        while True:
            missing = self.gate.missing(
                [c.get_subscription_count() > 0 for c in self.commands],
                self.induction.get_subscription_count() > 0,
            )
            if self.recorder_gate is not None:
                missing += self.recorder_gate.missing()
            if not missing:
                return
            if time.monotonic() >= end:
                raise UnitSilent(
                    "line_owner: " + self.gate.timeout_message(self.start_timeout, missing)
                )
            self._poll.wait(0.05)  # the spin thread fills the gate

    def end_units(self, timeout: float = 10.0) -> None:
        """Tell every unit the line is over (each then exits 0), and wait, bounded, until each
        acknowledged it: a unit on another host ends with the line as well."""
        for k, u in enumerate(self.owner.units):
            if not u.down:
                self._flush(k)
        up = [c for u, c in zip(self.owner.units, self.commands, strict=True) if not u.down]
        for c in up:
            c.publish(String(data=END))
        for c in up:
            c.wait_for_all_acked(Duration(seconds=timeout))
        end = time.monotonic() + timeout
        units = self.owner.units
        while time.monotonic() < end and any(
            self.latency_ns[k] is None for k, u in enumerate(units) if not u.down
        ):
            self._poll.wait(0.05)  # each unit's hand-offs' transit times, sent on end

    def handoff_latency(self) -> dict:
        """Transit of the hand-offs per link (DDS source timestamp -> reception), in ms."""
        names = [u.name for u in self.line.units]
        links = [f"induction>{names[0]}"]
        links += [f"{a}>{b}" for a, b in zip(names, names[1:], strict=False)]
        samples = dict(zip(links, self.latency_ns, strict=True))
        samples[f"{names[-1]}>recirculation"] = self.recirculation_latency_ns
        out = {link: latency_figures(v) for link, v in samples.items()}
        out["all"] = latency_figures([x for v in samples.values() for x in v or []])
        return out

    def run_line(self) -> dict:
        owner = self.owner
        self.get_logger().info("every unit is ready: the line runs")
        if self.warm:
            owner.warm_up()
        pace = PacedSteps(self.cfg.dt, self.rtf, owner.t)

        def step() -> float:
            owner.step()
            self.clock.publish(Clock(clock=_stamp(owner.t)))
            return owner.t

        wall0 = time.perf_counter()
        pace.run(lambda: owner.active() and owner.t < owner.limit(), step)
        owner.wall = time.perf_counter() - wall0
        return {
            **owner.summary(),
            "reply_wait_max_s": self.reply_wait_max,
            "pacing": pace.figures(),
        }

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        values = {
            "sim_time": f"{self.owner.t:.3f}",
            "induction_handoffs_published": self.induction_published,
            "recirculation_handoffs_arrived": self.recirculation_arrived,
            "units_ready": len(self.gate.ready),
            "units_down": sum(u.down for u in self.owner.units),
            "bad_messages": self.bad_messages,
        }
        status.values.extend(KeyValue(key=k, value=str(v)) for k, v in values.items())
        return status


def latency_figures(ns: list[int] | None) -> dict:
    """Count, median, p99 and max [ms] of transit times [ns] (negative: not measured);
    ``None``: the unit's figures did not arrive."""
    if ns is None:
        return {"n": 0, "missing": True}
    v = np.array([x for x in ns if x >= 0], dtype=float) * 1e-6
    if not len(v):
        return {"n": 0}
    p50, p99 = np.percentile(v, (50, 99))
    return {"n": len(v), "p50_ms": float(p50), "p99_ms": float(p99), "max_ms": float(v.max())}


def line_ok(s: dict) -> bool:
    """``line-sim``'s check (:func:`fence_sorter.line.multi_unit.line_problems`: drained,
    conservation exact, no wrong destination, hand-offs balanced, no intrusion with the guard,
    no failed event, no sorted parcel over a limit)."""
    return not line_problems(s)


def _stamp(t: float) -> Time:
    ns = round(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def main(args: Sequence[str] | None = None) -> int:
    """Run the line to the drain; exit 0 (drained, hand-offs balanced), 1, or 2 (bad input)."""
    rclpy.init(args=list(args) if args is not None else None)
    node: LineOwnerNode | None = None
    executor = SingleThreadedExecutor()
    spin = threading.Thread(target=_spin, args=(executor,), daemon=True)
    try:
        try:
            node = LineOwnerNode()
        except ValueError as exc:
            print(f"line_owner: {exc}", file=sys.stderr)
            return 2
        executor.add_node(node)
        spin.start()
        node.wait_ready()
        summary = node.run_line()
        node.end_units()
        summary["handoff_latency"] = node.handoff_latency()
        publish_summary(node.summary_pub, summary)
        text = json.dumps(json_safe(summary))
        if node.summary_path:
            with open(node.summary_path, "w", encoding="utf-8") as f:
                f.write(text + "\n")
        else:
            print(text)
        return 0 if line_ok(summary) else 1
    except UnitSilent as exc:
        print(str(exc), file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 1
    finally:
        rclpy.try_shutdown()  # wakes the spin thread, which then ends
        if spin.is_alive():
            spin.join(timeout=10.0)
        executor.shutdown()
        if node is not None:
            node.destroy_node()


def _spin(executor) -> None:
    try:
        executor.spin()
    except (ExternalShutdownException, Exception):  # the context shut down under it
        pass


if __name__ == "__main__":
    raise SystemExit(main())
