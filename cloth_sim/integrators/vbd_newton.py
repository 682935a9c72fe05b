"""``vbd``'s step solved whole, for a small cloth: Newton's method on the same incremental
potential, each iteration one sparse Cholesky factorisation of the step's Hessian.

The sweeps of :mod:`~cloth_sim.integrators.vbd` carry stiffness about one ring of vertices each,
so the sweeps a converged step needs grow with the fabric's stiffness over its vertices' inertia
(docs/convergence.md). On a small specimen of a real fabric that ratio is extreme: a cantilever
strip of 32×4 cells weighs a few micrograms a vertex, and its springs are ~10⁵ times that
inertia at 1/60 s, so the chosen substeps hit their cap and the strip crept for minutes of wall
time without coming to rest. A direct solve does not care about the ratio: Newton's method with
the Hessian factorised takes a few iterations a step whatever the stiffness, and a factorisation
of a few thousand unknowns costs less than the sweeps' one of them.

The step minimises ``G(x) = Σ m_i/(2h²)|x_i − y_i|² + d/(2h)|x_i − x_i^t|² + E(x)`` over the free
vertices (``E``: the springs' and the bending's energy; the drag ``d``), whose gradient is the
residual of :mod:`~cloth_sim.integrators.vbd_residual` (the same force, the same measure). Each
iteration solves ``H Δx = r`` with ``H = M/h² + d/h·I + Q − ∂f_springs/∂x`` assembled into one
fixed sparsity pattern (the springs' 3×3 blocks of
:func:`~cloth_sim.physics.force_kernels.spring_jacobian_blocks`, the bending's constant ``Q``) and
factorised by QDLDL (an LDLᵀ whose symbolic analysis is kept: a step refactorises numerically),
then backtracks on ``G`` until it descends. ``H`` is the exact Hessian while its step descends;
where a compressed spring makes it indefinite and its step does not, the springs' compressive
part is dropped for the rest of the step (positive definite, as VBD's own blocks are kept).
Measured on the Cusick drape of denim at 32 cells: the exact Hessian converges quadratically
(residual 1 → 0.3 → 0.02 → 1e-4 near rest) where the positive definite one stalls about 0.1 for
tens of iterations. The iterations start from ``x^t + h v`` (the state's own motion): on a stiff
fabric the inertial target ``y`` with all of gravity's ``h²g`` stretches the springs by
millimetres at once, a residual of ~10³ where ``x^t + h v`` starts at ~1–100.

Where the springs carry damping, ``G`` is no longer the step's potential (the damping force has
none), so :func:`applies` says no and the sweeps solve it.
"""

from __future__ import annotations

import time

import numpy as np
import qdldl
import scipy.sparse as sp

from .vbd_residual import G0

#: the most free vertices a step is solved directly for where ``vbd`` chooses (``direct`` not
#: given): an iteration costs ~0.13 s there, and its factor's memory grows as fast
DIRECT_MAX_VERTICES = 4000

# The cost model that chooses (:func:`direct_is_cheaper`), measured on two cores on hanging sheets
# (16×16, 32×32) and Cusick drape discs (16, 32 and 64 cells) of cotton and denim at 1/60 s:
#: sweeps a substep takes to the default tolerance (12.8–14.3 measured)
SWEEPS_PER_SUBSTEP = 13.0
#: seconds a vertex's sweep costs on the grid's blocks (96–260 ns)
GRID_SWEEP_SECONDS = 150e-9
#: and on the general sweep: on one core (350–490 ns), on two from :data:`PARALLEL_VERTICES`
#: (231–239 ns)
SWEEP_SECONDS, PARALLEL_SWEEP_SECONDS, PARALLEL_VERTICES = 400e-9, 240e-9, 1000
#: Newton iterations a step takes (2.4–9.7 measured, 5 typical)
NEWTON_ITERATIONS = 5.0
#: seconds of an iteration over ``n^1.5`` free vertices (a factorisation's fill on a surface:
#: 0.8 ms at 128, 5.8 ms at 504, 53 ms at 2,056)
FACTOR_SECONDS = 513e-9

#: the smallest share of a Newton step the line search tries before it stops (at rounding)
MIN_STEP = 1e-8

# each spring's four 3×3 blocks in H, as (row particle, column particle, sign)
_BLOCKS = ((0, 0, 1.0), (1, 1, 1.0), (0, 1, -1.0), (1, 0, -1.0))


def direct_is_cheaper(free: int, substeps: int, grid: bool) -> bool:
    """Whether a step of ``free`` vertices, whose sweeps need ``substeps`` substeps (uncapped)
    on the grid's blocks (``grid``) or the general sweep, costs less solved directly: the cost
    model above, within :data:`DIRECT_MAX_VERTICES`."""
    if free > DIRECT_MAX_VERTICES:
        return False
    if grid:
        each = GRID_SWEEP_SECONDS
    else:
        each = PARALLEL_SWEEP_SECONDS if free >= PARALLEL_VERTICES else SWEEP_SECONDS
    sweeps = substeps * SWEEPS_PER_SUBSTEP * free * each
    return NEWTON_ITERATIONS * FACTOR_SECONDS * free**1.5 < sweeps


def applies(forces) -> bool:
    """Whether the step of ``forces`` has a potential to descend on: springs without damping."""
    return not forces.with_damping


class _Pattern:
    """``H``'s upper triangle over the free coordinates as one CSC pattern for a force pipeline:
    where each spring's block entries and the constant parts (the inertia's and the drag's
    diagonal, the bending's ``Q ⊗ I₃``) land in its data."""

    def __init__(self, forces, masses: np.ndarray, free: np.ndarray):
        n = len(masses)
        local = np.full(3 * n, -1, np.int64)
        dofs = np.flatnonzero(np.repeat(free, 3))
        local[dofs] = np.arange(len(dofs))
        self.size = len(dofs)
        springs = forces.springs
        ar = np.arange(3)
        rows, cols = [], []
        m = len(springs)
        for a, b, _ in _BLOCKS:  # (m, 3, 3) global coordinates of each block's entries
            at_a = (3 * springs[:, a])[:, None, None] + ar[None, :, None]
            at_b = (3 * springs[:, b])[:, None, None] + ar[None, None, :]
            rows.append(np.broadcast_to(at_a, (m, 3, 3)))
            cols.append(np.broadcast_to(at_b, (m, 3, 3)))
        sr = local[np.stack(rows, axis=1).reshape(-1)]
        sc = local[np.stack(cols, axis=1).reshape(-1)]
        #: which of the springs' (m, 4, 3, 3) entries are in the upper triangle of free ones
        self.spring_entries = np.flatnonzero((sr >= 0) & (sc >= 0) & (sr <= sc))
        sr, sc = sr[self.spring_entries], sc[self.spring_entries]
        diag = np.arange(self.size)
        if forces.bending is not None:
            q = forces.bending.hessian().tocoo()
            qr, qc = local[q.row], local[q.col]
            keep = (qr >= 0) & (qc >= 0) & (qr <= qc)
            qr, qc, qv = qr[keep], qc[keep], q.data[keep]
        else:
            qr = qc = np.zeros(0, np.int64)
            qv = np.zeros(0)
        r = np.concatenate([sr, qr, diag])
        c = np.concatenate([sc, qc, diag])
        shape = (self.size, self.size)
        pattern = sp.csc_matrix((np.ones(len(r)), (r, c)), shape=shape)
        pattern.sum_duplicates()
        pattern.sort_indices()
        self.indptr, self.indices = pattern.indptr, pattern.indices
        keys = np.repeat(np.arange(self.size), np.diff(self.indptr)) * self.size + self.indices
        nnz = len(keys)
        self.spring_slots = np.searchsorted(keys, sc * self.size + sr)
        diag_slots = np.searchsorted(keys, diag * self.size + diag)
        #: the data of the inertia's diagonal over h² (times h²: the masses), of the drag's over h
        #: (times h: ones) and of the bending's Q
        self.inertia = np.bincount(diag_slots, np.repeat(masses, 3)[dofs], minlength=nnz)
        self.ones = np.bincount(diag_slots, np.ones(self.size), minlength=nnz)
        self.bending = np.bincount(
            np.searchsorted(keys, qc * self.size + qr), qv, minlength=nnz
        ).astype(np.float64)
        self.nnz = nnz

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.size, self.size))


class NewtonSolve:
    """The direct solve of one model's steps (``free``: the vertices it moves)."""

    def __init__(self, model, free: np.ndarray):
        self.masses = np.asarray(model.masses, np.float64)
        self.free = np.asarray(free, bool)
        #: the free coordinates, in the 3n vector's order
        self.dofs = np.flatnonzero(np.repeat(self.free, 3))
        self._f = np.zeros((model.n_particles, 3))
        self._v = np.zeros((model.n_particles, 3))
        self._pattern_of = None
        self._pattern = None
        self._factor = None
        self._blocks = None

    def merit(self, forces, x, xt, y, h) -> float:
        """``G(x)``: the inertia's, the drag's and the elastic energy (J)."""
        d = x - y
        e = 0.5 / (h * h) * float(np.sum(self.masses * np.einsum("ij,ij->i", d, d)))
        if forces.drag > 0:
            dt = x - xt
            e += 0.5 * forces.drag / h * float(np.sum(dt * dt))
        return e + forces.spring_energy(x)

    def residual(self, forces, x, xt, y, h) -> tuple[np.ndarray, float]:
        """The force ``r = −∂G/∂x`` (n, 3) and the relative residual: RMS over the free vertices
        of ``|r_i|/(m_i g₀)`` (:mod:`~cloth_sim.integrators.vbd_residual`)."""
        np.subtract(x, xt, out=self._v)
        self._v /= h
        r = forces.implicit_force(x, self._v, self._f)
        r -= (self.masses / (h * h))[:, None] * (x - y)
        w = self.masses[self.free] * G0
        rel = np.einsum("ij,ij->i", r[self.free], r[self.free]) / (w * w)
        return r, float(np.sqrt(rel.mean())) if len(rel) else 0.0

    def hessian(self, forces, x, h, clamp: bool) -> sp.csc_matrix:
        """``H = M/h² + d/h·I + Q ⊗ I₃ − ∂f_springs/∂x`` over the free coordinates, its upper
        triangle (``clamp``: the springs' compressive part dropped, positive definite)."""
        if self._pattern_of is not forces:
            self._pattern = _Pattern(forces, self.masses, self.free)
            self._pattern_of = forces
            self._factor = None
            m = len(forces.springs)
            self._blocks = tuple(np.empty((m, 3, 3)) for _ in range(3))
        pat = self._pattern
        kx = forces.spring_term.jacobian_blocks(x, x, clamp, False, self._blocks)[0]
        entries = np.stack([sign * (kx if a <= b else np.transpose(kx, (0, 2, 1)))
                            for a, b, sign in _BLOCKS], axis=1)  # fmt: skip
        data = np.bincount(
            pat.spring_slots, entries.reshape(-1)[pat.spring_entries], minlength=pat.nnz
        )
        data += pat.inertia / (h * h)
        data += pat.bending
        if forces.drag > 0:
            data += (forces.drag / h) * pat.ones
        return pat.matrix(data)

    def _direction(self, H, r) -> np.ndarray | None:
        """``H⁻¹ r`` by QDLDL (the symbolic analysis kept across calls); None where the
        factorisation fails (a zero pivot)."""
        try:
            if self._factor is None:
                self._factor = qdldl.Solver(H, upper=True)
            else:
                self._factor.update(H, upper=True)
        except (ValueError, RuntimeError):
            self._factor = None
            return None
        dx = self._factor.solve(r)
        return dx if np.all(np.isfinite(dx)) else None

    def solve(
        self, forces, x, xt, v, y, h, tolerance: float, iterations: int, deadline=None
    ) -> tuple[int, float]:
        """Newton's iterations on the step, in place in ``x``, from ``x^t + h v``, until the
        relative residual is at or below ``tolerance``, ``iterations`` are done, no step
        descends or (after one iteration) the clock passes ``deadline`` (``time.perf_counter()``'s
        seconds; None: none); returns the iterations and the last residual."""
        np.multiply(v, h, out=x)
        x += xt
        r, res = self.residual(forces, x, xt, y, h)
        g = self.merit(forces, x, xt, y, h)
        done = 0
        flat = x.reshape(-1)
        exact = True
        while done < iterations and res > tolerance:
            if done and deadline is not None and time.perf_counter() >= deadline:
                break
            rf = np.ascontiguousarray(r.reshape(-1)[self.dofs])
            dx = None
            if exact:  # the exact Hessian while its step descends
                dx = self._direction(self.hessian(forces, x, h, False), rf)
                if dx is None or not float(dx @ rf) > 0.0:
                    exact, dx = False, None
            if dx is None:
                dx = self._direction(self.hessian(forces, x, h, True), rf)
                if dx is None:
                    return done, res
            done += 1
            start = flat[self.dofs].copy()
            step, force_fell = 1.0, False
            while True:
                flat[self.dofs] = start + step * dx
                trial = self.merit(forces, x, xt, y, h)
                if trial <= g:
                    break
                if step == 1.0:
                    # near the minimum G's change is below its rounding (a residual of ~1e-7
                    # moves a stiff strip by 1e-11 m): the full step stands if it lowers the force
                    r_full, res_full = self.residual(forces, x, xt, y, h)
                    force_fell = res_full < res
                    if force_fell:
                        break
                step *= 0.5
                if step < MIN_STEP:  # no step lowers G or the force: the step's rounding
                    flat[self.dofs] = start
                    return done, res
            g = trial
            r, res = (r_full, res_full) if force_fell else self.residual(forces, x, xt, y, h)
        return done, res
