"""``vbd``'s iterations on a regular grid, a colour's vertices in SIMD lanes.

On a ``rows × cols`` grid whose springs and bending couplings all join a particle ``(i, j)`` to one
of the twelve of Provot's stencil, ``(i ± 1, j)``, ``(i, j ± 1)``, ``(i ± 1, j ± 1)``, ``(i ± 2,
j)``, ``(i, j ± 2)``, the nine classes ``(i mod 3, j mod 3)`` are colours: no spring joins two
particles of a class (each offset changes ``i`` or ``j`` by 1 or 2). Each class is stored as its
own block, and inside a block particle ``(3p + a, 3q + b)`` (in the grid padded by :data:`PAD`
ghost rows and columns on each side) sits at ``p·Q + q``; then the neighbour at a given offset of
every particle of a colour lies in one block at one fixed shift of the index. The sweep over a
colour is one loop over a contiguous range with the same twelve loads at constant shifts for every
particle, which the compiler turns into SIMD lanes (8 doubles on AVX-512), where the general sweep
(:func:`cloth_sim.integrators.vbd_kernels.sweep`) follows each vertex's spring list.

The ghost cells carry no spring (stiffness, damping, bending and mass 0) and are never moved;
a missing spring of a real particle (on the cloth's border, or a family absent from the model) is a
spring of stiffness 0 to its slot. Each particle's Newton step is the general sweep's, term for
term (the springs' Hooke force and Hessian with the compressed part's ``E'/l`` dropped, the
damping along the spring as the dissipation potential, the bending's ``−(Q x)_i`` and ``Q_ii``, the
inertia and the drag), in another colour order, so the iterates differ from the general path's in
the last bits and converge to the same step. Colliders: a second pass over each colour takes again
the steps of the vertices that may touch one, with the general sweep's contact terms
(:func:`_sweeps_touching`); self-contact and tethers use the general sweep. The same bits at any
thread count: a colour's particles read only other colours' rows, and each writes only its own.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from ..kernel_cache import keep_true
from ..kinds import LINEAR
from .vbd_contact import colliders_at, onset, truncate, within

#: the neighbour offsets ``(di, dj)``, in the sweep's order: structural, shear, bend
OFFSETS = (
    (0, 1),
    (0, -1),
    (1, 0),
    (-1, 0),
    (1, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
    (0, 2),
    (0, -2),
    (2, 0),
    (-2, 0),
)
#: ghost rows and columns on each side: a block's first and last rows and columns are ghosts, so
#: every shift from a real particle stays inside the block arrays
PAD = 3
#: a colour's range cut into this many chunks for the cores (the result does not depend on it)
CHUNKS = 8
#: slots per colour below which a colour is one chunk, on one thread (numba's thread count set to
#: 1 for the iterations): waking the second core for each of the nine colours costs more than it
#: shares. A 64×64 step of 20 iterations, in turn in one process (526 slots a colour): 8 chunks
#: on two threads 2.80 ms, one chunk on one thread 3.30, one chunk with the pool awake 3.56; per
#: iteration at 32×32 (141 slots): one thread 0.052 ms, 8 chunks on two 0.082
PARALLEL_MIN = 400
#: where a ghost sits (far from the cloth: its springs have length > 0 and stiffness 0)
GHOST = 1.0e6


class GridLayout:
    """The blocked layout of one grid model's springs and bending (built once per force pipeline).

    ``slot[v]`` is particle ``v``'s index in the flat block arrays (``block·PQ + p·Q + q``);
    ``shift[c, o]`` the index difference from a particle of colour ``c`` to its neighbour at
    ``OFFSETS[o]``; ``K, REST, C, QO`` ``(12, 9·PQ)`` each offset's spring stiffness, rest length,
    damping and bending coupling ``Q_ij``; ``QD`` the bending diagonal."""

    def __init__(self, rows: int, cols: int, springs, rest, k, c, bending_rows, pinned):
        self.rows, self.cols = rows, cols
        P = (rows + 2 * PAD + 2) // 3
        Q = (cols + 2 * PAD + 2) // 3
        self.P, self.Q, self.PQ = P, Q, P * Q
        size = 9 * P * Q
        n = len(pinned)
        i, j = np.divmod(np.arange(n), cols)
        I, J = i + PAD, j + PAD
        self.slot = np.ascontiguousarray(((I % 3) * 3 + J % 3) * P * Q + (I // 3) * Q + J // 3)
        self._fh = None  # the springs' force and Hessian a slot, where colliders need them
        #: each slot's particle, −1 for a ghost
        self.vof = np.full(9 * P * Q, -1, np.int64)
        self.vof[self.slot] = np.arange(n)
        self.shift = np.zeros((9, len(OFFSETS)), np.int64)
        for cb in range(9):
            a, b = divmod(cb, 3)
            for o, (di, dj) in enumerate(OFFSETS):
                na, nb = (a + di) % 3, (b + dj) % 3
                dp, dq = (a + di) // 3, (b + dj) // 3
                self.shift[cb, o] = ((na * 3 + nb) - cb) * P * Q + dp * Q + dq
        self.shift = self.shift.view(np.uint64)  # two's complement: t + shift wraps to t − |shift|
        # each offset's slot by (di + 2)·5 + (dj + 2), −1 off the stencil
        where = np.full(25, -1, np.int64)
        for o, (di, dj) in enumerate(OFFSETS):
            where[(di + 2) * 5 + dj + 2] = o

        def slots(u, w):
            di, dj = i[w] - i[u], j[w] - j[u]
            near = (np.abs(di) <= 2) & (np.abs(dj) <= 2)
            return np.where(near, where[np.clip((di + 2) * 5 + dj + 2, 0, 24)], -1)

        self.K = np.zeros((len(OFFSETS), size))
        self.REST = np.zeros((len(OFFSETS), size))
        self.C = np.zeros((len(OFFSETS), size))
        self.QO = np.zeros((len(OFFSETS), size))
        self.QD = np.zeros(size)
        taken = np.zeros((len(OFFSETS), size), bool)
        for end, other in ((0, 1), (1, 0)):
            u, w = springs[:, end], springs[:, other]
            o = slots(u, w)
            if np.any(o < 0):
                raise ValueError("a spring outside the grid's stencil")
            s = self.slot[u]
            if np.any(taken[o, s]) or len(np.unique(o * size + s)) != len(s):
                raise ValueError("two springs in one slot")
            taken[o, s] = True
            self.K[o, s], self.REST[o, s], self.C[o, s] = k, rest, c
        if bending_rows is not None:
            bptr, bidx, bval, _ = bending_rows
            owner = np.repeat(np.arange(n), np.diff(bptr))
            diag = bidx == owner
            self.QD[self.slot[owner[diag]]] = bval[diag]
            u, w, val = owner[~diag], bidx[~diag], bval[~diag]
            o = slots(u, w)
            if np.any(o < 0):
                raise ValueError("a bending coupling outside the grid's stencil")
            self.QO[o, self.slot[u]] = val
        # each colour's range: a block's rows 1 … P − 2 but the first and last slot (ghost
        # columns, whose shifts would leave the arrays)
        self.lo, self.hi = Q + 1, (P - 1) * Q - 1
        self.size = size
        # the iteration's arrays, one row per coordinate: the positions (two, taking turns: the
        # iterate, and Chebyshev's extrapolation of it for the next iteration), the step's start,
        # the inertial target, the sweep's new positions, the positions before the last sweep
        self.A, self.B, self.T, self.Y, self.N, self.P2 = (
            np.full((3, size), GHOST) for _ in range(6)
        )
        self.stepped = np.zeros(size)
        self.m_h2 = np.zeros(size)
        #: 1 for a slot whose particle moves, 0 for a pin (held particles are pins of the model)
        #: and a ghost
        self.free = np.zeros(size)
        self.free[self.slot] = ~np.asarray(pinned, bool)
        #: the chunks a colour is cut into, and whether the iterations use every core (else numba's
        #: thread count is 1 while they run)
        self.parallel = self.hi - self.lo >= PARALLEL_MIN
        self.chunks = CHUNKS if self.parallel else 1
        #: what the sweeps read of the lattice, as they take it (:func:`solve`): the colours'
        #: shifts, the block size and each colour's range, the offsets' stiffness, rest length,
        #: damping and bending coupling, the bending diagonal, ``m/h²`` and which slots move
        self.lattice = (self.shift, self.PQ, self.lo, self.hi, self.K, self.REST, self.C,
                        self.QO, self.QD, self.m_h2, self.free)  # fmt: skip

    @classmethod
    def of(cls, model, forces) -> "GridLayout | None":
        """The layout of ``model`` under ``forces``, or ``None`` where the general sweep must run:
        not a grid, a spring that is not Hooke's (Choi–Ko's), or a spring or bending coupling
        outside the stencil."""
        rows, cols = model.rows, model.cols
        if rows is None or cols is None or rows * cols != model.n_particles:
            return None
        if len(forces.springs) and np.any(forces.kind != LINEAR):
            return None
        bending = forces.bending
        try:
            return cls(
                rows,
                cols,
                forces.springs,
                forces.rest,
                forces.k,
                forces.c,
                None if bending is None else bending.rows(),
                model.pinned,
            )
        except ValueError:
            return None

    def load(self, x, xt, y, m_h2) -> None:
        """A step's start: the iterate ``x``, the step's start ``xt``, the inertial target ``y``
        (each ``(n, 3)``) and ``m/h²``, into the blocks."""
        _scatter(x, xt, y, self.slot, self.A, self.T, self.Y)
        self.m_h2[self.slot] = m_h2

    def solve(
        self, inv_h, drag_h, first, last, total, rho, omega, contact=None
    ) -> tuple[float, int]:
        """Iterations ``first … last − 1`` of ``total`` on the loaded blocks (:func:`solve`);
        returns Chebyshev's weight and how many times the two position arrays took turns (the
        iterate is in ``A`` after an even number). ``contact``: :meth:`contact`'s tuple where
        the step has colliders."""
        return solve(
            (self.A, self.B, self.T, self.Y, self.N, self.P2),
            self.lattice,
            (inv_h, drag_h, rho),
            self.stepped,
            self.chunks,
            first,
            last,
            total,
            omega,
            contact,
        )

    def contact(self, xm, xt, near, touch, cut, x_cd, allow, gamma, law, colliders, rec, seen):
        """What the sweep with colliders reads besides the blocks (:func:`_sweeps_touching`):
        each slot's particle (``−1`` for a ghost), a scratch ``(n, 3)`` for the vertices it
        takes again, the step's start, the general sweep's per-vertex arrays, the contact law
        ``(τ, the penalty's stiffness, friction's ε)`` and the colliders, nine scratch rows
        for the springs' force and Hessian a slot, and the colliders' distances and normals a
        vertex (:func:`~.vbd_contact.colliders_at`)."""
        if self._fh is None:
            self._fh = tuple(np.zeros(self.size) for _ in range(9))
        return (self.vof, xm, xt, near, touch, cut, x_cd, allow, gamma, law, colliders, rec,
                self._fh, seen)  # fmt: skip

    def swap(self) -> None:
        """The two position arrays take turns (what :func:`solve` did inside, once)."""
        self.A, self.B = self.B, self.A

    def store(self, x, stepped, flips: int = 0) -> None:
        """The iterate back into ``x`` ``(n, 3)`` (in ``A``, or in ``B`` after an odd number of
        turns), each particle's last squared step into ``stepped``."""
        _gather(self.A if flips % 2 == 0 else self.B, self.slot, x)
        stepped[:] = self.stepped[self.slot]


@numba.njit(cache=True)
def _scatter(x, xt, y, slot, X, T, Y):
    for v in range(slot.shape[0]):
        s = slot[v]
        for c in range(3):
            X[c, s] = x[v, c]
            T[c, s] = xt[v, c]
            Y[c, s] = y[v, c]


@numba.njit(cache=True)
def _gather(X, slot, x):
    for v in range(slot.shape[0]):
        s = slot[v]
        for c in range(3):
            x[v, c] = X[c, s]


@numba.njit(cache=True, inline="always")
def _spring(X, T, j, t, o, K, REST, C, QO, inv_h, pm, fh):
    """Particle ``t``'s spring and bending coupling to its neighbour ``j`` (slot ``o``): the
    general sweep's spring terms (:func:`cloth_sim.integrators.vbd_terms.springs_at`): ``X`` the
    iterate and ``T`` the step's start (``(3, size)``, a row a coordinate), ``K, REST, C, QO``
    the offsets' springs (:class:`GridLayout`), ``pm`` the particle's position and its motion
    over the step (six numbers), ``fh`` its block (nine numbers). Whole arrays, indexed here, not
    tuples of their rows: a tuple of arrays, built in the colour's parallel loop or captured by
    it, cost the loop its SIMD lanes (numba's reference counting: packed square roots 12 → 0,
    ``test_the_grid_sweep_runs_in_simd_lanes``); tuples of numbers compile to the same code. (The
    four spring arrays as one ``(4, 12, size)`` array, indexed ``S[k, o, t]``: 8–10 % slower
    per iteration, measured in one process at 64² and 128².)"""
    xi, yi, zi, mx, my, mz = pm
    f0, f1, f2, h0, h1, h2, h3, h4, h5 = fh
    xj, yj, zj = X[0, j], X[1, j], X[2, j]
    dx, dy, dz = xj - xi, yj - yi, zj - zi
    l = np.sqrt(dx * dx + dy * dy + dz * dz)
    inv = 1.0 / l if l >= 1e-300 else 0.0
    ux, uy, uz = dx * inv, dy * inv, dz * inv
    kk = K[o, t]
    cs = C[o, t] * inv_h
    de = kk * (l - REST[o, t])
    mag = de + cs * (
        ((xj - T[0, j]) - mx) * ux + ((yj - T[1, j]) - my) * uy + ((zj - T[2, j]) - mz) * uz
    )
    q = QO[o, t]
    f0 += mag * ux - q * xj
    f1 += mag * uy - q * yj
    f2 += mag * uz - q * zj
    geo = de * inv if de > 0.0 else 0.0
    w = kk + cs - geo
    wx, wy = w * ux, w * uy
    h0 += wx * ux + geo
    h1 += wx * uy
    h2 += wx * uz
    h3 += wy * uy + geo
    h4 += wy * uz
    h5 += w * uz * uz + geo
    return f0, f1, f2, h0, h1, h2, h3, h4, h5


@numba.njit(cache=True, inline="always")
def _advance(t, p, fh, free, N, stepped):
    """Slot ``t``'s Newton step (:func:`_solve`) from ``p``, its position, and ``fh``, its block
    (force and Hessian, nine numbers: :mod:`~cloth_sim.integrators.vbd_terms`): the new position
    into ``N``, its squared force (the imbalance the step answers) into ``stepped``. (A call of
    more than 30 arguments compiles to a tuple and ``*args``, which numba cannot inline: hence
    the springs' terms, :func:`_terms`, and this step are two calls.)"""
    xi, yi, zi = p
    f0, f1, f2, a0, b, c, dd, e, ff = fh
    sx, sy, sz = _solve(a0, b, c, dd, e, ff, f0, f1, f2, free)
    N[0, t], N[1, t], N[2, t] = xi + sx, yi + sy, zi + sz
    stepped[t] = f0 * f0 + f1 * f1 + f2 * f2  # its imbalance as the sweep found it


@numba.njit(cache=True)
def next_omega(it, rho, omega):
    """Chebyshev's weight after iteration ``it`` (the general loop's): ``ω₁ = 1``, ``ω₂ = 2/(2 −
    ρ²)``, ``ω_k = 4/(4 − ρ² ω_{k−1})``."""
    if it == 0:
        return 1.0
    if it == 1:
        return 2.0 / (2.0 - rho * rho)
    return 4.0 / (4.0 - rho * rho * omega)


@numba.njit(cache=True, inline="always")
def _terms(t, n, X, T, Y, K, REST, C, QO, QD, MH2, rates):
    """Slot ``t``'s position, and its force and Hessian (six entries) of the incremental
    potential from its inertia, drag, bending diagonal and twelve springs (``n``: its colour's
    twelve shifts, a tuple): the general sweep's terms
    (:func:`cloth_sim.integrators.vbd_kernels.sweep`).
    ``rates``: :func:`solve`'s. (Whole arrays, as :func:`_spring` says.)"""
    inv_h, drag_h, _ = rates
    xi, yi, zi = X[0, t], X[1, t], X[2, t]
    mx, my, mz = xi - T[0, t], yi - T[1, t], zi - T[2, t]
    m = MH2[t]
    qd = QD[t]
    d = m + drag_h + qd
    f0 = -m * (xi - Y[0, t]) - drag_h * mx - qd * xi
    f1 = -m * (yi - Y[1, t]) - drag_h * my - qd * yi
    f2 = -m * (zi - Y[2, t]) - drag_h * mz - qd * zi
    fh = (f0, f1, f2, d, 0.0, 0.0, d, 0.0, d)
    pm = (xi, yi, zi, mx, my, mz)
    # the twelve springs, one a line (as a loop over the twelve offsets the colour's loop lost
    # its SIMD lanes: packed square roots 12 → 0)
    # fmt: off
    fh = _spring(X, T, t + n[0], t, 0, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[1], t, 1, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[2], t, 2, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[3], t, 3, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[4], t, 4, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[5], t, 5, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[6], t, 6, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[7], t, 7, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[8], t, 8, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[9], t, 9, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[10], t, 10, K, REST, C, QO, inv_h, pm, fh)
    fh = _spring(X, T, t + n[11], t, 11, K, REST, C, QO, inv_h, pm, fh)
    # fmt: on
    f0, f1, f2, a0, b, c, dd, e, ff = fh
    return xi, yi, zi, f0, f1, f2, a0, b, c, dd, e, ff


@numba.njit(cache=True, inline="always")
def _solve(a0, b, c, dd, e, ff, f0, f1, f2, free):
    """``H⁻¹ f`` by the adjugate, times ``free`` (0 or 1); zero where ``H`` is singular (the
    ghosts). The general sweep's :func:`~.vbd_contact.solve3` with selects instead of its early
    return, which would take the loop out of SIMD lanes."""
    c00 = dd * ff - e * e
    c01 = c * e - b * ff
    c02 = b * e - c * dd
    det = a0 * c00 + b * c01 + c * c02
    inv = free / det if det > 1e-300 else 0.0
    c11 = a0 * ff - c * c
    c12 = b * c - a0 * e
    c22 = a0 * dd - b * b
    return (
        (c00 * f0 + c01 * f1 + c02 * f2) * inv,
        (c01 * f0 + c11 * f1 + c12 * f2) * inv,
        (c02 * f0 + c12 * f1 + c22 * f2) * inv,
    )


@numba.njit(cache=True)
def solve(blocks, lattice, rates, stepped, chunks, first, last, total, omega, contact):
    """Iterations ``first … last − 1`` of a step of ``total``; returns Chebyshev's weight and how
    many times ``A`` and ``B`` took turns. Each iteration sweeps the nine colours in order from the
    iterate ``A`` (:func:`_sweeps`). Where ``rho > 0``, after every iteration but the step's last,
    the general loop's Chebyshev step (:func:`cloth_sim.integrators.vbd_kernels.chebyshev` and its
    copy): the next iterate ``ω (x − p) + p`` of each free particle not in contact, ``p`` its
    position before the last iteration's sweep (``P``), is written to ``B`` as each colour's sweep
    ends, while ``A`` keeps the swept positions the later colours read; then ``A`` and ``B`` take
    turns. The same arithmetic as a separate pass after the sweeps, without that pass over every
    array.

    ``blocks`` holds ``A, B, T, Y, N, P``, ``(3, size)`` arrays, a row a coordinate (the
    iterate, its extrapolation, the step's start, the inertial target, the sweep's new
    positions, the older positions); ``lattice``: :attr:`GridLayout.lattice`; ``rates``:
    ``(1/h, drag/h, ρ)``; ``contact``: the colliders and the vertices' bounds
    (:meth:`GridLayout.contact`), or ``None``. (The bundles are plain tuples, unpacked in their
    order: numba types a NamedTuple argument on a slow path, ~1 µs a call.)"""
    A, B, T, Y, N, P = blocks
    _, _, rho = rates
    flips = 0
    for it in range(first, last):
        mode = 0  # 0: no Chebyshev step; 1: its copy only (ω₁ = 1); 2: the extrapolation
        if rho > 0.0 and it < total - 1:
            omega = next_omega(it, rho, omega)
            mode = 2 if it > 0 else 1
        _iteration((A, B, T, Y, N, P), lattice, rates, stepped, chunks, mode, omega, contact)
        if mode:
            A, B = B, A
            flips += 1
    return omega, flips


def _iteration(blocks, lattice, rates, stepped, chunks, mode, omega, contact):
    """One iteration's sweeps: :func:`_sweeps` where ``contact`` is ``None``, else
    :func:`_sweeps_touching` (chosen by its type as :func:`solve` compiles, so that a signature
    compiles only its own: ``contact is None`` in the body left both branches to compile, 24 s of
    the colliders' signature spent on the sweep it never runs)."""
    raise NotImplementedError("compiled only: called from solve")


@overload(_iteration, inline="always")
def _iteration_for(blocks, lattice, rates, stepped, chunks, mode, omega, contact):
    if isinstance(contact, types.NoneType):

        def plain(blocks, lattice, rates, stepped, chunks, mode, omega, contact):
            _sweeps(blocks, lattice, rates, stepped, chunks, mode, omega)

        return plain

    def touching(blocks, lattice, rates, stepped, chunks, mode, omega, contact):
        _sweeps_touching(blocks, lattice, rates, stepped, chunks, mode, omega, contact)

    return touching


@numba.njit(cache=True, inline="always")
def _colour(shift, cb, PQ, lo, hi, chunks):
    """Colour ``cb``'s range ``[a, b)``, its chunks' size and its twelve shifts (scalars: a row
    of ``shift`` would be a view; flat: numba's array analysis fails on a tuple in a tuple
    returned by a helper)."""
    a, b = cb * PQ + lo, cb * PQ + hi
    return (
        a, b, (b - a + chunks - 1) // chunks,
        shift[cb, 0], shift[cb, 1], shift[cb, 2], shift[cb, 3], shift[cb, 4], shift[cb, 5],
        shift[cb, 6], shift[cb, 7], shift[cb, 8], shift[cb, 9], shift[cb, 10], shift[cb, 11],
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _chunk(a, b, size, ch):
    """Chunk ``ch``'s slots as unsigned indices: numba then adds no wrap-around of negative ones,
    which made every load a gather (the shifts are stored as unsigned, two's complement: the
    sums wrap)."""
    return np.uint64(a + ch * size), np.uint64(min(a + ch * size + size, b))


@numba.njit(cache=True, inline="always")
def _commit(t, x, move, mode, omega, X, B, P):
    """Slot ``t``'s new position ``x`` (three numbers) into ``A`` (``X``) and, where ``mode`` asks
    for Chebyshev's step (:func:`solve`), the next iterate into ``B`` (extrapolated if ``move``)
    and the position before into ``P``; returns what went into ``B``."""
    x0, x1, x2 = x
    b0, b1, b2 = x0, x1, x2
    if mode == 2 and move:
        b0 = omega * (x0 - P[0, t]) + P[0, t]
        b1 = omega * (x1 - P[1, t]) + P[1, t]
        b2 = omega * (x2 - P[2, t]) + P[2, t]
    if mode:
        B[0, t], B[1, t], B[2, t] = b0, b1, b2
        P[0, t], P[1, t], P[2, t] = X[0, t], X[1, t], X[2, t]
    X[0, t], X[1, t], X[2, t] = x0, x1, x2
    return b0, b1, b2


@numba.njit(cache=True, parallel=True, error_model="numpy", fastmath={"contract"})
def _sweeps(blocks, lattice, rates, stepped, chunks, mode, omega):
    """One iteration's sweeps: the nine colours in order, each colour's range cut into
    ``chunks`` for the cores (any number gives the same bits). Each particle's Newton step is
    written to ``N`` (its squared length to ``stepped``), then committed (:func:`_commit`). Free
    particles only move (not pins, not ghosts).

    The tuples are unpacked here: inside the parallel loop below numba declares its distinct
    arrays unaliased (nothing in it may take a view, which numba counts as an alias), so the
    particles' loop runs in SIMD lanes without run-time overlap checks, and the new positions go
    to ``N`` first so that no array is both read at a shift and written. ``fastmath={"contract"}``
    only fuses multiplies and adds (FMA): the same in every lane and in the scalar remainder,
    ~10 % faster. The bundles: :func:`solve`'s."""
    X, B, T, Y, N, P = blocks
    shift, PQ, lo, hi, K, REST, C, QO, QD, MH2, FREE = lattice
    for cb in range(9):
        a, bb, size, n0, n1, n2, n3, n4, n5, n6, n7, n8, n9, n10, n11 = _colour(
            shift, cb, PQ, lo, hi, chunks
        )
        n = (n0, n1, n2, n3, n4, n5, n6, n7, n8, n9, n10, n11)
        for ch in numba.prange(chunks):
            lo_, hi_ = _chunk(a, bb, size, ch)
            for t in range(lo_, hi_):
                xi, yi, zi, f0, f1, f2, a0, b, c, dd, e, ff = _terms(
                    t, n, X, T, Y, K, REST, C, QO, QD, MH2, rates
                )
                _advance(t, (xi, yi, zi), (f0, f1, f2, a0, b, c, dd, e, ff), FREE[t], N, stepped)
            for t in range(lo_, hi_):
                move = FREE[t] != 0.0
                _commit(t, (N[0, t], N[1, t], N[2, t]), move, mode, omega, X, B, P)


@numba.njit(cache=True, parallel=True, error_model="numpy", fastmath={"contract"})
def _sweeps_touching(blocks, lattice, rates, stepped, chunks, mode, omega, contact):
    """:func:`_sweeps` with colliders: each colour's SIMD loop as there, then a second pass over
    its slots (:func:`_touch_colour`, a parallel loop of its own: the contact terms take views of
    the colliders' arrays, which would cost the first loop its unaliased arrays) that takes again
    the step of each vertex that may touch a collider (``near``), from the springs' force and
    Hessian the first loop left, with the collider's penalty and friction in it and held at a
    contact's onset (the general sweep's :func:`~.vbd_contact.colliders_at` and
    :func:`~.vbd_contact.onset`, on the vertex's row of the original arrays), holds every step
    and every extrapolation within the vertex's bounds (:func:`~.vbd_contact.within`,
    :func:`~.vbd_contact.truncate`: what the last search lets it move), extrapolates no vertex in
    contact, and commits."""
    X, B, T, Y, N, P = blocks
    shift, PQ, lo, hi, K, REST, C, QO, QD, MH2, FREE = lattice
    # the springs' blocks, for the second pass (the rest of the bundle is _touch_colour's)
    (_, _, _, _, _, _, _, _, _, _, _, _, fh, _) = contact
    F0, F1, F2, H0, H1, H2, H3, H4, H5 = fh
    for cb in range(9):
        a, bb, size, n0, n1, n2, n3, n4, n5, n6, n7, n8, n9, n10, n11 = _colour(
            shift, cb, PQ, lo, hi, chunks
        )
        n = (n0, n1, n2, n3, n4, n5, n6, n7, n8, n9, n10, n11)
        for ch in numba.prange(chunks):
            lo_, hi_ = _chunk(a, bb, size, ch)
            for t in range(lo_, hi_):
                xi, yi, zi, f0, f1, f2, a0, b, c, dd, e, ff = _terms(
                    t, n, X, T, Y, K, REST, C, QO, QD, MH2, rates
                )
                _advance(t, (xi, yi, zi), (f0, f1, f2, a0, b, c, dd, e, ff), FREE[t], N, stepped)
                # the springs' force and Hessian, for the vertices the second pass takes again
                F0[t], F1[t], F2[t] = f0, f1, f2
                H0[t], H1[t], H2[t], H3[t], H4[t], H5[t] = a0, b, c, dd, e, ff
        _touch_colour((a, bb, size, chunks), blocks, FREE, stepped, mode, omega, contact)


@numba.njit(cache=True, parallel=True, error_model="numpy", fastmath={"contract"})
def _touch_colour(span, blocks, FREE, stepped, mode, omega, contact):
    """:func:`_sweeps_touching`'s second pass over one colour's slots, ``span``: its range
    ``[a, b)``, chunk size and chunks. A function of its own, called once a colour: inside
    :func:`_sweeps_touching` beside the first pass, numba's parallel passes over the one
    function with the colliders' queries inlined cost 68 s of one core to compile, 56 s as two
    (the same bits; the queries called once a vertex instead: 37 s, but the calls count their
    18 arrays in and out, and the table ran 30–50 % slower: docs/contributing.md)."""
    a, bb, size, chunks = span
    X, B, T, Y, N, P = blocks
    (vof, xm, xt, near, touch, cut, x_cd, allow, gamma, law, co, sc, fh, seen) = contact
    tau = law[0]
    F0, F1, F2, H0, H1, H2, H3, H4, H5 = fh
    ckind, cgeo, cmu = co.kinds, co.geo, co.mu
    pose, pose0 = (co.pos, co.rot, co.reach), (co.pos0, co.rot0)
    cbank = (co.reals, co.ints, co.starts)
    shapes = (ckind, co.pos, co.rot, cgeo, co.reals, co.ints, co.starts)
    rec_ptr, rec_v, rec_w, rec_n, gptr, grec, pidx, pcoef, pnrm, pdist, dmin, rec_d = sc
    for ch in numba.prange(chunks):
        lo_, hi_ = _chunk(a, bb, size, ch)
        for t in range(lo_, hi_):
            v = vof[t]
            if v < 0 or FREE[t] == 0.0:  # a ghost or a pin: kept
                _commit(t, (N[0, t], N[1, t], N[2, t]), False, mode, omega, X, B, P)
                continue
            x0, x1, x2 = N[0, t], N[1, t], N[2, t]
            touch[v] = 0
            if near[v]:
                xi, yi, zi = X[0, t], X[1, t], X[2, t]
                f0, f1, f2 = F0[t], F1[t], F2[t]
                a0, b, c, dd, e, ff = H0[t], H1[t], H2[t], H3[t], H4[t], H5[t]
                xm[v, 0], xm[v, 1], xm[v, 2] = xi, yi, zi
                f0, f1, f2, a0, b, c, dd, e, ff, touched = colliders_at(
                    v, xm, xt, ckind, pose, pose0, cgeo, cmu, cbank, law,
                    (f0, f1, f2, a0, b, c, dd, e, ff), seen,
                )  # fmt: skip
                if touched:
                    touch[v] = 1
                sx, sy, sz = _solve(a0, b, c, dd, e, ff, f0, f1, f2, 1.0)
                sx, sy, sz = onset(v, (sx, sy, sz), xm, (rec_ptr, rec_w, rec_n, rec_d), tau,
                                   ckind.shape[0], shapes, seen)  # fmt: skip
                x0, x1, x2 = xi + sx, yi + sy, zi + sz
                stepped[t] = f0 * f0 + f1 * f1 + f2 * f2
            x0, x1, x2, was_cut, settled = within(x0, x1, x2, x_cd[v, 0], x_cd[v, 1],
                                                  x_cd[v, 2], allow[v], dmin[v],
                                                  gamma)  # fmt: skip
            if not settled:
                x0, x1, x2, was_cut = truncate(v, (x0, x1, x2), x_cd, allow, gptr, grec, pidx,
                                               pcoef, pnrm, pdist, dmin, gamma)  # fmt: skip
            if was_cut:
                cut[v] = 1
            b0, b1, b2 = _commit(t, (x0, x1, x2), touch[v] == 0, mode, omega, X, B, P)
            if mode == 2 and touch[v] == 0:  # the extrapolation within the bounds too
                b0, b1, b2, was_cut, settled = within(b0, b1, b2, x_cd[v, 0], x_cd[v, 1],
                                                      x_cd[v, 2], allow[v], dmin[v],
                                                      gamma)  # fmt: skip
                if not settled:
                    b0, b1, b2, was_cut = truncate(v, (b0, b1, b2), x_cd, allow, gptr, grec,
                                                   pidx, pcoef, pnrm, pdist, dmin,
                                                   gamma)  # fmt: skip
                B[0, t], B[1, t], B[2, t] = b0, b1, b2
                if was_cut:
                    cut[v] = 1


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
