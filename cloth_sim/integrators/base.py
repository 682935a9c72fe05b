"""The integrator protocol: what every method declares and the duties it implements.

Like ``scipy.integrate.OdeSolver``, the base class states the duties and keeps the bookkeeping in
one place. A method is constructed for one model (``cls(model, **options)``) and then

* ``reset(state, forces, dt)`` — rebuild its history in ``state.history`` from ``state.x``,
  ``state.v`` (called when the state, ``dt`` or the method changes);
* ``step(state, forces, dt)`` — advance ``state.x``, ``state.v`` by one step in place, reading
  forces only through ``forces`` (a :class:`~cloth_sim.physics.forces.Forces`, rebuilt by the
  simulator when parameters change, so a method never holds stale forces);
* ``pins_moved(state)`` — pinned particles were placed; keep them at rest;
* ``kinematic_velocities(state, indices, dt)`` — pinned particles move with ``state.v`` over the
  next step (grippers);
* ``parameters_changed(changed)`` — a set of names from :data:`CHANGES` saying what changed, so a
  method refactorises only when it must;
* ``attach(contacts, self_collision)`` — the contact stages, for a method that resolves them inside
  its step (it declares which in ``handles``; the simulator then skips them after the step);
* ``stable_dt(analysis)`` — the largest stable ``dt`` by its :class:`Stability` class, from a
  :class:`~cloth_sim.physics.stability.Analysis` of the material (computed once per material and
  kept).

It declares ``name``, ``order``, ``stability``, ``counter_names`` (the counters it keeps in
:attr:`counters`: solves, CG iterations, factorisations) and ``conserves_momentum``. Integrators
import nothing from the simulator.

To add a method: a subclass in this package decorated with ``@register`` (or a module imported at
the end of ``integrators/__init__.py``); the tests parametrised over ``integrators.available()``
then check its free fall, momentum, declared order and stability limit.
"""

from __future__ import annotations

import enum
import math
from typing import NamedTuple

import numpy as np

from ..physics import stability as stab
from ..physics.forces import GravityTerm, WindTerm

#: What ``parameters_changed`` may report.
CHANGES = frozenset({"stiffness", "damping", "drag", "dt", "gravity", "wind"})


class Stability(enum.Enum):
    """How a method's step limit is known."""

    #: from ω_max and the method's amplification matrix on ``x'' + 2ζω x' + ω² x = 0``
    AMPLIFICATION = "amplification"
    #: from the method's own analysis of the whole linearised step (:meth:`Integrator.analyse`)
    ANALYSIS = "analysis"
    #: stable at any ``dt`` on a linear system
    UNCONDITIONAL = "unconditional"


def _subclasses(cls) -> list:
    out = []
    for c in cls.__subclasses__():
        out += [c, *_subclasses(c)]
    return out


class VelocityOrigin(NamedTuple):
    """What a step's end velocities are measured over, for a stage's position correction
    (:meth:`Integrator.velocity_origin`): the positions ``x`` and the time ``h`` (a method's last
    substep, or the step), and whether they are the positions' own difference over it (``mean``
    False: a correction ``Δx`` moves a velocity by ``velocity_follow·Δx/h``) or not (``mean``
    True: a corrected particle takes its mean velocity over ``h`` and ``Δx/h``)."""

    x: np.ndarray
    h: float
    mean: bool = False


class Integrator:
    """Advances a :class:`~cloth_sim.state.State` by one step of ``dt``, in place."""

    name: str = ""
    order: int = 0
    stability: Stability = Stability.AMPLIFICATION
    #: True for methods that solve with the force Jacobian (Baraff–Witkin, its approximations).
    implicit: bool = False
    #: After a position correction ``Δx`` (strain limiting), the velocity moves by
    #: ``velocity_follow · Δx / dt``.
    velocity_follow: float = 1.0
    #: where, between the step's start (0) and its end before any correction (1), the forces that
    #: move the step are evaluated, as an average: 0 for explicit Euler, symplectic Euler and
    #: Verlet, ½ for midpoint and RK4, 1 for the implicit methods (a gripper's wrench reads the
    #: springs there, so it balances the momentum the step gave the cloth)
    force_point: float = 0.0
    #: True for methods whose stability region misses the imaginary axis near 0 (explicit Euler,
    #: midpoint): an undamped oscillator grows at every dt.
    needs_damping: bool = False
    #: False for a method whose step does not conserve linear momentum when no external force acts.
    conserves_momentum: bool = True
    #: Names of the counters the method keeps in :attr:`counters`.
    counter_names: tuple[str, ...] = ()
    #: Names of the post-step stages (``contacts``, ``self_collision``) the method resolves inside
    #: its own step: the simulator does not run them after it, and gives them to :meth:`attach`.
    handles: frozenset = frozenset()
    #: whether its step keeps every particle's path out of the colliders (vbd's conservative
    #: bound): the contact stage then only projects and filters, without checking the paths again
    keeps_paths_off_colliders: bool = False
    #: whether the method takes a material's bending energy (``model.bending``, a constant
    #: Hessian): the explicit methods through the force, vbd in its vertex solve
    takes_bending: bool = False

    def __init__(self, model):
        if getattr(model, "bending", None) is not None and not self.takes_bending:
            takers = sorted(c.name for c in _subclasses(Integrator) if c.takes_bending and c.name)
            raise ValueError(
                f"integrator {self.name!r} does not take a material's bending rigidity yet; "
                f"with a material use one of: {', '.join(takers)}"
            )
        self.model = model
        self.counters = dict.fromkeys(self.counter_names, 0)

    # ------------------------------------------------------------------ duties
    def reset(self, state, forces, dt: float) -> None:
        """Rebuild any history from the current state (no-op for one-step methods)."""

    def step(self, state, forces, dt: float) -> None:
        raise NotImplementedError

    def velocity_origin(self, start_x, dt) -> VelocityOrigin | None:
        """What the last step's end velocities are measured over (:class:`VelocityOrigin`) where
        that is not the positions' difference over the step from ``start_x`` (``None`` here: it
        is, for symplectic Euler and the implicit methods): a method's last substep (``vbd``,
        ``xpbd``), or the step's mean (the explicit Runge–Kutta methods). A stage's position
        correction moves the velocities by it
        (:class:`~cloth_sim.constraints.strain_limit.Stage`)."""
        return None

    def pins_moved(self, state) -> None:
        """Pinned particles were placed (no-op for methods without position history)."""

    def kinematic_velocities(self, state, indices, dt: float) -> None:
        """The pinned particles ``indices`` were given velocities ``state.v[indices]`` to move with
        over the next step (a gripper's motion): a method whose position update is not
        ``x += dt·v`` for a particle without acceleration makes its history agree (no-op here)."""

    def parameters_changed(self, changed: frozenset) -> None:
        """Some of :data:`CHANGES` changed (no-op by default)."""

    def attach(self, contacts, self_collision, strain_limit=None) -> None:
        """The simulator's contact stage (:class:`~cloth_sim.contact.colliders.Contacts`),
        self-collision stage (:class:`~cloth_sim.contact.self_collision.SelfCollision`) and strain
        limit (:class:`~cloth_sim.constraints.strain_limit.StrainLimit`), for a method that
        resolves or uses them (:attr:`handles`); called whenever they or the method change (no-op
        by default)."""

    # ------------------------------------------------------------------ stability
    @classmethod
    def amplification(cls, h: float, omega: float, zeta: float) -> np.ndarray:
        """The matrix taking the method's state to the next step for ``x'' + 2ζω x' + ω² x = 0``
        (:attr:`Stability.AMPLIFICATION` methods): 2×2 on ``(x, v)`` for one-step methods. ``h``,
        ``omega`` and ``zeta`` may be arrays (broadcast together): the result is then
        ``(*batch, n, n)``, one matrix per step and oscillator."""
        raise NotImplementedError

    @classmethod
    def spectral_radii(cls, h, omega, zeta) -> np.ndarray:
        """Spectral radius of :meth:`amplification` (arrays broadcast together); methods with a
        cheaper closed form override it."""
        return stab.spectral_radii(cls.amplification(h, omega, zeta))

    def analysis_key(self):
        """What, beside the material, the method's own analysis depends on (its options)."""
        return ()

    def analyse(self, analysis: "stab.Analysis") -> float:
        """The method's own stability analysis (:attr:`Stability.ANALYSIS` methods)."""
        raise NotImplementedError

    def stable_dt(self, analysis: "stab.Analysis") -> float:
        """Largest ``dt`` expected to be stable on this material: ``inf`` for unconditionally
        stable methods (unless Choi–Ko's onset load would throw the cloth about at some step), the
        amplification matrix's limit on the fastest mode, or the method's own analysis; each
        computed once per material and kept in ``analysis``; at most
        :func:`~cloth_sim.physics.stability.buckling_onset_limit` (Choi–Ko's onset load, a jump
        that no mode analysis sees)."""
        if self.stability is Stability.UNCONDITIONAL:
            return analysis.onset_band[0]
        if self.stability is Stability.AMPLIFICATION:
            limit = analysis.limit(
                ("amplification", type(self)), lambda a: stab.one_step_limit(type(self), a)
            )
        else:
            limit = analysis.limit(("analysis", type(self), self.analysis_key()), self.analyse)
        # Choi–Ko's buckling load jumps in at the onset of compression: no mode analysis sees it
        return min(limit, analysis.onset_limit)

    def stable_again_above(self, analysis: "stab.Analysis") -> float:
        """The step above which a method without a step limit is fine again although
        :meth:`stable_dt` is finite (the top of Choi–Ko's onset band,
        :func:`~cloth_sim.physics.stability.buckling_onset_band`); ``inf`` for the other
        methods."""
        if self.stability is Stability.UNCONDITIONAL:
            return analysis.onset_band[1]
        return math.inf

    def step_is_stable(self, analysis: "stab.Analysis", dt: float) -> bool:
        """``dt ≤ stable_dt`` or ``dt ≥ stable_again_above``."""
        return dt <= self.stable_dt(analysis) or dt >= self.stable_again_above(analysis)

    def known_stable_dt(self, analysis: "stab.Analysis") -> float | None:
        """:meth:`stable_dt` if it costs nothing now (computed before, or unconditional), else
        ``None``: what an error path may report."""
        if self.stability is Stability.UNCONDITIONAL:
            return analysis.onset_band[0]
        if self.stability is Stability.AMPLIFICATION:
            known = analysis.known(("amplification", type(self)))
        else:
            known = analysis.known(("analysis", type(self), self.analysis_key()))
        return None if known is None else min(known, analysis.onset_limit)

    # ------------------------------------------------------------------ helpers
    def _external_force(self, forces, x, v) -> np.ndarray:
        """Gravity's and the wind's force at ``(x, v)`` (a scratch array): what the implicit
        methods take at the step's start, in their inertial target."""
        f = self._buffer("_f_external", x)
        f[:] = 0.0
        for term in forces.terms:
            if isinstance(term, (GravityTerm, WindTerm)):
                term.add_force(x, v, f)
        return f

    def _buffer(self, name: str, like: np.ndarray) -> np.ndarray:
        """A scratch array of ``like``'s shape, allocated once."""
        buf = self.__dict__.get(name)
        if buf is None or buf.shape != like.shape:
            buf = np.empty_like(like)
            self.__dict__[name] = buf
        return buf


def oscillator_matrix(omega, zeta) -> np.ndarray:
    """``J`` of the first-order system ``(x, v)' = J (x, v)`` of a damped oscillator (a batch of
    them for arrays ``omega``, ``zeta``: ``(..., 2, 2)``)."""
    omega, zeta = np.asarray(omega, dtype=np.float64), np.asarray(zeta, dtype=np.float64)
    return matrices([[0.0, 1.0], [-omega * omega, -2.0 * zeta * omega]])


def matrices(entries) -> np.ndarray:
    """Stack a matrix given entry by entry, each a scalar or an array (broadcast together: a batch
    of steps or of oscillators), into ``(*batch, n, n)``: :meth:`Integrator.amplification`
    evaluates many at once."""
    entries = [[np.asarray(e, dtype=np.float64) for e in row] for row in entries]
    shape = np.broadcast_shapes(*(e.shape for row in entries for e in row))
    return np.stack(
        [np.stack([np.broadcast_to(e, shape) for e in row], axis=-1) for row in entries], axis=-2
    )
