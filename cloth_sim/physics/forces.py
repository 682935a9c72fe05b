"""Forces on the particles, assembled from what the scene actually has.

Terms (the review's equations in brackets):

* ``spring:<family>`` — Hooke's law along each spring [1.6]; for Choi & Ko (2002) the type-1
  (tension only) and type-2 (immediate buckling) interactions.
* ``damping:<family>`` — damping along each spring, ``−k_d ((v2 − v1)·u) u`` [1.7].
* ``gravity`` — ``m g`` [1.4].
* ``wind`` — ``(n_i·W) n_i`` on the unit normal of each particle [1.5], with ``W = w·direction``.
* ``drag`` — linear air drag ``−c v``.

A family whose stiffness is zero contributes no ``spring:`` term, one whose damping is zero no
``damping:`` term; no wind, no gravity, no drag: no such term. :attr:`Forces.active_terms` lists
what is evaluated, and springs belonging to no active term are not even visited.

Choi & Ko's immediate-buckling model
------------------------------------
A compressed type-2 pair of rest length ``L`` at distance ``|x| < L`` is taken as an arc of length
``L`` with curvature ``κ`` solving ``|x| = L·sin(κL/2)/(κL/2)``. With ``θ = κL/2`` and ``r =
|x|/L``
its energy is ``½ k_b κ² L = (k_b/L)·h(r)``, ``h = 2θ²``, and it pushes the pair apart with
``k_b κ² / (sinc θ − cos θ) = −(k_b/L²)·h'(r)``, which tends to ``12 k_b/L²`` as ``r → 1``.
Stretched,
it is a linear spring of stiffness ``k_b``. ``h(r)`` is smooth on ``[0, 1]`` (``h ≈ 12(1 − r)``
near
the onset, ``h(0) = 2π²``), so it is tabulated once on :data:`BUCKLE_TABLE_SIZE` uniform nodes with
its exact slope and evaluated as a cubic Hermite spline: the hot loop never solves for ``θ``, and
the
force is exactly minus the derivative of the tabulated energy. Against the exact solution the
spline's relative error is below 2e-10 in the energy and 3e-8 in the force over ``r ∈ [0, 1]``
(``test_choi_ko_table_matches_exact_solution`` measures it); at the onset ``r = 1`` the force is
exactly ``12 k_b/L²``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic
from scipy.optimize import brentq

from ..model import LINEAR, TENSION_ONLY, ClothModel
from ..threads import start_pool
from .bending import bending_row

BUCKLE_TABLE_SIZE = 513


# --------------------------------------------------------------------------- Choi–Ko table
def buckling_theta(r: float) -> float:
    """Half the bend angle ``θ = κL/2`` for the length ratio ``r = |x|/L`` (exact, by root
    finding)."""
    if r >= 1.0:
        return 0.0
    if r <= 0.0:
        return np.pi
    return brentq(lambda t: np.sinc(t / np.pi) - r, 1e-300, np.pi, xtol=1e-15, rtol=1e-15)


def buckling_h_exact(r: float) -> tuple[float, float]:
    """``h(r) = 2θ²`` and ``h'(r) = 4θ³/(θ cos θ − sin θ)`` from the exact ``θ(r)``."""
    t = buckling_theta(r)
    if t < 1e-3:  # series about the onset, θ cos θ − sin θ = −θ³/3 + θ⁵/30 − …
        return 2 * t * t, -12.0 / (1.0 - t * t / 10.0)
    return 2 * t * t, 4 * t**3 / (t * np.cos(t) - np.sin(t))


def _build_buckle_table(size: int = BUCKLE_TABLE_SIZE) -> np.ndarray:
    """Rows ``(h, h')`` at ``r_k = k/(size−1)``."""
    r = np.linspace(0.0, 1.0, size)
    tab = np.empty((size, 2))
    for k, rk in enumerate(r):
        tab[k] = buckling_h_exact(rk)
    tab[-1] = (0.0, -12.0)
    return tab


BUCKLE_TABLE = _build_buckle_table()
BUCKLE_TABLE.setflags(write=False)


@numba.njit(cache=True, inline="always")
def _buckle(r, tab):
    """Cubic Hermite spline of ``h`` at ``r``: returns ``(h, h', h'')``."""
    n = tab.shape[0] - 1
    if r <= 0.0:
        r = 0.0
    s = r * n
    k = int(s)
    if k >= n:
        k = n - 1
    t = s - k
    d = 1.0 / n
    h0, m0, h1, m1 = tab[k, 0], tab[k, 1] * d, tab[k + 1, 0], tab[k + 1, 1] * d
    t2 = t * t
    t3 = t2 * t
    h = (
        (2 * t3 - 3 * t2 + 1) * h0
        + (t3 - 2 * t2 + t) * m0
        + (-2 * t3 + 3 * t2) * h1
        + (t3 - t2) * m1
    )
    dh = (
        (6 * t2 - 6 * t) * h0
        + (3 * t2 - 4 * t + 1) * m0
        + (-6 * t2 + 6 * t) * h1
        + (3 * t2 - 2 * t) * m1
    )
    d2h = (12 * t - 6) * h0 + (6 * t - 4) * m0 + (-12 * t + 6) * h1 + (6 * t - 2) * m1
    return h, dh * n, d2h * n * n


def buckling_h(r: float) -> tuple[float, float, float]:
    """The tabulated ``(h, h', h'')`` at ``r`` (what the simulation uses)."""
    return _buckle(float(r), BUCKLE_TABLE)


# --------------------------------------------------------------------------- spring kernels
@numba.njit(cache=True, inline="always")
def spring_vector(x, i, j):
    """``x_j − x_i`` and its length."""
    dx = x[j, 0] - x[i, 0]
    dy = x[j, 1] - x[i, 1]
    dz = x[j, 2] - x[i, 2]
    return dx, dy, dz, np.sqrt(dx * dx + dy * dy + dz * dz)


@numba.njit(cache=True, inline="always")
def axial(l, L, k, kind, tab):
    """Energy ``E(l)``, ``dE/dl`` and ``d²E/dl²`` of one spring."""
    e = l - L
    if kind == LINEAR or e >= 0.0:
        return 0.5 * k * e * e, k * e, k
    if kind == TENSION_ONLY:
        return 0.0, 0.0, 0.0
    # BUCKLING, compressed: E = (k/L) h(l/L)
    h, dh, d2h = _buckle(l / L, tab)
    return k / L * h, k / (L * L) * dh, k / (L * L * L) * d2h


@numba.njit(cache=True, inline="always")
def _spring_force(d, w, law, tab, with_damping):
    """The force on a spring's first end, from ``d = (dx, dy, dz, l)``, ``x_j − x_i`` and its
    length ``l > 0``, and ``w = v_j − v_i`` (read only ``with_damping``), for the spring's
    ``law = (rest, k, c, kind)`` and the Choi–Ko table ``tab``: :func:`axial`'s ``dE/dl`` plus the
    damping along the spring, times the unit vector. (Inlined, the tuples of numbers too:
    measured as fast as the lines written out, docs/BENCHMARKS.md §7.)"""
    dx, dy, dz, l = d
    wx, wy, wz = w
    rest, k, c, kind = law
    inv = 1.0 / l
    ux, uy, uz = dx * inv, dy * inv, dz * inv
    _, de, _ = axial(l, rest, k, kind, tab)
    mag = de
    if with_damping:
        mag += c * (wx * ux + wy * uy + wz * uz)
    return mag * ux, mag * uy, mag * uz


@numba.njit(cache=True)
def spring_forces(x, v, springs, rest, k, c, kind, tab, with_damping, f):
    """Add every listed spring's elastic (and, if ``with_damping``, damping) force to ``f``."""
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        dx, dy, dz, l = spring_vector(x, i, j)
        if l < 1e-300:
            continue
        fx, fy, fz = _spring_force(
            (dx, dy, dz, l),
            (v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], v[j, 2] - v[i, 2]),
            (rest[s], k[s], c[s], kind[s]),
            tab,
            with_damping,
        )
        f[i, 0] += fx
        f[i, 1] += fy
        f[i, 2] += fz
        f[j, 0] -= fx
        f[j, 1] -= fy
        f[j, 2] -= fz


#: what :func:`spring_forces_gather` does with each particle's summed force
GATHER_FORCE, GATHER_KICK_DRIFT, GATHER_ACCELERATION, GATHER_RK_STAGE = 0, 1, 2, 3


@numba.njit(cache=True, inline="always")
def combine_particle(xo, vo, x, v, kx, kv, coef, p):
    """Particle ``p``'s ``xo = x + Σ_j kx[j]·coef[j]``, ``vo = v + Σ_j kv[j]·coef[j]`` over the
    non-zero coefficients, ``j`` in increasing order (a Runge–Kutta stage's state or update; see
    :func:`cloth_sim.integrators.explicit._combine`)."""
    for d in range(3):
        xa = x[p, d]
        va = v[p, d]
        for j in range(coef.shape[0]):
            cj = coef[j]
            if cj != 0.0:
                xa += kx[j, p, d] * cj
                va += kv[j, p, d] * cj
        xo[p, d] = xa
        vo[p, d] = va


#: springs per block of :func:`spring_forces_gather`'s first loop (its ends' differences, 24 KB,
#: stay in a core's L1 cache between the block's two passes)
GATHER_BLOCK = 512


@intrinsic
def _block_buffer(typingctx):
    """A ``(6, GATHER_BLOCK)`` float64 array on the stack of the compiled function that calls it
    (reserved once in its entry block, 24 kB): each core's block of springs' differences in
    :func:`spring_forces_gather`. A heap array made there (``np.empty``) was as fast but is an
    allocation per call and core (``test_a_step_allocates_no_array`` caught it); one made once and
    passed in, or one per core indexed by ``numba.get_thread_id()``, was 5–25 % slower a step at
    128×128 — a fresh allocation, on the heap or the stack, is known to the compiler to alias none
    of the arrays the block reads."""
    array = types.Array(types.float64, 2, "C")

    def codegen(context, builder, signature, args):
        data = cgutils.alloca_once(
            builder, context.get_value_type(types.float64), size=6 * GATHER_BLOCK
        )
        out = context.make_array(array)(context, builder)
        intp = lambda n: context.get_constant(types.intp, n)  # noqa: E731
        context.populate_array(
            out,
            data=data,
            shape=[intp(6), intp(GATHER_BLOCK)],
            strides=[intp(8 * GATHER_BLOCK), intp(8)],
            itemsize=intp(8),
            meminfo=None,
        )
        return out._getvalue()

    return array(), codegen


@numba.njit(cache=True, error_model="numpy")
def _block_forces(d, rest, k, c, kind, tab, with_damping, fx, fy, fz):
    """One block of springs' forces from their ends' differences ``d`` (rows ``x_j − x_i`` and
    ``v_j − v_i`` by coordinate, one column per spring), written by coordinate into ``fx``, ``fy``,
    ``fz``: the operations of :func:`spring_forces` for each spring, in a loop over contiguous
    arrays that the compiler turns into SIMD (four or eight springs' square roots and divisions at
    once; a per-spring loop reading the ends through their indices stays scalar). IEEE square root
    and division give the same bits in SIMD lanes as alone, so this is :func:`spring_forces`'s
    result bit for bit. Hooke's law first for every spring; then, one by one with the serial loop's
    :func:`_spring_force`, the compressed springs of a kind other than
    :data:`~cloth_sim.model.LINEAR` (Choi–Ko's tension-only and buckling pairs).
    ``error_model="numpy"``: ``1/l`` is computed in every lane and discarded where ``l < 1e-300``
    (such a spring's force is 0, as in the serial loop)."""
    n = rest.shape[0]
    dx_, dy_, dz_, wx, wy, wz = d[0], d[1], d[2], d[3], d[4], d[5]
    for t in range(n):
        dx, dy, dz = dx_[t], dy_[t], dz_[t]
        l = np.sqrt(dx * dx + dy * dy + dz * dz)
        inv = 0.0 if l < 1e-300 else 1.0 / l
        ux, uy, uz = dx * inv, dy * inv, dz * inv
        mag = k[t] * (l - rest[t])
        if with_damping:
            mag += c[t] * (wx[t] * ux + wy[t] * uy + wz[t] * uz)
        zero = l < 1e-300
        fx[t] = 0.0 if zero else mag * ux
        fy[t] = 0.0 if zero else mag * uy
        fz[t] = 0.0 if zero else mag * uz
    for t in range(n):
        if kind[t] == LINEAR:
            continue
        dx, dy, dz = dx_[t], dy_[t], dz_[t]
        l = np.sqrt(dx * dx + dy * dy + dz * dz)
        if l < 1e-300 or l >= rest[t]:  # Hooke's law above is this spring's force
            continue
        fx[t], fy[t], fz[t] = _spring_force(
            (dx, dy, dz, l),
            (wx[t], wy[t], wz[t]),
            (rest[t], k[t], c[t], kind[t]),
            tab,
            with_damping,
        )


class GatherSprings(NamedTuple):
    """What :func:`spring_forces_gather` reads of the springs besides the state, made by
    :func:`gather_arrays`: their ends (32-bit, in :func:`spring_layout`'s order) and material in
    that order, the Choi–Ko table, whether they carry damping, each particle's springs
    (:func:`incidence`: ``ptr``, ``adj``, ``sign``), the per-spring force scratch by coordinate
    ``fs`` (3, springs), and the rows of a material's bending ``Q`` (``qptr``, ``qidx``,
    ``qval``) with its scratch ``fb`` (n, 3) (:data:`NO_BENDING_ROWS` without)."""

    ends: np.ndarray
    rest: np.ndarray
    k: np.ndarray
    c: np.ndarray
    kind: np.ndarray
    tab: np.ndarray
    with_damping: bool
    ptr: np.ndarray
    adj: np.ndarray
    sign: np.ndarray
    fs: np.ndarray
    qptr: np.ndarray
    qidx: np.ndarray
    qval: np.ndarray
    fb: np.ndarray


@numba.njit(cache=True, parallel=True)
def spring_forces_gather(x, v, net, base, f, inv_mass, dt, mode, xo, vo, stage):
    """:func:`spring_forces` on every core, deterministically: each spring's force into ``fs`` (one
    spring per iteration), then each particle gathers its springs' forces in increasing spring
    order (``ptr``/``adj``/``sign``: :func:`incidence`) — the order the serial loop adds them in,
    so the result is bit-identical to it at any thread count (no racy scatter). Each particle's sum
    starts from ``base`` (``f`` itself to add to it, or gravity's force: no pass to copy it first).
    ``net``: the springs' arrays (:class:`GatherSprings`' fields as a plain tuple,
    :attr:`SpringTerm.net`; 32-bit indices, ``fs`` by coordinate, (3, springs)). A material's
    bending (its ``qptr``, ``qidx``, ``qval``: the rows of its ``Q``, ``fb`` (n, 3) scratch;
    ``qptr`` of length 1 without) is summed into ``fb`` in a pass of its own before the gather,
    which starts each particle's sum from ``base + fb``. The bundle's fields are taken out before
    the parallel loops, whose bodies read and write only those (a write through a bundle's field
    in a parallel loop's body is lost: numba issues 7135 and 10338).

    The springs go in blocks of :data:`GATHER_BLOCK` in :func:`spring_layout`'s order: their ends'
    differences gathered into a small array, then :func:`_block_forces` in SIMD. What each of these
    choices bought is in docs/BENCHMARKS.md §7.

    ``mode`` says what each particle does with its summed force ``f`` in the same pass:
    :data:`GATHER_FORCE` keeps it; :data:`GATHER_ACCELERATION` turns it into ``f·m⁻¹`` (the product
    :meth:`Forces.acceleration` takes afterwards otherwise: the same bits, one pass over ``f``
    fewer); :data:`GATHER_RK_STAGE` does that and then computes the particle's next Runge–Kutta
    stage (or the step's update) from ``stage = (x₀, v₀, kx, kv, coef)`` into ``xo``, ``vo``
    (:func:`combine_particle`; ``f`` is ``kv``'s current stage); with :data:`GATHER_KICK_DRIFT` it
    takes symplectic Euler's update, ``v += (f·m⁻¹)·dt; x += v·dt`` into ``xo``, ``vo`` (``x`` and
    ``v`` themselves: separate arguments so that read-only ``x``, ``v`` type-check when there is no
    update, and ``xo``, ``vo`` are then :data:`NO_STATE`; ``inv_mass``: (n, 1), 0 on pins), the
    operations of :func:`cloth_sim.integrators.explicit.kick_drift` in its order. No
    particle's position is read after the first loop, and each core updates the particles whose
    forces it summed, while they are in its cache (a separate serial pass cost most of what the
    second core saved: docs/BENCHMARKS.md §7)."""
    # (GatherSprings' fields; passed as a plain tuple: numba types a NamedTuple argument on a
    # slow path, ~1 µs a call, keeping objects for its first hundreds of calls)
    springs, rest, k, c, kind, tab, with_damping, ptr, adj, sign, fs, qptr, qidx, qval, fb = net
    m = springs.shape[0]
    for b in numba.prange((m + GATHER_BLOCK - 1) // GATHER_BLOCK):
        lo = b * GATHER_BLOCK
        hi = min(lo + GATHER_BLOCK, m)
        d = _block_buffer()
        for s in range(lo, hi):
            i = springs[s, 0]
            j = springs[s, 1]
            t = s - lo
            d[0, t] = x[j, 0] - x[i, 0]
            d[1, t] = x[j, 1] - x[i, 1]
            d[2, t] = x[j, 2] - x[i, 2]
            if with_damping:
                d[3, t] = v[j, 0] - v[i, 0]
                d[4, t] = v[j, 1] - v[i, 1]
                d[5, t] = v[j, 2] - v[i, 2]
        _block_forces(
            d,
            rest[lo:hi],
            k[lo:hi],
            c[lo:hi],
            kind[lo:hi],
            tab,
            with_damping,
            fs[0, lo:hi],
            fs[1, lo:hi],
            fs[2, lo:hi],
        )
    if qptr.shape[0] > 1:  # a material's bending, −(Q x)_p, before any position moves
        for p in numba.prange(f.shape[0]):
            fb[p, 0], fb[p, 1], fb[p, 2] = bending_row(x, qptr, qidx, qval, p)
    for p in numba.prange(f.shape[0]):
        ax, ay, az = base[p, 0], base[p, 1], base[p, 2]
        if qptr.shape[0] > 1:
            ax += fb[p, 0]
            ay += fb[p, 1]
            az += fb[p, 2]
        for e in range(ptr[p], ptr[p + 1]):
            s = adj[e]
            if sign[e] > 0:
                ax += fs[0, s]
                ay += fs[1, s]
                az += fs[2, s]
            else:
                ax -= fs[0, s]
                ay -= fs[1, s]
                az -= fs[2, s]
        if mode == GATHER_ACCELERATION or mode == GATHER_RK_STAGE:
            w = inv_mass[p, 0]
            f[p, 0] = ax * w
            f[p, 1] = ay * w
            f[p, 2] = az * w
            if mode == GATHER_RK_STAGE:
                xb, vb, kx, kv, coef = stage
                combine_particle(xo, vo, xb, vb, kx, kv, coef, p)
            continue
        f[p, 0] = ax
        f[p, 1] = ay
        f[p, 2] = az
        if mode == GATHER_KICK_DRIFT:
            w = inv_mass[p, 0]
            vo[p, 0] += (ax * w) * dt
            vo[p, 1] += (ay * w) * dt
            vo[p, 2] += (az * w) * dt
            xo[p, 0] += vo[p, 0] * dt
            xo[p, 1] += vo[p, 1] * dt
            xo[p, 2] += vo[p, 2] * dt


#: (Kept beside :func:`spring_forces_gather`: a cached kernel that calls a parallel one from
#: another module crashed when loaded from numba's cache (numba/numba#8578, open: the outer
#: function serial, the inner parallel, the fault only from the cache); moved into the integrators'
#: module, RK4's first step from the cache was a segmentation fault every time.)
@numba.njit(cache=True)
def runge_kutta_fused(x, v, A, b, dt, kx, kv, xs, coef, net, base, inv_mass):
    """A whole explicit Runge–Kutta step of tableau ``(A, b)`` in place on ``x``, ``v``, each stage
    one pass of :func:`spring_forces_gather` in :data:`GATHER_RK_STAGE` (its forces, the division
    by the mass and the next stage's state, or in the last stage the step's update): the operations
    of the stage-by-stage Python loop in
    :class:`~cloth_sim.integrators.explicit.ExplicitRungeKutta`, in one call instead of one per
    stage. ``kx``, ``kv`` (stages, n, 3), ``xs`` (n, 3) and ``coef`` (stages,) are scratch;
    ``net``: the springs' :class:`GatherSprings`."""
    stages = b.shape[0]
    for p in range(x.shape[0]):
        for d in range(3):
            kx[0, p, d] = v[p, d]
    for i in range(stages):
        last = i == stages - 1
        m = stages if last else i + 1
        for j in range(m):
            coef[j] = (b[j] if last else A[i + 1, j]) * dt
        spring_forces_gather(
            x if i == 0 else xs,
            kx[i],
            net,
            base,
            kv[i],
            inv_mass,
            0.0,
            np.int64(GATHER_RK_STAGE),  # (a number, not the constant: one signature, not two)
            x if last else xs,
            v if last else kx[i + 1],
            (x, v, kx, kv, coef[:m]),
        )


def incidence(springs: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ptr, adj, sign)``: particle ``p``'s springs are ``adj[ptr[p]:ptr[p+1]]`` in increasing
    order, ``sign`` +1 where ``p`` is the spring's first end (it feels ``+f``), −1 where second."""
    ends = springs.ravel()
    perm = np.argsort(ends, kind="stable")  # stable: within a particle, in spring order
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(ends, minlength=n), out=ptr[1:])
    return ptr, np.ascontiguousarray(perm // 2), np.where(perm % 2 == 0, 1, -1).astype(np.int8)


@numba.njit(cache=True)
def spring_energy(x, springs, rest, k, kind, tab):
    """Total elastic energy of the listed springs."""
    total = 0.0
    for s in range(springs.shape[0]):
        e, _, _ = axial(
            spring_vector(x, springs[s, 0], springs[s, 1])[3], rest[s], k[s], kind[s], tab
        )
        total += e
    return total


@numba.njit(cache=True)
def spring_strains(x, springs, rest):
    """Strain ``(l − L)/L`` of each listed spring."""
    out = np.empty(springs.shape[0])
    for s in range(springs.shape[0]):
        out[s] = spring_vector(x, springs[s, 0], springs[s, 1])[3] / rest[s] - 1.0
    return out


@numba.njit(cache=True)
def max_spring_strain(x, springs, rest):
    """The largest strain ``(l − L)/L`` of the listed springs (``-inf`` for none; NaN where a
    length is NaN), as the largest ``(l/L)²`` and one square root: no square root and no array a
    spring (the node asks it every tick: 0.25 ms at 128×128 by :func:`spring_strains`)."""
    best = -math.inf
    for s in range(springs.shape[0]):
        i, j = springs[s, 0], springs[s, 1]
        dx, dy, dz = x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], x[j, 2] - x[i, 2]
        r = rest[s]
        q = (dx * dx + dy * dy + dz * dz) / (r * r)
        if q != q:
            return math.nan
        if q > best:
            best = q
    return math.sqrt(best) - 1.0 if best >= 0.0 else best


@numba.njit(cache=True)
def vertex_normals(x, tris, out):
    """Unit normals of each particle from its adjacent triangles (area weighted); zero if none."""
    out[:] = 0.0
    for t in range(tris.shape[0]):
        a, b, cc = tris[t, 0], tris[t, 1], tris[t, 2]
        e1x, e1y, e1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        e2x, e2y, e2z = x[cc, 0] - x[a, 0], x[cc, 1] - x[a, 1], x[cc, 2] - x[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        for p in (a, b, cc):
            out[p, 0] += nx
            out[p, 1] += ny
            out[p, 2] += nz
    for p in range(out.shape[0]):
        nrm = np.sqrt(out[p, 0] ** 2 + out[p, 1] ** 2 + out[p, 2] ** 2)
        if nrm > 0.0:
            out[p, 0] /= nrm
            out[p, 1] /= nrm
            out[p, 2] /= nrm


@numba.njit(cache=True)
def wind_forces(x, tris, wind, normals, f):
    """Add ``(n_i·W) n_i`` to each particle's force."""
    vertex_normals(x, tris, normals)
    for p in range(f.shape[0]):
        proj = normals[p, 0] * wind[0] + normals[p, 1] * wind[1] + normals[p, 2] * wind[2]
        f[p, 0] += proj * normals[p, 0]
        f[p, 1] += proj * normals[p, 1]
        f[p, 2] += proj * normals[p, 2]


# --------------------------------------------------------------------------- terms
#: From this many springs (a 19×19 grid) the spring forces run on every core: below it the
#: parallel regions' fork and join cost more than they save (the crossing measured: docs/
#: BENCHMARKS.md §7). Both give the same bits at any thread count.
PARALLEL_MIN_SPRINGS = 2000
# the gather's inverse masses and state outputs when it does not update the state
_NO_MASS = np.zeros((1, 1))
NO_STATE = np.zeros((1, 3))
NO_STAGE = (NO_STATE, NO_STATE, np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), np.zeros(0))

_INCIDENCE: dict = {}


def spring_layout(springs: np.ndarray, n: int) -> tuple:
    """How :func:`spring_forces_gather` lays the springs out: ``(order, ends, ptr, adj, sign)``.

    ``order``: the springs sorted by their lower end, then their higher one, so that the springs
    one core computes are mostly the springs of the particles it then sums (a model lists its
    springs by family: in that order each core computed half of every particle's springs and the
    other core read them back across the cache; docs/BENCHMARKS.md §7). ``ends``: the springs in
    that order (their own orientation, 32-bit). ``ptr``, ``adj``, ``sign``: :func:`incidence` of
    the springs as given — each particle still sums its springs in their given order, the serial
    loop's, so the bits do not change — with ``adj`` pointing at where each spring's force sits in
    ``order`` (32-bit indices: the 64-bit ones' loads cost the gather, docs/BENCHMARKS.md §7)."""
    if n >= 2**32 or len(springs) >= 2**32:
        raise ValueError(
            f"the spring gather indexes with 32 bits: {n} particles, {len(springs)} springs"
        )
    ptr, adj, sign = incidence(springs, n)
    order = np.lexsort((springs.max(axis=1), springs.min(axis=1)))
    where = np.empty(len(order), np.int64)
    where[order] = np.arange(len(order))
    return (
        order,
        springs[order].astype(np.uint32),
        ptr.astype(np.uint32),
        where[adj].astype(np.uint32),
        sign,
    )


#: no bending in the gather: an empty CSR (its ``ptr`` of length 1) and no scratch
NO_BENDING_ROWS = (np.zeros(1, np.uint32), np.zeros(0, np.uint32), np.zeros(0), np.zeros((0, 3)))


def gather_arrays(
    springs, rest, k, c, kind, with_damping: bool, n: int, layout=None, bending=None
) -> GatherSprings:
    """What :func:`spring_forces_gather` reads of these springs (:class:`GatherSprings`): their
    ends and material in :func:`spring_layout`'s order, the Choi–Ko table, the incidence, the
    per-spring force scratch by coordinate (3, springs), and the rows of a material's bending
    ``Q`` with their scratch (:data:`NO_BENDING_ROWS` without). ``layout``: the springs'
    :func:`spring_layout`, if already at hand."""
    order, ends, ptr, adj, sign = spring_layout(springs, n) if layout is None else layout
    if bending is None:
        rows = NO_BENDING_ROWS
    else:
        qptr, qidx, qval = bending.csr
        rows = (  # 32-bit indices, as the springs' (their loads cost the gather)
            qptr.astype(np.uint32),
            qidx.astype(np.uint32),
            qval,
            np.empty((n, 3)),
        )
    return GatherSprings(
        ends,
        rest[order],
        k[order],
        c[order],
        kind[order],
        BUCKLE_TABLE,
        with_damping,
        ptr,
        adj,
        sign,
        np.empty((3, len(springs))),
        *rows,
    )


def _layout_of(model: ClothModel, live: np.ndarray):
    """:func:`spring_layout` of the model's live springs, kept per model and set of live springs (a
    material change rebuilds the force pipeline; the springs it keeps rarely change)."""
    key = (id(model), live.tobytes())
    hit = _INCIDENCE.get(key)
    if hit is None or hit[0] is not model:
        hit = (model, spring_layout(np.ascontiguousarray(model.springs[live]), model.n_particles))
        _INCIDENCE[key] = hit
        while len(_INCIDENCE) > 16:
            _INCIDENCE.pop(next(iter(_INCIDENCE)))
    return hit[1]


class SpringTerm:
    """Hooke (or Choi–Ko) and damping along every spring whose family has a non-zero stiffness or
    damping [1.6, 1.7]: one compiled loop over the live springs. Energy: the elastic energy.
    Jacobian blocks: :func:`spring_jacobian_blocks`, which Baraff–Witkin assembles from and
    :meth:`Forces.jacobians` reports."""

    def __init__(
        self, model: ClothModel, stiffness: np.ndarray, damping: np.ndarray, bending=None
    ):
        names, fam = model.family_names, model.family
        k_on = np.array([np.any(stiffness[fam == i] > 0) for i in range(len(names))], bool)
        c_on = np.array([np.any(damping[fam == i] > 0) for i in range(len(names))], bool)
        self.labels = tuple(
            [f"spring:{n}" for n, on in zip(names, k_on) if on]
            + [f"damping:{n}" for n, on in zip(names, c_on) if on]
        )
        live = (k_on | c_on)[fam] & ((stiffness > 0) | (damping > 0))
        self.springs = np.ascontiguousarray(model.springs[live])
        self.rest = np.ascontiguousarray(model.rest_lengths[live])
        self.k = np.ascontiguousarray(stiffness[live])
        self.c = np.ascontiguousarray(damping[live])
        self.kind = np.ascontiguousarray(model.kind[live])
        self.with_damping = bool(np.any(self.c > 0))
        self.parallel = len(self.springs) >= PARALLEL_MIN_SPRINGS  # decided once, per term
        #: a material's bending summed inside the parallel gather (one pass fewer than a term of
        #: its own, and the fused stages keep fusing); None: the bending is a term of its own
        self.bending = bending if self.parallel else None
        if self.parallel:
            #: what every call of the gather passes first (:func:`gather_arrays`)
            self._gather_args = gather_arrays(
                self.springs,
                self.rest,
                self.k,
                self.c,
                self.kind,
                self.with_damping,
                model.n_particles,
                _layout_of(model, live),
                self.bending,
            )
            g = self._gather_args
            self._incidence, self._fs = (g.ptr, g.adj, g.sign), g.fs
            #: the same as the plain tuple :func:`spring_forces_gather` takes
            self.net = tuple(g)
            if self.bending is not None:
                self.labels = (*self.labels, "bending")

    @property
    def active(self) -> bool:
        return len(self.springs) > 0

    def streamed_bytes(self) -> tuple[int, int]:
        """``(read, written)``: the bytes of this term's own arrays one evaluation streams (rest
        lengths, stiffness, damping, kinds and the springs' ends; the parallel gather's incidence
        lists and its per-spring force array, written and read back). For the memory-bandwidth
        bound of :mod:`cloth_sim.bench.scaling`."""
        read = sum(a.nbytes for a in (self.rest, self.k, self.c, self.kind))
        read += (self._gather_args.ends if self.parallel else self.springs).nbytes
        written = 0
        if self.parallel:
            read += sum(a.nbytes for a in self._incidence) + self._fs.nbytes
            written += self._fs.nbytes
        return read, written

    def add_force(self, x, v, f):
        if self.parallel:
            spring_forces_gather(
                x,
                v,
                self.net,
                f,
                f,
                _NO_MASS,
                0.0,
                GATHER_FORCE,
                NO_STATE,
                NO_STATE,
                NO_STAGE,
            )
        else:  # the same bits on one core
            spring_forces(
                x,
                v,
                self.springs,
                self.rest,
                self.k,
                self.c,
                self.kind,
                BUCKLE_TABLE,
                self.with_damping,
                f,
            )

    def energy(self, x) -> float:
        return float(spring_energy(x, self.springs, self.rest, self.k, self.kind, BUCKLE_TABLE))

    def jacobian_blocks(self, x, v, clamp: bool = False, position_damping: bool = True, out=None):
        """Per-spring ``(kx, dx, cv)`` 3×3 blocks (see :func:`spring_jacobian_blocks`); ``dx`` is
        left zero without ``position_damping``. ``out``: three ``(m, 3, 3)`` arrays to fill."""
        m = len(self.springs)
        if out is None:
            out = np.empty((m, 3, 3)), np.empty((m, 3, 3)), np.empty((m, 3, 3))
        out = tuple(out)
        spring_jacobian_blocks(
            np.ascontiguousarray(x, dtype=np.float64),
            np.ascontiguousarray(v, dtype=np.float64),
            self.springs,
            self.rest,
            self.k,
            self.c,
            self.kind,
            BUCKLE_TABLE,
            clamp,
            position_damping,
            out,
        )
        return out


class GravityTerm:
    """``m g`` [1.4]; energy ``−Σ m_i g·x_i``."""

    labels = ("gravity",)

    def __init__(self, masses: np.ndarray, gravity: np.ndarray):
        self.masses = masses
        self.gravity = gravity
        self.force = masses[:, None] * gravity[None, :]

    def add_force(self, x, v, f):
        f += self.force

    def energy(self, x) -> float:
        return -float(np.sum(self.masses * (x @ self.gravity)))


class WindTerm:
    """``(n_i·W) n_i`` on each particle's unit normal [1.5]; no energy (it is not conservative)."""

    labels = ("wind",)

    def __init__(self, triangles: np.ndarray, wind: np.ndarray, n: int):
        self.triangles = triangles
        self.wind = wind
        self._normals = np.zeros((n, 3))

    def add_force(self, x, v, f):
        wind_forces(x, self.triangles, self.wind, self._normals, f)


class DragTerm:
    """Linear air drag ``−c v``; its Jacobian is ``∂f/∂v = −c I``."""

    labels = ("drag",)

    def __init__(self, drag: float):
        self.drag = drag
        self._dv = None

    def add_force(self, x, v, f):
        if self._dv is None or self._dv.shape != v.shape:
            self._dv = np.empty_like(v)
        f -= np.multiply(v, self.drag, out=self._dv)  # no temporary per evaluation


class BendingTerm:
    """A material's flexural rigidity: ``−(Q ⊗ I₃) x`` (:mod:`cloth_sim.physics.bending`), where
    the springs are not summed on every core (those sum it in their gather)."""

    labels = ("bending",)

    def __init__(self, bending):
        self.bending = bending

    def add_force(self, x, v, f):
        self.bending.add_force(x, f)

    def energy(self, x) -> float:
        return self.bending.energy(x)


class Forces:
    """The force pipeline of one simulator: a list of terms compiled from the scene's non-zero
    ones (:attr:`terms`). Each term adds its force; the conservative ones report their energy; the
    springs and drag have Jacobians. Rebuild it (cheap) whenever stiffness, damping, gravity, wind
    or drag change: integrators receive the current pipeline with every step.
    """

    def __init__(
        self,
        model: ClothModel,
        stiffness: np.ndarray,
        damping: np.ndarray,
        gravity=(0.0, 0.0, -9.81),
        wind=None,
        drag: float = 0.0,
    ):
        self.model = model
        self.gravity = np.asarray(gravity, dtype=np.float64).reshape(3)
        wind = None if wind is None else np.asarray(wind, dtype=np.float64).reshape(3)
        self.drag = float(drag)
        bending = getattr(model, "bending", None)
        self.bending = bending if bending is not None and bending.Q.nnz else None
        self.spring_term = SpringTerm(
            model,
            np.asarray(stiffness, np.float64),
            np.asarray(damping, np.float64),
            self.bending,
        )
        # evaluation order: gravity first (it initialises the sum), then springs, wind, drag
        terms: list = (
            [GravityTerm(model.masses, self.gravity)] if np.any(self.gravity != 0) else []
        )
        if self.spring_term.active:
            terms.append(self.spring_term)
        if self.bending is not None and not (
            self.spring_term.active and self.spring_term.bending is not None
        ):
            terms.append(BendingTerm(self.bending))
        if wind is not None and np.any(wind != 0) and len(model.triangles):
            terms.append(WindTerm(model.triangles, wind, model.n_particles))
            self.wind = wind
        else:
            self.wind = None
        if self.drag > 0:
            terms.append(DragTerm(self.drag))
        self.terms = tuple(terms)
        order = [self.spring_term] + [t for t in terms if t is not self.spring_term]
        self.active_terms = tuple(label for t in order for label in t.labels)
        inv = 1.0 / model.masses
        inv[model.pinned] = 0.0
        self.inv_mass = inv[:, None].copy()
        # the same values per coordinate: an in-place product with the (n, 1) column makes numpy
        # allocate a temporary of the whole array on every evaluation
        self._inv_mass3 = np.repeat(self.inv_mass, 3, axis=1)
        self.evaluations = 0
        #: where the springs run on every core and are the last term, their gather takes the whole
        #: sum from here (gravity's force, or zeros) and the update after it
        #: (:meth:`gather_update`, :meth:`acceleration`); ``None`` otherwise
        self.gather_base = None
        st = self.spring_term
        if st.parallel and self.terms[-1] is st:
            if len(self.terms) == 2 and isinstance(self.terms[0], GravityTerm):
                self.gather_base = self.terms[0].force
            elif len(self.terms) == 1:
                self.gather_base = np.zeros((model.n_particles, 3))
        if self.gather_base is not None:  # runge_kutta_fused calls the parallel gather
            start_pool()

    # the spring term's arrays, which the implicit integrators assemble from
    springs = property(lambda self: self.spring_term.springs)
    rest = property(lambda self: self.spring_term.rest)
    k = property(lambda self: self.spring_term.k)
    c = property(lambda self: self.spring_term.c)
    kind = property(lambda self: self.spring_term.kind)
    with_damping = property(lambda self: self.spring_term.with_damping)

    @property
    def n_active_springs(self) -> int:
        """How many springs a force evaluation visits."""
        return len(self.spring_term.springs)

    def force(self, x: np.ndarray, v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Total force on each particle (pins included: their force is reported, not applied)."""
        f = np.empty_like(x) if out is None else out
        for term in self._start_sum(f):
            term.add_force(x, v, f)
        self.evaluations += 1
        return f

    def _start_sum(self, f: np.ndarray) -> tuple:
        """Set ``f`` to the sum's start — gravity when it is on (it initialises the sum: 0 + m·g
        is m·g), else 0 — and return the terms still to add."""
        terms = self.terms
        if terms and isinstance(terms[0], GravityTerm):
            np.copyto(f, terms[0].force)
            return terms[1:]
        f[:] = 0.0
        return terms

    def gather_update(self, x, v, out, dt: float, mode: int, xo, vo, stage=None) -> None:
        """One force evaluation with an update fused into the springs' gather, where
        :attr:`fuses_stages` (the springs summed on every core, and the last term): ``mode`` one of
        :func:`spring_forces_gather`'s (:data:`GATHER_KICK_DRIFT`: symplectic Euler's ``v +=
        (f·m⁻¹)·dt``, ``x += v·dt`` into ``xo``, ``vo``; :data:`GATHER_RK_STAGE`: a Runge–Kutta
        stage, ``stage`` its arrays), the summed force in ``out``. The integrators' steps
        (:mod:`cloth_sim.integrators.explicit`) call it; what the update is belongs to them."""
        spring_forces_gather(
            x,
            v,
            self.spring_term.net,
            self.gather_base,
            out,
            self.inv_mass,
            dt,
            mode,
            xo,
            vo,
            NO_STAGE if stage is None else stage,
        )
        self.evaluations += 1

    def acceleration(
        self, x: np.ndarray, v: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """``M⁻¹ f``, zero on pinned particles. Where the springs are summed on every core and are
        the last term, the division by the mass runs inside their gather (the same bits)."""
        a = np.empty_like(x) if out is None else out
        base = self.gather_base
        if base is not None:
            spring_forces_gather(
                x,
                v,
                self.spring_term.net,
                base,
                a,
                self.inv_mass,
                0.0,
                GATHER_ACCELERATION,
                NO_STATE,
                NO_STATE,
                NO_STAGE,
            )
            self.evaluations += 1
            return a
        self.force(x, v, a)
        a *= self._inv_mass3
        return a

    @property
    def fuses_stages(self) -> bool:
        """Whether :meth:`gather_update` applies (the springs on every core, and last)."""
        return self.gather_base is not None

    def implicit_force(self, x: np.ndarray, v: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The force of the terms :meth:`jacobians` differentiates, into ``out``: the springs
        (elastic and damping), the bending and the drag; without gravity and the wind, which the
        implicit methods take at the step's start."""
        out[:] = 0.0
        for term in self.terms:
            if not isinstance(term, (GravityTerm, WindTerm)):
                term.add_force(x, v, out)
        return out

    def spring_energy(self, x: np.ndarray) -> float:
        """The elastic energy: the springs' and, with a material's bending, the bending's."""
        e = self.spring_term.energy(x)
        if self.bending is not None:
            e += self.bending.energy(x)
        return e

    def jacobians(self, x: np.ndarray, v: np.ndarray, clamp: bool = False):
        """``(∂f/∂x, ∂f/∂v)`` as ``3n×3n`` sparse matrices (row ``3i + a`` is component ``a`` of
        the force on particle ``i``), exact for every term that depends on the state: Hooke and the
        Choi–Ko interactions, spring damping (including its dependence on positions) and drag.
        Gravity is constant. Wind is left out: its force depends on the normals of the adjacent
        triangles, and every implicit method here treats it explicitly. ``clamp`` drops the
        compressive, indefinite part of the elastic blocks, as the implicit integrators may.

        The blocks come from :meth:`SpringTerm.jacobian_blocks`, the kernel Baraff–Witkin's
        assembly uses, so the finite-difference tests of this method cover the solver's matrix."""
        n = len(x)
        springs = self.spring_term.springs
        kx, dx, cv = self.spring_term.jacobian_blocks(x, v, clamp)
        # ∂f_j/∂x_i is kxᵀ (= kx) for the elastic part and +dx for damping, whose r = v_j − v_i and
        # u both change sign with the pair's order
        dfdx = spring_coupling_matrix(springs, kx + dx, np.transpose(kx, (0, 2, 1)) + dx, n)
        dfdv = spring_coupling_matrix(springs, cv, cv, n)
        if self.bending is not None:
            dfdx = dfdx - self.bending.hessian()
        if self.drag > 0:
            dfdv = dfdv - self.drag * sp.identity(3 * n, format="csr")
        return dfdx.tocsr(), dfdv.tocsr()


def spring_sums(springs: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """``Σ_j w_ij`` per particle over the springs it belongs to (a graph Laplacian's diagonal)."""
    return np.bincount(
        springs.ravel(), weights=np.repeat(np.asarray(w, np.float64), 2), minlength=n
    )


def spring_coupling_matrix(
    springs: np.ndarray, row_i: np.ndarray, row_j: np.ndarray, n: int
) -> sp.csr_matrix:
    """Sparse ``3n×3n`` matrix coupling each spring's two particles ``(i, j)``: block ``(i, j)`` is
    ``row_i[s]`` and block ``(i, i)`` is ``−row_i[s]``; block ``(j, i)`` is ``row_j[s]`` and
    ``(j, j)`` is ``−row_j[s]`` (duplicates add). It is the pattern of every pairwise force's
    Jacobian, and with ``row_i = row_j = −k uuᵀ`` the stiffness matrix ``K``."""
    m = len(springs)
    i, j = springs[:, 0], springs[:, 1]
    ar = np.arange(3)
    rows, cols, vals = [], [], []
    for a, b, blocks in ((i, j, row_i), (i, i, -row_i), (j, i, row_j), (j, j, -row_j)):
        rows.append(np.broadcast_to((3 * a)[:, None, None] + ar[None, :, None], (m, 3, 3)).ravel())
        cols.append(np.broadcast_to((3 * b)[:, None, None] + ar[None, None, :], (m, 3, 3)).ravel())
        vals.append(np.ascontiguousarray(blocks).ravel())
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n)
    )


# --------------------------------------------------------------------------- Jacobians
@numba.njit(cache=True, inline="always")
def _stiffness_coefficients(l, L, k, kind, tab, clamp):
    """``(a, t)`` with ``∂f_i/∂x_j = a·uuᵀ + t·(I − uuᵀ)`` for one spring: ``a = E''(l)``,
    ``t = E'(l)/l``. ``clamp`` drops the negative (compressive, indefinite) parts."""
    _, de, d2e = axial(l, L, k, kind, tab)
    a, t = d2e, de / l
    if clamp:
        if a < 0.0:
            a = 0.0
        if t < 0.0:
            t = 0.0
    return a, t


@numba.njit(cache=True, parallel=True)
def spring_jacobian_blocks(x, v, springs, rest, k, c, kind, tab, clamp, position_damping, out):
    """Per-spring 3×3 blocks of the force Jacobians, as ``∂f_i/∂x_j`` and ``∂f_i/∂v_j``, into
    ``out = (kx, dx, cv)`` (three ``(m, 3, 3)`` arrays):

    * ``kx[s]`` — elastic ``E''·uuᵀ + (E'/l)·(I − uuᵀ)`` (symmetric),
    * ``dx[s]`` — the damping force's dependence on positions, ``(c/l)·(u (P r)ᵀ + (r·u) P)`` with
      ``P = I − uuᵀ`` and ``r = v_j − v_i`` (not symmetric),
    * ``cv[s]`` — damping ``c·uuᵀ``.

    The other blocks follow: ``∂f_i/∂x_i = ∂f_j/∂x_j = −block``, ``∂f_j/∂x_i = blockᵀ`` (the
    damping blocks ``dx`` change sign with ``r``: ``∂f_j/∂x_i = dx``, as ``f_j = −f_i``).
    Without ``position_damping`` ``dx`` stays zero (Baraff–Witkin leave it out of their matrix).
    Springs on every core (each writes only its own blocks; the three arrays taken out of
    ``out`` before the parallel loop, whose body would lose writes through a tuple's items:
    docs/contributing.md)."""
    kx, dx, cv = out
    for s in numba.prange(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        ddx, ddy, ddz, l = spring_vector(x, i, j)
        kx[s] = 0.0
        dx[s] = 0.0
        cv[s] = 0.0
        if l < 1e-300:
            continue
        # tuples, not arrays: an array per spring was a heap allocation (docs/BENCHMARKS.md §7)
        u = (ddx / l, ddy / l, ddz / l)
        a, t = _stiffness_coefficients(l, rest[s], k[s], kind[s], tab, clamp)
        r = (v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], v[j, 2] - v[i, 2])
        ru = r[0] * u[0] + r[1] * u[1] + r[2] * u[2]
        pr = (r[0] - ru * u[0], r[1] - ru * u[1], r[2] - ru * u[2])
        cl = c[s] / l
        for p in range(3):
            for q in range(3):
                uu = u[p] * u[q]
                delta = 1.0 if p == q else 0.0
                kx[s, p, q] = a * uu + t * (delta - uu)
                cv[s, p, q] = c[s] * uu
                if position_damping:
                    dx[s, p, q] = cl * (u[p] * pr[q] + ru * (delta - uu))
