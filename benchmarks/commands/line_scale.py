"""``python -m benchmarks line-scale``: the line over DDS against its number of units.

For each number of units (default 1, 2, 4, 8) a line file with that many units is written
from four_units.yaml's pattern (unit k at X = 3 + 5 k m, the side, scene and overrides of
four_units' unit k mod 4, two destinations per unit with equal shares, the belt 6 m past the
last fence; the rest of four_units as it is), and ``fence-sorter run --line`` runs it on this
host, one process per unit and the owner, in lockstep over DDS:

- unpaced (``--rtf 0``): the line's speed, sim time over the wall time of the clock's loop;
- paced (``--rtf 1`` by default): the line clock's deadline misses and slips (the owner's
  ``PacedSteps``), whether that many units keep real time here;
- both: the hand-offs' transit, DDS writer's source timestamp to the reader's reception, per
  link and over all links (median, p99, max).

The load average is taken before and after each run (the machine is shared: each figure is
written beside the load it was measured under). Writes ``--out`` (Markdown) and the same
figures as JSON beside it (``.json``), each with the command and commit.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from fence_sorter.verification.machine import git_revision

REPO = Path(__file__).resolve().parents[2]
PATTERN = REPO / "config" / "lines" / "four_units.yaml"


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "The line over DDS: speed, paced deadline misses, hand-off transit."
    parser.add_argument("--units", default="1,2,4,8", metavar="N1,N2,...")
    parser.add_argument("--parcels", type=int, default=8, metavar="N", help="per run")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument(
        "--rtf", type=float, default=1.0, help="real-time factor of the paced runs (0: none)"
    )
    parser.add_argument("--out", default="docs/reports/line-scale.md", metavar="FILE")
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"benchmarks: error: {msg}", file=sys.stderr)
    return 2


def line_of(n: int) -> dict:
    """four_units.yaml with ``n`` units in its pattern (see the module's docstring)."""
    base = yaml.safe_load(PATTERN.read_text())
    pattern = base["units"]
    units = []
    for k in range(n):
        u = dict(pattern[k % len(pattern)])
        u.update(
            name=f"unit_{k + 1}",
            position=3.0 + 5.0 * k,
            destinations=[f"D{2 * k + 1}", f"D{2 * k + 2}"],
        )
        units.append(u)
    share = 1.0 / (2 * n)
    base["name"] = f"units_{n}"
    base["units"] = units
    base["induction"]["destinations"] = {f"D{j + 1}": share for j in range(2 * n)}
    base["conveyor"]["length"] = 3.0 + 5.0 * (n - 1) + 6.0
    return base


def run_line(path: Path, parcels: int, seed: int, rtf: float) -> dict:
    """One ``fence-sorter run --line`` to the drain; its summary with the load around it."""
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--line", str(path),
           "--parcels", str(parcels), "--seed", str(seed), "--rtf", repr(rtf),
           "--json"]  # fmt: skip
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=3600)
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[2:])} exited {proc.returncode}: {proc.stderr[-400:]}")
    s = json.loads(proc.stdout)
    return {
        "rtf_target": rtf,
        "sim_time_s": s["sim_time_s"],
        "loop_wall_s": s["wall_time_s"],
        "command_wall_s": wall,
        # CPU of every process of the run (runner, owner, units), start-up and warm-up included
        "cpu_s": (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime),
        "sim_per_wall": s["real_time_factor"],
        "load_before": load0,
        "load_after": os.getloadavg()[0],
        "conservation_ok": s["conservation_ok"],
        "handoffs_balanced": s["handoffs_balanced"],
        "pacing": s["pacing"],
        "handoff_latency": s["handoff_latency"],
    }


def _cpu(run: dict) -> str:
    return "-" if "cpu_s" not in run else f"{run['cpu_s']:.0f}"


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def run(args: argparse.Namespace) -> int:
    try:
        counts = [int(n) for n in args.units.split(",")]
    except ValueError:
        return _error(f"--units must be unit counts separated by commas, got {args.units!r}")
    if not counts or not all(1 <= n <= 16 for n in counts):
        return _error(f"--units must be in [1, 16], got {args.units!r}")
    if not 1 <= args.parcels <= 10_000:
        return _error(f"--parcels must be in [1, 10000], got {args.parcels}")
    if not 0.0 <= args.rtf <= 100.0:
        return _error(f"--rtf must be in [0, 100], got {args.rtf}")
    command = (
        f"python -m benchmarks line-scale --units {args.units} --parcels {args.parcels} "
        f"--seed {args.seed} --rtf {args.rtf:g}"
    )
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="line_scale_") as tmp:
        for n in counts:
            path = Path(tmp) / f"units_{n}.yaml"
            path.write_text(yaml.safe_dump(line_of(n), sort_keys=False))
            row = {"units": n, "cores": os.cpu_count()}
            row["unpaced"] = run_line(path, args.parcels, args.seed, 0.0)
            print(json.dumps({"units": n, "unpaced": row["unpaced"]["sim_per_wall"]}), flush=True)
            if args.rtf > 0.0:
                row["paced"] = run_line(path, args.parcels, args.seed, args.rtf)
                print(json.dumps({"units": n, "paced": row["paced"]["pacing"]}), flush=True)
            rows.append(row)
    result = {
        "command": command,
        "commit": git_revision(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "cores": os.cpu_count(),
        "rows": rows,
    }
    text = report(result)
    print(text)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
        out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
    return 0 if all(r["unpaced"]["conservation_ok"] for r in rows) else 1


def report(r: dict) -> str:
    """The Markdown report of :func:`run`'s figures."""
    head = [
        "| units | unpaced sim/wall | CPU [s] | load | paced misses | slips | lateness p99 [ms] "
        "| load | hand-off p50 [ms] | p99 [ms] | max [ms] | hand-offs |",
        "|" + " --- |" * 12,
    ]
    for row in r["rows"]:
        u, p = row["unpaced"], row.get("paced")
        lat = (p or u)["handoff_latency"]["all"]
        if p is None:
            paced = "- | - | - | -"
        else:
            pc = p["pacing"]
            paced = (
                f"{pc['deadline_misses']} of {pc['cycles']} ({pc['deadline_miss_share']:.2%}) "
                f"| {pc['catch_up_slips']} | {_ms(pc['lateness_p99_ms'])} "
                f"| {p['load_before']:.1f}-{p['load_after']:.1f}"
            )
        head.append(
            f"| {row['units']} | {u['sim_per_wall']:.2f}x ({u['sim_time_s']:.1f} s in "
            f"{u['loop_wall_s']:.1f} s) | {_cpu(u)} "
            f"| {u['load_before']:.1f}-{u['load_after']:.1f} "
            f"| {paced} | {_ms(lat.get('p50_ms'))} | {_ms(lat.get('p99_ms'))} "
            f"| {_ms(lat.get('max_ms'))} | {lat['n']} |"
        )
    return (
        "# The line over DDS against its number of units\n\n"
        f"`{r['command']}` at commit {r['commit']}, {r['date']}, on this {r['cores']}-core "
        "machine shared with other work (load: the 1-minute load average before and after "
        "each run).\n\n"
        "Each line: four_units.yaml's pattern with that many units (one `line_unit` process "
        "each, and the `line_owner`), the same stream and seed, run to the drain with "
        "`fence-sorter run --line`. Unpaced sim/wall: sim time over the wall time of the "
        "owner's clock loop (start-up and warm-up not in it); CPU: the CPU time of every "
        "process of the unpaced run, start-up and warm-up included. Paced: every 10 ms step "
        "of the line clock has a deadline; a miss is a deadline passed before the loop ran "
        "it or a step that ended more than one period after its deadline; a slip drops more "
        "than 0.1 s of lag from the grid. Hand-off transit: the DDS writer's source "
        "timestamp to the reader's reception, over every link of the paced run (of the "
        "unpaced one without it), one clock on one host.\n\n" + "\n".join(head) + "\n"
    )
