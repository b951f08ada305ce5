"""``python -m benchmarks line-bench``: the saturation curve of a line (sort rate against
induction).

For each induction rate (default 2000 to 12000 pcs/h) one ROS-free run of the line
(:mod:`fence_sorter.line.multi_unit`, guard on) of a stream drawn over ``--duration`` (600 s)
at that rate (or of ``--parcels``), to the drain: what the stream offered, and throughput in
and out of the cohort of parcels first inducted in the run's steady window
(:mod:`fence_sorter.line.steady`: out / in at most 1), inducted against offered, whether the
line is saturated and where its queue forms, out against in less the parcels no pass could
read, sort rate, recirculation share, rejects, intrusions and
conservation, the sorted parcels over each limit (10)-(12) and the failed events, with each
unit's capacity bound W_t (1)-(2) of its median stroke beside them. Exits 1 when a row has an
intrusion, a conservation error, a failed event or a sorted parcel over a limit.
Prints a Markdown table and writes it with the command and commit to ``--out``
(docs/reports/line-bench.md by default; ``--out ''`` writes nothing); ``--json FILE`` writes
the rows' figures as one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from fence_sorter.jsonsafe import json_safe
from fence_sorter.physics.params import ParameterError
from fence_sorter.verification.machine import git_revision


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Saturation curve of a line: sort rate and throughput against rate."
    parser.add_argument("line", nargs="?", default="four_units", metavar="LINE")
    parser.add_argument(
        "--duration", type=float, default=600.0, metavar="S",
        help="seconds of the stream drawn per rate (default 600)",
    )  # fmt: skip
    parser.add_argument(
        "--parcels", type=int, default=None, metavar="N", help="per rate, instead of --duration"
    )
    parser.add_argument(
        "--rates", default="2000,3000,4000,6000,8000,12000", metavar="R1,R2,...",
        help="induction rates [pcs/h]",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--out", default="docs/reports/line-bench.md", metavar="FILE")
    parser.add_argument("--json", default=None, metavar="FILE", help="the rows as JSON")
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
    if args.parcels is not None and not 1 <= args.parcels <= 10**6:
        return _error(f"--parcels must be in [1, 1000000], got {args.parcels}")
    if not 1.0 <= args.duration <= 1e5:
        return _error(f"--duration must be in [1, 100000] s, got {args.duration:g}")
    if args.json is not None and not Path(args.json).parent.is_dir():
        return _error(f"--json must be a FILE in an existing directory, got {args.json}")
    # lazy: the line's physics loads Numba and the compiled kernel
    from fence_sorter.line.line_file import load_line
    from fence_sorter.line.multi_unit import LinePlant, LineRunConfig

    try:
        line = load_line(args.line)
    except (ParameterError, OSError) as exc:
        return _error(str(exc))
    commit = git_revision()  # the code the runs below use, whatever changes meanwhile
    # the share of parcels no pass reads: a no-read goes round and is scanned again, so only
    # a parcel unread on each of its max_passes passes is lost to the no-reads
    unread = line.no_read_share**line.max_passes
    head = (
        "| rate set [pcs/h] | offered [pcs/h] | in [pcs/h] | in / offered | out [pcs/h] "
        "| out / in | out / (in (1 - p^k)) | saturated (queue at) | sort rate "
        "| recirculated | rejected | intrusions | conservation "
        "| sorted over (10) / (11) / (12) | failed | W_t per unit [pcs/h] "
        "| window [s] | sim/wall |"
    )
    rows = [head, "|" + " --- |" * 18]
    print(head, flush=True)
    ok = True
    saturated: list[str] = []
    figures: list[dict] = []
    for rate in rates:
        cfg = (
            LineRunConfig(parcels=args.parcels, rate_pcs_h=rate, seed=args.seed)
            if args.parcels is not None
            else LineRunConfig(parcels=None, duration=args.duration, rate_pcs_h=rate,
                               seed=args.seed)
        )  # fmt: skip
        plant = LinePlant(line, cfg)
        plant.warm_up()
        s = plant.run()
        over = s["parcels_over_limits"]
        ok &= s["conservation_ok"] and s["swept_sector_intrusions"] == 0
        ok &= s["solver_failures"] == 0 and not any(over.values())
        over_cells = " / ".join(str(len(over.get(c, []))) for c in ("10", "11", "12"))
        wt = ", ".join(
            "-" if math.isnan(u["capacity_bound_pcs_h"]) else f"{u['capacity_bound_pcs_h']:.0f}"
            for u in s["units"].values()
        )
        w, st = s["steady_window"], s["steady"]
        sat = "yes (" + (", ".join(st["queue_at"]) or "-") + ")" if st["saturated"] else "no"
        if st["saturated"]:
            saturated.append(
                f"{rate:.0f} (offered {st['offered_pcs_h']:.0f}, inducted "
                f"{st['inducted_pcs_h']:.0f} pcs/h; queue at {', '.join(st['queue_at'])})"
            )
        row = (
            f"| {rate:.0f} | {st['offered_pcs_h']:.0f} | {st['inducted_pcs_h']:.0f} "
            f"| {st['inducted_over_offered']:.3f} | {st['sorted_pcs_h']:.0f} "
            f"| {st['out_over_in']:.3f} | {st['out_over_in'] / (1.0 - unread):.3f} | {sat} "
            f"| {s['sort_rate']:.1%} | {s['recirculation_share']:.1%} "
            f"| {s['rejected']} | {s['swept_sector_intrusions']} "
            f"| {'exact' if s['conservation_ok'] else 'NO'} | {over_cells} "
            f"| {s['solver_failures']} | {wt} "
            + ("| - " if w is None else f"| {w['start_s']:.0f}-{w['end_s']:.0f} ")
            + f"| {s['real_time_factor']:.0f}x |"
        )
        rows.append(row)
        print(row, flush=True)
        figures.append({"rate_set_pcs_h": rate, "steady": st, "steady_window": w, **{
            k: s[k] for k in ("sort_rate", "recirculation_share", "rejected",
                              "swept_sector_intrusions", "conservation_ok", "solver_failures",
                              "parcels_over_limits", "induction_hold_s")
        }})  # fmt: skip
    verdict = (
        "Saturated: " + "; ".join(saturated) + "." if saturated else "No rate saturated the line."
    )
    print(verdict, flush=True)
    when = time.strftime("%Y-%m-%d", time.gmtime())
    size = f"--parcels {args.parcels}" if args.parcels is not None else (
        f"--duration {args.duration:g}"
    )  # fmt: skip
    p, k = line.no_read_share, line.max_passes
    text = (
        f"# Line saturation curve ({line.name})\n\n"
        f"`python -m benchmarks line-bench {args.line} {size} --rates {args.rates}"
        + ("" if args.seed is None else f" --seed {args.seed}")
        + f"` at commit {commit}, {when}, on this 2-core machine under load "
        "(sim/wall is the speed of the whole ROS-free line, planning included, while other "
        "work ran: not a speed benchmark; that is `python -m benchmarks line-speed`).\n\n"
        "Each row: one stream of the given rate run to the drain with the guard on.\n"
        "`offered`: the stream's arrivals per hour. `in` and `out` are those of the cohort\n"
        "of parcels first inducted in the run's steady window (`window`, sim time: from one\n"
        "loop cycle, belt length / v + transit time, after the first parcel's first induction\n"
        "to the last parcel's first induction, so the fill and the drain are left out): `in`:\n"
        "the cohort per hour of the window, after the induction held it for returning parcels\n"
        "and, with induction.min_gap, to the line's gap; `out`: the cohort's parcels sorted by\n"
        "the end of the run, per hour of the window. `out / in` is the share of the cohort\n"
        "sorted, at most 1 by construction; the rest was rejected, failed or left on the line.\n"
        "A no-read parcel goes round the loop and is scanned again: only\n"
        f"p^k = {p:g}^{k} = {unread:.1e} of the parcels stay unread on all k = {k} passes, so\n"
        "with every readable parcel sorted, out = in (1 - p^k). `saturated`: a queue grows\n"
        "faster than 0.05 s per s of sim time (the induction's wait of new parcels, or the\n"
        "returning parcels' wait at the merge), with where it forms: `induction hold\n"
        "(min_gap)`, `induction hold (returning parcels)`, `merge waits`; a saturated line\n"
        "inducts less than offered (`in / offered` < 1). The induction keeps the stream's own\n"
        "spacing: a hold delays every parcel behind it, and the time is not made up later,\n"
        "so the holds for returning parcels cost induction rate at any rate. Recirculated:\n"
        "share of parcels that went round the loop at least once; sorted over (10) / (11) /\n"
        "(12): the parcels sorted whose delivered impact speed, acceleration or exit speed\n"
        "went over the limit its unit planned for; failed: events whose simulation failed\n"
        "(counted apart); W_t: each unit's capacity (1)-(2) for its median stroke (by scraping\n"
        "time t_z) and the median parcel length (`-`: no\n"
        "stroke).\n\n" + "\n".join(rows) + "\n\n" + verdict + "\n"
    )
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    if args.json is not None:
        doc = {"line": line.name, "commit": commit, "unread_share": unread, "rows": figures}
        Path(args.json).write_text(json.dumps(json_safe(doc)))
    return 0 if ok else 1
