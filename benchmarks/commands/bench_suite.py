"""``python -m benchmarks bench-suite``: the node suite against its pacing targets.

Runs :mod:`benchmarks.bench_suite` (a paced run at rtf 1.0 for 60 s at
2400 pcs/h, then an unpaced run), prints the section and writes it between the suite markers
of the output file (default ``docs/reports/benchmarks.md``; the rest of the file is left as it is).

Exit codes: 0 the bench ran (missed targets are reported in the table, and so is a run's
exit 3, a divert parcel without an outcome: what a starved paced run does, a figure of the
machine's load), 1 a run failed (any other exit), 2 bad arguments.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from benchmarks.bench_suite import render, run_bench, write_json, write_section
from fence_sorter.cli.run import add_param_option
from fence_sorter.runner.job import BadInput
from fence_sorter.verification.machine import git_revision, machine_info

DEFAULT_OUT = "docs/reports/benchmarks.md"
#: a run's exits that are figures of the bench, not failures: clean, and divert parcels
#: without an outcome (fence_sorter.cli.run's exit 3, reported in the table)
RAN = {0, 3}


def register(parser: argparse.ArgumentParser) -> None:

    parser.description = (
        "Paced run (rtf 1.0, 60 s, 2400 pcs/h) and unpaced run of the node suite; "
        "writes the figures between <!-- suite:begin --> and <!-- suite:end --> in --out."
    )
    parser.add_argument("--out", default=DEFAULT_OUT, help="markdown file (section replaced)")
    parser.add_argument("--duration", type=float, default=60.0, help="paced stream length [s]")
    parser.add_argument("--unpaced-parcels", type=int, default=40, help="parcels, unpaced run")
    add_param_option(
        parser,
        "node parameter override for both runs, e.g. simulator:physics_rate=500.0 "
        "(repeatable; the report lists them)",
    )
    parser.add_argument(
        "--rrd",
        action="store_true",
        help="both runs also save a Rerun recording (measures the logging overhead)",
    )
    parser.add_argument(
        "--json",
        metavar="FILE",
        help="also store the figures in FILE, under plain or rrd (the other entry is kept)",
    )
    parser.add_argument("--no-write", action="store_true", help="print only; --json is written")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.duration > 0 or args.unpaced_parcels < 1:
        print(
            "benchmarks: error: --duration must be in (0, inf) s and --unpaced-parcels in "
            "[1, inf)",
            file=sys.stderr,
        )
        return 2
    out = Path(args.out)
    if not args.no_write and not out.parent.is_dir():
        print(f"benchmarks: error: --out {out}: no such directory", file=sys.stderr)
        return 2
    if args.json and not Path(args.json).parent.is_dir():
        print(f"benchmarks: error: --json {args.json}: no such directory", file=sys.stderr)
        return 2

    try:
        fig = run_bench(
            args.duration,
            args.unpaced_parcels,
            say=lambda s: print(s, file=sys.stderr),
            params=args.params,
            rrd=args.rrd,
        )
    except BadInput as exc:
        print(f"benchmarks: error: {exc}", file=sys.stderr)
        return 2
    command = "python -m benchmarks bench-suite " + " ".join(
        shlex.quote(a) for a in sys.argv[2:] if a != "--no-write"
    )
    revision = git_revision()
    section = render(fig, command.strip(), machine_info(), revision)
    print(section)
    if args.json:
        write_json(Path(args.json), fig, command.strip(), revision)
        print(f"wrote the figures to {args.json}", file=sys.stderr)
    if not args.no_write:
        write_section(out, section)
        print(f"wrote the suite section of {out}", file=sys.stderr)
    return 0 if {fig["paced_exit"], fig["unpaced_exit"]} <= RAN else 1
