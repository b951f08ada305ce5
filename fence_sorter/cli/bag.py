"""``fence-sorter bag info BAG``: a stand-in for ``ros2 bag info`` (no rosbag2 CLI in the ROS 2
wheels): files, size, storage, duration, start and end, messages per topic with their types,
compression, and the health of each segment.

Exit codes: 0 every segment healthy; 1 a segment or metadata.yaml has a problem (named, the
rest is counted); 2 not a bag.
"""

from __future__ import annotations

import argparse
import json
import sys

from fence_sorter.cli.subcommands import add_subcommands, doc_summary


def register(parser: argparse.ArgumentParser) -> None:
    commands = add_subcommands(
        parser, "Stand-ins for `ros2 bag` subcommands, without rosbag2.", "bag_command"
    )
    info = commands.add_parser(
        "info",
        help="what `ros2 bag info` shows, plus the health of each segment",
        description=doc_summary(__doc__),
    )
    info.add_argument("bag", help="bag directory (or one .mcap/.db3 file)")
    info.add_argument("--json", action="store_true", help="print it as one JSON object")
    info.set_defaults(func=run_info)


def run_info(args: argparse.Namespace) -> int:
    from fence_sorter.recording.baginfo import bag_info, format_info  # lazy: loads rosbags
    from fence_sorter.recording.bagread import BagReadError

    try:
        info = bag_info(args.bag)
    except BagReadError as exc:
        print(f"fence-sorter bag info: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(info.to_json(), indent=1) if args.json else format_info(info))
    return 0 if info.healthy else 1
