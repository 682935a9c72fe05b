"""``sensor_msgs/PointCloud2`` read back from a bag's CDR bytes with no ROS import: the x, y, z
fields of any cloud (organised or not, float32 or float64), its stamp, as numpy."""

from __future__ import annotations

import struct

import numpy as np

from .store import BagError, iter_messages

POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
#: sensor_msgs/PointField datatypes this reader takes for x, y, z
_FLOATS = {7: "f4", 8: "f8"}


class _Reader:
    """Little- or big-endian plain CDR; alignment counted after the 4-byte encapsulation."""

    def __init__(self, data: bytes):
        if len(data) < 4 or data[1] not in (0, 1):
            raise ValueError("not a CDR message (bad encapsulation header)")
        self.data, self.pos = data, 4
        self.e = "<" if data[1] == 1 else ">"

    def _align(self, n: int) -> None:
        self.pos += -(self.pos - 4) % n

    def _take(self, fmt: str, size: int):
        self._align(size)
        if self.pos + size > len(self.data):
            raise ValueError("truncated message")
        v = struct.unpack_from(self.e + fmt, self.data, self.pos)[0]
        self.pos += size
        return v

    def u8(self) -> int:
        return self._take("B", 1)

    def u32(self) -> int:
        return self._take("I", 4)

    def i32(self) -> int:
        return self._take("i", 4)

    def string(self) -> str:
        n = self.u32()
        if self.pos + n > len(self.data):
            raise ValueError("truncated string")
        s = self.data[self.pos : self.pos + n - 1].decode()
        self.pos += n
        return s

    def octets(self) -> bytes:
        n = self.u32()
        if self.pos + n > len(self.data):
            raise ValueError("truncated data")
        b = self.data[self.pos : self.pos + n]
        self.pos += n
        return b


def decode_point_cloud(data: bytes) -> tuple[int, np.ndarray]:
    """``(stamp ns, points (n, 3) float64)`` of a CDR ``PointCloud2``: its x, y, z fields, the
    points with a non-finite coordinate left out (a depth camera's holes)."""
    r = _Reader(data)
    sec, nsec = r.i32(), r.u32()
    r.string()  # frame_id
    height, width = r.u32(), r.u32()
    fields = {}
    for _ in range(r.u32()):
        name, offset, datatype, count = r.string(), r.u32(), r.u8(), r.u32()
        fields[name] = (offset, datatype, count)
    big = bool(r.u8())
    point_step, _row_step = r.u32(), r.u32()
    raw = r.octets()
    n = height * width
    if not all(k in fields for k in "xyz"):
        raise ValueError(f"a cloud without x, y, z fields (fields: {', '.join(fields) or 'none'})")
    if len(raw) < n * point_step:
        raise ValueError(f"data holds {len(raw)} bytes, {n} points of {point_step} need more")
    out = np.empty((n, 3))
    for k, name in enumerate("xyz"):
        offset, datatype, _ = fields[name]
        if datatype not in _FLOATS:
            raise ValueError(f"field {name}: datatype {datatype} is not float32 or float64")
        dt = np.dtype(_FLOATS[datatype]).newbyteorder(">" if big else "<")
        out[:, k] = np.ndarray((n,), dt, raw, offset, (point_step,))
    return sec * 1_000_000_000 + nsec, out[np.isfinite(out).all(axis=1)]


def read_point_clouds(path, topic: str | None = None) -> tuple[str, list[tuple[int, np.ndarray]]]:
    """``(topic, [(stamp ns, points)])`` of the bag's point clouds in order: those of ``topic``,
    or of its only ``PointCloud2`` topic. A bag without one, or with several and no ``topic``
    named, raises :class:`~cloth_sim.bag.store.BagError` saying which it has."""
    from .store import bag_info

    info = bag_info(path)
    topics = {t.name: t.type for f in info.files for t in f.topics.values()}
    clouds = sorted(name for name, typ in topics.items() if typ == POINT_CLOUD2)
    if topic is None:
        if not clouds:
            raise BagError(
                f"{path}: no sensor_msgs/msg/PointCloud2 topic (it has "
                f"{', '.join(f'{n} ({t})' for n, t in sorted(topics.items())) or 'no topics'})"
            )
        if len(clouds) > 1:
            raise BagError(f"{path}: several point-cloud topics ({', '.join(clouds)}): name one")
        topic = clouds[0]
    elif topics.get(topic) != POINT_CLOUD2:
        raise BagError(
            f"{path}: topic {topic!r} is not a PointCloud2 topic of this bag (its point-cloud "
            f"topics: {', '.join(clouds) or 'none'})"
        )
    out = []
    for _, msg in iter_messages(path, {topic}):
        try:
            out.append(decode_point_cloud(msg.data))
        except (ValueError, UnicodeDecodeError, struct.error) as e:
            raise BagError(f"{path}: topic {topic}: a message that is not a point cloud: {e}")
    if not out:
        raise BagError(f"{path}: topic {topic} holds no messages")
    return topic, out
