"""Start cloth_sim_node with config/cloth_sim.yaml; `scene:=flag` picks another scene.

ros2 launch cloth_sim cloth_sim.launch.py scene:=flag
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description():
    share = get_package_share_directory("cloth_sim")
    params = os.path.join(share, "config", "cloth_sim.yaml")
    # the scenes the package has: its config/scenes directory, where the node looks them up too
    scenes = sorted(
        name[:-5]
        for name in os.listdir(os.path.join(share, "config", "scenes"))
        if name.endswith(".yaml")
    )
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "scene",
                default_value="hanging",
                description=f"{', '.join(scenes)} or a scene YAML path",
            ),
            Node(
                package="cloth_sim",
                executable="cloth_sim_node",
                name="cloth_sim",
                output="screen",
                parameters=[params, {"scene": LaunchConfiguration("scene")}],
            ),
        ]
    )
