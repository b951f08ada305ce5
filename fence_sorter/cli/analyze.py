"""``fence-sorter analyze BAG``: per-parcel table, stream capacity and share sorted, paper-style
plots, and the check of the recorded states against the live outcomes.

Exit codes: 0 analysed, every file readable and the states agree with the live outcomes;
1 analysed what was readable but the bag has problems (named per file), the states disagree,
or an outcome or command is in the bag without its parcel's /parcels message;
2 not a bag / nothing readable.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Analyse a bag recorded by the recorder node (fence-sorter run --bag DIR)."
    )
    parser.add_argument("bag", help="bag directory (or one .mcap/.db3 file)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument(
        "--out",
        metavar="DIR",
        help="write parcels.csv, analysis.json and the plots here (default: print only)",
    )
    parser.add_argument("--no-plots", action="store_true", help="skip the plots")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # lazy: loads rosbags
    from fence_sorter.analysis.report import analyze_bag, format_report, missing_parcels
    from fence_sorter.recording.bagread import BagReadError

    bag = Path(args.bag)
    out = Path(args.out) if args.out else None
    try:
        report = analyze_bag(bag, out, plots=not args.no_plots)
    except BagReadError as exc:
        print(f"fence-sorter analyze: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report.to_json(), indent=1))
    else:
        print(format_report(report))
    for issue in report.issues:
        print(f"fence-sorter analyze: {issue}", file=sys.stderr)
    missing = missing_parcels(report.summary)
    for problem in missing:
        print(f"fence-sorter analyze: {problem}", file=sys.stderr)
    if report.issues or missing or report.summary["agrees_with_live"] is False:
        return 1
    return 0
