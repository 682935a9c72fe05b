"""The ROS 2 adapter: the only part of cloth_sim that imports rclpy and ROS messages."""
