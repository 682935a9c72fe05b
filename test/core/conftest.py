"""The core's tests run without ROS: a run of this folder alone fails if rclpy was imported."""

import sys


def pytest_sessionfinish(session, exitstatus):
    alone = all("test/core/" in str(item.path) for item in session.items)
    if alone and "rclpy" in sys.modules:
        print("\ncloth_sim's core imported rclpy: the core must not need ROS", file=sys.stderr)
        session.exitstatus = 1
