"""ROS 2 nodes of fence_sorter, one module per executable (see setup.py console_scripts)."""
