"""rclpy QoS profiles of the suite's topics, built from :mod:`fence_sorter.recording.topics`
(the one place for topic names, types, QoS and history depths)."""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

from fence_sorter.recording import topics
from fence_sorter.recording.topics import QosSpec


def profile(spec: QosSpec) -> QoSProfile:
    """The rclpy profile of a :class:`QosSpec`."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if spec.keep_all else HistoryPolicy.KEEP_LAST,
        depth=spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE
        ),
    )


def topic_qos(name: str, depth: int | None = None) -> QoSProfile:
    """The profile a suite or measured topic is published and subscribed with (``depth``: another
    keep-last depth, e.g. the recorder's)."""
    spec = topics.ALL_TOPICS[name].qos
    return profile(spec if depth is None else spec.with_depth(depth))


# High-rate state (fence state, load states): the newest sample is what counts.
SENSOR_QOS = profile(topics.STATE_QOS)
# Sort outcomes, diagnostics, scan progress: none may drop.
RELIABLE_QOS = profile(topics.EVENT_QOS)
# /clock: reliable keep-last, compatible with rclpy/rclcpp's best-effort clock subscriptions
# and with reliable ones (recorders); /joint_states and /markers as robot_state_publisher and
# RViz ask for them.
CLOCK_QOS = profile(topics.CLOCK_QOS)
VIEWER_QOS = CLOCK_QOS
# /parcels and /fence_commands: reliable, transient local, history covering the stream, so a
# subscriber that joins late (recorder, restarted controller) still gets every message. Their
# subscribers are transient local too: a volatile publisher on these topics is not matched
# (rclpy logs the incompatible QoS). The depth also lets a flood be refused and counted by the
# node (fence_sorter.nodes.intake) instead of overwriting real messages in the history unseen.
STREAM_QOS = profile(topics.STREAM_QOS)
# What the nodes take in from outside (/parcels, /fence_commands): keep-all, transient local.
# A keep-last reader's history silently overwrites samples it has not taken yet (a flood pushed
# real parcels out unseen); a keep-all reader keeps every sample until the node takes it and
# refuses or accepts it (fence_sorter.nodes.intake), and what a writer gives up before
# delivery reaches the reader as the middleware's message-lost event, counted there.
INPUT_QOS = profile(topics.INPUT_QOS)
# Static descriptions (scene, fence geometry markers): late joiners get the last one.
LATCHED_QOS = profile(topics.LATCHED_QOS)
# /tf: reliable, volatile, depth 100 (what tf2's TransformListener asks for).
TF_QOS = profile(topics.TF_QOS)

__all__ = [
    "CLOCK_QOS",
    "INPUT_QOS",
    "LATCHED_QOS",
    "RELIABLE_QOS",
    "SENSOR_QOS",
    "STREAM_QOS",
    "TF_QOS",
    "VIEWER_QOS",
    "profile",
    "topic_qos",
]
