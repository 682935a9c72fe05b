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


class Grips:
    """A simulator's grippers by name: which free particles a new grasp takes, where the held
    particles go over a step, and the pins they add to the model's. The simulator rebuilds what
    depends on the pins when the set changes; this part knows nothing of the integrator but the
    hook it calls (``kinematic_velocities``)."""

    def __init__(self):
        self.held: dict[str, Gripper] = {}

    def __bool__(self) -> bool:
        return bool(self.held)

    def new_name(self, name) -> str:
        """``name`` for a new gripper: a non-empty string not in use (``ValueError`` otherwise)."""
        name = check_name(name)
        if name in self.held:
            raise ValueError(
                f"gripper {name!r} already holds {len(self.held[name].indices)} "
                f"particles: release it first"
            )
        return name

    def get(self, name) -> Gripper:
        """Gripper ``name`` (``ValueError`` naming the grippers there are otherwise)."""
        g = self.held.get(name) if isinstance(name, str) else None
        if g is None:
            raise ValueError(
                f"unknown gripper {name!r}; grippers: "
                f"{', '.join(self.held) if self.held else 'none (grasp first)'}"
            )
        return g

    @staticmethod
    def nearest(x: np.ndarray, pinned: np.ndarray, point) -> tuple[int, float]:
        """``(index, distance)`` of the free particle of ``x`` nearest to ``point`` (the first of
        the nearest, as ``np.argmin`` takes it), ``(-1, inf)`` where none is free (a picker's
        grasp)."""
        if not (~pinned).any():
            return -1, np.inf
        d = np.linalg.norm(x - point, axis=1)
        d[pinned] = np.inf
        j = int(np.argmin(d))
        return j, float(d[j])

    @staticmethod
    def within(name: str, x: np.ndarray, pinned: np.ndarray, point, radius) -> np.ndarray:
        """The free particles of ``x`` within ``radius`` of ``point`` (checked by
        :func:`check_grasp`); ``ValueError`` when there is none, naming the nearest's distance."""
        d = np.linalg.norm(x - point, axis=1)
        idx = np.flatnonzero((d <= radius) & ~pinned)
        if len(idx) == 0:
            near = float(d[~pinned].min()) if (~pinned).any() else float("nan")
            raise ValueError(
                f"grasp {name!r}: no free particle within radius {radius:g} m of point "
                f"{point.tolist()} (the nearest is {near:.4g} m away)"
            )
        return idx

    @staticmethod
    def inside(name: str, x: np.ndarray, pinned: np.ndarray, lo, hi) -> np.ndarray:
        """The free particles of ``x`` inside the axis-aligned box ``[lo, hi]`` (checked by
        :func:`check_box`); ``ValueError`` when there is none."""
        idx = np.flatnonzero(np.all((x >= lo) & (x <= hi), axis=1) & ~pinned)
        if len(idx) == 0:
            raise ValueError(
                f"grasp {name!r}: no free particle inside the box {lo.tolist()} .. {hi.tolist()}"
            )
        return idx

    def add(self, name: str, idx: np.ndarray, x: np.ndarray, point, orientation=None) -> Gripper:
        """Hold the particles ``idx`` at ``x[idx]`` with a gripper at ``point`` (and
        ``orientation``: their offsets are then in its frame)."""
        g = Gripper(name, idx, x[idx] - point, point)
        if orientation is not None:
            g.position, g.orientation, g.rotation = check_pose(point, orientation)
            g.offsets = g.offsets @ g.rotation
        self.held[name] = g
        return g

    def aim(self, name, position, orientation, teleport: bool) -> Gripper | None:
        """Gripper ``name``'s next pose (checked: an unknown name or a bad pose raises
        ``ValueError`` and changes nothing): reached over the next step, or with ``teleport``
        its pose now, at rest; returns the gripper when teleported (its caller puts the held
        particles at their places), else None."""
        g = self.get(name)
        pose = check_pose(position, orientation)
        if not teleport:
            g.target = pose
            return None
        g.position, g.orientation, g.rotation = pose
        g.target, g.goal, g.moving = None, None, False
        return g

    def pinned(self, base: np.ndarray) -> np.ndarray:
        """``base``'s pins and every held particle."""
        mask = np.array(base)
        for g in self.held.values():
            mask[g.indices] = True
        return mask

    def settle(self, x: np.ndarray, v: np.ndarray) -> None:
        """Held particles at their grippers' places, at rest, none moving (a state put back)."""
        for g in self.held.values():
            x[g.indices] = g.places(g.position, g.rotation)
            v[g.indices] = 0.0
            g.moving, g.target = False, None

    def before_step(self, state, integrator, dt: float) -> None:
        """Held particles get the velocity that takes them to their places at the gripper's target
        (zero when it stays)."""
        x, v = state.x, state.v
        for g in self.held.values():
            if g.target is not None:
                g.goal = g.places(g.target[0], g.target[2])
                v[g.indices] = (g.goal - x[g.indices]) / dt
                integrator.kinematic_velocities(state, g.indices, dt)
            elif g.moving:
                v[g.indices] = 0.0
                integrator.kinematic_velocities(state, g.indices, dt)

    def after_step(self, x: np.ndarray) -> None:
        """Held particles exactly at their places (the integrators' ``x + dt·v`` rounds)."""
        for g in self.held.values():
            if g.target is not None:
                x[g.indices] = g.goal

    def commit(self) -> None:
        """The step is taken: each gripper is at its target."""
        for g in self.held.values():
            g.moving = g.target is not None
            if g.target is not None:
                g.position, g.orientation, g.rotation = g.target
                g.target = None
