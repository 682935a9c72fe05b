"""The depth camera on the ROS side: renders :class:`cloth_sim.sensors.camera.DepthCamera` from the
node's ``camera.*`` parameters at ``camera.rate`` (wall time, its own timer), only while one of its
topics has a subscriber, and publishes, stamped like every message of the node, in the optical
frame ``<frame_id>/camera_optical`` (on ``/tf`` via :mod:`cloth_sim.ros.frames`):

* ``~/camera/depth/image`` — ``sensor_msgs/Image`` ``32FC1``, metres, NaN where nothing is in range
  (REP 118);
* ``~/camera/depth/camera_info`` — the pinhole intrinsics, no distortion;
* ``~/camera/points`` — an organised ``PointCloud2`` (height × width, float32 x y z, NaN where the
  image is): what ``depth_image_proc/point_cloud_xyz`` makes of the image;
* ``~/camera/labels`` — ``16SC1``: −1 nothing, 0 the cloth, 1 + i collider i (the ground truth),
  and ``~/camera/triangles`` — ``32SC1``: the cloth triangle each pixel sees, −1 elsewhere.
"""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from ..sensors.camera import camera_from_settings

# the checks are the core's (the sweeps use them too)
from ..settings import CAMERA_SETTINGS as SETTINGS  # noqa: E402
from ..settings import camera_reason as check  # noqa: E402
from ..settings import camera_settings as settings  # noqa: E402
from . import interface, messages

__all__ = ["SETTINGS", "CameraPublisher", "check", "settings"]


class CameraPublisher:
    """The camera's topics and timer on ``node``."""

    def __init__(self, node, session, stamp):
        self.node, self.session, self.stamp = node, session, stamp
        self.image_pub = interface.publisher(node, "camera_image", Image)
        self.info_pub = interface.publisher(node, "camera_info", CameraInfo)
        self.points_pub = interface.publisher(node, "camera_points", PointCloud2)
        self.labels_pub = interface.publisher(node, "camera_labels", Image)
        self.triangles_pub = interface.publisher(node, "camera_triangles", Image)
        self.camera = None
        self.timer = None
        self.frames = 0
        self._points = None  # the cloud's buffer, reused frame to frame
        self._settings = None
        self.configure(session.cfg)

    def optical_frame(self) -> str:
        return f"{self.session.cfg['frame_id']}/camera_optical"

    def transforms(self, stamp) -> list:
        """The optical frame in ``frame_id``, for ``/tf`` (none while the camera is off)."""
        if self.camera is None:
            return []
        return [
            messages.transform(
                self.session.cfg["frame_id"],
                self.optical_frame(),
                self.camera.position,
                self.camera.orientation,
                stamp,
            )
        ]

    def configure(self, cfg: dict) -> None:
        """Build the camera from ``cfg`` (already checked by :func:`check`) and time it; off when
        ``camera.enable`` is false. A first tiny render compiles or loads the kernels, here rather
        than in a tick."""
        new = settings(cfg)
        if new == self._settings:
            return
        self._settings = new
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None
        self.camera = camera_from_settings(new) if new["enable"] else None
        if self.camera is not None:
            # compiled (or loaded) for any size by a tiny image: a 4096² one would hold up the
            # parameter answer
            camera_from_settings({**new, "width": 4, "height": 3}).render(self.session.sim)
            self.timer = self.node.create_timer(1.0 / float(new["rate"]), self._on_timer)

    def _subscribed(self) -> bool:
        return any(
            p.get_subscription_count() > 0
            for p in (
                self.image_pub,
                self.info_pub,
                self.points_pub,
                self.labels_pub,
                self.triangles_pub,
            )
        )

    def _on_timer(self) -> None:
        if self.camera is None or not self._subscribed():
            return
        frame = self.camera.render(self.session.sim)
        stamp, optical = self.stamp(), self.optical_frame()
        self.frames += 1
        # serialised here with one copy of the pixels (messages.image_bytes): at 640×480 and 30 Hz
        # building message objects cost the node a third of its time
        if self.image_pub.get_subscription_count():
            self.image_pub.publish(messages.image_bytes(frame.depth, "32FC1", optical, stamp))
        if self.info_pub.get_subscription_count():
            self.info_pub.publish(messages.camera_info(self.camera, optical, stamp))
        if self.points_pub.get_subscription_count():
            h, w = frame.depth.shape
            if self._points is None or self._points.shape != (h, w, 3):
                self._points = np.empty((h, w, 3), np.float32)
            frame.points(out=self._points)
            dense = not np.isnan(frame.depth).any()
            self.points_pub.publish(
                messages.point_cloud_bytes(self._points, optical, stamp, dense)
            )
        if self.labels_pub.get_subscription_count():
            self.labels_pub.publish(messages.image_bytes(frame.object, "16SC1", optical, stamp))
        if self.triangles_pub.get_subscription_count():
            self.triangles_pub.publish(
                messages.image_bytes(frame.triangle, "32SC1", optical, stamp)
            )
