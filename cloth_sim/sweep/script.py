"""A run's script: grasps, moves and releases at given simulated times (the spec's ``script``, its
``$variables`` resolved).

Before each step :meth:`Script.before_step` applies what is due: an event fires at the first step
that begins at or after its ``at``; a move carries a gripper or a collider in a straight line from
where it is when the move begins to ``to`` over ``duration`` seconds (its orientation kept), by
setting the pose the step ends at, so grippers drag their particles as the node's grippers do.
"""

from __future__ import annotations

import numpy as np


class ScriptError(ValueError):
    """An event that cannot be carried out (no particle within a grasp's radius, an unknown gripper
    or collider); the message names the event."""


class Script:
    def __init__(self, events: list):
        self.events = sorted(enumerate(events), key=lambda e: e[1]["at"])
        self._next = 0
        # (label, kind, key, start time, start position, end position, duration)
        self._moves: list = []

    @property
    def idle(self) -> bool:
        """Nothing left to fire and nothing moving."""
        return self._next >= len(self.events) and not self._moves

    def before_step(self, sim) -> None:
        t = sim.time
        while self._next < len(self.events) and self.events[self._next][1]["at"] <= t + 1e-12:
            i, event = self.events[self._next]
            self._next += 1
            self._fire(sim, i, event)
        if self._moves:
            self._move(sim, t + sim.dt)

    def _fire(self, sim, i: int, event: dict) -> None:
        kind = next(k for k in event if k != "at")
        body = event[kind]
        label = f"script[{i}].{kind}"
        try:
            if kind == "grasp":
                held = sim.grasp(body["gripper"], body["point"], body["radius"])
                if len(held) == 0:
                    raise ScriptError(
                        f"{label}: no particle within radius {body['radius']:g} m of "
                        f"{np.round(body['point'], 4).tolist()}"
                    )
            elif kind == "release":
                sim.release(body["gripper"])
                self._moves = [m for m in self._moves if m[1:3] != ("gripper", body["gripper"])]
            else:
                if "gripper" in body:
                    key, what = body["gripper"], "gripper"
                    start = sim.gripper_pose(key)[0]
                else:
                    names = [c.name for c in sim.colliders]
                    if body["collider"] not in names:
                        raise ScriptError(
                            f"{label}.collider: {body['collider']!r} is not a collider "
                            f"of this run; its colliders are {', '.join(names) or 'none'}"
                        )
                    key, what = names.index(body["collider"]), "collider"
                    start = sim.colliders[key].position.copy()
                self._moves = [m for m in self._moves if m[1:3] != (what, key)]
                self._moves.append(
                    (
                        label,
                        what,
                        key,
                        sim.time,
                        np.array(start, float),
                        np.array(body["to"], float),
                        float(body["duration"]),
                    )
                )
        except ScriptError:
            raise
        except (KeyError, ValueError) as e:  # an unknown gripper, a grasp by a name already held
            raise ScriptError(f"{label}: {e}") from None

    def _move(self, sim, t_end: float) -> None:
        left = []
        for move in self._moves:
            label, what, key, t0, p0, p1, duration = move
            f = 1.0 if duration <= 0 else min(1.0, (t_end - t0) / duration)
            p = (1 - f) * p0 + f * p1
            if what == "gripper":
                sim.set_gripper_pose(key, p, sim.gripper_pose(key)[1])
            else:
                sim.set_collider_pose(key, p, sim.colliders[key].orientation)
            if f < 1.0:
                left.append(move)
        self._moves = left
