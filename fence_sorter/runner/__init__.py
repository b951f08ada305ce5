"""The node suite as one job: processes on an isolated ROS domain, a monitor, a summary.

``processes`` (ROS-free): start nodes in their own process groups, stop them SIGINT -> SIGTERM ->
SIGKILL, find leftovers. ``monitor``: an rclpy node in the job's process that listens to the
suite. ``summary`` (ROS-free): the figures of a run. ``job``: `fence-sorter run` end to end.
"""
