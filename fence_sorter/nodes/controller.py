"""Controller node: plans a fence stroke (R_s, t1, alpha_k) per scanned parcel to divert.

Subscribes /parcels, publishes one fence_sorter_msgs/FenceCommand per divert parcel on
/fence_commands: feasible with the predicted figures, or feasible=false with the reason. The
planning itself is :class:`fence_sorter.capacity.Planner` under the swept-sector guard of
:class:`fence_sorter.line.one_unit.UnitTraffic` (both ROS-free): a divert parcel is planned at
its decision time (:func:`fence_sorter.line.one_unit.decision_time`), when the parcels behind
it are scanned, and a stroke whose sector another parcel enters is passed over (none left: a
``sector_occupied`` decline). This module only turns messages into their inputs and plans into
messages. A parcel whose R_s is already behind when the controller gets it (e.g. right after a
restart) gets no command (logged and counted).
"""

from __future__ import annotations

import heapq
import math
import time
from collections import Counter, deque
from collections.abc import Sequence

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter
from rclpy.time import Time

from fence_sorter.capacity.planner import LoadRequest, Plan, Planner, PlannerConfig
from fence_sorter.inputs import InputError, ParcelSpec, validate_parcel
from fence_sorter.line.one_unit import UnitTraffic, decision_time, decline_reason
from fence_sorter.line.routing import NO_FEASIBLE_STROKE, SECTOR_OCCUPIED
from fence_sorter.nodes.base import FenceSorterNode, run_node
from fence_sorter.nodes.convert import parcel_from_msg
from fence_sorter.nodes.intake import ParcelRegistry, TopicIntake
from fence_sorter.nodes.parameters import CONTROLLER_PARAMETERS, PLANNER_PARAMETERS
from fence_sorter.nodes.qos import INPUT_QOS, topic_qos
from fence_sorter.nodes.sources import sign
from fence_sorter.physics.params import ParameterError, ParcelParams
from fence_sorter.recording import topics
from fence_sorter.scene import DEFAULT_SCENE, load_scene
from fence_sorter.stream import load_stream
from fence_sorter_msgs.msg import FenceCommand, Parcel

#: the planner's parameters: a change at run time gives the next parcels a new planner
PLANNER_KEYS = frozenset(spec.name for spec in PLANNER_PARAMETERS)


def request_from_spec(spec: ParcelSpec) -> LoadRequest:
    """A validated parcel -> the planner's LoadRequest."""
    return LoadRequest(
        parcel_id=int(spec.parcel_id),
        parcel=spec.to_parcel_params(),
        scan_time=spec.scan_time,
        scan_position_x=spec.scan_position_x,
        mu_belt=spec.mu_belt,
        mu_fence=spec.mu_fence,
    )


def fill_command(cmd, plan: Plan, alpha_k: float) -> None:
    """Copy a plan into a FenceCommand (START_AT_RS; NaN figures when infeasible)."""
    cmd.parcel_id = plan.parcel_id
    cmd.start_mode = cmd.START_AT_RS
    cmd.feasible = plan.feasible
    cmd.reason = plan.reason
    ev = plan.evaluation
    cmd.alpha_k = alpha_k
    if ev is None:
        nan = math.nan
        cmd.r_s = cmd.t1 = nan
        cmd.predicted_capacity_pcs_h = cmd.predicted_impact_speed = nan
        cmd.predicted_peak_accel = cmd.predicted_exit_speed = cmd.predicted_peak_force = nan
        return
    cmd.r_s = ev.r_s
    cmd.t1 = ev.t1
    cmd.start_time = Time(nanoseconds=int(round(plan.start_time * 1e9))).to_msg()
    cmd.predicted_capacity_pcs_h = ev.capacity_pcs_h
    cmd.predicted_impact_speed = ev.impact_speed
    cmd.predicted_peak_accel = ev.peak_accel
    cmd.predicted_exit_speed = ev.exit_speed
    cmd.predicted_peak_force = ev.peak_force


#: wall time reserved (times the real-time factor) for a command to reach the simulator [s]
DELIVERY_ALLOWANCE = 0.01


class RateEstimate:
    """Real-time factor seen by the node: sim time over wall time since a reference point
    at least ``window`` wall seconds back (1.0 until it can tell)."""

    def __init__(self, window: float = 2.0):
        self.window = window
        self.points: deque[tuple[float, float]] = deque()
        self.value = 1.0

    def update(self, wall: float, sim: float) -> float:
        self.points.append((wall, sim))
        while len(self.points) > 2 and wall - self.points[1][0] >= self.window:
            self.points.popleft()
        w0, s0 = self.points[0]
        if wall - w0 >= 0.2 and sim >= s0:
            self.value = (sim - s0) / (wall - w0)
        return self.value


class ControllerStats:
    """Counters and latency samples reported on /diagnostics (ROS-free)."""

    def __init__(self, window: int = 10000):
        self.latency = deque(maxlen=window)  # parcel received to command published [s] (wall)
        # the parcel's publication (the scanner's send time) to the command published [s]: a
        # process stopped as a whole receives late, so only this one sees its stop
        self.latency_from_send = deque(maxlen=window)
        self.lead = deque(maxlen=window)  # command sim time before the front reaches R_s [s]
        # sim time from a divert parcel's decision time to its planning [s]: the timer's tick
        # normally; a stopped or starved controller decides late by up to its stop
        self.decision_lateness = deque(maxlen=window)
        self.received = self.commands = self.infeasible = self.late = 0
        self.rejected = self.not_diverted = self.evaluations = self.replans = 0
        self.replanned_configs = 0  # planner settings changed at run time
        self.rejected_by_key: Counter[str] = Counter()  # InputError.key -> parcels
        # divert parcels without a stroke by reason: the swept-sector guard's, or none feasible
        self.declined: Counter[str] = Counter({NO_FEASIBLE_STROKE: 0, SECTOR_OCCUPIED: 0})

    def percentile(self, q: float, samples=None) -> float:
        samples = self.latency if samples is None else samples
        return float(np.percentile(samples, q)) if samples else math.nan

    def values(self) -> dict[str, str]:
        return {
            "parcels_received": str(self.received),
            "commands": str(self.commands),
            "infeasible": str(self.infeasible),
            "late_no_command": str(self.late),
            "rejected_parcels": str(self.rejected),
            "not_diverted": str(self.not_diverted),
            "evaluations": str(self.evaluations),
            "replans": str(self.replans),
            "planner_changes": str(self.replanned_configs),
            "latency_p50_ms": f"{1e3 * self.percentile(50):.3f}",
            "latency_p99_ms": f"{1e3 * self.percentile(99):.3f}",
            "latency_max_ms": f"{1e3 * max(self.latency, default=math.nan):.3f}",
            "latency_from_send_p99_ms": f"{1e3 * self.percentile(99, self.latency_from_send):.3f}",
            "latency_from_send_max_ms": (
                f"{1e3 * max(self.latency_from_send, default=math.nan):.3f}"
            ),
            "min_lead_s": f"{min(self.lead, default=math.nan):.4f}",
            "decision_lateness_max_s": f"{max(self.decision_lateness, default=math.nan):.4f}",
            **{f"rejected_parcels.{k}": str(v) for k, v in sorted(self.rejected_by_key.items())},
            **{f"declined.{k}": str(v) for k, v in sorted(self.declined.items())},
        }


class ControllerNode(FenceSorterNode):
    """Fence controller: turns scanned parcels into fence_sorter_msgs/FenceCommand."""

    NODE_NAME = "controller"
    STATUS = "planning fence strokes"
    PARAMETERS = CONTROLLER_PARAMETERS

    def validate_parameters(self, parameters: Sequence[Parameter]) -> str | None:
        """Refuse a planner configuration the planner would refuse (names key and range).

        At run time the changed values are checked together with the current ones, and the
        planner they make is built here, so a change that is accepted is one that works."""
        values = {p.name: p.value for p in parameters}
        if not PLANNER_KEYS & values.keys():
            return None
        if hasattr(self, "planner"):  # a change at run time: the others as they are
            values = {k: self.get_parameter(k).value for k in PLANNER_KEYS} | values
        try:
            config = PlannerConfig.from_mapping(values)
            if hasattr(self, "planner"):
                self._next_planner = Planner(self.base, config)
        except (ParameterError, OSError, ValueError) as exc:
            return str(exc)
        return None

    def apply_parameters(self, parameters: Sequence[Parameter]) -> None:
        """A new planner for the next parcel (its evaluations are made anew under the new
        settings; the fence-busy window of the strokes already commanded is kept); the scan
        line check takes its new values at once."""
        values = {p.name: p.value for p in parameters}
        if PLANNER_KEYS & values.keys():
            planner, self._next_planner = self._next_planner, None
            planner.busy_until = self.planner.busy_until
            self.planner, self.config = planner, planner.config
            self.stats.replanned_configs += 1
            self.get_logger().info(
                "planner settings changed ("
                + ", ".join(f"{k} = {values[k]}" for k in sorted(PLANNER_KEYS & values.keys()))
                + "): the next parcels are planned with them"
            )
        if "scan_line_x" in values:
            self.scan_line_x = float(values["scan_line_x"])
            self.traffic.scan_line_x = self.scan_line_x
        if "scan_line_tolerance" in values:
            self.scan_line_tolerance = float(values["scan_line_tolerance"])

    def __init__(self) -> None:
        super().__init__()
        try:
            self._setup()
        except ParameterError as exc:  # bad scene, stream or planner settings
            raise ParameterException(str(exc), "controller") from None

    def _setup(self) -> None:
        self._command_class = FenceCommand
        p = self.parameter_values()
        scene = p["scene"] or DEFAULT_SCENE
        self.base = load_scene(scene).scenario
        self.config = PlannerConfig.from_mapping(p)
        self.planner = Planner(self.base, self.config)
        self.frame_id = p["frame_id"]
        self.scan_line_x = float(p["scan_line_x"])
        self.scan_line_tolerance = float(p["scan_line_tolerance"])
        self.run_id = int(p["run_id"])
        self.parcel_intake = TopicIntake("parcels", self.run_id)
        self.registry = ParcelRegistry()
        self.stats = ControllerStats()
        self.rtf = RateEstimate()
        # sampled on the steady clock, so the estimate follows the sim clock between parcels
        self._rtf_timer = self.create_timer(
            0.25,
            lambda: self.rtf.update(time.monotonic(), self.get_clock().now().nanoseconds * 1e-9),
            clock=Clock(clock_type=ClockType.STEADY_TIME),
        )
        self.seen: set[int] = set()
        # the swept-sector guard's traffic; divert parcels wait for their decision time
        self.traffic = UnitTraffic.of_scenario(self.base, self.scan_line_x)
        self.pending: list[tuple[float, int, ParcelSpec]] = []
        self._warm_up(p)
        self._pub = self.create_publisher(
            FenceCommand, topics.FENCE_COMMANDS, topic_qos(topics.FENCE_COMMANDS)
        )
        self._due_timer = self.create_timer(
            0.01, self._plan_due, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )
        # Listen to /parcels only once a commands subscriber (the simulator) is matched: a
        # command published before discovery completes would be lost (volatile QoS).
        self._parcel_class = Parcel
        self._sub = None
        self._min_subscribers = int(p["wait_for_command_subscribers"])
        self._listen_timer = self.create_timer(
            0.02, self._listen_when_matched, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )
        self.get_logger().info(
            f"controller ready: scene {scene}, {len(self.planner.candidate_list)} candidates, "
            f"fence model {self.config.fence_model}, {len(self.planner.cache)} cached evaluations"
            + (
                f", decision table {self.config.decision_table} "
                f"({len(self.planner.table.entries)} classes)"
                if self.planner.table is not None
                else ""
            )
        )

    def _warm_up(self, p: dict) -> None:
        """Compile the kernel and fill the cache before subscribing (first plans are fast)."""
        wall0 = time.perf_counter()
        loads = [ParcelParams(length_a=0.4, width_b=0.3, mass=5.0)]
        if p["warmup_stream"] and p["warmup_parcels"] > 0:
            specs = load_stream(
                p["warmup_stream"],
                self.base.conveyor.belt_speed,
                count=int(p["warmup_parcels"]),
                seed=987654321,  # not the scanner's draw: classes, not the same parcels
                belt_width=self.base.conveyor.width,
            )
            loads += [s.to_parcel_params() for s in specs if s.divert]
        # the first evaluation loads (or, after a kernel change, compiles) the JIT kernel: not
        # counted in the warm-up's time budget
        self.planner.warm_up(loads[:1], math.inf)
        classes = self.planner.warm_up(loads, float(p["warmup_time"]))
        self.planner.evaluations = self.planner.cache_hits = 0
        self.get_logger().info(
            f"warm-up: {classes} load classes in {time.perf_counter() - wall0:.2f} s"
        )

    def _listen_when_matched(self) -> None:
        if self._sub is None:
            if self._pub.get_subscription_count() < self._min_subscribers:
                return
            self._sub = self.create_intake_subscription(
                self._parcel_class,
                topics.PARCELS,
                self.on_parcel,
                INPUT_QOS,
                self.parcel_intake,
                with_info=True,
            )
            self.get_logger().info("listening on /parcels")
        # the run starts its stream on this news: a heartbeat now, not in up to 1 s, once sim
        # time runs (one stamped 0 after later ones is out of order in a bag)
        if self.get_clock().now().nanoseconds > 0:
            self._listen_timer.cancel()
            self.publish_heartbeat()

    def on_parcel(self, msg, info=None) -> None:
        """Hand the parcel to :func:`handle_parcel`; publish what it returns. Its latency runs
        from the middleware's reception of the parcel (``info['received_timestamp']``, system
        clock), so time the message waited for the callback (a busy or stopped executor)
        counts too."""
        received, sent = message_times_ns(info)
        cmd = handle_parcel(self, msg)
        if cmd is not None:
            self._pub.publish(cmd)
            now = time.time_ns()
            self.stats.latency.append(1e-9 * (now - received))
            self.stats.latency_from_send.append(1e-9 * (now - sent))

    def _plan_due(self) -> None:
        """Plan the parcels whose decision time (:func:`decision_time`) has come; their
        latency runs from then."""
        if clock_behind(self):  # its time is not the run's yet: decide with the next tick
            return
        t_now = self.get_clock().now().nanoseconds * 1e-9
        self.traffic.prune(t_now)
        while self.pending and self.pending[0][0] <= t_now:
            due_wall = time.time_ns()
            due, _, spec = heapq.heappop(self.pending)
            self.stats.decision_lateness.append(t_now - due)
            cmd = plan_parcel(self, spec)
            if cmd is not None:
                self._pub.publish(cmd)
                self.stats.latency.append(1e-9 * (time.time_ns() - due_wall))

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        values = self.stats.values()
        values["cache_entries"] = str(len(self.planner.cache))
        values["pending_parcels"] = str(len(self.pending))
        values["listening"] = str(self._sub is not None).lower()
        # matched /parcels publishers: a parcel published before its scanner is matched with
        # this subscription is lost to it (volatile QoS), whatever "listening" says
        values["parcel_publishers"] = str(self._sub.get_publisher_count() if self._sub else 0)
        values["real_time_factor_seen"] = f"{self.rtf.value:.3f}"
        # the limits its strokes are planned for: what analyze judges a bag's outcomes by
        prof = self.planner.config.profile
        values["limits.w_dop"] = repr(prof.w_dop)
        values["limits.a_ndop"] = repr(prof.a_ndop)
        values["limits.ydot_dop"] = repr(prof.ydot_dop)
        values["limits.active"] = ",".join(str(c) for c in prof.active)
        values.update(self.parcel_intake.values())
        values.update(self.registry.values())
        status.values.extend(KeyValue(key=k, value=v) for k, v in values.items())
        return status


def message_times_ns(info) -> tuple[int, int]:
    """The middleware's reception time of a message and its publisher's send time [ns, system
    clock] from rclpy's message info (``received_timestamp``, ``source_timestamp``); now for
    either when it is missing (a direct call)."""
    now = time.time_ns()
    out = []
    for key in ("received_timestamp", "source_timestamp"):
        try:
            t = int(info[key])
        except (TypeError, KeyError, ValueError):
            t = 0
        out.append(t if t > 0 else now)
    return out[0], out[1]


def handle_parcel(node: ControllerNode, msg):
    """One parcel message -> a FenceCommand to publish, or None (not to divert, rejected, late)."""
    stats = node.stats
    stats.received += 1
    log = node.get_logger()
    now = node.get_clock().now()
    t_now = now.nanoseconds * 1e-9
    spec = parcel_from_msg(msg)
    seen = node.registry.register(spec)
    if seen != "new":  # refused, counted by the registry (duplicate or conflict)
        if seen == "conflict":
            log.error(
                f"parcel {spec.parcel_id}: a second authentic message with another spec; the "
                "first one stays, the parcel is disputed"
            )
        return None
    try:
        validate_parcel(
            spec,
            node.base.conveyor.width,
            node.seen,
            now=t_now,
            scan_line_x=node.scan_line_x,
            scan_line_tolerance=node.scan_line_tolerance,
        )
    except InputError as exc:
        stats.rejected += 1
        stats.rejected_by_key[exc.key] += 1
        log.warning(f"parcel {msg.parcel_id} rejected ({exc.key}): {exc}")
        return None
    node.seen.add(spec.parcel_id)
    node.traffic.scanned(spec)
    if not spec.divert:
        stats.not_diverted += 1
        return None
    due = decision_time(spec, node.planner.v, node.config)
    # planned then (``_plan_due``): the parcels behind it are scanned by then; also when the
    # node's time lags the run's (received just after a stop, before the clock's next tick)
    if t_now < due or clock_behind(node):
        heapq.heappush(node.pending, (due, spec.parcel_id, spec))
        return None
    stats.decision_lateness.append(t_now - due)
    return plan_parcel(node, spec)


def clock_behind(node) -> bool:
    """Whether the node's sim time lags the run's clock (a stop or a long callback kept it
    from the clock's messages): a plan from that time would start its stroke in the past."""
    pinned = getattr(node, "pinned_clock", None)
    return pinned is not None and pinned.behind(time.monotonic())


def plan_parcel(node: ControllerNode, spec: ParcelSpec):
    """A divert parcel at its decision time -> its FenceCommand, or None (too late). Each
    feasible stroke must pass the swept-sector guard (``node.traffic``); the planner passes
    one it refuses over for its next feasible one."""
    stats = node.stats
    log = node.get_logger()
    now = node.get_clock().now()
    t_now = now.nanoseconds * 1e-9
    req = request_from_spec(spec)
    rtf = node.rtf.update(time.monotonic(), t_now)
    evals0 = node.planner.evaluations
    # the stroke must start after the command is out: DELIVERY_ALLOWANCE of wall time (times
    # the real-time factor in sim time) for the message; the planning time itself is checked
    # after planning: a plan that took too long for its own stroke is made again from the
    # new time (its evaluations are cached, so that is quick)
    # the planner evaluates until its stroke is verified or the command's deadline comes (the
    # front at the last R_s less start_margin, at the real-time factor seen)
    t_plan = t_now + rtf * DELIVERY_ALLOWANCE
    deadline = node.planner.deadline(req, t_plan, rtf, time.perf_counter())
    plan = node.traffic.plan(node.planner, req, t_plan, deadline=deadline)
    if plan.feasible:
        t_after = node.get_clock().now().nanoseconds * 1e-9
        earliest = t_after + rtf * DELIVERY_ALLOWANCE + node.config.start_margin
        if plan.start_time < earliest:
            stats.replans += 1
            t_plan = t_after + rtf * DELIVERY_ALLOWANCE
            plan = node.traffic.plan(node.planner, req, t_plan, deadline=deadline)
    if plan.feasible:
        node.planner.busy_until = plan.end_time
        node.traffic.book(req.parcel_id, plan.start_time, plan.end_time, node.config.alpha_k)
    stats.evaluations += node.planner.evaluations - evals0
    if not plan.feasible and plan.reason.startswith("too late"):
        stats.late += 1
        log.warning(f"parcel {req.parcel_id}: no command: {plan.reason}")
        return None
    cmd = node._command_class()
    cmd.header.stamp = now.to_msg()
    cmd.header.frame_id = node.frame_id
    fill_command(cmd, plan, node.config.alpha_k)
    cmd.run_id = node.run_id
    sign(cmd, node.run_key)
    stats.commands += 1
    if plan.feasible:
        stats.lead.append(plan.start_time - now.nanoseconds * 1e-9)
        ev = plan.evaluation
        log.info(
            f"parcel {req.parcel_id}: R_s {ev.r_s:g} m, t1 {ev.t1:g} s, W_t "
            f"{ev.capacity_pcs_h:.0f} pcs/h, start t = {plan.start_time:.3f} s "
            f"({plan.evaluations} evaluations, {plan.cache_hits} cached, "
            f"{1e3 * plan.wall_time:.1f} ms)"
        )
    else:
        stats.infeasible += 1
        stats.declined[decline_reason(plan)] += 1
        log.warning(f"parcel {req.parcel_id}: infeasible: {plan.reason}")
    return cmd


def main(args: Sequence[str] | None = None) -> int:
    """Run the controller node until Ctrl-C or SIGTERM."""
    return run_node(ControllerNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
