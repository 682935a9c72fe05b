"""Post-step stages: corrections of positions (and velocities) after each integrator step.

A stage is an object with ``name``, ``active`` and ``apply(state, start, dt, velocity_follow,
origin)``.
The simulator runs its active stages in order after every step; an inactive stage costs nothing (it
is not even called). To add a stage (contacts, grippers): a class with those three members, and one
line where :class:`~cloth_sim.simulator.Simulator` builds its ``stages`` list.

Provot's super-elasticity correction (:class:`StrainLimit`)
------------------------------------------------------------

Provot (1995) keeps structural and shear springs from stretching beyond a critical deformation rate
``τc``: after the particles move, every spring longer than ``(1 + τc)·L`` is shortened to exactly
that length by moving both ends equally along the spring, or only the free end when the other is
pinned. One pass visits every limited spring once (Gauss–Seidel), so a pass can stretch a spring an
earlier correction had fixed. Springs are visited outward from the pins (by graph distance), so one
pass carries a correction from a pin to the far edge, as the weight hangs; passes stop early once
one corrects nothing. A pass after the first visits only the springs that can have changed since
its last visit, with the same result (:func:`provot_passes`).

Provot's passes alone let a hanging cloth's stretch accumulate along its length: each pass moves a
correction one spring down a chain that is N springs long, and at 64×64 twenty passes left the
worst strain at 0.156 against τ = 0.1. So, for a pinned cloth, each step first applies **long-range
attachments** (Kim, Chentanez & Müller 2012, "Long range attachments — a method to simulate
inextensible clothing in computer games"): a particle may be no farther from a pin than ``(1 + τ)``
times its rest geodesic distance to it (the shortest path along the springs at rest, an upper bound
of the distance in the cloth, so the attachment never asks for less stretch than the springs
allow); one pass, against each particle's two nearest pins, removes the stretch accumulated along
the chain, the Provot passes then fix local excess, and the attachments are applied again after
each pass (a pass moves a pin's neighbours back out, and for those the attachment is their spring's
own limit). ``long_range=False`` keeps Provot's passes alone, for comparison.

``method="projection"`` replaces the passes by one projection of all the over-stretched springs
together (:mod:`cloth_sim.constraints.strain_projection`, after the attachments): the stretch is
held to ``τ`` plus the projection's own tolerance (its ``TOLERANCE``, 1e-3), for more work a step
(hanging 64×64: worst strain 0.1010 against the passes' 0.119; figures in docs/BENCHMARKS.md §3
and §11).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import shortest_path

from ..kinds import STRAIN_LIMIT_METHODS
from ..threads import start_pool
from . import strain_projection
from .strain_limit_kernels import (
    FULL_PASS_SHARE,
    NO_ANCHOR,
    NO_REACH,
    Attachments,
    PassWork,
    attachment_pass,
    attachment_pass_parallel,
    follow_corrections,
    provot_passes,
)

#: Passes per step unless the simulator is told otherwise.
DEFAULT_STRAIN_LIMIT_PASSES = 20
#: From this many particles on, the attachments run on every core (below, waking the second core
#: costs more than it saves: docs/BENCHMARKS.md §7)
PARALLEL_MIN_PARTICLES = 2048
#: Strain above ``τc`` that a pass tolerates (so passes stop once nothing is meaningfully too
#: long).
STRAIN_LIMIT_TOLERANCE = 1e-4


def nearest_attachments(model, count: int = 2, pinned=None) -> tuple[np.ndarray, np.ndarray]:
    """``(anchor, reach)``, ``(n, count)``: each free particle's ``count`` nearest pins by rest
    geodesic distance (shortest paths along all springs, weighted by rest length) and those
    distances; ``-1`` where there is none (a pin itself, or no pin reachable). ``pinned``: the
    pins, the model's own when None."""
    pinned = np.asarray(model.pinned if pinned is None else pinned, bool)
    pins = np.flatnonzero(pinned)
    if len(pins) == 0 or model.n_springs == 0:
        pins = pins[:0]
        dist = np.zeros((0, model.n_particles))
    else:
        dist = geodesic_distances(model, pins)
    anchor, reach = attachments_from(dist[None], pins[None], pinned[None], count)
    return anchor[0], reach[0]


def geodesic_distances(model, sources=None) -> np.ndarray:
    """``(len(sources), n)``: the rest geodesic distance from each of ``sources`` (every particle
    when None) to every particle, along the springs weighted by their rest lengths (Dijkstra from
    each source: the same numbers whichever sources are asked)."""
    n = model.n_particles
    s = model.springs
    graph = sp.csr_matrix((model.rest_lengths, (s[:, 0], s[:, 1])), shape=(n, n))
    return shortest_path(graph, method="D", directed=False, indices=sources)


def attachments_from(dist, pins, pinned, count: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_attachments` of ``W`` cloths of one topology at once, each with ``k``
    pins: ``dist`` ``(W, k, n)`` the rest geodesic distances from each one's pins ``pins``
    ``(W, k)`` (in index order), ``pinned`` ``(W, n)``; ``(anchor, reach)``, each
    ``(W, n, count)``."""
    w, k, n = dist.shape
    anchor = np.full((w, n, count), -1, dtype=np.int64)
    reach = np.zeros((w, n, count))
    if k == 0:
        return anchor, reach
    m = min(count, k)
    if k == 1:
        order = np.zeros((w, 1, n), np.int64)
    elif k == 2:  # (the stable sort of two: the first unless the second is nearer)
        second = (dist[:, 1] < dist[:, 0]).astype(np.int64)
        order = np.stack([second, 1 - second], axis=1)[:, :m]
    else:
        order = np.argsort(dist, axis=1, kind="stable")[:, :m]  # (W, m, n)
    near = np.take_along_axis(dist, order, axis=1)
    who = np.take_along_axis(np.broadcast_to(pins[:, :, None], dist.shape), order, axis=1)
    ok = np.isfinite(near) & ~pinned[:, None, :]
    anchor[:, :, :m] = np.where(ok, who, -1).transpose(0, 2, 1)
    reach[:, :, :m] = np.where(ok, near, 0.0).transpose(0, 2, 1)
    return anchor, reach


def _no_attachments(x, anchor, reach, tau) -> int:
    """The attachments of a cloth without a pin: none moves."""
    return 0


class _PassScratch:
    """What :func:`provot_passes` keeps: each particle's limited springs (CSR, in the springs'
    order) and its stamps and scratch arrays, as :attr:`work` (:class:`PassWork`)."""

    def __init__(self, springs: np.ndarray, n: int):
        ends = springs.astype(np.int64).ravel()
        order = np.argsort(ends, kind="stable")
        self.inc = np.ascontiguousarray(order // 2)
        self.inc_ptr = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(ends, minlength=n), out=self.inc_ptr[1:])
        m = len(springs)
        self.work = PassWork(
            self.inc_ptr,
            self.inc,
            np.zeros(1, np.int64),  # the clock
            np.zeros((3, max(m, 1)), np.int64),  # the heap, the next pass, queued (stamps)
            np.zeros((4, max(n, 1)), np.int64),  # listed (stamps), last, the two lists
        )


class Stage:
    """A post-step correction. ``apply(state, start, dt, velocity_follow, origin)`` changes
    ``state.x`` / ``state.v`` in place; ``start`` is the state before the step. A position change
    ``Δx`` moves the velocity by ``velocity_follow·Δx/h`` (the integrator's own factor: 1 for
    one-step methods, 1.5 for Verlet's BDF2 velocity), ``h`` the time the step's velocity was
    measured over: ``origin``, where not None, is the integrator's
    :meth:`~cloth_sim.integrators.base.Integrator.velocity_origin` (``x``, ``h`` and ``mean``: a
    method's last substep, or for the explicit Runge–Kutta methods the step with ``mean``, a
    corrected particle then taking its mean velocity over it and ``Δx/h``), else ``(start.x,
    dt)``."""

    name = ""

    @property
    def active(self) -> bool:
        raise NotImplementedError

    def apply(self, state, start, dt: float, velocity_follow: float, origin=None) -> None:
        raise NotImplementedError


class StrainLimit(Stage):
    """Provot's correction over a model's strain-limited springs, after long-range attachments to
    the pins (``long_range``); active when ``tau`` is set. ``method``: one of
    :data:`STRAIN_LIMIT_METHODS` (``"projection"``: ``passes`` bounds its iterations instead)."""

    name = "strain_limit"

    def __init__(
        self,
        model,
        tau: float | None = None,
        passes: int = DEFAULT_STRAIN_LIMIT_PASSES,
        long_range: bool = True,
        method: str = "provot",
    ):
        if int(passes) < 1:
            raise ValueError(f"strain_limit_passes must be >= 1, got {passes}")
        if method not in STRAIN_LIMIT_METHODS:
            raise ValueError(
                f"strain_limit_method must be one of {', '.join(STRAIN_LIMIT_METHODS)}, "
                f"got {method!r}"
            )
        self.passes = int(passes)
        self.long_range = bool(long_range)
        self.method = method
        self._scratch = None
        self.model = model
        self._anchor = None
        self.tau = None
        self._springs = None  # built when first made active
        self._passes = None  # the passes' topology and scratch (_PassScratch)
        self.last_passes = 0
        self.set_tau(tau)

    def set_tau(self, tau: float | None) -> None:
        """``None`` (or 0 from the node's parameter, which maps it to ``None``) turns it off."""
        if tau is not None:
            tau = float(tau)
            if not (math.isfinite(tau) and tau >= 0):
                raise ValueError(f"strain_limit must be a finite number >= 0 (or None), got {tau}")
            if self._springs is None:
                model = self.model
                sel = np.flatnonzero(model.strain_limited)
                sel = sel[_outward_order(model, model.springs[sel])]
                # 32-bit unsigned ends: numba wraps negative indices of a signed type around, at
                # each use (docs/BENCHMARKS.md §7)
                self._springs = model.springs[sel].astype(np.uint32)
                self._rest = np.ascontiguousarray(model.rest_lengths[sel])
                self._pinned = np.ascontiguousarray(model.pinned)
            if self.long_range and self._anchor is None:
                self._anchor, self._reach = nearest_attachments(self.model)
                self._attach = (
                    attachment_pass_parallel
                    if self.model.n_particles >= PARALLEL_MIN_PARTICLES
                    else attachment_pass
                )
                if not np.any(self._anchor >= 0):
                    # no pin (a cloth dropped on a table): nothing to attach; the parallel pass
                    # over every particle cost ~20 µs a call, after each of up to 20 Provot
                    # passes a step (docs/BENCHMARKS.md §11)
                    self._attach = _no_attachments
        self.tau = tau

    @property
    def active(self) -> bool:
        return self.tau is not None

    def attachments(self, x: np.ndarray) -> int:
        """The long-range attachments alone on ``x`` (in place): each particle pulled back to
        ``(1 + τ)`` times its rest geodesic distance from its nearest pins; returns how many
        moved (0 when the limit or its attachments are off). An integrator that iterates may
        apply them between its iterations (vbd's ``tethers``)."""
        if self.tau is None or not self.long_range:
            return 0
        return self._attach(x, self._anchor, self._reach, self.tau)

    def correct(self, x: np.ndarray) -> int:
        """Correct ``x`` in place; returns the number of passes (or projection iterations) that
        changed something."""
        lra = self.long_range
        if self.method == "projection":
            used = 1 if lra and self._attach(x, self._anchor, self._reach, self.tau) else 0
            used += self._project(x)
            self.last_passes = used
            return used
        if self._passes is None:
            self._passes = _PassScratch(self._springs, self.model.n_particles)
        used = provot_passes(
            x,
            self._springs,
            self._rest,
            self.tau,
            STRAIN_LIMIT_TOLERANCE,
            self._pinned,
            self.passes,
            FULL_PASS_SHARE,
            # the bundles as plain tuples (a NamedTuple argument takes numba's slow path)
            tuple(
                Attachments(
                    self._anchor if lra else NO_ANCHOR,
                    self._reach if lra else NO_REACH,
                    lra and self._attach is not _no_attachments,
                )
            ),
            tuple(self._passes.work),
        )
        self.last_passes = used
        return used

    def _project(self, x) -> int:
        if self._scratch is None:
            model = self.model
            w = np.where(model.pinned, 0.0, 1.0 / model.masses)
            top = w.max()
            self._w = np.ascontiguousarray(w / top if top > 0 else w)
            self._scratch = strain_projection.Scratch(self._springs, model.positions)
            start_pool()  # the projection's solve calls the parallel search for springs over τ
        sp = strain_projection
        settings = sp.Settings(self.tau, max_outer=self.passes)
        return sp.project(
            x, self._springs, self._rest, self._w, settings, self._scratch.workspace()
        )

    def apply(self, state, start, dt, velocity_follow, origin=None):
        """Correct the positions; the velocities follow the part of each particle's correction no
        longer than its own motion over the time its velocity was measured over (``origin``:
        :class:`Stage`; the step, or a method's last substep). A correction beyond that undoes
        stretch that was there before (the limit was just tightened, or a pass left some over):
        moving it back is a projection, and divided by a small dt it would be a false speed (1.6
        mm over dt = 1e-6 s is 1600 m/s)."""
        self.correct_within(state, (start.x, dt) if origin is None else origin, velocity_follow)
        if self.track_reaction:
            self._react(dt)

    def correct_within(self, state, origin, velocity_follow) -> None:
        """The correction after a part of a step: the velocities, measured over ``origin``
        (``(x, h)`` or a :class:`~cloth_sim.integrators.base.VelocityOrigin`), follow it as
        :meth:`apply` says; where they are not the positions' difference over it (its ``mean``),
        a corrected particle takes its mean velocity over ``h`` and the correction's. A method
        that steps in substeps (``vbd``, ``xpbd``) corrects after each but the last (the stage's
        own :meth:`apply` after the step): a velocity follows only the corrections of its own
        substep, so a correction of several substeps' stretch divided by the whole step left the
        rest of a velocity that stretched the springs, and the cloth beside the pins kept moving
        at ~1 m/s (cotton hanging at 32×32, ``vbd`` at 1/60 s in 5 substeps, still after 10 s).
        The corrections' momentum is gathered over the step for :attr:`reaction` (with ``mean``,
        a corrected particle's whole change of velocity, the mean's included)."""
        if self._before is None or self._before.shape != state.x.shape:
            self._before = np.empty_like(state.x)
        before = self._before
        np.copyto(before, state.x)
        start_x, h, *mean = origin  # (a VelocityOrigin's third field)
        mean = bool(mean and mean[0])
        v_end = state.v.copy() if mean and self.track_reaction else None
        if self.correct(state.x):
            follow_corrections(state.x, before, start_x, state.v, velocity_follow / h, mean)
        if self.track_reaction:
            if self._gained is None or self._gained.shape != state.x.shape:
                self._gained = np.zeros_like(state.x)
            if mean:
                moved = np.any(state.x != before, axis=1)[:, None]
                self._gained += np.where(moved, (state.x - start_x) / h - v_end, 0.0)
            else:
                self._gained += (state.x - before) / h

    _before = None
    _gained = None  # the step's corrections' Δx/h so far, per particle (for the reaction)
    #: keep :attr:`reaction` (grippers ask for it): the force the limit's corrections put on the
    #: pins
    track_reaction = False
    #: ``(n, 3)``: per pinned particle, the force (N) the last step's corrections exerted on it
    reaction = None

    def _react(self, dt):
        """The momentum the step's corrections imply for each free particle (``Δv = Δx/h`` for
        each, summed: the whole correction, whether or not the velocity was let follow all of it)
        came from the constraints holding the cloth up; each particle's share is put on its
        nearest pin (by rest distance along the springs, as the long-range attachments use), as
        the reaction ``−m·Δv/dt``."""
        model = self.model
        if self._nearest is None:
            anchor = self._anchor if self._anchor is not None else nearest_attachments(model)[0]
            self._nearest = anchor[:, 0]
        if self.reaction is None:
            self.reaction = np.zeros((model.n_particles, 3))
        self.reaction[:] = 0.0
        near = self._nearest
        ok = near >= 0
        dv = self._gained
        np.add.at(self.reaction, near[ok], -(model.masses[ok, None] * dv[ok]) / dt)
        dv[:] = 0.0

    _nearest = None


def _outward_order(model, springs) -> np.ndarray:
    """Order of ``springs`` by hop distance of their nearer end from the nearest pin (stable)."""
    pins = np.flatnonzero(model.pinned)
    if len(pins) == 0 or len(springs) == 0:
        return np.arange(len(springs))
    n = model.n_particles
    s = model.springs
    graph = sp.csr_matrix((np.ones(len(s)), (s[:, 0], s[:, 1])), shape=(n, n))
    hops = shortest_path(graph, directed=False, unweighted=True, indices=pins).min(axis=0)
    near = np.minimum(hops[springs[:, 0]], hops[springs[:, 1]])
    far = np.maximum(hops[springs[:, 0]], hops[springs[:, 1]])
    return np.lexsort((far, near))
