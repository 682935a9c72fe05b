"""Forces on the particles, assembled from what the scene actually has.

Terms (the review's equations in brackets):

* ``spring:<family>`` — Hooke's law along each spring [1.6]; for Choi & Ko (2002) the type-1
  (tension only) and type-2 (immediate buckling) interactions.
* ``damping:<family>`` — damping along each spring, ``−k_d ((v2 − v1)·u) u`` [1.7].
* ``gravity`` — ``m g`` [1.4].
* ``wind`` — ``(n_i·W) n_i`` on the unit normal of each particle [1.5], with ``W = w·direction``.
* ``drag`` — linear air drag ``−c v``.

A family whose stiffness is zero contributes no ``spring:`` term, one whose damping is zero no
``damping:`` term; no wind, no gravity, no drag: no such term. :attr:`Forces.active_terms` lists
what is evaluated, and springs belonging to no active term are not even visited.

The kernels these terms call (the springs' forces, their gather on every core, the Choi–Ko
table, the normals and the wind, the springs' Jacobian blocks) are in
:mod:`cloth_sim.physics.force_kernels`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..model import ClothModel
from ..threads import start_pool
from .force_kernels import (
    BUCKLE_TABLE,
    GATHER_ACCELERATION,
    GATHER_FORCE,
    GatherSprings,
    spring_energy,
    spring_forces,
    spring_forces_gather,
    spring_jacobian_blocks,
    wind_forces,
)


def incidence(springs: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ptr, adj, sign)``: particle ``p``'s springs are ``adj[ptr[p]:ptr[p+1]]`` in increasing
    order, ``sign`` +1 where ``p`` is the spring's first end (it feels ``+f``), −1 where second."""
    ends = springs.ravel()
    perm = np.argsort(ends, kind="stable")  # stable: within a particle, in spring order
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(ends, minlength=n), out=ptr[1:])
    return ptr, np.ascontiguousarray(perm // 2), np.where(perm % 2 == 0, 1, -1).astype(np.int8)


# --------------------------------------------------------------------------- terms
#: From this many springs (a 19×19 grid) the spring forces run on every core: below it the
#: parallel regions' fork and join cost more than they save (the crossing measured: docs/
#: BENCHMARKS.md §7). Both give the same bits at any thread count.
PARALLEL_MIN_SPRINGS = 2000
# the gather's inverse masses and state outputs when it does not update the state
_NO_MASS = np.zeros((1, 1))
NO_STATE = np.zeros((1, 3))
NO_STAGE = (NO_STATE, NO_STATE, np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), np.zeros(0))

_INCIDENCE: dict = {}


def spring_layout(springs: np.ndarray, n: int) -> tuple:
    """How :func:`spring_forces_gather` lays the springs out: ``(order, ends, ptr, adj, sign)``.

    ``order``: the springs sorted by their lower end, then their higher one, so that the springs
    one core computes are mostly the springs of the particles it then sums (a model lists its
    springs by family: in that order each core computed half of every particle's springs and the
    other core read them back across the cache; docs/BENCHMARKS.md §7). ``ends``: the springs in
    that order (their own orientation, 32-bit). ``ptr``, ``adj``, ``sign``: :func:`incidence` of
    the springs as given — each particle still sums its springs in their given order, the serial
    loop's, so the bits do not change — with ``adj`` pointing at where each spring's force sits in
    ``order`` (32-bit indices: the 64-bit ones' loads cost the gather, docs/BENCHMARKS.md §7)."""
    if n >= 2**32 or len(springs) >= 2**32:
        raise ValueError(
            f"the spring gather indexes with 32 bits: {n} particles, {len(springs)} springs"
        )
    ptr, adj, sign = incidence(springs, n)
    order = np.lexsort((springs.max(axis=1), springs.min(axis=1)))
    where = np.empty(len(order), np.int64)
    where[order] = np.arange(len(order))
    return (
        order,
        springs[order].astype(np.uint32),
        ptr.astype(np.uint32),
        where[adj].astype(np.uint32),
        sign,
    )


#: no bending in the gather: an empty CSR (its ``ptr`` of length 1) and no scratch
NO_BENDING_ROWS = (np.zeros(1, np.uint32), np.zeros(0, np.uint32), np.zeros(0), np.zeros((0, 3)))


def gather_arrays(
    springs, rest, k, c, kind, with_damping: bool, n: int, layout=None, bending=None
) -> GatherSprings:
    """What :func:`spring_forces_gather` reads of these springs (:class:`GatherSprings`): their
    ends and material in :func:`spring_layout`'s order, the Choi–Ko table, the incidence, the
    per-spring force scratch by coordinate (3, springs), and the rows of a material's bending
    ``Q`` with their scratch (:data:`NO_BENDING_ROWS` without). ``layout``: the springs'
    :func:`spring_layout`, if already at hand."""
    order, ends, ptr, adj, sign = spring_layout(springs, n) if layout is None else layout
    if bending is None:
        rows = NO_BENDING_ROWS
    else:
        qptr, qidx, qval = bending.csr
        rows = (  # 32-bit indices, as the springs' (their loads cost the gather)
            qptr.astype(np.uint32),
            qidx.astype(np.uint32),
            qval,
            np.empty((n, 3)),
        )
    return GatherSprings(
        ends,
        rest[order],
        k[order],
        c[order],
        kind[order],
        BUCKLE_TABLE,
        with_damping,
        ptr,
        adj,
        sign,
        np.empty((3, len(springs))),
        *rows,
    )


def _layout_of(model: ClothModel, live: np.ndarray):
    """:func:`spring_layout` of the model's live springs, kept per model and set of live springs (a
    material change rebuilds the force pipeline; the springs it keeps rarely change)."""
    key = (id(model), live.tobytes())
    hit = _INCIDENCE.get(key)
    if hit is None or hit[0] is not model:
        hit = (model, spring_layout(np.ascontiguousarray(model.springs[live]), model.n_particles))
        _INCIDENCE[key] = hit
        while len(_INCIDENCE) > 16:
            _INCIDENCE.pop(next(iter(_INCIDENCE)))
    return hit[1]


class SpringTerm:
    """Hooke (or Choi–Ko) and damping along every spring whose family has a non-zero stiffness or
    damping [1.6, 1.7]: one compiled loop over the live springs. Energy: the elastic energy.
    Jacobian blocks: :func:`spring_jacobian_blocks`, which Baraff–Witkin assembles from and
    :meth:`Forces.jacobians` reports."""

    def __init__(
        self, model: ClothModel, stiffness: np.ndarray, damping: np.ndarray, bending=None
    ):
        names, fam = model.family_names, model.family
        k_on = np.array([np.any(stiffness[fam == i] > 0) for i in range(len(names))], bool)
        c_on = np.array([np.any(damping[fam == i] > 0) for i in range(len(names))], bool)
        self.labels = tuple(
            [f"spring:{n}" for n, on in zip(names, k_on) if on]
            + [f"damping:{n}" for n, on in zip(names, c_on) if on]
        )
        live = (k_on | c_on)[fam] & ((stiffness > 0) | (damping > 0))
        self.springs = np.ascontiguousarray(model.springs[live])
        self.rest = np.ascontiguousarray(model.rest_lengths[live])
        self.k = np.ascontiguousarray(stiffness[live])
        self.c = np.ascontiguousarray(damping[live])
        self.kind = np.ascontiguousarray(model.kind[live])
        self.with_damping = bool(np.any(self.c > 0))
        self.parallel = len(self.springs) >= PARALLEL_MIN_SPRINGS  # decided once, per term
        #: a material's bending summed inside the parallel gather (one pass fewer than a term of
        #: its own, and the fused stages keep fusing); None: the bending is a term of its own
        self.bending = bending if self.parallel else None
        if self.parallel:
            #: what every call of the gather passes first (:func:`gather_arrays`)
            self._gather_args = gather_arrays(
                self.springs,
                self.rest,
                self.k,
                self.c,
                self.kind,
                self.with_damping,
                model.n_particles,
                _layout_of(model, live),
                self.bending,
            )
            g = self._gather_args
            self._incidence, self._fs = (g.ptr, g.adj, g.sign), g.fs
            #: the same as the plain tuple :func:`spring_forces_gather` takes
            self.net = tuple(g)
            if self.bending is not None:
                self.labels = (*self.labels, "bending")

    @property
    def active(self) -> bool:
        return len(self.springs) > 0

    def streamed_bytes(self) -> tuple[int, int]:
        """``(read, written)``: the bytes of this term's own arrays one evaluation streams (rest
        lengths, stiffness, damping, kinds and the springs' ends; the parallel gather's incidence
        lists and its per-spring force array, written and read back). For the memory-bandwidth
        bound of :mod:`cloth_sim.bench.scaling`."""
        read = sum(a.nbytes for a in (self.rest, self.k, self.c, self.kind))
        read += (self._gather_args.ends if self.parallel else self.springs).nbytes
        written = 0
        if self.parallel:
            read += sum(a.nbytes for a in self._incidence) + self._fs.nbytes
            written += self._fs.nbytes
        return read, written

    def add_force(self, x, v, f):
        if self.parallel:
            spring_forces_gather(
                x,
                v,
                self.net,
                f,
                f,
                _NO_MASS,
                0.0,
                GATHER_FORCE,
                NO_STATE,
                NO_STATE,
                NO_STAGE,
            )
        else:  # the same bits on one core
            spring_forces(
                x,
                v,
                self.springs,
                self.rest,
                self.k,
                self.c,
                self.kind,
                BUCKLE_TABLE,
                self.with_damping,
                f,
            )

    def energy(self, x) -> float:
        return float(spring_energy(x, self.springs, self.rest, self.k, self.kind, BUCKLE_TABLE))

    def jacobian_blocks(self, x, v, clamp: bool = False, position_damping: bool = True, out=None):
        """Per-spring ``(kx, dx, cv)`` 3×3 blocks (see :func:`spring_jacobian_blocks`); ``dx`` is
        left zero without ``position_damping``. ``out``: three ``(m, 3, 3)`` arrays to fill."""
        m = len(self.springs)
        if out is None:
            out = np.empty((m, 3, 3)), np.empty((m, 3, 3)), np.empty((m, 3, 3))
        out = tuple(out)
        spring_jacobian_blocks(
            np.ascontiguousarray(x, dtype=np.float64),
            np.ascontiguousarray(v, dtype=np.float64),
            self.springs,
            self.rest,
            self.k,
            self.c,
            self.kind,
            BUCKLE_TABLE,
            clamp,
            position_damping,
            out,
        )
        return out


class GravityTerm:
    """``m g`` [1.4]; energy ``−Σ m_i g·x_i``."""

    labels = ("gravity",)

    def __init__(self, masses: np.ndarray, gravity: np.ndarray):
        self.masses = masses
        self.gravity = gravity
        self.force = masses[:, None] * gravity[None, :]

    def add_force(self, x, v, f):
        f += self.force

    def energy(self, x) -> float:
        return -float(np.sum(self.masses * (x @ self.gravity)))


class WindTerm:
    """``(n_i·W) n_i`` on each particle's unit normal [1.5]; no energy (it is not conservative)."""

    labels = ("wind",)

    def __init__(self, triangles: np.ndarray, wind: np.ndarray, n: int):
        self.triangles = triangles
        self.wind = wind
        self._normals = np.zeros((n, 3))

    def add_force(self, x, v, f):
        wind_forces(x, self.triangles, self.wind, self._normals, f)


class DragTerm:
    """Linear air drag ``−c v``; its Jacobian is ``∂f/∂v = −c I``."""

    labels = ("drag",)

    def __init__(self, drag: float):
        self.drag = drag
        self._dv = None

    def add_force(self, x, v, f):
        if self._dv is None or self._dv.shape != v.shape:
            self._dv = np.empty_like(v)
        f -= np.multiply(v, self.drag, out=self._dv)  # no temporary per evaluation


class BendingTerm:
    """A material's flexural rigidity: ``−(Q ⊗ I₃) x`` (:mod:`cloth_sim.physics.bending`), where
    the springs are not summed on every core (those sum it in their gather)."""

    labels = ("bending",)

    def __init__(self, bending):
        self.bending = bending

    def add_force(self, x, v, f):
        self.bending.add_force(x, f)

    def energy(self, x) -> float:
        return self.bending.energy(x)


class Forces:
    """The force pipeline of one simulator: a list of terms compiled from the scene's non-zero
    ones (:attr:`terms`). Each term adds its force; the conservative ones report their energy; the
    springs and drag have Jacobians. Rebuild it (cheap) whenever stiffness, damping, gravity, wind
    or drag change: integrators receive the current pipeline with every step.
    """

    def __init__(
        self,
        model: ClothModel,
        stiffness: np.ndarray,
        damping: np.ndarray,
        gravity=(0.0, 0.0, -9.81),
        wind=None,
        drag: float = 0.0,
    ):
        self.model = model
        self.gravity = np.asarray(gravity, dtype=np.float64).reshape(3)
        wind = None if wind is None else np.asarray(wind, dtype=np.float64).reshape(3)
        self.drag = float(drag)
        bending = getattr(model, "bending", None)
        self.bending = bending if bending is not None and bending.Q.nnz else None
        self.spring_term = SpringTerm(
            model,
            np.asarray(stiffness, np.float64),
            np.asarray(damping, np.float64),
            self.bending,
        )
        # evaluation order: gravity first (it initialises the sum), then springs, wind, drag
        terms: list = (
            [GravityTerm(model.masses, self.gravity)] if np.any(self.gravity != 0) else []
        )
        if self.spring_term.active:
            terms.append(self.spring_term)
        if self.bending is not None and not (
            self.spring_term.active and self.spring_term.bending is not None
        ):
            terms.append(BendingTerm(self.bending))
        if wind is not None and np.any(wind != 0) and len(model.triangles):
            terms.append(WindTerm(model.triangles, wind, model.n_particles))
            self.wind = wind
        else:
            self.wind = None
        if self.drag > 0:
            terms.append(DragTerm(self.drag))
        self.terms = tuple(terms)
        order = [self.spring_term] + [t for t in terms if t is not self.spring_term]
        self.active_terms = tuple(label for t in order for label in t.labels)
        inv = 1.0 / model.masses
        inv[model.pinned] = 0.0
        self.inv_mass = inv[:, None].copy()
        # the same values per coordinate: an in-place product with the (n, 1) column makes numpy
        # allocate a temporary of the whole array on every evaluation
        self._inv_mass3 = np.repeat(self.inv_mass, 3, axis=1)
        self.evaluations = 0
        #: where the springs run on every core and are the last term, their gather takes the whole
        #: sum from here (gravity's force, or zeros) and the update after it
        #: (:meth:`gather_update`, :meth:`acceleration`); ``None`` otherwise
        self.gather_base = None
        st = self.spring_term
        if st.parallel and self.terms[-1] is st:
            if len(self.terms) == 2 and isinstance(self.terms[0], GravityTerm):
                self.gather_base = self.terms[0].force
            elif len(self.terms) == 1:
                self.gather_base = np.zeros((model.n_particles, 3))
        if self.gather_base is not None:  # runge_kutta_fused calls the parallel gather
            start_pool()

    # the spring term's arrays, which the implicit integrators assemble from
    springs = property(lambda self: self.spring_term.springs)
    rest = property(lambda self: self.spring_term.rest)
    k = property(lambda self: self.spring_term.k)
    c = property(lambda self: self.spring_term.c)
    kind = property(lambda self: self.spring_term.kind)
    with_damping = property(lambda self: self.spring_term.with_damping)

    @property
    def n_active_springs(self) -> int:
        """How many springs a force evaluation visits."""
        return len(self.spring_term.springs)

    def force(self, x: np.ndarray, v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Total force on each particle (pins included: their force is reported, not applied)."""
        f = np.empty_like(x) if out is None else out
        for term in self._start_sum(f):
            term.add_force(x, v, f)
        self.evaluations += 1
        return f

    def _start_sum(self, f: np.ndarray) -> tuple:
        """Set ``f`` to the sum's start — gravity when it is on (it initialises the sum: 0 + m·g
        is m·g), else 0 — and return the terms still to add."""
        terms = self.terms
        if terms and isinstance(terms[0], GravityTerm):
            np.copyto(f, terms[0].force)
            return terms[1:]
        f[:] = 0.0
        return terms

    def gather_update(self, x, v, out, dt: float, mode: int, xo, vo, stage=None) -> None:
        """One force evaluation with an update fused into the springs' gather, where
        :attr:`fuses_stages` (the springs summed on every core, and the last term): ``mode`` one of
        :func:`spring_forces_gather`'s (:data:`GATHER_KICK_DRIFT`: symplectic Euler's ``v +=
        (f·m⁻¹)·dt``, ``x += v·dt`` into ``xo``, ``vo``; :data:`GATHER_RK_STAGE`: a Runge–Kutta
        stage, ``stage`` its arrays), the summed force in ``out``. The integrators' steps
        (:mod:`cloth_sim.integrators.explicit`) call it; what the update is belongs to them."""
        spring_forces_gather(
            x,
            v,
            self.spring_term.net,
            self.gather_base,
            out,
            self.inv_mass,
            dt,
            mode,
            xo,
            vo,
            NO_STAGE if stage is None else stage,
        )
        self.evaluations += 1

    def acceleration(
        self, x: np.ndarray, v: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """``M⁻¹ f``, zero on pinned particles. Where the springs are summed on every core and are
        the last term, the division by the mass runs inside their gather (the same bits)."""
        a = np.empty_like(x) if out is None else out
        base = self.gather_base
        if base is not None:
            spring_forces_gather(
                x,
                v,
                self.spring_term.net,
                base,
                a,
                self.inv_mass,
                0.0,
                GATHER_ACCELERATION,
                NO_STATE,
                NO_STATE,
                NO_STAGE,
            )
            self.evaluations += 1
            return a
        self.force(x, v, a)
        a *= self._inv_mass3
        return a

    @property
    def fuses_stages(self) -> bool:
        """Whether :meth:`gather_update` applies (the springs on every core, and last)."""
        return self.gather_base is not None

    def implicit_force(self, x: np.ndarray, v: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The force of the terms :meth:`jacobians` differentiates, into ``out``: the springs
        (elastic and damping), the bending and the drag; without gravity and the wind, which the
        implicit methods take at the step's start."""
        out[:] = 0.0
        for term in self.terms:
            if not isinstance(term, (GravityTerm, WindTerm)):
                term.add_force(x, v, out)
        return out

    def spring_energy(self, x: np.ndarray) -> float:
        """The elastic energy: the springs' and, with a material's bending, the bending's."""
        e = self.spring_term.energy(x)
        if self.bending is not None:
            e += self.bending.energy(x)
        return e

    def jacobians(self, x: np.ndarray, v: np.ndarray, clamp: bool = False):
        """``(∂f/∂x, ∂f/∂v)`` as ``3n×3n`` sparse matrices (row ``3i + a`` is component ``a`` of
        the force on particle ``i``), exact for every term that depends on the state: Hooke and the
        Choi–Ko interactions, spring damping (including its dependence on positions) and drag.
        Gravity is constant. Wind is left out: its force depends on the normals of the adjacent
        triangles, and every implicit method here treats it explicitly. ``clamp`` drops the
        compressive, indefinite part of the elastic blocks, as the implicit integrators may.

        The blocks come from :meth:`SpringTerm.jacobian_blocks`, the kernel Baraff–Witkin's
        assembly uses, so the finite-difference tests of this method cover the solver's matrix."""
        n = len(x)
        springs = self.spring_term.springs
        kx, dx, cv = self.spring_term.jacobian_blocks(x, v, clamp)
        # ∂f_j/∂x_i is kxᵀ (= kx) for the elastic part and +dx for damping, whose r = v_j − v_i and
        # u both change sign with the pair's order
        dfdx = spring_coupling_matrix(springs, kx + dx, np.transpose(kx, (0, 2, 1)) + dx, n)
        dfdv = spring_coupling_matrix(springs, cv, cv, n)
        if self.bending is not None:
            dfdx = dfdx - self.bending.hessian()
        if self.drag > 0:
            dfdv = dfdv - self.drag * sp.identity(3 * n, format="csr")
        return dfdx.tocsr(), dfdv.tocsr()


def spring_sums(springs: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """``Σ_j w_ij`` per particle over the springs it belongs to (a graph Laplacian's diagonal)."""
    return np.bincount(
        springs.ravel(), weights=np.repeat(np.asarray(w, np.float64), 2), minlength=n
    )


def spring_coupling_matrix(
    springs: np.ndarray, row_i: np.ndarray, row_j: np.ndarray, n: int
) -> sp.csr_matrix:
    """Sparse ``3n×3n`` matrix coupling each spring's two particles ``(i, j)``: block ``(i, j)`` is
    ``row_i[s]`` and block ``(i, i)`` is ``−row_i[s]``; block ``(j, i)`` is ``row_j[s]`` and
    ``(j, j)`` is ``−row_j[s]`` (duplicates add). It is the pattern of every pairwise force's
    Jacobian, and with ``row_i = row_j = −k uuᵀ`` the stiffness matrix ``K``."""
    m = len(springs)
    i, j = springs[:, 0], springs[:, 1]
    ar = np.arange(3)
    rows, cols, vals = [], [], []
    for a, b, blocks in ((i, j, row_i), (i, i, -row_i), (j, i, row_j), (j, j, -row_j)):
        rows.append(np.broadcast_to((3 * a)[:, None, None] + ar[None, :, None], (m, 3, 3)).ravel())
        cols.append(np.broadcast_to((3 * b)[:, None, None] + ar[None, None, :], (m, 3, 3)).ravel())
        vals.append(np.ascontiguousarray(blocks).ravel())
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n)
    )
