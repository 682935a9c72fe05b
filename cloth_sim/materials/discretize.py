"""A fabric mapped onto a model: spring stiffnesses, masses and bending stencils that carry the
fabric's values at any resolution.

**Grid** (spacing ``ax`` along columns, the weft, ``ay`` along rows, the warp; one structural
spring per cell side, both diagonals per cell). Under a uniform strain ``ε`` each spring stores
``½k(L ε_n)²``; summed per cell area the lattice's energy density is ``½C11ε_xx² + ½C22ε_yy² +
C12ε_xxε_yy + 2C66ε_xy²`` with

    C11 = k_x·ax/ay + G_d·ax²/ay²,   C22 = k_y·ay/ax + G_d·ay²/ax²,   C12 = C66 = G_d,
    G_d = 2 k_d·ax·ay/d²   (d the diagonal's length),

independent of the cell count: the same material at every resolution. So ``k_d`` is set from the
fabric's shear and ``k_x``, ``k_y`` so that the strip stiffnesses ``C11 − C12²/C22`` and
``C22 − C12²/C11`` are the fabric's weft and warp stretch, exactly. What springs cannot carry is a
Poisson's ratio of its own: it follows as ``ν = C12/C22`` (Cauchy's relation ``C12 = C66``), and
where a fabric's shear stiffness is so high against its stretch that ``k_x`` or ``k_y`` would be
negative, the diagonals take the largest shear that keeps them ≥ 0 (:func:`grid_lattice` says
which). Springs on the cloth's edge stand for half a cell: half stiffness. Masses are the density
times each particle's share of the area (edges a half, corners a quarter). Bending:
:func:`cloth_sim.physics.bending.grid_stencils` (``G`` exactly, at any spacing); Provot's bend
springs are kept with stiffness 0 (``set_stiffness("bend", k)`` adds them back).

**Mesh**: each edge's stiffness is ``E·ΣA_t/l²`` over its triangles (Van Gelder 1998: on an
equilateral mesh it is the triangular lattice of Young's modulus ``E`` and ``ν = 1/3``), with
``E = √(E_warp·E_weft)``: a mesh has no warp direction here, so it is isotropic, and its shear
stiffness follows (``3E/8``). Bending: the cotangent stencils with ``G = √(G_warp·G_weft)``.
"""

from __future__ import annotations

import math

import numpy as np

from ..physics.bending import Bending, grid_stencils, mesh_stencils
from ..physics.mesh import triangle_areas
from .fabric import Fabric


def _moduli(ex: float, ey: float, g: float) -> tuple[float, float]:
    """``(C11, C22)`` with ``C12 = g`` whose strip stiffnesses are ``ex`` (x) and ``ey`` (y)."""
    p = 0.5 * ex + math.sqrt(0.25 * ex * ex + g * g * ex / ey)
    return p, ey * p / ex


def grid_lattice(fabric: Fabric, ax: float, ay: float) -> dict:
    """Per-spring stiffnesses of an interior cell: ``k_x`` (along x, the weft), ``k_y`` (along y,
    the warp), ``k_d`` (each diagonal), and the shear ``G_d`` the diagonals carry (the fabric's, or
    less where the springs cannot: see the module's note) and the Poisson's ratio that follows."""
    ey, ex = fabric.stretch  # warp along +y (rows), weft along +x (columns)
    rx, ry = ax / ay, ay / ax

    def springs(g):
        p, q = _moduli(ex, ey, g)
        return (p - g * rx * rx) / rx, (q - g * ry * ry) / ry, p, q

    g = fabric.shear
    kx, ky, _, _ = springs(g)
    if kx < 0 or ky < 0:  # the largest shear the lattice can carry with the stretch exact
        lo, hi = 0.0, g
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            a, b, _, _ = springs(mid)
            lo, hi = (mid, hi) if (a >= 0 and b >= 0) else (lo, mid)
        g = lo
    kx, ky, p, q = springs(g)
    d2 = ax * ax + ay * ay
    return {
        "k_x": max(kx, 0.0),
        "k_y": max(ky, 0.0),
        "k_d": g * d2 / (2.0 * ax * ay),
        "shear": g,
        "poisson": g / p if p > 0 else 0.0,  # the weft's contraction per warp strain
        "C11": p,
        "C22": q,
    }


def grid_material(
    fabric: Fabric,
    rows: int,
    cols: int,
    ax: float,
    ay: float,
    springs,
    family,
    families,
    pinned=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, Bending]:
    """``(stiffness (m,), damping (m,), masses (n,), bending)`` of a grid's springs (as
    :meth:`~cloth_sim.model.ClothModel.grid` builds them) for ``fabric``."""
    lat = grid_lattice(fabric, ax, ay)
    i, j = springs[:, 0], springs[:, 1]
    ri, ci = np.divmod(i, cols)
    rj, cj = np.divmod(j, cols)
    structural = family == families.index("structural")
    shear = family == families.index("shear")
    along_x = structural & (ri == rj)
    along_y = structural & (ci == cj)
    k = np.zeros(len(springs))
    k[along_x] = lat["k_x"]
    k[along_y] = lat["k_y"]
    k[shear] = lat["k_d"]
    edge = (along_x & ((ri == 0) | (ri == rows - 1))) | (along_y & ((ci == 0) | (ci == cols - 1)))
    k[edge] *= 0.5  # a cloth's edge line stands for half a cell
    share = np.ones(rows * cols)
    r, c = np.divmod(np.arange(rows * cols), cols)
    share[(r == 0) | (r == rows - 1)] *= 0.5
    share[(c == 0) | (c == cols - 1)] *= 0.5
    masses = fabric.density * ax * ay * share
    st, w, b = grid_stencils(rows, cols, ax, ay, *fabric.bend, poisson=fabric.poisson)
    if pinned is not None:
        b = clamped_edges(st, w, b, np.asarray(pinned, bool))
    return k, fabric.damping * k, masses, Bending(st, w, b, rows * cols)


def clamped_edges(stencils, weights, rigidity, pinned) -> np.ndarray:
    """Rigidities of line stencils ``(i−1, i, i+1)`` where the line leaves a clamp at ``i``
    (``i`` and one neighbour pinned, the other free) doubled. There the cloth is straight on one
    side and bent to ``κ`` on the other, so the stencil measures the cell's *average* curvature
    ``κ/2``, and ``½G(κ/2)²·a`` is half the cell's ``½Gκ²·a/2``: left alone, every clamped edge
    is too soft by an amount of the order of the spacing (the cantilever's bending length came
    out 9, 4.7, 2.4, 1.2 % short at 8, 16, 32, 64 cells). Twist stencils are left as they are."""
    line = weights[:, 3] == 0.0
    a, mid, c = (pinned[stencils[:, k]] for k in range(3))
    edge = line & mid & (a != c)
    out = rigidity.copy()
    out[edge] *= 2.0
    return out


def mesh_material(
    fabric: Fabric, x: np.ndarray, triangles: np.ndarray, springs: np.ndarray, family: np.ndarray
) -> tuple[np.ndarray, np.ndarray, Bending]:
    """``(stiffness (m,), damping (m,), bending)`` of a mesh's springs (structural: its edges;
    bend: across interior edges, given stiffness 0) for ``fabric``, isotropic (module's note)."""

    e_iso = math.sqrt(fabric.stretch[0] * fabric.stretch[1])
    area = triangle_areas(x, triangles)
    # every triangle's area to each of its three edges
    tri_edges = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=-1).reshape(-1, 2)
    key = np.sort(tri_edges, axis=1)
    n = np.int64(len(x))
    uniq, inv = np.unique(key[:, 0] * n + key[:, 1], return_inverse=True)
    acc = np.bincount(inv.ravel(), weights=np.repeat(area, 3), minlength=len(uniq))
    k = np.zeros(len(springs))
    s = np.sort(springs, axis=1)
    structural = np.flatnonzero(family == 0)
    at = np.searchsorted(uniq, s[structural, 0] * n + s[structural, 1])
    lengths = np.linalg.norm(x[springs[structural, 1]] - x[springs[structural, 0]], axis=1)
    k[structural] = e_iso * acc[at] / lengths**2
    st, w, b = mesh_stencils(x, triangles, math.sqrt(fabric.bend[0] * fabric.bend[1]))
    return k, fabric.damping * k, Bending(st, w, b, int(n))
