"""Views of the twin (Rerun), ROS-free."""
