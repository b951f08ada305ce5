"""QoS profiles of fence_sorter topics, as named constants chosen per kind of topic."""

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

# High-rate state (fence state, load states, joint states): the newest sample is what counts.
SENSOR_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=5,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)

# Scanned parcels, fence commands, sort outcomes, diagnostics: none may drop.
RELIABLE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# What the nodes take in from outside (/parcels, /fence_commands): reliable, and a history deep
# enough for a burst far beyond any stream, so a flood is refused and counted by the node
# (fence_sorter.nodes.intake) instead of overwriting real messages in the history unseen.
INPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=5000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# Static descriptions (scene, fence geometry markers): late joiners get the last one.
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# /tf: reliable, volatile, depth 100 (what tf2's TransformListener asks for).
TF_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

__all__ = ["INPUT_QOS", "LATCHED_QOS", "RELIABLE_QOS", "SENSOR_QOS", "TF_QOS"]
