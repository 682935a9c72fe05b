"""The node's parameters: ROS descriptors made from :data:`cloth_sim.parameters.SCHEMA`, and the
values a scene implies. The bounds live in the schema only."""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from ..constraints import DEFAULT_STRAIN_LIMIT_PASSES
from ..parameters import SCHEMA, Param, ParameterError
from ..scene import Scene

_TYPES = {float: ParameterType.PARAMETER_DOUBLE, int: ParameterType.PARAMETER_INTEGER,
          str: ParameterType.PARAMETER_STRING, bool: ParameterType.PARAMETER_BOOL,
          "vector3": ParameterType.PARAMETER_DOUBLE_ARRAY}


def type_name(spec: Param) -> str:
    return {float: "double", int: "integer", str: "string", bool: "bool",
            "vector3": "double array"}[spec.type]


def descriptor(spec: Param) -> ParameterDescriptor:
    """``ros2 param describe``: description with unit and how it applies, the range, the choices."""
    how = {"live": "live", "rebuild": "rebuilds the cloth and resets it",
           "node": "the node's own setting"}[spec.apply]
    unit = f" Unit: {spec.unit}." if spec.unit else ""
    d = ParameterDescriptor(name=spec.name, type=_TYPES[spec.type],
                            description=f"{spec.description}{unit} ({how})",
                            additional_constraints=spec.range_text())
    if spec.type is float:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.lo),
                                                     to_value=float(spec.hi), step=0.0)]
    elif spec.type is int:
        d.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=1)]
    return d


def check_value(name: str, value):
    """``(canonical value, None)``, or ``(None, reason)`` naming the parameter, the value and the
    accepted range."""
    try:
        return SCHEMA[name].check(value), None
    except ParameterError as e:
        return None, str(e)


#: the parameters that shape a grid only, and a mesh only: a scene of the other kind refuses a change
GRID_ONLY = ("rows", "cols", "spacing", "particle_mass", "stiffness.shear", "damping.shear")
MESH_ONLY = ("density",)
#: what those parameters hold while the scene does not use them (start-up on a scene of the other
#: kind; they keep their values across scene changes)
UNUSED_VALUES = {"rows": 32, "cols": 32, "spacing": 1.0 / 31, "particle_mass": 0.01,
                 "stiffness.shear": 0.0, "damping.shear": 0.0, "density": 0.1}


def scene_values(scene: Scene) -> dict:
    """The parameter values a scene implies (a grid's size and mass or a mesh's density; the
    parameters of the other kind are left out)."""
    values = {
        "integrator": scene.integrator, "dt": float(scene.dt),
        "gravity": [float(g) for g in scene.gravity],
        "wind.direction": [float(w) for w in scene.wind_direction],
        "wind.strength": float(scene.wind_strength), "drag": float(scene.drag),
        "strain_limit": float(scene.strain_limit or 0.0),
        "model": scene.model, "thickness": float(scene.thickness),
        "self_collision": bool(scene.self_collision),
    }
    if scene.mesh is not None:
        values["density"] = float(scene.mesh["density"])
    else:
        values.update({"rows": int(scene.rows), "cols": int(scene.cols),
                       "spacing": float(scene.spacing), "particle_mass": float(scene.particle_mass)})
    for k, value in scene.camera.items():  # (the scene's camera, or the default one)
        values[f"camera.{k}"] = [float(x) for x in value] if isinstance(value, list) else value
    for f in scene.families:
        values[f"stiffness.{f}"] = float(scene.stiffness[f])
        values[f"damping.{f}"] = float(scene.damping[f])
    return values


def not_applicable(scene: Scene, cand: dict, current: dict) -> str | None:
    """The reason to refuse a change of a parameter ``scene``'s cloth does not have (a grid's size
    on a mesh, a mesh's density on a grid), ``None`` when there is none."""
    names = GRID_ONLY if scene.mesh is not None else MESH_ONLY
    changed = [n for n in names if cand[n] != current[n]]
    if not changed:
        return None
    if scene.mesh is not None:
        return (f"{', '.join(changed)}: not used by scene {scene.name}, a triangle mesh "
                f"({scene.mesh['file'].name}): its particles are the mesh's vertices, its masses come "
                f"from density (kg/m²) and its springs are structural (edges) and bend (across edges), "
                f"no shear")
    return (f"{', '.join(changed)}: not used by scene {scene.name}, a {scene.rows}×{scene.cols} grid "
            f"(its masses come from particle_mass); density applies to mesh scenes")


def defaults(scene: Scene) -> dict:
    values = {"scene": scene.name, "allow_unstable": False, "publish_rate": 60.0, "frame_id": "cloth",
              "world_frame_id": "world",
              "publish_clock": False, "real_time_factor": 1.0,
              "strain_limit_passes": DEFAULT_STRAIN_LIMIT_PASSES}
    values.update(UNUSED_VALUES)
    values.update(scene_values(scene))
    return values
