"""Keep the CPUs from halting while a paced loop sleeps between its deadlines.

A guest without a cpuidle driver (this project's Firecracker VMs: ``cpuidle/current_driver``
is ``none``) idles with HLT, which exits to the hypervisor; a sleeping thread's timer then
wakes it only when the host runs the vCPU again, milliseconds later on a busy host. Writing 0
to ``/dev/cpu_dma_latency`` (what cyclictest does) has no effect without a cpuidle driver. One
busy process per CPU at ``SCHED_IDLE`` keeps each vCPU running instead: it gets the CPU only
when nothing else wants it (weight 3 against a nice-0 task's 1024), so it costs other work
nothing measurable, and the loop's timer interrupt finds the vCPU awake. The price is power
and a "100 % CPU" line in ``top``.

The spinners die with their parent (``PR_SET_PDEATHSIG``) and live in its process group.
"""

from __future__ import annotations

import os
import subprocess
import sys

#: the spinner: pin to one CPU, drop to SCHED_IDLE, die with the parent, spin
_SPIN = """
import ctypes, os, signal, sys
cpu, parent = int(sys.argv[1]), int(sys.argv[2])
ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
if os.getppid() != parent:
    sys.exit(0)
os.sched_setaffinity(0, {cpu})
os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
while True:
    pass
"""


def start_spinners(cpus: set[int] | None = None) -> list[subprocess.Popen]:
    """One SCHED_IDLE busy process per CPU of ``cpus`` (default: this process's affinity)."""
    cpus = set(os.sched_getaffinity(0)) if cpus is None else cpus
    return [
        subprocess.Popen(
            [sys.executable, "-c", _SPIN, str(cpu), str(os.getpid())],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for cpu in sorted(cpus)
    ]


def stop_spinners(procs: list[subprocess.Popen]) -> None:
    """Kill and reap the spinners."""
    for p in procs:
        if p.poll() is None:
            p.kill()
    for p in procs:
        p.wait(timeout=5.0)
