"""XPBD: Macklin, Müller & Chentanez (2016), "XPBD: position-based simulation of compliant
constrained dynamics", with the substeps of Macklin et al. (2019), "Small steps in physics
simulation".

Each spring is a distance constraint ``C = |x_j − x_i| − L`` with compliance ``α = 1/k``. A step of
``dt`` is ``substeps`` substeps of ``h = dt/substeps``; in each, the velocities take the external
forces (gravity, wind; drag implicitly, with them held), the positions are predicted, ``p = x +
h·v``, and ``iterations`` Gauss–Seidel sweeps over the springs, in a fixed order, project

    Δλ = (−C − α̃·λ − γ·∇C·(p − x)) / ((1 + γ)·(w_i + w_j) + α̃),      α̃ = α/h²,  γ = α·β/h,

with ``w`` the inverse masses (0 on pins), ``λ`` the constraint's multiplier accumulated over the
substep's sweeps, and ``β`` the spring's damping coefficient: the papers' constraint damping, which
resists the relative velocity of the ends along the spring like ``−c·(u·v_ij)·u``. The new velocity
is ``(p − x)/h``. The update is evaluated multiplied through by ``k·h²``, so ``k = 0`` (a
damping-only spring) and ``c = 0`` need no special case.

Spring laws other than Hooke. A spring with energy ``E(l)`` projects with its force in place of
``k·C``: ``Δλ = (−h²E'(l) − λ − h·c·∇C·(p − x)) / ((h²·w_s + h·c)(w_i + w_j) + 1)`` in the scaled
form, ``w_s`` its linearised stiffness (the stiffer branch, as the other implicit methods use):
for Hooke it is the XPBD update above; Choi & Ko's tension-only pairs exert nothing when compressed
and their buckling pairs push with the arc model's force.

Stability. Each projection moves the two ends by at most what makes the constraint's
compliance-weighted residual zero, so no step size makes it grow without bound: the method has no
step limit (it has an error that grows with ``h``: stiff springs come out softer, by the constraint
residual left after the sweeps, which falls with more substeps).
"""

from __future__ import annotations

import numba
import numpy as np

from ..kernel_cache import keep_true
from ..physics import stability as stab
from ..physics.force_kernels import BUCKLE_TABLE, axial, spring_vector
from ..physics.forces import GravityTerm, WindTerm
from .base import Integrator, Stability, VelocityOrigin
from .registry import register


@numba.njit(cache=True)
def _project(p, x, springs, rest, k, w, c, kind, tab, inv_mass, h, lam):
    """One Gauss–Seidel sweep over the springs in their order, in place on ``p``; ``lam`` holds
    each spring's multiplier accumulated over the substep's sweeps (an impulse times ``h``: the
    force is ``lam/h²``)."""
    h2 = h * h
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        wi = inv_mass[i]
        wj = inv_mass[j]
        wsum = wi + wj
        if wsum == 0.0:
            continue
        dx, dy, dz, l = spring_vector(p, i, j)
        if l < 1e-300:
            continue
        ux, uy, uz = dx / l, dy / l, dz / l
        _, de, _ = axial(l, rest[s], k[s], kind[s], tab)
        # the relative displacement over the substep along the spring: ∇C·(p − x)
        rel = (
            ((p[j, 0] - x[j, 0]) - (p[i, 0] - x[i, 0])) * ux
            + ((p[j, 1] - x[j, 1]) - (p[i, 1] - x[i, 1])) * uy
            + ((p[j, 2] - x[j, 2]) - (p[i, 2] - x[i, 2])) * uz
        )
        hc = h * c[s]
        den = (h2 * w[s] + hc) * wsum + 1.0
        if den == 1.0:  # neither stiffness nor damping
            continue
        dlam = (-h2 * de - lam[s] - hc * rel) / den
        lam[s] += dlam
        p[i, 0] -= wi * dlam * ux
        p[i, 1] -= wi * dlam * uy
        p[i, 2] -= wi * dlam * uz
        p[j, 0] += wj * dlam * ux
        p[j, 1] += wj * dlam * uy
        p[j, 2] += wj * dlam * uz


@register
class XPBD(Integrator):
    """XPBD (Macklin, Müller & Chentanez 2016) with substeps (Macklin et al. 2019): compliant
    distance constraints (compliance ``1/k``) projected by Gauss–Seidel, constraint damping from
    the spring damping coefficients.

    Options: ``substeps`` (default 10) per step and ``iterations`` (default 1, as "Small steps"
    recommends: substeps buy more accuracy than iterations) per substep.

    First order; linear momentum conserved (each projection moves the two ends by opposite
    impulses); no step limit (see the module docstring). External forces are applied at the start
    of each substep (symplectic Euler in the substep), drag implicitly per particle.
    """

    name = "xpbd"
    order = 1
    force_point = 0.55  # (S + 1)/(2S) at the default 10 substeps; set per instance
    stability = Stability.UNCONDITIONAL
    counter_names = ("substeps",)

    def __init__(self, model, substeps: int = 10, iterations: int = 1):
        super().__init__(model)
        for name, value in (("substeps", substeps), ("iterations", iterations)):
            if isinstance(value, bool) or int(value) != value or not 1 <= value <= 10_000:
                raise ValueError(f"{name} must be an integer in [1, 10000], got {value!r}")
        self.substeps = int(substeps)
        self.iterations = int(iterations)
        # the constraint impulses act at the end of each substep, k/S of the way (k = 1…S): on
        # average (S + 1)/(2S) of it (a gripper's wrench reads the springs there)
        self.force_point = (self.substeps + 1) / (2 * self.substeps)
        self._w_of = None
        self._strain_limit = None
        self._origin = None  # the last substep's start and h (velocity_origin)

    def attach(self, contacts, self_collision, strain_limit=None) -> None:
        """Keeps the strain limit: it corrects after each substep but the last (the simulator's
        stage corrects after the last, over :meth:`velocity_origin`)."""
        self._strain_limit = strain_limit

    def velocity_origin(self, start_x, dt) -> VelocityOrigin | None:
        """The last substep's start and ``h``: a substep's velocity is ``(p − x)/h`` over it."""
        return self._origin

    def _weights(self, forces):
        if self._w_of is not forces:
            self._w = stab.springs_effective_stiffness(forces.kind, forces.rest, forces.k)
            inv = np.where(self.model.pinned, 0.0, 1.0 / self.model.masses)
            self._inv_mass = inv
            self._w_of = forces
        return self._w

    def step(self, state, forces, dt):
        x, v = state.x, state.v
        w = self._weights(forces)
        inv_mass = self._inv_mass
        free = ~self.model.pinned
        h = dt / self.substeps
        p = self._buffer("_p", x)
        a = self._buffer("_a", x)
        lam = self.__dict__.get("_lam")
        if lam is None or len(lam) != len(forces.springs):
            lam = self._lam = np.empty(len(forces.springs))
        external = [t for t in forces.terms if isinstance(t, (GravityTerm, WindTerm))]
        # Drag is backward Euler within the substep, coupled with the constraints: from (m +
        # h·d)·v' = m·(v + h·a) + h·f_constraints, the prediction is v' = (v + h·a)/(1 + h·d/m) and
        # the projections move the particles with inverse masses 1/(m + h·d). A free particle then
        # falls at exactly the terminal velocity m·a/d at any h (damping the substep's starting
        # velocity and then kicking it by h·a left a full kick on top: 19 mg particles in a 24 N
        # wind with drag 60 ended a 1 ms step above 1000 m/s, against a terminal velocity of a few
        # m/s), and a cloth at rest hangs at the springs' static extension under its full weight.
        damp, inv_solve = None, inv_mass
        if forces.drag > 0:
            damp = 1.0 / (1.0 + h * forces.drag * inv_mass)  # 1 on pins
            inv_solve = damp * inv_mass  # 1/(m + h·d); 0 on pins
        strain = self._strain_limit
        strain = strain if strain is not None and strain.active else None
        start = self._buffer("_start", x)
        for k in range(self.substeps):
            if k > 0 and strain is not None:
                # the last substep's stretch corrected, its velocity following over h: corrected
                # once a step over dt, a correction of several substeps' stretch left the rest of
                # a velocity that stretched the springs again (a soft sheet under a strain limit
                # kept moving at 0.56 m/s after 10 s)
                strain.correct_within(state, VelocityOrigin(start, h), self.velocity_follow)
            if strain is not None or k == self.substeps - 1:  # (the last: velocity_origin's)
                np.copyto(start, x)
            a[:] = 0.0
            for term in external:
                term.add_force(x, v, a)
            a *= inv_mass[:, None]
            v[free] += h * a[free]
            if forces.drag > 0:
                v *= damp[:, None]
            np.multiply(v, h, out=p)
            p += x
            lam[:] = 0.0
            for _ in range(self.iterations):
                _project(
                    p,
                    x,
                    forces.springs,
                    forces.rest,
                    forces.k,
                    w,
                    forces.c,
                    forces.kind,
                    BUCKLE_TABLE,
                    inv_solve,
                    h,
                    lam,
                )
            # v = (p − x)/h on the free particles; pins keep their velocity and land at x + h·v
            v[free] = (p[free] - x[free]) / h
            np.copyto(x, p)
        self._origin = VelocityOrigin(start, h)
        self.counters["substeps"] += self.substeps


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
