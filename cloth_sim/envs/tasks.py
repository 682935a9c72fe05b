"""SoftGym's three cloth tasks (Lin et al. 2020: ``softgym/envs/cloth_{flatten,fold,drop}.py``).

* :class:`ClothFlattenEnv` — a crumpled cloth on the floor; spread it out. Variation: the flat
  cloth grasped at a random particle, lifted 0.5–1 m, held until still (at most 5 s), dropped and
  left until still (at most 5 s), centred. Performance: the covered area; normalized: the coverage
  improvement from the start to the flat cloth's area.
* :class:`ClothFoldEnv` — a flat cloth turned by a random angle in ±45°; fold it in half, left onto
  right. Performance: ``−(mean |x_a − x_b| + 1.2 · mean |x_b − x_b(0)|)`` over the mirrored halves;
  normalized: from the start (0) to a perfect fold (1).
* :class:`ClothDropEnv` — a cloth hanging from its two top corners (0.1–0.2 m above the floor at
  its lowest, at least 0.5 m at its top, a random ±0.1 m along x); lay it flat at its target, the
  cloth lying along +x from x = 0. The pickers start at the two corners (not holding them: the
  first action must pick) and stay at least 0.5 m up. Performance: minus the mean distance to the
  target; normalized: from the start (0) to on target (1).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from . import metrics
from .cloth_env import ClothEnv

MAX_WAIT = 300  # frames (5 s), SoftGym's max_wait_step


class ClothFlattenEnv(ClothEnv):
    task = "ClothFlatten"  # SoftGym's horizon 100 and action repeat 8: ClothEnv's defaults
    instruction = "Spread the crumpled cloth out flat on the floor."

    def _generate(self, rng):
        x = self.lay_flat()
        j = int(rng.integers(len(x)))
        lift = 0.5 + 0.5 * rng.random()
        p0 = x[j].copy()
        self.sim.grasp("crumple", p0, 1e-12)
        up = p0 + (0.0, 0.0, lift)
        # lifted at 1 m/s (SoftGym moves it there at once), then held until still
        steps = int(np.ceil(lift / 1.0 / self.sim.dt))
        for i in range(1, steps + 1):
            self.sim.set_gripper_pose("crumple", p0 + (up - p0) * (i / steps))
            self.sim.step()
        self.frames(MAX_WAIT, self.still(0.01))
        self.sim.release("crumple")
        self.frames(MAX_WAIT, self.still(0.01))
        x = self.sim.positions.copy()
        x[:, :2] -= (x[:, :2].min(axis=0) + x[:, :2].max(axis=0)) / 2
        return dict(positions=x, velocities=self.sim.velocities.copy())

    @property
    def radius(self) -> float:
        return self.spacing / 2

    def _start(self):
        x = self.sim.positions
        lo, hi = x[:, :2].min(axis=0), x[:, :2].max(axis=0)
        self.pickers.reset(self.sim, [*(lo + hi) / 2, 0.2])
        self.area_start = metrics.covered_area(x, self.radius)

    @cached_property
    def area_flat(self) -> float:
        """The flat cloth's covered area: the best possible (one per env: it depends on the
        grid)."""
        return metrics.covered_area(self.flat_positions(), self.radius)

    def _performance(self):
        return metrics.covered_area(self.sim.positions, self.radius), {}

    def _normalized(self, performance):
        return metrics.normalized(performance, self.area_start, self.area_flat)


class ClothFoldEnv(ClothEnv):
    task = "ClothFold"
    instruction = "Fold the cloth in half, its left half onto its right."

    def _generate(self, rng):
        self.lay_flat()
        self.frames(MAX_WAIT, self.still(0.01))
        x = self.sim.positions.copy()
        c = x[:, :2].mean(axis=0)
        a = (rng.random() - 0.5) * np.pi / 2
        rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        x[:, :2] = (x[:, :2] - c) @ rot.T
        v = self.sim.velocities.copy()
        v[:, :2] = v[:, :2] @ rot.T
        return dict(positions=x, velocities=v, angle=np.float64(a))

    def _start(self):
        x = self.sim.positions
        mid = x[self.corners[:2]].mean(axis=0)
        self.pickers.reset(self.sim, [mid[0], mid[1], 0.1])
        self.group_a, self.group_b = metrics.fold_groups(self.rows, self.cols)
        self.start_positions = x.copy()
        self.performance_start = self._performance()[0]

    def _performance(self):
        p, group, fixation = metrics.fold_distance(
            self.sim.positions, self.start_positions, self.group_a, self.group_b
        )
        return p, dict(neg_group_dist=-group, neg_fixation_dist=-fixation)

    def _normalized(self, performance):
        return metrics.normalized(performance, self.performance_start, 0.0)


class ClothDropEnv(ClothEnv):
    task = "ClothDrop"
    instruction = "Lay the hanging cloth flat on the floor at its target."
    defaults = dict(horizon=30, action_repeat=16)
    picker_bounds = ((-0.28, -0.48, 0.52), (0.48, 0.48, 1.98))
    camera = dict(position=(1.3, -1.1, 1.1), look_at=(0.15, 0.0, 0.3), fov=45.0)

    def _check_task(self):
        if self.num_picker != 2:
            raise ValueError(
                f"num_picker = {self.num_picker} is not accepted by ClothDrop: it holds "
                f"the cloth by its two top corners (2)"
            )

    def target(self) -> np.ndarray:
        """The cloth flat on the floor along +x from x = 0, centred on y = 0, column 0 at x = 0."""
        x = self.flat_positions()
        x[:, 0] -= x[:, 0].min()
        return x

    def _generate(self, rng):
        s = self.spacing
        row, col = np.divmod(np.arange(self.rows * self.cols), self.cols)
        x = np.empty((self.rows * self.cols, 3))
        x[:, 0] = rng.random() * 0.2 - 0.1
        x[:, 1] = row * s - (self.rows - 1) * s / 2
        x[:, 2] = (self.cols - 1 - col) * s + 0.1 + 0.1 * rng.random()
        x[:, 2] += max(0.0, 0.5 - x[:, 2].max())
        x[0, 0] += rng.random() * 0.001  # SoftGym's jitter: the cloth does not hang perfectly flat
        self._set_state(x, np.zeros_like(x))
        for name, i in zip(("a", "b"), self.corners[:2]):
            self.sim.grasp(name, x[i], 1e-12)
        self.frames(60)
        self.frames(MAX_WAIT - 60, self.still(0.1))
        return dict(positions=self.sim.positions.copy(), velocities=self.sim.velocities.copy())

    def _start(self):
        top = self.sim.positions[self.corners[:2]]
        self.pickers.reset(self.sim, top.mean(axis=0), bounds=self.picker_bounds)
        self.pickers.place(top + (0.0, 0.0, self.picker_radius))  # as SoftGym places them
        self.goal = self.target()
        self.performance_start = self._performance()[0]

    def _performance(self):
        return -metrics.mean_distance(self.sim.positions, self.goal), {}

    def _normalized(self, performance):
        return metrics.normalized(performance, self.performance_start, 0.0)
