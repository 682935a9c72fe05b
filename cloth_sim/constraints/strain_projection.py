"""The strain limit as one projection of every over-stretched spring at once.

Provot's passes (:mod:`cloth_sim.constraints.strain_limit`) shorten one spring at a time, so a
correction travels one spring per pass: a hanging 64×64 cloth kept its worst strain at 0.119
against τ = 0.1 however many passes it was given (20: 0.119, 40: 0.120). This stage instead solves
for all the springs longer than ``(1 + τ)·L`` together — Goldenthal, Harmon, Fattal, Bercovier &
Grinspun (2007), "Efficient simulation of inextensible cloth", *fast projection*: with ``C_s = l_s
− (1 + τ)L_s`` over the active springs ``A``, ``J = ∂C/∂x`` and ``W`` the inverse masses (0 for a
pin), each iteration takes the smallest mass-weighted change of the positions that zeroes the
linearised constraints,

    (J W Jᵀ + ε I) λ = C,        Δx = −W Jᵀ λ,

then recomputes the lengths. Springs found too long after an iteration join ``A`` until no spring
exceeds ``(1 + τ + tol)·L`` (``tol``: :data:`TOLERANCE`); after the first iteration only the
springs of the particles it moved are measured again. A spring of ``A`` within its bound is held
at its length (``C_s = 0``), never pulled out to the bound: the projection adds no stretch. ``A``
only grows within a step.

Each solve moves the set's particles, which stretches the ring of springs around the set: left to
itself the set grows by about a ring an iteration (128×128 at the bottom of the swing: 14,000
springs, and 20 iterations were not enough). So the first iteration's set also takes the last
step's springs still within :data:`WARM_START` of their bound — held at their length if within it —
which is most of the ring-by-ring growth at once. Tried and dropped: letting a spring within its
bound whose ``λ`` came out negative (pushed out) leave the set and solving again — with the loose
solves below ``λ``'s sign near 0 is noise, and the set cycled. (Both measured: docs/BENCHMARKS.md
§7.)

The system is solved by conjugate gradients, matrix-free, over the active springs and their
particles only (a compact numbering, so a step with a few hundred active springs touches a few
hundred), and loosely (:data:`CG_TOLERANCE`): the next iteration linearises again anyway. Its
preconditioner is the system's blocks along **chains**: the springs that go on straight through
a particle (:func:`chain_neighbours`: on a grid its rows, columns and diagonals) couple only to
the ones before and after them, so a chain's block is tridiagonal and ``L D Lᵀ`` solves it
exactly in O(length). A hanging cloth's load runs down such chains, 64 springs long at 64×64:
the diagonal alone (Jacobi) saw each as a 1-D Laplacian and took ~32 CG iterations a solve to
bring its residual to 0.3 of the first; the chains take ~6 (the same bound, about the same set,
the projection 2–3× faster: docs/BENCHMARKS.md §11). A solve's set is numbered chain by chain
(:func:`_chain_order`), so the blocks are consecutive and their solve two passes over the set; a
closed ring of springs is cut where its walk starts. Any pairing keeps the preconditioner
definite: a spring's two couplings, ``w_i |n_a·n_b|`` and ``w_j |n_a·n_c|``, are less than its
diagonal ``w_i + w_j + ε`` together, so each block is diagonally dominant.

``ε`` (:data:`REGULARISATION`, the inverse masses scaled so the largest is 1) keeps the system
definite where the active springs are redundant — the four sides and two diagonals of a quad lying
flat ask six things of its four points' five in-plane freedoms; with ε = 1e-6 a crumpled cloth
with every spring over its bound diverged. Each iteration leaves ``ε/(w_i + w_j + ε)`` of a lone
spring's excess.

What it costs, against Provot's passes, and the preconditioner tried before (symmetric
Gauss–Seidel, not kept): docs/BENCHMARKS.md §3 and §7. The worst case is a crumpled cloth with
every spring over: all active and redundant.

Each iteration moves the particles by ``−W Jᵀ λ``, so the mass-weighted sum of the moves is zero
where no pin takes part: the centre of mass (and the linear momentum, the velocities following the
moves) is kept. A step's first measure of every spring runs in parallel over fixed chunks
(:func:`_over_bound`), merged in the springs' order; the rest runs on one core in a fixed order:
the same bits at any thread count. Nothing the size of the springs is reset a call (``seen`` holds
stamps, the last set is kept as a list): at 128×128 (64,770 springs, ~1,000 active) the serial
measure and resets were 0.13 of the projection's 0.62 ms a step.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from ..kernel_cache import keep_true

#: ``ε``, in units of the largest inverse mass (see the module docstring)
REGULARISATION = 1e-3
#: the projection stops once no spring's strain exceeds ``τ`` by more than this. Each
#: linearisation takes the worst excess down by about the CG's tolerance, and the last ones are
#: the dearest: what is left lies in the redundant constraints' slow modes, 40–70 CG iterations a
#: solve where the first takes 3–4 (hanging 64×64 at the bottom of its swing, ~4,800 springs
#: active). 1e-3 (0.1 % of a spring's rest length) instead of Provot's passes' 1e-4 spares one or
#: two of them: the hanging 64×64 cloth in the node 0.929–0.963 → 0.987–0.988 of real time, its
#: worst strain 0.1001 → 0.1010 (docs/BENCHMARKS.md §11, sixth session)
TOLERANCE = 1e-3
#: most conjugate-gradient iterations per solve
MAX_CG_ITERATIONS = 400
#: a solve stops once its residual is this fraction of the first (loose: the next iteration
#: linearises again anyway; the same worst strain at a third of the cost: docs/BENCHMARKS.md §7)
CG_TOLERANCE = 0.3
#: a spring joins the active set when its strain exceeds ``τ`` by more than this (rounding aside)
_JOIN = 1e-9
#: a spring of the last step's set joins the first iteration's set at once while its strain is
#: within this of ``τ`` (below it: held at its length, not pulled out to the bound; module
#: docstring)
WARM_START = 0.005
#: two springs at a particle continue each other in a chain of the preconditioner when the cosine
#: of their directions is below ``−STRAIGHT`` (the module docstring)
STRAIGHT = 0.9
#: springs a chunk of the first measure (:func:`_over_bound`) takes: fixed, so its chunks, and the
#: set they make, are the same at any thread count
CHUNK = 2048


@numba.njit(cache=True, inline="always")
def _scatter(g, q, k, ea, eb, nrm, lam):
    """``g = Jᵀ λ`` over the ``q`` local particles (row ``a`` of ``J``: ``−n_a`` at end ``ea[a]``,
    ``+n_a`` at ``eb[a]``)."""
    for p in range(q):
        g[p, 0] = 0.0
        g[p, 1] = 0.0
        g[p, 2] = 0.0
    for a in range(k):
        i, j, v = ea[a], eb[a], lam[a]
        g[j, 0] += nrm[a, 0] * v
        g[j, 1] += nrm[a, 1] * v
        g[j, 2] += nrm[a, 2] * v
        g[i, 0] -= nrm[a, 0] * v
        g[i, 1] -= nrm[a, 1] * v
        g[i, 2] -= nrm[a, 2] * v


@numba.njit(cache=True)
def _solve(k, q, work, eps, rel_tol, max_it):
    """CG for ``(J W Jᵀ + ε) λ = c`` from ``λ = 0``, preconditioned by the chains' blocks ``M``
    factored as ``L D Lᵀ`` (``low``: ``L``'s subdiagonal, 0 where a chain starts; ``dinv``:
    ``D⁻¹``; the set is numbered chain by chain); returns its iterations. ``z = M⁻¹ r`` is a
    forward pass (``y``, beside the residual's update) and a backward one (beside ``r·z``)."""
    ea, eb, wl, nrm, g = work.ea, work.eb, work.wl, work.nrm, work.g
    sp = work.spring
    c, low, dinv, lam, r, z, p, ap, y = (
        sp[0],
        sp[1],
        sp[2],
        sp[3],
        sp[4],
        sp[5],
        sp[6],
        sp[7],
        sp[8],
    )
    r0 = 0.0
    prev = 0.0
    for a in range(k):
        lam[a] = 0.0
        p[a] = 0.0
        r[a] = c[a]
        r0 += r[a] * r[a]
        prev = r[a] - low[a] * prev
        y[a] = prev
    goal = rel_tol * rel_tol * r0
    beta = 0.0
    rz = 1.0
    it = 0
    while it < max_it and r0 > 0.0:
        # z = M⁻¹ r (backward), r·z, and the search direction p = z + β p with Jᵀ p and W Jᵀ p
        nxt = 0.0
        rz_new = 0.0
        for a in range(k - 1, -1, -1):
            nxt = y[a] * dinv[a] - (low[a + 1] * nxt if a + 1 < k else 0.0)
            z[a] = nxt
            rz_new += r[a] * nxt
        if it > 0:
            beta = rz_new / rz
        rz = rz_new
        for t in range(q):
            g[t, 0] = 0.0
            g[t, 1] = 0.0
            g[t, 2] = 0.0
        for a in range(k):
            v = z[a] + beta * p[a]
            p[a] = v
            i, j = ea[a], eb[a]
            g[j, 0] += nrm[a, 0] * v
            g[j, 1] += nrm[a, 1] * v
            g[j, 2] += nrm[a, 2] * v
            g[i, 0] -= nrm[a, 0] * v
            g[i, 1] -= nrm[a, 1] * v
            g[i, 2] -= nrm[a, 2] * v
        for t in range(q):
            g[t, 0] *= wl[t]
            g[t, 1] *= wl[t]
            g[t, 2] *= wl[t]
        pap = 0.0
        for a in range(k):
            i, j = ea[a], eb[a]
            v = (
                nrm[a, 0] * (g[j, 0] - g[i, 0])
                + nrm[a, 1] * (g[j, 1] - g[i, 1])
                + nrm[a, 2] * (g[j, 2] - g[i, 2])
                + eps * p[a]
            )
            ap[a] = v
            pap += p[a] * v
        if pap <= 0.0:
            break
        alpha = rz / pap
        rr = 0.0
        prev = 0.0
        for a in range(k):
            lam[a] += alpha * p[a]
            ra = r[a] - alpha * ap[a]
            r[a] = ra
            rr += ra * ra
            prev = ra - low[a] * prev
            y[a] = prev
        it += 1
        if rr <= goal:
            break
    return it


@numba.njit(cache=True)
def _chain_order(k, act, springs, nb, mark, order, link):
    """Renumber the set ``act[:k]`` chain by chain (``nb``: :func:`chain_neighbours`), a chain's
    springs one after the other; ``link[a]``: the particle spring ``a`` shares with spring
    ``a − 1`` of its chain, −1 where a chain starts. ``mark`` (−1 outside the set) is left so."""
    for a in range(k):
        mark[act[a]] = 0  # in the set, not yet placed
    n = 0
    # from the ends of the open chains first (a spring with at most one chain neighbour in the
    # set), then whatever is left, which lies on closed rings: each cut where its walk starts
    for rings in range(2):
        for a in range(k):
            s = act[a]
            if mark[s] != 0:
                continue
            if rings == 0:
                inside = 0
                for e in range(2):
                    t = nb[s, e]
                    if t >= 0 and mark[t] >= 0:
                        inside += 1
                if inside == 2:
                    continue
            before = -1
            joint = -1
            cur = s
            while True:
                order[n] = cur
                link[n] = joint
                mark[cur] = 1
                n += 1
                nxt = -1
                for e in range(2):
                    t = nb[cur, e]
                    if t >= 0 and t != before and mark[t] == 0:
                        nxt = t
                        joint = springs[cur, e]
                        break
                if nxt < 0:
                    break
                before = cur
                cur = nxt
    for a in range(k):
        act[a] = order[a]
        mark[order[a]] = -1


@numba.njit(cache=True)
def chain_neighbours(springs, positions, inc_ptr, inc, straight):
    """Per spring and end, the spring that goes on straight through that end, −1 for none: at
    each particle its springs are paired, the most nearly opposite first, while the cosine of
    their directions (away from the particle) is below ``−straight``. On a grid the chains are
    its lines: rows, columns and diagonals. ``inc_ptr``, ``inc``: each particle's springs (CSR)."""
    m = springs.shape[0]
    nb = np.full((m, 2), -1, np.int64)
    most = 0
    for p in range(inc_ptr.shape[0] - 1):
        most = max(most, inc_ptr[p + 1] - inc_ptr[p])
    u = np.empty((most, 3))
    cos = np.empty((most, most))
    taken = np.empty(most, np.uint8)
    for p in range(inc_ptr.shape[0] - 1):
        lo = inc_ptr[p]
        d = inc_ptr[p + 1] - lo
        if d < 2:
            continue
        for h in range(d):
            s = inc[lo + h]
            o = springs[s, 1] if springs[s, 0] == p else springs[s, 0]
            vx = positions[o, 0] - positions[p, 0]
            vy = positions[o, 1] - positions[p, 1]
            vz = positions[o, 2] - positions[p, 2]
            length = np.sqrt(vx * vx + vy * vy + vz * vz)
            u[h, 0] = vx / length
            u[h, 1] = vy / length
            u[h, 2] = vz / length
            taken[h] = 0
        for h in range(d):
            for i in range(h + 1, d):
                cos[h, i] = u[h, 0] * u[i, 0] + u[h, 1] * u[i, 1] + u[h, 2] * u[i, 2]
        while True:  # the most nearly opposite pair left, first in index order on a tie
            best, bh, bi = -straight, -1, -1
            for h in range(d):
                if taken[h]:
                    continue
                for i in range(h + 1, d):
                    if not taken[i] and cos[h, i] < best:
                        best, bh, bi = cos[h, i], h, i
            if bh < 0:
                break
            taken[bh] = 1
            taken[bi] = 1
            sh, si = inc[lo + bh], inc[lo + bi]
            nb[sh, 0 if springs[sh, 0] == p else 1] = si
            nb[si, 0 if springs[si, 0] == p else 1] = sh
    return nb


class Workspace(NamedTuple):
    """The arrays :func:`project` works in (:class:`Scratch` makes them once per spring set):
    each particle's springs (CSR ``inc_ptr``, ``inc``), each spring's chain neighbours ``nb``,
    the last call's set ``prev`` (the warm start), the active set and its chains, the set's
    springs' ends and directions, ``spring``'s nine rows (c, L's subdiagonal, D⁻¹, λ, r, z, p,
    Ap, y), the set's particles with their local numbers and inverse masses, ``g = Jᵀλ``,
    ``stats``: the last call's (iterations, CG iterations, active springs, worst excess strain
    left), the first measure's per chunk (``found``, ``most``), the last set as a list
    (``prev_set``) and ``tally`` (the last stamp in ``seen``, the last set's size)."""

    inc_ptr: np.ndarray
    inc: np.ndarray
    seen: np.ndarray
    cand: np.ndarray
    prev: np.ndarray
    inset: np.ndarray
    act: np.ndarray
    nb: np.ndarray
    mark: np.ndarray
    order: np.ndarray
    link: np.ndarray
    ea: np.ndarray
    eb: np.ndarray
    nrm: np.ndarray
    spring: np.ndarray
    pl: np.ndarray
    loc: np.ndarray
    wl: np.ndarray
    g: np.ndarray
    stats: np.ndarray
    found: np.ndarray
    most: np.ndarray
    prev_set: np.ndarray
    tally: np.ndarray


class Settings(NamedTuple):
    """How far :func:`project` goes: the strain limit ``tau``, the worst excess it stops at
    (``tol``), its most linearisations, the most CG iterations a solve, the regularisation
    ``eps`` and the CG's relative tolerance."""

    tau: float
    tol: float = TOLERANCE
    max_outer: int = 20
    max_cg: int = MAX_CG_ITERATIONS
    eps: float = REGULARISATION
    cg_tol: float = CG_TOLERANCE


class Scratch:
    """The arrays :func:`project` works in, made once per spring set (a step allocates none), and
    the preconditioner's chains, paired by the springs' directions at ``positions`` (the model's
    initial positions: any pairing is valid, a straight one is fast)."""

    def __init__(self, springs: np.ndarray, positions: np.ndarray):
        m, n = len(springs), len(positions)
        # each particle's springs (CSR): after a solve, only the moved particles' springs can have
        # changed length, so only those are measured again (docs/BENCHMARKS.md §7)
        ends = np.concatenate([springs[:, 0], springs[:, 1]]).astype(np.int64)
        order = np.argsort(ends, kind="stable")
        self.inc_ptr = np.zeros(n + 1, np.int64)
        np.add.at(self.inc_ptr, ends + 1, 1)
        self.inc_ptr = np.cumsum(self.inc_ptr)
        self.inc = np.ascontiguousarray(np.r_[np.arange(m), np.arange(m)][order], dtype=np.int64)
        #: per spring and end, the spring it goes on into straight (the preconditioner's chains)
        self.nb = chain_neighbours(
            np.array(springs, np.int64),  # copies: writable, one signature whatever is given
            np.array(positions, np.float64),
            self.inc_ptr,
            self.inc,
            STRAIGHT,
        )
        self.seen = np.full(m, -1, np.int64)
        self.cand = np.empty(m, np.int64)
        self.inset = np.zeros(m, np.uint8)
        self.prev = np.zeros(m, np.uint8)  # the last call's set (the warm start)
        self.act = np.empty(m, np.int64)
        self.mark = np.full(m, -1, np.int64)
        self.order = np.empty(m, np.int64)
        self.link = np.empty(m, np.int64)
        self.ea = np.empty(m, np.int64)
        self.eb = np.empty(m, np.int64)
        self.nrm = np.empty((m, 3))
        self.spring = np.empty((9, m))  # c, L's subdiagonal, D⁻¹, λ, r, z, p, Ap, y
        self.pl = np.empty(n, np.int64)
        self.loc = np.full(n, -1, np.int64)
        self.wl = np.empty(n)
        self.g = np.empty((n, 3))
        #: the last call's (iterations, CG iterations, active springs, worst excess strain left)
        self.stats = np.zeros(4)
        chunks = -(-m // CHUNK)
        self.found = np.zeros(chunks, np.int64)  # the first measure's, per chunk
        self.most = np.zeros(chunks)
        self.prev_set = np.empty(m, np.int64)  # the last call's set, as a list
        #: the last stamp ``seen`` holds, and the size of the last call's set
        self.tally = np.zeros(2, np.int64)

    def workspace(self) -> Workspace:
        return Workspace(
            self.inc_ptr,
            self.inc,
            self.seen,
            self.cand,
            self.prev,
            self.inset,
            self.act,
            self.nb,
            self.mark,
            self.order,
            self.link,
            self.ea,
            self.eb,
            self.nrm,
            self.spring,
            self.pl,
            self.loc,
            self.wl,
            self.g,
            self.stats,
            self.found,
            self.most,
            self.prev_set,
            self.tally,
        )


@numba.njit(cache=True, inline="always")
def _length2(x, springs, w, s):
    """Spring ``s``'s squared length at ``x``; −1 where both its ends are pinned (``w`` 0: no
    projection moves it)."""
    i = springs[s, 0]
    j = springs[s, 1]
    if w[i] == 0.0 and w[j] == 0.0:
        return -1.0
    dx = x[j, 0] - x[i, 0]
    dy = x[j, 1] - x[i, 1]
    dz = x[j, 2] - x[i, 2]
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True, parallel=True)
def _over_bound(x, springs, rest, w, tau, prev, cand, found, worst):
    """A step's first measure of every spring, in parallel over chunks of :data:`CHUNK` springs:
    chunk ``c`` writes the springs that join the set (longer than ``(1 + τ)·L``, or in the last
    call's set ``prev`` and within :data:`WARM_START` of it) to ``cand[c·CHUNK:]`` in their order,
    their number to ``found[c]`` and the worst excess strain among them to ``worst[c]``."""
    m = springs.shape[0]
    for c in numba.prange(found.shape[0]):
        lo = c * CHUNK
        hi = min(lo + CHUNK, m)
        count = 0
        most = 0.0
        for s in range(lo, hi):
            l2 = _length2(x, springs, w, s)
            if l2 < 0.0:
                continue
            b = (1.0 + tau + _JOIN) * rest[s]
            if l2 <= b * b:
                # within its bound: joins only if it was in the last step's set and is near it
                near = (1.0 + tau - WARM_START) * rest[s]
                if not (prev[s] == 1 and l2 > near * near):
                    continue
            else:
                most = max(most, np.sqrt(l2) / rest[s] - 1.0 - tau)
            cand[lo + count] = s
            count += 1
        found[c] = count
        worst[c] = most


@numba.njit(cache=True)
def project(x, springs, rest, w, settings, work):
    """Shorten every spring of ``springs`` (``(m, 2)``, rest lengths ``rest``) to at most
    ``(1 + tau)·rest``, to within ``tol`` of strain (``settings``: :class:`Settings`), by fast
    projection (module docstring), moving ``x`` in place; ``w`` the particles' inverse masses (0:
    pinned), scaled so a free particle's are about 1. ``work``: :class:`Scratch`'s arrays
    (:class:`Workspace`); its ``prev`` (the last call's set) is read and then replaced by this
    call's. Returns the iterations (linearise and solve) it took; ``work.stats``: those, the CG
    iterations, the active springs and the worst excess strain left."""
    tau, tol, max_outer = settings.tau, settings.tol, settings.max_outer
    max_cg, eps, cg_tol = settings.max_cg, settings.eps, settings.cg_tol
    inc_ptr, inc, seen, cand, prev = work.inc_ptr, work.inc, work.seen, work.cand, work.prev
    inset, act, nb, mark, order, link = (
        work.inset,
        work.act,
        work.nb,
        work.mark,
        work.order,
        work.link,
    )
    ea, eb, nrm, pl, loc, wl, g = work.ea, work.eb, work.nrm, work.pl, work.loc, work.wl, work.g
    stats, spring = work.stats, work.spring
    found, most, prev_set, tally = work.found, work.most, work.prev_set, work.tally
    c, low, dinv, lam = spring[0], spring[1], spring[2], spring[3]
    # ``inset`` is all 0 between calls; ``seen`` holds stamps, each measure after a solve a new
    # one, going on from the last call's: no array the size of the springs is reset
    stamp = tally[0]
    # int64 from the start: a literal 0, reassigned later, made numba compile _solve and
    # _chain_order for it too
    k = np.int64(0)
    q = np.int64(0)
    cg_total = 0
    outer = 0
    worst = 0.0
    while True:
        # the springs now too long join the set; the worst excess decides whether to go on. First
        # every spring, in parallel; after a solve, the springs of the particles it moved (the
        # others' lengths are as they were: within the bound, or in the set, whose springs all
        # moved)
        worst = 0.0
        if outer == 0:
            _over_bound(x, springs, rest, w, tau, prev, cand, found, most)
            for h in range(found.shape[0]):
                worst = max(worst, most[h])
                for u in range(h * CHUNK, h * CHUNK + found[h]):
                    s = cand[u]
                    inset[s] = 1
                    act[k] = s
                    k += 1
        else:
            stamp += 1
            count = 0
            for t in range(q):
                pp = pl[t]
                for h in range(inc_ptr[pp], inc_ptr[pp + 1]):
                    s = inc[h]
                    if seen[s] != stamp:
                        seen[s] = stamp
                        cand[count] = s
                        count += 1
            for u in range(count):
                s = cand[u]
                l2 = _length2(x, springs, w, s)
                if l2 < 0.0:
                    continue
                b = (1.0 + tau + _JOIN) * rest[s]
                if l2 <= b * b:
                    continue
                worst = max(worst, np.sqrt(l2) / rest[s] - 1.0 - tau)
                if inset[s] == 0:
                    inset[s] = 1
                    act[k] = s
                    k += 1
        if worst <= tol or outer >= max_outer:
            break
        # the set chain by chain, and its particles numbered locally
        _chain_order(k, act, springs, nb, mark, order, link)
        q = np.int64(0)
        for a in range(k):
            s = act[a]
            i = springs[s, 0]
            j = springs[s, 1]
            if loc[i] < 0:
                loc[i] = q
                pl[q] = i
                wl[q] = w[i]
                q += 1
            if loc[j] < 0:
                loc[j] = q
                pl[q] = j
                wl[q] = w[j]
                q += 1
            ea[a] = loc[i]
            eb[a] = loc[j]
        # the linearised constraints, and the chains' blocks of J W Jᵀ + ε factored: a spring's
        # diagonal w_i + w_j + ε, and ±w_p n_a·n_b with the one before it in its chain (p the
        # particle they share; − where p ends one spring and starts the other)
        for a in range(k):
            s = act[a]
            i = springs[s, 0]
            j = springs[s, 1]
            dx = x[j, 0] - x[i, 0]
            dy = x[j, 1] - x[i, 1]
            dz = x[j, 2] - x[i, 2]
            l = np.sqrt(dx * dx + dy * dy + dz * dz)
            nrm[a, 0] = dx / l
            nrm[a, 1] = dy / l
            nrm[a, 2] = dz / l
            c[a] = max(l - (1.0 + tau) * rest[s], 0.0)  # within the bound: held, not pulled out
            d = wl[ea[a]] + wl[eb[a]] + eps
            low[a] = 0.0
            pj = link[a]
            if pj >= 0:
                before = act[a - 1]
                sign = (1.0 if springs[before, 1] == pj else -1.0) * (
                    1.0 if springs[s, 1] == pj else -1.0
                )
                off = (
                    sign
                    * w[pj]
                    * (
                        nrm[a - 1, 0] * nrm[a, 0]
                        + nrm[a - 1, 1] * nrm[a, 1]
                        + nrm[a - 1, 2] * nrm[a, 2]
                    )
                )
                low[a] = off * dinv[a - 1]
                d -= low[a] * off
            dinv[a] = 1.0 / d
        cg_total += _solve(k, q, work, eps, cg_tol, max_cg)
        _scatter(g, q, k, ea, eb, nrm, lam)
        for t in range(q):
            pp = pl[t]
            wt = wl[t]
            x[pp, 0] -= wt * g[t, 0]
            x[pp, 1] -= wt * g[t, 1]
            x[pp, 2] -= wt * g[t, 2]
            loc[pp] = -1
        outer += 1
    # this call's set becomes the next one's warm start, and ``inset`` all 0 again
    for a in range(tally[1]):
        prev[prev_set[a]] = 0
    for a in range(k):
        s = act[a]
        prev[s] = 1
        prev_set[a] = s
        inset[s] = 0
    tally[0] = stamp
    tally[1] = k
    stats[0] = outer
    stats[1] = cg_total
    stats[2] = k
    stats[3] = worst
    return outer


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
