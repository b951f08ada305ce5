"""Joining a ROS domain from the command line (``fence-sorter topic``, ``fence-sorter param``):
the ``--domain`` and ``--timeout`` options, and a session on the chosen domain: an rclpy
context with one node and its executor, with localhost discovery as a run's nodes use."""

from __future__ import annotations

import argparse
import os


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
