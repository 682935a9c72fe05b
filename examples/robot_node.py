"""A robot in the node's scene from its URDF, driven by joint states, as a ROS robot is.

    .venv/bin/cloth_sim_node --ros-args -p scene:=hanging -p robot.enable:=true   # one terminal
    .venv/bin/python examples/robot_node.py                                       # another

Publishes the demo arm's URDF on ``/robot_description`` (transient local, as
``robot_state_publisher`` does; its links become colliders) and a swing of its shoulder on
``/joint_states`` at 30 Hz (``joint_state_publisher`` or a real driver would), through the hanging
cloth; then asks the node where the hand is (the ROS simulation standard's ``get_entity_state`` of
``robot/demo_arm/hand``). The node's ``robot.description_topic`` and ``robot.joint_states_topic``
name other topics.
"""

import argparse
import math
from pathlib import Path

import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from simulation_interfaces.srv import GetEntities, GetEntityState
from std_msgs.msg import String

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="a short swing (the tests)")
p.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the node")
args = p.parse_args()

urdf = Path(__file__).resolve().parents[1] / "config" / "robots" / "arm.urdf"
mesh = urdf.parent / "meshes" / "forearm.obj"  # a robot_description names meshes by URI
description = urdf.read_text().replace('"meshes/forearm.obj"', f'"{mesh.as_uri()}"')

rclpy.init()
node = rclpy.create_node("arm_driver")
latched = QoSProfile(
    depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)
node.create_publisher(String, "/robot_description", latched).publish(String(data=description))
states = node.create_publisher(JointState, "/joint_states", 10)


def call(srv, name, request):
    client = node.create_client(srv, name)
    if not client.wait_for_service(timeout_sec=args.timeout):
        raise SystemExit(f"{name}: no such service; is the node running?")
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future)
    return future.result()


# wait until the node has put the robot in its scene
for _ in range(int(args.timeout * 10)):
    entities = call(GetEntities, "/cloth_sim/get_entities", GetEntities.Request()).entities
    if "robot/demo_arm" in entities:
        break
    rclpy.spin_once(node, timeout_sec=0.1)
else:
    raise SystemExit("the node has no robot/demo_arm: is it running with robot.enable:=true?")
print("the node's robot entities:", ", ".join(n for n in entities if n.startswith("robot/")))

n = 15 if args.quick else 90
for k in range(n + 1):  # the shoulder from 0.2 rad to 2.9 rad at 30 Hz (1 m/s at the elbow)
    msg = JointState()
    msg.header.stamp = node.get_clock().now().to_msg()
    msg.name = ["shoulder_yaw", "shoulder_pitch"]
    msg.position = [0.2 + 2.7 * k / 90, -0.2]
    states.publish(msg)
    rclpy.spin_once(node, timeout_sec=1 / 30)
yaw = msg.position[0]
# the node reaches a joint state within its next tick; a busy machine may delay that tick
for _ in range(int(args.timeout * 20)):
    hand = call(
        GetEntityState,
        "/cloth_sim/get_entity_state",
        GetEntityState.Request(entity="demo_arm/hand"),
    ).state.pose.position
    if abs(math.atan2(hand.y, hand.x) - yaw) < 1e-6:
        break
    rclpy.spin_once(node, timeout_sec=0.05)
print(f"shoulder_yaw {yaw:.3f} rad: the hand is at ({hand.x:.3f}, {hand.y:.3f}, {hand.z:.3f}) m")
print(f"its heading atan2(y, x) = {math.atan2(hand.y, hand.x):.3f} rad")
node.destroy_node()
rclpy.shutdown()
