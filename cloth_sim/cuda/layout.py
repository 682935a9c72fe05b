"""A model's arrays as :mod:`cloth_sim.cuda.kernels` reads them: three named bundles, built on the
host with numpy and copied to the device once.

* :class:`Topology`, shared by every world: each vertex's springs (CSR in the vertex's order: the
  other end, the family, rest length, the model's stiffness and damping), the material's bending
  rows (``Q``'s CSR and diagonal), each vertex's triangles (for its normal) and the colour groups
  (no two vertices of a colour share a spring or a bending stencil).
* :class:`Worlds`, one row a world: masses, which vertices are free, gravity, wind, drag and each
  family's stiffness and damping where a world overrides the model's (``−1``: the model's own);
  its static colliders as the CPU's packed colliders give them (``ckind[w, c]`` the shape's code,
  ``cpos``, ``crot`` its position and rotation, ``cpos0``, ``crot0`` where the step starts them
  (the same but over a step that sweeps them), ``cgeo`` its four numbers, ``cmu`` its friction,
  ``ncol`` how many), the thickness ``tau`` the cloth keeps from them and ``vbd``'s contact
  stiffness ``kc``; a mesh collider's baked distance grid (``cgeo[w, c, 0]`` its index), shared
  by every world: ``gbox`` (its first node, cell and band), ``gdim`` (its nodes along x, y, z and
  its first value) and ``gval`` (every grid's values,
  :func:`cloth_sim.contact.distance_grid.pack_grids`); and what the contact stage writes where
  the worlds record it, ``cimp`` ``(worlds, n, colliders, 6)`` (each vertex's impulse on each
  collider and its moment, for the colliders' wrenches; ``(worlds, 0, 1, 6)`` where not).
* :class:`Iterate`, one ``(worlds, n, 3)`` array a world's positions, velocities and the step's
  scratch: the step's start ``xt``, the inertial target ``y``, the iterate before the sweep ``xs``,
  the Chebyshev history ``prev2``, the last step's acceleration ``aprev``, and each vertex's
  squared force from the last sweep ``stepped``.
* :class:`Limits`, Provot's strain limit: the limited springs grouped by colour (no two springs of
  a colour share a vertex, so a colour's are shortened at once) and each world's long-range
  attachments to its pins (held vertices included).
* :class:`Run`, the scalars of a launch that runs whole steps.

Floating-point arrays are ``float32`` or ``float64`` (the backend's ``precision``); indices int32.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..integrators.vbd_kernels import colour_groups
from ..model import ClothModel
from ..physics.forces import incidence


class Topology(NamedTuple):
    inc_ptr: np.ndarray
    nbr: np.ndarray
    fam: np.ndarray
    rest: np.ndarray
    k: np.ndarray
    c: np.ndarray
    bptr: np.ndarray
    bidx: np.ndarray
    bval: np.ndarray
    bdiag: np.ndarray
    tptr: np.ndarray
    tlist: np.ndarray
    tris: np.ndarray
    cverts: np.ndarray


class Worlds(NamedTuple):
    masses: np.ndarray
    free: np.ndarray
    gravity: np.ndarray
    wind: np.ndarray
    windy: np.ndarray
    drag: np.ndarray
    kfam: np.ndarray
    cfam: np.ndarray
    ckind: np.ndarray
    cpos: np.ndarray
    crot: np.ndarray
    cpos0: np.ndarray
    crot0: np.ndarray
    cgeo: np.ndarray
    cmu: np.ndarray
    ncol: np.ndarray
    tau: np.ndarray
    kc: np.ndarray
    gbox: np.ndarray
    gdim: np.ndarray
    gval: np.ndarray
    cimp: np.ndarray


class Iterate(NamedTuple):
    """The worlds' state and the solve's buffers, ``(worlds, n, 3)`` unless said: the state
    ``x, v``; the substep's start ``xt`` (BDF2's ``x̂``), inertial target ``y``, the iterate's
    copies ``xs, prev2`` (Chebyshev), the last acceleration ``aprev``, each vertex's squared
    imbalance ``stepped`` ``(worlds, n)``; BDF2's substep start ``sx, sv`` and history ``px, pv``
    (the last substep's start), and per world whether that history serves (``past``) and whether
    this substep is BDF2's (``bdf``), both ``(worlds,)`` int8."""

    x: np.ndarray
    v: np.ndarray
    xt: np.ndarray
    y: np.ndarray
    xs: np.ndarray
    prev2: np.ndarray
    aprev: np.ndarray
    stepped: np.ndarray
    sx: np.ndarray
    sv: np.ndarray
    px: np.ndarray
    pv: np.ndarray
    past: np.ndarray
    bdf: np.ndarray


class Limits(NamedTuple):
    """Provot's strain limit (:mod:`cloth_sim.constraints.strain_limit`) on the device: the
    model's strain-limited springs ``ends`` ``(m, 2)`` with their ``rest`` lengths, grouped by
    colour (colour ``c`` is ``sptr[c]:sptr[c + 1]``; no two springs of a colour share a vertex);
    each world's long-range attachments, ``anchor`` ``(worlds, n, 2)`` (a pin, or −1) and
    ``reach`` (its rest geodesic distance); ``flags`` ``(worlds, 3)``: whether a world's pass
    shortened anything (three in turn: one written, the last read, the next cleared);
    ``gained`` ``(worlds, n, 3)``: each vertex's corrections over the last step, ``Σ Δx/h`` (the
    limit's reaction on the pins: a gripper's wrench)."""

    ends: np.ndarray
    rest: np.ndarray
    sptr: np.ndarray
    anchor: np.ndarray
    reach: np.ndarray
    flags: np.ndarray
    gained: np.ndarray


class Run(NamedTuple):
    """What :func:`~cloth_sim.cuda.kernels.frames_in_blocks` runs: ``steps`` steps of ``substeps``
    substeps of ``h`` by ``method`` (0: symplectic Euler, 1: vbd with its ``iterations``,
    ``tolerance``, ``check_every`` and ``rho``; ``bdf2`` 1 where its substeps are BDF2's, each
    then backward Euler's of ``hb = 2h/3``); after each symplectic Euler step, Provot's strain
    limit ``limit`` (τ; negative: none) in at most ``passes`` passes (:class:`Limits`)."""

    h: float
    hb: float
    bdf2: int
    steps: int
    substeps: int
    method: int
    iterations: int
    tolerance: float
    check_every: int
    rho: float
    limit: float
    passes: int


def _csr(owner: np.ndarray, item: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(owner, kind="stable")
    ptr = np.zeros(n + 1, np.int32)
    np.cumsum(np.bincount(owner, minlength=n), out=ptr[1:])
    return ptr, item[order].astype(np.int32)


def topology(model: ClothModel, real) -> tuple[Topology, np.ndarray]:
    """The model's :class:`Topology` (host arrays, floating point as ``real``) and the colour
    groups' bounds ``cptr`` (colour ``c`` is ``cverts[cptr[c]:cptr[c+1]]``: every vertex, pinned
    or not, since pins differ from world to world)."""
    n = model.n_particles
    springs = np.asarray(model.springs, np.int64)
    ptr, inc, _ = incidence(springs, n)
    ends = np.repeat(np.arange(n), np.diff(ptr))
    nbr = springs[inc, 0] + springs[inc, 1] - ends
    bending = model.bending
    if bending is None:
        bptr, bidx, bval, bdiag = np.zeros(n + 1, np.int64), np.zeros(0), np.zeros(0), np.zeros(n)
        coupled = springs
    else:
        bptr, bidx, bval, bdiag = bending.rows()
        coupled = np.concatenate([springs, bending.couplings()[0]])
    cptr, cverts = colour_groups(coupled, n, np.ones(n, bool))
    tris = np.ascontiguousarray(model.triangles, np.int64).reshape(-1, 3)
    tptr, tlist = _csr(tris.ravel(), np.repeat(np.arange(len(tris)), 3), n)
    top = Topology(
        inc_ptr=ptr.astype(np.int32),
        nbr=nbr.astype(np.int32),
        fam=np.asarray(model.family, np.int32)[inc],
        rest=np.asarray(model.rest_lengths, real)[inc],
        k=np.asarray(model.stiffness, real)[inc],
        c=np.asarray(model.damping, real)[inc],
        bptr=np.asarray(bptr, np.int32),
        bidx=np.asarray(bidx, np.int32),
        bval=np.asarray(bval, real),
        bdiag=np.asarray(bdiag, real),
        tptr=tptr,
        tlist=tlist,
        tris=tris.astype(np.int32),
        cverts=cverts.astype(np.int32),
    )
    return top, cptr


def spring_colours(springs: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(order, sptr)``: ``springs`` (``(m, 2)``) reordered so that each colour's are together
    (colour ``c``: ``order[sptr[c]:sptr[c + 1]]``), no two of a colour sharing a vertex; greedy,
    in the springs' order, each taking the least colour free at both ends (a grid's structural
    and shear springs take 8)."""
    m = len(springs)
    colour = np.zeros(m, np.int64)
    used: list[set] = [set() for _ in range(n)]
    for s in range(m):
        i, j = int(springs[s, 0]), int(springs[s, 1])
        c = 0
        while c in used[i] or c in used[j]:
            c += 1
        colour[s] = c
        used[i].add(c)
        used[j].add(c)
    order = np.argsort(colour, kind="stable")
    sptr = np.zeros((colour.max() + 2) if m else 1, np.int32)
    np.cumsum(np.bincount(colour, minlength=len(sptr) - 1), out=sptr[1:])
    return order, sptr


def limits(model: ClothModel, worlds: int, real) -> Limits:
    """The model's :class:`Limits` on the host, every world without attachments (``anchor``
    −1: :meth:`~cloth_sim.cuda.worlds.CudaWorlds` fills them from each world's pins)."""
    sel = np.flatnonzero(model.strain_limited)
    springs = np.asarray(model.springs, np.int64)[sel]
    order, sptr = spring_colours(springs, model.n_particles)
    n = model.n_particles
    return Limits(
        ends=np.ascontiguousarray(springs[order], np.int32).reshape(-1, 2),
        rest=np.asarray(model.rest_lengths, real)[sel][order],
        sptr=sptr,
        anchor=np.full((worlds, n, 2), -1, np.int32),
        reach=np.zeros((worlds, n, 2), real),
        flags=np.zeros((worlds, 3), np.int32),
        gained=np.zeros((worlds, n, 3), real),
    )


def same_topology(models: list[ClothModel]) -> None:
    """Raise ``ValueError`` naming the first field in which ``models`` differ where worlds must
    agree (they share one :class:`Topology`)."""
    first = models[0]
    for m, other in enumerate(models[1:], start=1):
        for field in ("springs", "rest_lengths", "kind", "family", "triangles"):
            if not np.array_equal(getattr(first, field), getattr(other, field)):
                raise ValueError(
                    f"models[{m}].{field} differs from models[0]'s: worlds stepped together share "
                    "one topology (springs, rest lengths, kinds, families, triangles)"
                )
        if first.family_names != other.family_names:
            raise ValueError(f"models[{m}].family_names differs from models[0]'s")
        b0, b1 = first.bending, other.bending
        if (b0 is None) != (b1 is None) or (
            b0 is not None and (b0.Q != b1.Q).nnz  # type: ignore[union-attr]
        ):
            raise ValueError(f"models[{m}].bending differs from models[0]'s")
