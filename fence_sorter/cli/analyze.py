"""``fence-sorter analyze BAG``: per-parcel table, stream capacity and share sorted, paper-style
plots, and the check of the recorded states against the live outcomes.

A line's bag (``fence-sorter run --line LINE --bag DIR``): the line summary computed from the
bag alone (:mod:`fence_sorter.analysis.line_bag`), as ``run --line`` prints it; ``--json`` is
the live run's ``--json`` summary field by field.

Exit codes: 0 analysed, every file readable and the states agree with the live outcomes (a
line's bag: the computed summary equals the live one and the recorded commands are the
replayed ones); 1 analysed what was readable but the bag has problems (named per file), the
states disagree, or an outcome or command is in the bag without its parcel's /parcels message
(a line's bag: a unit's reply is missing, or the summaries or commands differ); 2 not a bag /
nothing readable; 7 the bag agrees with itself, but a sorted parcel went over a limit of the
paper ((7), (10)-(12) as the run's controller had them) or an event's simulation failed (the
parcels are named).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fence_sorter.capacity.delivered import describe
from fence_sorter.cli.line_sim import format_summary
from fence_sorter.jsonsafe import json_safe

#: a clean bag whose sorted parcels went over a limit, or whose events failed
EXIT_LIMITS = 7


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
    from fence_sorter.analysis.line_bag import looks_like_line_bag
    from fence_sorter.analysis.report import analyze_bag, format_report, missing_parcels
    from fence_sorter.recording.bagread import BagReadError

    bag = Path(args.bag)
    out = Path(args.out) if args.out else None
    if looks_like_line_bag(bag):
        return _run_line(bag, out, args.json)
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
    limits = report.summary["limits"]
    if not limits["clean"]:
        print(f"fence-sorter analyze: not within the limits: {describe(limits)}", file=sys.stderr)
        return EXIT_LIMITS
    return 0


def _run_line(bag: Path, out: Path | None, as_json: bool) -> int:
    """The line summary of a line's bag; the checks' failures on stderr, one line each."""
    # lazy: the line's replay loads the line's physics (Numba) and rosbags
    from fence_sorter.analysis.line_bag import LineBagError, analyze_line_bag
    from fence_sorter.recording.bagread import BagReadError

    try:
        report = analyze_line_bag(bag)
    except BagReadError as exc:
        print(f"fence-sorter analyze: error: {exc}", file=sys.stderr)
        return 2
    except LineBagError as exc:
        print(f"fence-sorter analyze: {exc}", file=sys.stderr)
        return 1
    text = json.dumps(json_safe(report.summary))
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "line_summary.json").write_text(text + "\n", encoding="utf-8")
    if as_json:
        print(text)
    else:
        print(format_summary(report.summary))
        live = {None: "no live summary in the bag", True: "equals the live one"}.get(
            report.agrees_with_live, "DIFFERS from the live one"
        )
        print(
            f"from the bag: {report.commands_checked} commands replayed, "
            f"{len(report.commands_differing)} differ from the recorded ones; summary {live}"
        )
    for issue in report.issues:
        print(f"fence-sorter analyze: {issue}", file=sys.stderr)
    for key, (got, live_value) in report.differences.items():
        print(f"fence-sorter analyze: {key}: {got!r} from the bag, {live_value!r} live",
              file=sys.stderr)  # fmt: skip
    if report.commands_differing:
        print("fence-sorter analyze: replayed commands differ from the recorded ones: "
              + ", ".join(report.commands_differing), file=sys.stderr)  # fmt: skip
    return 0 if report.ok else 1
