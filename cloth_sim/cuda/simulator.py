""":class:`cloth_sim.Simulator`'s and :class:`cloth_sim.BatchSimulator`'s faces on the CUDA device.

``Simulator(model, integrator="vbd", dt=1/60, device="cuda")`` is a :class:`CudaSimulator`: one
world of :class:`~cloth_sim.cuda.worlds.CudaWorlds`, with the CPU simulator's names for what it
has. The state lives on the device; :attr:`CudaSimulator.positions` copies it to the host when
asked, once a step (the node's publish asks once a tick). Asked for something the device does not
run yet (:func:`cloth_sim.backends.refusal`), it raises ``ValueError`` naming the argument.
"""

from __future__ import annotations

import math

import numpy as np
from numba import cuda

from .. import backends, integrators
from ..backends import models_of
from ..constraints.grippers import Grips, check_box, check_grasp
from ..contact.colliders import check_index, check_new
from ..model import ClothModel
from ..parameters import SCHEMA
from ..physics import stability as stab
from ..physics.forces import Forces
from ..robot.placement import RobotMethods, Robots
from ..state import SimulationDiverged, State
from .worlds import CudaWorlds

#: :class:`cloth_sim.Simulator`'s arguments for the stages (the strain limit's, the thickness
#: contacts keep)
_STAGES = (
    "strain_limit",
    "strain_limit_passes",
    "strain_limit_long_range",
    "strain_limit_method",
    "thickness",
)


def robots_refused(integrator: str) -> ValueError:
    """The error for a robot under a method other than symplectic Euler on the device."""
    return ValueError(
        f"robot: a robot's links under {integrator} are not on the cuda device yet (they sweep "
        "over each step, which the device's vbd does not take yet; symplectic_euler sweeps "
        "them); device='cpu' runs robots under every method"
    )


def projection_refused(integrator: str, model: ClothModel) -> ValueError:
    """The error for a strain limit by projection on the device (Provot's passes run there)."""
    return ValueError(backends.refusal("cuda", integrator, model, strain_limit_method=True)[0])


class CudaSimulator(RobotMethods):
    """One cloth on the CUDA device (see the module docstring); ``precision`` ``"float32"``
    (default) or ``"float64"``."""

    device = "cuda"

    def __init__(
        self,
        model: ClothModel,
        integrator: str = "symplectic_euler",
        dt: float = 1e-3,
        gravity=(0.0, 0.0, -9.81),
        wind=None,
        drag: float = 0.0,
        max_speed: float = 1e3,
        max_coordinate: float = 1e6,
        integrator_options: dict | None = None,
        precision: str = "float32",
        launch: str = "auto",
        block_threads: int | None = None,
        **cpu_only,
    ):
        unknown = sorted(set(cpu_only) - {"colliders", "self_collision"} - set(_STAGES))
        if unknown:
            raise TypeError(f"unexpected argument(s) {', '.join(unknown)}")
        colliders = list(cpu_only.get("colliders") or ())
        tau = cpu_only.get("strain_limit")
        limit_method = SCHEMA["strain_limit_method"].check(
            cpu_only.get("strain_limit_method", "provot")
        )
        refused = backends.refusal(
            "cuda",
            integrator,
            model,
            strain_limit_method=tau is not None and limit_method != "provot",
            self_collision=bool(cpu_only.get("self_collision")),
        )
        if refused is not None:
            raise ValueError(refused[0])
        self.model = model
        self._gravity = np.asarray(gravity, np.float64)
        self._wind = None if wind is None else np.asarray(wind, np.float64)
        self._drag = float(drag)
        self.max_speed, self.max_coordinate = float(max_speed), float(max_coordinate)
        self.thickness = float(cpu_only.get("thickness", 0.005))
        self.motion = None
        self._worlds = CudaWorlds(
            [model],
            integrator,
            dt,
            gravity,
            wind,
            drag,
            integrator_options,
            precision,
            launch,
            block_threads,
            colliders,
            self.thickness,
        )
        self._worlds.set_strain_limit(
            tau,
            cpu_only.get("strain_limit_passes"),
            cpu_only.get("strain_limit_long_range", True),
        )
        self._strain_method = limit_method
        self._colliders = colliders
        self._k = np.array(model.stiffness, dtype=np.float64)
        self._c = np.array(model.damping, dtype=np.float64)
        self._t_base = 0.0
        self._checkpoint = None
        self._host = None  # the positions and velocities copied at the last ask
        self.steps_taken = 0
        self._counters = dict(steps=0)
        self._forces = None
        self._analysis = None
        self._grips = Grips()
        self._swept = False  # a collider's pose was set to be swept over the next step
        self._worlds.record_wrenches()
        self.robot_placement = Robots(
            self.add_collider,
            self._place_colliders,
            self.remove_collider,
            lambda: self._colliders,
            self.set_gripper_pose,
        )

    # ------------------------------------------------------------------ state
    def _copy(self):
        if self._host is None:
            w = self._worlds
            self._host = (w.positions_host()[0], w.velocities_host()[0])
            for a in self._host:
                a.setflags(write=False)
        return self._host

    @property
    def positions(self) -> np.ndarray:
        """``(n, 3)`` positions, copied from the device (once a step; read-only)."""
        return self._copy()[0]

    @positions.setter
    def positions(self, x) -> None:
        self._worlds.write([0], x=self._checked("positions", x)[None])
        self._host = None

    @property
    def velocities(self) -> np.ndarray:
        return self._copy()[1]

    @velocities.setter
    def velocities(self, v) -> None:
        v = self._checked("velocities", v).copy()
        v[self.model.pinned] = 0.0
        self._worlds.write([0], v=v[None])
        self._host = None

    @property
    def device_positions(self):
        """The ``(n, 3)`` positions on the device (``__cuda_array_interface__``), no copy."""
        return self._worlds.positions[0]

    def _checked(self, name, a) -> np.ndarray:
        a = np.asarray(a, np.float64)
        if a.shape != (self.model.n_particles, 3) or not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite with shape ({self.model.n_particles}, 3)")
        return a

    def move_pins(self, positions, indices=None) -> None:
        pinned = np.flatnonzero(self.model.pinned)
        idx = pinned if indices is None else np.asarray(indices, np.int64).ravel()
        if not np.all(self.model.pinned[idx]):
            raise ValueError(
                f"move_pins: every index must be a pinned particle; pinned are {pinned.tolist()}"
            )
        self._worlds.place([0], idx, positions)
        self._host = None

    @property
    def time(self) -> float:
        return self._t_base + int(self._worlds.steps[0]) * self._worlds.dt

    def set_time(self, t: float) -> None:
        t = float(t)
        if not (math.isfinite(t) and t >= 0):
            raise ValueError(f"time must be a finite number >= 0, got {t!r}")
        self._t_base, self._worlds.steps[0] = t, 0

    def reset(self) -> None:
        """Back to the model's initial positions, at rest, at time 0; parameters are kept, every
        gripper is released."""
        if self._grips:
            self._grips.held.clear()
            self.robot_placement.bound.clear()
            self._worlds.release([0])
            self._worlds.restart([0])
        self._worlds.reset([0])
        self._t_base = 0.0
        self._host = None

    def save_state(self) -> State:
        x, v = self._copy()
        saved = State(x, v)
        saved.t_base, saved.method = self.time, self.integrator
        return saved

    def restore_state(self, saved: State) -> None:
        """As the CPU's: the saved positions, velocities and time; held vertices stay with their
        grippers, at rest."""
        self._worlds.write([0], x=saved.x[None], v=saved.v[None])
        self.set_time(saved.time(self.dt))
        if self._grips:
            for g in self._grips.held.values():
                self._worlds.place([0], g.indices, g.places(g.position, g.rotation))
                g.moving, g.target = False, None
            self._worlds.restart([0])
        self._host = None

    # ------------------------------------------------------------------ parameters
    @property
    def dt(self) -> float:
        return self._worlds.dt

    @dt.setter
    def dt(self, value: float) -> None:
        t = self.time
        self._worlds.dt = SCHEMA["dt"].check(value)
        self.set_time(t)

    @property
    def integrator(self) -> str:
        return self._worlds.method

    @property
    def launch_mode(self) -> str:
        """How a run of steps is launched (:meth:`CudaWorlds.launch_mode`)."""
        return self._worlds.launch_mode()

    @property
    def integrator_options(self) -> dict:
        return dict(self._worlds.options)

    def set_integrator(self, name: str, **options) -> None:
        """Switch method on the device; positions and velocities carry over. A robot's links
        sweep over each step, which only symplectic Euler takes here (:meth:`add_robot`): with a
        robot in the scene another method raises ``ValueError`` and nothing changes."""
        if self.robot_placement.placed and not backends.sweeps_colliders("cuda", name):
            raise robots_refused(name)
        self._rebuild(name, options, self._colliders)
        self._counters = dict(steps=0)

    def _rebuild(self, method: str, options: dict, colliders: list) -> None:
        """The worlds made again for ``method`` and ``colliders``, the state, time, material and
        grippers carried over (a new method, a collider added or removed): the held vertices stay
        held where they are, at rest, and a collider set to be swept over the next step stands
        at its new pose."""
        x, v = self._copy()
        t = self.time
        old = self._worlds
        new = CudaWorlds(
            [self.model],
            method,
            self.dt,
            self._gravity,
            self._wind,
            self._drag,
            options,
            old.precision,
            old.launch,
            old.block_threads,
            colliders,
            self.thickness,
        )
        new.set_strain_limit(
            old.strain_limit, old.strain_limit_passes, old.strain_limit_long_range
        )
        new.record_wrenches()
        self._worlds = new
        self._colliders = colliders
        self._swept = False
        self._apply_families()
        self._worlds.write([0], x=x[None], v=v[None])
        for g in self._grips.held.values():
            new.hold([0], g.indices, x[g.indices])
            g.moving = False
        self.set_time(t)
        self._host = None

    @property
    def integrator_stats(self) -> dict:
        w = self._worlds
        out = dict(self._counters, launches=w.launches, last_launches=w.last_launches)
        if w.settings is not None:
            res = float(w.last_residual[0])
            out.update(
                iterations=int(w.iterations[0]),
                unconverged_steps=int(w.unconverged_steps[0]),
                last_iterations=w.last_iterations,
                last_residual=res,
                converged=bool(res <= w.settings.tolerance),
                tolerance=w.settings.tolerance,
                last_substeps=w.last_substeps,
            )
        return out

    @property
    def gravity(self) -> np.ndarray:
        return self._gravity.copy()

    @gravity.setter
    def gravity(self, g) -> None:
        self._worlds.set([0], gravity=g)
        self._gravity = np.asarray(g, np.float64)
        self._forces = None

    @property
    def wind(self):
        return None if self._wind is None else self._wind.copy()

    @wind.setter
    def wind(self, w) -> None:
        self._worlds.set([0], wind=np.zeros(3) if w is None else w)
        self._wind = None if w is None else np.asarray(w, np.float64)
        self._forces = None

    @property
    def drag(self) -> float:
        return self._drag

    @drag.setter
    def drag(self, value: float) -> None:
        self._worlds.set([0], drag=value)
        self._drag = float(value)
        self._forces = None
        self._analysis = None

    def stiffness(self, family: str) -> np.ndarray:
        return self._k[self.model.family == self.model.family_index(family)].copy()

    def set_stiffness(self, family: str, k: float) -> None:
        self._worlds.set([0], stiffness={family: k})
        self._k[self.model.family == self.model.family_index(family)] = float(k)
        self._forces = None
        self._analysis = None

    def set_damping(self, family: str, c: float) -> None:
        self._worlds.set([0], damping={family: c})
        self._c[self.model.family == self.model.family_index(family)] = float(c)
        self._forces = None
        self._analysis = None

    def _apply_families(self) -> None:
        m = self.model
        for f, name in enumerate(m.family_names):
            sel = m.family == f
            if not sel.any():
                continue
            k, c = self._k[sel], self._c[sel]
            if np.any(k != m.stiffness[sel]) and np.all(k == k[0]):
                self._worlds.set([0], stiffness={name: k[0]})
            if np.any(c != m.damping[sel]) and np.all(c == c[0]):
                self._worlds.set([0], damping={name: c[0]})

    @property
    def forces(self) -> Forces:
        """The same forces on the host (the terms the device steps), for what reads them between
        steps: the node's energy balance (the wind's and the pins' power)."""
        if self._forces is None:
            self._forces = Forces(
                self.model, self._k, self._c, self._gravity, self._wind, self._drag
            )
        return self._forces

    # what the device does not have (refused at construction): empty, as the CPU reports it when
    # none is there
    @property
    def colliders(self) -> list:
        """The static colliders the cloth keeps ``thickness`` from (planes, spheres, boxes,
        capsules and cylinders on the device)."""
        return list(self._colliders)

    def set_collider_pose(
        self, i, position, orientation=(1.0, 0.0, 0.0, 0.0), teleport: bool = False
    ) -> None:
        """As the CPU's: swept there over the next step under symplectic Euler (the contact
        stage carries the cloth's path with the collider and friction drags what it carries), or
        with ``teleport`` there now, at rest. Under ``vbd`` a swept move is not on the device yet
        (its substeps and bounds would take the motion in parts): refused, nothing moved."""
        if not teleport and not self.sweeps_colliders:
            raise ValueError(
                f"set_collider_pose: a collider's swept motion under {self.integrator} is not on "
                "the cuda device yet (symplectic_euler sweeps it; teleport=True puts it there at "
                "rest); device='cpu' sweeps it"
            )
        check_index(i, len(self._colliders), "move")
        collider = self._colliders[i]
        collider.set_pose(position, orientation)  # (checked: a bad pose moves nothing)
        self._place_colliders([(collider, None)], teleport)

    @property
    def sweeps_colliders(self) -> bool:
        """Whether :meth:`set_collider_pose` sweeps a collider over the next step here (under
        symplectic Euler; under ``vbd`` a pose is placed by teleport only)."""
        return backends.sweeps_colliders("cuda", self.integrator)

    def add_collider(self, collider) -> int:
        """As :meth:`cloth_sim.Simulator.add_collider` (a mesh read from its distance grid,
        :mod:`cloth_sim.contact.distance_grid`); it stands where it is added. Something not a
        collider or a name in use raises ``ValueError`` and changes nothing."""
        check_new(collider, self._colliders)
        self._rebuild(self.integrator, self._worlds.options, [*self._colliders, collider])
        return len(self._colliders) - 1

    def remove_collider(self, i: int):
        """Remove collider ``i`` (the later ones move up by one); returns it. A bad index raises
        ``ValueError``."""
        check_index(i, len(self._colliders), "remove")
        kept = list(self._colliders)
        gone = kept.pop(i)
        self._rebuild(self.integrator, self._worlds.options, kept)
        return gone

    def collider_wrench(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`cloth_sim.Simulator.collider_wrench`: the impulses the last step's contact
        stage took from the vertices touching collider ``i`` (recorded on the device, summed on
        the host), over its step (under ``vbd``, its last substep's: the device's stage runs
        after each)."""
        check_index(i, len(self._colliders), "read")
        w = self._worlds
        h = self.dt if self.integrator == "symplectic_euler" else self.dt / w.last_substeps
        return w.collider_wrench(0, int(i) % len(self._colliders), h)

    def robot_refusal(self) -> ValueError | None:
        """A robot's links are colliders on the device (a mesh read from its distance grid),
        swept over each step by symplectic Euler's contact stage as the joints move; under
        ``vbd`` the device sweeps no collider yet: the error naming it."""
        return None if self.sweeps_colliders else robots_refused(self.integrator)

    def _place_colliders(self, placements, teleport: bool = False) -> None:
        """``[(collider, 4×4 transform)]`` from a robot's kinematics (the CPU's
        :meth:`~cloth_sim.contact.colliders.Contacts.place`): each collider object placed (the
        transform None: where it stands), and on the device swept there over the next step or,
        with ``teleport``, there now."""
        index = {id(c): i for i, c in enumerate(self._colliders)}
        rows = []
        for collider, transform in placements:
            if transform is not None:  # (None: placed already, set_collider_pose)
                collider.place(transform)
            rows.append((index[id(collider)], collider.position, collider.rotation))
        self._worlds.place_colliders([0], rows, teleport)
        self._swept = self._swept or not teleport

    # ------------------------------------------------------------------ grippers
    @property
    def grippers(self) -> dict:
        """``{name: indices}`` of the vertices each gripper holds (as the CPU's)."""
        return {name: g.indices.copy() for name, g in self._grips.held.items()}

    def grasp(self, name: str, point, radius: float, link=None) -> np.ndarray:
        """As :meth:`cloth_sim.Simulator.grasp`: every free vertex within ``radius`` of ``point``
        held by a gripper ``name`` there; on the device they leave the solve and move with it
        (:meth:`set_gripper_pose`), or with ``link`` (a ``(robot, link)`` pair) they follow that
        link. A name in use, a bad point, radius or link and no vertex in reach raise
        ``ValueError``, nothing changed."""
        name = self._grips.new_name(name)
        point, radius = check_grasp(point, radius)
        frame = bound = None
        if link is not None:
            frame, bound = self.link_frame(link)
        idx = Grips.within(name, self.positions, self._held_mask(), point, radius)
        if frame is None:
            return self._hold(name, idx, point)
        held = self._hold(name, idx, frame[0], frame[1])
        self.robot_placement.bound[name] = bound
        return held

    def grasp_box(self, name: str, lo, hi) -> np.ndarray:
        """As :meth:`cloth_sim.Simulator.grasp_box`: every free vertex inside ``[lo, hi]``."""
        name = self._grips.new_name(name)
        lo, hi = check_box(lo, hi)
        idx = Grips.inside(name, self.positions, self._held_mask(), lo, hi)
        return self._hold(name, idx, 0.5 * (lo + hi))

    def _held_mask(self) -> np.ndarray:
        """The vertices the solve does not move: the model's pins and every held one."""
        mask = np.zeros(self.model.n_particles, bool)
        mask[self._worlds.held(0)] = True
        return mask

    def _hold(self, name: str, idx: np.ndarray, point: np.ndarray, orientation=None) -> np.ndarray:
        """Gripper ``name`` at ``point`` (turned by ``orientation``: a link's) holding ``idx``
        where they are, at rest; the method starts again around the new pins, as the CPU's is
        made anew."""
        self._grips.add(name, idx, np.array(self.positions), point, orientation)
        self._worlds.hold([0], idx)
        self._worlds.restart([0])
        self._host = None
        return idx.copy()

    def set_gripper_pose(
        self, name: str, position, orientation=(1.0, 0.0, 0.0, 0.0), teleport: bool = False
    ) -> None:
        """As :meth:`cloth_sim.Simulator.set_gripper_pose`: reached over the next step (the held
        vertices move with the velocity that takes them there, and end there exactly), or with
        ``teleport`` there now, at rest. An unknown name or a bad pose raises ``ValueError``."""
        g = self._grips.aim(name, position, orientation, teleport)
        if g is None:
            return
        self._worlds.place([0], g.indices, g.places(g.position, g.rotation))
        self._host = None

    def gripper_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(position, orientation)`` of gripper ``name`` now."""
        g = self._grips.get(name)
        return g.position.copy(), g.orientation.copy()

    def gripper_wrench(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(force, torque)`` the cloth's springs exert on the vertices gripper ``name`` holds,
        at the end of the last step (the CPU's for ``vbd``, which evaluates them there, before
        the strain limit's last correction; the CPU's symplectic Euler reads them at the step's
        start), plus the strain limit's force on them over the last step when it is on (as the
        CPU's), torque about the gripper's position; world frame, from the state copied to the
        host."""
        g = self._grips.get(name)
        x, v = self._copy()
        # under vbd with the limit, the springs where the CPU's reads them: the last substep
        # solved, before the limit's last correction (its stage)
        xs, vs = self._worlds.before_limit(0) or (x, v)
        f = np.zeros_like(x)
        term = self.forces.spring_term
        if term is not None and term.active:
            term.add_force(xs, vs, f)
        fi = f[g.indices] + self._worlds.limit_reaction(0)[g.indices]
        return fi.sum(axis=0), np.cross(x[g.indices] - g.position, fi).sum(axis=0)

    def release(self, name: str) -> np.ndarray:
        """Let go: the vertices of gripper ``name`` move freely again, with the velocity it gave
        them over the last step; returns their indices."""
        g = self._grips.get(name)
        del self._grips.held[name]
        self.robot_placement.bound.pop(name, None)
        self._worlds.release([0], g.indices)
        self._worlds.restart([0])
        self._host = None
        return g.indices.copy()

    def _moving(self) -> bool:
        """Whether a gripper moves over the next step or moved over the last, or a collider is
        swept over the next."""
        return self._swept or any(
            g.target is not None or g.moving for g in self._grips.held.values()
        )

    def _step_holding(self, n: int) -> None:
        """``n`` steps with grippers or colliders that move: the first carries each moving
        gripper's vertices to its target (velocity to it, then exactly there), stops those of a
        gripper that moved over the step before and sweeps the colliders set moving; the rest run
        as one, the colliders standing where the first left them."""
        w, dt = self._worlds, self.dt
        self._host = None  # (a step of this call may have moved them since the last copy)
        x = self.positions  # (the held vertices: where the last step put them)
        moved = {}
        for name, g in self._grips.held.items():
            here = x[g.indices]
            if g.target is not None:
                g.goal = g.places(g.target[0], g.target[2])
                moved[name] = (g.goal - here) / dt
                w.carry([0], g.indices, here, moved[name])
            elif g.moving:
                w.carry([0], g.indices, here, np.zeros_like(here))
        w.step(1)
        if self._swept:
            w.settle_colliders()
            self._swept = False
        for name, g in self._grips.held.items():
            if name in moved:
                w.carry([0], g.indices, g.goal, moved[name])
            g.moving = g.target is not None
            if g.target is not None:
                g.position, g.orientation, g.rotation = g.target
                g.target = None
        if n > 1:
            for g in self._grips.held.values():
                if g.moving:
                    here = g.goal
                    w.carry([0], g.indices, here, np.zeros_like(here))
                    g.moving = False
            w.step(n - 1)
        self._host = None

    @property
    def self_collision(self) -> bool:
        return False

    @property
    def strain_limit(self) -> float | None:
        """Provot's ``τc`` after each step (symplectic Euler) or substep (``vbd``), None for none,
        as the CPU's; refused with the projection method."""
        return self._worlds.strain_limit

    @strain_limit.setter
    def strain_limit(self, tau) -> None:
        if tau is not None and self._strain_method != "provot":
            raise projection_refused(self.integrator, self.model)
        self._worlds.set_strain_limit(tau)

    @property
    def strain_limit_passes(self) -> int:
        return self._worlds.strain_limit_passes

    @strain_limit_passes.setter
    def strain_limit_passes(self, passes: int) -> None:
        self._worlds.set_strain_limit(self._worlds.strain_limit, passes)

    @property
    def strain_limit_method(self) -> str:
        """``"provot"`` (the device's); ``"projection"`` is kept while the limit is off and
        refused while it is on."""
        return self._strain_method

    @strain_limit_method.setter
    def strain_limit_method(self, method: str) -> None:
        method = SCHEMA["strain_limit_method"].check(method)
        if method != "provot" and self.strain_limit is not None:
            raise projection_refused(self.integrator, self.model)
        self._strain_method = method

    @property
    def active_stages(self) -> tuple[str, ...]:
        return ("strain_limit",) if self.strain_limit is not None else ()

    @property
    def active_terms(self) -> tuple[str, ...]:
        return self.forces.active_terms

    @property
    def contact_counts(self) -> tuple[int, int]:
        return 0, 0

    # ------------------------------------------------------------------ the method's analysis
    @property
    def analysis(self) -> stab.Analysis:
        """The stability analysis of the current material (the CPU's, on the host)."""
        if self._analysis is None:
            self._analysis = stab.analysis_for(self.model, self._k, self._c, self._drag)
        return self._analysis

    def stable_dt(self) -> float:
        """As :meth:`cloth_sim.simulator.Simulator.stable_dt`, for the method run here."""
        return integrators.get(self.integrator)(self.model).stable_dt(self.analysis)

    def step_is_stable(self, dt: float | None = None) -> bool:
        method = integrators.get(self.integrator)(self.model)
        return method.step_is_stable(self.analysis, self.dt if dt is None else float(dt))

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """``n`` steps of ``dt``; then the state is checked once (copied to the host: NaN, inf,
        or past ``max_speed`` / ``max_coordinate``), and on divergence the state before these
        ``n`` steps is restored and :class:`~cloth_sim.simulator.SimulationDiverged` raised."""
        w = self._worlds
        it = w.it
        if self._checkpoint is None:
            self._checkpoint = (cuda.device_array_like(it.x), cuda.device_array_like(it.v))
        self._checkpoint[0].copy_to_device(it.x)
        self._checkpoint[1].copy_to_device(it.v)
        steps_before = int(w.steps[0])
        grips = {
            name: (g.position, g.orientation, g.rotation, g.target, g.moving)
            for name, g in self._grips.held.items()
        }
        if self.motion is not None:  # the script's gripper poses before each step, as the CPU
            for _ in range(int(n)):
                self.motion.drive(self, self.time, self.time + self.dt)
                if self._moving():
                    self._step_holding(1)
                else:
                    w.step(1)
        elif n > 0 and self._moving():
            self._step_holding(int(n))
        else:
            w.step(n)
        self._counters["steps"] += int(n)
        self._host = None
        x, v = self._copy()
        if not (
            np.all(np.isfinite(x))
            and np.all(np.isfinite(v))
            and float(np.max(np.einsum("ij,ij->i", v, v), initial=0.0)) <= self.max_speed**2
            and float(np.max(np.abs(x), initial=0.0)) <= self.max_coordinate
        ):
            it.x.copy_to_device(self._checkpoint[0])
            it.v.copy_to_device(self._checkpoint[1])
            for name, (p, q, r, target, moving) in grips.items():  # where they were
                g = self._grips.held[name]
                g.position, g.orientation, g.rotation, g.target, g.moving = p, q, r, target, moving
            w.forget()
            w.steps[0] = steps_before
            self._host = None
            raise SimulationDiverged(
                f"the state left its bounds within {int(n)} step(s) of dt={self.dt} on the cuda "
                "device; the state before them is restored"
            )
        self.steps_taken += int(n)

    def advance(self, t: float) -> int:
        n = max(0, math.ceil((t - self.time) / self.dt - 1e-9))
        self.step(n)
        return n

    # ------------------------------------------------------------------ diagnostics
    def energy(self) -> dict:
        """Kinetic, spring (Hooke's, and the material's bending) and gravitational energy (J),
        from the positions copied to the host."""
        x, v = self._copy()
        m = self.model
        kinetic = 0.5 * float(np.sum(m.masses * np.einsum("ij,ij->i", v, v)))
        d = x[m.springs[:, 1]] - x[m.springs[:, 0]]
        stretch = np.linalg.norm(d, axis=1) - m.rest_lengths
        spring = 0.5 * float(np.sum(self._k * stretch * stretch))
        if m.bending is not None:
            spring += m.bending.energy(x)
        gravity = -float(np.sum(m.masses * (x @ self._gravity)))
        return {"kinetic": kinetic, "spring": spring, "gravity": gravity}

    def strains(self, limited_only: bool = False) -> np.ndarray:
        x, _ = self._copy()
        m = self.model
        sel = m.strain_limited if limited_only else slice(None)
        d = x[m.springs[sel, 1]] - x[m.springs[sel, 0]]
        return np.linalg.norm(d, axis=1) / m.rest_lengths[sel] - 1.0

    def max_strain(self) -> float:
        s = self.strains()
        return float(s.max()) if len(s) else 0.0


class CudaBatchSimulator(CudaWorlds):
    """:class:`cloth_sim.BatchSimulator` on the CUDA device: ``worlds`` copies of ``model`` (or a
    list of models of one topology), stepped in the same launches; :meth:`set` and
    :meth:`reset` take world indices."""

    device = "cuda"

    def __init__(
        self,
        models,
        worlds: int | None = None,
        integrator: str = "vbd",
        dt: float = 1 / 60,
        strain_limit: float | None = None,
        strain_limit_passes: int | None = None,
        strain_limit_long_range: bool = True,
        strain_limit_method: str = "provot",
        **kwargs,
    ):
        models = models_of(models, worlds)
        method = SCHEMA["strain_limit_method"].check(strain_limit_method)
        if strain_limit is not None and method != "provot":
            raise projection_refused(integrator, models[0])
        super().__init__(models, integrator, dt, **kwargs)
        self.set_strain_limit(strain_limit, strain_limit_passes, strain_limit_long_range)

    @property
    def time(self) -> np.ndarray:
        """Each world's simulated time (s)."""
        return self.times()

    def advance(self, t: float) -> int:
        """Step every world until the first world's time reaches ``t``; the steps taken."""
        n = max(0, math.ceil((t - float(self.times().min())) / self.dt - 1e-9))
        self.step(n)
        return n

    @property
    def integrator_stats(self) -> dict:
        out = dict(launches=self.launches, last_launches=self.last_launches)
        if self.settings is not None:
            out.update(
                last_iterations=self.last_iterations,
                last_residual=self.last_residual.copy(),
                tolerance=self.settings.tolerance,
                last_substeps=self.last_substeps,
            )
        return out
