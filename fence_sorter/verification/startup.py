"""Where a new process's first solve spends its time (a benchmark, not a test).

``python -m fence_sorter.verification.startup [--scene NAME] [--rounds N]``.

Each round starts a fresh interpreter that times, in order: importing NumPy and SciPy's linear
algebra, Numba, the physics (``physics.simulate``: the kernel's dispatchers, no compilation),
loading a scene, the first ``simulate`` (Numba's first-use set-up of its typing and target
contexts, then loading the cached machine code of the solve loop), and a second ``simulate``
(the solve itself). It also times ``import rclpy``, which every node process pays. Medians over
the rounds; the kernel must have been compiled into the cache first (scripts/bootstrap.sh does).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

PROBE = r"""
import json, sys, time
t = [time.perf_counter()]
import numpy, scipy.linalg
t.append(time.perf_counter())
import numba
t.append(time.perf_counter())
from fence_sorter.physics.simulate import simulate
t.append(time.perf_counter())
from fence_sorter.scene import load_scene
sc = load_scene(sys.argv[1]).scenario
t.append(time.perf_counter())
simulate(sc)
t.append(time.perf_counter())
simulate(sc)
t.append(time.perf_counter())
print(json.dumps([b - a for a, b in zip(t, t[1:])]))
"""
PARTS = (
    "import numpy, scipy.linalg",
    "import numba",
    "import physics.simulate",
    "load the scene",
    "first simulate",
    "second simulate",
)
RCLPY = "import time; t = time.perf_counter(); import rclpy; print(time.perf_counter() - t)"


def measure(scene: str, rounds: int) -> dict[str, float]:
    """Median seconds of each part over ``rounds`` fresh interpreters."""
    samples: list[list[float]] = []
    rclpy: list[float] = []
    for _ in range(rounds):
        out = subprocess.run(
            [sys.executable, "-c", PROBE, scene], check=True, capture_output=True, text=True
        )
        samples.append(json.loads(out.stdout.strip().splitlines()[-1]))
        out = subprocess.run([sys.executable, "-c", RCLPY], capture_output=True, text=True)
        if out.returncode == 0:
            rclpy.append(float(out.stdout.strip().splitlines()[-1]))
    medians = {name: statistics.median(s[k] for s in samples) for k, name in enumerate(PARTS)}
    if rclpy:
        medians["import rclpy (a node's own)"] = statistics.median(rclpy)
    return medians


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="positioned_stiff")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error(f"--rounds must be >= 1, got {args.rounds}")
    medians = measure(args.scene, args.rounds)
    print(f"{args.scene}, median of {args.rounds} fresh processes")
    for name, seconds in medians.items():
        print(f"  {name:30s} {1e3 * seconds:9.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
