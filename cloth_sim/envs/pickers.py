"""SoftGym's pickers on cloth_sim's grippers.

A picker is a point that moves by at most ``max_move`` per frame inside a box (``low``, ``high``:
the bounds of its centre) and, while its pick flag is on, holds the one free particle that was
nearest to it, within ``reach``, when the flag went on (SoftGym's ``Picker``: Lin et al. 2020,
``softgym/action_space/action_space.py``). The particle is held rigidly at its offset from the
picker: it is a cloth_sim gripper (``Simulator.grasp``), so the strain limit, contacts and the
gripper's wrench all see it. Turning the flag off releases it with the picker's velocity. Unlike
SoftGym's spheres, pickers do not collide with the cloth, so their centres may go down to the
height of a particle lying on the floor: SoftGym's spheres stop 5 cm up and take the nearest
particle within 6 cm, which in a crumpled pile is often one on top of the corner aimed at rather
than the corner itself.

Coordinates are cloth_sim's (z up); SoftGym's FleX scenes are y up, so its ``(x, y, z)`` bounds are
``(x, z, y)`` here.
"""

from __future__ import annotations

import numpy as np

from ..constraints.grippers import Grips


class Pickers:
    """``count`` pickers; :meth:`reset` places them, :meth:`frame` moves them over one frame."""

    def __init__(self, count: int, radius: float, reach: float, max_move: float, low, high):
        self.count = int(count)
        self.radius = float(radius)
        self.reach = float(reach)
        self.max_move = float(max_move)
        self._span = (np.array(low, float), np.array(high, float))
        self.low, self.high = self._span[0].copy(), self._span[1].copy()
        self.positions = np.zeros((self.count, 3))
        #: the gripper offset (held particle − picker) of each picker holding one, else None
        self.held: list = [None] * self.count
        #: each picker's gripper name in the simulator
        self.names = tuple(f"picker{i}" for i in range(self.count))

    def reset(self, sim, center, bounds=None) -> None:
        """Release everything, centre the bounds on ``center`` horizontally (SoftGym's
        ``Picker.reset``; or use ``bounds = (low, high)`` as given) and place the pickers on a
        circle of radius ``2·radius·√(count − 1)`` about ``center``."""
        for i in range(self.count):
            self._release(sim, i)
        center = np.asarray(center, float)[None]
        if bounds is None:
            low, high = centred_bounds(center, *self._span)
        else:
            low, high = (np.array(b, float)[None] for b in bounds)
        self.low, self.high = low[0], high[0]
        self.positions = on_circle(center, self.count, self.radius, low, high)[0]

    def place(self, positions) -> None:
        """Put the pickers at ``positions`` (clipped to the bounds) without moving anything
        held."""
        self.positions = np.array([self.clip(p) for p in np.asarray(positions, float)])

    def clip(self, p) -> np.ndarray:
        """``p`` inside the bounds (of the picker's centre)."""
        return np.clip(p, self.low, self.high)

    def frame(self, sim, delta, pick, substeps: int) -> None:
        """One frame: release where ``pick`` went off, grasp where it is on and nothing is held,
        then move by ``delta`` (each component clipped to ``±max_move``, the end clipped to the
        bounds) in ``substeps`` equal steps of the simulation, dragging what is held."""
        delta = np.clip(
            np.asarray(delta, float).reshape(self.count, 3), -self.max_move, self.max_move
        )
        for i in range(self.count):
            if not pick[i]:
                self._release(sim, i)
        for i in range(self.count):
            if pick[i] and self.held[i] is None:
                self._grasp(sim, i)
        start = self.positions.copy()
        end = np.array([self.clip(p) for p in start + delta])
        moving = [
            i
            for i in range(self.count)
            if self.held[i] is not None and not np.array_equal(start[i], end[i])
        ]
        for s in range(1, substeps + 1):
            for i in moving:
                p = start[i] + (end[i] - start[i]) * (s / substeps)
                sim.set_gripper_pose(self.names[i], p + self.held[i])
            sim.step()
        self.positions = end

    def _grasp(self, sim, i: int) -> None:
        x = sim.positions
        j, d = Grips.nearest(x, sim.model.pinned, self.positions[i])
        if j < 0 or d > self.reach:
            return
        sim.grasp(self.names[i], x[j], 1e-12)
        self.held[i] = x[j] - self.positions[i]

    def _release(self, sim, i: int) -> None:
        if self.held[i] is not None:
            sim.release(self.names[i])
            self.held[i] = None


def centred_bounds(centers, low, high) -> tuple[np.ndarray, np.ndarray]:
    """Bounds ``low``–``high`` (each ``(3,)``) moved horizontally to be centred on each of
    ``centers`` (``(W, 3)``): ``(lows, highs)``, each ``(W, 3)`` (SoftGym's ``Picker.reset``)."""
    lows = np.tile(np.asarray(low, float), (len(centers), 1))
    highs = np.tile(np.asarray(high, float), (len(centers), 1))
    shift = centers[:, :2] - (lows[:, :2] + highs[:, :2]) / 2
    lows[:, :2] += shift
    highs[:, :2] += shift
    return lows, highs


def on_circle(centers, count: int, radius: float, lows, highs) -> np.ndarray:
    """``(W, count, 3)``: ``count`` pickers of ``radius`` on a circle of radius ``2·radius·√(count
    − 1)`` about each of ``centers`` (``(W, 3)``), each clipped to its world's bounds."""
    r = np.sqrt(count - 1) * radius * 2.0
    a = 2 * np.pi * np.arange(count) / count
    pts = np.empty((len(centers), count, 3))
    pts[:, :, 0] = centers[:, None, 0] + np.sin(a) * r
    pts[:, :, 1] = centers[:, None, 1] + np.cos(a) * r
    pts[:, :, 2] = centers[:, None, 2]
    return np.clip(pts, lows[:, None], highs[:, None])
