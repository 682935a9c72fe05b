"""The per-vertex contact terms of :mod:`~cloth_sim.integrators.vbd`, and its 3×3 solve: what the
general sweep and the grid's blocks (:mod:`~cloth_sim.integrators.vbd_grid`) both take a vertex's
Newton step with (the penalty and lagged friction of a collider, the step held at a contact's
onset and within the conservative bounds). Each function is the vertex's part alone, on its own
rows of the arrays it is given. The method and its bounds: :mod:`cloth_sim.integrators.vbd`.
"""

from __future__ import annotations

import math

import numba

from ..contact.collider_kernels import MESH, beyond_reach, carried, mesh_sdf, pose_change, sdf
from ..kernel_cache import keep_true


@numba.njit(cache=True, inline="always")
def solve3(a, b, c, d, e, f, fx, fy, fz):
    """``H⁻¹ f`` for a symmetric positive definite ``H`` (6 entries); zeros if it is singular."""
    c00 = d * f - e * e
    c01 = c * e - b * f
    c02 = b * e - c * d
    det = a * c00 + b * c01 + c * c02
    if not det > 1e-300:
        return 0.0, 0.0, 0.0
    c11 = a * f - c * c
    c12 = b * c - a * e
    c22 = a * d - b * b
    inv = 1.0 / det
    return (
        (c00 * fx + c01 * fy + c02 * fz) * inv,
        (c01 * fx + c11 * fy + c12 * fz) * inv,
        (c02 * fx + c12 * fy + c22 * fz) * inv,
    )


@numba.njit(cache=True, inline="always")
def press(mag, s, n, fh):
    """A contact's force ``mag·n`` and stiffness ``s·n nᵀ`` (``n``: its unit normal, three
    numbers) added to a vertex's block ``fh`` (:mod:`~cloth_sim.integrators.vbd_terms`: its force
    and Hessian, nine numbers)."""
    nx, ny, nz = n
    f0, f1, f2, h0, h1, h2, h3, h4, h5 = fh
    return (
        f0 + mag * nx,
        f1 + mag * ny,
        f2 + mag * nz,
        h0 + s * nx * nx,
        h1 + s * nx * ny,
        h2 + s * nx * nz,
        h3 + s * ny * ny,
        h4 + s * ny * nz,
        h5 + s * nz * nz,
    )


@numba.njit(cache=True, inline="always")
def slide(sf, t, s, n, fh):
    """Friction's force ``−sf·t`` (``t``: the tangential motion) and its stiffness ``s (I − n
    nᵀ)`` (the normal held) added to a vertex's block ``fh``."""
    tx, ty, tz = t
    nx, ny, nz = n
    f0, f1, f2, h0, h1, h2, h3, h4, h5 = fh
    return (
        f0 - sf * tx,
        f1 - sf * ty,
        f2 - sf * tz,
        h0 + (s - s * nx * nx),
        h1 - s * nx * ny,
        h2 - s * nx * nz,
        h3 + (s - s * ny * ny),
        h4 - s * ny * nz,
        h5 + (s - s * nz * nz),
    )


@numba.njit(cache=True, inline="always")
def colliders_at(i, x, xt, ckind, pose, pose0, cgeo, cmu, cbank, law, fh, seen):
    """Vertex ``i``'s collider contacts added to its block ``fh``: the penalty, and IPC's lagged
    friction on its motion over the step relative to the collider's point under it; returns the
    block's nine numbers and whether it touches one, flat (a tuple in a tuple, unpacked in a
    parallel loop, fails numba's array analysis). ``pose``: the colliders' positions, rotations
    and reaches now; ``pose0``: their positions and rotations at the step's start; ``law``:
    ``(τ, the penalty's stiffness, friction's ε)``. Each collider's signed distance and normal
    at ``x[i]`` go to ``seen[i, c]``, for :func:`onset` at the same point (beyond its reach by
    the thickness: that lower bound and no normal, unasked), which reads them instead of asking
    again (:func:`asked`: inlined a second time there, the queries doubled their share of the
    sweeps' compilation; storing the primitives' answers costs a step nothing measurable). (The
    arrays that the calls inside that are not inlined, the
    mesh's search, take are passed as they are: in a bundle of more, those calls would count the
    bundle's references on every call.) ``seen[i, c, 4]``: the last search's lower bound on the
    distance while the vertex keeps within its allowance (a collider it keeps beyond ``τ`` is
    asked nothing)."""
    tau, kc, eps = law
    cpos, crot, creach = pose
    cpos0, crot0 = pose0
    touched = False
    for c in range(ckind.shape[0]):
        # kept beyond the thickness wherever the vertex may be until the next search (the
        # search's bound, ``seen[i, c, 4]``: collider_allowances): no contact, without the
        # query; that lower bound kept for onset, which asks only where a step is longer
        clear = seen[i, c, 4]
        if clear >= tau:
            seen[i, c, 0], seen[i, c, 1], seen[i, c, 2], seen[i, c, 3] = clear, 0.0, 0.0, 0.0
            continue
        # beyond its reach by the thickness: no contact, without the query (a robot's links each
        # asked by every vertex near any of them: most of a Franka Panda's step); a mesh's lower
        # bound kept for onset
        far = beyond_reach(cpos, creach, c, x[i, 0], x[i, 1], x[i, 2])
        if far >= tau:
            seen[i, c, 0], seen[i, c, 1], seen[i, c, 2], seen[i, c, 3] = far, 0.0, 0.0, 0.0
            continue
        if ckind[c] == MESH:
            reals, ints, starts = cbank
            d, nx, ny, nz = mesh_sdf(
                cpos, crot, cgeo, c, x[i, 0], x[i, 1], x[i, 2], reals, ints, starts
            )
        else:
            d, nx, ny, nz = sdf(ckind[c], cpos, crot, cgeo, c, x[i, 0], x[i, 1], x[i, 2])
        seen[i, c, 0], seen[i, c, 1], seen[i, c, 2], seen[i, c, 3] = d, nx, ny, nz
        p = tau - d
        if p <= 0.0:
            continue
        touched = True
        lam = kc * p
        fh = press(lam, kc, (nx, ny, nz), fh)
        mu = cmu[c]
        if mu <= 0.0:
            continue
        # where the collider's point now under the vertex was at the step's start
        sx, sy, sz = carried(cpos0, crot0, cpos, crot, c, x[i, 0], x[i, 1], x[i, 2])
        rx, ry, rz = sx - xt[i, 0], sy - xt[i, 1], sz - xt[i, 2]
        rn = rx * nx + ry * ny + rz * nz
        tx, ty, tz = rx - rn * nx, ry - rn * ny, rz - rn * nz
        tl = math.sqrt(tx * tx + ty * ty + tz * tz)
        g = 1.0 / tl if tl > eps else (2.0 - tl / eps) / eps
        s = mu * lam * g
        fh = slide(s, (tx, ty, tz), s, (nx, ny, nz), fh)
    f0, f1, f2, h0, h1, h2, h3, h4, h5 = fh
    return f0, f1, f2, h0, h1, h2, h3, h4, h5, touched


@numba.njit(cache=True, inline="always")
def within(px, py, pz, cx, cy, cz, allow_i, dmin_i, gamma):
    """A vertex held within its bounds where that needs no look at its pairs (:func:`truncate`):
    vertex at ``p`` whose search was made at ``c``, its allowance and its nearest pair's
    distance; returns the position, whether it was cut and whether that is final (else
    :func:`truncate` must look at its pairs, from the same scale). Scalars only: the inlined
    :func:`truncate`, with its nine arrays, cost ~40 ns a vertex where this arithmetic is a few
    (``chebyshev`` at 128×128: 0.70 → 0.06 ms, the same bits; docs/BENCHMARKS.md §11); the
    callers take :func:`truncate` only where this leaves the pairs to look at."""
    if allow_i == math.inf and dmin_i == math.inf:
        return px, py, pz, False, True
    ex, ey, ez = px - cx, py - cy, pz - cz
    t = 1.0
    el = math.sqrt(ex * ex + ey * ey + ez * ez)
    if el > allow_i:
        t = allow_i / el
    if el * t <= gamma * dmin_i:
        if t >= 1.0:
            return px, py, pz, False, True
        return cx + t * ex, cy + t * ey, cz + t * ez, True, True
    return px, py, pz, False, False


@numba.njit(cache=True, inline="always")
def truncate(i, p, x_cd, allow, gptr, grec, pidx, pcoef, pnrm, pdist, dmin, gamma):
    """Vertex ``i`` moved to ``p`` (three numbers), held within its bounds from where the last
    search was made (``x_cd``): its displacement scaled down (whole: every bound is linear in it)
    so that it moves at most ``allow[i]`` (the pairs the search did not find, the far side of a
    collider) and, for each pair the search found (its records ``grec``), approaches the pair's
    other side along the pair's normal by at most ``γ`` times their distance (Newton's planar
    truncation of the paper's bound: moving away, or sideways, costs nothing). Both sides of a pair
    approach by at most ``γ·d`` each, ``γ < ½``, and the normal separates them by ``d`` at the
    search (the nearest points' direction: every point of the one primitive is at least ``d`` from
    every point of the other along it), so no pair crosses. ``dmin``: each vertex's nearest pair at
    the search (a displacement below ``γ·dmin`` needs no look at its pairs). Called where
    :func:`within`, which answers every vertex that needs no look at its pairs, was not settled.
    Returns the position and whether it was cut."""
    px, py, pz = p
    ex, ey, ez = px - x_cd[i, 0], py - x_cd[i, 1], pz - x_cd[i, 2]
    t = 1.0
    el = math.sqrt(ex * ex + ey * ey + ez * ez)
    if el > allow[i]:
        t = allow[i] / el
    for q in range(gptr[i], gptr[i + 1]):
        r = grec[q]
        pair = r // 4
        w = pcoef[pair, r % 4]
        # its approach to the other side: along −n for the side with positive weights
        toward = -(pnrm[pair, 0] * ex + pnrm[pair, 1] * ey + pnrm[pair, 2] * ez)
        if w < 0.0:
            toward = -toward
        room = gamma * pdist[pair]
        if toward * t > room:
            t = room / toward
    if t >= 1.0:
        return px, py, pz, False
    return x_cd[i, 0] + t * ex, x_cd[i, 1] + t * ey, x_cd[i, 2] + t * ez, True


@numba.njit(cache=True, error_model="numpy", fastmath=False)
def asked(shapes, c, x, y, z):
    """Collider ``c``'s signed distance and normal at ``(x, y, z)`` (``shapes``: :func:`onset`'s),
    for :func:`onset` where :func:`colliders_at` left no answer of its own: compiled on its own
    and called, not inlined. Inlined in :func:`onset` as well as in :func:`colliders_at`, the
    queries' code was in every sweep twice: ``vbd_grid._touch_colour`` took 65.5 s of one core to
    compile, 39.4 s with this called, and ``vbd_kernels.sweep`` 41.1 s, 25.7 s (``cloth-sim bench
    compile``, side by side, 2026-12-02). ``error_model="numpy"``, as
    the sweeps that call it (a division by zero does not raise). ``fastmath=False`` said, not
    left to numba: a callee that sets no flag takes its first caller's, and its cached build serves
    every later caller. Left unset, ``asked`` contracted its arithmetic into fused multiply-adds
    where ``vbd_grid``'s kernels (``fastmath={"contract"}``) compiled it first, as ``make install``
    does, and not where ``sweep`` did, as a process compiling lazily does: robot_sweep and drape on
    ``vbd`` ended on other bits by how their kernels had been compiled
    (``test_kernel_cache.py``)."""
    kinds, pos, rot, geo, reals, ints, starts = shapes
    if kinds[c] == MESH:
        return mesh_sdf(pos, rot, geo, c, x, y, z, reals, ints, starts)
    return sdf(kinds[c], pos, rot, geo, c, x, y, z)


@numba.njit(cache=True, inline="always")
def onset(i, s, x, records, tau, colliders, shapes, seen):
    """Vertex ``i``'s step ``s`` from ``x[i]`` with the part that would press a contact not yet
    pressed (distance at least ``τ``: not in the step's Hessian) taken off along that contact's
    normal, so that it stops at its onset (the next iteration sees it); the motion along the
    surface stays. (A self-contact pair within :data:`~cloth_sim.integrators.vbd_terms.NEAR` of
    its onset is in the Hessian already, so its cut is rare: a cut moves one side of the pair
    alone.) The self-contact pairs by their linear distance, the first ``colliders``
    colliders by their signed distance along their normal, as :func:`colliders_at` left it in
    ``seen[i]`` for the same point; where that left only a lower bound, asked here through
    :func:`asked` (``shapes = (kinds, positions, rotations, geometry, and the mesh bank's reals,
    ints and starts)``) where the step is longer than the bound's room (a shorter step stops short
    of the onset whatever the normal: ``n·s ≥ −|s| > τ − d``).
    ``s``: three numbers, and so is what it returns. ``records``: the vertices' self-contact
    records' ``(ptr, weights, normals, distances)``
    (:func:`cloth_sim.integrators.vbd.pack_records`)."""
    rec_ptr, rec_w, rec_n, rec_d = records
    sx, sy, sz = s
    for q in range(rec_ptr[i], rec_ptr[i + 1]):
        d = rec_d[q]  # (its distance as self_contacts_at found it for this step)
        if d < tau:
            continue
        w = rec_w[q, 4]
        nx, ny, nz = w * rec_n[q, 0], w * rec_n[q, 1], w * rec_n[q, 2]
        over = (tau - d) - (nx * sx + ny * sy + nz * sz)  # how far past the onset d would go
        if over > 0.0:
            f = over / (nx * nx + ny * ny + nz * nz)
            sx, sy, sz = sx + f * nx, sy + f * ny, sz + f * nz
    for c in range(colliders):
        d, nx, ny, nz = seen[i, c, 0], seen[i, c, 1], seen[i, c, 2], seen[i, c, 3]
        if nx == 0.0 and ny == 0.0 and nz == 0.0:
            # a lower bound d ≥ τ (colliders_at did not ask it): a step shorter than d − τ stops
            # short of the onset whatever the normal; a longer one asks
            if d - tau >= math.sqrt(sx * sx + sy * sy + sz * sz) * (1.0 + 1e-9):
                continue
            d, nx, ny, nz = asked(shapes, c, x[i, 0], x[i, 1], x[i, 2])
        if d < tau:
            continue
        over = (tau - d) - (nx * sx + ny * sy + nz * sz)
        if over > 0.0:
            sx, sy, sz = sx + over * nx, sy + over * ny, sz + over * nz
    return sx, sy, sz


@numba.njit(cache=True)
def comes_within(x, free, pos, reach, c, motion, allow, tau):
    """Whether collider ``c`` (``pos``, ``reach``: every collider's position and reach at the
    step's end), its points moving at most ``motion`` over the step, could come within ``tau`` of
    a free vertex of ``x`` moving at most its ``allow``: it was within its reach of its position
    at the step's end, and within that reach plus ``motion`` all along. A half-space always
    could."""
    if not reach[c] < math.inf:
        return True
    for i in range(x.shape[0]):
        if not free[i]:
            continue
        beyond = beyond_reach(pos, reach, c, x[i, 0], x[i, 1], x[i, 2]) - motion
        if not beyond >= (allow[i] + 1.01 * tau) * (1.0 + 1e-9):  # (a NaN is near)
            return True
    return False


@numba.njit(cache=True)
def moving_within_reach(x, free, co, allow, tau):
    """Whether a collider of ``co`` that moved over the step (from ``pos0``, ``rot0`` to ``pos``,
    ``rot``) could come within ``tau`` of a free vertex of ``x`` moving at most its ``allow``
    (:func:`comes_within`, its points moving at most ``|Δpos| + reach·‖ΔR‖``). One that moved far
    from the cloth is asked nothing, as a still one."""
    kinds, pos, rot, pos0, rot0, reach = co.kinds, co.pos, co.rot, co.pos0, co.rot0, co.reach
    for c in range(kinds.shape[0]):
        shift, turn = pose_change(pos, rot, pos0, rot0, c)
        if shift == 0.0 and turn == 0.0:
            continue
        if comes_within(x, free, pos, reach, c, shift + reach[c] * turn, allow, tau):
            return True
    return False


@numba.njit(cache=True)
def travel_within_reach(x, free, co, allow, tau, travel):
    """The farthest ``travel[c]`` (how far collider ``c``'s points moved over the step:
    :meth:`~cloth_sim.contact.colliders.Contacts.travels`) among the colliders of ``co`` that
    could come within ``tau`` of a free vertex of ``x`` moving at most its ``allow``
    (:func:`comes_within`); 0 where none did. A link moving fast far from the cloth is not
    counted."""
    farthest = 0.0
    for c in range(co.kinds.shape[0]):
        if travel[c] > farthest and comes_within(
            x, free, co.pos, co.reach, c, travel[c], allow, tau
        ):
            farthest = travel[c]
    return farthest


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
