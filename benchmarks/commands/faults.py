"""``python -m benchmarks faults``: the fault-injection campaign of the node suite ->
docs/reports/reliability.md.

Repeated Ctrl-C, floods on /parcels and /fence_commands, insiders with the run's own id
(forged duplicates, a flood, a second /clock), hostile and malformed messages, bad files,
scenes, streams and parameters; a line's link cut, unit kill and host kill
(:mod:`benchmarks.faults`). Exit codes:
0 every case met its target, 1 some did not (named), 2 bad arguments.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks.faults import campaign

CASES = ("wire", "cli", "floods", "insiders", "interrupts", "freezes", "line")


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Inject the faults of the reliability campaign (repeated Ctrl-C, floods, "
        "hostile messages, bad input, a line's link, unit and host faults), count what the "
        "suite refused, dropped and sorted, and write the report."
    )
    parser.add_argument(
        "--out",
        default="docs/reports/reliability.md",
        help="report (markdown; its data beside it as .json: a run of some --cases replaces "
        "only their sections)",
    )
    parser.add_argument(
        "--trials", type=int, default=20, help="repeated Ctrl-C trials (default 20)"
    )
    parser.add_argument(
        "--cases", nargs="+", choices=CASES, default=list(CASES), help="cases to run"
    )
    parser.add_argument("--seed", type=int, default=16, help="seed of the signal moments")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.trials < 1:
        print(
            f"benchmarks: error: --trials must be in [1, inf), got {args.trials}",
            file=sys.stderr,
        )
        return 2

    met = campaign(
        Path(args.out),
        trials=args.trials,
        seed=args.seed,
        which=tuple(c for c in CASES if c in args.cases),
        progress=lambda s: print(s, flush=True),
    )
    print(f"report: {args.out}")
    missed = [k for k, ok in met.items() if not ok]
    if missed:
        print(f"targets not met: {', '.join(missed)}")
        return 1
    return 0
