"""The robot as ROS publishes it: ``robot_description`` puts it in the scene, ``/joint_states``
(or ``/tf``) moves its links.

With ``robot.enable``, the node subscribes to ``robot.description_topic`` (``std_msgs/String``,
transient local, as ``robot_state_publisher`` publishes it) and ``robot.joint_states_topic``
(``sensor_msgs/JointState``). Each description loads a :class:`cloth_sim.robot.Robot` (its
``package://`` meshes looked up in the ament index and ``ROS_PACKAGE_PATH``) and puts it in the
scene in place of the last one the topic gave, its root link at the node's frame origin; a
description that does not load is logged with its reason and the scene stays as it was. Joint
states are checked whole (an unknown joint, a non-finite position, names and positions of
different lengths: logged, the message ignored) and kept as the target the next tick's steps
reach, in equal parts (so the links sweep there and friction drags the cloth); a joint state that
arrives before its robot waits for it. No joint state for :data:`STALE` s while a robot is in the
scene WARNs on ``/diagnostics``.

With ``robot.source: tf`` the links' poses come from ``/tf`` and ``/tf_static`` instead (what
``robot_state_publisher`` broadcasts, or a real robot's driver): each link's transform from
``robot.base_frame`` (empty: the URDF's root link), chained through the frames received, places
it, the base frame at the cloth's frame origin; the links sweep there over the first step of the
next tick. A link whose chain to the base frame is not (yet) complete keeps its pose; no transform
for :data:`STALE` s WARNs.
"""

from __future__ import annotations

import math
import time

import numpy as np
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from ..contact.geometry import quaternion_matrix
from ..robot import Robot
from . import interface

#: seconds (wall) without a joint state before /diagnostics warns
STALE = 1.0

DESCRIPTION_QOS = QoSProfile(
    depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)
TF_STATIC_QOS = QoSProfile(
    depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)
#: frames a link's chain to the base frame may pass through at most
MAX_CHAIN = 64


class RobotState:
    """The subscriptions, the robot they put in the session's simulator, and the joint targets
    the :class:`~cloth_sim.ros.ticker.Stepper` reaches over a tick."""

    def __init__(self, node, session):
        self.node, self.session = node, session
        self._subs = []
        self._topics = None
        #: the robot the description topic gave (its name in the simulator), or None
        self.name: str | None = None
        #: joint positions received and not yet reached
        self.target: dict | None = None
        self.last_joint_state: float | None = None  # wall time of the last good one
        self.since: float | None = None  # wall time the robot came
        self.rejected = 0  # joint states ignored (logged)
        self.error: str | None = None  # why the last description was refused
        #: TF frames received: child -> (parent, 4×4), and whether a new one came since the tick
        self._tf: dict[str, tuple[str, np.ndarray]] = {}
        self._tf_new = False
        self._source, self._base_frame = "joint_states", ""

    # ------------------------------------------------------------------ parameters
    def configure(self, cfg: dict) -> None:
        """Subscribe (or not) as ``cfg``'s ``robot.*`` values say."""
        topics = (
            (
                cfg["robot.description_topic"],
                cfg["robot.joint_states_topic"],
                cfg["robot.source"],
                cfg["robot.base_frame"],
            )
            if cfg["robot.enable"]
            else None
        )
        if topics == self._topics:
            return
        for sub in self._subs:
            self.node.destroy_subscription(sub)
        self._subs, self._topics, self._tf = [], topics, {}
        if topics is None:
            self._remove()
            return
        self._source, self._base_frame = topics[2], topics[3]
        try:
            self._subscribe(topics)
        except Exception as e:  # noqa: BLE001 (rclpy's RCLError: a topic of another type there)
            for sub in self._subs:
                self.node.destroy_subscription(sub)
            self._subs = []
            self.error = f"robot topics {topics[0]!r}, {topics[1]!r}: not subscribed: {e}"
            self.node.get_logger().error(self.error)

    def _subscribe(self, topics) -> None:
        self._subs.append(
            interface.subscription(
                self.node,
                "robot_description",
                String,
                self._on_description,
                qos=DESCRIPTION_QOS,
                topic=topics[0],
            )
        )
        if self._source == "tf":  # (the standard /tf topics, the node's own output beside)
            self._subs += [
                self.node.create_subscription(TFMessage, "/tf", self._on_tf, 100),
                self.node.create_subscription(TFMessage, "/tf_static", self._on_tf, TF_STATIC_QOS),
            ]
        else:
            self._subs.append(
                interface.subscription(
                    self.node, "joint_states", JointState, self._on_joint_states, topic=topics[1]
                )
            )

    def restarted(self) -> None:
        """The simulation is back at its scene's start: in a new simulator (a new scene or size)
        the robot goes in again; a reset keeps it where it is."""
        if self._robot is not None and self.name not in self.session.sim.robots:
            self.name = None
            self._place(self._robot)

    _robot: Robot | None = None

    # ------------------------------------------------------------------ callbacks
    def _on_description(self, msg) -> None:
        try:
            robot = Robot.from_urdf(msg.data)
        except ValueError as e:
            self.error = str(e)
            self.node.get_logger().error(f"robot_description refused, the scene is kept: {e}")
            return
        self.error = None
        self._remove()
        self._place(robot)

    def _place(self, robot: Robot) -> None:
        sim = self.session.sim
        name = robot.name
        if name in sim.robots:  # the scene has a robot of that name: the description's is apart
            name = f"{name}_description"
        try:
            self.name = sim.add_robot(robot, name=name, joints=self._known(robot, self.target))
        except ValueError as e:
            self.error = str(e)
            self.node.get_logger().error(f"robot {robot.name!r} not placed: {e}")
            return
        self._robot, self.since = robot, time.monotonic()
        self.node.get_logger().info(
            f"robot {name!r} in the scene: {len(robot.joint_names)} joints, "
            f"{len(robot.shapes)} collision shapes"
        )

    def _remove(self) -> None:
        if self.name is not None and self.name in self.session.sim.robots:
            self.session.sim.remove_robot(self.name)
        self.name, self._robot, self.target = None, None, None

    @staticmethod
    def _known(robot, values):
        return {k: v for k, v in (values or {}).items() if k in robot.joint_names}

    def _on_joint_states(self, msg) -> None:
        problem = None
        if len(msg.position) != len(msg.name):
            problem = f"{len(msg.name)} names but {len(msg.position)} positions"
        else:
            values = dict(zip(msg.name, (float(p) for p in msg.position)))
            bad = next((n for n, v in values.items() if not math.isfinite(v)), None)
            if bad is not None:
                problem = f"joint {bad!r}: position must be a finite number, got {values[bad]}"
            elif self._robot is not None:
                try:
                    values = self._robot.check_joints(values)
                except ValueError as e:
                    problem = str(e)
        if problem:
            self.rejected += 1
            self.node.get_logger().warning(
                f"{self._topics[1]} ignored: {problem}", throttle_duration_sec=1.0
            )
            return
        self.target = {**(self.target or {}), **values}
        self.last_joint_state = time.monotonic()

    def _on_tf(self, msg) -> None:
        for t in msg.transforms:
            tr, q = t.transform.translation, t.transform.rotation
            p = np.array([tr.x, tr.y, tr.z])
            quat = np.array([q.w, q.x, q.y, q.z])
            if not (np.all(np.isfinite(p)) and np.all(np.isfinite(quat))) or not any(quat):
                self.rejected += 1
                self.node.get_logger().warning(
                    f"/tf: {t.header.frame_id} -> {t.child_frame_id} ignored: not a finite "
                    f"pose with a nonzero quaternion",
                    throttle_duration_sec=1.0,
                )
                continue
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = quaternion_matrix(quat), p
            self._tf[t.child_frame_id] = (t.header.frame_id, T)
            self._tf_new = True
            if self._robot is not None and t.child_frame_id in self._robot.all_links:
                self.last_joint_state = time.monotonic()  # (the node's own frames do not count)

    def link_transforms(self) -> dict:
        """Each of the robot's links whose chain of TF frames reaches the base frame: its 4×4
        transform from it."""
        robot = self._robot
        base = self._base_frame or robot.root
        out = {}
        for link in robot.all_links:
            T, frame = np.eye(4), link
            for _ in range(MAX_CHAIN):
                if frame == base:
                    out[link] = T
                    break
                if frame not in self._tf:
                    break
                parent, step = self._tf[frame]
                T, frame = step @ T, parent
        return out

    # ------------------------------------------------------------------ the ticker's side
    def tf_move(self):
        """``(name, {link: 4×4})``: the links' poses from TF received since the last tick, or
        None."""
        if self._source != "tf" or not self._tf_new or self.name is None:
            return None
        if self.name not in self.session.sim.robots:
            return None
        self._tf_new = False
        links = self.link_transforms()
        return (self.name, links) if links else None

    def joint_move(self):
        """``(name, q0, q1)``: from the robot's joints now to the target received, or None."""
        if self.name is None or self.target is None or self.name not in self.session.sim.robots:
            return None
        q0 = self.session.sim.joint_positions(self.name)
        q1 = {**q0, **self._known(self._robot, self.target)}
        self.target = None
        return (self.name, q0, q1) if q1 != q0 else None

    def problem(self) -> str | None:
        """What /diagnostics warns of: a refused description, or stale joint states."""
        if self.error:
            return f"robot_description refused: {self.error}"
        if self.name is None:
            return None
        last = self.last_joint_state if self.last_joint_state is not None else self.since
        age = time.monotonic() - last
        if age > STALE:
            if self._source == "tf":
                return f"no transforms on /tf for {age:.1f} s"
            return f"no joint states on {self._topics[1]} for {age:.1f} s"
        return None
