"""Vertex Block Descent: Chen, Macklin, Ju, Li, Kavan, Yuksel et al. (SIGGRAPH 2024), "Vertex Block
Descent" — the solver Newton made its default for cloth.

A step of ``h`` is backward Euler written as the minimum of the incremental potential

    G(x) = Σ_i m_i/(2h²) |x_i − y_i|² + E(x),      y = x^t + h v^t + h² a_ext,

``E`` the springs' energy (every family, Hooke or Choi–Ko's), their damping along the spring and the
air drag as dissipation potentials of ``(x − x^t)/h``, and the contacts' energies. Block coordinate
descent over the vertices: each vertex in turn takes one Newton step on ``G`` with the others held,

    Δx_i = H_i⁻¹ f_i,   f_i = −∂G/∂x_i,   H_i = m_i/h² I + Σ_springs ∂²E/∂x_i² (+ contacts),

its 3×3 Hessian made positive semi-definite term by term (a compressed spring's ``E'/l`` part is
dropped, as the paper and Newton do). Vertices that share no spring never read each other's
positions in their step, so a **colour** of such vertices (greedy colouring of the spring graph) is
updated at once, in parallel. Each vertex writes only its own position and reads its partners'
in contact from the start of the iteration: the result is the same bits at any thread count.
Any iteration count gives a usable state: the iterate is a descent sequence from the initial guess
(the paper's adaptive one: inertia, with gravity's part of the last step's acceleration clamped to
``[0, |g|]``). **Chebyshev acceleration** (the paper's, with its spectral radius ``rho``) blends
each iterate with the one two iterations back; ``rho=0`` turns it off.

Wind acts explicitly (its force at the step's start, in ``y``): it depends on the normals. Pins and
held particles are kinematic: they go to ``x + h v`` and are not solved.

Contacts inside the solve (when the simulator lets the method handle them, :attr:`VBD.handles`):

* **Colliders**: ``½ k_c (τ − d)²`` for a vertex closer than the thickness ``τ`` to a collider
  surface (``d`` the signed distance), and Coulomb friction as IPC's smoothed, lagged friction on
  the vertex's motion relative to the collider's surface over the step (the normal force from the
  current iterate, the contact normal held), as the paper does.
* **Self-contact** between the cloth's own primitives, vertex–triangle and edge–edge, the same
  energy on their distance. Candidates come from the self-collision stage's tree
  (:mod:`cloth_sim.collision_tree`) at the start of the step and every ``collision_interval``
  iterations, each vertex reaching ``τ/2`` plus its allowance of motion (``τ/2`` and 1.5 times its
  inertial motion). **Conservative bound** (the paper's): between two searches a vertex moves at
  most ``γ = 0.45`` of the smallest distance the search found between its primitives (itself, its
  triangles, its edges) and any other, and at most its allowance; so two primitives that were
  ``d`` apart stay ``(1 − 2γ)·d > 0`` apart, those not found stay beyond ``τ``, and no vertex passes
  through the cloth or a collider (its allowance is also kept below the distance to the far side of
  the thinnest collider near it). Over a whole step the cloth never crosses itself.

The self-collision stage does not run after the method (:attr:`VBD.handles`); the contact stage
does, as an exact finish of what the iterations did (the distance and static friction to rounding),
and so does the strain limit where one is set.

Counters (:attr:`Simulator.integrator_stats`): ``steps``, ``iterations``, ``last_iterations``,
``last_residual`` (the root mean square of the free vertices' Newton steps in the last iteration,
m), ``detections`` (candidate searches), ``last_contacts`` (self-contact pairs and vertices touching
a collider at the last search) and ``truncated`` (vertex updates the conservative bound shortened).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from .. import stability as stab  # noqa: F401 (the protocol's stability class comes from the base)
from ..colliders import carried, sdf
from ..forces import BUCKLE_TABLE, GravityTerm, WindTerm, axial, incidence
from ..model import LINEAR
from ..self_collision import closest_on_segment_pair, closest_on_triangle
from . import register
from .base import Integrator, Stability

#: the share of the nearest found distance a vertex may move between two candidate searches
GAMMA = 0.45
#: IPC's friction smoothing: relative tangential motion below EPS_V·h (m) is static
EPS_V = 1e-3
#: vertices per colour below which a colour is updated on one core (the pool's wake-up costs more)
PARALLEL_MIN_VERTICES = 512


# ---------------------------------------------------------------------------- set-up
@numba.njit(cache=True)
def colour_greedy(ptr, nbr, free):
    """Colour of each free vertex (``-1`` for the others): the smallest colour none of its
    neighbours (CSR ``ptr``, ``nbr``) has taken, in vertex order."""
    n = ptr.shape[0] - 1
    colour = np.full(n, -1, np.int64)
    taken = np.full(64, -1, np.int64)  # taken[c] == i: colour c is a neighbour's of vertex i
    for i in range(n):
        if not free[i]:
            continue
        for q in range(ptr[i], ptr[i + 1]):
            c = colour[nbr[q]]
            if c >= 0:
                if c >= taken.shape[0]:
                    grown = np.full(2 * c + 2, -1, np.int64)
                    grown[:taken.shape[0]] = taken
                    taken = grown
                taken[c] = i
        c = 0
        while c < taken.shape[0] and taken[c] == i:
            c += 1
        colour[i] = c
    return colour


def colour_groups(springs: np.ndarray, n: int, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(ptr, verts)``: colour ``c``'s vertices are ``verts[ptr[c]:ptr[c+1]]``, in increasing order;
    no two vertices of a colour share a spring. Pinned vertices are in none."""
    a = np.concatenate([springs[:, 0], springs[:, 1]])
    b = np.concatenate([springs[:, 1], springs[:, 0]])
    order = np.lexsort((b, a))
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(a, minlength=n), out=ptr[1:])
    colour = colour_greedy(ptr, np.ascontiguousarray(b[order]), np.ascontiguousarray(free))
    verts = np.flatnonzero(colour >= 0)
    verts = verts[np.argsort(colour[verts], kind="stable")]
    counts = np.bincount(colour[colour >= 0], minlength=max(int(colour.max()) + 1, 0))
    cptr = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=cptr[1:])
    return cptr, np.ascontiguousarray(verts, dtype=np.int64)


def _csr(owner: np.ndarray, item: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR of ``item`` grouped by ``owner`` (in ``item``'s order within an owner)."""
    order = np.argsort(owner, kind="stable")
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=ptr[1:])
    return ptr, np.ascontiguousarray(item[order], dtype=np.int64)


# ---------------------------------------------------------------------------- per-vertex terms
# A vertex's force is (f0, f1, f2) and its symmetric Hessian (h0 … h5) = (xx, xy, xz, yy, yz, zz);
# each term takes them and returns them with its own part added.
@numba.njit(cache=True, inline="always")
def _solve3(a, b, c, d, e, f, fx, fy, fz):
    """``H⁻¹ f`` for a symmetric positive definite ``H`` (6 entries); zeros if it is singular."""
    c00 = d * f - e * e
    c01 = c * e - b * f
    c02 = b * e - c * d
    det = a * c00 + b * c01 + c * c02
    if not det > 1e-300:
        return 0.0, 0.0, 0.0
    c11 = a * f - c * c
    c12 = b * c - a * e
    c22 = a * d - b * b
    inv = 1.0 / det
    return ((c00 * fx + c01 * fy + c02 * fz) * inv, (c01 * fx + c11 * fy + c12 * fz) * inv,
            (c02 * fx + c12 * fy + c22 * fz) * inv)


@numba.njit(cache=True, inline="always")
def _springs_at(i, x, xt, inc_ptr, nbr, rest, k, c, kind, tab, inv_h,
                f0, f1, f2, h0, h1, h2, h3, h4, h5):
    """Vertex ``i``'s springs: elastic, and damping along the spring; and whether one of them is a
    compressed Choi–Ko buckling pair (the step is then checked against the energy)."""
    rough = False
    xi, yi, zi = x[i, 0], x[i, 1], x[i, 2]
    # the vertex's own motion over the step, for the damping
    mx, my, mz = xi - xt[i, 0], yi - xt[i, 1], zi - xt[i, 2]
    for q in range(inc_ptr[i], inc_ptr[i + 1]):
        j = nbr[q]
        xj, yj, zj = x[j, 0], x[j, 1], x[j, 2]
        dx, dy, dz = xj - xi, yj - yi, zj - zi
        l = math.sqrt(dx * dx + dy * dy + dz * dz)
        if l < 1e-300:
            continue
        inv = 1.0 / l
        ux, uy, uz = dx * inv, dy * inv, dz * inv
        L, kk, kd = rest[q], k[q], kind[q]
        if kd == LINEAR:
            de, d2e = kk * (l - L), kk
        else:
            _, de, d2e = axial(l, L, kk, kd, tab)
            if l < L:
                rough = True  # a compressed Choi–Ko pair: its energy is not smooth at the rest length
        # the force on i pulls it towards j by E'(l); the damping along the spring resists the
        # ends' relative motion over the step
        cs = c[q] * inv_h
        mag = de
        if cs > 0.0:
            mag += cs * (((xj - xt[j, 0]) - mx) * ux + ((yj - xt[j, 1]) - my) * uy
                         + ((zj - xt[j, 2]) - mz) * uz)
        f0 += mag * ux
        f1 += mag * uy
        f2 += mag * uz
        # E'' u uᵀ + (E'/l)(I − u uᵀ), each part clamped at 0 (positive semi-definite), and the
        # damping's (c/h) u uᵀ
        geo = de * inv if de > 0.0 else 0.0
        w = (d2e if d2e > 0.0 else 0.0) + cs - geo
        wx, wy = w * ux, w * uy
        h0 += wx * ux + geo
        h1 += wx * uy
        h2 += wx * uz
        h3 += wy * uy + geo
        h4 += wy * uz
        h5 += w * uz * uz + geo
    return f0, f1, f2, h0, h1, h2, h3, h4, h5, rough


@numba.njit(cache=True, inline="always")
def _local_energy(i, px, py, pz, x, xt, y, m_h2, drag_h, inc_ptr, nbr, rest, k, c, kind, tab,
                  inv_h):
    """The part of the incremental potential that depends on vertex ``i`` placed at ``p``: its
    inertia and drag, its springs' energy and their damping potential (contacts left out)."""
    ax, ay, az = px - y[i, 0], py - y[i, 1], pz - y[i, 2]
    bx, by, bz = px - xt[i, 0], py - xt[i, 1], pz - xt[i, 2]
    e = 0.5 * m_h2[i] * (ax * ax + ay * ay + az * az) + 0.5 * drag_h * (bx * bx + by * by + bz * bz)
    for q in range(inc_ptr[i], inc_ptr[i + 1]):
        j = nbr[q]
        dx, dy, dz = x[j, 0] - px, x[j, 1] - py, x[j, 2] - pz
        l = math.sqrt(dx * dx + dy * dy + dz * dz)
        if l < 1e-300:
            continue
        es, _, _ = axial(l, rest[q], k[q], kind[q], tab)
        e += es
        if c[q] > 0.0:
            rel = ((x[j, 0] - xt[j, 0]) - bx) * dx + ((x[j, 1] - xt[j, 1]) - by) * dy \
                + ((x[j, 2] - xt[j, 2]) - bz) * dz
            rel /= l
            e += 0.5 * c[q] * inv_h * rel * rel
    return e


@numba.njit(cache=True, inline="always")
def _colliders_at(i, x, xt, ckind, cpos, crot, cpos0, crot0, cgeo, cmu, tau, kc, eps,
                  f0, f1, f2, h0, h1, h2, h3, h4, h5):
    """Vertex ``i``'s collider contacts: the penalty, and IPC's lagged friction on its motion over
    the step relative to the collider's point under it; and whether it touches one."""
    touched = False
    for c in range(ckind.shape[0]):
        d, nx, ny, nz = sdf(ckind[c], cpos[c], crot[c], cgeo[c], x[i, 0], x[i, 1], x[i, 2])
        p = tau - d
        if p <= 0.0:
            continue
        touched = True
        lam = kc * p
        f0 += lam * nx
        f1 += lam * ny
        f2 += lam * nz
        h0 += kc * nx * nx
        h1 += kc * nx * ny
        h2 += kc * nx * nz
        h3 += kc * ny * ny
        h4 += kc * ny * nz
        h5 += kc * nz * nz
        mu = cmu[c]
        if mu <= 0.0:
            continue
        # where the collider's point now under the vertex was at the step's start
        sx, sy, sz = carried(cpos0[c], crot0[c], cpos[c], crot[c], x[i, 0], x[i, 1], x[i, 2])
        rx, ry, rz = sx - xt[i, 0], sy - xt[i, 1], sz - xt[i, 2]
        rn = rx * nx + ry * ny + rz * nz
        tx, ty, tz = rx - rn * nx, ry - rn * ny, rz - rn * nz
        tl = math.sqrt(tx * tx + ty * ty + tz * tz)
        g = 1.0 / tl if tl > eps else (2.0 - tl / eps) / eps
        s = mu * lam * g
        f0 -= s * tx
        f1 -= s * ty
        f2 -= s * tz
        # s (I − n nᵀ): the contact normal held
        h0 += s - s * nx * nx
        h1 -= s * nx * ny
        h2 -= s * nx * nz
        h3 += s - s * ny * ny
        h4 -= s * ny * nz
        h5 += s - s * nz * nz
    return f0, f1, f2, h0, h1, h2, h3, h4, h5, touched


@numba.njit(cache=True, inline="always")
def _pick(x, xs, colour, i, p):
    """Vertex ``p``'s position as vertex ``i`` reads it: the iterate (``i`` itself, and the other
    colours', done earlier in this iteration or not yet begun), or, for a vertex of ``i``'s own
    colour (being moved at the same time), where it was when the iteration began."""
    if p != i and colour[p] == colour[i]:
        return xs[p, 0], xs[p, 1], xs[p, 2]
    return x[p, 0], x[p, 1], x[p, 2]


@numba.njit(cache=True, inline="always")
def _self_contacts_at(i, x, xs, colour, rec_ptr, rec, vt, ee, tris, edges, tau, ks,
                      f0, f1, f2, h0, h1, h2, h3, h4, h5):
    """Vertex ``i``'s self-contacts: ``½ k (τ − d)²`` on the distance ``d`` of each vertex–triangle
    pair it is the vertex or a corner of and each edge pair it is an end of (the partners' positions
    by :func:`_pick`: Gauss–Seidel across colours, the same bits at any thread count)."""
    for q in range(rec_ptr[i], rec_ptr[i + 1]):
        r = rec[q]
        pair = r // 2
        if r % 2 == 0:  # vertex–triangle
            p = vt[pair, 0]
            t = vt[pair, 1]
            a, b, cc = tris[t, 0], tris[t, 1], tris[t, 2]
            px, py, pz = _pick(x, xs, colour, i, p)
            ax, ay, az = _pick(x, xs, colour, i, a)
            bx, by, bz = _pick(x, xs, colour, i, b)
            cx, cy, cz = _pick(x, xs, colour, i, cc)
            wa, wb, wc = closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
            nx = px - (wa * ax + wb * bx + wc * cx)
            ny = py - (wa * ay + wb * by + wc * cy)
            nz = pz - (wa * az + wb * bz + wc * cz)
            w = 1.0 if p == i else (-wa if a == i else (-wb if b == i else -wc))
        else:  # edge–edge
            e = ee[pair, 0]
            f = ee[pair, 1]
            a, b, cc, dd = edges[e, 0], edges[e, 1], edges[f, 0], edges[f, 1]
            ax, ay, az = _pick(x, xs, colour, i, a)
            bx, by, bz = _pick(x, xs, colour, i, b)
            cx, cy, cz = _pick(x, xs, colour, i, cc)
            dx, dy, dz = _pick(x, xs, colour, i, dd)
            sv, tv = closest_on_segment_pair(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz)
            nx = (ax + sv * (bx - ax)) - (cx + tv * (dx - cx))
            ny = (ay + sv * (by - ay)) - (cy + tv * (dy - cy))
            nz = (az + sv * (bz - az)) - (cz + tv * (dz - cz))
            w = 1.0 - sv if a == i else (sv if b == i else (tv - 1.0 if cc == i else -tv))
        d = math.sqrt(nx * nx + ny * ny + nz * nz)
        if d >= tau or d < 1e-300 or w == 0.0:
            continue
        nx /= d
        ny /= d
        nz /= d
        # ∂d/∂x_i = w n: the force pushes the pair apart along n
        mag = ks * (tau - d) * w
        f0 += mag * nx
        f1 += mag * ny
        f2 += mag * nz
        s = ks * w * w
        h0 += s * nx * nx
        h1 += s * nx * ny
        h2 += s * nx * nz
        h3 += s * ny * ny
        h4 += s * ny * nz
        h5 += s * nz * nz
    return f0, f1, f2, h0, h1, h2, h3, h4, h5


# ---------------------------------------------------------------------------- the iteration
@numba.njit(cache=True)
def _sweep(verts, lo, hi, x, xt, y, xs, m_h2, sp, inv_h, drag_h, co, tau, kc, eps, sc, ks, x_cd,
           bound, stepped, cut, touch):
    """The Newton steps of vertices ``verts[lo:hi]`` in order, each on the incremental potential,
    written to its row of ``x``, within its conservative bound. ``sp``: each vertex's springs (CSR:
    the other end, rest length, k, c, kind, in the vertex's order) and Choi–Ko's table; ``co``: the
    colliders (:meth:`~cloth_sim.colliders.Contacts.packed`); ``sc``: the self-contact records, pairs
    and topology. (The arrays are unpacked here, once a chunk: unpacked per vertex, or passed one
    by one to a function per vertex, their reference counting cost more than the vertex's work.)"""
    inc_ptr, nbr, rest, k, c, kind, tab, nonsmooth = sp
    ckind, cpos, crot, cpos0, crot0, cgeo, cmu = co
    rec_ptr, rec, vt, ee, tris, edges, colour = sc
    for q in range(lo, hi):
        i = verts[q]
        m = m_h2[i] + drag_h  # the inertia's m/h², and the drag's d/h
        f0 = -m_h2[i] * (x[i, 0] - y[i, 0]) - drag_h * (x[i, 0] - xt[i, 0])
        f1 = -m_h2[i] * (x[i, 1] - y[i, 1]) - drag_h * (x[i, 1] - xt[i, 1])
        f2 = -m_h2[i] * (x[i, 2] - y[i, 2]) - drag_h * (x[i, 2] - xt[i, 2])
        h0, h1, h2, h3, h4, h5 = m, 0.0, 0.0, m, 0.0, m
        f0, f1, f2, h0, h1, h2, h3, h4, h5, rough = _springs_at(i, x, xt, inc_ptr, nbr, rest, k, c,
                                                                kind, tab, inv_h, f0, f1, f2, h0, h1,
                                                                h2, h3, h4, h5)
        touch[i] = 0
        if ckind.shape[0]:
            f0, f1, f2, h0, h1, h2, h3, h4, h5, touched = _colliders_at(i, x, xt, ckind, cpos, crot, cpos0,
                                                               crot0, cgeo, cmu, tau, kc, eps, f0, f1,
                                                               f2, h0, h1, h2, h3, h4, h5)
            if touched:
                touch[i] = 1
        if rec_ptr[i + 1] > rec_ptr[i]:
            touch[i] = 1
            f0, f1, f2, h0, h1, h2, h3, h4, h5 = _self_contacts_at(i, x, xs, colour, rec_ptr, rec, vt, ee,
                                                                   tris, edges, tau, ks, f0, f1, f2,
                                                                   h0, h1, h2, h3, h4, h5)
        sx, sy, sz = _solve3(h0, h1, h2, h3, h4, h5, f0, f1, f2)
        if rough or nonsmooth:
            # Choi–Ko's energies are not smooth at the rest length (a buckling pair's force jumps
            # at the onset, a tension-only pair's stiffness vanishes): Newton's step may overshoot.
            # Backtrack (halving, at most 8 times) until the vertex's energy does not rise, so each
            # vertex step, and so each iteration, descends
            e0 = _local_energy(i, x[i, 0], x[i, 1], x[i, 2], x, xt, y, m_h2, drag_h, inc_ptr, nbr,
                               rest, k, c, kind, tab, inv_h)
            tries = 0
            while _local_energy(i, x[i, 0] + sx, x[i, 1] + sy, x[i, 2] + sz, x, xt, y, m_h2, drag_h,
                                inc_ptr, nbr, rest, k, c, kind, tab, inv_h) > e0:
                tries += 1
                if tries > 8:
                    sx = sy = sz = 0.0
                    break
                sx, sy, sz = 0.5 * sx, 0.5 * sy, 0.5 * sz
        nx, ny, nz = x[i, 0] + sx, x[i, 1] + sy, x[i, 2] + sz
        stepped[i] = sx * sx + sy * sy + sz * sz
        b = bound[i]
        if b < math.inf:
            ex, ey, ez = nx - x_cd[i, 0], ny - x_cd[i, 1], nz - x_cd[i, 2]
            el = math.sqrt(ex * ex + ey * ey + ez * ez)
            if el > b:
                f = b / el
                nx, ny, nz = x_cd[i, 0] + f * ex, x_cd[i, 1] + f * ey, x_cd[i, 2] + f * ez
                cut[i] = 1
        x[i, 0] = nx
        x[i, 1] = ny
        x[i, 2] = nz




#: chunks a colour is cut into for the cores (a fixed number: the result does not depend on it)
CHUNKS = 16


@numba.njit(cache=True, parallel=True)
def _iterate_parallel(verts, cptr, x, xt, y, xs, m_h2, sp, inv_h, drag_h, co, tau, kc, eps, sc, ks,
                      x_cd, bound, stepped, cut, touch):
    """One iteration: the colours in order, each colour's vertices at once, in chunks (each vertex
    writes only its own row; a colour reads other colours' rows and, for contacts, ``xs``)."""
    for col in range(cptr.shape[0] - 1):
        lo, hi = cptr[col], cptr[col + 1]
        size = (hi - lo + CHUNKS - 1) // CHUNKS
        for b in numba.prange(CHUNKS):
            a = lo + b * size
            _sweep(verts, a, min(a + size, hi), x, xt, y, xs, m_h2, sp, inv_h, drag_h, co, tau, kc,
                   eps, sc, ks, x_cd, bound, stepped, cut, touch)


def _iterate_serial(verts, cptr, *args):
    """:func:`_iterate_parallel` on one core (the same bits): the colours' vertices in order."""
    _sweep(verts, 0, len(verts), *args)


@numba.njit(cache=True)
def _chebyshev(x, x_prev2, omega, free, x_cd, bound, cut, touch):
    """``x ← ω (x − x_prev2) + x_prev2`` on the free vertices not in contact (extrapolated, a
    contact's penalty made the cloth chatter on a table), within their bounds."""
    for i in range(x.shape[0]):
        if not free[i] or touch[i]:
            continue
        for d in range(3):
            x[i, d] = omega * (x[i, d] - x_prev2[i, d]) + x_prev2[i, d]
        b = bound[i]
        if b < math.inf:
            ex, ey, ez = x[i, 0] - x_cd[i, 0], x[i, 1] - x_cd[i, 1], x[i, 2] - x_cd[i, 2]
            el = math.sqrt(ex * ex + ey * ey + ez * ez)
            if el > b:
                f = b / el
                x[i, 0] = x_cd[i, 0] + f * ex
                x[i, 1] = x_cd[i, 1] + f * ey
                x[i, 2] = x_cd[i, 2] + f * ez
                cut[i] = 1


@numba.njit(cache=True)
def _bounds(n, x, vt, vt_d, ee, ee_d, tris, edges, vtri_ptr, vtri, vedge_ptr, vedge, allowance,
            ckind, cpos, crot, cgeo, cdepth, tau, gamma, bound):
    """Each vertex's conservative bound: ``γ`` times the smallest distance found between its
    primitives (itself, its triangles, its edges) and any other, at most its allowance, and short
    of the far side of any collider near it."""
    d_v = np.full(n, np.inf)
    d_t = np.full(tris.shape[0], np.inf)
    d_e = np.full(edges.shape[0], np.inf)
    for q in range(vt.shape[0]):
        p, t, d = vt[q, 0], vt[q, 1], vt_d[q]
        d_v[p] = min(d_v[p], d)
        d_t[t] = min(d_t[t], d)
    for q in range(ee.shape[0]):
        d = ee_d[q]
        d_e[ee[q, 0]] = min(d_e[ee[q, 0]], d)
        d_e[ee[q, 1]] = min(d_e[ee[q, 1]], d)
    for i in range(n):
        m = d_v[i]
        for q in range(vtri_ptr[i], vtri_ptr[i + 1]):
            m = min(m, d_t[vtri[q]])
        for q in range(vedge_ptr[i], vedge_ptr[i + 1]):
            m = min(m, d_e[vedge[q]])
        b = min(gamma * m, allowance[i])
        for c in range(ckind.shape[0]):
            if cdepth[c] < math.inf:
                d = sdf(ckind[c], cpos[c], crot[c], cgeo[c], x[i, 0], x[i, 1], x[i, 2])[0]
                b = min(b, max(d, 0.0) + 0.9 * cdepth[c])
        bound[i] = b


@register
class VBD(Integrator):
    """Vertex Block Descent (Chen et al. 2024): backward Euler by per-vertex 3×3 Newton steps over
    colour groups, Chebyshev-accelerated, with collider contact and self-contact inside the
    iterations (module docstring).

    Options: ``iterations`` (default 10) per step; ``rho`` (default 0.8), the Chebyshev
    acceleration's spectral radius estimate, 0 for none (measured on the swinging 48×48 cloth: 0.8
    is the best of 0.5, 0.8, 0.9 and 0.95 at 1/240 s, 15× closer to the converged step than none
    after 10 iterations; docs/BENCHMARKS.md); ``contact_stiffness`` (N/m, default 1e4);
    ``collision_interval`` (default 5): iterations between candidate searches when the cloth
    self-collides; ``time_budget`` (s, default None): when set, iterate until that much wall time
    has passed (at least one iteration, at most ``iterations``) — a node that must keep its tick,
    whose results then depend on the machine.

    First order (backward Euler); no step limit; any iteration count gives a usable state.
    """

    name = "vbd"
    order = 1
    stability = Stability.UNCONDITIONAL
    implicit = True
    force_point = 1.0
    #: backward Euler's step conserves it; the iterations do to their residual (as the CG solve of
    #: implicit_euler does to its tolerance): 2.5e-13 of the momentum after 0.5 s at 200 iterations
    conserves_momentum = True
    counter_names = ("steps", "iterations", "last_iterations", "last_residual", "detections",
                     "last_contacts", "truncated")
    #: the post-step stages resolved inside the iterations. Self-contact, and with it every
    #: self-collision pass, is; the colliders' contacts are in the iterations too, and their stage
    #: still runs after the step, as an exact finish: a penalty leaves the cloth a little inside
    #: the thickness (its weight over the stiffness) and smoothed friction creeps by up to its
    #: smoothing distance a step, where the stage's projection and Coulomb velocity filter hold the
    #: distance and static friction to rounding (a few microseconds a step)
    handles = frozenset({"self_collision"})

    def __init__(self, model, iterations: int = 10, rho: float = 0.8, contact_stiffness: float = 1e4,
                 collision_interval: int = 5, time_budget: float | None = None):
        super().__init__(model)
        for name, value, hi in (("iterations", iterations, 10_000),
                                ("collision_interval", collision_interval, 10_000)):
            if isinstance(value, bool) or int(value) != value or not 1 <= value <= hi:
                raise ValueError(f"{name} must be an integer in [1, {hi}], got {value!r}")
        if not (isinstance(rho, (int, float)) and 0.0 <= rho < 1.0):
            raise ValueError(f"rho must be a number in [0, 1), got {rho!r}")
        if not (isinstance(contact_stiffness, (int, float)) and 0 < contact_stiffness < math.inf):
            raise ValueError(f"contact_stiffness must be a positive number (N/m), got {contact_stiffness!r}")
        if time_budget is not None and not (isinstance(time_budget, (int, float))
                                            and 0 < time_budget < math.inf):
            raise ValueError(f"time_budget must be None or a positive number of seconds, "
                             f"got {time_budget!r}")
        self.iterations = int(iterations)
        self.rho = float(rho)
        self.contact_stiffness = float(contact_stiffness)
        self.collision_interval = int(collision_interval)
        self.time_budget = None if time_budget is None else float(time_budget)
        self.free = ~np.asarray(model.pinned, bool)
        self._layout_of = None
        self._colours_of = None
        self._contacts = None
        self._self_collision = None
        n = model.n_particles
        self._a_prev = np.zeros((n, 3))
        self._stepped = np.zeros(n)
        self._cut = np.zeros(n, np.int8)
        self._touch = np.zeros(n, np.int8)  # in contact in the last iteration: not extrapolated
        self._no_touch = np.zeros(n, np.int8)
        self._bound = np.full(n, np.inf)
        tris = np.ascontiguousarray(model.triangles, dtype=np.int64).reshape(-1, 3)
        self._tris = tris
        self._no_rec = (np.zeros(n + 1, np.int64), np.zeros(0, np.int64), np.zeros((0, 2), np.int64),
                        np.zeros((0, 2), np.int64))
        self._no_colliders = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                              np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 4)), np.zeros(0))

    # ------------------------------------------------------------------ protocol
    def attach(self, contacts, self_collision) -> None:
        self._contacts = contacts
        self._self_collision = self_collision

    def reset(self, state, forces, dt):
        self._a_prev[:] = 0.0

    def _layout(self, forces):
        """Per force pipeline: each vertex's springs (CSR of the other end and the spring's
        material, in the vertex's order, read contiguously) and the colour groups (per set of
        live springs)."""
        if self._layout_of is not forces:
            n = self.model.n_particles
            springs = forces.springs
            ptr, inc, _ = incidence(springs, n)
            ends = np.repeat(np.arange(n), np.diff(ptr))
            nbr = springs[inc, 0] + springs[inc, 1] - ends
            # a model with Choi–Ko pairs checks every vertex step against the energy (the line
            # search in _sweep): one compressed pair makes its neighbours' steps overshoot too
            nonsmooth = bool(np.any(forces.kind != LINEAR))
            self._springs = (ptr, np.ascontiguousarray(nbr, dtype=np.int64),
                             *(np.ascontiguousarray(a[inc]) for a in (forces.rest, forces.k, forces.c,
                                                                      forces.kind)), BUCKLE_TABLE,
                             nonsmooth)
            if self._colours_of is None or not np.array_equal(self._colours_of, springs):
                self._colours = colour_groups(springs, n, self.free)
                self._colours_of = springs
                cptr, verts = self._colours
                self._colour = np.full(n, -1, np.int64)
                self._colour[verts] = np.repeat(np.arange(len(cptr) - 1), np.diff(cptr))
            self._layout_of = forces
        return self._springs, self._colours

    @property
    def colours(self) -> int:
        """How many colour groups the last step used."""
        return len(self._colours[0]) - 1 if self._layout_of is not None else 0

    # ------------------------------------------------------------------ the step
    def step(self, state, forces, dt):
        x, v = state.x, state.v
        model = self.model
        sp, (cptr, verts) = self._layout(forces)
        free = self.free
        n = len(x)
        h = dt
        xt = self._buffer("_xt", x)
        np.copyto(xt, x)
        # the external acceleration: gravity and the wind at the step's start
        a = self._buffer("_a", x)
        a[:] = 0.0
        for term in forces.terms:
            if isinstance(term, (GravityTerm, WindTerm)):
                term.add_force(x, v, a)
        a /= model.masses[:, None]
        y = self._buffer("_y", x)
        np.multiply(v, h, out=y)
        y += xt
        y[free] += (h * h) * a[free]
        # the paper's adaptive initial guess: inertia, with gravity's part of the last step's
        # acceleration clamped to [0, |g|]
        g = forces.gravity
        gn = float(np.linalg.norm(g))
        np.copyto(x, y)
        if gn > 0:
            gh = g / gn
            along = np.clip(self._a_prev @ gh, 0.0, gn)
            x[free] += (h * h) * ((along[free] - gn)[:, None] * gh)  # y has all of g: keep `along`
        x[~free] = y[~free]  # kinematic: pins and held particles go to x + h v
        m_h2 = model.masses / (h * h)
        drag_h = forces.drag / h
        # contacts handled here: colliders, and self-contact's candidates and bounds
        contacts = self._contacts
        colliders = self._no_colliders
        tau = 0.0
        if contacts is not None and contacts.active:
            colliders = contacts.packed()
            tau = contacts.thickness
        sc = self._self_collision
        self_contact = sc is not None and sc.active
        if self_contact:
            tau = sc.thickness
        rec = self._no_rec
        x_cd = self._buffer("_x_cd", x)
        bound = self._bound
        bound[:] = np.inf
        if self_contact or len(colliders[0]):
            rec = self._detect(xt, y, colliders, tau, self_contact, x_cd)
            # the initial guess within the bounds
            _chebyshev(x, x_cd, 1.0, free, x_cd, bound, self._cut, self._no_touch)
        xs = self._buffer("_xs", x)
        prev2 = self._buffer("_prev2", x)
        np.copyto(prev2, x)
        ks = self.contact_stiffness
        kc = self.contact_stiffness
        eps = EPS_V * h
        run = _iterate_parallel if len(verts) >= PARALLEL_MIN_VERTICES else _iterate_serial
        stepped, cut, touch = self._stepped, self._cut, self._touch
        stepped[:] = 0.0
        cut[:] = 0
        omega = 1.0
        budget_end = None if self.time_budget is None else time.perf_counter() + self.time_budget
        done = 0
        for it in range(self.iterations):
            if self_contact and it > 0 and it % self.collision_interval == 0:
                rec = self._detect(x, y, colliders, tau, self_contact, x_cd)
            np.copyto(xs, x)
            run(verts, cptr, x, xt, y, xs, m_h2, sp, 1.0 / h, drag_h, colliders, tau, kc, eps,
                (*rec, self._tris, self._edges(), self._colour), ks, x_cd, bound, stepped, cut,
                touch)
            done += 1
            if self.rho > 0.0:
                # Chebyshev: ω₁ = 1, ω₂ = 2/(2 − ρ²), ω_k = 4/(4 − ρ² ω_{k−1})
                omega = 1.0 if it == 0 else (2.0 / (2.0 - self.rho ** 2) if it == 1
                                             else 4.0 / (4.0 - self.rho ** 2 * omega))
                if it > 0:
                    _chebyshev(x, prev2, omega, free, x_cd, bound, cut, touch)
                np.copyto(prev2, xs)
            if budget_end is not None and time.perf_counter() >= budget_end:
                break
        # v = (x − x^t)/h; pins keep their velocity (they moved by h·v)
        new_v = (x - xt) / h
        acc = (new_v - v) / h
        v[free] = new_v[free]
        self._a_prev[:] = acc
        c = self.counters
        c["steps"] += 1
        c["iterations"] += done
        c["last_iterations"] = done
        nf = int(free.sum())
        c["last_residual"] = float(math.sqrt(stepped[free].sum() / nf)) if nf else 0.0
        c["truncated"] += int(cut.sum())

    def _edges(self):
        sc = self._self_collision
        return sc.edges if sc is not None else np.zeros((0, 2), np.int64)

    def _detect(self, x, y, colliders, tau, self_contact, x_cd):
        """Candidate search from ``x`` (kept in ``x_cd``): the self-contact records and every
        vertex's conservative bound. Returns the records' arrays."""
        np.copyto(x_cd, x)
        n = len(x)
        allowance = 0.5 * tau + 1.5 * np.linalg.norm(y - x, axis=1)
        c = self.counters
        c["detections"] += 1
        rec = self._no_rec
        vt = ee = rec[2]
        vt_d = ee_d = np.zeros(0)
        sc = self._self_collision
        if self_contact:
            # each vertex reaches τ/2 and its allowance: a pair not found stays beyond τ
            vt, vt_d, ee, ee_d = sc.candidates(x, 0.5 * tau + allowance)
            rec = self._records(n, vt, ee, sc.edges)
        self._adjacency(sc)
        depth = self._depths(colliders)
        _bounds(n, x, vt, vt_d, ee, ee_d, self._tris, self._edges(), *self._vtri, *self._vedge,
                allowance if self_contact else np.full(n, np.inf), colliders[0], colliders[1],
                colliders[2], colliders[5], depth, tau, GAMMA, self._bound)
        self._bound[~self.free] = np.inf
        c["last_contacts"] = len(vt) + len(ee)
        return rec

    def _records(self, n, vt, ee, edges):
        """Per vertex, its self-contact records (``2·pair`` for a vertex–triangle pair,
        ``2·pair + 1`` for an edge pair), as CSR."""
        tris = self._tris
        owners = [vt[:, 0], tris[vt[:, 1]].ravel(), edges[ee[:, 0]].ravel(), edges[ee[:, 1]].ravel()]
        items = [2 * np.arange(len(vt)), np.repeat(2 * np.arange(len(vt)), 3),
                 np.repeat(2 * np.arange(len(ee)) + 1, 2), np.repeat(2 * np.arange(len(ee)) + 1, 2)]
        owner = np.concatenate(owners).astype(np.int64)
        item = np.concatenate(items).astype(np.int64)
        ptr, rec = _csr(owner, item, n)
        return ptr, rec, np.ascontiguousarray(vt, dtype=np.int64), np.ascontiguousarray(ee, dtype=np.int64)

    def _adjacency(self, sc):
        """Each vertex's triangles and edges (CSR), once."""
        if getattr(self, "_vtri", None) is None:
            n = self.model.n_particles
            tris = self._tris
            self._vtri = _csr(tris.ravel(), np.repeat(np.arange(len(tris)), 3), n)
            edges = self._edges()
            self._vedge = _csr(edges.ravel(), np.repeat(np.arange(len(edges)), 2), n)

    @staticmethod
    def _depths(colliders):
        """Per collider, how far in its far side is (half its thinnest dimension; ``inf`` for a
        plane, a half-space)."""
        from ..colliders import BOX, CAPSULE, SPHERE

        kinds, geo = colliders[0], colliders[5]
        depth = np.full(len(kinds), np.inf)
        for c, kind in enumerate(kinds):
            if kind == SPHERE:
                depth[c] = geo[c, 0]
            elif kind == CAPSULE:
                depth[c] = geo[c, 3]
            elif kind == BOX:
                depth[c] = float(np.min(geo[c, :3]))
        return depth
