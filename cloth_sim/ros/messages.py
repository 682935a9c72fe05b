"""The node's messages as pure functions of the simulation's numbers: testable without a ROS
graph."""

from __future__ import annotations

import array
import math
import sys
from dataclasses import fields

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Vector3
from sensor_msgs.msg import PointCloud2, PointField
from simulation_interfaces.msg import Result
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ..tick_stats import TickStats

FIELDS = [
    PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
    for i, n in enumerate("xyz")
]


def point_cloud(positions: np.ndarray, rows: int, cols: int, frame_id: str, stamp) -> PointCloud2:
    """An organised cloud (height = rows, width = cols) of float32 x y z."""
    msg = PointCloud2()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = rows, cols
    msg.fields = FIELDS
    msg.is_bigendian = sys.byteorder == "big"
    msg.point_step = 12
    msg.row_step = 12 * cols
    msg.is_dense = bool(np.all(np.isfinite(positions)))
    msg.data = array.array("B", np.ascontiguousarray(positions, dtype=np.float32).tobytes())
    return msg


def mesh(positions: np.ndarray, triangles: np.ndarray, frame_id: str, stamp) -> Marker:
    """A TRIANGLE_LIST marker of the cloth for RViz."""
    m = Marker()
    m.header.stamp = stamp
    m.header.frame_id = frame_id
    m.ns, m.id = "cloth", 0
    m.type, m.action = Marker.TRIANGLE_LIST, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 1.0
    m.color = ColorRGBA(r=0.2, g=0.5, b=0.9, a=1.0)
    m.points = [Point(x=p[0], y=p[1], z=p[2]) for p in positions[triangles.ravel()].tolist()]
    return m


#: A point no cloth has (subnormal coordinates): where the template's point data begins.
_PROBE = np.array([[3e-310, 5e-310, 7e-310]])


def mesh_bytes(positions: np.ndarray, triangles: np.ndarray, frame_id: str, stamp) -> bytes:
    """:func:`mesh` serialised (CDR, what rclpy publishes), built without a Python object per
    point: a one-point marker is serialised by rclpy as the template and the point data is spliced
    in (``geometry_msgs/Point`` is three little-endian float64, 24 bytes, so every later field
    keeps its alignment; docs/BENCHMARKS.md §7). :class:`MeshBytes` does the same with its
    buffer kept between calls (the node's ticks)."""
    return MeshBytes()(positions, triangles, frame_id, stamp)


class MeshBytes:
    """:func:`mesh_bytes` for a publisher that sends the mesh every tick: the triangles' corners
    are gathered into a buffer kept between calls and copied once, into the message's bytes (a
    fresh 2.3 MB gather and two copies took 1.1 ms a tick at 128×128, ~0.5 this way:
    docs/BENCHMARKS.md §11)."""

    def __init__(self):
        self._points = np.empty((0, 3), dtype="<f8")

    def __call__(
        self, positions: np.ndarray, triangles: np.ndarray, frame_id: str, stamp
    ) -> bytes:
        from rclpy.serialization import serialize_message

        template = serialize_message(
            mesh(_PROBE, np.zeros((1, 1), dtype=np.int64), frame_id, stamp)
        )
        at = template.find(_PROBE.astype("<f8").tobytes())
        if at < 4 or template[at - 4 : at] != (1).to_bytes(4, "little"):
            raise RuntimeError("unexpected Marker serialisation")  # not little-endian CDR
        corners = triangles.ravel()
        if self._points.shape[0] != corners.size:
            self._points = np.empty((corners.size, 3), dtype="<f8")
        np.take(np.asarray(positions, dtype="<f8"), corners, axis=0, out=self._points)
        return b"".join(
            (
                template[: at - 4],
                corners.size.to_bytes(4, "little"),
                memoryview(self._points).cast("B"),
                template[at + 24 :],
            )
        )


def stats(Stats, stamp, frame_id: str, s: TickStats):
    """The package's ``Stats`` message (``Stats`` is the generated type) of ``s``, field for
    field."""
    msg = Stats()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    for f in fields(s):
        setattr(msg, f.name, getattr(s, f.name))
    return msg


def diagnostic_status(
    *,
    error: str | None,
    paused: bool,
    rtf: float,
    rtf_known: bool,
    rtf_warn: float,
    dt: float,
    stable_dt: float | None,
    warn_margin: float,
    values: dict,
    energy: str | None = None,
    others: list | None = None,
) -> DiagnosticStatus:
    """``cloth_sim: simulation``: ERROR after a blow-up, WARN when the real-time factor is below
    ``rtf_warn`` (while running; 0 when the node runs as fast as it can), dt is above
    ``warn_margin`` of stable_dt, ``energy`` says the energy balance found energy no source put
    in (:mod:`cloth_sim.physics.energy_balance`), or ``others`` has problems of the node's parts
    (a robot's stale joint states), OK otherwise."""
    level, message = DiagnosticStatus.OK, "running"
    if error:
        level, message = DiagnosticStatus.ERROR, f"simulation diverged and is paused: {error}"
    else:
        problems = []
        if not paused and rtf_known and rtf < rtf_warn:
            problems.append(f"real-time factor {rtf:.2f} below the target")
        if stable_dt is not None and math.isfinite(stable_dt) and dt > warn_margin * stable_dt:
            problems.append(
                f"dt={dt:g} s is above {warn_margin:.0%} of stable_dt={stable_dt:.4g} s"
            )
        if energy:
            problems.append(energy)
        problems.extend(others or ())
        if problems:
            level, message = DiagnosticStatus.WARN, "; ".join(problems)
        elif paused:
            message = "paused"
    return DiagnosticStatus(
        level=level,
        name="cloth_sim: simulation",
        message=message,
        hardware_id="cloth_sim",
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
    )


def diagnostic_array(status: DiagnosticStatus, stamp) -> DiagnosticArray:
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = [status]
    return msg


def _quaternion_between(a, b):
    """(w, x, y, z) turning unit vector ``a`` onto unit vector ``b``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    c = float(a @ b)
    if c < -1 + 1e-12:  # opposite: half a turn about any perpendicular axis
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return (0.0, *axis)
    axis = np.cross(a, b)
    q = np.array([1.0 + c, *axis])
    return tuple(q / np.linalg.norm(q))


#: how far a plane's marker reaches either way (m): RViz draws no infinite planes
PLANE_EXTENT = 5.0


def collider_markers(colliders, frame_id: str, stamp, grippers=None) -> MarkerArray:
    """One marker per collider (two more for a capsule's end caps), ``ns`` = the collider's name:
    a plane as a thin square ``2·PLANE_EXTENT`` wide, a sphere, a box, a capsule as a cylinder and
    two spheres; and a small orange sphere per gripper (``grippers``: name -> position),
    ``ns`` = ``gripper/<name>``."""
    out = MarkerArray()
    grey = ColorRGBA(r=0.6, g=0.6, b=0.6, a=0.6)

    def marker(ns, idx, kind, position, q, scale):
        m = Marker()
        m.header.stamp = stamp
        m.header.frame_id = frame_id
        m.ns, m.id = ns, idx
        m.type, m.action = kind, Marker.ADD
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in position)
        m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z = (
            float(v) for v in q
        )
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
        m.color = grey
        out.markers.append(m)

    for c in colliders:
        kind = type(c).__name__
        if kind == "Plane":
            marker(
                c.name,
                0,
                Marker.CUBE,
                c.position,
                _quaternion_between((0, 0, 1), c.normal),
                (2 * PLANE_EXTENT, 2 * PLANE_EXTENT, 1e-3),
            )
        elif kind == "Sphere":
            marker(c.name, 0, Marker.SPHERE, c.position, (1, 0, 0, 0), [2 * c.radius] * 3)
        elif kind == "Box":
            marker(c.name, 0, Marker.CUBE, c.position, c.orientation, 2 * c.half_extents)
        elif kind == "Capsule":
            axis = c.b - c.a
            length = float(np.linalg.norm(axis))
            q = _quaternion_between((0, 0, 1), axis) if length > 0 else (1, 0, 0, 0)
            marker(c.name, 0, Marker.CYLINDER, c.position, q, (2 * c.radius, 2 * c.radius, length))
            marker(c.name, 1, Marker.SPHERE, c.a, (1, 0, 0, 0), [2 * c.radius] * 3)
            marker(c.name, 2, Marker.SPHERE, c.b, (1, 0, 0, 0), [2 * c.radius] * 3)
    for name, position in (grippers or {}).items():
        marker(f"gripper/{name}", 0, Marker.SPHERE, position, (1, 0, 0, 0), [0.03] * 3)
        out.markers[-1].color = ColorRGBA(r=1.0, g=0.5, b=0.0, a=0.9)
    return out


def wrench(force, torque, frame_id: str, stamp):
    """``geometry_msgs/WrenchStamped``: what the cloth exerts on a gripper."""
    from geometry_msgs.msg import WrenchStamped

    m = WrenchStamped()
    m.header.stamp = stamp
    m.header.frame_id = frame_id
    m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = (float(v) for v in force)
    m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = (float(v) for v in torque)
    return m


def transform(parent: str, child: str, position, orientation, stamp):
    """``geometry_msgs/TransformStamped``: ``child`` at ``position`` with ``orientation`` (w, x, y,
    z) in ``parent``."""
    from geometry_msgs.msg import TransformStamped

    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = (
        float(v) for v in position
    )
    (
        t.transform.rotation.w,
        t.transform.rotation.x,
        t.transform.rotation.y,
        t.transform.rotation.z,
    ) = (float(v) for v in orientation)
    return t


def entity_frames(sim, frame_id: str, stamp) -> list:
    """The moving frames of a simulation for ``/tf``: each collider
    (``<frame_id>/collider/<name>``)
    and each gripper (``<frame_id>/gripper/<name>``) in ``frame_id``, named as the standard's
    entities are."""
    out = [
        transform(frame_id, f"{frame_id}/collider/{c.name}", c.position, c.orientation, stamp)
        for c in sim.colliders
    ]
    for name in sim.grippers:
        p, q = sim.gripper_pose(name)
        out.append(transform(frame_id, f"{frame_id}/gripper/{name}", p, q, stamp))
    return out


def checked_pose(pose, frame: str, frames, prefix: str = ""):
    """``(position, unit quaternion (w, x, y, z), None)`` from a ``geometry_msgs/Pose`` given in
    ``frame``, or ``(None, None, problem)`` naming the field (``prefix`` + its name) and what is
    expected: a frame not in ``frames`` (the node's ``frame_id`` and its ``world_frame_id``, which
    ``/tf_static`` makes the same frame) and not empty (the standard's default), a non-finite
    position, a zero or non-finite quaternion."""
    import numpy as np

    p, q = pose.position, pose.orientation
    position = np.array([p.x, p.y, p.z])
    orientation = np.array([q.w, q.x, q.y, q.z])
    if frame and frame not in frames:
        return (
            None,
            None,
            (
                f"{prefix}header.frame_id = {frame!r}: expected "
                f"{' or '.join(repr(f) for f in dict.fromkeys(frames))} (the node's "
                f"frame_id and world_frame_id, one frame on /tf_static), or empty; the "
                f"node does not look poses up in TF"
            ),
        )
    if not np.all(np.isfinite(position)):
        return (
            None,
            None,
            f"{prefix}pose.position = {position.tolist()}: expected 3 finite numbers",
        )
    if not (np.all(np.isfinite(orientation)) and np.linalg.norm(orientation) > 1e-6):
        return (
            None,
            None,
            (
                f"{prefix}pose.orientation = {orientation.tolist()} (w, x, y, z): "
                f"expected a finite, nonzero quaternion"
            ),
        )
    return position, orientation / np.linalg.norm(orientation), None


def image(values: np.ndarray, encoding: str, frame_id: str, stamp):
    """``sensor_msgs/Image`` of a 2-D array (``32FC1`` float32 depth in metres with NaN invalid, as
    REP 118 says; ``16SC1`` and ``32SC1`` labels)."""
    a = np.ascontiguousarray(values)
    return _image(a, encoding, frame_id, stamp, array.array("B", a.tobytes()))


def _image(a: np.ndarray, encoding: str, frame_id: str, stamp, data):
    from sensor_msgs.msg import Image

    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = a.shape
    msg.encoding = encoding
    msg.is_bigendian = sys.byteorder == "big"
    msg.step = a.shape[1] * a.itemsize
    msg.data = data
    return msg


#: bytes no header or size serialises to: where a template's ``data`` begins
_DATA_PROBE = b"\xa5cloth_sim data\x5a"


def _splice(template_msg, payload) -> bytes:
    """``template_msg`` (its ``data`` set to :data:`_DATA_PROBE`) serialised with ``payload`` (a
    buffer) as its ``data``: a ``uint8[]`` is a 4-byte length and the bytes, and what follows it in
    ``Image`` (nothing) and ``PointCloud2`` (``bool is_dense``) needs no alignment, so the rest of
    the serialisation stands. One copy of the payload instead of three (array, array.array,
    CDR)."""
    from rclpy.serialization import serialize_message

    template = serialize_message(template_msg)
    at = template.rfind(_DATA_PROBE)
    if at < 4 or template[at - 4 : at] != len(_DATA_PROBE).to_bytes(4, "little"):
        raise RuntimeError("unexpected serialisation")  # not little-endian CDR
    payload = memoryview(payload).cast("B")
    return b"".join(
        (
            template[: at - 4],
            len(payload).to_bytes(4, "little"),
            payload,
            template[at + len(_DATA_PROBE) :],
        )
    )


def image_bytes(values: np.ndarray, encoding: str, frame_id: str, stamp) -> bytes:
    """:func:`image`, serialised (what rclpy publishes), built with one copy of the pixels."""
    a = np.ascontiguousarray(values)
    return _splice(_image(a, encoding, frame_id, stamp, _DATA_PROBE), a)


def point_cloud_bytes(points: np.ndarray, frame_id: str, stamp, dense: bool) -> bytes:
    """:func:`point_cloud` of an organised ``(H, W, 3)`` float32 C-contiguous array, serialised,
    built with one copy of the points; ``dense``: no point is NaN (the caller knows it from the
    image, cheaper than scanning the cloud)."""
    h, w, _ = points.shape
    msg = point_cloud(np.zeros((0, 3), np.float32), h, w, frame_id, stamp)
    msg.is_dense = bool(dense)
    msg.data = _DATA_PROBE
    return _splice(msg, points)


def camera_info(camera, frame_id: str, stamp):
    """``sensor_msgs/CameraInfo`` of a :class:`~cloth_sim.sensors.camera.DepthCamera`: pinhole, no
    distortion (``plumb_bob`` with zeros), ``P = [K | 0]``."""
    from sensor_msgs.msg import CameraInfo

    msg = CameraInfo()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.width, msg.height = camera.width, camera.height
    msg.distortion_model = "plumb_bob"
    msg.d = [0.0] * 5
    msg.k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return msg


def result(code: int = Result.RESULT_OK, message: str = "") -> Result:
    """The ROS simulation standard's result: ``code`` and the message that explains it."""
    return Result(result=code, error_message=message)


def vector(a) -> Vector3:
    return Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2]))
