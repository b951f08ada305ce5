"""The host stall probe finds the gaps a descheduled busy loop sees, and runs as a child."""

from __future__ import annotations

import pytest

from benchmarks.stall_probe import busy_probe, run_probe, summarise


def test_busy_probe_reports_each_gap_of_a_scripted_clock():
    # readings 10 us apart with a 0.7 ms and a 3 ms jump (the loop lost the CPU twice), in
    # one burst
    steps = [1e-5] * 49 + [7e-4] + [1e-5] * 99 + [3e-3] + [1e-5] * 999
    readings = [0.0]
    for dt in steps:
        readings.append(readings[-1] + dt)
    ticks = iter(readings)

    def clock() -> float:
        return next(ticks)

    slept: list[float] = []
    import benchmarks.stall_probe as sp

    burst, sp.BURST = sp.BURST, 0.005
    try:
        n, gaps = busy_probe(0.0045, clock=clock, sleep=slept.append)
    finally:
        sp.BURST = burst
    assert slept == []  # one burst
    assert gaps == pytest.approx([7e-4, 3e-3], abs=1e-12)
    r = summarise(0.0045, "test", n, gaps)
    assert (r.gaps_over_0_5ms, r.gaps_over_1ms, r.gaps_over_2ms) == (2, 1, 1)
    assert r.max_gap_ms == pytest.approx(3.0) and r.stalled_ms == pytest.approx(3.7)
    assert r.per_minute(r.gaps_over_1ms) == pytest.approx(60.0 / 0.0045)


def test_probe_child_process_reports_its_policy():
    r = run_probe(0.05, priority=0)
    assert r.policy == "SCHED_OTHER" and r.readings > 1000
    assert r.gaps_over_2ms <= r.gaps_over_1ms <= r.gaps_over_0_5ms


@pytest.mark.parametrize(
    "args", [("--duration", "0"), ("--duration", "601"), ("--priority", "100")]
)
def test_bad_probe_options_exit_2_naming_the_range(args):
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.stall_probe", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert "--duration must be in (0, 600] s, --priority in [0, 99]" in done.stderr
    assert "Traceback" not in done.stderr
