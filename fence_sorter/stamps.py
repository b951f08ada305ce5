"""builtin_interfaces/Time in seconds, for every layer: rclpy's messages and the ones rosbags
deserialises from a bag alike (both have ``sec`` and ``nanosec``), so it needs no ROS."""

from __future__ import annotations


def time_to_sec(stamp) -> float:
    """builtin_interfaces/Time (``sec``, ``nanosec``) -> seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


__all__ = ["time_to_sec"]
