"""The speed bench's child processes: the kernel with and without the JIT, a cold Numba
cache, the resident memory of one event (see :mod:`benchmarks.bench`)."""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass

from benchmarks import REPO
from benchmarks.bench_runs import JIT_SCENE, JIT_T_END, Log, _median, _quiet

# -- child processes: JIT on / off, cold cache, resident memory -----------------------------------
_CHILD = r"""
import json, resource, sys, time
def hwm_kib():
    # VmHWM: this process's peak resident set (ru_maxrss can carry the parent's across exec)
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
from fence_sorter.physics.params import FenceParams
from fence_sorter.physics.scenario import RECORDABLE
from fence_sorter.scene import load_scene
from fence_sorter.physics.simulate import simulate
import numba
t_import = time.perf_counter() - t0
args = json.loads(sys.argv[1])
sc = load_scene(args["scene"], args["overrides"]).scenario
rss0 = hwm_kib()
walls, peaks, steps = [], [], []
for _ in range(args["runs"]):
    t = time.perf_counter()
    r = simulate(sc)
    walls.append(time.perf_counter() - t)
    peaks.append(r.peak_contact_force)
    steps.append(r.steps)
print(json.dumps({
    "import_s": t_import, "walls": walls, "peaks": peaks, "steps": steps,
    "sim_time": r.sim_time, "success": r.success,
    "rss_after_import_kib": rss0,
    "rss_kib": hwm_kib(),
    "jit_disabled": bool(numba.config.DISABLE_JIT),
}))
"""


def run_child(scene: str, overrides: Sequence[str], runs: int, env_changes: dict) -> dict:
    """Run ``simulate`` ``runs`` times on a scene in a fresh Python process; its JSON report."""
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop("NUMBA_CACHE_DIR", None)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env.update(env_changes)
    arg = json.dumps({"scene": scene, "overrides": list(overrides), "runs": runs})
    p = subprocess.run(
        [sys.executable, "-c", _CHILD, arg],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
        timeout=1800,
        check=False,
    )
    if p.returncode != 0:
        tail = (p.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"benchmark child process failed ({p.returncode}): {tail}")
    return json.loads(p.stdout.strip().splitlines()[-1])


@dataclass
class JitResult:
    scene: str
    t_end: float
    sim_time: float
    steps: int
    jit_walls: list[float]  # warm calls, JIT on (the warm-up call excluded)
    nojit_walls: list[float]  # NUMBA_DISABLE_JIT=1 (the first call excluded)
    jit_peak: float
    nojit_peak: float
    jit_child_confirmed: bool  # the child reported the JIT disabled
    warm_cache_first_call: float  # [s] first call with the on-disk cache
    cold_first_call: float = math.nan  # [s] first call with an empty cache (compilation)
    cold_second_call: float = math.nan
    cold_scene: str = ""

    @property
    def jit_wall(self) -> float:
        return _median(self.jit_walls)

    @property
    def nojit_wall(self) -> float:
        return _median(self.nojit_walls)

    @property
    def ratio(self) -> float:
        return self.nojit_wall / self.jit_wall if self.jit_wall > 0 else math.nan


def jit_comparison(jit_repeats: int, nojit_repeats: int, cold: bool, log: Log = _quiet):
    overrides = [f"solver.t_end={JIT_T_END}"]
    log(f"JIT on: {JIT_SCENE} to t = {JIT_T_END} s, 1 + {jit_repeats} calls in a fresh process")
    on = run_child(JIT_SCENE, overrides, 1 + jit_repeats, {})
    log(f"JIT off (NUMBA_DISABLE_JIT=1): 1 + {nojit_repeats} calls in a fresh process")
    off = run_child(JIT_SCENE, overrides, 1 + nojit_repeats, {"NUMBA_DISABLE_JIT": "1"})
    res = JitResult(
        scene=JIT_SCENE,
        t_end=JIT_T_END,
        sim_time=on["sim_time"],
        steps=on["steps"][-1],
        jit_walls=on["walls"][1:],
        nojit_walls=off["walls"][1:],
        jit_peak=on["peaks"][-1],
        nojit_peak=off["peaks"][-1],
        jit_child_confirmed=off["jit_disabled"] and not on["jit_disabled"],
        warm_cache_first_call=on["walls"][0],
    )
    if cold:
        log(f"cold Numba cache: first call of {JIT_SCENE} (compiles the kernel)")
        with tempfile.TemporaryDirectory(prefix="fence_sorter_numba_") as d:
            c = run_child(JIT_SCENE, [], 2, {"NUMBA_CACHE_DIR": d})
        res.cold_first_call, res.cold_second_call = c["walls"][0], c["walls"][1]
        res.cold_scene = JIT_SCENE
    return res


def peak_rss_kib() -> int:
    """This process's peak resident set size [KiB] (VmHWM; getrusage's ru_maxrss without
    /proc)."""
    try:
        with open("/proc/self/status", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


@dataclass
class MemoryResult:
    scene: str
    tracemalloc_peak: int  # [bytes] one default run, in this process
    rss_after_import_kib: int  # fresh process: imports and scene loaded
    rss_after_run_kib: int  # fresh process: after one event
