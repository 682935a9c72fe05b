"""Byte-exact CDR for the messages a headless run writes into its bag, with no ROS import.

rclpy's ``serialize_message`` leaves the padding bytes CDR inserts before an aligned field
uninitialised (a ``PointField``'s ``uint8 datatype`` is followed by three bytes of whatever was in
memory), so the same message can serialise to different bytes. A sweep promises that a run's files
depend on its values alone, so its bags are written by this module: little-endian plain CDR
(XCDR1, what rmw_fastrtps sends), padding zero, every field in its ``.msg`` order. Tests check each
message against rclpy's deserialiser and an independent one (rosbags).
"""

from __future__ import annotations

import struct
import sys

import numpy as np

from ..tick_stats import TickStats

_HEADER = b"\x00\x01\x00\x00"  # CDR_LE, no options


class CdrWriter:
    """Appends fields; alignment is counted from the end of the 4-byte encapsulation header."""

    def __init__(self):
        self._parts: list = [_HEADER]
        self._n = 0

    def _put(self, data, align: int) -> None:
        pad = -self._n % align
        if pad:
            self._parts.append(b"\x00" * pad)
            self._n += pad
        self._parts.append(data)
        self._n += len(data)

    def u8(self, v: int) -> None:
        self._put(struct.pack("<B", v), 1)

    def boolean(self, v: bool) -> None:
        self.u8(1 if v else 0)

    def u32(self, v: int) -> None:
        self._put(struct.pack("<I", v), 4)

    def i32(self, v: int) -> None:
        self._put(struct.pack("<i", v), 4)

    def u64(self, v: int) -> None:
        self._put(struct.pack("<Q", v), 8)

    def f64(self, v: float) -> None:
        self._put(struct.pack("<d", v), 8)

    def string(self, s: str) -> None:
        data = s.encode() + b"\x00"
        self.u32(len(data))
        self._put(data, 1)

    def octets(self, buffer) -> None:
        """A ``uint8[]``: its length and the bytes of ``buffer`` (any contiguous buffer)."""
        view = memoryview(buffer).cast("B")
        self.u32(len(view))
        self._put(view, 1)

    def f64_array(self, values, sequence: bool) -> None:
        """``float64[N]`` (``sequence=False``) or ``float64[]``."""
        a = np.ascontiguousarray(values, dtype="<f8")
        if sequence:
            self.u32(len(a))
        if len(a):
            self._put(a.tobytes(), 8)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        """``std_msgs/Header``: ``builtin_interfaces/Time`` (int32 sec, uint32 nanosec) and the
        frame."""
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        self.i32(sec)
        self.u32(nanosec)
        self.string(frame_id)

    def getvalue(self) -> bytes:
        return b"".join(self._parts)


#: sensor_msgs/PointField.FLOAT32
_FLOAT32 = 7


def point_cloud(
    positions: np.ndarray, rows: int, cols: int, frame_id: str, stamp_ns: int
) -> bytes:
    """``sensor_msgs/PointCloud2``: ``rows`` × ``cols`` float32 x y z (what the node's ``~/points``
    and ``~/camera/points`` carry)."""
    pts = np.ascontiguousarray(positions, dtype=np.float32)
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.u32(rows)
    w.u32(cols)
    w.u32(3)
    for i, name in enumerate("xyz"):
        w.string(name)
        w.u32(4 * i)
        w.u8(_FLOAT32)
        w.u32(1)
    w.boolean(sys.byteorder == "big")
    w.u32(12)
    w.u32(12 * cols)
    w.octets(pts)
    w.boolean(bool(np.isfinite(pts).all()))
    return w.getvalue()


def image(values: np.ndarray, encoding: str, frame_id: str, stamp_ns: int) -> bytes:
    """``sensor_msgs/Image`` of a 2-D array (``32FC1``, ``16SC1``, ``32SC1``)."""
    a = np.ascontiguousarray(values)
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.u32(a.shape[0])
    w.u32(a.shape[1])
    w.string(encoding)
    w.u8(1 if sys.byteorder == "big" else 0)
    w.u32(a.shape[1] * a.itemsize)
    w.octets(a)
    return w.getvalue()


def camera_info(camera, frame_id: str, stamp_ns: int) -> bytes:
    """``sensor_msgs/CameraInfo`` of a :class:`~cloth_sim.sensors.camera.DepthCamera` (pinhole, no
    distortion: ``plumb_bob`` with zeros, ``P = [K | 0]``), as the node publishes it."""
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.u32(camera.height)
    w.u32(camera.width)
    w.string("plumb_bob")
    w.f64_array([0.0] * 5, sequence=True)
    w.f64_array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], sequence=False)
    w.f64_array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], sequence=False)
    w.f64_array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0], sequence=False)
    w.u32(0)  # binning_x
    w.u32(0)  # binning_y
    for _ in range(4):  # roi: x_offset, y_offset, height, width (all zero: the whole image)
        w.u32(0)
    w.boolean(False)  # roi.do_rectify
    return w.getvalue()


def stats(stamp_ns: int, frame_id: str, s: TickStats) -> bytes:
    """``cloth_sim/msg/Stats`` (msg/Stats.msg), field for field from ``s``."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.string(s.integrator)
    w.f64(s.dt)
    w.u32(s.steps)
    for v in (
        s.step_time_mean,
        s.step_time_max,
        s.tick_wall_time,
        s.real_time_factor,
        s.sim_time,
        s.kinetic_energy,
        s.potential_energy,
        s.max_strain,
    ):
        w.f64(v)
    w.u64(s.overruns)
    w.f64(s.stability_margin)
    w.boolean(s.paused)
    w.u32(s.solver_iterations)
    w.f64(s.solver_residual)
    w.boolean(s.solver_converged)
    return w.getvalue()
