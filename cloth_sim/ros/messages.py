"""The node's messages as pure functions of the simulation's numbers: testable without a ROS graph."""

from __future__ import annotations

import array
import math
import sys

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

FIELDS = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
          for i, n in enumerate("xyz")]


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
    in (``geometry_msgs/Point`` is three little-endian float64, 24 bytes, so every later field keeps
    its alignment). 0.3 ms at 32×32 where building and serialising the Point list took 70 ms."""
    from rclpy.serialization import serialize_message

    template = serialize_message(mesh(_PROBE, np.zeros((1, 1), dtype=np.int64), frame_id, stamp))
    at = template.find(_PROBE.astype("<f8").tobytes())
    if at < 4 or template[at - 4:at] != (1).to_bytes(4, "little"):
        raise RuntimeError("unexpected Marker serialisation")  # not little-endian CDR
    points = np.ascontiguousarray(positions[triangles.ravel()], dtype="<f8")
    return b"".join((template[:at - 4], len(points).to_bytes(4, "little"), points.tobytes(),
                     template[at + 24:]))


def stability_margin(dt: float, stable_dt: float | None) -> float:
    """``dt / stable_dt``: 0 for an unconditionally stable method (or an unknown limit), inf when no
    step is stable."""
    if stable_dt is None or math.isinf(stable_dt):
        return 0.0
    return dt / stable_dt if stable_dt > 0 else math.inf


def stats(Stats, *, stamp, frame_id: str, integrator: str, dt: float, steps: int, step_wall: float,
          step_max: float, tick_wall: float, rtf: float, sim_time: float, energy: dict,
          max_strain: float, overruns: int, stable_dt: float | None, paused: bool):
    """The package's ``Stats`` message (``Stats`` is the generated type)."""
    msg = Stats()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.integrator = integrator
    msg.dt = dt
    msg.steps = steps
    msg.step_time_mean = step_wall / steps if steps else 0.0
    msg.step_time_max = step_max
    msg.tick_wall_time = tick_wall
    msg.real_time_factor = rtf
    msg.sim_time = sim_time
    msg.kinetic_energy = energy["kinetic"]
    msg.potential_energy = energy["spring"] + energy["gravity"]
    msg.max_strain = max_strain
    msg.overruns = overruns
    msg.stability_margin = stability_margin(dt, stable_dt)
    msg.paused = paused
    return msg


def diagnostic_status(*, error: str | None, paused: bool, rtf: float, rtf_known: bool,
                      rtf_warn: float, dt: float, stable_dt: float | None, warn_margin: float,
                      values: dict) -> DiagnosticStatus:
    """``cloth_sim: simulation``: ERROR after a blow-up, WARN when the real-time factor is below
    ``rtf_warn`` (while running) or dt is above ``warn_margin`` of stable_dt, OK otherwise."""
    level, message = DiagnosticStatus.OK, "running"
    if error:
        level, message = DiagnosticStatus.ERROR, f"simulation diverged and is paused: {error}"
    else:
        problems = []
        if not paused and rtf_known and rtf < rtf_warn:
            problems.append(f"real-time factor {rtf:.2f} < 1")
        if stable_dt is not None and math.isfinite(stable_dt) and dt > warn_margin * stable_dt:
            problems.append(f"dt={dt:g} s is above {warn_margin:.0%} of stable_dt={stable_dt:.4g} s")
        if problems:
            level, message = DiagnosticStatus.WARN, "; ".join(problems)
        elif paused:
            message = "paused"
    return DiagnosticStatus(level=level, name="cloth_sim: simulation", message=message,
                            hardware_id="cloth_sim",
                            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])


def diagnostic_array(status: DiagnosticStatus, stamp) -> DiagnosticArray:
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = [status]
    return msg
