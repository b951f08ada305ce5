"""fence_sorter: digital twin of a rotary active fence parcel sorter (ROS 2, rosbag2, Rerun)."""

__version__ = "0.1.0"
