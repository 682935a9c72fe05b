"""Grasping the cloth through the node: a gripper's services and topics from your own rclpy node.

    make run                                   # the node, in one terminal
    .venv/bin/python examples/grasp_node.py    # this, in another (the same ROS_DOMAIN_ID)

Grasps the hanging cloth's corner (``~/grasp``), prints the pull it feels
(``~/grippers/left/wrench``), lifts it by publishing poses (``~/grippers/left/pose``), lets go
(``~/release``), then pauses the node and steps it in lockstep (``~/pause``, ``~/step``).
"""

import argparse

import rclpy
from geometry_msgs.msg import Point, PoseStamped, WrenchStamped
from std_srvs.srv import SetBool

from cloth_sim.srv import Grasp, Release, Step

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="a short lift (the tests)")
p.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the node")
args = p.parse_args()

rclpy.init()
node = rclpy.create_node("hand")


def call(srv, name, request):
    client = node.create_client(srv, name)
    if not client.wait_for_service(timeout_sec=args.timeout):
        raise SystemExit(f"{name}: no such service; is the node running (make run)?")
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future)
    return future.result()


grasp = call(Grasp, "/cloth_sim/grasp", Grasp.Request(gripper="left", point=Point(), radius=0.05))
print("grasp:", grasp.success, grasp.message)
pulls = []
node.create_subscription(
    WrenchStamped, "/cloth_sim/grippers/left/wrench", lambda m: pulls.append(m.wrench.force), 10
)
pose = node.create_publisher(PoseStamped, "/cloth_sim/grippers/left/pose", 10)
n = 10 if args.quick else 60
for k in range(1, n + 1):  # lift the corner 0.3 m over 2 s (at 30 poses a second)
    msg = PoseStamped()
    msg.header.frame_id = "cloth"
    msg.pose.position.z = 0.3 * k / 60
    msg.pose.orientation.w = 1.0
    pose.publish(msg)
    rclpy.spin_once(node, timeout_sec=1 / 30)
if pulls:
    f = pulls[-1]
    print(f"pull on the gripper: ({f.x:.3f}, {f.y:.3f}, {f.z:.3f}) N")
print("release:", call(Release, "/cloth_sim/release", Release.Request(gripper="left")).success)
call(SetBool, "/cloth_sim/pause", SetBool.Request(data=True))  # lockstep: paused, then
step = call(Step, "/cloth_sim/step", Step.Request(steps=100))  # exactly 100 steps a call
print(f"stepped to t = {step.sim_time:.3f} s")
call(SetBool, "/cloth_sim/pause", SetBool.Request(data=False))
node.destroy_node()
rclpy.shutdown()
