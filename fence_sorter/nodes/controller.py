"""Controller node: plans a fence stroke (R_s, t1, alpha_k) per scanned parcel.

For now it only declares its parameters and reports through the diagnostic heartbeat.
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.parameter import Parameter

from fence_sorter.nodes.base import FenceSorterNode, ParamSpec, run_node


class ControllerNode(FenceSorterNode):
    """Fence controller: turns scanned parcels into fence_sorter_msgs/FenceCommand."""

    NODE_NAME = "controller"
    STATUS = "not yet implemented (issue: controller node)"
    PARAMETERS = (
        ParamSpec("t1_min", 0.2, "Shortest working time t1 [s]", min_value=0.01, max_value=10.0),
        ParamSpec("t1_max", 1.5, "Longest working time t1 [s]", min_value=0.01, max_value=10.0),
        ParamSpec(
            "alpha_k_max",
            1.0,
            "Largest fence angle alpha_k [rad]",
            min_value=0.0,
            max_value=1.5707963267948966,
        ),
        ParamSpec(
            "max_peak_force",
            0.0,
            "Limit on the predicted contact force N [N]; 0: no limit",
            min_value=0.0,
            max_value=1.0e6,
        ),
        ParamSpec(
            "max_peak_accel",
            0.0,
            "Limit on the predicted parcel acceleration [m/s^2]; 0: no limit",
            min_value=0.0,
            max_value=1.0e4,
        ),
    )

    def validate_parameters(self, parameters: Sequence[Parameter]) -> str | None:
        """Refuse t1_min > t1_max."""
        values = {p.name: p.value for p in parameters}
        t1_min = values.get("t1_min", self.get_parameter("t1_min").value)
        t1_max = values.get("t1_max", self.get_parameter("t1_max").value)
        if t1_min > t1_max:
            return f"t1_min ({t1_min} s) must not exceed t1_max ({t1_max} s)"
        return None


def main(args: Sequence[str] | None = None) -> int:
    """Run the controller node until Ctrl-C or SIGTERM."""
    return run_node(ControllerNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
