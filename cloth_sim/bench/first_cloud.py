"""Seconds from `ros2 run cloth_sim cloth_sim_node` to the first ~/points cloud, as a ROS user sees
it after `colcon build` (run in a shell with the ROS set-up and the workspace's install/setup.bash
sourced; ../shared/rostools gives both here):

    python3 tools/ros_first_cloud.py [--runs 3]

The first run after a build is the one that paid numba's compilation before CMakeLists.txt compiled
the kernels at install time (47.6 s against 3.7 s, measured through colcon on this machine).
"""

import argparse
import os
import signal
import subprocess
import time

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2


def first_cloud(probe: Node, got: list, timeout: float = 120.0) -> float:
    got.clear()
    t0 = time.monotonic()
    node = subprocess.Popen(
        ["ros2", "run", "cloth_sim", "cloth_sim_node"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        while not got and time.monotonic() - t0 < timeout:
            rclpy.spin_once(probe, timeout_sec=0.05)
    finally:
        os.killpg(node.pid, signal.SIGINT)
        node.wait(timeout=20)
    return got[0] - t0 if got else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    rclpy.init()
    probe = Node("first_cloud_probe")
    got: list = []
    probe.create_subscription(
        PointCloud2, "/cloth_sim/points", lambda _: got.append(time.monotonic()), 10
    )
    for i in range(args.runs):
        print(f"run {i + 1}: first cloud after {first_cloud(probe, got):.2f} s", flush=True)
    rclpy.shutdown()


if __name__ == "__main__":
    main()
