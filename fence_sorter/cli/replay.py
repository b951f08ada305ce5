"""``fence-sorter replay BAG [--rate R] [--topics ...]``: republish a recorded bag over DDS with
its original timing scaled by R, /clock included (fence_sorter.nodes.replay).

Exit codes: 0 replayed a clean bag; 1 replayed what was readable (problems named per file on
stderr); 2 bad input (not a bag, --rate <= 0, a topic not in the bag); 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Republish every message of a bag (or the chosen topics) on the current "
        "ROS_DOMAIN_ID with the recorded timing divided by --rate; /clock comes from the bag, so "
        "nodes with use_sim_time:=true follow it."
    )
    parser.add_argument("bag", help="bag directory (or one .mcap/.db3 file)")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    parser.add_argument(
        "--wait",
        type=float,
        default=0.0,
        metavar="S",
        help="wait up to S s for a subscriber before starting",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fence_sorter.recording.bagread import BagReadError, read_bag  # lazy: loads rosbags

    if not (args.rate > 0 and args.rate < float("inf")):
        print(f"fence-sorter replay: error: --rate must be in (0, inf), got {args.rate}",
              file=sys.stderr)  # fmt: skip
        return 2
    try:
        contents = read_bag(Path(args.bag))
    except BagReadError as exc:
        print(f"fence-sorter replay: error: {exc}", file=sys.stderr)
        return 2
    for issue in contents.issues:
        print(f"fence-sorter replay: {issue}", file=sys.stderr)
    if args.topics:
        missing = sorted(set(args.topics) - set(contents.counts()))
        if missing:
            print(
                f"fence-sorter replay: error: --topics: {', '.join(missing)} not in the bag "
                f"(it has {', '.join(sorted(contents.counts()))})",
                file=sys.stderr,
            )
            return 2
    from fence_sorter.nodes.replay import replay  # lazy: loads rosbags

    try:
        result = replay(contents, args.rate, args.topics, wait_for_subscribers=args.wait)
    except KeyboardInterrupt:
        print("fence-sorter replay: interrupted", file=sys.stderr)
        return 130
    counts = ", ".join(f"{t} {n}" for t, n in sorted(result.published.items()))
    print(
        f"replayed {sum(result.published.values())} messages ({counts}) in "
        f"{result.wall_time:.2f} s wall for {result.bag_time:.2f} s of bag; max lateness "
        f"{1e3 * result.max_lateness:.1f} ms"
    )
    if result.unacknowledged:
        print(
            "not acknowledged by every reliable subscriber: " + " ".join(result.unacknowledged),
            file=sys.stderr,
        )
    return 1 if contents.issues else 0
