"""Scene files: load, validate, and build a model and a simulator from them.

A scene is a YAML mapping (see ``config/scenes/*.yaml``)::

    grid: {rows: 24, cols: 24, spacing: 0.04, orientation: horizontal}
    model: provot                  # or choi_ko
    particle_mass: 0.01
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

Every field but ``grid`` has a default. A malformed file raises :class:`SceneError` naming the file,
the field and what was expected.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .model import GRID_FAMILIES, ORIENTATIONS, ClothModel
from .parameters import SCHEMA, ParameterError
from .simulator import Simulator

EDGES = ("first_row", "last_row", "first_col", "last_col")


class SceneError(ValueError):
    """A scene file that cannot be used; the message names the file and the field."""


@dataclass
class Scene:
    """A validated scene."""

    name: str
    rows: int
    cols: int
    spacing: float
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
    integrator: str = "symplectic_euler"
    dt: float = 1e-3
    source: str = "<dict>"

    @property
    def wind(self):
        w = self.wind_strength * np.asarray(self.wind_direction, dtype=float)
        return None if not np.any(w) else w

    def pinned_cells(self, rows: int | None = None, cols: int | None = None) -> list:
        """``(row, col)`` pins for a grid of the given size (pins outside it are dropped)."""
        rows = self.rows if rows is None else rows
        cols = self.cols if cols is None else cols
        cells = []
        for p in self.pinned:
            if isinstance(p, str):
                cells += {"first_row": [(0, c) for c in range(cols)],
                          "last_row": [(rows - 1, c) for c in range(cols)],
                          "first_col": [(r, 0) for r in range(rows)],
                          "last_col": [(r, cols - 1) for r in range(rows)]}[p]
            elif -rows <= p[0] < rows and -cols <= p[1] < cols:
                cells.append((p[0] % rows, p[1] % cols))
        return sorted(set(cells))

    def build_model(self, **override) -> ClothModel:
        """The scene's model; ``override`` replaces rows, cols, spacing, particle_mass, model,
        stiffness or damping (used by the node's live parameters)."""
        p = {"rows": self.rows, "cols": self.cols, "spacing": self.spacing,
             "particle_mass": self.particle_mass, "model": self.model,
             "stiffness": self.stiffness, "damping": self.damping}
        p.update(override)
        return ClothModel.grid(p["rows"], p["cols"], p["spacing"], p["particle_mass"],
                               stiffness=p["stiffness"], damping=p["damping"],
                               pinned=self.pinned_cells(p["rows"], p["cols"]), model=p["model"],
                               orientation=self.orientation)

    SIMULATOR_OPTIONS = ("integrator", "dt", "gravity", "wind", "strain_limit", "drag",
                         "integrator_options")

    def build_simulator(self, **override) -> Simulator:
        """A simulator of the scene; ``override`` takes :meth:`build_model`'s keys and the
        simulator's ``integrator``, ``dt``, ``gravity``, ``wind``, ``strain_limit``, ``drag`` and
        ``integrator_options``."""
        sim_kw = {"integrator": self.integrator, "dt": self.dt, "gravity": self.gravity,
                  "wind": self.wind, "strain_limit": self.strain_limit, "drag": self.drag}
        for key in self.SIMULATOR_OPTIONS:
            if key in override:
                sim_kw[key] = override.pop(key)
        return Simulator(self.build_model(**override), **sim_kw)


# --------------------------------------------------------------------------- loading
def scene_dirs() -> list[Path]:
    """Where named scenes are looked up: the source tree, then the installed share directory."""
    dirs = [Path(__file__).resolve().parent.parent / "config" / "scenes",
            Path(sys.prefix) / "share" / "cloth_sim" / "config" / "scenes"]
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


def find_scene(name_or_path: str) -> Path:
    """A scene file from a path or a scene name."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or os.sep in str(name_or_path):
        if not p.is_file():
            raise SceneError(f"{name_or_path}: no such scene file")
        return p
    for d in scene_dirs():
        candidate = d / f"{name_or_path}.yaml"
        if candidate.is_file():
            return candidate
    raise SceneError(f"unknown scene {name_or_path!r}; available: {', '.join(available_scenes())}")


def load_scene(name_or_path: str) -> Scene:
    """Load and validate a scene by name (``hanging``) or path."""
    path = find_scene(name_or_path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise SceneError(f"{path}: not valid YAML: {e}") from None
    return scene_from_dict(data, source=str(path), name=path.stem)


def scene_from_dict(data, source: str = "<dict>", name: str = "scene") -> Scene:
    """Validate a scene mapping; errors name ``source`` and the field. Every value is checked
    against :data:`cloth_sim.parameters.SCHEMA` (the field's ``scene_key``), so a scene accepts
    exactly what the node's parameters accept."""
    v = _Validator(source)
    if not isinstance(data, dict):
        v.fail("(top level)", "a mapping of scene fields", data)
    known = {"name", "grid", "model", "particle_mass", "stiffness", "damping", "pinned",
             "pinned_edges", "gravity", "wind", "drag", "strain_limit", "integrator", "dt"}
    v.known("", data, known)
    grid = data.get("grid")
    if not isinstance(grid, dict):
        v.fail("grid", "a mapping with rows, cols, spacing", grid)
    v.known("grid.", grid, {"rows", "cols", "spacing", "orientation"})
    s = Scene(name=str(data.get("name", name)), source=source,
              rows=v.param("rows", grid.get("rows")), cols=v.param("cols", grid.get("cols")),
              spacing=v.param("spacing", grid.get("spacing")),
              orientation=v.choice("grid.orientation", grid.get("orientation", "horizontal"),
                                   ORIENTATIONS))
    s.model = v.param("model", data.get("model", "provot"))
    s.particle_mass = v.param("particle_mass", data.get("particle_mass", s.particle_mass))
    s.stiffness = v.families("stiffness", data.get("stiffness", s.stiffness))
    s.damping = v.families("damping", data.get("damping", s.damping))
    pins = data.get("pinned", [])
    if not isinstance(pins, list):
        v.fail("pinned", "a list of [row, col] pairs", pins)
    for i, p in enumerate(pins):
        if not (isinstance(p, (list, tuple)) and len(p) == 2 and all(
                isinstance(q, int) and not isinstance(q, bool) for q in p)):
            v.fail(f"pinned[{i}]", "a [row, col] pair of integers", p)
        if not (-s.rows <= p[0] < s.rows and -s.cols <= p[1] < s.cols):
            v.fail(f"pinned[{i}]", f"a cell inside the {s.rows}×{s.cols} grid", p)
    edges = data.get("pinned_edges", [])
    if not isinstance(edges, list):
        v.fail("pinned_edges", f"a list of {', '.join(EDGES)}", edges)
    for i, e in enumerate(edges):
        v.choice(f"pinned_edges[{i}]", e, EDGES)
    s.pinned = [tuple(p) for p in pins] + list(edges)
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
    s.integrator = v.param("integrator", data.get("integrator", s.integrator))
    s.dt = v.param("dt", data.get("dt", s.dt))
    return s


class _Validator:
    def __init__(self, source):
        self.source = source

    def fail(self, fld, expected, got):
        raise SceneError(f"{self.source}: field '{fld}' must be {expected}, got {_short(got)}")

    def known(self, prefix, mapping, keys):
        unknown = sorted(str(k) for k in mapping if k not in keys)
        if unknown:
            raise SceneError(f"{self.source}: unknown field(s) {prefix}{(', ' + prefix).join(unknown)}; "
                             f"expected {', '.join(sorted(keys))}")

    def param(self, name, x):
        """``x`` checked against the schema's entry ``name``, reported under its scene key."""
        spec = SCHEMA[name]
        try:
            return spec.check(x, field=spec.scene_key)
        except ParameterError as e:
            self.fail(e.name, e.accepted, x)

    def choice(self, fld, x, options):
        if x not in options:
            self.fail(fld, f"one of {', '.join(options)}", x)
        return x

    def families(self, fld, x):
        if isinstance(x, (int, float)) and not isinstance(x, bool):
            x = {f: x for f in GRID_FAMILIES}
        if not isinstance(x, dict):
            self.fail(fld, f"a mapping of {', '.join(GRID_FAMILIES)} to numbers >= 0", x)
        unknown = sorted(str(k) for k in x if k not in GRID_FAMILIES)
        if unknown:
            self.fail(fld, f"keyed by {', '.join(GRID_FAMILIES)}", unknown)
        return {f: self.param(f"{fld}.{f}", x.get(f, 0.0)) for f in GRID_FAMILIES}


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
