"""The node's graph is its declaration (cloth_sim/ros/interface.py, from which the site's topic and
service tables are generated): a running node with its camera, a collider, a robot, a gripper,
/clock and the robot's ROS inputs on has every declared topic and service with the declared type,
and no other topic or service of its own (the simulation standard's, parameters' and ROS's own
aside)."""

import re
import time

import rclpy
from geometry_msgs.msg import Point
from rclpy.executors import SingleThreadedExecutor
from ros_helpers import next_domain, start_node

from cloth_sim.ros.interface import SERVICES, TOPICS
from cloth_sim.srv import Grasp


def resolve(declared: str, **names) -> str:
    name = declared.format(**names)
    return "/cloth_sim/" + name[2:] if name.startswith("~/") else name


def test_a_running_nodes_topics_and_services_are_the_declared_ones():
    domain = next_domain()
    proc = start_node(
        domain,
        # robot_pick: a collider (the shelf) and a robot (the pinch gripper) in the scene
        *("-p", "scene:=robot_pick", "-p", "camera.enable:=true", "-p", "publish_clock:=true"),
        *("-p", "robot.enable:=true"),
    )
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    probe = rclpy.create_node("interface_probe", context=ctx)
    try:
        client = probe.create_client(Grasp, "/cloth_sim/grasp")
        assert client.wait_for_service(timeout_sec=60)
        future = client.call_async(Grasp.Request(gripper="hand", point=Point(), radius=0.5))
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(probe)
        executor.spin_until_future_complete(future, timeout_sec=30)
        assert future.result().success, future.result().message
        expected_topics = {}
        example = {"grippers": "hand", "colliders": "shelf", "robots": "gripper/finger_left"}
        for t in TOPICS.values():
            names = {"name": next((v for k, v in example.items() if f"/{k}/" in t.name), "")}
            expected_topics[resolve(t.name, **names)] = (t.type, t.direction)
        expected_services = {resolve(s.name): s.type for s in SERVICES.values()}
        deadline = time.monotonic() + 30
        # one node of that name in the domain: the graph queries below read the first they find
        # (a node an earlier test left alive on a reused domain once answered for this one)
        assert [n for n in probe.get_node_names() if n == "cloth_sim"] == ["cloth_sim"]
        while True:
            pubs = dict(probe.get_publisher_names_and_types_by_node("cloth_sim", "/"))
            subs = dict(probe.get_subscriber_names_and_types_by_node("cloth_sim", "/"))
            srvs = dict(probe.get_service_names_and_types_by_node("cloth_sim", "/"))
            seen = {n: (ts[0], "out") for n, ts in pubs.items()}
            seen.update({n: (ts[0], "in") for n, ts in subs.items()})
            if all(seen.get(n) == v for n, v in expected_topics.items()) or (
                time.monotonic() > deadline
            ):
                break
            time.sleep(0.2)
        for name, declared in expected_topics.items():
            assert seen.get(name) == declared, (name, seen.get(name), declared)
        for name, declared in expected_services.items():
            assert srvs.get(name) == [declared], (name, srvs.get(name))
        # nothing of its own beyond the declaration (the standard's services, the parameter
        # services and ROS's /rosout and /parameter_events are declared elsewhere)
        ours = {n for n in seen if n.startswith("/cloth_sim/") and "/_action/" not in n} | {
            "/clock",
            "/tf",
            "/tf_static",
            "/diagnostics",
        } & set(seen)
        patterns = [  # (a robot's link topics are named robot/link)
            re.compile(
                re.escape(resolve(t.name, name="NAME")).replace(
                    "NAME", r"\w+/\w+" if "/robots/" in t.name else r"\w+"
                )
                + "$"
            )
            for t in TOPICS.values()
        ]
        undeclared = {n for n in ours if not any(p.match(n) for p in patterns)}
        assert undeclared == set()
        own_services = {
            n
            for n in srvs
            if n.startswith("/cloth_sim/")
            and n.rsplit("/", 1)[1] in {s.name[2:] for s in SERVICES.values()}
        }
        assert own_services == set(expected_services)
    finally:
        probe.destroy_node()
        rclpy.shutdown(context=ctx)
        proc.terminate()
        proc.communicate(timeout=30)


def test_a_destroyed_node_leaves_the_graph():
    """An in-process node destroyed and its context shut down is gone from the graph, action
    server included (rclpy's destroy_node leaves action servers: such a node lingered with its
    action's topics, and a later test on the same domain met it)."""
    from rclpy.parameter import Parameter

    from cloth_sim.ros.node import ClothSimNode

    domain = next_domain()
    ctx, probe_ctx = rclpy.Context(), rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    rclpy.init(context=probe_ctx, domain_id=domain)
    probe = rclpy.create_node("leave_probe", context=probe_ctx)
    try:
        node = ClothSimNode(
            context=ctx,
            parameter_overrides=[Parameter("rows", value=4), Parameter("cols", value=4)],
        )

        def seen():
            return "cloth_sim" in probe.get_node_names()

        end = time.monotonic() + 30
        while not seen() and time.monotonic() < end:
            time.sleep(0.1)
        assert seen()  # the probe sees the node while it lives
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        end = time.monotonic() + 30
        while seen() and time.monotonic() < end:
            time.sleep(0.1)
        assert not seen()
    finally:
        probe.destroy_node()
        rclpy.shutdown(context=probe_ctx)
