"""TF: the node's frames on ``/tf_static`` and ``/tf`` (``tf2_msgs/TFMessage``).

* ``/tf_static`` (transient local, as tf2's static broadcaster): ``world_frame_id`` → ``frame_id``,
  the identity — the simulation's frame placed in the world — again whenever either name changes;
* ``/tf``: each collider and gripper in ``frame_id`` (``<frame_id>/collider/<name>``,
  ``<frame_id>/gripper/<name>``) and the depth camera's optical frame
  (``<frame_id>/camera_optical``),
  every tick while ``/tf`` has a subscriber.

The messages are built by :func:`cloth_sim.ros.messages.transform` and
:func:`~cloth_sim.ros.messages.entity_frames`.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from . import interface, messages

#: tf2's static broadcaster's profile: late joiners get the last message
STATIC_QOS = QoSProfile(
    depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)


class Frames:
    """The node's TF publishers."""

    def __init__(self, node):
        self.node = node
        self.static_pub = interface.publisher(node, "tf_static", TFMessage, STATIC_QOS)
        self.pub = interface.publisher(node, "tf", TFMessage)
        self._static = None

    def publish_static(self, world: str, frame: str) -> None:
        """``world`` → ``frame`` (identity) on ``/tf_static``, when it is new."""
        if self._static == (world, frame):
            return
        self._static = (world, frame)
        t = messages.transform(
            world,
            frame,
            (0.0, 0.0, 0.0),
            (1.0, 0.0, 0.0, 0.0),
            self.node.get_clock().now().to_msg(),
        )
        self.static_pub.publish(TFMessage(transforms=[t]))

    def publish(self, sim, frame: str, stamp, camera=None) -> None:
        """The colliders' and grippers' frames, and ``camera``'s optical frame (a
        :class:`~cloth_sim.ros.camera_publisher.CameraPublisher`), on ``/tf`` — built only while
        someone listens."""
        if self.pub.get_subscription_count() == 0:
            return
        transforms = messages.entity_frames(sim, frame, stamp)
        if camera is not None:
            transforms += camera.transforms(stamp)
        if transforms:
            self.pub.publish(TFMessage(transforms=transforms))
