"""Linear stability analysis: pure functions of a model and its material, and a cache of their results.

* :func:`rest_matrices` — stiffness and damping matrices ``K``, ``C`` linearised about the rest shape.
* :func:`fastest_mode` — ``(ω_max, ζ)``: the highest natural frequency of ``M⁻¹K`` over the free
  particles (Lanczos, tight) and that mode's damping ratio, spring damping and drag included.
* :func:`amplification_limit` — a one-step method's largest stable ``ω·dt`` at damping ratio ``ζ``,
  from its amplification matrix (spectral radius ≤ 1); cached per method and ``ζ``.
* :func:`kang_step_matrix`, :func:`kang_stable_dt` — Kang et al.'s approximated implicit step has no
  scalar mode model (its matrix ignores the springs' directions and lags the neighbours' ``Δv``), so
  its step is analysed as a whole: a von Neumann (Fourier) analysis of the infinite grid for a
  regular grid with uniform families (tens of milliseconds), the spectral radius of the whole linearised
  step matrix otherwise (ARPACK: seconds at 16×16, minutes at 32×32).
* :class:`Analysis` — one material's results, computed at most once: :func:`analysis_for` returns
  the same object for the same model, stiffness, damping and drag, so the node's parameter checks
  and the simulator share them, and nothing here runs inside a step or an error path.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from functools import lru_cache
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import ArpackNoConvergence, eigs, eigsh

from .forces import BUCKLE_TABLE, buckling_h, spring_coupling_matrix, spring_sums
from .model import BUCKLING, ClothModel

#: The amplification scan's resolution in ω·dt and its end (no method here is stable beyond 8).
_SCAN_STEP, _SCAN_END = 0.05, 8.0


class Mode(NamedTuple):
    """The fastest linear mode: natural frequency ``omega`` (rad/s) and damping ratio ``zeta``."""

    omega: float
    zeta: float


# --------------------------------------------------------------------------- matrices
def effective_stiffness(model: ClothModel, k: np.ndarray) -> np.ndarray:
    """Per-spring stiffness of the linearisation: Choi–Ko buckling pairs count with the stiffer of
    their two branches (``k`` stretched, ``k·max|h''|/L³`` compressed)."""
    return springs_effective_stiffness(model.kind, model.rest_lengths, k)


def springs_effective_stiffness(kind: np.ndarray, rest: np.ndarray, k: np.ndarray) -> np.ndarray:
    """:func:`effective_stiffness` of a list of springs given by their kinds and rest lengths."""
    k_eff = np.array(k, dtype=np.float64)
    buck = kind == BUCKLING
    if buck.any():
        L = rest[buck]
        k_eff[buck] = np.maximum(k_eff[buck], k_eff[buck] * _buckling_curvature_max() / L ** 3)
    return k_eff


@lru_cache(maxsize=1)
def _buckling_curvature_max() -> float:
    return float(np.max(np.abs([buckling_h(r)[2] for r in np.linspace(0, 1, len(BUCKLE_TABLE))])))


def rest_directions(model: ClothModel) -> np.ndarray:
    """Unit vectors along each spring at rest, ``(m, 3)``."""
    d = model.positions[model.springs[:, 1]] - model.positions[model.springs[:, 0]]
    return d / np.linalg.norm(d, axis=1)[:, None]


def rest_matrices(model: ClothModel, k: np.ndarray, c: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``(K, C)``: ``3n×3n`` ``Σ k uuᵀ`` and ``Σ c uuᵀ`` over the springs about the rest shape
    (``u`` the rest directions; :func:`effective_stiffness` for Choi–Ko). Near rest the force is
    ``−K·δx − C·v``."""
    u = rest_directions(model)
    uu = np.einsum("si,sj->sij", u, u)
    n = model.n_particles

    def axial(w):
        blocks = -np.asarray(w)[:, None, None] * uu
        return spring_coupling_matrix(model.springs, blocks, blocks, n)

    return axial(effective_stiffness(model, k)), axial(c)


class _ModeBasis(NamedTuple):
    """Per model: ``B`` (m × free dofs), row ``s`` = ``u_sᵀ`` at ``j`` and ``−u_sᵀ`` at ``i``, columns
    scaled by ``m^-½``, so that ``M^-½ K M^-½ = Bᵀ diag(k_eff) B`` over the free particles; and the
    squared scale per free dof (``1/m``)."""

    B: sp.csr_matrix
    inv_mass: np.ndarray
    last_mode: list  # [q] of the last fastest mode found on this model: the next solve starts there


_BASES: OrderedDict = OrderedDict()


def _mode_basis(model: ClothModel) -> _ModeBasis:
    hit = _BASES.get(id(model))
    if hit is not None and hit[0] is model:
        return hit[1]
    m, n = model.n_springs, model.n_particles
    u = rest_directions(model)
    i, j = model.springs[:, 0], model.springs[:, 1]
    rows = np.repeat(np.arange(m), 6)
    cols = np.concatenate([3 * j[:, None] + np.arange(3), 3 * i[:, None] + np.arange(3)], axis=1).ravel()
    vals = np.concatenate([u, -u], axis=1).ravel()
    B = sp.csr_matrix((vals, (rows, cols)), shape=(m, 3 * n))
    dofs = np.repeat(~model.pinned, 3)
    scale = np.repeat(1.0 / np.sqrt(model.masses), 3)[dofs]
    basis = _ModeBasis((B[:, dofs] @ sp.diags(scale)).tocsr(), scale * scale,
                       [np.linspace(1.0, 2.0, int(dofs.sum()))])
    _BASES[id(model)] = (model, basis)
    while len(_BASES) > _ANALYSES_KEPT:
        _BASES.popitem(last=False)
    return basis


def fastest_mode(model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float = 0.0) -> Mode:
    """``(ω_max, ζ)`` of the free particles linearised about the rest shape: ``ω_max²`` the largest
    eigenvalue of ``M^-½ K M^-½`` (Lanczos, so tight: the tests' 16×16 cloth gives 3.15·√(k/m);
    assembled as ``Bᵀ diag(k_eff) B`` from a basis kept per model, started from the model's last
    mode), ``ζ = qᵀ(C + drag·I)q / 2ω`` in the mass-weighted mode ``q``. 5–15 ms at 32×32."""
    if not (~model.pinned).any() or model.n_springs == 0:
        return Mode(0.0, 0.0)
    basis = _mode_basis(model)
    B, k_eff = basis.B, effective_stiffness(model, k)
    nd = B.shape[1]
    if not np.any(k_eff > 0):  # no stiffness at all: no oscillation (ARPACK would fail on A = 0)
        return Mode(0.0, 0.0)
    if nd <= 3:
        vals, vecs = np.linalg.eigh((B.T @ sp.diags(k_eff) @ B).toarray())
        lam, q = vals[-1], vecs[:, -1]
    else:
        A = (B.T @ sp.diags(k_eff) @ B).tocsr()
        # started from the model's last mode (a material change moves it little: 3–5× fewer
        # iterations); tol 1e-6 gives ω to about 1e-8 relative, whatever the start
        vals, vecs = eigsh(A, k=1, which="LA", tol=1e-6, v0=basis.last_mode[0])
        lam, q = vals[0], vecs[:, 0]
        basis.last_mode[0] = q
    omega = math.sqrt(max(lam, 0.0))
    if omega == 0.0:
        return Mode(0.0, 0.0)
    Bq = B @ q
    damping = float(Bq @ (np.asarray(c, np.float64) * Bq)) + float(drag) * float(q @ (basis.inv_mass * q))
    return Mode(omega, damping / (2.0 * omega))


# --------------------------------------------------------------------------- one-step methods
@lru_cache(maxsize=256)
def amplification_limit(method: type, zeta: float) -> float:
    """Largest ``x = ω·dt`` with spectral radius of ``method.amplification(x, 1, ζ)`` ≤ 1, found by
    scanning ``x`` in steps of 0.05 up to the first unstable point, then bisecting. 0 when no step
    is stable (an undamped explicit Euler or midpoint), ``inf`` when none up to 8 is unstable."""
    if method.needs_damping and zeta <= 0:
        return 0.0

    return _scan_then_bisect(
        lambda x: spectral_radius_small(method.amplification(x, 1.0, zeta)) <= 1 + 1e-12)


def _scan_then_bisect(stable) -> float:
    """The end of the stable interval starting at 0: scan in steps of ``_SCAN_STEP`` to the first
    unstable point, then bisect 60 times; ``inf`` when stable up to ``_SCAN_END``."""
    last_ok = 0.0
    for x in np.arange(_SCAN_STEP, _SCAN_END + _SCAN_STEP / 2, _SCAN_STEP):
        if not stable(x):
            break
        last_ok = x
    else:
        return math.inf
    lo, hi = last_ok, x
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def spectral_radius_small(A: np.ndarray) -> float:
    """Spectral radius of a small dense matrix (closed form for 2×2)."""
    if A.shape == (2, 2):
        half_tr = 0.5 * (A[0, 0] + A[1, 1])
        det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        disc = half_tr * half_tr - det
        if disc < 0:  # a complex pair: |λ|² = det
            return math.sqrt(det)
        root = math.sqrt(disc)
        return max(abs(half_tr + root), abs(half_tr - root))
    return float(np.max(np.abs(np.linalg.eigvals(A))))


@lru_cache(maxsize=64)
def damping_limit(method: type) -> float:
    """Largest ``y = c·dt`` at which a one-step method is stable on pure damping ``v' = −c v`` (a
    mode without stiffness: a particle's drag, ``c = drag/m``), from the same amplification matrix
    with ``ω → 0``; ``inf`` when none up to 8 is unstable."""
    eps = 1e-8  # ω = ε, ζ = 1/(2ε): unit damping, stiffness ε² (nothing)
    return _scan_then_bisect(
        lambda y: spectral_radius_small(method.amplification(y, eps, 0.5 / eps)) <= 1 + 1e-9)


def limit_from_mode(method: type, mode: Mode) -> float:
    """``dt`` limit of a one-step method on the fastest mode (``inf`` when ``ω = 0``)."""
    if mode.omega <= 0:
        return math.inf
    return amplification_limit(method, round(mode.zeta, 12)) / mode.omega


def one_step_limit(method: type, analysis: "Analysis") -> float:
    """A one-step method's ``dt`` limit on a material: the fastest mode's, and that of the slowest
    modes, which drag alone damps (``c = drag/m`` of the lightest free particle, no stiffness): an
    explicit method overshoots a damping it takes explicitly (symplectic Euler needs ``c·dt ≤ 2``)."""
    limit = limit_from_mode(method, analysis.mode)
    free = ~analysis.model.pinned
    if analysis.drag > 0 and free.any():
        c = analysis.drag / float(analysis.model.masses[free].min())
        limit = min(limit, damping_limit(method) / c)
    if method.needs_damping:
        limit = min(limit, _lightly_damped_limit(method, analysis))
    return limit


def _lightly_damped_limit(method: type, analysis: "Analysis") -> float:
    """For a method that needs damping on every mode (explicit Euler, midpoint), the fastest mode is
    not the only danger: a slower, lightly damped one grows too. With ``α = min c_s/k_s`` over the
    stiff springs, ``C ≥ αK`` spring by spring, so every mode has ``ζ ≥ αω/2``; the limit along
    ``ζ = αω/2`` for ``ω`` from ω_max/32 to ω_max (8 points) bounds them (explicit Euler: exactly ``dt ≤ α``). A stiff
    spring without damping (α = 0) leaves a mode no step is stable for: 0."""
    stiff = analysis.k > 0
    omega_max = analysis.mode.omega
    if not stiff.any() or omega_max <= 0:
        return math.inf
    alpha = float(np.min(analysis.c[stiff] / analysis.k[stiff]))
    if alpha <= 0:
        return 0.0
    return min(amplification_limit(method, round(alpha * w / 2, 12)) / w
               for w in omega_max * np.geomspace(1 / 32, 1, 8))


# --------------------------------------------------------------------------- Kang et al. 2000
def _kang_parts(model: ClothModel, k: np.ndarray):
    """Kang's graph matrices: adjacency ``A`` (weights ``k``) and the per-particle sums ``Σ_j k_ij``."""
    n = model.n_particles
    s = model.springs
    adj = sp.coo_matrix((np.r_[k, k], (np.r_[s[:, 0], s[:, 1]], np.r_[s[:, 1], s[:, 0]])),
                        shape=(n, n)).tocsr()
    return adj, spring_sums(s, k, n)


def kang_step_matrix(model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float, dt: float,
                     sweeps: int = 1) -> sp.csr_matrix:
    """Kang's step as a linear map of ``(δx, v, Δv_prev)`` over the free coordinates, for the system
    linearised about its rest shape (force ``−K·δx − C·v − drag·v``), with ``sweeps`` Jacobi sweeps:
    ``Δv⁽ˢ⁺¹⁾ = R + G·Δv⁽ˢ⁾`` from ``Δv⁽⁰⁾ = Δv_prev``, so ``Δv' = (I + G + … + G^{S−1}) R + G^S Δv_prev``
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
    return sp.bmat([[eye + dt * Dx, dt * (eye + Dv), dt * Gs],
                    [Dx, eye + Dv, Gs],
                    [Dx, Dv, Gs]], format="csr")


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


class GridStencil(NamedTuple):
    """A regular grid's springs grouped by offset ``(dr, dc)``, each group uniform: per group the
    offset, rest direction ``u``, stiffness ``k``, linearised stiffness ``k_eff`` and damping ``c``;
    and the particle mass."""

    offsets: np.ndarray  # (g, 2)
    u: np.ndarray        # (g, 3)
    k: np.ndarray
    k_eff: np.ndarray
    c: np.ndarray
    mass: float


def grid_stencil(model: ClothModel, k: np.ndarray, c: np.ndarray) -> GridStencil | None:
    """The model's stencil when it is a regular grid with uniform masses and every offset's springs
    share stiffness and damping; ``None`` otherwise (then only the whole-system analysis applies)."""
    def uniform(a):  # rest lengths differ in the last bits from spring to spring
        return np.ptp(a) <= 1e-9 * np.max(np.abs(a))

    if model.cols is None or model.n_springs == 0 or not uniform(model.masses):
        return None
    s = model.springs
    r0, c0 = np.divmod(s[:, 0], model.cols)
    r1, c1 = np.divmod(s[:, 1], model.cols)
    d = np.stack([r1 - r0, c1 - c0], axis=1)
    flip = (d[:, 0] < 0) | ((d[:, 0] == 0) & (d[:, 1] < 0))
    d[flip] *= -1
    u = rest_directions(model)
    u[flip] *= -1
    k_eff = effective_stiffness(model, k)
    offsets, group = np.unique(d, axis=0, return_inverse=True)
    group = group.ravel()
    rows = []
    for g in range(len(offsets)):
        sel = group == g
        if not all(uniform(arr) for arr in (k[sel], k_eff[sel], c[sel])):
            return None
        if np.max(np.abs(u[sel] - u[sel][0])) > 1e-9:
            return None
        rows.append((u[sel][0], k[sel][0], k_eff[sel][0], c[sel][0]))
    return GridStencil(offsets.astype(float), np.array([r[0] for r in rows]),
                       np.array([r[1] for r in rows]), np.array([r[2] for r in rows]),
                       np.array([r[3] for r in rows]), float(model.masses[0]))


def _mirror_symmetric(st: GridStencil) -> bool:
    """Whether reflecting the columns (offset ``(dr, dc)`` → ``(dr, −dc)``) maps the stencil onto itself
    with the same material: then ``θ_c`` and ``−θ_c`` have the same spectral radius."""
    groups = {(float(o[0]), float(o[1])): (k, ke, c) for o, k, ke, c in
              zip(st.offsets, st.k, st.k_eff, st.c)}
    for (dr, dc), values in groups.items():
        mirror = (dr, -dc) if dr > 0 or dc == 0 else (dr, dc)  # (0, dc) maps to (0, −dc) ~ (0, dc)
        if mirror not in groups or not np.allclose(groups[mirror], values, rtol=1e-12, atol=0):
            return False
    return True


def _fourier_symbols(st: GridStencil, n_theta: int = 24):
    """Per wavenumber ``θ`` on ``[0, π] × [−π, π]`` (``[0, π]²`` for a mirror-symmetric stencil) in
    steps of ``π/n_theta``: ``K̂, Ĉ`` (3×3), ``Ĥ`` and ``Â`` (scalars times the identity) and
    ``D = Σ_j k_ij`` of an interior particle."""
    tr = np.linspace(0.0, np.pi, n_theta + 1)
    tc = tr if _mirror_symmetric(st) else np.linspace(-np.pi, np.pi, 2 * n_theta + 1)
    TR, TC = np.meshgrid(tr, tc, indexing="ij")
    phase = TR.ravel()[:, None] * st.offsets[None, :, 0] + TC.ravel()[:, None] * st.offsets[None, :, 1]
    s = 2.0 - 2.0 * np.cos(phase)  # (θ, g): (2 − e^{iφ} − e^{−iφ}) of a pair coupling
    uu = np.einsum("gi,gj->gij", st.u, st.u)
    K = np.einsum("tg,g,gij->tij", s, st.k_eff, uu)
    C = np.einsum("tg,g,gij->tij", s, st.c, uu)
    H = -(s @ st.k)
    A = (2.0 * np.cos(phase)) @ st.k
    return K, C, H, A, 2.0 * st.k.sum()


def kang_fourier_radius(st: GridStencil, drag: float, dt: float, sweeps: int = 1,
                        symbols=None) -> float:
    """Largest spectral radius over wavenumbers of Kang's step on the infinite grid: the Fourier
    symbol of :func:`kang_step_matrix`, split into the span of the springs' directions (the cloth's
    plane: a 6×6 per wavenumber) and the directions across it, where no spring acts at rest (a 2×2
    closed form, with the translation's eigenvalue 1). ``symbols``: :func:`_fourier_symbols` of
    ``st``, which do not depend on ``dt`` (computed here when not given)."""
    K, C, H, A, D = symbols if symbols is not None else _fourier_symbols(st)
    nt = len(K)
    _, sv, vt = np.linalg.svd(st.u)
    d = int(np.sum(sv > 1e-9 * sv[0]))
    E = vt[:d].T  # (3, d): an orthonormal basis of the springs' directions
    K, C = E.T @ K @ E, E.T @ C @ E
    W = 1.0 / (st.mass + dt * dt * D)
    g = W * dt * dt * A  # G = g·I
    P = sum(g ** j for j in range(int(sweeps)))
    gS = g ** int(sweeps)
    Id = np.broadcast_to(np.eye(d), (nt, d, d))
    Dx = (P * W * -dt)[:, None, None] * K
    Dv = (P * W)[:, None, None] * (-dt * (C + drag * Id) + (dt * dt * H)[:, None, None] * Id)
    Dd = gS[:, None, None] * Id
    T = np.empty((nt, 3 * d, 3 * d))
    blocks = [[Id + dt * Dx, dt * (Id + Dv), dt * Dd], [Dx, Id + Dv, Dd], [Dx, Dv, Dd]]
    for i, row in enumerate(blocks):
        for j, block in enumerate(row):
            T[:, i * d:(i + 1) * d, j * d:(j + 1) * d] = block
    rho = float(np.max(np.abs(np.linalg.eigvals(T))))
    if d < 3:  # across the plane: Δv' = dv·v + gS·Δv (no spring force at rest), and x' = x + dt·v'
        dv = P * W * (-dt * drag + dt * dt * H)
        across = np.empty((nt, 2, 2))
        across[:, 0, 0], across[:, 0, 1], across[:, 1, 0], across[:, 1, 1] = 1 + dv, gS, dv, gS
        rho = max(rho, 1.0, float(np.max(np.abs(np.linalg.eigvals(across)))))
    return rho


def _bisect_stable(stable, omega: float, rel_tol: float) -> float:
    """Largest ``dt`` with ``stable(dt)``, bracketed from ``1/ω`` by doubling/halving, then bisected
    to ``rel_tol``; ``inf`` when still stable at ``1000/ω``."""
    lo, hi = 0.0, 1.0 / omega
    while stable(hi):
        lo, hi = hi, 2.0 * hi
        if hi > 1e3 / omega:
            return math.inf
    if lo == 0.0:
        lo = hi / 8
        while not stable(lo):
            hi, lo = lo, lo / 8
            if lo < 1e-6 / omega:
                return 0.0
    while hi - lo > rel_tol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def kang_stable_dt(model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float, sweeps: int = 1,
                   omega: float | None = None, rel_tol: float = 0.01,
                   method: str = "auto") -> float:
    """Largest ``dt`` whose linearised Kang step has spectral radius ≤ 1, by bisection to
    ``rel_tol``. ``method``: ``"fourier"`` (a regular grid with uniform families: the infinite
    grid's von Neumann analysis, which leaves out the boundary rows and the pins), ``"full"`` (the
    whole step matrix, seconds to minutes) or ``"auto"`` (Fourier where it applies). Linearised about
    the flat rest shape, it is conservative: a cloth hanging under gravity survives up to about twice
    this step."""
    if omega is None:
        omega = fastest_mode(model, k, c, drag).omega
    if omega == 0.0:
        return math.inf
    st = grid_stencil(model, k, c) if method in ("auto", "fourier") else None
    if st is None and method == "fourier":
        raise ValueError("the Fourier analysis needs a regular grid with uniform spring families")
    if st is not None:
        # the grid's own wavenumbers πj/N up to N = 24 (the finite grid has none finer; the
        # instability sits at long wavelengths, so the limit falls slowly as the sampling gets finer:
        # 24 per axis is within 1.5 % of 48)
        symbols = _fourier_symbols(st, min(24, max(model.rows, model.cols)))

        def stable(h):
            return kang_fourier_radius(st, drag, h, sweeps, symbols) <= 1.0 + 1e-9
    else:
        def stable(h):
            return spectral_radius(kang_step_matrix(model, k, c, drag, h, sweeps)) <= 1.0 + 1e-7
    return _bisect_stable(stable, omega, rel_tol)


# --------------------------------------------------------------------------- cache
class Analysis:
    """The stability results of one material (model, per-spring stiffness and damping, drag),
    each computed when first asked and kept."""

    def __init__(self, model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float):
        self.model = model
        self.k = np.array(k, dtype=np.float64)
        self.c = np.array(c, dtype=np.float64)
        self.drag = float(drag)
        self._mode: Mode | None = None
        self._limits: dict = {}

    @property
    def mode(self) -> Mode:
        if self._mode is None:
            self._mode = fastest_mode(self.model, self.k, self.c, self.drag)
        return self._mode

    def limit(self, key, compute) -> float:
        """``compute(self)`` the first time ``key`` is asked for, the kept value after."""
        if key not in self._limits:
            self._limits[key] = float(compute(self))
        return self._limits[key]

    def known(self, key) -> float | None:
        """A limit already computed, or ``None`` (never computes)."""
        return self._limits.get(key)


_ANALYSES: OrderedDict = OrderedDict()
_ANALYSES_KEPT = 16


def analysis_for(model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float) -> Analysis:
    """The :class:`Analysis` of this material, shared by every caller that asks with equal values
    (the last 16 are kept)."""
    k = np.ascontiguousarray(k, dtype=np.float64)
    c = np.ascontiguousarray(c, dtype=np.float64)
    key = (id(model), k.tobytes(), c.tobytes(), float(drag))
    hit = _ANALYSES.get(key)
    if hit is not None and hit.model is model:
        _ANALYSES.move_to_end(key)
        return hit
    a = Analysis(model, k, c, drag)
    _ANALYSES[key] = a
    while len(_ANALYSES) > _ANALYSES_KEPT:
        _ANALYSES.popitem(last=False)
    return a
