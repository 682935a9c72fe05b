"""Scene files: load, validate, and build a model and a simulator from them.

A scene is a YAML mapping (see ``config/scenes/*.yaml``)::

    grid: {rows: 24, cols: 24, spacing: 0.04, orientation: horizontal}
    model: provot                  # or choi_ko
    particle_mass: 0.01            # per particle: a finer grid of this spacing is a bigger cloth
    stiffness: {structural: 1000, shear: 1000, bend: 100}
    damping: {structural: 0.05, shear: 0.05, bend: 0.01}
    pinned: [[0, 0], [0, -1]]      # (row, col) pairs, negative counts from the end
    pinned_edges: []               # any of first_row, last_row, first_col, last_col
    gravity: [0, 0, -9.81]
    wind: {direction: [0, 1, 0], strength: 0}
    drag: 0.0
    strain_limit: 0.1              # or null
    integrator: symplectic_euler
    dt: 0.001
    thickness: 0.005               # kept from colliders (and from itself with self_collision)
    self_collision: false
    grippers:                      # holding the cloth from the start
                                   # (moved by ~/grippers/<name>/pose)
      - {name: left, point: [0, 0, 0], radius: 0.02}         # the particles within radius of point
      - {name: edge, box: {min: [x, y, z], max: [x, y, z]}}  # or every particle inside a box
    colliders:                     # each with an optional name and friction
                                   # (Coulomb's μ, default 0)
      - {type: plane, normal: [0, 0, 1], offset: 0.0, friction: 0.5}
      - {type: sphere, center: [0.5, 0.5, -0.3], radius: 0.2}
      - {type: box, center: [0, 0, -0.5], half_extents: [0.5, 0.4, 0.02],
         orientation: [1, 0, 0, 0]}
      - {type: capsule, a: [0, 0, 0], b: [0, 0.2, 0], radius: 0.01}

``grid`` may also give ``origin: [x, y, z]``, where particle (0, 0) starts. A cloth that stays
the same cloth at any ``rows`` and ``cols`` gives its extent and its mass per area instead of a
spacing and a particle mass::

    grid: {rows: 32, cols: 32, orientation: horizontal}
    size: [1.0, 1.0]               # m: rows and cols set the resolution, the spacing follows
    density: 10.24                 # kg/m²: each of the rows·cols particles carries an equal share

(the springs' stiffness per spring keeps a square lattice's membrane stiffness at any spacing; a
``material`` maps a fabric in SI units exactly, bending included).

A garment or any triangle mesh takes the place of ``grid`` (see :meth:`ClothModel.from_mesh
<cloth_sim.model.ClothModel.from_mesh>`)::

    mesh: {file: ../meshes/towel.obj,   # relative to this scene file; OBJ, PLY, STL, glTF/GLB, OFF
           scale: 1.0,                  # metres per file unit
           density: 0.2,                # kg/m²
           position: [0, 0, 1],         # the scaled mesh rotated by orientation, then moved here
           orientation: [1, 0, 0, 0]}   # (w, x, y, z)
    stiffness: {structural: 1000, bend: 1}   # a mesh's two families
    pinned: [0, 17]                     # vertex indices of the file
    pinned_box: {min: [x, y, z], max: [x, y, z]}   # and every vertex inside this box (placed)

Every field but ``grid`` (or ``mesh``) has a default. A malformed file raises :class:`SceneError`
naming the file, the field and what was expected.
"""

from __future__ import annotations

import dataclasses
import os
import re
import reprlib
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .contact.colliders import KINDS
from .contact.self_collision import MAX_THICKNESS_FRACTION
from .integrators.vbd_options import TOLERANCE as VBD_TOLERANCE
from .materials import Fabric, get
from .model import GRID_FAMILIES, MESH_FAMILIES, ORIENTATIONS, ClothModel
from .motion import Motion, motion_from_dict
from .parameters import SCHEMA, ParameterError
from .physics.mesh import MESH_FORMATS, vertices_in_box
from .robot import Robot
from .simulator import Simulator
from .simulator_options import FED_BY, integrator_options, vbd_options
from .simulator_options import options as simulator_options

EDGES = ("first_row", "last_row", "first_col", "last_col")
#: the depth camera's settings when a scene does not give them (scene key ``camera``)
CAMERA_DEFAULTS = {
    "enable": False,
    "width": 640,
    "height": 480,
    "fov": 60.0,
    "position": [0.5, -1.0, 1.0],
    "look_at": [0.5, 0.5, 0.0],
    "rate": 30.0,
    "near": 0.1,
    "far": 10.0,
    "noise": "none",
}


class SceneError(ValueError):
    """A scene file that cannot be used; the message names the file and the field."""


@dataclass
class Scene:
    """A validated scene."""

    name: str
    rows: int | None
    cols: int | None
    spacing: float | None
    orientation: str = "horizontal"
    model: str = "provot"
    particle_mass: float = 0.01
    stiffness: dict = field(default_factory=lambda: {"structural": 1e3, "shear": 1e3, "bend": 1e2})
    damping: dict = field(default_factory=lambda: {f: 0.0 for f in GRID_FAMILIES})
    pinned: list = field(default_factory=list)
    gravity: tuple = (0.0, 0.0, -9.81)
    wind_direction: tuple = (0.0, 0.0, 0.0)
    wind_strength: float = 0.0
    drag: float = 0.0
    strain_limit: float | None = None
    strain_limit_method: str = "provot"
    integrator: str = "symplectic_euler"
    #: the vbd integrator's iterations a step at most (``vbd: {iterations: N}``), 0 for as many
    #: as a step needs to reach the tolerance
    vbd_iterations: int = 0
    #: the relative residual at which its steps stop iterating (``vbd: {tolerance: r}``)
    vbd_tolerance: float = VBD_TOLERANCE
    #: the substeps a step is cut into, 0 for as many as the cloth asks (``vbd: {substeps: n}``;
    #: a file that gives iterations alone keeps one step: :func:`scene_from_dict`). Both 0: vbd
    #: chooses its work from the fabric, the step and the tolerance
    #: (:func:`~cloth_sim.simulator_options.vbd_options`)
    vbd_substeps: int = 0
    dt: float = 1e-3
    origin: tuple = (0.0, 0.0, 0.0)
    thickness: float = 0.005
    self_collision: bool = False
    #: validated collider specifications: (type, keyword arguments); see :meth:`make_colliders`
    colliders: list = field(default_factory=list)
    #: grippers holding the cloth from the start: (name, point, radius, box), box ``(lo, hi)`` for
    #: a gripper holding what a box holds (point and radius then None), else None
    grippers: list = field(default_factory=list)
    source: str = "<dict>"
    #: a mesh scene: ``{file (Path), scale, density, position, orientation}``; ``None`` for a grid
    mesh: dict | None = None
    #: the depth camera's settings (the node's camera.* parameters), CAMERA_DEFAULTS where not
    #: given
    camera: dict = field(default_factory=lambda: dict(CAMERA_DEFAULTS))
    #: a mesh scene's pins by place: ``(lo, hi)`` corners of a box in world coordinates, or None
    pinned_box: tuple | None = None
    #: the scene's robot, or None (:mod:`cloth_sim.robot`): a dict of ``urdf`` (its path),
    #: ``robot`` (the loaded Robot: it keeps no configuration, so every simulator of the scene
    #: shares it), ``name``, ``position``, ``orientation``, ``joints`` and ``friction``
    robot: dict | None = None
    #: grippers bound to the robot's links: ``{gripper name: link}``
    gripper_links: dict = field(default_factory=dict)
    #: the scripted motion (:class:`cloth_sim.motion.Motion`), or None
    motion: Motion | None = None
    #: the cloth's fabric (:class:`cloth_sim.materials.Fabric`), or None for per-family springs
    material: object | None = None
    #: the library name the scene gave for its material ("" for a mapping or none)
    material_name: str = ""
    #: a grid's (width, height) in m, or None (spacing sets the extent)
    size: tuple | None = None
    #: a grid's mass per area in kg/m² (its particles share it equally: particle_mass follows
    #: from the size and resolution), or None (particle_mass is per particle)
    grid_density: float | None = None

    @property
    def families(self) -> tuple[str, ...]:
        """The spring families of the scene's cloth."""
        return MESH_FAMILIES if self.mesh is not None else GRID_FAMILIES

    def apply_grippers(self, sim) -> None:
        """Grasp with the scene's grippers; one whose radius reaches no particle (a coarser grid
        than the scene's) holds the particle nearest its point."""
        for name, point, radius, box in self.grippers:
            if box is not None:
                sim.grasp_box(name, *box)
                continue
            link = self.gripper_links.get(name)
            if link is not None:
                sim.grasp(name, point, radius, link=(self.robot["name"], link))
                continue
            try:
                sim.grasp(name, point, radius)
            except ValueError:
                free = ~sim.model.pinned
                d = np.linalg.norm(sim.positions - np.asarray(point), axis=1)
                d[~free] = np.inf
                sim.grasp(name, point, float(d.min()) * (1 + 1e-9) + 1e-12)

    def make_colliders(self) -> list:
        """Fresh collider objects (each simulator moves its own)."""
        return [KINDS[kind](**kw) for kind, kw in self.colliders]

    def pinned_cells(self, rows: int | None = None, cols: int | None = None) -> list:
        """``(row, col)`` pins for a grid of the given size (pins outside it are dropped)."""
        rows = self.rows if rows is None else rows
        cols = self.cols if cols is None else cols
        cells = []
        for p in self.pinned:
            if isinstance(p, str):
                cells += {
                    "first_row": [(0, c) for c in range(cols)],
                    "last_row": [(rows - 1, c) for c in range(cols)],
                    "first_col": [(r, 0) for r in range(rows)],
                    "last_col": [(r, cols - 1) for r in range(rows)],
                }[p]
            elif -rows <= p[0] < rows and -cols <= p[1] < cols:
                cells.append((p[0] % rows, p[1] % cols))
        return sorted(set(cells))

    def build_model(self, **override) -> ClothModel:
        """The scene's model; ``override`` replaces rows, cols, spacing, particle_mass, size and
        density (a grid's mass per area, which sets particle_mass when given) or density (a
        mesh), model, stiffness or damping (used by the node's live parameters). On a grid given
        by size and density, a spacing given without a size, or a particle mass without a
        density, replaces them."""
        p = (
            {"density": self.mesh["density"]}
            if self.mesh is not None
            else {
                "rows": self.rows,
                "cols": self.cols,
                "spacing": self.spacing,
                "particle_mass": self.particle_mass,
                "size": self.size,
                "density": self.grid_density,
            }
        )
        p.update(
            {
                "model": self.model,
                "stiffness": self.stiffness,
                "damping": self.damping,
                "material": self.material,
            }
        )
        unknown = sorted(set(override) - set(p))
        if unknown:  # (a misspelt or simulator-only option used to vanish here unnoticed)
            raise TypeError(
                f"unknown scene override(s): {', '.join(unknown)}; accepted: "
                f"{', '.join([*p, *self.SIMULATOR_OPTIONS])}"
            )
        p.update(override)
        if self.mesh is not None:
            return self._mesh_model(p)
        # a spacing or a particle mass given without a size or a density: that is the cloth asked
        # for (a scene given by size and density otherwise keeps its extent and mass)
        if "spacing" in override and "size" not in override:
            p["size"] = None
        if "particle_mass" in override and "density" not in override:
            p["density"] = None
        if p["material"] is not None:
            return ClothModel.grid(
                p["rows"],
                p["cols"],
                size=p["size"] or self.material_size(p["rows"], p["cols"], p["spacing"]),
                material=p["material"],
                pinned=self.pinned_cells(p["rows"], p["cols"]),
                model=p["model"],
                orientation=self.orientation,
                origin=self.origin,
            )
        return ClothModel.grid(
            p["rows"],
            p["cols"],
            None if p["size"] else p["spacing"],
            self.grid_particle_mass(p["rows"], p["cols"], p["spacing"], p["size"], p["density"])
            if p["density"] is not None
            else p["particle_mass"],
            stiffness=p["stiffness"],
            damping=p["damping"],
            size=p["size"] or None,
            pinned=self.pinned_cells(p["rows"], p["cols"]),
            model=p["model"],
            orientation=self.orientation,
            origin=self.origin,
        )

    def grid_particle_mass(
        self, rows: int, cols: int, spacing: float, size: tuple | None, density: float
    ) -> float:
        """Each particle's equal share of a grid of ``density`` kg/m²: the extent (``size``, else
        the spacing times the cells) times the density over ``rows·cols``."""
        w, h = size or self.material_size(rows, cols, spacing)
        return density * w * h / (rows * cols)

    def material_size(self, rows: int, cols: int, spacing: float | None) -> tuple:
        """A material grid's size when none is given: the scene's spacing times its cells."""
        return (spacing * (cols - 1), spacing * (rows - 1))

    def _mesh_model(self, p: dict) -> ClothModel:
        m = self.mesh
        fams = {
            name: {f: v for f, v in p[name].items() if f in MESH_FAMILIES}
            for name in ("stiffness", "damping")
        }
        if p["material"] is not None:
            fams = {"material": p["material"]}
        else:
            fams["density"] = p["density"]
        model = ClothModel.from_mesh(
            str(m["file"]),
            model=p["model"],
            pinned=[q for q in self.pinned if not isinstance(q, str)],
            scale=m["scale"],
            position=m["position"],
            orientation=m["orientation"],
            **fams,
        )
        if self.pinned_box is not None:
            inside = vertices_in_box(model.positions, *self.pinned_box)
            if len(inside) == 0:
                raise ValueError(
                    f"{self.source}: field 'pinned_box' holds no vertex of "
                    f"{m['file']} as placed (its vertices span "
                    f"{model.positions.min(0).round(4).tolist()} to "
                    f"{model.positions.max(0).round(4).tolist()})"
                )
            mask = np.array(model.pinned)
            mask[inside] = True
            model = dataclasses.replace(model, pinned=mask)
        return model

    #: what :meth:`build_simulator` passes on to the simulator: the options the parameters feed
    #: (:mod:`cloth_sim.simulator_options`) and those only code sets
    SIMULATOR_OPTIONS = (*FED_BY, "strain_limit_long_range", "colliders")

    def parameter_values(self) -> dict:
        """The parameter values (:data:`~cloth_sim.parameters.SCHEMA`'s names) this scene
        implies (a grid's size and mass or a mesh's density; the parameters of the other kind are
        left out)."""
        values = {
            "integrator": self.integrator,
            "dt": float(self.dt),
            "gravity": [float(g) for g in self.gravity],
            "wind.direction": [float(w) for w in self.wind_direction],
            "wind.strength": float(self.wind_strength),
            "drag": float(self.drag),
            "strain_limit": float(self.strain_limit or 0.0),
            "strain_limit_method": self.strain_limit_method,
            "model": self.model,
            "thickness": float(self.thickness),
            "self_collision": bool(self.self_collision),
            "vbd.iterations": int(self.vbd_iterations),
            "vbd.tolerance": float(self.vbd_tolerance),
            "vbd.substeps": int(self.vbd_substeps),
            "material": self.material_name,
        }
        if self.mesh is not None:
            values["density"] = float(self.mesh["density"])
        else:
            values.update(
                {
                    "rows": int(self.rows),
                    "cols": int(self.cols),
                    "spacing": float(self.spacing),
                    "particle_mass": float(self.particle_mass),
                    "size": [float(x) for x in self.size] if self.size else [0.0, 0.0],
                }
            )
            if self.grid_density is not None:
                values["density"] = float(self.grid_density)
        for k, value in self.camera.items():  # (the scene's camera, or the default one)
            values[f"camera.{k}"] = [float(x) for x in value] if isinstance(value, list) else value
        for f in self.families:
            values[f"stiffness.{f}"] = float(self.stiffness[f])
            values[f"damping.{f}"] = float(self.damping[f])
        return values

    def vbd_options(self) -> dict:
        """The vbd integrator's options this scene sets (:func:`vbd_options`)."""
        return vbd_options(self.vbd_iterations, self.vbd_tolerance, self.vbd_substeps)

    def build_simulator(self, **override) -> Simulator:
        """A simulator of the scene; ``override`` takes :meth:`build_model`'s keys and the
        simulator's options in :attr:`SIMULATOR_OPTIONS`; any other key is a ``TypeError``."""
        values = self.parameter_values()
        sim_kw = {**simulator_options(values), "colliders": self.make_colliders()}
        given = {key: override.pop(key) for key in self.SIMULATOR_OPTIONS if key in override}
        if "integrator" in given and "integrator_options" not in given:  # (vbd's are the scene's)
            sim_kw["integrator_options"] = integrator_options(
                {**values, "integrator": given["integrator"]}
            )
        sim_kw.update(given)
        sim = Simulator(self.build_model(**override), **sim_kw)
        if self.robot is not None:
            self.add_robot(sim)
        self.apply_grippers(sim)
        sim.motion = self.motion
        return sim

    def add_robot(self, sim) -> None:
        """Put the scene's robot into ``sim`` at its pose and joint positions (the script's
        first keyframe where it has one)."""
        r = self.robot
        joints = dict(r["joints"])
        if self.motion is not None:
            joints.update(self.motion.joints_at(0.0))
        sim.add_robot(
            r["robot"],
            name=r["name"],
            position=r["position"],
            orientation=r["orientation"],
            joints=joints,
            friction=r["friction"],
        )


# --------------------------------------------------------------------------- loading
def scene_dirs() -> list[Path]:
    """Where named scenes are looked up: the source tree, then the installed share directory."""
    dirs = [
        Path(__file__).resolve().parent.parent / "config" / "scenes",
        Path(sys.prefix) / "share" / "cloth_sim" / "config" / "scenes",
    ]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / "cloth_sim" / "config" / "scenes")
    return dirs


def available_scenes() -> list[str]:
    names = set()
    for d in scene_dirs():
        if d.is_dir():
            names.update(p.stem for p in d.glob("*.yaml"))
    return sorted(names)


#: scene files larger than this are refused unread (a scene is a few hundred bytes)
MAX_SCENE_BYTES = 1 << 20
#: nesting deeper than this is refused (a scene is three levels deep)
MAX_SCENE_DEPTH = 32


def find_scene(name_or_path: str) -> Path:
    """A scene file from a path or a scene name."""
    if not isinstance(name_or_path, str) or not name_or_path:
        raise SceneError(f"scene must be a scene name or a path, got {_short(name_or_path)}")
    p = Path(name_or_path)
    try:
        if p.suffix in (".yaml", ".yml") or os.sep in name_or_path:
            if p.is_dir():
                raise SceneError(f"{_short_path(name_or_path)}: is a directory, not a scene file")
            if p.is_symlink() and not p.exists():
                raise SceneError(
                    f"{_short_path(name_or_path)}: a symbolic link to nothing, or a loop of links"
                )
            if not p.is_file():
                raise SceneError(f"{_short_path(name_or_path)}: no such scene file")
            return p
        for d in scene_dirs():
            candidate = d / f"{name_or_path}.yaml"
            if candidate.is_file():
                return candidate
    except OSError as e:  # a name too long for the file system, a symbolic link loop, …
        raise SceneError(
            f"{_short_path(name_or_path)}: cannot be opened ({e.strerror or e})"
        ) from None
    raise SceneError(
        f"unknown scene {_short(name_or_path)}; available: {', '.join(available_scenes())}"
    )


class _SceneLoader(yaml.SafeLoader):
    """PyYAML's safe loader without anchors and aliases (scenes need none, and an alias bomb — the
    'billion laughs' — would expand exponentially in whatever walks the result) and with a bound
    on nesting."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise yaml.MarkedYAMLError(
                problem="aliases (*name) are not accepted in a scene file", problem_mark=mark
            )
        self._depth = getattr(self, "_depth", 0) + 1
        try:
            if self._depth > MAX_SCENE_DEPTH:
                raise yaml.MarkedYAMLError(
                    problem=f"nesting deeper than {MAX_SCENE_DEPTH} levels",
                    problem_mark=self.peek_event().start_mark,
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def compose_document(
        self,
    ):  # anchors are allowed by the grammar: drop them, and the aliases fail
        node = super().compose_document()
        self.anchors = {}
        return node


def load_scene(name_or_path: str) -> Scene:
    """Load and validate a scene by name (``hanging``) or path. Anything wrong — no such file, a
    directory, unreadable, larger than :data:`MAX_SCENE_BYTES`, not UTF-8, not YAML (reported by
    line and column, never quoting the file), aliases, deep nesting, wrong fields or values — is
    one :class:`SceneError` naming the file and what is expected."""
    path = find_scene(name_or_path)
    where = _short_path(str(path))
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_SCENE_BYTES + 1)
    except OSError as e:
        raise SceneError(f"{where}: cannot be read ({e.strerror or e})") from None
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(
            f"{where}: larger than {MAX_SCENE_BYTES} bytes; a scene file is a short YAML mapping"
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise SceneError(f"{where}: not UTF-8 text (byte {e.start})") from None
    try:
        data = yaml.load(text, Loader=_SceneLoader)  # noqa: S506 (a safe loader)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        why = (
            e.problem
            if isinstance(e.problem, str) and e.problem.startswith(("aliases", "nesting"))
            else ""
        )
        raise SceneError(f"{where}: not valid YAML{at}{': ' + why if why else ''}") from None
    except (yaml.YAMLError, RecursionError):
        raise SceneError(f"{where}: not valid YAML") from None
    return scene_from_dict(data, source=str(path), name=path.stem)


def _short_path(path: str) -> str:
    return path if len(path) <= 120 else path[:60] + "…" + path[-40:]


def scene_from_dict(data, source: str = "<dict>", name: str = "scene") -> Scene:
    """Validate a scene mapping; errors name ``source`` and the field. Every value is checked
    against :data:`cloth_sim.parameters.SCHEMA` (the field's ``scene_key``), so a scene accepts
    exactly what the node's parameters accept."""
    v = SceneValidator(source)
    if not isinstance(data, dict):
        v.fail("(top level)", "a mapping of scene fields", data)
    known = {
        "name",
        "grid",
        "mesh",
        "model",
        "particle_mass",
        "stiffness",
        "damping",
        "pinned",
        "pinned_edges",
        "pinned_box",
        "gravity",
        "wind",
        "drag",
        "strain_limit",
        "strain_limit_method",
        "integrator",
        "vbd",
        "dt",
        "thickness",
        "self_collision",
        "colliders",
        "grippers",
        "camera",
        "robot",
        "motion",
        "material",
        "size",
        "density",
    }
    v.known("", data, known)
    if "mesh" in data:
        if "grid" in data:
            raise SceneError(
                f"{source}: fields 'grid' and 'mesh' are both given: a scene's cloth is "
                f"one or the other"
            )
        s = _mesh_scene(v, data, source, name)
    else:
        s = _grid_scene(v, data, source, name)
    _material(v, data, s, source)
    s.model = v.param("model", data.get("model", "provot"))
    s.gravity = tuple(v.param("gravity", data.get("gravity", s.gravity)))
    wind = data.get("wind", {}) or {}
    if not isinstance(wind, dict):
        v.fail("wind", "a mapping with direction and strength", wind)
    v.known("wind.", wind, {"direction", "strength"})
    s.wind_direction = tuple(v.param("wind.direction", wind.get("direction", (0.0, 0.0, 0.0))))
    s.wind_strength = v.param("wind.strength", wind.get("strength", 0.0))
    s.drag = v.param("drag", data.get("drag", 0.0))
    sl = data.get("strain_limit", None)
    s.strain_limit = None if sl is None else v.param("strain_limit", sl)
    s.strain_limit_method = v.param(
        "strain_limit_method", data.get("strain_limit_method", "provot")
    )
    s.integrator = v.param("integrator", data.get("integrator", s.integrator))
    vbd = data.get("vbd", {}) or {}
    if not isinstance(vbd, dict):
        v.fail("vbd", "a mapping with iterations", vbd)
    v.known("vbd.", vbd, {"iterations", "tolerance", "substeps"})
    s.vbd_iterations = v.param("vbd.iterations", vbd.get("iterations", s.vbd_iterations))
    s.vbd_tolerance = v.param("vbd.tolerance", vbd.get("tolerance", s.vbd_tolerance))
    # iterations given alone keep one step a frame (the shipped vbd scenes' own work); given
    # neither, vbd chooses its work
    default_substeps = 1 if s.vbd_iterations else s.vbd_substeps
    s.vbd_substeps = v.param("vbd.substeps", vbd.get("substeps", default_substeps))
    s.dt = v.param("dt", data.get("dt", s.dt))
    s.thickness = v.param("thickness", data.get("thickness", s.thickness))
    s.self_collision = v.param("self_collision", data.get("self_collision", False))
    # (a mesh's shortest edge is known once it is read: Simulator checks the thickness there)
    if s.self_collision and s.mesh is None and s.thickness > MAX_THICKNESS_FRACTION * s.spacing:
        v.fail(
            "thickness",
            f"at most {MAX_THICKNESS_FRACTION:g} × grid.spacing = "
            f"{MAX_THICKNESS_FRACTION * s.spacing:.4g} m with self_collision on",
            s.thickness,
        )
    cam = data.get("camera", {}) or {}
    if not isinstance(cam, dict):
        v.fail(
            "camera",
            "a mapping of camera settings (enable, width, height, fov, position, "
            "look_at, rate, near, far, noise)",
            cam,
        )
    v.known("camera.", cam, set(CAMERA_DEFAULTS))
    s.camera = {
        k: v.param(f"camera.{k}", cam.get(k, default)) for k, default in CAMERA_DEFAULTS.items()
    }
    # (near < far and look_at ≠ position are checked where the camera is built: the node's gate)
    cols_ = data.get("colliders", []) or []
    if not isinstance(cols_, list):
        v.fail("colliders", "a list of collider mappings", cols_)
    if len(cols_) > MAX_COLLIDERS:
        v.fail("colliders", f"at most {MAX_COLLIDERS} colliders", f"{len(cols_)} colliders")
    s.colliders = [v.collider(i, c) for i, c in enumerate(cols_)]
    names = [kw["name"] for _, kw in s.colliders]
    for i, n in enumerate(names):
        if n in names[:i]:
            v.fail(f"colliders[{i}].name", "unique (it names the collider's pose topic)", n)
    grips = data.get("grippers", []) or []
    if not isinstance(grips, list) or len(grips) > MAX_GRIPPERS:
        v.fail(
            "grippers",
            f"a list of at most {MAX_GRIPPERS} {{name, point, radius}} or {{name, box}} mappings",
            grips,
        )
    for i, g in enumerate(grips):
        where = f"grippers[{i}]"
        if not isinstance(g, dict):
            v.fail(where, "a mapping with name, and point and radius or box", g)
        v.known(f"{where}.", g, {"name", "point", "radius", "box", "link"})
        name = g.get("name")
        if not (isinstance(name, str) and GRIPPER_NAME.fullmatch(name)):
            v.fail(
                f"{where}.name",
                "a name of ASCII letters, digits and _ (at most 64, not starting with a digit)",
                name,
            )
        if name in [n for n, *_ in s.grippers]:
            v.fail(f"{where}.name", "unique (it names the gripper's topics)", name)
        if "box" in g:
            box = g["box"]
            if "point" in g or "radius" in g:
                v.fail(where, "either point and radius or box, not both", g)
            if not isinstance(box, dict):
                v.fail(f"{where}.box", "a mapping {min: [x, y, z], max: [x, y, z]}", box)
            v.known(f"{where}.box.", box, {"min", "max"})
            lo = v.vector(f"{where}.box.min", box.get("min"), 3)
            hi = v.vector(f"{where}.box.max", box.get("max"), 3)
            if any(a > b for a, b in zip(lo, hi)):
                v.fail(f"{where}.box", "min <= max on every axis", box)
            s.grippers.append((name, None, None, (lo, hi)))
            continue
        point = v.vector(f"{where}.point", g.get("point"), 3)
        radius = v.number(f"{where}.radius", g.get("radius"), lo=0.0)
        if radius <= 0:
            v.fail(f"{where}.radius", "a finite number > 0", radius)
        s.grippers.append((name, point, radius, None))
        if "link" in g:
            s.gripper_links[name] = g["link"]
    s.robot = _robot(v, data.get("robot"), source) if "robot" in data else None
    for name, link in s.gripper_links.items():
        if s.robot is None or link not in s.robot["links"]:
            v.fail(
                f"grippers.{name}.link",
                "a link of the scene's robot"
                + (f" ({', '.join(s.robot['links'])})" if s.robot else " (the scene has none)"),
                link,
            )
    if "motion" in data:
        s.motion = motion_from_dict(
            v,
            data["motion"],
            s.robot["name"] if s.robot else None,
            [n for n, *_ in s.grippers],
        )
        if s.robot is not None:
            for name in {j for _, js in s.motion.joints for j in js}:
                if name not in s.robot["joints_all"]:
                    v.fail(
                        "motion.robot",
                        f"joints of the robot ({', '.join(s.robot['joints_all'])})",
                        name,
                    )
    return s


def _robot(v: "SceneValidator", r, source: str) -> dict:
    """A scene's ``robot`` mapping: ``urdf`` (a file relative to the scene file), ``name``,
    ``position``, ``orientation``, ``joints``, ``friction``; the URDF is loaded here, so that a
    bad one is refused with the scene."""

    if not isinstance(r, dict):
        v.fail("robot", "a mapping with urdf and optional name, position, orientation, joints", r)
    v.known("robot.", r, {"urdf", "name", "position", "orientation", "joints", "friction"})
    file = r.get("urdf")
    if not isinstance(file, str) or not file:
        v.fail("robot.urdf", "a URDF file path, relative to the scene file", file)
    path = Path(file)
    if not path.is_absolute():
        path = (Path(source).parent if source != "<dict>" else Path.cwd()) / path
    try:
        robot = Robot.from_urdf(Path(os.path.normpath(path)))
    except ValueError as e:
        raise SceneError(f"{source}: field 'robot.urdf': {e}") from None
    name = r.get("name", robot.name)
    if not (isinstance(name, str) and GRIPPER_NAME.fullmatch(name)):
        v.fail("robot.name", "a name of ASCII letters, digits and _", name)
    joints = r.get("joints", {}) or {}
    if not isinstance(joints, dict):
        v.fail("robot.joints", "a mapping of joint names to positions", joints)
    try:
        joints = robot.check_joints(joints)
    except ValueError as e:
        raise SceneError(f"{source}: field 'robot.joints': {e}") from None
    return {
        "urdf": path,
        "robot": robot,
        "name": name,
        "position": v.vector("robot.position", r.get("position", [0.0, 0.0, 0.0]), 3),
        "orientation": v.vector("robot.orientation", r.get("orientation", [1, 0, 0, 0]), 4),
        "joints": joints,
        "friction": v.number("robot.friction", r.get("friction", 0.5), lo=0.0),
        "links": robot.all_links,
        "joints_all": robot.joint_names,
    }


def _grid_scene(v: "SceneValidator", data: dict, source: str, name: str) -> Scene:
    grid = data.get("grid")
    if not isinstance(grid, dict):
        v.fail("grid", "a mapping with rows, cols, spacing (or a mesh mapping instead)", grid)
    v.known("grid.", grid, {"rows", "cols", "spacing", "orientation", "origin"})
    if "pinned_box" in data:
        raise SceneError(
            f"{source}: field 'pinned_box' is for mesh scenes; a grid pins (row, col) "
            f"cells with pinned and pinned_edges"
        )
    rows, cols = v.param("rows", grid.get("rows")), v.param("cols", grid.get("cols"))
    size = None
    if data.get("size") is not None:
        size = tuple(v.param("size", data["size"]))
        if min(size) <= 0:
            v.fail("size", "[width, height], each > 0 m", data["size"])
        spacing = min(size[0] / (cols - 1), size[1] / (rows - 1))
        if "spacing" in grid:
            raise SceneError(
                f"{source}: fields 'size' and 'grid.spacing' are both given: with a size, rows "
                f"and cols set the spacing"
            )
    else:
        spacing = v.param("spacing", grid.get("spacing"))
    s = Scene(
        name=str(data.get("name", name)),
        source=source,
        rows=rows,
        cols=cols,
        spacing=spacing,
        size=size,
        orientation=v.choice(
            "grid.orientation", grid.get("orientation", "horizontal"), ORIENTATIONS
        ),
    )
    if "density" in data:
        if "particle_mass" in data:
            raise SceneError(
                f"{source}: fields 'density' and 'particle_mass' are both given: with a density "
                f"(kg/m²) the particles share the cloth's mass equally"
            )
        s.grid_density = v.param("density", data["density"], field="density")
        s.particle_mass = s.grid_particle_mass(rows, cols, spacing, size, s.grid_density)
    else:
        s.particle_mass = v.param("particle_mass", data.get("particle_mass", s.particle_mass))
    s.stiffness = v.families("stiffness", data.get("stiffness", s.stiffness))
    s.damping = v.families("damping", data.get("damping", s.damping))
    pins = data.get("pinned", [])
    if not isinstance(pins, list):
        v.fail("pinned", "a list of [row, col] pairs", pins)
    for i, p in enumerate(pins):
        if not (
            isinstance(p, (list, tuple))
            and len(p) == 2
            and all(isinstance(q, int) and not isinstance(q, bool) for q in p)
        ):
            v.fail(f"pinned[{i}]", "a [row, col] pair of integers", p)
        if not (-s.rows <= p[0] < s.rows and -s.cols <= p[1] < s.cols):
            v.fail(f"pinned[{i}]", f"a cell inside the {s.rows}×{s.cols} grid", p)
    edges = data.get("pinned_edges", [])
    if not isinstance(edges, list):
        v.fail("pinned_edges", f"a list of {', '.join(EDGES)}", edges)
    for i, e in enumerate(edges):
        v.choice(f"pinned_edges[{i}]", e, EDGES)
    s.pinned = [tuple(p) for p in pins] + list(edges)
    s.origin = tuple(v.vector("grid.origin", grid.get("origin", (0.0, 0.0, 0.0)), 3))
    return s


#: the most vertex indices a mesh scene's pinned list may hold
MAX_PINNED = 100_000


def _mesh_scene(v: "SceneValidator", data: dict, source: str, name: str) -> Scene:
    """A mesh scene's own fields: ``mesh`` (file relative to the scene file, scale, density, pose),
    ``pinned`` vertex indices and ``pinned_box``; grid-only fields are refused with the reason."""
    mesh = data.get("mesh")
    if not isinstance(mesh, dict):
        v.fail(
            "mesh", "a mapping with file, density and optional scale, position, orientation", mesh
        )
    v.known("mesh.", mesh, {"file", "scale", "density", "position", "orientation"})
    for key in ("particle_mass", "density", "pinned_edges"):
        if key in data:
            raise SceneError(
                f"{source}: field '{key}' is for grid scenes; "
                + (
                    "a mesh's masses come from mesh.density (kg/m²)"
                    if key in ("particle_mass", "density")
                    else "a mesh pins vertex indices (pinned) or a box (pinned_box)"
                )
            )
    file = mesh.get("file")
    if not isinstance(file, str) or not file:
        v.fail(
            "mesh.file",
            f"a mesh file path ({', '.join('.' + e for e in MESH_FORMATS)}), "
            f"relative to the scene file",
            file,
        )
    path = Path(file)
    if not path.is_absolute():
        path = (Path(source).parent if source != "<dict>" else Path.cwd()) / path
    path = Path(os.path.normpath(path))
    if path.suffix.lower().lstrip(".") not in MESH_FORMATS:
        v.fail(
            "mesh.file", f"a mesh file ending in {', '.join('.' + e for e in MESH_FORMATS)}", file
        )
    try:
        found = path.is_file()
    except OSError:
        found = False
    if not found:
        v.fail("mesh.file", f"an existing mesh file (looked for {_short_path(str(path))})", file)
    scale = v.number("mesh.scale", mesh.get("scale", 1.0), lo=0.0)
    if scale <= 0:
        v.fail("mesh.scale", "a finite number > 0 (metres per file unit)", scale)
    if "size" in data:
        raise SceneError(
            f"{source}: field 'size' is for grid scenes; a mesh's extent is its file's times "
            f"mesh.scale"
        )
    if "density" not in mesh and "material" in data:
        mesh = {**mesh, "density": 0.1}  # unused: the material's density applies
    elif "density" in mesh and "material" in data:
        raise SceneError(
            f"{source}: fields 'mesh.density' and 'material' are both given: the material's "
            f"density applies"
        )
    if "density" not in mesh:
        raise SceneError(
            f"{source}: field 'mesh.density' is missing: a mesh's masses come from its "
            f"areal density (kg/m²)"
        )
    density = v.param("density", mesh["density"], field="mesh.density")
    position = v.vector("mesh.position", mesh.get("position", (0.0, 0.0, 0.0)), 3)
    orientation = v.vector("mesh.orientation", mesh.get("orientation", (1.0, 0.0, 0.0, 0.0)), 4)
    if not np.any(orientation):
        v.fail("mesh.orientation", "a nonzero quaternion (w, x, y, z)", orientation)
    s = Scene(
        name=str(data.get("name", name)),
        source=source,
        rows=None,
        cols=None,
        spacing=None,
        mesh={
            "file": path,
            "scale": scale,
            "density": density,
            "position": position,
            "orientation": orientation,
        },
    )
    s.stiffness = v.families(
        "stiffness", data.get("stiffness", {"structural": 1e3, "bend": 1.0}), MESH_FAMILIES
    )
    s.damping = v.families("damping", data.get("damping", 0.0), MESH_FAMILIES)
    pins = data.get("pinned", [])
    if not isinstance(pins, list) or len(pins) > MAX_PINNED:
        v.fail("pinned", f"a list of at most {MAX_PINNED} vertex indices", pins)
    for i, p in enumerate(pins):
        if not (isinstance(p, int) and not isinstance(p, bool) and p >= 0):
            v.fail(f"pinned[{i}]", "a vertex index (an integer >= 0)", p)
    s.pinned = list(pins)
    box = data.get("pinned_box")
    if box is not None:
        if not isinstance(box, dict):
            v.fail("pinned_box", "a mapping with min and max corners", box)
        v.known("pinned_box.", box, {"min", "max"})
        lo = v.vector("pinned_box.min", box.get("min"), 3)
        hi = v.vector("pinned_box.max", box.get("max"), 3)
        if any(a > b for a, b in zip(lo, hi)):
            v.fail("pinned_box", "min <= max in every coordinate", box)
        s.pinned_box = (lo, hi)
    return s


def _material(v: "SceneValidator", data: dict, s: Scene, source: str) -> None:
    """A scene's ``material:`` (a library name or a mapping of a fabric's fields): it replaces the
    per-family springs and masses, so those fields are refused beside it."""

    m = data.get("material")
    if m is None:
        return
    clash = [k for k in ("particle_mass", "density", "stiffness", "damping") if k in data]
    if clash:
        raise SceneError(
            f"{source}: field 'material' and {', '.join(repr(k) for k in clash)} are both "
            f"given: a material sets the masses, springs and damping itself"
        )
    try:
        if isinstance(m, str):
            s.material, s.material_name = get(m), m
        else:
            s.material = Fabric.from_mapping(m, where="material")
    except ValueError as e:
        raise SceneError(f"{source}: field {e}") from None
    if s.mesh is None and s.size is None:
        s.size = s.material_size(s.rows, s.cols, s.spacing)


#: grippers a scene may declare
MAX_GRIPPERS = 16
#: a gripper's name: it names its topics
GRIPPER_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")


#: colliders a scene may have (each costs a distance test per particle per step)
MAX_COLLIDERS = 64
#: the fields of each collider type, with their lengths (1 = a number) and whether required
_COLLIDER_FIELDS = {
    "plane": {"normal": 3, "offset": 1},
    "sphere": {"center": 3, "radius": 1},
    "box": {"center": 3, "half_extents": 3, "orientation": 4},
    "capsule": {"a": 3, "b": 3, "radius": 1},
    "cylinder": {"center": 3, "radius": 1, "length": 1, "orientation": 4},
    # (file: a path relative to the scene file, as mesh.file)
    "mesh": {"file": 0, "position": 3, "orientation": 4, "scale": 1},
}
_COLLIDER_REQUIRED = {
    "plane": ("normal",),
    "sphere": ("center", "radius"),
    "box": ("center", "half_extents"),
    "capsule": ("a", "b", "radius"),
    "cylinder": ("center", "radius", "length"),
    "mesh": ("file",),
}


class SceneValidator:
    """Checks a scene's fields one at a time; each refusal is a :class:`SceneError` naming the
    source, the field and what it accepts (scene files, and the node's ``spawn_entity``)."""

    def __init__(self, source):
        self.source = source

    def fail(self, fld, expected, got):
        raise SceneError(f"{self.source}: field '{fld}' must be {expected}, got {_short(got)}")

    def known(self, prefix, mapping, keys):
        unknown = sorted(
            k if isinstance(k, str) and k.isprintable() else _short(k)
            for k in mapping
            if k not in keys
        )
        if unknown:
            raise SceneError(
                f"{self.source}: unknown field(s) {prefix}{(', ' + prefix).join(unknown)}; "
                f"expected {', '.join(sorted(keys))}"
            )

    def param(self, name, x, field=None):
        """``x`` checked against the schema's entry ``name``, reported under its scene key (or
        ``field``)."""
        spec = SCHEMA[name]
        try:
            return spec.check(x, field=field or spec.scene_key)
        except ParameterError as e:
            self.fail(e.name, e.accepted, x)

    def vector(self, fld, x, n):
        if not (
            isinstance(x, (list, tuple))
            and len(x) == n
            and all(
                isinstance(q, (int, float)) and not isinstance(q, bool) and np.isfinite(q)
                for q in x
            )
        ):
            self.fail(fld, f"a list of {n} finite numbers", x)
        return [float(q) for q in x]

    def collider(self, i, c):
        """One collider mapping, as ``(type, keyword arguments)`` for :data:`KINDS`."""
        where = f"colliders[{i}]"
        if not isinstance(c, dict):
            self.fail(
                where, f"a mapping with type ({', '.join(_COLLIDER_FIELDS)}) and its fields", c
            )
        kind = c.get("type")
        if kind not in _COLLIDER_FIELDS:
            self.fail(f"{where}.type", f"one of {', '.join(_COLLIDER_FIELDS)}", kind)
        fields = _COLLIDER_FIELDS[kind]
        self.known(f"{where}.", c, {"type", "name", "friction", *fields})
        kw = {}
        for name in _COLLIDER_REQUIRED[kind]:
            if name not in c:
                raise SceneError(
                    f"{self.source}: field '{where}.{name}' is missing: a {kind} needs "
                    f"{', '.join(_COLLIDER_REQUIRED[kind])}"
                )
        for name, n in fields.items():
            if name in c and n == 0:  # a file, relative to the scene file
                if not isinstance(c[name], str) or not c[name]:
                    self.fail(
                        f"{where}.{name}", "a mesh file path, relative to the scene", c[name]
                    )
                path = Path(c[name])
                if not path.is_absolute():
                    base = Path(self.source).parent if self.source != "<dict>" else Path.cwd()
                    path = base / path
                kw["source"] = str(Path(os.path.normpath(path)))
            elif name in c:
                kw[name] = (
                    self.vector(f"{where}.{name}", c[name], n)
                    if n > 1
                    else self.number(f"{where}.{name}", c[name])
                )
        if "friction" in c:
            kw["friction"] = self.number(f"{where}.friction", c["friction"], lo=0.0)
        if "name" in c:
            if not (
                isinstance(c["name"], str)
                and c["name"].isidentifier()
                and c["name"].isascii()
                and len(c["name"]) <= 64
            ):
                self.fail(
                    f"{where}.name",
                    "a name of ASCII letters, digits and _ (at most 64, "
                    "not starting with a digit)",
                    c["name"],
                )
        kw["name"] = c.get("name", f"{kind}_{i}")
        try:
            KINDS[kind](**kw)  # the shape's own checks (a positive radius, a nonzero normal, …)
        except ValueError as e:  # "radius must be …": name the field in full
            if kind == "mesh":  # (the file's errors name the file and the element)
                raise SceneError(f"{self.source}: field '{where}.file': {e}") from None
            name, _, rest = str(e).partition(" ")
            raise SceneError(f"{self.source}: field '{where}.{name}' {rest}") from None
        return kind, kw

    def number(self, fld, x, lo=None):
        if not (
            isinstance(x, (int, float))
            and not isinstance(x, bool)
            and np.isfinite(x)
            and (lo is None or x >= lo)
        ):
            self.fail(fld, "a finite number" + (f" >= {lo:g}" if lo is not None else ""), x)
        return float(x)

    def choice(self, fld, x, options):
        if x not in options:
            self.fail(fld, f"one of {', '.join(options)}", x)
        return x

    def families(self, fld, x, families=GRID_FAMILIES):
        if isinstance(x, (int, float)) and not isinstance(x, bool):
            x = {f: x for f in families}
        if not isinstance(x, dict):
            self.fail(fld, f"a mapping of {', '.join(families)} to numbers >= 0", x)
        unknown = sorted(_short(k) for k in x if k not in families)
        if unknown:
            self.fail(
                fld,
                f"keyed by {', '.join(families)}"
                + (
                    " (a mesh has no shear springs)"
                    if "shear" in x and "shear" not in families
                    else ""
                ),
                unknown,
            )
        return {f: self.param(f"{fld}.{f}", x.get(f, 0.0)) for f in families}


_REPR = reprlib.Repr()
_REPR.maxstring = _REPR.maxother = 60
_REPR.maxlevel, _REPR.maxdict, _REPR.maxlist = 3, 4, 6


def _short(value) -> str:
    """A bounded repr: a value from an untrusted file may be huge or deep."""
    return _REPR.repr(value)
