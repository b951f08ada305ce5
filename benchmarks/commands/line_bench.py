"""``python -m benchmarks line-bench``: the saturation curve of a line (sort rate against
induction).

For each induction rate (default 2000 to 12000 pcs/h) one ROS-free run of the line
(:mod:`fence_sorter.line.multi_unit`, guard on) to the drain: throughput in and out, sort rate,
recirculation share, rejects, intrusions and conservation, with each unit's capacity bound
W_t (1)-(2) of its median stroke beside them. Prints a Markdown table and
writes it with the command and commit to ``--out`` (docs/reports/line-bench.md by default;
``--out ''`` writes nothing).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from fence_sorter.physics.params import ParameterError
from fence_sorter.verification.machine import git_revision


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Saturation curve of a line: sort rate and throughput against rate."
    parser.add_argument("line", nargs="?", default="four_units", metavar="LINE")
    parser.add_argument("--parcels", type=int, default=200, metavar="N", help="per rate")
    parser.add_argument(
        "--rates", default="2000,3000,4000,6000,8000,12000", metavar="R1,R2,...",
        help="induction rates [pcs/h]",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--out", default="docs/reports/line-bench.md", metavar="FILE")
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"benchmarks: error: {msg}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    try:
        rates = [float(r) for r in args.rates.split(",")]
    except ValueError:
        return _error(f"--rates must be numbers separated by commas, got {args.rates!r}")
    if not rates or not all(1.0 <= r <= 1e5 for r in rates):
        return _error(f"--rates must be in [1, 100000] pcs/h, got {args.rates!r}")
    if not 1 <= args.parcels <= 10**6:
        return _error(f"--parcels must be in [1, 1000000], got {args.parcels}")
    # lazy: the line's physics loads Numba and the compiled kernel
    from fence_sorter.line.line_file import load_line
    from fence_sorter.line.multi_unit import LinePlant, LineRunConfig

    try:
        line = load_line(args.line)
    except (ParameterError, OSError) as exc:
        return _error(str(exc))
    head = (
        "| rate set [pcs/h] | in [pcs/h] | out [pcs/h] | sort rate | recirculated | rejected "
        "| intrusions | conservation | W_t per unit [pcs/h] | sim/wall |"
    )
    rows = [head, "|" + " --- |" * 10]
    print(head, flush=True)
    ok = True
    for rate in rates:
        plant = LinePlant(
            line, LineRunConfig(parcels=args.parcels, rate_pcs_h=rate, seed=args.seed)
        )
        plant.warm_up()
        s = plant.run()
        ok &= s["conservation_ok"] and s["swept_sector_intrusions"] == 0
        wt = ", ".join(
            "-" if math.isnan(u["capacity_bound_pcs_h"]) else f"{u['capacity_bound_pcs_h']:.0f}"
            for u in s["units"].values()
        )
        row = (
            f"| {rate:.0f} | {s['throughput_in_pcs_h']:.0f} | {s['throughput_out_pcs_h']:.0f} "
            f"| {s['sort_rate']:.1%} | {s['recirculation_share']:.1%} | {s['rejected']} "
            f"| {s['swept_sector_intrusions']} | {'exact' if s['conservation_ok'] else 'NO'} "
            f"| {wt} | {s['real_time_factor']:.0f}x |"
        )
        rows.append(row)
        print(row, flush=True)
    when = time.strftime("%Y-%m-%d", time.gmtime())
    text = (
        f"# Line saturation curve ({line.name})\n\n"
        f"`python -m benchmarks line-bench {args.line} --parcels {args.parcels} "
        f"--rates {args.rates}` "
        f"at commit {git_revision()}, {when}, on this 2-core machine under load "
        "(sim/wall is the speed of the whole ROS-free line, planning included).\n\n"
        "Each row: one stream of the given rate run to the drain with the guard on. `in`:\n"
        "first inductions per hour, after the induction held new parcels for returning ones\n"
        "and (induction.min_gap) to the line's gap, so it stays below the rate set once the\n"
        "line is saturated; `out`: sorts per hour while the induction ran (that window\n"
        "shifted by the median induction-to-sort time); recirculated: share of parcels that\n"
        "went round the loop at least once; W_t: each unit's capacity (1)-(2) for its median\n"
        "stroke (by scraping time t_z) and the median parcel length (`-`: no stroke).\n\n"
        + "\n".join(rows)
        + "\n"
    )
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    return 0 if ok else 1
