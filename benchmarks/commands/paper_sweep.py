"""``python -m benchmarks paper-sweep NAME``: the optimisation sweeps behind the paper's Figs.
3-10 and the controller's decision table (:mod:`benchmarks.paper.sweep`) -> docs/reports/paper/.

NAME is a sweep (``fig3`` ... ``fig10``, ``fig7-fixed-rz``, ``fig10-fixed-rz``,
``decision-table``), several separated by commas, or ``all`` (the paper's figures). Exit codes:
0 done, 1 a point failed (the others are saved; a rerun retries it), 2 bad arguments, 130
interrupted (finished points are saved; a rerun resumes).
"""

from __future__ import annotations

import argparse
import sys

DEFAULT_OUT = "docs/reports/paper"
DEFAULT_TABLE = "config/decision_table.yaml"


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Run (or resume) the paper's optimisation sweeps: one optimum of W_t (1) per point of a "
        "figure, appended to <out>/<run>.csv, then the figure as <out>/<name>.png."
    )
    parser.add_argument("sweep", metavar="NAME", help="a sweep (e.g. fig6), several, or all")
    parser.add_argument("--out", default=DEFAULT_OUT, help="output directory (%(default)s)")
    parser.add_argument(
        "--table",
        default=DEFAULT_TABLE,
        metavar="PATH",
        help="where the decision-table sweep writes the controller's table (%(default)s)",
    )
    parser.add_argument(
        "--resume",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="continue a sweep from its saved results (default: yes)",
    )
    parser.add_argument(
        "--repair",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="after a sweep, re-solve each looser problem whose optimum lies below a tighter "
        "neighbour's, starting from the tighter optima (default: yes)",
    )
    parser.add_argument(
        "--max-points",
        type=int,
        default=None,
        metavar="N",
        help="stop a sweep after N new points (resume later)",
    )
    parser.add_argument(
        "--plots-only",
        action="store_true",
        help="redraw the sweeps' figures from their CSVs in --out, solve nothing",
    )
    parser.add_argument("--workers", type=int, default=None, help="processes (default: CPU count)")
    parser.add_argument(
        "--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler, e.g. tcp://h:8786"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    for option, value in (("--max-points", args.max_points), ("--workers", args.workers)):
        if value is not None and value < 1:
            print(f"benchmarks: error: {option} must be in [1, inf), got {value}", file=sys.stderr)
            return 2
    from benchmarks.paper import sweep  # lazy: loads the kernel (Numba), SciPy

    return int(sweep.main(args) or 0)
