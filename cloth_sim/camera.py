"""The depth camera's public home (``from cloth_sim.camera import DepthCamera``); it lives in
:mod:`cloth_sim.sensors.camera`."""

from .sensors.camera import DepthCamera, Frame, camera_from_settings, look_at_orientation

__all__ = ["DepthCamera", "Frame", "camera_from_settings", "look_at_orientation"]
