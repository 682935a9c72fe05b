"""Robots placed in a simulation: each link's shapes as colliders that follow the joint positions,
and grippers bound to links.

The simulator owns one :class:`Robots` and hands it what it needs (composition): a way to add,
move and remove colliders and to move a gripper. Links move kinematically: a new configuration
becomes each link collider's pose at the end of the next step, so the step sweeps it there (its
velocity is its pose change over the step, and friction drags the cloth it touches) and a gripper
bound to a link carries its particles along the same way.
"""

from __future__ import annotations

import numpy as np

from ..contact.geometry import matrix_quaternion, quaternion_matrix, unit_quaternion, vector
from .robot import Robot


class Placed:
    """A robot in the scene: its base pose (4×4), joint positions and colliders (with their links'
    shapes)."""

    def __init__(self, robot: Robot, name: str, base: np.ndarray, joints: dict):
        self.robot, self.name, self.base, self.joints = robot, name, base, joints
        self.colliders = []  # (collider, shape)
        #: links placed directly (from TF), 4×4 in the robot's root frame, over their FK poses
        self.placed_links: dict[str, np.ndarray] = {}
        self._poses = None  # link_poses() until the joints or placed links change

    def set_joints(self, values: dict) -> None:
        """Joint positions (checked), over those it has."""
        self.joints = {**self.joints, **values}
        self._poses = None

    def place_links(self, transforms: dict) -> None:
        """Links placed directly (checked 4×4s in the root frame), over their FK poses."""
        self.placed_links.update(transforms)
        self._poses = None

    def link_poses(self) -> dict[str, np.ndarray]:
        """Every link's pose (4×4) in the world: its forward kinematics at the current joint
        positions, or where it was placed directly (computed once per configuration: a tick's
        wrenches and poses read it per link; read-only)."""
        if self._poses is None:
            poses = {**self.robot.link_transforms(self.joints), **self.placed_links}
            self._poses = {k: self.base @ t for k, t in poses.items()}
        return self._poses


def _pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return T[:3, 3].copy(), matrix_quaternion(T[:3, :3])


class Robots:
    """The robots of one simulation (``add_collider(c) -> i``, ``remove_collider(i)``,
    ``colliders()`` and ``set_gripper_pose(name, p, q)`` are the simulator's; ``place([(collider,
    4×4)], teleport)`` its contact stage's :meth:`~cloth_sim.contact.colliders.Contacts.place`)."""

    def __init__(self, add_collider, place, remove_collider, colliders, set_gripper_pose):
        self._add, self._place, self._remove = add_collider, place, remove_collider
        self._colliders, self._move_gripper = colliders, set_gripper_pose
        self.placed: dict[str, Placed] = {}
        #: gripper name -> (robot name, link)
        self.bound: dict[str, tuple[str, str]] = {}

    def add(
        self,
        robot: Robot,
        name=None,
        position=(0.0, 0.0, 0.0),
        orientation=(1.0, 0.0, 0.0, 0.0),
        joints=None,
        friction: float = 0.5,
    ) -> str:
        if not isinstance(robot, Robot):
            raise ValueError(
                f"add_robot: robot must be a cloth_sim.robot.Robot, got {type(robot).__name__}"
            )
        name = robot.name if name is None else name
        if not isinstance(name, str) or not name or "/" in name:
            raise ValueError(f"robot name must be a non-empty string without '/', got {name!r}")
        if name in self.placed:
            raise ValueError(f"a robot named {name!r} is in the scene already")
        base = np.eye(4)
        base[:3, :3] = quaternion_matrix(unit_quaternion(orientation))
        base[:3, 3] = vector("position", position)
        values = robot.check_joints(joints or {})
        placed = Placed(robot, name, base, values)
        taken = {c.name for c in self._colliders()}
        made = []
        for k, shape in enumerate(robot.shapes):
            cname = f"{name}/{shape.link}"
            if sum(s.link == shape.link for s in robot.shapes) > 1:
                cname += f"/{k}"
            if cname in taken:
                raise ValueError(f"a collider named {cname!r} exists already")
            made.append((shape.make(cname, friction), shape))
        poses = placed.link_poses()
        for collider, shape in made:  # (all made before any is added: a failure adds nothing)
            collider.place(poses[shape.link] @ shape.origin)
            self._add(collider)
            placed.colliders.append((collider, shape))
        self.placed[name] = placed
        return name

    def remove(self, name: str) -> Robot:
        placed = self._placed(name)
        for collider, _ in placed.colliders:
            self._remove(self._index(collider))
        for g in [g for g, (r, _) in self.bound.items() if r == name]:
            del self.bound[g]
        del self.placed[name]
        return placed.robot

    def set_joints(self, name: str, values, teleport: bool = False) -> None:
        placed = self._placed(name)
        placed.set_joints(placed.robot.check_joints(values))
        self._follow(placed, None, teleport)

    def set_link_transforms(self, name: str, transforms: dict, teleport: bool = False) -> None:
        """Links of robot ``name`` placed directly, ``{link: 4×4 in the robot's root frame}`` (a
        robot whose links come from TF): they sweep there over the next step, as by joints."""
        placed = self._placed(name)
        for link, T in transforms.items():
            if link not in placed.robot.all_links:
                raise ValueError(f"robot {name!r} has no link {link!r}")
            T = np.asarray(T, dtype=np.float64)
            if T.shape != (4, 4) or not np.all(np.isfinite(T)):
                raise ValueError(f"link {link!r}: a transform must be a finite 4×4 matrix")
        placed.place_links({k: np.asarray(v, float) for k, v in transforms.items()})
        self._follow(placed, set(transforms), teleport)

    def _follow(self, placed: Placed, links, teleport: bool) -> None:
        """The colliders of ``placed``'s links (all, or those in ``links``) and the grippers bound
        to them to the links' poses now: reached over the next step, or there at once."""
        poses = placed.link_poses()
        self._place(
            [
                (c, poses[s.link] @ s.origin)
                for c, s in placed.colliders
                if links is None or s.link in links
            ],
            teleport,
        )
        for gripper, (robot, link) in self.bound.items():
            if robot == placed.name and (links is None or link in links):
                self._move_gripper(gripper, *_pose(poses[link]), teleport)

    def joints(self, name: str) -> dict:
        placed = self._placed(name)
        return {j: float(placed.joints.get(j, 0.0)) for j in placed.robot.joint_names}

    def link_pose(self, name: str, link: str) -> tuple[np.ndarray, np.ndarray]:
        placed = self._placed(name)
        if link not in placed.robot.all_links:
            raise ValueError(
                f"robot {name!r} has no link {link!r}; its links: "
                f"{', '.join(placed.robot.all_links)}"
            )
        return _pose(placed.link_poses()[link])

    def link_wrench(self, name: str, link: str, collider_wrench):
        """The wrench on a link: ``collider_wrench(i)`` of its colliders, the torques moved to
        the link's origin."""
        origin, _ = self.link_pose(name, link)
        force, torque = np.zeros(3), np.zeros(3)
        for collider, shape in self._placed(name).colliders:
            if shape.link == link:
                f, t = collider_wrench(self._index(collider))
                force += f
                torque += t + np.cross(collider.position - origin, f)
        return force, torque

    def _placed(self, name) -> Placed:
        if name not in self.placed:
            raise ValueError(f"unknown robot {name!r}; robots: {', '.join(self.placed) or 'none'}")
        return self.placed[name]

    def _index(self, collider) -> int:
        for i, c in enumerate(self._colliders()):
            if c is collider:
                return i
        raise LookupError(f"collider {collider.name!r} is no longer in the simulation")


class RobotMethods:
    """The robot methods every simulator has (the CPU's :class:`cloth_sim.Simulator` and the
    cuda device's), over its :attr:`robot_placement`: a :class:`Robots` made with its own
    colliders and grippers, and its ``collider_wrench``."""

    #: the simulator's robots (set by the simulator)
    robot_placement: Robots

    @property
    def robots(self) -> dict:
        """``{name: Robot}``: the robots in the scene (:mod:`cloth_sim.robot`)."""
        return {name: p.robot for name, p in self.robot_placement.placed.items()}

    def add_robot(
        self,
        robot,
        name: str | None = None,
        position=(0.0, 0.0, 0.0),
        orientation=(1.0, 0.0, 0.0, 0.0),
        joints: dict | None = None,
        friction: float = 0.5,
    ) -> str:
        """Put ``robot`` (a :class:`cloth_sim.robot.Robot`) in the scene as ``name`` (its URDF's
        name unless given), its root link at ``position``, ``orientation``: every ``<collision>``
        of its links becomes a collider ``name/link`` (``name/link/k`` where a link has several)
        with Coulomb ``friction``, at the joint positions ``joints`` (0 for those not named).
        Returns the name. A name in use, a bad pose or joint, or a simulator that cannot move
        a robot's links (:meth:`robot_refusal`) raises ``ValueError`` and adds nothing."""
        refused = self.robot_refusal()
        if refused is not None:
            raise refused
        return self.robot_placement.add(robot, name, position, orientation, joints, friction)

    def robot_refusal(self) -> ValueError | None:
        """Why a robot cannot be added here now, or ``None``: every method sweeps a robot's
        links on the CPU; a device names what it lacks."""
        return None

    def remove_robot(self, name: str):
        """Take robot ``name`` and its colliders out of the scene (grippers bound to its links stay
        where they are); returns the Robot."""
        return self.robot_placement.remove(name)

    def set_joint_positions(self, name: str, positions: dict, teleport: bool = False) -> None:
        """Robot ``name``'s joints to ``positions`` (joint name to rad or m; joints not named keep
        their value): forward kinematics places every link, which sweeps there over the next step
        (with ``teleport``, is there now, at rest), and grippers bound to its links follow. An
        unknown robot or joint, or a non-finite value, raises ``ValueError`` and moves nothing."""
        self.robot_placement.set_joints(name, positions, teleport)

    def set_link_transforms(self, name: str, transforms: dict, teleport: bool = False) -> None:
        """Place links of robot ``name`` directly: ``{link: 4×4 transform in the robot's root
        frame}`` (where something else computes the poses, as TF does for the node's
        ``robot.source: tf``); they sweep there over the next step, and override the links'
        forward kinematics from then on. An unknown robot or link, or a non-finite transform,
        raises ``ValueError``."""
        self.robot_placement.set_link_transforms(name, transforms, teleport)

    def joint_positions(self, name: str) -> dict:
        """Robot ``name``'s joint positions now (every movable joint)."""
        return self.robot_placement.joints(name)

    def link_wrench(self, name: str, link: str) -> tuple[np.ndarray, np.ndarray]:
        """``(force, torque)`` the cloth exerted on link ``link`` of robot ``name`` over the last
        step (its colliders' ``collider_wrench`` summed; torque about the link's origin): what a
        finger feels when it holds the cloth by friction."""
        return self.robot_placement.link_wrench(name, link, self.collider_wrench)

    def link_pose(self, name: str, link: str) -> tuple[np.ndarray, np.ndarray]:
        """``(position, orientation (w, x, y, z))`` of link ``link`` of robot ``name`` in the
        world, at its current joint positions."""
        return self.robot_placement.link_pose(name, link)

    def gripper_link(self, name: str):
        """The ``(robot, link)`` gripper ``name`` is bound to (it follows that link), or None
        for a gripper moved by its pose."""
        return self.robot_placement.bound.get(name)

    def link_frame(self, link):
        """``((position, orientation), (robot, link))``: the pose of a ``(robot, link)`` pair a
        gripper is to be bound to, and the pair (``ValueError`` for anything else)."""
        try:
            robot, link_name = link
        except (TypeError, ValueError):
            raise ValueError(f"link must be a (robot, link) pair, got {link!r}") from None
        return self.robot_placement.link_pose(robot, link_name), (robot, link_name)
