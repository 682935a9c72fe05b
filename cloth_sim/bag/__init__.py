"""rosbag2-compatible MCAP bags: ``store`` (write/read/inspect/repair, no ROS), ``record`` and
``play`` (rclpy, imported only by the commands that need a ROS graph)."""

from .store import BagError, BagWriter, bag_info, iter_messages, reindex

__all__ = ["BagError", "BagWriter", "bag_info", "iter_messages", "reindex"]
