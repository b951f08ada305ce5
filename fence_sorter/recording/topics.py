"""The topics of the node suite as they are recorded: type and whether they are reliable."""

from __future__ import annotations

#: topic -> (type, reliable). Reliable topics are recorded (and replayed) reliable, the others
#: best effort: what their publishers offer (fence_sorter/nodes/qos.py, nodes/simulator.py).
TOPIC_TYPES: dict[str, tuple[str, bool]] = {
    "/clock": ("rosgraph_msgs/msg/Clock", True),
    "/parcels": ("fence_sorter_msgs/msg/Parcel", True),
    "/scan_progress": ("rosgraph_msgs/msg/Clock", True),
    "/fence_commands": ("fence_sorter_msgs/msg/FenceCommand", True),
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
