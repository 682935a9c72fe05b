"""The features of a triangle mesh's candidate grid (:mod:`.triangle_meshes`): for each cell, found
once when the mesh is built, the one feature of the mesh that is nearest all over it where there is
one, so that a query there is that feature's closed form instead of the cell's list of triangles.

- A **plane**: every point of the cell lies over one face (one triangle, or several in one plane
  facing one way whose union covers the cell's shadow: a box's face and its diagonal).
- An **edge**: every point lies in one edge's region (beyond it, between its ends).
- A **crease**, on a closed mesh: the cell holds points nearest two faces and the edge between
  them (a box's edge with a cloth draped over it), answered by the two planes and the edge
  together (:func:`crease_distance`: the distance from the wedge the faces bound, convex or
  concave).

Each is checked against the cell's listed triangles at its eight corners with linear or convex
conditions that then hold over the whole cell (:func:`find_features`); the test
``test_mesh_colliders.py::test_the_candidate_grid_answers_as_the_walk_does`` compares every
answer with the hierarchy walk's. On a box-like mesh most of the surface's neighbourhood is
answered this way; on a body's or a robot link's small triangles, little of it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..kernel_cache import keep_true
from .geometry import corners_d2

#: a cell's feature (:func:`find_features`): its kind, in column 0 of its row of ``cell_features``
NO_FEATURE, PLANE_FEATURE, EDGE_FEATURE, CREASE_FEATURE = 0, 1, 2, 3
#: a feature's row: the kind, then a plane's ``(n, offset)``; an edge's first end, its
#: direction ``b − a``, ``1/|b − a|²`` and its sign (+1 outside, −1 inside); or a crease's two
#: planes, a point of its edge, the edge's unit direction and its sign (:func:`crease_distance`)
FEATURE_WIDTH = 16


@numba.njit(cache=True, inline="always")
def _triangle_d2(v, t, k, x, y, z):
    """Triangle ``k``'s point nearest ``(x, y, z)``: the squared distance, the point and its
    barycentric weights."""
    a, b, c = t[k, 0], t[k, 1], t[k, 2]
    return corners_d2(
        x, y, z, v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1], v[b, 2], v[c, 0], v[c, 1], v[c, 2]
    )


@numba.njit(cache=True, inline="always")
def _coplanar(v, t, fn, k, tri, a):
    """Whether triangle ``k`` lies in triangle ``tri``'s plane (``a`` one of its vertices): a point
    whose projection on that plane is inside ``tri`` is then nearer ``tri`` than ``k``."""
    cross = (
        abs(fn[k, 1] * fn[tri, 2] - fn[k, 2] * fn[tri, 1])
        + abs(fn[k, 2] * fn[tri, 0] - fn[k, 0] * fn[tri, 2])
        + abs(fn[k, 0] * fn[tri, 1] - fn[k, 1] * fn[tri, 0])
    )
    if cross > 1e-12:
        return False
    for corner in range(3):
        b = t[k, corner]
        off = (
            fn[tri, 0] * (v[b, 0] - v[a, 0])
            + fn[tri, 1] * (v[b, 1] - v[a, 1])
            + fn[tri, 2] * (v[b, 2] - v[a, 2])
        )
        if abs(off) > 1e-12:
            return False
    return True


@numba.njit(cache=True, inline="always")
def _same_point(v, i, j):
    return v[i, 0] == v[j, 0] and v[i, 1] == v[j, 1] and v[i, 2] == v[j, 2]


@numba.njit(cache=True, inline="always")
def _shares_edge(v, t, k, i, j):
    """Whether triangle ``k`` has an edge from the point of vertex ``i`` to that of ``j`` (in
    either direction; vertices compared by position, as :func:`_solid` welds them)."""
    for e in range(3):
        p, q = t[k, e], t[k, (e + 1) % 3]
        if (_same_point(v, p, i) and _same_point(v, q, j)) or (
            _same_point(v, p, j) and _same_point(v, q, i)
        ):
            return True
    return False


@numba.njit(cache=True, inline="always")
def _third(v, t, k, i, j):
    """The corner of triangle ``k`` that is neither the point of vertex ``i`` nor that of ``j``
    (its edge ``ij``'s opposite corner)."""
    third = t[k, 0]
    for e in range(3):
        if not (_same_point(v, t[k, e], i) or _same_point(v, t[k, e], j)):
            third = t[k, e]
    return third


@numba.njit(cache=True, inline="always")
def _in_plane_group(v, t, fn, k, tri, a):
    """Whether triangle ``k`` lies in triangle ``tri``'s plane facing the same way."""
    same = fn[k, 0] * fn[tri, 0] + fn[k, 1] * fn[tri, 1] + fn[k, 2] * fn[tri, 2] > 0.0
    return same and (k == tri or _coplanar(v, t, fn, k, tri, a))


@numba.njit(cache=True, inline="always")
def _segment_d2(px, py, pz, ax, ay, az, bx, by, bz):
    """The squared distance from ``p`` to the segment ``ab``."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    ee = ex * ex + ey * ey + ez * ez
    s = ((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / ee
    s = min(1.0, max(0.0, s))
    dx, dy, dz = px - ax - s * ex, py - ay - s * ey, pz - az - s * ez
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True, inline="always")
def _on_line(v, i, line):
    """Whether vertex ``i`` lies on the line ``(a point, a unit direction)``, six numbers (never,
    where the direction is zero)."""
    ax, ay, az, ux, uy, uz = line
    if ux == 0.0 and uy == 0.0 and uz == 0.0:
        return False
    wx, wy, wz = v[i, 0] - ax, v[i, 1] - ay, v[i, 2] - az
    s = wx * ux + wy * uy + wz * uz
    wx, wy, wz = wx - s * ux, wy - s * uy, wz - s * uz
    return wx * wx + wy * wy + wz * wz <= 1e-24 * max(1.0, s * s)


@numba.njit(cache=True)
def _plane_group(mesh, tri, a, cid, r, cell_centre, line):
    """Whether the distance is ``tri``'s plane's over cell ``cid`` whose eight corners each lie
    nearest a triangle of that plane (facing the same way), exactly over it: the cell's
    projection on the plane lies inside the union of the plane's listed triangles when no edge
    of that union's boundary (an edge of one of them that no other of them shares) comes within
    ``r`` (the cell's half diagonal) of the cell centre's projection, in the plane. (The
    projection of every corner is inside the union, and the projected cell inside the disc of
    radius ``r``.) ``line``, six numbers ``(point, unit direction)``, names a crease whose edges
    are passed over (:func:`_crease_cell`; a zero direction: none). (Its callers give it the
    same types, so that it compiles once: its triangle's index an ``int64`` from the start, not
    a literal ``-1`` reassigned later, which numba's type inference compiled it for too, and
    the line as numbers, not a view beside a read-only global array: four signatures, 14 s.)"""
    v, t, order, fn, _, _, ptr, listed = mesh
    nx, ny, nz = fn[tri, 0], fn[tri, 1], fn[tri, 2]
    cx, cy, cz = cell_centre[0], cell_centre[1], cell_centre[2]
    off = nx * (cx - v[a, 0]) + ny * (cy - v[a, 1]) + nz * (cz - v[a, 2])
    qx, qy, qz = cx - off * nx, cy - off * ny, cz - off * nz  # the centre on the plane
    for j in range(ptr[cid], ptr[cid + 1]):
        k = order[listed[j]]
        if not _in_plane_group(v, t, fn, k, tri, a):
            continue
        for e in range(3):
            i0, i1 = t[k, e], t[k, (e + 1) % 3]
            shared = False
            for j2 in range(ptr[cid], ptr[cid + 1]):
                k2 = order[listed[j2]]
                if k2 != k and _in_plane_group(v, t, fn, k2, tri, a):
                    if _shares_edge(v, t, k2, i0, i1):
                        shared = True
                        break
            if shared or (_on_line(v, i0, line) and _on_line(v, i1, line)):
                continue
            d2 = _segment_d2(
                qx, qy, qz, v[i0, 0], v[i0, 1], v[i0, 2], v[i1, 0], v[i1, 1], v[i1, 2]
            )
            if d2 <= r * r:
                return False
    return True


@numba.njit(cache=True, parallel=True)
def find_features(v, t, order, fn, closed, origin, cell, dims, band, ptr, listed):
    """Each cell's *feature* where one answers every query in the cell exactly: ``(feature,
    rows)``, ``feature[cid]`` the row of cell ``cid`` in ``rows`` (``(f, FEATURE_WIDTH)``), −1
    where none does. The cells are tried in slabs of constant x in parallel, each into a row of
    its own, and numbered in cell order after: the same rows at any thread count.

    - A **plane** ``(n, offset)``, where the distance from every point ``x`` of the cell is
      ``n·x + offset``: the nearest point of each of the cell's eight corners lies inside one
      triangle ``T`` (not on its edges), so every point of the cell has its nearest point of
      ``T``'s plane inside ``T`` (a triangle is convex); or each corner lies nearest, and over,
      a triangle of ``T``'s plane facing its way and no edge of those triangles' union's border
      comes near the cell (:func:`_plane_group`: a face made of several triangles, a box's
      diagonal). The plane is ``T``'s outward one on a closed mesh (the signed distance; the
      face's pseudonormal is its normal), and turned towards the cell on an open one, whose
      corners must then lie on one side (or on the plane).
    - An **edge** ``ab``, where the distance is the distance from the segment: every corner lies
      in the edge's region of each triangle that has it (its projection on the triangle's plane
      beyond the edge, between the perpendicular planes at its ends: linear conditions, so the
      whole cell does), where that triangle's nearest point is on the edge; a closed mesh's
      sign is the edge pseudonormal's, the same at every corner
      (:func:`.triangle_meshes.mesh_distance`).
    - A **crease**, on a closed mesh, where two faces meet at an edge: the planes' and the edge's
      distance combined (:func:`crease_distance`, checked by :func:`_crease_cell`), near a box's
      edges where a cell holds points nearest a face and points nearest the edge.

    In each, every corner lies within the band (so what the cell does not list is farther), and
    every other listed triangle is farther from the cell's centre, less the half diagonal, than
    the feature is from any corner (the feature's distance is convex: its largest over the cell
    is at a corner), so none is nearer anywhere in the cell."""
    ny, nz = dims[1], dims[2]
    cells = dims[0] * ny * nz
    mesh = (v, t, order, fn, closed, band, ptr, listed)
    r = 0.5 * cell * math.sqrt(3.0)
    found = np.zeros(cells, np.bool_)
    every = np.zeros((cells, FEATURE_WIDTH))  # (a row's columns past its kind's stay 0)
    for ix in numba.prange(dims[0]):
        corners = np.empty((8, 3))
        centre = np.empty(3)
        # each corner's nearest listed triangle (−2: not asked yet, −1: none within the band),
        # its squared distance and its weights there, asked as the tests need them
        near_k = np.empty(8, np.int64)
        near_d2 = np.empty(8)
        near_w = np.empty((8, 3))
        for iy in range(ny):
            for iz in range(nz):
                cid = (ix * ny + iy) * nz + iz
                if ptr[cid + 1] == ptr[cid]:
                    continue
                for corner in range(8):
                    corners[corner, 0] = origin[0] + (ix + (corner & 1)) * cell
                    corners[corner, 1] = origin[1] + (iy + ((corner >> 1) & 1)) * cell
                    corners[corner, 2] = origin[2] + (iz + ((corner >> 2) & 1)) * cell
                    near_k[corner] = -2
                centre[0] = origin[0] + (ix + 0.5) * cell
                centre[1] = origin[1] + (iy + 0.5) * cell
                centre[2] = origin[2] + (iz + 0.5) * cell
                at = (cid, corners, centre, r, near_k, near_d2, near_w)
                row = every[cid]
                found[cid] = (
                    _plane_cell(mesh, at, row)
                    or _edge_cell(mesh, at, row)
                    or _crease_cell(mesh, at, row)
                )
    feature = np.full(cells, -1, np.int64)
    count = 0
    for cid in range(cells):
        if found[cid]:
            feature[cid] = count
            count += 1
    rows = np.empty((count, FEATURE_WIDTH))
    for cid in range(cells):
        if found[cid]:
            rows[feature[cid]] = every[cid]
    return feature, rows


@numba.njit(cache=True)
def _near(mesh, at, corner):
    """The nearest listed point to corner ``corner`` of the cell ``at`` (:func:`find_features`),
    asked once: its triangle (−1: none within the band), squared distance and weights."""
    cid, corners, _, _, near_k, near_d2, near_w = at
    if near_k[corner] == -2:
        k, d2, wa, wb, wc = _nearest_listed(
            mesh, cid, corners[corner, 0], corners[corner, 1], corners[corner, 2]
        )
        near_k[corner], near_d2[corner] = k, d2
        near_w[corner, 0], near_w[corner, 1], near_w[corner, 2] = wa, wb, wc
    return near_k[corner], near_d2[corner], near_w[corner, 0], near_w[corner, 1], near_w[corner, 2]


@numba.njit(cache=True)
def _nearest_listed(mesh, cid, x, y, z):
    """The nearest point of cell ``cid``'s listed triangles to ``(x, y, z)`` within the band: its
    triangle (−1: none), squared distance and barycentric weights."""
    v, t, order, _, _, band, ptr, listed = mesh
    best = band * band
    bk = -1
    wa = wb = wc = 0.0
    for j in range(ptr[cid], ptr[cid + 1]):
        k = order[listed[j]]
        d2, _, _, _, ka, kb, kc = _triangle_d2(v, t, k, x, y, z)
        if d2 < best:
            best, bk, wa, wb, wc = d2, k, ka, kb, kc
    return bk, best, wa, wb, wc


@numba.njit(cache=True)
def _plane_cell(mesh, at, row):
    """Whether a plane answers the cell ``at`` (:func:`find_features`), written to ``row``."""
    v, t, order, fn, closed, band, ptr, listed = mesh
    cid, corners, centre, r, near_k, near_d2, near_w = at
    tri = a = np.int64(-1)  # (not a literal: _plane_group's docstring)
    far = side = 0.0
    grouped = False
    for corner in range(8):
        x, y, z = corners[corner, 0], corners[corner, 1], corners[corner, 2]
        bk, best, wa, wb, wc = _near(mesh, at, corner)
        inner = wa > 1e-9 and wb > 1e-9 and wc > 1e-9
        if bk < 0:
            return False
        if tri < 0:
            tri, a = bk, t[bk, 0]
        d = fn[tri, 0] * (x - v[a, 0]) + fn[tri, 1] * (y - v[a, 1]) + fn[tri, 2] * (z - v[a, 2])
        if bk != tri or not inner:  # a face of several triangles: over one of them
            if not _in_plane_group(v, t, fn, bk, tri, a):
                return False
            if abs(math.sqrt(best) - abs(d)) > 1e-9 * band:
                return False
            grouped = True
        if not closed and d != 0.0:  # (a corner on the plane is on either side)
            s = 1.0 if d > 0.0 else -1.0
            if side != 0.0 and s != side:
                return False
            side = s
        far = max(far, abs(d))
    if not closed and side == 0.0:
        return False
    no_line = (centre[0], centre[1], centre[2], 0.0, 0.0, 0.0)
    if grouped and not _plane_group(mesh, tri, a, cid, r, centre, no_line):
        return False
    cx, cy, cz = centre[0], centre[1], centre[2]
    for j in range(ptr[cid], ptr[cid + 1]):
        k = order[listed[j]]
        if k == tri or _coplanar(v, t, fn, k, tri, a):
            continue  # (its points are off the cell's projection: farther)
        if math.sqrt(_triangle_d2(v, t, k, cx, cy, cz)[0]) - r <= far:
            return False
    s = 1.0 if closed else side
    nx, ny, nz = s * fn[tri, 0], s * fn[tri, 1], s * fn[tri, 2]
    row[0] = PLANE_FEATURE
    row[1], row[2], row[3] = nx, ny, nz
    row[4] = -(nx * v[a, 0] + ny * v[a, 1] + nz * v[a, 2])
    return True


@numba.njit(cache=True)
def _edge_cell(mesh, at, row):
    """Whether an edge answers the cell ``at`` (:func:`find_features`), written to ``row``."""
    v, t, order, fn, closed, band, ptr, listed = mesh
    cid, corners, centre, r, _, _, _ = at
    # the edge: where the first corner's nearest point lies, inside an edge
    bk, _, wa, wb, wc = _near(mesh, at, np.int64(0))  # (not a literal: one signature)
    if bk < 0:
        return False
    if wc == 0.0 and wa > 0.0 and wb > 0.0:
        i0, i1 = t[bk, 0], t[bk, 1]
    elif wa == 0.0 and wb > 0.0 and wc > 0.0:
        i0, i1 = t[bk, 1], t[bk, 2]
    elif wb == 0.0 and wc > 0.0 and wa > 0.0:
        i0, i1 = t[bk, 2], t[bk, 0]
    else:
        return False
    ax, ay, az = v[i0, 0], v[i0, 1], v[i0, 2]
    ex, ey, ez = v[i1, 0] - ax, v[i1, 1] - ay, v[i1, 2] - az
    ee = ex * ex + ey * ey + ez * ez
    # every corner in the edge's region of each triangle that has it
    sx = sy = sz = 0.0  # (their normals' sum: the edge's pseudonormal, where closed)
    for j in range(ptr[cid], ptr[cid + 1]):
        k = order[listed[j]]
        if not _shares_edge(v, t, k, i0, i1):
            continue
        third = _third(v, t, k, i0, i1)
        wx, wy, wz = v[third, 0] - ax, v[third, 1] - ay, v[third, 2] - az
        f = (wx * ex + wy * ey + wz * ez) / ee
        mx, my, mz = wx - f * ex, wy - f * ey, wz - f * ez  # in the plane, across the edge
        for corner in range(8):
            px, py, pz = corners[corner, 0] - ax, corners[corner, 1] - ay, corners[corner, 2] - az
            if px * mx + py * my + pz * mz > 0.0:
                return False
        sx, sy, sz = sx + fn[k, 0], sy + fn[k, 1], sz + fn[k, 2]
    far = 0.0
    sign = 0.0
    for corner in range(8):
        px, py, pz = corners[corner, 0] - ax, corners[corner, 1] - ay, corners[corner, 2] - az
        s = px * ex + py * ey + pz * ez
        if s <= 0.0 or s >= ee:
            return False
        s /= ee
        qx, qy, qz = px - s * ex, py - s * ey, pz - s * ez  # from the edge to the corner
        d2 = qx * qx + qy * qy + qz * qz
        if d2 >= band * band or d2 == 0.0:
            return False
        far = max(far, math.sqrt(d2))
        if closed:
            side = qx * sx + qy * sy + qz * sz
            if side == 0.0 or (sign != 0.0 and (side > 0.0) != (sign > 0.0)):
                return False
            sign = 1.0 if side > 0.0 else -1.0
    for j in range(ptr[cid], ptr[cid + 1]):
        k = order[listed[j]]
        if _shares_edge(v, t, k, i0, i1):
            continue
        if math.sqrt(_triangle_d2(v, t, k, centre[0], centre[1], centre[2])[0]) - r <= far:
            return False
    row[0] = EDGE_FEATURE
    row[1], row[2], row[3] = ax, ay, az
    row[4], row[5], row[6] = ex, ey, ez
    row[7] = 1.0 / ee
    row[8] = sign if closed else 1.0
    return True


@numba.njit(cache=True, inline="always")
def crease_distance(row, x, y, z):
    """The signed distance from ``(x, y, z)`` of a crease's row (:func:`_crease_cell`) and its
    gradient: the solid's distance where two faces meet at an edge, convex (the solid is the
    wedge ``{d1 ≤ 0, d2 ≤ 0}`` of the faces' planes, the row's sign +1) or concave (the union
    of their half-spaces: the row's planes turned over and the sign −1). In the wedge the nearer
    plane is the surface; outside, a face's plane where the point's projection on it lies in the
    wedge, and the edge elsewhere."""
    d1 = row[1] * x + row[2] * y + row[3] * z + row[4]
    d2 = row[5] * x + row[6] * y + row[7] * z + row[8]
    sign = row[15]
    if d1 <= 0.0 and d2 <= 0.0:
        if d1 >= d2:
            return sign * d1, sign * row[1], sign * row[2], sign * row[3]
        return sign * d2, sign * row[5], sign * row[6], sign * row[7]
    c = row[1] * row[5] + row[2] * row[6] + row[3] * row[7]
    if d1 > 0.0 and d2 - d1 * c <= 0.0:
        return sign * d1, sign * row[1], sign * row[2], sign * row[3]
    if d2 > 0.0 and d1 - d2 * c <= 0.0:
        return sign * d2, sign * row[5], sign * row[6], sign * row[7]
    wx, wy, wz = x - row[9], y - row[10], z - row[11]
    s = wx * row[12] + wy * row[13] + wz * row[14]
    wx, wy, wz = wx - s * row[12], wy - s * row[13], wz - s * row[14]
    d = math.sqrt(wx * wx + wy * wy + wz * wz)
    if d == 0.0:  # (on the edge: the first face's normal)
        return 0.0, sign * row[1], sign * row[2], sign * row[3]
    return sign * d, sign * wx / d, sign * wy / d, sign * wz / d


@numba.njit(cache=True)
def _crease_cell(mesh, at, row):
    """Whether a crease answers the cell ``at`` of a closed mesh (:func:`find_features`), written
    to ``row``: an edge of the first corner's nearest triangle shared with a face not in its
    plane, whose distance (:func:`crease_distance`)
    is the mesh's at every point of the cell: every corner lies nearest, within the band, a
    triangle of one of the two faces' planes (facing its way) at the crease's distance; every
    corner projects onto the edge inside it; on each face's plane, no edge of the border of the
    union of its listed triangles but the crease comes within the cell's half diagonal of the
    cell centre's projection (so where the crease takes a face's plane, the face is there:
    :func:`_plane_group`); every other listed triangle is farther than the crease's largest
    bound on the cell (each plane's distance and the edge's, largest at a corner)."""
    t, closed = mesh[1], mesh[4]
    if not closed:
        return False
    bk = _near(mesh, at, np.int64(0))[0]  # (not a literal: one signature)
    if bk < 0:
        return False
    for e in range(3):  # the edges of the first corner's nearest triangle
        if _crease_row(mesh, at, bk, t[bk, e], t[bk, (e + 1) % 3], row):
            return True
    return False


@numba.njit(cache=True)
def _crease_row(mesh, at, f1, i0, i1, row):
    """:func:`_crease_cell` of the edge ``i0 i1`` of triangle ``f1``."""
    v, t, order, fn, _, band, ptr, listed = mesh
    cid, corners, centre, r, _, _, _ = at
    ax, ay, az = v[i0, 0], v[i0, 1], v[i0, 2]
    ex, ey, ez = v[i1, 0] - ax, v[i1, 1] - ay, v[i1, 2] - az
    length = math.sqrt(ex * ex + ey * ey + ez * ez)
    ux, uy, uz = ex / length, ey / length, ez / length
    for corner in range(8):  # (first the cheapest test: the corners project inside the edge)
        s = (corners[corner, 0] - ax) * ux + (corners[corner, 1] - ay) * uy
        s += (corners[corner, 2] - az) * uz
        if s <= 0.0 or s >= length:
            return False
    f2 = np.int64(-1)  # (not a literal: _plane_group's docstring)
    for j in range(ptr[cid], ptr[cid + 1]):
        k = order[listed[j]]
        if k != f1 and _shares_edge(v, t, k, i0, i1):
            f2 = k
    if f2 < 0:
        return False
    nx = fn[f1, 1] * fn[f2, 2] - fn[f1, 2] * fn[f2, 1]
    ny = fn[f1, 2] * fn[f2, 0] - fn[f1, 0] * fn[f2, 2]
    nz = fn[f1, 0] * fn[f2, 1] - fn[f1, 1] * fn[f2, 0]
    if nx * nx + ny * ny + nz * nz < 1e-12:
        return False  # (coplanar: a plane's, or none)
    # convex where the second face's far corner lies behind the first face's plane
    third = _third(v, t, f2, i0, i1)
    behind = (
        fn[f1, 0] * (v[third, 0] - ax)
        + fn[f1, 1] * (v[third, 1] - ay)
        + fn[f1, 2] * (v[third, 2] - az)
    )
    if behind == 0.0:
        return False
    sign = 1.0 if behind < 0.0 else -1.0
    row[0] = CREASE_FEATURE
    for g, f in enumerate((f1, f2)):
        row[1 + 4 * g], row[2 + 4 * g], row[3 + 4 * g] = (
            sign * fn[f, 0],
            sign * fn[f, 1],
            sign * fn[f, 2],
        )
        row[4 + 4 * g] = -sign * (fn[f, 0] * ax + fn[f, 1] * ay + fn[f, 2] * az)
    row[9], row[10], row[11] = ax, ay, az
    row[12], row[13], row[14] = ux, uy, uz
    row[15] = sign
    far = 0.0
    for corner in range(8):
        x, y, z = corners[corner, 0], corners[corner, 1], corners[corner, 2]
        s = (x - ax) * ux + (y - ay) * uy + (z - az) * uz
        k, nearest2 = _near(mesh, at, corner)[:2]
        if k < 0:
            return False
        if not (
            _in_plane_group(v, t, fn, k, f1, t[f1, 0])
            or _in_plane_group(v, t, fn, k, f2, t[f2, 0])
        ):
            return False
        d = crease_distance(row, x, y, z)[0]
        if abs(math.sqrt(nearest2) - abs(d)) > 1e-9 * band:
            return False
        p1 = row[1] * x + row[2] * y + row[3] * z + row[4]
        p2 = row[5] * x + row[6] * y + row[7] * z + row[8]
        wx, wy, wz = x - ax - s * ux, y - ay - s * uy, z - az - s * uz
        far = max(far, abs(p1), abs(p2), math.sqrt(wx * wx + wy * wy + wz * wz))
    line = (row[9], row[10], row[11], row[12], row[13], row[14])
    if not (
        _plane_group(mesh, f1, t[f1, 0], cid, r, centre, line)
        and _plane_group(mesh, f2, t[f2, 0], cid, r, centre, line)
    ):
        return False
    for j in range(ptr[cid], ptr[cid + 1]):
        k = order[listed[j]]
        if _in_plane_group(v, t, fn, k, f1, t[f1, 0]) or _in_plane_group(
            v, t, fn, k, f2, t[f2, 0]
        ):
            continue
        if math.sqrt(_triangle_d2(v, t, k, centre[0], centre[1], centre[2])[0]) - r <= far:
            return False
    return True


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
