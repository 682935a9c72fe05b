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
  stiffness ``kc``.
* :class:`Iterate`, one ``(worlds, n, 3)`` array a world's positions, velocities and the step's
  scratch: the step's start ``xt``, the inertial target ``y``, the iterate before the sweep ``xs``,
  the Chebyshev history ``prev2``, the last step's acceleration ``aprev``, and each vertex's
  squared force from the last sweep ``stepped``.
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


class Run(NamedTuple):
    """What :func:`~cloth_sim.cuda.kernels.frames_in_blocks` runs: ``steps`` steps of ``substeps``
    substeps of ``h`` by ``method`` (0: symplectic Euler, 1: vbd with its ``iterations``,
    ``tolerance``, ``check_every`` and ``rho``; ``bdf2`` 1 where its substeps are BDF2's, each
    then backward Euler's of ``hb = 2h/3``)."""

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
