"""The pacing grid (fence_sorter.line.pacing) on a fake clock: deadlines, catch-up, slips."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fence_sorter.line.pacing import MIN_MARGIN, LatenessHistogram, PacedSteps, Pacer


class FakeClock:
    """A steady clock that sleeps exactly; every reading advances it 1 us (a busy-wait ends)."""

    def __init__(self) -> None:
        self.now = 100.0
        self.oversleep = 0.0  # added to every sleep (a loaded machine wakes late)
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        self.now += 1e-6
        return self.now

    def sleep(self, dt: float) -> None:
        self.sleeps.append(dt)
        self.now += dt + self.oversleep


def pacer(clock: FakeClock, **kw) -> Pacer:
    base = dict(period=1e-3, rtf=1.0, sim0=5.0, max_catch_up=0.01, spin_margin=3e-4)
    base.update(kw)
    return Pacer(clock=clock, sleep=clock.sleep, **base)


def test_cycles_follow_the_grid_and_lock_sim_time_to_wall_time():
    clock = FakeClock()
    p = pacer(clock, rtf=2.0)
    for k in range(1, 6):
        tick = p.wait()
        assert tick.k == k
        assert tick.deadline == pytest.approx(100.0 + k * 1e-3)
        assert tick.t_sim == pytest.approx(5.0 + 2.0 * k * 1e-3)  # period x rtf per cycle
        assert clock.now >= tick.deadline and tick.lateness == pytest.approx(0.0, abs=1e-5)
        clock.now += 2e-4  # the cycle's work
    # it slept until spin_margin before each deadline (the rest is the busy-wait)
    assert clock.sleeps[1] == pytest.approx(1e-3 - 2e-4 - 3e-4, abs=1e-5)


def test_a_late_cycle_catches_up_in_one_step():
    clock = FakeClock()
    p = pacer(clock)
    p.wait()
    clock.now += 3.5e-3  # a stall of 3.5 periods
    tick = p.wait()
    assert tick.lateness == pytest.approx(2.5e-3, abs=1e-5)
    assert tick.k == 4 and tick.t_sim == pytest.approx(5.0 + 4e-3)  # no sim time lost
    assert not tick.slipped and p.slips == 0
    assert p.wait().k == 5


def test_catch_up_beyond_the_cap_slips_sim_time():
    clock = FakeClock()
    p = pacer(clock, max_catch_up=0.01)
    p.wait()
    clock.now += 0.1  # 100 periods lost, the cap allows 10 ms of sim
    tick = p.wait()
    assert tick.slipped and p.slips == 1
    assert tick.t_sim == pytest.approx(5.0 + 2e-3 + 0.01, abs=1e-9)
    # the grid moved: the next cycle is on time again, one period later
    nxt = p.wait()
    assert nxt.lateness == pytest.approx(0.0, abs=1e-5)
    assert nxt.t_sim - tick.t_sim == pytest.approx(1e-3)


@pytest.mark.parametrize("stop_s", [0.004, 0.1, 3.0])
def test_a_stopped_loop_reports_every_deadline_it_did_not_run(stop_s: float):
    """A loop stopped for ``stop_s`` (SIGSTOP, a starved CPU) wakes once; the deadlines that
    passed meanwhile are cycles not run: floor(lateness / period) of them, with or without a
    slip (3 s at 1 kHz: 2999 skipped, the late wake-up itself the 3000th miss)."""
    clock = FakeClock()
    p = pacer(clock, max_catch_up=0.01)
    first = p.wait()
    clock.now += stop_s
    tick = p.wait()
    assert tick.skipped == math.floor(tick.lateness / 1e-3)
    assert tick.skipped == round(stop_s / 1e-3) - 1  # the first deadline is the wake's own
    # the grid index counts every deadline (run, skipped or dropped by a slip) up to the cap
    kept = min(tick.skipped, int(0.01 / 1e-3))
    assert tick.k == first.k + 1 + kept
    assert p.wait().skipped == 0  # on time again


def test_unpaced_never_waits():
    clock = FakeClock()
    p = pacer(clock, rtf=0.0, unpaced_step=0.02)
    ticks = [p.wait() for _ in range(3)]
    assert [t.t_sim for t in ticks] == pytest.approx([5.02, 5.04, 5.06])
    assert clock.sleeps == [] and math.isinf(ticks[0].deadline)
    p.restart(1.0, 5.06)
    assert p.wait().t_sim == pytest.approx(5.061)


def test_histogram_percentiles():
    h = LatenessHistogram()
    assert math.isnan(h.percentile(50))
    for i in range(1000):
        h.add(i * 1e-6)  # 0 .. 0.999 ms
    h.add(0.5)  # beyond the last bin: counted, max exact
    assert h.percentile(50) == pytest.approx(0.5e-3, abs=2e-5)  # one 10 us bin
    assert h.percentile(99) == pytest.approx(0.99e-3, abs=2e-5)
    assert h.percentile(100) == 0.5 and h.max == 0.5


def test_busy_wait_follows_the_sleep_overshoot():
    clock = FakeClock()
    p = pacer(clock, spin_margin=4e-4)
    for _ in range(5000):  # exact sleeps: the margin decays to its floor
        p.wait()
    assert p.margin == pytest.approx(MIN_MARGIN)
    clock.oversleep = 1.2e-4  # sleeps now wake 0.12 ms late
    tick = p.wait()
    assert p.margin == pytest.approx(1.25 * 1.2e-4, rel=0.05)
    assert tick.lateness < 1.2e-4  # this one still woke late, after the margin it had
    assert p.wait().lateness == pytest.approx(0.0, abs=1e-5)  # the next is on time
    clock.oversleep = 5e-3  # a long preemption: the margin stops at its cap
    p.wait()
    assert p.margin == 4e-4


def test_cycle_trace_keeps_the_last_cycles_in_order():
    from fence_sorter.line.pacing import CycleTrace

    trace = CycleTrace(capacity=4)
    for k in range(1, 7):
        times = [k + 0.1 * j for j in range(len(CycleTrace.COLUMNS))]
        trace.record(k, times, CycleTrace.MISS if k % 2 else 0)
    a = trace.arrays()
    assert list(a["k"]) == [3, 4, 5, 6] and trace.n == 6
    assert list(a["deadline"]) == [3.0, 4.0, 5.0, 6.0]
    assert np.allclose(a["end"] - a["deadline"], 0.1 * (len(CycleTrace.COLUMNS) - 1))
    assert list(a["flags"]) == [CycleTrace.MISS, 0, CycleTrace.MISS, 0]
    with pytest.raises(ValueError, match="capacity"):
        CycleTrace(capacity=0)


def test_histogram_percentiles_in_one_pass_match_one_at_a_time():
    rng = np.random.default_rng(3)
    h = LatenessHistogram()
    assert all(math.isnan(v) for v in h.percentiles((50.0, 99.0)))
    for v in rng.exponential(2e-4, 5000):
        h.add(float(v))
    qs = (50.0, 90.0, 99.0, 99.9, 100.0)
    assert h.percentiles(qs) == [h.percentile(q) for q in qs]
    c = h.copy()
    h.add(0.05)
    assert c.n == h.n - 1 and c.max < 0.05 and c.percentiles(qs) != h.percentiles(qs)


class Steps:
    """A line of fixed steps on the fake clock: each step costs ``cost[j]`` wall seconds
    (0 when not given) and advances sim time by dt."""

    def __init__(self, clock: FakeClock, dt: float, n: int, cost: dict[int, float] | None = None):
        self.clock, self.dt, self.n, self.cost = clock, dt, n, cost or {}
        self.t = 0.0
        self.times: list[float] = []  # sim time at the start of each step

    def active(self) -> bool:
        return len(self.times) < self.n

    def step(self) -> float:
        self.times.append(self.t)
        self.clock.now += self.cost.get(len(self.times), 0.0)
        self.t += self.dt
        return self.t


def paced(clock: FakeClock, rtf: float, **kw) -> PacedSteps:
    return PacedSteps(0.01, rtf, 0.0, clock=clock, sleep=clock.sleep, **kw)


def test_paced_steps_are_the_unpaced_steps_and_a_late_one_is_counted():
    """rtf 2 (period 5 ms): step 5 costs 3.5 periods. Its cycle ends 2.5 periods after its
    deadline's period (a miss); the next wake finds 2 more deadlines past (2 misses) and runs
    3 steps to catch up, ending more than a period late as well (a miss): 4 misses of 20
    cycles, no slip, and the same 20 steps of 10 ms as unpaced, in the same order."""
    free = Steps(FakeClock(), 0.01, 20)
    unpaced = paced(FakeClock(), 0.0)
    unpaced.run(free.active, free.step)
    assert unpaced.steps == unpaced.cycles == 20 and unpaced.figures()["deadline_misses"] == 0
    assert math.isnan(unpaced.figures()["lateness_p99_ms"])

    clock = FakeClock()
    line = Steps(clock, 0.01, 20, {5: 3.5 * 5e-3})
    p = paced(clock, 2.0)
    t0 = clock.now
    p.run(line.active, line.step)
    assert line.times == free.times  # pacing changes when, never what
    f = p.figures()
    assert (f["steps"], f["cycles"], f["deadline_misses"], f["catch_up_slips"]) == (20, 20, 4, 0)
    assert f["deadline_miss_share"] == pytest.approx(0.2)
    assert f["period_s"] == pytest.approx(5e-3)
    # locked to wall time: 20 cycles of 5 ms (the last one's deadline)
    assert clock.now - t0 == pytest.approx(20 * 5e-3, abs=1e-4)


def test_paced_steps_slip_beyond_the_catch_up_cap_without_dropping_a_step():
    """rtf 1: step 3 stalls 0.5 s (50 periods); the cap (0.1 s) keeps 10 steps of catch-up
    and slips the rest: 1 slip, 49 deadlines past counted missed, every step still 10 ms."""
    clock = FakeClock()
    line = Steps(clock, 0.01, 40, {3: 0.5})
    p = paced(clock, 1.0)
    p.run(line.active, line.step)
    f = p.figures()
    assert f["catch_up_slips"] == 1 and f["steps"] == 40
    assert np.allclose(np.diff(line.times), 0.01)
    assert f["deadline_misses"] == 1 + 49 + 1  # the stalled cycle, the deadlines past, catch-up
    assert f["cycles"] == f["steps"] + 49 - 10  # the slipped deadlines were cycles not run


def test_paced_steps_refuse_a_bad_rate():
    with pytest.raises(ValueError):
        PacedSteps(0.01, -1.0)
    with pytest.raises(ValueError):
        PacedSteps(0.0, 1.0)
