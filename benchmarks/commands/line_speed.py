"""``python -m benchmarks line-speed``: how much faster than real time the ROS-free line runs.

A few runs of one line (four_units by default) unpaced, on one stream (a fixed seed, 6000
pcs/h offered, ``--duration`` of it) to the drain, each with its planners warmed up first as
``line-sim`` does. Per run: sim time / wall time (``LinePlant.run``, planning, traffic,
guard and every stroke's solve included), sim time / CPU time of this process, and the
machine's 1-minute load average before and after it (the machine is shared: the wall figure
moves with the load, the CPU figure much less). Prints one line per run and the medians, and
writes them with the command and commit to ``--json`` (docs/reports/line-speed.json) and
``--out`` (docs/reports/line-speed.md); ``''`` writes nothing. Exits 1 if the runs' line
figures differ (the line is deterministic on a seed).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import sys
import time
from pathlib import Path

from fence_sorter.jsonsafe import json_safe
from fence_sorter.physics.params import ParameterError
from fence_sorter.verification.machine import git_revision

#: the summary's fields that must be the same in every run (the line's own figures)
SAME = ("sim_time_s", "parcels_inducted", "sorted", "rejected", "inductions", "handoffs")


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Speed of the ROS-free line: sim time / wall time, median of runs."
    parser.add_argument("line", nargs="?", default="four_units", metavar="LINE")
    parser.add_argument("--runs", type=int, default=3, metavar="N", help="default 3")
    parser.add_argument("--rate", type=float, default=6000.0, metavar="PCS_H")
    parser.add_argument(
        "--duration", type=float, default=300.0, metavar="S", help="of the stream (default 300)"
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default="docs/reports/line-speed.md", metavar="FILE")
    parser.add_argument("--json", default="docs/reports/line-speed.json", metavar="FILE")
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"benchmarks: error: {msg}", file=sys.stderr)
    return 2


def _load() -> float:
    return os.getloadavg()[0]


def run(args: argparse.Namespace) -> int:
    if not 1 <= args.runs <= 100:
        return _error(f"--runs must be in [1, 100], got {args.runs}")
    if not 1.0 <= args.rate <= 1e5:
        return _error(f"--rate must be in [1, 100000] pcs/h, got {args.rate:g}")
    if not 1.0 <= args.duration <= 1e5:
        return _error(f"--duration must be in [1, 100000] s, got {args.duration:g}")
    # lazy: the line's physics loads Numba and the compiled kernel
    from fence_sorter.line.line_file import load_line
    from fence_sorter.line.multi_unit import LinePlant, LineRunConfig

    try:
        line = load_line(args.line)
    except (ParameterError, OSError) as exc:
        return _error(str(exc))
    commit = git_revision()  # the code the runs use, whatever changes meanwhile
    cfg = LineRunConfig(parcels=None, duration=args.duration, rate_pcs_h=args.rate, seed=args.seed)
    runs, figures = [], []
    for i in range(args.runs):
        plant = LinePlant(line, cfg)
        plant.warm_up()
        load_before = _load()
        cpu0 = time.process_time()
        s = plant.run()
        cpu = time.process_time() - cpu0
        r = {
            "sim_s": s["sim_time_s"],
            "wall_s": s["wall_time_s"],
            "cpu_s": cpu,
            "sim_per_wall": s["sim_time_s"] / s["wall_time_s"],
            "sim_per_cpu": s["sim_time_s"] / cpu,
            "load_before": load_before,
            "load_after": _load(),
        }
        runs.append(r)
        figures.append({k: s[k] for k in SAME})
        print(
            f"run {i + 1}: {r['sim_s']:.1f} s sim in {r['wall_s']:.1f} s wall "
            f"({r['sim_per_wall']:.1f}x real time), {r['cpu_s']:.1f} s CPU "
            f"({r['sim_per_cpu']:.1f}x), load average {r['load_before']:.2f} -> "
            f"{r['load_after']:.2f}",
            flush=True,
        )
    same = all(f == figures[0] for f in figures)
    data = {
        "command": (
            f"python -m benchmarks line-speed {shlex.quote(args.line)} --runs {args.runs} "
            f"--rate {args.rate:g} --duration {args.duration:g} --seed {args.seed}"
        ),
        "commit": commit,
        "date": time.strftime("%Y-%m-%d", time.gmtime()),
        "cpus": os.cpu_count(),
        "line": line.name,
        "rate_pcs_h": args.rate,
        "duration_s": args.duration,
        "seed": args.seed,
        "figures": figures[0],
        "figures_same_in_every_run": same,
        "runs": runs,
        "median_sim_per_wall": statistics.median(r["sim_per_wall"] for r in runs),
        "median_sim_per_cpu": statistics.median(r["sim_per_cpu"] for r in runs),
        "median_load": statistics.median(0.5 * (r["load_before"] + r["load_after"]) for r in runs),
    }
    print(
        f"median: {data['median_sim_per_wall']:.1f}x real time (sim / wall), "
        f"{data['median_sim_per_cpu']:.1f}x sim / CPU, load average {data['median_load']:.2f} "
        f"on {data['cpus']} CPUs; line figures the same in every run: {same}"
    )
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(json_safe(data), indent=1) + "\n")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(render(data))
    return 0 if same else 1


def render(data: dict) -> str:
    f = data["figures"]
    rows = "\n".join(
        f"| {i + 1} | {r['sim_s']:.1f} | {r['wall_s']:.1f} | {r['sim_per_wall']:.1f}x "
        f"| {r['cpu_s']:.1f} | {r['sim_per_cpu']:.1f}x "
        f"| {r['load_before']:.2f} -> {r['load_after']:.2f} |"
        for i, r in enumerate(data["runs"])
    )
    return (
        f"# Line speed ({data['line']})\n\n"
        f"`{data['command']}` at commit {data['commit']}, {data['date']}, on this machine "
        f"({data['cpus']} CPUs, shared with other work: the load average is beside each run; "
        f"figures also in [line-speed.json](line-speed.json)).\n\n"
        f"The ROS-free line (`LinePlant.run`, what `fence-sorter line-sim` runs) unpaced, "
        f"{data['duration_s']:g} s of a stream offered at {data['rate_pcs_h']:g} pcs/h (seed "
        f"{data['seed']}) to the drain: {f['parcels_inducted']} parcels, {f['sorted']} sorted, "
        f"{f['sim_time_s']:.1f} s of sim time; planners warmed up before each run. sim / wall "
        f"is the real-time factor; sim / CPU counts this process's CPU time only, so it moves "
        f"less with the load.\n\n"
        "| run | sim [s] | wall [s] | sim / wall | CPU [s] | sim / CPU | load average |\n"
        "| --- | --- | --- | --- | --- | --- | --- |\n"
        f"{rows}\n\n"
        f"Median: **{data['median_sim_per_wall']:.1f}x real time** (sim / wall), "
        f"{data['median_sim_per_cpu']:.1f}x sim / CPU, at load average "
        f"{data['median_load']:.2f}. The line's figures were "
        f"{'the same' if data['figures_same_in_every_run'] else 'NOT the same'} in every run.\n"
    )
