"""``fence-sorter demo-roundtrip``: every fence_sorter_msgs message between two nodes over DDS.

Starts an echo node in a second process, publishes one sample of every message type (every
field set) from this process and checks that each comes back unchanged.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys

from fence_sorter.cli.check import FIX

ECHO_EXIT_WAIT = 5.0  # s to wait for the echo process to end by itself


def _domain_id(requested: int | None) -> int:
    if requested is not None:
        return requested
    env = os.environ.get("ROS_DOMAIN_ID")
    if env and env.isdigit():
        return int(env)
    return random.randint(101, 199)  # away from the default domain 0 and other runs


def run(args: argparse.Namespace) -> int:
    """Run the round trip; print one line per message type; return 0 if all came back."""
    try:
        import rclpy  # lazy: rclpy (0.25 s), only where ROS runs

        # lazy: loads rclpy, ROS messages, rosbags
        from fence_sorter.nodes.roundtrip import print_result, run_publisher
    except Exception as exc:
        print(f"FAIL cannot import rclpy / fence_sorter_msgs ({exc}); {FIX}")
        return 1
    domain_id = _domain_id(args.domain_id)
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    print(f"demo-roundtrip: ROS_DOMAIN_ID={domain_id}, echo node in a second process")
    echo = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "fence_sorter.nodes.roundtrip",
            "echo",
            "--timeout",
            str(args.timeout + ECHO_EXIT_WAIT),
        ],
        env=os.environ.copy(),
    )
    try:
        rclpy.init(domain_id=domain_id)
        try:
            result = run_publisher(args.timeout)
        finally:
            rclpy.try_shutdown()
        print_result(result)
        try:
            echo.wait(timeout=ECHO_EXIT_WAIT)
        except subprocess.TimeoutExpired:
            pass
    finally:
        if echo.poll() is None:
            echo.terminate()
            try:
                echo.wait(timeout=ECHO_EXIT_WAIT)
            except subprocess.TimeoutExpired:
                echo.kill()
                echo.wait()
    if result.ok:
        print(f"demo-roundtrip: all {len(result.diffs)} message types made the round trip")
        return 0
    print("demo-roundtrip: FAILED")
    return 1


def register(parser: argparse.ArgumentParser) -> None:
    """Configure the ``demo-roundtrip`` subcommand."""
    parser.add_argument("--timeout", type=float, default=30.0, help="give up after [s]")
    parser.add_argument(
        "--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: env or random)"
    )
    parser.set_defaults(func=run)
