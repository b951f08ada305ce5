"""Simulator node: the sorting line (:class:`fence_sorter.line.SortingLine`) in soft real time.

Threads: rclpy's executor spins in the main thread; its callbacks only put messages into
thread-safe queues. A dedicated pacing loop thread owns the line: every cycle (period
1 / physics_rate on the steady clock, ``time.perf_counter``) it sleeps until ``spin_margin``
before its deadline, busy-waits to it, hands the queued parcels and commands to the line,
advances sim time by period x real_time_factor and publishes outcomes at once and /clock and
states every publish period. ``real_time_factor`` 0 runs unpaced (no sleep: each cycle advances
one period of sim time as fast as it can). A cycle that wakes late advances the sim by the
missed periods in one go, up to ``max_catch_up`` of sim time; beyond that sim time slips
(counted). Lateness (wake - deadline) of every paced cycle feeds the percentiles on
/diagnostics. See docs/simulator.md.
"""

from __future__ import annotations

import gc
import math
import os
import queue
import signal
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.logging import LoggingSeverity
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from fence_sorter.line import (
    InputError,
    LineConfig,
    Outcome,
    OutcomeCode,
    OverlapWarning,
    ParcelSpec,
    SolverWarning,
    SortingLine,
    StrokeCommand,
    StrokeStarted,
)
from fence_sorter.line.awake import start_spinners, stop_spinners
from fence_sorter.line.pacing import CycleTrace, LatenessHistogram, Pacer
from fence_sorter.nodes import convert
from fence_sorter.nodes.base import FenceSorterNode, ParamSpec, spin_node
from fence_sorter.nodes.qos import RELIABLE_QOS, SENSOR_QOS
from fence_sorter.scene import load_scene
from fence_sorter_msgs.msg import FenceCommand, FenceState, LoadState, Parcel, SortOutcome

DEFAULT_SCENE = "impact_flexible"
#: sim time a command for a not-yet-known parcel waits for its parcel message [s]
COMMAND_HOLD = 0.5
#: the loop collects garbage only with this much time left before the next deadline [s]
GC_SLACK = 0.0006
#: cycles' worth of wall time between full collections [s]
FULL_GC_PERIOD = 10.0
#: publications (snapshots, marker frames, event batches, log lines) the pacing loop may be
#: ahead of the publisher thread before it waits for it
PUBLISH_QUEUE = 64
#: the publisher starts a message only if its estimated cost, times this, ends before the
#: pacing thread's next wake-up
PUBLISH_COST_SAFETY = 2.0
#: ... unless it has waited this long for such a window: it goes at the start of the next sleep
#: (a message costlier than any window is published late rather than never) [s]
PUBLISH_MAX_DEFER = 0.01

# /clock: reliable keep-last, compatible with rclpy/rclcpp's best-effort clock subscriptions
# and with reliable ones (recorders).
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
# /joint_states and /markers: reliable keep-last, what robot_state_publisher and RViz ask for.
VIEWER_QOS = CLOCK_QOS


class SimulatorNode(FenceSorterNode):
    """Digital twin of the sorter: belt, rotary fence and parcels, paced by wall time."""

    NODE_NAME = "simulator"
    STATUS = "running"
    STATUS_LEVEL = DiagnosticStatus.OK
    PARAMETERS = (
        ParamSpec(
            "scene",
            DEFAULT_SCENE,
            "Scene (name in config/scenes or YAML path): conveyor, fence, contact and solver "
            "of the line (its parcel and drive are only used to warm the JIT up)",
            read_only=True,
        ),
        ParamSpec(
            "frame_id", "sorter", "Fixed frame of the sorter (REP-103, z up)", read_only=True
        ),
        ParamSpec(
            "real_time_factor",
            1.0,
            "Sim time advanced per wall second [-]; 0: unpaced, as fast as possible",
            min_value=0.0,
            max_value=100.0,
        ),
        ParamSpec(
            "physics_rate",
            1000.0,
            "Pacing loop rate [Hz] (wall clock); each cycle advances 1/physics_rate x rtf of sim",
            read_only=True,
            min_value=10.0,
            max_value=10000.0,
        ),
        ParamSpec(
            "publish_rate",
            50.0,
            "Rate of /clock, /fence_state, /joint_states, /load_states [Hz] (in cycles: wall "
            "Hz when paced, sim Hz when unpaced)",
            read_only=True,
            min_value=1.0,
            max_value=1000.0,
        ),
        ParamSpec(
            "marker_rate",
            10.0,
            "Rate of /markers [Hz] (same clock as publish_rate); 0: no markers",
            read_only=True,
            min_value=0.0,
            max_value=100.0,
        ),
        ParamSpec(
            "max_catch_up",
            0.1,
            "Largest sim time one late cycle may advance to catch up [s]; beyond it sim time "
            "slips behind the wall clock",
            read_only=True,
            min_value=0.001,
            max_value=10.0,
        ),
        ParamSpec(
            "spin_margin",
            0.0004,
            "Largest busy-wait before each deadline [s]; below it the wait follows the recent "
            "oversleep of time.sleep (at least 50 us)",
            read_only=True,
            min_value=0.0,
            max_value=0.005,
        ),
        ParamSpec(
            "lookahead",
            0.05,
            "Sim time the running solves may be stepped ahead of the line clock in each paced "
            "cycle's spare wall time [s], so the costly stretch of an impact is spread over "
            "the cycles before it is due; 0: off (each cycle does all of its physics)",
            read_only=True,
            min_value=0.0,
            max_value=1.0,
        ),
        ParamSpec(
            "prefetch_reserve",
            0.0002,
            "Wall time left free before the next cycle's busy-wait when stepping ahead [s] (one "
            "solver step may overrun the budget by its own cost)",
            read_only=True,
            min_value=0.0,
            max_value=0.01,
        ),
        ParamSpec(
            "line_end_x",
            3.0,
            "x0 where parcels leave the line (rear passing it) [m]",
            read_only=True,
            min_value=-10.0,
            max_value=100.0,
        ),
        ParamSpec(
            "r_s_min",
            -0.5,
            "Smallest R_s a command may ask for [m] (paper range (3))",
            read_only=True,
            min_value=-10.0,
            max_value=10.0,
        ),
        ParamSpec(
            "r_s_max",
            2.0,
            "Largest R_s a command may ask for [m]; a divert parcel whose front passes it with "
            "no accepted command is NO_COMMAND (point of no return)",
            read_only=True,
            min_value=-10.0,
            max_value=10.0,
        ),
        ParamSpec(
            "realtime_priority",
            50,
            "SCHED_FIFO priority of the pacing thread, the process's other threads one below "
            "(1-99; needs CAP_SYS_NICE or an rtprio limit, otherwise a warning and normal "
            "scheduling); 0: normal scheduling",
            read_only=True,
            min_value=0,
            max_value=99,
        ),
        ParamSpec(
            "warm_up",
            True,
            "Run one short stroke before starting so the compiled kernel is loaded",
            read_only=True,
        ),
        ParamSpec(
            "keep_cpus_awake",
            False,
            "Paced runs: one SCHED_IDLE busy process per CPU keeps the CPUs from halting "
            "between deadlines (on a VM whose guest idles with HLT, a sleeping loop otherwise "
            "wakes when the host runs its vCPU again); they yield to any other work",
            read_only=True,
        ),
        ParamSpec(
            "cycle_trace",
            "",
            "Write the paced loop's per-cycle timing (deadline, wake, end of each phase, what "
            "the cycle did) to this .npz at shutdown, to diagnose deadline misses (last 600000 "
            "cycles); empty: none",
            read_only=True,
        ),
        ParamSpec(
            "rrd_path",
            "",
            "Save a Rerun recording (.rrd) of the run here (logged in a child process from the "
            "snapshots published at publish_rate); empty: none",
            read_only=True,
        ),
        ParamSpec(
            "rrd_url",
            "",
            "Also stream to a Rerun viewer listening at this gRPC url (e.g. "
            "rerun+http://127.0.0.1:9876/proxy); empty: none",
            read_only=True,
        ),
        ParamSpec(
            "rrd_scan_line_x",
            -3.0,
            "x0 of the scan line drawn in the Rerun view [m] (drawing only)",
            read_only=True,
            min_value=-100.0,
            max_value=100.0,
        ),
    )

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        p = {spec.name: self.get_parameter(spec.name).value for spec in self.PARAMETERS}
        self.frame_id = str(p["frame_id"])
        loaded = load_scene(p["scene"] or DEFAULT_SCENE)  # SceneError: exit 2 in main()
        self.scene_name = loaded.name
        self.line_config = LineConfig.from_scenario(
            loaded.scenario,
            r_s_range=(float(p["r_s_min"]), float(p["r_s_max"])),
            line_end_x=float(p["line_end_x"]),
        )
        self.line = SortingLine(self.line_config)  # ValueError: exit 2 in main()
        if p["warm_up"]:
            _warm_up(self.line_config, loaded.scenario)
        self.rtf = float(p["real_time_factor"])
        self.period = 1.0 / float(p["physics_rate"])
        self.publish_every = max(1, round(float(p["physics_rate"]) / float(p["publish_rate"])))
        rate = float(p["marker_rate"])
        self.marker_every = max(1, round(float(p["physics_rate"]) / rate)) if rate > 0.0 else 0
        self.max_catch_up = float(p["max_catch_up"])
        self.spin_margin = float(p["spin_margin"])
        self.lookahead = float(p["lookahead"])
        self.prefetch_reserve = float(p["prefetch_reserve"])
        self.rt_priority = int(p["realtime_priority"])
        self.trace_path = str(p["cycle_trace"])
        self.trace = CycleTrace() if self.trace_path else None
        self.keep_cpus_awake = bool(p["keep_cpus_awake"])
        self._spinners: list = []

        self._inbox: queue.SimpleQueue = queue.SimpleQueue()
        # the pacing thread hands publications to the publisher thread: (kind, payload, due)
        self._publications: deque = deque()
        self._held: list[tuple[float, StrokeCommand]] = []  # commands for unknown parcels
        self.create_subscription(Parcel, "/parcels", self._on_parcel, RELIABLE_QOS)
        self.create_subscription(FenceCommand, "/fence_commands", self._on_command, RELIABLE_QOS)
        self.pub_clock = self.create_publisher(Clock, "/clock", CLOCK_QOS)
        self.pub_fence = self.create_publisher(FenceState, "/fence_state", SENSOR_QOS)
        self.pub_joint = self.create_publisher(JointState, "/joint_states", VIEWER_QOS)
        self.pub_loads = self.create_publisher(LoadState, "/load_states", SENSOR_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, "/markers", VIEWER_QOS)
        self.pub_outcomes = self.create_publisher(SortOutcome, "/sort_outcomes", RELIABLE_QOS)

        belt_x = (min(-3.0, self.line_config.r_s_range[0]), self.line_config.line_end_x)
        self._markers = convert.MarkerBuilder(
            self.line_config.conveyor.width, belt_x, self.frame_id
        )
        self.rerun = _start_rerun(p, self.line_config.conveyor.width, belt_x, self.rtf)
        self._clock_msg, self._fence_msg = Clock(), FenceState()
        self._joint_msg, self._load_msg = JointState(), LoadState()

        # statistics: written by the loop thread, read by the heartbeat under the lock
        self._lock = threading.Lock()
        self.hist = LatenessHistogram()
        self.work = LatenessHistogram()  # cycle work time (wake to done) [s]
        self.publish_lag = LatenessHistogram()  # snapshot due -> its messages published [s]
        self.cycles = 0
        self.misses = 0
        self.slips = 0
        self.counts: Counter[str] = Counter()
        self.bad_parcels: Counter[str] = Counter()
        self.rejected_commands: Counter[str] = Counter()
        self.outcome_counts: Counter[str] = Counter()
        self.sim_time = self.line.t
        self.loop_error: str | None = None
        self._rtf_window = (time.perf_counter(), self.line.t)
        self._stop = threading.Event()
        self._saved_switch: float | None = None
        self._thread = threading.Thread(target=self._loop, name="simulator-loop", daemon=True)
        # The publisher thread works only while the pacing thread sleeps (always when
        # unpaced), and only on messages it expects to finish before the pacing thread wakes
        # (_wake_at): Python threads share one interpreter lock with no priorities, so a
        # publisher running beside the cycle's work would take the lock from it for up to the
        # switch interval plus a whole rclpy publish() call (which does not release it).
        self._ready = threading.Event()  # the pacing thread went to sleep (unpaced: posted)
        self._wake_at = math.inf  # wall time the pacing thread wakes (perf_counter)
        self._debug_enabled = self.get_logger().is_enabled_for(LoggingSeverity.DEBUG)
        self._slept_at = -math.inf  # when it last went to sleep
        self._clock_published = self.line.t  # sim time of the last /clock message
        self._publisher = threading.Thread(
            target=self._publish_loop, name="simulator-publisher", daemon=True
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

    # -- callbacks: hand off only --------------------------------------------------------------
    def _on_parcel(self, msg: Parcel) -> None:
        self._inbox.put(("parcel", msg))

    def _on_command(self, msg: FenceCommand) -> None:
        self._inbox.put(("command", msg))

    # -- lifecycle -----------------------------------------------------------------------------
    def start(self) -> None:
        # A thread waking from sleep waits for the GIL until the holder's switch interval
        # (5 ms by default) expires: keep it well below the cycle period.
        self._saved_switch = sys.getswitchinterval()
        sys.setswitchinterval(min(self._saved_switch, 0.25 * self.period))
        # The cyclic GC would stop the loop for 1-60 ms at moments of its choosing: freeze
        # what exists after start-up (modules, compiled kernel, scene) and let the loop collect
        # the young generation in the slack after its work, the old one every few seconds.
        gc.collect()
        gc.freeze()
        gc.disable()
        if self.keep_cpus_awake and self.rtf > 0.0:
            self._spinners = start_spinners()
            self.get_logger().info(
                f"keep_cpus_awake: {len(self._spinners)} SCHED_IDLE spinner processes"
            )
        self._publisher.start()  # first: the pacing thread sets its priority below its own
        self._thread.start()

    def stop(self) -> None:
        """End the loop thread and give the process its GC and switch interval back."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        if self._publisher.is_alive():  # publishes what the loop handed over, then ends
            self._wake_at = math.inf
            self._publications.append((None, None, None))
            self._ready.set()
            self._publisher.join(timeout=5.0)
        spinners, self._spinners = self._spinners, []
        stop_spinners(spinners)
        if self.trace is not None:
            trace, self.trace = self.trace, None
            try:
                trace.save(self.trace_path)
                self.get_logger().info(f"cycle trace: {trace.n} cycles in {self.trace_path}")
            except OSError as exc:
                self.get_logger().error(f"cycle_trace {self.trace_path}: not written: {exc}")
        if self.rerun is not None:  # the child logs what it holds, then the file is closed
            rerun, self.rerun = self.rerun, None
            rerun.close()
        if self._saved_switch is not None:
            sys.setswitchinterval(self._saved_switch)
            gc.unfreeze()
            gc.enable()
            self._saved_switch = None

    # -- the pacing loop -------------------------------------------------------------------------
    def _loop(self) -> None:
        try:
            self._run_loop()
        except Exception as exc:  # report, then end the process through the executor
            # Ctrl-C/SIGTERM shutting the context down under a publish is a clean stop; the
            # main thread may still be on its way to set _stop, so give it a moment
            shutting_down = "context is invalid" in str(exc) or not self.context.ok()
            if shutting_down or self._stop.wait(0.5) or not self.context.ok():
                return
            self.loop_error = f"{type(exc).__name__}: {exc}"
            if not self._stop.is_set():
                self.get_logger().fatal(f"pacing loop failed: {self.loop_error}")
                self.context.try_shutdown()

    def _set_priority(self) -> None:
        """SCHED_FIFO for this (the pacing) thread, and one level below for the process's other
        threads (rclpy executor, DDS), as ros2_control does for its update loop: under normal
        scheduling another process's time slice delays a wake-up by milliseconds, and an
        ordinary thread preempted while it holds the GIL or a DDS lock would stall the pacing
        thread all the same (priority inversion). Falls back to normal scheduling with a
        warning where the process may not (no CAP_SYS_NICE or rtprio limit)."""
        if self.rt_priority <= 0 or self.rtf <= 0.0:
            return  # unpaced, the loop never sleeps: at SCHED_FIFO it would hold a core
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.rt_priority))
        except (OSError, AttributeError) as exc:
            self.get_logger().warning(f"realtime_priority not applied ({exc}); normal scheduling")
            return
        others = 0
        me = threading.get_native_id()
        below = os.sched_param(max(1, self.rt_priority - 1))
        for tid in os.listdir("/proc/self/task"):
            if int(tid) == me:
                continue
            try:
                os.sched_setscheduler(int(tid), os.SCHED_FIFO, below)
                others += 1
            except OSError:  # a thread that just ended, or not permitted: leave it
                pass
        self.get_logger().info(
            f"pacing thread: SCHED_FIFO priority {self.rt_priority}; {others} other threads at "
            f"{below.sched_priority}"
        )

    def _run_loop(self) -> None:
        self._set_priority()
        clock = time.perf_counter
        period, line = self.period, self.line
        # unpaced: a cycle is one publish period of sim time (a 1 ms cycle would spend its time
        # in Python overhead, not physics)
        ready = self._ready

        def sleep(seconds: float) -> None:  # the publisher thread works while this one sleeps
            self._slept_at = now = clock()
            self._wake_at = now + seconds
            ready.set()  # (also for messages left over from the last sleep)
            time.sleep(seconds)
            if pacer.rtf > 0.0:
                self._wake_at = -math.inf

        pacer = Pacer(
            period,
            self.rtf,
            line.t,
            self.max_catch_up,
            self.spin_margin,
            unpaced_step=self.publish_every * period,
            sleep=sleep,
        )
        if self.rtf == 0.0:
            self._wake_at = math.inf  # unpaced: the two threads share the interpreter as usual
        next_pub = next_marker = 0  # cycle index of the next publication (k may skip)
        next_gc = next_full_gc = 0
        post = self._post
        post(("states", line.snapshot(), None))
        while not self._stop.is_set():
            rtf = pacer.rtf
            tick = pacer.wait()
            deadline, t_target = tick.deadline, tick.t_sim
            # k counts periods of 1/physics_rate in both modes (publication schedule)
            k = tick.k if rtf > 0.0 else tick.k * self.publish_every
            if rtf > 0.0:
                wake = deadline + tick.lateness
                with self._lock:
                    self.hist.add(tick.lateness)
                    self.slips = pacer.slips
            else:
                wake = None
            flags = 0
            self._drain_inbox()
            events = line.advance(t_target)
            if events:
                flags |= CycleTrace.EVENTS
                post(("events", events, None))
            advanced = clock()
            # publishing is the publisher thread's: the loop hands over a snapshot (a copy),
            # so a slow publish or log write never delays the physics
            if k >= next_pub:
                flags |= CycleTrace.STATES
                next_pub = (k // self.publish_every + 1) * self.publish_every
                post(("states", line.snapshot(), wake))
            if self.marker_every and k >= next_marker:
                flags |= CycleTrace.MARKERS
                next_marker = (k // self.marker_every + 1) * self.marker_every
                post(("markers", line.snapshot(), wake))
            done = clock()
            if k >= next_gc and pacer.next_deadline - done > GC_SLACK:
                gen = 2 if k >= next_full_gc else 0
                flags |= CycleTrace.GC_FULL if gen == 2 else CycleTrace.GC_YOUNG
                gc.collect(gen)
                next_gc = k + self.publish_every
                if gen == 2:
                    next_full_gc = k + round(FULL_GC_PERIOD / period)
            collected = clock()
            if rtf > 0.0 and self.lookahead > 0.0:
                # spare time: step the running solves ahead (the wait below still starts its
                # busy-wait on time; one solver step may overrun by its own cost)
                line.prefetch(
                    self.lookahead * rtf,
                    pacer.next_deadline - self.spin_margin - self.prefetch_reserve,
                    clock,
                )
            with self._lock:
                if rtf > 0.0:
                    self.work.add(done - wake)
                self.cycles += 1
                self.sim_time = line.t
                if done > deadline + period:
                    self.misses += 1
                    flags |= CycleTrace.MISS
            if self.trace is not None and rtf > 0.0:
                self.trace.record(k, (deadline, wake, advanced, done, collected, clock()), flags)
            if self.rtf != pacer.rtf:  # changed at run time: a new grid from here
                if self.rtf == 0.0 and os.sched_getscheduler(0) == os.SCHED_FIFO:
                    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
                pacer.restart(self.rtf, line.t)
                next_pub = next_marker = next_gc = next_full_gc = 0

    def _drain_inbox(self) -> None:
        """Hand queued messages to the line: parcels first, then commands. A command for a
        parcel the line does not know yet is held up to ``COMMAND_HOLD`` of sim time (the
        parcel may still be in flight on the other topic) before it is rejected."""
        parcels, commands = [], []
        while True:
            try:
                kind, msg = self._inbox.get_nowait()
            except queue.Empty:
                break
            (parcels if kind == "parcel" else commands).append(msg)
        line = self.line
        log = self._log  # written by the publisher thread
        for msg in parcels:
            self.counts["parcels_received"] += 1
            try:
                line.add_parcel(convert.parcel_from_msg(msg), line.t)
            except InputError as exc:
                self.bad_parcels[exc.key] += 1
                log("warning", f"parcel {msg.parcel_id} rejected ({exc.key}): {exc}")
            except (ValueError, OverflowError) as exc:
                self.bad_parcels["invalid"] += 1
                log("warning", f"parcel {msg.parcel_id} rejected (invalid): {exc}")
        held, self._held = self._held, []
        for msg in commands:
            self.counts["commands_received"] += 1
            held.append((line.t, convert.command_from_msg(msg)))
        for t_in, cmd in held:
            res = line.command(cmd, line.t)
            if res.code == "unknown_parcel" and line.t - t_in < COMMAND_HOLD:
                self._held.append((t_in, cmd))
            elif res.accepted:
                self.counts[f"commands_{res.code}"] += 1
                if res.code == "accepted":
                    log(
                        "debug",
                        f"parcel {cmd.parcel_id}: stroke planned at t = "
                        f"{res.start_time:.3f} s (t1 = {cmd.t1:g} s)",
                    )
            else:
                self.rejected_commands[res.code] += 1
                log("warning", f"command for parcel {cmd.parcel_id} rejected: {res.reason}")

    def _handle(self, events: list) -> None:
        """Publish and log the line's events (publisher thread)."""
        log = self.get_logger()
        for e in events:
            if isinstance(e, Outcome):
                self.pub_outcomes.publish(convert.outcome_to_msg(e, self.frame_id))
                self.outcome_counts[e.code.name] += 1
                text = f"parcel {e.parcel_id}: {e.code.name} at t = {e.t:.3f} s: {e.reason}"
                if self.rerun is not None:
                    ok = e.code in (OutcomeCode.SORTED, OutcomeCode.NOT_DIVERTED)
                    self.rerun.event(e.t, text, ok)
                # the routine outcomes at DEBUG (they are on /sort_outcomes): an rclpy log
                # line costs ~0.4 ms of interpreter time the pacing loop may be waiting for
                if e.code in (OutcomeCode.SORTED, OutcomeCode.NOT_DIVERTED):
                    log.debug(text)
                else:
                    log.warning(text)
            elif isinstance(e, OverlapWarning):
                self.counts["overlap_warnings"] += 1
                log.warning(
                    f"parcel {e.other_parcel_id} is in the fence's swept area during the stroke "
                    f"for parcel {e.stroke_parcel_id} at t = {e.t:.3f} s (parcel-parcel contact "
                    "is not modelled)"
                )
            elif isinstance(e, SolverWarning):
                self.counts["solver_failures_after_outcome"] += 1
                log.error(f"stroke for parcel {e.parcel_id}: solver failure: {e.diagnosis}")
            elif isinstance(e, StrokeStarted):
                self.counts["strokes"] += 1

    def _log(self, level: str, text: str) -> None:
        """Log from the pacing thread: the publisher thread writes it (a log call may block on
        the console, the log file or /rosout). DEBUG lines are dropped here unless enabled."""
        if level == "debug" and not self._debug_enabled:
            return
        self._post(("log", (level, text), None))

    def _post(self, item: tuple) -> None:
        """Hand a publication to the publisher thread (pacing thread). Waits (sleeping, which
        lets the publisher run) only when ``PUBLISH_QUEUE`` publications are pending."""
        box = self._publications
        while len(box) >= PUBLISH_QUEUE and self._publisher.is_alive():
            self._wake_at = time.perf_counter() + 1e-3
            self._ready.set()
            time.sleep(1e-3)
            self._wake_at = -math.inf
        box.append(item)
        if self._wake_at == -math.inf:  # paced and awake: the publisher waits for the sleep
            if time.perf_counter() - self._slept_at < PUBLISH_MAX_DEFER:
                return
            # overloaded: the loop has not slept for a while (it runs behind its deadlines);
            # the publisher runs beside it until its next sleep rather than not at all
            self._wake_at = math.inf
        self._ready.set()

    # -- the publisher thread --------------------------------------------------------------------
    def _publish_loop(self) -> None:
        """Publish what the pacing loop hands over, in order, until the stop sentinel: state
        messages of a snapshot (/clock first), marker frames, events (outcomes, warnings) and
        log lines. A message starts only while the pacing thread sleeps and only if its
        running-mean cost (times ``PUBLISH_COST_SAFETY``) ends before that thread's wake-up;
        otherwise it waits for the next sleep. Records the lag from a snapshot's due time to
        its last message."""
        clock, cpu = time.perf_counter, time.thread_time
        box, ready = self._publications, self._ready
        pending: deque = deque()  # (cost key, function, argument, due) of taken publications
        cost: dict[str, float] = {}  # running mean CPU time per message kind [s]
        deferred = math.inf  # when the first pending message was first put off
        try:
            while True:
                ready.wait()
                ready.clear()
                while pending or box:
                    if not pending:
                        kind, payload, due = box.popleft()
                        if kind is None:  # the stop sentinel
                            return
                        pending.extend(self._messages(kind, payload, due))
                    key, fn, arg, due = pending[0]
                    t0 = clock()
                    if t0 + PUBLISH_COST_SAFETY * cost.get(key, 0.0) > self._wake_at and (
                        t0 - deferred < PUBLISH_MAX_DEFER or t0 > self._wake_at
                    ):
                        deferred = min(deferred, t0)
                        break  # not before the pacing thread wakes: at its next sleep
                    c0 = cpu()
                    fn(arg)
                    c1, t1 = cpu(), clock()
                    pending.popleft()
                    deferred = math.inf
                    # the thread's CPU time: its wall time would count waits for the
                    # interpreter lock while the pacing thread works
                    cost[key] = 0.9 * cost.get(key, c1 - c0) + 0.1 * (c1 - c0)
                    if due is not None:
                        with self._lock:
                            self.publish_lag.add(t1 - due)
        except Exception as exc:  # report, then end the process through the executor
            if "context is invalid" in str(exc) or not self.context.ok():
                return
            self.loop_error = f"publisher: {type(exc).__name__}: {exc}"
            self.get_logger().fatal(self.loop_error)
            self.context.try_shutdown()

    def _messages(self, kind: str, payload, due: float | None) -> list[tuple]:
        """One publication as messages: (cost key, function, argument, due or None)."""
        if kind == "states":
            snap = payload
            msgs = [
                ("clock", self._publish_clock, snap, None),
                ("fence", self._publish_fence, snap, None),
                ("joint", self._publish_joint, snap, None),
            ]
            msgs += [("load", self._publish_load, (snap, p), None) for p in snap.parcels]
            if self.rerun is not None:
                msgs.append(("rerun", self.rerun.offer, snap, None))  # packed, piped
            last = msgs[-1]
            msgs[-1] = (*last[:3], due)
            return msgs
        if kind == "markers":  # built, then published: two shorter steps
            return [
                ("markers_build", self._build_markers, payload, None),
                ("markers", self._publish_markers, None, due),
            ]
        if kind == "events":
            return [("events", self._handle, payload, None)]
        if kind == "heartbeat":
            return [
                ("heartbeat_build", self._build_heartbeat, None, None),
                ("heartbeat", self._send_heartbeat, None, None),
            ]
        return [("log", self._write_log, payload, None)]

    def _write_log(self, item: tuple[str, str]) -> None:
        level, text = item
        log = self.get_logger()  # one call site per severity (rclpy requires it)
        if level == "debug":
            log.debug(text)
        elif level == "info":
            log.info(text)
        elif level == "warning":
            log.warning(text)
        else:
            log.error(text)

    # one message object per topic, filled in place: publish() serialises it at once
    def _publish_clock(self, snap) -> None:
        self.pub_clock.publish(convert.fill_clock(self._clock_msg, snap.t))
        self._clock_published = snap.t

    def _publish_fence(self, snap) -> None:
        msg = convert.fill_fence_state(self._fence_msg, snap.fence, snap.t, self.frame_id)
        self.pub_fence.publish(msg)

    def _publish_joint(self, snap) -> None:
        self.pub_joint.publish(convert.fill_joint_state(self._joint_msg, snap.fence, snap.t))

    def _publish_load(self, item) -> None:
        snap, parcel = item
        self.pub_loads.publish(
            convert.fill_load_state(self._load_msg, parcel, snap.t, self.frame_id)
        )

    def _build_heartbeat(self, _) -> None:
        self._heartbeat_msg = self.heartbeat_message()

    def _send_heartbeat(self, _) -> None:
        self._diagnostics_pub.publish(self._heartbeat_msg)

    def _build_markers(self, snap) -> None:
        self._marker_msg = self._markers.build(snap)

    def _publish_markers(self, _) -> None:
        self.pub_markers.publish(self._marker_msg)

    # -- diagnostics -----------------------------------------------------------------------------
    def publish_heartbeat(self) -> None:
        """Timer callback (executor thread): the publisher thread builds and publishes the
        heartbeat, in the pacing thread's sleep like every other message (its ~0.3 ms of
        Python would otherwise compete with the loop for the interpreter lock)."""
        if not self._publisher.is_alive():
            super().publish_heartbeat()  # before start() / after stop()
            return
        self._publications.append(("heartbeat", None, None))
        if self._wake_at != -math.inf:  # not paced-and-awake: nobody else will wake it
            self._ready.set()

    def heartbeat_stamp(self):
        """The last /clock this node published (sim time), as the /diagnostics of the nodes
        that follow that clock are stamped: one time base on the topic, and no stamp ahead of
        what a sim-time recorder has seen (bag tools order the topic by this stamp)."""
        return convert.fill_clock(Clock(), self._clock_published).clock

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        now = time.perf_counter()
        with self._lock:  # copies only: the pacing thread takes this lock every cycle
            hist, work, lag = self.hist.copy(), self.work.copy(), self.publish_lag.copy()
            cycles, misses, slips, sim_t = self.cycles, self.misses, self.slips, self.sim_time
            counts = dict(self.counts)
            bad = dict(self.bad_parcels)
            rejected = dict(self.rejected_commands)
            outcomes = dict(self.outcome_counts)
        qs = (50.0, 99.0, 99.9)
        p50, p99, p999 = (1e3 * v for v in hist.percentiles(qs))
        w50, w99, w999 = (1e3 * v for v in work.percentiles(qs))
        g50, g99, g999 = (1e3 * v for v in lag.percentiles(qs))
        lat_max, w_max, g_max = 1e3 * hist.max, 1e3 * work.max, 1e3 * lag.max
        w0, s0 = self._rtf_window
        self._rtf_window = (now, sim_t)
        rtf = (sim_t - s0) / (now - w0) if now > w0 else math.nan
        values = {
            "scene": self.scene_name,
            "sim_time_s": f"{sim_t:.3f}",
            "real_time_factor_target": f"{self.rtf:g}",
            "real_time_factor_achieved": f"{rtf:.3f}",
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
            # snapshot due (its cycle's wake) -> its last state message published, paced only
            "publish_lag_p50_ms": f"{g50:.4f}",
            "publish_lag_p99_ms": f"{g99:.4f}",
            "publish_lag_p99_9_ms": f"{g999:.4f}",
            "publish_lag_max_ms": f"{g_max:.4f}",
            "parcels_on_line": str(self.line.parcels_on_line),
            "bad_parcels": str(sum(bad.values())),
            "commands_rejected": str(sum(rejected.values())),
            "overlap_warnings": str(counts.get("overlap_warnings", 0)),
        }
        if self.rerun is not None:
            values["rerun_frames_sent"] = str(self.rerun.sent)
            values["rerun_frames_dropped"] = str(self.rerun.dropped)
        values.update({k: str(v) for k, v in counts.items() if k != "overlap_warnings"})
        values.update({f"bad_parcels.{k}": str(v) for k, v in sorted(bad.items())})
        values.update({f"commands_rejected.{k}": str(v) for k, v in sorted(rejected.items())})
        values.update({f"outcomes.{k}": str(v) for k, v in sorted(outcomes.items())})
        status.values.extend(KeyValue(key=k, value=v) for k, v in values.items())
        if self.loop_error:
            status.level = DiagnosticStatus.ERROR
            status.message = f"pacing loop failed: {self.loop_error}"
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
        if "real_time_factor" in values and hasattr(self, "_thread"):
            self.rtf = float(values["real_time_factor"])  # the loop restarts its grid
        return None


def _start_rerun(p: dict, belt_width: float, belt_x: tuple[float, float], rtf: float):
    """The Rerun child process when rrd_path or rrd_url is set (fence_sorter.visualisation):
    the loop hands it each published snapshot without blocking; unpaced runs wait for it."""
    path, url = str(p["rrd_path"]), str(p["rrd_url"])
    if not path and not url:
        return None
    from fence_sorter.visualisation.rerun_live import RerunProcess
    from fence_sorter.visualisation.rerun_log import SceneGeometry

    # chute as convert.MarkerBuilder draws it
    chute = (0.75, belt_width + 0.3, 1.5, 0.6)
    scene = SceneGeometry(belt_width, belt_x, chute, float(p["rrd_scan_line_x"]))
    return RerunProcess(scene, path or None, url or None, lossless=rtf == 0.0)


def _warm_up(config: LineConfig, scenario) -> None:
    """One short stroke on a scratch line so the kernel's compiled code is loaded before the
    pacing loop starts (loading it inside the loop would stall it by a few hundred ms)."""
    line = SortingLine(config)
    pp = scenario.parcel
    spec = ParcelSpec(
        0,
        length_a=pp.length_a,
        width_b=pp.width_b,
        height=pp.height,
        mass=pp.mass,
        cog_offset_x=pp.cog_offset_x,
        cog_offset_y=pp.cog_offset_y,
        lateral_gap=pp.lateral_gap,
        yaw=pp.yaw,
        divert=True,
        scan_position_x=scenario.drive.r_s,
    )
    line.add_parcel(spec)
    drive = scenario.drive
    line.command(StrokeCommand(0, r_s=drive.r_s, t1=drive.t1, alpha_k=drive.alpha_k))
    for k in range(1, 41):
        line.advance(0.01 * k)
        line.snapshot()


def main(args: Sequence[str] | None = None) -> int:
    """Run the simulator until Ctrl-C or SIGTERM; exit 2 with one line on a bad scene or
    parameter, 1 if the pacing loop failed."""
    # A SIGINT/SIGTERM that arrives while rclpy.init installs its handlers, before the context
    # exists, is lost (the process then runs on): hold them until init is done.
    stop_signals = {signal.SIGINT, signal.SIGTERM}
    signal.pthread_sigmask(signal.SIG_BLOCK, stop_signals)
    try:
        rclpy.init(args=list(args) if args is not None else None)
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, stop_signals)
    node: SimulatorNode | None = None
    code = 0
    try:
        node = SimulatorNode()
        node.start()
        spin_node(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterException as exc:
        print(f"simulator: invalid parameter: {exc}", file=sys.stderr)
        code = 2
    except ValueError as exc:  # SceneError, a line setting out of range
        print(f"simulator: {exc}", file=sys.stderr)
        code = 2
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
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    raise SystemExit(main())
