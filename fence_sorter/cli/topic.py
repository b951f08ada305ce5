"""``fence-sorter topic list|echo|hz``: stand-ins for ``ros2 topic`` (no ros2cli in the ROS 2
wheels), over rclpy, joining the ROS domain of a run (``--domain``; `fence-sorter run` prints
its domain; default ROS_DOMAIN_ID) with localhost discovery, as the run's nodes use.

- ``list``: the topics on the graph (``-t``: with their types), after a discovery wait.
- ``echo TOPIC``: each message as YAML (``--json``: one JSON object a line), ``-n`` messages.
- ``hz TOPIC``: the rate of arrival on the wall clock (average, min, max, std dev of the
  intervals, as ``ros2 topic hz``) and, for stamped messages, the rate of their header
  stamps, which is the sim-time rate in a run on /clock.

The subscription's QoS follows the publishers' (best effort if any offers only that,
transient local if all keep their last message), as ``ros2 topic echo`` chooses it.
Exit codes: 0 done; 1 the topic did not appear, or fewer messages than asked for came
within ``--timeout``; 2 bad options; 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import yaml

from fence_sorter.cli.ros_session import DomainSession, domain_options, run_in_session
from fence_sorter.cli.subcommands import add_subcommands, doc_summary
from fence_sorter.jsonsafe import json_safe
from fence_sorter.stamps import time_to_sec

#: seconds without a change of the graph after which `list` takes it as discovered
SETTLE = 0.5


def register(parser: argparse.ArgumentParser) -> None:
    commands = add_subcommands(parser, doc_summary(__doc__), "topic_command")
    common = domain_options("the topic and its messages")
    p_list = commands.add_parser(
        "list",
        parents=[common],
        help="the topics on the graph",
        description="Topics on the graph.",
    )
    p_list.add_argument("-t", "--show-types", action="store_true", help="with their types")
    p_list.add_argument(
        "--wait", type=float, default=5.0, help="longest discovery wait [s] (default 5)"
    )
    p_list.set_defaults(func=run_list)
    p_echo = commands.add_parser(
        "echo", parents=[common], help="print a topic's messages", description="Print messages."
    )
    p_echo.add_argument("topic")
    p_echo.add_argument("-n", "--count", type=int, default=0, help="stop after N (0: Ctrl-C)")
    p_echo.add_argument("--json", action="store_true", help="one JSON object a line")
    p_echo.set_defaults(func=run_echo)
    p_hz = commands.add_parser(
        "hz", parents=[common], help="a topic's rate", description="Rate of a topic."
    )
    p_hz.add_argument("topic")
    p_hz.add_argument(
        "-n", "--count", type=int, default=0, help="report once after N messages (0: Ctrl-C)"
    )
    p_hz.add_argument(
        "--window", type=int, default=10000, help="intervals kept for the figures (default all)"
    )
    p_hz.add_argument("--json", action="store_true", help="print the figures as JSON")
    p_hz.set_defaults(func=run_hz)


class TopicError(RuntimeError):
    """The topic is not on the graph or its type cannot be loaded (exit 1)."""


class _Session(DomainSession):
    """A session on the chosen domain that reads the graph's topics."""

    def __init__(self, domain: int | None, name: str) -> None:
        super().__init__(domain, f"fence_sorter_topic_{name}_{os.getpid()}")

    def topics(self) -> dict[str, list[str]]:
        return dict(self.node.get_topic_names_and_types())

    def wait_for(self, topic: str, timeout: float) -> str:
        """The type of ``topic`` once a publisher of it is on the graph."""
        deadline = time.monotonic() + timeout
        while True:
            types = self.topics().get(topic)
            if types and self.node.get_publishers_info_by_topic(topic):
                return types[0]
            if time.monotonic() > deadline:
                raise TopicError(f"topic {topic}: no publisher on the graph within {timeout:g} s")
            self.spin(0.05)

    def subscribe(self, topic: str, msgtype: str, callback):
        """A subscription with QoS the topic's publishers can serve."""
        # lazy: loads rclpy
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        # lazy: loads rclpy, ROS messages, rosbags
        from fence_sorter.nodes.recorder import message_class

        try:
            cls = message_class(msgtype)
        except (ImportError, AttributeError, ValueError) as exc:
            raise TopicError(f"topic {topic}: type {msgtype} cannot be loaded: {exc}") from None
        offered = [i.qos_profile for i in self.node.get_publishers_info_by_topic(topic)]
        best_effort = any(q.reliability == ReliabilityPolicy.BEST_EFFORT for q in offered)
        latched = bool(offered) and all(
            q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered
        )
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=100,
            reliability=ReliabilityPolicy.BEST_EFFORT
            if best_effort
            else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        return self.node.create_subscription(cls, topic, callback, qos)


def _run(args: argparse.Namespace, name: str, body) -> int:
    def session() -> _Session:
        return _Session(args.domain, name)

    return run_in_session(args, "topic", name, TopicError, session, body)


def run_list(args: argparse.Namespace) -> int:
    def body(s: _Session) -> int:
        # discovery: until another node is on the graph and the topics stopped changing for
        # SETTLE s, or --wait
        deadline = time.monotonic() + args.wait
        seen, changed = s.topics(), time.monotonic()
        own = s.node.get_fully_qualified_name()
        while time.monotonic() < deadline:
            s.spin(0.05)
            now = s.topics()
            if now != seen:
                seen, changed = now, time.monotonic()
            others = [n for n in s.node.get_fully_qualified_node_names() if n != own]
            if others and time.monotonic() - changed >= SETTLE:
                break
        for topic, types in sorted(seen.items()):
            print(f"{topic} [{', '.join(types)}]" if args.show_types else topic)
        return 0

    return _run(args, "list", body)


def plain(value):
    """A message dict for printing: rosidl's byte and char fields (bytes) as integers (a list
    for several), NaN and infinities as null for JSON."""
    if isinstance(value, bytes):
        return value[0] if len(value) == 1 else list(value)
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [plain(v) for v in value]
    return value


def run_echo(args: argparse.Namespace) -> int:
    from fence_sorter.nodes.convert import msg_to_dict  # lazy: loads ROS messages

    if args.count < 0:
        print(f"fence-sorter topic echo: --count must be >= 0, got {args.count}", file=sys.stderr)
        return 2

    def body(s: _Session) -> int:
        msgtype = s.wait_for(args.topic, args.timeout)
        received = []

        def show(msg) -> None:
            if args.count and len(received) >= args.count:
                return
            received.append(1)
            data = plain(msg_to_dict(msg))
            if args.json:
                print(json.dumps(json_safe(data)), flush=True)
            else:
                print(yaml.safe_dump(data, sort_keys=False).rstrip() + "\n---", flush=True)

        s.subscribe(args.topic, msgtype, show)
        deadline = time.monotonic() + args.timeout
        while not args.count or len(received) < args.count:
            if args.count and time.monotonic() > deadline:
                raise TopicError(
                    f"topic {args.topic}: {len(received)} of {args.count} messages "
                    f"within {args.timeout:g} s"
                )
            s.spin(0.1)
        return 0

    return _run(args, "echo", body)


def rate_figures(times: list[float]) -> dict[str, float] | None:
    """ros2 topic hz's figures of arrival (or stamp) times [s]: average rate [Hz] and min, max
    and standard deviation of the intervals [s]; None below two times."""
    if len(times) < 2:
        return None
    intervals = [b - a for a, b in zip(times, times[1:], strict=False)]
    mean = sum(intervals) / len(intervals)
    var = sum((d - mean) ** 2 for d in intervals) / len(intervals)
    return {
        "rate": 1.0 / mean if mean > 0 else math.inf,
        "min": min(intervals),
        "max": max(intervals),
        "std_dev": math.sqrt(var),
        "window": len(intervals),
    }


def _format_rate(label: str, f: dict[str, float]) -> str:
    return (
        f"{label}average rate: {f['rate']:.3f}\n\tmin: {f['min']:.6f}s max: {f['max']:.6f}s "
        f"std dev: {f['std_dev']:.6f}s window: {f['window']}"
    )


def run_hz(args: argparse.Namespace) -> int:
    if args.count < 0 or args.count == 1 or args.window < 1:
        print(
            "fence-sorter topic hz: --count must be 0 or >= 2 and --window >= 1",
            file=sys.stderr,
        )
        return 2

    def body(s: _Session) -> int:
        msgtype = s.wait_for(args.topic, args.timeout)
        arrivals: list[float] = []
        stamps: list[float] = []

        def tick(msg) -> None:
            if args.count and len(arrivals) >= args.count:
                return
            arrivals.append(time.monotonic())
            header = getattr(msg, "header", None)
            if header is not None:
                stamps.append(time_to_sec(header.stamp))
            del arrivals[: -args.window - 1], stamps[: -args.window - 1]

        s.subscribe(args.topic, msgtype, tick)
        deadline = time.monotonic() + args.timeout
        next_report = time.monotonic() + 1.0
        while True:
            s.spin(0.05)
            done = args.count and len(arrivals) >= args.count
            if args.count and not done and time.monotonic() > deadline:
                raise TopicError(
                    f"topic {args.topic}: {len(arrivals)} of {args.count} messages "
                    f"within {args.timeout:g} s"
                )
            if done or (not args.count and time.monotonic() >= next_report):
                next_report += 1.0
                wall, stamped = rate_figures(arrivals), rate_figures(stamps)
                if args.json:
                    print(json.dumps({"topic": args.topic, "wall": wall, "stamps": stamped}))
                elif wall is not None:
                    print(_format_rate("", wall), flush=True)
                    if stamped is not None:
                        print(_format_rate("header stamps: ", stamped), flush=True)
            if done:
                return 0

    return _run(args, "hz", body)
