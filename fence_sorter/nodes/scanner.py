"""Scanner node: measures parcels upstream of the fence and publishes fence_sorter_msgs/Parcel.

For now it only declares its parameters and reports through the diagnostic heartbeat.
"""

from __future__ import annotations

from collections.abc import Sequence

from fence_sorter.nodes.base import FenceSorterNode, ParamSpec, run_node


class ScannerNode(FenceSorterNode):
    """Scanner upstream of the fence: size, mass, gap Delta_s and yaw phi of each parcel."""

    NODE_NAME = "scanner"
    STATUS = "not yet implemented (issue: scanner node)"
    PARAMETERS = (
        ParamSpec(
            "frame_id", "sorter", "Fixed frame of the sorter (REP-103, z up)", read_only=True
        ),
        ParamSpec(
            "scan_position_x",
            -2.0,
            "Scan line position along the belt, frame sorter (fence axis at x = 0) [m]",
            read_only=True,
            min_value=-100.0,
            max_value=0.0,
        ),
        ParamSpec(
            "position_noise",
            0.0,
            "Standard deviation of the measured gap and sizes [m]",
            min_value=0.0,
            max_value=0.1,
        ),
        ParamSpec(
            "yaw_noise",
            0.0,
            "Standard deviation of the measured yaw phi [rad]",
            min_value=0.0,
            max_value=0.5,
        ),
    )


def main(args: Sequence[str] | None = None) -> int:
    """Run the scanner node until Ctrl-C or SIGTERM."""
    return run_node(ScannerNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
