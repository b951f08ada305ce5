"""Recorder node: writes the sorter topics to a rosbag2 (MCAP) bag.

For now it only declares its parameters and reports through the diagnostic heartbeat.
"""

from __future__ import annotations

from collections.abc import Sequence

from fence_sorter.nodes.base import FenceSorterNode, ParamSpec, run_node

DEFAULT_TOPICS = [
    "/clock",
    "/parcels",
    "/fence_commands",
    "/fence_state",
    "/load_states",
    "/sort_outcomes",
    "/joint_states",
    "/markers",
    "/diagnostics",
]


class RecorderNode(FenceSorterNode):
    """Bag recorder: subscribes raw (CDR passed through) and writes rosbag2 MCAP."""

    NODE_NAME = "recorder"
    STATUS = "not yet implemented (issue: recorder node)"
    PARAMETERS = (
        ParamSpec(
            "output_dir",
            "bags",
            "Directory that receives one bag per run (created if missing)",
            read_only=True,
        ),
        ParamSpec(
            "storage", "mcap", "rosbag2 storage plugin (only mcap is supported)", read_only=True
        ),
        ParamSpec("topics", list(DEFAULT_TOPICS), "Topics to record", read_only=True),
    )


def main(args: Sequence[str] | None = None) -> int:
    """Run the recorder node until Ctrl-C or SIGTERM."""
    return run_node(RecorderNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
