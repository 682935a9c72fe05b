"""Scripted motion: a scene's time-stamped joint positions for its robot and poses for its
grippers, played as the simulator advances.

A :class:`Motion` is keyframes: joint positions interpolated linearly between their times, a
gripper's position linearly and its orientation by spherical interpolation (so a quarter turn
between two keyframes turns at a constant rate). Before each step the simulator asks it for the
values at the step's end (:meth:`drive`) and the robot's links and the grippers sweep there over
the step, as if a controller had sent them; before the first keyframe the first holds, after the
last the script lets go and they stay there until something else moves them (a node's joint states
or pose topics); with ``repeat`` it starts over.

In a scene file (``motion:``)::

    motion:
      repeat: false
      robot:                      # the scene's robot (robot:), joints not named keep their value
        - {t: 0.0, joints: {shoulder_yaw: 0.2}}
        - {t: 0.7, joints: {shoulder_yaw: 1.9}}
      grippers:                   # grippers the scene declares (grippers:)
        left:
          - {t: 0.0, position: [-0.75, 0, 1], orientation: [1, 0, 0, 0]}
          - {t: 1.0, position: [-0.75, 0, 1], orientation: [0.866, 0.5, 0, 0]}
"""

from __future__ import annotations

import math

import numpy as np

#: keyframes a script may hold (per robot or gripper)
MAX_KEYFRAMES = 10_000


def slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions ``(w, x, y, z)`` (the shorter arc)."""
    d = float(q0 @ q1)
    if d < 0.0:
        q1, d = -q1, -d
    if d > 1.0 - 1e-12:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    a = math.acos(min(1.0, d))
    return (math.sin((1 - s) * a) * q0 + math.sin(s * a) * q1) / math.sin(a)


def _bracket(times: np.ndarray, t: float) -> tuple[int, int, float]:
    """Keyframes ``(i, j, s)`` around ``t`` and the fraction ``s`` of the way from i to j."""
    if t <= times[0]:
        return 0, 0, 0.0
    if t >= times[-1]:
        return len(times) - 1, len(times) - 1, 0.0
    j = int(np.searchsorted(times, t, side="right"))
    i = j - 1
    return i, j, (t - times[i]) / (times[j] - times[i])


class Motion:
    """Keyframes: ``robot`` (its name) with ``joints`` ``[(t, {joint: value})]``, ``grippers``
    ``{name: [(t, position, orientation)]}``, each list in increasing time; ``repeat`` plays it
    over and over (period: the last keyframe's time)."""

    def __init__(self, robot=None, joints=(), grippers=None, repeat: bool = False):
        self.robot = robot
        self.joints = list(joints)
        self.grippers = {k: list(v) for k, v in (grippers or {}).items()}
        self.repeat = bool(repeat)
        self._jt = np.array([t for t, _ in self.joints])
        self._gt = {k: np.array([t for t, *_ in v]) for k, v in self.grippers.items()}
        ends = [self._jt[-1]] if len(self._jt) else []
        ends += [t[-1] for t in self._gt.values() if len(t)]
        #: the script's length (s)
        self.duration = float(max(ends)) if ends else 0.0

    def _local(self, t: float) -> float:
        if self.repeat and self.duration > 0:
            return math.fmod(t, self.duration)
        return t

    def joints_at(self, t: float) -> dict:
        """The robot's joint positions at time ``t`` (the joints the keyframes name)."""
        if not self.joints:
            return {}
        i, j, s = _bracket(self._jt, self._local(t))
        a, b = self.joints[i][1], self.joints[j][1]
        names = set(a) | set(b)
        return {n: (1 - s) * a.get(n, b.get(n)) + s * b.get(n, a.get(n)) for n in sorted(names)}

    def gripper_at(self, name: str, t: float) -> tuple[np.ndarray, np.ndarray]:
        frames = self.grippers[name]
        i, j, s = _bracket(self._gt[name], self._local(t))
        (_, p0, q0), (_, p1, q1) = frames[i], frames[j]
        return (1 - s) * p0 + s * p1, slerp(q0, q1, s)

    def drive(self, sim, start: float, t: float) -> None:
        """Set ``sim``'s robot joints and gripper targets to their values at time ``t``, the end
        of the step about to be taken from ``start``. A gripper of the script that holds nothing
        at the moment is skipped. Once a script that does not repeat has ended (the step starts at
        or after its last keyframe, which the step before reached), it sets nothing: the joints
        and grippers stay there until something else moves them (joint states, pose topics)."""
        if not self.repeat and start >= self.duration and start > 0.0:
            return
        if self.robot is not None and self.joints and self.robot in sim.robots:
            sim.set_joint_positions(self.robot, self.joints_at(t))
        held = sim.grippers
        for name in self.grippers:
            if name in held:
                sim.set_gripper_pose(name, *self.gripper_at(name, t))


def motion_from_dict(v, data, robot: str | None, grippers) -> Motion:
    """Validate a scene's ``motion`` mapping (``v`` the scene's validator: every refusal names the
    field); ``robot`` the scene's robot name (None without one), ``grippers`` the names the scene
    declares."""
    if not isinstance(data, dict):
        v.fail("motion", "a mapping with robot and/or grippers keyframes, and repeat", data)
    v.known("motion.", data, {"robot", "grippers", "repeat"})
    repeat = data.get("repeat", False)
    if not isinstance(repeat, bool):
        v.fail("motion.repeat", "true or false", repeat)
    joints = []
    if "robot" in data:
        if robot is None:
            v.fail("motion.robot", "keyframes for the scene's robot, which it lacks (robot:)", {})
        frames = _frames(v, "motion.robot", data["robot"])
        for k, f in enumerate(frames):
            where = f"motion.robot[{k}]"
            v.known(f"{where}.", f, {"t", "joints"})
            js = f.get("joints")
            if not isinstance(js, dict) or not js:
                v.fail(f"{where}.joints", "a mapping of joint names to positions", js)
            joints.append(
                (
                    _time(v, where, f, joints),
                    {str(n): v.number(f"{where}.joints.{n}", x) for n, x in js.items()},
                )
            )
    gr = {}
    g = data.get("grippers", {}) or {}
    if not isinstance(g, dict):
        v.fail("motion.grippers", "a mapping of gripper names to keyframes", g)
    for name, frames_ in g.items():
        if name not in grippers:
            v.fail(
                f"motion.grippers.{name}",
                f"a gripper the scene declares ({', '.join(grippers) or 'none'})",
                name,
            )
        frames, out = _frames(v, f"motion.grippers.{name}", frames_), []
        for k, f in enumerate(frames):
            where = f"motion.grippers.{name}[{k}]"
            v.known(f"{where}.", f, {"t", "position", "orientation"})
            p = np.array(v.vector(f"{where}.position", f.get("position"), 3))
            q = np.array(v.vector(f"{where}.orientation", f.get("orientation", [1, 0, 0, 0]), 4))
            if not np.linalg.norm(q) > 1e-12:
                v.fail(f"{where}.orientation", "a nonzero quaternion (w, x, y, z)", q.tolist())
            out.append((_time(v, where, f, out), p, q / np.linalg.norm(q)))
        gr[name] = out
    return Motion(robot if joints else None, joints, gr, repeat)


def _frames(v, where, frames) -> list:
    if not isinstance(frames, list) or not 1 <= len(frames) <= MAX_KEYFRAMES:
        v.fail(where, f"a list of 1 to {MAX_KEYFRAMES} keyframes {{t, …}}", frames)
    for k, f in enumerate(frames):
        if not isinstance(f, dict):
            v.fail(f"{where}[{k}]", "a mapping with t and its values", f)
    return frames


def _time(v, where, frame, earlier) -> float:
    t = v.number(f"{where}.t", frame.get("t"), lo=0.0)
    if earlier and t <= earlier[-1][0]:
        v.fail(f"{where}.t", f"a time after the keyframe before ({earlier[-1][0]:g} s)", t)
    return t
