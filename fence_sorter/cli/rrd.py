"""``fence-sorter rrd BAG [--out FILE] [--force]``: a recorded bag as a Rerun recording (.rrd);
without ``--out`` it is ``<bag>.rrd`` beside the bag, and an existing one is kept unless
``--force``.

A line's bag (``run --line --bag``): the line's view, its units simulated again from their
recorded commands (:mod:`fence_sorter.visualisation.line_bag_view`).

Exit codes: 0 written from a clean bag (a line's bag: every reply of the units simulated
again equals the recorded one); 1 written from what was readable (problems named per
file on stderr); 2 not a bag / nothing readable, the output cannot be written, or the
default output exists (without --force).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fence_sorter.recording.topics import LINE_SETUP
from fence_sorter.visualisation.frames import scene_from_bag
from fence_sorter.visualisation.rerun_bag import bag_end, log_bag
from fence_sorter.visualisation.rerun_layout import open_recording


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Log a bag recorded by the recorder node into an .rrd (conveyor, chute, "
        "fence with its deflection, parcels, contact forces, time series on sim_time) with a "
        "default blueprint; open it with `rerun FILE`."
    )
    parser.add_argument("bag", help="bag directory (or one .mcap/.db3 file)")
    parser.add_argument(
        "-o",
        "--out",
        metavar="FILE",
        help="output .rrd (default: <bag>.rrd beside the bag, not overwritten without --force)",
    )
    parser.add_argument(
        "--force", action="store_true", help="overwrite the default <bag>.rrd if it exists"
    )
    parser.add_argument(
        "--spawn", action="store_true", help="also stream to a Rerun viewer spawned locally"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fence_sorter.recording.bagread import BagReadError, read_bag  # lazy: loads rosbags

    bag = Path(args.bag)
    out = Path(args.out) if args.out else bag.resolve().with_suffix(".rrd")
    if out.suffix != ".rrd":
        print(f"fence-sorter rrd: error: --out {out}: must end in .rrd", file=sys.stderr)
        return 2
    if not args.out and out.exists() and not args.force:
        print(f"fence-sorter rrd: error: {out} exists (the default output, <bag>.rrd): give "
              "--out FILE, or --force to overwrite it", file=sys.stderr)  # fmt: skip
        return 2
    try:
        contents = read_bag(bag)
    except BagReadError as exc:
        print(f"fence-sorter rrd: error: {exc}", file=sys.stderr)
        return 2
    if not out.parent.is_dir():
        print(f"fence-sorter rrd: error: --out {out}: no directory {out.parent}", file=sys.stderr)
        return 2
    if contents.by_topic(LINE_SETUP):
        return _line(contents, out, args.spawn)
    rec = open_recording(
        out, spawn=args.spawn, scene=scene_from_bag(contents), t_end=bag_end(contents)
    )
    logger = log_bag(contents, rec)
    logger.close()
    print(f"wrote {out} ({logger.frames} frames, {out.stat().st_size / 1e6:.2f} MB)")
    for issue in contents.issues:
        print(f"fence-sorter rrd: {issue}", file=sys.stderr)
    return 1 if contents.issues else 0


def _line(contents, out: Path, spawn: bool) -> int:
    # lazy: the line's units load Numba and the compiled kernel
    from fence_sorter.visualisation.line_bag_view import write_line_view

    return write_line_view(contents, out, spawn, say=print, warn=_warn)


def _warn(line: str) -> None:
    print(f"fence-sorter rrd: {line}", file=sys.stderr)
