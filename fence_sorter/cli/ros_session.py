"""Joining a ROS domain from the command line (``fence-sorter topic``, ``fence-sorter param``):
the ``--domain`` and ``--timeout`` options, and a session on the chosen domain: an rclpy
context with one node and its executor, with localhost discovery as a run's nodes use."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable


def domain_options(timeout_help: str) -> argparse.ArgumentParser:
    """A parent parser with ``--domain`` and ``--timeout`` (``timeout_help`` says what the
    command waits for)."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--domain",
        type=int,
        default=None,
        help="ROS domain id to join (0-232; default: ROS_DOMAIN_ID or 0)",
    )
    common.add_argument(
        "--timeout",
        type=float,
        default=10.0,
        help=f"seconds to wait for {timeout_help} (default 10)",
    )
    return common


def run_in_session(
    args: argparse.Namespace,
    command: str,
    name: str,
    errors: type[Exception],
    open_session: Callable[[], DomainSession],
    body: Callable,
) -> int:
    """Check ``--domain`` and ``--timeout`` (exit 2), open a session with ``open_session()``
    and return ``body(session)``'s exit status; an ``errors`` exception prints as
    ``fence-sorter COMMAND NAME: <it>`` (exit 1), Ctrl-C exits 130; the session is closed in
    any case."""
    if args.domain is not None and not 0 <= args.domain <= 232:
        print(
            f"fence-sorter {command}: --domain must be in 0..232, got {args.domain}",
            file=sys.stderr,
        )
        return 2
    if args.timeout <= 0:
        print(
            f"fence-sorter {command}: --timeout must be > 0 s, got {args.timeout}", file=sys.stderr
        )
        return 2
    session = open_session()
    try:
        return body(session)
    except errors as exc:
        print(f"fence-sorter {command} {name}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        session.close()


class DomainSession:
    """An rclpy context and a node named ``node_name`` on ``domain`` (None: ROS_DOMAIN_ID),
    spun by a single-threaded executor."""

    def __init__(self, domain: int | None, node_name: str) -> None:
        import rclpy  # lazy: rclpy (0.25 s), only where ROS runs
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        self.rclpy = rclpy
        self.context = rclpy.Context()
        kwargs = {"domain_id": domain} if domain is not None else {}
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO, **kwargs)
        self.node = rclpy.create_node(node_name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin(self, seconds: float) -> None:
        self.executor.spin_once(timeout_sec=seconds)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)
