"""The per-vertex terms of :mod:`~cloth_sim.integrators.vbd`'s incremental potential that are not
contacts with colliders (those: :mod:`~cloth_sim.integrators.vbd_contact`): a vertex's springs
(elastic and their damping), its part of the potential for a line search, and its self-contacts.
Each adds its part to a vertex's **block** ``fh = (f0, f1, f2, h0, …, h5)``, the vertex's force
and symmetric Hessian ``(xx, xy, xz, yy, yz, zz)`` as nine numbers, and returns it, for the sweeps
(:func:`cloth_sim.integrators.vbd_kernels.sweep`). A vertex's springs are one bundle, ``springs =
(inc_ptr, nbr, rest, k, c, kind, tab)`` (CSR: each vertex's springs' other ends, rest lengths,
stiffnesses, dampings and kinds, and Choi–Ko's table); its self-contact records another,
``records = (rec_ptr, rec_v, rec_w, rec_n, rec_d)``, each record's pair copied in
(:func:`cloth_sim.integrators.vbd.pack_records`). (Bundles of arrays cost nothing in these
functions: they are inlined and call nothing that is not.)
"""

from __future__ import annotations

import math

import numba

from ..kernel_cache import keep_true
from ..kinds import LINEAR
from ..physics.force_kernels import axial
from .vbd_contact import press, slide


@numba.njit(cache=True, inline="always")
def spring_part(u, inv, mag, de, d2e, cs, fh):
    """One spring's share of a vertex's Newton step added to its block ``fh``, along the unit
    vector ``u`` (three numbers) to the other end (``inv``: one over the length): the force
    ``mag·u``, and the Hessian ``E'' u uᵀ + (E'/l)(I − u uᵀ)``, each part clamped at 0 (positive
    semi-definite), plus the damping's ``(c/h) u uᵀ`` (``de``, ``d2e``: ``E'``, ``E''``; ``cs``:
    ``c/h``). Numbers only: the CUDA kernels call it too
    (:func:`cloth_sim.cuda.kernels.newton_at`)."""
    ux, uy, uz = u
    f0, f1, f2, h0, h1, h2, h3, h4, h5 = fh
    f0 += mag * ux
    f1 += mag * uy
    f2 += mag * uz
    geo = de * inv if de > 0.0 else 0.0
    w = (d2e if d2e > 0.0 else 0.0) + cs - geo
    wx, wy = w * ux, w * uy
    h0 += wx * ux + geo
    h1 += wx * uy
    h2 += wx * uz
    h3 += wy * uy + geo
    h4 += wy * uz
    h5 += w * uz * uz + geo
    return f0, f1, f2, h0, h1, h2, h3, h4, h5


@numba.njit(cache=True, inline="always")
def springs_at(i, x, xt, springs, inv_h, fh):
    """Vertex ``i``'s springs added to its block: elastic, and damping along the spring; returns
    the block and whether one of them is a compressed Choi–Ko buckling pair (the step is then
    checked against the energy)."""
    inc_ptr, nbr, rest, k, c, kind, tab = springs
    rough = False
    xi, yi, zi = x[i, 0], x[i, 1], x[i, 2]
    # the vertex's own motion over the step, for the damping
    mx, my, mz = xi - xt[i, 0], yi - xt[i, 1], zi - xt[i, 2]
    for q in range(inc_ptr[i], inc_ptr[i + 1]):
        j = nbr[q]
        xj, yj, zj = x[j, 0], x[j, 1], x[j, 2]
        dx, dy, dz = xj - xi, yj - yi, zj - zi
        l = math.sqrt(dx * dx + dy * dy + dz * dz)
        if l < 1e-300:
            continue
        inv = 1.0 / l
        ux, uy, uz = dx * inv, dy * inv, dz * inv
        L, kk, kd = rest[q], k[q], kind[q]
        if kd == LINEAR:
            de, d2e = kk * (l - L), kk
        else:
            _, de, d2e = axial(l, L, kk, kd, tab)
            if l < L:
                rough = (
                    True  # a compressed Choi–Ko pair: its energy is not smooth at the rest length
                )
        # the force on i pulls it towards j by E'(l); the damping along the spring resists the
        # ends' relative motion over the step
        cs = c[q] * inv_h
        mag = de
        if cs > 0.0:
            mag += cs * (
                ((xj - xt[j, 0]) - mx) * ux
                + ((yj - xt[j, 1]) - my) * uy
                + ((zj - xt[j, 2]) - mz) * uz
            )
        fh = spring_part((ux, uy, uz), inv, mag, de, d2e, cs, fh)
    return fh, rough


@numba.njit(cache=True, inline="always")
def local_energy(i, p, x, xt, y, m_h2, drag_h, springs, inv_h, bend):
    """The part of the incremental potential that depends on vertex ``i`` placed at ``p`` (three
    numbers): its inertia and drag, its springs' energy and their damping potential, the
    bending's ``½Q_ii|p|² + p·Σ_j Q_ij x_j`` (contacts left out)."""
    px, py, pz = p
    inc_ptr, nbr, rest, k, c, kind, tab = springs
    ax, ay, az = px - y[i, 0], py - y[i, 1], pz - y[i, 2]
    bx, by, bz = px - xt[i, 0], py - xt[i, 1], pz - xt[i, 2]
    e = 0.5 * m_h2[i] * (ax * ax + ay * ay + az * az) + 0.5 * drag_h * (
        bx * bx + by * by + bz * bz
    )
    bptr, bidx, bval, bdiag = bend
    if bdiag.shape[0]:
        e += 0.5 * bdiag[i] * (px * px + py * py + pz * pz)
        for q in range(bptr[i], bptr[i + 1]):
            j = bidx[q]
            if j != i:
                e += bval[q] * (px * x[j, 0] + py * x[j, 1] + pz * x[j, 2])
    for q in range(inc_ptr[i], inc_ptr[i + 1]):
        j = nbr[q]
        dx, dy, dz = x[j, 0] - px, x[j, 1] - py, x[j, 2] - pz
        l = math.sqrt(dx * dx + dy * dy + dz * dz)
        if l < 1e-300:
            continue
        es, _, _ = axial(l, rest[q], k[q], kind[q], tab)
        e += es
        if c[q] > 0.0:
            rel = (
                ((x[j, 0] - xt[j, 0]) - bx) * dx
                + ((x[j, 1] - xt[j, 1]) - by) * dy
                + ((x[j, 2] - xt[j, 2]) - bz) * dz
            )
            rel /= l
            e += 0.5 * c[q] * inv_h * rel * rel
    return e


#: a self-contact pair not pressed but within this share of the thickness beyond it (``τ ≤ d <
#: (1 + NEAR)·τ``) adds its penalty's stiffness ``k w² n nᵀ`` to the vertex's block, without a
#: force: a proximal term along the pair's normal that vanishes at the sweeps' fixed point, so the
#: step there is the penalty's own, but holds a vertex's step toward (or away from) the pair to
#: what the pressed penalty would allow. Without it, the step that would cross the onset was cut
#: there (:func:`~cloth_sim.integrators.vbd_contact.onset`): one side of the pair moved, the other
#: not, and a vertex held at the onset felt no normal force and so no friction. The resting
#: T-shirt walked across its table (in TshirtFold's start, variation 1, as stiff as the knit and
#: converged at 20 iterations a step: its mean vertex 33 mm in 3 s; 0.7 mm with this) and its
#: layers heaved (at 1e4 N/m and 8 s, 28 % of the vertices moving over 0.2 mm a step, kinetic
#: energy 2.5e-5 J; 4.6 % and 5.0e-6 J with this). A tenth and a half of the thickness: 8.3 % and
#: 7.1 %, 7.9e-6 and 5.0e-6 J (2026-12-03; docs/contacts.md)
NEAR = 0.25


@numba.njit(cache=True, inline="always")
def self_contacts_at(i, x, xs, xt, records, law, fh):
    """Vertex ``i``'s self-contacts: ``½ k (τ − d)²`` on each pair's distance ``d`` along the
    normal the search found, ``d = n·Σ_k w_k x_k`` over the pair's four vertices
    (:func:`~cloth_sim.integrators.vbd_kernels.contact_pairs`: the normal and the nearest points'
    weights held between two searches), for the pairs ``i`` is in (its records, each with its
    pair's vertices, weights and normal: :func:`~cloth_sim.integrators.vbd.pack_records`); and
    friction ``μ`` between the two sides as on a collider (IPC's smoothed, lagged friction on
    their relative tangential motion over the step, ``Σ_k w_k (x_k − x_k^t)``, with the pressing
    force of the iterate). A partner is read where it is now (``x``: another colour's, done
    earlier in this iteration or not yet begun), or, where its record marks it as of ``i``'s own
    colour (moved at the same time; its index stored as ``−v − 1``), where it was when the
    iteration began (``xs``). A pair not pressed but within :data:`NEAR` of it adds its
    stiffness alone. ``law``: ``(τ, the penalty's stiffness, μ, friction's ε)``; returns the
    block.

    (That choice is written out in the loop: as an inlined helper taking the three arrays, called
    for each of a record's vertices, numba counted the arrays' references at every call, 2.5× the
    whole function's time: 3.0 against 1.2 ms a pass over the T-shirt's 42,615 records. The mark
    made when the records are packed saves reading each partner's colour: 1.07 → 0.95 ms an
    iteration on the settled T-shirt.)"""
    rec_ptr, rec_v, rec_w, rec_n, rec_d = records
    tau, ks, mu, eps = law
    for q in range(rec_ptr[i], rec_ptr[i + 1]):
        w = rec_w[q, 4]
        nx, ny, nz = rec_n[q, 0], rec_n[q, 1], rec_n[q, 2]
        d = 0.0
        ux = uy = uz = 0.0
        for slot in range(4):
            cw = rec_w[q, slot]
            if cw != 0.0:
                v = rec_v[q, slot]
                if v < 0:  # of i's colour, moved at the same time
                    v = -v - 1
                    px, py, pz = xs[v, 0], xs[v, 1], xs[v, 2]
                else:
                    px, py, pz = x[v, 0], x[v, 1], x[v, 2]
                d += cw * (nx * px + ny * py + nz * pz)
                ux += cw * (px - xt[v, 0])
                uy += cw * (py - xt[v, 1])
                uz += cw * (pz - xt[v, 2])
        rec_d[q] = d  # (for vbd_contact.onset, after the step is solved)
        if d >= tau:
            if d < (1.0 + NEAR) * tau:  # not pressed, but near: its stiffness alone (NEAR)
                fh = press(0.0, ks * w * w, (nx, ny, nz), fh)
            continue
        # ∂d/∂x_i = w n: the force pushes the pair apart along n
        lam = ks * (tau - d)
        fh = press(lam * w, ks * w * w, (nx, ny, nz), fh)
        if mu <= 0.0:
            continue
        un = ux * nx + uy * ny + uz * nz
        tx, ty, tz = ux - un * nx, uy - un * ny, uz - un * nz
        tl = math.sqrt(tx * tx + ty * ty + tz * tz)
        g = 1.0 / tl if tl > eps else (2.0 - tl / eps) / eps
        sf = mu * lam * g
        fh = slide(sf * w, (tx, ty, tz), sf * w * w, (nx, ny, nz), fh)
    return fh


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
