"""Two-node round trip of every fence_sorter_msgs message over DDS (demo and test tool).

Run the two roles in two processes::

    python -m fence_sorter.nodes.roundtrip echo --record received.json
    python -m fence_sorter.nodes.roundtrip publish

``publish`` sends one sample of every message type (every field set to a non-default value,
see :func:`fence_sorter.recording.samples.sample_values`) on ``/fence_sorter/roundtrip/in/<Type>``
until the echo of each comes back on ``/fence_sorter/roundtrip/out/<Type>``, and checks that the
echo equals what it sent. ``echo`` republishes what it receives and records the first message
of each type as JSON, so a third party (the tests) can check the received fields as well.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from fence_sorter.nodes.convert import dict_to_msg, msg_to_dict
from fence_sorter.nodes.qos import RELIABLE_QOS
from fence_sorter.recording.msgtypes import MSG_PACKAGE, make_typestore, message_names
from fence_sorter.recording.msgtypes import msgtype_name as full_name
from fence_sorter.recording.samples import MessageDict, diff_values, sample_values

TOPIC_IN = "/fence_sorter/roundtrip/in/{}"
TOPIC_OUT = "/fence_sorter/roundtrip/out/{}"
DEFAULT_SEED = 1
RESEND_PERIOD = 0.25  # s between re-sends of messages not yet echoed


def message_class(name: str) -> type:
    """Return the rclpy class fence_sorter_msgs.msg.<name>."""
    module = importlib.import_module(f"{MSG_PACKAGE}.msg")
    return getattr(module, name)


def sample_messages(seed: int = DEFAULT_SEED) -> dict[str, MessageDict]:
    """Return {message name: sample dict} for every fence_sorter_msgs message."""
    typestore = make_typestore()
    return {name: sample_values(typestore, full_name(name), seed) for name in message_names()}


class EchoNode(Node):
    """Republishes every fence_sorter_msgs message it receives and keeps the first of each."""

    def __init__(self, names: Sequence[str]) -> None:
        super().__init__("roundtrip_echo")
        self.received: dict[str, MessageDict] = {}
        self.last_receive = time.monotonic()
        self._pubs = {}
        for name in names:
            cls = message_class(name)
            self._pubs[name] = self.create_publisher(cls, TOPIC_OUT.format(name), RELIABLE_QOS)
            self.create_subscription(
                cls, TOPIC_IN.format(name), self._make_callback(name), RELIABLE_QOS
            )

    def _make_callback(self, name: str) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            self.last_receive = time.monotonic()
            self.received.setdefault(name, msg_to_dict(msg))
            self._pubs[name].publish(msg)

        return callback


class PublishNode(Node):
    """Sends the samples until each has come back from the echo node."""

    def __init__(self, samples: dict[str, MessageDict]) -> None:
        super().__init__("roundtrip_publish")
        self.samples = samples
        self.echoed: dict[str, MessageDict] = {}
        self._messages = {}
        self._pubs = {}
        for name, values in samples.items():
            cls = message_class(name)
            self._messages[name] = dict_to_msg(cls, values)
            self._pubs[name] = self.create_publisher(cls, TOPIC_IN.format(name), RELIABLE_QOS)
            self.create_subscription(
                cls, TOPIC_OUT.format(name), self._make_callback(name), RELIABLE_QOS
            )

    def _make_callback(self, name: str) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            self.echoed.setdefault(name, msg_to_dict(msg))

        return callback

    def send_pending(self) -> None:
        """Publish every sample whose echo has not arrived yet."""
        for name, msg in self._messages.items():
            if name not in self.echoed:
                self._pubs[name].publish(msg)


@dataclass
class RoundTripResult:
    """Outcome of one round trip: per message name, the list of differences (empty: equal)."""

    diffs: dict[str, list[str]] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True if every message came back, equal to what was sent."""
        return not self.missing and not any(self.diffs.values())


def run_publisher(timeout: float, seed: int = DEFAULT_SEED) -> RoundTripResult:
    """Publish the samples until all echoes arrived or ``timeout`` s passed (rclpy initialised)."""
    node = PublishNode(sample_messages(seed))
    try:
        deadline = time.monotonic() + timeout
        next_send = 0.0
        while len(node.echoed) < len(node.samples) and time.monotonic() < deadline:
            now = time.monotonic()
            if now >= next_send:
                node.send_pending()
                next_send = now + RESEND_PERIOD
            rclpy.spin_once(node, timeout_sec=0.05)
        result = RoundTripResult()
        for name, expected in node.samples.items():
            if name in node.echoed:
                result.diffs[name] = diff_values(expected, node.echoed[name])
            else:
                result.missing.append(name)
        return result
    finally:
        node.destroy_node()


def run_echo(timeout: float, linger: float, record: Path | None) -> int:
    """Echo until all types were received and ``linger`` s passed quietly, or ``timeout``."""
    names = message_names()
    node = EchoNode(names)
    try:
        deadline = time.monotonic() + timeout
        written = False
        while time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
            complete = len(node.received) == len(names)
            if complete and record is not None and not written:
                record.write_text(json.dumps(node.received, indent=1, sort_keys=True))
                written = True
            if complete and time.monotonic() - node.last_receive > linger:
                return 0
        missing = sorted(set(names) - set(node.received))
        print(f"echo: timed out; never received: {', '.join(missing)}", file=sys.stderr)
        return 2
    finally:
        node.destroy_node()


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m fence_sorter.nodes.roundtrip")
    sub = parser.add_subparsers(dest="role", required=True)
    echo = sub.add_parser("echo", help="republish and record every fence_sorter_msgs message")
    echo.add_argument("--record", type=Path, help="write the received messages as JSON here")
    echo.add_argument("--timeout", type=float, default=30.0, help="give up after [s]")
    echo.add_argument("--linger", type=float, default=1.0, help="quiet time before exit [s]")
    pub = sub.add_parser("publish", help="send every message and check the echoes")
    pub.add_argument("--timeout", type=float, default=30.0, help="give up after [s]")
    pub.add_argument("--seed", type=int, default=DEFAULT_SEED, help="sample seed")
    return parser


def print_result(result: RoundTripResult, stream: Any = sys.stdout) -> None:
    """Print one line per message type: OK, or what differs."""
    for name, diffs in sorted(result.diffs.items()):
        if diffs:
            print(f"FAIL {name}: " + "; ".join(diffs), file=stream)
        else:
            print(f"OK   {name}: every field came back unchanged", file=stream)
    for name in result.missing:
        print(f"FAIL {name}: no echo received", file=stream)


def main(argv: Sequence[str] | None = None) -> int:
    """Run one role of the round trip; exit 0 on success."""
    args = _parser().parse_args(argv)
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        print("--timeout must be a positive number of seconds", file=sys.stderr)
        return 2
    rclpy.init()
    try:
        if args.role == "echo":
            return run_echo(args.timeout, args.linger, args.record)
        result = run_publisher(args.timeout, args.seed)
        print_result(result)
        return 0 if result.ok else 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    raise SystemExit(main())
