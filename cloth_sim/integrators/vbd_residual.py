"""How far an iterate of :mod:`~cloth_sim.integrators.vbd` is from its backward-Euler step: the
step's force imbalance, relative to the cloth's weight.

A step of ``h`` is the minimum of the incremental potential ``G(x) = Σ m_i/(2h²)|x_i − y_i|² +
E(x)`` (:mod:`~cloth_sim.integrators.vbd`), so the step is solved where every free vertex's force

    r_i = −∂G/∂x_i = −m_i/h² (x_i − y_i) − d/h (x_i − x_i^t) + f_i(x, (x − x^t)/h)

vanishes: the inertia's and the drag's part against the springs (elastic and damping), the
bending, the colliders' penalty and friction and the self-contacts, every term the sweeps step on
(:mod:`~cloth_sim.integrators.vbd_terms`, :mod:`~cloth_sim.integrators.vbd_contact`). Each sweep
computes ``r_i`` for its Newton step anyway (``Δx_i = H_i⁻¹ r_i``), at the iterate as the sweep
finds it (the colours before ``i``'s already moved: Gauss–Seidel's order); the sweeps keep
``|r_i|²``, so the residual costs nothing (measured at the iterate itself, by a kernel of its own,
it cost about one sweep and a third: 25 % of the T-shirt's step).

**The residual** is the root mean square over the free vertices of ``|r_i| / (m_i g₀)``, ``g₀ =
9.80665 m/s²`` (standard gravity, whatever the scene's gravity), from the last sweep: the
unbalanced force as a fraction of each vertex's own weight. Why the weight and not the last Newton
steps' length: a stiff sheet far from its step moves little in one sweep (each vertex's Newton step
is its imbalance over its springs' stiffness, ~10³–10⁴ times its inertia ``m/h²`` on a real fabric
at 1/60 s), so the steps' length says more about the stiffness than about the distance to the
solution; the force does not shrink with the stiffness. And why the weight rather than ``|∇G|`` at
the step's start: it is a fixed scale, the same at every resolution (both sides are per vertex,
``∝ m_i``), so one tolerance means the same at 32×32 and at 128×128, on a grid and on a mesh. What
the residual means in metres: an imbalance ``r`` moves a vertex by about ``r g₀ h²`` in the soft
(bending, swinging) modes, where the Hessian is the inertia (2.7 mm × r at 1/60 s), and far less
along the stiff ones.
"""

from __future__ import annotations

import math

import numba

from ..kernel_cache import keep_true

#: the residual's unit of force per kilogram (standard gravity, m/s²)
G0 = 9.80665


@numba.njit(cache=True)
def sweep_residual(squared, masses, free):
    """The residual from the sweep's own figures: ``squared[i]`` the squared force of vertex
    ``i`` as the last sweep found it (before its Newton step), each over ``(m_i g₀)²``, RMS over
    the free vertices, summed in their order."""
    s = 0.0
    n = 0
    for i in range(squared.shape[0]):
        if free[i]:
            w = masses[i] * G0
            s += squared[i] / (w * w)
            n += 1
    return math.sqrt(s / n) if n else 0.0


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
