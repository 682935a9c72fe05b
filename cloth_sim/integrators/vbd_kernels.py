"""The kernels of :mod:`cloth_sim.integrators.vbd` (Vertex Block Descent), apart from the
:class:`~cloth_sim.integrators.vbd.VBD` class that holds their arrays and calls them:

* set-up: the spring graph's greedy colouring (:func:`colour_groups`), the substeps a cloth needs
  (:func:`substeps_needed`);
* self-contact: the candidate pairs' nearest points and normals (:func:`contact_pairs`) and each
  vertex's records of them (:func:`contact_records`, :func:`pack_records`);
* the iteration: a colour's sweep (:func:`sweep`: a vertex's Newton step on its springs, bending,
  colliders and self-contact, held within its bounds), the colours in parallel
  (:func:`iterate_parallel`), Chebyshev's extrapolation (:func:`chebyshev`), the initial guess,
  the velocities at the step's end and BDF2's start;
* the colliders' hold on a vertex's motion (:func:`collider_allowances`) and whether a moving
  collider overtook the cloth (:func:`overtaken`).

The method, its bounds and its counters: :mod:`cloth_sim.integrators.vbd`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..contact.collider_kernels import MESH, beyond_reach, collider_distance
from ..contact.geometry import segment_parameters, triangle_weights
from ..contact.triangle_meshes import mesh_closed
from ..kernel_cache import keep_true
from ..physics.bending import bending_row
from .vbd_contact import colliders_at, onset, solve3, truncate, within
from .vbd_terms import local_energy, self_contacts_at, springs_at

#: how far a vertex may move between two searches besides that bound: (a, b) for a·τ + b·|its
#: motion to the step's initial guess| (a search then serves the next steps while they stay
#: within). The guess, not the inertia: a vertex lying on the table or on another layer has
#: gravity's h²·g in its inertia and never moves it, and reaching that far multiplied the pairs
#: measured (docs/BENCHMARKS.md §3h)
ALLOWANCE = (0.1, 1.0)
#: without self-contact, a vertex farther than this many times its allowance from every
#: collider's skin is held within that distance for the step and skips the colliders' terms
#: (:func:`collider_allowances`); the hold binds only a vertex moving FAR times farther than its
#: way to the step's initial guess
FAR = 4.0
#: where ``substeps`` is not given, a step is cut into substeps until every vertex's
#: stiffness-to-inertia ratio over a substep is at most this (measured: the fewest sweeps a
#: frame on cotton hanging at 32×32 and 64×64 at ratios of 10–30; docs/convergence.md)
SUBSTEP_RATIO = 25.0
#: the most substeps a step is cut into where they are chosen
MAX_SUBSTEPS = 64


# ---------------------------------------------------------------------------- set-up
@numba.njit(cache=True)
def colour_greedy(ptr, nbr, free):
    """Colour of each free vertex (``-1`` for the others): the smallest colour none of its
    neighbours (CSR ``ptr``, ``nbr``) has taken, in vertex order."""
    n = ptr.shape[0] - 1
    colour = np.full(n, -1, np.int64)
    taken = np.full(64, -1, np.int64)  # taken[c] == i: colour c is a neighbour's of vertex i
    for i in range(n):
        if not free[i]:
            continue
        for q in range(ptr[i], ptr[i + 1]):
            c = colour[nbr[q]]
            if c >= 0:
                if c >= taken.shape[0]:
                    grown = np.full(2 * c + 2, -1, np.int64)
                    grown[: taken.shape[0]] = taken
                    taken = grown
                taken[c] = i
        c = 0
        while c < taken.shape[0] and taken[c] == i:
            c += 1
        colour[i] = c
    return colour


def colour_groups(springs: np.ndarray, n: int, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(ptr, verts)``: colour ``c``'s vertices are ``verts[ptr[c]:ptr[c+1]]``, in increasing
    order; no two vertices of a colour share a spring. Pinned vertices are in none."""
    a = np.concatenate([springs[:, 0], springs[:, 1]])
    b = np.concatenate([springs[:, 1], springs[:, 0]])
    order = np.lexsort((b, a))
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(a, minlength=n), out=ptr[1:])
    colour = colour_greedy(ptr, np.ascontiguousarray(b[order]), np.ascontiguousarray(free))
    verts = np.flatnonzero(colour >= 0)
    verts = verts[np.argsort(colour[verts], kind="stable")]
    counts = np.bincount(colour[colour >= 0], minlength=max(int(colour.max()) + 1, 0))
    cptr = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=cptr[1:])
    return cptr, np.ascontiguousarray(verts, dtype=np.int64)


def summed_at(ptr, values) -> np.ndarray:
    """Per vertex, the sum of its springs' ``values`` (``ptr``: the vertices' springs, CSR;
    ``values`` in that order)."""
    n = len(ptr) - 1
    owner = np.repeat(np.arange(n), np.diff(ptr))  # each vertex's springs, in CSR order
    return np.bincount(owner, weights=values, minlength=n)


def substeps_needed(ptr, k, c, bdiag, masses, free, dt, cap: int = MAX_SUBSTEPS) -> int:
    """The fewest substeps (at most ``cap``) of a step of ``dt`` in which every free
    vertex's ``(h²·Σk + h·Σc + h²·Q_ii)/m`` is at most :data:`SUBSTEP_RATIO`: ``ptr`` the
    vertices' springs (CSR), ``k``, ``c`` their stiffness and damping in that order, ``bdiag`` the
    bending's diagonal (empty for none). What :meth:`VBD.substeps_for` chooses, and the CUDA
    backend with it."""
    ks, cs = summed_at(ptr, k), summed_at(ptr, c)
    if len(bdiag):
        ks = ks + bdiag
    ratio = (dt * dt * ks + dt * cs)[free] / masses[free]
    worst = float(ratio.max()) if len(ratio) else 0.0
    steps = math.ceil(math.sqrt(worst / SUBSTEP_RATIO)) if worst > SUBSTEP_RATIO else 1
    return min(cap, steps)


def csr(owner: np.ndarray, item: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR of ``item`` grouped by ``owner`` (in ``item``'s order within an owner)."""
    order = np.argsort(owner, kind="stable")
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=ptr[1:])
    return ptr, np.ascontiguousarray(item[order], dtype=np.int64)


def allowances(x, y, tau):
    """How far each vertex at ``x`` may move before it is searched again, :data:`ALLOWANCE`:
    ``a·τ`` and ``b`` times its way to ``y``, the step's initial guess."""
    return ALLOWANCE[0] * tau + ALLOWANCE[1] * np.linalg.norm(y - x, axis=1)


@numba.njit(cache=True, parallel=True)
def contact_pairs(x, vt, ee, tris, edges, tri_edge, edge_owner, vertex_owner):
    """Every candidate pair as its four vertices, the weights of its nearest points and the unit
    normal between them at ``x``: a vertex–triangle pair ``(p; a, b, c)`` with weights ``(1, −w_a,
    −w_b, −w_c)``, an edge pair ``(a, b; c, d)`` with ``(1 − s, s, −(1 − t), −t)``, so that ``n·Σ_k
    w_k x_k`` is their distance along ``n`` (where the two touch, the triangle's normal or the
    normal to both edges); and whether the pair carries the contact energy.

    Every pair bounds its vertices' motion (:func:`.truncate`); the energy is carried by each
    contact once, as Bridson, Fedkiw & Anderson (2002) count them: a vertex against the inside of a
    triangle's face, or against an edge or a corner of the other cloth only from the triangle that
    owns it (its first), and two edges whose nearest points lie inside both. Counting a vertex
    against every triangle within reach (two layers lying together have six of the other layer
    near each vertex) made a T-shirt's contact 4× the work; counting only faces left a vertex
    sliding over an edge of the other layer without support for a step."""
    nv = vt.shape[0]
    m = nv + ee.shape[0]
    idx = np.empty((m, 4), np.int64)  # (every row written; a normal only where there is one)
    coef = np.empty((m, 4))
    nrm = np.zeros((m, 3))
    energy = np.empty(m, np.bool_)
    for q in numba.prange(m):  # each candidate in its own row (the same rows at any thread count)
        if q < nv:
            p, t = vt[q, 0], vt[q, 1]
            a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
            wa, wb, wc = triangle_weights(x, p, a, b, c)
            if wa > 0.0 and wb > 0.0 and wc > 0.0:
                energy[q] = True
            elif wa >= 1.0 or wb >= 1.0 or wc >= 1.0:  # nearest a corner: from its owner only
                energy[q] = vertex_owner[a if wa >= 1.0 else (b if wb >= 1.0 else c)] == t
            else:  # nearest an edge: from its owner only
                energy[q] = (
                    edge_owner[tri_edge[t, 0 if wc == 0.0 else (1 if wa == 0.0 else 2)]] == t
                )
            dx = x[p, 0] - (wa * x[a, 0] + wb * x[b, 0] + wc * x[c, 0])
            dy = x[p, 1] - (wa * x[a, 1] + wb * x[b, 1] + wc * x[c, 1])
            dz = x[p, 2] - (wa * x[a, 2] + wb * x[b, 2] + wc * x[c, 2])
            ux, uy, uz = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
            vx, vy, vz = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
            idx[q, 0], idx[q, 1], idx[q, 2], idx[q, 3] = p, a, b, c
            coef[q, 0], coef[q, 1], coef[q, 2], coef[q, 3] = 1.0, -wa, -wb, -wc
        else:
            e = q - nv
            a, b = edges[ee[e, 0], 0], edges[ee[e, 0], 1]
            c, d_ = edges[ee[e, 1], 0], edges[ee[e, 1], 1]
            sv, tv = segment_parameters(x, a, b, c, d_)
            energy[q] = 0.0 < sv < 1.0 and 0.0 < tv < 1.0
            dx = (x[a, 0] + sv * (x[b, 0] - x[a, 0])) - (x[c, 0] + tv * (x[d_, 0] - x[c, 0]))
            dy = (x[a, 1] + sv * (x[b, 1] - x[a, 1])) - (x[c, 1] + tv * (x[d_, 1] - x[c, 1]))
            dz = (x[a, 2] + sv * (x[b, 2] - x[a, 2])) - (x[c, 2] + tv * (x[d_, 2] - x[c, 2]))
            ux, uy, uz = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
            vx, vy, vz = x[d_, 0] - x[c, 0], x[d_, 1] - x[c, 1], x[d_, 2] - x[c, 2]
            idx[q, 0], idx[q, 1], idx[q, 2], idx[q, 3] = a, b, c, d_
            coef[q, 0], coef[q, 1], coef[q, 2], coef[q, 3] = 1.0 - sv, sv, -(1.0 - tv), -tv
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d < 1e-12:  # touching: the triangle's normal, or the normal to both edges
            dx, dy, dz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d > 0.0:
            nrm[q, 0], nrm[q, 1], nrm[q, 2] = dx / d, dy / d, dz / d
    return idx, coef, nrm, energy


#: the runs of pairs :func:`contact_records` counts and fills on the cores at once (a fixed
#: number: the records are the same whatever the threads)
RECORD_RUNS = 8


@numba.njit(cache=True, parallel=True)
def contact_records(n, idx, coef, energy):
    """Per vertex, the pairs it is in (CSR of ``4·pair + slot``, in pair order): those that carry
    the energy, and all of them, ``(ptr, rec, all_ptr, all_rec)``. One counting sort for both, its
    pairs cut into :data:`RECORD_RUNS` runs in order, each run counted and then filled on a core of
    its own from where the runs before it end for each vertex, so each vertex's records stay in
    pair order: the serial sort's arrays, 0.47 → 0.30 ms a search on the resting T-shirt (two
    cores)."""
    m = idx.shape[0]
    size = (m + RECORD_RUNS - 1) // RECORD_RUNS
    count = np.zeros((RECORD_RUNS, n), np.int64)
    acount = np.zeros((RECORD_RUNS, n), np.int64)
    for b in numba.prange(RECORD_RUNS):
        for q in range(b * size, min(m, (b + 1) * size)):
            for slot in range(4):
                if coef[q, slot] != 0.0:
                    acount[b, idx[q, slot]] += 1
                    if energy[q]:
                        count[b, idx[q, slot]] += 1
    ptr = np.zeros(n + 1, np.int64)
    aptr = np.zeros(n + 1, np.int64)
    for i in range(n):  # each run's first slot for each vertex, in place of its count
        e, a = ptr[i], aptr[i]
        for b in range(RECORD_RUNS):
            c, ac = count[b, i], acount[b, i]
            count[b, i], acount[b, i] = e, a
            e += c
            a += ac
        ptr[i + 1], aptr[i + 1] = e, a
    rec = np.empty(ptr[n], np.int64)
    arec = np.empty(aptr[n], np.int64)
    for b in numba.prange(RECORD_RUNS):
        for q in range(b * size, min(m, (b + 1) * size)):
            for slot in range(4):
                if coef[q, slot] != 0.0:
                    v = idx[q, slot]
                    arec[acount[b, v]] = 4 * q + slot
                    acount[b, v] += 1
                    if energy[q]:
                        rec[count[b, v]] = 4 * q + slot
                        count[b, v] += 1
    return ptr, rec, aptr, arec


@numba.njit(cache=True, parallel=True)
def pack_records(rec, idx, coef, nrm, colour):
    """The energy records ``rec`` (``4·pair + slot``, each vertex's in a run:
    :func:`contact_records`) with their pairs' data copied in, record by record: ``(vertices
    (R, 4), weights (R, 5): the pair's four and then the record's own, normal (R, 3))``; a
    vertex of the record's own vertex's ``colour`` (another than itself) is stored as ``−v − 1``
    (:func:`~cloth_sim.integrators.vbd_terms.self_contacts_at` reads it where the iteration
    began). A sweep reads a vertex's records in a row: one iteration on the settled T-shirt
    (42,990 records, two threads) took 1.27 ms reading each pair's rows of ``idx``, ``coef`` and
    ``nrm`` through its record and each partner's colour, 0.95 ms reading these (the same bits);
    making them costs ~0.25 ms a search."""
    m = rec.shape[0]
    rv, rw, rn = np.empty((m, 4), np.int64), np.empty((m, 5)), np.empty((m, 3))
    for q in numba.prange(m):  # (each record its own row: the same at any thread count)
        pair = rec[q] // 4
        own = idx[pair, rec[q] % 4]
        for slot in range(4):
            v = idx[pair, slot]
            rv[q, slot] = -v - 1 if v != own and colour[v] == colour[own] else v
            rw[q, slot] = coef[pair, slot]
        rw[q, 4] = coef[pair, rec[q] % 4]
        for k in range(3):
            rn[q, k] = nrm[pair, k]
    return rv, rw, rn


@numba.njit(cache=True, parallel=True)
def nearest_distances(ptr, rec, dist):
    """Each vertex's nearest pair distance over its records (``inf``: none)."""
    n = ptr.shape[0] - 1
    out = np.full(n, np.inf)
    for i in numba.prange(n):
        for q in range(ptr[i], ptr[i + 1]):
            out[i] = min(out[i], dist[rec[q] // 4])
    return out


# ---------------------------------------------------------------------------- the iteration
@numba.njit(cache=True, error_model="numpy")
def sweep(verts, lo, hi, state, inertia, sp, co, sc, law, bounds, out):
    """The Newton steps of vertices ``verts[lo:hi]`` in order, each on the incremental potential,
    written to its row of ``x``, within its bounds (:func:`.truncate`). The bundles:

    * ``state = (x, xt, y, xs)``: the iterate (written), the step's start, the inertial target,
      the iterate as this iteration began (what a vertex reads of its own colour's);
    * ``inertia = (m_h2, inv_h, drag_h)``: each vertex's ``m/h²``, ``1/h``, the drag's ``d/h``;
    * ``sp``: each vertex's springs (CSR: the other end, rest length, k, c, kind, in the vertex's
      order), Choi–Ko's table, whether any is not smooth, and the bending's rows;
    * ``co``: the colliders (:class:`~cloth_sim.contact.collider_kernels.PackedColliders`);
      ``sc``: the self-contact records and pairs (:meth:`VBD._records`);
    * ``law = (τ, the colliders' penalty stiffness, friction's ε, self-contact's stiffness and
      μ, γ)``; ``bounds = (x_cd, allow, near)``: where the last search was made, each vertex's
      allowance, and whether it may touch a collider;
    * ``out = (stepped, cut, touch, seen)``: each vertex's squared force, whether its step was
      cut, whether it touches something, and each collider's distance and normal at it
      (:func:`.colliders_at`; written).

    (The arrays are unpacked here, once a chunk: unpacked per vertex, or passed one by one to a
    function per vertex, their reference counting cost more than the vertex's work.)"""
    x, xt, y, xs = state
    m_h2, inv_h, drag_h = inertia
    tau, kc, eps, ks, mu_self, gamma = law
    x_cd, allow, near = bounds
    stepped, cut, touch, seen = out
    inc_ptr, nbr, rest, k, c, kind, tab, nonsmooth, bptr, bidx, bval, bdiag = sp
    springs = (inc_ptr, nbr, rest, k, c, kind, tab)
    bend = (bptr, bidx, bval, bdiag)
    ckind, cpos, crot, cgeo, cmu = co.kinds, co.pos, co.rot, co.geo, co.mu
    cpos0, crot0, cbank = co.pos0, co.rot0, (co.reals, co.ints, co.starts)
    pose, pose0 = (cpos, crot, co.reach), (cpos0, crot0)
    shapes = (ckind, cpos, crot, cgeo, co.reals, co.ints, co.starts)
    rec_ptr, rec_v, rec_w, rec_n, gptr, grec, pidx, pcoef, pnrm, pdist, dmin, rec_d = sc
    records = (rec_ptr, rec_v, rec_w, rec_n, rec_d)
    collider_law, self_law = (tau, kc, eps), (tau, ks, mu_self, eps)
    for q in range(lo, hi):
        i = verts[q]
        m = m_h2[i] + drag_h  # the inertia's m/h², and the drag's d/h
        f0 = -m_h2[i] * (x[i, 0] - y[i, 0]) - drag_h * (x[i, 0] - xt[i, 0])
        f1 = -m_h2[i] * (x[i, 1] - y[i, 1]) - drag_h * (x[i, 1] - xt[i, 1])
        f2 = -m_h2[i] * (x[i, 2] - y[i, 2]) - drag_h * (x[i, 2] - xt[i, 2])
        # the vertex's block: its force and Hessian (vbd_terms)
        fh, rough = springs_at(i, x, xt, springs, inv_h, (f0, f1, f2, m, 0.0, 0.0, m, 0.0, m))
        f0, f1, f2, h0, h1, h2, h3, h4, h5 = fh
        if bdiag.shape[0]:
            # the material's bending, quadratic: −(Q x)_i, and Q_ii on the Hessian's diagonal
            b0, b1, b2 = bending_row(x, bptr, bidx, bval, i)
            f0 += b0
            f1 += b1
            f2 += b2
            qd = bdiag[i]
            h0 += qd
            h3 += qd
            h5 += qd
        fh = (f0, f1, f2, h0, h1, h2, h3, h4, h5)
        touch[i] = 0
        if ckind.shape[0] and near[i]:
            f0, f1, f2, h0, h1, h2, h3, h4, h5, touched = colliders_at(
                i, x, xt, ckind, pose, pose0, cgeo, cmu, cbank, collider_law, fh, seen
            )
            fh = (f0, f1, f2, h0, h1, h2, h3, h4, h5)
            if touched:
                touch[i] = 1
        if rec_ptr[i + 1] > rec_ptr[i]:
            touch[i] = 1
            fh = self_contacts_at(i, x, xs, xt, records, self_law, fh)
        f0, f1, f2, h0, h1, h2, h3, h4, h5 = fh
        stepped[i] = f0 * f0 + f1 * f1 + f2 * f2  # its imbalance as the sweep found it
        sx, sy, sz = solve3(h0, h1, h2, h3, h4, h5, f0, f1, f2)
        if touch[i] or near[i]:
            # a contact not yet pressed is not in the Hessian (a self-contact near its onset has
            # its stiffness there: vbd_terms.NEAR): a step past its onset would land deep inside
            # (the next iteration pushing back out: the iterations cycled); the step stops at its
            # onset, where the next iteration sees it
            sx, sy, sz = onset(
                i,
                (sx, sy, sz),
                x,
                (rec_ptr, rec_w, rec_n, rec_d),
                tau,
                ckind.shape[0] if near[i] else 0,  # where colliders_at looked
                shapes,
                seen,
            )
        if rough or nonsmooth:
            # Choi–Ko's energies are not smooth at the rest length (a buckling pair's force jumps
            # at the onset, a tension-only pair's stiffness vanishes): Newton's step may overshoot.
            # Backtrack (halving, at most 8 times) until the vertex's energy does not rise, so each
            # vertex step, and so each iteration, descends
            e0 = local_energy(
                i, (x[i, 0], x[i, 1], x[i, 2]), x, xt, y, m_h2, drag_h, springs, inv_h, bend
            )
            tries = 0
            while (
                local_energy(
                    i,
                    (x[i, 0] + sx, x[i, 1] + sy, x[i, 2] + sz),
                    x,
                    xt,
                    y,
                    m_h2,
                    drag_h,
                    springs,
                    inv_h,
                    bend,
                )
                > e0
            ):
                tries += 1
                if tries > 8:
                    sx = sy = sz = 0.0
                    break
                sx, sy, sz = 0.5 * sx, 0.5 * sy, 0.5 * sz
        nx, ny, nz = x[i, 0] + sx, x[i, 1] + sy, x[i, 2] + sz
        nx, ny, nz, was_cut, settled = within(
            nx, ny, nz, x_cd[i, 0], x_cd[i, 1], x_cd[i, 2], allow[i], dmin[i], gamma
        )
        if not settled:
            nx, ny, nz, was_cut = truncate(
                i, (nx, ny, nz), x_cd, allow, gptr, grec, pidx, pcoef, pnrm, pdist, dmin, gamma
            )
        if was_cut:
            cut[i] = 1
        x[i, 0] = nx
        x[i, 1] = ny
        x[i, 2] = nz


#: a model without bending: empty rows (the kernels test ``bdiag.shape[0]``)
NO_BENDING = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))

#: chunks a colour is cut into for the cores (a fixed number: the result does not depend on it)
CHUNKS = 16


@numba.njit(cache=True, parallel=True)
def iterate_parallel(verts, cptr, state, inertia, sp, co, sc, law, bounds, out):
    """One iteration: the colours in order, each colour's vertices at once, in chunks (each vertex
    writes only its own row; a colour reads other colours' rows and, for contacts, ``xs``)."""
    for col in range(cptr.shape[0] - 1):
        lo, hi = cptr[col], cptr[col + 1]
        size = (hi - lo + CHUNKS - 1) // CHUNKS
        for b in numba.prange(CHUNKS):
            a = lo + b * size
            sweep(verts, a, min(a + size, hi), state, inertia, sp, co, sc, law, bounds, out)


def iterate_serial(verts, cptr, *args):
    """:func:`iterate_parallel` on one core (the same bits): the colours' vertices in order."""
    sweep(verts, 0, len(verts), *args)


@numba.njit(cache=True, error_model="numpy")
def chebyshev(x, x_prev2, omega, free, x_cd, allow, gamma, sc, cut, touch):
    """``x ← ω (x − x_prev2) + x_prev2`` on the free vertices not in contact (extrapolated, a
    contact's penalty made the cloth chatter on a table), within their bounds (:func:`.truncate`);
    ``ω = 1`` only holds them there."""
    _, _, _, _, gptr, grec, pidx, pcoef, pnrm, pdist, dmin, _ = sc
    for i in range(x.shape[0]):
        if not free[i] or touch[i]:
            continue
        px = omega * (x[i, 0] - x_prev2[i, 0]) + x_prev2[i, 0]
        py = omega * (x[i, 1] - x_prev2[i, 1]) + x_prev2[i, 1]
        pz = omega * (x[i, 2] - x_prev2[i, 2]) + x_prev2[i, 2]
        px, py, pz, was_cut, settled = within(
            px, py, pz, x_cd[i, 0], x_cd[i, 1], x_cd[i, 2], allow[i], dmin[i], gamma
        )
        if not settled:
            px, py, pz, was_cut = truncate(
                i, (px, py, pz), x_cd, allow, gptr, grec, pidx, pcoef, pnrm, pdist, dmin, gamma
            )
        x[i, 0], x[i, 1], x[i, 2] = px, py, pz
        if was_cut:
            cut[i] = 1


@numba.njit(cache=True)
def initial_guess(x, y, xt, v, a, free, h, along, gn, gh, adaptive):
    """``y = x^t + h v + h² a`` (``a`` on the free particles only) and the initial guess ``x``:
    ``y``, with gravity's part of the free particles' acceleration ``along`` in ``[0, |g|]``
    instead of all of it where ``adaptive`` (``y`` has all of g: keep ``along``); the kinematic
    particles (pins, held) go to ``x^t + h v``. Each particle's arithmetic in numpy's order."""
    hh = h * h
    for i in range(x.shape[0]):
        for c in range(3):
            yc = v[i, c] * h + xt[i, c]
            if free[i]:
                yc = yc + hh * a[i, c]
            y[i, c] = yc
            if free[i] and adaptive:
                x[i, c] = yc + hh * ((along[i] - gn) * gh[c])
            else:
                x[i, c] = yc


@numba.njit(cache=True)
def step_velocities(x, xt, v, free, h, acc):
    """The step's end: ``v = (x − x^t)/h`` on the free particles (pins keep theirs: they moved by
    ``h v``) and each particle's acceleration ``(x − x^t)/h − v)/h`` into ``acc``."""
    for i in range(x.shape[0]):
        for c in range(3):
            nv = (x[i, c] - xt[i, c]) / h
            acc[i, c] = (nv - v[i, c]) / h
            if free[i]:
                v[i, c] = nv


@numba.njit(cache=True)
def bdf2_start(x, v, past_x, past_v, free, start_x, start_v):
    """BDF2's substep as a backward-Euler one: the state's ``x, v`` kept in ``start_x, start_v``
    and replaced by ``x̂ = (4x − xₙ₋₁)/3``, ``v̂ = (4v − vₙ₋₁)/3`` on the free particles; a
    kinematic one keeps ``x`` and takes ``1.5·v``, so that its step of ``2h/3`` moves it by
    ``h·v``."""
    for i in range(x.shape[0]):
        for c in range(3):
            xi, vi = x[i, c], v[i, c]
            start_x[i, c] = xi
            start_v[i, c] = vi
            if free[i]:
                x[i, c] = (4.0 * xi - past_x[i, c]) / 3.0
                v[i, c] = (4.0 * vi - past_v[i, c]) / 3.0
            else:
                v[i, c] = 1.5 * vi


@numba.njit(cache=True)
def keep_kinematic(v, start_v, free):
    """The kinematic particles' velocities back to their substep's start."""
    for i in range(v.shape[0]):
        if not free[i]:
            for c in range(3):
                v[i, c] = start_v[i, c]


@numba.njit(cache=True, parallel=True)
def collider_allowances(x, allowance, bounded, co, cdepth, tau, allow, near, clear):
    """How far each vertex may move from ``x`` before the next search (``allow``) and whether it
    can come within the thickness of a collider meanwhile (``near``: the iterations look at the
    colliders only for those); ``co``: the colliders
    (:class:`~cloth_sim.contact.collider_kernels.PackedColliders`), ``cdepth`` how far in each
    one's far side is (:meth:`VBD.depths`).

    ``bounded`` (self-contact): ``allowance`` is each vertex's bound whatever the pairs found,
    kept short of the far side of any collider near it. Otherwise ``allowance`` is only the
    vertex's expected motion: it may move without bound, short of the far side of a collider near
    it, except that a vertex farther than :data:`FAR` times that from every collider's skin (``d
    − 1.01 τ``) is held within that distance (its signed distances are 1-Lipschitz, so it cannot
    reach a skin within the step) and is not near: the iterations then skip the colliders' terms
    for it (on a 128×128 cloth over the ball and its floor, every vertex was near, and those
    terms were most of the iterations' time; docs/BENCHMARKS.md §11).

    ``clear[i, c]``: a lower bound on vertex ``i``'s distance to collider ``c`` wherever it is
    within its ``allow`` of ``x`` (the distance or its lower bound here, less ``allow``: the
    distances are 1-Lipschitz), ``−inf`` where ``allow`` is unbounded. Where it is at least the
    thickness the iterations ask that collider nothing (:func:`.colliders_at`): on Newton's shirt
    with the FR3 at it, a vertex on the table near one link was asking all eleven."""
    ckind, cpos, crot, cgeo, creach = co.kinds, co.pos, co.rot, co.geo, co.reach
    cbank = (co.reals, co.ints, co.starts)
    reals, ints, starts = cbank
    for i in numba.prange(x.shape[0]):  # (each vertex its own rows: the same at any thread count)
        b = allowance[i] if bounded else math.inf
        nearest = math.inf
        for c in range(ckind.shape[0]):
            far = -math.inf  # d is at least that
            if allowance[i] < math.inf:
                far = beyond_reach(cpos, creach, c, x[i, 0], x[i, 1], x[i, 2])
            if bounded and far >= (allowance[i] + tau * 1.01) * (1.0 + 1e-9):
                # beyond its reach: d ≥ allowance + 1.01 τ, so it neither bounds the vertex below
                # its allowance nor makes it near (the same as measured)
                clear[i, c] = far
                continue
            if not bounded and far >= (FAR * allowance[i] + tau * 1.01) * (1.0 + 1e-9):
                # far beyond its reach: measured by the lower bound, the vertex is held within it
                # (not near; a hold no motion of FAR times its expected motion meets), without
                # the query (a Franka Panda's meshes asked by every vertex of a 32×32 cloth at
                # every search: 22 of a step's 35 ms)
                d = far
            else:
                xi, yi, zi = x[i, 0], x[i, 1], x[i, 2]
                d = collider_distance(
                    ckind[c], cpos, crot, cgeo, c, xi, yi, zi, reals, ints, starts, math.inf
                )[0]
            nearest = min(nearest, d)
            clear[i, c] = d
            if cdepth[c] < math.inf:
                reach = max(d, 0.0) + 0.9 * cdepth[c]
                if d < tau and ckind[c] == MESH and mesh_closed(cbank, int(cgeo[c, 0])):
                    # a solid's skin is reached along its outward normal: a vertex a link
                    # overtook gets out on the side it came from (held where it is, the link
                    # carried it on inside, and out of its far side)
                    reach = max(reach, tau - d)
                b = min(b, reach)
        if not bounded:
            room = nearest - tau * 1.01
            if room > FAR * allowance[i]:
                b = min(b, room * (1.0 - 1e-9))
        allow[i] = b
        near[i] = nearest - b < tau * 1.01
        for c in range(ckind.shape[0]):
            clear[i, c] = clear[i, c] - b if b < math.inf else -math.inf


@numba.njit(cache=True, parallel=True)
def overtaken(x, free, co, tau):
    """The initial guess of each free vertex that a moving collider of ``co`` overtook over the
    step (closer than ``τ`` to its new pose) put on its skin, ``τ`` out along its normal; returns
    how many. Without it a vertex in front of a link sweeping many thicknesses a step starts the
    iterations inside the link, where its bounds let it out by a fraction of ``τ`` a search."""
    ckind, cpos, crot, cpos0, crot0 = co.kinds, co.pos, co.rot, co.pos0, co.rot0
    cgeo, creach, reals, ints, starts = co.geo, co.reach, co.reals, co.ints, co.starts
    moved = 0
    for c in range(ckind.shape[0]):
        still = True
        for a in range(3):
            if cpos[c, a] != cpos0[c, a]:
                still = False
            for b in range(3):
                if crot[c, a, b] != crot0[c, a, b]:
                    still = False
        if still:
            continue
        for i in numba.prange(x.shape[0]):  # (a collider at a time; each vertex its own row)
            if not free[i]:
                continue
            if beyond_reach(cpos, creach, c, x[i, 0], x[i, 1], x[i, 2]) >= tau:
                continue
            xi, yi, zi = x[i, 0], x[i, 1], x[i, 2]
            d, nx, ny, nz = collider_distance(
                ckind[c], cpos, crot, cgeo, c, xi, yi, zi, reals, ints, starts, tau
            )
            if d < tau:
                x[i, 0] += (tau - d) * nx
                x[i, 1] += (tau - d) * ny
                x[i, 2] += (tau - d) * nz
                moved += 1
    return moved


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
