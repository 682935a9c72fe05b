"""Self-collision: the cloth keeps ``thickness`` from its own non-adjacent triangles and never passes
through one.

A post-step stage (see :mod:`cloth_sim.constraints`) over particle–triangle pairs, the triangle not
containing the particle. Each step:

1. **Candidates**, from a spatial hash of the particles at the step's start (Teschner et al. 2003:
   one counting sort per step, cells as wide as the longest triangle side or the search radius if
   larger), which each triangle queries over its box grown by the radius. The radius
   ``thickness + 2·max|Δx|`` holds every pair that can come within ``thickness`` or cross over the
   step. Measured in one run on the hanging cloth: hashing the triangles into every cell their
   grown box overlaps and querying per particle took 2.9 ms at 64×64 (75,000 entries) and 87 ms at
   128×128 (400,000 pairs within the radius there: a 5 mm thickness is most of that cloth's 7.9 mm
   spacing); hashing the particles and querying per triangle, 3.4 ms and 53 ms. A bounding-volume
   hierarchy would be refitted and traversed every step for the same answer; for cloth of
   near-uniform triangles the hash is the usual choice.
   A particle is paired with every triangle it is not a corner of (Bridson et al.): excluding the
   triangles of its neighbours too was tried and lets the ``fold`` scene cross itself where a crease
   is one triangle wide. Neighbours in a flat or compressed cloth are never pushed out of its plane
   (step 2), and the no-crossing bound (step 3) slows them only when they move by most of an edge.
2. **Proximity** (Bridson, Fedkiw & Anderson 2002): a pair closer than ``thickness`` at the end of
   the step is pushed apart, shared by inverse mass between its two sides (each moved as a whole,
   held particles staying), and an approaching normal velocity between them is removed alike (an
   inelastic impulse). By where the particle's nearest point on the triangle lies:

   * inside the face: along the triangle's normal, on the side the particle was at the start (so
     neighbours in a flat or compressed cloth are never pushed out of its plane);
   * on an edge (**point–edge**) or at a corner (**point–point**): along the line from that point to
     the particle, each edge and corner handled once (from the first triangle that has it), and only
     when the particle shares no triangle with it. Without these, the hems and openings of a garment
     — where the nearest point is an edge — kept no distance: the edge particles of a U-folded cloth
     came within 1.5–1.9 mm of the other layer at a thickness of 5 mm;
   * and **edge–edge**: two edges sharing no particle whose nearest points both lie inside them (two
     hems crossing), from their own search (edge midpoints hashed as the particles are), pushed
     apart along the line between those points. In a flat cloth two edges are nearest at an end of
     one of them, so this never acts between neighbours lying flat.
3. **No crossing**, guaranteed: the distance from a moving point to a moving triangle, with every
   vertex on a straight path over the step, changes at most by ``|Δp| + max|Δv_i|`` (the triangle's
   points are convex combinations of its corners). A pair whose distance at the start ``d₀`` is
   below that has the displacements of its four particles scaled by ``0.9·d₀ / (|Δp| + max|Δv_i|)``
   (the smallest factor over the pairs a particle is in; velocities scaled alike), so the distance
   stays above 10 % of ``d₀`` over the whole step: no particle passes through a triangle between
   two steps, whatever the speed. The same bound holds for two moving edges (``max`` of each edge's
   two ends' displacements, summed), so edge pairs get factors alike and no edge passes through
   another. One pass suffices, because every factor only shrinks motion.
   A particle that starts touching a triangle (``d₀ = 0``) does not move that step.

The cost is one hash build and one distance test per candidate pair; ``self_collision=False`` (the
default) runs none of it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .colliders import SUPPORT


@numba.njit(cache=True, inline="always")
def closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Barycentric weights ``(wa, wb, wc)`` of the point of triangle ``abc`` closest to ``p``
    (Ericson, Real-Time Collision Detection, 5.1.5)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3) if d1 != d3 else 0.0
        return 1.0 - v, v, 0.0
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6) if d2 != d6 else 0.0
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        den = (d4 - d3) + (d5 - d6)
        w = (d4 - d3) / den if den != 0.0 else 0.0
        return 0.0, 1.0 - w, w
    den = va + vb + vc
    if den == 0.0:  # degenerate triangle
        return 1.0, 0.0, 0.0
    v = vb / den
    w = vc / den
    return 1.0 - v - w, v, w


@numba.njit(cache=True, inline="always")
def _distance(x, p, a, b, c):
    wa, wb, wc = closest_on_triangle(x[p, 0], x[p, 1], x[p, 2], x[a, 0], x[a, 1], x[a, 2],
                                     x[b, 0], x[b, 1], x[b, 2], x[c, 0], x[c, 1], x[c, 2])
    dx = x[p, 0] - (wa * x[a, 0] + wb * x[b, 0] + wc * x[c, 0])
    dy = x[p, 1] - (wa * x[a, 1] + wb * x[b, 1] + wc * x[c, 1])
    dz = x[p, 2] - (wa * x[a, 2] + wb * x[b, 2] + wc * x[c, 2])
    return math.sqrt(dx * dx + dy * dy + dz * dz), wa, wb, wc


@numba.njit(cache=True, inline="always")
def _cell(v, inv):
    return np.int64(math.floor(v * inv))


@numba.njit(cache=True, inline="always")
def _hash(i, j, k, size):
    h = (i * 73856093) ^ (j * 19349663) ^ (k * 83492791)
    return h % size if h >= 0 else (-h) % size


#: hash cell size as a fraction of the longest triangle side, unless the search radius is larger
#: (measured at 64×64: 3.4 ms at 1.0, 7.5 ms at 0.5, 2.8 ms at 2.0 but 4× the pairs to visit in a
#: crumpled cloth)
CELL = 1.0


#: the searches split their triangles (edges) into this many fixed, contiguous chunks, run on every
#: core; each chunk's pairs are kept in order and the chunks joined in order, so the result does not
#: depend on the thread count
CHUNKS = 64


@numba.njit(cache=True)
def _particle_hash(x0, tris, radius):
    """The particles in a spatial hash (one cell each, a counting sort): ``(inv, size, start,
    members, cell)``, ``inv`` the inverse cell size and ``cell[p]`` particle ``p``'s cell."""
    n, t = x0.shape[0], tris.shape[0]
    longest = 0.0
    for i in range(t):
        for e in range(3):
            a, b = tris[i, e], tris[i, (e + 1) % 3]
            d = ((x0[a, 0] - x0[b, 0]) ** 2 + (x0[a, 1] - x0[b, 1]) ** 2
                 + (x0[a, 2] - x0[b, 2]) ** 2)
            longest = max(longest, d)
    size_cell = max(radius, CELL * math.sqrt(longest))
    inv = 1.0 / size_cell
    size = 2 * n + 1
    start = np.zeros(size + 1, np.int64)
    cell = np.empty((n, 3), np.int64)
    bucket_of = np.empty(n, np.int64)
    for p in range(n):
        for k in range(3):
            cell[p, k] = _cell(x0[p, k], inv)
        b = _hash(cell[p, 0], cell[p, 1], cell[p, 2], size)
        bucket_of[p] = b
        start[b + 1] += 1
    for b in range(size):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    members = np.empty(n, np.int64)
    for p in range(n):
        members[fill[bucket_of[p]]] = p
        fill[bucket_of[p]] += 1
    return inv, size, start, members, cell


@numba.njit(cache=True, inline="always")
def _put(pairs, dist, row, m, cap, i, j, d):
    """Pair ``(i, j)`` at distance ``d`` as its chunk's ``m``-th (at ``row + m``) if the chunk has
    room (``m < cap``); returns the chunk's count, ``m + 1``, either way (a count above ``cap`` makes
    :func:`_join_chunks` search again with more rows)."""
    if m < cap:
        pairs[row + m, 0] = i
        pairs[row + m, 1] = j
        dist[row + m] = d
    return m + 1


@numba.njit(cache=True, parallel=True)
def _triangle_queries(x0, tris, radius, inv, size, start, members, cell, cap, pairs, dist, counts):
    """Each chunk of triangles (:data:`CHUNKS`) visits the cells its triangles' boxes, grown by
    ``radius``, overlap, and writes its pairs from row ``chunk·cap`` on (``counts[chunk]``: how many
    it found, which may exceed ``cap``: then only the first ``cap`` were written). A particle is
    taken only from the bucket of its own cell (another cell hashed to the same bucket does not
    count), so each is looked at once per triangle without a shared "seen" array."""
    t = tris.shape[0]
    per = (t + CHUNKS - 1) // CHUNKS
    for chunk in numba.prange(CHUNKS):
        m = 0
        row = chunk * cap
        for i in range(chunk * per, min(t, (chunk + 1) * per)):
            a, b, c = tris[i, 0], tris[i, 1], tris[i, 2]
            lo0 = min(x0[a, 0], x0[b, 0], x0[c, 0]) - radius
            lo1 = min(x0[a, 1], x0[b, 1], x0[c, 1]) - radius
            lo2 = min(x0[a, 2], x0[b, 2], x0[c, 2]) - radius
            hi0 = max(x0[a, 0], x0[b, 0], x0[c, 0]) + radius
            hi1 = max(x0[a, 1], x0[b, 1], x0[c, 1]) + radius
            hi2 = max(x0[a, 2], x0[b, 2], x0[c, 2]) + radius
            for ci in range(_cell(lo0, inv), _cell(hi0, inv) + 1):
                for cj in range(_cell(lo1, inv), _cell(hi1, inv) + 1):
                    for ck in range(_cell(lo2, inv), _cell(hi2, inv) + 1):
                        bucket = _hash(ci, cj, ck, size)
                        for e in range(start[bucket], start[bucket + 1]):
                            p = members[e]
                            if cell[p, 0] != ci or cell[p, 1] != cj or cell[p, 2] != ck:
                                continue  # another cell's particle in this bucket
                            if p == a or p == b or p == c:
                                continue  # its corners are not paired with it
                            if not (lo0 <= x0[p, 0] <= hi0 and lo1 <= x0[p, 1] <= hi1
                                    and lo2 <= x0[p, 2] <= hi2):
                                continue
                            d0 = _distance(x0, p, a, b, c)[0]
                            if d0 >= radius:
                                continue
                            m = _put(pairs, dist, row, m, cap, p, i, d0)
        counts[chunk] = m


def _join_chunks(run, rows: int, cap=None):
    """Run a chunked search (``run(rows, pairs, dist, counts)``) with ``rows`` per chunk, again with
    enough rows if a chunk found more, and join the chunks' pairs in chunk order. ``cap``: an
    optional one-element integer array remembering the rows the last search needed (a stage passes
    its own, so a step whose cloth has as many pairs as the last searches once)."""
    if cap is not None:
        rows = max(rows, int(cap[0]))
    cap_rows = rows
    while True:
        pairs = np.empty((CHUNKS * cap_rows, 2), np.int64)
        dist = np.empty(CHUNKS * cap_rows)
        counts = np.zeros(CHUNKS, np.int64)
        run(cap_rows, pairs, dist, counts)
        most = int(counts.max())
        if most <= cap_rows:
            break
        cap_rows = most + most // 4
    if cap is not None:
        cap[0] = most + most // 4
    keep = (np.arange(cap_rows)[None, :] < counts[:, None]).ravel()
    return pairs[keep], dist[keep]


def candidate_pairs(x0, tris, radius, cap=None):
    """``(pairs, distances)``: every (particle, triangle) pair whose start positions lie within
    ``radius``, and that distance; the particle not a corner of the triangle; in a fixed order (by
    triangle, then by the cells visited), the same at any thread count.

    The particles go into a spatial hash (one cell each, a counting sort); each triangle visits the
    cells its box, grown by ``radius``, overlaps; the triangles are searched in :data:`CHUNKS`
    chunks on every core."""
    tris = np.ascontiguousarray(tris, dtype=np.int64)
    if len(tris) == 0 or len(x0) == 0:
        return np.empty((0, 2), np.int64), np.empty(0)
    hashed = _particle_hash(x0, tris, float(radius))

    def run(rows, pairs, dist, counts):
        _triangle_queries(x0, tris, float(radius), *hashed, rows, pairs, dist, counts)

    return _join_chunks(run, 4 * len(x0) // CHUNKS + 16, cap)


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
        d, wa, wb, wc = _distance(x, p, a, b, c)
        if d >= h or wa <= 0.0 or wb <= 0.0 or wc <= 0.0:
            continue  # far, or nearest to an edge or a corner: the face is not in front of it
        d0, wa0, wb0, wc0 = _distance(x0, p, a, b, c)
        side = ((x0[p, 0] - (wa0 * x0[a, 0] + wb0 * x0[b, 0] + wc0 * x0[c, 0])) * nx
                + (x0[p, 1] - (wa0 * x0[a, 1] + wb0 * x0[b, 1] + wc0 * x0[c, 1])) * ny
                + (x0[p, 2] - (wa0 * x0[a, 2] + wb0 * x0[b, 2] + wc0 * x0[c, 2])) * nz)
        if side < 0.0:
            nx, ny, nz = -nx, -ny, -nz
        sd = ((x[p, 0] - (wa * x[a, 0] + wb * x[b, 0] + wc * x[c, 0])) * nx
              + (x[p, 1] - (wa * x[a, 1] + wb * x[b, 1] + wc * x[c, 1])) * ny
              + (x[p, 2] - (wa * x[a, 2] + wb * x[b, 2] + wc * x[c, 2])) * nz)
        if sd >= h:
            continue
        # the particle takes the share α of the push and the triangle, moved as a whole (its held
        # corners staying), the rest: every particle moves at most the push, however lopsided the
        # weights (barycentric mass weighting would move a lone free corner by push / w)
        if not _separate(x, v, held_inv_mass, free_inv_mass, clearance, (p, p, p), (1.0, 0.0, 0.0),
                         (a, b, c), (wa, wb, wc), nx, ny, nz, min(h - sd, 2.0 * h)):
            continue
        pushed += 1
    return pushed


@numba.njit(cache=True)
def displacement_factors(x, x0, tris, pairs, start_distance, factor):
    """The no-crossing factors of particle–triangle pairs (module docstring, step 3), written into
    ``factor`` (1 = unchanged); :func:`scale_displacements` applies them."""
    n = x.shape[0]
    disp = np.empty(n)
    for p in range(n):
        disp[p] = math.sqrt((x[p, 0] - x0[p, 0]) ** 2 + (x[p, 1] - x0[p, 1]) ** 2
                            + (x[p, 2] - x0[p, 2]) ** 2)
        factor[p] = 1.0
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
def closest_on_segments(x, a, b, c, d):
    """``(s, t, distance)``: the nearest points ``a + s(b − a)`` and ``c + t(d − c)`` of two segments
    (Ericson, Real-Time Collision Detection, 5.1.9; a parallel pair takes ``s = 0``)."""
    d1x, d1y, d1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
    d2x, d2y, d2z = x[d, 0] - x[c, 0], x[d, 1] - x[c, 1], x[d, 2] - x[c, 2]
    rx, ry, rz = x[a, 0] - x[c, 0], x[a, 1] - x[c, 1], x[a, 2] - x[c, 2]
    aa = d1x * d1x + d1y * d1y + d1z * d1z
    ee = d2x * d2x + d2y * d2y + d2z * d2z
    ff = d2x * rx + d2y * ry + d2z * rz
    cc = d1x * rx + d1y * ry + d1z * rz
    bb = d1x * d2x + d1y * d2y + d1z * d2z
    den = aa * ee - bb * bb
    sv = min(max((bb * ff - cc * ee) / den, 0.0), 1.0) if den > 1e-30 * aa * ee else 0.0
    tv = (bb * sv + ff) / ee if ee > 0.0 else 0.0
    if tv < 0.0:
        tv = 0.0
        sv = min(max(-cc / aa, 0.0), 1.0) if aa > 0.0 else 0.0
    elif tv > 1.0:
        tv = 1.0
        sv = min(max((bb - cc) / aa, 0.0), 1.0) if aa > 0.0 else 0.0
    px, py, pz = rx + sv * d1x - tv * d2x, ry + sv * d1y - tv * d2y, rz + sv * d1z - tv * d2z
    return sv, tv, math.sqrt(px * px + py * py + pz * pz)


@numba.njit(cache=True)
def _edge_hash(x0, edges, radius):
    """The edges' boxes in a spatial hash, each in every cell it overlaps (cells as wide as the
    longest edge or ``radius`` if larger: one to eight cells an edge): ``(inv, size, start, members,
    lo, hi, first, entry_cell)``, ``lo``/``hi`` the boxes, ``first`` the lowest cell of each and
    ``entry_cell`` the cell each entry of ``members`` was put there for."""
    m = edges.shape[0]
    longest = 0.0
    for e in range(m):
        a, b = edges[e, 0], edges[e, 1]
        longest = max(longest, (x0[a, 0] - x0[b, 0]) ** 2 + (x0[a, 1] - x0[b, 1]) ** 2
                      + (x0[a, 2] - x0[b, 2]) ** 2)
    inv = 1.0 / max(radius, math.sqrt(longest), 1e-300)  # (half that: 1.7× slower at 64×64)
    lo = np.empty((m, 3))
    hi = np.empty((m, 3))
    first = np.empty((m, 3), np.int64)
    for e in range(m):
        a, b = edges[e, 0], edges[e, 1]
        for k in range(3):
            lo[e, k] = min(x0[a, k], x0[b, k])
            hi[e, k] = max(x0[a, k], x0[b, k])
            first[e, k] = _cell(lo[e, k], inv)
    size = 4 * m + 1
    start = np.zeros(size + 1, np.int64)
    for e in range(m):  # count the entries per bucket
        for ci in range(first[e, 0], _cell(hi[e, 0], inv) + 1):
            for cj in range(first[e, 1], _cell(hi[e, 1], inv) + 1):
                for ck in range(first[e, 2], _cell(hi[e, 2], inv) + 1):
                    start[_hash(ci, cj, ck, size) + 1] += 1
    for q in range(size):
        start[q + 1] += start[q]
    fill = start[:-1].copy()
    members = np.empty(start[size], np.int64)
    entry_cell = np.empty((start[size], 3), np.int64)
    for e in range(m):
        for ci in range(first[e, 0], _cell(hi[e, 0], inv) + 1):
            for cj in range(first[e, 1], _cell(hi[e, 1], inv) + 1):
                for ck in range(first[e, 2], _cell(hi[e, 2], inv) + 1):
                    bucket = _hash(ci, cj, ck, size)
                    q = fill[bucket]
                    members[q] = e
                    entry_cell[q, 0], entry_cell[q, 1], entry_cell[q, 2] = ci, cj, ck
                    fill[bucket] += 1
    return inv, size, start, members, lo, hi, first, entry_cell


@numba.njit(cache=True, parallel=True)
def _edge_queries(x0, edges, radius, inv, size, start, members, lo, hi, first, entry_cell, cap,
                  pairs, dist, counts):
    """Each chunk of edges (:data:`CHUNKS`) visits the cells its edges' boxes, grown by ``radius``,
    overlap, and writes its pairs from row ``chunk·cap`` on (as :func:`_triangle_queries`). An edge
    ``f`` sits in several cells; the pair ``(e, f)`` is taken only from ``f``'s entry for the first
    cell (lowest on each axis) that both ``e``'s grown box and ``f``'s box overlap, so once, without
    a "seen" array (entries of other cells hashed to the same bucket, ``f``'s own included, are
    passed over)."""
    m_edges = edges.shape[0]
    per = (m_edges + CHUNKS - 1) // CHUNKS
    for chunk in numba.prange(CHUNKS):
        n_pairs = 0
        row = chunk * cap
        for e in range(chunk * per, min(m_edges, (chunk + 1) * per)):
            a, b = edges[e, 0], edges[e, 1]
            q0 = _cell(lo[e, 0] - radius, inv)
            q1 = _cell(lo[e, 1] - radius, inv)
            q2 = _cell(lo[e, 2] - radius, inv)
            for ci in range(q0, _cell(hi[e, 0] + radius, inv) + 1):
                for cj in range(q1, _cell(hi[e, 1] + radius, inv) + 1):
                    for ck in range(q2, _cell(hi[e, 2] + radius, inv) + 1):
                        bucket = _hash(ci, cj, ck, size)
                        for q in range(start[bucket], start[bucket + 1]):
                            f = members[q]
                            if f <= e:
                                continue
                            if (entry_cell[q, 0] != ci or entry_cell[q, 1] != cj
                                    or entry_cell[q, 2] != ck):
                                continue  # another cell's entry in this bucket
                            if (ci != max(q0, first[f, 0]) or cj != max(q1, first[f, 1])
                                    or ck != max(q2, first[f, 2])):
                                continue  # not the first cell the two share
                            c, d = edges[f, 0], edges[f, 1]
                            if c == a or c == b or d == a or d == b:
                                continue
                            if (lo[f, 0] > hi[e, 0] + radius or lo[e, 0] > hi[f, 0] + radius
                                    or lo[f, 1] > hi[e, 1] + radius or lo[e, 1] > hi[f, 1] + radius
                                    or lo[f, 2] > hi[e, 2] + radius or lo[e, 2] > hi[f, 2] + radius):
                                continue  # boxes farther apart than radius: no distance needed
                            dd = closest_on_segments(x0, a, b, c, d)[2]
                            if dd >= radius:
                                continue
                            n_pairs = _put(pairs, dist, row, n_pairs, cap, e, f, dd)
        counts[chunk] = n_pairs


def edge_pairs(x0, edges, radius, cap=None):
    """``(pairs, distances)``: every pair of edges ``(e, f)``, ``e < f``, sharing no particle, whose
    segments at the start lie within ``radius``, and that distance; in a fixed order (by ``e``, then
    by the cells visited), the same at any thread count. Each edge's box goes into every cell of a
    spatial hash it overlaps; each edge visits the cells its box grown by ``radius`` overlaps, in
    :data:`CHUNKS` chunks on every core. (Hashing midpoints and visiting the 27 cells around them,
    cells of the longest edge plus the radius, took 19 ms on the T-shirt lying flat, 6,814 edges and
    35,000 pairs between its layers; this takes a fraction.)"""
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    if len(edges) == 0:
        return np.empty((0, 2), np.int64), np.empty(0)
    hashed = _edge_hash(x0, edges, float(radius))

    def run(rows, pairs, dist, counts):
        _edge_queries(x0, edges, float(radius), *hashed, rows, pairs, dist, counts)

    return _join_chunks(run, 2 * len(edges) // CHUNKS + 16, cap)


@numba.njit(cache=True, inline="always")
def _separate(x, v, held_inv_mass, free_inv_mass, clearance, s1, w1, s2, w2, nx, ny, nz, push):
    """Push side 1 (the points ``Σ w1·x[s1]``) along ``+n`` and side 2 along ``−n`` by ``push`` in
    all, shared by their inverse masses (each side moved as a whole, held particles staying), and
    remove an approaching velocity along ``n`` alike. ``s1, s2``: 3 particle indices each, ``w1, w2``
    their weights (0 for an unused slot). A side held by a collider (``held_inv_mass`` 0) stays; when
    both are, the side farther above the colliders (``clearance``) moves alone, by its own masses.
    Returns whether anything could move."""
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
        moving = (w1[0] * inv_mass[s1[0]] + w1[1] * inv_mass[s1[1]] + w1[2] * inv_mass[s1[2]]
                  if alpha == 1.0 else
                  w2[0] * inv_mass[s2[0]] + w2[1] * inv_mass[s2[1]] + w2[2] * inv_mass[s2[2]])
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
    """Unit vector from the point ``Σ w2·x[s2]`` to particle ``p`` now, turned to the side it had at
    the start (from the start positions when they coincide now); and the distance now."""
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
def proximity_features(x, x0, v, tris, pairs, held_inv_mass, free_inv_mass, clearance, h, tri_edge,
                       edge_owner, edge_tris, vertex_owner, adj_ptr, adj):
    """The point–edge and point–point cases of the proximity pass (module docstring): candidate
    pairs whose nearest point on the triangle is on an edge or a corner; returns how many were
    pushed."""
    pushed = 0
    for q in range(pairs.shape[0]):
        p, i = pairs[q, 0], pairs[q, 1]
        a, b, c = tris[i, 0], tris[i, 1], tris[i, 2]
        d, wa, wb, wc = _distance(x, p, a, b, c)
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
        if _separate(x, v, held_inv_mass, free_inv_mass, clearance, (p, p, p), (1.0, 0.0, 0.0), s2, w2,
                     nx, ny, nz,
                     min(h - d, 2.0 * h)):
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
        if _separate(x, v, held_inv_mass, free_inv_mass, clearance, (a, b, b), (1.0 - sv, sv, 0.0),
                     (c, d, d),
                     (1.0 - tv, tv, 0.0),
                     nx / nl, ny / nl, nz / nl, min(h - dist, 2.0 * h)):
            pushed += 1
    return pushed


@numba.njit(cache=True)
def edge_displacement_factors(x, x0, edges, pairs, start_distance, factor):
    """Step 3's factors for edge pairs, lowering those :func:`displacement_factors` wrote (it runs
    first and resets them); the positions are scaled by the caller."""
    for q in range(pairs.shape[0]):
        e, f = pairs[q, 0], pairs[q, 1]
        a, b, c, d = edges[e, 0], edges[e, 1], edges[f, 0], edges[f, 1]
        da = max(_disp(x, x0, a), _disp(x, x0, b))
        dc = max(_disp(x, x0, c), _disp(x, x0, d))
        need = da + dc
        if need == 0.0 or start_distance[q] > need:
            continue
        r = 0.9 * start_distance[q] / need
        for vert in (a, b, c, d):
            if r < factor[vert]:
                factor[vert] = r


@numba.njit(cache=True, inline="always")
def _disp(x, x0, p):
    return math.sqrt((x[p, 0] - x0[p, 0]) ** 2 + (x[p, 1] - x0[p, 1]) ** 2 + (x[p, 2] - x0[p, 2]) ** 2)


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
def max_displacement(x, x0):
    m = 0.0
    for p in range(x.shape[0]):
        m = max(m, (x[p, 0] - x0[p, 0]) ** 2 + (x[p, 1] - x0[p, 1]) ** 2 + (x[p, 2] - x0[p, 2]) ** 2)
    return math.sqrt(m)


#: self-collision's thickness may be at most this fraction of the shortest triangle edge at rest
MAX_THICKNESS_FRACTION = 0.5


def thickness_limit(model) -> float:
    """The largest thickness self-collision accepts on ``model``: half its shortest triangle edge
    at rest. A thicker skin reaches past the triangles next to a particle in a flat cloth (they
    are about one edge away), so the search finds every neighbour of every particle (at 128×128
    with 5 mm, 400,000 pairs a step) and a crumpled cloth is pushed apart from itself."""
    t = model.triangles
    if len(t) == 0:
        return 0.0
    x = model.positions
    edges = np.concatenate([x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 1]], x[t[:, 0]] - x[t[:, 2]]])
    return MAX_THICKNESS_FRACTION * float(np.sqrt((edges * edges).sum(axis=1)).min())


def check_thickness(model, thickness: float) -> None:
    """``ValueError`` naming thickness and self_collision when self-collision cannot use it."""
    limit = thickness_limit(model)
    if not thickness <= limit * (1 + 1e-9):  # a spacing of 0.02 measures 0.0199999…
        raise ValueError(f"thickness = {thickness:g} m is too thick for self_collision on this cloth: "
                         f"expected at most {limit:.4g} m (half its shortest triangle edge at rest); "
                         f"lower thickness or turn self_collision off")


class SelfCollision:
    """The self-collision stage (module docstring); active when ``enabled``."""

    name = "self_collision"

    def __init__(self, model, thickness: float = 0.005, enabled: bool = False):
        self.model = model
        self.thickness = float(thickness)
        self.enabled = False
        self._tris = np.ascontiguousarray(model.triangles, dtype=np.int64)
        self._features = _features(self._tris, model.n_particles)
        self.set_enabled(enabled)
        inv = np.where(model.pinned, 0.0, 1.0 / model.masses)
        self._inv_mass = np.ascontiguousarray(inv)
        self._factor = np.ones(model.n_particles)
        self._no_clearance = np.full(model.n_particles, np.inf)
        self._caps = (np.zeros(1, np.int64), np.zeros(1, np.int64))  # rows per search chunk
        self.last_pairs = self.last_pushed = self.last_slowed = self.last_edge_pairs = 0

    @property
    def active(self) -> bool:
        return self.enabled

    def set_enabled(self, on: bool) -> None:
        """Turn it on or off; on needs the model's triangles and a thickness it can use
        (``ValueError`` otherwise, and nothing changes)."""
        if on and len(self._tris) == 0:
            raise ValueError("self_collision needs the model's triangles (a grid has them; "
                             "ClothModel.from_springs takes triangles=...)")
        if on:
            check_thickness(self.model, self.thickness)
        self.enabled = bool(on)

    #: per particle, how far above a collider's skin the contact stage left it (``inf``: no collider;
    #: set by the simulator): within ``SUPPORT·thickness`` self-collision moves it as if pinned, so it
    #: never pushes the cloth into a collider
    clearance = None

    def apply(self, state, start, dt, velocity_follow):
        x, x0, v = state.x, start.x, state.v
        h = self.thickness
        inv_mass = self._inv_mass
        clearance = self._no_clearance if self.clearance is None else self.clearance
        held = clearance < SUPPORT * h
        if held.any():
            inv_mass = np.where(held, 0.0, inv_mass)
        radius = h + 2.0 * max_displacement(x, x0)
        tris, (edges, tri_edge, edge_owner, edge_tris, vertex_owner, adj_ptr, adj) = \
            self._tris, self._features
        caps = self._caps
        pairs, dist = candidate_pairs(x0, tris, radius, caps[0])
        e_pairs, e_dist = edge_pairs(x0, edges, radius, caps[1])
        free = self._inv_mass
        self.last_pushed = (proximity(x, x0, v, tris, pairs, inv_mass, free, clearance, h)
                            + proximity_features(x, x0, v, tris, pairs, inv_mass, free, clearance, h,
                                                 tri_edge, edge_owner, edge_tris, vertex_owner,
                                                 adj_ptr, adj)
                            + proximity_edges(x, x0, v, edges, e_pairs, inv_mass, free, clearance, h))
        # a pair the no-crossing pass must see is closer at the start than the two motions
        # together, at most twice the longest: the search covered that unless the pushes made
        # some motion longer than radius / 2
        grown = 2.0 * max_displacement(x, x0)
        if grown > radius:
            pairs, dist = candidate_pairs(x0, tris, grown, caps[0])
            e_pairs, e_dist = edge_pairs(x0, edges, grown, caps[1])
        self.last_pairs, self.last_edge_pairs = len(pairs), len(e_pairs)
        displacement_factors(x, x0, tris, pairs, dist, self._factor)
        edge_displacement_factors(x, x0, edges, e_pairs, e_dist, self._factor)
        self.last_slowed = scale_displacements(x, x0, self._factor)
        if self.last_slowed:
            v *= self._factor[:, None]


def _features(tris: np.ndarray, n: int):
    """What the point–edge, point–point and edge–edge cases need of the topology: the unique edges
    ``(e, 2)``; each triangle's edge in slots 0 (a–b), 1 (b–c), 2 (c–a); each edge's first triangle
    (its owner) and its (up to) two triangles (−1 for none); each particle's first triangle; and the
    particles' neighbours along edges (CSR ``adj_ptr``, ``adj``)."""
    if len(tris) == 0:
        z = np.zeros((0, 2), np.int64)
        return (z, np.zeros((0, 3), np.int64), np.zeros(0, np.int64), z, np.full(n, -1, np.int64),
                np.zeros(n + 1, np.int64), np.zeros(0, np.int64))
    from .mesh import _half_edges  # the unique edges, and each half-edge's

    a = tris.ravel()
    edges, group, _ = _half_edges(tris, n)
    tri_edge = group.reshape(-1, 3).astype(np.int64)
    edges = edges.astype(np.int64)
    half_tri = np.repeat(np.arange(len(tris), dtype=np.int64), 3)
    order = np.lexsort((half_tri, tri_edge.ravel()))
    e_sorted, t_sorted = tri_edge.ravel()[order], half_tri[order]
    first = np.r_[True, e_sorted[1:] != e_sorted[:-1]]
    edge_tris = np.full((len(edges), 2), -1, np.int64)
    edge_tris[e_sorted[first], 0] = t_sorted[first]
    edge_tris[e_sorted[~first], 1] = t_sorted[~first]  # a cloth edge has at most two triangles
    edge_owner = np.ascontiguousarray(edge_tris[:, 0])
    vertex_owner = np.full(n, np.iinfo(np.int64).max, np.int64)
    np.minimum.at(vertex_owner, a, half_tri)
    vertex_owner[vertex_owner == np.iinfo(np.int64).max] = -1
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    other = np.concatenate([edges[:, 1], edges[:, 0]])
    order = np.argsort(ends, kind="stable")
    adj_ptr = np.zeros(n + 1, np.int64)
    np.add.at(adj_ptr, ends + 1, 1)
    return (edges, tri_edge, edge_owner, edge_tris, vertex_owner, np.cumsum(adj_ptr),
            np.ascontiguousarray(other[order]))
