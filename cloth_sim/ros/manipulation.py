"""Manipulation: grippers (``~/grasp``, ``~/release``, ``~/grippers/<name>/pose`` in and
``~/grippers/<name>/wrench`` out) and the colliders' pose topics (``~/colliders/<name>/pose``). A
pose received is reached over the next tick's steps (:meth:`cloth_sim.ros.ticker.Stepper.advance`).
"""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import PoseStamped, WrenchStamped

from ..scene import GRIPPER_NAME
from . import interface, messages


def _srv_types():
    from cloth_sim.srv import Grasp, Release  # generated from srv/ by rosidl

    return Grasp, Release


class Manipulation:
    """Grippers and collider poses over the node's :class:`~cloth_sim.ros.session.Session`: the
    services ``~/grasp`` and ``~/release``, each gripper's pose and wrench topics, each collider's
    pose topic, and the twists the standard's ``set_entity_state`` gives."""

    def __init__(self, node, session):
        self.node, self.session = node, session
        self.grippers = {}  # name -> (its pose subscription, its wrench publisher)
        self._pose_subs = []
        Grasp, Release = _srv_types()
        interface.service(node, "grasp", Grasp, self._on_grasp)
        interface.service(node, "release", Release, self._on_release)
        self.subscribe_colliders()
        self.adopt_grippers()

    def set_twist(self, kind: str, name: str, linear, angular) -> None:
        """Keep collider or gripper ``name`` moving at this twist from the next step on (zero
        stops it); a pose received on its topic stops it too."""
        twists = dict(self.session.twists)
        if np.any(linear) or np.any(angular):
            twists[(kind, name)] = (np.array(linear, float), np.array(angular, float))
        else:
            twists.pop((kind, name), None)
        self.session.twists = twists

    def pose_frames(self) -> tuple[str, str]:
        """The frames a pose may be given in: ``frame_id``, and ``world_frame_id`` (the same frame:
        ``/tf_static`` publishes the identity between them)."""
        return self.session.cfg["frame_id"], self.session.cfg["world_frame_id"]

    def stop_colliders(self) -> None:
        """No collider moves at a twist any more (a reset: the scene's colliders stand still)."""
        self.session.twists = {k: v for k, v in self.session.twists.items() if k[0] != "collider"}

    def twist(self, kind: str, name: str):
        """``(linear, angular)`` the entity moves at (zeros when it is not moving by a twist)."""
        return self.session.twists.get((kind, name), (np.zeros(3), np.zeros(3)))

    def apply_twists(self, dt: float) -> None:
        """Each moving collider and gripper one step of ``dt`` further along its twist (an entity
        gone since is dropped)."""
        sim = self.session.sim
        index = {c.name: i for i, c in enumerate(sim.colliders)}
        for (kind, name), (v, w) in list(self.session.twists.items()):
            if (kind == "collider" and name not in index) or (
                kind == "gripper" and name not in sim.grippers
            ):
                self.set_twist(kind, name, 0, 0)
                continue
            if kind == "collider":
                c = sim.colliders[index[name]]
                p, q = c.position, c.orientation
            else:
                p, q = sim.gripper_pose(name)
            q = _turn(q, w, dt)
            if kind == "collider":  # (by teleport on a device that cannot sweep one)
                sim.set_collider_pose(
                    index[name], p + v * dt, q, teleport=not sim.sweeps_colliders
                )
            else:
                sim.set_gripper_pose(name, p + v * dt, q)

    def _on_grasp(self, request, response):
        p = request.point
        name = request.gripper
        response.success, response.count = False, 0
        if not GRIPPER_NAME.fullmatch(name or ""):  # the same rule as a scene's gripper names
            response.message = (
                f"gripper = {name!r}: expected a name of ASCII letters, digits and _ "
                f"(not starting with a digit, at most 64); it names its topics"
            )
            return response
        link = None
        if request.link:
            robot, _, link_name = request.link.partition("/")
            if not robot or not link_name:
                response.message = (
                    f"link = {request.link!r}: expected <robot>/<link>, a robot in the scene "
                    f"({', '.join(self.session.sim.robots) or 'none'}) and one of its links"
                )
                return response
            link = (robot, link_name)
        try:
            idx = self.session.sim.grasp(name, (p.x, p.y, p.z), request.radius, link=link)
        except ValueError as e:
            response.message = str(e)
            return response
        self._gripper_topics(name)
        response.success, response.count = True, len(idx)
        on = f" on {request.link}" if link else ""
        response.message = f"gripper {name!r}{on} holds {len(idx)} particles"
        return response

    def _gripper_topics(self, name: str) -> None:
        """Its wrench topic, and its pose topic unless a robot's link moves it."""
        pose_sub = None
        if self.session.sim.gripper_link(name) is None:
            topic = interface.topic_name("gripper_pose", name=name)
            pose_sub = interface.subscription(
                self.node,
                "gripper_pose",
                PoseStamped,
                lambda msg, name=name: self._on_pose(("gripper", name), topic, msg),
                name=name,
            )
        wrench_pub = interface.publisher(self.node, "gripper_wrench", WrenchStamped, name=name)
        self.grippers[name] = (pose_sub, wrench_pub)

    def adopt_grippers(self) -> None:
        """Topics for the grippers the scene declares (the simulator holds with them already)."""
        for name in self.session.sim.grippers:
            if name not in self.grippers:
                self._gripper_topics(name)

    def release_gripper(self, name: str) -> None:
        """Let go with gripper ``name`` and drop its topics (``ValueError`` for an unknown one)."""
        self.session.sim.release(name)
        sub, pub = self.grippers.pop(name)
        if sub is not None:
            self.node.destroy_subscription(sub)
        self.node.destroy_publisher(pub)
        self.session.pose_targets.pop(("gripper", name), None)

    def _on_release(self, request, response):
        name = request.gripper
        try:
            self.release_gripper(name)
        except ValueError as e:
            response.success, response.message = False, str(e)
            return response
        response.success, response.message = True, f"gripper {name!r} released"
        return response

    def drop_grippers(self) -> None:
        """A rebuild or a reset: the grippers' particles are gone or back in place; so are they."""
        for sub, pub in self.grippers.values():
            if sub is not None:
                self.node.destroy_subscription(sub)
            self.node.destroy_publisher(pub)
        self.grippers = {}
        self.session.pose_targets = {
            k: v for k, v in self.session.pose_targets.items() if k[0] != "gripper"
        }

    def subscribe_colliders(self) -> None:
        """``~/colliders/<name>/pose`` for each collider of the current scene (again after a
        scene change)."""
        for sub in self._pose_subs:
            self.node.destroy_subscription(sub)
        self._pose_subs = []
        self.session.pose_targets = {
            k: v for k, v in self.session.pose_targets.items() if k[0] != "collider"
        }
        for i, c in enumerate(self.session.sim.colliders):
            if "/" in c.name:  # a robot's link (robot/link): its joints move it
                continue
            topic = interface.topic_name("collider_pose", name=c.name)
            self._pose_subs.append(
                interface.subscription(
                    self.node,
                    "collider_pose",
                    PoseStamped,
                    lambda msg, i=i, topic=topic: self._on_pose(("collider", i), topic, msg),
                    name=c.name,
                )
            )

    def forget_pose_target(self, kind: str, name: str) -> None:
        """Drop a pose received on the topic of collider or gripper ``name`` and not yet reached
        (a pose set since overtakes it)."""
        if kind == "collider":
            name = next(
                (i for i, c in enumerate(self.session.sim.colliders) if c.name == name), None
            )
        self.session.pose_targets.pop((kind, name), None)

    def colliders_changed(self) -> None:
        """After a collider was spawned or deleted: the pose topics follow the new list."""
        self.subscribe_colliders()

    def _on_pose(self, key, topic: str, msg) -> None:
        """A new pose for a collider or a gripper: checked here (a bad one is logged, naming the
        field, and ignored), reached over the next tick's steps (its velocity is the pose change
        over them)."""
        position, orientation, problem = messages.checked_pose(
            msg.pose, msg.header.frame_id, self.pose_frames()
        )
        if problem:
            self.node.get_logger().warning(
                f"{topic} ignored: {problem}", throttle_duration_sec=1.0
            )
            return
        kind, which = key
        self.set_twist(
            kind, self.session.sim.colliders[which].name if kind == "collider" else which, 0, 0
        )
        self.session.pose_targets[key] = (position, orientation)

    def pose_moves(self) -> dict:
        """``{key: (p0, q0, p1, q1)}``: from where each moved collider or gripper is to its target
        (the quaternion's sign chosen for the shorter way)."""
        moves, sim = {}, self.session.sim
        for (kind, key), (p1, q1) in self.session.pose_targets.items():
            if kind == "collider":
                c = sim.colliders[key]
                p0, q0 = c.position.copy(), c.orientation.copy()
            elif key in sim.grippers:
                p0, q0 = sim.gripper_pose(key)
            else:
                continue
            if float(q0 @ q1) < 0:
                q1 = -q1
            moves[(kind, key)] = (p0, q0, p1, q1)
        self.session.pose_targets = {}
        return moves


def _turn(q, w, dt: float) -> np.ndarray:
    """The unit quaternion ``q`` (w, x, y, z) turned by the world-frame angular velocity ``w`` over
    ``dt``: ``exp(w·dt/2) ⊗ q``."""
    angle = float(np.linalg.norm(w)) * dt
    if angle == 0.0:
        return np.asarray(q, float)
    axis = np.asarray(w, float) / np.linalg.norm(w)
    a0, (a1, a2, a3) = math.cos(angle / 2), math.sin(angle / 2) * axis
    b0, b1, b2, b3 = q
    out = np.array(
        [
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
        ]
    )
    return out / np.linalg.norm(out)
