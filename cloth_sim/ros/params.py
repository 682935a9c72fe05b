"""The node's parameters: names, descriptors, defaults from a scene, and validation of a batch.

Kept free of node state so the rules are easy to read and to test: :func:`validate` takes the
current values and a batch of changes and returns the reason to refuse it, or ``None``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from .. import integrators
from ..model import GRID_FAMILIES, MODELS
from ..scene import Scene, SceneError, load_scene

MAX_PUBLISH_RATE = 1000.0
MAX_GRID = 512
STIFFNESS_MAX = 1e9
DAMPING_MAX = 1e6

#: parameters whose change rebuilds the cloth and resets it
TOPOLOGY = ("scene", "rows", "cols", "spacing", "model", "particle_mass")


@dataclass(frozen=True)
class Spec:
    name: str
    type: int
    description: str
    lo: float | None = None
    hi: float | None = None
    read_only: bool = False
    constraints: str = ""

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, type=self.type, description=self.description,
                                read_only=self.read_only, additional_constraints=self.constraints)
        if self.lo is not None and self.type == ParameterType.PARAMETER_DOUBLE:
            d.floating_point_range = [FloatingPointRange(from_value=float(self.lo),
                                                         to_value=float(self.hi), step=0.0)]
        elif self.lo is not None and self.type == ParameterType.PARAMETER_INTEGER:
            d.integer_range = [IntegerRange(from_value=int(self.lo), to_value=int(self.hi), step=1)]
        return d


D, I, S, B, DA = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_INTEGER,
                  ParameterType.PARAMETER_STRING, ParameterType.PARAMETER_BOOL,
                  ParameterType.PARAMETER_DOUBLE_ARRAY)

SPECS = [
    Spec("scene", S, "Scene name (hanging, curtain, flag, free_fall) or path to a scene YAML file. "
         "Changing it rebuilds the cloth from that scene, its parameters included, and resets it."),
    Spec("integrator", S, "Time integrator; switching keeps positions and velocities.",
         constraints="one of: " + ", ".join(integrators.available())),
    Spec("dt", D, "Simulation time step (s). Explicit methods refuse a dt above their stable_dt "
         "unless allow_unstable is true.", 1e-7, 1.0),
    Spec("allow_unstable", B, "Accept a dt above the explicit method's stable_dt."),
    Spec("publish_rate", D, "Ticks per second: each tick advances 1/publish_rate of simulated time "
         "in whole steps of dt and publishes.", 0.1, MAX_PUBLISH_RATE),
    *[Spec(f"stiffness.{f}", D, f"Spring stiffness of the {f} springs (N/m); live.", 0.0, STIFFNESS_MAX)
      for f in GRID_FAMILIES],
    *[Spec(f"damping.{f}", D, f"Damping along the {f} springs (N·s/m); live.", 0.0, DAMPING_MAX)
      for f in GRID_FAMILIES],
    Spec("particle_mass", D, "Mass of each particle (kg); rebuilds and resets the cloth.", 1e-6, 1e3),
    Spec("gravity", DA, "Gravity acceleration [x, y, z] (m/s²); live.",
         constraints="3 finite numbers"),
    Spec("wind.direction", DA, "Wind direction [x, y, z]; particle i feels strength·(n_i·d) n_i.",
         constraints="3 finite numbers"),
    Spec("wind.strength", D, "Wind strength w (N per unit of normal projection); 0 turns wind off.",
         0.0, 1e3),
    Spec("drag", D, "Linear air drag per particle (N·s/m); live.", 0.0, 1e3),
    Spec("strain_limit", D, "Provot's critical deformation rate (0.1 = 10 %); 0 turns it off.", 0.0, 10.0),
    Spec("rows", I, "Particles along the grid's rows; rebuilds and resets the cloth.", 2, MAX_GRID),
    Spec("cols", I, "Particles along the grid's columns; rebuilds and resets the cloth.", 2, MAX_GRID),
    Spec("spacing", D, "Rest distance between neighbouring particles (m); rebuilds and resets.", 1e-4, 10.0),
    Spec("model", S, "Spring model; rebuilds and resets.", constraints="one of: " + ", ".join(MODELS)),
    Spec("frame_id", S, "frame_id of the published cloud, mesh and stats."),
]
SPEC = {s.name: s for s in SPECS}


def scene_values(scene: Scene) -> dict:
    """The parameter values a scene implies."""
    values = {
        "integrator": scene.integrator, "dt": float(scene.dt),
        "particle_mass": float(scene.particle_mass),
        "gravity": [float(g) for g in scene.gravity],
        "wind.direction": [float(w) for w in scene.wind_direction],
        "wind.strength": float(scene.wind_strength), "drag": float(scene.drag),
        "strain_limit": float(scene.strain_limit or 0.0),
        "rows": int(scene.rows), "cols": int(scene.cols), "spacing": float(scene.spacing),
        "model": scene.model,
    }
    for f in GRID_FAMILIES:
        values[f"stiffness.{f}"] = float(scene.stiffness[f])
        values[f"damping.{f}"] = float(scene.damping[f])
    return values


def defaults(scene: Scene) -> dict:
    values = {"scene": scene.name, "allow_unstable": False, "publish_rate": 60.0, "frame_id": "cloth"}
    values.update(scene_values(scene))
    return values


def _finite_vector(name, value) -> str | None:
    try:
        vec = [float(v) for v in value]
    except (TypeError, ValueError):
        return f"{name} must be 3 finite numbers, got {value!r}"
    if len(vec) != 3:
        return f"{name} must have exactly 3 elements [x, y, z], got {len(vec)}"
    if not all(math.isfinite(v) for v in vec):
        return f"{name} must be 3 finite numbers, got {vec}"
    return None


def check_value(name: str, value) -> str | None:
    """The reason ``value`` is not acceptable for ``name`` on its own, or ``None``."""
    spec = SPEC.get(name)
    if spec is None:
        return None
    if spec.type == DA:
        return _finite_vector(name, value)
    if spec.type == S:
        if name == "integrator" and value not in integrators.available():
            return (f"integrator {value!r} is unknown; accepted values: "
                    f"{', '.join(integrators.available())}")
        if name == "model" and value not in MODELS:
            return f"model {value!r} is unknown; accepted values: {', '.join(MODELS)}"
        if name == "frame_id" and not value:
            return "frame_id must not be empty"
        if name == "scene":
            try:
                load_scene(value)
            except SceneError as e:
                return f"scene: {e}"
        return None
    if spec.type in (D, I):
        v = float(value)
        if not math.isfinite(v):
            return f"{name} must be finite, got {value}"
        if spec.lo is not None and not (spec.lo <= v <= spec.hi):
            if name == "dt":
                return f"dt must be > 0 and <= {spec.hi:g} s, got {value}"
            if name.startswith(("stiffness.", "damping.")):
                return f"{name} must be >= 0 (and <= {spec.hi:g}), got {value}"
            return f"{name} must be in [{spec.lo:g}, {spec.hi:g}], got {value}"
    return None
