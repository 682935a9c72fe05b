"""N cloths of one topology stepped together on a CUDA device: each world its own state and its
own masses, pins, gravity, wind, drag and family stiffness and damping.

A step is a few launches whatever the number of worlds (every kernel takes every world's vertices
at once): symplectic Euler one launch a substep; ``vbd`` two to start a substep, one a colour an
iteration, one for Chebyshev's extrapolation, one for the residual at each measure (its ``W``
numbers come back to the host, the only copy a step makes) and one to end it. :attr:`launches`
counts them.

The same methods and defaults as the CPU (:mod:`cloth_sim.integrators.explicit`'s symplectic Euler
and :class:`~cloth_sim.integrators.vbd.VBD`'s general sweep: substeps chosen from the cloth, a
relative residual against ``tolerance`` measured every ``check_every`` iterations, Chebyshev's
``rho``), with colliders (planes, spheres, boxes, capsules, cylinders, and meshes read from a
distance grid baked at load: :mod:`cloth_sim.contact.distance_grid`) and Provot's strain limit
(:meth:`CudaWorlds.set_strain_limit`: the CPU's passes and long-range attachments, a pass taking
its springs a colour at a time); a collider moved over a step is swept by symplectic Euler's
contact stage (a robot's links: :meth:`CudaWorlds.place_colliders`), which can record each
vertex's impulse on each collider for their wrenches (:meth:`CudaWorlds.record_wrenches`). What
stays on the CPU for now: colliders swept under ``vbd``, self-contact, the strain limit's
projection and Choi & Ko's nonlinear pairs (:func:`cloth_sim.backends.refusal` names them).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import cuda

from .. import backends
from ..constraints.strain_limit import (
    DEFAULT_STRAIN_LIMIT_PASSES,
    attachments_from,
    geodesic_distances,
    nearest_attachments,
)
from ..contact.collider_kernels import MESH
from ..contact.distance_grid import grid_for, pack_grids
from ..contact.geometry import positive
from ..integrators.vbd import VBD
from ..integrators.vbd_kernels import substeps_needed
from ..model import ClothModel
from ..parameters import SCHEMA
from . import kernels as K
from . import simulated
from .layout import Iterate, Limits, Run, Topology, Worlds, limits, same_topology, topology

#: floating point on the device: float32 (the default: half the bytes a sweep moves) or float64
PRECISIONS = {"float32": np.float32, "float64": np.float64}
#: how a run of steps is launched: "blocks" (one launch, a thread block a world), "grid" (one
#: cooperative launch, the whole GPU on every world, synchronised between stages), "stages" (a
#: launch a stage: a colour's sweep, the residual, ...), "auto" (blocks for a world of at most
#: BLOCK_WORLD vertices, else grid)
LAUNCHES = ("auto", "blocks", "grid", "stages")
#: the largest world "auto" runs a block a world: 64×64 (its block's threads then take four
#: vertices each; a larger world alone would leave all but one multiprocessor idle)
BLOCK_WORLD = 4096
#: threads a block of the cooperative launch
GRID_THREADS = 256
#: vertices a thread takes in a block where the worlds fill the GPU's multiprocessors
VERTICES_PER_THREAD = 4
#: ``vbd``'s options here (the CPU's others concern contacts and the node's time budget)
VBD_OPTIONS = ("iterations", "tolerance", "check_every", "substeps", "rho", "scheme")


def _grid(total: int) -> tuple[int, int]:
    """A launch's blocks and threads for ``total`` threads (one a vertex of a world)."""
    threads = max(1, min(K.BLOCK, total))
    return (total + threads - 1) // threads, threads


#: the colliders' poses and where a step starts them (:class:`Worlds`)
_POSES = ("cpos", "crot", "cpos0", "crot0")


def collider_rows(colliders) -> tuple:
    """``(kinds, positions, rotations, geometry, friction)`` of the static colliders, as the CPU's
    packed colliders give them (:meth:`cloth_sim.contact.colliders.Contacts.packed`), so that the
    device asks the same signed distances of the same numbers (a mesh's geometry: the index of
    its distance grid, :func:`mesh_grids`); one empty row for none."""
    count = max(1, len(colliders))
    kinds = np.zeros(count, np.int32)
    pos, rot = np.zeros((count, 3)), np.zeros((count, 3, 3))
    geo, mu = np.zeros((count, 4)), np.zeros(count)
    meshes = 0
    for c, collider in enumerate(colliders):
        kinds[c] = collider.kind
        pos[c], rot[c] = collider.position, collider.rotation
        geo[c], mu[c] = np.reshape(collider.geometry, 4), collider.friction
        if collider.kind == MESH:
            geo[c] = (meshes, 0.0, 0.0, 0.0)
            meshes += 1
    return kinds, pos, rot, geo, mu


def _write_poses(new: dict, ids, rows, names) -> None:
    """``rows`` ``[(index, position, rotation)]`` written for worlds ``ids`` into the pose arrays
    ``new[name]`` of ``names`` (positions into ``cpos``/``cpos0``, rotations into
    ``crot``/``crot0``)."""
    for index, position, rotation in rows:
        for name in names:
            new[name][ids, index] = position if name.startswith("cpos") else rotation


def mesh_grids(colliders, thickness: float, real) -> tuple:
    """The mesh colliders' distance grids for a cloth keeping ``thickness`` from them, in their
    order (:func:`collider_rows` numbers them so), packed as the kernels read them (``gbox, gdim,
    gval``: :func:`cloth_sim.contact.distance_grid.pack_grids`)."""
    grids = [grid_for(c.mesh, thickness) for c in colliders if c.kind == MESH]
    return pack_grids(grids, real)


class CudaWorlds:
    """``models`` (one per world, one topology: :func:`~cloth_sim.cuda.layout.same_topology`)
    stepped by ``integrator`` (``cloth_sim.backends.METHODS["cuda"]``) at ``dt`` on the CUDA
    device.

    ``gravity``, ``wind`` (``None`` or a 3-vector, as :class:`cloth_sim.Simulator`'s) and ``drag``
    start the same in every world; :meth:`set` changes them per world. ``precision``: the device's
    floating point (:data:`PRECISIONS`)."""

    def __init__(
        self,
        models: list[ClothModel],
        integrator: str = "vbd",
        dt: float = 1 / 60,
        gravity=(0.0, 0.0, -9.81),
        wind=None,
        drag: float = 0.0,
        integrator_options: dict | None = None,
        precision: str = "float32",
        launch: str = "auto",
        block_threads: int | None = None,
        colliders=None,
        thickness: float = 0.005,
    ):
        if not models:
            raise ValueError("models: at least one world")
        same_topology(models)
        first = models[0]
        colliders = list(colliders or ())
        #: the static colliders, as built (their shapes say what a pose means: :meth:`set`)
        self.colliders = colliders
        refused = backends.refusal("cuda", integrator, first)
        if refused is not None:
            raise ValueError(refused[0])
        if precision not in PRECISIONS:
            raise ValueError(
                f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}"
            )
        if launch not in LAUNCHES:
            raise ValueError(f"launch must be one of {', '.join(LAUNCHES)}, got {launch!r}")
        if block_threads is not None and (
            isinstance(block_threads, bool) or block_threads not in [2**p for p in range(11)]
        ):
            raise ValueError(
                f"block_threads must be None (chosen) or a power of two in [1, {K.MAX_BLOCK}], "
                f"got {block_threads!r}"
            )
        options = dict(integrator_options or {})
        if integrator == "vbd":
            unknown = sorted(set(options) - set(VBD_OPTIONS))
            if unknown:
                raise ValueError(
                    f"vbd option(s) {', '.join(unknown)} not on the cuda device; it takes "
                    f"{', '.join(VBD_OPTIONS)}"
                )
            # the CPU method checks the options and chooses what they leave open (its iterations'
            # cap, the substeps "auto"): one set of rules on both devices
            self.settings = VBD(first, **options)
        elif options:
            raise ValueError(f"{integrator} takes no options, got {sorted(options)}")
        else:
            self.settings = None
        self.method = integrator
        self.options = options
        self.models = list(models)
        self.precision = precision
        real = PRECISIONS[precision]
        self.real = real
        worlds, n = len(models), first.n_particles
        self.worlds, self.n = worlds, n
        top, self._cptr = topology(first, real)
        self._top_host = top
        self.top = Topology(*(cuda.to_device(a) for a in top))
        self.families = first.family_names
        fams = len(first.family_names)
        g = np.array(SCHEMA["gravity"].check(gravity), dtype=np.float64)
        wind_v = np.zeros(3) if wind is None else np.asarray(wind, np.float64)
        if wind_v.shape != (3,) or not np.all(np.isfinite(wind_v)):
            raise ValueError(f"wind must be None or a finite 3-vector, got {wind!r}")
        ckind, cpos, crot, cgeo, cmu = collider_rows(colliders)
        thickness = positive("thickness", thickness)
        gbox, gdim, gval = mesh_grids(colliders, thickness, real)
        #: each world's model's own pins (what release leaves pinned)
        self._pinned = np.stack([np.asarray(m.pinned, bool) for m in models])
        self._host = Worlds(
            masses=np.stack([np.asarray(m.masses, real) for m in models]),
            free=(~self._pinned).astype(np.int8),
            gravity=np.tile(g.astype(real), (worlds, 1)),
            wind=np.tile(wind_v.astype(real), (worlds, 1)),
            windy=np.full(worlds, wind is not None and bool(np.any(wind_v)), np.int8),
            drag=np.full(worlds, SCHEMA["drag"].check(drag), real),
            kfam=np.full((worlds, fams), -1.0, real),
            cfam=np.full((worlds, fams), -1.0, real),
            ckind=np.tile(ckind, (worlds, 1)),
            cpos=np.tile(cpos.astype(real), (worlds, 1, 1)),
            crot=np.tile(crot.astype(real), (worlds, 1, 1, 1)),
            cpos0=np.tile(cpos.astype(real), (worlds, 1, 1)),
            crot0=np.tile(crot.astype(real), (worlds, 1, 1, 1)),
            cgeo=np.tile(cgeo.astype(real), (worlds, 1, 1)),
            cmu=np.tile(cmu.astype(real), (worlds, 1)),
            ncol=np.full(worlds, len(colliders), np.int32),
            tau=np.full(worlds, thickness, real),
            kc=np.full(
                worlds, self.settings.contact_stiffness if self.settings is not None else 0.0, real
            ),
            gbox=gbox,
            gdim=gdim,
            gval=gval,
            cimp=np.zeros((worlds, 0, max(1, len(colliders)), 6), real),
        )
        self.wor = Worlds(*(cuda.to_device(a) for a in self._host))
        x0 = np.stack([np.asarray(m.positions, real) for m in models])
        self._x0 = x0
        #: the positions each world was last set to (:meth:`write`, :meth:`reset`), on the host
        #: and the device: :meth:`mean_distance`'s reference
        self._set_host = x0.copy()
        self._set = cuda.to_device(x0)
        per_vertex = {"stepped": np.zeros((worlds, n), real)}
        per_world = ("past", "bdf")
        self.it = Iterate(
            *(
                cuda.to_device(
                    np.zeros(worlds, np.int8)
                    if name in per_world
                    else per_vertex.get(name, x0 if name == "x" else np.zeros_like(x0))
                )
                for name in Iterate._fields
            )
        )
        #: the substep BDF2's history was kept at (None: none yet)
        self._past_h = None
        self.launch = launch
        self.block_threads = block_threads
        self._out = cuda.device_array((worlds, 3), np.float64)
        self._cptr_device = cuda.to_device(self._cptr.astype(np.int32))
        #: the recorded impulses copied to the host since the last step (:meth:`collider_wrench`)
        self._impulses = None
        self._partial = cuda.device_array((1, 2), np.float64)
        #: each world's steps that ended above the tolerance, and the sweeps of every step
        #: (each world's); ``last_iterations``: the sweeps of the last step (of the last run of
        #: steps in one launch: their mean, the most any world took)
        self.unconverged_steps = np.zeros(worlds, np.int64)
        self.iterations = np.zeros(worlds, np.int64)
        self.dt = SCHEMA["dt"].check(dt)
        self.steps = np.zeros(worlds, np.int64)
        self.launches = 0
        self.last_launches = 0
        self.last_residual = np.zeros(worlds)
        self.last_iterations = 0
        self.last_substeps = 1
        self._residual = cuda.device_array(worlds, np.float64)
        self._substeps_key = None
        self._substeps = 1
        #: Provot's strain limit τ after each step or vbd substep (None: none), its passes at
        #: most and whether long-range attachments to the pins come first
        #: (:meth:`set_strain_limit`)
        self.strain_limit = None
        self.strain_limit_passes = DEFAULT_STRAIN_LIMIT_PASSES
        self.strain_limit_long_range = True
        self._lim_host = None
        self.lim = Limits(
            *(
                cuda.to_device(a)
                for a in Limits(
                    ends=np.zeros((1, 2), np.int32),
                    rest=np.zeros(1, real),
                    sptr=np.zeros(1, np.int32),
                    anchor=np.full((1, 1, 2), -1, np.int32),
                    reach=np.zeros((1, 1, 2), real),
                    flags=np.zeros((1, 3), np.int32),
                    gained=np.zeros((1, 1, 3), real),
                )
            )
        )
        self._attached = None  # the pins the attachments were made for (worlds, n), or None
        self._geodesic = None  # every particle's rest geodesic distances (n, n), or None

    # ------------------------------------------------------------------ the strain limit
    def set_strain_limit(self, tau, passes=None, long_range=None) -> None:
        """Provot's strain limit ``tau`` (``None``: none) in every world after every symplectic
        Euler step, or every ``vbd`` substep (from the substep's start, which is then backward
        Euler's, as the CPU's ``VBD`` applies it), in at most ``passes`` passes (unchanged when
        None), after long-range attachments to each world's pins and held vertices where
        ``long_range`` (as the CPU's :class:`~cloth_sim.constraints.strain_limit.StrainLimit`
        with ``method="provot"``). Checked first."""
        if tau is not None:
            tau = SCHEMA["strain_limit"].check(tau)
        if passes is not None:
            passes = SCHEMA["strain_limit_passes"].check(passes)
        if tau is not None and self._lim_host is None:
            self._lim_host = limits(self.models[0], self.worlds, self.real)
            self.lim = Limits(*(cuda.to_device(a) for a in self._lim_host))
            self._attached = None
        self.strain_limit = tau
        if passes is not None:
            self.strain_limit_passes = passes
        if long_range is not None and bool(long_range) != self.strain_limit_long_range:
            self.strain_limit_long_range = bool(long_range)
            self._attached = None

    _limit_now = False  # (whether the step being taken is limited)

    def _limited(self) -> bool:
        """Whether the strain limit runs after this step; its attachments made for the pins now
        where they are not."""
        if self.strain_limit is None:
            return False
        pins = self._host.free == 0
        if self._attached is None:
            changed = np.arange(self.worlds)
        else:
            changed = np.flatnonzero(np.any(pins != self._attached, axis=1))
            if not len(changed):
                return True
        h = self._lim_host
        if not self.strain_limit_long_range or self.models[0].n_springs == 0:
            h.anchor[changed], h.reach[changed] = -1, 0.0
        elif self.n > self.GEODESIC_ALL_MAX:
            for w in changed:
                h.anchor[w], h.reach[w] = nearest_attachments(self.models[w], 2, pins[w])
        else:
            if self._geodesic is None:  # (every world's springs and rest lengths: one topology)
                self._geodesic = geodesic_distances(self.models[0])
            count = pins[changed].sum(axis=1)
            for k in np.unique(count):  # the worlds with k pins at once
                ws = changed[count == k]
                rows, cols = np.nonzero(pins[ws])
                pin = cols.reshape(len(ws), k)
                h.anchor[ws], h.reach[ws] = attachments_from(self._geodesic[pin], pin, pins[ws])
        self.lim.anchor.copy_to_device(h.anchor)
        self.lim.reach.copy_to_device(h.reach)
        self._attached = pins
        return True

    def before_limit(self, world: int):
        """``(x, v)`` of ``world`` at the end of the last step before the strain limit's last
        correction (what the CPU's ``vbd`` leaves to its stages: its last substep solved; the
        velocity ``(x − x^t)/h`` of a free vertex), or None where the last step was not a
        limited ``vbd`` step."""
        if not (self._limit_now and self.method == "vbd" and self.steps.any()):
            return None
        w = int(self._ids([world])[0])
        x = self.it.xs[w].copy_to_host().astype(np.float64)
        v = self.it.v[w].copy_to_host().astype(np.float64)
        free = self._host.free[w] != 0
        start = self.it.xt[w].copy_to_host().astype(np.float64)
        v[free] = (x[free] - start[free]) / (self.dt / self.last_substeps)
        return x, v

    def limit_reaction(self, world: int) -> np.ndarray:
        """``(n, 3)``: the force (N) the strain limit's corrections over the last step put on
        each pin of ``world`` (the CPU's ``StrainLimit.reaction``: each free vertex's ``−m Σ
        Δx/h / dt`` on its nearest pin by rest geodesic distance); zero without a limit."""
        w = int(self._ids([world])[0])
        out = np.zeros((self.n, 3))
        if self.strain_limit is None or self._lim_host is None:
            return out
        if self.strain_limit_long_range and self._attached is not None:
            near = self._lim_host.anchor[w, :, 0].astype(np.int64)
        else:
            near = nearest_attachments(self.models[w], 1, self._host.free[w] == 0)[0][:, 0]
        gained = self.lim.gained[w].copy_to_host().astype(np.float64)
        ok = near >= 0
        m = self._host.masses[w].astype(np.float64)
        np.add.at(out, near[ok], -(m[ok, None] * gained[ok]) / self.dt)
        return out

    #: up to this many particles the rest geodesic distances between every two are kept (8 bytes
    #: each: 32 MB at the most), so that new pins' attachments (a grasp) are a lookup for every
    #: world at once (:func:`~cloth_sim.constraints.strain_limit.attachments_from`: the CPU's
    #: numbers), not a search a world
    GEODESIC_ALL_MAX = 2048

    # ------------------------------------------------------------------ per world
    def _ids(self, worlds) -> np.ndarray:
        return backends.world_ids(worlds, self.worlds)

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
        """Per-world parameters for ``worlds`` (indices; ``None``: all): ``gravity`` and ``wind``
        (a 3-vector, or one a world), ``drag``, ``stiffness`` / ``damping`` as ``{family:
        value}`` (N/m, N·s/m; every spring of the family), and ``colliders`` as ``{index:
        (position, orientation)}``: collider ``index`` there in those worlds now, at rest (the
        CPU's ``set_collider_pose(..., teleport=True)``; a pose means what it means for the shape,
        :mod:`cloth_sim.contact.colliders`). Everything is checked before anything changes."""
        ids = self._ids(worlds)
        h = self._host
        changed = ("gravity", "wind", "windy", "drag", "kfam", "cfam") + _POSES
        new = {name: getattr(h, name).copy() for name in changed}

        if gravity is not None:
            new["gravity"][ids] = backends.world_vectors("gravity", gravity, len(ids))
        if wind is not None:
            a = backends.world_vectors("wind", wind, len(ids))
            new["wind"][ids] = a
            new["windy"][ids] = np.any(a != 0.0, axis=1)
        if drag is not None:
            new["drag"][ids] = SCHEMA["drag"].check(float(drag))
        for name, table, given in (("stiffness", "kfam", stiffness), ("damping", "cfam", damping)):
            for fam, value in (given or {}).items():
                if fam not in self.families:
                    raise ValueError(
                        f"{name}: unknown family {fam!r}; this cloth has "
                        f"{', '.join(self.families)}"
                    )
                v = float(value)
                if not (math.isfinite(v) and v >= 0.0):
                    raise ValueError(
                        f"{name}[{fam!r}] must be a finite number >= 0, got {value!r}"
                    )
                new[table][ids, self.families.index(fam)] = v
        placed = []
        for index, pose in (colliders or {}).items():
            shape = backends.placed_collider(self.colliders, index, pose)
            placed.append((index, shape.position, shape.rotation))
        _write_poses(new, ids, placed, _POSES)
        self._host = h._replace(**new)
        for name in changed:
            getattr(self.wor, name).copy_to_device(getattr(self._host, name))

    def place_colliders(self, worlds, rows, teleport: bool) -> None:
        """Colliders of ``worlds`` placed where the caller has checked them (a robot's links, a
        pose ``set_collider_pose`` checked): ``rows`` ``[(index, position, rotation matrix)]``,
        swept there over the next step (the contact stage sees each sweep there from where the
        step starts it, the CPU's ``set_collider_pose`` without ``teleport``, until
        :meth:`settle_colliders`), or with ``teleport`` there now, at rest. One copy to the
        device for all of them."""
        ids = self._ids(worlds)
        names = _POSES if teleport else ("cpos", "crot")
        new = {name: getattr(self._host, name).copy() for name in names}
        _write_poses(new, ids, rows, names)
        self._host = self._host._replace(**new)
        for name in names:
            getattr(self.wor, name).copy_to_device(getattr(self._host, name))

    def settle_colliders(self) -> None:
        """Every collider's step starts where it stands now (after a step that swept it)."""
        self._host = self._host._replace(
            cpos0=self._host.cpos.copy(), crot0=self._host.crot.copy()
        )
        for name in ("cpos0", "crot0"):
            getattr(self.wor, name).copy_to_device(getattr(self._host, name))

    def reset(self, worlds=None) -> None:
        """Back to the models' initial positions, at rest, at time 0, for ``worlds`` (``None``:
        all); their parameters are kept."""
        ids = self._ids(worlds)
        if not len(ids):
            return
        idx = np.arange(self.n, dtype=np.int32)
        self._place(ids, idx, self._x0[ids])
        self.forget(ids)
        self.steps[ids] = 0
        self._set_host[ids] = self._x0[ids]
        self._set.copy_to_device(self._set_host)

    def forget(self, worlds=None) -> None:
        """BDF2's history of ``worlds`` (``None``: all) no longer serves: their state was set, so
        their next substep is backward Euler's (as the CPU's ``VBD.reset``)."""
        ids = self._ids(worlds)
        past = self.it.past.copy_to_host()
        past[ids] = 0
        self.it.past.copy_to_device(past)

    def _place(self, ids, idx, points, velocities=None) -> None:
        """``idx`` of worlds ``ids`` at ``points`` (``(len(ids), len(idx), 3)``), moving at
        ``velocities`` (the same shape), or at rest where None (:func:`kernels.place`)."""
        moving = velocities is not None
        v = np.ascontiguousarray(velocities if moving else np.zeros((1, 1, 3)), self.real)
        K.place[_grid(len(ids) * len(idx))](
            self.it,
            cuda.to_device(np.asarray(idx, np.int32)),
            cuda.to_device(np.ascontiguousarray(points, self.real)),
            cuda.to_device(v),
            cuda.to_device(np.asarray(ids, np.int32)),
            moving,
        )
        self.launches += 1

    def place(self, worlds, indices, points) -> None:
        """Put vertices ``indices`` of ``worlds`` at ``points`` (``(worlds, p, 3)`` or ``(p, 3)``
        for all of them), at rest."""
        ids = self._ids(worlds)
        idx = self._vertices(indices)
        p = np.asarray(points, np.float64)
        if p.shape == (len(idx), 3):
            p = np.broadcast_to(p, (len(ids), len(idx), 3))
        if p.shape != (len(ids), len(idx), 3) or not np.all(np.isfinite(p)):
            raise ValueError(
                f"points must be finite, ({len(idx)}, 3) or ({len(ids)}, {len(idx)}, 3); "
                f"got {np.shape(points)}"
            )
        self._place(ids, idx, p)

    def carry(self, worlds, indices, points, velocities) -> None:
        """Put held vertices ``indices`` of ``worlds`` at ``points`` moving at ``velocities``
        (each ``(p, 3)``, the same for every world named): a gripper's step (the device moves
        them by ``h v`` a substep, as the CPU's methods move a kinematic vertex)."""
        ids = self._ids(worlds)
        idx = self._vertices(indices)
        shape = (len(ids), len(idx), 3)
        p = np.broadcast_to(np.asarray(points, np.float64), shape)
        v = np.broadcast_to(np.asarray(velocities, np.float64), shape)
        self._place(ids, idx, p, v)

    def restart(self, worlds=None) -> None:
        """The method starts again from the state of ``worlds`` (``None``: all), as the CPU's
        integrator made anew does when the pins change (a grasp, a release): BDF2's history and
        the last accelerations forgotten."""
        ids = self._ids(worlds)
        self.forget(ids)
        if len(ids):
            K.restart[_grid(len(ids) * self.n)](self.it, cuda.to_device(np.asarray(ids, np.int32)))
            self.launches += 1

    def hold(self, worlds, indices, points=None) -> None:
        """Hold vertices ``indices`` of ``worlds`` kinematically (a gripper's grasp, a pin added):
        they leave the solve and stay where :meth:`place` puts them (``points``, as there; their
        current positions when None), at rest."""
        ids = self._ids(worlds)
        idx = self._vertices(indices)
        if points is None:
            points = self.positions_host()[np.ix_(ids, idx)]
        self.place(ids, idx, points)
        free = self._host.free.copy()
        free[np.ix_(ids, idx)] = 0
        self._upload_free(free)

    def release(self, worlds, indices=None) -> None:
        """Let ``worlds``' held vertices ``indices`` (all of them when None) go: back into the
        solve, at rest, except the models' own pins, which stay pinned."""
        ids = self._ids(worlds)
        idx = np.arange(self.n) if indices is None else self._vertices(indices)
        free = self._host.free.copy()
        free[np.ix_(ids, idx)] = ~self._pinned[np.ix_(ids, idx)]
        self._upload_free(free)

    def _pairs(self, worlds, indices) -> tuple[np.ndarray, np.ndarray]:
        return backends.world_pairs(worlds, indices, self.worlds, self.n)

    def hold_pairs(self, worlds, indices) -> None:
        """Hold vertex ``indices[r]`` of world ``worlds[r]``, one a row, where it is, at rest
        (:meth:`carry_pairs` and :meth:`drag` move it): :meth:`hold` for vertices that differ
        from world to world, in one upload and one launch."""
        w, i = self._pairs(worlds, indices)
        free = self._host.free.copy()
        free[w, i] = 0
        self._upload_free(free)
        if len(w):
            K.stop_pairs[_grid(len(w))](
                self.it, cuda.to_device(w.astype(np.int32)), cuda.to_device(i.astype(np.int32))
            )
            self.launches += 1

    def release_pairs(self, worlds, indices) -> None:
        """Let vertex ``indices[r]`` of world ``worlds[r]`` go, one a row (a model's own pin stays
        pinned), with the velocity it has."""
        w, i = self._pairs(worlds, indices)
        free = self._host.free.copy()
        free[w, i] = ~self._pinned[w, i]
        self._upload_free(free)

    def carry_pairs(self, worlds, indices, points, velocities) -> None:
        """Held vertex ``indices[r]`` of world ``worlds[r]`` to ``points[r]``, moving at
        ``velocities[r]`` (one a row; the device moves a held vertex by ``h v`` a step)."""
        w, i = self._pairs(worlds, indices)
        p = np.ascontiguousarray(np.reshape(points, (len(w), 3)), self.real)
        v = np.ascontiguousarray(np.reshape(velocities, (len(w), 3)), self.real)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise ValueError("points and velocities must be finite")
        if len(w):
            K.place_pairs[_grid(len(w))](
                self.it,
                cuda.to_device(w.astype(np.int32)),
                cuda.to_device(i.astype(np.int32)),
                cuda.to_device(p),
                cuda.to_device(v),
            )
            self.launches += 1

    def drag(self, worlds, indices, ends, steps: int, starts=None) -> None:
        """``steps`` steps while held vertex ``indices[r]`` of world ``worlds[r]`` (one a row)
        moves in a straight line at constant speed from ``starts[r]`` (where it is when None) to
        ``ends[r]``, where the last step leaves it with that velocity (a gripper dragging it, as
        the CPU's :meth:`cloth_sim.batch.BatchSimulator.drag`): two launches and the steps'."""
        w, i = self._pairs(worlds, indices)
        end = np.reshape(np.asarray(ends, np.float64), (len(w), 3))
        if starts is not None:
            start = np.reshape(np.asarray(starts, np.float64), (len(w), 3))
        else:
            start = self.positions_host()[w, i] if len(w) else end
        v = (end - start) / (steps * self.dt)
        self._settle_dragged()
        self.carry_pairs(w, i, start, v)
        self.step(steps)
        self.carry_pairs(w, i, end, v)
        self._dragged = (w, i)

    _dragged = None  # the rows the last drag left moving: (worlds, indices), or None

    def _settle_dragged(self) -> None:
        """The vertices the last :meth:`drag` left moving and still held stop where they are (a
        gripper that moved over the last step and stays): their velocity, kept until now for a
        release, would move them on."""
        if self._dragged is None:
            return
        w, i = self._dragged
        self._dragged = None
        still = self._host.free[w, i] == 0
        if np.any(still):
            K.stop_pairs[_grid(int(still.sum()))](
                self.it,
                cuda.to_device(w[still].astype(np.int32)),
                cuda.to_device(i[still].astype(np.int32)),
            )
            self.launches += 1

    def held(self, world: int) -> np.ndarray:
        """The vertices of ``world`` that do not move by the solve (the model's pins and what
        :meth:`hold` holds)."""
        w = int(self._ids([world])[0])
        return np.flatnonzero(self._host.free[w] == 0)

    def _vertices(self, indices) -> np.ndarray:
        """``indices`` as an int64 array, each a vertex of the cloth."""
        idx = np.asarray(indices, np.int64).ravel()
        if idx.size and (idx.min() < 0 or idx.max() >= self.n):
            raise ValueError(f"indices must lie in [0, {self.n - 1}]")
        return idx

    def _upload_free(self, free: np.ndarray) -> None:
        self._host = self._host._replace(free=free.astype(np.int8))
        self.wor.free.copy_to_device(self._host.free)
        if self.records_wrenches:  # a vertex held now gave no impulse over the last step
            self.wor.cimp.copy_to_device(np.zeros(self.wor.cimp.shape, self.real))
            self._impulses = None

    # ------------------------------------------------------------------ colliders' wrenches
    @property
    def records_wrenches(self) -> bool:
        """Whether the contact stage records each vertex's impulse on each collider
        (:meth:`record_wrenches`)."""
        return self.wor.cimp.shape[1] == self.n

    def record_wrenches(self) -> None:
        """From the next step on, the contact stage records each vertex's impulse on each collider
        (``(worlds, n, colliders, 6)`` numbers on the device), so that :meth:`collider_wrench`
        can give the colliders' wrenches."""
        if not self.records_wrenches:
            cimp = np.zeros((self.worlds, self.n, self._host.cimp.shape[2], 6), self.real)
            self._host = self._host._replace(cimp=cimp[:, :0])
            self.wor = self.wor._replace(cimp=cuda.to_device(cimp))

    def collider_wrench(self, w: int, c: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(force, torque)`` the cloth of world ``w`` exerted on collider ``c`` over its last
        contact stage of ``dt`` (N, N·m; torque about the collider's position): the impulses
        the stage recorded, summed in the vertices' order, over ``dt`` (the CPU's
        :meth:`~cloth_sim.contact.colliders.Contacts.wrench`); zeros where nothing is recorded."""
        if not self.records_wrenches or c >= self.wor.cimp.shape[2]:
            return np.zeros(3), np.zeros(3)
        if self._impulses is None:  # one copy a step, however many colliders are asked
            self._impulses = self.wor.cimp.copy_to_host()
        imp = self._impulses[w, :, c].astype(np.float64).sum(axis=0)
        return imp[:3] / dt, imp[3:] / dt

    # ------------------------------------------------------------------ state
    @property
    def positions(self):
        """``(worlds, n, 3)`` positions on the device (``__cuda_array_interface__``: torch and
        CuPy read them without a copy)."""
        return self.it.x

    def positions_host(self) -> np.ndarray:
        return self.it.x.copy_to_host().astype(np.float64)

    def velocities_host(self) -> np.ndarray:
        return self.it.v.copy_to_host().astype(np.float64)

    def write(self, worlds, x=None, v=None) -> None:
        """Set whole worlds' positions and/or velocities (``(len(worlds), n, 3)``) from the
        host."""
        ids = self._ids(worlds)
        for name, value in (("x", x), ("v", v)):
            if value is None:
                continue
            a = np.asarray(value, np.float64).reshape(len(ids), self.n, 3)
            host = getattr(self.it, name).copy_to_host()
            host[ids] = a
            getattr(self.it, name).copy_to_device(host.astype(self.real))
            if name == "x":
                self._set_host[ids] = a
                self._set.copy_to_device(self._set_host)
        self.forget(ids)

    def mean_distance(self, a, b, reference: bool = False) -> np.ndarray:
        """``(worlds,)``: each world's mean over ``k`` of ``|x[a[k]] − x[b[k]]|`` (with
        ``reference``, ``x[b[k]]`` where the world was last set: :meth:`write`, :meth:`reset`),
        on the device, only the means copied back (a task's metric: ClothFold's pairs and
        drift)."""
        a = self._vertices(a).astype(np.int32)
        b = self._vertices(b).astype(np.int32)
        if len(a) != len(b):
            raise ValueError(f"a and b: one vertex each a pair, got {len(a)} and {len(b)}")
        out = cuda.device_array(self.worlds, np.float64)
        K.mean_pair_distance[self.worlds, K.REDUCE](
            self.it.x,
            cuda.to_device(a),
            self._set if reference else self.it.x,
            cuda.to_device(b),
            out,
        )
        self.launches += 1
        return out.copy_to_host()

    def nearest_free(self, worlds, points) -> tuple[np.ndarray, np.ndarray]:
        """For each row ``r``, the vertex of world ``worlds[r]`` nearest to ``points[r]`` among
        those the solve moves (not pinned, not held): ``(indices, positions)``, ``−1`` (and 0)
        where none is (a launch, a block a row; only the rows come back)."""
        w = self._ids(np.asarray(worlds, np.int64).ravel())
        p = np.asarray(points, np.float64).reshape(len(w), 3)
        if not len(w):
            return np.zeros(0, np.int64), np.zeros((0, 3))
        out_i = cuda.device_array(len(w), np.int32)
        out_x = cuda.device_array((len(w), 3), self.real)
        K.nearest_free[len(w), K.REDUCE](
            self.it,
            self.wor,
            cuda.to_device(w.astype(np.int32)),
            cuda.to_device(np.ascontiguousarray(p, self.real)),
            out_i,
            out_x,
        )
        self.launches += 1
        return out_i.copy_to_host().astype(np.int64), out_x.copy_to_host().astype(np.float64)

    def gather(self, indices, extra=None):
        """``(worlds, 3 (k + e))`` float32 on the device: each world's vertices ``indices`` (``k``
        of them), then its ``extra`` points (``(worlds, e, 3)`` from the host, or none), each
        point's ``x, y, z`` in turn (an observation torch or CuPy read without a copy)."""
        idx = self._vertices(indices).astype(np.int32)
        more = np.zeros((self.worlds, 0, 3)) if extra is None else np.asarray(extra, np.float64)
        if more.ndim != 3 or more.shape[0] != self.worlds or more.shape[2] != 3:
            raise ValueError(f"extra: expected ({self.worlds}, e, 3) points, got {more.shape}")
        out = cuda.device_array((self.worlds, 3 * (len(idx) + more.shape[1])), np.float32)
        if not more.shape[1]:  # (a point that is never read: no zero-sized array to copy)
            more = np.zeros((self.worlds, 1, 3))
        K.gather_points[_grid(out.size)](
            self.it,
            cuda.to_device(idx),
            cuda.to_device(np.ascontiguousarray(more, self.real)),
            out,
        )
        self.launches += 1
        return out

    def times(self) -> np.ndarray:
        return self.steps * self.dt

    # ------------------------------------------------------------------ stepping
    def substeps(self) -> int:
        """``vbd``'s substeps a step (every world takes the most any world needs)."""
        s = self.settings
        if s is None or s.substeps is not None:
            return 1 if s is None else s.substeps
        h = self._host
        key = (self.dt, h.kfam.tobytes(), h.cfam.tobytes(), h.masses.tobytes(), h.free.tobytes())
        if key != self._substeps_key:
            top = self._top_host
            worst = 1
            for w in range(self.worlds):
                k = np.where(h.kfam[w, top.fam] >= 0, h.kfam[w, top.fam], top.k)
                c = np.where(h.cfam[w, top.fam] >= 0, h.cfam[w, top.fam], top.c)
                bdiag = top.bdiag if self.models[0].bending is not None else np.zeros(0)
                worst = max(
                    worst,
                    substeps_needed(
                        top.inc_ptr,
                        k.astype(np.float64),
                        c.astype(np.float64),
                        bdiag,
                        h.masses[w].astype(np.float64),
                        h.free[w].astype(bool),
                        self.dt,
                    ),
                )
            self._substeps_key, self._substeps = key, worst
        return self._substeps

    def launch_mode(self) -> str:
        """How a run of steps is launched (:data:`LAUNCHES`): ``"auto"`` is ``"blocks"`` for a
        world of at most :data:`BLOCK_WORLD` vertices, else ``"grid"``."""
        if self.launch != "auto":
            return self.launch
        return "blocks" if self.n <= BLOCK_WORLD else "grid"

    def threads(self) -> int:
        """The threads of a world's block in :func:`frames_in_blocks`: ``block_threads``, or
        the power of two that gives each thread about :data:`VERTICES_PER_THREAD` vertices (one
        where the worlds are fewer than a GPU's multiprocessors), at most 1024."""
        if self.block_threads is not None:
            return self.block_threads
        per = 1 if self.worlds < 132 else VERTICES_PER_THREAD
        want = max(1, -(-self.n // per))
        least = 1 if simulated() else 32  # (the simulator runs a Python thread a thread)
        return int(min(K.MAX_BLOCK, max(least, 1 << (want - 1).bit_length())))

    def step(self, n: int = 1) -> None:
        """``n`` steps of :attr:`dt` in every world."""
        n = int(n)
        if n <= 0:
            return
        before = self.launches
        self._impulses = None  # (the stage records them again)
        self._settle_dragged()
        mode = self.launch_mode()
        self._limit_now = self._limited()
        if mode in ("blocks", "grid"):
            self._run_whole(n, mode)
        else:
            for _ in range(n):
                if self.method == "vbd":
                    self._vbd_step()
                else:
                    self._explicit_step()
        self.steps += n
        self.last_launches = (self.launches - before) / n

    def _substep_length(self, parts: int) -> float:
        """``dt / parts``; a new length starts BDF2 again (its history was kept at the old)."""
        h = self.dt / parts
        if h != self._past_h:
            self.forget()
            self._past_h = h
        return h

    def _bdf2(self) -> int:
        """Whether ``vbd``'s substeps are BDF2's: its scheme, but backward Euler's under the
        strain limit (as on the CPU: the limit's velocity follows ``Δx/h``, backward Euler's
        relation)."""
        return int(
            self.settings is not None
            and self.settings.scheme == "bdf2"
            and self.strain_limit is None
        )

    def _run_whole(self, n: int, mode: str) -> None:
        s = self.settings
        vbd = self.method == "vbd"
        parts = self.substeps()
        h = self._substep_length(parts) if vbd else self.dt
        run = Run(
            h=self.real(h),
            hb=self.real(2.0 * h / 3.0),
            bdf2=self._bdf2(),
            steps=n,
            substeps=parts,
            method=1 if vbd else 0,
            iterations=s.iterations if vbd else 0,
            tolerance=s.tolerance if vbd else 0.0,
            check_every=s.check_every if vbd else 1,
            rho=s.rho if vbd else 0.0,
            limit=self.strain_limit if self._limit_now else -1.0,
            passes=self.strain_limit_passes,
        )
        if mode == "blocks":
            K.frames_in_blocks[self.worlds, self.threads()](
                self.top, self.wor, self.it, self._cptr_device, self.lim, run, self._out
            )
        else:
            blocks, threads = self._grid_shape(run)
            if self._limit_now:
                self.lim.flags.copy_to_device(np.zeros((self.worlds, 3), np.int32))
            K.frames_on_grid[blocks, threads](*self._grid_args(run))
        self.launches += 1
        self.last_substeps = parts
        if vbd:
            out = self._out.copy_to_host()
            self.last_residual = out[:, 0]
            self.iterations += out[:, 1].astype(np.int64)
            self.last_iterations = int(out[:, 1].max()) // n
            self.unconverged_steps += out[:, 2].astype(np.int64)

    def _grid_args(self, run) -> tuple:
        """:func:`kernels.frames_on_grid`'s arguments for ``run``."""
        return (
            self.top,
            self.wor,
            self.it,
            self._cptr_device,
            self.lim,
            run,
            self._out,
            self._partial,
        )

    def _grid_shape(self, run) -> tuple[int, int]:
        """The cooperative launch's blocks (as many as the GPU holds at once, at most one a
        :data:`GRID_THREADS` vertices) and threads a block; its scratch for the residual."""
        threads = 1 if simulated() else GRID_THREADS
        total = self.worlds * self.n
        blocks = max(1, -(-total // threads))
        if simulated():
            blocks = 1  # (the simulator's cooperative grids have one block)
        else:
            sig = tuple(numba.typeof(a) for a in self._grid_args(run))
            K.frames_on_grid.compile(sig)
            blocks = min(
                blocks, K.frames_on_grid.overloads[sig].max_cooperative_grid_blocks(threads)
            )
        if self._partial is None or self._partial.shape[0] < blocks:
            self._partial = cuda.device_array((blocks, 2), np.float64)
        return blocks, threads

    def _explicit_step(self) -> None:
        total = self.worlds * self.n
        launch = _grid(total)
        h = self.real(self.dt)
        limited = self._limit_now
        K.explicit_substep[launch](self.top, self.wor, self.it, h, True, not limited)
        self.launches += 1
        if limited:
            self._limit_stages(h, True)
        K.copy_back[launch](self.it)
        self.launches += 1
        self.last_substeps = 1

    def _limit_stages(self, h, first: bool) -> None:
        """The strain limit after :func:`kernels.explicit_substep`, a launch a stage: the start,
        a colour of a pass at a time (each pass's flag read back: the passes stop after one that
        shortens nothing), the attachments after a pass, the velocities and colliders."""
        launch = _grid(self.worlds * self.n)
        tau = self.real(self.strain_limit)
        lim = self.lim
        explicit = self.method != "vbd"
        K.limit_begin[launch](lim, self.wor, self.it, tau, explicit)
        self.launches += 1
        sptr = self._lim_host.sptr
        flags = np.zeros((self.worlds, 3), np.int32)
        for p in range(self.strain_limit_passes):
            lim.flags.copy_to_device(flags)
            for c in range(len(sptr) - 1):
                count = int(sptr[c + 1] - sptr[c])
                K.limit_colour[_grid(self.worlds * count)](
                    lim, self.wor, self.it, tau, int(sptr[c]), count, p == 0, explicit
                )
            self.launches += len(sptr) - 1
            flags = lim.flags.copy_to_host()
            if not flags[:, 0].any():
                break
            K.limit_attach[launch](lim, self.wor, self.it, tau, explicit)
            self.launches += 1
            flags[:, 1] = flags[:, 0]  # (a world takes the next pass if this one shortened)
            flags[:, 0] = 0
        K.limit_end[launch](lim, self.wor, self.it, h, explicit, first)
        self.launches += 1

    def _vbd_step(self) -> None:
        s = self.settings
        parts = self.substeps()
        iterations, worst = 0, np.zeros(self.worlds)
        h = self._substep_length(parts)
        for part in range(parts):
            done, res = self._vbd_substep(h, part == 0)
            iterations += done
            worst = np.maximum(worst, res)
        self.last_iterations = iterations
        self.last_substeps = parts
        self.last_residual = worst
        self.iterations += iterations
        self.unconverged_steps += worst > s.tolerance

    def _measure(self) -> np.ndarray:
        K.vbd_residual[self.worlds, K.REDUCE](self.wor, self.it, self._residual)
        self.launches += 1
        return self._residual.copy_to_host()

    def _vbd_substep(self, dt: float, first: bool):
        s = self.settings
        top, wor, it = self.top, self.wor, self.it
        total = self.worlds * self.n
        launch = _grid(total)
        h, hb, bdf2 = self.real(dt), self.real(2.0 * dt / 3.0), self._bdf2()
        K.vbd_start[launch](wor, it, bdf2)
        K.vbd_guess[launch](top, wor, it, h, hb)
        self.launches += 2
        cptr = self._cptr
        res = np.full(self.worlds, np.inf)
        omega = 1.0
        done, measured = 0, -1
        for k in range(s.iterations):
            for c in range(len(cptr) - 1):
                count = int(cptr[c + 1] - cptr[c])
                K.vbd_colour[_grid(self.worlds * count)](top, wor, it, int(cptr[c]), count, h, hb)
            self.launches += len(cptr) - 1
            done += 1
            if done < s.iterations and done % s.check_every == 0:
                res, measured = self._measure(), done
            if k == s.iterations - 1 or np.all(res <= s.tolerance):
                break
            if s.rho > 0.0:
                rho2 = s.rho * s.rho
                omega = (
                    1.0
                    if k == 0
                    else (2.0 / (2.0 - rho2) if k == 1 else 4.0 / (4.0 - rho2 * omega))
                )
                K.vbd_accelerate[launch](wor, it, self.real(omega), k > 0)
                self.launches += 1
        if measured != done:  # the step's last sweep's
            res = self._measure()
        K.vbd_finish[launch](wor, it, h, hb, bdf2)
        self.launches += 1
        if self._limit_now:  # (after each substep, from its start: backward Euler's)
            self._limit_stages(h, first)
        return done, res
