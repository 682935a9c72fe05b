"""The node takes a robot as ROS publishes it: robot_description (transient local) puts it in the
scene, /joint_states moves its links within a tick, bad input is logged and ignored with the
scene kept, stale joint states WARN on /diagnostics; and a scene's robot and scripted motion play
in the node."""

import math
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from cloth_sim.robot import Robot

ROOT = Path(__file__).resolve().parents[2]
ARM = ROOT / "config" / "robots" / "arm.urdf"
LATCHED = QoSProfile(
    depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)


def description() -> str:
    """The demo arm's URDF as a robot_description: its mesh by a file:// URI."""
    mesh = (ROOT / "config" / "robots" / "meshes" / "forearm.obj").as_uri()
    return ARM.read_text().replace('filename="meshes/forearm.obj"', f'filename="{mesh}"')


def joint_state(names, positions) -> JointState:
    msg = JointState()
    msg.name, msg.position = list(names), [float(p) for p in positions]
    return msg


def test_robot_description_and_joint_states_move_the_links_within_a_tick(ros):
    node = ros.start(**{"robot.enable": True, "scene": "hanging"})
    desc = ros.node.create_publisher(String, "/robot_description", LATCHED)
    desc.publish(String(data=description()))
    assert ros.spin_until(lambda: "demo_arm" in node.sim.robots, 15)
    names = [c.name for c in node.sim.colliders]
    assert "demo_arm/forearm" in names and "demo_arm/finger_right" in names
    states = ros.node.create_publisher(JointState, "/joint_states", 10)
    assert ros.spin_until(lambda: states.get_subscription_count() > 0, 10)
    q = {"shoulder_yaw": 0.7, "elbow": -0.4, "finger_left_joint": 0.02}
    expected = Robot.from_urdf(ARM).link_transforms(q)
    hand = node.sim.colliders[names.index("demo_arm/hand")]
    states.publish(joint_state(q, q.values()))
    # (spin_until checks after each callback: the steps when the node took the message)
    assert ros.spin_until(lambda: node.robot_state.last_joint_state is not None, 10)
    taken = node.sim.steps_taken
    per_tick = round(1 / node.cfg["publish_rate"] / node.sim.dt)

    def reached():
        return np.allclose(node.sim.link_pose("demo_arm", "hand")[0], expected["hand"][:3, 3])

    assert ros.spin_until(reached, 10)
    # reached by the end of the first tick after the message was taken
    assert node.sim.steps_taken - taken <= per_tick + 1
    np.testing.assert_allclose(hand.position, (expected["hand"] @ _origin(hand, "hand"))[:3, 3])
    # bad joint states are ignored and the links stay
    before = [c.position.copy() for c in node.sim.colliders]
    for names_, values in [(["elbow", "nope"], [0.1, 0.2]), (["elbow"], [math.nan])]:
        states.publish(joint_state(names_, values))
    ros.spin_for(0.5)
    assert all(np.array_equal(c.position, p) for c, p in zip(node.sim.colliders, before))
    assert node.robot_state.rejected == 2
    # a description that does not load is refused and the robot kept
    desc.publish(String(data="<robot name='broken'><link name='a'></robot>"))
    assert ros.spin_until(lambda: node.robot_state.error is not None, 10)
    assert "does not parse" in node.robot_state.error and "demo_arm" in node.sim.robots
    # ~/grasp on a link: the held particles keep their place in the hand's frame as it moves
    from geometry_msgs.msg import Point
    from std_srvs.srv import SetBool

    from cloth_sim.srv import Grasp

    # paused, so that the cloth is where the request says (it swings meanwhile, under load far)
    assert ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=True)).success
    x = node.sim.positions[len(node.sim.positions) // 2]  # a free particle mid-cloth
    req = Grasp.Request(gripper="g", point=Point(x=x[0], y=x[1], z=x[2]), radius=0.05)
    for link, why in [("demo_arm", "<robot>/<link>"), ("demo_arm/nope", "nope")]:
        req.link = link
        bad = ros.call(Grasp, "/cloth_sim/grasp", req)
        assert not bad.success and why in bad.message and "g" not in node.sim.grippers
    req.link = "demo_arm/hand"
    res = ros.call(Grasp, "/cloth_sim/grasp", req)
    assert res.success and "demo_arm/hand" in res.message, res.message
    assert node.sim.gripper_link("g") == ("demo_arm", "hand")
    assert ros.node.get_publishers_info_by_topic("/cloth_sim/grippers/g/wrench")
    assert not ros.node.get_subscriptions_info_by_topic("/cloth_sim/grippers/g/pose")
    idx = node.sim.grippers["g"]

    def in_hand():
        p, q = node.sim.link_pose("demo_arm", "hand")
        return _rotation(q).T @ (node.sim.positions[idx] - p).T

    local = in_hand()
    assert ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=False)).success
    states.publish(joint_state(["shoulder_yaw", "elbow"], [0.2, 0.3]))
    moved = Robot.from_urdf(ARM).link_transforms({**q, "shoulder_yaw": 0.2, "elbow": 0.3})
    assert not np.allclose(moved["hand"][:3, 3], expected["hand"][:3, 3], atol=0.05)
    assert ros.spin_until(
        lambda: np.allclose(node.sim.link_pose("demo_arm", "hand")[0], moved["hand"][:3, 3]), 10
    )
    # (links placed when a tick ends early are reached by the particles over the next step)
    assert ros.spin_until(lambda: np.allclose(in_hand(), local, atol=1e-9), 5)


def _rotation(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _origin(collider, link):
    robot = Robot.from_urdf(ARM)
    return next(s.origin for s in robot.shapes if s.link == link)


def test_stale_joint_states_warn_on_diagnostics(ros):
    node = ros.start(**{"robot.enable": True, "scene": "hanging"})
    got = ros.collect(DiagnosticArray, "/diagnostics")
    desc = ros.node.create_publisher(String, "/robot_description", LATCHED)
    desc.publish(String(data=description()))
    assert ros.spin_until(lambda: node.robot_state.name is not None, 15)

    def warned():
        return any("no joint states" in s.message for m in got for s in m.status)

    assert ros.spin_until(warned, 10)
    states = ros.node.create_publisher(JointState, "/joint_states", 10)
    assert ros.spin_until(lambda: states.get_subscription_count() > 0, 10)
    got.clear()
    for _ in range(30):  # at 20 Hz, fresh
        states.publish(joint_state(["elbow"], [0.1]))
        ros.spin_for(0.05)
    assert got and not any("no joint states" in s.message for m in got[-1:] for s in m.status)


def test_a_scene_robot_and_its_scripted_motion_play_in_the_node(ros):
    node = ros.start(scene="robot_sweep", rows=12, cols=12, spacing=1.0 / 11)
    assert "arm" in node.sim.robots and node.sim.motion is not None
    yaw0 = node.sim.joint_positions("arm")["shoulder_yaw"]
    assert ros.spin_until(lambda: node.sim.time > 1.0, 20)
    yaw = node.sim.joint_positions("arm")["shoulder_yaw"]
    assert yaw > yaw0 + 0.5  # the script swung it
    assert abs(yaw - node.sim.motion.joints_at(node.sim.time)["shoulder_yaw"]) < 1e-9


def test_spawn_entity_takes_a_urdf_and_the_robot_and_its_links_are_entities(ros):
    from simulation_interfaces import srv
    from simulation_interfaces.msg import EntityCategory, Result

    ns = "/cloth_sim"
    node = ros.start(scene="hanging")
    req = srv.SpawnEntity.Request(name="arm", resource_string=description())
    req.initial_pose.pose.position.x, req.initial_pose.pose.position.z = 2.0, 0.5
    req.initial_pose.pose.orientation.w = 1.0
    r = ros.call(srv.SpawnEntity, f"{ns}/spawn_entity", req)
    assert r.result.result == Result.RESULT_OK, r.result.error_message
    assert r.entity_name == "robot/arm"
    names = ros.call(srv.GetEntities, f"{ns}/get_entities", srv.GetEntities.Request()).entities
    assert "robot/arm" in names and "robot/arm/forearm" in names
    assert not any(n.startswith("collider/arm") for n in names)
    # a link's state is its pose: FK from the spawn pose
    st = ros.call(
        srv.GetEntityState, f"{ns}/get_entity_state", srv.GetEntityState.Request(entity="arm/hand")
    ).state
    hand = Robot.from_urdf(ARM).link_transforms({})["hand"][:3, 3] + [2.0, 0.0, 0.5]
    np.testing.assert_allclose(
        [st.pose.position.x, st.pose.position.y, st.pose.position.z], hand, atol=1e-9
    )
    info = ros.call(
        srv.GetEntityInfo, f"{ns}/get_entity_info", srv.GetEntityInfo.Request(entity="robot/arm")
    ).info
    assert info.category.category == EntityCategory.CATEGORY_ROBOT
    # a URDF that does not parse, by the standard's code; a link cannot be set or deleted alone
    bad = srv.SpawnEntity.Request(name="x", resource_string="<robot name='x'><link></robot>")
    r = ros.call(srv.SpawnEntity, f"{ns}/spawn_entity", bad)
    assert r.result.result == srv.SpawnEntity.Response.RESOURCE_PARSE_ERROR
    assert "does not parse" in r.result.error_message
    r = ros.call(
        srv.DeleteEntity, f"{ns}/delete_entity", srv.DeleteEntity.Request(entity="robot/arm/hand")
    )
    assert r.result.result == Result.RESULT_OPERATION_FAILED
    r = ros.call(
        srv.DeleteEntity, f"{ns}/delete_entity", srv.DeleteEntity.Request(entity="robot/arm")
    )
    assert r.result.result == Result.RESULT_OK and node.sim.robots == {}
    assert node.sim.colliders == []


def test_with_robot_source_tf_the_links_follow_the_transforms(ros):
    """robot.source tf: the links' poses come from /tf and /tf_static, chained to
    robot.base_frame; a joint move published as TF moves them as the same joints would."""
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    from cloth_sim.contact.geometry import matrix_quaternion

    node = ros.start(
        **{"robot.enable": True, "robot.source": "tf", "robot.base_frame": "base_link"},
        scene="hanging",
    )
    desc = ros.node.create_publisher(String, "/robot_description", LATCHED)
    desc.publish(String(data=description()))
    assert ros.spin_until(lambda: "demo_arm" in node.sim.robots, 15)
    tf = ros.node.create_publisher(TFMessage, "/tf", 100)
    q = {"shoulder_yaw": -0.6, "elbow": 0.5, "finger_left_joint": 0.01}
    robot = Robot.from_urdf(ARM)
    fk = robot.link_transforms(q)
    msg = TFMessage()
    for parent, child in robot.tree:  # every joint's frames, as robot_state_publisher sends
        rel = np.linalg.inv(fk[parent]) @ fk[child]
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = parent, child
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = rel[
            :3, 3
        ]
        w, x, y, z = matrix_quaternion(rel[:3, :3])
        t.transform.rotation.w, t.transform.rotation.x = w, x
        t.transform.rotation.y, t.transform.rotation.z = y, z
        msg.transforms.append(t)
    assert ros.spin_until(lambda: tf.get_subscription_count() > 0, 10)

    def there():
        tf.publish(msg)
        return np.allclose(node.sim.link_pose("demo_arm", "hand")[0], fk["hand"][:3, 3])

    assert ros.spin_until(there, 10)
    np.testing.assert_allclose(
        node.sim.link_pose("demo_arm", "finger_right")[0], fk["finger_right"][:3, 3], atol=1e-9
    )


def test_each_robot_link_reports_the_wrench_the_cloth_exerts_on_it(ros):
    from geometry_msgs.msg import WrenchStamped
    from std_srvs.srv import SetBool

    node = ros.start(scene="robot_pick")
    got = ros.collect(WrenchStamped, "/cloth_sim/robots/gripper/finger_left/wrench")
    assert ros.spin_until(lambda: len(got) >= 3, 15)
    assert ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=True)).success
    ros.spin_for(0.3)
    n = len(got)
    assert ros.spin_until(lambda: len(got) > n, 5)  # (published while paused too)
    force, torque = node.sim.link_wrench("gripper", "finger_left")
    w = got[-1].wrench
    assert got[-1].header.frame_id == node.cfg["frame_id"]
    assert [w.force.x, w.force.y, w.force.z] == force.tolist()
    assert [w.torque.x, w.torque.y, w.torque.z] == torque.tolist()
