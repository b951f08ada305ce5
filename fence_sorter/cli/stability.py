"""``fence-sorter stability``: the stability campaign over stiff and extreme cases.

Runs the cases of :mod:`fence_sorter.verification.stability` (all, the fast subset with
``--quick``, or the ones named with ``--cases``), prints one line per case and writes
``README.md``, ``results.json`` and ``summary.png`` into ``--out`` (default ``stability`` in the
current directory).

Exit codes: 0 every case met its expectation, 1 some did not (they are named), 2 bad arguments
(an unknown case name: one line ``fence-sorter: error: ...`` naming the allowed names).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from datetime import UTC, datetime

from fence_sorter.verification import stability_cases as C
from fence_sorter.verification.machine import git_revision, machine_info

EXIT_OK = 0
EXIT_UNMET = 1
EXIT_BAD_ARGS = 2
DEFAULT_OUT = "stability"


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Solve every stability case, check its invariants (finite results, energy never "
        "rising without a power source, bounded penetration, convergence when the step is "
        "halved, a named diagnosis when a case cannot be solved) and write the report."
    )
    parser.add_argument(
        "--out",
        default=DEFAULT_OUT,
        metavar="DIR",
        help="directory for README.md, results.json and summary.png (default: %(default)s)",
    )
    which = parser.add_mutually_exclusive_group()
    which.add_argument(
        "--cases",
        nargs="+",
        metavar="NAME",
        help="run only these cases (names separated by spaces or commas; see --list)",
    )
    which.add_argument(
        "--quick", action="store_true", help="run the fast subset (the one CI runs)"
    )
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.set_defaults(func=run)


def _line(cr) -> str:
    c = cr.case
    flag = "" if cr.meets_expectation else f"  <- expected {c.expected}"
    failed = ", ".join(i.name for i in cr.failed_invariants)
    detail = f"  failed: {failed}" if failed else ""
    if cr.diagnosis:
        detail += f"  diagnosis: {cr.diagnosis}"
    return f"{c.name:24s} {cr.verdict:9s} {cr.wall_time:7.2f} s{detail}{flag}"


def run(args: argparse.Namespace) -> int:
    # lazy: loads the kernel (Numba), SciPy
    from fence_sorter.verification import stability as S
    from fence_sorter.verification import stability_report as R

    if args.list:
        for c in C.CASES:
            print(f"{c.name:24s} {c.speed:4s} {c.expected:9s} {c.description}")
        return EXIT_OK
    names = None
    if args.cases:
        names = [n for item in args.cases for n in item.split(",") if n.strip()]
        names = [n.strip() for n in names]
    try:
        cases = C.select_cases(names, quick=args.quick)
    except KeyError as exc:
        unknown = exc.args[0]
        print(
            f"fence-sorter: error: unknown stability case {unknown}; "
            f"allowed: {', '.join(C.case_names())}",
            file=sys.stderr,
        )
        return EXIT_BAD_ARGS
    if not cases:
        print("fence-sorter: error: no stability case selected", file=sys.stderr)
        return EXIT_BAD_ARGS

    print(f"compiling the kernel for {len(cases)} case(s) ...", flush=True)
    warm = S.warm_up(cases)
    t0 = time.perf_counter()
    results = S.run_cases(cases, progress=lambda cr: print(_line(cr), flush=True))
    wall = time.perf_counter() - t0

    argv = ["fence-sorter", "stability"]
    if args.out != DEFAULT_OUT:
        argv += ["--out", args.out]
    if args.quick:
        argv.append("--quick")
    if names:
        argv += ["--cases", *names]
    meta = {
        "command": shlex.join(argv),
        "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": git_revision(),
        "machine": machine_info(),
        "warm_up_s": warm,
        "wall_time_s": wall,
    }
    paths = R.write_report(results, args.out, meta)
    missed = [cr.case.name for cr in results if not cr.meets_expectation]
    print(
        f"{len(results)} case(s) in {wall:.1f} s; report: {paths['readme']}",
        flush=True,
    )
    if missed:
        print(f"did not meet their expectation: {', '.join(missed)}")
        return EXIT_UNMET
    print("every case met its expectation")
    return EXIT_OK
