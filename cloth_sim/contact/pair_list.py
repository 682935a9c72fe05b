"""Self-collision's candidate pairs kept between searches: a Verlet list over the tree's pairs.

The tree (:class:`~cloth_sim.contact.collision_tree.TriangleTree`) finds every particle–triangle
and edge–edge pair within the sum of its two sides' reaches, walking its refitted hierarchy every
step. Most steps of a cloth at rest or in slow contact find the same pairs again. So the search is
made with every reach grown by a **skin**, and its pairs are kept: while no primitive has moved,
since, by more than the skin leaves room for, every pair within reach now was within the grown
reach then, and the kept list, measured again at the new positions, answers the query alone
(Verlet's neighbour lists, 1967: molecular dynamics keeps its neighbours within a cut-off plus
a skin the same way).

**Why it answers as the tree does.** A point's distance to a triangle moves by at most the point's
displacement plus the largest of the triangle's corners' (the triangle is the corners' convex
hull); two segments' distance by the largest displacement of each one's ends. So a pair within
``r_p + r_T`` now was within ``r_p + D_p + r_T + D_T`` at the search, which the grown reaches cover
while ``r_p + D_p`` stays below the particle's grown reach and ``r_T + D_T`` below the triangle's
(and each edge's alike: :func:`_covers`). The kept pairs are measured by the tree's own distance
functions and tests (the same box check first, the same strict comparison), and they come in the
tree's order (its walk is fixed by the hierarchy's shape, and a search with larger reaches only
adds pairs between those it finds with smaller ones), so the answer is the tree's pairs, in its
order, with its distances, to the bit. The one exception would be a pair at its reach to within
rounding that the tree's coarser box tests let pass while they reject it here: none was seen
(``test_contacts.py`` compares the two answers at every query on a pile of cloth).

A search made for one query alone (no skin) is kept the same way, and answers any later query it
covers: after ``vbd``'s step the guard on the contact stage
(:class:`cloth_sim.contact.self_collision.Uncrossed`) asks for the pairs closer than that stage's
small push, which ``vbd``'s last search, with its larger reaches, covers (on the resting T-shirt
2.3 → 0.6 ms a step, the same bits).

The skin trades the search for the list's length: a thicker skin keeps the list longer and makes it
longer. Its caller chooses it (self-collision: :data:`cloth_sim.contact.self_collision.SKIN`).

**Where it pays** depends on the cloth: on the fold scene at 24×24 the kept pairs cost 0.6 of a
search every step, at 32×32 and finer (a thickness near half the spacing: the grown reaches take
in every next-but-one neighbour of the flat cloth) 1.15–2× more. The caller decides
(:attr:`cloth_sim.contact.self_collision.SelfCollision.keeps_pairs`); both give the same answer.
"""

from __future__ import annotations

import numba
import numpy as np

from .collision_tree import TriangleTree, reaches
from .geometry import closest_on_segments, point_triangle_distance, read_only

#: room kept for rounding in the cover test (m): a list is searched again that much early
ROUNDING = 1e-9


@numba.njit(cache=True)
def _covers(x0, reach, x_s, reach_s, tris, edges):
    """Whether the search at ``x_s`` with reaches ``reach_s`` found every pair within ``reach`` at
    ``x0`` (module docstring): each particle's, triangle's and edge's reach plus its (largest)
    displacement since within what the search gave it."""
    n = x0.shape[0]
    moved = np.empty(n)
    for i in range(n):
        dx, dy, dz = x0[i, 0] - x_s[i, 0], x0[i, 1] - x_s[i, 1], x0[i, 2] - x_s[i, 2]
        moved[i] = np.sqrt(dx * dx + dy * dy + dz * dz)
        if not reach[i] + moved[i] <= reach_s[i] - ROUNDING:  # (a NaN searches again)
            return False
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        need = max(reach[a], reach[b], reach[c]) + max(moved[a], moved[b], moved[c])
        if need > max(reach_s[a], reach_s[b], reach_s[c]) - ROUNDING:
            return False
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        need = max(reach[a], reach[b]) + max(moved[a], moved[b])
        if need > max(reach_s[a], reach_s[b]) - ROUNDING:
            return False
    return True


@numba.njit(cache=True, parallel=True)
def _near_now(x0, reach, tris, edges, vf, ee):
    """Which kept pairs are still within reach at ``x0``, and their distances: the tree's tests
    (:func:`cloth_sim.contact.collision_tree._point_triangle` and the edge–edge test of
    ``_traverse``) on each, every pair on its own (so the same at any thread count)."""
    keep_vf, vf_d = np.zeros(vf.shape[0], np.bool_), np.empty(vf.shape[0])
    for q in numba.prange(vf.shape[0]):
        p, t = vf[q, 0], vf[q, 1]
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        r, tr = reach[p], max(reach[a], reach[b], reach[c])
        outside = False
        for k in range(3):
            lo = min(x0[a, k], x0[b, k], x0[c, k]) - tr
            hi = max(x0[a, k], x0[b, k], x0[c, k]) + tr
            if x0[p, k] < lo - r or x0[p, k] > hi + r:
                outside = True
        if outside:
            continue
        d = point_triangle_distance(x0, p, a, b, c)[0]
        if d >= r + tr:
            continue
        keep_vf[q], vf_d[q] = True, d
    keep_ee, ee_d = np.zeros(ee.shape[0], np.bool_), np.empty(ee.shape[0])
    for q in numba.prange(ee.shape[0]):
        e, f = ee[q, 0], ee[q, 1]
        e0, e1, f0, f1 = edges[e, 0], edges[e, 1], edges[f, 0], edges[f, 1]
        r = max(reach[e0], reach[e1]) + max(reach[f0], reach[f1])
        apart = False
        for k in range(3):
            elo, ehi = min(x0[e0, k], x0[e1, k]), max(x0[e0, k], x0[e1, k])
            flo, fhi = min(x0[f0, k], x0[f1, k]), max(x0[f0, k], x0[f1, k])
            if elo - fhi >= r or flo - ehi >= r:
                apart = True
        if apart:
            continue
        d = closest_on_segments(x0, e0, e1, f0, f1)[2]
        if d >= r:
            continue
        keep_ee[q], ee_d[q] = True, d
    return keep_vf, vf_d, keep_ee, ee_d


class PairList:
    """The tree's pairs, searched with a skin and kept while they cover a query (module
    docstring). :meth:`pairs` answers as :meth:`TriangleTree.pairs` does; ``searches`` counts the
    searches made for the list and ``queries`` the queries."""

    def __init__(self, tree: TriangleTree):
        self.tree = tree
        self._at = None  # (positions, reaches) of the last search
        self._vf = self._ee = None
        self.searches = self.queries = 0

    def pairs(self, x0, radius, skin):
        """:meth:`TriangleTree.pairs`'s answer for ``x0`` and ``radius``, from the kept list where
        it covers them, else from a new search with every reach grown by ``skin`` (m: a number,
        or one per particle)."""
        x0 = read_only(x0, np.float64)
        reach = read_only(reaches(radius, len(x0)), np.float64)
        self.queries += 1
        tree = self.tree
        if self._at is None or not _covers(x0, reach, *self._at, tree.tris, tree.edges):
            grown = reach + np.asarray(skin, np.float64)
            found = tree.pairs(x0, grown)
            self._at = (x0.copy(), grown)
            self._vf, self._ee = found[0], found[2]
            self.searches += 1
            if not np.any(skin):
                return found  # searched for this query alone: its answer
        near_vf, vf_d, near_ee, ee_d = _near_now(
            x0, reach, tree.tris, tree.edges, self._vf, self._ee
        )
        return self._vf[near_vf], vf_d[near_vf], self._ee[near_ee], ee_d[near_ee]
