"""Compile the physics kernel into Numba's on-disk cache: ``python -m ...physics.warmup``.

scripts/bootstrap.sh runs it once per change of the physics sources, so that the first
``simulate`` after set-up loads compiled code instead of compiling for about a minute in
silence. It solves a stiff and a flexible bench scene with the default adaptive scheme (the
compiled loop and every force and step function it calls) and a short generalized-alpha solve
(its step function), and prints one progress line per part.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from fence_sorter.scene import load_scene

from .simulate import simulate

PARTS = (
    ("compiled loop, stiff fence", "positioned_stiff", "adaptive"),
    ("compiled loop, flexible fence", "impact_flexible", "adaptive"),
    ("generalized-alpha step", "positioned_stiff", "generalized_alpha"),
)


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    start = time.perf_counter()
    for label, scene, method in PARTS:
        t0 = time.perf_counter()
        sc = load_scene(scene).scenario
        if method != sc.solver.method:
            sc = replace(sc, solver=replace(sc.solver, method=method, t_end=0.05))
        simulate(sc)
        print(f"  kernel: {label} ready in {time.perf_counter() - t0:.1f} s", flush=True)
    print(f"  kernel: compiled in {time.perf_counter() - start:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
