"""Triangle meshes as colliders' shapes: a mesh in its own frame with a bounding-volume hierarchy,
and the closest-point query the contact kernels call.

A mesh collider is two-sided: both sides of every triangle are surfaces, and its distance is the
unsigned distance to the nearest triangle (a closed link mesh is then a shell the cloth keeps off
from outside; an open mesh, a body's or a plate's, works the same). The kernels read all the meshes
of a simulation packed into one *bank* (:func:`pack`), each mesh addressed by its index there.

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

    @property
    def extent(self) -> float:
        """The largest distance of a vertex from the mesh's origin (its reach when it turns)."""
        return float(np.sqrt((self.vertices**2).sum(axis=1).max()))


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
    root)`` with every mesh's arrays one after the other (its nodes, triangles and vertices
    renumbered), ``root[m]`` mesh ``m``'s root node; ``left`` a node's first child (−1: a leaf),
    ``right`` the node after its subtree (−1: the mesh's last). An empty list gives empty arrays
    of the same types."""
    vs, ts, los, his, ls, rs, fs, es, os_, roots = [], [], [], [], [], [], [], [], [], []
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
def mesh_distance(bank, m, x, y, z, cutoff=np.inf):
    """Unsigned distance of the point ``(x, y, z)`` (in the mesh's frame) from mesh ``m`` of the
    bank and the unit direction from the surface to the point (the distance's gradient). With a
    ``cutoff``, a point at least that far is answered ``(cutoff, 0, 0, 0)`` without the walk
    below boxes farther than it."""
    v, t, lo, hi, left, right, first, end, order, root = bank
    r = root[m]
    best = cutoff * cutoff
    px = py = pz = 0.0
    btri = -1
    node = r  # preorder: a node's first child is the next one, right[node] the one after it
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
            node = right[node]
            continue
        node = left[node]
    if btri < 0:
        return cutoff, 0.0, 0.0, 0.0
    d = math.sqrt(best)
    if d > 1e-12:
        return d, (x - px) / d, (y - py) / d, (z - pz) / d
    # on the surface: the triangle's normal
    a, b, c = t[btri, 0], t[btri, 1], t[btri, 2]
    ux, uy, uz = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
    wx, wy, wz = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
    nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    return d, nx / nn, ny / nn, nz / nn
