"""The strain limit's kernels (:mod:`cloth_sim.constraints.strain_limit`): Provot's passes over
the over-stretched springs (in order, then from a heap of the springs that may have changed), the
long-range attachments to the pins (one core and every core), and the velocity that follows a
correction. The stage that calls them, its options and its bookkeeping:
:mod:`cloth_sim.constraints.strain_limit`.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from ..kernel_cache import keep_true

#: a pass after the first visits every spring when more than ``1/FULL_PASS_SHARE`` of them may
#: have changed (:func:`provot_passes`; a visit from its heap costs more than one in order)
FULL_PASS_SHARE = 32


#: ``l² ≤ this·bound²`` proves ``√l² ≤ bound`` after both roundings (their relative errors are
#: ~1e-16), so the passes take a square root only for a length near or over its bound and decide
#: exactly as with ``l = √l²`` for every one: the same bits. Most springs are within their bound;
#: a square root per spring visit was a tenth of the step (docs/BENCHMARKS.md §7).
_SURELY_WITHIN = 1.0 - 1e-12


@numba.njit(cache=True, inline="always")
def _shorten(x, i, j, pi, pj, rest, tau, tol):
    """Spring ``(i, j)`` (rest length ``rest``, ends pinned where ``pi``, ``pj``) shortened to
    strain ``tau`` if its strain exceeds ``tau + tol``, by moving both ends equally, or only the
    free one; whether it was. (``x`` is its one array: an inlined function taking the springs'
    arrays too binds each anew at every call, an atomic reference count up and down, and a pass
    took 9× as long.)"""
    if pi and pj:
        return False
    dx, dy, dz = x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], x[j, 2] - x[i, 2]
    l2 = dx * dx + dy * dy + dz * dz
    lmax = (1.0 + tau) * rest
    bound = lmax + tol * rest
    if l2 <= _SURELY_WITHIN * (bound * bound):  # no square root for a spring surely short enough
        return False
    l = np.sqrt(l2)
    if l <= bound:
        return False
    excess = (l - lmax) / l  # fraction of the spring vector to remove
    if pi:
        wi, wj = 0.0, 1.0
    elif pj:
        wi, wj = 1.0, 0.0
    else:
        wi, wj = 0.5, 0.5
    x[i, 0] += wi * excess * dx
    x[i, 1] += wi * excess * dy
    x[i, 2] += wi * excess * dz
    x[j, 0] -= wj * excess * dx
    x[j, 1] -= wj * excess * dy
    x[j, 2] -= wj * excess * dz
    return True


@numba.njit(cache=True)
def provot_pass(x, springs, rest, tau, tol, pinned):
    """One Gauss–Seidel pass of Provot's correction; returns how many springs it shortened.

    A spring counts as too long when its strain exceeds ``tau + tol``; it is then shortened to
    strain ``tau`` exactly."""
    corrected = 0
    for s in range(springs.shape[0]):
        i, j = springs[s, 0], springs[s, 1]
        if _shorten(x, i, j, pinned[i], pinned[j], rest[s], tau, tol):
            corrected += 1
    return corrected


@numba.njit(cache=True, inline="always")
def _attach(x, anchor, reach, tau, p):
    """Particle ``p``'s attachments (:func:`attachment_pass`); 1 if it moved, else 0."""
    moved = 0
    for a in range(anchor.shape[1]):
        q = anchor[p, a]
        if q < 0:
            continue
        dx, dy, dz = x[p, 0] - x[q, 0], x[p, 1] - x[q, 1], x[p, 2] - x[q, 2]
        l2 = dx * dx + dy * dy + dz * dz
        lmax = (1.0 + tau) * reach[p, a]
        if l2 <= _SURELY_WITHIN * (lmax * lmax):
            continue
        l = np.sqrt(l2)
        if l > lmax:
            f = lmax / l
            x[p, 0] = x[q, 0] + f * dx
            x[p, 1] = x[q, 1] + f * dy
            x[p, 2] = x[q, 2] + f * dz
            moved = 1
    return moved


@numba.njit(cache=True)
def attachment_pass(x, anchor, reach, tau):
    """Long-range attachments: each particle ``p`` with an anchor ``anchor[p, a] >= 0`` (a pin) is
    pulled back along the line to it when farther than ``(1 + τ)·reach[p, a]``; returns how many
    particles were moved. :func:`attachment_pass_parallel` does the same on every core."""
    moved = 0
    for p in range(x.shape[0]):
        moved += _attach(x, anchor, reach, tau, p)
    return moved


@numba.njit(cache=True, parallel=True)
def attachment_pass_parallel(x, anchor, reach, tau):
    """:func:`attachment_pass` on every core: each particle moves only itself and reads only pins,
    which no attachment moves, so the same bits at any thread count."""
    moved = 0
    for p in numba.prange(x.shape[0]):
        moved += _attach(x, anchor, reach, tau, p)
    return moved


@numba.njit(cache=True, inline="always")
def _push(heap, size, s):
    """``s`` onto the binary min-heap ``heap[:size]``; returns the new size."""
    k = size
    heap[k] = s
    while k > 0:
        up = (k - 1) // 2
        if heap[up] <= s:
            break
        heap[k] = heap[up]
        k = up
    heap[k] = s
    return size + 1


@numba.njit(cache=True, inline="always")
def _pop(heap, size):
    """The least of ``heap[:size]`` and the new size."""
    top = heap[0]
    size -= 1
    last = heap[size]
    k = 0
    while True:
        c = 2 * k + 1
        if c >= size:
            break
        if c + 1 < size and heap[c + 1] < heap[c]:
            c += 1
        if heap[c] >= last:
            break
        heap[k] = heap[c]
        k = c
    heap[k] = last
    return top, size


@numba.njit(cache=True, inline="always")
def _attach_all(x, anchor, reach, tau, moved):
    """Every particle's attachments (:func:`attachment_pass`), the moved ones listed in
    ``moved``; returns how many."""
    n = 0
    for p in range(x.shape[0]):
        if _attach(x, anchor, reach, tau, p):
            moved[n] = p
            n += 1
    return n


class PassWork(NamedTuple):
    """What :func:`provot_passes` keeps from call to call (:class:`_PassScratch` makes it once per
    spring set): each particle's limited springs (CSR ``inc_ptr``, ``inc``, in the springs'
    order); the ``clock`` (one entry); ``by_spring`` (3 rows: the heap, the next pass's springs,
    and the stamps of those queued) and ``by_particle`` (4 rows: the stamps of those listed as
    moved, the last spring that moved each in the pass, the lists of the moved and of those the
    attachments moved): the stamps kept, the rest scratch."""

    inc_ptr: np.ndarray
    inc: np.ndarray
    clock: np.ndarray
    by_spring: np.ndarray
    by_particle: np.ndarray


class Attachments(NamedTuple):
    """The long-range attachments :func:`provot_passes` applies: each particle's nearest pins
    ``anchor`` and its rest geodesic distances to them ``reach`` (:func:`_attach`), and whether
    they are on (``on``; off: :data:`NO_ANCHOR`, :data:`NO_REACH`)."""

    anchor: np.ndarray
    reach: np.ndarray
    on: bool


@numba.njit(cache=True)
def provot_passes(x, springs, rest, tau, tol, pinned, passes, share, tethers, work):
    """What :meth:`StrainLimit.correct` does with Provot's passes: with ``attach``, the long-range
    attachments first; then up to ``passes`` of :func:`provot_pass`, stopping after one that
    shortens nothing, each followed by the attachments if it shortened something; returns how
    many of these changed something. The same corrections in the same order, so the same bits,
    but a pass after the first visits only the springs that can have changed since their last
    visit, those at a particle moved after it (a spring neither of whose ends moved is as that
    visit left it, within its bound), in the springs' order (a heap), unless they are more than
    ``1/share`` of all (:data:`FULL_PASS_SHARE`; 0: never); and the attachments after a pass look
    only at the particles moved since they last did (one they put at its bound is looked at
    again: a rounding can leave it over). A cloth over a table's edge at 128×128 has ~20 springs
    over the limit after a step and takes 20 passes, each of which visited all 64,000 springs
    (docs/BENCHMARKS.md §11).

    ``tethers``: the attachments (:class:`Attachments`' fields as a plain tuple); ``work``: the
    topology, stamps and scratch (:class:`PassWork`'s, alike). (Twenty separate arguments of
    these types made numba's dispatcher keep 400 bytes a call, never freed.)"""
    # (the bundles' fields, passed as plain tuples: numba types a NamedTuple argument on a slow
    # path, ~1 µs a call, keeping objects for its first hundreds of calls)
    anchor, reach, attach = tethers
    inc_ptr, inc, clock, by_spring, by_particle = work
    heap, nxt, queued = by_spring[0], by_spring[1], by_spring[2]
    listed, last = by_particle[0], by_particle[1]
    n_springs = springs.shape[0]
    stamp = clock[0]
    used = 0
    n_next = 0
    moved, carried = by_particle[2], by_particle[3]
    n_moved = n_carried = 0  # particles moved in the pass; moved by the last attachments
    if attach:
        n_carried = _attach_all(x, anchor, reach, tau, carried)
        if n_carried:
            used = 1
    for pas in range(passes):
        stamp += 3  # this pass's: listed as moved (stamp), queued (stamp + 1), next (stamp + 2)
        corrected = 0
        n_moved = 0
        full = pas == 0 or n_next * share > n_springs
        size = 0
        if not full:
            for q in range(n_next):
                t = nxt[q]
                queued[t] = stamp + 1
                size = _push(heap, size, t)
        if full:  # every spring: the step moved every particle, or many changed
            for s in range(n_springs):
                i, j = springs[s, 0], springs[s, 1]
                if not _shorten(x, i, j, pinned[i], pinned[j], rest[s], tau, tol):
                    continue
                corrected += 1
                # the passes visit in the springs' order: the latest is the last (the moved
                # particles are listed after the pass, where few moved)
                last[i] = last[j] = s
                listed[i] = listed[j] = stamp
            if 2 * corrected * share <= n_springs:
                for p in range(x.shape[0]):
                    if listed[p] == stamp:
                        moved[n_moved] = p
                        n_moved += 1
            else:
                n_moved = 2 * corrected  # many (or none): the list is not needed
        # (the full pass has a loop of its own: 1.5× as fast as the heap's with a branch)
        while size > 0:  # the springs that may have changed, in order
            s, size = _pop(heap, size)
            i, j = springs[s, 0], springs[s, 1]
            if not _shorten(x, i, j, pinned[i], pinned[j], rest[s], tau, tol):
                continue
            corrected += 1
            for end in range(2):
                p = j if end else i
                last[p] = s
                if listed[p] != stamp:
                    listed[p] = stamp
                    moved[n_moved] = p
                    n_moved += 1
                for q in range(inc_ptr[p], inc_ptr[p + 1]):  # its springs still to visit
                    t = inc[q]
                    if t > s and queued[t] != stamp + 1:
                        queued[t] = stamp + 1
                        size = _push(heap, size, t)
        if corrected == 0:
            break
        used += 1
        # the next pass's springs: at a particle moved after their visit in this one (unless
        # so many particles moved that the next pass visits every spring anyway)
        n_next = 0
        many = n_moved * share > n_springs  # (n_moved is a bound where not listed)
        if many:
            n_next = n_springs  # (the next pass is a full one)
        else:
            for k in range(n_moved):
                p = moved[k]
                for q in range(inc_ptr[p], inc_ptr[p + 1]):
                    t = inc[q]
                    if t < last[p] and queued[t] != stamp + 2:
                        queued[t] = stamp + 2
                        nxt[n_next] = t
                        n_next += 1
        if attach:
            if many:  # every particle's attachments (as a full pass visits every spring)
                n_carried = _attach_all(x, anchor, reach, tau, carried)
                continue
            # the particles this pass moved, and those the last attachments moved
            for k in range(n_carried):
                p = carried[k]
                if listed[p] != stamp:
                    listed[p] = stamp
                    moved[n_moved] = p
                    n_moved += 1
            n_carried = 0
            for k in range(n_moved):
                p = moved[k]
                if _attach(x, anchor, reach, tau, p):
                    carried[n_carried] = p
                    n_carried += 1
                    for q in range(inc_ptr[p], inc_ptr[p + 1]):  # all its springs again
                        t = inc[q]
                        if queued[t] != stamp + 2:
                            queued[t] = stamp + 2
                            nxt[n_next] = t
                            n_next += 1
    clock[0] = stamp + 3
    return used


@numba.njit(cache=True)
def follow_corrections(x, before, start, v, gain, mean):
    """``v += gain·Δx`` per particle, ``Δx = x − before`` shortened to at most ``|before −
    start|``; with ``mean``, a corrected particle's velocity is first set to ``gain·(before −
    start)``, its mean over the step."""
    for p in range(x.shape[0]):
        d0, d1, d2 = x[p, 0] - before[p, 0], x[p, 1] - before[p, 1], x[p, 2] - before[p, 2]
        corr2 = d0 * d0 + d1 * d1 + d2 * d2
        if corr2 == 0.0:
            continue
        m0, m1, m2 = (
            before[p, 0] - start[p, 0],
            before[p, 1] - start[p, 1],
            before[p, 2] - start[p, 2],
        )
        move2 = m0 * m0 + m1 * m1 + m2 * m2
        scale = gain
        if corr2 > move2:
            scale *= np.sqrt(move2 / corr2)
        if mean:
            v[p, 0] = gain * m0
            v[p, 1] = gain * m1
            v[p, 2] = gain * m2
        v[p, 0] += scale * d0
        v[p, 1] += scale * d1
        v[p, 2] += scale * d2


#: no anchors (a cloth whose attachments are off): what :func:`provot_passes` is given then
NO_ANCHOR = np.full((1, 1), -1, np.int64)
NO_REACH = np.zeros((1, 1))

keep_true(__name__)  # (its kernels compile again when a file it imports changes)
