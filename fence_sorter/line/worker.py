"""The pacing loop in a process of its own: the line stepped against the wall clock, with no
ROS and no other Python thread beside it.

Why a process: Python threads share one interpreter lock with no priorities. In the
simulator node's process, rclpy's executor, the publisher thread and the log calls took that
lock from the loop for up to ~2 ms at a time (an rclpy ``publish()`` does not release it); the
cycle traces showed this as the main cause of deadline misses (docs/design/simulator.md). Here the
loop is the process's only thread. It reads parcels and commands from one pipe at the start of
every cycle (non-blocking) and writes what the node publishes (snapshots, events, log lines,
counters) to another, never waiting for the reader in a paced run.

Wire format (both pipes): frames of a 4-byte little-endian length and a pickle. The node
(:class:`LineProcess`) sends ``("parcel", ParcelSpec)``, ``("command", StrokeCommand)``,
``("rtf", float)`` and ``("stop",)``; the loop sends ``("ready", t)``,
``("states", LineCapture, due)``, ``("markers", LineCapture, due)``, ``("events", list)``,
``("log", level, text)``, ``("stats", LoopStats)`` (counters by name, when they change),
``("error", text)``; a ``markers`` frame with no capture means the one of the ``states`` frame
before it. The node renders a capture into a ``LineSnapshot`` with its own copy of the line's
fence geometry (``SortingLine.render``). ``due`` is the cycle's wake time on
``time.perf_counter`` (CLOCK_MONOTONIC, the same in both processes). The running figures
(cycles, misses, lateness and work histograms, sim time) are not sent: the loop writes them
into shared memory (:class:`Gauges`) every cycle.

Run as ``python -m fence_sorter.line.worker IN_FD OUT_FD GAUGES_FD PARENT_PID``, or forked
from the node's process before it starts rclpy (``LineProcess(fork=True)``: the copy has the
line's modules imported already, which a fresh interpreter takes about a second of CPU to
do); either way it is named :data:`PROCESS_NAME` and the first frame on IN_FD is
``(LineConfig, scenario or None, LoopSettings)``.
"""

from __future__ import annotations

import ctypes
import fcntl
import gc
import math
import mmap
import os
import pickle
import select
import signal
import subprocess
import sys
import threading
import time
import traceback
from collections import Counter, deque
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from fence_sorter.inputs import InputError, ParcelSpec, StrokeCommand

from .frames import HEADER, FrameBuffer, Inbox, Outbox, frame, read_exact
from .one_fence import LineConfig, SortingLine
from .pacing import CycleTrace, LatenessHistogram, Pacer

#: sim time a command for a not-yet-known parcel waits for its parcel message [s]
COMMAND_HOLD = 0.5
#: the loop collects garbage or sends its counters only with this much time left before the
#: next deadline [s]
GC_SLACK = 0.0006
#: wall time between full collections [s]
FULL_GC_PERIOD = 10.0
#: unpaced, the loop waits for the reader beyond this many unsent bytes (backpressure)
UNPACED_BACKLOG = 1 << 18
#: paced, unsent bytes beyond this mean the reader is gone: the loop fails
PACED_BACKLOG = 1 << 26
#: pipe buffer asked for (Linux F_SETPIPE_SZ; the default is 64 KiB)
PIPE_SIZE = 1 << 20
_F_SETPIPE_SZ = 1031
_PR_SET_PDEATHSIG, _PR_SET_NAME = 1, 15
#: the loop's process's name (/proc/PID/comm), started either way
PROCESS_NAME = "fs-line-worker"
#: held while the node forks the loop's process, until the copy ignores them
_STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})


class LoopStartError(RuntimeError):
    """The loop's process ended or failed before it was ready."""


@dataclass(frozen=True)
class LoopSettings:
    """How the loop paces and what it sends (the simulator node's parameters, SI)."""

    period: float  # wall period of a paced cycle [s]
    rtf: float  # real-time factor (0: unpaced)
    max_catch_up: float = 0.1  # [s] of sim time one late cycle may advance
    spin_margin: float = 4e-4  # largest busy-wait before a deadline [s]
    lookahead: float = 0.05  # [s] of sim time the solves may run ahead in spare time
    prefetch_reserve: float = 2e-4  # [s] of wall time kept free when stepping ahead
    publish_every: int = 20  # cycles between state snapshots
    marker_every: int = 100  # cycles between marker snapshots (0: none)
    rt_priority: int = 0  # SCHED_FIFO priority in paced runs (0: normal scheduling)
    loop_cpu: int = -1  # CPU the loop's process is pinned to (-1: not pinned)
    command_wait: float = 1.0  # unpaced: wall time to hold sim time for a command [s]; 0: off
    publish_lead: float = math.inf  # unpaced: sim time the loop may be ahead of the node's
    # last published snapshot (Gauges.PUBLISHED) [s]; inf: no such wait
    debug: bool = False  # send DEBUG log lines
    trace_path: str = ""  # CycleTrace .npz written at the end ("": none)
    warm_up: bool = True  # one short stroke before the loop starts

    def __post_init__(self) -> None:
        checks = (
            ("period", self.period, self.period > 0.0, "> 0 s"),
            ("rtf", self.rtf, self.rtf >= 0.0, ">= 0"),
            ("max_catch_up", self.max_catch_up, self.max_catch_up > 0.0, "> 0 s"),
            ("spin_margin", self.spin_margin, self.spin_margin >= 0.0, ">= 0 s"),
            ("lookahead", self.lookahead, self.lookahead >= 0.0, ">= 0 s"),
            ("prefetch_reserve", self.prefetch_reserve, self.prefetch_reserve >= 0.0, ">= 0 s"),
            ("publish_every", self.publish_every, self.publish_every >= 1, ">= 1"),
            ("marker_every", self.marker_every, self.marker_every >= 0, ">= 0"),
            ("rt_priority", self.rt_priority, 0 <= self.rt_priority <= 99, "in 0..99"),
            ("loop_cpu", self.loop_cpu, self.loop_cpu >= -1, ">= -1"),
            ("command_wait", self.command_wait, 0.0 <= self.command_wait <= 60.0, "in [0, 60] s"),
            ("publish_lead", self.publish_lead, self.publish_lead > 0.0, "> 0 s"),
        )
        for name, value, ok, allowed in checks:
            if not ok:
                raise ValueError(f"LoopSettings.{name} = {value!r}: must be {allowed}")


@dataclass
class LoopStats:
    """The loop's counters by name, sent when they change and at the end (the running
    figures are in :class:`Gauges`)."""

    counts: dict[str, int] = field(default_factory=dict)
    bad_parcels: dict[str, int] = field(default_factory=dict)
    rejected_commands: dict[str, int] = field(default_factory=dict)


class Gauges:
    """The loop's running figures in memory shared with the node (a memfd mapped by both):
    the loop writes them every cycle at the cost of a few array stores, the node reads them
    for its heartbeat with no frame and no work in the loop. Aligned 8-byte stores, so no
    value is ever read torn; a set read while a cycle runs may be one cycle apart."""

    CYCLES, MISSES, SLIPS, SIM_TIME, LATENESS_MAX, WORK_MAX, ON_LINE, PUBLISHED = range(8)
    SCAN_LIMIT = 8
    WAITING = 9
    RTF = 10
    HEADER = 11
    #: values of header[WAITING]: what an unpaced loop is blocked on (0: stepping)
    WAIT_READER, WAIT_NODE, WAIT_COMMAND = 1.0, 2.0, 3.0

    def __init__(self, fd: int | None = None) -> None:
        bins = LatenessHistogram.BINS + 1
        size = 8 * (self.HEADER + 2 * bins)
        if fd is None:
            fd = os.memfd_create("fence_sorter_gauges")
            os.ftruncate(fd, size)
        self.fd = fd
        self._mm = mmap.mmap(fd, size)
        #: cycles, misses, slips, sim time [s], lateness and work max [s], parcels on line,
        #: and (written by the node) the sim time of the last snapshot it published [s] and
        #: the sim time an unpaced loop may not pass (the scanner's progress; inf: no limit);
        #: what an unpaced loop is waiting for (WAIT_*, 0 while it steps); the real-time
        #: factor the loop paces with (0: unpaced)
        self.header = np.ndarray((self.HEADER,), np.float64, self._mm, 0)
        #: lateness and work histogram counts (LatenessHistogram bins)
        self.counts = np.ndarray((2, bins), np.int64, self._mm, 8 * self.HEADER)

    def histogram(self, which: int) -> LatenessHistogram:
        """A copy of histogram 0 (lateness) or 1 (work) (node side)."""
        h = LatenessHistogram.__new__(LatenessHistogram)
        h.counts = self.counts[which].copy()
        h.n = int(h.counts.sum())
        h.max = float(self.header[self.LATENESS_MAX if which == 0 else self.WORK_MAX])
        return h

    def value(self, index: int) -> float:
        return float(self.header[index])


# -- the loop -------------------------------------------------------------------------------------
class PacedLoop:
    """The line stepped on a :class:`Pacer` grid: inputs at the start of each cycle, physics,
    snapshots every ``publish_every`` cycles, garbage collection and statistics in the slack,
    then the running solves stepped ahead in the spare time (``SortingLine.prefetch``)."""

    def __init__(
        self,
        line: SortingLine,
        settings: LoopSettings,
        inbox: Inbox,
        out: Outbox,
        gauges: Gauges,
    ):
        self.line, self.s, self.inbox, self.out = line, settings, inbox, out
        self.rtf = settings.rtf
        self.stop = False
        self.gauges = gauges
        # histograms counting straight into the shared memory
        self.hist, self.work = LatenessHistogram(), LatenessHistogram()
        self.hist.counts, self.work.counts = gauges.counts[0], gauges.counts[1]
        self.counters_changed = False
        self.counts: Counter[str] = Counter()
        self.bad_parcels: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self.held: list[tuple[float, StrokeCommand]] = []  # commands for unknown parcels
        self.waiting: dict[int, float] = {}  # unpaced lockstep: parcel id -> wait start
        self.gave_up: set[int] = set()
        self.trace = CycleTrace() if settings.trace_path else None

    def log(self, level: str, text: str) -> None:
        if level != "debug" or self.s.debug:
            self.out.send(("log", level, text))

    def set_priority(self) -> None:
        """SCHED_FIFO in paced runs: a wake-up is then not delayed by another process's time
        slice. Normal scheduling with a warning where the process may not. Pinned to
        ``loop_cpu`` if set (whatever the rate)."""
        if self.s.loop_cpu >= 0 and os.sched_getaffinity(0) != {self.s.loop_cpu}:
            try:
                os.sched_setaffinity(0, {self.s.loop_cpu})
                self.log("info", f"pacing process: pinned to CPU {self.s.loop_cpu}")
            except OSError as exc:
                self.log("warning", f"loop_cpu {self.s.loop_cpu} not applied ({exc})")
        if self.s.rt_priority <= 0 or self.rtf <= 0.0:
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.s.rt_priority))
        except (OSError, AttributeError) as exc:
            self.log("warning", f"realtime_priority not applied ({exc}); normal scheduling")
            return
        self.log("info", f"pacing process: SCHED_FIFO priority {self.s.rt_priority}")

    def send_stats(self) -> None:
        self.counters_changed = False
        stats = LoopStats(dict(self.counts), dict(self.bad_parcels), dict(self.rejected))
        self.out.send(("stats", stats))

    def take_inputs(self) -> None:
        """Parcels first, then commands. A command for a parcel the line does not know yet is
        held up to ``COMMAND_HOLD`` of sim time (the parcel may still be in flight on the
        other topic) before it is rejected."""
        items = self.inbox.take()
        if items or self.held:
            self.counters_changed = True
        if self.inbox.closed:
            self.stop = True
        line, log = self.line, self.log
        commands = []
        for item in items:
            kind = item[0]
            if kind == "parcel":
                spec: ParcelSpec = item[1]
                self.counts["parcels_received"] += 1
                try:
                    line.add_parcel(spec, line.t)
                except InputError as exc:
                    self.bad_parcels[exc.key] += 1
                    log("warning", f"parcel {spec.parcel_id} rejected ({exc.key}): {exc}")
                except (ValueError, OverflowError) as exc:
                    self.bad_parcels["invalid"] += 1
                    log("warning", f"parcel {spec.parcel_id} rejected (invalid): {exc}")
            elif kind == "command":
                self.counts["commands_received"] += 1
                commands.append(item[1])
            elif kind == "rtf":
                self.rtf = float(item[1])
            elif kind == "stop":
                self.stop = True
        held, self.held = self.held, []
        held += [(line.t, cmd) for cmd in commands]
        for t_in, cmd in held:
            res = line.command(cmd, line.t)
            if res.code == "unknown_parcel" and line.t - t_in < COMMAND_HOLD:
                self.held.append((t_in, cmd))
            elif res.accepted:
                self.counts[f"commands_{res.code}"] += 1
                if res.code == "accepted":
                    log(
                        "debug",
                        f"parcel {cmd.parcel_id}: stroke planned at t = "
                        f"{res.start_time:.3f} s (t1 = {cmd.t1:g} s)",
                    )
            else:
                self.rejected[res.code] += 1
                log("warning", f"command for parcel {cmd.parcel_id} rejected: {res.reason}")

    def hold_for_commands(self, t_target: float, pacer: Pacer) -> float:
        """Unpaced lockstep: a parcel to divert without a command must not reach the lowest
        R_s before its command had a chance to arrive (at hundreds of times real time the
        controller's answer would otherwise come too late). Advance only up to there, and
        wait for the command there, taking inputs, for up to ``command_wait`` of wall time per
        parcel; then give up on it (it becomes NO_COMMAND as in a paced run). Sim time goes
        on from the held time."""
        line, clock = self.line, time.perf_counter
        while not self.stop:
            t_hold, pid = line.awaiting_command(self.gave_up)
            if t_target <= t_hold:
                return t_target
            if t_hold > line.t:
                # the next tick goes on from the held time (the grid index is kept: it counts
                # the publication schedule)
                pacer.sim0 = t_hold - pacer.k * pacer.unpaced_step
                return t_hold
            waited_since = self.waiting.setdefault(pid, clock())
            if clock() - waited_since > self.s.command_wait:
                self.gave_up.add(pid)
                self.counts["command_waits_given_up"] += 1
                self.counters_changed = True
                continue
            self.gauges.header[Gauges.WAITING] = Gauges.WAIT_COMMAND
            self.out.drain(0, self.inbox)  # the node publishes what it holds meanwhile
            select.select([self.inbox.fd], [], [], 1e-3)
            self.take_inputs()
        return line.t

    def wait_for_node(self) -> None:
        """Unpaced: wait until the node has published the line up to ``publish_lead`` behind
        its time, and while the line has reached ``Gauges.SCAN_LIMIT`` (the scanner's
        progress plus a lead, written by the node). The other nodes run on the published
        /clock: a loop far ahead of it, or of the scanner, would receive parcels scanned (and
        commands planned) seconds of sim time in its past."""
        g, lead, inbox, line = self.gauges.header, self.s.publish_lead, self.inbox, self.line
        while (
            g[Gauges.PUBLISHED] < line.t - lead or line.t >= g[Gauges.SCAN_LIMIT]
        ) and not self.stop:
            g[Gauges.WAITING] = Gauges.WAIT_NODE
            self.out.drain(0, inbox)
            if select.select([inbox.fd], [], [], 2e-4)[0]:
                inbox.read()
            if inbox.stop_requested:
                return

    def run(self) -> None:
        s, line, out = self.s, self.line, self.out
        clock = time.perf_counter
        period = s.period
        pacer = Pacer(
            period, self.rtf, line.t, s.max_catch_up, s.spin_margin,
            unpaced_step=s.publish_every * period,
        )  # fmt: skip
        self.set_priority()
        next_pub = next_marker = next_gc = next_full_gc = 0  # cycle indices (k may skip)
        g = self.gauges.header
        cycles = misses = 0
        g[Gauges.SIM_TIME] = line.t
        out.send(("states", line.capture(), None))
        while not self.stop:
            rtf = pacer.rtf
            tick = pacer.wait()
            deadline = tick.deadline
            # k counts periods of 1/physics_rate in both modes (publication schedule)
            k = tick.k if rtf > 0.0 else tick.k * s.publish_every
            wake = deadline + tick.lateness if rtf > 0.0 else None
            if wake is not None:
                self.hist.add(tick.lateness)
            flags = 0
            self.take_inputs()
            t_target = tick.t_sim
            if rtf == 0.0 and s.command_wait > 0.0:
                t_target = self.hold_for_commands(t_target, pacer)
            events = line.advance(t_target)
            if events:
                flags |= CycleTrace.EVENTS
                out.send(("events", events))
            # the cycle's due work ends here: the line has reached the cycle's sim time and its
            # outcomes are on their way (a cycle misses when `done` is late). Captures of the
            # line at that time, serialising and writing frames, garbage collection and
            # statistics use the slack before the next cycle advances the line
            done = clock()
            # the cycle captures the line's state as plain numbers; the node renders it
            cap = None
            if k >= next_pub:
                flags |= CycleTrace.STATES
                next_pub = (k // s.publish_every + 1) * s.publish_every
                cap = line.capture()
                out.send(("states", cap, wake))
            if s.marker_every and k >= next_marker:
                flags |= CycleTrace.MARKERS
                next_marker = (k // s.marker_every + 1) * s.marker_every
                # None: the node builds the markers from the states snapshot just sent
                out.send(("markers", None if cap is not None else line.capture(), wake))
            captured = clock()
            budget_end = pacer.next_deadline - s.spin_margin
            out.flush(budget_end)
            slack = pacer.next_deadline - clock() > GC_SLACK
            if k >= next_gc and slack:
                gen = 2 if k >= next_full_gc else 0
                flags |= CycleTrace.GC_FULL if gen == 2 else CycleTrace.GC_YOUNG
                gc.collect(gen)
                next_gc = k + s.publish_every
                if gen == 2:
                    next_full_gc = k + round(FULL_GC_PERIOD / period)
            # cycles: the grid's deadlines, run or not; a stalled loop (stopped, starved)
            # misses every deadline that passed while it did not run, not only the one it
            # woke for
            cycles += 1 + tick.skipped
            misses += tick.skipped
            if wake is not None:
                self.work.add(done - wake)
                if done > deadline + period:
                    misses += 1
                    flags |= CycleTrace.MISS
            g[Gauges.CYCLES], g[Gauges.MISSES], g[Gauges.SLIPS] = cycles, misses, pacer.slips
            g[Gauges.SIM_TIME], g[Gauges.ON_LINE] = line.t, line.parcels_on_line
            g[Gauges.RTF] = rtf
            g[Gauges.LATENESS_MAX], g[Gauges.WORK_MAX] = self.hist.max, self.work.max
            if self.counters_changed and (slack or rtf == 0.0):
                self.send_stats()
                out.flush(budget_end)
            collected = clock()
            if rtf > 0.0 and s.lookahead > 0.0:
                # spare time: step the running solves ahead (the wait still starts its
                # busy-wait on time; one solver step may overrun by its own cost)
                line.prefetch(
                    s.lookahead * rtf,
                    pacer.next_deadline - s.spin_margin - s.prefetch_reserve,
                    clock,
                )
            elif rtf == 0.0:  # unpaced: the reader sets the pace
                if len(out.buf) > UNPACED_BACKLOG:
                    g[Gauges.WAITING] = Gauges.WAIT_READER
                out.drain(UNPACED_BACKLOG, self.inbox)
                self.wait_for_node()
                g[Gauges.WAITING] = 0.0
            if len(out.buf) > PACED_BACKLOG:
                raise RuntimeError(f"{len(out.buf)} bytes unsent: the node stopped reading")
            if self.trace is not None and rtf > 0.0:
                self.trace.record(k, (deadline, wake, done, captured, collected, clock()), flags)
            if self.rtf != pacer.rtf:  # changed at run time: a new grid from here
                if self.rtf == 0.0 and os.sched_getscheduler(0) == os.SCHED_FIFO:
                    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
                elif pacer.rtf == 0.0:
                    self.set_priority()
                pacer.restart(self.rtf, line.t)
                next_pub = next_marker = next_gc = next_full_gc = 0

    def finish(self) -> None:
        """After the loop: the trace written, the final statistics sent."""
        if self.trace is not None:
            try:
                self.trace.save(self.s.trace_path)
                self.log("info", f"cycle trace: {self.trace.n} cycles in {self.s.trace_path}")
            except OSError as exc:
                self.log("error", f"cycle_trace {self.s.trace_path}: not written: {exc}")
        self.send_stats()


def warm_up(config: LineConfig, scenario) -> None:
    """One short stroke on a scratch line so the kernel's compiled code is loaded before the
    pacing loop starts (loading it inside the loop would stall it by a few hundred ms)."""
    line = SortingLine(replace(config, scan_line_x=None))  # its parcel starts at R_s
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


def main(argv: list[str]) -> int:
    """The process: read the set-up frame, build and warm the line, run the loop until the
    node sends ``stop`` or goes away."""
    try:
        in_fd, out_fd, gauges_fd, parent = (int(a) for a in argv)
    except ValueError:
        print(
            "usage: python -m fence_sorter.line.worker IN_FD OUT_FD GAUGES_FD PARENT_PID "
            f"(four integers, started by the simulator node); got {argv}",
            file=sys.stderr,
        )
        return 2
    return serve(in_fd, out_fd, gauges_fd, parent)


def serve(in_fd: int, out_fd: int, gauges_fd: int, parent: int) -> int:
    """The loop's process on its pipes, however started (:func:`main` or a fork)."""
    # die with the node; Ctrl-C and SIGTERM reach the whole process group, but only the node
    # ends this process (stop frame, or its end of the pipe closing), after the last frames
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    libc.prctl(_PR_SET_NAME, PROCESS_NAME.encode())
    if os.getppid() != parent:
        return 0
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)  # held by a fork until now
    try:
        fcntl.fcntl(out_fd, _F_SETPIPE_SZ, PIPE_SIZE)
    except OSError:
        pass  # the default 64 KiB: the outbox holds the rest
    out = Outbox(out_fd)
    try:
        (n,) = HEADER.unpack(read_exact(in_fd, 4))  # the set-up frame, blocking
        config, scenario, settings = pickle.loads(read_exact(in_fd, n))
        inbox = Inbox(in_fd)
        line = SortingLine(config)
        if settings.warm_up and scenario is not None:
            warm_up(config, scenario)
        loop = PacedLoop(line, settings, inbox, out, Gauges(gauges_fd))
        # the cyclic GC would stop the loop for 1-60 ms at moments of its choosing: freeze
        # what exists after start-up (modules, compiled kernel, scene); the loop collects the
        # young generation in the slack after its work, the old one every few seconds
        gc.collect()
        gc.freeze()
        gc.disable()
        out.send(("ready", line.t))
        out.flush()
        try:
            loop.run()
        finally:
            loop.finish()
    except Exception:
        out.send(("error", traceback.format_exc(limit=8)))
        code = 1
    else:
        code = 0
    os.set_blocking(out_fd, True)
    out.drain(0)
    os.close(out_fd)
    return code


# -- the node's side ------------------------------------------------------------------------------
def _fork(args: tuple[int, int, int, int], close: tuple[int, ...]) -> _Forked:
    """Fork the loop's process: the copy closes the node's ends of the pipes (``close``) and
    serves ``args`` (:func:`serve`); SIGINT and SIGTERM are held across the fork, so the copy
    ignores them before one can reach it."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            for fd in close:
                os.close(fd)
            code = serve(*args)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    signal.pthread_sigmask(signal.SIG_SETMASK, held)
    return _Forked(pid)


class _Forked:
    """A forked loop process, seen through the part of subprocess.Popen that LineProcess and
    the node use (pid, returncode, poll, wait, kill)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.returncode: int | None = None
        self._pidfd = os.pidfd_open(pid)

    def _reap(self, options: int) -> int | None:
        if self.returncode is None:
            done, status = os.waitpid(self.pid, options)
            if done:
                self.returncode = os.waitstatus_to_exitcode(status)
                os.close(self._pidfd)
        return self.returncode

    def poll(self) -> int | None:
        return self._reap(os.WNOHANG)

    def wait(self, timeout: float | None = None) -> int:
        if self.poll() is None and not select.select([self._pidfd], [], [], timeout)[0]:
            raise subprocess.TimeoutExpired(PROCESS_NAME, timeout)
        return self._reap(0)

    def kill(self) -> None:
        if self.poll() is None:
            os.kill(self.pid, signal.SIGKILL)


class LineProcess:
    """The loop's process seen from the node: start it, send it inputs (thread-safe), iterate
    over what it sends, stop it."""

    def __init__(
        self,
        config: LineConfig | None = None,
        scenario=None,
        settings: LoopSettings | None = None,
        scan_limit: float = math.inf,
        fork: bool = False,
    ) -> None:
        """Start the loop's process and, given a ``config``, :meth:`configure` it. ``fork``:
        a copy of this process, which must have no other thread yet (the simulator's main
        before rclpy starts its own); else a fresh interpreter."""
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        try:
            fcntl.fcntl(from_child_w, _F_SETPIPE_SZ, PIPE_SIZE)
        except OSError:
            pass
        self._lock = threading.Lock()
        #: the loop's running figures (cycles, misses, lateness and work histograms, ...)
        self.gauges = Gauges()
        fds = (to_child_r, from_child_w, self.gauges.fd, os.getpid())
        if fork:
            self.proc = _fork(fds, close=(self._to_child, self._from_child))
        else:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "fence_sorter.line.worker", *map(str, fds)],
                pass_fds=fds[:3],
                stdin=subprocess.DEVNULL,
            )
        os.close(to_child_r)
        os.close(from_child_w)
        os.close(self.gauges.fd)  # the mapping stays
        self._frames = FrameBuffer()
        self._pending: deque = deque()
        self._eof = False
        if config is not None:
            self.configure(config, scenario, settings, scan_limit)

    def configure(
        self, config: LineConfig, scenario, settings: LoopSettings, scan_limit: float = math.inf
    ) -> None:
        """Send the set-up: the line, the scenario to warm the kernel up with (None: no
        warm-up), the loop's settings; ``scan_limit``: the initial Gauges.SCAN_LIMIT (an
        unpaced loop does not pass it)."""
        self.gauges.header[Gauges.SCAN_LIMIT] = scan_limit
        self.send((config, scenario, settings))

    def send(self, item: object) -> bool:
        """Send one frame; False if the loop's process is gone."""
        data = frame(item)
        with self._lock:
            if self._to_child < 0:
                return False
            try:
                os.write(self._to_child, data)  # blocking: the loop reads every cycle
            except OSError:  # BrokenPipeError: it ended
                return False
        return True

    def _read(self) -> None:
        data = os.read(self._from_child, 1 << 20)
        if data:
            self._pending.extend(self._frames.feed(data))
        else:
            self._eof = True

    def frames(self) -> Iterator:
        """What the loop sends, in order, until its end of the pipe closes (blocking)."""
        while True:
            while self._pending:
                yield self._pending.popleft()
            if self._eof:
                return
            self._read()

    def wait_ready(self, timeout: float) -> float:
        """Block until the loop is ready (after its warm-up); return the line time. Raises
        LoopStartError with the loop's error if it ended instead, or after ``timeout`` [s]."""
        end = time.monotonic() + timeout
        while True:
            for item in self._pending:
                if item[0] == "ready":
                    self._pending.remove(item)
                    return float(item[1])
                if item[0] == "error":
                    raise LoopStartError(item[1].strip().splitlines()[-1])
            if self._eof:
                raise LoopStartError(f"line process exited ({self.proc.wait()}) before ready")
            left = end - time.monotonic()
            if left <= 0.0 or not select.select([self._from_child], [], [], left)[0]:
                raise LoopStartError(f"line process not ready after {timeout:g} s")
            self._read()

    def stop(self, timeout: float = 5.0) -> int | None:
        """Ask the loop to stop (it sends its last frames first) and reap the process."""
        self.send(("stop",))
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(timeout=timeout)

    def close(self) -> None:
        """Close our ends of the pipes, after the reader is done with :meth:`frames` (the
        loop's process, if still running, sees its input end and stops)."""
        with self._lock:
            if self._to_child >= 0:
                os.close(self._to_child)
                self._to_child = -1
        if self.proc.poll() is None:
            try:
                self.proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5.0)
        if self._from_child >= 0:
            os.close(self._from_child)
            self._from_child = -1


if __name__ == "__main__":
    # through the package's module, so what it pickles is fence_sorter.line.worker.X, not
    # __main__.X (which the node could not unpickle)
    from fence_sorter.line import worker

    raise SystemExit(worker.main(sys.argv[1:]))
