"""``python -m benchmarks limits``: whether every sorted parcel stayed within the paper's
limits on the plant, for a user's own mixed stream.

Runs ``fence-sorter run`` (its nodes over DDS) on the default scene with the belt at 2.0 m/s
(``benchmarks/limits/belt_2ms.yaml``) and a mixed stream of 0.2-0.6 m boxes of 0.5-25 kg,
all to divert, at 4000 pcs/h (``benchmarks/limits/mixed_stream.yaml``), once per variant
(``--variants``): ``plant`` (the controller as configured) and ``sensors`` (the same with the
sensors node, ``--sensors camera60``). Per variant: the sorted parcels over each limit (7),
(10)-(12) as delivered, the worst excess, failed events, the share of the divert parcels
sorted, the declines by reason, the capacity sorted, and the planner's evaluations and latency.
Prints a Markdown table and writes it with the command, commit and load to ``--out``
(docs/reports/limits.md) and ``--json``. Exits 1 when a variant has a sorted parcel over a
limit, a failed event, or sorts under ``--min-share`` of its divert parcels.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from benchmarks import REPO
from benchmarks.runs import finish, last_json
from fence_sorter.verification.machine import git_revision

DATA = REPO / "benchmarks" / "limits"
VARIANTS = {"plant": [], "sensors": ["--sensors", "camera60"]}


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Sorted parcels against the paper's limits on the plant."
    parser.add_argument("--parcels", type=int, default=60, metavar="N")
    parser.add_argument("--rtf", type=float, default=1.0, help="real-time factor (0: unpaced)")
    parser.add_argument("--variants", default="plant,sensors", metavar="V1,V2")
    parser.add_argument("--min-share", type=float, default=0.95, metavar="F")
    parser.add_argument("--out", default="docs/reports/limits.md", metavar="FILE")
    parser.add_argument("--json", default="docs/reports/limits.json", metavar="FILE")
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"benchmarks: error: {msg}", file=sys.stderr)
    return 2


def one_run(variant: str, parcels: int, rtf: float, workdir: Path) -> dict:
    """One ``fence-sorter run --json`` of the campaign; its summary and exit status."""
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--scene"]
    cmd += [str(DATA / "belt_2ms.yaml"), "--stream", str(DATA / "mixed_stream.yaml")]
    cmd += ["--parcels", str(parcels), "--rtf", f"{rtf:g}", "--json", *VARIANTS[variant]]
    t0 = time.monotonic()
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=workdir,
        start_new_session=True,
    )  # fmt: skip
    s = last_json(finish(proc, timeout=1800.0))
    return {"variant": variant, "exit": proc.returncode, "wall_s": time.monotonic() - t0, **s}


def row(r: dict) -> dict:
    """The campaign's figures of one run."""
    lim = r.get("limits") or {}
    over = lim.get("over_limit", {})
    divert = r.get("divert") or 0
    ctrl = r.get("controller", {})
    declined = {
        k: v for k, v in (r.get("missed_by_reason") or {}).items() if k != "SORTED"
    }  # fmt: skip
    return {
        "variant": r["variant"],
        "exit": r["exit"],
        "divert": divert,
        "sorted_divert": r.get("sorted_divert", 0),
        "share_sorted": (r.get("sorted_divert", 0) / divert) if divert else float("nan"),
        "over": {c: len(ids) for c, ids in over.items()},
        "over_ids": over,
        "worst_excess": lim.get("worst_excess", {}),
        "failed_events": lim.get("failed_events", []),
        "declined": declined,
        "declined_examples": r.get("missed_examples", {}),
        "sorted_pcs_h": r.get("sorted_pcs_h", float("nan")),
        "throughput_pcs_h": r.get("throughput_pcs_h", float("nan")),
        "peak_impact_speed_mps": r.get("peak_impact_speed_mps"),
        "peak_exit_speed_mps": r.get("peak_exit_speed_mps"),
        "peak_accel_mps2": r.get("peak_accel_mps2"),
        "evaluations": ctrl.get("evaluations"),
        "latency_p99_ms": r.get("controller_latency_p99_ms"),
        "intrusions": r.get("swept_sector_intrusions", 0),
    }


def row_ok(x: dict, min_share: float) -> bool:
    return (
        not any(x["over"].values())
        and not x["failed_events"]
        and x["share_sorted"] >= min_share
        and not x["intrusions"]
    )


def run(args: argparse.Namespace) -> int:
    variants = [v for v in args.variants.split(",") if v]
    bad = [v for v in variants if v not in VARIANTS]
    if bad or not variants:
        return _error(f"--variants must be names from {', '.join(VARIANTS)}, got {args.variants}")
    if not 1 <= args.parcels <= 10000:
        return _error(f"--parcels must be in [1, 10000], got {args.parcels}")
    if not 0.0 <= args.rtf <= 100.0:
        return _error(f"--rtf must be in [0, 100], got {args.rtf:g}")
    commit = git_revision()
    load0 = os.getloadavg()[0]
    workdir = Path(os.environ.get("TMPDIR", "/tmp"))
    rows = []
    for v in variants:
        x = row(one_run(v, args.parcels, args.rtf, workdir))
        rows.append(x)
        print(json.dumps({k: x[k] for k in ("variant", "exit", "share_sorted", "over")}))
    load1 = os.getloadavg()[0]
    head = (
        "| variant | exit | divert sorted | over (7) / (10) / (11) / (12) | worst excess "
        "| failed events | declined (reason: n) | sorted [pcs/h] | peak w_n / a_N / ydot "
        "| evaluations | controller latency p99 [ms] | intrusions |"
    )
    lines = [head, "|" + " --- |" * 12]
    for x in rows:
        over = " / ".join(str(x["over"].get(c, "-")) for c in ("7", "10", "11", "12"))
        worst = "; ".join(
            f"({c}) {w['parcel_id']}: {w.get('delivered', w['excess']):.3g}"
            for c, w in x["worst_excess"].items()
        ) or "-"  # fmt: skip
        declined = ", ".join(f"{k}: {n}" for k, n in sorted(x["declined"].items())) or "none"
        lines.append(
            f"| {x['variant']} | {x['exit']} | {x['sorted_divert']} of {x['divert']} "
            f"({x['share_sorted']:.1%}) | {over} | {worst} | {len(x['failed_events'])} "
            f"| {declined} | {x['sorted_pcs_h']:.0f} "
            f"| {x['peak_impact_speed_mps']:.2f} / {x['peak_accel_mps2']:.0f} / "
            f"{x['peak_exit_speed_mps']:.2f} | {x['evaluations']} | {x['latency_p99_ms']} "
            f"| {x['intrusions']} |"
        )
    table = "\n".join(lines)
    print(table)
    command = (
        f"python -m benchmarks limits --parcels {args.parcels} --rtf {args.rtf:g} "
        f"--variants {args.variants}"
    )
    examples = "\n".join(
        f"- {x['variant']}, {name}: {why}"
        for x in rows
        for name, why in sorted(x["declined_examples"].items())
    )
    text = (
        "# Sorted parcels against the paper's limits, on the plant\n\n"
        f"`{command}` at commit {commit}, {time.strftime('%Y-%m-%d', time.gmtime())}, load "
        f"average {load0:.1f} at the start and {load1:.1f} at the end (2-core machine).\n\n"
        "The default scene with the belt at 2.0 m/s, a mixed stream of 0.2-0.6 m boxes of\n"
        "0.5-25 kg, all to divert, 4000 pcs/h, seed 11 (benchmarks/limits/). Each row is one\n"
        "`fence-sorter run --json` over DDS; `sensors` adds the sensors node (camera60).\n"
        "`over`: sorted parcels whose delivered figure went over the limit of (7), (10) w_dop\n"
        "2.4 m/s, (11) a_Ndop 300 m/s^2, (12) ydot_dop 2.5 m/s; `worst excess`: the parcel\n"
        "and its delivered value; `declined`: divert parcels not sorted, by outcome (the\n"
        "controller names the constraint that failed); peaks leave failed events out.\n\n"
        + table
        + ("\n\nDeclines, one example each:\n\n" + examples if examples else "")
        + "\n"
    )
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        data = {"command": command, "commit": commit, "load": [load0, load1], "rows": rows}
        Path(args.json).write_text(json.dumps(data, indent=1) + "\n")
    return 0 if all(row_ok(x, args.min_share) for x in rows) else 1
