"""Scanner node: injects the parcel stream at the scan line and publishes fence_sorter_msgs/Parcel.

The stream (random from a config in config/streams/, or a CSV manifest) is drawn once at start
(:mod:`fence_sorter.stream`); each parcel is published on /parcels when its front crosses the
scan line x = scan_line_x in sim time, with scan_time (the crossing time) and scan_position_x.

The stream starts once every node named in ``start_gate`` is in the ROS graph with a
subscription on each topic it needs (``NODE_SUBSCRIPTIONS`` of
:mod:`fence_sorter.recording.topics`; by node name, so extra listeners on /parcels do not
count) and, when the recorder is named, once a recorder heartbeat sent after that reports
every publisher in the graph matched (``publishers_unmatched`` empty, and its
``publishers_matched`` counts no fewer publishers per topic than this node's graph shows: the
recorder's own graph may not show them all yet): the graph shows a subscription before DDS has
matched it, and the volatile state topics (/clock, /load_states) published in between would be
missing from the bag. /parcels is transient local with a
history covering the stream, so a subscriber whose matching completes after the gate opened
still gets every parcel.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.exceptions import ParameterException
from rclpy.time import Time
from rosgraph_msgs.msg import Clock

from fence_sorter.nodes.base import FenceSorterNode, run_node
from fence_sorter.nodes.convert import fill_clock
from fence_sorter.nodes.parameters import SCANNER_PARAMETERS
from fence_sorter.nodes.qos import topic_qos
from fence_sorter.nodes.sources import sign
from fence_sorter.physics.params import ParameterError
from fence_sorter.recording import topics
from fence_sorter.scene import DEFAULT_SCENE, load_scene
from fence_sorter.stream import DEFAULT_STREAM, ParcelSpec, load_stream
from fence_sorter_msgs.msg import Parcel


def fill_parcel(
    msg, spec: ParcelSpec, scan_time: float, scan_x: float, frame_id: str, run_id: int = 0
) -> None:
    """Copy a ParcelSpec into a Parcel message of run ``run_id`` scanned at ``scan_time`` at
    x = ``scan_x``."""
    stamp = Time(nanoseconds=int(round(scan_time * 1e9))).to_msg()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.parcel_id = spec.parcel_id
    msg.run_id = run_id
    msg.length_a = spec.length_a
    msg.width_b = spec.width_b
    msg.height = spec.height
    msg.mass = spec.mass
    msg.cog_offset_x = spec.cog_offset_x
    msg.cog_offset_y = spec.cog_offset_y
    msg.lateral_gap = spec.lateral_gap
    msg.yaw = spec.yaw
    msg.mu_belt = spec.mu_belt
    msg.mu_fence = spec.mu_fence
    msg.divert = spec.divert
    msg.scan_time = stamp
    msg.scan_position_x = scan_x


#: a parcel published this much sim time after its scan time is logged [s]
SCAN_LAG_WARN = 0.1
#: /scan_progress at least every this much sim time [s] and this much wall time [s]
PROGRESS_PERIOD = 0.2
PROGRESS_WALL_PERIOD = 0.1


#: the start gate looks at the ROS graph at most this often [s] (wall clock)
GATE_CHECK_PERIOD = 0.02
#: the node whose heartbeat must report its publishers matched before the stream starts
MATCH_REPORTER = "recorder"
#: a recorder that reports unmatched publishers this long [s] (wall clock; for example a
#: publisher of incompatible QoS) no longer holds the stream back; the scanner logs it
MATCH_WAIT_MAX = 15.0


def gate_requirements(names: str) -> list[tuple[str, str]]:
    """'simulator,controller' -> the (node, topic) subscriptions the start gate waits for."""
    nodes = [n.strip() for n in names.split(",") if n.strip()]
    return [(n, t) for n in nodes for t in topics.NODE_SUBSCRIPTIONS.get(n, (topics.PARCELS,))]


def due(stream: Sequence[ParcelSpec], next_index: int, t0: float, now: float) -> int:
    """Index past the last parcel whose front has crossed the scan line by ``now``."""
    i = next_index
    while i < len(stream) and t0 + stream[i].arrival_time <= now:
        i += 1
    return i


class ScannerNode(FenceSorterNode):
    """Scanner upstream of the fence: publishes each parcel as it crosses the scan line."""

    NODE_NAME = "scanner"
    STATUS = "scanning"
    PARAMETERS = SCANNER_PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        try:
            self._setup()
        except ParameterError as exc:  # bad scene, stream or planner settings
            raise ParameterException(str(exc), "scanner") from None

    def _setup(self) -> None:
        p = self.parameter_values()
        base = load_scene(p["scene"] or DEFAULT_SCENE).scenario
        self.belt_speed = base.conveyor.belt_speed
        count = int(p["parcels"]) or None
        duration = float(p["duration"]) or None
        if count is None and duration is None:
            count = 100
        self.stream_name = p["stream"] or DEFAULT_STREAM
        self.stream = load_stream(
            self.stream_name,
            self.belt_speed,
            count=count,
            duration=duration,
            seed=None if p["seed"] < 0 else int(p["seed"]),
            belt_width=base.conveyor.width,
            rate_pcs_h=float(p["rate"]) or None,
        )
        self.scan_x = float(p["scan_line_x"])
        self.start_delay = float(p["start_delay"])
        self.gate = gate_requirements(str(p["start_gate"]))
        self.gate_missing: list[str] = [f"{n}:{t}" for n, t in self.gate]
        self._gate_checked = -math.inf
        # (wall time received, topics it has not matched) of the recorder's latest heartbeat
        self._match_report: tuple[float, str] | None = None
        self._graph_open_at: float | None = None
        if any(n == MATCH_REPORTER for n, _ in self.gate):
            self.create_subscription(
                DiagnosticArray,
                topics.DIAGNOSTICS,
                self._on_diagnostics,
                topic_qos(topics.DIAGNOSTICS),
            )
        self.frame_id = p["frame_id"]
        self.run_id = int(p["run_id"])
        self.t0: float | None = None
        self.next_index = 0
        # sim time from a parcel's scan time to its publication (the tick, and how late the
        # executor ran it: /clock at hundreds of messages per second when unpaced)
        self.scan_lag_max = 0.0
        self._parcel_class = Parcel
        self._pub = self.create_publisher(Parcel, topics.PARCELS, self._stream_qos())
        # how far it has scanned: an unpaced simulator keeps within its scan_lead of it
        self._progress = self.create_publisher(
            Clock, topics.SCAN_PROGRESS, topic_qos(topics.SCAN_PROGRESS)
        )
        self._progress_msg = Clock()
        self._progress_sent = -math.inf
        self._timer = self._jump = self._wall = None
        if self.get_parameter("use_sim_time").value:
            # once per /clock message: sim time only moves then, and a sim-time timer of a
            # shorter period fires several times per message, each through the executor,
            # which fell behind an unpaced simulator's /clock (parcels published seconds late)
            self._jump = self.get_clock().create_jump_callback(
                JumpThreshold(
                    min_forward=Duration(nanoseconds=1), min_backward=None, on_clock_change=False
                ),
                post_callback=lambda jump: self.tick(),
            )
            # and on the wall clock: the first progress report while sim time still waits
            # for it (an unpaced simulator holds at its start), then a steady report
            self._wall = self.create_timer(
                PROGRESS_WALL_PERIOD,
                lambda: self.tick(report=True),
                clock=RosClock(clock_type=ClockType.STEADY_TIME),
            )
        else:
            self._timer = self.create_timer(float(p["tick_period"]), self.tick)
        self.get_logger().info(
            f"scanner: {len(self.stream)} parcels from {self.stream_name} at x = "
            f"{self.scan_x:g} m, belt {self.belt_speed:g} m/s"
        )

    def _stream_qos(self):
        """/parcels' profile with a history covering the whole stream (late joiners get
        every parcel)."""
        return topic_qos(topics.PARCELS, max(topics.STREAM_HISTORY_DEPTH, len(self.stream)))

    def tick(self, report: bool = False) -> None:
        """Publish the parcels whose front crossed the scan line since the last tick, and the
        progress every PROGRESS_PERIOD of sim time (``report``: now)."""
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.t0 is None:
            if not self._gate_open():
                return
            self._report(max(now, 0.0), report)  # ready: nothing is due before now
            if now <= 0.0:  # no /clock yet
                return
            self.t0 = now + self.start_delay
        end = due(self.stream, self.next_index, self.t0, now)
        for spec in self.stream[self.next_index : end]:
            msg = self._parcel_class()
            stamp = self.t0 + spec.arrival_time
            fill_parcel(msg, spec, stamp, self.scan_x, self.frame_id, self.run_id)
            self._pub.publish(sign(msg, self.run_key))
            self.scan_lag_max = max(self.scan_lag_max, now - stamp)
            if now - stamp > SCAN_LAG_WARN:
                self.get_logger().warning(
                    f"parcel {spec.parcel_id} published {now - stamp:.3f} s (sim) after its "
                    "scan time: the scanner is behind /clock"
                )
        self.next_index = end
        self._report(now, report)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == f"fence_sorter/{MATCH_REPORTER}":
                values = {kv.key: kv.value for kv in status.values}
                if "publishers_unmatched" in values:
                    unmatched = values["publishers_unmatched"].split()
                    # its graph may lag this one's: a publisher seen here, not matched there
                    for item in values.get("publishers_matched", "").split():
                        topic, _, count = item.rpartition("=")
                        if self.count_publishers(topic) > int(count) and topic not in unmatched:
                            unmatched.append(topic)
                    self._match_report = (time.monotonic(), " ".join(unmatched))

    def _gate_open(self) -> bool:
        """Every (node, topic) of the start gate is in the graph, and the recorder, if named,
        has matched every publisher (checked every GATE_CHECK_PERIOD of wall time; once open
        it stays open). ``gate_missing`` lists what it still waits for as node:topic."""
        if not self.gate_missing:
            return True
        wall = time.monotonic()
        if wall - self._gate_checked < GATE_CHECK_PERIOD:
            return False
        self._gate_checked = wall
        if self._graph_open_at is None:
            subscribed: dict[str, set[str]] = {}
            for _, topic in self.gate:
                if topic not in subscribed:
                    infos = self.get_subscriptions_info_by_topic(topic)
                    subscribed[topic] = {i.node_name for i in infos}
            self.gate_missing = [f"{n}:{t}" for n, t in self.gate if n not in subscribed[t]]
            if self.gate_missing:
                return False
            self._graph_open_at = wall
        if any(n == MATCH_REPORTER for n, _ in self.gate):
            report = self._match_report
            fresh = report is not None and report[0] > self._graph_open_at
            if not fresh or report[1]:
                unmatched = report[1].split() if fresh else ["heartbeat"]
                self.gate_missing = [f"{MATCH_REPORTER}:{t}" for t in unmatched]
                if wall - self._graph_open_at < MATCH_WAIT_MAX:
                    return False
                self.get_logger().warning(
                    f"start gate: the {MATCH_REPORTER} has not matched the publishers of "
                    f"{' '.join(unmatched)} after {MATCH_WAIT_MAX:g} s; starting the stream"
                )
        self.gate_missing = []
        self.get_logger().info(
            "start gate open: "
            + ", ".join(sorted({n for n, _ in self.gate}))
            + " subscribed on their topics"
        )
        return True

    def _report(self, now: float, force: bool) -> None:
        """/scan_progress: every parcel due by sim time ``now`` is out."""
        if force or now - self._progress_sent >= PROGRESS_PERIOD:
            self._progress.publish(fill_clock(self._progress_msg, now))
            self._progress_sent = now

    def publish_heartbeat(self) -> bool:
        """Not before the first /clock: the scanner starts into a running simulation, and a
        heartbeat stamped 0 in mid-run is logged before every message stamped later
        (StampOrder), into a bag chunk written long before (rerun reports the chunks out of
        order)."""
        return self.get_clock().now().nanoseconds > 0 and super().publish_heartbeat()

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        done = self.next_index >= len(self.stream)
        last = self.stream[-1].arrival_time if self.stream else math.nan
        status.values.extend(
            KeyValue(key=k, value=v)
            for k, v in {
                "stream": self.stream_name,
                "parcels_total": str(len(self.stream)),
                "parcels_published": str(self.next_index),
                "done": str(done).lower(),
                "last_arrival_s": f"{last:.3f}",
                "scan_lag_max_s": f"{self.scan_lag_max:.4f}",
                # node:topic subscriptions the start gate still waits for
                "start_gate_missing": " ".join(self.gate_missing),
            }.items()
        )
        return status


def main(args: Sequence[str] | None = None) -> int:
    """Run the scanner node until Ctrl-C or SIGTERM."""
    return run_node(ScannerNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
