"""Host stall probe: how long a bare busy loop loses the CPU on this machine.

A process that does nothing but read the steady clock sees every interval in which it did not
run as a gap between two consecutive readings. On a quiet bare-metal core the gaps stay in the
microseconds; on a shared virtual machine the hypervisor deschedules the vCPU (steal time)
and the gaps reach milliseconds whatever the guest does. A paced loop cannot meet a deadline
that falls inside such a gap, so :mod:`benchmarks.bench_suite` runs this probe
beside the node suite and reports the host's stalls next to the simulator's deadline misses.

The probe runs in a child process (``python -m benchmarks.stall_probe``) at
the simulator's pacing priority (SCHED_FIFO 50 when permitted, else normal scheduling, and
the report says which), so it competes for the CPU as the pacing thread does. It busy-waits
for the whole probe: run it on a machine with a core to spare, and only for seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import asdict, dataclass

#: gaps at or above this are recorded individually [s]
RECORD_GAP = 2e-4
#: busy burst and the rest between bursts [s] (duty 83 %, under the RT throttling budget)
BURST, REST = 0.5, 0.1


@dataclass
class StallReport:
    """Gaps between consecutive clock readings of a busy loop over ``duration`` seconds."""

    duration: float  # busy time probed [s]
    policy: str  # "SCHED_FIFO 50" or "SCHED_OTHER"
    readings: int
    gaps_over_0_5ms: int
    gaps_over_1ms: int
    gaps_over_2ms: int
    max_gap_ms: float
    stalled_ms: float  # total time in gaps >= RECORD_GAP [ms]

    def per_minute(self, count: int) -> float:
        """A gap count scaled to one minute of wall time."""
        return count * 60.0 / self.duration if self.duration > 0 else float("nan")


def busy_probe(
    duration: float, clock=time.perf_counter, sleep=time.sleep
) -> tuple[int, list[float]]:
    """Spin for ``duration`` s of busy time reading ``clock``; return the readings and every
    gap >= :data:`RECORD_GAP` (seconds).

    The spin runs in bursts of :data:`BURST` s with a :data:`REST` s sleep between them (not
    measured): a SCHED_FIFO task that never sleeps is throttled by the kernel's real-time
    budget (``sched_rt_runtime_us``, 0.95 s per second by default), a 50 ms gap a sleeping
    pacing loop never sees."""
    gaps: list[float] = []
    n = 0
    left = duration
    while left > 0.0:
        burst = min(BURST, left)
        prev = start = clock()
        end = start + burst
        while prev < end:
            t = clock()
            n += 1
            if t - prev >= RECORD_GAP:
                gaps.append(t - prev)
            prev = t
        left -= burst
        if left > 0.0:
            sleep(REST)
    return n, gaps


def summarise(duration: float, policy: str, readings: int, gaps: list[float]) -> StallReport:
    """Counts of the gaps over 0.5, 1 and 2 ms, the longest and the total stalled time."""
    return StallReport(
        duration=duration,
        policy=policy,
        readings=readings,
        gaps_over_0_5ms=sum(g >= 5e-4 for g in gaps),
        gaps_over_1ms=sum(g >= 1e-3 for g in gaps),
        gaps_over_2ms=sum(g >= 2e-3 for g in gaps),
        max_gap_ms=1e3 * max(gaps, default=0.0),
        stalled_ms=1e3 * sum(gaps),
    )


def _set_priority(priority: int) -> str:
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            return f"SCHED_FIFO {priority}"
        except (PermissionError, AttributeError, OSError):
            pass
    return "SCHED_OTHER"


def run_probe(duration: float, priority: int = 50, timeout: float | None = None) -> StallReport:
    """Run the probe in a child process (its scheduling policy stays there)."""
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.stall_probe",
        "--duration",
        repr(duration),
        "--priority",
        str(priority),
    ]
    done = subprocess.run(
        cmd, capture_output=True, text=True, timeout=timeout or duration + 30.0, check=True
    )
    return StallReport(**json.loads(done.stdout))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=10.0, help="probe length [s]")
    parser.add_argument("--priority", type=int, default=50, help="SCHED_FIFO priority; 0: normal")
    args = parser.parse_args(argv)
    if not 0.0 < args.duration <= 600.0 or not 0 <= args.priority <= 99:
        msg = "stall_probe: --duration must be in (0, 600] s, --priority in [0, 99]"
        print(msg, file=sys.stderr)
        return 2
    policy = _set_priority(args.priority)
    readings, gaps = busy_probe(args.duration)
    print(json.dumps(asdict(summarise(args.duration, policy, readings, gaps))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
