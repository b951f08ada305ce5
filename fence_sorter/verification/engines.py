"""The two control loops timed side by side: ``python -m fence_sorter.verification.engines``.

``solver.engine = python`` (``integrators.Integrator``) and ``compiled`` (``kernel.solve``) on the
bench scenes, interleaved, as ``fence-sorter bench`` times an event; the bench reports it.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import gc
import os
import statistics
import time

from fence_sorter.physics.engine import collector_off
from fence_sorter.physics.simulate import SortingModel, simulate
from fence_sorter.scene import load_scene

BENCH_SCENES = ("impact_flexible", "slide_flexible", "positioned_stiff", "arbitrary_stiff")


def compare_engines(scenes=BENCH_SCENES, repeats: int = 7) -> list[dict]:
    """Wall time per event of each scene (as ``fence-sorter bench`` times it: ``simulate`` on a
    freshly built model, the garbage collector off during the call and a collection before the
    repeats), python and compiled loop interleaved, medians of ``repeats``."""
    rows = []
    for name in scenes:
        sc = load_scene(name).scenario
        runs = {
            e: dc.replace(sc, solver=dc.replace(sc.solver, engine=e))
            for e in ("python", "compiled")
        }
        walls: dict[str, list[float]] = {e: [] for e in runs}
        cpus: dict[str, list[float]] = {e: [] for e in runs}
        results = {e: simulate(s) for e, s in runs.items()}  # warm-up (loads the JIT cache)
        gc.collect()  # before the block of repeats; the collector is off during each call
        for _ in range(repeats):
            for e, s in runs.items():
                with collector_off():
                    c0 = time.process_time()
                    t0 = time.perf_counter()
                    results[e] = simulate(s, SortingModel(s))
                    walls[e].append(time.perf_counter() - t0)
                    cpus[e].append(time.process_time() - c0)
        med = {e: statistics.median(w) for e, w in walls.items()}
        cpu = {e: statistics.median(c) for e, c in cpus.items()}
        sim = results["compiled"].sim_time
        rows.append(
            {
                "scene": name,
                "sim_time": float(sim),
                "steps": int(results["compiled"].steps),
                "python_ms": 1e3 * med["python"],
                "compiled_ms": 1e3 * med["compiled"],
                "python_rtf": sim / med["python"],
                "compiled_rtf": sim / med["compiled"],
                "speedup": med["python"] / med["compiled"],
                "python_cpu_ms": 1e3 * cpu["python"],
                "compiled_cpu_ms": 1e3 * cpu["compiled"],
                "same_peak": bool(
                    results["python"].peak_contact_force == results["compiled"].peak_contact_force
                ),
            }
        )
    return rows


def main(argv=None) -> int:
    """``python -m fence_sorter.verification.engines [--repeats N] [scene ...]``: the side-by-side
    timing of the two loops."""
    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("scenes", nargs="*", default=list(BENCH_SCENES))
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f"--repeats must be >= 1, got {args.repeats}")
    print(
        f"median of {args.repeats}, model build included, python and compiled interleaved; "
        f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}"
    )
    print(
        f"{'scene':18s} {'sim [s]':>8s} {'steps':>6s} {'python [ms]':>12s} "
        f"{'compiled [ms]':>14s} {'python RTF':>11s} {'compiled RTF':>13s} {'speed-up':>9s} "
        f"{'CPU python/compiled [ms]':>25s}"
    )
    for r in compare_engines(args.scenes, args.repeats):
        print(
            f"{r['scene']:18s} {r['sim_time']:8.3f} {r['steps']:6d} {r['python_ms']:12.2f} "
            f"{r['compiled_ms']:14.2f} {r['python_rtf']:10.1f}x {r['compiled_rtf']:12.1f}x "
            f"{r['speedup']:8.2f}x {r['python_cpu_ms']:12.2f} / {r['compiled_cpu_ms']:<10.2f}"
            + ("" if r["same_peak"] else "  (peak N differs!)")
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
