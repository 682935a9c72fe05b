"""The force kernels of :mod:`cloth_sim.physics.forces`: the springs' forces (one core, and
gathered on every core with an update fused in), their energy and strains, the vertex normals
and the wind, and the springs' Jacobian blocks for the implicit methods.

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
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic
from scipy.optimize import brentq

from ..kernel_cache import keep_true
from ..kinds import LINEAR, TENSION_ONLY
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


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
