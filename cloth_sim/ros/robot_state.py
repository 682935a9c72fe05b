"""The robot as ROS publishes it: ``robot_description`` puts it in the scene, ``/joint_states``
moves its links.

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
"""

from __future__ import annotations

import math
import time

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ..robot import Robot
from . import interface

#: seconds (wall) without a joint state before /diagnostics warns
STALE = 1.0

DESCRIPTION_QOS = QoSProfile(
    depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)


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

    # ------------------------------------------------------------------ parameters
    def configure(self, cfg: dict) -> None:
        """Subscribe (or not) as ``cfg``'s ``robot.*`` values say."""
        topics = (
            (cfg["robot.description_topic"], cfg["robot.joint_states_topic"])
            if cfg["robot.enable"]
            else None
        )
        if topics == self._topics:
            return
        for sub in self._subs:
            self.node.destroy_subscription(sub)
        self._subs, self._topics = [], topics
        if topics is None:
            self._remove()
            return
        self._subs = [
            interface.subscription(
                self.node,
                "robot_description",
                String,
                self._on_description,
                qos=DESCRIPTION_QOS,
                topic=topics[0],
            ),
            interface.subscription(
                self.node, "joint_states", JointState, self._on_joint_states, topic=topics[1]
            ),
        ]

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

    # ------------------------------------------------------------------ the ticker's side
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
            return f"no joint states on {self._topics[1]} for {age:.1f} s"
        return None
