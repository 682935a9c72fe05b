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
(and each edge's alike). The kept pairs are measured by the tree's own distance functions and
tests (the same box check first, the same strict comparison), so the answer is the tree's pairs
with its distances, to the bit, given in one order of theirs (:func:`tree_ranks`). The one
exception would be a pair at its reach to within rounding that the tree's coarser box tests let
pass while they reject it here: none was seen (``test_contacts.py`` compares the two answers at
every query on a pile of cloth).

**A particle that outran its skin is searched again alone.** The cover is a feature's, so the
list keeps, per particle, the place and the reach its pairs were found with; the list holds every
pair within those reaches at those places, whatever moment each place is of (the argument above
asks nothing more: each side's displacement is measured from its own place). Where a particle
outran its skin (:func:`_outran`: its own cover, then its triangles' and edges', each corner taken
as searched again where it is marked), only its pairs are searched again
(:meth:`TriangleTree.pairs_touching`, from its new place with its new reach, every other particle
at its kept place): the list's pairs without a feature of it are unchanged by the move, and those
with one are exactly what that search finds. So one fast particle no longer costs the whole
cloth's walk. The answer holds the tree's pairs and distances, to the bit, in an order of the
pairs' own (:func:`_ordered`): a refreshed list held in its history's order (the kept pairs first,
then the refreshed) and answered in that order stepped an environment reset to a seed on to other
bits (Gymnasium's check of TshirtFold). The list is kept in that order (a search's pairs sorted
once, a refresh's merged in: :func:`_merged`), so a query's answer is the list's pairs within
reach as they come (on the resting T-shirt the sorting went from 0.7 to 0.1 ms a step: only a
refresh's new pairs are sorted).

On the resting T-shirt (``vbd``, a skin of half a thickness) 5–8 % of the particles are searched
again a step (their own cover and their triangles' and edges'), where 40 % outran the bound that
made ``vbd`` walk the whole tree every step; the refresh costs about half a whole walk (the
touched particles are spread over the garment: ~90 a step, whose ~22,000 pairs of items in reach
are what the walk measures; walking each of their items down the tree alone was 3.8× slower).

**A kept pair is measured only where it may be within reach.** The list keeps each pair's
distance where its sides' places are, and by the argument above the distance now is at least that
less the two sides' displacements since: a pair that this leaves at its reach or beyond is beyond
it now, as the tree's tests would find (:func:`_near_now`). On the resting T-shirt a third of
``vbd``'s kept pairs and 98 % of the guard's (below) are passed over so (the guard's query 0.48 →
0.30 ms).

A search made for one query alone (no skin) is kept the same way, and answers any later query it
covers: after ``vbd``'s step the guard on the contact stage
(:class:`cloth_sim.contact.self_collision.Uncrossed`) asks for the pairs closer than that stage's
small push, which ``vbd``'s last search, with its larger reaches, covers (on the resting T-shirt
2.3 → 0.6 ms a step, the same bits).

The skin trades the search for the list's length: a thicker skin keeps the list longer and makes it
longer. Its caller chooses it (the contact stage: :data:`cloth_sim.contact.self_collision.SKIN`;
``vbd``: :data:`cloth_sim.integrators.vbd.SEARCH_SKIN`).

**Where it pays** depends on the cloth: on the fold scene at 24×24 the kept pairs cost 0.6 of a
search every step, at 32×32 and finer (a thickness near half the spacing: the grown reaches take
in every next-but-one neighbour of the flat cloth) 1.15–2× more. The caller decides
(:attr:`cloth_sim.contact.self_collision.SelfCollision.keeps_pairs`); both give the same answer.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from ..kernel_cache import keep_true
from .collision_tree import TriangleTree, reaches, touching
from .geometry import closest_on_segments, point_triangle_distance, read_only

#: room kept for rounding in the cover test (m): a list is searched again that much early
ROUNDING = 1e-9
#: the share of the particles at most whose pairs are searched again alone where they outran the
#: list (:meth:`PairList.pairs`); beyond it the whole cloth is searched
REFRESH_SHARE = 0.1


@numba.njit(cache=True)
def _displacements(x0, places):
    """Each particle's distance from its kept place to ``x0``."""
    moved = np.empty(x0.shape[0])
    for i in range(x0.shape[0]):
        dx, dy, dz = x0[i, 0] - places[i, 0], x0[i, 1] - places[i, 1], x0[i, 2] - places[i, 2]
        moved[i] = np.sqrt(dx * dx + dy * dy + dz * dz)
    return moved


@numba.njit(cache=True)
def _outran(reach, grown, moved, reach_s, tris, edges):
    """Per particle, whether its pairs must be searched again (where it is now, with the reaches
    ``grown``) for the kept list, found within the reaches ``reach_s`` at the list's places, to
    hold every pair within ``reach`` now (module docstring): its own reach plus its displacement
    since (``moved``: :func:`_displacements`) beyond what the list gave it; then each triangle
    (edge) whose largest corner's reach plus the largest of its corners' displacements is beyond
    the largest of their kept reaches, each corner taken as searched again where it is marked, has
    all its corners marked, until none is left (a corner searched again moves no more and may
    reach less: so a marked corner's triangles are looked at again)."""
    n = reach.shape[0]
    out = np.zeros(n, np.bool_)
    for i in range(n):
        if not reach[i] + moved[i] <= reach_s[i] - ROUNDING:  # (a NaN is outrun)
            out[i] = True
    changed = True
    while changed:
        changed = False
        for t in range(tris.shape[0] + edges.shape[0]):
            if t < tris.shape[0]:
                a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
            else:
                a, b = edges[t - tris.shape[0], 0], edges[t - tris.shape[0], 1]
                c = b
            if out[a] and out[b] and out[c]:
                continue
            need, have = 0.0, 0.0
            far = 0.0
            for k in (a, b, c):
                need = max(need, reach[k])
                far = max(far, 0.0 if out[k] else moved[k])
                have = max(have, grown[k] if out[k] else reach_s[k])
            if not need + far <= have - ROUNDING:
                out[a] = out[b] = out[c] = True
                changed = True
    return out


@numba.njit(cache=True, inline="always")
def _compacted(pairs, dist, keep):
    """The ``pairs`` and ``dist`` that ``keep`` marks, in their order."""
    m = 0
    for q in range(keep.shape[0]):
        m += keep[q]
    out, out_d = np.empty((m, 2), np.int64), np.empty(m)
    m = 0
    for q in range(keep.shape[0]):
        if keep[q]:
            out[m, 0], out[m, 1], out_d[m] = pairs[q, 0], pairs[q, 1], dist[q]
            m += 1
    return out, out_d


@numba.njit(cache=True, parallel=True)
def _near_now(x0, reach, tris, edges, kept, moved):
    """Which kept pairs are still within reach at ``x0``, and their distances: the tree's tests
    (:func:`cloth_sim.contact.collision_tree._point_triangle` and the edge–edge test of
    ``_traverse``) on each, every pair on its own (so the same at any thread count). A pair whose
    distance at the kept places (``kept``: the list's :class:`Kept`), less how far its two sides
    moved since (``moved``, per particle: the bound of the module docstring), is at least its
    reach plus :data:`ROUNDING` is beyond reach without being measured: the tests would reject
    it too, so the answer is theirs. Returns the pairs within reach and their distances, in the
    list's order."""
    vf, ee = kept.vf, kept.ee
    keep_vf, vf_d = np.zeros(vf.shape[0], np.bool_), np.empty(vf.shape[0])
    for q in numba.prange(vf.shape[0]):
        p, t = vf[q, 0], vf[q, 1]
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        r, tr = reach[p], max(reach[a], reach[b], reach[c])
        if r + tr <= 0.0:
            continue  # nothing reaches: a distance is never below 0 (the guard's still cloth)
        if kept.vf_d[q] - moved[p] - max(moved[a], moved[b], moved[c]) >= r + tr + ROUNDING:
            continue  # (a NaN is measured)
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
        if r <= 0.0:
            continue
        if kept.ee_d[q] - max(moved[e0], moved[e1]) - max(moved[f0], moved[f1]) >= r + ROUNDING:
            continue
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
    return (*_compacted(vf, vf_d, keep_vf), *_compacted(ee, ee_d, keep_ee))


@numba.njit(cache=True)
def _ordered(pairs, dist, rank):
    """The ``pairs`` and their distances by the ``rank`` of their first index (a permutation),
    then by their second index (each pair is unique, so this order is the pairs' own, whatever
    order they came in): a radix sort of two digits, each a stable counting sort (by the second
    index, then by the first's rank), linear in the pairs. (It was one counting sort by rank and
    an insertion sort of each rank's run, quadratic in a run's length: 2.6–3.3× the time on a
    crumpled T-shirt's searches, whose particles and edges pair with up to ~750 items.)"""
    m, buckets = pairs.shape[0], rank.shape[0]
    second = 0
    for q in range(m):
        second = max(second, pairs[q, 1] + 1)
    by_second = np.zeros(second + 1, np.int64)
    by_rank = np.zeros(buckets + 1, np.int64)
    for q in range(m):
        by_second[pairs[q, 1] + 1] += 1
        by_rank[rank[pairs[q, 0]] + 1] += 1
    for b in range(second):
        by_second[b + 1] += by_second[b]
    for b in range(buckets):
        by_rank[b + 1] += by_rank[b]
    # the first digit: by the second index, into a copy of the pairs' columns
    first, other, d = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m)
    for q in range(m):
        b = pairs[q, 1]
        r = by_second[b]
        by_second[b] = r + 1
        first[r], other[r], d[r] = pairs[q, 0], b, dist[q]
    # the second: by the first index's rank, stable (so each rank's run stays in second order)
    out, out_d = np.empty((m, 2), np.int64), np.empty(m)
    for q in range(m):
        b = rank[first[q]]
        r = by_rank[b]
        by_rank[b] = r + 1
        out[r, 0], out[r, 1], out_d[r] = first[q], other[q], d[q]
    return out, out_d


@numba.njit(cache=True)
def _merged(pairs, dist, gone, new, new_d, rank):
    """``pairs`` (in :func:`_ordered`'s order) but those ``gone`` marks, merged with ``new`` (in
    that order too, none of them among ``pairs``), with their distances: the two in that order."""
    m = new.shape[0]
    for q in range(gone.shape[0]):
        m += not gone[q]
    out, out_d = np.empty((m, 2), np.int64), np.empty(m)
    q, j = 0, 0
    for r in range(m):
        while q < pairs.shape[0] and gone[q]:
            q += 1
        take_old = j >= new.shape[0] or (
            q < pairs.shape[0]
            and (
                rank[pairs[q, 0]] < rank[new[j, 0]]
                or (rank[pairs[q, 0]] == rank[new[j, 0]] and pairs[q, 1] < new[j, 1])
            )
        )
        if take_old:
            out[r, 0], out[r, 1], out_d[r] = pairs[q, 0], pairs[q, 1], dist[q]
            q += 1
        else:
            out[r, 0], out[r, 1], out_d[r] = new[j, 0], new[j, 1], new_d[j]
            j += 1
    return out, out_d


class Kept(NamedTuple):
    """The kept pairs in :func:`_ordered`'s order, with their distances where the list's places
    are (each pair's sides at their own places: module docstring)."""

    vf: np.ndarray
    vf_d: np.ndarray
    ee: np.ndarray
    ee_d: np.ndarray


def _in_order(vf, vf_d, ee, ee_d, ranks) -> Kept:
    """A search's answer as a :class:`Kept` list: its pairs in :func:`_ordered`'s order."""
    vranks, eranks = ranks
    return Kept(
        *_ordered(vf, vf_d, vranks),
        *_ordered(ee, ee_d, eranks),
    )


def tree_ranks(tree: TriangleTree) -> tuple[np.ndarray, np.ndarray]:
    """Each particle's and each edge's place in the tree's leaf order (by the triangle that is
    the first to hold it, then its place in that triangle; a lone particle where its leaf is): the
    order the answers come in, the tree's own walk's as near as one order of the features can be
    (an order by index interleaves far parts of a garment's panels: on the resting T-shirt the
    layers settled to twice the motion a step)."""
    order = tree.tree.order
    n_tris = len(tree.tris)
    is_tri = order < n_tris
    none = np.full((len(order), 3), -1, np.int64)
    rows = np.minimum(order, max(n_tris - 1, 0))
    own_v = tree.prim.own_v[rows] if n_tris else none
    own_e = tree.prim.own_e[rows] if n_tris else none
    lone = none.copy()
    lone[~is_tri, 0] = tree.orphans[order[~is_tri] - n_tris]
    by_leaf = np.where(is_tri[:, None], own_v, lone).ravel()
    by_leaf = by_leaf[by_leaf >= 0]
    vrank = np.empty(len(by_leaf), np.int64)
    vrank[by_leaf] = np.arange(len(by_leaf))
    edges_by_leaf = np.where(is_tri[:, None], own_e, -1).ravel()
    edges_by_leaf = edges_by_leaf[edges_by_leaf >= 0]
    erank = np.empty(len(tree.edges), np.int64)
    erank[edges_by_leaf] = np.arange(len(edges_by_leaf))
    return vrank, erank


class PairList:
    """The tree's pairs, searched with a skin and kept while they cover a query, each particle's
    part searched again where it outran its skin (module docstring). :meth:`pairs` answers with
    :meth:`TriangleTree.pairs`' pairs and distances; ``searches`` counts the whole searches made
    for the list, ``refreshes`` the searches of a few particles' pairs and ``queries`` the
    queries."""

    def __init__(self, tree: TriangleTree):
        self.tree = tree
        self._at = None  # (places, reaches) the kept pairs were found within, per particle
        self._kept: Kept | None = None  # the pairs found there, in the answers' order
        self.searches = self.refreshes = self.queries = 0
        self._ranks = None if tree.empty else tree_ranks(tree)  # (the answers' order)

    def pairs(self, x0, radius, skin):
        """:meth:`TriangleTree.pairs`'s pairs and distances for ``x0`` and ``radius``: from the
        kept list where it covers them; where it does not for at most :data:`REFRESH_SHARE` of
        the particles, those particles' pairs searched again from ``x0`` with their reaches grown
        by ``skin`` (m: a number, or one per particle) and the list's other pairs kept; else from
        a new search with every reach grown by ``skin``. The same pairs and distances as the tree
        gives, in one order of theirs (:func:`tree_ranks`, :func:`_ordered`): the answer does
        not depend on the list's history (which searches and refreshes made it), so a simulation
        set back to a state steps on to the same bits."""
        x0 = read_only(x0, np.float64)
        reach = read_only(reaches(radius, len(x0)), np.float64)
        self.queries += 1
        tree = self.tree
        if tree.empty:
            return tree.pairs(x0, reach)  # (nothing to pair, nothing to keep)
        grown = reach + np.asarray(skin, np.float64)
        if self._at is not None:
            moved = _displacements(x0, self._at[0])  # (each particle's, from its kept place)
            out = _outran(reach, grown, moved, self._at[1], tree.tris, tree.edges)
            outran = np.count_nonzero(out)
            if (
                outran
                and np.any(skin)
                and outran <= REFRESH_SHARE * len(out)
                and np.isfinite(grown[out]).all()  # (a NaN: searched whole)
                and np.isfinite(x0[out]).all()
            ):
                self._refresh(x0, grown, out)
                moved[out] = 0.0  # (their kept places are where they are now)
                outran = 0
        if self._at is None or outran:
            vf, vf_d, ee, ee_d = tree.pairs(x0, grown)
            self._at = (x0.copy(), np.array(grown, np.float64))
            self._kept = _in_order(vf, vf_d, ee, ee_d, self._ranks)
            self.searches += 1
            if not np.any(skin):
                # searched for this query alone: its answer, copied (the list reads its own)
                return tuple(a.copy() for a in self._kept)
            moved = np.zeros(len(x0))  # (every kept place is where its particle is now)
        return _near_now(x0, reach, tree.tris, tree.edges, self._kept, moved)

    def _refresh(self, x0, grown, out) -> None:
        """The particles ``out`` (a boolean each) placed at ``x0`` with reaches ``grown``, every
        other particle kept where the list has it; the pairs with a feature of theirs are those
        within the reaches at those places (:meth:`TriangleTree.pairs_touching`), merged into the
        list's other pairs (module docstring: why the list then covers as after a search)."""
        tree = self.tree
        places, reach = self._at
        places[out] = x0[out]
        reach[out] = grown[out]
        new = _in_order(*tree.pairs_touching(places, reach, out), self._ranks)
        kept = self._kept
        gone_vf, gone_ee = touching(kept.vf, kept.ee, tree.tris, tree.edges, out)
        vranks, eranks = self._ranks
        self._kept = Kept(
            *_merged(kept.vf, kept.vf_d, gone_vf, new.vf, new.vf_d, vranks),
            *_merged(kept.ee, kept.ee_d, gone_ee, new.ee, new.ee_d, eranks),
        )
        self.refreshes += 1


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
