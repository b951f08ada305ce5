"""Simulator node: the sorting line (:class:`fence_sorter.line.SortingLine`) in soft real time.

Two processes: the pacing loop runs in a process of its own with no ROS and no other thread
(:mod:`fence_sorter.line.worker`): every cycle (period 1 / physics_rate on the steady clock) it
sleeps until ``spin_margin`` before its deadline, busy-waits to it, takes the parcels and
commands this node forwarded, advances sim time by period x real_time_factor and sends
outcomes at once and snapshots every publish period over a pipe. This node's process (rclpy's
executor in the main thread, one publisher thread) forwards the subscriptions to the loop and
publishes what it sends: /clock, states, markers, outcomes, diagnostics. Python threads share
one interpreter lock, so publishing in the loop's own process took the lock from the loop for
milliseconds at a time (docs/design/simulator.md). ``real_time_factor`` 0 runs unpaced (each cycle
advances one publish period as fast as the publisher keeps up). A cycle that wakes late
advances the sim by the missed periods in one go, up to ``max_catch_up`` of sim time; beyond
that sim time slips (counted). Lateness (wake - deadline) of every paced cycle feeds the
percentiles on /diagnostics. See docs/design/simulator.md.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.logging import LoggingSeverity
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from fence_sorter.affinity import keep_on
from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.line import (
    EventTrace,
    LatenessHistogram,
    LineConfig,
    Outcome,
    OutcomeCode,
    OverlapWarning,
    SolverWarning,
    SortingLine,
    StrokeStarted,
)
from fence_sorter.line.awake import start_spinners, stop_spinners
from fence_sorter.line.worker import Gauges, LineProcess, LoopSettings, LoopStartError, LoopStats
from fence_sorter.nodes import convert
from fence_sorter.nodes.base import FenceSorterNode, spin_node
from fence_sorter.nodes.intake import ParcelRegistry, TopicIntake
from fence_sorter.nodes.parameters import SIMULATOR_PARAMETERS
from fence_sorter.nodes.qos import CLOCK_QOS, INPUT_QOS, topic_qos
from fence_sorter.nodes.sources import SourceWatch, sign, sign_clock
from fence_sorter.nodes.tf_publisher import TfPublisher
from fence_sorter.recording import topics
from fence_sorter.scene import DEFAULT_SCENE, load_scene
from fence_sorter.stamps import time_to_sec
from fence_sorter.visualisation.frames import SceneGeometry, unit_chute
from fence_sorter.visualisation.rerun_live import RerunProcess
from fence_sorter_msgs.msg import (
    FenceCommand,
    FenceState,
    LoadState,
    Parcel,
    RunClock,
    SortEvent,
    SortOutcome,
)

#: unpaced, the loop waits for this node to publish up to this much sim time behind it [s]
UNPACED_PUBLISH_LEAD = 0.1
#: the node process's GIL switch interval while running [s] (see start())
SWITCH_INTERVAL = 2e-4
#: (topic, the node that owns it): any other publisher of these is named (wall period [s])
WATCHED_SOURCES = (
    (topics.CLOCK, "simulator"),
    (topics.RUN_CLOCK, "simulator"),
    (topics.PARCELS, "scanner"),
    (topics.FENCE_COMMANDS, "controller"),
    (topics.SORT_OUTCOMES, "simulator"),
)
GRAPH_PERIOD = 0.2
#: after a publisher of /parcels or /fence_commands is matched, the graph is looked at this
#: often [s] for GRAPH_BURST [s]: an insider that publishes a few messages and leaves within
#: a GRAPH_PERIOD is still named
GRAPH_FAST_PERIOD = 0.02
GRAPH_BURST = 1.0


class SimulatorNode(FenceSorterNode):
    """Digital twin of the sorter: belt, rotary fence and parcels, paced by wall time."""

    NODE_NAME = "simulator"
    STATUS = "running"
    PARAMETERS = SIMULATOR_PARAMETERS

    def __init__(self, loop: LineProcess | None = None, **kwargs: object) -> None:
        """``loop``: the loop's process, started and waiting for its set-up, which it gets
        here (else :meth:`start` starts one)."""
        super().__init__(**kwargs)
        p = self.parameter_values()
        self.frame_id = str(p["frame_id"])
        self.limits = ConstraintProfile(w_dop=float(p["w_dop"]), a_ndop=float(p["a_ndop"]))
        self._risks: dict[int, dict] = {}  # damage risk of an outcome until its EventTrace
        loaded = load_scene(p["scene"] or DEFAULT_SCENE)  # SceneError: exit 2 in main()
        self.scene_name = loaded.name
        self.line_config = LineConfig.from_scenario(
            loaded.scenario,
            r_s_range=(float(p["r_s_min"]), float(p["r_s_max"])),
            line_end_x=float(p["line_end_x"]),
            scan_line_x=float(p["scan_line_x"]),
            scan_line_tolerance=float(p["scan_line_tolerance"]),
        )
        # ValueError: exit 2 in main(). The loop's own line is in its process; this copy
        # renders the loop's captures into snapshots (it has the same fence geometry)
        line = SortingLine(self.line_config)
        self._render = line.render
        self._warm_scenario = loaded.scenario if p["warm_up"] else None
        self.rtf = float(p["real_time_factor"])
        self.period = 1.0 / float(p["physics_rate"])
        rate = float(p["marker_rate"])
        self.settings = LoopSettings(
            period=self.period,
            rtf=self.rtf,
            max_catch_up=float(p["max_catch_up"]),
            spin_margin=float(p["spin_margin"]),
            lookahead=float(p["lookahead"]),
            prefetch_reserve=float(p["prefetch_reserve"]),
            publish_every=max(1, round(float(p["physics_rate"]) / float(p["publish_rate"]))),
            marker_every=max(1, round(float(p["physics_rate"]) / rate)) if rate > 0.0 else 0,
            rt_priority=int(p["realtime_priority"]),
            loop_cpu=int(p["loop_cpu"]),
            command_wait=float(p["command_wait"]),
            publish_lead=UNPACED_PUBLISH_LEAD,
            debug=self.get_logger().is_enabled_for(LoggingSeverity.DEBUG),
            trace_path=str(p["cycle_trace"]),
            warm_up=bool(p["warm_up"]),
        )
        self.keep_cpus_awake = bool(p["keep_cpus_awake"])
        self._spinners: list = []
        self.scan_lead = float(p["scan_lead"])
        self._scan_limit = -math.inf  # the scanner's progress + scan_lead (sim s)
        self._t0 = line.t
        self.loop: LineProcess | None = None
        if loop is not None:  # it builds and warms its line while this node sets up
            self._configure_loop(loop)

        run_id = int(p["run_id"])
        self.parcel_intake = TopicIntake("parcels", run_id)
        self.command_intake = TopicIntake("commands", run_id)
        self.parcel_registry = ParcelRegistry()
        self.run_id = run_id
        # publishers of the run's topics that are not the run's own nodes, from the graph
        self.sources = SourceWatch(WATCHED_SOURCES)
        self._graph_next = self._graph_burst_end = 0.0
        self._parcel_sub = self.create_intake_subscription(
            Parcel,
            topics.PARCELS,
            self._on_parcel,
            INPUT_QOS,
            self.parcel_intake,
            on_matched=self._on_publisher_matched,
        )
        self._command_sub = self.create_intake_subscription(
            FenceCommand,
            topics.FENCE_COMMANDS,
            self._on_command,
            INPUT_QOS,
            self.command_intake,
            on_matched=self._on_publisher_matched,
        )
        self._progress_sub = self.create_subscription(
            Clock, topics.SCAN_PROGRESS, self._on_scan_progress, topic_qos(topics.SCAN_PROGRESS)
        )

        def publisher(msg_type, name):
            return self.create_publisher(msg_type, name, topic_qos(name))

        self.pub_clock = publisher(Clock, topics.CLOCK)
        # the run's clock under its key, for the nodes of the run (fence_sorter.provenance)
        self.pub_run_clock = (
            self.create_publisher(RunClock, topics.RUN_CLOCK, CLOCK_QOS)
            if self.run_key is not None
            else None
        )
        self._run_clock_msg = RunClock(run_id=run_id)
        self._graph_timer = self.create_timer(
            GRAPH_FAST_PERIOD,
            self._watch_sources,
            clock=RosClock(clock_type=ClockType.STEADY_TIME),
        )
        self.pub_fence = publisher(FenceState, topics.FENCE_STATE)
        self.pub_joint = publisher(JointState, topics.JOINT_STATES)
        self.pub_loads = publisher(LoadState, topics.LOAD_STATES)
        self.pub_markers = publisher(MarkerArray, topics.MARKERS)
        self.pub_outcomes = publisher(SortOutcome, topics.SORT_OUTCOMES)
        self.pub_events = publisher(SortEvent, topics.SORT_EVENTS)
        self.tf = TfPublisher(self, self.line_config, self.frame_id)  # /tf, /tf_static, URDF
        self.tf.publish_static(line.t)

        belt_x = (min(-3.0, self.line_config.r_s_range[0]), self.line_config.line_end_x)
        self._markers = convert.MarkerBuilder(
            self.line_config.conveyor.width, belt_x, self.frame_id
        )
        self.rerun = _start_rerun(p, self.line_config.conveyor.width, belt_x, self.rtf)
        self._clock_msg, self._fence_msg = Clock(), FenceState()
        self._joint_msg, self._load_msg = JointState(), LoadState()

        # what the loop's process reports (reader thread) and what this process counts
        # (reader and executor threads), read by the heartbeat under the lock
        self._lock = threading.Lock()
        self.stats = LoopStats()
        self.publish_lag = LatenessHistogram()  # snapshot due -> its messages published [s]
        self.counts: Counter[str] = Counter()
        self.outcome_counts: Counter[str] = Counter()
        self._gauges_left: Gauges | None = None  # the stopped loop's, for a last heartbeat
        self.loop_error: str | None = None
        self._rtf_window = (time.perf_counter(), line.t)
        self._stopping = False
        self._saved_switch: float | None = None
        self._clock_published = line.t  # sim time of the last /clock message
        self._clock_sent = -math.inf  # the same, -inf before the first
        self._reader = threading.Thread(
            target=self._receive_loop, name="simulator-publisher", daemon=True
        )
        log = self.get_logger()
        for warning in loaded.warnings:
            log.warning(f"scene {loaded.name}: {warning}")
        cfg = self.line_config
        fence = "flexible" if cfg.fence is not None else "stiff"
        log.info(
            f"line: scene {loaded.name} ({fence} fence R_z = {cfg.length:g} m, belt "
            f"{cfg.conveyor.belt_speed:g} m/s, s = {cfg.conveyor.width:g} m); rtf {self.rtf:g}, "
            f"{p['physics_rate']:g} Hz loop, {p['publish_rate']:g} Hz publication"
        )

    @property
    def sim_time(self) -> float:
        """The line's sim time [s], as the loop's process last wrote it."""
        g = self._gauges()
        return g.value(Gauges.SIM_TIME) if g is not None else self._t0

    def _gauges(self) -> Gauges | None:
        """The running loop's gauges, the stopped loop's after stop(), None before start()."""
        loop = self.loop
        return loop.gauges if loop is not None else self._gauges_left

    # -- callbacks: hand off only --------------------------------------------------------------
    def _on_parcel(self, msg: Parcel) -> None:
        spec = convert.parcel_from_msg(msg)
        seen = self.parcel_registry.register(spec)
        if seen == "new":
            self._send(("parcel", spec))
        elif seen == "conflict":
            self.get_logger().error(
                f"parcel {spec.parcel_id}: a second authentic message with another spec; "
                "the first one stays, the parcel is disputed"
            )

    def _watch_sources(self) -> None:
        """Name every publisher of a watched topic that is not its owner (a second /clock,
        an insider on /parcels or /fence_commands), for the heartbeat: every GRAPH_PERIOD,
        every GRAPH_FAST_PERIOD within GRAPH_BURST of a match."""
        now = time.monotonic()
        if now < self._graph_next:
            return
        fast = now < self._graph_burst_end
        self._graph_next = now + (GRAPH_FAST_PERIOD if fast else GRAPH_PERIOD) * 0.9
        for topic, names in self.sources.poll(self, now).items():
            self.get_logger().error(f"{topic}: a publisher that is not the run's: {names}")

    def _on_publisher_matched(self, status) -> None:
        """A publisher of /parcels or /fence_commands came (or left): look at the graph now,
        and often for a while, while a short-lived one is still in it."""
        if status.current_count_change > 0:
            self._graph_burst_end = time.monotonic() + GRAPH_BURST
            self._graph_next = 0.0
            self._watch_sources()

    def _on_command(self, msg: FenceCommand) -> None:
        self._send(("command", convert.command_from_msg(msg)))

    def _send(self, item: tuple) -> None:
        loop = self.loop
        if loop is None or not loop.send(item):
            with self._lock:
                self.counts[f"{item[0]}s_dropped_loop_down"] += 1

    # -- lifecycle -----------------------------------------------------------------------------
    def start(self, ready_timeout: float = 120.0) -> None:
        """Start the loop's process (it warms the kernel up first) and the publisher thread.
        Raises LoopStartError if the loop does not come up."""
        # the publisher thread is busy all the time when unpaced; rclpy's executor takes and
        # drops the interpreter lock many times per callback and would wait up to the switch
        # interval (5 ms by default) each time: /parcels and /fence_commands would reach the
        # loop seconds late in sim time
        self._saved_switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL)
        if self.loop is None:
            self._configure_loop(LineProcess())
        # convert.event_to_msg's N_stiff courses, imported while the loop's process warms up
        # (not in the publisher thread: its first /clock messages would leave in a burst)
        from fence_sorter.physics import contact  # noqa: F401  # lazy: scipy.integrate, ~0.3 s

        self.loop.wait_ready(ready_timeout)
        # the loop runs from here: what it sends is published at once, not after the rest
        self._reader.start()
        # the spinners once the loop is up: interpreters whose start-up is not idle
        if self.keep_cpus_awake and self.rtf > 0.0:
            cpus = set(os.sched_getaffinity(0))  # and the loop's, if pinned outside them
            cpus |= {self.settings.loop_cpu} if self.settings.loop_cpu >= 0 else set()
            self._spinners = start_spinners(cpus)
            self.get_logger().info(
                f"keep_cpus_awake: {len(self._spinners)} SCHED_IDLE spinner processes"
            )
        self._set_priority()  # the publisher thread's too
        if self._held():
            self.get_logger().info(
                f"unpaced: sim time keeps within scan_lead {self.scan_lead:g} s of the "
                "scanner's /scan_progress (scan_lead:=0 turns it off)"
            )

    def _held(self) -> bool:
        """Unpaced, with scan_lead: the loop is held at the start until the scanner's first
        report."""
        return self.scan_lead > 0.0 and self.rtf == 0.0

    def _configure_loop(self, loop: LineProcess) -> None:
        """Send the loop's process its set-up; it is this node's loop from now on."""
        self.loop = loop
        limit = self._t0 if self._held() else math.inf
        loop.configure(self.line_config, self._warm_scenario, self.settings, scan_limit=limit)

    def _on_scan_progress(self, msg: Clock) -> None:
        """The scanner has scanned up to this sim time: an unpaced loop may run scan_lead past
        it (Gauges.SCAN_LIMIT; a paced loop does not look)."""
        loop = self.loop
        if loop is not None and self.scan_lead > 0.0:
            t = time_to_sec(msg.clock)
            self._scan_limit = max(self._scan_limit, t + self.scan_lead)
            loop.gauges.header[Gauges.SCAN_LIMIT] = self._scan_limit

    def stop(self) -> None:
        """Stop the loop's process (its last outcomes and statistics are published first),
        then the publisher thread, the spinners and the Rerun child."""
        self._stopping = True
        loop, self.loop = self.loop, None
        if loop is not None:
            self._gauges_left = loop.gauges
            loop.stop()
            if self._reader.is_alive():
                self._reader.join(timeout=5.0)
            loop.close()
        spinners, self._spinners = self._spinners, []
        stop_spinners(spinners)
        if self._saved_switch is not None:
            sys.setswitchinterval(self._saved_switch)
            self._saved_switch = None
        if self.rerun is not None:  # the child logs what it holds, then the file is closed
            rerun, self.rerun = self.rerun, None
            rerun.close()

    def _set_priority(self) -> None:
        """In paced runs, this process's threads (rclpy executor, publisher, DDS) at SCHED_FIFO
        one level below the loop's process, as ros2_control does for the threads around its
        update loop: outcomes and /clock then leave on time on a loaded machine. Normal
        scheduling where the process may not (no CAP_SYS_NICE or rtprio limit). With
        ``loop_cpu`` set, the threads keep off the loop's CPU."""
        cpu = self.settings.loop_cpu
        others = os.sched_getaffinity(0) - {cpu}
        if cpu >= 0 and others:
            keep_on(os.getpid(), others)
            if self.rerun is not None:  # started before, with this process's CPUs
                keep_on(self.rerun.proc.pid, others)
            self.get_logger().info(f"node threads: kept off CPU {cpu} (the loop's)")
        prio = self.settings.rt_priority - 1
        if prio < 1 or self.rtf <= 0.0:
            return
        done = 0
        for tid in os.listdir("/proc/self/task"):
            try:
                os.sched_setscheduler(int(tid), os.SCHED_FIFO, os.sched_param(prio))
                done += 1
            except OSError:  # a thread that just ended, or not permitted: leave it
                pass
        self.get_logger().info(f"node threads: {done} at SCHED_FIFO priority {prio}")

    # -- the publisher thread --------------------------------------------------------------------
    def _receive_loop(self) -> None:
        """Publish what the loop's process sends, in order, until it ends: state messages of a
        snapshot (/clock first), marker frames, events (outcomes, warnings) and log lines;
        keep its statistics for the heartbeat. The loop's process ending on its own (not
        asked to by stop()) ends this node with status 1."""
        clock = time.perf_counter
        loop = self.loop
        snap = None
        try:
            for item in loop.frames():
                kind = item[0]
                if kind == "states":
                    _, cap, due = item
                    snap = self._render(cap)
                    self._publish_states(snap)
                    if due is not None:
                        with self._lock:
                            self.publish_lag.add(clock() - due)
                elif kind == "markers":  # no capture: the states snapshot just before
                    mark = self._render(item[1]) if item[1] is not None else snap
                    self.pub_markers.publish(self._markers.build(mark))
                elif kind == "events":
                    self._handle(item[1])
                elif kind == "log":
                    self._write_log(item[1], item[2])
                elif kind == "stats":
                    with self._lock:
                        self.stats = item[1]
                elif kind == "error":
                    self._fail(f"pacing loop failed: {item[1].strip().splitlines()[-1]}")
                    self.get_logger().error(item[1])
            if not self._stopping and self.loop_error is None:
                self._fail(f"pacing loop process ended (exit status {loop.proc.wait()})")
        except Exception as exc:  # report, then end the process through the executor
            if "context is invalid" in str(exc) or not self.context.ok():
                return  # Ctrl-C/SIGTERM shut the context down under a publish: a clean stop
            self._fail(f"publisher: {type(exc).__name__}: {exc}")

    def _fail(self, text: str) -> None:
        self.loop_error = text
        self.get_logger().fatal(text)
        self.context.try_shutdown()

    def _publish_clock(self, t: float) -> None:
        """/clock at ``t`` unless it went out already (an outcome at a snapshot's time)."""
        if t > self._clock_sent:
            self.pub_clock.publish(convert.fill_clock(self._clock_msg, t))
            if self.pub_run_clock is not None:
                msg = self._run_clock_msg
                msg.clock = self._clock_msg.clock
                self.pub_run_clock.publish(sign_clock(msg, self.run_key))
            self._clock_published = self._clock_sent = t

    def _publish_states(self, snap) -> None:
        """/clock first, then the fence, the drive joint and each parcel; one message object
        per topic, filled in place (publish() serialises it at once)."""
        self._publish_clock(snap.t)
        loop = self.loop
        if loop is not None:  # the unpaced loop waits for this (LoopSettings.publish_lead)
            loop.gauges.header[Gauges.PUBLISHED] = snap.t
        self.pub_fence.publish(
            convert.fill_fence_state(self._fence_msg, snap.fence, snap.t, self.frame_id)
        )
        self.pub_joint.publish(convert.fill_joint_state(self._joint_msg, snap.fence, snap.t))
        for parcel in snap.parcels:
            self.pub_loads.publish(
                convert.fill_load_state(self._load_msg, parcel, snap.t, self.frame_id)
            )
        self.tf.publish(snap)
        if self.rerun is not None:
            self.rerun.offer(snap)  # packed, piped to the Rerun child

    def _handle(self, events: list) -> None:
        """Publish and log the line's events."""
        log = self.get_logger()
        for e in events:
            if isinstance(e, Outcome):
                # the loop has reached e.t (its events come from line.advance): /clock goes to
                # e.t first, so a sim-time subscriber (the recorder) receives the outcome at
                # its stamp, not up to a publish period before it
                self._publish_clock(e.t)
                out = convert.outcome_to_msg(e, self.frame_id, self.limits)
                out.disputed = e.parcel_id in self.parcel_registry.disputed
                out.run_id = self.run_id
                self.pub_outcomes.publish(sign(out, self.run_key))
                if self.rerun is not None and math.isfinite(e.peak_normal_force):
                    # its EventTrace follows in the same list: the damage colours of the view
                    from fence_sorter.analysis.events import risk_of  # lazy: see _start_rerun

                    self._risks[e.parcel_id] = risk_of(
                        {
                            "impact_normal_speed": e.impact_normal_speed,
                            "peak_normal_accel": e.peak_normal_accel,
                            "w_dop": self.limits.w_dop,
                            "a_ndop": self.limits.a_ndop,
                        }
                    )
                with self._lock:
                    self.outcome_counts[e.code.name] += 1
                text = f"parcel {e.parcel_id}: {e.code.name} at t = {e.t:.3f} s: {e.reason}"
                if self.rerun is not None:
                    ok = e.code in (OutcomeCode.SORTED, OutcomeCode.NOT_DIVERTED)
                    self.rerun.event(e.t, text, ok)
                # the routine outcomes at DEBUG (they are on /sort_outcomes)
                if e.code in (OutcomeCode.SORTED, OutcomeCode.NOT_DIVERTED):
                    log.debug(text)
                else:
                    log.warning(text)
            elif isinstance(e, OverlapWarning):
                with self._lock:
                    self.counts["overlap_warnings"] += 1
                log.warning(
                    f"parcel {e.other_parcel_id} is in the fence's swept area during the stroke "
                    f"for parcel {e.stroke_parcel_id} at t = {e.t:.3f} s (parcel-parcel contact "
                    "is not modelled)"
                )
            elif isinstance(e, SolverWarning):
                with self._lock:
                    self.counts["solver_failures_after_outcome"] += 1
                log.error(f"stroke for parcel {e.parcel_id}: solver failure: {e.diagnosis}")
            elif isinstance(e, EventTrace):
                msg = convert.event_to_msg(e, self.frame_id)
                self.pub_events.publish(msg)
                with self._lock:
                    self.counts["sort_events"] += 1
                if self.rerun is not None:  # the same curves as a bag's (fence-sorter rrd)
                    from fence_sorter.analysis.events import SortEventData  # lazy: _start_rerun

                    risk = self._risks.pop(e.parcel_id, None)
                    self.rerun.sort_event(SortEventData.from_msg(msg), risk)
            elif isinstance(e, StrokeStarted):
                with self._lock:
                    self.counts["strokes"] += 1

    def _write_log(self, level: str, text: str) -> None:
        log = self.get_logger()  # one call site per severity (rclpy requires it)
        if level == "debug":
            log.debug(text)
        elif level == "info":
            log.info(text)
        elif level == "warning":
            log.warning(text)
        else:
            log.error(text)

    # -- diagnostics -----------------------------------------------------------------------------
    def heartbeat_stamp(self):
        """The last /clock this node published (sim time), as the /diagnostics of the nodes
        that follow that clock are stamped: one time base on the topic, and no stamp ahead of
        what a sim-time recorder has seen (bag tools order the topic by this stamp)."""
        return convert.fill_clock(Clock(), self._clock_published).clock

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        now = time.perf_counter()
        with self._lock:
            st, lag = self.stats, self.publish_lag.copy()
            counts = Counter(st.counts) + self.counts
            outcomes = dict(self.outcome_counts)
        g = self._gauges()
        if g is not None:  # the loop's running figures, read from the shared memory
            hist, work = g.histogram(0), g.histogram(1)
            cycles, misses = int(g.value(Gauges.CYCLES)), int(g.value(Gauges.MISSES))
            slips, on_line = int(g.value(Gauges.SLIPS)), int(g.value(Gauges.ON_LINE))
        else:  # before start()
            hist, work = LatenessHistogram(), LatenessHistogram()
            cycles = misses = slips = on_line = 0
        bad, rejected = st.bad_parcels, st.rejected_commands
        qs = (50.0, 99.0, 99.9)
        p50, p99, p999 = (1e3 * v for v in hist.percentiles(qs))
        w50, w99, w999 = (1e3 * v for v in work.percentiles(qs))
        g50, g99, g999 = (1e3 * v for v in lag.percentiles(qs))
        lat_max, w_max = 1e3 * hist.max, 1e3 * work.max
        g_max = 1e3 * lag.max if lag.n else math.nan
        w0, s0 = self._rtf_window
        sim_t = self.sim_time
        self._rtf_window = (now, sim_t)
        rtf = (sim_t - s0) / (now - w0) if now > w0 else math.nan
        values = {
            "scene": self.scene_name,
            "sim_time_s": f"{sim_t:.3f}",
            "real_time_factor_target": f"{self.rtf:g}",
            "real_time_factor_achieved": f"{rtf:.3f}",
            # unpaced: how far the scanner's progress lets the line run (-inf: no report yet)
            "scan_limit_s": f"{self._scan_limit:.3f}",
            "cycles": str(cycles),
            "deadline_misses": str(misses),
            "catch_up_slips": str(slips),
            "cycle_lateness_p50_ms": f"{p50:.4f}",
            "cycle_lateness_p99_ms": f"{p99:.4f}",
            "cycle_lateness_p99_9_ms": f"{p999:.4f}",
            "cycle_lateness_max_ms": f"{lat_max:.4f}",
            "cycle_work_p50_ms": f"{w50:.4f}",
            "cycle_work_p99_ms": f"{w99:.4f}",
            "cycle_work_p99_9_ms": f"{w999:.4f}",
            "cycle_work_max_ms": f"{w_max:.4f}",
            # snapshot due (its cycle's wake) -> its state messages published, paced only
            "publish_lag_p50_ms": f"{g50:.4f}",
            "publish_lag_p99_ms": f"{g99:.4f}",
            "publish_lag_p99_9_ms": f"{g999:.4f}",
            "publish_lag_max_ms": f"{g_max:.4f}",
            "parcels_on_line": str(on_line),
            "bad_parcels": str(sum(bad.values())),
            "commands_rejected": str(sum(rejected.values())),
            "overlap_warnings": str(counts.get("overlap_warnings", 0)),
            # the same count under the line's name: parcels in a stroke's swept sector
            "swept_sector_intrusions": str(counts.get("overlap_warnings", 0)),
            # publishers this node's subscriptions are matched with (its side of discovery:
            # a command sent before the simulator matched its publisher is lost)
            "parcel_publishers": str(self._parcel_sub.get_publisher_count()),
            "command_publishers": str(self._command_sub.get_publisher_count()),
        }
        values.update(self.parcel_intake.values())
        values.update(self.command_intake.values())
        values.update(self.parcel_registry.values())
        values.update(self.sources.values())
        if self.rerun is not None:
            values["rerun_frames_sent"] = str(self.rerun.sent)
            values["rerun_frames_dropped"] = str(self.rerun.dropped)
        values.update({k: str(v) for k, v in sorted(counts.items()) if k != "overlap_warnings"})
        values.update({f"bad_parcels.{k}": str(v) for k, v in sorted(bad.items())})
        values.update({f"commands_rejected.{k}": str(v) for k, v in sorted(rejected.items())})
        values.update({f"outcomes.{k}": str(v) for k, v in sorted(outcomes.items())})
        status.values.extend(KeyValue(key=k, value=v) for k, v in values.items())
        if self.loop_error:
            status.level = DiagnosticStatus.ERROR
            status.message = self.loop_error
        elif cycles and misses > 0.001 * cycles:
            status.level = DiagnosticStatus.WARN
            status.message = f"running; deadline misses {misses} of {cycles} cycles"
        return status

    def validate_parameters(self, parameters: Sequence[Parameter]) -> str | None:
        values = {p.name: p.value for p in parameters}
        lo = values.get("r_s_min")
        hi = values.get("r_s_max")
        end = values.get("line_end_x")
        if lo is not None and hi is not None and not lo < hi:
            return f"r_s_min ({lo}) must be below r_s_max ({hi})"
        if hi is not None and end is not None and not end > hi:
            return f"line_end_x ({end}) must exceed r_s_max ({hi})"
        if "real_time_factor" in values and hasattr(self, "loop"):
            self.rtf = float(values["real_time_factor"])
            if self.loop is not None:  # the loop restarts its grid
                self.loop.send(("rtf", self.rtf))
        return None


def _start_rerun(p: dict, belt_width: float, belt_x: tuple[float, float], rtf: float):
    """The Rerun child process when rrd_path or rrd_url is set (fence_sorter.visualisation):
    the loop hands it each published snapshot without blocking; unpaced runs wait for it."""
    path, url = str(p["rrd_path"]), str(p["rrd_url"])
    if not path and not url:
        return None
    # what a Rerun view needs, here rather than at an event in the publisher thread
    from fence_sorter.analysis import events  # noqa: F401  # lazy: fence_sorter.analysis pulls rosbags

    scene = SceneGeometry(belt_width, belt_x, unit_chute(belt_width), float(p["rrd_scan_line_x"]))
    return RerunProcess(scene, path or None, url or None, lossless=rtf == 0.0)


class OrderlyStop:
    """SIGINT/SIGTERM handler of the simulator: the first signal stops the pacing loop, lets
    the publisher thread publish what the loop still sends (its last outcomes and complete
    snapshots: no /clock whose states never went out) and then shuts rclpy down, in a thread
    of its own; a second signal raises KeyboardInterrupt at once. rclpy's own handlers would
    shut the context down under a snapshot half published."""

    def __init__(self) -> None:
        self.node: SimulatorNode | None = None
        self.signals = 0
        self._thread: threading.Thread | None = None

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum, frame) -> None:
        self.signals += 1
        if self.signals > 1:
            raise KeyboardInterrupt
        self._thread = threading.Thread(target=self.stop, name="simulator-stop", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        node = self.node
        if node is not None:
            node.stop()
        rclpy.try_shutdown()


def main(args: Sequence[str] | None = None) -> int:
    """Run the simulator until Ctrl-C or SIGTERM (:class:`OrderlyStop`); exit 2 with one line
    on a bad scene or parameter, 1 if the pacing loop failed."""
    # the loop's process first, while this process has no other thread: a copy of it with the
    # line's modules imported, which builds and warms its line while this one starts rclpy
    loop = LineProcess(fork=True)
    stopper = OrderlyStop()
    stopper.install()
    rclpy.init(
        args=list(args) if args is not None else None,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    node: SimulatorNode | None = None
    code = 0
    try:
        if stopper.signals:  # a signal before the context existed
            return 0
        node = SimulatorNode(loop)
        stopper.node = node
        node.start()
        if stopper.signals:  # a signal during start-up: the stop thread may have missed it
            stopper.stop()
        spin_node(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterException as exc:
        print(f"simulator: invalid parameter: {exc}", file=sys.stderr)
        code = 2
    except ValueError as exc:  # SceneError, a line setting out of range
        print(f"simulator: {exc}", file=sys.stderr)
        code = 2
    except LoopStartError as exc:
        if not stopper.signals:  # else: stopped by the signal during start-up
            print(f"simulator: pacing loop did not start: {exc}", file=sys.stderr)
            code = 1
    except Exception as exc:  # RCLError: a signal shut the context down during start-up
        if rclpy.ok():
            raise
        del exc
    finally:
        if node is not None:
            node.stop()
            if node.loop_error:
                code = 1
            node.destroy_node()
        loop.close()  # not yet the node's: its pipe closes, it ends
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    raise SystemExit(main())
