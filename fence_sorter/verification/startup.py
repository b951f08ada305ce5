"""Where a new process's first solve spends its time (a benchmark, not a test).

``python -m fence_sorter.verification.startup [--scene NAME ...] [--rounds N] [--out DIR]``.

Each round starts a fresh interpreter per scene that times, in order: importing NumPy and
SciPy's linear algebra, Numba, the physics (``physics.simulate``: the kernel's dispatchers, no
compilation), loading a scene, the first ``simulate`` (through the loop's ahead-of-time
extension when it is built for the current sources, else Numba's first-use set-up and the
cached machine code) and a second ``simulate`` (the solve itself); the first ``simulate``
once more through the JIT (FENCE_SORTER_AOT=0) for comparison; and, in its own
interpreter, ``import rclpy``, which every node process pays. Medians over the rounds, printed
and written as ``startup.json`` and ``README.md`` (rendered from the JSON) into ``--out``
(default docs/startup/), with the command, the revision and the load average. The kernel must
have been compiled first (scripts/bootstrap.sh does).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

from .machine import REPO, git_revision, load_average, machine_info
from .report import fmt, table

PROBE = r"""
import json, sys, time
t = [time.perf_counter()]
import numpy, scipy.linalg
t.append(time.perf_counter())
import numba
t.append(time.perf_counter())
from fence_sorter.physics.simulate import simulate
from fence_sorter.physics import kernel
t.append(time.perf_counter())
from fence_sorter.scene import load_scene
sc = load_scene(sys.argv[1]).scenario
t.append(time.perf_counter())
simulate(sc)
t.append(time.perf_counter())
simulate(sc)
t.append(time.perf_counter())
print(json.dumps({"parts": [b - a for a, b in zip(t, t[1:])], "aot": bool(kernel.solve.entries)}))
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
NODE = (
    "import sys, time; t = time.perf_counter(); import importlib; "
    "importlib.import_module(sys.argv[1]); print(time.perf_counter() - t)"
)
NODES = ("controller", "simulator", "scanner", "recorder")
#: fence-sorter run's line "nodes up in 4.2 s (heartbeats: controller 3.1 s, ...); running"
NODES_UP = re.compile(r"nodes up in ([0-9.]+) s \(heartbeats: ([^)]*)\)")
FIRST_SOLVE_TARGET = 0.050  # [s] issue 19: a new process's first solve


def _probe(scene: str, aot: bool) -> dict:
    env = dict(os.environ, FENCE_SORTER_AOT="1" if aot else "0")
    out = subprocess.run(
        [sys.executable, "-c", PROBE, scene], check=True, capture_output=True, text=True, env=env
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure(scene: str, rounds: int) -> dict:
    """Median seconds of each part over ``rounds`` fresh interpreters; whether the first
    solve went through the ahead-of-time extension in every round; the median first solve
    through the JIT dispatcher (FENCE_SORTER_AOT=0), for comparison."""
    samples: list[list[float]] = []
    jit: list[float] = []
    aot = True
    for _ in range(rounds):
        probe = _probe(scene, aot=True)
        samples.append(probe["parts"])
        aot = aot and probe["aot"]
        jit.append(_probe(scene, aot=False)["parts"][PARTS.index("first simulate")])
    medians = {name: statistics.median(s[k] for s in samples) for k, name in enumerate(PARTS)}
    return {"scene": scene, "aot": aot, "seconds": medians, "jit_first": statistics.median(jit)}


def measure_rclpy(rounds: int) -> float | None:
    """Median seconds of ``import rclpy`` in a fresh interpreter (None without rclpy)."""
    times = []
    for _ in range(rounds):
        out = subprocess.run([sys.executable, "-c", RCLPY], capture_output=True, text=True)
        if out.returncode != 0:
            return None
        times.append(float(out.stdout.strip().splitlines()[-1]))
    return statistics.median(times)


def measure_nodes(rounds: int) -> dict[str, float]:
    """Median seconds of importing each node's module in a fresh interpreter."""
    out = {}
    for node in NODES:
        times = []
        for _ in range(rounds):
            proc = subprocess.run(
                [sys.executable, "-c", NODE, f"fence_sorter.nodes.{node}"],
                check=True,
                capture_output=True,
                text=True,
            )
            times.append(float(proc.stdout.strip().splitlines()[-1]))
        out[node] = statistics.median(times)
    return out


def measure_run(rounds: int) -> list[dict]:
    """``fence-sorter run --parcels 1`` ``rounds`` times: seconds to "nodes up" and to each
    node's first heartbeat, as the run prints them."""
    runs = []
    for _ in range(rounds):
        proc = subprocess.run(
            [sys.executable, "-m", "fence_sorter.cli.main", "run", "--parcels", "1"],
            capture_output=True,
            text=True,
        )
        found = NODES_UP.search(proc.stdout)
        if proc.returncode != 0 or not found:
            raise RuntimeError(
                f"fence-sorter run failed ({proc.returncode}): {proc.stdout[-800:]}"
            )
        beats = dict(b.rsplit(" ", 2)[:2] for b in found.group(2).split(", "))
        runs.append({"nodes_up": float(found.group(1)), **{k: float(v) for k, v in beats.items()}})
    return runs


def render(data: dict) -> str:
    """README.md of the start-up figures, from ``startup.json`` alone."""
    scenes = data["scenes"]
    rows = [
        [part] + [fmt(1e3 * s["seconds"][part], ".1f") for s in scenes] for part in data["parts"]
    ]
    rows.append(
        ["first solve through the ahead-of-time extension"]
        + ["yes" if s["aot"] else "no (JIT)" for s in scenes]
    )
    rows.append(
        ["first simulate through the JIT dispatcher (FENCE_SORTER_AOT=0)"]
        + [fmt(1e3 * s["jit_first"], ".1f") for s in scenes]
    )
    m = data["machine"]
    lines = [
        "# Start-up of a process",
        "",
        f"Written by `{data['command']}` at {data['revision']} from `startup.json`; do not edit "
        'by hand. What the parts are and why: docs/numerics.md, "Start-up of a process".',
        "",
        f"Median of {data['rounds']} fresh interpreters per scene, in ms. Machine: {m['cpu']}, "
        f"{m['cores']}; load average {data['load_average']} at the start.",
        "",
        *table(["part [ms]", *(s["scene"] for s in scenes)], rows),
        "",
    ]
    if data.get("import_rclpy") is not None:
        lines += [
            f"`import rclpy` in a fresh interpreter (each node process): "
            f"{1e3 * data['import_rclpy']:.1f} ms.",
            "",
        ]
    if data.get("node_imports"):
        lines += [
            "Importing each node's module in a fresh interpreter (median, ms): "
            + ", ".join(f"{n} {1e3 * t:.0f}" for n, t in data["node_imports"].items())
            + ".",
            "",
        ]
    if data.get("runs"):
        keys = list(data["runs"][0])
        lines += [
            "`fence-sorter run --parcels 1` (real-time factor 1), seconds from the runner's start "
            'to each node\'s first heartbeat and to "nodes up":',
            "",
            *table(
                ["run", *keys],
                [
                    [k + 1, *(fmt(r.get(c), ".1f") for c in keys)]
                    for k, r in enumerate(data["runs"])
                ],
            ),
            "",
        ]
    target = 1e3 * data["first_solve_target"]
    worst = max(1e3 * s["seconds"]["first simulate"] for s in scenes)
    verdict = "met" if worst <= target else "not met"
    lines += [f"First solve <= {target:.0f} ms: {verdict} (slowest scene {worst:.1f} ms).", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--scene", action="append", help="bench scene (repeatable; default two scenes)"
    )
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--runs", type=int, default=3, help="fence-sorter runs to time (0: none)")
    ap.add_argument("--out", default=str(REPO / "docs" / "startup"), help="'' writes nothing")
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error(f"--rounds must be >= 1, got {args.rounds}")
    scenes = args.scene or ["positioned_stiff", "impact_flexible"]
    data = {
        "command": "python -m fence_sorter.verification.startup "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "revision": git_revision(),
        "load_average": load_average(),
        "machine": machine_info(),
        "rounds": args.rounds,
        "parts": list(PARTS),
        "first_solve_target": FIRST_SOLVE_TARGET,
        "scenes": [measure(scene, args.rounds) for scene in scenes],
        "import_rclpy": measure_rclpy(args.rounds),
        "node_imports": measure_nodes(args.rounds),
        "runs": measure_run(args.runs),
    }
    data["command"] = data["command"].rstrip()
    print(render(data))
    if args.out:
        out = Path(args.out)
        os.makedirs(out, exist_ok=True)
        (out / "startup.json").write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        (out / "README.md").write_text(render(data), encoding="utf-8")
        print(f"written: {out / 'startup.json'}, {out / 'README.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
