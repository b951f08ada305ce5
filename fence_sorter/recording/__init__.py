"""Recording of fence_sorter runs: rosbag2 (MCAP) bags and the message type registry."""
