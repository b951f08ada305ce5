"""Simulator node: runs the physics of belt, fence and parcels and publishes /clock and states.

For now it only declares its parameters and reports through the diagnostic heartbeat.
"""

from __future__ import annotations

from collections.abc import Sequence

from fence_sorter.nodes.base import FenceSorterNode, ParamSpec, run_node


class SimulatorNode(FenceSorterNode):
    """Digital twin of the sorter: belt, rotary fence and parcels, paced by wall time."""

    NODE_NAME = "simulator"
    STATUS = "not yet implemented (issue: simulator node)"
    PARAMETERS = (
        ParamSpec(
            "scene",
            "",
            "Scene YAML file (config/scenes/...); empty: the default scene",
            read_only=True,
        ),
        ParamSpec(
            "frame_id", "sorter", "Fixed frame of the sorter (REP-103, z up)", read_only=True
        ),
        ParamSpec(
            "real_time_factor",
            1.0,
            "Sim time advanced per wall second [-]",
            min_value=0.01,
            max_value=100.0,
        ),
        ParamSpec(
            "physics_dt",
            1.0e-4,
            "Physics integration step [s]",
            read_only=True,
            min_value=1.0e-6,
            max_value=1.0e-2,
        ),
        ParamSpec(
            "publish_rate",
            50.0,
            "Rate of /clock, state and marker publication [Hz] (wall clock)",
            read_only=True,
            min_value=1.0,
            max_value=1000.0,
        ),
        ParamSpec(
            "max_catch_up",
            0.1,
            "Largest sim time advanced in one pacing step after a stall [s]",
            min_value=0.0,
            max_value=10.0,
        ),
    )


def main(args: Sequence[str] | None = None) -> int:
    """Run the simulator node until Ctrl-C or SIGTERM."""
    return run_node(SimulatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
