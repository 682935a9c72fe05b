"""Triangle meshes as colliders' shapes: a mesh in its own frame with a bounding-volume hierarchy,
and the closest-point query the contact kernels call.

A **closed** mesh (every edge shared by exactly two triangles, in opposite directions, once
vertices at the same position are welded: a robot link's watertight collision mesh) is a solid:
its distance is signed, negative inside, the sign taken from the angle-weighted pseudonormal of the
nearest feature (face, edge or vertex; Bærentzen & Aanæs 2005, exact for a closed, consistently
oriented mesh), its faces turned outwards where the file has them inwards (a negative volume). So
a vertex a fast link overtook, or one squeezed in, is inside and is pushed out, never kept at the
thickness from the inner surface. An **open** mesh, a body's or a plate's, is two-sided: both sides
of every triangle are surfaces and its distance is the unsigned distance to the nearest triangle.
The kernels read all the meshes of a simulation packed into one *bank* (:func:`pack`), each mesh
addressed by its index there.

The hierarchy is :func:`cloth_sim.contact.collision_tree.build_hierarchy`'s median split over the
triangles' centres (the self-collision tree's), built once in the mesh's frame; a node's box holds
its triangles and never changes (the collider moves, its mesh does not deform). A query walks it
in depth-first order without a stack (the nodes renumbered in preorder, each with the node after
its subtree: nothing is allocated a query) and prunes every box farther than the best triangle
found (Ericson, *Real-Time Collision Detection*, 6.1); the answer is exact everywhere. (An
earlier version answered the root box's distance outside it, a lower bound: next to a body's box
but far from the body that put phantom contacts on the box's faces. The kernels skip far colliders
by their reach instead.)

Near the surface a query does not walk: each mesh has a **candidate grid** in its frame, cells of
half its median edge over its box grown by a band of two cells, and each cell lists the triangles
whose box, grown by the band, meets the cell (built once, by rasterising each triangle's grown
box). Every triangle within the band of a point in the cell is listed, so where the nearest listed
triangle lies within the band, or a query's cutoff does, the cell's list is the answer; the list
keeps the walk's order and the arithmetic is the walk's, so the answer is the walk's to the bit
(but where two triangles sharing an edge tie for the nearest: the walk passes over a box no nearer
than its best so far, and may keep the other one, the same point to rounding).

A cell over which one *feature* is nearest everywhere (:mod:`.mesh_features`) keeps it, and a query
there is the feature's closed form, equal to the walk's answer to rounding
(``test_mesh_colliders.py``): a **plane** where every point's nearest point lies inside one face
(one dot product); an **edge** where it lies inside one edge (a point's distance from a segment,
signed by the edge's pseudonormal); a **crease** on a closed mesh, where it lies on one of two
faces or on the edge between them (two planes and a segment: a box's edge, where the face's and
the edge's points share cells). A cloth lying on a box mesh, on its faces and over its edges, is
answered this way but near the box's corners, at about three times the Box primitive's cost a
query (44–54 against 13–17 ns) where the list and the walk take about ten
(``python -m cloth_sim.bench.robot``, ``mesh_queries``). Elsewhere the list or the walk answers.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..kernel_cache import keep_true
from .collision_tree import build_hierarchy
from .geometry import corners_d2
from .mesh_features import (
    CREASE_FEATURE,
    FEATURE_WIDTH,
    NO_FEATURE,
    PLANE_FEATURE,
    crease_distance,
    find_features,
)

#: triangles a leaf holds at most
LEAF = 4
#: a mesh's candidate grid (module docstring): at least this many cells along its longest side,
#: at most this many cells in all, and its band (where a cell's list answers) in cells
GRID_CELLS = 32
MAX_CELLS = 1 << 18
BAND_CELLS = 2


class TriangleMesh:
    """A rigid triangle mesh in its own frame: ``vertices (n, 3)`` metres, ``triangles (t, 3)``,
    and its hierarchy (``left``, ``right``, ``first``, ``end``, ``order``, the nodes' boxes ``lo``,
    ``hi``)."""

    def __init__(self, vertices, triangles, name: str, grid: bool = True):
        # a copy of its own: the caller's array may change after (a simulation's positions), and a
        # read-only one (those positions' view) would make numba compile every kernel here again
        # for read-only arrays
        v = np.array(vertices, dtype=np.float64, order="C")
        t = np.ascontiguousarray(triangles, dtype=np.int64)
        a, b, c = (v[t[:, k]] for k in range(3))
        area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        keep = area2 > 1e-14 * max(1e-300, float(np.max(area2)) if len(area2) else 0.0)
        t = np.ascontiguousarray(t[keep])  # a zero-area triangle has no closest point of its own
        if len(t) == 0:
            raise ValueError(f"{name}: the mesh has no triangle of nonzero area")
        self.name = name
        self.vertices, self.triangles = v, t
        centres = v[t].mean(axis=1)
        left, right, first, end, _, self.order = build_hierarchy(
            np.ascontiguousarray(centres), LEAF
        )
        # the nodes renumbered in depth-first preorder, so that a node's first child is the next
        # node and ``skip`` the one after its subtree: the query walks it without a stack
        pre, size = [], np.ones(len(left), np.int64)
        todo = [0]
        while todo:
            n = todo.pop()
            pre.append(n)
            if left[n] >= 0:
                todo += [right[n], left[n]]
        for n in reversed(pre):
            if left[n] >= 0:
                size[n] += size[left[n]] + size[right[n]]
        pre = np.array(pre)
        at = np.empty(len(pre), np.int64)
        at[pre] = np.arange(len(pre))
        #: ``-1`` for a leaf, else its first child (the next node in preorder)
        self.left = np.where(left[pre] >= 0, np.arange(len(pre)) + 1, -1)
        #: the node after a node's subtree in preorder (``-1``: none)
        self.right = np.arange(len(pre)) + size[pre]
        self.right[self.right >= len(pre)] = -1
        self.first, self.end = first[pre].copy(), end[pre].copy()
        self.lo, self.hi = _boxes(v, t, self.order, self.first, self.end)
        self.closed, self.face_normals, self.vertex_normals, self.edge_normals = _solid(v, t)
        # the candidate grid over the root box grown by the band and a cell, in the mesh's
        # frame: cells of half the median edge (a cell lists the few triangles around it), at
        # least GRID_CELLS along the longest side, at most MAX_CELLS in all
        span = self.hi[0] - self.lo[0]
        longest = max(float(span.max()), 1e-9)
        edges = np.linalg.norm(v[t] - v[np.roll(t, 1, axis=1)], axis=2)
        cell = max(min(longest / GRID_CELLS, 0.5 * float(np.median(edges))), longest / 1024)
        while np.prod(np.ceil(span / cell) + 2 * (BAND_CELLS + 1)) > MAX_CELLS:
            cell *= 1.25
        #: the grid's first corner, its cells' side (m), its cells along x, y, z, and the band
        #: (m) within which a cell's list answers a query
        self.grid_band = BAND_CELLS * cell
        self.grid_origin = self.lo[0] - (BAND_CELLS + 1) * cell
        self.grid_cell = cell
        self.grid_dims = (np.ceil(span / cell) + 2 * (BAND_CELLS + 1)).astype(np.int64)
        if not grid:  # (no cell: every query walks)
            self.grid_dims = np.zeros(3, np.int64)
        #: each cell's candidates (positions in ``order``, in the walk's order), a CSR
        self.cell_ptr, self.cell_list = _candidates(
            v, t, self.order, self.grid_origin, cell, self.grid_dims, self.grid_band
        )
        #: each cell's feature (its row in ``cell_features``, −1: none) where one answers every
        #: query in the cell (a plane, an edge, a crease: :func:`.mesh_features.find_features`)
        self.cell_feature, self.cell_features = find_features(
            v, t, self.order, self.face_normals, self.closed, self.grid_origin, cell,
            self.grid_dims, self.grid_band, self.cell_ptr, self.cell_list,
        )  # fmt: skip

    def feature_at(self, point) -> int:
        """The kind of feature that answers a query at ``point`` (in the mesh's frame):
        ``PLANE_FEATURE``, ``EDGE_FEATURE``, ``CREASE_FEATURE`` or ``NO_FEATURE`` (the cell's
        list or the walk answers)."""
        at = (np.asarray(point, dtype=np.float64) - self.grid_origin) / self.grid_cell
        cell = np.floor(at).astype(np.int64)
        if not np.all((cell >= 0) & (cell < self.grid_dims)):
            return NO_FEATURE
        f = self.cell_feature[
            (cell[0] * self.grid_dims[1] + cell[1]) * self.grid_dims[2] + cell[2]
        ]
        return NO_FEATURE if f < 0 else int(self.cell_features[f, 0])

    @property
    def extent(self) -> float:
        """The largest distance of a vertex from the mesh's origin (its reach when it turns)."""
        return float(np.sqrt((self.vertices**2).sum(axis=1).max()))


def _solid(v: np.ndarray, t: np.ndarray):
    """``(closed, face normals (t, 3), vertex pseudonormals (n, 3), edge pseudonormals (t, 3,
    3))`` of a mesh: whether it is closed (module docstring), each face's unit normal (outwards
    where closed), each vertex's angle-weighted sum of its faces' normals, and for each
    triangle's edges ``ab``, ``bc``, ``ca`` the sum of the two faces' normals. Vertices at the
    same position are one (an STL's triangles each have their own corners)."""
    welded, w = np.unique(v, axis=0, return_inverse=True)
    w = w.reshape(-1)
    tw = w[t]
    n = len(welded)
    a, b, c = (v[t[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    ends = np.concatenate([tw[:, [0, 1]], tw[:, [1, 2]], tw[:, [2, 0]]])  # edge e of triangle k
    key = ends[:, 0] * n + ends[:, 1]
    back = ends[:, 1] * n + ends[:, 0]
    order = np.argsort(key, kind="stable")
    unique = len(np.unique(key)) == len(key)
    found = np.searchsorted(key[order], back)
    found = np.minimum(found, len(key) - 1)
    paired = unique and bool(np.all(key[order][found] == back))
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0
    closed = paired and volume != 0.0
    if closed and volume < 0.0:
        normal = -normal  # the file's faces turn inwards
    m = len(t)
    # each triangle edge's other face (its reverse edge's triangle), where closed
    other = order[found] % m if closed else np.arange(3 * m) % m
    edge = (normal[np.tile(np.arange(m), 3)] + normal[other]).reshape(3, m, 3).transpose(1, 0, 2)
    # the angle of each triangle at each corner, for the vertices' pseudonormals
    vertex = np.zeros((n, 3))
    for k, (p, q, r) in enumerate(((a, b, c), (b, c, a), (c, a, b))):
        u, s = q - p, r - p
        cos = np.einsum("ij,ij->i", u, s) / (np.linalg.norm(u, axis=1) * np.linalg.norm(s, axis=1))
        np.add.at(vertex, tw[:, k], np.arccos(np.clip(cos, -1.0, 1.0))[:, None] * normal)
    return (
        closed,
        np.ascontiguousarray(normal),
        np.ascontiguousarray(vertex[w]),
        np.ascontiguousarray(edge),
    )


@numba.njit(cache=True)
def _boxes(v, t, order, first, end):
    n = first.shape[0]
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    for node in range(n):
        for q in range(first[node], end[node]):
            for k in range(3):
                for a in range(3):
                    c = v[t[order[q], k], a]
                    lo[node, a] = min(lo[node, a], c)
                    hi[node, a] = max(hi[node, a], c)
    return lo, hi


@numba.njit(cache=True)
def _candidates(v, t, order, origin, cell, dims, band):
    """The candidate grid's CSR ``(ptr, positions)``: for each cell (x slowest, z fastest) the
    positions ``q`` in ``order`` of the triangles whose box, grown by ``band``, meets the cell, in
    the walk's order (increasing ``q``). Every triangle within ``band`` of a point of the cell is
    listed (one that is not lies farther than ``band`` along some axis)."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    cells = nx * ny * nz
    lo = np.empty((len(order), 3), np.int64)
    hi = np.empty((len(order), 3), np.int64)
    count = np.zeros(cells + 1, np.int64)
    for q in range(len(order)):
        k = order[q]
        for a in range(3):
            a_lo = min(v[t[k, 0], a], v[t[k, 1], a], v[t[k, 2], a]) - band
            a_hi = max(v[t[k, 0], a], v[t[k, 1], a], v[t[k, 2], a]) + band
            lo[q, a] = max(0, int(math.floor((a_lo - origin[a]) / cell)))
            hi[q, a] = min(dims[a] - 1, int(math.floor((a_hi - origin[a]) / cell)))
        for ix in range(lo[q, 0], hi[q, 0] + 1):
            for iy in range(lo[q, 1], hi[q, 1] + 1):
                for iz in range(lo[q, 2], hi[q, 2] + 1):
                    count[(ix * ny + iy) * nz + iz + 1] += 1
    ptr = np.cumsum(count)
    fill = ptr[:-1].copy()
    out = np.empty(ptr[cells], np.int64)
    for q in range(len(order)):
        for ix in range(lo[q, 0], hi[q, 0] + 1):
            for iy in range(lo[q, 1], hi[q, 1] + 1):
                for iz in range(lo[q, 2], hi[q, 2] + 1):
                    cid = (ix * ny + iy) * nz + iz
                    out[fill[cid]] = q
                    fill[cid] += 1
    return ptr, out


#: a bank (:func:`pack`) is the tuple ``(reals, ints, starts)``, read as ``bank[REALS]`` …
REALS, INTS, STARTS = range(3)


#: where each part of the bank starts: ``bank[STARTS][PART]`` in ``bank[REALS]`` (the first
#: ten) or in ``bank[INTS]`` (the rest)
(
    VERTS, VNORMALS, FNORMALS, ENORMALS, BOX_LO, BOX_HI, ORIGIN, PER_CELL, BAND, FEATURES,
    TRIS, LEFT, RIGHT, FIRST, END, ORDER, ROOT, CLOSED, DIMS, START, PTR, LISTED, FEATURE,
) = range(23)  # fmt: skip


def pack(meshes) -> tuple:
    """The bank of ``meshes`` (:class:`TriangleMesh`) in the order given, mesh ``m`` numbered
    ``m`` there (an empty list gives the bank of no mesh): every mesh of a simulation packed for
    the kernels as ``(reals, ints, starts)``, two flat arrays and where each part starts in
    them.

    Three arrays, not one a part: numba counts every array a function takes in and out where the
    function calls another, inlined or not (~5 ns an array, measured), and a contact query takes
    the bank at every vertex near a mesh; the bank of 22 arrays this replaced cost more than the
    query's arithmetic. A plain tuple, spread flat into the colliders' record
    (:class:`~cloth_sim.contact.collider_kernels.PackedColliders`): numba's parallel loops refuse a
    tuple held in another.

    ``reals`` (float64) holds, mesh after mesh: the vertices and their angle-weighted normals
    (3 a vertex each), each triangle's face normal and its three edges' normals (3 and 9), each
    node's box corners (3 and 3), each mesh's candidate grid's first corner (3), cell side and
    band (m), and each cell's plane ``(n, offset)`` (4; NaN where the distance is not affine
    there). ``ints`` (int64) holds the triangles' corners (3 a triangle), each node's first
    child (−1: a leaf), the node after its subtree (−1: the mesh's last), its triangles
    ``order[first:end]``, the triangles in leaf order, each mesh's root node, whether it is
    closed (1) (:class:`TriangleMesh`), its grid's cells along x, y and z and its first cell,
    and the cells' CSR (``ptr``, one more than the cells, and the listed positions in ``order``).
    ``starts`` says where each part starts in its array (:data:`VERTS` …); meshes, triangles,
    vertices, nodes and cells are numbered across the bank."""
    vs, ts, los, his, ls, rs, fs, es, os_, roots = [], [], [], [], [], [], [], [], [], []
    fns, vns, ens, closed = [], [], [], []
    gorg, gcell, gdim, gstart, cptrs, clists, gband = [], [], [], [], [], [], []
    rows, feature = [], []
    nv = nt = nn = nc = nl = nf = 0
    for m in meshes:
        gorg.append(m.grid_origin)
        gcell.append(m.grid_cell)
        gband.append(m.grid_band)
        rows.append(m.cell_features)
        feature.append(np.where(m.cell_feature >= 0, m.cell_feature + nf, -1))
        nf += len(m.cell_features)
        gdim.append(m.grid_dims)
        gstart.append(nc)
        cptrs.append(m.cell_ptr[:-1] + nl)
        clists.append(m.cell_list + nt)
        nc, nl = nc + len(m.cell_ptr) - 1, nl + len(m.cell_list)
        vs.append(m.vertices)
        ts.append(m.triangles + nv)
        los.append(m.lo)
        his.append(m.hi)
        ls.append(np.where(m.left >= 0, m.left + nn, -1))
        rs.append(np.where(m.right >= 0, m.right + nn, -1))
        fs.append(m.first + nt)
        es.append(m.end + nt)
        os_.append(m.order + nt)
        roots.append(nn)
        fns.append(m.face_normals)
        vns.append(m.vertex_normals)
        ens.append(m.edge_normals)
        closed.append(1 if m.closed else 0)
        nv, nt, nn = nv + len(m.vertices), nt + len(m.triangles), nn + len(m.left)
    reals = [
        ("verts", vs),
        ("vnormals", vns),
        ("fnormals", fns),
        ("enormals", ens),
        ("box_lo", los),
        ("box_hi", his),
        ("origin", gorg),
        ("per_cell", [np.atleast_1d(1.0 / c) for c in gcell]),
        ("band", [np.atleast_1d(b) for b in gband]),
        ("features", rows),
    ]
    ints = [
        ("tris", ts),
        ("left", ls),
        ("right", rs),
        ("first", fs),
        ("end", es),
        ("order", os_),
        ("root", [np.atleast_1d(r) for r in roots]),
        ("closed", [np.atleast_1d(c) for c in closed]),
        ("dims", gdim),
        ("start", [np.atleast_1d(s) for s in gstart]),
        ("ptr", [*cptrs, np.array([nl])]),
        ("listed", clists),
        ("feature", feature),
    ]
    at = {}

    def flat(parts, dtype):
        out, n = [], 0
        for name, arrays in parts:
            at[name] = n
            for a in arrays:
                out.append(np.asarray(a, dtype=dtype).ravel())
                n += out[-1].size
        return np.ascontiguousarray(np.concatenate(out) if out else np.zeros(0), dtype=dtype)

    r, i = flat(reals, np.float64), flat(ints, np.int64)
    starts = np.array([at[name] for name, _ in reals + ints], np.int64)
    return (r, i, starts)


#: the bank of no mesh
EMPTY = pack([])


def box_triangles(half_extents) -> tuple[np.ndarray, np.ndarray]:
    """A box centred at the origin, ``half_extents`` along x, y and z, as 8 corners and 12
    outward triangles, ``(vertices (8, 3), triangles (12, 3))``: a
    :class:`~cloth_sim.contact.colliders.Mesh` source, the Box primitive as a mesh."""
    hx, hy, hz = (float(h) for h in half_extents)
    v = np.array(
        [[sx * hx, sy * hy, sz * hz] for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)]
    )
    f = [
        [0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
        [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5],
    ]  # fmt: skip
    return v, np.array(f, np.int64)


@numba.njit(cache=True, inline="always")
def _bank_triangle_d2(bank, k, x, y, z):
    """The nearest point of the bank's triangle ``k`` (:func:`.geometry.corners_d2`)."""
    r, t = bank[REALS], bank[INTS]
    a = bank[STARTS][VERTS] + 3 * t[bank[STARTS][TRIS] + 3 * k]
    b = bank[STARTS][VERTS] + 3 * t[bank[STARTS][TRIS] + 3 * k + 1]
    c = bank[STARTS][VERTS] + 3 * t[bank[STARTS][TRIS] + 3 * k + 2]
    return corners_d2(
        x, y, z, r[a], r[a + 1], r[a + 2], r[b], r[b + 1], r[b + 2], r[c], r[c + 1], r[c + 2]
    )


@numba.njit(cache=True, inline="always")
def _box_distance2(bank, node, x, y, z):
    """The squared distance from ``(x, y, z)`` to node ``node``'s box (0 inside it)."""
    r, lo, hi = bank[REALS], bank[STARTS][BOX_LO] + 3 * node, bank[STARTS][BOX_HI] + 3 * node
    dx = max(r[lo] - x, 0.0, x - r[hi])
    dy = max(r[lo + 1] - y, 0.0, y - r[hi + 1])
    dz = max(r[lo + 2] - z, 0.0, z - r[hi + 2])
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True, fastmath=False)  # (said: numba gives a callee its first caller's)
def _nearest(bank, m, x, y, z, cutoff):
    """The nearest point of mesh ``m`` to ``(x, y, z)`` within ``cutoff``: its squared distance,
    the point, its triangle (−1: none that near) and its barycentric weights there."""
    t = bank[INTS]
    best = cutoff * cutoff
    px = py = pz = 0.0
    btri = -1
    ba = bb = bc = 0.0
    # preorder: a node's first child is the next one, RIGHT the one after its subtree
    node = t[bank[STARTS][ROOT] + m]
    while node >= 0:
        if _box_distance2(bank, node, x, y, z) >= best:
            node = t[bank[STARTS][RIGHT] + node]
            continue
        if t[bank[STARTS][LEFT] + node] < 0:
            for q in range(t[bank[STARTS][FIRST] + node], t[bank[STARTS][END] + node]):
                k = t[bank[STARTS][ORDER] + q]
                d2, cx, cy, cz, wa, wb, wc = _bank_triangle_d2(bank, k, x, y, z)
                if d2 < best:
                    best, px, py, pz, btri = d2, cx, cy, cz, k
                    ba, bb, bc = wa, wb, wc
            node = t[bank[STARTS][RIGHT] + node]
            continue
        node = t[bank[STARTS][LEFT] + node]
    return best, px, py, pz, btri, ba, bb, bc


@numba.njit(cache=True, inline="always")
def _feature_of(r, t, starts, m, x, y, z):
    """The candidate grid's cell (its index in the bank) that holds ``(x, y, z)``, −1 if none,
    and the row of the feature that answers there, −1 if none."""
    per = r[starts[PER_CELL] + m]
    o, d = starts[ORIGIN] + 3 * m, starts[DIMS] + 3 * m
    fx, fy, fz = (x - r[o]) * per, (y - r[o + 1]) * per, (z - r[o + 2]) * per
    if not (fx >= 0.0 and fy >= 0.0 and fz >= 0.0):  # (NaN too)
        return -1, -1
    ix, iy, iz = int(fx), int(fy), int(fz)  # (floors: not negative)
    if not (ix < t[d] and iy < t[d + 1] and iz < t[d + 2]):
        return -1, -1
    cid = t[starts[START] + m] + (ix * t[d + 1] + iy) * t[d + 2] + iz
    f = t[starts[FEATURE] + cid]
    return cid, f


@numba.njit(cache=True, inline="always")
def _pseudonormal(bank, k, wa, wb, wc):
    """The pseudonormal of the feature of triangle ``k`` that the weights ``(wa, wb, wc)`` of
    its nearest point name: a corner (a weight of 1), an edge (a weight of 0) or the face."""
    r, t = bank[REALS], bank[INTS]
    corner = -1
    if wa == 1.0:
        corner = 0
    elif wb == 1.0:
        corner = 1
    elif wc == 1.0:
        corner = 2
    if corner >= 0:
        v = bank[STARTS][VNORMALS] + 3 * t[bank[STARTS][TRIS] + 3 * k + corner]
        return r[v], r[v + 1], r[v + 2]
    edge = -1
    if wc == 0.0:
        edge = 0
    elif wa == 0.0:
        edge = 1
    elif wb == 0.0:
        edge = 2
    if edge >= 0:
        e = bank[STARTS][ENORMALS] + 9 * k + 3 * edge
        return r[e], r[e + 1], r[e + 2]
    f = bank[STARTS][FNORMALS] + 3 * k
    return r[f], r[f + 1], r[f + 2]


@numba.njit(cache=True, fastmath=False)  # (said: numba gives a callee its first caller's)
def _inside_box(bank, m, x, y, z):
    """Whether ``(x, y, z)`` lies inside mesh ``m``'s root box."""
    r, root = bank[REALS], bank[INTS][bank[STARTS][ROOT] + m]
    lo, hi = bank[STARTS][BOX_LO] + 3 * root, bank[STARTS][BOX_HI] + 3 * root
    return r[lo] <= x <= r[hi] and r[lo + 1] <= y <= r[hi + 1] and r[lo + 2] <= z <= r[hi + 2]


@numba.njit(cache=True, inline="always")
def mesh_closed(bank, m):
    """Whether mesh ``m`` of the bank is closed: a solid, its distance signed (module
    docstring)."""
    return bank[INTS][bank[STARTS][CLOSED] + m] != 0


@numba.njit(cache=True, inline="always")
def mesh_distance(reals, ints, starts, m, x, y, z, cutoff=np.inf):
    """Distance of the point ``(x, y, z)`` (in the mesh's frame) from mesh ``m`` of the bank,
    signed (negative inside) where the mesh is closed and unsigned where it is open (module
    docstring), and the distance's gradient: the unit direction from the surface to the point,
    outwards from a closed mesh's inside. With a ``cutoff``, a point at least that far from the
    surface (and outside) is answered ``(cutoff, 0, 0, 0)`` without the walk below boxes farther
    than it; a point inside a closed mesh is answered whatever its depth.

    Inlined where it is called, so that a cell with a feature answers without a call."""
    cid, f = _feature_of(reals, ints, starts, m, x, y, z)
    if cid >= 0:
        if f >= 0:  # one feature answers over the cell
            r, p = reals, starts[FEATURES] + FEATURE_WIDTH * f
            if r[p] == PLANE_FEATURE:
                d = r[p + 1] * x + r[p + 2] * y + r[p + 3] * z + r[p + 4]
                if d >= cutoff:
                    return cutoff, 0.0, 0.0, 0.0
                return d, r[p + 1], r[p + 2], r[p + 3]
            if r[p] == CREASE_FEATURE:
                d, nx, ny, nz = crease_distance(r[p : p + FEATURE_WIDTH], x, y, z)
                if d >= cutoff:
                    return cutoff, 0.0, 0.0, 0.0
                return d, nx, ny, nz
            # an edge: the distance from the segment, the edge's sign
            px, py, pz = x - r[p + 1], y - r[p + 2], z - r[p + 3]
            s = (px * r[p + 4] + py * r[p + 5] + pz * r[p + 6]) * r[p + 7]
            s = min(1.0, max(0.0, s))
            px, py, pz = px - s * r[p + 4], py - s * r[p + 5], pz - s * r[p + 6]
            d = math.sqrt(px * px + py * py + pz * pz)
            if d > 1e-12:
                sign = r[p + 8]
                if sign > 0.0 and d >= cutoff:
                    return cutoff, 0.0, 0.0, 0.0
                return sign * d, sign * px / d, sign * py / d, sign * pz / d
    return _listed_distance((reals, ints, starts), m, x, y, z, cutoff, cid)


@numba.njit(cache=True, fastmath=False)  # (said: numba gives a callee its first caller's)
def _listed_distance(bank, m, x, y, z, cutoff, cid):
    """:func:`mesh_distance` from the nearest point: from the candidate grid's cell ``cid`` that
    holds ``(x, y, z)`` (−1: none) where that is the answer, the nearest listed triangle lying
    within the band or the cutoff within it (every triangle the cell does not list lies beyond
    the band); the cell lists every triangle within the band in the walk's order and the
    arithmetic is the walk's, so its nearest point is the walk's to the bit. Elsewhere (outside
    the grid, nothing listed that near) the walk's."""
    t = bank[INTS]
    closed = mesh_closed(bank, m)
    found = False
    if cid >= 0:
        band = bank[REALS][bank[STARTS][BAND] + m]
        best = cutoff * cutoff
        px = py = pz = 0.0
        btri = -1
        wa = wb = wc = 0.0
        for j in range(t[bank[STARTS][PTR] + cid], t[bank[STARTS][PTR] + cid + 1]):
            k = t[bank[STARTS][ORDER] + t[bank[STARTS][LISTED] + j]]
            d2, cx, cy, cz, ka, kb, kc = _bank_triangle_d2(bank, k, x, y, z)
            if d2 < best:
                best, px, py, pz, btri = d2, cx, cy, cz, k
                wa, wb, wc = ka, kb, kc
        found = cutoff <= band or (btri >= 0 and best < band * band)
    if not found:
        best, px, py, pz, btri, wa, wb, wc = _nearest(bank, m, x, y, z, cutoff)
    if btri < 0:
        if not (closed and _inside_box(bank, m, x, y, z)):
            return cutoff, 0.0, 0.0, 0.0
        best, px, py, pz, btri, wa, wb, wc = _nearest(bank, m, x, y, z, np.inf)
    d = math.sqrt(best)
    sign = 1.0
    if closed:
        nx, ny, nz = _pseudonormal(bank, btri, wa, wb, wc)
        if (x - px) * nx + (y - py) * ny + (z - pz) * nz < 0.0:
            sign = -1.0
        elif btri >= 0 and cutoff < math.inf and d >= cutoff:
            return cutoff, 0.0, 0.0, 0.0  # outside, found by the second walk: beyond the cutoff
    if d > 1e-12:
        return sign * d, sign * (x - px) / d, sign * (y - py) / d, sign * (z - pz) / d
    # on the surface: the face's normal (outwards where the mesh is closed)
    f = bank[STARTS][FNORMALS] + 3 * btri
    return 0.0, bank[REALS][f], bank[REALS][f + 1], bank[REALS][f + 2]


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
