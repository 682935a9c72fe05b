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
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .collision_tree import build_hierarchy
from .geometry import closest_on_triangle

#: triangles a leaf holds at most
LEAF = 4


class TriangleMesh:
    """A rigid triangle mesh in its own frame: ``vertices (n, 3)`` metres, ``triangles (t, 3)``,
    and its hierarchy (``left``, ``right``, ``first``, ``end``, ``order``, the nodes' boxes ``lo``,
    ``hi``)."""

    def __init__(self, vertices, triangles, name: str):
        v = np.ascontiguousarray(vertices, dtype=np.float64)
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


def pack(meshes) -> tuple:
    """The bank the kernels read: ``(vertices, triangles, lo, hi, left, right, first, end, order,
    root, face normals, vertex normals, edge normals, closed)`` with every mesh's arrays one after
    the other (its nodes, triangles and vertices renumbered), ``root[m]`` mesh ``m``'s root node;
    ``left`` a node's first child (−1: a leaf), ``right`` the node after its subtree (−1: the
    mesh's last); ``closed[m]`` 1 where mesh ``m`` is a solid (:class:`TriangleMesh`). An empty
    list gives empty arrays of the same types."""
    vs, ts, los, his, ls, rs, fs, es, os_, roots = [], [], [], [], [], [], [], [], [], []
    fns, vns, ens, closed = [], [], [], []
    nv = nt = nn = 0
    for m in meshes:
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

    def cat(parts, shape, dtype):
        if not parts:
            return np.zeros(shape, dtype)
        return np.ascontiguousarray(np.concatenate(parts).astype(dtype))

    return (
        cat(vs, (0, 3), np.float64),
        cat(ts, (0, 3), np.int64),
        cat(los, (0, 3), np.float64),
        cat(his, (0, 3), np.float64),
        cat(ls, (0,), np.int64),
        cat(rs, (0,), np.int64),
        cat(fs, (0,), np.int64),
        cat(es, (0,), np.int64),
        cat(os_, (0,), np.int64),
        np.array(roots, dtype=np.int64),
        cat(fns, (0, 3), np.float64),
        cat(vns, (0, 3), np.float64),
        cat(ens, (0, 3, 3), np.float64),
        np.array(closed, dtype=np.int64),
    )


#: the bank of no mesh
EMPTY = pack([])


@numba.njit(cache=True, inline="always")
def _box_distance2(lo, hi, node, x, y, z):
    dx = max(lo[node, 0] - x, 0.0, x - hi[node, 0])
    dy = max(lo[node, 1] - y, 0.0, y - hi[node, 1])
    dz = max(lo[node, 2] - z, 0.0, z - hi[node, 2])
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True)
def _nearest(bank, m, x, y, z, cutoff):
    """The nearest point of mesh ``m`` to ``(x, y, z)`` within ``cutoff``: its squared distance,
    the point, its triangle (−1: none that near) and its barycentric weights there."""
    v, t, lo, hi, left, right, first, end, order, root = bank[:10]
    best = cutoff * cutoff
    px = py = pz = 0.0
    btri = -1
    ba = bb = bc = 0.0
    node = root[m]  # preorder: a node's first child is the next one, right[node] the one after
    while node >= 0:
        if _box_distance2(lo, hi, node, x, y, z) >= best:
            node = right[node]
            continue
        if left[node] < 0:
            for q in range(first[node], end[node]):
                k = order[q]
                a, b, c = t[k, 0], t[k, 1], t[k, 2]
                wa, wb, wc = closest_on_triangle(
                    x, y, z, v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1], v[b, 2],
                    v[c, 0], v[c, 1], v[c, 2],
                )  # fmt: skip
                cx = wa * v[a, 0] + wb * v[b, 0] + wc * v[c, 0]
                cy = wa * v[a, 1] + wb * v[b, 1] + wc * v[c, 1]
                cz = wa * v[a, 2] + wb * v[b, 2] + wc * v[c, 2]
                d2 = (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2
                if d2 < best:
                    best, px, py, pz, btri = d2, cx, cy, cz, k
                    ba, bb, bc = wa, wb, wc
            node = right[node]
            continue
        node = left[node]
    return best, px, py, pz, btri, ba, bb, bc


@numba.njit(cache=True, inline="always")
def _pseudonormal(bank, k, wa, wb, wc):
    """The pseudonormal of the feature of triangle ``k`` that the weights ``(wa, wb, wc)`` of
    its nearest point name: a corner (a weight of 1), an edge (a weight of 0) or the face."""
    t, fn, vn, en = bank[1], bank[10], bank[11], bank[12]
    if wa == 1.0:
        return vn[t[k, 0], 0], vn[t[k, 0], 1], vn[t[k, 0], 2]
    if wb == 1.0:
        return vn[t[k, 1], 0], vn[t[k, 1], 1], vn[t[k, 1], 2]
    if wc == 1.0:
        return vn[t[k, 2], 0], vn[t[k, 2], 1], vn[t[k, 2], 2]
    if wc == 0.0:
        return en[k, 0, 0], en[k, 0, 1], en[k, 0, 2]
    if wa == 0.0:
        return en[k, 1, 0], en[k, 1, 1], en[k, 1, 2]
    if wb == 0.0:
        return en[k, 2, 0], en[k, 2, 1], en[k, 2, 2]
    return fn[k, 0], fn[k, 1], fn[k, 2]


@numba.njit(cache=True)
def _inside_box(bank, m, x, y, z):
    lo, hi, root = bank[2], bank[3], bank[9]
    r = root[m]
    return lo[r, 0] <= x <= hi[r, 0] and lo[r, 1] <= y <= hi[r, 1] and lo[r, 2] <= z <= hi[r, 2]


@numba.njit(cache=True)
def mesh_distance(bank, m, x, y, z, cutoff=np.inf):
    """Distance of the point ``(x, y, z)`` (in the mesh's frame) from mesh ``m`` of the bank,
    signed (negative inside) where the mesh is closed and unsigned where it is open (module
    docstring), and the distance's gradient: the unit direction from the surface to the point,
    outwards from a closed mesh's inside. With a ``cutoff``, a point at least that far from the
    surface (and outside) is answered ``(cutoff, 0, 0, 0)`` without the walk below boxes farther
    than it; a point inside a closed mesh is answered whatever its depth."""
    closed = bank[13][m] != 0
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
    fn = bank[10]
    return 0.0, fn[btri, 0], fn[btri, 1], fn[btri, 2]
