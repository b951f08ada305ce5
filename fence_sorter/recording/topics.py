"""The topics of the node suite as they are recorded: type and whether they are reliable."""

from __future__ import annotations

PARCELS = "/parcels"
FENCE_COMMANDS = "/fence_commands"
#: measured topics a real sorter can record (docs/calibration.md): drive encoder (>= 200 Hz),
#: overhead camera poses of the parcels (25-120 Hz), fence root bending moment (>= 1 kHz)
DRIVE_ENCODER = "/sensors/drive_encoder"
CAMERA_POSES = "/sensors/camera/parcel_poses"
FENCE_ROOT_MOMENT = "/sensors/fence_root/moment"

#: topic -> (type, reliable). Reliable topics are recorded (and replayed) reliable, the others
#: best effort: what their publishers offer (fence_sorter/nodes/qos.py, nodes/simulator.py).
TOPIC_TYPES: dict[str, tuple[str, bool]] = {
    "/clock": ("rosgraph_msgs/msg/Clock", True),
    PARCELS: ("fence_sorter_msgs/msg/Parcel", True),
    "/scan_progress": ("rosgraph_msgs/msg/Clock", True),
    FENCE_COMMANDS: ("fence_sorter_msgs/msg/FenceCommand", True),
    "/fence_state": ("fence_sorter_msgs/msg/FenceState", False),
    "/load_states": ("fence_sorter_msgs/msg/LoadState", False),
    "/sort_outcomes": ("fence_sorter_msgs/msg/SortOutcome", True),
    "/sort_events": ("fence_sorter_msgs/msg/SortEvent", True),
    "/joint_states": ("sensor_msgs/msg/JointState", True),
    "/markers": ("visualization_msgs/msg/MarkerArray", True),
    "/diagnostics": ("diagnostic_msgs/msg/DiagnosticArray", True),
    "/tf": ("tf2_msgs/msg/TFMessage", True),
    "/tf_static": ("tf2_msgs/msg/TFMessage", True),
    "/robot_description": ("std_msgs/msg/String", True),
}
#: published once, transient local: subscribed transient local so a late recorder gets them
LATCHED_TOPICS = frozenset({"/tf_static", "/robot_description"})
SUITE_TOPICS = list(TOPIC_TYPES)
MEASURED_TOPICS: dict[str, tuple[str, bool]] = {
    DRIVE_ENCODER: ("sensor_msgs/msg/JointState", False),
    CAMERA_POSES: ("fence_sorter_msgs/msg/LoadState", False),
    FENCE_ROOT_MOMENT: ("geometry_msgs/msg/WrenchStamped", False),
}
