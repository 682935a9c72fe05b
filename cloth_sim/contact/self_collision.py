"""Self-collision: the cloth keeps ``thickness`` from its own non-adjacent triangles and never
passes through one.

A post-step stage (see :mod:`cloth_sim.constraints.strain_limit`) over particle–triangle pairs, the
triangle not containing the particle. Each step:

1. **Candidates**, from a bounding-volume hierarchy over the triangles
   (:mod:`cloth_sim.contact.collision_tree`: built once from the rest layout, refitted to the
   step's start positions and traversed against itself). Each particle **reaches** half the
   thickness beyond its own motion over the step, ``h/2 + |Δx|``; a triangle or an edge reaches as
   far as its farthest corner. A pair is a candidate when its distance at the start is below its
   two reaches: farther apart, it can neither come within ``h`` nor cross over the step. (A search
   radius of ``h + 2·max|Δx|`` for every pair lets the cloth's fastest particle widen everyone's
   search; a spatial hash did the search before. What each cost: docs/BENCHMARKS.md §3c, §7.) A
   particle is paired with every triangle it is not a corner of (Bridson et al.): excluding the
   triangles of its neighbours too was tried and lets the ``fold`` scene cross itself where a
   crease is one triangle wide. Neighbours in a flat or compressed cloth are never pushed out of
   its plane (step 2), and the no-crossing bound (step 3) slows them only when they move by most of
   an edge.
2. **Proximity** (Bridson, Fedkiw & Anderson 2002): a pair closer than ``thickness`` at the end of
   the step is pushed apart, shared by inverse mass between its two sides (each moved as a whole,
   held particles staying), and an approaching normal velocity between them is removed alike (an
   inelastic impulse). By where the particle's nearest point on the triangle lies:

   * inside the face: along the triangle's normal, on the side the particle was at the start (so
     neighbours in a flat or compressed cloth are never pushed out of its plane);
   * on an edge (**point–edge**) or at a corner (**point–point**): along the line from that point
     to the particle, each edge and corner handled once (from the first triangle that has it), and
     only when the particle shares no triangle with it. Without these, the hems and openings of a
     garment — where the nearest point is an edge — kept no distance: the edge particles of a
     U-folded cloth came within 1.5–1.9 mm of the other layer at a thickness of 5 mm;
   * and **edge–edge**: two edges sharing no particle whose nearest points both lie inside them
     (two hems crossing), found by the same traversal (each edge from its first triangle), pushed
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

The cost is one refit and traversal of the tree and one distance test per pair of overlapping
boxes; ``self_collision=False`` (the default) runs none of it. The kernels of steps 2 and 3:
:mod:`cloth_sim.contact.self_collision_kernels`.
"""

from __future__ import annotations

import numpy as np

from ..physics.mesh import half_edges
from .colliders import SUPPORT
from .collision_tree import TriangleTree
from .pair_list import PairList
from .self_collision_kernels import (
    displacement_factors,
    displacements,
    edge_displacement_factors,
    proximity,
    proximity_edges,
    proximity_features,
    scale_displacements,
)

#: self-collision's thickness may be at most this fraction of the shortest triangle edge at rest
MAX_THICKNESS_FRACTION = 0.5

#: the skin of the candidate pairs kept between searches (:mod:`cloth_sim.contact.pair_list`), in
#: thicknesses: the fastest measured on the fold scene (a quarter, a half, one, one and a half and
#: two tried; a thicker skin keeps the list more steps and makes it longer)
SKIN = 1.0

#: the pairs are kept only while the grown reach of a pair, ``(1 + 2·skin)·thickness``, stays
#: within this share of the median rest edge: beyond it the kept list takes in the flat cloth's
#: next-but-one neighbours. On the fold scene (1 s from 0.5 s), the kept pairs against a search
#: every step: 0.6× the cost at a ratio of 0.52 (24×24), 1.15× at 0.70 (32×32), 1.4× at 0.88
#: (40×40), 1.3× at 1.06 (48×48), 1.8× at 1.42 (64×64). (The median, not the shortest: a mesh's
#: few short edges bring a few pairs into the list, not the cloth's; Newton's shirt has edges
#: of 1.5 mm and a median of 10 mm, at a thickness of half the shortest.)
KEEP_BELOW = 0.6


def rest_edges(model) -> np.ndarray:
    """The lengths of ``model``'s triangle edges at rest (each as often as triangles have it)."""
    t = model.triangles
    x = model.positions
    edges = np.concatenate(
        [x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 1]], x[t[:, 0]] - x[t[:, 2]]]
    ).reshape(-1, 3)
    return np.sqrt((edges * edges).sum(axis=1))


def shortest_edge(model) -> float:
    """``model``'s shortest triangle edge at rest (0 without triangles)."""
    lengths = rest_edges(model)
    return float(lengths.min()) if len(lengths) else 0.0


def thickness_limit(model) -> float:
    """The largest thickness self-collision accepts on ``model``: half its shortest triangle edge
    at rest. A thicker skin reaches past the triangles next to a particle in a flat cloth (they
    are about one edge away), so the search finds every neighbour of every particle (at 128×128
    with 5 mm, 400,000 pairs a step) and a crumpled cloth is pushed apart from itself."""
    return MAX_THICKNESS_FRACTION * shortest_edge(model)


def check_thickness(model, thickness: float) -> None:
    """``ValueError`` naming thickness and self_collision when self-collision cannot use it."""
    limit = thickness_limit(model)
    if not thickness <= limit * (1 + 1e-9):  # a spacing of 0.02 measures 0.0199999…
        raise ValueError(
            f"thickness = {thickness:g} m is too thick for self_collision on this cloth: "
            f"expected at most {limit:.4g} m (half its shortest triangle edge at rest); "
            f"lower thickness or turn self_collision off"
        )


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
        self._moved = np.zeros(model.n_particles)
        self._no_clearance = np.full(model.n_particles, np.inf)
        self._pairs = None  # the candidate pairs' hierarchy and kept list, built at the first step
        lengths = rest_edges(model)
        # the median rest edge: what the flat cloth's next neighbours are apart (a mesh's few
        # short edges bring a few of them into a kept list, not the whole cloth's)
        self._typical_edge = float(np.median(lengths)) if len(lengths) else 0.0
        self.last_pairs = self.last_pushed = self.last_slowed = self.last_edge_pairs = 0

    @property
    def active(self) -> bool:
        return self.enabled

    @property
    def features(self) -> tuple:
        """The topology the contacts read: ``(edges, tri_edge, edge_owner, edge_tris,
        vertex_owner, adj_ptr, adj)`` (:func:`_features`)."""
        return self._features

    @property
    def triangles(self) -> np.ndarray:
        """``(t, 3)``: the cloth's triangles (int64)."""
        return self._tris

    @property
    def edges(self) -> np.ndarray:
        """``(e, 2)``: the cloth's unique edges (the edge–edge pairs' indices)."""
        return self._features[0]

    @property
    def keeps_pairs(self) -> bool:
        """Whether the stage's searches keep their pairs on this cloth at this thickness
        (:data:`KEEP_BELOW`)."""
        return self.skin(SKIN) > 0.0

    def skin(self, thicknesses: float) -> float:
        """A skin of ``thicknesses`` thicknesses for the kept pairs, in metres, where it keeps
        the flat cloth's neighbours out of the list on this cloth (:data:`KEEP_BELOW` of its
        median rest edge), else 0."""
        grown = (1 + 2 * thicknesses) * self.thickness
        return thicknesses * self.thickness if grown <= KEEP_BELOW * self._typical_edge else 0.0

    @property
    def _skin(self) -> float:
        """The stage's own searches' skin (m): :data:`SKIN` thicknesses where it keeps its pairs
        (:attr:`keeps_pairs`), else none."""
        return self.skin(SKIN)

    def candidates(self, x0, reach, skin=0.0):
        """``(vf, vf_distance, ee, ee_distance)``: the particle–triangle and edge–edge pairs within
        ``reach`` of each other at ``x0``, as
        :meth:`cloth_sim.contact.collision_tree.TriangleTree.pairs` finds them: from the pairs
        kept since the last search while they cover the query
        (:mod:`cloth_sim.contact.pair_list`), else from a new search with every reach grown by
        ``skin`` (m, a number or one per particle; 0 searches for the query alone and keeps that
        for the next). The same answer either way, cheaper where the positions move little
        between queries."""
        return self._pair_list().pairs(x0, reach, skin)

    def candidates_touching(self, x0, reach, touched):
        """The pairs :meth:`candidates` would find at ``x0`` with a feature that has a
        ``touched`` particle, found by walking only the tree's leaves that hold them
        (:meth:`~cloth_sim.contact.collision_tree.TriangleTree.pairs_touching`); in the whole
        search's order, not kept for later queries."""
        return self._pair_list().tree.pairs_touching(x0, reach, touched)

    def _pair_list(self) -> PairList:
        if self._pairs is None:
            tree = TriangleTree(self._tris, self.model.positions, self._features)
            self._pairs = PairList(tree)
        return self._pairs

    def set_enabled(self, on: bool) -> None:
        """Turn it on or off; on needs the model's triangles and a thickness it can use
        (``ValueError`` otherwise, and nothing changes)."""
        if on and len(self._tris) == 0:
            raise ValueError(
                "self_collision needs the model's triangles (a grid has them; "
                "ClothModel.from_springs takes triangles=...)"
            )
        if on:
            check_thickness(self.model, self.thickness)
        self.enabled = bool(on)

    #: per particle, how far above a collider's skin the contact stage left it (``inf``: no
    #: collider; set by the simulator): within ``SUPPORT·thickness`` self-collision moves it as if
    #: pinned, so it never pushes the cloth into a collider
    clearance = None

    def apply(self, state, start, dt, velocity_follow, origin=None):
        x, x0, v = state.x, start.x, state.v
        h = self.thickness
        inv_mass = self._inv_mass
        clearance = self._no_clearance if self.clearance is None else self.clearance
        held = clearance < SUPPORT * h
        if held.any():
            inv_mass = np.where(held, 0.0, inv_mass)
        # each particle reaches half the thickness beyond its own motion: a pair farther apart at
        # the start than its two reaches can neither come within h nor cross over the step
        moved = displacements(x, x0, self._moved)
        if not np.isfinite(moved).all():
            return  # a diverged step: the simulator's check after the stages restores the state
        reach = 0.5 * h + moved
        tris, edges = self._tris, self._features[0]
        # the stage's steps are small: the kept pairs answer most of them where the cloth is
        # coarse against its thickness (keeps_pairs: the fold scene 1.6x faster at 24x24); vbd's
        # 1/60 s steps move too far between its queries to gain
        pairs, dist, e_pairs, e_dist = self.candidates(x0, reach, self._skin)
        free = self._inv_mass
        self.last_pushed = (
            proximity(x, x0, v, tris, pairs, inv_mass, free, clearance, h)
            + proximity_features(
                x, x0, v, tris, pairs, inv_mass, free, clearance, h, self._features
            )
            + proximity_edges(x, x0, v, edges, e_pairs, inv_mass, free, clearance, h)
        )
        # a pair the no-crossing pass must see is closer at the start than its two motions: the
        # search covered that unless the pushes moved some particle more than h / 2 further
        moved = displacements(x, x0, self._moved)
        if (moved > reach).any():
            pairs, dist, e_pairs, e_dist = self.candidates(x0, moved, self._skin)
        self.last_pairs, self.last_edge_pairs = len(pairs), len(e_pairs)
        displacement_factors(moved, tris, pairs, dist, self._factor)
        edge_displacement_factors(moved, edges, e_pairs, e_dist, self._factor)
        self.last_slowed = scale_displacements(x, x0, self._factor)
        if self.last_slowed:
            v *= self._factor[:, None]


def _features(tris: np.ndarray, n: int):
    """What the point–edge, point–point and edge–edge cases need of the topology: the unique edges
    ``(e, 2)``; each triangle's edge in slots 0 (a–b), 1 (b–c), 2 (c–a); each edge's first triangle
    (its owner) and its (up to) two triangles (−1 for none); each particle's first triangle; and
    the particles' neighbours along edges (CSR ``adj_ptr``, ``adj``)."""
    if len(tris) == 0:
        z = np.zeros((0, 2), np.int64)
        return (
            z,
            np.zeros((0, 3), np.int64),
            np.zeros(0, np.int64),
            z,
            np.full(n, -1, np.int64),
            np.zeros(n + 1, np.int64),
            np.zeros(0, np.int64),
        )

    a = tris.ravel()
    edges, group, _ = half_edges(tris, n)
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
    return (
        edges,
        tri_edge,
        edge_owner,
        edge_tris,
        vertex_owner,
        np.cumsum(adj_ptr),
        np.ascontiguousarray(other[order]),
    )


class Uncrossed:
    """A post-step stage (``stage``) kept from making the cloth cross itself: whatever it moves is
    scaled back by step 3's no-crossing factors over that stage's own displacement (the pairs
    closer, where the stage started, than their two displacements; module docstring). For an
    integrator that resolves self-contact inside its step (``vbd``) and leaves the contact stage
    after it an exact finish against the colliders: pushed out of a link that pinches a fold, a
    vertex would otherwise pass through the layer beside it. A vertex so held stays where the
    stage's push would cross (inside the collider by what is left of its depth): the cloth never
    crossing itself comes first. Velocities are the stage's."""

    def __init__(self, stage, self_collision: SelfCollision):
        self.stage = stage
        self.name = stage.name
        self._self = self_collision
        n = self_collision.model.n_particles
        self._before = np.zeros((n, 3))
        self._moved = np.zeros(n)
        self._factor = np.ones(n)
        #: particles the last step's guard held back from a crossing
        self.last_slowed = 0

    @property
    def active(self) -> bool:
        return self.stage.active

    def apply(self, state, start, dt, velocity_follow, origin=None):
        np.copyto(self._before, state.x)
        self.stage.apply(state, start, dt, velocity_follow, origin)
        moved = displacements(state.x, self._before, self._moved)
        self.last_slowed = 0
        if not moved.any() or not np.isfinite(moved).all():
            return  # nothing moved, or a diverged step (the simulator restores it)
        pairs, dist, e_pairs, e_dist = self._self.candidates(self._before, moved)
        displacement_factors(moved, self._self.triangles, pairs, dist, self._factor)
        edge_displacement_factors(moved, self._self.edges, e_pairs, e_dist, self._factor)
        self.last_slowed = scale_displacements(state.x, self._before, self._factor)
