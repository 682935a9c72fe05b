"""How far an iterate of :mod:`~cloth_sim.integrators.vbd` is from its backward-Euler step: the
step's force imbalance, relative to the cloth's weight.

A step of ``h`` is the minimum of the incremental potential ``G(x) = Σ m_i/(2h²)|x_i − y_i|² +
E(x)`` (:mod:`~cloth_sim.integrators.vbd`), so the step is solved where every free vertex's force

    r_i = −∂G/∂x_i = −m_i/h² (x_i − y_i) − d/h (x_i − x_i^t) + f_i(x, (x − x^t)/h)

vanishes: the inertia's and the drag's part against the springs (elastic and damping), the
bending, the colliders' penalty and friction and the self-contacts, every term the sweeps step on
(:mod:`~cloth_sim.integrators.vbd_terms`, :mod:`~cloth_sim.integrators.vbd_contact`), taken at the
iterate alone (no Gauss–Seidel order: each vertex sees the others where they ended).

**The residual** is the root mean square over the free vertices of ``|r_i| / (m_i g₀)``, ``g₀ =
9.80665 m/s²`` (standard gravity, whatever the scene's gravity): the unbalanced force as a fraction
of each vertex's own weight. Why the weight and not the last Newton steps' length: a stiff sheet
far from its step moves little in one sweep (each vertex's Newton step is its imbalance over its
springs' stiffness, ~10³–10⁴ times its inertia ``m/h²`` on a real fabric at 1/60 s), so the steps'
length says more about the stiffness than about the distance to the solution; the force does not
shrink with the stiffness. And why the weight rather than ``|∇G|`` at the step's start: it is a
fixed scale, the same at every resolution (both sides are per vertex, ``∝ m_i``), so one tolerance
means the same at 32×32 and at 128×128, on a grid and on a mesh. What the residual means in metres:
an imbalance ``r`` moves a vertex by about ``r g₀ h²`` in the soft (bending, swinging) modes, where
the Hessian is the inertia (2.7 mm × r at 1/60 s), and far less along the stiff ones.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from ..physics.bending import bending_row
from .vbd_contact import colliders_at
from .vbd_terms import self_contacts_at, springs_at

#: the residual's unit of force per kilogram (standard gravity, m/s²)
G0 = 9.80665
#: runs the vertices are cut into for the cores (each vertex's share is its own: the same bits)
CHUNKS = 8


class StepPoint(NamedTuple):
    """The step a residual is measured on: the iterate ``x``, the step's start ``xt`` and inertial
    target ``y`` (each ``(n, 3)``), ``m/h²`` and the masses ``(n,)``, ``1/h``, the drag's ``d/h``,
    and which vertices are free (``(n,)`` bool)."""

    x: np.ndarray
    xt: np.ndarray
    y: np.ndarray
    m_h2: np.ndarray
    masses: np.ndarray
    inv_h: float
    drag_h: float
    free: np.ndarray


class ContactTerms(NamedTuple):
    """The contacts' constants in the step's potential: the thickness ``tau``, the colliders' and
    the self-contacts' stiffness ``kc`` and ``ks``, the friction's smoothing ``eps`` (m), the
    cloth's own Coulomb μ and which vertices may touch a collider (``near``, ``(n,)`` bool). The
    colliders themselves (:meth:`~cloth_sim.contact.colliders.Contacts.packed`) and the
    self-contact records (:class:`~cloth_sim.integrators.vbd.VBD`'s, with the colours) travel
    beside it as tuples of their own (numba's parallel loops take no tuple inside a tuple)."""

    tau: float
    kc: float
    eps: float
    ks: float
    mu_self: float
    near: np.ndarray


@numba.njit(cache=True, inline="always")
def _imbalance(i, p, sp, co, sc, ct):
    """``r_i`` (module docstring) of free vertex ``i``."""
    x, xt, y = p.x, p.xt, p.y
    inc_ptr, nbr, rest, k, c, kind, tab, _, bptr, bidx, bval, bdiag = sp
    m, d = p.m_h2[i], p.drag_h
    f0 = -m * (x[i, 0] - y[i, 0]) - d * (x[i, 0] - xt[i, 0])
    f1 = -m * (x[i, 1] - y[i, 1]) - d * (x[i, 1] - xt[i, 1])
    f2 = -m * (x[i, 2] - y[i, 2]) - d * (x[i, 2] - xt[i, 2])
    h0 = h1 = h2 = h3 = h4 = h5 = 0.0
    f0, f1, f2, h0, h1, h2, h3, h4, h5, _ = springs_at(
        i, x, xt, inc_ptr, nbr, rest, k, c, kind, tab, p.inv_h, f0, f1, f2, h0, h1, h2, h3, h4, h5
    )
    if bdiag.shape[0]:
        b0, b1, b2 = bending_row(x, bptr, bidx, bval, i)
        f0 += b0
        f1 += b1
        f2 += b2
    ckind, cpos, crot, cpos0, crot0, cgeo, cmu = co[:7]
    if ckind.shape[0] and ct.near[i]:
        f0, f1, f2, h0, h1, h2, h3, h4, h5, _ = colliders_at(
            i, x, xt, ckind, cpos, crot, cpos0, crot0, cgeo, cmu, co[8:], ct.tau, ct.kc, ct.eps,
            f0, f1, f2, h0, h1, h2, h3, h4, h5,
        )  # fmt: skip
    rec_ptr, rec, _, _, pidx, pcoef, pnrm, _, _, rec_d, colour = sc
    if rec_ptr[i + 1] > rec_ptr[i]:
        f0, f1, f2, h0, h1, h2, h3, h4, h5 = self_contacts_at(
            i, x, x, xt, colour, rec_ptr, rec, pidx, pcoef, pnrm, ct.tau, ct.ks, ct.mu_self,
            ct.eps, rec_d, f0, f1, f2, h0, h1, h2, h3, h4, h5,
        )  # fmt: skip
    return math.sqrt(f0 * f0 + f1 * f1 + f2 * f2) / (p.masses[i] * G0)


@numba.njit(cache=True)
def _run(lo, hi, p, sp, co, sc, ct, out):
    """:func:`imbalances` of vertices ``lo … hi − 1``."""
    for i in range(lo, hi):
        out[i] = _imbalance(i, p, sp, co, sc, ct) if p.free[i] else 0.0


@numba.njit(cache=True, parallel=True)
def imbalances(p, sp, co, sc, ct, out):
    """Each free vertex's ``|r_i| / (m_i g₀)`` into ``out`` (0 for the others), in
    :data:`CHUNKS` runs for the cores. ``sp``: the vertices' springs and bending rows as the sweeps
    take them (``VBD._layout``); ``co``, ``sc``: the colliders and the self-contact records
    (:class:`ContactTerms`)."""
    n = out.shape[0]
    size = (n + CHUNKS - 1) // CHUNKS
    for ch in numba.prange(CHUNKS):
        _run(ch * size, min(n, ch * size + size), p, sp, co, sc, ct, out)


@numba.njit(cache=True)
def _rms(values, free):
    """The root mean square of ``values`` over ``free``, summed in the vertices' order (the same
    bits at any thread count)."""
    s = 0.0
    n = 0
    for i in range(values.shape[0]):
        if free[i]:
            s += values[i] * values[i]
            n += 1
    return math.sqrt(s / n) if n else 0.0


@numba.njit(cache=True)
def _grid_run(lo, hi, F, slot, p, co, ct, out):
    """:func:`_grid_imbalances` of vertices ``lo … hi − 1``."""
    F0, F1, F2 = F
    x, xt = p.x, p.xt
    ckind, cpos, crot, cpos0, crot0, cgeo, cmu = co[:7]
    for i in range(lo, hi):
        if not p.free[i]:
            out[i] = 0.0
            continue
        s = slot[i]
        f0, f1, f2 = F0[s], F1[s], F2[s]
        if ckind.shape[0] and ct.near[i]:
            h0 = h1 = h2 = h3 = h4 = h5 = 0.0
            f0, f1, f2, h0, h1, h2, h3, h4, h5, _ = colliders_at(
                i, x, xt, ckind, cpos, crot, cpos0, crot0, cgeo, cmu, co[8:], ct.tau, ct.kc,
                ct.eps, f0, f1, f2, h0, h1, h2, h3, h4, h5,
            )  # fmt: skip
        out[i] = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2) / (p.masses[i] * G0)


@numba.njit(cache=True, parallel=True)
def _grid_imbalances(F, slot, p, co, ct, out):
    """:func:`imbalances` from the grid's forces by slot (``F``: springs, bending, inertia and
    drag, :meth:`~cloth_sim.integrators.vbd_grid.GridLayout.forces`), the colliders' terms added
    for the vertices that may touch one (the grid's sweeps take no self-contact)."""
    n = out.shape[0]
    size = (n + CHUNKS - 1) // CHUNKS
    for ch in numba.prange(CHUNKS):
        _grid_run(ch * size, min(n, ch * size + size), F, slot, p, co, ct, out)


def grid_residual(
    forces: tuple, slot: np.ndarray, p: StepPoint, co: tuple, ct: ContactTerms, out: np.ndarray
) -> float:
    """:func:`residual` where the grid's blocks gave the forces (``forces`` by slot, ``slot``
    each vertex's; ``p.x`` the same iterate, gathered)."""
    _grid_imbalances(forces, slot, p, co, ct, out)
    return float(_rms(out, p.free))


def residual(
    p: StepPoint, sp: tuple, co: tuple, sc: tuple, ct: ContactTerms, out: np.ndarray
) -> float:
    """The relative residual of the iterate ``p.x`` (module docstring); ``out`` ``(n,)`` receives
    each vertex's share."""
    imbalances(p, sp, co, sc, ct, out)
    return float(_rms(out, p.free))
