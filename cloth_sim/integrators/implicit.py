"""Implicit integrators: Baraff & Witkin's implicit Euler, its prefactored form and Kang's method.

All three take one linearised step of backward Euler (the review's eqs. 1.16–1.18),

    (M − dt·∂f/∂v − dt²·∂f/∂x) Δv = dt·(f + dt·∂f/∂x·v),    v ← v + Δv,    x ← x + dt·v,

and differ in the matrix they use and how they solve with it:

* ``implicit_euler`` (Baraff & Witkin 1998): the analytic Jacobians of the springs (Hooke and the
  Choi–Ko interactions), their damping and drag, refilled every step into a sparsity pattern built
  once; solved by Jacobi-preconditioned conjugate gradients or a direct sparse solve.
* ``implicit_euler_prefactored`` (eqs. 1.19–1.20): ∂f/∂x replaced by the constant graph matrix
  ``H`` (``H_ij = k_ij``, ``H_ii = −Σ_j k_ij``, the same for each coordinate) and ∂f/∂v by ``C`` built
  the same way from the damping coefficients, so the matrix is constant: one sparse Cholesky
  factorisation (``cholespy``) serves every step until stiffness, damping, drag or dt change.
* ``kang`` (Kang, Choi & Cho 2000): the same ``H`` with no solve at all; one Jacobi sweep per step
  with the neighbours' ``Δv`` from the previous step.

Pinned particles are eliminated: the unknowns are the free particles' velocity changes only, so pins
never move. Gravity and wind are explicit (in ``f``); wind depends on the positions through the
triangle normals and is not linearised.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import cg, eigs, splu

from ..forces import BUCKLE_TABLE, _stiffness_coefficients, spring_vector
from . import register
from .base import Integrator

SOLVERS = ("cg", "direct")


# --------------------------------------------------------------------------- pattern
def _block_pattern(springs: np.ndarray, free_index: np.ndarray, n_free: int):
    """CSR pattern over the free degrees of freedom of ``Σ`` spring blocks plus the diagonal.

    Returns ``(indptr, indices, slot, dslot)``: ``slot[s, b, p, q]`` is where entry ``(p, q)`` of
    block ``b`` (0: ii, 1: jj, 2: ij, 3: ji) of spring ``s`` lives in the data array (−1 where a pin
    eliminates it), ``dslot[i, p]`` the diagonal entry of particle ``i``'s coordinate ``p``."""
    i, j = springs[:, 0], springs[:, 1]
    pairs = np.stack([np.stack([i, i], 1), np.stack([j, j], 1), np.stack([i, j], 1),
                      np.stack([j, i], 1)], 1)  # (m, 4, 2)
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
    dslot_free = inverse[int(keep.sum()):]
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
def _assemble_baraff_witkin(x, v, f, springs, rest, k, c, kind, tab, clamp, h, diag, slot, dslot,
                            data, rhs):
    """Fill ``data`` with ``M − h·∂f/∂v − h²·∂f/∂x`` and ``rhs`` with ``h·(f + h·∂f/∂x·v)``.

    ``diag[i]`` is ``m_i + h·drag``. The damping force's dependence on positions is left out (it
    would make the matrix unsymmetric), as Baraff & Witkin do."""
    data[:] = 0.0
    n = x.shape[0]
    for p in range(n):
        for a in range(3):
            rhs[p, a] = h * f[p, a]
            d = dslot[p, a]
            if d >= 0:
                data[d] += diag[p]
    h2 = h * h
    blk = np.empty((3, 3))
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        dx, dy, dz, l = spring_vector(x, i, j)
        if l < 1e-300:
            continue
        u0, u1, u2 = dx / l, dy / l, dz / l
        a, t = _stiffness_coefficients(l, rest[s], k[s], kind[s], tab, clamp)
        cs = c[s]
        r0, r1, r2 = v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], v[j, 2] - v[i, 2]
        ut = u0 * r0 + u1 * r1 + u2 * r2
        # K r = a u (u·r) + t (r − u (u·r))
        kr0 = (a - t) * ut * u0 + t * r0
        kr1 = (a - t) * ut * u1 + t * r1
        kr2 = (a - t) * ut * u2 + t * r2
        rhs[i, 0] += h2 * kr0
        rhs[i, 1] += h2 * kr1
        rhs[i, 2] += h2 * kr2
        rhs[j, 0] -= h2 * kr0
        rhs[j, 1] -= h2 * kr1
        rhs[j, 2] -= h2 * kr2
        uu = (u0, u1, u2)
        for p in range(3):
            for q in range(3):
                w = uu[p] * uu[q]
                blk[p, q] = h * cs * w + h2 * (a * w + t * ((1.0 if p == q else 0.0) - w))
        for b in range(4):
            sign = 1.0 if b < 2 else -1.0
            for p in range(3):
                for q in range(3):
                    e = slot[s, b, p, q]
                    if e >= 0:
                        data[e] += sign * blk[p, q]


@numba.njit(cache=True)
def _graph_product(springs, w, v, out):
    """``out_i += Σ_j w_ij (v_j − v_i)``: the graph matrix (``H`` or ``C``) times ``v``."""
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        ws = w[s]
        for a in range(3):
            d = ws * (v[j, a] - v[i, a])
            out[i, a] += d
            out[j, a] -= d


def _spring_sums(springs: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """``Σ_j w_ij`` per particle over the springs it belongs to (the graph matrix's diagonal)."""
    return np.bincount(springs.ravel(), weights=np.repeat(w, 2), minlength=n)


@numba.njit(cache=True)
def _kang_sweeps(f, v, dv, springs, k, h, sweeps, inv_den, acc, new):
    """Kang et al.'s update ``Δv_i = (h f_i + h² Σ_j k_ij (v_j − v_i + Δv_j)) / (m_i + h² Σ_j k_ij)``,
    ``sweeps`` Jacobi sweeps starting from ``dv`` (the previous step's ``Δv``); result in ``dv``.
    ``inv_den`` is ``1/(m_i + h² Σ_j k_ij)``, 0 for pinned particles."""
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


# --------------------------------------------------------------------------- base
class _LinearisedImplicitEuler(Integrator):
    order = 1
    implicit = True
    unconditionally_stable = True

    def __init__(self, system):
        super().__init__(system)
        self._f = None
        self.solves = 0

    def amplification(self, h, omega, zeta):
        # (1 + 2ζωh + ω²h²) Δv = h(−ω² x − 2ζω v − h ω² v); exact for a linear oscillator
        w2, c = omega * omega, 2.0 * zeta * omega
        den = 1.0 + h * c + h * h * w2
        dv_x, dv_v = -h * w2 / den, -h * (c + h * w2) / den
        return np.array([[1.0 + h * dv_x, h * (1.0 + dv_v)], [dv_x, 1.0 + dv_v]])

    def _force(self, x, v):
        if self._f is None or self._f.shape != x.shape:
            self._f = np.empty_like(x)
        return self.system.forces.force(x, v, out=self._f)

    def _free(self):
        model = self.system.model
        free = ~model.pinned
        index = np.full(model.n_particles, -1, dtype=np.int64)
        index[free] = np.arange(int(free.sum()))
        return free, index

    def stats(self) -> dict:
        return {"solves": self.solves}


@register
class ImplicitEuler(_LinearisedImplicitEuler):
    """Baraff & Witkin (1998): one Newton step of backward Euler with the analytic spring Jacobians.

    Options (keyword arguments of the constructor, or attributes):

    * ``solver`` — ``"cg"``: conjugate gradients preconditioned with the diagonal (Jacobi),
      warm-started from the last ``Δv``, stopping at ``cg_tolerance`` (relative residual) or
      ``cg_max_iterations``; ``"direct"``: a sparse LU factorisation (SuperLU, symmetric ordering) of the same
      system every step.
    * ``clamp_compression`` (default on) — drop the compressive, indefinite part of each spring's
      stiffness block (``E''`` and ``E'/l`` below zero), which keeps the matrix symmetric positive
      definite so CG applies at any step. It changes the Jacobian, not the force: the step stays
      first-order accurate here, but the linearisation is no longer exact for compressed springs, so
      it costs accuracy there, and a method built on the exact Jacobian (a BDF2 step, a full Newton
      iteration) would lose its higher order.

    The damping force's dependence on positions is left out of the matrix (Baraff & Witkin do the
    same: it is small and unsymmetric). Wind and gravity are explicit.
    """

    name = "implicit_euler"

    def __init__(self, system, solver: str = "cg", cg_tolerance: float = 1e-6,
                 cg_max_iterations: int = 1000, clamp_compression: bool = True):
        super().__init__(system)
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
        if not (cg_tolerance > 0 and math.isfinite(cg_tolerance)):
            raise ValueError(f"cg_tolerance must be a finite number > 0, got {cg_tolerance}")
        if int(cg_max_iterations) < 1:
            raise ValueError(f"cg_max_iterations must be >= 1, got {cg_max_iterations}")
        self.solver = solver
        self.cg_tolerance = float(cg_tolerance)
        self.cg_max_iterations = int(cg_max_iterations)
        self.clamp_compression = bool(clamp_compression)
        self.cg_iterations = 0
        self.last_cg_iterations = 0
        self.cg_not_converged = 0
        self._pattern_of = None
        self._dv = None

    def reset(self, x, v, dt):
        self._dv = None  # the warm start is stale after a jump of the state or of dt

    def _build(self):
        forces = self.system.forces
        free, index = self._free()
        n_free = int(free.sum())
        indptr, indices, slot, dslot = _block_pattern(forces.springs, index, n_free)
        self._free_dofs = np.flatnonzero(np.repeat(free, 3))
        self._n = 3 * n_free
        self._slot, self._dslot = slot, dslot
        self._matrix = sp.csr_matrix((np.zeros(len(indices)), indices, indptr),
                                     shape=(self._n, self._n))
        self._matrix.has_sorted_indices = True
        self._diag_entries = dslot[free].ravel()
        self._rhs = np.empty((self.system.model.n_particles, 3))
        self._pattern_of = forces

    def step(self, x, v, dt):
        forces = self.system.forces
        if self._pattern_of is not forces:  # a new pipeline: is the set of active springs the same?
            if self._pattern_of is None or not np.array_equal(self._pattern_of.springs,
                                                              forces.springs):
                self._build()
                self._dv = None
            self._pattern_of = forces
        f = self._force(x, v)
        masses = self.system.model.masses
        A = self._matrix
        _assemble_baraff_witkin(x, v, f, forces.springs, forces.rest, forces.k, forces.c,
                                forces.kind, BUCKLE_TABLE, self.clamp_compression, dt,
                                masses + dt * forces.drag, self._slot, self._dslot, A.data,
                                self._rhs)
        b = self._rhs.ravel()[self._free_dofs]
        if self._n == 0:
            return
        if self.solver == "direct":
            # the matrix is symmetric: a symmetric ordering and diagonal pivots halve SuperLU's time
            dv = splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A",
                      options={"SymmetricMode": True}).solve(b)
        else:
            dv = self._cg(A, b)
        self._dv = dv
        self.solves += 1
        v.reshape(-1)[self._free_dofs] += dv
        x += dt * v

    def _cg(self, A, b):
        inv_diag = 1.0 / A.data[self._diag_entries]
        pre = sp.diags(inv_diag)
        count = [0]

        def counter(_):
            count[0] += 1

        x0 = self._dv if self._dv is not None and len(self._dv) == len(b) else None
        dv, info = cg(A, b, x0=x0, rtol=self.cg_tolerance, atol=0.0, maxiter=self.cg_max_iterations,
                      M=pre, callback=counter)
        self.last_cg_iterations = count[0]
        self.cg_iterations += count[0]
        if info != 0:
            self.cg_not_converged += 1
        return dv

    def stats(self) -> dict:
        return {"solves": self.solves, "cg_iterations": self.cg_iterations,
                "last_cg_iterations": self.last_cg_iterations,
                "cg_not_converged": self.cg_not_converged}


@register
class ImplicitEulerPrefactored(_LinearisedImplicitEuler):
    """The review's eqs. 1.16–1.20: implicit Euler with the constant matrix
    ``M − dt·C − dt²·H`` (``H_ij = k_ij``, ``H_ii = −Σ_j k_ij``; ``C`` the same from the damping
    coefficients; drag on the diagonal), one ``n×n`` matrix shared by the three coordinates.

    It is symmetric positive definite, factorised once by sparse Cholesky (``cholespy``) and reused
    for every step; it is refactorised when stiffness, damping, drag, dt, pins or topology change
    (:attr:`factorizations` counts them). ``H`` ignores the springs' directions and the Choi–Ko
    nonlinearity, so the step is stable but damps and distorts more than :class:`ImplicitEuler`.
    """

    name = "implicit_euler_prefactored"

    def __init__(self, system):
        super().__init__(system)
        self.factorizations = 0
        self._key = None
        self._solver = None
        self._stale = True

    def reset(self, x, v, dt):
        self._stale = True

    def parameters_changed(self):
        self._stale = True

    def _ensure_factor(self, dt):
        forces = self.system.forces
        old = self._key
        if (old is not None and old[0] == dt and old[1] == forces.drag
                and np.array_equal(old[2], forces.springs) and np.array_equal(old[3], forces.k)
                and np.array_equal(old[4], forces.c)):
            self._stale = False
            return
        model = self.system.model
        free, index = self._free()
        n_free = int(free.sum())
        i, j = forces.springs[:, 0], forces.springs[:, 1]
        w = dt * forces.c + dt * dt * forces.k  # −(dt·C + dt²·H) off the diagonal, negated
        diag = _spring_sums(forces.springs, w, model.n_particles) + model.masses + dt * forces.drag
        fi, fj = index[i], index[j]
        both = (fi >= 0) & (fj >= 0)
        rows = np.concatenate([fi[both], fj[both], np.arange(n_free)])
        cols = np.concatenate([fj[both], fi[both], np.arange(n_free)])
        vals = np.concatenate([-w[both], -w[both], diag[free]])
        A = sp.csc_matrix((vals, (rows, cols)), shape=(n_free, n_free))
        A.sum_duplicates()
        self._matrix = A
        self._factor(A, n_free)
        self.factorizations += 1
        self._key = (dt, forces.drag, forces.springs.copy(), forces.k.copy(), forces.c.copy())
        self._free_mask = free
        self._rhs_full = np.empty((model.n_particles, 3))
        self._b = np.empty((n_free, 3))
        self._dv = np.empty((n_free, 3))
        self._stale = False

    def _factor(self, A, n):
        from cholespy import CholeskySolverD, MatrixType

        if n == 0:
            self._solver = None
            return
        self._solver = CholeskySolverD(n, A.indptr.astype(np.int32), A.indices.astype(np.int32),
                                       np.ascontiguousarray(A.data), MatrixType.CSC)

    def step(self, x, v, dt):
        if self._stale:
            self._ensure_factor(dt)
        forces = self.system.forces
        f = self._force(x, v)
        rhs = self._rhs_full
        rhs[:] = 0.0
        _graph_product(forces.springs, forces.k, v, rhs)  # H v
        rhs *= dt
        rhs += f
        rhs *= dt
        if self._solver is None:
            return
        np.copyto(self._b, rhs[self._free_mask])
        self._solver.solve(self._b, self._dv)
        self.solves += 1
        v[self._free_mask] += self._dv
        x += dt * v

    def stats(self) -> dict:
        return {"solves": self.solves, "factorizations": self.factorizations}


@register
class Kang(_LinearisedImplicitEuler):
    """Kang, Choi & Cho (2000), the approximated implicit method: the linear system of
    :class:`ImplicitEulerPrefactored` without damping in the matrix, not solved but approximated per
    particle by ``sweeps`` Jacobi sweeps (the paper: one),

        Δv_i = (dt·f_i + dt²·Σ_j k_ij·(v_j − v_i + Δv_j)) / (m_i + dt²·Σ_j k_ij),

    with the neighbours' ``Δv_j`` from the previous step. Spring damping stays explicit in ``f``.
    Not unconditionally stable: the lagged ``Δv_j`` and explicit damping limit the step
    (:meth:`linear_stable_dt` finds the limit of the linearised step), and the simulator's guard
    catches a blow-up like any explicit method's.
    """

    name = "kang"
    unconditionally_stable = False
    # no scalar-mode amplification matrix (its lagged neighbours couple modes): not implicit
    # Euler's, which it would otherwise inherit; see linear_stable_dt
    amplification = Integrator.amplification

    def __init__(self, system, sweeps: int = 1):
        super().__init__(system)
        if int(sweeps) < 1:
            raise ValueError(f"sweeps must be >= 1, got {sweeps}")
        self.sweeps = int(sweeps)
        self._dv = None

    def linear_step_matrix(self, dt: float) -> sp.csr_matrix:
        """The step as a linear map of ``(δx, v, Δv_prev)`` over the free coordinates, for the
        system linearised about its rest shape (force ``−K·δx − C·v − drag·v``)."""
        system = self.system
        model = system.model
        forces = system.forces
        K, C = system.rest_matrices()
        n = model.n_particles
        s, k = forces.springs, forces.k
        adj = sp.coo_matrix((np.r_[k, k], (np.r_[s[:, 0], s[:, 1]], np.r_[s[:, 1], s[:, 0]])),
                            shape=(n, n)).tocsr()
        ksum = _spring_sums(s, k, n)
        A3 = sp.kron(adj, sp.identity(3), format="csr")
        H3 = A3 - sp.diags(np.repeat(ksum, 3))
        free = np.repeat(~model.pinned, 3)
        W = sp.diags(1.0 / np.repeat(model.masses + dt * dt * ksum, 3)[free])

        def sel(X):
            return X.tocsr()[free][:, free]

        K, C, H3, A3 = sel(K), sel(C), sel(H3), sel(A3)
        eye = sp.identity(K.shape[0], format="csr")
        Dx = W @ (-dt * K)
        Dv = W @ (-dt * (C + forces.drag * eye) + dt * dt * H3)
        Dd = W @ (dt * dt * A3)
        # Δv' = Dx δx + Dv v + Dd Δv ;  v' = v + Δv' ;  δx' = δx + dt·v'
        return sp.bmat([[eye + dt * Dx, dt * (eye + Dv), dt * Dd],
                        [Dx, eye + Dv, Dd],
                        [Dx, Dv, Dd]], format="csr")

    def spectral_radius(self, dt: float) -> float:
        """Largest eigenvalue modulus of :meth:`linear_step_matrix` (ARPACK)."""
        T = self.linear_step_matrix(dt)
        if T.shape[0] == 0:
            return 0.0
        if T.shape[0] <= 600:
            return float(np.max(np.abs(np.linalg.eigvals(T.toarray()))))
        vals = eigs(T, k=3, which="LM", return_eigenvectors=False, tol=1e-6, maxiter=100000)
        return float(np.max(np.abs(vals)))

    def linear_stable_dt(self, rel_tol: float = 0.05) -> float:
        """Largest ``dt`` whose linearised step (:meth:`linear_step_matrix`) has spectral radius
        ≤ 1, by bisection to ``rel_tol``. Kang's method has no scalar mode model (its matrix ignores
        the springs' directions and lags the neighbours' ``Δv``), so the whole system is analysed;
        It costs seconds (about 4 s for a 16×16 cloth, minutes at 32×32; the simulator caches it) and
        is conservative: a cloth that leaves its flat rest shape under gravity survives up to about
        twice this step."""
        omega, _ = self.system.fastest_mode()
        if omega == 0.0:
            return math.inf

        def stable(h):
            return self.spectral_radius(h) <= 1.0 + 1e-7

        lo, hi = 0.0, 1.0 / omega
        while stable(hi):
            lo, hi = hi, 2.0 * hi
            if hi > 1e3 / omega:
                return math.inf
        while hi - lo > rel_tol * hi:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if stable(mid) else (lo, mid)
        return lo

    def reset(self, x, v, dt):
        self._dv = np.zeros_like(x)
        self._acc = np.empty_like(x)
        self._new = np.empty_like(x)
        self._den_of = None

    def _inverse_denominators(self, dt):
        """``1/(m_i + dt²·Σ_j k_ij)``, 0 on pins; rebuilt only when the forces or dt change."""
        forces = self.system.forces
        if self._den_of != (forces, dt):
            model = self.system.model
            den = model.masses + dt * dt * _spring_sums(forces.springs, forces.k, model.n_particles)
            self._inv_den = np.where(model.pinned, 0.0, 1.0 / den)
            self._den_of = (forces, dt)
        return self._inv_den

    def step(self, x, v, dt):
        forces = self.system.forces
        f = self._force(x, v)
        _kang_sweeps(f, v, self._dv, forces.springs, forces.k, dt, self.sweeps,
                     self._inverse_denominators(dt), self._acc, self._new)
        self.solves += 1
        v += self._dv
        x += dt * v
