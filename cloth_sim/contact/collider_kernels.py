"""The colliders' kernels, apart from the collider classes and the contact stage that call them
(:mod:`cloth_sim.contact.colliders`): each shape's signed distance and normal (:func:`sdf`, a
mesh's :func:`mesh_sdf`), a collider's pose change and reach, the contact stage's kernel
(:func:`resolve_contacts`: continuous detection, projection with friction, the velocity filter)
and its crease pass, and the bundle they read (:class:`PackedColliders`). The integrators' contact
terms (:mod:`cloth_sim.integrators.vbd_contact`) ask the same :func:`sdf`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from ..kernel_cache import keep_true
from . import triangle_meshes
from .triangle_meshes import mesh_distance

#: the collider kinds' codes in :attr:`PackedColliders.kinds`
PLANE, SPHERE, BOX, CAPSULE, CYLINDER, MESH = 0, 1, 2, 3, 4, 5
#: the fraction of ``thickness`` within which a particle counts as touching (its velocity is
#: filtered) though not inside (its position is not moved)
CONTACT_TOLERANCE = 0.02


@numba.njit(cache=True, inline="always")
def sdf(kind, pos, rot, geo, c, x, y, z):
    """Signed distance of the point ``(x, y, z)`` from collider ``c`` of the packed colliders
    (``pos[c]`` its position, ``rot[c]`` its rotation, ``geo[c]`` its geometry; ``kind`` its
    kind, any but ``MESH``: :func:`mesh_sdf`) and the outward unit normal there (the distance's
    gradient).

    A kernel asks ``mesh_sdf`` where ``kind == MESH`` and this otherwise, in two branches of its
    own: one inlined function taking the packed meshes (a tuple of ten arrays) bound them anew
    at each call, ten reference counts up and down (atomic) whether the mesh branch ran or not,
    ~95 ns a call: the contact stage's loop took 113 ns a particle against one plane, 10 with
    the meshes out of the inlined code (docs/BENCHMARKS.md §11). The collider is named by its
    index rather than by views ``pos[c]``, … for the same reason."""
    dx, dy, dz = x - pos[c, 0], y - pos[c, 1], z - pos[c, 2]
    if kind == PLANE:
        nx = rot[c, 0, 0] * geo[c, 0] + rot[c, 0, 1] * geo[c, 1] + rot[c, 0, 2] * geo[c, 2]
        ny = rot[c, 1, 0] * geo[c, 0] + rot[c, 1, 1] * geo[c, 1] + rot[c, 1, 2] * geo[c, 2]
        nz = rot[c, 2, 0] * geo[c, 0] + rot[c, 2, 1] * geo[c, 1] + rot[c, 2, 2] * geo[c, 2]
        return nx * dx + ny * dy + nz * dz, nx, ny, nz
    if kind == SPHERE:
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        if r < 1e-300:
            return -geo[c, 0], 0.0, 0.0, 1.0
        return r - geo[c, 0], dx / r, dy / r, dz / r
    if kind == CAPSULE:
        hx = rot[c, 0, 0] * geo[c, 0] + rot[c, 0, 1] * geo[c, 1] + rot[c, 0, 2] * geo[c, 2]
        hy = rot[c, 1, 0] * geo[c, 0] + rot[c, 1, 1] * geo[c, 1] + rot[c, 1, 2] * geo[c, 2]
        hz = rot[c, 2, 0] * geo[c, 0] + rot[c, 2, 1] * geo[c, 1] + rot[c, 2, 2] * geo[c, 2]
        hh = hx * hx + hy * hy + hz * hz
        s = 0.0
        if hh > 0.0:
            s = (dx * hx + dy * hy + dz * hz) / hh
            s = min(1.0, max(-1.0, s))
        ex, ey, ez = dx - s * hx, dy - s * hy, dz - s * hz
        r = math.sqrt(ex * ex + ey * ey + ez * ez)
        if r < 1e-300:  # on the axis: any perpendicular direction
            if abs(hx) < 0.9 * math.sqrt(hh) or hh == 0.0:
                ux, uy, uz = 0.0, hz, -hy
            else:
                ux, uy, uz = -hz, 0.0, hx
            u = math.sqrt(ux * ux + uy * uy + uz * uz)
            if u == 0.0:
                return -geo[c, 3], 0.0, 0.0, 1.0
            return -geo[c, 3], ux / u, uy / u, uz / u
        return r - geo[c, 3], ex / r, ey / r, ez / r
    # BOX, CYLINDER: in the shape's frame
    qx, qy, qz = _to_frame(pos, rot, c, x, y, z)
    if kind == CYLINDER:
        d, lx, ly, lz = cylinder_distance(geo[c, 0], geo[c, 1], qx, qy, qz)
    else:
        d, lx, ly, lz = box_distance(geo[c, 0], geo[c, 1], geo[c, 2], qx, qy, qz)
    nx, ny, nz = _from_frame(rot, c, lx, ly, lz)
    return d, nx, ny, nz


@numba.njit(cache=True, inline="always")
def mesh_sdf(pos, rot, geo, c, x, y, z, reals, ints, starts, cutoff=math.inf):
    """:func:`sdf` of a Mesh collider ``c`` (``geo[c, 0]`` its index in ``bank``, the packed
    meshes of :func:`.triangle_meshes.pack`): signed where the mesh is closed, unsigned where it is
    open; a point outside and at least ``cutoff`` from it is answered ``(cutoff, 0, 0, 0)`` (a
    query that only asks whether the point is within the cutoff walks less of the tree)."""
    qx, qy, qz = _to_frame(pos, rot, c, x, y, z)
    d, lx, ly, lz = mesh_distance(reals, ints, starts, int(geo[c, 0]), qx, qy, qz, cutoff)
    nx, ny, nz = _from_frame(rot, c, lx, ly, lz)
    return d, nx, ny, nz


@numba.njit(cache=True, inline="always")
def _to_frame(pos, rot, c, x, y, z):
    """The point ``(x, y, z)`` in collider ``c``'s own frame."""
    dx, dy, dz = x - pos[c, 0], y - pos[c, 1], z - pos[c, 2]
    return (
        rot[c, 0, 0] * dx + rot[c, 1, 0] * dy + rot[c, 2, 0] * dz,
        rot[c, 0, 1] * dx + rot[c, 1, 1] * dy + rot[c, 2, 1] * dz,
        rot[c, 0, 2] * dx + rot[c, 1, 2] * dy + rot[c, 2, 2] * dz,
    )


@numba.njit(cache=True, inline="always")
def _from_frame(rot, c, lx, ly, lz):
    """A direction in collider ``c``'s frame, in the world's."""
    return (
        rot[c, 0, 0] * lx + rot[c, 0, 1] * ly + rot[c, 0, 2] * lz,
        rot[c, 1, 0] * lx + rot[c, 1, 1] * ly + rot[c, 1, 2] * lz,
        rot[c, 2, 0] * lx + rot[c, 2, 1] * ly + rot[c, 2, 2] * lz,
    )


@numba.njit(cache=True, inline="always")
def cylinder_distance(radius, half, qx, qy, qz):
    """A cylinder's signed distance and normal in its own frame (axis z)."""
    r = math.sqrt(qx * qx + qy * qy)
    if r > 1e-300:
        ux, uy = qx / r, qy / r
    else:
        ux, uy = 1.0, 0.0
    a, b = r - radius, abs(qz) - half
    sz = math.copysign(1.0, qz)
    if a > 0.0 or b > 0.0:
        oa, ob = max(a, 0.0), max(b, 0.0)
        d = math.sqrt(oa * oa + ob * ob)
        return d, ux * oa / d, uy * oa / d, sz * ob / d
    if a >= b:  # inside: out through the nearer of the side and the caps
        return a, ux, uy, 0.0
    return b, 0.0, 0.0, sz


@numba.njit(cache=True, inline="always")
def box_distance(gx, gy, gz, qx, qy, qz):
    """A box's (half extents ``gx, gy, gz``) signed distance and normal in its own frame."""
    ax, ay, az = abs(qx) - gx, abs(qy) - gy, abs(qz) - gz
    if ax > 0.0 or ay > 0.0 or az > 0.0:
        ox, oy, oz = max(ax, 0.0), max(ay, 0.0), max(az, 0.0)
        d = math.sqrt(ox * ox + oy * oy + oz * oz)
        lx = math.copysign(ox, qx) / d
        ly = math.copysign(oy, qy) / d
        lz = math.copysign(oz, qz) / d
    else:  # inside: out through the nearest face
        lx = ly = lz = 0.0
        if ax >= ay and ax >= az:
            d = ax
            lx = math.copysign(1.0, qx)
        elif ay >= az:
            d = ay
            ly = math.copysign(1.0, qy)
        else:
            d = az
            lz = math.copysign(1.0, qz)
    return d, lx, ly, lz


@numba.njit(cache=True)
def distances(kind, pos, rot, geo, pts, bank):
    """The signed distances of ``pts`` from the one collider packed in ``pos``, ``rot``,
    ``geo`` (index 0)."""
    out = np.empty(pts.shape[0])
    r, t, s = bank
    for i in range(pts.shape[0]):
        if kind == MESH:
            out[i] = mesh_sdf(pos, rot, geo, 0, pts[i, 0], pts[i, 1], pts[i, 2], r, t, s)[0]
        else:
            out[i] = sdf(kind, pos, rot, geo, 0, pts[i, 0], pts[i, 1], pts[i, 2])[0]
    return out


@numba.njit(cache=True, inline="always")
def pose_change(pos, rot, pos0, rot0, c):
    """How far collider ``c`` moved from its pose ``pos0``, ``rot0`` to ``pos``, ``rot``: its
    position's shift and ``‖R − R₀‖`` (Frobenius). A point of it ``r`` from its position moved
    at most ``shift + r·‖R − R₀‖``."""
    shift = 0.0
    turn = 0.0
    for i in range(3):
        shift += (pos[c, i] - pos0[c, i]) ** 2
        for j in range(3):
            turn += (rot[c, i, j] - rot0[c, i, j]) ** 2
    return math.sqrt(shift), math.sqrt(turn)


@numba.njit(cache=True, inline="always")
def beyond_reach(pos, reach, c, x, y, z):
    """How far the point ``(x, y, z)`` lies beyond collider ``c``'s reach, ``|x − pos| − reach``
    (every point of the collider is within its reach of its position, so the point's distance
    from it is at least that); ``−inf`` for a half-space, whose reach is unbounded."""
    if not reach[c] < math.inf:
        return -math.inf
    r2 = (x - pos[c, 0]) ** 2 + (y - pos[c, 1]) ** 2
    return math.sqrt(r2 + (z - pos[c, 2]) ** 2) - reach[c]


@numba.njit(cache=True, inline="always")
def carried(p_old, R_old, p_new, R_new, c, x, y, z):
    """Where the point ``(x, y, z)`` attached to collider ``c``'s new pose (``p_new[c]``,
    ``R_new[c]``) was at its old pose (``p_old[c]``, ``R_old[c]``); by index, as :func:`sdf`."""
    dx, dy, dz = x - p_new[c, 0], y - p_new[c, 1], z - p_new[c, 2]
    lx = R_new[c, 0, 0] * dx + R_new[c, 1, 0] * dy + R_new[c, 2, 0] * dz
    ly = R_new[c, 0, 1] * dx + R_new[c, 1, 1] * dy + R_new[c, 2, 1] * dz
    lz = R_new[c, 0, 2] * dx + R_new[c, 1, 2] * dy + R_new[c, 2, 2] * dz
    return (
        p_old[c, 0] + R_old[c, 0, 0] * lx + R_old[c, 0, 1] * ly + R_old[c, 0, 2] * lz,
        p_old[c, 1] + R_old[c, 1, 0] * lx + R_old[c, 1, 1] * ly + R_old[c, 1, 2] * lz,
        p_old[c, 2] + R_old[c, 2, 0] * lx + R_old[c, 2, 1] * ly + R_old[c, 2, 2] * lz,
    )


#: sphere-tracing steps along a particle's path before the hit is taken where the march stands
_MARCH_STEPS = 64


class ContactResults(NamedTuple):
    """What the contact stage's kernel writes (:func:`resolve_contacts`): per particle whether it
    touches a collider and how far above the nearest collider's skin it ends (``inf``: none); per
    collider the impulse the particles gave it (N·s) and its moment about the collider's
    position."""

    touching: np.ndarray
    clearance: np.ndarray
    push: np.ndarray
    turn: np.ndarray


@numba.njit(cache=True)
def spread_tasks(n):
    """``0 … n−1`` in bit-reversed order (of the next power of two, those below ``n`` kept): any
    run of the list that a thread takes holds indices from all over the range."""
    bits = 0
    while (1 << bits) < n:
        bits += 1
    order = np.empty(n, np.int64)
    m = 0
    for k in range(1 << bits):
        r = 0
        for b in range(bits):
            if (k >> b) & 1:
                r |= 1 << (bits - 1 - b)
        if r < n:
            order[m] = r
            m += 1
    return order


#: particles a task of the contact stage's kernel takes (:func:`resolve_contacts`): the tasks'
#: impulse sums are joined in task order, so they are the same at any thread count
CONTACT_CHUNK = 256


# the distance query compiled on its own, for kernels outside the iterations' hot loops to call:
# with sdf inlined at its five call sites (as elsewhere) resolve_contacts took 77 s to compile,
# 21 s with the queries called, at the same speed a thread as the serial kernel it replaced;
# vbd's collider_allowances and overtaken (once a search, once a step) compiled in 10.9 and
# 9.2 s of their own with both queries inlined, 3.4 and 1.8 s with them called (the queries 1.9 s
# once, shared with resolve_contacts; an empty cache, 2026-12-03): the same bits, and
# collider_allowances 11 µs slower a call on robot_sweep's arm (66 → 77 µs), 0.38 ms faster on
# tshirt_on_body's mannequin (3.75 → 3.37 ms), side by side in one process
@numba.njit(cache=True)
def collider_distance(kind, pos, rot, geo, c, x, y, z, reals, ints, starts, cutoff):
    """Collider ``c``'s signed distance and outward normal at ``(x, y, z)``, whatever its
    ``kind``: :func:`mesh_sdf` within ``cutoff`` (``math.inf`` for none: given at every call, one
    signature to compile) for a mesh, :func:`sdf` for any other; not inlined."""
    if kind == MESH:
        return mesh_sdf(pos, rot, geo, c, x, y, z, reals, ints, starts, cutoff)
    return sdf(kind, pos, rot, geo, c, x, y, z)


@numba.njit(cache=True, parallel=True)
def resolve_contacts(x, v, x0, pinned, masses, co, h, dt, continuous, out):
    """The contact stage's kernel, particle by particle (each is independent; in tasks of
    :data:`CONTACT_CHUNK` on every core): the colliders ``co`` (:class:`PackedColliders`), its
    results written to ``out`` (:class:`ContactResults`).

    For each collider, in order: (1) continuous detection: the particle's path over the step, seen
    from the collider (its start carried by the collider's motion), is marched by sphere tracing on
    the distance minus ``h``; a path that reaches the surface stops there, so no particle crosses a
    collider however thin or fast. (2) Projection: a particle closer than ``h`` moves out along the
    normal by the depth ``δ``; its tangential motion relative to the collider over the step shrinks
    by ``μ·δ`` (to zero when it is smaller: static friction). (3) Velocity filter, for a particle
    within ``h·(1 + CONTACT_TOLERANCE)``: an approaching normal velocity relative to the collider
    is removed and the tangential one shrinks by ``μ`` times what was removed (Coulomb's cone on
    the impulse). Returns the number of particles touching; ``touching[p]`` says which, and
    ``clearance[p]`` how far above the nearest collider's skin the particle ends (``inf``:
    none). ``push[c]`` and ``turn[c]`` gather the impulse the particles gave collider ``c`` in
    (3) (``m·Δv``, N·s) and its moment about the collider's position: summed in index order over
    each task's particles, the tasks' sums added in order (the same sums at any thread count). A
    collider whose ``reach`` (every point of it within that of its position) keeps the particle's
    whole path beyond ``h·(1 + CONTACT_TOLERANCE)`` is passed over: it could do nothing (only its
    clearance is left unmeasured, far above any skin)."""
    kinds, pos, rot, pos0, rot0, geo = co.kinds, co.pos, co.rot, co.pos0, co.rot0, co.geo
    mu, reach, bank = co.mu, co.reach, (co.reals, co.ints, co.starts)
    reals, ints, starts = co.reals, co.ints, co.starts
    touching, clearance, push, turn = out.touching, out.clearance, out.push, out.turn
    n = x.shape[0]
    edge = h * (1.0 + CONTACT_TOLERANCE) * (1.0 + 1e-9)
    # per collider how far its position moved over the step and ‖R − R₀‖ (Frobenius): with the
    # particle's own motion they bound its path's length seen from the collider (below)
    shift = np.empty(kinds.shape[0])
    turned = np.empty(kinds.shape[0])
    for c in range(kinds.shape[0]):
        shift[c], turned[c] = pose_change(pos, rot, pos0, rot0, c)
    tasks = (n + CONTACT_CHUNK - 1) // CONTACT_CHUNK
    pushes = np.zeros((tasks, kinds.shape[0], 3))
    turns = np.zeros((tasks, kinds.shape[0], 3))
    counts = np.zeros(tasks, np.int64)
    # the threads take equal runs of the list, and the particles touching lie together (a cloth's
    # rows on a table): in index order one core idled, spread (:func:`spread_tasks`) each run holds
    # tasks from all over the cloth
    order = spread_tasks(tasks)
    for j in numba.prange(tasks):
        task = order[j]
        for p in range(task * CONTACT_CHUNK, min(n, (task + 1) * CONTACT_CHUNK)):
            touching[p] = False
            clearance[p] = np.inf
            if pinned[p]:
                continue
            travel = math.sqrt(
                (x[p, 0] - x0[p, 0]) ** 2 + (x[p, 1] - x0[p, 1]) ** 2 + (x[p, 2] - x0[p, 2]) ** 2
            )
            for c in range(kinds.shape[0]):
                k = kinds[c]
                if not continuous and reach[c] == np.inf and k != MESH:
                    # a half-space after an integrator that kept the path off it: only (2) and (3)
                    # below can act, and only within its edge; farther, its clearance is all there
                    # is to measure (the same as below, without carrying the path's ends)
                    d = collider_distance(
                        k, pos, rot, geo, c, x[p, 0], x[p, 1], x[p, 2],
                        reals, ints, starts, math.inf,
                    )[0]  # fmt: skip
                    if d >= h * (1.0 + CONTACT_TOLERANCE):
                        clearance[p] = min(clearance[p], max(d - h, 0.0))
                        continue
                a = 0.0  # the end's distance from the collider's position (a bounded collider's)
                if reach[c] < np.inf:
                    # the test below before its start is carried: b = |s − pos| is |x0 − pos0| (a
                    # rigid motion), and L ≤ |x − x0| + |x0 − s| ≤ travel + shift + ‖R − R₀‖·b,
                    # so a collider this passes over the exact test passes over too (with room
                    # for rounding); a far link costs two distances, not two frame changes
                    a = math.sqrt(
                        (x[p, 0] - pos[c, 0]) ** 2
                        + (x[p, 1] - pos[c, 1]) ** 2
                        + (x[p, 2] - pos[c, 2]) ** 2
                    )
                    b0 = math.sqrt(
                        (x0[p, 0] - pos0[c, 0]) ** 2
                        + (x0[p, 1] - pos0[c, 1]) ** 2
                        + (x0[p, 2] - pos0[c, 2]) ** 2
                    )
                    longest = travel + shift[c] + turned[c] * b0
                    if 0.5 * (a + b0 - longest) - reach[c] > edge + 1e-9 * (a + b0 + reach[c]):
                        continue
                # the start, carried with the collider to its new pose (x0 for a static one)
                sx, sy, sz = carried(pos, rot, pos0, rot0, c, x0[p, 0], x0[p, 1], x0[p, 2])
                if reach[c] < np.inf:  # every point q of the path s→x: |q − pos| ≥ (a + b − L)/2
                    b = math.sqrt(
                        (sx - pos[c, 0]) ** 2 + (sy - pos[c, 1]) ** 2 + (sz - pos[c, 2]) ** 2
                    )
                    L = math.sqrt((x[p, 0] - sx) ** 2 + (x[p, 1] - sy) ** 2 + (x[p, 2] - sz) ** 2)
                    if 0.5 * (a + b - L) - reach[c] > edge:
                        continue
                # where the collider's point under x[p] was at the start: its displacement over the
                # step
                cx, cy, cz = carried(pos0, rot0, pos, rot, c, x[p, 0], x[p, 1], x[p, 2])
                ux, uy, uz = x[p, 0] - cx, x[p, 1] - cy, x[p, 2] - cz
                # (1) continuous detection from a start outside the skin (not after an integrator
                # that kept the path out of the colliders itself)
                held = False  # the step's motion undone: it moved with the collider
                # whether (1) asked the distance and normal at x[p] already (d, n)
                known = False
                d = nx = ny = nz = 0.0
                if continuous:
                    r0, mx, my, mz = collider_distance(
                        k, pos, rot, geo, c, sx, sy, sz, reals, ints, starts, math.inf
                    )
                    d0 = r0 - h
                    ex, ey, ez = x[p, 0] - sx, x[p, 1] - sy, x[p, 2] - sz
                    length = math.sqrt(ex * ex + ey * ey + ez * ez)
                    if d0 <= CONTACT_TOLERANCE * h:
                        # a start touching the surface: the end is projected below, unless the path
                        # went past the middle of the solid or through it (the normal at the end
                        # points the other way: a straight path between opposite sides crosses the
                        # solid): stay
                        de, fx, fy, fz = collider_distance(
                            k, pos, rot, geo, c, x[p, 0], x[p, 1], x[p, 2],
                            reals, ints, starts, math.inf,
                        )  # fmt: skip
                        known = True
                        d, nx, ny, nz = de, fx, fy, fz
                        if fx * mx + fy * my + fz * mz < 0.0:
                            x[p, 0], x[p, 1], x[p, 2] = sx, sy, sz
                            held = True
                            d, nx, ny, nz = r0, mx, my, mz
                    elif length > d0:
                        t = 0.0
                        hit = False
                        for _ in range(_MARCH_STEPS):
                            qx, qy, qz = sx + t * ex, sy + t * ey, sz + t * ez
                            d, nx, ny, nz = collider_distance(
                                k, pos, rot, geo, c, qx, qy, qz, reals, ints, starts, math.inf
                            )
                            if d - h <= 1e-3 * h:
                                hit = True
                                known = True  # (x[p] is set to this point below)
                                break
                            t += (d - h) / length
                            if t >= 1.0:
                                break
                        if not hit and t < 1.0:
                            hit = True  # the march did not settle: stop where it stands
                        if hit:
                            x[p, 0], x[p, 1], x[p, 2] = sx + t * ex, sy + t * ey, sz + t * ez
                # (2) projection with friction on the motion relative to the collider
                if not known:
                    d, nx, ny, nz = collider_distance(
                        k, pos, rot, geo, c, x[p, 0], x[p, 1], x[p, 2],
                        reals, ints, starts, math.inf,
                    )  # fmt: skip
                # (0 once projected onto the skin)
                clearance[p] = min(clearance[p], max(d - h, 0.0))
                if d >= h * (1.0 + CONTACT_TOLERANCE):
                    continue
                touching[p] = True
                stuck = held
                if d < h:
                    depth = h - d
                    x[p, 0] += depth * nx
                    x[p, 1] += depth * ny
                    x[p, 2] += depth * nz
                    rx, ry, rz = x[p, 0] - sx, x[p, 1] - sy, x[p, 2] - sz
                    rn = rx * nx + ry * ny + rz * nz
                    tx, ty, tz = rx - rn * nx, ry - rn * ny, rz - rn * nz
                    tl = math.sqrt(tx * tx + ty * ty + tz * tz)
                    budget = mu[c] * depth
                    stuck = stuck or tl <= budget
                    if tl > 0.0:
                        f = 1.0 if stuck else budget / tl
                        x[p, 0] -= f * tx
                        x[p, 1] -= f * ty
                        x[p, 2] -= f * tz
                # (3) velocity filter relative to the collider's velocity at the point: an
                # approaching normal velocity removed, the tangential one shrunk by μ times what
                # was removed; held by static friction in (2), no tangential velocity either (a
                # particle the projection keeps in place whose velocity slid on would gather the
                # springs' pull step after step: a cloth caught under a moving link reached
                # 900 m/s)
                wx, wy, wz = ux / dt, uy / dt, uz / dt
                rx, ry, rz = v[p, 0] - wx, v[p, 1] - wy, v[p, 2] - wz
                vn = rx * nx + ry * ny + rz * nz
                if vn < 0.0 or stuck:
                    tx, ty, tz = rx - vn * nx, ry - vn * ny, rz - vn * nz
                    tl = math.sqrt(tx * tx + ty * ty + tz * tz)
                    keep = 0.0
                    if tl > 0.0 and not stuck:
                        keep = max(0.0, 1.0 - mu[c] * (-vn) / tl)
                    vn = max(vn, 0.0)  # (separating: kept)
                    jx, jy, jz = v[p, 0], v[p, 1], v[p, 2]
                    v[p, 0] = wx + vn * nx + keep * tx
                    v[p, 1] = wy + vn * ny + keep * ty
                    v[p, 2] = wz + vn * nz + keep * tz
                    # the impulse the particle gave the collider
                    jx, jy, jz = (
                        masses[p] * (jx - v[p, 0]),
                        masses[p] * (jy - v[p, 1]),
                        masses[p] * (jz - v[p, 2]),
                    )
                    pushes[task, c, 0] += jx
                    pushes[task, c, 1] += jy
                    pushes[task, c, 2] += jz
                    ax, ay, az = x[p, 0] - pos[c, 0], x[p, 1] - pos[c, 1], x[p, 2] - pos[c, 2]
                    turns[task, c, 0] += ay * jz - az * jy
                    turns[task, c, 1] += az * jx - ax * jz
                    turns[task, c, 2] += ax * jy - ay * jx
            if touching[p] and kinds.shape[0] > 1:
                crease(x, p, kinds, pos, rot, geo, reach, bank, h)
            if touching[p]:
                counts[task] += 1
    count = 0
    for task in range(tasks):
        count += counts[task]
        for c in range(kinds.shape[0]):
            for i in range(3):
                push[c, i] += pushes[task, c, i]
                turn[c, i] += turns[task, c, i]
    return count


#: passes of :func:`crease` at most
CREASE_PASSES = 8


#: a collider whose reach keeps a particle farther than this many ``h`` is not asked by
#: :func:`crease` (its distance is above every threshold there, ``h·(1 + 1e-6)`` the largest,
#: with room for rounding)
_CREASE_FAR = 1.0 + 1e-5


@numba.njit(cache=True, inline="always")
def _crease_ask(kinds, pos, rot, geo, reach, bank, h, c, x, y, z):
    """Collider ``c``'s distance and normal at ``(x, y, z)`` as :func:`crease` needs them: exact
    up to ``h·_CREASE_FAR``, and that distance (normal 0) for any point farther, which a collider
    beyond its reach is answered without a query and a mesh by a walk of its tree that stops
    there."""
    far = h * _CREASE_FAR
    if beyond_reach(pos, reach, c, x, y, z) > far:
        return far, 0.0, 0.0, 0.0
    r, t, s = bank
    return collider_distance(kinds[c], pos, rot, geo, c, x, y, z, r, t, s, far)


# compiled on its own, not inlined: resolve_contacts took 55 s to compile with it inlined (its
# four distance queries copied in), 21 s without it and 11 s for it, at the same speed (called
# once a touching particle, where there is more than one collider); its own queries called
# (_crease_ask), 16.9 → 0.9 s of its own (an empty cache, 2026-12-03; the same bits)
@numba.njit(cache=True)
def crease(x, p, kinds, pos, rot, geo, reach, bank, h):
    """Particle ``p`` after the colliders' projections, one after the other: where two colliders
    meet (a robot's links at a joint), pushing it out of the later one may have pushed it into an
    earlier one. The projections are repeated, normal only, until it is within none (at most
    ``CREASE_PASSES`` passes: they alternate towards the crease, where both are ``h`` away).

    Where two links meet face to face (a vertex between the upper arm's end and the forearm's, at
    the elbow) there is no such crease: each pass pushes the particle out of one into the other,
    and the last left it ``h`` inside a solid. Unsettled after the passes and inside a solid, it
    is moved along that solid's normal to where it is as deep in the other link that faces it as
    in this one: between two faces that touch, onto the seam, inside neither.

    Every decision here compares a distance with at most ``h·(1 + 1e-6)``, so each collider is
    asked through :func:`_crease_ask`, which answers a farther one without its exact distance:
    the same moves. Asking every link's mesh in full for each particle lying on a table took
    13 of the 16 ms of the contact stage on Newton's shirt beside the FR3."""
    for _ in range(CREASE_PASSES):
        moved = False
        for c in range(kinds.shape[0]):
            d, nx, ny, nz = _crease_ask(
                kinds, pos, rot, geo, reach, bank, h, c, x[p, 0], x[p, 1], x[p, 2]
            )
            if d < h * (1.0 - 1e-6):
                x[p, 0] += (h - d) * nx
                x[p, 1] += (h - d) * ny
                x[p, 2] += (h - d) * nz
                moved = True
        if not moved:
            return
    # unsettled: the deepest solid, and the link facing it that pushed the particle in (each
    # collider asked once: its distance and normal)
    dn = np.empty((kinds.shape[0], 4))
    deepest = 0
    for c in range(kinds.shape[0]):
        d, nx, ny, nz = _crease_ask(
            kinds, pos, rot, geo, reach, bank, h, c, x[p, 0], x[p, 1], x[p, 2]
        )
        dn[c, 0], dn[c, 1], dn[c, 2], dn[c, 3] = d, nx, ny, nz
        if d < dn[deepest, 0]:
            deepest = c
    d1, n1x, n1y, n1z = dn[deepest, 0], dn[deepest, 1], dn[deepest, 2], dn[deepest, 3]
    if d1 >= 0.0:
        return
    d2 = math.inf
    for c in range(kinds.shape[0]):
        d, nx, ny, nz = dn[c, 0], dn[c, 1], dn[c, 2], dn[c, 3]
        if d > d1 and d < h * (1.0 + 1e-6) and nx * n1x + ny * n1y + nz * n1z < -0.5:
            d2 = min(d2, d)
    if d2 < math.inf:
        move = min(0.5 * (d2 - d1), h - d1)
        x[p, 0] += move * n1x
        x[p, 1] += move * n1y
        x[p, 2] += move * n1z


class PackedColliders(NamedTuple):
    """The colliders as the contact kernels read them (:meth:`Contacts.packed`): per collider its
    kind, position and rotation at the step's end and at its start (``pos0``, ``rot0``), its
    geometry (:attr:`Collider.geometry`), friction and ``reach`` (every point of it within that of
    its position; ``inf`` for a plane); then the bank of its meshes
    (:func:`.triangle_meshes.pack`), its three arrays flat beside the rest: numba's parallel loops
    take a tuple of arrays, not one holding another (a kernel reads the bank as
    ``(co.reals, co.ints, co.starts)``)."""

    kinds: np.ndarray
    pos: np.ndarray
    rot: np.ndarray
    pos0: np.ndarray
    rot0: np.ndarray
    geo: np.ndarray
    mu: np.ndarray
    reach: np.ndarray
    reals: np.ndarray
    ints: np.ndarray
    starts: np.ndarray


NO_COLLIDERS = PackedColliders(
    np.zeros(0, np.int64),
    np.zeros((0, 3)),
    np.zeros((0, 3, 3)),
    np.zeros((0, 3)),
    np.zeros((0, 3, 3)),
    np.zeros((0, 4)),
    np.zeros(0),
    np.zeros(0),
    *triangle_meshes.EMPTY,
)

keep_true(__name__)  # (its kernels compile again when a file it imports changes)
