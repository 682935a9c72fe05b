"""The node on the CUDA backend (``-p device:=cuda``): it starts, steps and publishes its status,
and exits cleanly on SIGINT. On numba-cuda's simulator a 4×4 cloth steps at a few hundredths of
real time; what is checked is that the node's every use of the simulator works on the device's."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def test_the_node_runs_on_the_cuda_backend():
    """The default scene (hanging, whose strain limit is the projection) started with
    ``device:=cuda``: the node says the projection is not on the device and runs it there with
    Provot's passes, steps and logs its status, and exits cleanly on SIGINT."""
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(180 + os.getpid() % 40),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_LOG_DIR=str(ROOT / ".ros_log"),
        PYTHONUNBUFFERED="1",
    )
    args = ["device:=cuda", "rows:=4", "cols:=4", "publish_rate:=20.0"]
    argv = [str(Path(sys.executable).parent / "cloth_sim_node"), "--ros-args"]
    for a in args:
        argv += ["-p", a]
    proc = subprocess.Popen(
        argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    lines = []
    end = time.monotonic() + 300  # (the kernels compile at start-up where the cache is cold)
    try:
        while time.monotonic() < end:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if " rtf=" in line:  # the status the node logs every 5 s of wall time
                break
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
        lines.append(out)
    text = "".join(lines)
    assert proc.returncode == 0 and "Traceback" not in text, text[-3000:]
    assert "symplectic_euler on the cuda" in text, text[-3000:]
    assert "strain_limit_method: not on the cuda device yet" in text, text[-3000:]
    assert "Instead: running on cuda with Provot's passes" in text, text[-3000:]
    assert " rtf=" in text and "max_strain=" in text, text[-3000:]


def test_the_node_on_cuda_moves_spawns_and_deletes_colliders_and_grasps():
    """On the cuda device the drape scene's ball follows its pose topic (placed at rest step by
    step: the device does not sweep a collider yet, which the node says once in its log), a
    box spawned through ``~/spawn_entity`` joins the colliders and ``~/delete_entity`` takes it
    away again, ``~/grasp`` holds a corner that its gripper's pose topic then lifts (its wrench
    published), and a robot spawned from its description joins with its link's wrench published;
    the cloth keeps stepping, finite. The pose, the spawn and the grasp had raised inside the
    tick and the services (a swept move refused, no ``add_collider``, no ``grasp`` on the
    device), and a robot's spawn was refused."""
    import numpy as np
    import rclpy
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from simulation_interfaces import srv

    from cloth_sim.ros.node import ClothSimNode
    from cloth_sim.srv import Grasp

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=220 + os.getpid() % 10)
    ex = SingleThreadedExecutor(context=ctx)
    client = rclpy.create_node("cuda_test", context=ctx)
    ex.add_node(client)
    # as fast as the simulator can (real_time_factor 0): a pose is reached over one tick's steps
    over = dict(
        scene="drape", device="cuda", rows=4, cols=4, strain_limit=0.0, publish_rate=10.0,
        real_time_factor=0.0,
    )  # fmt: skip
    node = ClothSimNode(
        context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in over.items()]
    )
    ex.add_node(node)

    def spin_until(cond, timeout=60.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
            if cond():
                return True
        return False

    try:
        sim = node.session.sim
        assert sim.device == "cuda" and [c.name for c in sim.colliders] == ["ball", "floor"]
        pub = client.create_publisher(PoseStamped, "/cloth_sim/colliders/ball/pose", 10)
        msg = PoseStamped()
        msg.header.frame_id = "cloth"
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = 0.5, 0.5, 0.1
        msg.pose.orientation.w = 1.0
        assert spin_until(lambda: pub.get_subscription_count() > 0)
        pub.publish(msg)
        assert spin_until(lambda: abs(node.session.sim.colliders[0].center[2] - 0.1) < 1e-9)
        t = node.session.sim.time
        assert spin_until(lambda: node.session.sim.time > t)  # still stepping

        def call(kind, name, request):
            cli = client.create_client(kind, f"/cloth_sim/{name}")
            assert cli.wait_for_service(timeout_sec=30)
            future = cli.call_async(request)
            assert spin_until(future.done)
            return future.result()

        req = srv.SpawnEntity.Request(
            name="crate", uri="cloth_sim://box?half_extents=0.1,0.1,0.1&friction=0.5"
        )
        req.initial_pose.header.frame_id = "cloth"
        req.initial_pose.pose.position.z = -0.5
        req.initial_pose.pose.orientation.w = 1.0
        done = call(srv.SpawnEntity, "spawn_entity", req)
        assert done.result.result == 1, done.result.error_message  # RESULT_OK
        assert [c.name for c in node.session.sim.colliders] == ["ball", "floor", "crate"]
        assert node.session.sim.colliders[2].center[2] == -0.5
        t = node.session.sim.time
        assert spin_until(lambda: node.session.sim.time > t)
        gone = call(srv.DeleteEntity, "delete_entity", srv.DeleteEntity.Request(entity="crate"))
        assert gone.result.result == 1, gone.result.error_message
        assert [c.name for c in node.session.sim.colliders] == ["ball", "floor"]
        t = node.session.sim.time
        assert spin_until(lambda: node.session.sim.time > t)
        # a gripper through ~/grasp, moved by its pose topic; its wrench is published
        corner = node.session.sim.positions[0]
        req = Grasp.Request(gripper="hand", radius=0.05)
        req.point.x, req.point.y, req.point.z = (float(c) for c in corner)
        held = call(Grasp, "grasp", req)
        assert held.success and held.count >= 1, held.message
        wrenches = []
        client.create_subscription(
            WrenchStamped, "/cloth_sim/grippers/hand/wrench", wrenches.append, 10
        )
        grip = client.create_publisher(PoseStamped, "/cloth_sim/grippers/hand/pose", 10)
        msg.pose.position.x, msg.pose.position.y = float(corner[0]), float(corner[1])
        msg.pose.position.z = float(corner[2]) + 0.2
        assert spin_until(lambda: grip.get_subscription_count() > 0)
        grip.publish(msg)
        up = float(corner[2]) + 0.2
        assert spin_until(lambda: abs(node.session.sim.gripper_pose("hand")[0][2] - up) < 1e-9)
        assert spin_until(lambda: len(wrenches) > 0)
        # a robot spawned from its description: its link a collider on the device, its wrench
        # published every tick
        arm = (
            "<robot name='arm'><link name='paddle'><collision><geometry>"
            "<box size='0.2 0.2 0.02'/></geometry></collision></link></robot>"
        )
        req = srv.SpawnEntity.Request(resource_string=arm)
        req.initial_pose.header.frame_id = "cloth"
        req.initial_pose.pose.position.z = -0.8
        req.initial_pose.pose.orientation.w = 1.0
        spawned = call(srv.SpawnEntity, "spawn_entity", req)
        assert spawned.result.result == 1, spawned.result.error_message
        assert "arm/paddle" in [c.name for c in node.session.sim.colliders]
        paddle = []
        client.create_subscription(
            WrenchStamped, "/cloth_sim/robots/arm/paddle/wrench", paddle.append, 10
        )
        assert spin_until(lambda: len(paddle) > 0)
        t = node.session.sim.time
        assert spin_until(lambda: node.session.sim.time > t)
        assert np.all(np.isfinite(node.session.sim.positions))
    finally:
        ex.remove_node(node)
        node.destroy_node()
        client.destroy_node()
        rclpy.shutdown(context=ctx)
