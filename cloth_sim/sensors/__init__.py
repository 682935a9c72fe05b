"""Sensors that look at the simulation: the depth camera (:mod:`.camera`).

``from cloth_sim.sensors import DepthCamera`` is its public name (imported when first used)."""

from ..lazy import exports

_NAMES = {
    "DepthCamera": ".camera",
    "Frame": ".camera",
    "camera_from_settings": ".camera",
    "look_at_orientation": ".camera",
}
__all__ = sorted(_NAMES)
__getattr__, __dir__ = exports(__name__, _NAMES)
