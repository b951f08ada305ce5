"""Spin a node through rare take failures instead of dying on the first one.

Under heavy load rclpy's ``take_message`` occasionally raises ``RuntimeError: Unable to convert
call argument '0' to Python object`` for a message that arrived (seen here once in some
thirty suite runs on a loaded 2-core machine; ros/joint_state_publisher#117 reports the same
under load). :func:`run_resilient` logs and counts such a failure (the node reports
``take_errors`` in its diagnostics), loses that one message, and keeps spinning; shutdown,
Ctrl-C and SIGTERM end it as :func:`fence_sorter.nodes.base.run_node` does.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from fence_sorter.nodes.base import FenceSorterNode

#: more take failures than this in one run: something is really broken, stop
MAX_TAKE_ERRORS = 100


def run_resilient(node_class: type[FenceSorterNode], args: Sequence[str] | None = None) -> int:
    """Init rclpy, spin one node until Ctrl-C, SIGTERM or shutdown; return the exit code."""
    rclpy.init(args=list(args) if args is not None else None)
    node: FenceSorterNode | None = None
    try:
        node = node_class()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok():
            try:
                executor.spin_once(timeout_sec=0.1)
            except (KeyboardInterrupt, ExternalShutdownException):
                raise
            except RuntimeError as exc:  # rclpy's RCLError is one too
                if not rclpy.ok():
                    break
                node.take_errors = getattr(node, "take_errors", 0) + 1
                node.get_logger().error(
                    f"a message could not be taken ({type(exc).__name__}: {exc}); "
                    f"{node.take_errors} so far, going on"
                )
                if node.take_errors > MAX_TAKE_ERRORS:
                    raise
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterException as exc:
        print(f"{node_class.NODE_NAME}: invalid parameter: {exc}", file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
