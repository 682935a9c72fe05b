"""Grippers: named rigid holds on the cloth, moved by the user, reporting the force the cloth pulls
with.

``Simulator.grasp(name, point, radius)`` takes every particle within ``radius`` of ``point`` (none
already held) and holds them rigidly: they keep their offsets from the gripper's pose at the moment
of the grasp (position ``point``, orientation identity), rotated with it. Held particles are
kinematic, as pins are: the integrators give them no acceleration, and before a step in which the
gripper moves each held particle gets the velocity that carries it from where it is to its place at
the new pose over the step (every integrator then moves it there: its position update is ``x +=
dt·v`` for a particle with no acceleration, and Verlet's history is set to match), and after the
step it is put exactly there. So the springs and their damping see the gripper's real motion, and a
released particle keeps the gripper's last velocity (no jerk).

The wrench is what the cloth's springs exert on the held particles at the end of the last step:
force ``Σ f_i`` and torque ``Σ (x_i − p) × f_i`` about the gripper's position ``p`` (world frame).
The held particles move with the gripper, so their own weight is the gripper's, not the cloth's: a
cloth hanging at rest from one gripper pulls it with the weight of its free particles,
``M_free·g``.
"""

from __future__ import annotations

import numpy as np

from ..contact.geometry import positive, quaternion_matrix, unit_quaternion, vector


class Gripper:
    """One named hold: its particles, their offsets in its frame, its pose and a pending target."""

    def __init__(self, name: str, indices: np.ndarray, offsets: np.ndarray, position: np.ndarray):
        self.name = name
        self.indices = indices
        self.offsets = offsets
        self.position = position
        self.orientation = np.array([1.0, 0.0, 0.0, 0.0])
        self.rotation = np.eye(3)
        #: ``(position, orientation, rotation)`` to reach over the next step, or None
        self.target = None
        #: the held particles' places at ``target`` (set when the step towards it begins)
        self.goal = None
        #: whether the held particles have a velocity (the gripper moved over the last step)
        self.moving = False

    def places(self, position, rotation) -> np.ndarray:
        """Where the held particles are at a pose."""
        return position + self.offsets @ rotation.T


def check_pose(position, orientation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(position, unit quaternion, rotation matrix)``, or ``ValueError`` naming what is wrong."""
    p = vector("position", position)
    q = unit_quaternion(orientation)
    return p, q, quaternion_matrix(q)


def check_name(name) -> str:
    if not isinstance(name, str) or not name:
        raise ValueError(f"gripper name must be a non-empty string, got {name!r}")
    return name


def check_grasp(point, radius) -> tuple[np.ndarray, float]:
    return vector("point", point), positive("radius", radius)


def check_box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = vector("box min", lo), vector("box max", hi)
    if np.any(lo > hi):
        raise ValueError(f"box: min {lo.tolist()} must not exceed max {hi.tolist()} on any axis")
    return lo, hi
