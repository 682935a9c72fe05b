"""Implicit integrators: Baraff & Witkin's implicit Euler, its prefactored form and Kang's method.

All three take one linearised step of backward Euler (the review's eqs. 1.16–1.18),

    (M − dt·∂f/∂v − dt²·∂f/∂x) Δv = dt·(f + dt·∂f/∂x·v),    v ← v + Δv,    x ← x + dt·v,

and differ in the matrix they use and how they solve with it:

* ``implicit_euler`` (Baraff & Witkin 1998): the analytic Jacobians of the springs (Hooke and the
  Choi–Ko interactions), their damping and drag, refilled every step into a sparsity pattern built
  once; solved by block-Jacobi-preconditioned conjugate gradients or a direct sparse solve.
* ``implicit_euler_prefactored`` (eqs. 1.19–1.20): ∂f/∂x replaced by the constant graph matrix
  ``H`` (``H_ij = k_ij``, ``H_ii = −Σ_j k_ij``, the same for each coordinate) and ∂f/∂v by ``C``
  built the same way from the damping coefficients, so the matrix is constant: one sparse Cholesky
  factorisation (``cholespy``) serves every step until stiffness, damping, drag or dt change.
* ``kang`` (Kang, Choi & Cho 2000): the same ``H`` with no solve at all; one Jacobi sweep per step
  with the neighbours' ``Δv`` from the previous step.

Pinned particles are eliminated: the unknowns are the free particles' velocity changes only, so
pins never move. Gravity and wind are explicit (in ``f``); wind depends on the positions through
the triangle normals and is not linearised.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..kernel_cache import keep_true
from ..physics import stability as stab
from ..physics.forces import incidence, spring_sums
from ..threads import start_pool
from . import kang_analysis
from .base import Integrator, Stability, matrices
from .registry import register

SOLVERS = ("cg", "direct")


# --------------------------------------------------------------------------- pattern
def _block_pattern(springs: np.ndarray, free_index: np.ndarray, n_free: int):
    """CSR pattern over the free degrees of freedom of ``Σ`` spring blocks plus the diagonal.

    Returns ``(indptr, indices, slot, dslot)``: ``slot[s, b, p, q]`` is where entry ``(p, q)`` of
    block ``b`` (0: ii, 1: jj, 2: ij, 3: ji) of spring ``s`` lives in the data array (−1 where a
    pin eliminates it), ``dslot[i, p]`` the diagonal entry of particle ``i``'s coordinate ``p``."""
    i, j = springs[:, 0], springs[:, 1]
    pairs = np.stack(
        [np.stack([i, i], 1), np.stack([j, j], 1), np.stack([i, j], 1), np.stack([j, i], 1)], 1
    )  # (m, 4, 2)
    rp = free_index[pairs[..., 0]]  # (m, 4) free particle index of the row, −1 if pinned
    cp = free_index[pairs[..., 1]]
    m = len(springs)
    ar = np.arange(3)
    rows = np.broadcast_to(3 * rp[:, :, None, None] + ar[:, None], (m, 4, 3, 3))
    cols = np.broadcast_to(3 * cp[:, :, None, None] + ar[None, :], (m, 4, 3, 3))
    keep = np.broadcast_to((rp >= 0)[:, :, None, None] & (cp >= 0)[:, :, None, None], (m, 4, 3, 3))
    nd = 3 * n_free
    diag = np.arange(nd)
    keys = np.concatenate([(rows * nd + cols)[keep], diag * nd + diag])
    uniq, inverse = np.unique(keys, return_inverse=True)
    slot = np.full(keep.shape, -1, dtype=np.int64)
    slot[keep] = inverse[: int(keep.sum())]
    dslot_free = inverse[int(keep.sum()) :]
    dslot = np.full((len(free_index), 3), -1, dtype=np.int64)
    free = free_index >= 0
    dslot[free] = dslot_free.reshape(-1, 3)
    urow = uniq // nd
    indptr = np.zeros(nd + 1, dtype=np.int64)
    np.add.at(indptr, urow + 1, 1)
    indptr = np.cumsum(indptr)
    indices = (uniq % nd).astype(np.int32)
    return indptr.astype(np.int32), indices, slot, dslot


@numba.njit(cache=True)
def _assemble_baraff_witkin(springs, kx, cv, f, v, h, diag, slot, dslot, data, rhs):
    """Fill ``data`` with ``M − h·∂f/∂v − h²·∂f/∂x`` and ``rhs`` with ``h·(f + h·∂f/∂x·v)`` from
    the springs' Jacobian blocks ``kx`` (elastic) and ``cv`` (damping), as
    :meth:`~cloth_sim.physics.forces.SpringTerm.jacobian_blocks` gives them (the same blocks
    :meth:`~cloth_sim.physics.forces.Forces.jacobians` reports). ``diag[i]`` is ``m_i + h·drag``.
    The damping force's dependence on positions is left out (it would make the matrix unsymmetric),
    as Baraff & Witkin do."""
    data[:] = 0.0
    _baraff_witkin_rhs(springs, kx, f, v, h, rhs)
    for p in range(f.shape[0]):
        for a in range(3):
            d = dslot[p, a]
            if d >= 0:
                data[d] += diag[p]
    h2 = h * h
    for s in range(springs.shape[0]):
        for b in range(4):
            sign = 1.0 if b < 2 else -1.0
            for p in range(3):
                for q in range(3):
                    e = slot[s, b, p, q]
                    if e >= 0:
                        data[e] += sign * (h * cv[s, p, q] + h2 * kx[s, p, q])


@numba.njit(cache=True)
def _baraff_witkin_rhs(springs, kx, f, v, h, rhs):
    """``rhs = h·(f + h·∂f/∂x·v)`` from the springs' elastic blocks ``kx``."""
    h2 = h * h
    for p in range(f.shape[0]):
        for a in range(3):
            rhs[p, a] = h * f[p, a]
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        for p in range(3):
            kr = 0.0
            for q in range(3):
                kr += kx[s, p, q] * (v[j, q] - v[i, q])
            rhs[i, p] += h2 * kr
            rhs[j, p] -= h2 * kr


#: a symmetric 3×3 block stored as its upper triangle: (0,0) (0,1) (0,2) (1,1) (1,2) (2,2)
_SYM = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
#: CG's sums run over this many fixed slices of the particles, each summed on one core and the
#: slices' sums added in order: the same bits at any thread count
_SLICES = 64


@numba.njit(cache=True)
def _system_blocks(springs, kx, cv, f, v, h, diag, rhs, blocks, D):
    """The Baraff–Witkin system without its matrix: ``rhs`` as :func:`_assemble_baraff_witkin`
    fills it, each spring's coupling block ``B_s = h·cv + h²·kx`` into ``blocks`` and each
    particle's diagonal block ``m_i + h·drag + Σ_{s∋i} B_s`` into ``D``, both symmetric and kept as
    their upper triangles (:data:`_SYM`): ``A`` is then ``(A·x)_i = D_i·x_i − Σ_{s∋i} B_s·x_j``
    over the free ``j``."""
    _baraff_witkin_rhs(springs, kx, f, v, h, rhs)
    h2 = h * h
    for p in range(f.shape[0]):
        D[p, 0] = diag[p]
        D[p, 1] = 0.0
        D[p, 2] = 0.0
        D[p, 3] = diag[p]
        D[p, 4] = 0.0
        D[p, 5] = diag[p]
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        for u in range(6):
            p, q = _SYM[u]
            e = h * cv[s, p, q] + h2 * kx[s, p, q]
            blocks[s, u] = e
            D[i, u] += e
            D[j, u] += e


@numba.njit(cache=True, inline="always")
def _sym_product(b, k, x, o):
    """``b[k]`` (a symmetric block's upper triangle) times ``x[3o:3o+3]``."""
    x0, x1, x2 = x[3 * o], x[3 * o + 1], x[3 * o + 2]
    return (
        b[k, 0] * x0 + b[k, 1] * x1 + b[k, 2] * x2,
        b[k, 1] * x0 + b[k, 3] * x1 + b[k, 4] * x2,
        b[k, 2] * x0 + b[k, 4] * x1 + b[k, 5] * x2,
    )


@numba.njit(cache=True, parallel=True)
def _system_product(particles, ptr, adj, other, blocks, D, x, out, partial):
    """``out = A·x`` over the free particles (``particles[k]``: the particle of free index ``k``;
    ``other[e]``: the free index of the far end of incidence ``e``'s spring, −1 for a pin), each
    particle summing its springs in incidence order, and ``partial[c, 0]`` the sum of ``x·out``
    over slice ``c`` of the particles; the slices on every core (the same bits at any thread
    count). Reads 6 numbers per spring and particle where the assembled CSR matrix streamed 9 per
    coupling and index (docs/BENCHMARKS.md §7)."""
    nf = particles.shape[0]
    for c in numba.prange(_SLICES):
        acc = 0.0
        for k in range(c * nf // _SLICES, (c + 1) * nf // _SLICES):
            p = particles[k]
            a0, a1, a2 = _sym_product(D, p, x, k)
            for e in range(ptr[p], ptr[p + 1]):
                o = other[e]
                if o < 0:
                    continue
                b0, b1, b2 = _sym_product(blocks, adj[e], x, o)
                a0 -= b0
                a1 -= b1
                a2 -= b2
            out[3 * k] = a0
            out[3 * k + 1] = a1
            out[3 * k + 2] = a2
            acc += x[3 * k] * a0 + x[3 * k + 1] * a1 + x[3 * k + 2] * a2
        partial[c, 0] = acc


@numba.njit(cache=True)
def _block_inverses(particles, D, inv):
    """``inv[k]``: the inverse of free particle ``k``'s 3×3 diagonal block (symmetric positive
    definite, as the matrix is; so is its inverse, kept as its upper triangle), by its adjugate."""
    for k in range(particles.shape[0]):
        p = particles[k]
        a, b, c, d, e, f = D[p, 0], D[p, 1], D[p, 2], D[p, 3], D[p, 4], D[p, 5]
        c00 = d * f - e * e
        c01 = c * e - b * f
        c02 = b * e - c * d
        det = a * c00 + b * c01 + c * c02
        inv[k, 0] = c00 / det
        inv[k, 1] = c01 / det
        inv[k, 2] = c02 / det
        inv[k, 3] = (a * f - c * c) / det
        inv[k, 4] = (b * c - a * e) / det
        inv[k, 5] = (a * d - b * b) / det


@numba.njit(cache=True, parallel=True)
def _cg_update(alpha, x, r, p, q, inv, z, partial):
    """``x += α·p``, ``r −= α·q``, ``z = P⁻¹·r`` (the blocks' inverses), and per slice the sums of
    ``r·r`` and ``r·z`` into ``partial[c, 1:3]``, in one pass on every core."""
    nf = inv.shape[0]
    for c in numba.prange(_SLICES):
        rr = 0.0
        rz = 0.0
        for k in range(c * nf // _SLICES, (c + 1) * nf // _SLICES):
            for a in range(3):
                x[3 * k + a] += alpha * p[3 * k + a]
                r[3 * k + a] -= alpha * q[3 * k + a]
            z0, z1, z2 = _sym_product(inv, k, r, k)
            z[3 * k] = z0
            z[3 * k + 1] = z1
            z[3 * k + 2] = z2
            r0, r1, r2 = r[3 * k], r[3 * k + 1], r[3 * k + 2]
            rr += r0 * r0 + r1 * r1 + r2 * r2
            rz += r0 * z0 + r1 * z1 + r2 * z2
        partial[c, 1] = rr
        partial[c, 2] = rz


@numba.njit(cache=True, parallel=True)
def _cg_direction(beta, z, p):
    """``p = z + β·p`` on every core."""
    for i in numba.prange(p.shape[0]):
        p[i] = z[i] + beta * p[i]


@numba.njit(cache=True)
def _slices_sum(partial, col):
    """The slices' sums of column ``col``, added in slice order. (Its callers pass ``col`` as
    ``np.int64``: a constant argument compiles a signature of its own, three where one does.)"""
    acc = 0.0
    for c in range(partial.shape[0]):
        acc += partial[c, col]
    return acc


@numba.njit(cache=True)
def _dot(a, b):
    """``a·b`` summed in index order (one core: the same bits at any thread count)."""
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@numba.njit(cache=True)
def _pcg(system, inv, b, x, rtol, maxiter, r, z, p, q, partial):
    """Conjugate gradients on ``A·x = b`` (``x`` holds the start and receives the solution), ``A``
    applied by :func:`_system_product` from ``system = (particles, ptr, adj, other, blocks, D)``,
    preconditioned with the 3×3 diagonal blocks' inverses ``inv``; stops when ``|b − A·x| ≤
    rtol·|b|`` (the recurrence's residual, as ``scipy.sparse.linalg.cg``). Returns the iterations
    taken, or −1 when ``maxiter`` did not reach the tolerance. ``r``, ``z``, ``p``, ``q`` are
    scratch of ``b``'s length, ``partial`` of ``(_SLICES, 3)``. Each iteration is three passes on
    every core — the product with ``p·Ap``, the update with ``r·r`` and ``r·z``, the new direction
    — whose sums are taken over fixed slices (the same bits at any thread count)."""
    particles, ptr, adj, other, blocks, D = system
    n = b.shape[0]
    _system_product(particles, ptr, adj, other, blocks, D, x, q, partial)
    for i in range(n):
        r[i] = b[i] - q[i]
        p[i] = 0.0
    stop = rtol * rtol * _dot(b, b)
    # r·r and z = P⁻¹r, r·z, through the update with α = 0 (x and r unchanged)
    _cg_update(0.0, x, r, p, q, inv, z, partial)
    rr = _slices_sum(partial, np.int64(1))
    if rr <= stop:
        return 0
    rz = _slices_sum(partial, np.int64(2))
    for i in range(n):
        p[i] = z[i]
    for it in range(1, maxiter + 1):
        _system_product(particles, ptr, adj, other, blocks, D, p, q, partial)
        alpha = rz / _slices_sum(partial, np.int64(0))
        _cg_update(alpha, x, r, p, q, inv, z, partial)
        rr = _slices_sum(partial, np.int64(1))
        if rr <= stop:
            return it
        rz_new = _slices_sum(partial, np.int64(2))
        beta = rz_new / rz
        rz = rz_new
        _cg_direction(beta, z, p)
    return -1


@numba.njit(cache=True)
def graph_product(springs, w, v, out):
    """``out_i += Σ_j w_ij (v_j − v_i)``: the graph matrix (``H`` or ``C``) times ``v``."""
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        ws = w[s]
        for a in range(3):
            d = ws * (v[j, a] - v[i, a])
            out[i, a] += d
            out[j, a] -= d


@numba.njit(cache=True)
def _kang_sweeps(f, v, dv, springs, k, h, sweeps, inv_den, acc, new):
    """Kang et al.'s update ``Δv_i = (h f_i + h² Σ_j k_ij (v_j − v_i + Δv_j)) / (m_i + h² Σ_j
    k_ij)``, ``sweeps`` Jacobi sweeps starting from ``dv`` (the previous step's ``Δv``); result in
    ``dv``. ``inv_den`` is ``1/(m_i + h² Σ_j k_ij)``, 0 for pinned particles."""
    n = f.shape[0]
    h2 = h * h
    for _ in range(sweeps):
        for p in range(n):
            for a in range(3):
                acc[p, a] = h * f[p, a]
        for s in range(springs.shape[0]):
            i = springs[s, 0]
            j = springs[s, 1]
            ks = h2 * k[s]
            for a in range(3):
                acc[i, a] += ks * (v[j, a] - v[i, a] + dv[j, a])
                acc[j, a] += ks * (v[i, a] - v[j, a] + dv[i, a])
        for p in range(n):
            for a in range(3):
                new[p, a] = acc[p, a] * inv_den[p]
        dv[:] = new


# --------------------------------------------------------------------------- the constant matrix
def cholesky(A: sp.spmatrix):
    """A sparse Cholesky factorisation (``cholespy``) of the symmetric positive definite ``A``;
    ``None`` for an empty matrix. Its ``solve(b, x)`` takes one or several right-hand sides."""
    from cholespy import CholeskySolverD, MatrixType

    A = A.tocsc()
    if A.shape[0] == 0:
        return None
    return CholeskySolverD(
        A.shape[0],
        A.indptr.astype(np.int32),
        A.indices.astype(np.int32),
        np.ascontiguousarray(A.data),
        MatrixType.CSC,
    )


def constant_system(model, forces, dt: float):
    """``M + dt·c_d·I + dt·C + dt²·H`` over the free particles: one ``n_free×n_free`` matrix (CSC)
    for the three coordinates, with ``H`` the graph Laplacian of the springs' linearised stiffness
    (a Choi–Ko buckling pair resists compression with ``k·max|h''|/L³``, far above ``k``: with
    ``k`` the prefactored matrix was too soft and the step diverged) and ``C`` that of their
    damping coefficients. Returns ``(A, h, w, index)``: ``h`` those stiffnesses, ``w = dt·c +
    dt²·h`` the Laplacian's weights and ``index`` each particle's row (−1 on pins, which are
    eliminated)."""
    free = ~model.pinned
    index = np.full(model.n_particles, -1, dtype=np.int64)
    n_free = int(free.sum())
    index[free] = np.arange(n_free)
    h = stab.springs_effective_stiffness(forces.kind, forces.rest, forces.k)
    w = dt * forces.c + dt * dt * h  # −(dt·C + dt²·H) off the diagonal, negated
    diag = spring_sums(forces.springs, w, model.n_particles) + model.masses + dt * forces.drag
    fi, fj = index[forces.springs[:, 0]], index[forces.springs[:, 1]]
    both = (fi >= 0) & (fj >= 0)
    rows = np.concatenate([fi[both], fj[both], np.arange(n_free)])
    cols = np.concatenate([fj[both], fi[both], np.arange(n_free)])
    vals = np.concatenate([-w[both], -w[both], diag[free]])
    A = sp.csc_matrix((vals, (rows, cols)), shape=(n_free, n_free))
    if forces.bending is not None:  # a material's bending: its constant Hessian, exactly
        A = A + (dt * dt) * forces.bending.Q[free][:, free].tocsc()
    A.sum_duplicates()
    return A, h, w, index


def system_key(forces, dt: float) -> tuple:
    """What :func:`constant_system` depends on besides the model (a new model, a new
    integrator)."""
    return (
        dt,
        forces.drag,
        forces.springs.copy(),
        forces.k.copy(),
        forces.c.copy(),
        forces.bending,
    )


def same_system(key, forces, dt: float) -> bool:
    """Whether ``key`` (:func:`system_key`) still describes ``forces`` and ``dt``."""
    return (
        key is not None
        and key[0] == dt
        and key[1] == forces.drag
        and np.array_equal(key[2], forces.springs)
        and np.array_equal(key[3], forces.k)
        and np.array_equal(key[4], forces.c)
        and key[5] is forces.bending
    )


# --------------------------------------------------------------------------- base
class _LinearisedImplicitEuler(Integrator):
    order = 1
    force_point = 1.0
    implicit = True
    stability = Stability.UNCONDITIONAL
    counter_names = ("solves",)

    @classmethod
    def amplification(cls, h, omega, zeta):
        # (1 + 2ζωh + ω²h²) Δv = h(−ω² x − 2ζω v − h ω² v); exact for a linear oscillator
        w2, c = omega * omega, 2.0 * zeta * omega
        den = 1.0 + h * c + h * h * w2
        dv_x, dv_v = -h * w2 / den, -h * (c + h * w2) / den
        return matrices([[1.0 + h * dv_x, h * (1.0 + dv_v)], [dv_x, 1.0 + dv_v]])

    def _free(self):
        free = ~self.model.pinned
        index = np.full(self.model.n_particles, -1, dtype=np.int64)
        index[free] = np.arange(int(free.sum()))
        return free, index


@register
class ImplicitEuler(_LinearisedImplicitEuler):
    """Baraff & Witkin (1998): one Newton step of backward Euler with the analytic spring
    Jacobians.

    Options (keyword arguments of the constructor, or attributes):

    * ``solver`` — ``"cg"``: conjugate gradients preconditioned with each particle's 3×3 diagonal
      block, compiled (:func:`_pcg`), warm-started from the last two steps' ``Δv``, stopping at
      ``cg_tolerance`` (relative residual); when it has not converged after ``cg_max_iterations``
      (1000) the step is solved directly instead, and so are the next 16 (the counter
      ``direct_fallbacks``): a stiff or heavily damped material makes the system ill-conditioned.
      The cap is well below what a direct solve costs (docs/BENCHMARKS.md §7); ``"direct"``: a
      direct solve every step, sparse Cholesky (``cholespy``) of the symmetric positive definite
      matrix, or SuperLU's LU when ``clamp_compression`` is off and the matrix may be indefinite.
    * ``clamp_compression`` (default on) — drop the compressive, indefinite part of each spring's
      stiffness block (``E''`` and ``E'/l`` below zero), which keeps the matrix symmetric positive
      definite so CG applies at any step. It changes the Jacobian, not the force: the step stays
      first-order accurate here, but the linearisation is no longer exact for compressed springs,
      so it costs accuracy there, and a method built on the exact Jacobian (a BDF2 step, a full
      Newton iteration) would lose its higher order.

    The matrix is assembled from the spring term's Jacobian blocks (the ones
    :meth:`~cloth_sim.physics.forces.Forces.jacobians` reports and the tests check by finite
    differences) refilled into a sparsity pattern built once. The damping force's dependence on
    positions is left out of the matrix (Baraff & Witkin do the same: it is small and unsymmetric).
    Wind and gravity are explicit.
    """

    name = "implicit_euler"
    counter_names = ("solves", "cg_iterations", "last_cg_iterations", "direct_fallbacks")
    takes_bending = True

    def __init__(
        self,
        model,
        solver: str = "cg",
        cg_tolerance: float = 1e-6,
        cg_max_iterations: int = 1000,
        clamp_compression: bool = True,
    ):
        super().__init__(model)
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        if not (cg_tolerance > 0 and math.isfinite(cg_tolerance)):
            raise ValueError(f"cg_tolerance must be a finite number > 0, got {cg_tolerance}")
        if int(cg_max_iterations) < 1:
            raise ValueError(f"cg_max_iterations must be >= 1, got {cg_max_iterations}")
        self.solver = solver
        if solver == "cg":  # _pcg calls the parallel products
            start_pool()
        self.cg_tolerance = float(cg_tolerance)
        self.cg_max_iterations = int(cg_max_iterations)
        self.clamp_compression = bool(clamp_compression)
        self._pattern_springs = None
        self._direct_steps = 0

    #: After CG failed to converge, this many steps are solved directly before CG is tried again.
    DIRECT_AFTER_FALLBACK = 16

    def reset(self, state, forces, dt):
        # the warm start is stale after a jump of the state or of dt
        state.history.pop("dv", None)
        state.history.pop("dv_before", None)
        self._direct_steps = 0

    def _build(self, springs):
        free, index = self._free()
        n_free = int(free.sum())
        indptr, indices, slot, dslot = _block_pattern(springs, index, n_free)
        self._free_dofs = np.flatnonzero(np.repeat(free, 3))
        self._n = 3 * n_free
        self._slot, self._dslot = slot, dslot
        self._matrix = sp.csr_matrix(
            (np.zeros(len(indices)), indices, indptr), shape=(self._n, self._n)
        )
        self._matrix.has_sorted_indices = True
        self._rhs = np.empty((self.model.n_particles, 3))
        self._pattern_springs = springs
        # CG's matrix-free operator: each free particle's springs and their far ends' free indices
        ptr, adj, sign = incidence(springs, len(index))
        far = np.where(sign > 0, springs[adj, 1], springs[adj, 0])
        self._system = (
            np.flatnonzero(free).astype(np.int32),
            ptr.astype(np.int32),
            adj.astype(np.int32),
            index[far].astype(np.int32),
            np.empty((len(springs), 6)),
            np.empty((len(index), 6)),
        )
        self._block_inv = np.empty((n_free, 6))
        self._cg_work = np.empty((6, 3 * n_free))  # b, b/s, and CG's r, z, p, q
        self._cg_partial = np.empty((_SLICES, 3))
        self._y = np.empty(3 * n_free)
        self._jacobian = tuple(np.empty((len(springs), 3, 3)) for _ in range(3))
        self._diag = np.empty(len(index))

    def _pairs(self, forces):
        """The springs, and with a material's bending each pair its ``Q`` couples after them
        (:meth:`~cloth_sim.physics.bending.Bending.couplings`), with constant Jacobian blocks
        ``−Q_ij·I`` (:attr:`_bend_blocks`). Kept while the forces' springs and bending are the
        same objects."""
        springs, bending = forces.springs, forces.bending
        if bending is None:
            self._bend_blocks = None
            return springs
        key = self.__dict__.get("_pairs_key")
        if key is None or key[0] is not springs or key[1] is not bending:
            pairs, q = bending.couplings()
            self._bend_blocks = -q[:, None, None] * np.eye(3)
            self._pairs_key = (springs, bending, np.concatenate([springs, pairs]))
        return self._pairs_key[2]

    def step(self, state, forces, dt):
        x, v = state.x, state.v
        springs = self._pairs(forces)
        if self._pattern_springs is not springs and not (
            self._pattern_springs is not None and np.array_equal(self._pattern_springs, springs)
        ):
            self._build(springs)  # the set of active springs changed
            state.history.pop("dv", None)
            state.history.pop("dv_before", None)
        self._pattern_springs = springs
        f = forces.force(x, v, out=self._buffer("_f", x))
        m = len(forces.springs)
        kx, dxb, cv = self._jacobian
        forces.spring_term.jacobian_blocks(
            x, v, self.clamp_compression, position_damping=False, out=(kx[:m], dxb[:m], cv[:m])
        )
        if self._bend_blocks is not None:  # the bending's constant blocks after the springs'
            kx[m:] = self._bend_blocks
            cv[m:] = 0.0
        if self._n == 0:
            return
        diag = np.add(self.model.masses, dt * forces.drag, out=self._diag)
        dv = None
        if self.solver == "cg" and self._direct_steps == 0:
            _system_blocks(springs, kx, cv, f, v, dt, diag, self._rhs, *self._system[4:])
            # (mode="clip": with "raise" numpy buffers the output, a temporary of its size)
            b = np.take(self._rhs.reshape(-1), self._free_dofs, out=self._cg_work[0], mode="clip")
            dv = self._cg(b, state)
            if dv is None:  # the next steps go straight to the direct solve, then CG again
                self._direct_steps = self.DIRECT_AFTER_FALLBACK
        elif self._direct_steps:
            self._direct_steps -= 1
        if dv is None:  # the matrix itself, assembled
            A = self._matrix
            _assemble_baraff_witkin(
                springs, kx, cv, f, v, dt, diag, self._slot, self._dslot, A.data, self._rhs
            )
            last = state.history.get("dv")
            if last is not None:  # the warm start's second point, for when CG is tried again
                state.history["dv_before"] = last
            dv = state.history["dv"] = self._direct(A, self._rhs.ravel()[self._free_dofs])
        self.counters["solves"] += 1
        _update(x, v, self._system[0], dv, dt)

    def _direct(self, A, b):
        """A direct solve: sparse Cholesky (``cholespy``) when the matrix is symmetric positive
        definite (``clamp_compression``; no pivoting, so its cost does not depend on the values:
        docs/BENCHMARKS.md §7), SuperLU otherwise."""
        A = A.tocsc()
        if self.clamp_compression:
            dv = np.zeros_like(b)
            cholesky(A).solve(np.ascontiguousarray(b), dv)
            return dv
        # symmetric: a symmetric ordering and diagonal pivots halve SuperLU's time
        return splu(A, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True}).solve(b)

    def _cg(self, b, state):
        """CG on ``A·dv = b`` with ``A`` applied without assembling it (:func:`_system_product`,
        from each spring's 3×3 block), preconditioned with the inverses of the particles' 3×3
        diagonal blocks (a particle's own coupling, which the plain diagonal leaves out), compiled
        (:func:`_pcg`: the products on every core, the sums of the dot products in a fixed order,
        so the same bits at any thread count), warm-started from the last two steps' ``Δv`` (the
        state's ``history["dv"]``, which receives the solution, and ``history["dv_before"]``);
        solved as ``A·y = b/s`` with ``s`` the power of two nearest ``|b|`` (exact, so the iterates
        are those of the unscaled solve) so that a right-hand side near zero (a cloth coming to
        rest: its velocities decay into subnormal numbers) cannot make CG divide 0 by 0; ``b = 0``
        gives ``dv = 0``. ``None`` when it has not converged: the caller solves directly. Every
        array is the integrator's or the state's own: a step allocates none."""
        n = len(b)
        dv = state.history.get("dv")
        if dv is None or len(dv) != n:
            dv = state.history["dv"] = np.zeros(n)  # no warm start
        before = state.history.get("dv_before")  # the step before's Δv
        if before is None or len(before) != n:
            before = state.history["dv_before"] = dv.copy()
        # not np.linalg.norm: its BLAS threads spin on the cores for milliseconds after the call,
        # which slowed every product of the solve after it 2.4× on two cores
        norm = math.sqrt(_dot(b, b))
        self.counters["last_cg_iterations"] = 0
        if norm == 0.0:
            np.copyto(before, dv)
            dv[:] = 0.0
            return dv
        inv_scale = math.ldexp(1.0, -math.frexp(norm)[1])  # a power of two: scaling by it is exact
        _block_inverses(self._system[0], self._system[5], self._block_inv)
        # start from the last two steps' Δv extrapolated, 2·Δv₁ − Δv₂ (9 % fewer iterations than
        # from Δv₁ on the hanging 64×64 cloth at dt = 1/60; it is Δv₁ itself on the first step)
        y = np.multiply(dv, 2.0, out=self._y)
        y -= before
        y *= inv_scale
        np.copyto(before, dv)
        its = _pcg(
            self._system,
            self._block_inv,
            np.multiply(b, inv_scale, out=self._cg_work[1]),
            y,
            self.cg_tolerance,
            self.cg_max_iterations,
            *self._cg_work[2:],
            self._cg_partial,
        )
        count = self.cg_max_iterations if its < 0 else its
        self.counters["last_cg_iterations"] = count
        self.counters["cg_iterations"] += count
        if its < 0:
            self.counters["direct_fallbacks"] += 1
            return None
        return np.divide(y, inv_scale, out=dv)


@numba.njit(cache=True)
def _update(x, v, particles, dv, h):
    """``v += Δv`` on the free particles (``particles[k]`` takes ``dv[3k:3k+3]``), then ``x +=
    h·v``: the array expressions' operations, in one pass and without temporaries."""
    for k in range(particles.shape[0]):
        p = particles[k]
        for a in range(3):
            v[p, a] += dv[3 * k + a]
    for p in range(x.shape[0]):
        for a in range(3):
            x[p, a] += h * v[p, a]


@register
class ImplicitEulerPrefactored(_LinearisedImplicitEuler):
    """The review's eqs. 1.16–1.20: implicit Euler with the constant matrix ``M − dt·C − dt²·H``
    (``H_ij = k_ij``, ``H_ii = −Σ_j k_ij``; ``C`` the same from the damping coefficients; drag on
    the diagonal), one ``n×n`` matrix shared by the three coordinates. For Choi & Ko's buckling
    pairs ``k_ij`` is their linearised stiffness, the stiffer of the two branches
    (:func:`cloth_sim.physics.stability.effective_stiffness`); with the bare ``k`` the step
    diverges.

    It is symmetric positive definite, factorised once by sparse Cholesky (``cholespy``) and reused
    for every step; it is refactorised when stiffness, damping, drag, dt, pins or topology change
    (the counter ``factorizations`` counts them). ``H`` ignores the springs' directions and the
    Choi–Ko nonlinearity, so the step is stable but damps and distorts more than
    :class:`ImplicitEuler`.
    """

    name = "implicit_euler_prefactored"
    counter_names = ("solves", "factorizations")
    takes_bending = True
    _REFACTOR = frozenset({"stiffness", "damping", "drag", "dt"})

    def __init__(self, model):
        super().__init__(model)
        self._key = None
        self._solver = None
        self._stale = True

    def reset(self, state, forces, dt):
        self._stale = True

    def parameters_changed(self, changed):
        if changed & self._REFACTOR:
            self._stale = True

    def _ensure_factor(self, forces, dt):
        if same_system(self._key, forces, dt):
            self._stale = False
            return
        A, self._h, _, index = constant_system(self.model, forces, dt)
        n_free = A.shape[0]
        self._matrix = A
        self._solver = cholesky(A)
        self.counters["factorizations"] += 1
        self._key = system_key(forces, dt)
        self._free_mask = index >= 0
        self._rhs_full = np.empty((self.model.n_particles, 3))
        self._b = np.empty((n_free, 3))
        self._dv = np.empty((n_free, 3))
        self._stale = False

    def step(self, state, forces, dt):
        if self._stale:
            self._ensure_factor(forces, dt)
        x, v = state.x, state.v
        f = forces.force(x, v, out=self._buffer("_f", x))
        rhs = self._rhs_full
        rhs[:] = 0.0
        graph_product(forces.springs, self._h, v, rhs)  # H v
        if forces.bending is not None:
            rhs -= forces.bending.Q @ v  # and the bending's, −Q v
        rhs *= dt
        rhs += f
        rhs *= dt
        if self._solver is None:
            return
        np.copyto(self._b, rhs[self._free_mask])
        self._solver.solve(self._b, self._dv)
        self.counters["solves"] += 1
        v[self._free_mask] += self._dv
        x += dt * v


@register
class Kang(_LinearisedImplicitEuler):
    """Kang, Choi & Cho (2000), the approximated implicit method: the linear system of
    :class:`ImplicitEulerPrefactored` without damping in the matrix, not solved but approximated
    per particle by ``sweeps`` Jacobi sweeps (the paper: one),

        Δv_i = (dt·f_i + dt²·Σ_j k_ij·(v_j − v_i + Δv_j)) / (m_i + dt²·Σ_j k_ij),

    with the neighbours' ``Δv_j`` from the previous step (kept in ``state.history["dv"]``). Spring
    damping stays explicit in ``f``. Not unconditionally stable: the lagged ``Δv_j`` and explicit
    damping limit the step, which its own analysis finds
    (:func:`cloth_sim.integrators.kang_analysis.kang_stable_dt`: a von Neumann analysis of the
    grid, tens of milliseconds; the whole linearised step for other spring networks), and the
    simulator's guard catches a blow-up like any explicit method's. The per-particle scaling does
    not conserve linear momentum while ``Δv`` changes from step to step.
    """

    name = "kang"
    # f(xₙ) plus a stiffness correction from neighbours' Δv lagged by a step: between the two
    force_point = 0.5
    stability = Stability.ANALYSIS
    conserves_momentum = False

    @classmethod
    def amplification(cls, h, omega, zeta):
        raise NotImplementedError(
            "kang has no scalar mode model (its lagged neighbours couple the "
            "modes): see cloth_sim.integrators.kang_analysis.kang_stable_dt"
        )

    def __init__(self, model, sweeps: int = 1):
        super().__init__(model)
        if int(sweeps) < 1:
            raise ValueError(f"sweeps must be >= 1, got {sweeps}")
        self.sweeps = int(sweeps)
        self._den_of = None

    def analysis_key(self):
        return (self.sweeps,)

    def analyse(self, analysis):
        return kang_analysis.kang_stable_dt(
            self.model,
            analysis.k,
            analysis.c,
            analysis.drag,
            self.sweeps,
            omega=analysis.mode.omega,
        )

    def reset(self, state, forces, dt):
        state.history["dv"] = np.zeros_like(state.x)

    def _inverse_denominators(self, forces, dt):
        """``1/(m_i + dt²·Σ_j k_ij)``, 0 on pins; rebuilt only when the forces or dt change."""
        if self._den_of != (forces, dt):
            model = self.model
            den = model.masses + dt * dt * spring_sums(forces.springs, forces.k, model.n_particles)
            self._inv_den = np.where(model.pinned, 0.0, 1.0 / den)
            self._den_of = (forces, dt)
        return self._inv_den

    def step(self, state, forces, dt):
        x, v, dv = state.x, state.v, state.history["dv"]
        f = forces.force(x, v, out=self._buffer("_f", x))
        _kang_sweeps(
            f,
            v,
            dv,
            forces.springs,
            forces.k,
            dt,
            self.sweeps,
            self._inverse_denominators(forces, dt),
            self._buffer("_acc", x),
            self._buffer("_new", x),
        )
        self.counters["solves"] += 1
        v += dv
        x += np.multiply(v, dt, out=self._buffer("_new", x))  # no temporary


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
