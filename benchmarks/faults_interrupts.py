"""The fault campaign's interrupts (see :mod:`benchmarks.faults`): a run started as from a
terminal, then SIGINT to its process group at a random moment, 2-5 times."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from benchmarks.faults_processes import start_watched


# -- interrupts ------------------------------------------------------------------------------
@dataclass
class InterruptTrial:
    first_signal_s: float
    signals: int
    exit_code: int | None
    exit_after_s: float  # from the first signal
    leftovers: int
    traceback: bool
    leftover_names: str = ""


def _names(pids: list[int]) -> str:
    """The leftovers' executables, e.g. "simulator, python (2)"."""
    names = Counter()
    for pid in pids:
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        words = [Path(a.decode(errors="replace")).name for a in argv if a]
        mod = next((w for w in words if w.startswith("fence_sorter.")), None)
        names[
            mod
            or (
                words[1]
                if len(words) > 1 and words[0].startswith("python")
                else words[0]
                if words
                else "?"
            )
        ] += 1
    return ", ".join(f"{n}" + (f" ({c})" if c > 1 else "") for n, c in sorted(names.items()))


def interrupt_trial(rng: random.Random, workdir: Path, parcels: int = 20) -> InterruptTrial:
    """One run interrupted by 2-5 SIGINTs (see the module docstring)."""
    log = workdir / f"interrupt-{time.time_ns()}.log"
    with open(log, "w") as out:
        proc, watch = start_watched(
            ("run", "--parcels", str(parcels)), workdir, out, subprocess.STDOUT
        )
    first = rng.uniform(0.0, 30.0)
    n = rng.randint(2, 5)
    t0 = time.monotonic()
    while time.monotonic() - t0 < first and proc.poll() is None:
        time.sleep(0.01)
    t_sig = time.monotonic()
    sent = 0
    for i in range(n):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, signal.SIGINT)
            sent += 1
        except ProcessLookupError:
            break
        if i < n - 1:
            time.sleep(rng.uniform(0.0, 0.5))
    try:
        proc.wait(timeout=60.0)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    exit_after = time.monotonic() - t_sig
    time.sleep(1.0)
    watch.poll()
    watch.done.set()
    left = watch.alive()
    names = _names(left)
    watch.kill_alive()
    text = log.read_text(errors="replace")
    return InterruptTrial(
        round(first, 2), sent, proc.returncode, exit_after, len(left), "Traceback" in text, names
    )
