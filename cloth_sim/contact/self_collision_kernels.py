"""The self-collision stage's kernels (:mod:`cloth_sim.contact.self_collision`): Bridson,
Fedkiw & Anderson's proximity impulses on the candidate vertex–triangle and edge–edge pairs, each
with its feature rules, and the displacement factors that scale each particle's motion so that no
pair crosses (the stage's last resort). The stage, its thickness rules and its candidate search:
:mod:`cloth_sim.contact.self_collision`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..kernel_cache import keep_true
from .geometry import closest_on_segments, point_triangle_distance


@numba.njit(cache=True)
def proximity(x, x0, v, tris, pairs, held_inv_mass, free_inv_mass, clearance, h):
    """Push pairs closer than ``h`` apart (on the particle's side at the start) and remove their
    approaching normal velocity; returns how many pairs were pushed. ``held_inv_mass`` is 0 where a
    collider supports the particle (:func:`_separate` for the rest)."""
    pushed = 0
    for q in range(pairs.shape[0]):
        p, i = pairs[q, 0], pairs[q, 1]
        a, b, c = tris[i, 0], tris[i, 1], tris[i, 2]
        # the triangle's normal now, oriented to the side the particle started on
        e1x, e1y, e1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        e2x, e2y, e2z = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        nl = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nl == 0.0:
            continue
        nx, ny, nz = nx / nl, ny / nl, nz / nl
        d, wa, wb, wc = point_triangle_distance(x, p, a, b, c)
        if d >= h or wa <= 0.0 or wb <= 0.0 or wc <= 0.0:
            continue  # far, or nearest to an edge or a corner: the face is not in front of it
        d0, wa0, wb0, wc0 = point_triangle_distance(x0, p, a, b, c)
        side = (
            (x0[p, 0] - (wa0 * x0[a, 0] + wb0 * x0[b, 0] + wc0 * x0[c, 0])) * nx
            + (x0[p, 1] - (wa0 * x0[a, 1] + wb0 * x0[b, 1] + wc0 * x0[c, 1])) * ny
            + (x0[p, 2] - (wa0 * x0[a, 2] + wb0 * x0[b, 2] + wc0 * x0[c, 2])) * nz
        )
        if side < 0.0:
            nx, ny, nz = -nx, -ny, -nz
        sd = (
            (x[p, 0] - (wa * x[a, 0] + wb * x[b, 0] + wc * x[c, 0])) * nx
            + (x[p, 1] - (wa * x[a, 1] + wb * x[b, 1] + wc * x[c, 1])) * ny
            + (x[p, 2] - (wa * x[a, 2] + wb * x[b, 2] + wc * x[c, 2])) * nz
        )
        if sd >= h:
            continue
        # the particle takes the share α of the push and the triangle, moved as a whole (its held
        # corners staying), the rest: every particle moves at most the push, however lopsided the
        # weights (barycentric mass weighting would move a lone free corner by push / w)
        if not _separate(
            x,
            v,
            held_inv_mass,
            free_inv_mass,
            clearance,
            (p, p, p),
            (1.0, 0.0, 0.0),
            (a, b, c),
            (wa, wb, wc),
            (nx, ny, nz),
            min(h - sd, 2.0 * h),
        ):
            continue
        pushed += 1
    return pushed


@numba.njit(cache=True)
def displacement_factors(disp, tris, pairs, start_distance, factor):
    """The no-crossing factors of particle–triangle pairs (module docstring, step 3), from each
    particle's displacement over the step (:func:`displacements`), written into ``factor``
    (1 = unchanged); :func:`scale_displacements` applies them."""
    factor[:] = 1.0
    for q in range(pairs.shape[0]):
        p, i = pairs[q, 0], pairs[q, 1]
        a, b, c = tris[i, 0], tris[i, 1], tris[i, 2]
        need = disp[p] + max(disp[a], disp[b], disp[c])
        if need == 0.0:
            continue
        d0 = start_distance[q]
        if d0 > need:
            continue
        r = 0.9 * d0 / need
        for vert in (p, a, b, c):
            if r < factor[vert]:
                factor[vert] = r


@numba.njit(cache=True, inline="always")
def _separate(x, v, held_inv_mass, free_inv_mass, clearance, s1, w1, s2, w2, n, push):
    """Push side 1 (the points ``Σ w1·x[s1]``) along ``+n`` (three numbers) and side 2 along ``−n``
    by ``push`` in all, shared by their inverse masses (each side moved as a whole, held particles
    staying), and remove an approaching velocity along ``n`` alike. ``s1, s2``: 3 particle
    indices each, ``w1, w2`` their weights (0 for an unused slot). A side held by a collider
    (``held_inv_mass`` 0) stays; when both are, the side farther above the colliders
    (``clearance``) moves alone, by its own masses. Returns whether anything could move."""
    nx, ny, nz = n
    inv_mass = held_inv_mass
    i1 = w1[0] * inv_mass[s1[0]] + w1[1] * inv_mass[s1[1]] + w1[2] * inv_mass[s1[2]]
    i2 = w2[0] * inv_mass[s2[0]] + w2[1] * inv_mass[s2[1]] + w2[2] * inv_mass[s2[2]]
    if i1 + i2 != 0.0:
        alpha = i1 / (i1 + i2)
    else:
        inv_mass = free_inv_mass
        c1, c2 = np.inf, np.inf
        for k in range(3):
            if w1[k] > 0.0:
                c1 = min(c1, clearance[s1[k]])
            if w2[k] > 0.0:
                c2 = min(c2, clearance[s2[k]])
        alpha = 1.0 if c1 >= c2 else 0.0
        moving = (
            w1[0] * inv_mass[s1[0]] + w1[1] * inv_mass[s1[1]] + w1[2] * inv_mass[s1[2]]
            if alpha == 1.0
            else w2[0] * inv_mass[s2[0]] + w2[1] * inv_mass[s2[1]] + w2[2] * inv_mass[s2[2]]
        )
        if moving == 0.0:
            return False
    vn = 0.0
    for k in range(3):
        vn += (w1[k] * v[s1[k], 0] - w2[k] * v[s2[k], 0]) * nx
        vn += (w1[k] * v[s1[k], 1] - w2[k] * v[s2[k], 1]) * ny
        vn += (w1[k] * v[s1[k], 2] - w2[k] * v[s2[k], 2]) * nz
    vn = min(vn, 0.0)  # only an approaching velocity goes
    for k in range(3):
        p = s1[k]
        if w1[k] > 0.0 and inv_mass[p] > 0.0 and alpha > 0.0:
            x[p, 0] += alpha * push * nx
            x[p, 1] += alpha * push * ny
            x[p, 2] += alpha * push * nz
            v[p, 0] -= alpha * vn * nx
            v[p, 1] -= alpha * vn * ny
            v[p, 2] -= alpha * vn * nz
        q = s2[k]
        if w2[k] > 0.0 and inv_mass[q] > 0.0 and alpha < 1.0:
            x[q, 0] -= (1.0 - alpha) * push * nx
            x[q, 1] -= (1.0 - alpha) * push * ny
            x[q, 2] -= (1.0 - alpha) * push * nz
            v[q, 0] += (1.0 - alpha) * vn * nx
            v[q, 1] += (1.0 - alpha) * vn * ny
            v[q, 2] += (1.0 - alpha) * vn * nz
    return True


@numba.njit(cache=True, inline="always")
def _direction(x, x0, p, s2, w2):
    """Unit vector from the point ``Σ w2·x[s2]`` to particle ``p`` now, turned to the side it had
    at the start (from the start positions when they coincide now); and the distance now."""
    nx = x[p, 0] - (w2[0] * x[s2[0], 0] + w2[1] * x[s2[1], 0] + w2[2] * x[s2[2], 0])
    ny = x[p, 1] - (w2[0] * x[s2[0], 1] + w2[1] * x[s2[1], 1] + w2[2] * x[s2[2], 1])
    nz = x[p, 2] - (w2[0] * x[s2[0], 2] + w2[1] * x[s2[1], 2] + w2[2] * x[s2[2], 2])
    ox = x0[p, 0] - (w2[0] * x0[s2[0], 0] + w2[1] * x0[s2[1], 0] + w2[2] * x0[s2[2], 0])
    oy = x0[p, 1] - (w2[0] * x0[s2[0], 1] + w2[1] * x0[s2[1], 1] + w2[2] * x0[s2[2], 1])
    oz = x0[p, 2] - (w2[0] * x0[s2[0], 2] + w2[1] * x0[s2[1], 2] + w2[2] * x0[s2[2], 2])
    d = math.sqrt(nx * nx + ny * ny + nz * nz)
    if d == 0.0:
        nx, ny, nz = ox, oy, oz
    elif nx * ox + ny * oy + nz * oz < 0.0:
        nx, ny, nz = -nx, -ny, -nz
    nl = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nl == 0.0:
        return 0.0, 0.0, 0.0, d
    return nx / nl, ny / nl, nz / nl, d


@numba.njit(cache=True, inline="always")
def _adjacent(p, q, adj_ptr, adj):
    for k in range(adj_ptr[q], adj_ptr[q + 1]):
        if adj[k] == p:
            return True
    return False


@numba.njit(cache=True)
def proximity_features(
    x, x0, v, tris, pairs, held_inv_mass, free_inv_mass, clearance, h, features
):
    """The point–edge and point–point cases of the proximity pass (module docstring): candidate
    pairs whose nearest point on the triangle is on an edge or a corner; returns how many were
    pushed. ``features``: the cloth's topology (:attr:`SelfCollision.features`)."""
    _, tri_edge, edge_owner, edge_tris, vertex_owner, adj_ptr, adj = features
    pushed = 0
    for q in range(pairs.shape[0]):
        p, i = pairs[q, 0], pairs[q, 1]
        a, b, c = tris[i, 0], tris[i, 1], tris[i, 2]
        d, wa, wb, wc = point_triangle_distance(x, p, a, b, c)
        if d >= h or (wa > 0.0 and wb > 0.0 and wc > 0.0):
            continue  # far, or in front of the face (the face case)
        if wa > 0.0 and wb > 0.0 or wb > 0.0 and wc > 0.0 or wc > 0.0 and wa > 0.0:
            # on an edge: slot 0 = a–b (wc = 0), 1 = b–c (wa = 0), 2 = c–a (wb = 0)
            slot = 0 if wc <= 0.0 else (1 if wa <= 0.0 else 2)
            e = tri_edge[i, slot]
            if edge_owner[e] != i:
                continue
            other = edge_tris[e, 1] if edge_tris[e, 0] == i else edge_tris[e, 0]
            if other >= 0 and (tris[other, 0] == p or tris[other, 1] == p or tris[other, 2] == p):
                continue  # the particle is a corner of the edge's other triangle
            s2 = (a, b, c)
            w2 = (wa, wb, wc)
        else:
            vert = a if wa > 0.0 else (b if wb > 0.0 else c)
            if vertex_owner[vert] != i or _adjacent(p, vert, adj_ptr, adj):
                continue
            s2 = (vert, vert, vert)
            w2 = (1.0, 0.0, 0.0)
        nx, ny, nz, d = _direction(x, x0, p, s2, w2)
        if nx == 0.0 and ny == 0.0 and nz == 0.0:
            continue
        if _separate(
            x,
            v,
            held_inv_mass,
            free_inv_mass,
            clearance,
            (p, p, p),
            (1.0, 0.0, 0.0),
            s2,
            w2,
            (nx, ny, nz),
            min(h - d, 2.0 * h),
        ):
            pushed += 1
    return pushed


@numba.njit(cache=True)
def proximity_edges(x, x0, v, edges, pairs, held_inv_mass, free_inv_mass, clearance, h):
    """The edge–edge case of the proximity pass: pairs whose nearest points both lie inside their
    edges, closer than ``h``, pushed apart; returns how many."""
    pushed = 0
    for q in range(pairs.shape[0]):
        e, f = pairs[q, 0], pairs[q, 1]
        a, b, c, d = edges[e, 0], edges[e, 1], edges[f, 0], edges[f, 1]
        sv, tv, dist = closest_on_segments(x, a, b, c, d)
        if dist >= h or not (0.0 < sv < 1.0 and 0.0 < tv < 1.0):
            continue
        nx = (1 - sv) * x[a, 0] + sv * x[b, 0] - (1 - tv) * x[c, 0] - tv * x[d, 0]
        ny = (1 - sv) * x[a, 1] + sv * x[b, 1] - (1 - tv) * x[c, 1] - tv * x[d, 1]
        nz = (1 - sv) * x[a, 2] + sv * x[b, 2] - (1 - tv) * x[c, 2] - tv * x[d, 2]
        ox = (1 - sv) * x0[a, 0] + sv * x0[b, 0] - (1 - tv) * x0[c, 0] - tv * x0[d, 0]
        oy = (1 - sv) * x0[a, 1] + sv * x0[b, 1] - (1 - tv) * x0[c, 1] - tv * x0[d, 1]
        oz = (1 - sv) * x0[a, 2] + sv * x0[b, 2] - (1 - tv) * x0[c, 2] - tv * x0[d, 2]
        if dist == 0.0:
            nx, ny, nz = ox, oy, oz
        elif nx * ox + ny * oy + nz * oz < 0.0:
            nx, ny, nz = -nx, -ny, -nz
        nl = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nl == 0.0:
            continue
        if _separate(
            x,
            v,
            held_inv_mass,
            free_inv_mass,
            clearance,
            (a, b, b),
            (1.0 - sv, sv, 0.0),
            (c, d, d),
            (1.0 - tv, tv, 0.0),
            (nx / nl, ny / nl, nz / nl),
            min(h - dist, 2.0 * h),
        ):
            pushed += 1
    return pushed


@numba.njit(cache=True)
def edge_displacement_factors(disp, edges, pairs, start_distance, factor):
    """Step 3's factors for edge pairs, lowering those :func:`displacement_factors` wrote (it runs
    first and resets them); the positions are scaled by the caller."""
    for q in range(pairs.shape[0]):
        e, f = pairs[q, 0], pairs[q, 1]
        a, b, c, d = edges[e, 0], edges[e, 1], edges[f, 0], edges[f, 1]
        da = max(disp[a], disp[b])
        dc = max(disp[c], disp[d])
        need = da + dc
        if need == 0.0 or start_distance[q] > need:
            continue
        r = 0.9 * start_distance[q] / need
        for vert in (a, b, c, d):
            if r < factor[vert]:
                factor[vert] = r


@numba.njit(cache=True)
def scale_displacements(x, x0, factor):
    """Positions moved back towards the start by each particle's factor; returns how many moved."""
    slowed = 0
    for p in range(x.shape[0]):
        f = factor[p]
        if f < 1.0:
            for k in range(3):
                x[p, k] = x0[p, k] + f * (x[p, k] - x0[p, k])
            slowed += 1
    return slowed


@numba.njit(cache=True)
def displacements(x, x0, out):
    """Each particle's displacement over the step, ``|x − x0|``, written into ``out``."""
    for p in range(x.shape[0]):
        out[p] = math.sqrt(
            (x[p, 0] - x0[p, 0]) ** 2 + (x[p, 1] - x0[p, 1]) ** 2 + (x[p, 2] - x0[p, 2]) ** 2
        )
    return out


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
