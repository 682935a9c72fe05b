"""Many worlds of one cloth stepped together: :class:`BatchSimulator`.

``BatchSimulator(model, worlds=4096, integrator="vbd", dt=1/60, device="cuda")`` steps every world
in the same launches on a GPU (:class:`cloth_sim.cuda.simulator.CudaBatchSimulator`);
``device="cpu"`` (the default) is this class: one :class:`~cloth_sim.simulator.Simulator` a world,
stepped in turn, with the same names, so code written against a batch runs on either.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from . import backends
from .constraints.grippers import Grips
from .parameters import SCHEMA
from .simulator import Simulator


class BatchSimulator:
    """``worlds`` copies of ``model`` (or a list of models, one a world), each with its own
    parameters (:meth:`set`) and state.

    ``positions``: ``(worlds, n, 3)``; on the GPU a device array (``__cuda_array_interface__``),
    here a numpy array (a copy). :meth:`positions_host` is the numpy array on both."""

    def __new__(cls, *args, device: str = "cpu", **kwargs):
        if cls is BatchSimulator and device != "cpu":
            return backends.implementation(device, batch=True)(*args, **kwargs)
        return super().__new__(cls)

    def __init__(
        self,
        models,
        worlds: int | None = None,
        integrator: str = "vbd",
        dt: float = 1 / 60,
        device: str = "cpu",
        **kwargs,
    ):
        backends.check_device(device)
        self.device = "cpu"
        models = backends.models_of(models, worlds)
        colliders = kwargs.pop("colliders", None) or ()
        # each world its own collider shapes: a world's moved collider is its own
        self.sims = [
            Simulator(
                m,
                integrator=integrator,
                dt=dt,
                colliders=[copy.copy(c) for c in colliders],
                **kwargs,
            )
            for m in models
        ]
        self.worlds = len(self.sims)
        self.dt = float(dt)
        #: the positions each world was last set to (:meth:`write`, :meth:`reset`)
        self._set = np.stack([m.positions for m in models]).astype(np.float64)

    def _ids(self, worlds) -> np.ndarray:
        return backends.world_ids(worlds, self.worlds)

    @property
    def positions(self) -> np.ndarray:
        return np.stack([s.positions for s in self.sims])

    def positions_host(self) -> np.ndarray:
        return self.positions

    def velocities_host(self) -> np.ndarray:
        return np.stack([s.velocities for s in self.sims])

    @property
    def time(self) -> np.ndarray:
        return np.array([s.time for s in self.sims])

    def set(
        self,
        worlds=None,
        *,
        gravity=None,
        wind=None,
        drag=None,
        stiffness=None,
        damping=None,
        colliders=None,
    ):
        """As :meth:`cloth_sim.cuda.worlds.CudaWorlds.set`: per-world ``gravity``, ``wind`` (a
        3-vector or one a world), ``drag``, ``stiffness``/``damping`` ``{family: value}``, and
        ``colliders`` ``{index: (position, orientation)}`` (each world's collider there now, at
        rest). Everything is checked, for every world named, before anything changes: a bad
        value raises ``ValueError`` naming it and leaves every world as it was."""
        ids = self._ids(worlds)
        g = None if gravity is None else backends.world_vectors("gravity", gravity, len(ids))
        a = None if wind is None else backends.world_vectors("wind", wind, len(ids))
        if g is not None:  # each world's in the simulator's range
            g = [SCHEMA["gravity"].check(row.tolist()) for row in g]
        if drag is not None:
            SCHEMA["drag"].check(drag)
        plan = [self._checked(self.sims[w], stiffness, damping, colliders) for w in ids]
        for r, (w, (families, poses)) in enumerate(zip(ids, plan)):
            s = self.sims[w]
            if g is not None:
                s.gravity = g[r]
            if a is not None:
                s.wind = a[r]
            if drag is not None:
                s.drag = drag
            for what, fam, value in families:
                (s.set_stiffness if what == "stiffness" else s.set_damping)(fam, value)
            for index, (position, orientation) in poses:
                s.set_collider_pose(index, position, orientation, teleport=True)

    @staticmethod
    def _checked(sim, stiffness, damping, colliders):
        """:meth:`set`'s values for one world named, ``sim``, that depend on its cloth and
        colliders, checked as the simulator's own setters check them (nothing is changed):
        ``([(what, family, value)], [(collider index, (position, orientation))])``."""
        families = []
        for what, given in (("stiffness", stiffness), ("damping", damping)):
            for fam, value in (given or {}).items():
                sim.model.family_index(fam)  # an unknown family: the model's names
                spec = SCHEMA.get(f"{what}.{fam}", SCHEMA[f"{what}.structural"])
                families.append((what, fam, spec.check(value, field=f"{what}.{fam}")))
        poses = []
        shapes = sim.colliders
        for index, pose in (colliders or {}).items():
            backends.placed_collider(shapes, index, pose)  # (the pose as the shape checks it)
            poses.append((int(index), tuple(pose)))
        return families, poses

    def hold(self, worlds, indices, points=None) -> None:
        """Hold vertices ``indices`` of ``worlds`` where ``points`` puts them (``(p, 3)`` or one
        set a world; their current positions when None), at rest: a gripper a vertex on the cpu
        (``hold:<index>``), a vertex taken out of the solve on cuda."""
        ids = self._ids(worlds)
        idx = np.asarray(indices, np.int64).ravel()
        pts = None if points is None else np.asarray(points, np.float64)
        for r, w in enumerate(ids):
            sim = self.sims[w]
            at = sim.positions[idx] if pts is None else (pts[r] if pts.ndim == 3 else pts)
            for k, i in enumerate(idx):
                x = sim.positions[i]
                sim.grasp_box(f"hold:{i}", x, x)
                sim.set_gripper_pose(f"hold:{i}", at[k], teleport=True)

    def release(self, worlds, indices=None) -> None:
        """Let ``worlds``' held vertices ``indices`` (all when None) go."""
        for w in self._ids(worlds):
            sim = self.sims[w]
            names = [n for n in sim.grippers if n.startswith("hold:")]
            if indices is not None:
                wanted = {f"hold:{int(i)}" for i in np.asarray(indices).ravel()}
                names = [n for n in names if n in wanted]
            for name in names:
                sim.release(name)

    def _pairs(self, worlds, indices):
        return backends.world_pairs(worlds, indices, self.worlds, self.sims[0].model.n_particles)

    def hold_pairs(self, worlds, indices) -> None:
        """Hold vertex ``indices[r]`` of world ``worlds[r]`` where it is, one a row (a gripper
        ``hold:<index>`` each, as :meth:`hold`; at rest until :meth:`drag` moves it)."""
        for w, i in zip(*self._pairs(worlds, indices)):
            x = self.sims[w].positions[i]
            self.sims[w].grasp_box(f"hold:{i}", x, x)

    def release_pairs(self, worlds, indices) -> None:
        """Let vertex ``indices[r]`` of world ``worlds[r]`` go, one a row."""
        for w, i in zip(*self._pairs(worlds, indices)):
            self.sims[w].release(f"hold:{i}")

    def drag(self, worlds, indices, ends, steps: int, starts=None) -> None:
        """``steps`` steps while held vertex ``indices[r]`` of world ``worlds[r]`` (one a row)
        moves in a straight line at constant speed from ``starts[r]`` (where it is when None) to
        ``ends[r]``: its gripper set to the line's point at each step's end
        (:meth:`Simulator.set_gripper_pose`)."""
        w, i = self._pairs(worlds, indices)
        end = np.reshape(np.asarray(ends, np.float64), (len(w), 3))
        if starts is not None:
            start = np.reshape(np.asarray(starts, np.float64), (len(w), 3))
        else:
            start = np.array([self.sims[a].positions[b] for a, b in zip(w, i)]).reshape(-1, 3)
        moving = [r for r in range(len(w)) if not np.array_equal(start[r], end[r])]
        for s in range(1, steps + 1):
            for r in moving:
                p = start[r] + (end[r] - start[r]) * (s / steps)
                self.sims[w[r]].set_gripper_pose(f"hold:{i[r]}", p)
            self.step()

    def held(self, world: int) -> np.ndarray:
        """The vertices of ``world`` the solve does not move (the model's pins, what is held)."""
        sim = self.sims[int(self._ids([world])[0])]
        return np.flatnonzero(sim.model.pinned)

    def reset(self, worlds=None) -> None:
        for w in self._ids(worlds):
            self.sims[w].reset()
            self._set[w] = self.sims[w].positions

    def nearest_free(self, worlds, points) -> tuple[np.ndarray, np.ndarray]:
        """For each row ``r``, the particle of world ``worlds[r]`` nearest to ``points[r]`` among
        those not pinned (nor held): ``(indices, positions)``, ``−1`` (and 0) where none is (the
        first of the nearest, as ``np.argmin`` takes it)."""
        w = self._ids(np.asarray(worlds, np.int64).ravel())
        p = np.asarray(points, np.float64).reshape(len(w), 3)
        idx = np.full(len(w), -1, np.int64)
        at = np.zeros((len(w), 3))
        for r, world in enumerate(w):
            sim = self.sims[world]
            idx[r] = Grips.nearest(sim.positions, sim.model.pinned, p[r])[0]
            if idx[r] >= 0:
                at[r] = sim.positions[idx[r]]
        return idx, at

    def gather(self, indices, extra=None) -> np.ndarray:
        """``(worlds, 3 (k + e))`` float32: each world's vertices ``indices``, then its ``extra``
        points (``(worlds, e, 3)``, or none), each point's ``x, y, z`` in turn (on cuda the same
        on the device)."""
        x = self.positions_host()[:, np.asarray(indices, np.int64)].reshape(self.worlds, -1)
        if extra is None:
            return x.astype(np.float32)
        return np.concatenate([x, np.reshape(extra, (self.worlds, -1))], axis=1).astype(np.float32)

    def write(self, worlds, x=None, v=None) -> None:
        """Set whole worlds' positions and/or velocities (``(len(worlds), n, 3)``), as the
        simulator's ``positions`` and ``velocities`` setters do (checked there)."""
        ids = self._ids(worlds)
        for r, w in enumerate(ids):
            if x is not None:
                self.sims[w].positions = x[r]
                self._set[w] = self.sims[w].positions
            if v is not None:
                self.sims[w].velocities = v[r]

    def mean_distance(self, a, b, reference: bool = False) -> np.ndarray:
        """``(worlds,)``: each world's mean over ``k`` of ``|x[a[k]] − x[b[k]]|`` (with
        ``reference``, ``x[b[k]]`` where the world was last set: :meth:`write`, :meth:`reset`)
        (on cuda computed on the device)."""
        a, b = np.asarray(a, np.int64).ravel(), np.asarray(b, np.int64).ravel()
        if len(a) != len(b):
            raise ValueError(f"a and b: one vertex each a pair, got {len(a)} and {len(b)}")
        x = self.positions_host()
        y = self._set if reference else x
        return np.mean(np.linalg.norm(x[:, a] - y[:, b], axis=2), axis=1)

    def step(self, n: int = 1) -> None:
        for s in self.sims:
            s.step(n)

    def advance(self, t: float) -> int:
        n = max(0, math.ceil((t - float(self.time.min())) / self.dt - 1e-9))
        self.step(n)
        return n
