"""``fence-sorter replay BAG [--rate R] [--topics ...] [--domain N]``: republish a recorded bag
over DDS with its original timing scaled by R, /clock included (fence_sorter.nodes.replay).

Exit codes: 0 replayed a clean bag; 1 replayed what was readable (problems named per file on
stderr); 2 bad input (not a bag, --rate <= 0, --domain outside 0-232, a topic not in the
bag); 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fence_sorter.recording.topics import CLOCK
from fence_sorter.runner.processes import DomainError, check_domain
from fence_sorter.visualisation.foxglove_address import AddressError, check_free, parse_address


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Republish every message of a bag (or the chosen topics) on the ROS domain --domain "
        "(default: ROS_DOMAIN_ID) with the recorded timing divided by --rate; /clock comes "
        "from the bag, so nodes with use_sim_time:=true follow it."
    )
    parser.add_argument("bag", help="bag directory (or one .mcap/.db3 file)")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    parser.add_argument(
        "--domain",
        type=int,
        metavar="N",
        help="ROS domain id to publish on, 0-232 (default: ROS_DOMAIN_ID or 0); e.g. the "
        "domain `fence-sorter run` prints",
    )
    parser.add_argument(
        "--wait",
        type=float,
        default=0.0,
        metavar="S",
        help="wait up to S s for a subscriber (or a Foxglove client) before starting",
    )
    parser.add_argument(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="serve the bag to the Foxglove app over the Foxglove WebSocket protocol at "
        "ws://HOST:PORT while it is replayed (HOST default 127.0.0.1; docs/guide/foxglove.md)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fence_sorter.recording.bagread import BagReadError, read_bag  # lazy: loads rosbags

    if not (args.rate > 0 and args.rate < float("inf")):
        print(f"fence-sorter replay: error: --rate must be in (0, inf), got {args.rate}",
              file=sys.stderr)  # fmt: skip
        return 2
    if args.domain is not None:
        try:
            check_domain(args.domain)
        except DomainError as exc:
            print(f"fence-sorter replay: error: {exc}", file=sys.stderr)
            return 2
    address = None
    if args.foxglove is not None:
        try:
            address = parse_address(args.foxglove)
            check_free(address)
        except AddressError as exc:
            print(f"fence-sorter replay: error: {exc}", file=sys.stderr)
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

    server = None
    hooks = {}
    if address is not None:
        try:
            server = _foxglove_server(contents, address, args.topics)
        except RuntimeError as exc:
            print(f"fence-sorter replay: error: --foxglove {args.foxglove}: {exc}",
                  file=sys.stderr)  # fmt: skip
            return 2
        print(f"serving the bag to Foxglove on ws://{server.host}:{server.port}", flush=True)
        hooks = {"on_publish": _foxglove_forward(server), "ready": server.has_clients}
    try:
        result = replay(
            contents,
            args.rate,
            args.topics,
            wait_for_subscribers=args.wait,
            domain=args.domain,
            **hooks,
        )
    except KeyboardInterrupt:
        print("fence-sorter replay: interrupted", file=sys.stderr)
        return 130
    finally:
        if server is not None:
            server.stop()
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


def _foxglove_server(contents, address: tuple[str, int], topics: list[str] | None):
    """A Foxglove server with a channel per replayed topic (the bag's embedded definitions)."""
    # lazy: websockets and rosbags only when serving
    from fence_sorter.recording.msgtypes import make_typestore
    from fence_sorter.visualisation.foxglove_live import LiveServer

    server = LiveServer(make_typestore(), host=address[0], port=address[1])
    for topic, msgtype in sorted(contents.types.items()):
        if topics is None or topic in topics:
            server.add_topic(topic, msgtype, contents.msgdefs.get(msgtype))
    return server


def _foxglove_forward(server):
    """Each replayed message to the Foxglove server as it is published (CDR as recorded);
    /clock is the server's time."""

    def forward(m) -> None:
        server.log(m.topic, m.raw, m.t_ns)
        if m.topic == CLOCK:
            server.broadcast_time(m.t_ns)

    return forward
