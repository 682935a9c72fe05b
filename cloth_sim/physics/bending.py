"""Bending with a flexural rigidity: the quadratic (isometric) bending energy of Bergou, Wardetzky,
Harmon, Zorin & Grinspun (2006), "A Quadratic Bending Model for Inextensible Surfaces".

Why not springs: a spring ``[i]–[i+2]`` across a flat strip (Provot's bend springs) changes length
only with the *square* of the strip's curvature, so it resists a small bend not at all and a
cantilever of it droops as if it had no rigidity; it has no flexural rigidity ``G`` (N·m) to map a
fabric's onto. Choi & Ko's buckling pair has one, but its force jumps from 0 to ``12 k_b/L²`` at
the onset, where a cloth at rest sits. The energy here is ``E = ½ Σ_s B_s ‖Σ_k w_sk x_k‖²`` with
``Σ_k w_sk = 0``, one term per **stencil** ``s`` (a few particles, weights ``w_s`` that annihilate
a straight or flat configuration): ``x_{i−1} − 2x_i + x_{i+1}`` along a grid line, ``≈ a²κ`` for a
line bent to curvature ``κ``, and the cotangent Laplacian at each interior vertex of a triangle
mesh (the discrete Laplace–Beltrami operator, whose image of the positions is the mean-curvature
normal). For a surface bent without stretching (what cloth does) ``‖Σ w x‖`` is that curvature
measure, so the energy is rotation invariant and consistent with ``½ G κ²`` per area. It is
*quadratic*: the force is ``−(Q ⊗ I₃) x`` with ``Q = Σ_s B_s w_s w_sᵀ`` a constant ``n × n``
matrix, and the Hessian is that constant ``Q`` — every integrator can take it implicitly at no
extra assembly.

What it leaves out (Bergou et al. say so): the energy assumes a flat rest shape (a mesh modelled
curved relaxes towards flat by its bending rigidity, which for fabrics is small: bending lengths of
1–3 cm), and the plate's ``2ν κ_xx κ_yy`` coupling (a strip bent cylindrically, as in the textile
tests, does not have it).
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from ..contact.geometry import read_only
from ..kernel_cache import keep_true
from .mesh import half_edges, triangle_areas


class Bending:
    """Stencils ``(s, k)`` particle indices with weights ``(s, k)`` (rows summing to 0; unused
    slots weight 0) and rigidities ``B (s,)`` (N/m: ``G`` × the stencil's width over its length
    cubed), assembled once into ``Q`` (CSR, ``n × n``)."""

    def __init__(self, stencils, weights, rigidity, n: int):
        idx = np.ascontiguousarray(stencils, dtype=np.int64)
        w = np.ascontiguousarray(weights, dtype=np.float64)
        b = np.ascontiguousarray(rigidity, dtype=np.float64).ravel()
        if idx.ndim != 2 or w.shape != idx.shape or b.shape != (len(idx),):
            raise ValueError("bending: stencils and weights must be (s, k) and rigidity (s,)")
        if len(idx) and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"bending: particle indices must lie in [0, {n - 1}]")
        if np.any(~np.isfinite(b)) or np.any(b < 0) or np.any(~np.isfinite(w)):
            raise ValueError("bending: rigidities must be finite and >= 0, weights finite")
        self.stencils, self.weights, self.rigidity, self.n = idx, w, b, int(n)
        k = idx.shape[1] if idx.ndim == 2 else 0
        rows = np.repeat(idx, k, axis=1).ravel()
        cols = np.tile(idx, (1, k)).ravel()
        vals = (b[:, None, None] * w[:, :, None] * w[:, None, :]).ravel()
        Q = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
        Q.sum_duplicates()
        Q.eliminate_zeros()
        Q.sort_indices()
        self.Q = Q
        for a in (idx, w, b):
            a.setflags(write=False)

        #: ``Q``'s CSR rows with 64-bit indices (its diagonal in them), what the kernels read
        self.csr = (Q.indptr.astype(np.int64), Q.indices.astype(np.int64), Q.data)

    # ------------------------------------------------------------------ evaluation
    def add_force(self, x: np.ndarray, f: np.ndarray) -> None:
        """``f −= Q x`` (each coordinate), by :func:`bending_forces`."""
        bending_forces(x, *self.csr, f)

    def energy(self, x: np.ndarray) -> float:
        """``½ Σ_s B_s ‖Σ_k w_sk x_k‖²`` (:func:`bending_energy`; ``x`` read as a read-only
        view, one compiled signature whoever owns it)."""
        return float(
            bending_energy(read_only(x, np.float64), self.stencils, self.weights, self.rigidity)
        )

    def hessian(self) -> sp.csr_matrix:
        """``Q ⊗ I₃`` (``3n × 3n``): minus the force's Jacobian, constant."""
        return sp.kron(self.Q, sp.identity(3), format="csr")

    def rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:attr:`csr` and the diagonal ``Q_ii``: what a per-vertex solver (``vbd``) reads."""
        return (*self.csr, self.Q.diagonal())

    def couplings(self) -> tuple[np.ndarray, np.ndarray]:
        """``((p, 2) pairs, (p,) Q_ij)``: the particle pairs ``Q`` couples (``i < j``) and its
        entries there — a per-vertex solver's colouring keeps each pair in different colours, and
        each is a zero-length spring of stiffness ``−Q_ij`` in a Jacobian (``Q``'s rows sum to
        0)."""
        Q = self.Q.tocoo()
        keep = Q.row < Q.col
        return np.stack([Q.row[keep], Q.col[keep]], axis=1).astype(np.int64), Q.data[keep]


@numba.njit(cache=True, inline="always")
def bending_row(x, qptr, qidx, qval, p):
    """``−(Q x)_p`` from ``Q``'s CSR rows: particle ``p``'s bending force."""
    bx = by = bz = 0.0
    for e in range(qptr[p], qptr[p + 1]):
        j = qidx[e]
        w = qval[e]
        bx -= w * x[j, 0]
        by -= w * x[j, 1]
        bz -= w * x[j, 2]
    return bx, by, bz


@numba.njit(cache=True)
def bending_energy(x, stencils, weights, rigidity):
    """``½ Σ_s B_s ‖Σ_k w_sk x_k‖²``, one stencil after another: what the node's statistics and
    energy balance ask every tick (the same sum gathered by NumPy took 3.2 ms a call at
    128×128, the kernel 0.19: docs/BENCHMARKS.md §11)."""
    total = 0.0
    for s in range(stencils.shape[0]):
        dx = dy = dz = 0.0
        for k in range(stencils.shape[1]):
            w = weights[s, k]
            p = stencils[s, k]
            dx += w * x[p, 0]
            dy += w * x[p, 1]
            dz += w * x[p, 2]
        total += rigidity[s] * (dx * dx + dy * dy + dz * dz)
    return 0.5 * total


@numba.njit(cache=True)
def bending_forces(x, qptr, qidx, qval, f):
    """``f −= (Q ⊗ I₃) x`` from ``Q``'s CSR rows, one particle after another."""
    for p in range(x.shape[0]):
        bx, by, bz = bending_row(x, qptr, qidx, qval, p)
        f[p, 0] += bx
        f[p, 1] += by
        f[p, 2] += bz


def grid_stencils(
    rows: int, cols: int, ax: float, ay: float, g_warp: float, g_weft: float, poisson: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``rows × cols`` grid (particle ``(r, c)`` at index ``r·cols + c``, spacing ``ax`` along
    columns, ``ay`` along rows) with flexural rigidities ``g_warp`` (curvature along the rows'
    direction, +y) and ``g_weft`` (+x), N·m.

    * Along each grid line, ``x_{i−1} − 2x_i + x_{i+1}`` with ``B = G·w/a³``: for a line of spacing
      ``a`` bent to curvature ``κ`` it is ``a²κ``, so the term is ``½ G κ²`` over the strip of
      length ``a`` and width ``w`` the middle particle stands for (``w`` the cross spacing, half on
      the cloth's edge lines): a strip of any resolution carries ``G`` exactly.
    * Per cell, the twist ``x_00 − x_10 − x_01 + x_11 ≈ ax·ay·κ_xy`` with ``B = 2(1 − ν)·√(G_w G_f)
      /(ax·ay)``: a plate's ``(1 − ν) D κ_xy²``, so that the grid has no zero-energy saddle. It is
      zero for any in-plane parallelogram, so it does not resist shear."""
    idx = np.arange(rows * cols).reshape(rows, cols)
    sten, wts, rig = [], [], []
    if rows >= 3 and g_warp > 0:
        width = np.full(cols, ax)
        width[[0, -1]] = ax / 2 if cols > 1 else ax
        s = np.stack([idx[:-2, :], idx[1:-1, :], idx[2:, :]], axis=-1).reshape(-1, 3)
        sten.append(np.pad(s, ((0, 0), (0, 1)), mode="edge"))
        wts.append(np.tile([1.0, -2.0, 1.0, 0.0], (len(s), 1)))
        rig.append(np.tile(g_warp * width / ay**3, rows - 2))
    if cols >= 3 and g_weft > 0:
        width = np.full(rows, ay)
        width[[0, -1]] = ay / 2 if rows > 1 else ay
        s = np.stack([idx[:, :-2], idx[:, 1:-1], idx[:, 2:]], axis=-1).reshape(-1, 3)
        sten.append(np.pad(s, ((0, 0), (0, 1)), mode="edge"))
        wts.append(np.tile([1.0, -2.0, 1.0, 0.0], (len(s), 1)))
        rig.append(np.repeat(g_weft * width / ax**3, cols - 2))
    d = np.sqrt(g_warp * g_weft)
    if rows >= 2 and cols >= 2 and d > 0 and poisson < 1:
        s = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[:-1, 1:], idx[1:, 1:]], axis=-1)
        s = s.reshape(-1, 4)
        sten.append(s)
        wts.append(np.tile([1.0, -1.0, -1.0, 1.0], (len(s), 1)))
        rig.append(np.full(len(s), 2.0 * (1.0 - poisson) * d / (ax * ay)))
    if not sten:
        return np.zeros((0, 4), np.int64), np.zeros((0, 4)), np.zeros(0)
    return np.concatenate(sten), np.concatenate(wts), np.concatenate(rig)


def mesh_stencils(x: np.ndarray, triangles: np.ndarray, g: float):
    """One stencil per interior vertex of a triangle mesh: the cotangent Laplacian,
    ``(Lx)_v = Σ_j w_vj (x_j − x_v)``, ``w_vj = ½(cot α + cot β)`` over the two angles facing edge
    ``vj``, which is ``2H·n·A_v`` (the mean-curvature normal times the vertex's area ``A_v``, a
    third of its triangles'), with rigidity ``G/A_v``: ``½G|Lx|²/A_v = ½G(2H)²A_v``, which is
    ``½Gκ²`` per area for a cylindrical bend on any mesh (Wardetzky et al. 2007's vertex-based
    quadratic energy; the per-edge form of Bergou et al. sums the Laplacian's pieces' squares
    instead, which on a mesh of right triangles came out 0.78 of the continuum's and on an
    equilateral one 0.99). Boundary vertices have none (a free edge carries no moment). The rest
    shape is taken as flat (the module's note); ``G`` isotropic (a mesh has no warp direction
    here)."""

    n = len(x)
    if g <= 0 or not len(triangles):
        return np.zeros((0, 1), np.int64), np.zeros((0, 1)), np.zeros(0)
    t = np.asarray(triangles, np.int64)
    # the cotangent of each corner, which weighs the edge facing it
    w_pairs, w_vals = [], []
    for k in range(3):
        a, b, c = t[:, k], t[:, (k + 1) % 3], t[:, (k + 2) % 3]
        u, v = x[b] - x[a], x[c] - x[a]
        cot = np.einsum("ij,ij->i", u, v) / np.maximum(
            np.linalg.norm(np.cross(u, v), axis=1), 1e-300
        )
        w_pairs.append(np.stack([b, c], axis=1))
        w_vals.append(0.5 * cot)
    pairs = np.concatenate(w_pairs)
    vals = np.concatenate(w_vals)
    pairs = np.concatenate([pairs, pairs[:, ::-1]])
    vals = np.concatenate([vals, vals])
    W = sp.csr_matrix((vals, (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    W.sum_duplicates()
    _, group, counts = half_edges(t, n)
    lo = np.minimum(t, np.roll(t, -1, axis=1)).ravel()
    hi = np.maximum(t, np.roll(t, -1, axis=1)).ravel()
    boundary = np.zeros(n, bool)
    once = counts[group] == 1
    boundary[lo[once]] = True
    boundary[hi[once]] = True
    area = np.bincount(t.ravel(), weights=np.repeat(triangle_areas(x, t) / 3.0, 3), minlength=n)
    inner = np.flatnonzero(~boundary & (np.diff(W.indptr) > 0))
    width = int(np.diff(W.indptr)[inner].max()) + 1 if len(inner) else 1
    sten = np.repeat(inner[:, None], width, axis=1)
    wts = np.zeros((len(inner), width))
    for r, v in enumerate(inner):
        lo_, hi_ = W.indptr[v], W.indptr[v + 1]
        k = hi_ - lo_
        sten[r, 1 : k + 1] = W.indices[lo_:hi_]
        wts[r, 1 : k + 1] = W.data[lo_:hi_]
        wts[r, 0] = -W.data[lo_:hi_].sum()
    return sten, wts, g / area[inner]


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
