"""Liu, O'Sullivan, Sifakis & Kavan (2013), "Fast simulation of mass-spring systems": backward
Euler for springs solved by block coordinate descent.

One step of backward Euler is the minimiser of

    g(x) = 1/(2h²)·‖x − y‖²_M + E(x),      y = xₙ + h·vₙ + h²·M⁻¹·f_ext,

and for a Hooke spring ``½k(|x_ij| − L)² = min_{|d| = L} ½k|x_ij − d|²`` (``x_ij = x_j − x_i``).
With the directions ``d`` as extra unknowns, ``g`` is minimised by alternating

* a **local step**: each spring's ``d = L·x_ij/|x_ij|`` (independent per spring), and
* a **global step**: ``(M + h²L) x = M y + h² J d``, with ``L`` the graph Laplacian of the
  stiffnesses, the same ``n×n`` matrix for the three coordinates, which never changes while the
  stiffness, masses, pins and ``h`` do not: it is factorised once (sparse Cholesky, ``cholespy``).

Each iteration lowers ``g``, and the iterates converge to the backward-Euler step.

Other spring laws. A spring whose energy is any ``E(l)`` of its length gets the target ``d = (l −
E'(l)/w)·x_ij/l`` with a weight ``w`` in the matrix: for Hooke (``w = k``) this is Liu's ``d =
L·x_ij/l``; in general the fixed point is still the backward-Euler step (``w·(x_ij − d)`` is the
spring's force), and the iteration is the quasi-Newton method with the constant Laplacian as the
Hessian that Liu, Bouaziz & Kavan (2017) derive. Choi & Ko's tension-only pairs (``E' = 0`` when
compressed: ``d = x_ij``, no force) and buckling pairs (``E'`` from the arc model) take this form
with ``w`` their linearised stiffness, the stiffer branch
(:func:`cloth_sim.physics.stability.springs_effective_stiffness`), so that ``w`` bounds the
energy's curvature and each iteration still lowers ``g``. At the buckling onset the force jumps
(the immediate-buckling load ``12 k/L²``): there ``E`` has a kink, which the iteration approaches
without oscillating but converges to more slowly.

Damping (Rayleigh, as the issue allows, since the paper leaves springs undamped). Spring damping
``c`` enters as the graph Laplacian ``C`` of the damping coefficients acting on the new velocity
``(x − xₙ)/h``: it damps the relative velocity of a spring's ends in every direction, not only
along the spring (that would make the matrix depend on the directions), conserves linear momentum,
and keeps the matrix constant; drag ``−c_d·v`` is implicit too. The global matrix is then ``M +
h·c_d·I + h·C + h²·L``. Gravity and wind are explicit, in ``y`` (wind at the step's start).

Pinned particles are eliminated; a pinned particle moves with its velocity (a gripper's), so it is
at ``xₙ + h·vₙ`` in the step's constraint.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from ..kernel_cache import keep_true
from ..physics.force_kernels import BUCKLE_TABLE, axial, spring_vector
from .base import Integrator, Stability
from .implicit import cholesky, constant_system, graph_product, same_system, system_key
from .registry import register


@numba.njit(cache=True)
def _local_global_rhs(x, springs, rest, k, w, kind, tab, h2, base, rhs):
    """``rhs = base + h²·J·d``: the local step (each spring's target ``d`` from the positions
    ``x``) and its contribution to the global step's right-hand side, ``−h²·w·d`` on ``i`` and
    ``+h²·w·d`` on ``j`` for the spring ``(i, j)``."""
    rhs[:] = base
    for s in range(springs.shape[0]):
        ws = w[s]
        if ws == 0.0:
            continue
        i = springs[s, 0]
        j = springs[s, 1]
        dx, dy, dz, l = spring_vector(x, i, j)
        if l < 1e-300:
            continue
        _, de, _ = axial(l, rest[s], k[s], kind[s], tab)
        # w·d = (w·l − E'(l))·x_ij/l
        scale = h2 * (ws * l - de) / l
        rhs[i, 0] -= scale * dx
        rhs[i, 1] -= scale * dy
        rhs[i, 2] -= scale * dz
        rhs[j, 0] += scale * dx
        rhs[j, 1] += scale * dy
        rhs[j, 2] += scale * dz


@register
class Liu2013(Integrator):
    """Liu et al. (2013): backward Euler by local/global iterations with one prefactored matrix.

    Options: ``iterations`` (default 10, the paper's real-time setting) — local/global iterations
    per step, each one spring pass and one solve with the prefactored Cholesky factor;
    ``chebyshev`` (default off) — Wang (2015)'s Chebyshev semi-iterative acceleration of the
    iterates, with ``rho`` the estimated spectral radius of the plain iteration (default 0.99) and
    Wang's under-relaxation 0.9: worth it from tens of iterations (on a 5×5 sheet at dt = 1/60,
    100 iterations land 80× closer to the step than without; at 10 it does not help).

    First order (backward Euler, whatever the iteration count: the iteration starts at ``y``,
    within ``O(h²)`` of the step, and only shrinks that error); linear momentum conserved (every
    spring and the damping act in equal and opposite pairs); no step limit (each iteration lowers
    the step's objective). The matrix is refactorised when stiffness, damping, drag or dt change
    (the counter ``factorizations``); see the module docstring for damping, Choi–Ko and pins.
    """

    name = "liu2013"
    order = 1
    #: a material's bending is quadratic: its constant Hessian goes into the global matrix
    takes_bending = True
    force_point = 1.0
    implicit = True
    stability = Stability.UNCONDITIONAL
    counter_names = ("solves", "iterations", "factorizations")

    #: Wang (2015)'s under-relaxation of the Chebyshev update.
    GAMMA = 0.9

    def __init__(self, model, iterations: int = 10, chebyshev: bool = False, rho: float = 0.99):
        super().__init__(model)
        if (
            isinstance(iterations, bool)
            or int(iterations) != iterations
            or not 1 <= iterations <= 10_000
        ):
            raise ValueError(f"iterations must be an integer in [1, 10000], got {iterations!r}")
        if not (isinstance(rho, (int, float)) and 0.0 < rho < 1.0):
            raise ValueError(f"rho must be a number in (0, 1), got {rho!r}")
        self.iterations = int(iterations)
        self.chebyshev = bool(chebyshev)
        self.rho = float(rho)
        self._key = None

    def parameters_changed(self, changed):
        if changed & {"stiffness", "damping", "drag", "dt"}:
            self._key = None

    # ------------------------------------------------------------------ the matrix
    def _ensure_factor(self, forces, dt):
        if same_system(self._key, forces, dt):
            return
        # the prefactored implicit Euler's matrix: M + h·c_d + h·C + h²·L with L of the
        # linearised stiffnesses w
        A, self._w, off, index = constant_system(self.model, forces, dt)
        n_free = A.shape[0]
        i, j = forces.springs[:, 0], forces.springs[:, 1]
        fi, fj = index[i], index[j]
        # a free particle's springs to pinned ones: their Laplacian entries move to the right-hand
        # side
        cross = (fi >= 0) != (fj >= 0)
        rows = np.where(fi[cross] >= 0, fi[cross], fj[cross])
        cols = np.where(fi[cross] >= 0, j[cross], i[cross])
        self._pin_coupling = sp.csr_matrix(
            (off[cross], (rows, cols)), shape=(n_free, self.model.n_particles)
        )
        if forces.bending is not None:  # the bending's couplings to pins, moved to the right
            Q = forces.bending.Q[~self.model.pinned]
            Q = Q @ sp.diags(self.model.pinned.astype(np.float64))
            self._pin_coupling = (self._pin_coupling - (dt * dt) * Q).tocsr()
        self._solver = cholesky(A)
        self._free = index >= 0
        self._free_index = np.flatnonzero(self._free)
        self.counters["factorizations"] += 1
        self._key = system_key(forces, dt)
        self._b = np.empty((n_free, 3))
        self._sol = np.empty((n_free, 3))
        self._cheb = tuple(np.empty((n_free, 3)) for _ in range(3))

    # ------------------------------------------------------------------ the step
    def step(self, state, forces, dt):
        self._ensure_factor(forces, dt)
        x, v = state.x, state.v
        free, h2 = self._free, dt * dt
        x0 = self._buffer("_x0", x)
        np.copyto(x0, x)
        # y = xₙ + h·vₙ + h²·M⁻¹·f_ext (pins: xₙ + h·vₙ, their place at the step's end)
        f_ext = self._external_force(forces, x, v)
        y = self._buffer("_y", x)
        np.multiply(v, dt, out=y)
        y += x0
        y[free] += h2 * f_ext[free] / self.model.masses[free, None]
        # base = M·y + (h·c_d)·xₙ + h·C·xₙ: the right-hand side's constant part
        base = self._buffer("_base", x)
        np.multiply(y, self.model.masses[:, None], out=base)
        base += (dt * forces.drag) * x0
        if forces.with_damping:  # + h·C·xₙ, Σ_j h·c_ij·(x_i − x_j): the graph product with −h·c
            graph_product(forces.springs, -dt * forces.c, x0, base)
        pins = self._pin_coupling @ y if self._pin_coupling.nnz else None
        rhs = self._buffer("_rhs", x)
        cur = self._buffer("_cur", x)
        np.copyto(cur, y)
        idx, b, sol = self._free_index, self._b, self._sol
        if self.chebyshev:  # the iterates in the free particles' space, three buffers rotated
            cur_f, prev_f, new_f = self._cheb
            np.take(y, idx, axis=0, out=cur_f)
            np.copyto(prev_f, cur_f)
        omega = 1.0
        for it in range(self.iterations):
            _local_global_rhs(
                cur,
                forces.springs,
                forces.rest,
                forces.k,
                self._w,
                forces.kind,
                BUCKLE_TABLE,
                h2,
                base,
                rhs,
            )
            np.take(rhs, idx, axis=0, out=b)
            if pins is not None:
                b += pins
            if self._solver is not None:
                self._solver.solve(b, sol)
            if not self.chebyshev:
                cur[idx] = sol
                continue
            # Wang (2015): x⁺ = ω·(γ·(x̂ − x) + x − x⁻) + x⁻, ω from the Chebyshev recurrence
            omega = (
                1.0
                if it == 0
                else (2.0 / (2.0 - self.rho**2) if it == 1 else 4.0 / (4.0 - self.rho**2 * omega))
            )
            np.subtract(sol, cur_f, out=new_f)
            new_f *= self.GAMMA
            new_f += cur_f
            new_f -= prev_f
            new_f *= omega
            new_f += prev_f
            prev_f, cur_f, new_f = cur_f, new_f, prev_f
            cur[idx] = cur_f
        self.counters["iterations"] += self.iterations
        self.counters["solves"] += 1
        # the new velocity from the displacement (pins keep theirs: they are at y, xₙ + h·vₙ)
        v[free] = (cur[free] - x0[free]) / dt
        x[free] = cur[free]
        x[~free] = y[~free]


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
