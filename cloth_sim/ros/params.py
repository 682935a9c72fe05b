"""The node's parameters: ROS descriptors made from :data:`cloth_sim.parameters.SCHEMA`, and the
values a scene implies. The bounds live in the schema only."""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from ..constraints import DEFAULT_STRAIN_LIMIT_PASSES
from ..model import GRID_FAMILIES
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
        "model": scene.model, "thickness": float(scene.thickness),
        "self_collision": bool(scene.self_collision),
    }
    for f in GRID_FAMILIES:
        values[f"stiffness.{f}"] = float(scene.stiffness[f])
        values[f"damping.{f}"] = float(scene.damping[f])
    return values


def defaults(scene: Scene) -> dict:
    values = {"scene": scene.name, "allow_unstable": False, "publish_rate": 60.0, "frame_id": "cloth",
              "publish_clock": False, "real_time_factor": 1.0,
              "strain_limit_passes": DEFAULT_STRAIN_LIMIT_PASSES}
    values.update(scene_values(scene))
    return values
