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

# What the nodes take in from outside (/parcels, /fence_commands): reliable, keep-all. A
# keep-last reader's history silently overwrites samples it has not taken yet (a flood would push
# real parcels out unseen); a keep-all reader keeps every sample until the node takes it and
# refuses or accepts it (fence_sorter.nodes.intake), and what a writer gives up before
# delivery reaches the reader as the middleware's message-lost event, counted there.
INPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    depth=1,
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
