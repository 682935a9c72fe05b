"""The simulator: a façade over model + state + forces + integrator + post-step stages.

* the **model** (:class:`~cloth_sim.model.ClothModel`) is read-only and may be shared;
* the **state** (:class:`~cloth_sim.state.State`) is what changes: positions, velocities, time and
  the integrator's history;
* the **forces** (:class:`~cloth_sim.physics.forces.Forces`) are a list of terms compiled from the
  current material and rebuilt when a parameter changes;
* the **integrator** (:mod:`cloth_sim.integrators`) advances the state with ``step(state, forces,
  dt)`` and imports nothing from here;
* the **stages** (:mod:`cloth_sim.constraints.strain_limit`) correct the state after each step;
  inactive ones are skipped;
* the **stability analysis** (:mod:`cloth_sim.physics.stability`) is computed when asked, once per
  material, never inside a step or an error path.

Every value a user sets is checked against :data:`cloth_sim.parameters.SCHEMA`.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np
import scipy.sparse as sp

from . import backends, integrators
from .constraints.grippers import Grips, check_box, check_grasp
from .constraints.strain_limit import DEFAULT_STRAIN_LIMIT_PASSES, StrainLimit
from .contact.colliders import Contacts
from .contact.geometry import positive
from .contact.self_collision import SelfCollision, Uncrossed, check_thickness
from .kernel_cache import keep_true
from .model import ClothModel
from .parameters import SCHEMA, ParameterError
from .physics import stability as stab
from .physics.force_kernels import max_spring_strain, spring_strains
from .physics.forces import Forces
from .robot.placement import RobotMethods, Robots
from .state import SimulationDiverged, State


@numba.njit(cache=True)
def _state_ok(x, v, vmax2, xmax):
    """Whether every speed is at most ``√vmax2`` and every coordinate at most ``xmax`` in size (NaN
    fails both). No early exit: over flat arrays the comparisons run in SIMD, faster than a
    particle loop that returns at the first failure (docs/BENCHMARKS.md §7) — the check runs
    after every step, and a failing state is the rare case."""
    xf = x.ravel()
    vf = v.ravel()
    bad = 0
    for q in range(xf.shape[0]):
        bad |= not (abs(xf[q]) <= xmax)
    for p in range(v.shape[0]):
        a, b, c = vf[3 * p], vf[3 * p + 1], vf[3 * p + 2]
        bad |= not (a * a + b * b + c * c <= vmax2)  # also catches NaN
    return bad == 0


def _finite_vector(name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite 3-vector, got {value!r}")
    return a


class Simulator(RobotMethods):
    """Advances a :class:`~cloth_sim.model.ClothModel` in time.

    >>> from cloth_sim import ClothModel, Simulator
    >>> model = ClothModel.grid(8, 8, 0.05, 0.01, stiffness=1e3, pinned=[(0, 0), (0, -1)])
    >>> sim = Simulator(model, integrator="rk4", dt=1e-3)
    >>> sim.advance(0.1); round(sim.time, 3)
    0.1

    Parameters:
        model: the cloth (never modified; several simulators may share it).
        integrator: a name from :func:`cloth_sim.integrators.available`.
        dt: time step (s).
        gravity: acceleration 3-vector (m/s²).
        wind: 3-vector ``w·W``; particle ``i`` feels ``(n_i·wind)·n_i``. ``None``: no wind.
        strain_limit: Provot's critical deformation rate ``τc`` (0.1 = 10 %), ``None`` for none.
        strain_limit_passes: maximum correction passes per step.
        strain_limit_method: ``"provot"`` (Gauss–Seidel passes) or ``"projection"`` (every
            over-stretched spring projected together,
            :mod:`cloth_sim.constraints.strain_projection`).
        strain_limit_long_range: long-range attachments to the pins before the passes (see
            :mod:`cloth_sim.constraints.strain_limit`); ``False`` for Provot's passes alone.
        drag: linear air drag coefficient (N·s/m per particle).
        max_speed, max_coordinate: the stability guard's bounds; a step that leaves them, or
            produces NaN or inf, is undone and raises :class:`SimulationDiverged`.
        integrator_options: keyword options of the integrator (e.g. ``{"solver": "direct"}`` for
            ``implicit_euler``, ``{"sweeps": 3}`` for ``kang``).
        colliders: shapes from :mod:`cloth_sim.contact.colliders` (plane, sphere, box,
            capsule) the cloth cannot enter; :attr:`colliders` keeps them in this order.
        thickness: distance (m) the cloth keeps from every collider and, with ``self_collision``,
            from its own non-adjacent triangles.
        self_collision: keep the cloth from passing through itself
            (:mod:`cloth_sim.contact.self_collision`).
        device: ``"cpu"`` (this class) or ``"cuda"``: the same method and API on a GPU
            (:mod:`cloth_sim.backends`; ``Simulator(..., device="cuda")`` returns
            :class:`cloth_sim.cuda.simulator.CudaSimulator`, and raises ``ValueError`` naming
            what is missing where no CUDA device can run).
    """

    #: whether :meth:`set_collider_pose` sweeps a collider over the next step (on a device that
    #: cannot, it places it by teleport only)
    sweeps_colliders = True

    def __new__(cls, *args, device: str = "cpu", **kwargs):
        if cls is Simulator and device != "cpu":  # another device's implementation
            return backends.implementation(device)(*args, **kwargs)
        return super().__new__(cls)

    def __init__(
        self,
        model: ClothModel,
        integrator: str = "symplectic_euler",
        dt: float = 1e-3,
        gravity=(0.0, 0.0, -9.81),
        wind=None,
        strain_limit: float | None = None,
        strain_limit_passes: int = DEFAULT_STRAIN_LIMIT_PASSES,
        strain_limit_long_range: bool = True,
        strain_limit_method: str = "provot",
        drag: float = 0.0,
        max_speed: float = 1e3,
        max_coordinate: float = 1e6,
        integrator_options: dict | None = None,
        colliders=None,
        thickness: float = 0.005,
        self_collision: bool = False,
        device: str = "cpu",
    ):
        if backends.check_device(device) != "cpu":
            raise ValueError(f"{type(self).__name__} steps on the cpu, got device={device!r}")
        #: where the cloth is stepped (:mod:`cloth_sim.backends`)
        self.device = "cpu"
        self.model = model
        #: the model as given; ``model`` is it with the held particles pinned while grippers hold
        #: some
        self.base_model = model
        self._grips = Grips()
        self._integrator_options = dict(integrator_options or {})
        self._strain_options = (
            SCHEMA["strain_limit_passes"].check(strain_limit_passes),
            bool(strain_limit_long_range),
            SCHEMA["strain_limit_method"].check(strain_limit_method),
        )
        self._k = np.array(model.stiffness, dtype=np.float64)
        self._c = np.array(model.damping, dtype=np.float64)
        self._gravity = np.array(SCHEMA["gravity"].check(gravity), dtype=np.float64)
        self._wind = None if wind is None else _finite_vector("wind", wind)
        self._drag = SCHEMA["drag"].check(drag)
        self._dt = SCHEMA["dt"].check(dt)
        self.state = State(model.positions)
        self._checkpoint = self.state.copy()
        self.steps_taken = 0
        self.max_speed = float(max_speed)
        self.max_coordinate = float(max_coordinate)
        sel = model.strain_limited
        self._limited = (
            np.ascontiguousarray(model.springs[sel]),
            np.ascontiguousarray(model.rest_lengths[sel]),
        )
        self._contacts = Contacts(model, colliders or (), thickness)
        self.robot_placement = Robots(
            self.add_collider,
            self._contacts.place,
            self.remove_collider,
            lambda: self._contacts.colliders,
            self.set_gripper_pose,
        )
        self._integrator = None  # (made below: the stages are built first)
        self._build_stages(model, None, self_collision)
        self.strain_limit = strain_limit
        self._evaluations_before = 0
        self._analysis = None
        self.forces = self._build_forces()
        self._integrator = integrators.get(integrator)(model, **(integrator_options or {}))
        self._integrator.reset(self.state, self.forces, self._dt)
        self._refresh_stages()

    # ------------------------------------------------------------------ state
    @property
    def positions(self) -> np.ndarray:
        """``(n, 3)`` positions (a read-only view; assign to change them)."""
        view = self.state.x.view()
        view.setflags(write=False)
        return view

    @positions.setter
    def positions(self, x) -> None:
        """Place every particle; pinned particles move with it (that is how a gripper drags the
        cloth)."""
        self.state.x[:] = self._check_state("positions", x)
        self._integrator.reset(self.state, self.forces, self._dt)

    @property
    def velocities(self) -> np.ndarray:
        """``(n, 3)`` velocities (a read-only view; assign to change them). Pinned rows are
        zero."""
        view = self.state.v.view()
        view.setflags(write=False)
        return view

    @velocities.setter
    def velocities(self, v) -> None:
        self.state.v[:] = self._check_state("velocities", v)
        self.state.v[self.model.pinned] = 0.0
        self._integrator.reset(self.state, self.forces, self._dt)

    def move_pins(self, positions, indices=None) -> None:
        """Move pinned particles to ``positions`` (``(p, 3)``; ``indices`` default to every pinned
        particle, in index order). They stay pinned, at rest; the rest of the cloth is
        untouched."""
        pinned_idx = np.flatnonzero(self.model.pinned)
        idx = pinned_idx if indices is None else np.asarray(indices, dtype=np.int64).ravel()
        if not np.all(self.model.pinned[idx]):
            raise ValueError(
                "move_pins: every index must be a pinned particle; pinned are "
                f"{pinned_idx.tolist()}"
            )
        p = np.asarray(positions, dtype=np.float64)
        if p.shape != (len(idx), 3) or not np.all(np.isfinite(p)):
            raise ValueError(
                f"move_pins: positions must be finite with shape ({len(idx)}, 3), got {p.shape}"
            )
        self.state.x[idx] = p
        self._integrator.pins_moved(self.state)

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return self.state.time(self._dt)

    def set_time(self, t: float) -> None:
        """Set the simulated time (s, finite, ≥ 0); the state is untouched (the standard's
        ``reset_simulation`` with only its time or only its state in scope)."""
        t = float(t)
        if not (math.isfinite(t) and t >= 0):
            raise ValueError(f"time must be a finite number >= 0, got {t!r}")
        self.state.t_base, self.state.steps = t, 0

    def reset(self) -> None:
        """Back to the model's initial positions, at rest, at time 0; parameters are kept, every
        gripper is released."""
        if self._grips:
            self._grips.held.clear()
            self.robot_placement.bound.clear()
            self._set_held()
        self.state.x[:] = self.model.positions
        self.state.v[:] = 0.0
        self.state.t_base, self.state.steps = 0.0, 0
        self._integrator.reset(self.state, self.forces, self._dt)

    def save_state(self) -> State:
        """A copy of the state (positions, velocities, time, the integrator's history), for
        :meth:`restore_state`."""
        saved = self.state.copy()
        saved.t_base, saved.steps = self.time, 0  # independent of a later change of dt
        saved.method = self.integrator
        return saved

    def restore_state(self, saved: State) -> None:
        """Go back to a state from :meth:`save_state` (time included). The integrator's history is
        the saved one when the same method saved it, rebuilt from the state otherwise."""
        if saved.x.shape != self.state.x.shape:
            raise ValueError(
                f"restore_state: a state of {len(saved.x)} particles for a cloth of "
                f"{len(self.state.x)}"
            )
        saved.copy_to(self.state)
        self._grips.settle(self.state.x, self.state.v)  # held particles stay with their grippers
        if saved.method != self.integrator or self._grips:
            self._integrator.reset(self.state, self.forces, self._dt)

    # ------------------------------------------------------------------ parameters
    @property
    def dt(self) -> float:
        return self._dt

    @dt.setter
    def dt(self, value: float) -> None:
        value = SCHEMA["dt"].check(value)
        self.state.rebase(self._dt)
        self._dt = value
        self._integrator.reset(self.state, self.forces, self._dt)
        self._integrator.parameters_changed(frozenset({"dt"}))

    @property
    def integrator(self) -> str:
        return self._integrator.name

    def set_integrator(self, name: str, **options) -> None:
        """Switch method (``options`` as for ``integrator_options``); positions and velocities
        carry over."""
        new = integrators.get(name)(self.model, **options)
        new.reset(self.state, self.forces, self._dt)
        self._integrator = new
        self._integrator_options = dict(options)
        self._refresh_stages()

    @property
    def integrator_options(self) -> dict:
        """The current method's options (as given to :meth:`set_integrator` or the constructor)."""
        return dict(self._integrator_options)

    @property
    def integrator_stats(self) -> dict:
        """The current method's counters since it was selected: ``solves``, ``cg_iterations`` /
        ``last_cg_iterations`` / ``direct_fallbacks`` (``implicit_euler``), ``factorizations``
        (``implicit_euler_prefactored``). Empty for explicit methods."""
        return dict(self._integrator.counters)

    def stiffness(self, family: str) -> np.ndarray:
        """Per-spring stiffness of a family (copy)."""
        return self._k[self.model.family == self.model.family_index(family)].copy()

    def set_stiffness(self, family: str, k: float) -> None:
        """Set every spring of ``family`` to stiffness ``k`` (N/m, ≥ 0); applies at the next
        step."""
        self._set_family(self._k, "stiffness", family, k)

    def set_damping(self, family: str, c: float) -> None:
        """Set every spring of ``family`` to damping ``c`` (N·s/m, ≥ 0); applies at the next
        step."""
        self._set_family(self._c, "damping", family, c)

    @property
    def gravity(self) -> np.ndarray:
        return self._gravity.copy()

    @gravity.setter
    def gravity(self, g) -> None:
        self._gravity = np.array(SCHEMA["gravity"].check(g), dtype=np.float64)
        self._parameters_changed("gravity")

    @property
    def wind(self):
        return None if self._wind is None else self._wind.copy()

    @wind.setter
    def wind(self, w) -> None:
        self._wind = None if w is None else _finite_vector("wind", w)
        self._parameters_changed("wind")

    @property
    def drag(self) -> float:
        return self._drag

    @drag.setter
    def drag(self, value: float) -> None:
        self._drag = SCHEMA["drag"].check(value)
        self._parameters_changed("drag")

    @property
    def strain_limit(self) -> float | None:
        return self._strain.tau

    @strain_limit.setter
    def strain_limit(self, tau: float | None) -> None:
        self._strain.set_tau(None if tau is None else SCHEMA["strain_limit"].check(tau))
        self._refresh_stages()

    @property
    def strain_limit_passes(self) -> int:
        """Most correction passes of the strain limit per step (the limit stops once a pass
        corrects nothing); fewer is faster and lets the cloth stretch more."""
        return self._strain.passes

    @strain_limit_passes.setter
    def strain_limit_passes(self, passes: int) -> None:
        passes = SCHEMA["strain_limit_passes"].check(passes)
        self._strain.passes = passes
        self._strain_options = (passes, *self._strain_options[1:])

    @property
    def strain_limit_method(self) -> str:
        """``"provot"`` or ``"projection"`` (:data:`~cloth_sim.model.STRAIN_LIMIT_METHODS`);
        live."""
        return self._strain.method

    @strain_limit_method.setter
    def strain_limit_method(self, method: str) -> None:
        method = SCHEMA["strain_limit_method"].check(method)
        self._strain.method = method  # both read the same springs and attachments
        self._strain_options = (*self._strain_options[:2], method)

    @property
    def colliders(self) -> list:
        """The colliders, in the order given (move one with :meth:`set_collider_pose`)."""
        return list(self._contacts.colliders)

    def set_collider_pose(
        self, i: int, position, orientation=(1.0, 0.0, 0.0, 0.0), teleport: bool = False
    ) -> None:
        """Move collider ``i`` to ``position`` with ``orientation`` (a unit quaternion ``(w, x, y,
        z)``; see :mod:`cloth_sim.contact.colliders` for what they mean per shape). The next step
        sweeps it there: its velocity over that step is the pose change divided by ``dt``, so
        friction drags what rests on it and nothing it meets on the way passes through. With
        ``teleport`` it is there now, at rest: the next step sees it standing at the new pose,
        drags nothing, and pushes out of it whatever it now overlaps (the ROS simulation standard's
        ``set_entity_state``). A bad index or a non-finite pose raises ``ValueError`` and moves
        nothing."""
        self._contacts.set_pose(i, position, orientation, teleport=teleport)

    def collider_wrench(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(force, torque)`` the cloth exerted on collider ``i`` over the last step: N and N·m,
        world frame, torque about its position (see
        :meth:`cloth_sim.contact.colliders.Contacts.wrench`)."""
        return self._contacts.wrench(i)

    def add_collider(self, collider) -> int:
        """Add a collider (a shape of :mod:`cloth_sim.contact.colliders`, its name not in use) from
        the next step on; returns its index in :attr:`colliders`. A bad shape or a name in use
        raises ``ValueError`` and changes nothing."""
        i = self._contacts.add(collider)
        self._refresh_stages()
        return i

    def remove_collider(self, i: int):
        """Remove collider ``i`` (the later ones move up by one); returns it. A bad index raises
        ``ValueError``."""
        c = self._contacts.remove(i)
        self._refresh_stages()
        return c

    #: a :class:`cloth_sim.motion.Motion` played as the simulator steps (a scene's scripted
    #: robot joints and gripper poses), or None
    motion = None

    # ------------------------------------------------------------------ robots
    # (add_robot, remove_robot, set_joint_positions, set_link_transforms, joint_positions,
    # link_wrench, link_pose, gripper_link: RobotMethods, over robot_placement)

    @property
    def thickness(self) -> float:
        """Distance (m) the cloth keeps from colliders and (with self-collision) from itself."""
        return self._contacts.thickness

    @thickness.setter
    def thickness(self, value: float) -> None:
        value = positive("thickness", value)
        if self._self_collision.enabled:
            check_thickness(self.model, value)
        self._contacts.thickness = self._self_collision.thickness = value

    @property
    def self_collision(self) -> bool:
        return self._self_collision.enabled

    @property
    def contact_counts(self) -> tuple[int, int]:
        """``(touching, pairs)`` of the last step: particles touching a collider, and
        self-collision's pairs within reach (0 when it is off)."""
        pairs = self._self_collision.last_pairs if self._self_collision.enabled else 0
        return int(self._contacts.last_touching), int(pairs)

    @self_collision.setter
    def self_collision(self, on: bool) -> None:
        if not isinstance(on, (bool, np.bool_)):
            raise ValueError(f"self_collision must be true or false, got {on!r}")
        self._self_collision.set_enabled(on)
        self._refresh_stages()

    @property
    def active_stages(self) -> tuple[str, ...]:
        """Names of the post-step stages that run after each step."""
        return tuple(s.name for s in self._active_stages)

    @property
    def active_terms(self) -> tuple[str, ...]:
        """Force terms the pipeline evaluates (see :mod:`cloth_sim.physics.forces`)."""
        return self.forces.active_terms

    @property
    def force_evaluations(self) -> int:
        return self.forces.evaluations + self._evaluations_before

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Take ``n`` steps of ``dt``. On divergence the state before the failing step is restored
        and :class:`SimulationDiverged` is raised."""
        state, checkpoint, dt = self.state, self._checkpoint, self._dt
        integ, forces, stages = self._integrator, self.forces, self._active_stages
        follow = integ.velocity_follow
        vmax2, xmax = self.max_speed**2, self.max_coordinate
        grippers = self._grips
        # the wrench reads the step's own end only for methods that evaluate forces past its start
        keep_end = bool(grippers) and integ.force_point > 0
        for _ in range(int(n)):
            if self.motion is not None:  # the script's joints and grippers at the step's end
                self.motion.drive(self, self.time, self.time + dt)
            state.copy_to(checkpoint)
            if grippers:
                grippers.before_step(state, integ, dt)
            integ.step(state, forces, dt)
            if keep_end:  # the step's own end, before any correction (for the wrench)
                np.copyto(self._prestage.x, state.x)
                np.copyto(self._prestage.v, state.v)
            if stages:
                origin = integ.velocity_origin(checkpoint.x, dt)
                for stage in stages:
                    stage.apply(state, checkpoint, dt, follow, origin)
            if self._contacts_inside:  # the colliders' poses this step ended at start the next
                self._contacts.end_step()
            if grippers:
                grippers.after_step(state.x)
            if not _state_ok(state.x, state.v, vmax2, xmax):
                self._diverged()
            if grippers:
                self._wrench_ready = True
                grippers.commit()
            state.steps += 1
            self.steps_taken += 1

    def advance(self, t: float) -> int:
        """Step until ``time >= t`` in whole steps; returns the number of steps taken."""
        n = max(0, math.ceil((t - self.time) / self._dt - 1e-9))
        self.step(n)
        return n

    # ------------------------------------------------------------------ diagnostics
    def energy(self) -> dict:
        """Kinetic, spring and gravitational energy (J); gravity's is ``−Σ m_i g·x_i``."""
        m = self.model.masses
        x, v = self.state.x, self.state.v
        return {
            "kinetic": 0.5 * float(np.sum(m * np.einsum("ij,ij->i", v, v))),
            "spring": self.forces.spring_energy(x),
            "gravity": -float(np.sum(m * (x @ self._gravity))),
        }

    def strains(self, limited_only: bool = False) -> np.ndarray:
        """``(l − L)/L`` per spring (every spring, or only the strain-limited ones)."""
        model = self.model
        if limited_only:
            return spring_strains(self.state.x, *self._limited)
        return spring_strains(self.state.x, model.springs, model.rest_lengths)

    def max_strain(self) -> float:
        """Largest strain over the structural and shear springs (every spring of a network)."""
        springs, rest = self._limited
        return float(max_spring_strain(self.state.x, springs, rest)) if len(springs) else 0.0

    @property
    def analysis(self) -> stab.Analysis:
        """The stability analysis of the current material (shared, computed when asked)."""
        if self._analysis is None:
            self._analysis = stab.analysis_for(self.model, self._k, self._c, self._drag)
        return self._analysis

    def fastest_mode(self) -> tuple[float, float]:
        """``(ω_max, ζ)``: the highest natural frequency of ``M⁻¹K`` over the free particles,
        linearised about the rest shape, and that mode's damping ratio (spring damping and drag);
        see :func:`cloth_sim.physics.stability.fastest_mode`."""
        return tuple(self.analysis.mode)

    def stable_dt(self) -> float:
        """Largest ``dt`` the current method is expected to survive: ``inf`` for unconditionally
        stable methods, from ω_max and its damping for the others, or the method's own analysis
        (``kang``); 0 for a method with no stable step. Computed once per material and method."""
        return self._integrator.stable_dt(self.analysis)

    def step_is_stable(self, dt: float | None = None) -> bool:
        """Whether ``dt`` (the current one by default) is a step the current method is expected to
        survive: at most :meth:`stable_dt`, or, for a method without a step limit, above the band
        of steps where Choi–Ko's onset load throws the cloth about
        (:func:`cloth_sim.physics.stability.buckling_onset_band`)."""
        return self._integrator.step_is_stable(
            self.analysis, self._dt if dt is None else float(dt)
        )

    def rest_matrices(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """``(K, C)`` linearised about the rest shape
        (:func:`cloth_sim.physics.stability.rest_matrices`)."""
        return stab.rest_matrices(self.model, self._k, self._c)

    # ------------------------------------------------------------------ grippers
    @property
    def grippers(self) -> dict:
        """``{name: indices}`` of the particles each gripper holds (see
        :mod:`cloth_sim.constraints.grippers`)."""
        return {name: g.indices.copy() for name, g in self._grips.held.items()}

    def grasp(self, name: str, point, radius: float, link=None) -> np.ndarray:
        """Hold every free particle within ``radius`` of ``point`` with a gripper called ``name``,
        placed at ``point`` with the identity orientation; returns their indices. With ``link``,
        a ``(robot, link)`` pair, the gripper is that link: placed at its pose, the held particles
        keep their offsets in its frame and follow it as the robot's joints move. A name in use,
        a bad point, radius or link, or no particle in reach raises ``ValueError`` and changes
        nothing."""
        name = self._grips.new_name(name)
        point, radius = check_grasp(point, radius)
        frame = None
        if link is not None:
            frame, bound = self.link_frame(link)
        idx = Grips.within(name, self.state.x, self.model.pinned, point, radius)
        if frame is None:
            return self._hold(name, idx, point)
        held = self._hold(name, idx, frame[0], frame[1])
        self.robot_placement.bound[name] = bound
        return held

    def grasp_box(self, name: str, lo, hi) -> np.ndarray:
        """Hold every free particle inside the axis-aligned box ``[lo, hi]`` (a whole edge of a
        cloth, say) with a gripper called ``name``, placed at the box's centre with the identity
        orientation; returns their indices. Errors as :meth:`grasp`, and a box with ``lo > hi``
        on an axis."""
        name = self._grips.new_name(name)
        lo, hi = check_box(lo, hi)
        idx = Grips.inside(name, self.state.x, self.model.pinned, lo, hi)
        return self._hold(name, idx, 0.5 * (lo + hi))

    def _hold(self, name: str, idx: np.ndarray, point: np.ndarray, orientation=None) -> np.ndarray:
        self._grips.add(name, idx, self.state.x, point, orientation)
        self._prestage = self.state.copy()
        self._wrench_ready = False
        self.state.v[idx] = 0.0  # the gripper is at rest until it is moved
        self._set_held()
        return idx.copy()

    def set_gripper_pose(
        self, name: str, position, orientation=(1.0, 0.0, 0.0, 0.0), teleport: bool = False
    ) -> None:
        """Move gripper ``name`` to ``position`` with ``orientation`` (a unit quaternion ``(w, x,
        y, z)``) over the next step: the particles it holds move with the velocity that takes them
        there. With ``teleport`` it and its particles are there now, at rest (the rest of the cloth
        follows by its springs). An unknown name or a non-finite pose raises ``ValueError``."""
        g = self._grips.aim(name, position, orientation, teleport)
        if g is None:
            return
        self.state.x[g.indices] = g.places(g.position, g.rotation)
        self.state.v[g.indices] = 0.0
        self._integrator.pins_moved(self.state)

    def gripper_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(position, orientation)`` of gripper ``name`` now."""
        g = self._grips.get(name)
        return g.position.copy(), g.orientation.copy()

    def gripper_wrench(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(force, torque)`` the cloth exerts on gripper ``name`` at the end of the last step:
        the springs' pull on the particles it holds, plus the strain limit's constraint force on
        them when it is on (N), and its moment about the gripper's position (N·m), world frame (see
        :mod:`cloth_sim.constraints.grippers`)."""
        g = self._grips.get(name)
        term = self.forces.spring_term
        f = np.zeros_like(self.state.x)
        if term is not None and term.active:
            # the springs where the step evaluated them: at its start (the checkpoint), at its end
            # before the corrections, or between (integrators' force_point); the current state
            # before any step
            theta = self._integrator.force_point if self._wrench_ready else 1.0
            ends = (
                (1.0 - theta, self._checkpoint),
                (theta, self._prestage if self._wrench_ready else self.state),
            )
            for weight, st in ends:
                if weight:
                    part = np.zeros_like(f)
                    term.add_force(st.x, st.v, part)
                    f += weight * part
        fi = f[g.indices]
        if self._strain.active and self._strain.reaction is not None:
            fi = fi + self._strain.reaction[g.indices]
        return fi.sum(axis=0), np.cross(self.state.x[g.indices] - g.position, fi).sum(axis=0)

    def release(self, name: str) -> np.ndarray:
        """Let go: the particles of gripper ``name`` move freely again, with the velocity the
        gripper gave them over the last step. Returns their indices."""
        g = self._grips.get(name)
        del self._grips.held[name]
        self.robot_placement.bound.pop(name, None)
        self._set_held()
        return g.indices.copy()

    def _set_held(self) -> None:
        """The model with the scene's pins and every held particle pinned; everything built from
        the model is rebuilt around the same state and parameters."""
        mask = self._grips.pinned(self.base_model.pinned)
        if np.array_equal(mask, self.model.pinned):
            return
        model = (
            self.base_model
            if np.array_equal(mask, self.base_model.pinned)
            else dataclasses.replace(self.base_model, pinned=mask)
        )
        self.model = model
        self._evaluations_before += self.forces.evaluations
        self.forces = self._build_forces()
        self._contacts.set_pinned(model.pinned)
        self._build_stages(model, self._strain.tau, self._self_collision.enabled)
        self._strain.track_reaction = bool(self._grips)
        self._analysis = None
        self._integrator = integrators.get(self.integrator)(model, **self._integrator_options)
        self._integrator.reset(self.state, self.forces, self._dt)
        self._refresh_stages()

    _prestage = None
    #: whether a step was taken since the grippers changed (the wrench reads its states)
    _wrench_ready = False

    # ------------------------------------------------------------------ internals
    def _build_stages(self, model, tau, self_collision: bool) -> None:
        """The post-step stages for ``model`` (the contact stage, which holds the colliders' poses,
        is kept and only told the pins)."""
        self._strain = StrainLimit(model, tau, *self._strain_options)
        self._self_collision = SelfCollision(model, self._contacts.thickness, self_collision)
        self._self_collision.clearance = self._contacts.clearance
        #: the post-step stages, in order; only the active ones run. Self-collision is last: its
        #: no-crossing guarantee is about the motion every other stage has shaped.
        self.stages = [self._strain, self._contacts, self._self_collision]
        self._refresh_stages()

    def _refresh_stages(self) -> None:
        """The stages that run after each step: the active ones the integrator does not resolve
        inside its own step (:attr:`~cloth_sim.integrators.base.Integrator.handles`), which it is
        given (:meth:`~cloth_sim.integrators.base.Integrator.attach`)."""
        integ = self._integrator
        handled = integ.handles if integ is not None else frozenset()
        self._active_stages = [s for s in self.stages if s.active and s.name not in handled]
        if "self_collision" in handled and self._self_collision.active:
            # the contact stage's finish after a method that kept the cloth uncrossed must not
            # push a vertex through the layer beside it
            self._active_stages = [
                Uncrossed(s, self._self_collision) if s is self._contacts else s
                for s in self._active_stages
            ]
        self._contacts_inside = "contacts" in handled and self._contacts.active
        self._contacts.continuous = integ is None or not integ.keeps_paths_off_colliders
        if integ is not None:
            integ.attach(self._contacts, self._self_collision, self._strain)

    def _build_forces(self) -> Forces:
        return Forces(self.model, self._k, self._c, self._gravity, self._wind, self._drag)

    def _parameters_changed(self, what: str) -> None:
        self._evaluations_before += self.forces.evaluations
        self.forces = self._build_forces()
        if what in ("stiffness", "damping", "drag"):
            self._analysis = None
        self._integrator.parameters_changed(frozenset({what}))

    def _set_family(self, arr, what, family, value):
        fi = self.model.family_index(family)
        spec = SCHEMA.get(f"{what}.{family}", SCHEMA[f"{what}.structural"])
        arr[self.model.family == fi] = spec.check(value, field=f"{what}.{family}")
        self._parameters_changed(what)

    def _diverged(self):
        bad_t = self.time + self._dt
        self._checkpoint.copy_to(self.state)
        limit = self._integrator.known_stable_dt(self.analysis)
        estimate = (
            "not computed (stable_dt() computes it)"
            if limit is None
            else f"stable_dt()={limit:.4g} s"
        )
        raise SimulationDiverged(
            f"the {self.integrator} step from t={self.time:.6g} s to t={bad_t:.6g} s diverged "
            f"(non-finite value, speed above {self.max_speed:g} m/s or coordinate above "
            f"{self.max_coordinate:g} m) with dt={self._dt:g} s; the stable limit estimate is "
            f"{estimate}. The state before that step was restored."
        )

    def _check_state(self, name, a):
        a = np.asarray(a, dtype=np.float64)
        if a.shape != self.state.x.shape:
            raise ValueError(f"{name} must have shape {self.state.x.shape}, got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite")
        return a


__all__ = ["ParameterError", "SimulationDiverged", "Simulator"]

keep_true(__name__)  # (its kernels compile again when a file it imports changes)
