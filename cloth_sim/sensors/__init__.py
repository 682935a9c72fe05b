"""Sensors that look at the simulation: the depth camera (:mod:`.camera`).

``from cloth_sim.sensors import DepthCamera`` is its public name."""

from .camera import DepthCamera, Frame, camera_from_settings, look_at_orientation

__all__ = ["DepthCamera", "Frame", "camera_from_settings", "look_at_orientation"]
