"""The CUDA kernels: each thread one vertex of one world, the worlds side by side in the arrays'
first axis, so one launch steps every world.

The arithmetic is the CPU's: its scalar-only functions are called as they are (a spring's share
of a Newton step, :func:`~cloth_sim.integrators.vbd_terms.spring_part`; the 3×3 solve,
:func:`~cloth_sim.integrators.vbd_contact.solve3`), and what reads arrays is written again for the
worlds' arrays (the CPU's kernels index one world; numba-cuda's simulator cannot pass them its
arrays): the
symplectic Euler force of :mod:`cloth_sim.physics.forces` (Hooke springs and their damping along
the spring, gravity, wind on the vertex normals, linear drag, the material's bending ``−Q x``),
and the per-vertex Newton step of :mod:`cloth_sim.integrators.vbd`'s general sweep (inertia, drag,
springs with their damping over the step, bending; the adaptive initial guess, Chebyshev's
extrapolation and the sweeps' residual of :mod:`cloth_sim.integrators.vbd_residual`). The tests
hold both to the CPU's numbers (``test/gpu``).

Kernels take three named bundles (:mod:`cloth_sim.cuda.layout`): ``top`` (the topology every world
shares), ``wor`` (each world's masses, pins, gravity, wind, drag and family overrides) and ``it``
(each world's positions, velocities and the step's scratch arrays), and a few scalars.
"""

from __future__ import annotations

import math

from numba import config, cuda, float64, int32

from ..constraints.strain_limit import STRAIN_LIMIT_TOLERANCE

# scalar-only numba functions of the CPU's sweep: a CUDA kernel calls them as they are (numba-cuda
# compiles them for the device; its simulator calls the CPU's build)
from ..contact.collider_kernels import (
    CAPSULE,
    CONTACT_TOLERANCE,
    CREASE_PASSES,
    CYLINDER,
    MESH,
    PLANE,
    SPHERE,
    box_distance,
    cylinder_distance,
)
from ..contact.distance_grid import outside, trilinear
from ..integrators.vbd import EPS_V
from ..integrators.vbd_contact import press, slide, solve3
from ..integrators.vbd_terms import spring_part

#: the decorator of a device function inlined into its kernels by NVVM (``forceinline``: the
#: ``alwaysinline`` attribute), typed and lowered once. Inlined at numba's IR level
#: (``inline=True``, which numba-cuda deprecates) it was typed and lowered again at every call
#: site: the PTX check took 106 s a precision, frames_in_blocks 46 s of it; 53 s and 21 s so
#: (2026-12-03), the PTX the same to 0.05 % of its instructions and calling no function either
#: way. numba-cuda's simulator, which runs the Python, takes no ``forceinline``.
inlined = (
    cuda.jit(device=True) if config.ENABLE_CUDASIM else cuda.jit(device=True, forceinline=True)
)

#: threads a block, at most (a launch over fewer threads takes as many)
BLOCK = 128
#: threads a world in the residual's reduction (a power of two: a warp)
REDUCE = 32
#: threads a block at most in :func:`frames_in_blocks` (a power of two: its reductions)
MAX_BLOCK = 1024
#: the contact stage's march along a particle's path at most (the CPU's ``_MARCH_STEPS``)
MARCH_STEPS = 64
#: standard gravity, the residual's unit of force per unit of mass (as on the CPU)
G0 = 9.80665
#: strain above τ a pass of the limit tolerates (the CPU's ``STRAIN_LIMIT_TOLERANCE``)
STRAIN_TOLERANCE = STRAIN_LIMIT_TOLERANCE


# --------------------------------------------------------------------------- per-vertex parts
@inlined
def spring_constants(top, wor, w, q):
    """Stiffness and damping of vertex incidence ``q`` in world ``w``: the world's family
    override where it has one (``≥ 0``), else the model's own."""
    f = top.fam[q]
    k = wor.kfam[w, f]
    c = wor.cfam[w, f]
    if k < 0:
        k = top.k[q]
    if c < 0:
        c = top.c[q]
    return k, c


@inlined
def normal_at(top, x, w, i):
    """Vertex ``i``'s unit normal: its triangles' area-weighted normals summed (zero without
    triangles), as :func:`cloth_sim.physics.force_kernels.vertex_normals`."""
    nx = ny = nz = 0.0
    for e in range(top.tptr[i], top.tptr[i + 1]):
        t = top.tlist[e]
        a, b, c = top.tris[t, 0], top.tris[t, 1], top.tris[t, 2]
        e1x, e1y, e1z = x[w, b, 0] - x[w, a, 0], x[w, b, 1] - x[w, a, 1], x[w, b, 2] - x[w, a, 2]
        e2x, e2y, e2z = x[w, c, 0] - x[w, a, 0], x[w, c, 1] - x[w, a, 1], x[w, c, 2] - x[w, a, 2]
        nx += e1y * e2z - e1z * e2y
        ny += e1z * e2x - e1x * e2z
        nz += e1x * e2y - e1y * e2x
    nrm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nrm > 0.0:
        nx, ny, nz = nx / nrm, ny / nrm, nz / nrm
    return nx, ny, nz


@inlined
def external_at(top, wor, x, w, i):
    """Gravity's and the wind's force on vertex ``i`` (N): ``m g + (n·W) n``."""
    m = wor.masses[w, i]
    fx, fy, fz = m * wor.gravity[w, 0], m * wor.gravity[w, 1], m * wor.gravity[w, 2]
    if wor.windy[w]:
        nx, ny, nz = normal_at(top, x, w, i)
        p = nx * wor.wind[w, 0] + ny * wor.wind[w, 1] + nz * wor.wind[w, 2]
        fx += p * nx
        fy += p * ny
        fz += p * nz
    return fx, fy, fz


@inlined
def bending_at(top, x, w, i):
    """``−(Q x)_i``: the material's bending force on vertex ``i``."""
    bx = by = bz = 0.0
    for e in range(top.bptr[i], top.bptr[i + 1]):
        j = top.bidx[e]
        q = top.bval[e]
        bx -= q * x[w, j, 0]
        by -= q * x[w, j, 1]
        bz -= q * x[w, j, 2]
    return bx, by, bz


@inlined
def mesh_at(wor, m, qx, qy, qz):
    """Mesh ``m``'s distance and outward normal at ``q`` in its own frame, read from its baked
    distance grid (``wor.gbox``, ``gdim``, ``gval``): the trilinear interpolation of the cell's
    eight nodes and its normalised gradient inside the grid, the band plus the distance from the
    grid's box outside it, by the CPU's own :func:`~cloth_sim.contact.distance_grid.trilinear`
    and :func:`~cloth_sim.contact.distance_grid.outside`
    (:meth:`cloth_sim.contact.distance_grid.DistanceGrid.at`, the same numbers)."""
    ox, oy, oz, h = wor.gbox[m, 0], wor.gbox[m, 1], wor.gbox[m, 2], wor.gbox[m, 3]
    nx, ny, nz, start = wor.gdim[m, 0], wor.gdim[m, 1], wor.gdim[m, 2], wor.gdim[m, 3]
    fx, fy, fz = (qx - ox) / h, (qy - oy) / h, (qz - oz) / h
    if not (0.0 <= fx <= nx - 1 and 0.0 <= fy <= ny - 1 and 0.0 <= fz <= nz - 1):
        return outside((ox, oy, oz, h, wor.gbox[m, 4]), nx, ny, nz, qx, qy, qz)
    i, j, k = min(int(fx), nx - 2), min(int(fy), ny - 2), min(int(fz), nz - 2)
    v = wor.gval
    a = start + (i * ny + j) * nz + k  # (x slowest, z fastest)
    b = a + ny * nz  # the next node along x
    return trilinear(
        (v[a], v[b], v[a + nz], v[b + nz], v[a + 1], v[b + 1], v[a + nz + 1], v[b + nz + 1]),
        fx - i,
        fy - j,
        fz - k,
        h,
    )


@cuda.jit(device=True)
def collider_at(wor, w, c, x, y, z):
    """World ``w``'s static collider ``c``: the outward unit normal and the signed distance of
    ``(x, y, z)`` from it, in the CPU's arithmetic (:func:`cloth_sim.contact.collider_kernels.sdf`:
    the same operations in the same order, here on the worlds' arrays, which the CPU's function
    cannot take on numba-cuda's simulator; a box's and a cylinder's in their own frame by the
    CPU's own scalar functions). A plane, a sphere, a capsule, a box, a cylinder, or a mesh from
    its distance grid (:func:`mesh_at`, in its own frame)."""
    kind = wor.ckind[w, c]
    dx, dy, dz = x - wor.cpos[w, c, 0], y - wor.cpos[w, c, 1], z - wor.cpos[w, c, 2]
    R = wor.crot
    g0, g1, g2, g3 = wor.cgeo[w, c, 0], wor.cgeo[w, c, 1], wor.cgeo[w, c, 2], wor.cgeo[w, c, 3]
    if kind == PLANE or kind == CAPSULE:  # the plane's normal, the capsule's half axis
        ax = R[w, c, 0, 0] * g0 + R[w, c, 0, 1] * g1 + R[w, c, 0, 2] * g2
        ay = R[w, c, 1, 0] * g0 + R[w, c, 1, 1] * g1 + R[w, c, 1, 2] * g2
        az = R[w, c, 2, 0] * g0 + R[w, c, 2, 1] * g1 + R[w, c, 2, 2] * g2
        if kind == PLANE:
            return ax, ay, az, ax * dx + ay * dy + az * dz
        hh = ax * ax + ay * ay + az * az
        s = 0.0
        if hh > 0.0:
            s = (dx * ax + dy * ay + dz * az) / hh
            s = min(1.0, max(-1.0, s))
        ex, ey, ez = dx - s * ax, dy - s * ay, dz - s * az
        r = math.sqrt(ex * ex + ey * ey + ez * ez)
        if r < 1e-300:  # on the axis: any perpendicular direction
            if abs(ax) < 0.9 * math.sqrt(hh) or hh == 0.0:
                px, py, pz = 0.0, az, -ay
            else:
                px, py, pz = -az, 0.0, ax
            u = math.sqrt(px * px + py * py + pz * pz)
            if u == 0.0:
                return 0.0, 0.0, 1.0, -g3
            return px / u, py / u, pz / u, -g3
        return ex / r, ey / r, ez / r, r - g3
    if kind == SPHERE:
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        if r < 1e-300:
            return 0.0, 0.0, 1.0, -g0
        return dx / r, dy / r, dz / r, r - g0
    # a box or a cylinder: in its own frame
    qx = R[w, c, 0, 0] * dx + R[w, c, 1, 0] * dy + R[w, c, 2, 0] * dz
    qy = R[w, c, 0, 1] * dx + R[w, c, 1, 1] * dy + R[w, c, 2, 1] * dz
    qz = R[w, c, 0, 2] * dx + R[w, c, 1, 2] * dy + R[w, c, 2, 2] * dz
    if kind == CYLINDER:
        d, lx, ly, lz = cylinder_distance(g0, g1, qx, qy, qz)
    elif kind == MESH:
        d, lx, ly, lz = mesh_at(wor, int(g0), qx, qy, qz)
    else:
        d, lx, ly, lz = box_distance(g0, g1, g2, qx, qy, qz)
    nx = R[w, c, 0, 0] * lx + R[w, c, 0, 1] * ly + R[w, c, 0, 2] * lz
    ny = R[w, c, 1, 0] * lx + R[w, c, 1, 1] * ly + R[w, c, 1, 2] * lz
    nz = R[w, c, 2, 0] * lx + R[w, c, 2, 1] * ly + R[w, c, 2, 2] * lz
    return nx, ny, nz, d


@cuda.jit(device=True)
def carried_at(wor, w, c, x, y, z, forward):
    """The point ``(x, y, z)`` attached to collider ``c`` carried over the step: with
    ``forward`` from where the step starts the collider (``cpos0``, ``crot0``) to where it ends
    (``cpos``, ``crot``), else back; in the CPU's arithmetic
    (:func:`cloth_sim.contact.collider_kernels.carried`), so that the stage below starts from the
    CPU's numbers (a collider that stays: the point itself, to rounding)."""
    if forward:
        P, R, Q, S = wor.cpos0, wor.crot0, wor.cpos, wor.crot
    else:
        P, R, Q, S = wor.cpos, wor.crot, wor.cpos0, wor.crot0
    dx, dy, dz = x - P[w, c, 0], y - P[w, c, 1], z - P[w, c, 2]
    lx = R[w, c, 0, 0] * dx + R[w, c, 1, 0] * dy + R[w, c, 2, 0] * dz
    ly = R[w, c, 0, 1] * dx + R[w, c, 1, 1] * dy + R[w, c, 2, 1] * dz
    lz = R[w, c, 0, 2] * dx + R[w, c, 1, 2] * dy + R[w, c, 2, 2] * dz
    return (
        Q[w, c, 0] + S[w, c, 0, 0] * lx + S[w, c, 0, 1] * ly + S[w, c, 0, 2] * lz,
        Q[w, c, 1] + S[w, c, 1, 0] * lx + S[w, c, 1, 1] * ly + S[w, c, 1, 2] * lz,
        Q[w, c, 2] + S[w, c, 2, 0] * lx + S[w, c, 2, 1] * ly + S[w, c, 2, 2] * lz,
    )


@cuda.jit(device=True)
def colliders_stage(wor, w, i, start, end, velocity, continuous, dt):
    """The contact stage after a step of ``dt`` for one free particle and world ``w``'s
    colliders, in order, as the CPU's
    (:func:`cloth_sim.contact.collider_kernels.resolve_contacts`): the path from the step's
    ``start`` (carried with a collider that moves over the step, from ``cpos0``/``crot0`` to
    ``cpos``/``crot``) to its ``end`` marched to the thickness's skin (``continuous``: after a
    method that does not keep paths off the colliders itself; a start on the skin whose end lies
    past the solid's middle stays at the start), the end projected out of the skin with friction
    on the motion relative to the collider, an approaching normal velocity removed and the
    tangential one shrunk by μ times what was removed (static friction: removed); then, touching
    one of several colliders, :func:`crease_at`. Points and the velocity are three numbers;
    returns the end and the velocity. Where the worlds record them (``wor.cimp`` sized for every
    vertex: :meth:`~cloth_sim.cuda.worlds.CudaWorlds.record_wrenches`), particle ``i``'s impulse
    on each collider in the velocity filter (``m·Δv``, N·s) and its moment about the collider's
    position go to ``wor.cimp[w, i, c]``, as the CPU's ``push`` and ``turn`` gather them."""
    h = wor.tau[w]
    px, py, pz = end
    vx, vy, vz = velocity
    touching = False
    record = wor.cimp.shape[1] == wor.masses.shape[1]
    if record:
        for c in range(wor.cimp.shape[2]):
            for k in range(6):
                wor.cimp[w, i, c, k] = 0.0
    for c in range(wor.ncol[w]):
        mu = wor.cmu[w, c]
        if not continuous and wor.ckind[w, c] == PLANE:
            # a half-space after a method that kept the path off it: only within its edge
            _, _, _, d = collider_at(wor, w, c, px, py, pz)
            if d >= h * (1.0 + CONTACT_TOLERANCE):
                continue
        sx, sy, sz = carried_at(wor, w, c, start[0], start[1], start[2], True)
        cx, cy, cz = carried_at(wor, w, c, px, py, pz, False)
        ux, uy, uz = px - cx, py - cy, pz - cz  # the collider's motion under the end: rounding
        held = False  # the step's motion undone
        known = False  # the distance and normal at the end asked already
        nx = ny = nz = d = 0.0
        if continuous:
            mx, my, mz, r0 = collider_at(wor, w, c, sx, sy, sz)
            d0 = r0 - h
            ex, ey, ez = px - sx, py - sy, pz - sz
            length = math.sqrt(ex * ex + ey * ey + ez * ez)
            if d0 <= CONTACT_TOLERANCE * h:
                fx, fy, fz, de = collider_at(wor, w, c, px, py, pz)
                known = True
                nx, ny, nz, d = fx, fy, fz, de
                if fx * mx + fy * my + fz * mz < 0.0:
                    px, py, pz = sx, sy, sz
                    held = True
                    nx, ny, nz, d = mx, my, mz, r0
            elif length > d0:
                t = 0.0
                hit = False
                for _ in range(MARCH_STEPS):
                    nx, ny, nz, d = collider_at(wor, w, c, sx + t * ex, sy + t * ey, sz + t * ez)
                    if d - h <= 1e-3 * h:
                        hit = True
                        known = True
                        break
                    t += (d - h) / length
                    if t >= 1.0:
                        break
                if not hit and t < 1.0:
                    hit = True
                if hit:
                    px, py, pz = sx + t * ex, sy + t * ey, sz + t * ez
        if not known:
            nx, ny, nz, d = collider_at(wor, w, c, px, py, pz)
        if d >= h * (1.0 + CONTACT_TOLERANCE):
            continue
        touching = True
        stuck = held
        if d < h:
            depth = h - d
            px, py, pz = px + depth * nx, py + depth * ny, pz + depth * nz
            rx, ry, rz = px - sx, py - sy, pz - sz
            rn = rx * nx + ry * ny + rz * nz
            tx, ty, tz = rx - rn * nx, ry - rn * ny, rz - rn * nz
            tl = math.sqrt(tx * tx + ty * ty + tz * tz)
            budget = mu * depth
            stuck = stuck or tl <= budget
            if tl > 0.0:
                f = 1.0 if stuck else budget / tl
                px, py, pz = px - f * tx, py - f * ty, pz - f * tz
        wx, wy, wz = ux / dt, uy / dt, uz / dt
        rx, ry, rz = vx - wx, vy - wy, vz - wz
        vn = rx * nx + ry * ny + rz * nz
        if vn < 0.0 or stuck:
            tx, ty, tz = rx - vn * nx, ry - vn * ny, rz - vn * nz
            tl = math.sqrt(tx * tx + ty * ty + tz * tz)
            keep = 0.0
            if tl > 0.0 and not stuck:
                keep = max(0.0, 1.0 - mu * (-vn) / tl)
            vn = max(vn, 0.0)
            jx, jy, jz = vx, vy, vz
            vx, vy, vz = (
                wx + vn * nx + keep * tx,
                wy + vn * ny + keep * ty,
                wz + vn * nz + keep * tz,
            )
            if record:  # the impulse the particle gave the collider, and its moment
                m = wor.masses[w, i]
                jx, jy, jz = m * (jx - vx), m * (jy - vy), m * (jz - vz)
                ax, ay, az = px - wor.cpos[w, c, 0], py - wor.cpos[w, c, 1], pz - wor.cpos[w, c, 2]
                wor.cimp[w, i, c, 0] = jx
                wor.cimp[w, i, c, 1] = jy
                wor.cimp[w, i, c, 2] = jz
                wor.cimp[w, i, c, 3] = ay * jz - az * jy
                wor.cimp[w, i, c, 4] = az * jx - ax * jz
                wor.cimp[w, i, c, 5] = ax * jy - ay * jx
    if touching and wor.ncol[w] > 1:
        px, py, pz = crease_at(wor, w, px, py, pz, h)
    return px, py, pz, vx, vy, vz


@cuda.jit(device=True)
def crease_at(wor, w, px, py, pz, h):
    """The CPU's :func:`cloth_sim.contact.collider_kernels.crease` for one particle at ``p``
    among world ``w``'s colliders: the projections repeated, normal only, until it is within none
    (at most ``CREASE_PASSES``), and unsettled inside a solid, moved onto the seam with the
    collider facing it. The CPU answers a collider beyond its reach without its exact distance;
    every decision compares the distance with at most ``h·(1 + 1e-6)``, so asking it exactly
    makes the same moves."""
    for _ in range(CREASE_PASSES):
        moved = False
        for c in range(wor.ncol[w]):
            nx, ny, nz, d = collider_at(wor, w, c, px, py, pz)
            if d < h * (1.0 - 1e-6):
                px, py, pz = px + (h - d) * nx, py + (h - d) * ny, pz + (h - d) * nz
                moved = True
        if not moved:
            return px, py, pz
    d1 = n1x = n1y = n1z = 0.0  # the deepest solid's
    for c in range(wor.ncol[w]):
        nx, ny, nz, d = collider_at(wor, w, c, px, py, pz)
        if c == 0 or d < d1:
            d1, n1x, n1y, n1z = d, nx, ny, nz
    if d1 >= 0.0:
        return px, py, pz
    d2 = math.inf
    for c in range(wor.ncol[w]):
        nx, ny, nz, d = collider_at(wor, w, c, px, py, pz)
        if d > d1 and d < h * (1.0 + 1e-6) and nx * n1x + ny * n1y + nz * n1z < -0.5:
            d2 = min(d2, d)
    if d2 < math.inf:
        move = min(0.5 * (d2 - d1), h - d1)
        px, py, pz = px + move * n1x, py + move * n1y, pz + move * n1z
    return px, py, pz


# --------------------------------------------------------------------------- one vertex's work
@inlined
def explicit_at(top, wor, x, v, xo, vo, h, w, i, collide):
    """Symplectic Euler for vertex ``i`` of world ``w``: the force at ``(x, v)`` (springs and their
    damping, bending, gravity, wind, drag), ``v' = v + h f/m`` on a free vertex (a pin keeps its
    velocity), ``x' = x + h v'``, written to ``(xo, vo)``; the colliders' stage after it where
    ``collide`` (else :func:`limit_end_at` runs it, after the strain limit, as the CPU orders
    its stages)."""
    xi, yi, zi = x[w, i, 0], x[w, i, 1], x[w, i, 2]
    ux, uy, uz = v[w, i, 0], v[w, i, 1], v[w, i, 2]
    if wor.free[w, i]:
        fx, fy, fz = external_at(top, wor, x, w, i)
        d = wor.drag[w]
        fx -= d * ux
        fy -= d * uy
        fz -= d * uz
        for q in range(top.inc_ptr[i], top.inc_ptr[i + 1]):
            j = top.nbr[q]
            dx, dy, dz = x[w, j, 0] - xi, x[w, j, 1] - yi, x[w, j, 2] - zi
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            if length < 1e-300:
                continue
            k, c = spring_constants(top, wor, w, q)
            inv = 1.0 / length
            ex, ey, ez = dx * inv, dy * inv, dz * inv
            mag = k * (length - top.rest[q])
            if c > 0.0:
                mag += c * (
                    (v[w, j, 0] - ux) * ex + (v[w, j, 1] - uy) * ey + (v[w, j, 2] - uz) * ez
                )
            fx += mag * ex
            fy += mag * ey
            fz += mag * ez
        bx, by, bz = bending_at(top, x, w, i)
        s = h / wor.masses[w, i]
        ux += (fx + bx) * s
        uy += (fy + by) * s
        uz += (fz + bz) * s
    px, py, pz = xi + ux * h, yi + uy * h, zi + uz * h
    if collide and wor.free[w, i] and wor.ncol[w]:
        px, py, pz, ux, uy, uz = colliders_stage(
            wor, w, i, (xi, yi, zi), (px, py, pz), (ux, uy, uz), True, h
        )
    vo[w, i, 0], vo[w, i, 1], vo[w, i, 2] = ux, uy, uz
    xo[w, i, 0], xo[w, i, 1], xo[w, i, 2] = px, py, pz


@inlined
def attach_at(lim, wor, x, tau, w, p):
    """Vertex ``p``'s long-range attachments in world ``w`` (the CPU's ``_attach``): pulled back
    along the line to each anchor (a pin) when farther than ``(1 + τ)`` times its rest geodesic
    distance; 1 if it moved. An attachment reads only pins, which none moves: every vertex at
    once."""
    moved = 0
    if not wor.free[w, p]:
        return moved
    for a in range(2):
        q = lim.anchor[w, p, a]
        if q < 0:
            continue
        dx, dy, dz = x[w, p, 0] - x[w, q, 0], x[w, p, 1] - x[w, q, 1], x[w, p, 2] - x[w, q, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        lmax = (1.0 + tau) * lim.reach[w, p, a]
        if length > lmax:
            f = lmax / length
            x[w, p, 0] = x[w, q, 0] + f * dx
            x[w, p, 1] = x[w, q, 1] + f * dy
            x[w, p, 2] = x[w, q, 2] + f * dz
            moved = 1
    return moved


@inlined
def shorten_at(lim, wor, x, tau, w, s):
    """Limited spring ``s`` of world ``w`` shortened to strain ``τ`` if it exceeds ``τ +``
    :data:`STRAIN_TOLERANCE`, both ends moving equally, or only the free one (the CPU's
    ``_shorten``); whether it was. A colour's springs share no vertex: all at once."""
    i, j = lim.ends[s, 0], lim.ends[s, 1]
    fi, fj = wor.free[w, i], wor.free[w, j]
    if not fi and not fj:
        return False
    dx, dy, dz = x[w, j, 0] - x[w, i, 0], x[w, j, 1] - x[w, i, 1], x[w, j, 2] - x[w, i, 2]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    rest = lim.rest[s]
    lmax = (1.0 + tau) * rest
    if length <= lmax + STRAIN_TOLERANCE * rest:
        return False
    excess = (length - lmax) / length
    wi = 0.5 if fi and fj else (1.0 if fi else 0.0)
    wj = 0.5 if fi and fj else (1.0 if fj else 0.0)
    x[w, i, 0] += wi * excess * dx
    x[w, i, 1] += wi * excess * dy
    x[w, i, 2] += wi * excess * dz
    x[w, j, 0] -= wj * excess * dx
    x[w, j, 1] -= wj * excess * dy
    x[w, j, 2] -= wj * excess * dz
    return True


@inlined
def limit_start_at(lim, wor, before, x, tau, w, p):
    """The limit's start for vertex ``p``: the step's end kept in ``before``, then its
    attachments."""
    for d in range(3):
        before[w, p, d] = x[w, p, d]
    attach_at(lim, wor, x, tau, w, p)


@inlined
def limit_end_at(lim, wor, before, start, x, v, h, w, p, collide, first):
    """After the limit's passes, vertex ``p``: its velocity follows its correction ``Δx = x −
    before`` by ``Δx/h``, the correction shortened to at most the step's own motion ``|before −
    start|`` (the CPU's ``follow_corrections``: a larger one undoes stretch that was there
    before, and divided by ``h`` it would be a false speed); then, where ``collide`` (after
    symplectic Euler: ``vbd``'s colliders act inside its substeps), the colliders' stage from
    the step's start to the corrected end. ``lim.gained`` gathers the correction's ``Δx/h``
    over the step (``first``: the step's first application of the limit starts it again)."""
    if first:
        for d in range(3):
            lim.gained[w, p, d] = 0.0
    if not wor.free[w, p]:
        return
    d0, d1, d2 = (
        x[w, p, 0] - before[w, p, 0],
        x[w, p, 1] - before[w, p, 1],
        x[w, p, 2] - before[w, p, 2],
    )
    corr2 = d0 * d0 + d1 * d1 + d2 * d2
    lim.gained[w, p, 0] += d0 / h
    lim.gained[w, p, 1] += d1 / h
    lim.gained[w, p, 2] += d2 / h
    if corr2 > 0.0:
        m0, m1, m2 = (
            before[w, p, 0] - start[w, p, 0],
            before[w, p, 1] - start[w, p, 1],
            before[w, p, 2] - start[w, p, 2],
        )
        move2 = m0 * m0 + m1 * m1 + m2 * m2
        scale = 1.0 / h
        if corr2 > move2:
            scale *= math.sqrt(move2 / corr2)
        v[w, p, 0] += scale * d0
        v[w, p, 1] += scale * d1
        v[w, p, 2] += scale * d2
    if collide and wor.ncol[w]:
        px, py, pz, ux, uy, uz = colliders_stage(
            wor,
            w,
            p,
            (start[w, p, 0], start[w, p, 1], start[w, p, 2]),
            (x[w, p, 0], x[w, p, 1], x[w, p, 2]),
            (v[w, p, 0], v[w, p, 1], v[w, p, 2]),
            True,
            h,
        )
        x[w, p, 0], x[w, p, 1], x[w, p, 2] = px, py, pz
        v[w, p, 0], v[w, p, 1], v[w, p, 2] = ux, uy, uz


@inlined
def limit_in_block(lim, wor, before, start, x, v, run, w, flags, count, first):
    """Provot's strain limit on world ``w`` by its block's threads after a symplectic Euler step
    from ``start`` to ``(x, v)`` (the CPU's :class:`~cloth_sim.constraints.strain_limit.
    StrainLimit` with its attachments): the attachments, then up to ``run.passes`` passes over
    the limited springs a colour at a time, stopping after one that shortens nothing, each
    followed by the attachments; then :func:`limit_end_at`. ``count``: the passes the launch has
    run so far (the flag a pass writes is ``flags[count % 3]``, the block's own: shared memory,
    zero at the launch's start); returns it updated."""
    tid = cuda.threadIdx.x
    size = cuda.blockDim.x
    n = x.shape[1]
    tau = run.limit
    for i in range(tid, n, size):
        limit_start_at(lim, wor, before, x, tau, w, i)
    cuda.syncthreads()
    colours = lim.sptr.shape[0] - 1
    for _ in range(run.passes):
        slot = count % 3
        if tid == 0:
            flags[(count + 1) % 3] = 0
        for c in range(colours):
            for s in range(lim.sptr[c] + tid, lim.sptr[c + 1], size):
                if shorten_at(lim, wor, x, tau, w, s):
                    flags[slot] = 1
            cuda.syncthreads()
        count += 1
        if flags[slot] == 0:
            break
        for i in range(tid, n, size):
            attach_at(lim, wor, x, tau, w, i)
        cuda.syncthreads()
    for i in range(tid, n, size):
        limit_end_at(lim, wor, before, start, x, v, run.h, w, i, run.method == 0, first)
    cuda.syncthreads()
    return count


@inlined
def copy_back_at(it, w, i):
    """``(x, v) ← (xt, y)``: a run of an odd number of explicit steps ends in the second
    buffers."""
    for d in range(3):
        it.x[w, i, d] = it.xt[w, i, d]
        it.v[w, i, d] = it.y[w, i, d]


@inlined
def start_at(wor, it, bdf2, w, i):
    """The substep's start ``(sx, sv) ← (x, v)`` (kept under the ``bdf2`` scheme only) and
    ``x^t``, which the initial guess reads (its normals included): ``x`` under backward Euler;
    under BDF2 (``bdf2``, a history, no colliders: as the CPU's ``VBD._substep``) ``x̂ = (4x −
    px)/3`` with ``v ← (4v − pv)/3`` on a free vertex, and a kinematic one's ``v ← 1.5 v`` (its
    step of ``2h/3`` moves it by ``h v``).
    ``bdf[w]`` says which (every thread writes the same)."""
    bdf = bdf2 and it.past[w] != 0 and wor.ncol[w] == 0
    free = wor.free[w, i]
    for d in range(3):
        xi = it.x[w, i, d]
        vi = it.v[w, i, d]
        if bdf2:  # (the history is kept under BDF2 only)
            it.sx[w, i, d] = xi
            it.sv[w, i, d] = vi
        if bdf and free:
            xi = (4.0 * xi - it.px[w, i, d]) / 3.0
            it.x[w, i, d] = xi
            it.v[w, i, d] = (4.0 * vi - it.pv[w, i, d]) / 3.0
        elif bdf:
            it.v[w, i, d] = 1.5 * vi
        it.xt[w, i, d] = xi
    it.bdf[w] = 1 if bdf else 0


@inlined
def step_of(it, h, hb, w):
    """The step world ``w``'s substep solves: ``hb`` (``2h/3``) under BDF2, else ``h``."""
    return hb if it.bdf[w] != 0 else h


@inlined
def guess_at(top, wor, it, h, w, i):
    """The inertial target ``y = x^t + h v + h² a`` (``a``: gravity and wind over the mass, on a
    free vertex) and the adaptive initial guess: ``y`` with gravity's part of the last step's
    acceleration clamped to ``[0, |g|]``; a pin goes to ``x^t + h v``. As the CPU's
    ``initial_guess``; ``x_s`` and the Chebyshev history start at the guess."""
    free = wor.free[w, i]
    gx, gy, gz = wor.gravity[w, 0], wor.gravity[w, 1], wor.gravity[w, 2]
    gn = math.sqrt(gx * gx + gy * gy + gz * gz)
    ax = ay = az = 0.0
    along = 0.0
    if free:
        fx, fy, fz = external_at(top, wor, it.xt, w, i)
        m = wor.masses[w, i]
        ax, ay, az = fx / m, fy / m, fz / m
        if gn > 0.0:
            gx, gy, gz = gx / gn, gy / gn, gz / gn
            along = it.aprev[w, i, 0] * gx + it.aprev[w, i, 1] * gy + it.aprev[w, i, 2] * gz
            along = min(max(along, 0.0), gn)
    hh = h * h
    for d in range(3):
        a = ax if d == 0 else (ay if d == 1 else az)
        gd = gx if d == 0 else (gy if d == 1 else gz)
        yc = it.v[w, i, d] * h + it.xt[w, i, d]
        if free:
            yc = yc + hh * a
        it.y[w, i, d] = yc
        xc = yc
        if free and gn > 0.0:
            xc = yc + hh * ((along - gn) * gd)
        it.x[w, i, d] = xc
        it.xs[w, i, d] = xc
        it.prev2[w, i, d] = xc


@inlined
def newton_at(top, wor, it, h, w, i):
    """Vertex ``i``'s Newton step on the incremental potential ``Σ m/(2h²)|x − y|² + E(x)``: its
    force ``r`` and 3×3 Hessian from its inertia, the drag, its springs (elastic, and their
    damping over the step; each part of the Hessian clamped to be positive semi-definite) and its
    bending row; ``x_i += H⁻¹ r``, and ``|r|²`` kept for the residual (the CPU's ``sweep``
    without contacts)."""
    x, xt, y = it.x, it.xt, it.y
    if not wor.free[w, i]:
        it.stepped[w, i] = 0.0
        return
    inv_h = 1.0 / h
    m_h2 = wor.masses[w, i] * inv_h * inv_h
    drag_h = wor.drag[w] * inv_h
    xi, yi, zi = x[w, i, 0], x[w, i, 1], x[w, i, 2]
    mx, my, mz = xi - xt[w, i, 0], yi - xt[w, i, 1], zi - xt[w, i, 2]
    f0 = -m_h2 * (xi - y[w, i, 0]) - drag_h * mx
    f1 = -m_h2 * (yi - y[w, i, 1]) - drag_h * my
    f2 = -m_h2 * (zi - y[w, i, 2]) - drag_h * mz
    m = m_h2 + drag_h
    h0, h1, h2, h3, h4, h5 = m, 0.0, 0.0, m, 0.0, m
    for q in range(top.inc_ptr[i], top.inc_ptr[i + 1]):
        j = top.nbr[q]
        xj, yj, zj = x[w, j, 0], x[w, j, 1], x[w, j, 2]
        dx, dy, dz = xj - xi, yj - yi, zj - zi
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length < 1e-300:
            continue
        k, c = spring_constants(top, wor, w, q)
        inv = 1.0 / length
        ux, uy, uz = dx * inv, dy * inv, dz * inv
        de = k * (length - top.rest[q])
        cs = c * inv_h
        mag = de
        if cs > 0.0:
            mag += cs * (
                ((xj - xt[w, j, 0]) - mx) * ux
                + ((yj - xt[w, j, 1]) - my) * uy
                + ((zj - xt[w, j, 2]) - mz) * uz
            )
        f0, f1, f2, h0, h1, h2, h3, h4, h5 = spring_part(
            (ux, uy, uz), inv, mag, de, k, cs, (f0, f1, f2, h0, h1, h2, h3, h4, h5)
        )
    if top.bptr[i + 1] > top.bptr[i]:
        b0, b1, b2 = bending_at(top, x, w, i)
        f0 += b0
        f1 += b1
        f2 += b2
        qd = top.bdiag[i]
        h0 += qd
        h3 += qd
        h5 += qd
    tau = wor.tau[w]
    kc = wor.kc[w]
    eps = EPS_V * h
    for c in range(wor.ncol[w]):
        nx, ny, nz, d = collider_at(wor, w, c, xi, yi, zi)
        p = tau - d
        if p <= 0.0:
            continue
        # the penalty ½ kc (τ − d)², and IPC's lagged friction on the vertex's motion over the
        # step (the collider does not move), as the CPU's colliders_at
        lam = kc * p
        f0, f1, f2, h0, h1, h2, h3, h4, h5 = press(
            lam, kc, (nx, ny, nz), (f0, f1, f2, h0, h1, h2, h3, h4, h5)
        )
        mu = wor.cmu[w, c]
        if mu <= 0.0:
            continue
        rn = mx * nx + my * ny + mz * nz
        tx, ty, tz = mx - rn * nx, my - rn * ny, mz - rn * nz
        tl = math.sqrt(tx * tx + ty * ty + tz * tz)
        g = 1.0 / tl if tl > eps else (2.0 - tl / eps) / eps
        s = mu * lam * g
        f0, f1, f2, h0, h1, h2, h3, h4, h5 = slide(
            s, (tx, ty, tz), s, (nx, ny, nz), (f0, f1, f2, h0, h1, h2, h3, h4, h5)
        )
    it.stepped[w, i] = f0 * f0 + f1 * f1 + f2 * f2
    sx, sy, sz = solve3(h0, h1, h2, h3, h4, h5, f0, f1, f2)
    for c in range(wor.ncol[w]):
        # a collider not yet pressed is not in the Hessian: the step stops at its onset (the
        # CPU's onset)
        nx, ny, nz, d = collider_at(wor, w, c, xi, yi, zi)
        if d < tau:
            continue
        over = (tau - d) - (nx * sx + ny * sy + nz * sz)
        if over > 0.0:
            sx, sy, sz = sx + over * nx, sy + over * ny, sz + over * nz
    x[w, i, 0] = xi + sx
    x[w, i, 1] = yi + sy
    x[w, i, 2] = zi + sz


@inlined
def accelerate_at(wor, it, omega, extrapolate, w, i):
    """After a sweep: Chebyshev's ``x ← ω (x − x_prev2) + x_prev2`` on a free vertex where
    ``extrapolate``, then the history moves on (``x_prev2 ← x_s``, ``x_s ← x``: the iterate before
    the next sweep)."""
    go = extrapolate and wor.free[w, i]
    for d in range(3):
        xc = it.x[w, i, d]
        if go:
            xc = omega * (xc - it.prev2[w, i, d]) + it.prev2[w, i, d]
            it.x[w, i, d] = xc
        it.prev2[w, i, d] = it.xs[w, i, d]
        it.xs[w, i, d] = xc


@inlined
def finish_at(wor, it, h, bdf2, w, i):
    """The step's end: ``v = (x − x^t)/h`` on a free vertex (a pin keeps its velocity) and its
    acceleration ``((x − x^t)/h − v)/h`` for the next initial guess; the substep's start becomes
    BDF2's history, which serves the next substep where ``bdf2`` (``past[w]``: every thread writes
    the same, and none reads it in this stage)."""
    free = wor.free[w, i]
    bdf = it.bdf[w] != 0
    for d in range(3):
        nv = (it.x[w, i, d] - it.xt[w, i, d]) / h
        it.aprev[w, i, d] = (nv - it.v[w, i, d]) / h
        if free:
            it.v[w, i, d] = nv
        elif bdf:  # a kinematic vertex keeps its velocity
            it.v[w, i, d] = it.sv[w, i, d]
        if bdf2:  # this substep's start is the next one's history
            it.px[w, i, d] = it.sx[w, i, d]
            it.pv[w, i, d] = it.sv[w, i, d]
    it.past[w] = 1 if bdf2 else 0
    if free and wor.ncol[w]:  # the contact stage after the step, as on the CPU
        px, py, pz, ux, uy, uz = colliders_stage(
            wor, w, i,
            (it.xt[w, i, 0], it.xt[w, i, 1], it.xt[w, i, 2]),
            (it.x[w, i, 0], it.x[w, i, 1], it.x[w, i, 2]),
            (it.v[w, i, 0], it.v[w, i, 1], it.v[w, i, 2]), False, h,
        )  # fmt: skip
        it.x[w, i, 0], it.x[w, i, 1], it.x[w, i, 2] = px, py, pz
        it.v[w, i, 0], it.v[w, i, 1], it.v[w, i, 2] = ux, uy, uz


@inlined
def residual_part(wor, it, w, i):
    """Vertex ``i``'s share of its world's residual: ``(|r_i|/(m_i g₀))², 1`` when it is free,
    ``(0, 0)`` otherwise."""
    if not wor.free[w, i]:
        return 0.0, 0.0
    g = wor.masses[w, i] * G0
    return it.stepped[w, i] / (g * g), 1.0


@inlined
def chebyshev_omega(k, rho, omega):
    """Chebyshev's weight after sweep ``k`` (0-based): 1, then ``2/(2 − ρ²)``, then ``4/(4 −
    ρ² ω)``."""
    rho2 = rho * rho
    if k == 0:
        return 1.0
    if k == 1:
        return 2.0 / (2.0 - rho2)
    return 4.0 / (4.0 - rho2 * omega)


# --------------------------------------------------------------------------- a launch a stage
@cuda.jit
def explicit_substep(top, wor, it, h, forward, collide):
    """One symplectic Euler step of ``h`` for every vertex of every world (:func:`explicit_at`,
    the colliders' stage where ``collide``). ``forward``: read ``(x, v)`` and write ``(xt, y)``,
    else the other way (two buffers, so every thread reads the step's start)."""
    t = cuda.grid(1)
    n = wor.masses.shape[1]
    if t >= wor.masses.shape[0] * n:
        return
    w = t // n
    i = t - w * n
    if forward:
        explicit_at(top, wor, it.x, it.v, it.xt, it.y, h, w, i, collide)
    else:
        explicit_at(top, wor, it.xt, it.y, it.x, it.v, h, w, i, collide)


@cuda.jit
def limit_begin(lim, wor, it, tau, explicit):
    """The strain limit's start for every vertex of every world (:func:`limit_start_at`, the end
    kept in ``it.xs``): after :func:`explicit_substep` (``explicit``, forward: the step's end in
    ``it.xt``) or a ``vbd`` substep (its end in ``it.x``)."""
    t = cuda.grid(1)
    n = wor.masses.shape[1]
    if t < wor.masses.shape[0] * n:
        limit_start_at(lim, wor, it.xs, it.xt if explicit else it.x, tau, t // n, t % n)


@cuda.jit
def limit_colour(lim, wor, it, tau, lo, count, first, explicit):
    """One colour of a pass of the limit (springs ``lo:lo + count``) in every world that takes
    the pass (its last shortened something: ``lim.flags[w, 1]``, or ``first``);
    ``lim.flags[w, 0]`` set where one was shortened."""
    t = cuda.grid(1)
    worlds = wor.masses.shape[0]
    if t < worlds * count:
        w = t // count
        x = it.xt if explicit else it.x
        if (first or lim.flags[w, 1]) and shorten_at(lim, wor, x, tau, w, lo + t - w * count):
            lim.flags[w, 0] = 1


@cuda.jit
def limit_attach(lim, wor, it, tau, explicit):
    """The attachments after a pass, every vertex of every world whose pass shortened
    something (``lim.flags[w, 0]``)."""
    t = cuda.grid(1)
    n = wor.masses.shape[1]
    if t < wor.masses.shape[0] * n:
        w = t // n
        if lim.flags[w, 0]:
            attach_at(lim, wor, it.xt if explicit else it.x, tau, w, t % n)


@cuda.jit
def limit_end(lim, wor, it, h, explicit, first):
    """:func:`limit_end_at` for every vertex of every world: the explicit step from ``it.x`` to
    ``(it.xt, it.y)``, the colliders' stage after it; or a ``vbd`` substep from ``it.xt`` to
    ``(it.x, it.v)``, whose colliders act inside it."""
    t = cuda.grid(1)
    n = wor.masses.shape[1]
    if t < wor.masses.shape[0] * n:
        if explicit:
            limit_end_at(lim, wor, it.xs, it.x, it.xt, it.y, h, t // n, t % n, True, first)
        else:
            limit_end_at(lim, wor, it.xs, it.xt, it.x, it.v, h, t // n, t % n, False, first)


@cuda.jit
def copy_back(it):
    """:func:`copy_back_at` for every vertex of every world."""
    t = cuda.grid(1)
    n = it.x.shape[1]
    if t < it.x.shape[0] * n:
        copy_back_at(it, t // n, t % n)


@cuda.jit
def vbd_start(wor, it, bdf2):
    """:func:`start_at` for every vertex of every world."""
    t = cuda.grid(1)
    n = it.x.shape[1]
    if t < it.x.shape[0] * n:
        start_at(wor, it, bdf2, t // n, t % n)


@cuda.jit
def vbd_guess(top, wor, it, h, hb):
    """:func:`guess_at` for every vertex of every world."""
    t = cuda.grid(1)
    n = it.x.shape[1]
    if t < it.x.shape[0] * n:
        w = t // n
        guess_at(top, wor, it, step_of(it, h, hb, w), w, t % n)


@cuda.jit
def vbd_colour(top, wor, it, lo, count, h, hb):
    """:func:`newton_at` for one colour's vertices (``top.cverts[lo:lo + count]``) in every
    world: no two vertices of a colour share a spring or a bending stencil, so they move at
    once."""
    t = cuda.grid(1)
    if t >= wor.masses.shape[0] * count:
        return
    w = t // count
    newton_at(top, wor, it, step_of(it, h, hb, w), w, top.cverts[lo + (t - w * count)])


@cuda.jit
def vbd_accelerate(wor, it, omega, extrapolate):
    """:func:`accelerate_at` for every vertex of every world."""
    t = cuda.grid(1)
    n = it.x.shape[1]
    if t < it.x.shape[0] * n:
        accelerate_at(wor, it, omega, extrapolate, t // n, t % n)


@inlined
def block_sum(sums, counts, s, c):
    """The block's sum of every thread's ``(s, c)`` (a tree in shared memory, the same order
    every time: the same bits run to run); every thread gets it."""
    tid = cuda.threadIdx.x
    sums[tid] = s
    counts[tid] = c
    cuda.syncthreads()
    step = cuda.blockDim.x // 2
    while step > 0:
        if tid < step:
            sums[tid] += sums[tid + step]
            counts[tid] += counts[tid + step]
        cuda.syncthreads()
        step //= 2
    total, count = sums[0], counts[0]
    cuda.syncthreads()  # (the arrays are reused by the next sum)
    return total, count


@cuda.jit
def vbd_residual(wor, it, out):
    """Each world's residual (one block a world, :data:`REDUCE` threads): the RMS over its free
    vertices of the last sweep's ``|r_i|/(m_i g₀)``
    (:func:`cloth_sim.integrators.vbd_residual.sweep_residual`), summed in float64."""
    w = cuda.blockIdx.x
    n = wor.masses.shape[1]
    sums = cuda.shared.array(REDUCE, dtype=float64)
    counts = cuda.shared.array(REDUCE, dtype=float64)
    s = 0.0
    c = 0.0
    for i in range(cuda.threadIdx.x, n, cuda.blockDim.x):
        a, b = residual_part(wor, it, w, i)
        s += a
        c += b
    total, count = block_sum(sums, counts, s, c)
    if cuda.threadIdx.x == 0:
        out[w] = math.sqrt(total / count) if count > 0 else 0.0


@cuda.jit
def vbd_finish(wor, it, h, hb, bdf2):
    """:func:`finish_at` for every vertex of every world."""
    t = cuda.grid(1)
    n = it.x.shape[1]
    if t < it.x.shape[0] * n:
        w = t // n
        finish_at(wor, it, step_of(it, h, hb, w), bdf2, w, t % n)


@cuda.jit
def place(it, idx, points, velocities, worlds, moving):
    """``x[w, idx[k]] ← points[r, k]`` for the listed worlds: with ``moving``, ``v ←
    velocities[r, k]`` (held vertices moving with their gripper: ``x + h v`` over the next step),
    else at rest, their last acceleration forgotten (pins moved, a reset, a grasp)."""
    t = cuda.grid(1)
    p = idx.shape[0]
    if t >= worlds.shape[0] * p:
        return
    r = t // p
    k = t - r * p
    w = worlds[r]
    i = idx[k]
    for d in range(3):
        it.x[w, i, d] = points[r, k, d]
        if moving:
            it.v[w, i, d] = velocities[r, k, d]
        else:
            it.v[w, i, d] = 0.0
            it.aprev[w, i, d] = 0.0


@cuda.jit
def place_pairs(it, worlds, idx, points, velocities):
    """``x[worlds[r], idx[r]] ← points[r]``, ``v ← velocities[r]``: vertices one a row, each in
    its own world (held vertices that differ from world to world, moving with their grippers)."""
    r = cuda.grid(1)
    if r >= worlds.shape[0]:
        return
    w = worlds[r]
    i = idx[r]
    for d in range(3):
        it.x[w, i, d] = points[r, d]
        it.v[w, i, d] = velocities[r, d]


@cuda.jit
def gather_points(it, idx, extra, out):
    """``out[w] = (x[w, idx[0]], …, x[w, idx[k - 1]], extra[w, 0], …)``, each point's three
    numbers in a row, for every world (an observation made on the device: a thread a number)."""
    t = cuda.grid(1)
    worlds = out.shape[0]
    width = out.shape[1]
    if t >= worlds * width:
        return
    w = t // width
    c = t - w * width
    q = c // 3
    d = c - 3 * q
    k = idx.shape[0]
    if q < k:
        out[w, c] = it.x[w, idx[q], d]
    else:
        out[w, c] = extra[w, q - k, d]


@cuda.jit
def nearest_free(it, wor, worlds, points, out_i, out_x):
    """Row ``r`` (a block of :data:`REDUCE` threads): the free vertex of world ``worlds[r]``
    nearest to ``points[r]`` (the lowest index of the nearest where two are as near), its index
    in ``out_i[r]`` (−1 where none is free) and its position in ``out_x[r]``."""
    r = cuda.blockIdx.x
    tid = cuda.threadIdx.x
    w = worlds[r]
    n = wor.free.shape[1]
    near = cuda.shared.array(REDUCE, dtype=float64)
    which = cuda.shared.array(REDUCE, dtype=int32)
    best = math.inf
    at = -1
    for i in range(tid, n, cuda.blockDim.x):  # (each thread's in increasing order)
        if wor.free[w, i]:
            dx = it.x[w, i, 0] - points[r, 0]
            dy = it.x[w, i, 1] - points[r, 1]
            dz = it.x[w, i, 2] - points[r, 2]
            d = dx * dx + dy * dy + dz * dz
            if d < best:
                best, at = d, i
    near[tid] = best
    which[tid] = at
    cuda.syncthreads()
    step = cuda.blockDim.x // 2
    while step > 0:
        if tid < step:
            o = tid + step
            if which[o] >= 0 and (
                which[tid] < 0
                or near[o] < near[tid]
                or (near[o] == near[tid] and which[o] < which[tid])
            ):
                near[tid] = near[o]
                which[tid] = which[o]
        cuda.syncthreads()
        step //= 2
    if tid == 0:
        out_i[r] = which[0]
        for d in range(3):
            out_x[r, d] = it.x[w, which[0], d] if which[0] >= 0 else 0.0


@cuda.jit
def mean_pair_distance(x, a, y, b, out):
    """``out[w]``: the mean over ``k`` of ``|x[w, a[k]] − y[w, b[k]]|`` (a block of
    :data:`REDUCE` threads a world, the sum in float64 in a fixed order: the same bits run to
    run)."""
    w = cuda.blockIdx.x
    sums = cuda.shared.array(REDUCE, dtype=float64)
    counts = cuda.shared.array(REDUCE, dtype=float64)
    s = 0.0
    for k in range(cuda.threadIdx.x, a.shape[0], cuda.blockDim.x):
        dx = x[w, a[k], 0] - y[w, b[k], 0]
        dy = x[w, a[k], 1] - y[w, b[k], 1]
        dz = x[w, a[k], 2] - y[w, b[k], 2]
        s += math.sqrt(dx * dx + dy * dy + dz * dz)
    total, _ = block_sum(sums, counts, s, 0.0)
    if cuda.threadIdx.x == 0:
        out[w] = total / a.shape[0] if a.shape[0] > 0 else 0.0


@cuda.jit
def stop_pairs(it, worlds, idx):
    """Vertex ``idx[r]`` of world ``worlds[r]`` at rest where it is, its last acceleration
    forgotten (one a row: a grasp)."""
    r = cuda.grid(1)
    if r >= worlds.shape[0]:
        return
    w = worlds[r]
    i = idx[r]
    for d in range(3):
        it.v[w, i, d] = 0.0
        it.aprev[w, i, d] = 0.0


@cuda.jit
def restart(it, worlds):
    """The listed worlds' vertices' last accelerations forgotten (the adaptive initial guess
    starts again, as after the CPU's ``VBD.reset``)."""
    t = cuda.grid(1)
    n = it.x.shape[1]
    if t < worlds.shape[0] * n:
        r = t // n
        i = t - r * n
        for d in range(3):
            it.aprev[worlds[r], i, d] = 0.0


# --------------------------------------------------------------------------- a frame a launch
@cuda.jit
def frames_in_blocks(top, wor, it, cptr, lim, run, out):
    """``run.steps`` steps of every world in one launch, one thread block a world (its threads
    share its vertices, :func:`cuda.syncthreads` between stages): symplectic Euler
    (``run.method`` 0) or ``vbd`` (1) in ``run.substeps`` substeps of ``run.h``, each iterating
    until the world's own residual is at most ``run.tolerance`` (measured every
    ``run.check_every`` sweeps) or ``run.iterations`` sweeps. ``out[w]``: the last step's
    residual (its substeps' worst), the sweeps done, the steps that ended above the tolerance
    (as :class:`cloth_sim.integrators.vbd.VBD` counts them). Symplectic Euler's steps and
    ``vbd``'s substeps are each followed by the strain limit where ``run.limit >= 0``
    (:func:`limit_in_block`)."""
    w = cuda.blockIdx.x
    tid = cuda.threadIdx.x
    size = cuda.blockDim.x
    n = wor.masses.shape[1]
    h = run.h
    sums = cuda.shared.array(MAX_BLOCK, dtype=float64)
    counts = cuda.shared.array(MAX_BLOCK, dtype=float64)
    flags = cuda.shared.array(3, dtype=int32)
    if tid < 3:
        flags[tid] = 0
    cuda.syncthreads()
    worst = 0.0
    sweeps = 0
    missed = 0
    if run.method == 0:
        limited = run.limit >= 0.0
        passes = 0
        for k in range(run.steps):
            for i in range(tid, n, size):
                if k % 2 == 0:
                    explicit_at(top, wor, it.x, it.v, it.xt, it.y, h, w, i, not limited)
                else:
                    explicit_at(top, wor, it.xt, it.y, it.x, it.v, h, w, i, not limited)
            cuda.syncthreads()
            if limited:
                if k % 2 == 0:
                    passes = limit_in_block(
                        lim, wor, it.xs, it.x, it.xt, it.y, run, w, flags, passes, True
                    )
                else:
                    passes = limit_in_block(
                        lim, wor, it.xs, it.xt, it.x, it.v, run, w, flags, passes, True
                    )
        if run.steps % 2 == 1:
            for i in range(tid, n, size):
                copy_back_at(it, w, i)
    else:
        colours = cptr.shape[0] - 1
        passes = 0
        for part in range(run.steps * run.substeps):
            if part % run.substeps == 0:
                worst = 0.0
            for i in range(tid, n, size):
                start_at(wor, it, run.bdf2, w, i)
            cuda.syncthreads()
            hw = step_of(it, h, run.hb, w)
            for i in range(tid, n, size):
                guess_at(top, wor, it, hw, w, i)
            cuda.syncthreads()
            omega = 1.0
            res = math.inf
            done = 0
            measured = -1
            for k in range(run.iterations):
                for c in range(colours):
                    for q in range(cptr[c] + tid, cptr[c + 1], size):
                        newton_at(top, wor, it, hw, w, top.cverts[q])
                    cuda.syncthreads()
                done += 1
                if done < run.iterations and done % run.check_every == 0:
                    s = 0.0
                    cnt = 0.0
                    for i in range(tid, n, size):
                        a, b = residual_part(wor, it, w, i)
                        s += a
                        cnt += b
                    total, count = block_sum(sums, counts, s, cnt)
                    res = math.sqrt(total / count) if count > 0 else 0.0
                    measured = done
                if k == run.iterations - 1 or res <= run.tolerance:
                    break
                if run.rho > 0.0:
                    omega = chebyshev_omega(k, run.rho, omega)
                    for i in range(tid, n, size):
                        accelerate_at(wor, it, omega, k > 0, w, i)
                    cuda.syncthreads()
            if measured != done:  # the substep's last sweep's
                s = 0.0
                cnt = 0.0
                for i in range(tid, n, size):
                    a, b = residual_part(wor, it, w, i)
                    s += a
                    cnt += b
                total, count = block_sum(sums, counts, s, cnt)
                res = math.sqrt(total / count) if count > 0 else 0.0
            for i in range(tid, n, size):
                finish_at(wor, it, hw, run.bdf2, w, i)
            cuda.syncthreads()
            if run.limit >= 0.0:  # (after each substep, from its start: backward Euler's)
                passes = limit_in_block(
                    lim,
                    wor,
                    it.xs,
                    it.xt,
                    it.x,
                    it.v,
                    run,
                    w,
                    flags,
                    passes,
                    part % run.substeps == 0,
                )
            worst = max(worst, res)
            sweeps += done
            if part % run.substeps == run.substeps - 1 and worst > run.tolerance:
                missed += 1
    if tid == 0:
        out[w, 0] = worst
        out[w, 1] = sweeps
        out[w, 2] = missed


@inlined
def grid_residual(wor, it, partial, w, rank, size):
    """World ``w``'s residual over the whole grid of a cooperative launch: each block's sum (in
    shared memory, :func:`block_sum`) into ``partial[block]``, the grid synchronised, then every
    thread adds the blocks' sums in block order (the same bits run to run, and the same answer in
    every thread)."""
    sums = cuda.shared.array(MAX_BLOCK, dtype=float64)
    counts = cuda.shared.array(MAX_BLOCK, dtype=float64)
    n = wor.masses.shape[1]
    s = 0.0
    c = 0.0
    for i in range(rank, n, size):
        a, b = residual_part(wor, it, w, i)
        s += a
        c += b
    total, count = block_sum(sums, counts, s, c)
    if cuda.threadIdx.x == 0:
        partial[cuda.blockIdx.x, 0] = total
        partial[cuda.blockIdx.x, 1] = count
    cuda.cg.this_grid().sync()
    total = 0.0
    count = 0.0
    for b in range(cuda.gridDim.x):
        total += partial[b, 0]
        count += partial[b, 1]
    cuda.cg.this_grid().sync()  # (partial is written again by the next measure)
    return math.sqrt(total / count) if count > 0 else 0.0


@inlined
def limit_on_grid(lim, wor, before, start, x, v, run, count, first):
    """:func:`limit_in_block` over a cooperative launch's whole grid, every world at once, the
    grid synchronised between stages. Each world stops after its own pass that shortened
    nothing, as in a block (``lim.flags[w, count % 3]``: whether world ``w``'s pass did; a world
    takes a pass while its last did), so a world's bits do not depend on the others."""
    g = cuda.cg.this_grid()
    rank = cuda.grid(1)
    size = cuda.gridsize(1)
    worlds = wor.masses.shape[0]
    n = x.shape[1]
    total = worlds * n
    tau = run.limit
    for t in range(rank, total, size):
        limit_start_at(lim, wor, before, x, tau, t // n, t % n)
    g.sync()
    colours = lim.sptr.shape[0] - 1
    for p in range(run.passes):
        slot = count % 3
        prev = (count + 2) % 3
        for w in range(rank, worlds, size):
            lim.flags[w, (count + 1) % 3] = 0
        for c in range(colours):
            lo = lim.sptr[c]
            m = lim.sptr[c + 1] - lo
            for t in range(rank, worlds * m, size):
                w = t // m
                if (p == 0 or lim.flags[w, prev]) and shorten_at(
                    lim, wor, x, tau, w, lo + t - w * m
                ):
                    lim.flags[w, slot] = 1
            g.sync()
        count += 1
        more = False
        for w in range(worlds):
            if lim.flags[w, slot]:
                more = True
                break
        if not more:
            break
        for t in range(rank, total, size):
            w = t // n
            if lim.flags[w, slot]:
                attach_at(lim, wor, x, tau, w, t - w * n)
        g.sync()
    for t in range(rank, total, size):
        limit_end_at(lim, wor, before, start, x, v, run.h, t // n, t % n, run.method == 0, first)
    g.sync()
    return count


@cuda.jit
def frames_on_grid(top, wor, it, cptr, lim, run, out, partial):
    """:func:`frames_in_blocks` for worlds too large for a block: every thread of a cooperative
    launch (as many blocks as the GPU holds at once) strides over every world's vertices, and the
    whole grid synchronises between stages (``cuda.cg.this_grid().sync()``): one launch for the
    run of steps however large the cloth. ``partial``: ``(blocks, 2)`` scratch for the residual's
    sums. The worlds iterate together, until every world's residual is at most the tolerance."""
    g = cuda.cg.this_grid()
    rank = cuda.grid(1)
    size = cuda.gridsize(1)
    worlds = wor.masses.shape[0]
    n = wor.masses.shape[1]
    total = worlds * n
    h = run.h
    if run.method == 0:
        limited = run.limit >= 0.0
        passes = 0
        for k in range(run.steps):
            for t in range(rank, total, size):
                w = t // n
                if k % 2 == 0:
                    explicit_at(top, wor, it.x, it.v, it.xt, it.y, h, w, t - w * n, not limited)
                else:
                    explicit_at(top, wor, it.xt, it.y, it.x, it.v, h, w, t - w * n, not limited)
            g.sync()
            if limited:
                if k % 2 == 0:
                    passes = limit_on_grid(lim, wor, it.xs, it.x, it.xt, it.y, run, passes, True)
                else:
                    passes = limit_on_grid(lim, wor, it.xs, it.xt, it.x, it.v, run, passes, True)
        if run.steps % 2 == 1:
            for t in range(rank, total, size):
                copy_back_at(it, t // n, t % n)
        return
    colours = cptr.shape[0] - 1
    missed = 0
    sweeps = 0
    worst = 0.0
    passes = 0
    for part in range(run.steps * run.substeps):
        if part % run.substeps == 0:
            worst = 0.0
        for t in range(rank, total, size):
            start_at(wor, it, run.bdf2, t // n, t % n)
        g.sync()
        for t in range(rank, total, size):
            w = t // n
            guess_at(top, wor, it, step_of(it, h, run.hb, w), w, t - w * n)
        g.sync()
        omega = 1.0
        res = math.inf
        done = 0
        measured = -1
        for k in range(run.iterations):
            for c in range(colours):
                lo = cptr[c]
                count = cptr[c + 1] - lo
                for t in range(rank, worlds * count, size):
                    w = t // count
                    hw = step_of(it, h, run.hb, w)
                    newton_at(top, wor, it, hw, w, top.cverts[lo + t - w * count])
                g.sync()
            done += 1
            if done < run.iterations and done % run.check_every == 0:
                res = 0.0
                for w in range(worlds):
                    res = max(res, grid_residual(wor, it, partial, w, rank, size))
                measured = done
            if k == run.iterations - 1 or res <= run.tolerance:
                break
            if run.rho > 0.0:
                omega = chebyshev_omega(k, run.rho, omega)
                for t in range(rank, total, size):
                    accelerate_at(wor, it, omega, k > 0, t // n, t % n)
                g.sync()
        if measured != done:
            res = 0.0
            for w in range(worlds):
                res = max(res, grid_residual(wor, it, partial, w, rank, size))
        for t in range(rank, total, size):
            w = t // n
            finish_at(wor, it, step_of(it, h, run.hb, w), run.bdf2, w, t - w * n)
        g.sync()
        if run.limit >= 0.0:  # (after each substep, from its start: backward Euler's)
            passes = limit_on_grid(
                lim, wor, it.xs, it.xt, it.x, it.v, run, passes, part % run.substeps == 0
            )
        worst = max(worst, res)
        sweeps += done
        if part % run.substeps == run.substeps - 1 and worst > run.tolerance:
            missed += 1
    for w in range(rank, worlds, size):  # (every thread holds the same, over all the worlds)
        out[w, 0] = worst
        out[w, 1] = sweeps
        out[w, 2] = missed
