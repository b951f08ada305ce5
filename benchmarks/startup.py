"""Where a new process's first solve spends its time (a benchmark, not a test).

``python -m benchmarks.startup [--scene NAME ...] [--rounds N] [--out DIR]``.

Each round starts a fresh interpreter per scene that times, in order: importing NumPy and
SciPy's linear algebra, Numba, the physics (``physics.simulate``: the kernel's dispatchers, no
compilation), loading a scene, the first ``simulate`` (through the loop's ahead-of-time
extension when it is built for the current sources, else Numba's first-use set-up and the
cached machine code) and a second ``simulate`` (the solve itself); the first ``simulate``
once more through the JIT (FENCE_SORTER_AOT=0) for comparison; and, in its own
interpreter, ``import rclpy``, which every node process pays. Then ``--runs`` runs of
``fence-sorter run --parcels 1``, on the machine as it is and again with ``--load N`` busy
processes beside them (each a Python loop started with setsid, as N other users' jobs: the
kernel's autogroup scheduling shares the CPUs between them), each with the seconds from the
runner's start to each node's process having built its node (its first log line: interpreter,
imports, rclpy, parameters) and to its first heartbeat. Medians over the rounds, printed and
written as ``startup.json`` and ``README.md`` (rendered from the JSON) into ``--out`` (default
docs/reports/startup/), with the command, the revision and the load average. The kernel must have
been compiled first (scripts/bootstrap.sh does).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import REPO
from fence_sorter.scene import available_scenes
from fence_sorter.verification.machine import git_revision, load_average, machine_info
from fence_sorter.verification.report import fmt, table

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
#: a node's first log line, "[INFO] [1795511389.514130065] [simulator]: simulator 0.1.0: ..."
FIRST_LOG = re.compile(r"^\[INFO\] \[([0-9.]+)\] \[(\w+)\]: ", re.MULTILINE)
FIRST_SOLVE_TARGET = 0.050  # [s] a new process's first solve
NODES_UP_TARGET = 5.0  # [s] `fence-sorter run` has its nodes up
BUSY = "while True: pass"


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


def _one_run() -> dict:
    """One ``fence-sorter run --parcels 1``: seconds from the runner's start to "nodes up", to
    each node's first heartbeat (as the run prints them) and to each node built (its first log
    line, placed on the runner's clock by the wall time the "nodes up" line arrived)."""
    logs = Path(tempfile.mkdtemp(prefix="fence_sorter_startup_"))
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "fence_sorter.cli.main", "run", "--parcels", "1"]
            + ["--log-dir", str(logs)],
            stdout=subprocess.PIPE,
            text=True,
        )
        out, found, up_at = [], None, 0.0
        for line in proc.stdout:
            out.append(line)
            if found is None and (found := NODES_UP.search(line)):
                up_at = time.time()
        if proc.wait() != 0 or found is None:
            raise RuntimeError(
                f"fence-sorter run failed ({proc.returncode}): {''.join(out)[-800:]}"
            )
        start = up_at - float(found.group(1))
        run = {"nodes_up": float(found.group(1))}
        for beat in found.group(2).split(", "):
            node, seconds = beat.rsplit(" ", 2)[:2]
            first = FIRST_LOG.search((logs / f"{node}.log").read_text(errors="replace"))
            run[f"{node} built"] = float(first.group(1)) - start if first else None
            run[node] = float(seconds)
        return run
    finally:
        shutil.rmtree(logs, ignore_errors=True)


def measure_run(rounds: int, load: int = 0) -> dict:
    """``rounds`` runs (:func:`_one_run`) beside ``load`` busy processes, each started with
    setsid; the load average before and after."""
    busy = [
        subprocess.Popen([sys.executable, "-c", BUSY], start_new_session=True) for _ in range(load)
    ]
    try:
        before = load_average()
        runs = [_one_run() for _ in range(rounds)]
        return {"load": load, "load_average": [before, load_average()], "runs": runs}
    finally:
        for p in busy:
            p.kill()
            p.wait()


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
        'by hand. What the parts are and why: docs/design/numerics.md, "Start-up of a process".',
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
    for series in data.get("run_series", []):
        runs = series["runs"]
        if not runs:
            continue
        keys = list(runs[0])
        busy = (
            f"beside {series['load']} busy processes (`--load {series['load']}`)"
            if series["load"]
            else "on the machine as it was"
        )
        before, after = series["load_average"]
        worst = max(r["nodes_up"] for r in runs)
        verdict = "met" if worst <= data["nodes_up_target"] else "not met"
        lines += [
            f"`fence-sorter run --parcels 1` (real-time factor 1) {busy}, load average {before} "
            f"before and {after} after; seconds from the runner's start to each node built (its "
            'first log line), to its first heartbeat and to "nodes up". Nodes up <= '
            f"{data['nodes_up_target']:g} s: {verdict} (slowest {worst:.1f} s).",
            "",
            *table(
                ["run", *keys],
                [[k + 1, *(fmt(r.get(c), ".1f") for c in keys)] for k, r in enumerate(runs)],
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
    ap.add_argument(
        "--load", type=int, default=0, help="the runs again beside N busy processes (0: not)"
    )
    ap.add_argument(
        "--out", default=str(REPO / "docs" / "reports" / "startup"), help="'' writes nothing"
    )
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error(f"--rounds must be >= 1, got {args.rounds}")
    for name in ("runs", "load"):
        if getattr(args, name) < 0:
            ap.error(f"--{name} must be >= 0, got {getattr(args, name)}")
    scenes = args.scene or ["positioned_stiff", "impact_flexible"]
    known = available_scenes()
    for scene in scenes:
        if scene not in known:
            ap.error(f"--scene: unknown scene {scene!r}; one of {', '.join(known)}")
    data = {
        "command": "python -m benchmarks.startup "
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
        "nodes_up_target": NODES_UP_TARGET,
        "run_series": [measure_run(args.runs, load) for load in sorted({0, args.load})],
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
