"""Soft-real-time pacing of the line: a fixed grid of wall-clock deadlines on a steady clock.

Cycle k has the deadline ``start + k * period``; :meth:`Pacer.wait` sleeps until a margin
before it, busy-waits to it and returns the sim time the line should reach,
``sim0 + k * period * rtf``, so sim time stays locked to wall time. The margin follows the
sleeps' recent overshoot, capped by ``spin_margin``: a quiet machine burns little CPU spinning,
a loaded one spins longer. A cycle that wakes late
skips the deadlines already past (one cycle advances them all) up to ``max_catch_up`` of sim
time; the rest is dropped by moving the grid (a *slip*: sim time falls behind the wall clock
instead of racing to catch up). With ``rtf`` 0 nothing waits and each cycle advances
``unpaced_step`` of sim time. The clock and sleep functions are injectable for tests; nothing
here reads ROS time.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

#: smallest busy-wait before a deadline [s] (a sleep's wake-up costs ~50 us on Linux)
MIN_MARGIN = 5e-5
#: per-cycle decay of the busy-wait envelope (1/e in ~1000 cycles)
MARGIN_DECAY = 0.999


@dataclass
class Tick:
    """One cycle: its index on the grid, the sim time to reach, the deadline it was scheduled
    for and how late it woke (a cycle whose work ends after ``deadline + period`` missed), and
    the deadlines that passed while it waited to wake (cycles the loop did not run: each one
    is a missed deadline, so a loop stopped for 3 s at 1 kHz misses about 3000)."""

    k: int
    t_sim: float
    deadline: float  # wall [s] (inf when unpaced)
    lateness: float  # wake - deadline [s] (0 when unpaced)
    slipped: bool  # the catch-up cap dropped sim time in this cycle
    skipped: int = 0  # later deadlines already past at the wake: cycles not run


class Pacer:
    """Deadline grid for a loop with period ``period`` wall seconds at real-time factor ``rtf``."""

    def __init__(
        self,
        period: float,
        rtf: float,
        sim0: float = 0.0,
        max_catch_up: float = 0.1,
        spin_margin: float = 3e-4,
        unpaced_step: float | None = None,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ):
        if not period > 0.0 or not rtf >= 0.0 or not max_catch_up > 0.0:
            raise ValueError("period and max_catch_up must be > 0 and rtf >= 0")
        self.period = period
        self.max_catch_up = max_catch_up
        self.spin_margin = spin_margin
        # the busy-wait actually used: an envelope of recent sleep overshoots (jumps up at
        # once, decays by MARGIN_DECAY per cycle), between MIN_MARGIN and spin_margin
        self.margin = spin_margin
        self.unpaced_step = unpaced_step if unpaced_step is not None else period
        self.clock = clock
        self.sleep = sleep
        self.slips = 0
        self.restart(rtf, sim0)

    def restart(self, rtf: float, sim0: float) -> None:
        """Start a new grid now (at start-up or when the real-time factor changes)."""
        self.rtf = rtf
        self.start = self.clock()
        self.sim0 = sim0
        self.k = 0

    @property
    def next_deadline(self) -> float:
        """Wall time of the next cycle's deadline (inf when unpaced)."""
        return self.start + (self.k + 1) * self.period if self.rtf > 0.0 else math.inf

    def wait(self) -> Tick:
        """Wait for the next deadline; return the cycle's tick."""
        if self.rtf <= 0.0:
            self.k += 1
            return Tick(self.k, self.sim0 + self.k * self.unpaced_step, math.inf, 0.0, False)
        self.k += 1
        period = self.period
        deadline = self.start + self.k * period
        remaining = deadline - self.clock()
        if remaining > self.margin:
            wake = deadline - self.margin
            self.sleep(remaining - self.margin)
            overshoot = self.clock() - wake
            self.margin = min(
                max(MIN_MARGIN, 1.25 * overshoot, self.margin * MARGIN_DECAY), self.spin_margin
            )
        while self.clock() < deadline:
            pass
        late = self.clock() - deadline
        slipped = False
        if late >= period:
            behind = skipped = int(late / period)  # deadlines already past
            step = period * self.rtf
            if behind * step > self.max_catch_up:
                keep = int(self.max_catch_up / step)
                self.start += (behind - keep) * period  # drop the rest: sim time slips
                behind = keep
                self.slips += 1
                slipped = True
            self.k += behind
            return Tick(
                self.k, self.sim0 + self.k * period * self.rtf, deadline, late, slipped, skipped
            )
        return Tick(self.k, self.sim0 + self.k * period * self.rtf, deadline, late, slipped)


class LatenessHistogram:
    """Durations [s] in 10 us bins up to 100 ms (exact max kept): percentiles over a whole
    run in constant memory and O(1) per sample."""

    BIN = 1e-5
    BINS = 10_000

    def __init__(self) -> None:
        self.counts = np.zeros(self.BINS + 1, dtype=np.int64)
        self.n = 0
        self.max = 0.0

    def add(self, value: float) -> None:
        k = int(max(value, 0.0) / self.BIN)
        self.counts[min(k, self.BINS)] += 1
        self.n += 1
        if value > self.max:
            self.max = value

    def copy(self) -> LatenessHistogram:
        """An independent copy (take it under the writer's lock, compute outside)."""
        other = LatenessHistogram.__new__(LatenessHistogram)
        other.counts, other.n, other.max = self.counts.copy(), self.n, self.max
        return other

    def percentiles(self, qs: Sequence[float]) -> list[float]:
        """:meth:`percentile` of each q, with one cumulative sum."""
        if self.n == 0:
            return [math.nan for _ in qs]
        cum = np.cumsum(self.counts)
        out = []
        for q in qs:
            k = int(np.searchsorted(cum, max(math.ceil(q / 100.0 * self.n), 1)))
            out.append(min((k + 1) * self.BIN, self.max) if k < self.BINS else self.max)
        return out

    def percentile(self, q: float) -> float:
        """Upper edge of the bin holding the q-th percentile [s], capped at the max (NaN
        before any sample)."""
        if self.n == 0:
            return math.nan
        rank = max(math.ceil(q / 100.0 * self.n), 1)
        k = int(np.searchsorted(np.cumsum(self.counts), rank))
        return min((k + 1) * self.BIN, self.max) if k < self.BINS else self.max


class CycleTrace:
    """Per-cycle timing of a paced loop for diagnosing deadline misses: the deadline, the wake
    and the wall time after each phase of the cycle, with flags saying what the cycle did.
    Preallocated arrays (no allocation per cycle); when full, the oldest cycles are
    overwritten. :meth:`save` writes an ``.npz`` with one array per column, in cycle order."""

    #: wall times recorded per cycle: deadline, wake, then the end of each phase (inputs taken,
    #: physics advanced and events handed over: the cycle's due work is done; snapshots
    #: captured; frames sent, garbage collected, statistics; prefetch done)
    COLUMNS = ("deadline", "wake", "advanced", "published", "collected", "end")
    #: flag bits
    STATES, MARKERS, EVENTS, GC_YOUNG, GC_FULL, MISS = 1, 2, 4, 8, 16, 32

    def __init__(self, capacity: int = 600_000):
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        self.times = np.zeros((capacity, len(self.COLUMNS)))
        self.k = np.zeros(capacity, dtype=np.int64)
        self.flags = np.zeros(capacity, dtype=np.int32)
        self.n = 0  # cycles recorded (may exceed capacity)

    def record(self, k: int, times: Sequence[float], flags: int) -> None:
        i = self.n % len(self.k)
        self.k[i] = k
        self.times[i] = times
        self.flags[i] = flags
        self.n += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """The recorded cycles, oldest first, one array per column plus ``k`` and ``flags``."""
        cap = len(self.k)
        order = np.arange(self.n - cap, self.n) % cap if self.n > cap else np.arange(self.n)
        out = {name: self.times[order, j] for j, name in enumerate(self.COLUMNS)}
        out["k"], out["flags"] = self.k[order], self.flags[order]
        return out

    def save(self, path: str) -> None:
        np.savez_compressed(path, **self.arrays())


class PacedSteps:
    """Fixed steps of ``dt`` sim seconds paced on a :class:`Pacer` grid of period ``dt / rtf``
    wall seconds (``rtf`` 0: unpaced, one step per cycle as fast as the steps go).

    Each cycle runs the steps that bring sim time up to the tick's sim time: one on time,
    several after a late wake (the catch-up, up to the pacer's ``max_catch_up``; beyond it the
    grid slips). The steps themselves never change size, so pacing changes no physics figure,
    only when the steps happen. Counted as the simulator's loop counts: every deadline of the
    grid is a cycle; a deadline that passed while the loop did not run is a miss, and so is a
    cycle whose steps end after its deadline plus one period."""

    def __init__(
        self,
        dt: float,
        rtf: float,
        sim0: float = 0.0,
        max_catch_up: float = 0.1,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ):
        if not dt > 0.0 or not rtf >= 0.0:
            raise ValueError("dt must be > 0 and rtf >= 0")
        self.dt, self.rtf, self.clock = dt, rtf, clock
        self.period = dt / rtf if rtf > 0.0 else dt
        self.pacer = Pacer(
            self.period, rtf, sim0, max_catch_up, unpaced_step=dt, clock=clock, sleep=sleep
        )
        self.cycles = self.misses = self.steps = 0
        self.lateness, self.work = LatenessHistogram(), LatenessHistogram()

    def run(self, active: Callable[[], bool], step: Callable[[], float]) -> None:
        """Call ``step`` (one step of ``dt``; it returns the new sim time) while ``active()``."""
        t = self.pacer.sim0
        half = 0.5 * self.dt
        while active():
            tick = self.pacer.wait()
            while t < tick.t_sim - half and active():
                t = step()
                self.steps += 1
            self.cycles += 1 + tick.skipped
            self.misses += tick.skipped
            if self.rtf > 0.0:
                wake = tick.deadline + tick.lateness
                done = self.clock()
                self.lateness.add(tick.lateness)
                self.work.add(done - wake)
                if done > tick.deadline + self.period:
                    self.misses += 1

    def figures(self) -> dict:
        """The paced clock's counts for a summary (ms; NaN where unpaced)."""
        l50, l99 = self.lateness.percentiles((50, 99))
        w50, w99 = self.work.percentiles((50, 99))
        return {
            "real_time_factor_target": self.rtf,
            "period_s": self.period,
            "steps": self.steps,
            "cycles": self.cycles,
            "deadline_misses": self.misses,
            "deadline_miss_share": self.misses / self.cycles if self.cycles else math.nan,
            "catch_up_slips": self.pacer.slips,
            "lateness_p50_ms": 1e3 * l50,
            "lateness_p99_ms": 1e3 * l99,
            "lateness_max_ms": 1e3 * self.lateness.max if self.lateness.n else math.nan,
            "cycle_work_p50_ms": 1e3 * w50,
            "cycle_work_p99_ms": 1e3 * w99,
            "cycle_work_max_ms": 1e3 * self.work.max if self.work.n else math.nan,
        }
