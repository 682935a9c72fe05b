"""Vertex Block Descent: Chen, Macklin, Ju, Li, Kavan, Yuksel et al. (SIGGRAPH 2024), "Vertex Block
Descent" — the solver Newton made its default for cloth.

A step of ``h`` is backward Euler written as the minimum of the incremental potential

    G(x) = Σ_i m_i/(2h²) |x_i − y_i|² + E(x),      y = x^t + h v^t + h² a_ext,

``E`` the springs' energy (every family, Hooke or Choi–Ko's), their damping along the spring and
the air drag as dissipation potentials of ``(x − x^t)/h``, and the contacts' energies. Block
coordinate descent over the vertices: each vertex in turn takes one Newton step on ``G`` with the
others held,

    Δx_i = H_i⁻¹ f_i,   f_i = −∂G/∂x_i,   H_i = m_i/h² I + Σ_springs ∂²E/∂x_i² (+ contacts),

its 3×3 Hessian made positive semi-definite term by term (a compressed spring's ``E'/l`` part is
dropped, as the paper and Newton do). Vertices that share no spring never read each other's
positions in their step, so a **colour** of such vertices (greedy colouring of the spring graph) is
updated at once, in parallel. Each vertex writes only its own position and reads its partners'
in contact from the start of the iteration: the result is the same bits at any thread count.
Any iteration count gives a usable state: the iterate is a descent sequence from the initial guess
(the paper's adaptive one: inertia, with gravity's part of the last step's acceleration clamped to
``[0, |g|]``). **Chebyshev acceleration** (the paper's, with its spectral radius ``rho``) blends
each iterate with the one two iterations back; ``rho=0`` turns it off.

Wind acts explicitly (its force at the step's start, in ``y``): it depends on the normals. Pins and
held particles are kinematic: they go to ``x + h v`` and are not solved.

Contacts inside the solve (when the simulator lets the method handle them, :attr:`VBD.handles`):

* **Colliders**: ``½ k_c (τ − d)²`` for a vertex closer than the thickness ``τ`` to a collider
  surface (``d`` the signed distance), and Coulomb friction as IPC's smoothed, lagged friction on
  the vertex's motion relative to the collider's surface over the step (the normal force from the
  current iterate, the contact normal held), as the paper does. A vertex farther than
  :data:`~.vbd_kernels.FAR` times its expected motion from every collider's skin is held within
  that distance for the step and skips the colliders' terms
  (:func:`~.vbd_kernels.collider_allowances`).
* **Self-contact** between the cloth's own primitives, vertex–triangle and edge–edge, the same
  energy on their distance. Candidates come from the self-collision stage's tree
  (:mod:`cloth_sim.contact.collision_tree`) at the start of the step and every
  ``collision_interval`` iterations, each vertex reaching ``τ/2`` plus its allowance of motion
  (:data:`~.vbd_kernels.ALLOWANCE`: a tenth of ``τ`` and its motion to the step's initial guess).
  **Conservative bound** (the paper's): between two searches a vertex moves at most ``γ = 0.45`` of
  the smallest distance the search found between its primitives (itself, its triangles, its edges)
  and any other, and at most its allowance; so two primitives that were ``d`` apart stay ``(1 −
  2γ)·d > 0`` apart, those not found stay beyond ``τ``, and no vertex passes through the cloth or a
  collider (its allowance is also kept below the distance to the far side of the thinnest collider
  near it; one within a solid's skin, a closed mesh's, may reach the skin along the outward
  normal). Over a whole step the cloth never crosses itself.

The self-collision stage does not run after the method (:attr:`VBD.handles`); the contact stage
does, as an exact finish of what the iterations did (the distance and static friction to rounding),
and so does the strain limit where one is set.

**Convergence**: a step iterates until its relative residual (:mod:`.vbd_residual`: the force
imbalance of the step over the vertices' weight, RMS) is at most ``tolerance``, measured every
``check_every`` iterations, or until ``iterations``, the cap (docs/convergence.md).

Counters (:attr:`Simulator.integrator_stats`): ``steps``, ``iterations``, ``last_iterations``,
``last_residual`` (that relative residual, from the step's last sweep; the worst of its
substeps'), ``converged`` (whether it reached the tolerance), ``tolerance``,
``unconverged_steps``, ``last_substeps``, ``detections`` (candidate
searches), ``last_contacts`` (self-contact pairs and vertices touching a collider at the last
search), ``truncated`` (vertex updates the conservative bound shortened) and ``grid_steps`` (steps
whose iterations ran on the grid's blocks, below).

**On a grid** of Hooke springs on Provot's stencil (a grid scene's springs, a material's bending
stencils) without self-contact or tethers, the iterations run on the grid's own layout instead of
the vertices' spring lists (:mod:`cloth_sim.integrators.vbd_grid`): the nine classes ``(i mod 3, j
mod 3)`` as the colours, each stored as a block, so that a colour's vertices are updated in SIMD
lanes (4–8× the general sweep per vertex and iteration here, docs/BENCHMARKS.md §11); colliders
are taken in a second pass over each colour (their terms, onset and bounds as here). The same
Newton step per vertex, term for term, in another colour order: a converged step is the same to
rounding, an unconverged one differs as another order's would. ``grid=False`` keeps the general
sweep.
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from ..contact.collider_kernels import BOX, CAPSULE, CYLINDER, MESH, NO_COLLIDERS, SPHERE
from ..contact.colliders import packed_parts
from ..contact.collision_tree import touching
from ..kinds import LINEAR
from ..physics.force_kernels import BUCKLE_TABLE
from ..physics.forces import incidence
from .base import Integrator, Stability, VelocityOrigin
from .registry import register
from .vbd_contact import moving_within_reach, travel_within_reach
from .vbd_grid import GridLayout
from .vbd_kernels import (
    MAX_SUBSTEPS,
    NO_BENDING,
    allowances,
    bdf2_start,
    chebyshev,
    collider_allowances,
    colour_groups,
    contact_pairs,
    contact_records,
    initial_guess,
    iterate_parallel,
    iterate_serial,
    keep_kinematic,
    nearest_distances,
    overtaken,
    pack_records,
    step_velocities,
    substeps_needed,
    summed_at,
)
from .vbd_newton import NewtonSolve, applies, direct_is_cheaper
from .vbd_options import COLLIDER_SHARE, VBDOptions
from .vbd_residual import sweep_residual

#: the skin of the candidate pairs kept between searches, in thicknesses, where the cloth is
#: coarse enough for it (:meth:`~cloth_sim.contact.self_collision.SelfCollision.skin`): a search
#: then walks the tree only where more than a tenth of the vertices outran their skins, and
#: searches again the pairs of those that did (:mod:`cloth_sim.contact.pair_list`). On the
#: resting T-shirt 5-8 % of the vertices are searched again a step: 9.07 → 7.28 ms a step (a
#: quarter of a thickness: 8.5 ms, a third 7.2, in an earlier run where a half gave 7.4: a
#: thicker skin keeps a longer list to measure again)
SEARCH_SKIN = 0.5
#: the share of the nearest found distance a vertex may move between two candidate searches
GAMMA = 0.45
#: iterations between two candidate searches where a vertex met its bound (the option
#: ``collision_interval`` where it is not given), and while a collider moves within reach of the
#: cloth (:func:`~cloth_sim.integrators.vbd_contact.moving_within_reach`): a link pushing the
#: cloth drives the vertices in front of it into their bounds iteration after iteration, and
#: pressed layers each move only γ of their gap a search (the Panda and the UR5 swung through a
#: sheet at 5 iterations a step: vertices 13-32 mm inside a link searched every fifth iteration,
#: none every other, at 0.97-1.27 times the step's time; docs/robots.md). An arm moving far from
#: the cloth is a still collider to it (Newton's shirt settling while the FR3 moves above it)
COLLISION_INTERVAL, MOVING_COLLISION_INTERVAL = 5, 2
#: a search during the iterations (vertices met their bounds) is made again only for the
#: vertices that met them, where they are at most this share of the free vertices
#: (:meth:`VBD._detect_touching`): robot_sweep's link pushing the sheet cut a median of 6 of its
#: 1,024 vertices a search
LOCAL_SEARCH_SHARE = 0.03
#: a search serves the next step while at most this share of the free vertices would move more
#: than half their bound by their initial guess (those are held to their bound until the next
#: search)
REUSE_OVER = 0.02
#: ``self_contact_stiffness='cloth'``: the self-contact penalty's stiffness as this share of the
#: cloth's springs' stiffness summed at its median vertex (:meth:`VBD.self_contact_stiffness_for`).
#: On the T-shirt (gray-interlock, 1/60 s × 3; 247 N/m at 1), side by side with the default 1e4
#: N/m (~40): at 1 it rests on its table (a vertex's vertical range over 0.67 s at 8 s: 0.55 mm at
#: the 99th percentile, kinetic energy 1.9e-8 J) where at 1e4 N/m a few of its vertices still
#: heave (8.6 mm, 5.0e-6 J; 11.4 mm and 2.5e-5 J before the near pairs' stiffness,
#: ``vbd_terms.NEAR``), and a search serves about two steps; at 0.4 it rested too but the
#: scripted TshirtFlatten fell to 0.45 ± 0.20 of flat over six variations (0.64 ± 0.08 at 1; an
#: earlier day's code). Not the default: the scripted TshirtFold reaches 0.73 at 1 against 0.82
#: at 1e4 N/m over six variations (2026-12-03): the part of the shirt that should stay moves
#: more (docs/contacts.md, with what else was tried)
SELF_CONTACT_SHARE = 1.0
#: IPC's friction smoothing: relative tangential motion below EPS_V·h (m) is static
EPS_V = 1e-3
#: the iterations a step may take when none are given
MAX_ITERATIONS = 200
#: vertices per colour below which a colour is updated on one core (the pool's wake-up costs more)
PARALLEL_MIN_VERTICES = 512


@register
class VBD(Integrator):
    """Vertex Block Descent (Chen et al. 2024): backward Euler by per-vertex 3×3 Newton steps over
    colour groups, Chebyshev-accelerated, with collider contact and self-contact inside the
    iterations (module docstring).

    Options (:class:`.vbd_options.VBDOptions`, each checked there): ``iterations`` per step at
    most (default :data:`MAX_ITERATIONS`); ``tolerance`` (default 1e-2): the relative residual at
    which a step stops (0: every iteration runs); ``check_every`` (default 5): iterations between
    two measures;
    ``substeps`` ('auto' where neither it nor ``iterations`` is given, else 1): backward-Euler
    steps a step is cut into, 'auto' from the cloth's stiffness over its inertia
    (:meth:`substeps_for`); ``collider_share`` (default 'auto':
    :data:`~.vbd_options.COLLIDER_SHARE`, 2.5, where the cloth self-collides, else off; None: off):
    a step in which a collider within reach of the cloth travels farther than this many
    thicknesses is cut into as many more substeps,
    each seeing the colliders' motion in part
    (:meth:`~cloth_sim.contact.colliders.Contacts.travels`,
    :func:`~.vbd_contact.travel_within_reach`): a link overtaking the cloth faster than its bounds
    let it give way otherwise ends inside (robot_sweep, and a Franka Panda swung through a sheet
    at 1/60 s a step; docs/robots.md); ``rho`` (default
    0.8), the Chebyshev acceleration's spectral radius estimate, 0 for none (measured on the
    swinging 48×48 cloth: 0.8 is the best of 0.5, 0.8, 0.9 and 0.95 at 1/240 s, 15× closer to the
    converged step than none after 10 iterations; docs/BENCHMARKS.md); ``contact_stiffness`` (N/m,
    default 1e4); ``collision_interval`` (default None: 5, and 2 while a collider moves,
    :data:`COLLISION_INTERVAL`): iterations between candidate searches when the cloth
    self-collides and a vertex met its bound; ``self_friction`` (default 0.5): Coulomb's
    μ between the cloth's own layers; ``time_budget`` (s, default None): when set, iterate until
    that much wall time has passed (at least one iteration, at most ``iterations``) — a node that
    must keep its tick, whose results then depend on the machine; ``tethers`` (default False): with
    a strain limit on a pinned cloth and no contacts, its long-range attachments (Kim, Chentanez &
    Müller 2012) after every sweep, so the pins' pull reaches the far edge at once instead of a
    ring of springs an iteration (the 2 m, 41 kg hanging cloth at 64×64, 1/60 s × 10: worst strain
    4.7 → 2.2 after the projection; not enough to ship: docs/BENCHMARKS.md §11); ``grid`` (default
    True): on a grid of Hooke springs without self-contact, the iterations on the grid's blocks
    (module docstring); False keeps the general sweep; ``scheme`` (None: ``bdf2`` where
    ``iterations`` is not given, else ``euler``): the implicit step a substep solves, BDF2 or
    backward Euler (:meth:`_substep`). On cotton and denim hanging at 32×32 and 64×64, BDF2 keeps
    the free edge's path within 0.9–2.0 % of a fine-step reference's travel where backward Euler
    is 2.9–5.4 % off, in 0.67–1.07 times the sweeps (docs/convergence.md). A capped BDF2 step
    can gain energy (a 16×16 sheet at 1/30 s and 3 iterations a step: its kinetic energy 26 J
    above the fall's after 10 s), which backward Euler's descent cannot; converged, it did not.
    A substep with colliders, self-contact or a strain limit active is backward Euler.
    ``direct`` (None: chosen where ``iterations`` and ``substeps`` are not given): solve each
    step whole by Newton's method with the Hessian factorised
    (:mod:`~cloth_sim.integrators.vbd_newton`) instead of sweeps, where it applies (no colliders,
    self-contact or tethers; springs without damping); chosen where its cost model says it is
    cheaper: a small cloth whose vertices are light beside its springs (a cantilever strip of a
    real fabric rests in 3 s of wall time where its capped sweeps never brought polyester's to
    rest; docs/convergence.md).

    Second order (BDF2) where the substeps solve it, else first order (backward Euler); no step
    limit; any iteration count gives a usable state.
    """

    name = "vbd"
    takes_bending = True
    order = 1
    stability = Stability.UNCONDITIONAL
    implicit = True
    force_point = 1.0
    #: backward Euler's step conserves it; the iterations do to their residual (as the CG solve of
    #: implicit_euler does to its tolerance): 2.5e-13 of the momentum after 0.5 s at 200 iterations
    conserves_momentum = True
    counter_names = (
        "steps",
        "iterations",
        "last_iterations",
        "last_residual",
        "converged",
        "tolerance",
        "unconverged_steps",
        "last_substeps",
        "detections",
        "local_detections",
        "last_contacts",
        "truncated",
        "grid_steps",
        "direct_steps",
    )
    #: the post-step stages resolved inside the iterations. Self-contact, and with it every
    #: self-collision pass, is; the colliders' contacts are in the iterations too, and their stage
    #: still runs after the step, as an exact finish: a penalty leaves the cloth a little inside
    #: the thickness (its weight over the stiffness) and smoothed friction creeps by up to its
    #: smoothing distance a step, where the stage's projection and Coulomb velocity filter hold the
    #: distance and static friction to rounding (a few microseconds a step)
    handles = frozenset({"self_collision"})
    keeps_paths_off_colliders = True

    def __init__(self, model, **options):
        super().__init__(model)
        o = VBDOptions.of(options)
        iterations = o.iterations
        self.chosen_iterations = iterations is None
        # a capped step is no BDF2 step, and can gain energy
        self.scheme = o.scheme or ("bdf2" if self.chosen_iterations else "euler")
        #: BDF2's where the substeps solve it (the class's 1 is backward Euler's)
        self.order = 2 if self.scheme == "bdf2" else 1
        self.tolerance = float(o.tolerance)
        self.check_every = int(o.check_every)
        substeps = o.substeps
        if substeps is None:  # the work is chosen where neither is given
            substeps = "auto" if self.chosen_iterations else 1
        self.substeps = None if substeps == "auto" else int(substeps)
        share = o.collider_share
        #: None (off), "auto" (:data:`~.vbd_options.COLLIDER_SHARE` with self-contact) or a number
        self.collider_share = share if share in (None, "auto") else float(share)
        self._substeps_of, self._substeps_n, self._substeps_wanted = None, 1, 1
        self.self_friction = float(o.self_friction)
        self.tethers = o.tethers
        self.grid = o.grid
        self.direct = o.direct
        self._newton = None
        self._strain_limit = None
        self.iterations = int(MAX_ITERATIONS if iterations is None else iterations)
        self.rho = float(o.rho)
        self.contact_stiffness = float(o.contact_stiffness)
        #: None (``contact_stiffness``), 'cloth' or N/m (:meth:`self_contact_stiffness_for`)
        ks = o.self_contact_stiffness
        self.self_contact_stiffness = ks if ks in (None, "cloth") else float(ks)
        self._self_stiffness_of = None  # (forces, its self-contact stiffness)
        #: None: :data:`COLLISION_INTERVAL`, :data:`MOVING_COLLISION_INTERVAL` while a collider
        #: moves
        self.collision_interval = o.collision_interval
        self.time_budget = None if o.time_budget is None else float(o.time_budget)
        self.free = ~np.asarray(model.pinned, bool)
        self._layout_of = None
        self._colours_of = None
        self._grid = None
        self._grid_of = None
        self._contacts = None
        self._self_collision = None
        n = model.n_particles
        self.counters["tolerance"] = self.tolerance
        self.counters["converged"] = False
        self.counters["last_residual"] = 0.0
        self._a_prev = np.zeros((n, 3))
        # BDF2's history: the last substep's start and its length (None: none to use)
        self._past_x, self._past_v = np.zeros((n, 3)), np.zeros((n, 3))
        self._past_h = None
        self._stepped = np.zeros(n)
        self._cut = np.zeros(n, np.int8)
        self._touch = np.zeros(n, np.int8)  # in contact in the last iteration: not extrapolated
        self._no_touch = np.zeros(n, np.int8)
        self._seen = np.zeros((n, 1, 5))
        self._allow = np.full(n, np.inf)  # how far each vertex may move from the last search
        self._near = np.ones(n, np.bool_)  # may touch a collider before the next search
        self._candidates = False  # whether the last search's pairs serve self-contact
        self._cd_colliders = None
        self._cut_last = False
        tris = np.ascontiguousarray(model.triangles, dtype=np.int64).reshape(-1, 3)
        self._tris = tris
        self._no_rec = (
            np.zeros(n + 1, np.int64),
            *pack_records(
                np.zeros(0, np.int64),
                np.zeros((0, 4), np.int64),
                np.zeros((0, 4)),
                np.zeros((0, 3)),
                np.zeros(0, np.int64),
            ),  # fmt: skip
            np.zeros(n + 1, np.int64),
            np.zeros(0, np.int64),
            np.zeros((0, 4), np.int64),
            np.zeros((0, 4)),
            np.zeros((0, 3)),
            np.zeros(0),
            np.full(n, np.inf),
            np.zeros(0),
        )
        self._rec = self._no_rec
        self._found = None  # the last search's pairs and allowances (_detect_touching)
        self._solve_h = None  # the last solve's step (velocity_origin)
        self._no_colliders = NO_COLLIDERS

    # ------------------------------------------------------------------ protocol
    def attach(self, contacts, self_collision, strain_limit=None) -> None:
        self._contacts = contacts
        self._self_collision = self_collision
        self._strain_limit = strain_limit

    def reset(self, state, forces, dt):
        self._a_prev[:] = 0.0
        self._candidates = False  # the state was set: search again
        self._past_h = None  # and BDF2 starts again from one backward-Euler step

    def _layout(self, forces):
        """Per force pipeline: each vertex's springs (CSR of the other end and the spring's
        material, in the vertex's order, read contiguously) and the colour groups (per set of
        live springs)."""
        if self._layout_of is not forces:
            n = self.model.n_particles
            springs = forces.springs
            ptr, inc, _ = incidence(springs, n)
            ends = np.repeat(np.arange(n), np.diff(ptr))
            nbr = springs[inc, 0] + springs[inc, 1] - ends
            # a model with Choi–Ko pairs checks every vertex step against the energy (the line
            # search in sweep): one compressed pair makes its neighbours' steps overshoot too
            nonsmooth = bool(np.any(forces.kind != LINEAR))
            bending = forces.bending
            self._springs = (
                ptr,
                np.ascontiguousarray(nbr, dtype=np.int64),
                *(
                    np.ascontiguousarray(a[inc])
                    for a in (forces.rest, forces.k, forces.c, forces.kind)
                ),
                BUCKLE_TABLE,
                nonsmooth,
                *(NO_BENDING if bending is None else bending.rows()),
            )
            if bending is not None:  # a colour's vertices share no bending stencil either
                springs = np.concatenate([springs, bending.couplings()[0]])
            if self._colours_of is None or not np.array_equal(self._colours_of, springs):
                self._colours = colour_groups(springs, n, self.free)
                self._colours_of = springs
                cptr, verts = self._colours
                self._colour = np.full(n, -1, np.int64)
                self._colour[verts] = np.repeat(np.arange(len(cptr) - 1), np.diff(cptr))
            self._layout_of = forces
        return self._springs, self._colours

    def self_contact_stiffness_for(self, forces) -> float:
        """The self-contact penalty's stiffness (N/m) over ``forces``' springs: the option's number
        where one is given, ``contact_stiffness`` where it is None, and with ``'cloth'``
        :data:`SELF_CONTACT_SHARE` of the median free vertex's springs' stiffness summed (the
        cloth's own stiffness at a vertex; ``contact_stiffness`` where it has none). As stiff as
        the cloth around it, two layers in contact converge in the sweeps as the cloth does: a
        resting garment rests, where a penalty forty times stiffer than the T-shirt's knit makes
        some of its vertices heave (by millimetres) and the candidate search run every step.
        Under a stack of layers the penalty yields their weight over the stiffness: 26 µm under
        ten of the T-shirt's, 0.6 % of its thickness."""
        ks = self.self_contact_stiffness
        if ks is None:
            return self.contact_stiffness
        if ks != "cloth":
            return ks
        if self._self_stiffness_of is None or self._self_stiffness_of[0] is not forces:
            ptr, _, _, k = self._layout(forces)[0][:4]  # each vertex's springs (CSR)
            at = summed_at(ptr, k)
            at = at[self.free & (at > 0.0)]
            ks = SELF_CONTACT_SHARE * float(np.median(at)) if len(at) else self.contact_stiffness
            self._self_stiffness_of = (forces, ks)
        return self._self_stiffness_of[1]

    def iteration_traffic(self, forces) -> int:
        """The bytes one iteration without contacts must move at least (each array once): the
        sweep reads the positions, the step's start and inertial target, the copy of the iterate,
        the masses, the colours' vertex list and every vertex's springs (their pointers, far
        ends, rest lengths, stiffness, damping and kinds, and a material's bending rows), and
        writes the positions and each vertex's step; the iterate's copy and the Chebyshev
        extrapolation each read and write the positions once more. Caches and the neighbours'
        repeated reads are not counted: a lower bound (``cloth-sim bench vbd-floor``). The
        model's data, whichever sweep runs: the grid's blocks stream about as much (a slot's
        twelve springs' four numbers where the lists have five, and the ghost slots)."""
        sp, (cptr, verts) = self._layout(forces)
        vec = self.model.positions.nbytes  # n × 3 float64
        n = self.model.n_particles
        arrays = sum(a.nbytes for a in sp if isinstance(a, np.ndarray) and a is not BUCKLE_TABLE)
        read = 4 * vec + 8 * n + verts.nbytes + cptr.nbytes + arrays
        written = vec + 8 * n
        copy_and_extrapolate = 2 * vec + 3 * vec
        return int(read + written + copy_and_extrapolate)

    @property
    def colours(self) -> int:
        """How many colour groups the last step used."""
        return len(self._colours[0]) - 1 if self._layout_of is not None else 0

    # ------------------------------------------------------------------ the step
    def substeps_for(self, forces, dt) -> int:
        """The substeps a step of ``dt`` takes: the ``substeps`` option, or where it was not given
        the fewest for which every free vertex's stiffness-to-inertia ratio over a substep (``h²·Σk
        + h·Σc`` over its springs, plus its bending's ``h²·Q_ii``, over ``m``) is at most
        :data:`~.vbd_kernels.SUBSTEP_RATIO` (at most :data:`~.vbd_kernels.MAX_SUBSTEPS`): the
        sweeps a substep needs grow with that ratio (docs/convergence.md)."""
        if self.substeps is not None:
            return self.substeps
        self._chosen_substeps(forces, dt)
        return self._substeps_n

    def _chosen_substeps(self, forces, dt) -> None:
        """The substeps chosen for ``forces`` and ``dt``, and those the sweeps would need without
        :data:`MAX_SUBSTEPS` (kept until either changes)."""
        key = (forces, float(dt))
        if self._substeps_of != key:
            sp, _ = self._layout(forces)
            wanted = substeps_needed(
                sp[0], sp[3], sp[4], sp[11], self.model.masses, self.free, dt, cap=2**62
            )
            self._substeps_of, self._substeps_n = key, min(MAX_SUBSTEPS, wanted)
            self._substeps_wanted = wanted

    def step(self, state, forces, dt):
        """One step of ``dt`` in :meth:`substeps_for` substeps, each a backward-Euler step of its
        own (the colliders' motion over the step taken in as many parts); the counters add the
        substeps' iterations and keep their worst residual."""
        contacts = self._contacts
        packed = contacts.packed() if contacts is not None and contacts.active else None
        direct = self._direct_for(forces, packed, dt)
        # a direct solve needs no substeps for its convergence
        n = 1 if direct and self.substeps is None else self.substeps_for(forces, dt)
        share = self.collider_share
        if share == "auto":  # where self-contact's bounds hold the cloth back (COLLIDER_SHARE)
            sc = self._self_collision
            share = COLLIDER_SHARE if sc is not None and sc.active else None
        if packed is not None and share is not None:
            # a collider within reach of the cloth moves ≤ share·τ a substep (the vertices
            # reaching as far as their allowance of the inertial guess, x + dt·v, would let them)
            tau = contacts.thickness
            reach = allowances(state.x, state.x + dt * state.v, tau)
            travels = contacts.travels(packed)
            travel = travel_within_reach(state.x, self.free, packed, reach, tau, travels)
            n = max(n, min(MAX_SUBSTEPS, math.ceil(travel / (share * tau))))
        # a step's time budget is shared by its substeps
        budget = None if self.time_budget is None else self.time_budget / n
        iterations, worst, on_grid = 0, 0.0, False
        strain = self._strain_limit
        parts = [None] * n if packed is None else packed_parts(packed, n)
        for part, colliders in enumerate(parts):
            done, res, blocks = self._substep(state, forces, dt / n, colliders, budget, direct)
            if part < n - 1 and strain is not None and strain.active:
                # each substep's stretch corrected before the next (the last: the simulator's
                # stage, over velocity_origin): a velocity follows its own substep's correction
                origin = VelocityOrigin(self._xt, self._solve_h)  # this substep's solve
                strain.correct_within(state, origin, self.velocity_follow)
            iterations += done
            worst = max(worst, res)
            on_grid = on_grid or blocks
        c = self.counters
        c["steps"] += 1
        c["iterations"] += iterations
        c["last_iterations"] = iterations
        c["last_substeps"] = n
        c["grid_steps"] += 1 if on_grid else 0
        c["direct_steps"] += 1 if direct else 0
        c["last_residual"] = worst
        c["converged"] = bool(worst <= self.tolerance)
        c["unconverged_steps"] += 0 if worst <= self.tolerance else 1

    def velocity_origin(self, start_x, dt) -> VelocityOrigin | None:
        """The last substep's solve: its start (``x̂`` under BDF2) and step, over which
        :func:`step_velocities` measured the velocities (``v = (x − xᵗ)/h``)."""
        return None if self._solve_h is None else VelocityOrigin(self._xt, self._solve_h)

    def _direct_for(self, forces, packed, dt) -> bool:
        """Whether a step of ``dt`` is solved directly (:mod:`~cloth_sim.integrators.vbd_newton`):
        the ``direct`` option, or where it was not given and ``vbd`` chooses its work, where the
        direct solve costs less than the sweeps would
        (:func:`~cloth_sim.integrators.vbd_newton.direct_is_cheaper`: a small specimen of a real
        fabric, whose vertices' inertia is tiny beside its springs); in either case only a step
        without contacts (``packed``: the colliders, or None), self-contact or tethers, whose
        springs carry no damping."""
        if self.direct is False:
            return False
        if self.direct is None:
            if not (self.chosen_iterations and self.substeps is None):
                return False
            self._chosen_substeps(forces, dt)
            grid = self._grid_layout(forces) is not None
            if not direct_is_cheaper(int(self.free.sum()), self._substeps_wanted, grid):
                return False
        sc, strain = self._self_collision, self._strain_limit
        return (
            packed is None
            and not (sc is not None and sc.active)
            and not (self.tethers and strain is not None and strain.active)
            and applies(forces)
        )

    def _substep(self, state, forces, h, packed, budget, direct):
        """A substep of ``h`` (``packed``: the colliders over it, or None; ``budget``: its wall
        time, s, or None; ``direct``: solved directly, :meth:`_direct_for`) by :attr:`scheme`;
        returns what :meth:`_solve` does.

        BDF2 is backward Euler's step of ``ĥ = 2h/3`` from ``x̂ = (4xₙ − xₙ₋₁)/3`` with velocity
        ``v̂ = (4vₙ − vₙ₋₁)/3`` (``xₙ₋₁, vₙ₋₁``: the last substep's start): its step
        ``x = x̂ + ĥ·v``, ``v = v̂ + ĥ·a(x, v)`` is BDF2's, so the same solve serves both. A
        kinematic particle (a pin, a held vertex) still ends at ``xₙ + h·vₙ`` and keeps ``vₙ``.
        It starts from one backward-Euler substep (after a reset, a change of ``h``). A substep
        is backward Euler where colliders, self-contact or a strain limit are active: their
        searches and bounds start from the substep's true start, which ``x̂`` is not, and the
        stages after the step correct a velocity by ``Δx/h``, backward Euler's relation (under
        BDF2 a strain-limited cloth at rest kept creeping: the correction's missing ``Δx/(2h)``
        came back every step)."""
        if self.scheme != "bdf2":  # (no history to keep)
            return self._solve(state, forces, h, packed, budget, direct)
        sc, strain = self._self_collision, self._strain_limit
        staged = (
            packed is not None
            or (sc is not None and sc.active)
            or (strain is not None and strain.active)
        )
        bdf2 = self._past_h == h and not staged
        x, v = state.x, state.v
        start_x, start_v = self._buffer("_start_x", x), self._buffer("_start_v", v)
        if bdf2:
            bdf2_start(x, v, self._past_x, self._past_v, self.free, start_x, start_v)
            out = self._solve(state, forces, 2.0 * h / 3.0, packed, budget, direct)
            keep_kinematic(v, start_v, self.free)
        else:
            np.copyto(start_x, x)
            np.copyto(start_v, v)
            out = self._solve(state, forces, h, packed, budget, direct)
        # this substep's start is the next one's history
        self._past_x, self._start_x = start_x, self._past_x
        self._past_v, self._start_v = start_v, self._past_v
        self._past_h = h
        return out

    def _solve(self, state, forces, dt, packed, budget, direct):
        """A backward-Euler step of ``dt`` from the state (``packed``: the colliders over it, or
        None; ``budget``: its wall time, s, or None; ``direct``: by
        :mod:`~cloth_sim.integrators.vbd_newton` instead of the sweeps); returns the iterations
        done, the residual of its last sweep and whether they ran on the grid's blocks."""
        x, v = state.x, state.v
        model = self.model
        sp, (cptr, verts) = self._layout(forces)
        free = self.free
        h = self._solve_h = dt
        xt = self._buffer("_xt", x)
        np.copyto(xt, x)
        # the external acceleration: gravity and the wind at the step's start
        a = self._external_force(forces, x, v)
        a /= model.masses[:, None]
        y = self._buffer("_y", x)
        # the paper's adaptive initial guess: inertia, with gravity's part of the last step's
        # acceleration clamped to [0, |g|]
        g = forces.gravity
        gn = float(np.linalg.norm(g))
        gh = g / gn if gn > 0 else g
        # (contiguous either way: a column's view would make numba compile the kernel again)
        along = np.clip(self._a_prev @ gh, 0.0, gn) if gn > 0 else self._a_prev[:, 0].copy()
        initial_guess(x, y, xt, v, a, free, h, along, gn, gh, gn > 0)
        if direct:
            if self._newton is None:
                self._newton = NewtonSolve(model, free)
            deadline = None if budget is None else time.perf_counter() + budget
            done, res = self._newton.solve(
                forces, x, xt, v, y, h, self.tolerance, self.iterations, deadline
            )
            step_velocities(x, xt, v, free, h, self._a_prev)
            return done, res, False
        m_h2 = model.masses / (h * h)
        drag_h = forces.drag / h
        # contacts handled here: colliders, and self-contact's candidates and bounds
        contacts = self._contacts
        colliders = self._no_colliders
        tau = 0.0
        if packed is not None:
            colliders = packed
            tau = contacts.thickness
        sc = self._self_collision
        self_contact = sc is not None and sc.active
        if self_contact:
            tau = sc.thickness
        x_cd = self._buffer("_x_cd", x)
        allow = self._allow
        if len(colliders.kinds):  # what a moving collider overtook starts on its skin
            overtaken(x, free, colliders, tau)
        # each collider's distance and normal at a vertex, as colliders_at saw them for onset,
        # and (its fifth number) the lower bound on that distance the last search left while
        # the vertex stays within its allowance (collider_allowances: colliders_at asks nothing
        # of a collider that bound keeps beyond the thickness)
        seen = self._seen
        if seen.shape[0] != len(x) or seen.shape[1] < len(colliders.kinds):
            seen = self._seen = np.zeros((len(x), max(1, len(colliders.kinds)), 5))
            self._candidates = False  # (the bounds are made with the search)
        if self_contact or len(colliders.kinds):
            # the initial guess, not the inertia: a layer resting on another or on a collider
            # is not going where gravity alone would take it
            if not self._detection_holds(x, colliders, tau, self_contact):
                self._detect(xt, x, colliders, tau, self_contact, x_cd)
            # the initial guess within the bounds
            chebyshev(
                x,
                x_cd,
                1.0,
                free,
                x_cd,
                allow,
                GAMMA,
                self._rec,
                self._cut,
                self._no_touch,
            )
        else:
            allow[:] = np.inf
            self._rec = self._no_rec
            self._candidates = False
        ks = self.self_contact_stiffness_for(forces)
        kc = self.contact_stiffness
        eps = EPS_V * h
        stepped, cut, touch = self._stepped, self._cut, self._touch
        stepped[:] = 0.0
        cut[:] = 0
        omega = 1.0
        budget_end = None if budget is None else time.perf_counter() + budget
        done = 0
        res = math.inf

        strain = self._strain_limit
        tether = (
            self.tethers
            and strain is not None
            and strain.active
            and not self_contact
            and not len(colliders.kinds)
        )
        grid = None if self_contact or tether else self._grid_layout(forces)
        if grid is not None:
            contact = None
            if len(colliders.kinds):
                xm = self._buffer("_xm", x)
                contact = grid.contact(
                    xm, xt, self._near, touch, cut, x_cd, allow, GAMMA, (tau, kc, eps), colliders,
                    self._rec, seen,
                )  # fmt: skip
            done = self._iterate_grid(grid, x, xt, y, m_h2, 1.0 / h, drag_h, budget_end, contact)
        else:  # the general sweep's buffers: the iterate's copy and the one two iterations back
            xs = self._buffer("_xs", x)
            prev2 = self._buffer("_prev2", x)
            np.copyto(prev2, x)
            run = iterate_parallel if len(verts) >= PARALLEL_MIN_VERTICES else iterate_serial
        interval = self.collision_interval
        if interval is None:
            # the vertices in front of a moving link meet their bounds iteration after
            # iteration; a link that moved far from every vertex's reach is as a still one
            moving = (
                self_contact
                and len(colliders.kinds)
                and moving_within_reach(x_cd, free, colliders, allow, tau)
            )
            interval = MOVING_COLLISION_INTERVAL if moving else COLLISION_INTERVAL
        for it in range(0 if grid is not None else self.iterations):
            if self_contact and it > 0 and it % interval == 0 and cut.any():
                # a vertex met its bound: search again from here, for room to move on. Where few
                # did, only they are searched again, with those near a collider that used half
                # their allowance (a link pushing them: they meet it at the next sweep)
                used = np.einsum("ij,ij->i", x - x_cd, x - x_cd) > 0.25 * allow * allow
                met = ((cut != 0) | (used & self._near)) & free
                if np.count_nonzero(met) <= LOCAL_SEARCH_SHARE * np.count_nonzero(free):
                    self._detect_touching(x, y, colliders, tau, x_cd, met)
                else:
                    self._detect(x, y, colliders, tau, self_contact, x_cd)
                cut[:] = 0
            sc_arrays = self._rec
            np.copyto(xs, x)
            run(
                verts,
                cptr,
                (x, xt, y, xs),
                (m_h2, 1.0 / h, drag_h),
                sp,
                colliders,
                sc_arrays,
                (tau, kc, eps, ks, self.self_friction, GAMMA),
                (x_cd, allow, self._near),
                (stepped, cut, touch, seen),
            )
            if tether:
                # the long-range attachments after each sweep: the pins' pull reaches the far
                # edge at once, where an iteration carries it about one ring of springs
                strain.attachments(x)
            done += 1
            if self._checks_at(done):  # the last sweep's, before any extrapolation
                res = sweep_residual(stepped, model.masses, free)
            last = (
                it == self.iterations - 1
                or (budget_end is not None and time.perf_counter() >= budget_end)
                or res <= self.tolerance
            )
            if last:
                # the step ends on a sweep, never on an extrapolation: an over-relaxed iterate is
                # no descent from the last one (at 2 iterations, ω = 1.47 on hang16 at 1/60 s
                # gained energy step after step until the cloth diverged)
                break
            if self.rho > 0.0:
                # Chebyshev: ω₁ = 1, ω₂ = 2/(2 − ρ²), ω_k = 4/(4 − ρ² ω_{k−1})
                omega = (
                    1.0
                    if it == 0
                    else (
                        2.0 / (2.0 - self.rho**2) if it == 1 else 4.0 / (4.0 - self.rho**2 * omega)
                    )
                )
                if it > 0:
                    chebyshev(x, prev2, omega, free, x_cd, allow, GAMMA, sc_arrays, cut, touch)
                np.copyto(prev2, xs)
        res = sweep_residual(stepped, model.masses, free)  # the step's last sweep's
        # v = (x − x^t)/h; pins keep their velocity (they moved by h·v)
        step_velocities(x, xt, v, free, h, self._a_prev)
        self.counters["truncated"] += int(cut.sum())
        self._cut_last = bool(cut.any())
        return done, res, grid is not None

    def _grid_layout(self, forces):
        """The grid's blocked layout (:mod:`~cloth_sim.integrators.vbd_grid`) for ``forces``, or
        ``None`` where the model is not a grid of Hooke springs on Provot's stencil."""
        if self._grid_of is not forces:
            self._grid = GridLayout.of(self.model, forces) if self.grid else None
            self._grid_of = forces
        return self._grid

    def _checks_at(self, done: int) -> bool:
        """Whether the residual is measured after ``done`` iterations, before the last: every
        :attr:`check_every` iterations (the sweeps keep each vertex's imbalance, so a measure is
        a sum over the vertices)."""
        return done < self.iterations and done % self.check_every == 0

    def _next_check(self, done: int) -> int:
        """The iterations after which the residual is next measured, past ``done`` (the step's
        cap if no measure comes before)."""
        return min(self.iterations, (done // self.check_every + 1) * self.check_every)

    def _iterate_grid(self, grid, x, xt, y, m_h2, inv_h, drag_h, budget_end, contact) -> int:
        """The step's iterations on the grid's blocks (no self-contact; ``contact``: the colliders'
        part, or None): the general loop's sweeps and Chebyshev steps, colour by colour in SIMD
        lanes, in runs of :attr:`check_every` iterations between two measures of the residual
        (on the iterate and imbalances gathered into ``x`` and ``stepped``); returns the
        iterations done."""
        grid.load(x, xt, y, m_h2)
        threads = numba.get_num_threads()
        if not grid.parallel:
            numba.set_num_threads(1)  # the same bits: the chunks do not depend on the threads
        total = self.iterations
        omega, done = 1.0, 0
        try:
            while True:
                # to the next measure or the end (one at a time under a budget: the clock)
                last = done + 1 if budget_end is not None else self._next_check(done)
                omega, flips = grid.solve(
                    inv_h, drag_h, done, last, total, self.rho, omega, contact
                )
                done = last
                # the step ends on a sweep (as in the general loop): the iterate, not the
                # extrapolation made for a next iteration, which took the last turn where made
                extrapolated = self.rho > 0.0 and done < total
                swept = flips + (1 if extrapolated else 0)  # turns before the swept iterate
                stop = done == total or (
                    budget_end is not None and time.perf_counter() >= budget_end
                )
                check = not stop and self._checks_at(done)
                if stop or check:
                    grid.store(x, self._stepped, swept)
                if check:
                    res = sweep_residual(self._stepped, self.model.masses, self.free)
                    stop = res <= self.tolerance
                if stop:
                    return done
                if flips % 2:
                    grid.swap()
        finally:
            numba.set_num_threads(threads)

    def _edges(self):
        sc = self._self_collision
        return sc.edges if sc is not None else np.zeros((0, 2), np.int64)

    def _detect(self, x, y, colliders, tau, self_contact, x_cd) -> None:
        """Candidate search from ``x`` (kept in ``x_cd``): the self-contact pairs and records
        (:attr:`_rec`), every vertex's allowance (its way to ``y``, where it is expected to go:
        the initial guess at the step's start, the inertia mid-step) and whether it may touch a
        collider."""
        np.copyto(x_cd, x)
        n = len(x)
        allowance = allowances(x, y, tau)
        c = self.counters
        c["detections"] += 1
        self._rec = self._no_rec
        self._energy_pairs = 0
        sc = self._self_collision
        if self_contact:
            # each vertex reaches τ/2 and its allowance: a pair not found stays beyond τ
            vt, vt_d, ee, ee_d = sc.candidates(x, 0.5 * tau + allowance, sc.skin(SEARCH_SKIN))
            self._rec = self._records(n, x, vt, vt_d, ee, ee_d, sc)
            self._found = (vt, vt_d, ee, ee_d, allowance)
        clear = np.full((n, self._seen.shape[1]), -np.inf)
        collider_allowances(
            x,
            allowance,
            self_contact,
            colliders,
            self.depths(colliders),
            tau,
            self._allow,
            self._near,
            clear,
        )
        self._allow[~self.free] = np.inf
        clear[~self.free] = -np.inf
        self._seen[:, :, 4] = clear
        c["last_contacts"] = self._energy_pairs
        self._candidates = self_contact
        self._cd_colliders = (colliders.pos.copy(), colliders.rot.copy(), tau)

    def _detect_touching(self, x, y, colliders, tau, x_cd, met) -> None:
        """The search of :meth:`_detect` made again for the vertices that ``met`` their bounds
        only: they are searched from where they are now (``x``), every other vertex keeps where
        its search was made (``x_cd``), its allowance and its pairs, and the pairs of a feature
        with a vertex that met its bound are those at these positions (the tree walked from the
        leaves holding them:
        :meth:`~cloth_sim.contact.self_collision.SelfCollision.candidates_touching`).

        Why it keeps the bounds: a pair's bound asks each side to approach the other by at most
        γ of their distance where their searches were made, along the normal between those
        places, and nothing of the argument asks both places to be of one moment. A pair of two
        vertices that did not meet their bounds is as the last search found it; every pair with a
        vertex that did is measured between the places kept now, each side's bound read from its
        own. A pair not found stays beyond τ while each side stays within its allowance of its
        place, as after a whole search (each reach is τ/2 and its vertex's allowance). A vertex
        that did not meet its bound but gains a pair may stand beyond that pair's bound: its next
        sweep, like every sweep, holds its step within all its bounds from its place."""
        n = len(x)
        self.counters["local_detections"] += 1
        vt, vt_d, ee, ee_d, allowance = self._found
        allowance = allowance.copy()
        x_cd[met] = x[met]
        allowance[met] = allowances(x[met], y[met], tau)
        sc = self._self_collision
        gone, gone_e = touching(vt, ee, self._tris, sc.edges, met)  # measured again below
        nvt, nvt_d, nee, nee_d = sc.candidates_touching(x_cd, 0.5 * tau + allowance, met)
        vt = np.concatenate([vt[~gone], nvt])
        vt_d = np.concatenate([vt_d[~gone], nvt_d])
        ee = np.concatenate([ee[~gone_e], nee])
        ee_d = np.concatenate([ee_d[~gone_e], nee_d])
        self._rec = self._records(n, x_cd, vt, vt_d, ee, ee_d, sc)
        self._found = (vt, vt_d, ee, ee_d, allowance)
        # the colliders' hold on the vertices searched again (the others' is as it was: the same
        # place, allowance and colliders)
        allow, near = self._allow[met], self._near[met]
        clear = np.full((len(allow), self._seen.shape[1]), -np.inf)
        collider_allowances(
            np.ascontiguousarray(x_cd[met]),
            allowance[met],
            True,
            colliders,
            self.depths(colliders),
            tau,
            allow,
            near,
            clear,
        )
        self._allow[met], self._near[met] = allow, near
        self._seen[met, :, 4] = clear
        self.counters["last_contacts"] = self._energy_pairs

    def _detection_holds(self, y, colliders, tau, self_contact) -> bool:
        """Whether the last candidate search serves this step too: it was made for self-contact,
        no collider moved and the thickness is the same, and all but :data:`REUSE_OVER` of the
        free vertices' initial guesses ``y`` stay within half their allowances of where the search
        was made. Its pairs, normals and bounds then still hold (they are taken from the
        search's positions, and so are the bounds), and the search costs most of a contact-rich
        step."""
        if not self_contact or not self._candidates:
            return False
        pos, rot, tau0 = self._cd_colliders
        if (
            tau0 != tau
            or pos.shape != colliders.pos.shape
            or not (np.array_equal(pos, colliders.pos) and np.array_equal(rot, colliders.rot))
        ):
            return False
        free = self.free
        moved = np.linalg.norm(y[free] - self._x_cd[free], axis=1)
        return bool(np.count_nonzero(moved > 0.5 * self._allow[free]) <= REUSE_OVER * len(moved))

    def _records(self, n, x, vt, vt_d, ee, ee_d, sc):
        """The candidate pairs at ``x`` (:func:`contact_pairs`) and each vertex's records of them:
        ``(energy ptr, the energy records' vertices, weights and normals (:func:`pack_records`),
        bound ptr, bound records, vertices, weights, normals, distances, each vertex's nearest
        distance, each energy record's distance in the current iteration)``."""
        _, tri_edge, edge_owner, _, vertex_owner = sc.features[:5]
        idx, coef, nrm, energy = contact_pairs(
            x,
            np.ascontiguousarray(vt, dtype=np.int64),
            np.ascontiguousarray(ee, dtype=np.int64),
            self._tris,
            sc.edges,
            tri_edge,
            edge_owner,
            vertex_owner,
        )
        dist = np.concatenate([vt_d, ee_d]).astype(np.float64)
        self._energy_pairs = int(energy.sum())
        ptr, rec, gptr, grec = contact_records(n, idx, coef, energy)
        return (
            ptr,
            *pack_records(rec, idx, coef, nrm, self._colour),
            gptr,
            grec,
            idx,
            coef,
            nrm,
            dist,
            nearest_distances(gptr, grec, dist),
            np.zeros(len(rec)),
        )

    @staticmethod
    def depths(colliders):
        """Per collider, how far in its far side is (half its thinnest dimension; ``inf`` for a
        plane, a half-space; 0 for a mesh: a vertex may not reach its surface between two
        searches, so a moving link cannot pass through the cloth; one already within a closed
        mesh's skin may get out to it, :func:`collider_allowances`)."""

        kinds, geo = colliders.kinds, colliders.geo
        depth = np.full(len(kinds), np.inf)
        for c, kind in enumerate(kinds):
            if kind == SPHERE:
                depth[c] = geo[c, 0]
            elif kind == CAPSULE:
                depth[c] = geo[c, 3]
            elif kind == BOX:
                depth[c] = float(np.min(geo[c, :3]))
            elif kind == CYLINDER:
                depth[c] = float(min(geo[c, 0], geo[c, 1]))
            elif kind == MESH:
                depth[c] = 0.0
        return depth
