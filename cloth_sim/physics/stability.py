"""Linear stability analysis: pure functions of a model and its material, and a cache of their
results.

* :func:`rest_matrices` — stiffness and damping matrices ``K``, ``C`` linearised about the rest
  shape.
* :func:`fastest_mode` — ``(ω_max, ζ)``: the highest natural frequency of ``M⁻¹K`` over the free
  particles and that mode's damping ratio. On a regular grid it is the von Neumann analysis of the
  infinite grid (an upper bound of the finite cloth's; docs/BENCHMARKS.md §7);
  on any other spring network, Lanczos.
* :func:`damping_rate` — the fastest decay, ``λ_max(M⁻¹(C + drag))`` over every shape the cloth can
  take (the springs' scalar graph Laplacian).
* :func:`mode_set_limit` — a one-step method's largest stable ``dt`` on every mode a material can
  have (``ω ≤ ω_max``, ``α·ω² ≤ c ≤ rate``), from its amplification matrix (spectral radius ≤ 1),
  evaluated on a batch of modes at once.
* :class:`Analysis` — one material's results, computed at most once: :func:`analysis_for` returns
  the same object for the same model, stiffness, damping and drag, so the node's parameter checks
  and the simulator share them, and nothing here runs inside a step or an error path.

Kang et al.'s step, which has no scalar mode model, is analysed as a whole in
:mod:`cloth_sim.integrators.kang_analysis`.

Everything here is linearised: a cloth far from its rest shape may need a smaller step (the
damping rate is taken over every shape for that reason), and forces that are not springs — wind on
the normals, Choi–Ko's buckling force, which jumps at the onset of compression — are not covered.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from functools import lru_cache
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import eigsh

from ..model import BUCKLING, ClothModel
from .force_kernels import BUCKLE_TABLE, buckling_h
from .forces import spring_coupling_matrix, spring_sums


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
        k_eff[buck] = np.maximum(k_eff[buck], k_eff[buck] * _buckling_curvature_max() / L**3)
    return k_eff


#: How far, as a fraction of its rest length, and how fast (m/s) one step may kick a buckling pair
#: at its onset (:func:`buckling_onset_limit`).
ONSET_CHATTER = 0.01
ONSET_SPEED = 10.0


def _onset_pairs(model: ClothModel, k: np.ndarray):
    """The buckling pairs that a step can kick: their rest lengths, ``a_i + a_j`` (the onset loads
    on their ends per mass) and ``w·(1/m_i + 1/m_j)`` (their linearised stiffness per mass);
    ``None`` without any."""
    k = np.asarray(k, dtype=np.float64)
    buck = (model.kind == BUCKLING) & (k > 0)
    if not buck.any():
        return None
    pairs, L = model.springs[buck], model.rest_lengths[buck]
    a = spring_sums(pairs, 12.0 * k[buck] / (L * L), model.n_particles) / model.masses
    a[model.pinned] = 0.0
    reach = a[pairs[:, 0]] + a[pairs[:, 1]]
    moved = reach > 0
    if not moved.any():
        return None
    inv = np.where(model.pinned, 0.0, 1.0 / model.masses)
    stiff = springs_effective_stiffness(model.kind[buck], L, k[buck]) * (
        inv[pairs[:, 0]] + inv[pairs[:, 1]]
    )
    return L[moved], reach[moved], stiff[moved]


def buckling_onset_limit(model: ClothModel, k: np.ndarray) -> float:
    """The largest ``dt`` at which Choi & Ko's buckling onset does not throw the cloth about, for a
    method that does not solve with the pairs' stiffness (the explicit ones, Kang's).

    A compressed type-2 pair pushes with ``12 k_b/L²`` from the first rounding-level compression
    (the immediate-buckling load: the force jumps there from 0), and no linearisation sees a jump,
    so :func:`fastest_mode` misses it. A particle whose pairs' onset loads add to ``F_i`` moves by
    ``F_i·dt²/m_i`` from it in one step, and the pair's tension branch pulls it back the next: a
    chatter of that amplitude and of speed ``F_i·dt/m_i``, which on a stiff bend family
    (``stiffness.bend`` is then a flexural rigidity, N·m²) trips the divergence guard (1000 m/s) at
    steps the modes allow. The limit keeps the kick each pair can get from its two ends, with
    ``a = F/m``, within :data:`ONSET_CHATTER` of its rest length, ``(a_i + a_j)·dt² ≤ 0.01·L``, and
    its speed below :data:`ONSET_SPEED`, ``(a_i + a_j)·dt ≤ 10 m/s``; ``inf`` without buckling
    pairs. A bend rigidity of real cloth (1e-6–1e-4 N·m² per pair) leaves it far above any other
    limit. It bounds a chatter, not a stability boundary: above it the step does not diverge at
    once, it chatters faster."""
    found = _onset_pairs(model, k)
    if found is None:
        return math.inf
    L, reach, _ = found
    return float(min(np.min(np.sqrt(ONSET_CHATTER * L / reach)), ONSET_SPEED / np.max(reach)))


def buckling_onset_band(model: ClothModel, k: np.ndarray) -> tuple[float, float]:
    """The steps ``(lo, hi)`` at which a method that solves with the pairs' linearised stiffness
    ``w`` (the unconditionally stable ones) is thrown about by Choi–Ko's onset load: there the
    kick's speed ``a·dt/(1 + dt²·s)``, ``s = w·(1/m_i + 1/m_j)``, exceeds :data:`ONSET_SPEED` for
    some pair (between the roots of ``V·s·dt² − a·dt + V = 0``). Small steps kick little, large
    ones are absorbed by the stiffness (``choi_ko`` with the prefactored method at 1 ms is calm
    while 1e-5 s is not). ``(inf, inf)`` when no step is: always for a real cloth's bend
    rigidity."""
    found = _onset_pairs(model, k)
    if found is None:
        return math.inf, math.inf
    _, reach, stiff = found
    disc = reach * reach - 4.0 * ONSET_SPEED**2 * stiff
    fast = disc > 0
    if not fast.any():
        return math.inf, math.inf
    root = np.sqrt(disc[fast])
    lo = (reach[fast] - root) / (2.0 * ONSET_SPEED * stiff[fast])
    hi = (reach[fast] + root) / (2.0 * ONSET_SPEED * stiff[fast])
    return float(lo.min()), float(hi.max())


@lru_cache(maxsize=1)
def _buckling_curvature_max() -> float:
    return float(np.max(np.abs([buckling_h(r)[2] for r in np.linspace(0, 1, len(BUCKLE_TABLE))])))


def rest_directions(model: ClothModel) -> np.ndarray:
    """Unit vectors along each spring at rest, ``(m, 3)``."""
    d = model.positions[model.springs[:, 1]] - model.positions[model.springs[:, 0]]
    return d / np.linalg.norm(d, axis=1)[:, None]


def rest_matrices(
    model: ClothModel, k: np.ndarray, c: np.ndarray
) -> tuple[sp.csr_matrix, sp.csr_matrix]:
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
    """Per model: ``B`` (m × free dofs), row ``s`` = ``u_sᵀ`` at ``j`` and ``−u_sᵀ`` at ``i``,
    columns scaled by ``m^-½``, so that ``M^-½ K M^-½ = Bᵀ diag(k_eff) B`` over the free particles;
    and the squared scale per free dof (``1/m``)."""

    B: sp.csr_matrix
    inv_mass: np.ndarray
    last_mode: (
        list  # [q] of the last fastest mode found on this model: the next solve starts there
    )


_BASES: OrderedDict = OrderedDict()


def _mode_basis(model: ClothModel) -> _ModeBasis:
    hit = _BASES.get(id(model))
    if hit is not None and hit[0] is model:
        return hit[1]
    m, n = model.n_springs, model.n_particles
    u = rest_directions(model)
    i, j = model.springs[:, 0], model.springs[:, 1]
    rows = np.repeat(np.arange(m), 6)
    cols = np.concatenate(
        [3 * j[:, None] + np.arange(3), 3 * i[:, None] + np.arange(3)], axis=1
    ).ravel()
    vals = np.concatenate([u, -u], axis=1).ravel()
    B = sp.csr_matrix((vals, (rows, cols)), shape=(m, 3 * n))
    dofs = np.repeat(~model.pinned, 3)
    scale = np.repeat(1.0 / np.sqrt(model.masses), 3)[dofs]
    basis = _ModeBasis(
        (B[:, dofs] @ sp.diags(scale)).tocsr(),
        scale * scale,
        [np.linspace(1.0, 2.0, int(dofs.sum()))],
    )
    _BASES[id(model)] = (model, basis)
    while len(_BASES) > _ANALYSES_KEPT:
        _BASES.popitem(last=False)
    return basis


def fastest_mode(model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float = 0.0) -> Mode:
    """``(ω_max, ζ)`` of the free particles linearised about the rest shape, ``ζ`` that mode's
    damping ratio (spring damping and drag).

    On a regular grid whose families are uniform (:func:`grid_stencil`: every scene) it is the von
    Neumann analysis of the infinite grid: ``ω_max² = sup_θ λ_max(K̂(θ))/m``, an upper bound of the
    finite grid's (its quadratic form is the infinite grid's restricted to the cloth, with fewer
    springs), at the same cost at any size. Elsewhere it is ``λ_max(M^-½ K M^-½)`` by Lanczos
    (tight, but its cost grows with the grid; the figures: docs/BENCHMARKS.md §7)."""
    if not (~model.pinned).any() or model.n_springs == 0:
        return Mode(0.0, 0.0)
    if not np.any(effective_stiffness(model, k) > 0):  # no stiffness at all: no oscillation
        return Mode(0.0, 0.0)
    st = grid_stencil(model, k, c) if getattr(model, "bending", None) is None else None
    if st is not None:
        return _stencil_mode(st, drag)
    return _lanczos_mode(model, k, c, drag)


def _lanczos_mode(model: ClothModel, k: np.ndarray, c: np.ndarray, drag: float) -> Mode:
    """:func:`fastest_mode` of any spring network: ``ω_max²`` the largest eigenvalue of
    ``Bᵀ diag(k_eff) B`` (Lanczos, from the model's last mode), ``ζ = qᵀ(C + drag·I)q / 2ω`` in the
    mass-weighted mode ``q``."""
    basis = _mode_basis(model)
    B, k_eff = basis.B, effective_stiffness(model, k)
    nd = B.shape[1]
    A = (B.T @ sp.diags(k_eff) @ B).tocsr()
    bending = getattr(model, "bending", None)
    if bending is not None:  # a material's bending: + M^-½ (Q ⊗ I) M^-½ on the free dofs
        dofs = np.repeat(~model.pinned, 3)
        scale = sp.diags(np.sqrt(basis.inv_mass))
        A = (A + scale @ bending.hessian()[dofs][:, dofs] @ scale).tocsr()
    if nd <= 3:
        vals, vecs = np.linalg.eigh(A.toarray())
        lam, q = vals[-1], vecs[:, -1]
    else:
        # tol 1e-6 gives ω to about 1e-8 relative, whatever the start
        vals, vecs = eigsh(A, k=1, which="LA", tol=1e-6, v0=basis.last_mode[0])
        lam, q = vals[0], vecs[:, 0]
        basis.last_mode[0] = q
    omega = math.sqrt(max(lam, 0.0))
    if omega == 0.0:
        return Mode(0.0, 0.0)
    Bq = B @ q
    damping = float(Bq @ (np.asarray(c, np.float64) * Bq)) + float(drag) * float(
        q @ (basis.inv_mass * q)
    )
    return Mode(omega, damping / (2.0 * omega))


#: Wavenumbers per half axis of the von Neumann bounds (the sup is sampled on them; the symbols are
#: smooth, and the corners (π, π), (π, 0), (0, π) are among them).
_BOUND_THETA = 48


def _plane_symbols(st: "GridStencil", weights: np.ndarray, which=slice(None)) -> np.ndarray:
    """``Σ_g w_g (2 − 2cos θ·o_g) u_g u_gᵀ`` in the cloth's plane (:func:`plane_basis`), per
    wavenumber of the bounds' sampling (those ``which`` selects): ``(θ, d, d)``."""
    uE = st.u @ plane_basis(st)
    d = uE.shape[1]
    uu = np.einsum("gi,gj->gij", uE, uE).reshape(len(uE), d * d)
    s = 2.0 - 2.0 * _cosines(st.offsets, _BOUND_THETA, _mirror_symmetric(st))[which]
    return (s @ (np.asarray(weights)[:, None] * uu)).reshape(-1, d, d)


def _stencil_mode(st: "GridStencil", drag: float) -> Mode:
    """``(ω, ζ)`` of the infinite grid's fastest Fourier mode: the largest eigenvalue of
    ``K̂(θ)/m`` over the wavenumbers (in the cloth's plane: no spring acts across it at rest), and
    ``ζ = (qᵀĈq + drag)/(2mω)`` in its eigenvector ``q``."""
    lam, vec = _largest_eigenpairs(_plane_symbols(st, st.k_eff))
    t = int(np.argmax(lam))
    if lam[t] <= 0.0:
        return Mode(0.0, 0.0)
    q = vec[t]
    omega = math.sqrt(float(lam[t]) / st.mass)
    C = _plane_symbols(st, st.c, [t])[0]  # at that wavenumber only
    return Mode(omega, (float(q @ C @ q) + float(drag)) / (2.0 * st.mass * omega))


def damping_rate(model: ClothModel, c: np.ndarray, drag: float) -> float:
    """The fastest decay a step must follow, over every shape the cloth can take: the largest
    eigenvalue of ``M⁻¹(C(x) + drag·I)`` over all directions of the springs, which is that of the
    scalar graph Laplacian ``L = Σ c_s (e_j − e_i)(e_j − e_i)ᵀ`` (reached when each spring points
    along the motion across it; at rest a grid's bend springs are crossed and give half of it, and
    a heavily damped cloth stretched under gravity went unstable at 0.6× the rest shape's limit).
    An explicit method overshoots a damping it takes explicitly: symplectic Euler needs ``rate·dt ≤
    2``. The infinite grid's bound on a regular grid, Lanczos elsewhere."""
    free = ~model.pinned
    if not free.any():
        return 0.0
    c = np.asarray(c, dtype=np.float64)
    drag_rate = float(drag) / float(model.masses[free].min())
    if model.n_springs == 0 or not np.any(c > 0):
        return drag_rate
    layout = _layout(model)
    groups = None if layout is None else _per_group(layout, c[:, None])
    if groups is not None:  # the sup over all wavenumbers of Σ_g c_g (2 − 2cos θ·o_g)
        s = 2.0 - 2.0 * _cosines(layout.offsets, _BOUND_THETA, False)
        return (float(np.max(s @ groups[:, 0])) + float(drag)) / layout.mass
    n = model.n_particles
    i, j = model.springs[:, 0], model.springs[:, 1]
    L = sp.coo_matrix(
        (np.r_[c, c, -c, -c], (np.r_[i, j, i, j], np.r_[i, j, j, i])), shape=(n, n)
    ).tocsr()
    scale = sp.diags(1.0 / np.sqrt(model.masses[free]))
    A = (scale @ L[free][:, free] @ scale).tocsr()
    if A.shape[0] <= 16:
        lam = float(np.linalg.eigvalsh(A.toarray())[-1])
    else:
        lam = float(
            eigsh(
                A,
                k=1,
                which="LA",
                tol=1e-6,
                v0=np.linspace(1.0, 2.0, A.shape[0]),
                return_eigenvectors=False,
            )[0]
        )
    return lam + drag_rate


# --------------------------------------------------------------------------- one-step methods
def spectral_radii(A: np.ndarray) -> np.ndarray:
    """Spectral radius of each small dense matrix in a batch ``(..., n, n)`` (closed form for
    2×2: ``|λ|² = det`` for a complex pair, ``|tr/2 ± √disc|`` for real roots)."""
    A = np.asarray(A, dtype=np.float64)
    if A.shape[-2:] != (2, 2):
        return np.max(np.abs(np.linalg.eigvals(A)), axis=-1)
    half_tr = 0.5 * (A[..., 0, 0] + A[..., 1, 1])
    det = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    disc = half_tr * half_tr - det
    root = np.sqrt(np.abs(disc))
    real = np.maximum(np.abs(half_tr + root), np.abs(half_tr - root))
    return np.where(disc < 0, np.sqrt(np.abs(det)), real)


def mode_set(omega: float, rate: float, alpha: float, n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Sample points ``(ω_i, c_i)`` of every linear mode a material can have: natural frequency
    ``ω ≤ ω_max`` and decay rate ``c`` (``= 2ζω``) with ``α·ω² ≤ c ≤ rate``, where ``rate`` is
    :func:`damping_rate` and ``α = min c_s/k_s`` over the stiff springs (``C ≥ α·K`` spring by
    spring, so in every mode). The boundary is sampled densely, corners included; ``ω`` runs from
    ω_max/1024 (a slow, lightly damped mode that explicit Euler and midpoint cannot follow)."""
    if omega > 0:
        w = np.unique(
            np.concatenate([omega * np.geomspace(1 / 1024, 1, n), omega * np.linspace(0.5, 1, n)])
        )
    else:
        w = np.array([0.0])
    lo = alpha * w * w
    hi = np.maximum(rate, lo)
    t = np.linspace(0.0, 1.0, n)
    return np.repeat(w, n), (lo[:, None] + (hi - lo)[:, None] * t[None, :]).ravel()


def mode_set_limit(
    method: type, omega: float, rate: float, alpha: float, rel_tol: float = 1e-4
) -> float:
    """Largest ``dt`` at which ``method``'s amplification matrix has spectral radius ≤ 1 on every
    point of :func:`mode_set`: the fastest mode, the fastest decay, and what lies between (a
    heavily damped soft family is limited by its damping, not by its stiffness: symplectic Euler
    needs ``ω²dt² + 2c·dt ≤ 4``). ``inf`` when nothing oscillates or decays, 0 when some mode is
    unstable at every step (an undamped spring under explicit Euler)."""
    if omega <= 0 and rate <= 0:
        return math.inf
    if method.needs_damping and omega > 0 and alpha <= 0:
        return 0.0
    W, C = mode_set(omega, rate, alpha)
    W = np.maximum(W, 1e-300 if omega <= 0 else omega * 1e-12)  # a pure decay: ω → 0, c kept
    Z = C / (2.0 * W)

    def stable(
        h,
    ):  # one step, every mode at once (bisection evaluates fewer matrices than batches)
        return bool(np.all(method.spectral_radii(h, W, Z) <= 1 + 1e-12))

    scale = 1.0 / max(omega, rate)
    if stable(8.0 * scale):
        if stable(1e3 * scale):
            return math.inf
        lo, hi = 8.0 * scale, 1e3 * scale
    else:
        lo, hi = 0.0, 8.0 * scale
    while hi - lo > rel_tol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return float(lo)


def one_step_limit(method: type, analysis: "Analysis") -> float:
    """A one-step method's ``dt`` limit on a material: :func:`mode_set_limit` with the material's
    ω_max, damping rate and ``α``."""
    k_eff = effective_stiffness(analysis.model, analysis.k)
    stiff = k_eff > 0
    alpha = float(np.min(analysis.c[stiff] / k_eff[stiff])) if stiff.any() else 0.0
    return mode_set_limit(method, analysis.mode.omega, analysis.damping_rate, alpha)


# --------------------------------------------------------------------------- regular grids
class GridStencil(NamedTuple):
    """A regular grid's springs grouped by offset ``(dr, dc)``, each group uniform: per group the
    offset, rest direction ``u``, stiffness ``k``, linearised stiffness ``k_eff`` and damping
    ``c``; and the particle mass."""

    offsets: np.ndarray  # (g, 2)
    u: np.ndarray  # (g, 3)
    k: np.ndarray
    k_eff: np.ndarray
    c: np.ndarray
    mass: float


class _Layout(NamedTuple):
    """Per model: its springs grouped by grid offset (sorted by group, ``starts`` of each), each
    group's offset and rest direction; ``None`` for a model that is not a regular grid with uniform
    masses and directions."""

    offsets: np.ndarray  # (g, 2)
    u: np.ndarray  # (g, 3)
    order: np.ndarray  # springs sorted by group
    starts: np.ndarray  # (g,) first sorted index of each group
    mass: float


_LAYOUTS: OrderedDict = OrderedDict()


def _layout(model: ClothModel) -> _Layout | None:
    hit = _LAYOUTS.get(id(model))
    if hit is not None and hit[0] is model:
        return hit[1]
    layout = _build_layout(model)
    _LAYOUTS[id(model)] = (model, layout)
    while len(_LAYOUTS) > _ANALYSES_KEPT:
        _LAYOUTS.popitem(last=False)
    return layout


def _uniform(a) -> bool:  # rest lengths differ in the last bits from spring to spring
    return np.ptp(a) <= 1e-9 * np.max(np.abs(a))


def _build_layout(model: ClothModel) -> _Layout | None:
    if model.cols is None or model.n_springs == 0 or not _uniform(model.masses):
        return None
    s = model.springs
    r0, c0 = np.divmod(s[:, 0], model.cols)
    r1, c1 = np.divmod(s[:, 1], model.cols)
    d = np.stack([r1 - r0, c1 - c0], axis=1)
    flip = (d[:, 0] < 0) | ((d[:, 0] == 0) & (d[:, 1] < 0))
    d[flip] *= -1
    u = rest_directions(model)
    u[flip] *= -1
    offsets, group = np.unique(d, axis=0, return_inverse=True)
    group = group.ravel()
    order = np.argsort(group, kind="stable")
    starts = np.searchsorted(group[order], np.arange(len(offsets)))
    us = u[order]
    lo, hi = np.minimum.reduceat(us, starts, axis=0), np.maximum.reduceat(us, starts, axis=0)
    if np.max(hi - lo) > 1e-9:
        return None
    return _Layout(offsets.astype(float), us[starts], order, starts, float(model.masses[0]))


def grid_stencil(model: ClothModel, k: np.ndarray, c: np.ndarray) -> GridStencil | None:
    """The model's stencil when it is a regular grid with uniform masses and every offset's springs
    share stiffness and damping; ``None`` otherwise (then only the whole-system analysis applies).
    The grouping is computed once per model; a material costs a few reductions."""
    layout = _layout(model)
    if layout is None:
        return None
    k = np.asarray(k, dtype=np.float64)
    c = np.asarray(c, dtype=np.float64)
    first = _per_group(layout, np.stack([k, effective_stiffness(model, k), c], axis=1))
    if first is None:
        return None
    return GridStencil(
        layout.offsets,
        layout.u,
        first[:, 0].copy(),
        first[:, 1].copy(),
        first[:, 2].copy(),
        layout.mass,
    )


def _per_group(layout: _Layout, values: np.ndarray) -> np.ndarray | None:
    """Per-spring ``values`` (m, columns) as one row per offset group, ``None`` when some group's
    springs differ (beyond the last bits)."""
    values = values[layout.order]
    lo = np.minimum.reduceat(values, layout.starts, axis=0)
    hi = np.maximum.reduceat(values, layout.starts, axis=0)
    if np.any(hi - lo > 1e-9 * np.maximum(np.abs(hi), np.abs(lo))):
        return None
    return values[layout.starts]


def _mirror_symmetric(st: GridStencil) -> bool:
    """Whether reflecting the columns (offset ``(dr, dc)`` → ``(dr, −dc)``) maps the stencil onto
    itself with the same material: then ``θ_c`` and ``−θ_c`` have the same spectral radius."""
    groups = {
        (float(o[0]), float(o[1])): (k, ke, c)
        for o, k, ke, c in zip(st.offsets, st.k, st.k_eff, st.c)
    }
    for (dr, dc), values in groups.items():
        mirror = (dr, -dc) if dr > 0 or dc == 0 else (dr, dc)  # (0, dc) maps to (0, −dc) ~ (0, dc)
        if mirror not in groups or not np.allclose(groups[mirror], values, rtol=1e-12, atol=0):
            return False
    return True


_COSINES: OrderedDict = OrderedDict()


def _cosines(offsets: np.ndarray, n_theta: int, mirror: bool) -> np.ndarray:
    """``cos(θ·offset)`` per wavenumber and offset, ``(θ, g)`` (kept: it depends on the grid
    only)."""
    key = (offsets.tobytes(), n_theta, mirror)
    hit = _COSINES.get(key)
    if hit is None:
        tr = np.linspace(0.0, np.pi, n_theta + 1)
        tc = tr if mirror else np.linspace(-np.pi, np.pi, 2 * n_theta + 1)
        TR, TC = np.meshgrid(tr, tc, indexing="ij")
        hit = np.cos(
            TR.ravel()[:, None] * offsets[None, :, 0] + TC.ravel()[:, None] * offsets[None, :, 1]
        )
        _COSINES[key] = hit
        while len(_COSINES) > 8:
            _COSINES.popitem(last=False)
    return hit


def fourier_symbols(st: GridStencil, n_theta: int = 24):
    """Per wavenumber ``θ`` on ``[0, π] × [−π, π]`` (``[0, π]²`` for a mirror-symmetric stencil) in
    steps of ``π/n_theta``: ``K̂, Ĉ`` (3×3), ``Ĥ`` and ``Â`` (scalars times the identity) and
    ``D = Σ_j k_ij`` of an interior particle."""
    cos = _cosines(st.offsets, n_theta, _mirror_symmetric(st))
    s = 2.0 - 2.0 * cos  # (θ, g): (2 − e^{iφ} − e^{−iφ}) of a pair coupling
    uu = np.einsum("gi,gj->gij", st.u, st.u).reshape(len(st.u), 9)
    K = (s @ (st.k_eff[:, None] * uu)).reshape(-1, 3, 3)
    C = (s @ (st.c[:, None] * uu)).reshape(-1, 3, 3)
    H = -(s @ st.k)
    A = (2.0 * cos) @ st.k
    return K, C, H, A, 2.0 * st.k.sum()


def plane_basis(st: GridStencil) -> np.ndarray:
    """``(3, d)``: an orthonormal basis of the springs' directions (the cloth's plane at rest)."""
    _, sv, vt = np.linalg.svd(st.u)
    return vt[: int(np.sum(sv > 1e-9 * sv[0]))].T


def _largest_eigenpairs(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest eigenvalue and its unit eigenvector of each symmetric matrix in ``(t, d, d)``
    (closed form for 2×2)."""
    if S.shape[-1] != 2:
        vals, vecs = np.linalg.eigh(S)
        return vals[:, -1], vecs[:, :, -1]
    a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
    half, r = 0.5 * (a + c), np.hypot(0.5 * (a - c), b)
    lam = half + r
    # eigenvector (b, λ − a), or (λ − c, b): the larger of the two, for accuracy
    v1 = np.stack([b, lam - a], axis=1)
    v2 = np.stack([lam - c, b], axis=1)
    v = np.where((np.abs(lam - a) >= np.abs(lam - c))[:, None], v1, v2)
    norm = np.linalg.norm(v, axis=1)
    v = np.where(norm[:, None] > 0, v / np.where(norm > 0, norm, 1.0)[:, None], [[1.0, 0.0]])
    return lam, v


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
        self._damping_rate: float | None = None
        self._onset_limit: float | None = None
        self._onset_band: tuple[float, float] | None = None
        self._limits: dict = {}

    @property
    def mode(self) -> Mode:
        if self._mode is None:
            self._mode = fastest_mode(self.model, self.k, self.c, self.drag)
        return self._mode

    @property
    def damping_rate(self) -> float:
        if self._damping_rate is None:
            self._damping_rate = damping_rate(self.model, self.c, self.drag)
        return self._damping_rate

    @property
    def onset_limit(self) -> float:
        """:func:`buckling_onset_limit` of the material (cheap: one pass over the springs)."""
        if self._onset_limit is None:
            self._onset_limit = buckling_onset_limit(self.model, self.k)
        return self._onset_limit

    @property
    def onset_band(self) -> tuple[float, float]:
        """:func:`buckling_onset_band`: the steps at which the methods without a step limit
        chatter."""
        if self._onset_band is None:
            self._onset_band = buckling_onset_band(self.model, self.k)
        return self._onset_band

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
