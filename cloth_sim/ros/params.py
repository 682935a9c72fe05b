"""The node's parameters: ROS descriptors made from :data:`cloth_sim.parameters.SCHEMA`, and the
node's defaults. The bounds live in the schema only."""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from ..parameters import SCHEMA, Param, ParameterError

_TYPES = {
    float: ParameterType.PARAMETER_DOUBLE,
    int: ParameterType.PARAMETER_INTEGER,
    str: ParameterType.PARAMETER_STRING,
    bool: ParameterType.PARAMETER_BOOL,
    "vector2": ParameterType.PARAMETER_DOUBLE_ARRAY,
    "vector3": ParameterType.PARAMETER_DOUBLE_ARRAY,
}


def type_name(spec: Param) -> str:
    return {
        float: "double",
        int: "integer",
        str: "string",
        bool: "bool",
        "vector2": "double array",
        "vector3": "double array",
    }[spec.type]


def descriptor(spec: Param) -> ParameterDescriptor:
    """``ros2 param describe``: description with unit and how it applies, the range, the
    choices."""
    how = {
        "live": "live",
        "rebuild": "rebuilds the cloth and resets it",
        "node": "the node's own setting",
    }[spec.apply]
    unit = f" Unit: {spec.unit}." if spec.unit else ""
    d = ParameterDescriptor(
        name=spec.name,
        type=_TYPES[spec.type],
        description=f"{spec.description}{unit} ({how})",
        additional_constraints=spec.range_text(),
    )
    if spec.type is float:
        d.floating_point_range = [
            FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi), step=0.0)
        ]
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


# the plain-value parts live in the core (the sweeps use them too)
from ..settings import defaults  # noqa: E402

__all__ = ["check_value", "defaults", "descriptor", "type_name"]
