"""One schema for every quantity a user can set: name, type, unit, range, description, how it
applies.

Scene files (:mod:`cloth_sim.scene`), the model and simulator
(:class:`~cloth_sim.model.ClothModel`, :class:`~cloth_sim.simulator.Simulator`), the ``cloth-sim``
command line and the ROS node's parameter descriptors and checks (:mod:`cloth_sim.ros.params`) all
read their bounds from :data:`SCHEMA`, so a quantity has one range everywhere. :meth:`Param.check`
turns a value into its canonical form or raises :class:`ParameterError`, whose message names the
parameter, the value and what is accepted.

``apply`` says what a change does: ``live`` (the running simulation takes it and keeps its state),
``rebuild`` (the cloth is rebuilt from the scene and reset) or ``node`` (the node's own settings).

To add a parameter: one :class:`Param` here (``scene_key`` if scene files may set it; for a live
value ``simulator``, the :class:`~cloth_sim.simulator.Simulator` option it feeds, which
:mod:`cloth_sim.simulator_options` reads to build and change simulators), then the code that uses
it (the ``Simulator`` property for a live value, ``Scene.build_model`` for a rebuild one).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from .kinds import DEVICES, GRID_FAMILIES, INTEGRATORS, MODELS, STRAIN_LIMIT_METHODS
from .materials.library import LIBRARY

#: the library's fabric names (the material parameter's choices)
MATERIAL_NAMES = tuple(sorted(LIBRARY))

#: vector parameter types and their lengths
VECTORS = {"vector2": 2, "vector3": 3}
VECTOR_NAMES = {2: "[width, height]", 3: "[x, y, z]"}

#: The largest grid side anywhere (scene files, the node, ``ClothModel.grid``).
MAX_GRID = 512


class ParameterError(ValueError):
    """A value outside its parameter's accepted set; the message names both."""

    def __init__(self, name: str, value, accepted: str, message: str | None = None):
        self.name, self.value, self.accepted = name, value, accepted
        super().__init__(
            message or f"{name} = {_show(value)} is not accepted: expected {accepted}"
        )


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _num(x: float) -> str:
    return f"{x:g}"


@dataclass(frozen=True)
class Param:
    """One user-settable quantity.

    ``type`` is ``float``, ``int``, ``bool``, ``str``, ``"vector2"`` or ``"vector3"`` (two or
    three floats). Numbers and vector components lie in ``[lo, hi]`` (``(lo, hi]`` with
    ``lo_open``); strings in ``choices`` when given, and non-empty when ``nonempty``.
    ``scene_key`` is the field's path in a scene file (``grid.rows``), ``None`` for parameters only
    the node has. ``simulator`` is the :class:`~cloth_sim.simulator.Simulator` option the value
    feeds (its keyword and settable attribute; several values may feed one, as wind's strength and
    direction feed ``wind``): :mod:`cloth_sim.simulator_options` builds and changes a simulator
    from there alone.
    """

    name: str
    type: object
    unit: str
    description: str
    apply: str = "live"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] | None = None
    nonempty: bool = False
    scene_key: str | None = None
    simulator: str | None = None

    # ------------------------------------------------------------------ text
    def range_text(self) -> str:
        """The accepted set in words: ``a number in [1e-07, 1] s``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.type is bool:
            return "true or false"
        if self.type is str:
            if self.choices is not None:
                return "one of " + ", ".join(self.choices)
            return "a non-empty string" if self.nonempty else "a string"
        lo = "(" if self.lo_open else "["
        interval = f"{lo}{_num(self.lo)}, {_num(self.hi)}]"
        if self.type is int:
            return f"an integer in {interval}{unit}"
        if self.type in VECTORS:
            return f"{VECTORS[self.type]} numbers, each in {interval}{unit}"
        return f"a number in {interval}{unit}"

    # ------------------------------------------------------------------ checks
    def check(self, value, field: str | None = None):
        """``value`` in canonical form (float, int, bool, str or a list of 2 or 3 floats), or
        :class:`ParameterError` naming ``field`` (default: the parameter's name)."""
        name = field or self.name
        if self.type is bool:
            if not isinstance(value, bool):
                raise ParameterError(name, value, self.range_text())
            return value
        if self.type is str:
            if isinstance(value, str) and self.choices is not None and value not in self.choices:
                raise ParameterError(
                    name,
                    value,
                    self.range_text(),
                    f"{name} {_show(value)} is unknown; accepted values: "
                    f"{', '.join(self.choices)}",
                )
            if not isinstance(value, str) or (self.nonempty and not value):
                raise ParameterError(name, value, self.range_text())
            return value
        if self.type in VECTORS:
            if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__"):
                raise ParameterError(name, value, self.range_text())
            n = VECTORS[self.type]
            if len(value) != n:
                raise ParameterError(
                    name,
                    value,
                    self.range_text(),
                    f"{name} must have exactly {n} elements {VECTOR_NAMES[n]}, got "
                    f"{len(value)}: {_show(value)}",
                )
            return [self._number(v, f"{name}[{i}]") for i, v in enumerate(value)]
        if self.type is int:
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise ParameterError(name, value, self.range_text())
            v = int(value)
            if not self.lo <= v <= self.hi:
                raise ParameterError(name, value, self.range_text())
            return v
        return self._number(value, name)

    def _number(self, x, name) -> float:
        """One number (a scalar parameter or one vector component) in range."""
        ok = not isinstance(x, bool) and isinstance(x, numbers.Real)  # numpy scalars are Real too
        if ok:
            f = float(x)
            ok = (
                math.isfinite(f)
                and f <= self.hi
                and (f > self.lo if self.lo_open else f >= self.lo)
            )
        if not ok:
            lo = "(" if self.lo_open else "["
            unit = f" {self.unit}" if self.unit else ""
            raise ParameterError(
                name, x, f"a number in {lo}{_num(self.lo)}, {_num(self.hi)}]{unit}"
            )
        return f

    def is_valid(self, value) -> bool:
        try:
            self.check(value)
        except ParameterError:
            return False
        return True


def _schema() -> dict[str, Param]:
    P = Param
    params = [
        P(
            "scene",
            str,
            "",
            "Scene name (hanging, curtain, flag, free_fall) or path to a scene YAML "
            "file. Changing it rebuilds the cloth from that scene, its values included, and "
            "resets it.",
            apply="rebuild",
            nonempty=True,
        ),
        P(
            "integrator",
            str,
            "",
            "Time integrator; switching keeps positions and velocities.",
            choices=INTEGRATORS,
            scene_key="integrator",
            simulator="integrator",
        ),
        P(
            "dt",
            float,
            "s",
            "Simulation time step. A conditionally stable method refuses a dt above "
            "its stable_dt unless allow_unstable is true.",
            lo=1e-7,
            hi=1.0,
            scene_key="dt",
            simulator="dt",
        ),
        P("allow_unstable", bool, "", "Accept a dt above the method's stable_dt.", apply="node"),
        P(
            "vbd.iterations",
            int,
            "",
            "Iterations per step of the vbd integrator (Vertex Block "
            "Descent) at most: it stops earlier where the step reaches vbd.tolerance; more is "
            "closer to backward Euler's step, any count gives a usable state. 0: as many as a "
            "step needs (200 at most); with vbd.substeps 0 as well, vbd chooses its work from "
            "the fabric, the step and the tolerance (docs/convergence.md).",
            lo=0,
            hi=10_000,
            scene_key="vbd.iterations",
            simulator="integrator_options",
        ),
        P(
            "vbd.tolerance",
            float,
            "",
            "The relative residual at which a vbd step stops iterating before vbd.iterations: "
            "the step's force imbalance over the weight, RMS over the vertices "
            "(docs/convergence.md). 0 runs every iteration; ~/stats says whether each step "
            "reached it (solver_converged) and /diagnostics warns while steps do not.",
            lo=0.0,
            hi=10.0,
            scene_key="vbd.tolerance",
            simulator="integrator_options",
        ),
        P(
            "vbd.substeps",
            int,
            "",
            "Substeps a vbd step is cut into, each a backward-Euler step of its own (0: as many "
            "as the cloth's stiffness over its inertia asks for at this dt, which converge in a "
            "few sweeps each; docs/convergence.md). vbd.iterations caps each substep.",
            lo=0,
            hi=10_000,
            scene_key="vbd.substeps",
            simulator="integrator_options",
        ),
        P(
            "vbd.fit_tick",
            bool,
            "",
            "vbd fits its iterations into the node's tick (at most "
            "vbd.iterations a step, at least one, each step its share of the tick's budget): the "
            "node keeps real time, and its results depend on the machine. Off: the same bits "
            "anywhere.",
            apply="node",
            simulator="integrator_options",
        ),
        P(
            "publish_rate",
            float,
            "Hz",
            "Ticks per second: each tick advances 1/publish_rate of "
            "simulated time in whole steps of dt and publishes.",
            lo=0.1,
            hi=1000.0,
            apply="node",
        ),
        *[
            P(
                f"stiffness.{f}",
                float,
                "N/m",
                f"Spring stiffness of the {f} springs.",
                lo=0.0,
                hi=1e9,
                scene_key=f"stiffness.{f}",
            )
            for f in GRID_FAMILIES
        ],
        *[
            P(
                f"damping.{f}",
                float,
                "N·s/m",
                f"Damping along the {f} springs.",
                lo=0.0,
                hi=1e6,
                scene_key=f"damping.{f}",
            )
            for f in GRID_FAMILIES
        ],
        P(
            "particle_mass",
            float,
            "kg",
            "Mass of each particle of a grid scene given by it (a grid scene given by its "
            "density shares that out instead); rebuilds and resets the cloth.",
            lo=1e-6,
            hi=1e3,
            apply="rebuild",
            scene_key="particle_mass",
        ),
        P(
            "material",
            str,
            "",
            "A library fabric (cloth_sim.materials.names()) mapped onto the cloth in SI units: "
            "its masses, springs and bending follow from the fabric and the cloth's size, the "
            "same at any rows and cols; '' keeps the scene's own (its material mapping, or "
            "per-family stiffness and particle_mass when it has none). Rebuilds and resets the "
            "cloth.",
            choices=("", *MATERIAL_NAMES),
            apply="rebuild",
        ),  # a scene's material: (a name or a mapping: cloth_sim.scene)
        P(
            "size",
            "vector2",
            "m",
            "The grid cloth's [width, height]: with it rows and cols set the resolution, not "
            "the extent (spacing follows); [0, 0]: spacing sets the extent. A material needs "
            "it. Rebuilds and resets the cloth. Grid scenes only.",
            lo=0.0,
            hi=100.0,
            apply="rebuild",
            scene_key="size",
        ),
        P(
            "density",
            float,
            "kg/m²",
            "Areal density of a mesh cloth (each vertex carries a third of its triangles' "
            "mass) or of a grid scene given by its size and density (its rows·cols particles "
            "share the mass equally, so rows and cols refine the same cloth); rebuilds and "
            "resets the cloth.",
            lo=1e-6,
            hi=1e3,
            apply="rebuild",
        ),  # a scene's mesh.density (cloth_sim.scene)
        P(
            "gravity",
            "vector3",
            "m/s²",
            "Gravity acceleration [x, y, z].",
            lo=-1e3,
            hi=1e3,
            scene_key="gravity",
            simulator="gravity",
        ),
        P(
            "wind.direction",
            "vector3",
            "",
            "Wind direction [x, y, z]; particle i feels strength·(n_i·d) n_i.",
            lo=-1e3,
            hi=1e3,
            scene_key="wind.direction",
            simulator="wind",
        ),
        P(
            "wind.strength",
            float,
            "N",
            "Wind strength w (N per unit of normal projection); 0 turns wind off.",
            lo=0.0,
            hi=1e3,
            scene_key="wind.strength",
            simulator="wind",
        ),
        P(
            "drag",
            float,
            "N·s/m",
            "Linear air drag on each particle.",
            lo=0.0,
            hi=1e3,
            scene_key="drag",
            simulator="drag",
        ),
        P(
            "strain_limit",
            float,
            "",
            "Provot's critical deformation rate (0.1 = 10 %); 0 turns it off.",
            lo=0.0,
            hi=10.0,
            scene_key="strain_limit",
            simulator="strain_limit",
        ),
        P(
            "strain_limit_passes",
            int,
            "",
            "Most correction passes of the strain limit per step (it "
            "stops once a pass corrects nothing): fewer is faster and lets the cloth stretch "
            "more.",
            lo=1,
            hi=100,
            simulator="strain_limit_passes",
        ),
        P(
            "strain_limit_method",
            str,
            "",
            "How the strain limit corrects: provot (Gauss–Seidel "
            "passes: fast, the stretch plateaus above the limit on a large hanging cloth) or "
            "projection "
            "(every over-stretched spring projected together: the stretch held to the limit; "
            "strain_limit_passes bounds its iterations).",
            choices=STRAIN_LIMIT_METHODS,
            scene_key="strain_limit_method",
            simulator="strain_limit_method",
        ),
        P(
            "rows",
            int,
            "",
            "Particles along the grid's rows; rebuilds and resets the cloth.",
            lo=2,
            hi=MAX_GRID,
            apply="rebuild",
            scene_key="grid.rows",
        ),
        P(
            "cols",
            int,
            "",
            "Particles along the grid's columns; rebuilds and resets the cloth.",
            lo=2,
            hi=MAX_GRID,
            apply="rebuild",
            scene_key="grid.cols",
        ),
        P(
            "spacing",
            float,
            "m",
            "Rest distance between neighbouring particles; rebuilds and resets the cloth.",
            lo=1e-4,
            hi=10.0,
            apply="rebuild",
            scene_key="grid.spacing",
        ),
        P(
            "model",
            str,
            "",
            "Spring model; rebuilds and resets the cloth.",
            choices=MODELS,
            apply="rebuild",
            scene_key="model",
        ),
        P(
            "world_frame_id",
            str,
            "",
            "Parent of frame_id on /tf_static (an identity transform): "
            "where the simulation's frame sits in the world.",
            apply="node",
            nonempty=True,
        ),
        P(
            "frame_id",
            str,
            "",
            "frame_id of the published cloud, mesh and stats.",
            apply="node",
            nonempty=True,
        ),
        P(
            "publish_clock",
            bool,
            "",
            "Publish /clock with the simulated time and stamp every message "
            "with it (for use_sim_time nodes, lockstep tests, data generation).",
            apply="node",
        ),
        P(
            "real_time_factor",
            float,
            "",
            "Simulated seconds per wall-clock second the node aims at; "
            "0 runs as fast as the CPU allows.",
            lo=0.0,
            hi=1000.0,
            apply="node",
            simulator="integrator_options",
        ),
        P(
            "camera.enable",
            bool,
            "",
            "Render and publish the depth camera (~/camera/...) while its topics are subscribed.",
            apply="node",
            scene_key="camera.enable",
        ),
        P(
            "camera.width",
            int,
            "px",
            "Depth image width.",
            lo=1,
            hi=4096,
            apply="node",
            scene_key="camera.width",
        ),
        P(
            "camera.height",
            int,
            "px",
            "Depth image height.",
            lo=1,
            hi=4096,
            apply="node",
            scene_key="camera.height",
        ),
        P(
            "camera.fov",
            float,
            "deg",
            "Horizontal field of view (square pixels, principal point at the image centre).",
            lo=1.0,
            hi=170.0,
            apply="node",
            scene_key="camera.fov",
        ),
        P(
            "camera.position",
            "vector3",
            "m",
            "Where the camera is, in frame_id.",
            lo=-1e3,
            hi=1e3,
            apply="node",
            scene_key="camera.position",
        ),
        P(
            "camera.look_at",
            "vector3",
            "m",
            "The point the optical axis goes through, in frame_id "
            "(image up is world +z, or +y looking straight up or down).",
            lo=-1e3,
            hi=1e3,
            apply="node",
            scene_key="camera.look_at",
        ),
        P(
            "camera.rate",
            float,
            "Hz",
            "Images per second of wall time.",
            lo=0.1,
            hi=120.0,
            apply="node",
            scene_key="camera.rate",
        ),
        P(
            "camera.near",
            float,
            "m",
            "Nearest depth seen.",
            lo=1e-3,
            hi=1e3,
            apply="node",
            scene_key="camera.near",
        ),
        P(
            "camera.far",
            float,
            "m",
            "Farthest depth seen (above camera.near).",
            lo=1e-3,
            hi=1e4,
            apply="node",
            scene_key="camera.far",
        ),
        P(
            "camera.noise",
            str,
            "",
            "Depth noise model: none, or kinect (Nguyen et al. 2012's axial noise).",
            choices=("none", "kinect"),
            apply="node",
            scene_key="camera.noise",
        ),
        P(
            "robot.enable",
            bool,
            "",
            "Take a robot as ROS publishes it: its URDF from robot.description_topic, its joints "
            "from robot.joint_states_topic; its links become colliders.",
            apply="node",
        ),
        P(
            "robot.description_topic",
            str,
            "",
            "The robot's URDF (std_msgs/String, transient local, as robot_state_publisher "
            "publishes it).",
            nonempty=True,
            apply="node",
        ),
        P(
            "robot.joint_states_topic",
            str,
            "",
            "The robot's joint positions (sensor_msgs/JointState).",
            nonempty=True,
            apply="node",
        ),
        P(
            "robot.source",
            str,
            "",
            "What moves the links: joint_states (forward kinematics of the URDF from "
            "robot.joint_states_topic) or tf (each link's pose from /tf and /tf_static, "
            "relative to robot.base_frame).",
            choices=("joint_states", "tf"),
            apply="node",
        ),
        P(
            "robot.base_frame",
            str,
            "",
            "With robot.source tf: the TF frame placed at the robot's root, the cloth's frame "
            "origin (the links' poses are taken relative to it); empty: the URDF's root link.",
            apply="node",
        ),
        P(
            "thickness",
            float,
            "m",
            "Distance the cloth keeps from every collider and, with "
            "self_collision, from its own non-adjacent triangles.",
            lo=0.0,
            lo_open=True,
            hi=1.0,
            scene_key="thickness",
            simulator="thickness",
        ),
        P(
            "self_collision",
            bool,
            "",
            "Keep the cloth from passing through itself (off: no self-collision code runs).",
            scene_key="self_collision",
            simulator="self_collision",
        ),
        P(
            "device",
            str,
            "",
            "Where the cloth is stepped: cpu, or cuda (an NVIDIA GPU through numba-cuda: make "
            "gpu; symplectic_euler and vbd: springs, bending, gravity, wind, drag, pins, "
            "grippers, colliders (a mesh from its distance grid) and Provot's strain limit). "
            "Changing it rebuilds the cloth on that device and resets it; cuda is refused, and "
            "the cpu keeps running, where no CUDA device can run or the scene needs what the "
            "device does not have (robots, self-collision, the strain limit's projection: a "
            "scene's own projection runs there as Provot's passes when the node starts on cuda).",
            apply="rebuild",
            choices=DEVICES,
            simulator="device",
        ),
    ]
    return {p.name: p for p in params}


#: Every user-settable quantity by name (the node's parameter names).
SCHEMA: dict[str, Param] = _schema()

#: Parameters whose change rebuilds the cloth and resets it.
REBUILD = tuple(name for name, p in SCHEMA.items() if p.apply == "rebuild")


def check(name: str, value, field: str | None = None):
    """``SCHEMA[name].check(value, field)``."""
    return SCHEMA[name].check(value, field)
