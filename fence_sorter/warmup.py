"""Compile the physics kernel: ``python -m fence_sorter.warmup``.

scripts/bootstrap.sh runs it once per change of the physics sources, so that no ``simulate``
after set-up compiles (about a minute in silence otherwise) or goes through Numba's dispatcher
for its first solve. It solves a stiff and a flexible bench scene with the default adaptive
scheme (the compiled loop and every force and step function it calls, into Numba's on-disk
cache) and a short generalized-alpha solve (its step function), then builds the loop's
ahead-of-time extension (``kernel.aot``) for the signatures those solves compiled, and prints
one progress line per part.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from fence_sorter.physics import kernel
from fence_sorter.physics.kernel import aot
from fence_sorter.physics.simulate import simulate
from fence_sorter.scene import load_scene

PARTS = (
    ("compiled loop, stiff fence", "positioned_stiff", "adaptive"),
    ("compiled loop, flexible fence", "impact_flexible", "adaptive"),
    ("generalized-alpha step", "positioned_stiff", "generalized_alpha"),
)


def solve_bench_scenes(say=lambda line: None) -> None:
    """Solve each part once (compiling or loading the JIT's code); ``say`` one line each."""
    for label, scene, method in PARTS:
        t0 = time.perf_counter()
        sc = load_scene(scene).scenario
        if method != sc.solver.method:
            sc = replace(sc, solver=replace(sc.solver, method=method, t_end=0.05))
        simulate(sc)
        say(f"  kernel: {label} ready in {time.perf_counter() - t0:.1f} s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-aot", action="store_true", help="the JIT's cache only")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    entry = kernel.solve
    entry.entries = []  # the JIT solves: its cache, and the signatures the extension exports
    solve_bench_scenes(lambda line: print(line, flush=True))
    entry.entries = None  # looked up again on the next call
    if not args.no_aot and not aot.numba.config.DISABLE_JIT:
        print("  kernel: building the ahead-of-time solve (numba.pycc, gcc) ...", flush=True)
        t0 = time.perf_counter()
        aot.build(entry.directory, entry.digest, entry.jit)
        took = time.perf_counter() - t0
        print(f"  kernel: ahead-of-time solve built in {took:.1f} s", flush=True)
    print(f"  kernel: compiled in {time.perf_counter() - start:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
