"""The energy balance of a simulation: energy that no source has put in marks it unstable.

A method past its stable step does not always blow up: under a strain limit, or with contacts, the
run-away can stay bounded and keep chattering (symplectic Euler 32× above ``stable_dt`` under the
strain projection: a 1.4 kg cloth with 45 J of kinetic energy after 0.3 s), which a check for
non-finite or huge values never sees. Energy does: the cloth's mechanical energy

    E = kinetic (free particles) + elastic (springs) + gravity's potential (free particles)

changes only by the work of what drives it — the wind, and the pins and grippers it is moved by —
and damping, drag, friction, contacts and the strain limit only take energy out. So

    excess(t) = E(t) − E(t₀) − W_in(t₀, t),     W_in = ∫ (Σ f_wind·v − Σ_kinematic f_springs·v) dt

is at most the method's own small error in a stable run, and grows without bound in a chattering
one. The work is integrated by the trapezoidal rule over samples ``interval`` apart (simulated
time). A collider that moves can push energy in through contact forces the balance does not see:
while one moves, the balance starts again from the current state (no verdict is drawn across it).

A run is **unstable** when the excess passes ``tolerance`` of the energy scale ``M·|g|·L`` (the
cloth's mass, gravity, the diagonal of its starting box) plus what was put in: 25 % by default,
far above the errors of a stable step and far below what chatter puts in.
"""

from __future__ import annotations

import numpy as np

from .forces import WindTerm


class EnergyBalance:
    """Samples ``sim`` (a :class:`~cloth_sim.simulator.Simulator`) after its steps: call
    :meth:`sample` after each step or burst of steps (it measures only every ``interval`` s of
    simulated time); :attr:`excess` and :attr:`unstable` say where the balance stands."""

    def __init__(self, sim, interval: float = 0.01, tolerance: float = 0.25):
        self.sim = sim
        self.interval = float(interval)
        self.tolerance = float(tolerance)
        model = sim.model
        x = sim.positions
        extent = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0))) if len(x) else 0.0
        g = float(np.linalg.norm(sim.gravity))
        #: the energy scale the tolerance is a share of (J): the weight over the starting box
        self.scale = float(model.masses.sum()) * max(g, 1.0) * max(extent, 1e-3)
        self._f = np.zeros_like(x)
        self.clear()

    def clear(self) -> None:
        """Forget the verdict and start again (a reset, a new simulation)."""
        self.excess = 0.0
        self.worst = 0.0
        self.restart()

    def restart(self) -> None:
        """Start the balance again from the current state, keeping the verdict so far (a change of
        parameters changes what the energy means; a collider moved)."""
        sim = self.sim
        self._t = sim.time
        self._e0 = self._energy()
        self._work = 0.0
        self._power = self._power_now()
        self._poses = self._collider_poses()

    def _energy(self, energy: dict | None = None) -> float:
        """The cloth's mechanical energy (J) from ``energy``, :meth:`Simulator.energy`'s terms at
        the current state (made here when not given), less the pins' kinetic and gravitational
        parts: the kinematic particles are driven, their energy is not the cloth's."""
        sim = self.sim
        if energy is None:
            energy = sim.energy()
        pinned = sim.model.pinned
        m = sim.model.masses[pinned]
        x, v = sim.positions[pinned], sim.velocities[pinned]
        pins = 0.5 * float(np.einsum("i,ij,ij->", m, v, v)) - float(
            np.einsum("i,ij,j->", m, x, sim.gravity)
        )
        return energy["kinetic"] + energy["spring"] + energy["gravity"] - pins

    def _power_now(self) -> float:
        """The power the wind and the kinematic particles (pins, held particles) put in now (W)."""
        sim = self.sim
        x, v = sim.positions, sim.velocities
        f = self._f
        pinned = sim.model.pinned
        power = 0.0
        for term in sim.forces.terms:
            if isinstance(term, WindTerm):
                f[:] = 0.0
                term.add_force(x, v, f)
                power += float(np.einsum("ij,ij->", f[~pinned], v[~pinned]))
        # (pins at rest put nothing in: the springs' force on them is not needed then)
        if pinned.any() and sim.forces.spring_term.active and np.any(v[pinned]):
            f[:] = 0.0
            sim.forces.spring_term.add_force(x, v, f)
            # the springs pull the kinematic particles with f; they are driven against it
            power -= float(np.einsum("ij,ij->", f[pinned], v[pinned]))
        return power

    def _collider_poses(self):
        return [(c.position.copy(), c.orientation.copy()) for c in self.sim.colliders]

    def sample(self, energy: dict | None = None) -> None:
        """Advance the balance to the simulator's time, if ``interval`` has passed since the last
        sample; ``energy``: :meth:`Simulator.energy` at the current state, where the caller has
        it (the node's tick publishes it too)."""
        sim = self.sim
        t = sim.time
        if t - self._t < self.interval * (1 - 1e-9):
            return
        poses = self._collider_poses()
        if len(poses) != len(self._poses) or any(
            not (np.array_equal(p, q) and np.array_equal(a, b))
            for (p, a), (q, b) in zip(poses, self._poses)
        ):
            self.restart()  # a collider moved: contact work unseen; no verdict across it
            return
        power = self._power_now()
        self._work += 0.5 * (power + self._power) * (t - self._t)
        self._t, self._power = t, power
        self.excess = self._energy(energy) - self._e0 - self._work
        self.worst = max(self.worst, self.excess / self.allowed)

    @property
    def allowed(self) -> float:
        """The excess (J) above which the run counts as unstable."""
        return self.tolerance * (self.scale + abs(self._work))

    @property
    def unstable(self) -> bool:
        """Whether the excess has ever passed what is allowed (since the balance began)."""
        return self.worst > 1.0

    def message(self) -> str:
        return (
            f"energy balance: {self.excess:.4g} J more mechanical energy than gravity, wind, pins "
            f"and grippers put in (allowed {self.allowed:.3g} J, {100 * self.tolerance:.0f} % of "
            f"M·|g|·L = {self.scale:.3g} J plus the work done); the step chatters: a smaller dt, "
            f"or an unconditionally stable method"
        )
