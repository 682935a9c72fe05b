"""Self-collision's candidate pairs, from a bounding-volume hierarchy over the cloth's triangles.

Built once from the rest layout (a median split of the triangles' centres along the longest axis of
their box, down to one triangle a leaf; a particle in no triangle is a leaf of its own), refitted
every step and traversed against itself (the usual choice in cloth codes: Bridson, Fedkiw &
Anderson 2002; Tang et al. 2009 among many). Every primitive has a **reach**: each particle one of
its own (self-collision gives it half the thickness plus its motion over the step), a triangle or
an edge the largest of its corners'. A leaf's box is its triangle's box grown by that reach, so two
leaves' boxes overlap whenever their primitives lie within the sum of their reaches. For each
overlapping pair of leaves ``(T1, T2)`` the exact distances are measured:

* **particle–triangle**: each corner of ``T1`` whose first triangle is ``T1`` against ``T2`` (not a
  corner of ``T2``), and the other way round;
* **edge–edge**: each edge of ``T1`` whose first triangle is ``T1`` against each of ``T2``'s alike,
  sharing no particle.

A pair of primitives within reach is seen from exactly one pair of leaves (their first triangles),
so each is found once without a "seen" array. The traversal is split into fixed tasks (subtrees
against themselves and pairs of subtrees, :func:`_tasks`), run on every core; each task writes its
pairs to its own rows and the tasks are joined in order, so the result is the same at any thread
count.

Why a tree and not the spatial hash this replaced: with a reach per primitive (the fast-moving
bottom of a swinging cloth no longer widens every particle's search) the hash still visited every
entry of about four cells per edge — about 90 entries an edge, 1.1 million a step at 64×64, for 800
pairs — while the refitted tree tests a few overlapping boxes per triangle (figures in
docs/BENCHMARKS.md §3c).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from ..kernel_cache import keep_true
from .geometry import closest_on_segments, point_triangle_distance, read_only

#: the traversal's tasks each hold at most 1/TASKS of the items against themselves or of all pairs
#: of items between two subtrees (:func:`_tasks`: ~200 tasks at 64×64, fewer on a small cloth)
TASKS = 64

#: rows a task has at least for each kind of pair. Rows kept large cost little (a task writes only
#: the rows it fills, and the rows are kept from search to search), while a search run again for
#: want of them costs a walk: so a task's rows only shrink when they are more than KEEP_ROWS and
#: more than SHRINK_ABOVE times what its last search found (plus a quarter), to SHRINK_TO times
#: that (shrinking robot_sweep's few hundred rows a task ran 4 % of its searches twice)
MIN_ROWS, KEEP_ROWS, SHRINK_ABOVE, SHRINK_TO = 16, 4096, 16, 4

#: a search in which at most this share of the particles reach anything (the others' reaches 0)
#: walks only the leaves that hold those (:meth:`TriangleTree.pairs`): on robot_sweep's sheet the
#: guard after the contact stage, ~3 % of the particles pushed, 0.75 → 0.13 ms a search
REACHING_WALK_SHARE = 0.5

#: items (triangles, lone particles) a leaf holds at most (the fastest search measured:
#: docs/BENCHMARKS.md §7)
LEAF = 8


class Hierarchy(NamedTuple):
    """The tree (:func:`build_hierarchy`): per node its children (−1 for a leaf), its items
    ``order[first:end]``, how many, and its box ``lo``/``hi``; per item row ``q`` (item
    ``order[q]``) its box ``ilo``/``ihi``. The boxes are refitted every search. ``mark`` (per
    node) and ``imark`` (per item row): a walk measures only pairs with a marked side (all
    marked for :meth:`TriangleTree.pairs`; the items with a touched particle and the nodes
    above them for :meth:`TriangleTree.pairs_touching`)."""

    left: np.ndarray
    right: np.ndarray
    first: np.ndarray
    end: np.ndarray
    size: np.ndarray
    order: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    ilo: np.ndarray
    ihi: np.ndarray
    mark: np.ndarray
    imark: np.ndarray


class Primitives(NamedTuple):
    """What a search measures: the start positions ``x0`` and each particle's ``reach``; the
    triangles (and their reaches), the particles in none (``orphans``) and the edges (their
    boxes and reaches at ``x0``); per triangle the corners (``own_v``) and edges (``own_e``) it
    is the first triangle of, −1 after them; per particle whether it is ``touched`` (a walk
    measures only the pairs with a feature of a touched particle: all of them in a whole
    search)."""

    x0: np.ndarray
    reach: np.ndarray
    tris: np.ndarray
    tri_reach: np.ndarray
    orphans: np.ndarray
    edges: np.ndarray
    own_v: np.ndarray
    own_e: np.ndarray
    elo: np.ndarray
    ehi: np.ndarray
    ereach: np.ndarray
    touched: np.ndarray


class TaskRows(NamedTuple):
    """Where the traversal's tasks write: task ``k``'s particle–triangle pairs (and distances)
    from row ``k·cap_vf`` of ``vf``, its edge pairs from row ``k·cap_ee`` of ``ee``, and
    ``counts[k]``, how many of each it found."""

    vf: np.ndarray
    vf_d: np.ndarray
    ee: np.ndarray
    ee_d: np.ndarray
    counts: np.ndarray
    cap_vf: int
    cap_ee: int


@numba.njit(cache=True)
def build_hierarchy(centres, leaf):
    """The tree over ``m`` item centres, at most ``leaf`` items a leaf: ``(left, right, first, end,
    size, order)``, per node its children (−1 for a leaf), its items ``order[first:end]`` and how
    many; the root is 0 and every child is numbered after its parent."""
    m = centres.shape[0]
    cap = 2 * m
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    first = np.zeros(cap, np.int64)
    end = np.zeros(cap, np.int64)
    order = np.arange(m)
    stack = np.empty((cap, 3), np.int64)  # node, first and end in ``order``
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, 0, m
    top = 0
    n_nodes = 1
    keys = np.empty(m)
    while top >= 0:
        node, s, e = stack[top, 0], stack[top, 1], stack[top, 2]
        top -= 1
        first[node], end[node] = s, e
        if e - s <= leaf:
            continue
        axis, extent = 0, -1.0
        for k in range(3):
            lo, hi = np.inf, -np.inf
            for q in range(s, e):
                lo = min(lo, centres[order[q], k])
                hi = max(hi, centres[order[q], k])
            if hi - lo > extent:
                axis, extent = k, hi - lo
        for q in range(s, e):
            keys[q] = centres[order[q], axis]
        idx = np.argsort(keys[s:e], kind="mergesort")  # stable: ties keep their order
        order[s:e] = order[s:e][idx]
        mid = (s + e) // 2
        lt, rt = n_nodes, n_nodes + 1
        n_nodes += 2
        left[node], right[node] = lt, rt
        top += 1
        stack[top, 0], stack[top, 1], stack[top, 2] = rt, mid, e
        top += 1
        stack[top, 0], stack[top, 1], stack[top, 2] = lt, s, mid
    return (
        left[:n_nodes].copy(),
        right[:n_nodes].copy(),
        first[:n_nodes].copy(),
        end[:n_nodes].copy(),
        (end - first)[:n_nodes].copy(),
        order,
    )


def _tasks(left, right, size, least: int) -> np.ndarray:
    """The traversal split into independent tasks, ``(a, b)`` rows: ``(a, a)`` the subtree ``a``
    against itself, ``(a, b)`` subtree ``a`` against ``b``. A subtree is split into its two halves
    and their pair while it holds more than ``1/least`` of the items (a spread-out cloth's pairs
    are mostly inside small subtrees), and a pair by opening its larger side while it could hold
    more than ``1/least`` of all pairs of items (a crumpled cloth's, where most boxes overlap, are
    mostly between subtrees); the tasks are listed depth first, so that equal runs of the list
    cover equal parts of the cloth and every core gets a like share either way."""
    budget = max(1, int(size[0]) * int(size[0]) // (2 * least))
    tasks = []

    def visit(a, b):
        if a == b:
            if left[a] < 0 or int(size[a]) * least <= int(size[0]):
                tasks.append((a, a))
                return
            lt, rt = int(left[a]), int(right[a])
            visit(lt, lt)
            visit(rt, rt)
            visit(lt, rt)
            return
        if int(size[a]) * int(size[b]) <= budget or (left[a] < 0 and left[b] < 0):
            tasks.append((a, b))
            return
        if left[a] >= 0 and (left[b] < 0 or size[a] >= size[b]):
            visit(int(left[a]), b)
            visit(int(right[a]), b)
        else:
            visit(a, int(left[b]))
            visit(a, int(right[b]))

    visit(0, 0)
    return np.array(tasks, np.int64).reshape(-1, 2)


@numba.njit(cache=True)
def _refit(prim, tree):
    """Each triangle's reach; each item's box (``ilo``/``ihi`` in leaf order: row ``q`` is item
    ``order[q]``), its primitive's box at the start grown by its reach; and every node's box, the
    union of its items' (children first)."""
    x0, reach, tris, orphans, tri_reach = (
        prim.x0,
        prim.reach,
        prim.tris,
        prim.orphans,
        prim.tri_reach,
    )
    left, right, first, end, order = tree.left, tree.right, tree.first, tree.end, tree.order
    lo, hi, ilo, ihi = tree.lo, tree.hi, tree.ilo, tree.ihi
    n_tris = tris.shape[0]
    for t in range(n_tris):
        tri_reach[t] = max(reach[tris[t, 0]], reach[tris[t, 1]], reach[tris[t, 2]])
    for q in range(order.shape[0]):
        k = order[q]
        if k < n_tris:
            a, b, c = tris[k, 0], tris[k, 1], tris[k, 2]
            r = tri_reach[k]
            for d in range(3):
                ilo[q, d] = min(x0[a, d], x0[b, d], x0[c, d]) - r
                ihi[q, d] = max(x0[a, d], x0[b, d], x0[c, d]) + r
        else:
            p = orphans[k - n_tris]
            for d in range(3):
                ilo[q, d] = x0[p, d] - reach[p]
                ihi[q, d] = x0[p, d] + reach[p]
    for node in range(left.shape[0] - 1, -1, -1):
        if left[node] < 0:
            for d in range(3):
                lo[node, d], hi[node, d] = np.inf, -np.inf
            for q in range(first[node], end[node]):
                for d in range(3):
                    lo[node, d] = min(lo[node, d], ilo[q, d])
                    hi[node, d] = max(hi[node, d], ihi[q, d])
        else:
            lt, rt = left[node], right[node]
            for d in range(3):
                lo[node, d] = min(lo[lt, d], lo[rt, d])
                hi[node, d] = max(hi[lt, d], hi[rt, d])


@numba.njit(cache=True)
def _edge_boxes(prim):
    """Each edge's box at ``x0`` and its reach (the larger of its ends'): what the edge–edge test
    reads for every pair of overlapping items, made once a search."""
    x0, reach, edges, elo, ehi, ereach = (
        prim.x0,
        prim.reach,
        prim.edges,
        prim.elo,
        prim.ehi,
        prim.ereach,
    )
    for e in range(edges.shape[0]):
        e0, e1 = edges[e, 0], edges[e, 1]
        for d in range(3):
            elo[e, d] = min(x0[e0, d], x0[e1, d])
            ehi[e, d] = max(x0[e0, d], x0[e1, d])
        ereach[e] = max(reach[e0], reach[e1])


@numba.njit(cache=True, inline="always")
def _apart(lo_a, hi_a, a, lo_b, hi_b, b):
    """Whether box ``a`` of ``(lo_a, hi_a)`` misses box ``b`` of ``(lo_b, hi_b)``."""
    return (
        lo_a[a, 0] > hi_b[b, 0]
        or lo_b[b, 0] > hi_a[a, 0]
        or lo_a[a, 1] > hi_b[b, 1]
        or lo_b[b, 1] > hi_a[a, 1]
        or lo_a[a, 2] > hi_b[b, 2]
        or lo_b[b, 2] > hi_a[a, 2]
    )


@numba.njit(cache=True, inline="always")
def _put(pairs, dist, row, m, cap, i, j, d):
    """Pair ``(i, j)`` at distance ``d`` as its task's ``m``-th (at ``row + m``) if the task has
    room; returns the task's count, ``m + 1``, either way (:meth:`TriangleTree.pairs` runs again
    with more rows when a count exceeds ``cap``)."""
    if m < cap:
        pairs[row + m, 0] = i
        pairs[row + m, 1] = j
        dist[row + m] = d
    return m + 1


@numba.njit(cache=True, inline="always")
def _point_triangle(x0, reach, tri_reach, tris, ilo, ihi, p, t, qt):
    """Particle ``p`` against triangle ``t`` (item row ``qt``): their distance where they lie
    within their reaches, else −1."""
    if p == tris[t, 0] or p == tris[t, 1] or p == tris[t, 2]:
        return -1.0
    r = reach[p]
    if (
        x0[p, 0] < ilo[qt, 0] - r
        or x0[p, 0] > ihi[qt, 0] + r
        or x0[p, 1] < ilo[qt, 1] - r
        or x0[p, 1] > ihi[qt, 1] + r
        or x0[p, 2] < ilo[qt, 2] - r
        or x0[p, 2] > ihi[qt, 2] + r
    ):
        return -1.0
    d = point_triangle_distance(x0, p, tris[t, 0], tris[t, 1], tris[t, 2])[0]
    if d >= r + tri_reach[t]:
        return -1.0
    return d


@numba.njit(cache=True, parallel=True)
def _traverse(tasks, tree, prim, rows, stack_size, leaf_cap):
    """Every task (:func:`_tasks`) walks its pairs of overlapping nodes depth first, and measures
    the primitives of each overlapping pair of items in two overlapping leaves (module docstring);
    its particle–triangle pairs go to rows ``task·cap_vf`` on of ``rows.vf``, its edge pairs to
    ``task·cap_ee`` on of ``rows.ee``, and ``rows.counts[task]`` says how many (possibly more than
    the rows: then run again). Of two different leaves, only the items whose boxes reach the
    other leaf's box are paired (the rest can overlap none of its items), in the same order.

    The bundles' fields are taken out before the parallel loop and the loop's body reads and
    writes only those: a write through a bundle's field in a parallel loop's body is lost (numba
    issues 7135 and 10338), and arrays that are the loop's own arguments are known not to alias,
    which the walk's loads need (the same walk in a function of its own was 1.7× slower)."""
    left, right, first, end, size = tree.left, tree.right, tree.first, tree.end, tree.size
    lo, hi, ilo, ihi, order = tree.lo, tree.hi, tree.ilo, tree.ihi, tree.order
    mark, imark = tree.mark, tree.imark
    x0, reach, tri_reach, tris, orphans = (
        prim.x0,
        prim.reach,
        prim.tri_reach,
        prim.tris,
        prim.orphans,
    )
    edges, own_v, own_e, elo, ehi, ereach, touched = (
        prim.edges,
        prim.own_v,
        prim.own_e,
        prim.elo,
        prim.ehi,
        prim.ereach,
        prim.touched,
    )
    vf, vf_d, ee, ee_d, counts = rows.vf, rows.vf_d, rows.ee, rows.ee_d, rows.counts
    cap_vf, cap_ee = rows.cap_vf, rows.cap_ee
    n_tris = tris.shape[0]
    for k in numba.prange(tasks.shape[0]):
        row_vf, row_ee = k * cap_vf, k * cap_ee
        stack = np.empty((stack_size, 2), np.int64)
        near_a = np.empty(leaf_cap, np.int64)
        near_b = np.empty(leaf_cap, np.int64)
        stack[0, 0], stack[0, 1] = tasks[k, 0], tasks[k, 1]
        top = 0
        m_vf = m_ee = 0
        while top >= 0:
            a, b = stack[top, 0], stack[top, 1]
            top -= 1
            if mark[a] == 0 and mark[b] == 0:
                continue  # neither side holds a marked item
            if a == b:  # a subtree against itself: each child against itself, and the two
                if left[a] >= 0:
                    stack[top + 1, 0], stack[top + 1, 1] = left[a], right[a]
                    stack[top + 2, 0], stack[top + 2, 1] = right[a], right[a]
                    stack[top + 3, 0], stack[top + 3, 1] = left[a], left[a]
                    top += 3
                    continue
            elif _apart(lo, hi, a, lo, hi, b):
                continue
            elif left[a] >= 0 and (left[b] < 0 or size[a] >= size[b]):  # open the larger
                stack[top + 1, 0], stack[top + 1, 1] = right[a], b
                stack[top + 2, 0], stack[top + 2, 1] = left[a], b
                top += 2
                continue
            elif left[b] >= 0:
                stack[top + 1, 0], stack[top + 1, 1] = a, right[b]
                stack[top + 2, 0], stack[top + 2, 1] = a, left[b]
                top += 2
                continue
            if a == b:  # a leaf against itself: each pair of its items once
                n_a = 0
                for qs in range(first[a], end[a]):
                    near_a[n_a] = qs
                    near_b[n_a] = qs
                    n_a += 1
                n_b = n_a
            else:  # two leaves: the items reaching the other leaf's box
                n_a = 0
                for qs in range(first[a], end[a]):
                    if not _apart(ilo, ihi, qs, lo, hi, b):
                        near_a[n_a] = qs
                        n_a += 1
                n_b = 0
                for qt in range(first[b], end[b]):
                    if not _apart(ilo, ihi, qt, lo, hi, a):
                        near_b[n_b] = qt
                        n_b += 1
            for i in range(n_a):
                qs = near_a[i]
                for j in range(i + 1 if a == b else 0, n_b):
                    qt = near_b[j]
                    if (imark[qs] == 0 and imark[qt] == 0) or _apart(ilo, ihi, qs, ilo, ihi, qt):
                        continue
                    s, t = order[qs], order[qt]
                    # the corners first seen in one triangle against the other
                    for side in range(2):
                        u, v, qv = (s, t, qt) if side == 0 else (t, s, qs)
                        if v >= n_tris:
                            continue  # against a lone particle: nothing to measure
                        for c in range(3):
                            p = (
                                own_v[u, c]
                                if u < n_tris
                                else (orphans[u - n_tris] if c == 0 else -1)
                            )
                            if p < 0:
                                break
                            if touched[p] == 0 and imark[qv] == 0:
                                continue  # neither the particle nor a corner is touched
                            d = _point_triangle(x0, reach, tri_reach, tris, ilo, ihi, p, v, qv)
                            if d >= 0.0:
                                m_vf = _put(vf, vf_d, row_vf, m_vf, cap_vf, p, v, d)
                    if s >= n_tris or t >= n_tris:
                        continue  # a lone particle has no edges
                    for c1 in range(3):  # the edges first seen in one triangle against the other's
                        e = own_e[s, c1]
                        if e < 0:
                            break
                        e0, e1 = edges[e, 0], edges[e, 1]
                        r_e = ereach[e]
                        for c2 in range(3):
                            f = own_e[t, c2]
                            if f < 0:
                                break
                            r = r_e + ereach[f]
                            if (
                                elo[e, 0] - ehi[f, 0] >= r
                                or elo[f, 0] - ehi[e, 0] >= r
                                or elo[e, 1] - ehi[f, 1] >= r
                                or elo[f, 1] - ehi[e, 1] >= r
                                or elo[e, 2] - ehi[f, 2] >= r
                                or elo[f, 2] - ehi[e, 2] >= r
                            ):
                                continue  # farther apart than r along an axis
                            f0, f1 = edges[f, 0], edges[f, 1]
                            if f0 == e0 or f0 == e1 or f1 == e0 or f1 == e1:
                                continue
                            if (
                                touched[e0] == 0
                                and touched[e1] == 0
                                and touched[f0] == 0
                                and touched[f1] == 0
                            ):
                                continue  # no end touched
                            # listed and measured lower edge first: the same bits whichever
                            # triangle saw it (pair_list measures the kept pairs again)
                            e_a, e_b = (e, f) if e < f else (f, e)
                            d = closest_on_segments(
                                x0, edges[e_a, 0], edges[e_a, 1], edges[e_b, 0], edges[e_b, 1]
                            )[2]
                            if d >= r:
                                continue
                            m_ee = _put(ee, ee_d, row_ee, m_ee, cap_ee, e_a, e_b, d)
        counts[k, 0] = m_vf
        counts[k, 1] = m_ee


@numba.njit(cache=True)
def _join(counts, cap, pairs, dist):
    """Each task's rows (``counts[k]`` from row ``k·cap``), joined in task order: the cost is the
    pairs', not the rows'."""
    total = 0
    for k in range(counts.shape[0]):
        total += counts[k]
    out, out_d = np.empty((total, 2), np.int64), np.empty(total)
    m = 0
    for k in range(counts.shape[0]):
        for q in range(k * cap, k * cap + counts[k]):
            out[m, 0], out[m, 1], out_d[m] = pairs[q, 0], pairs[q, 1], dist[q]
            m += 1
    return out, out_d


def _owned(slots, owner_of) -> np.ndarray:
    """Per triangle, the (up to three) primitives of its ``slots`` it is the first triangle of, in
    slot order, −1 after them."""
    slots = np.asarray(slots, np.int64)
    mine = owner_of[slots] == np.arange(len(slots))[:, None]
    first = np.argsort(~mine, axis=1, kind="stable")  # its own primitives first, in slot order
    return np.where(
        np.take_along_axis(mine, first, axis=1), np.take_along_axis(slots, first, axis=1), -1
    )


@numba.njit(cache=True)
def _marks(tree, touched, tris, orphans):
    """``(mark, imark)`` (:class:`Hierarchy`) for the ``touched`` particles: per item row whether
    its triangle has a touched corner (its lone particle is touched); per node whether it holds
    such an item (leaves from their items, each other node from its children, numbered after
    it)."""
    left, right, first, end, order = tree.left, tree.right, tree.first, tree.end, tree.order
    n_tris = tris.shape[0]
    imark = np.zeros(order.shape[0], np.int8)
    for q in range(order.shape[0]):
        k = order[q]
        if k < n_tris:
            if touched[tris[k, 0]] or touched[tris[k, 1]] or touched[tris[k, 2]]:
                imark[q] = 1
        elif touched[orphans[k - n_tris]]:
            imark[q] = 1
    mark = np.zeros(left.shape[0], np.int8)
    for node in range(left.shape[0] - 1, -1, -1):
        if left[node] < 0:
            for q in range(first[node], end[node]):
                if imark[q]:
                    mark[node] = 1
                    break
        else:
            mark[node] = mark[left[node]] | mark[right[node]]
    return mark, imark


@numba.njit(cache=True, parallel=True)
def _touching(vf, ee, tris, edges, touched):
    """:func:`touching`'s two masks, each pair on its own."""
    keep_vf = np.empty(vf.shape[0], np.bool_)
    for q in numba.prange(vf.shape[0]):
        t = vf[q, 1]
        keep_vf[q] = (
            touched[vf[q, 0]] or touched[tris[t, 0]] or touched[tris[t, 1]] or touched[tris[t, 2]]
        )
    keep_ee = np.empty(ee.shape[0], np.bool_)
    for q in numba.prange(ee.shape[0]):
        e, f = ee[q, 0], ee[q, 1]
        keep_ee[q] = (
            touched[edges[e, 0]] or touched[edges[e, 1]] or touched[edges[f, 0]]
            or touched[edges[f, 1]]
        )  # fmt: skip
    return keep_vf, keep_ee


def touching(vf, ee, tris, edges, touched) -> tuple[np.ndarray, np.ndarray]:
    """Which of the particle–triangle pairs ``vf`` and the edge pairs ``ee`` have a feature with a
    ``touched`` particle (a boolean per particle): the particle or a corner of the triangle, an end
    of either edge."""
    return _touching(
        np.ascontiguousarray(vf, np.int64),
        np.ascontiguousarray(ee, np.int64),
        tris,
        edges,
        np.ascontiguousarray(touched, np.bool_),
    )


def _no_pairs() -> tuple:
    """:meth:`TriangleTree.pairs`' answer where there is nothing to pair."""
    return np.empty((0, 2), np.int64), np.empty(0), np.empty((0, 2), np.int64), np.empty(0)


def reaches(radius, n: int) -> np.ndarray:
    """Per-particle reaches from a search radius: a number ``R`` (every pair within ``R``) is half
    of it for each particle; an array of ``n`` is taken as it is."""
    if np.ndim(radius) == 0:
        return np.full(n, 0.5 * float(radius))
    reach = np.ascontiguousarray(radius, dtype=np.float64)
    if reach.shape != (n,):
        raise ValueError(
            f"radius: expected a number or one reach per particle ({n}), got shape {reach.shape}"
        )
    return reach


class TriangleTree:
    """The hierarchy over a cloth's triangles (and its particles in no triangle), built from
    ``rest`` positions; :meth:`pairs` refits it to any positions. ``features``: the topology
    self-collision keeps (``self_collision._features``)."""

    def __init__(self, tris, rest, features, leaf: int = LEAF):
        self.tris = read_only(tris, np.int64)
        rest = np.asarray(rest, dtype=np.float64)
        n = len(rest)
        self.edges, tri_edge, edge_owner, _, vertex_owner = features[:5]
        used = np.zeros(n, bool)
        used[self.tris.ravel()] = True
        self.orphans = np.flatnonzero(~used).astype(np.int64)
        centres = np.concatenate([rest[self.tris].mean(axis=1), rest[self.orphans]])
        self.empty = len(centres) == 0
        if self.empty:
            return
        left, right, first, end, size, order = build_hierarchy(
            np.ascontiguousarray(centres), int(leaf)
        )
        n_nodes, n_items, n_edges = len(left), len(order), len(self.edges)
        self.tree = Hierarchy(
            left, right, first, end, size, order,
            np.empty((n_nodes, 3)), np.empty((n_nodes, 3)),
            np.empty((n_items, 3)), np.empty((n_items, 3)),
            np.ones(n_nodes, np.int8), np.ones(n_items, np.int8),
        )  # fmt: skip
        # what a search measures but the positions and reaches it is given: the topology, the
        # corners and edges each triangle is the first of, and the triangles' and edges' reaches
        # and the edges' boxes, made again every search
        self.prim = Primitives(
            x0=None,
            reach=None,
            tris=self.tris,
            tri_reach=np.empty(len(self.tris)),
            orphans=self.orphans,
            edges=self.edges,
            own_v=_owned(self.tris, vertex_owner),
            own_e=_owned(tri_edge, edge_owner),
            elo=np.empty((n_edges, 3)),
            ehi=np.empty((n_edges, 3)),
            ereach=np.empty(n_edges),
            touched=np.ones(n, np.int8),
        )
        self.tasks = _tasks(left, right, size, TASKS)
        depth = np.zeros(n_nodes, np.int64)
        for node in range(n_nodes):  # children are numbered after their parent
            if left[node] >= 0:
                depth[left[node]] = depth[right[node]] = depth[node] + 1
        # depth first, a walk keeps at most two pending entries per level of a subtree against
        # itself and one per level of each side of a pair
        self.stack_size = int(6 * (depth.max() + 2) + 8)
        self.leaf_cap = int((end - first)[left < 0].max())
        #: rows per task for particle–triangle and edge pairs, grown as a search needs more and
        #: shrunk when far above what it needed
        self.caps = np.array([MIN_ROWS, MIN_ROWS], np.int64)
        self._rows = None  # the rows at those caps (_task_rows)

    def pairs(self, x0, radius):
        """``(vf, vf_distance, ee, ee_distance)``: every (particle, triangle) pair, the particle
        not a corner, and every pair of edges ``(e, f)``, ``e < f``, sharing no particle, whose
        start positions ``x0`` lie within ``radius`` — a number, or a reach per particle
        (:func:`reaches`; a pair is kept when its distance is below the sum of its two sides'
        reaches, a triangle's or an edge's the largest of its corners') — with those distances, in
        a fixed order, the same at any thread count.

        A pair is kept only within the sum of its sides' reaches, so every pair found has a
        feature with a particle whose reach is above 0: where those are few (at most
        :data:`REACHING_WALK_SHARE` of the particles), the walk is :meth:`pairs_touching`'s for
        them, the same answer."""
        x0 = read_only(x0, np.float64)
        if self.empty:
            return _no_pairs()
        reach = reaches(radius, len(x0))
        reaching = ~(reach <= 0.0)  # (a NaN reach: the whole walk)
        if np.count_nonzero(reaching) <= REACHING_WALK_SHARE * len(reach):
            return self.pairs_touching(x0, reach, reaching)
        return self._search(x0, reach, self.tree)

    def _search(self, x0, radius, tree, touched=None):
        """The walk over ``tree`` (the hierarchy, marked: :class:`Hierarchy`) at ``x0``; with
        ``touched``, only the pairs with a touched feature are measured."""
        reach = read_only(reaches(radius, len(x0)), np.float64)
        prim = self.prim._replace(x0=x0, reach=reach)
        if touched is not None:
            prim = prim._replace(touched=touched.astype(np.int8))
        _refit(prim, tree)
        _edge_boxes(prim)
        while True:
            rows = self._task_rows()
            _traverse(self.tasks, tree, prim, rows, self.stack_size, self.leaf_cap)
            most = rows.counts.max(axis=0)
            if most[0] <= rows.cap_vf and most[1] <= rows.cap_ee:
                break
            self.caps = np.maximum(self.caps, most + most // 4)
        if touched is None:
            # a cap far above what the search needed shrinks back (one crumpled moment would
            # otherwise size every later search's rows); a search of a few particles' pairs
            # says nothing of what the whole cloth's needs
            need = np.maximum(most + most // 4, MIN_ROWS)
            shrink = (self.caps > KEEP_ROWS) & (self.caps > SHRINK_ABOVE * need)
            self.caps = np.where(shrink, SHRINK_TO * need, self.caps)
        # each column copied: a view of one is contiguous only where there is one task, and
        # numba compiles a kernel again for each layout
        vf_counts, ee_counts = rows.counts[:, 0].copy(), rows.counts[:, 1].copy()
        vf, vf_d = _join(vf_counts, rows.cap_vf, rows.vf, rows.vf_d)
        ee, ee_d = _join(ee_counts, rows.cap_ee, rows.ee, rows.ee_d)
        return vf, vf_d, ee, ee_d

    def pairs_touching(self, x0, radius, touched):
        """:meth:`pairs`' answer restricted to the pairs with a feature that has a ``touched``
        particle (a boolean per particle): a particle–triangle pair whose particle or a corner of
        whose triangle is touched, an edge pair with a touched end; the same pairs, distances and
        order as :meth:`pairs` gives of those. The walk is :meth:`pairs`' with the items holding a
        touched particle marked, and the nodes above them: a pair of nodes neither of which holds
        one is not opened, so a search for a few particles costs the walk around them, not the
        cloth's (``vbd``'s search after a few vertices met their bounds)."""
        x0 = read_only(x0, np.float64)
        touched = np.asarray(touched, bool)
        if self.empty or not touched.any():
            return _no_pairs()
        tree = self.tree
        mark, imark = _marks(tree, touched, self.tris, self.orphans)
        return self._search(x0, radius, tree._replace(mark=mark, imark=imark), touched)

    def _task_rows(self) -> TaskRows:
        """The traversal's rows for :attr:`caps`, kept from search to search and made again only
        when the caps change: made fresh every search, rows grown to 240,000 a task (176 tasks,
        1.4 GB untouched but mapped and unmapped each time) took longer than the walk itself
        (Newton's shirt: 24 ms a search, 9 ms of it the walk)."""
        cap_vf, cap_ee = (int(c) for c in self.caps)
        rows = self._rows
        if rows is None or (rows.cap_vf, rows.cap_ee) != (cap_vf, cap_ee):
            n_tasks = len(self.tasks)
            rows = self._rows = TaskRows(
                np.empty((n_tasks * cap_vf, 2), np.int64),
                np.empty(n_tasks * cap_vf),
                np.empty((n_tasks * cap_ee, 2), np.int64),
                np.empty(n_tasks * cap_ee),
                np.zeros((n_tasks, 2), np.int64),
                cap_vf,
                cap_ee,
            )
        return rows


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
