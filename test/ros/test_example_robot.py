"""examples/robot_node.py against a live node started with robot.enable: its URDF on
/robot_description puts the arm in the scene, its joint states swing the hand to the heading the
shoulder's yaw gives."""

import re

from ros_helpers import run_example


def test_the_robot_example_drives_the_node():
    r = run_example("robot_node.py", "-p", "robot.enable:=true", "-p", "scene:=hanging")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "robot/demo_arm/forearm" in r.stdout
    yaw = float(re.search(r"shoulder_yaw ([-\d.]+) rad", r.stdout).group(1))
    heading = float(re.search(r"atan2\(y, x\) = ([-\d.]+) rad", r.stdout).group(1))
    assert abs(heading - yaw) < 1e-6  # the hand is on the shoulder's heading: the link followed
