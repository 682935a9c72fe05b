"""Kang et al. 2000's step analysed for stability: the analysis behind
:class:`cloth_sim.integrators.implicit.KangIntegrator`'s ``analyse`` hook.

Kang's approximated implicit step has no scalar mode model (its matrix ignores the springs'
directions and lags the neighbours' ``Δv``), so, unlike the one-step methods of
:mod:`cloth_sim.physics.stability`, its step is analysed as a whole:

* :func:`kang_step_matrix` — the linearised step as a sparse map of ``(δx, v, Δv_prev)``;
* :func:`kang_fourier_radius` — its von Neumann (Fourier) symbol on the infinite grid, for a
  regular grid with uniform spring families (:func:`cloth_sim.physics.stability.grid_stencil`);
* :func:`kang_stable_dt` — the largest stable ``dt`` by bisection, from the Fourier analysis where
  it applies and the whole step matrix's spectral radius (ARPACK) otherwise, or
  :func:`equivalent_grid`'s stand-in on a large spring network (their costs: docs/BENCHMARKS.md
  §7).

Linearised about the flat rest shape, like the rest of the stability analysis.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import ArpackNoConvergence, eigs

from ..model import ClothModel
from ..physics.forces import spring_sums
from ..physics.stability import (
    GridStencil,
    effective_stiffness,
    fastest_mode,
    fourier_symbols,
    grid_stencil,
    plane_basis,
    rest_matrices,
    spectral_radii,
)


def _kang_parts(model: ClothModel, k: np.ndarray):
    """Kang's graph matrices: adjacency ``A`` (weights ``k``) and the per-particle sums ``Σ_j
    k_ij``."""
    n = model.n_particles
    s = model.springs
    adj = sp.coo_matrix(
        (np.r_[k, k], (np.r_[s[:, 0], s[:, 1]], np.r_[s[:, 1], s[:, 0]])), shape=(n, n)
    ).tocsr()
    return adj, spring_sums(s, k, n)


def kang_step_matrix(
    model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float, dt: float, sweeps: int = 1
) -> sp.csr_matrix:
    """Kang's step as a linear map of ``(δx, v, Δv_prev)`` over the free coordinates, for the
    system linearised about its rest shape (force ``−K·δx − C·v − drag·v``), with ``sweeps`` Jacobi
    sweeps:
    ``Δv⁽ˢ⁺¹⁾ = R + G·Δv⁽ˢ⁾`` from ``Δv⁽⁰⁾ = Δv_prev``, so ``Δv' = (I + G + … + G^{S−1}) R + G^S
    Δv_prev``
    with ``R = W(dt·f + dt²·H v)``, ``G = dt²·W·A`` and ``W = (M + dt²·diag Σk)⁻¹``."""
    K, C = rest_matrices(model, k, c)
    adj, ksum = _kang_parts(model, k)
    A3 = sp.kron(adj, sp.identity(3), format="csr")
    H3 = A3 - sp.diags(np.repeat(ksum, 3))
    free = np.repeat(~model.pinned, 3)
    W = sp.diags(1.0 / np.repeat(model.masses + dt * dt * ksum, 3)[free])

    def sel(X):
        return X.tocsr()[free][:, free]

    K, C, H3, A3 = sel(K), sel(C), sel(H3), sel(A3)
    eye = sp.identity(K.shape[0], format="csr")
    G = (W @ (dt * dt * A3)).tocsr()
    P, Gs = eye.copy(), eye.copy()
    for _ in range(int(sweeps) - 1):
        Gs = (Gs @ G).tocsr()
        P = P + Gs
    Gs = (Gs @ G).tocsr()
    Dx = P @ (W @ (-dt * K))
    Dv = P @ (W @ (-dt * (C + drag * eye) + dt * dt * H3))
    # Δv' = Dx δx + Dv v + Gs Δv ;  v' = v + Δv' ;  δx' = δx + dt·v'
    return sp.bmat(
        [[eye + dt * Dx, dt * (eye + Dv), dt * Gs], [Dx, eye + Dv, Gs], [Dx, Dv, Gs]], format="csr"
    )


def spectral_radius(T: sp.spmatrix) -> float:
    """Largest eigenvalue modulus of a sparse matrix (dense up to 600 rows, ARPACK above, dense
    again up to 4000 rows where ARPACK does not converge)."""
    if T.shape[0] == 0:
        return 0.0
    if T.shape[0] > 600:
        try:
            vals = eigs(T, k=3, which="LM", return_eigenvectors=False, tol=1e-6, maxiter=100000)
            return float(np.max(np.abs(vals)))
        except ArpackNoConvergence:
            if T.shape[0] > 4000:
                raise
    return float(np.max(np.abs(np.linalg.eigvals(T.toarray()))))


def kang_fourier_radius(
    st: GridStencil, drag: float, dt: float, sweeps: int = 1, symbols=None
) -> float:
    """Largest spectral radius over wavenumbers of Kang's step on the infinite grid: the Fourier
    symbol of :func:`kang_step_matrix`, split into the span of the springs' directions (the cloth's
    plane: a 6×6 per wavenumber) and the directions across it, where no spring acts at rest (a 2×2
    closed form, with the translation's eigenvalue 1). ``symbols``: :func:`fourier_symbols` of
    ``st``, which do not depend on ``dt`` (computed here when not given)."""
    symbols = symbols if symbols is not None else fourier_symbols(st)
    return max(1.0, float(np.max(kang_fourier_radii(st, drag, dt, sweeps, symbols))))


def kang_fourier_radii(
    st: GridStencil, drag: float, dt: float, sweeps: int, symbols, which=None
) -> np.ndarray:
    """:func:`kang_fourier_radius` per wavenumber (those of ``which``, an index array, or all)."""
    K, C, H, A, D = symbols
    if which is not None:
        K, C, H, A = K[which], C[which], H[which], A[which]
    nt = len(K)
    E = plane_basis(st)
    d = E.shape[1]
    K, C = E.T @ K @ E, E.T @ C @ E
    W = 1.0 / (st.mass + dt * dt * D)
    g = W * dt * dt * A  # G = g·I
    P = sum(g**j for j in range(int(sweeps)))
    gS = g ** int(sweeps)
    Id = np.broadcast_to(np.eye(d), (nt, d, d))
    Dx = (P * W * -dt)[:, None, None] * K
    Dv = (P * W)[:, None, None] * (-dt * (C + drag * Id) + (dt * dt * H)[:, None, None] * Id)
    Dd = gS[:, None, None] * Id
    T = np.empty((nt, 3 * d, 3 * d))
    blocks = [[Id + dt * Dx, dt * (Id + Dv), dt * Dd], [Dx, Id + Dv, Dd], [Dx, Dv, Dd]]
    for i, row in enumerate(blocks):
        for j, block in enumerate(row):
            T[:, i * d : (i + 1) * d, j * d : (j + 1) * d] = block
    rho = np.max(np.abs(np.linalg.eigvals(T)), axis=-1)
    if d < 3:  # across the plane: Δv' = dv·v + gS·Δv (no spring force at rest), and x' = x + dt·v'
        dv = P * W * (-dt * drag + dt * dt * H)
        across = np.empty((nt, 2, 2))
        across[:, 0, 0], across[:, 0, 1], across[:, 1, 0], across[:, 1, 1] = 1 + dv, gS, dv, gS
        rho = np.maximum(rho, spectral_radii(across))
    return rho


def _bisect_stable(
    stable, omega: float, rel_tol: float, guess: float = 1.0, ceiling: bool = False
) -> float:
    """Largest ``dt`` with ``stable(dt)`` on the grid ``dt_j = (1 + rel_tol)^j / ω``: bracketed
    from the point nearest ``guess/ω`` (the last material's ``ω·dt`` limit: a material change moves
    it little, and a good guess is bracketed by 10 grid steps in two evaluations) by widening
    steps, then bisected over ``j``. The answer is a grid point, so it does not depend on the guess
    (stability being monotone near the limit), only the number of evaluations does. ``inf`` when
    still stable at ``1000/ω``, 0 when unstable at ``1e-6/ω``. ``ceiling``: ``guess/ω`` is a grid
    point above which every point is known to be unstable (an analysis of a subset of the modes
    found it), so the search only goes down from it."""
    r = math.log1p(rel_tol)

    def at(j):
        return math.exp(j * r) / omega

    j_max, j_min = math.ceil(math.log(1e3) / r), math.floor(math.log(1e-6) / r)
    j = min(max(round(math.log(guess) / r), j_min), j_max)
    here = stable(at(j))
    if here and ceiling:
        return at(j)
    if here:
        lo, hi = j, j + 10
        while stable(at(hi)):
            if hi >= j_max:
                return math.inf
            lo, hi = hi, min(hi + 2 * (hi - lo), j_max)
    else:
        lo, hi = j - 10, j
        while not stable(at(lo)):
            if lo <= j_min:
                return 0.0
            hi, lo = lo, max(lo - 2 * (hi - lo), j_min)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if stable(at(mid)) else (lo, mid)
    return at(lo)


#: Kang's last ``ω·dt`` limit per number of sweeps: where the next analysis starts.
_KANG_GUESS: dict = {}


def kang_stable_dt(
    model: ClothModel,
    k: np.ndarray,
    c: np.ndarray,
    drag: float,
    sweeps: int = 1,
    omega: float | None = None,
    rel_tol: float = 0.01,
    method: str = "auto",
) -> float:
    """Largest ``dt`` whose linearised Kang step has spectral radius ≤ 1, by bisection to
    ``rel_tol``. ``method``: ``"fourier"`` (a regular grid with uniform families: the infinite
    grid's von Neumann analysis, which leaves out the boundary rows and the pins), ``"full"`` (the
    whole step matrix, seconds to minutes) or ``"auto"`` (Fourier where it applies). Linearised
    about the flat rest shape, it is conservative: a cloth hanging under gravity survives up to
    about twice this step."""
    if omega is None:
        omega = fastest_mode(model, k, c, drag).omega
    if omega == 0.0:
        return math.inf
    st = grid_stencil(model, k, c) if method in ("auto", "fourier") else None
    if st is None and method == "fourier":
        raise ValueError("the Fourier analysis needs a regular grid with uniform spring families")
    guess = _KANG_GUESS.get(int(sweeps), 1.0)  # the last material's ω·dt limit: where to start
    if st is not None:
        # the grid's own wavenumbers πj/N up to N = 24 (the finite grid has none finer; the
        # instability sits at long wavelengths, so the limit falls slowly as the sampling gets
        # finer:
        # 24 per axis is within 1.5 % of 48)
        n_theta = min(24, max(model.rows, model.cols))
        symbols = fourier_symbols(st, n_theta)
        # a coarse search first, on the wavenumbers πj/n_coarse with n_coarse dividing n_theta:
        # they are some of the fine set's, so its limit bounds the fine one from above, and the
        # fine search (over ten times the matrices) starts there and only goes down: a material far
        # from the last one once cost 15 fine evaluations (0.1–0.2 s inside a parameter callback)
        n_coarse = max(d for d in range(1, 7) if n_theta % d == 0)
        coarse = fourier_symbols(st, n_coarse)
        watch = [None]  # the wavenumbers that were worst last time: checked first, alone

        def stable_on(symbols):
            def stable(h):
                # an instability found on the watched few is one of the whole set: most unstable
                # evaluations of the search cost a tenth of a full one
                if (
                    watch[0] is not None
                    and np.max(kang_fourier_radii(st, drag, h, sweeps, symbols, watch[0]))
                    > 1.0 + 1e-9
                ):
                    return False
                rho = kang_fourier_radii(st, drag, h, sweeps, symbols)
                watch[0] = np.argsort(rho)[-8:]
                return float(np.max(rho)) <= 1.0 + 1e-9

            return stable

        upper = _bisect_stable(stable_on(coarse), omega, rel_tol, guess)
        watch[0] = None  # indices into the coarse set
        if upper == 0.0:
            return 0.0
        if upper < math.inf:
            limit = _bisect_stable(stable_on(symbols), omega, rel_tol, upper * omega, ceiling=True)
        else:
            limit = _bisect_stable(stable_on(symbols), omega, rel_tol, guess)
    elif method == "auto" and model.n_particles > KANG_FULL_MAX:
        # the whole step's spectral radius costs minutes here: a uniform grid with this network's
        # stiffest particle's load per mass stands in for it (an estimate, not a bound)
        grid, kg, cg = equivalent_grid(model, k, c)
        return kang_stable_dt(grid, kg, cg, drag, sweeps, rel_tol=rel_tol)
    else:

        def stable(h):
            return spectral_radius(kang_step_matrix(model, k, c, drag, h, sweeps)) <= 1.0 + 1e-7

        limit = _bisect_stable(stable, omega, rel_tol, guess)
    if 0.0 < limit < math.inf:
        _KANG_GUESS[int(sweeps)] = limit * omega
    return limit


#: spring networks (not regular grids) with more particles than this get Kang's limit from
#: :func:`equivalent_grid` (the whole step's spectral radius takes seconds at 256 particles and
#: minutes at 1024)
KANG_FULL_MAX = 300


def equivalent_grid(model: ClothModel, k: np.ndarray, c: np.ndarray):
    """``(grid model, k, c)``: a uniform 24×24 grid standing in for a spring network in Kang's
    analysis. Kang's Jacobi lag is set by each particle's ``dt²·Σk / (m + dt²·Σk)``: the grid's
    springs carry the network's mean stiffness and damping per family (structural, shear = the
    network's first family, bend = its last) and its particles the mass that gives them the largest
    ``Σk/m`` of the network's particles. An estimate (the network's shape and pins are not
    represented), computed in milliseconds at any size."""
    k = np.asarray(k, np.float64)
    c = np.asarray(c, np.float64)
    load = spring_sums(model.springs, effective_stiffness(model, k), model.n_particles)
    free = ~model.pinned
    worst = float(np.max(load[free] / model.masses[free])) if free.any() else 0.0
    fam = model.family
    first, last = 0, len(model.family_names) - 1

    def mean(a, f):
        sel = fam == f
        return float(a[sel].mean()) if sel.any() else 0.0

    ks = {"structural": mean(k, first), "shear": mean(k, first), "bend": mean(k, last)}
    cs = {"structural": mean(c, first), "shear": mean(c, first), "bend": mean(c, last)}
    grid = ClothModel.grid(24, 24, 0.01, 1.0, stiffness=ks, damping=cs, model=model.model)
    g_load = spring_sums(grid.springs, effective_stiffness(grid, grid.stiffness), grid.n_particles)
    mass = float(g_load.max()) / worst if worst > 0 else 1.0
    grid = dataclasses.replace(grid, masses=np.full(grid.n_particles, mass))
    return grid, np.array(grid.stiffness), np.array(grid.damping)
