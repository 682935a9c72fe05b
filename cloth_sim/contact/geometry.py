"""Geometric primitives the contact code shares: checks of the vectors, lengths and orientations a
user gives (each refusal names the field), the arrays the kernels are handed (:func:`read_only`),
rotation matrices of quaternions, and the closest points
of a point and a triangle and of two segments (Ericson, *Real-Time Collision Detection*, 5.1.5 and
5.1.9), compiled with numba for the kernels of :mod:`.colliders`, :mod:`.self_collision`,
:mod:`.collision_tree` and :mod:`cloth_sim.integrators.vbd`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..kernel_cache import keep_true


def vector(name: str, value, length: int = 3) -> np.ndarray:
    """``value`` as ``length`` finite float64s, or ``ValueError`` naming ``name``."""
    try:
        a = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {length} finite numbers, got {value!r}") from None
    if a.shape != (length,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be {length} finite numbers, got {value!r}")
    return a


def read_only(a, dtype) -> np.ndarray:
    """``a`` as a C-contiguous read-only array of ``dtype`` (a view where it already is one):
    whoever owns the array (a state's writable positions, a simulator's read-only view), a kernel
    sees one type and numba compiles it once (a second signature compiled for 26 s inside a test:
    docs/BENCHMARKS.md §11)."""
    out = np.ascontiguousarray(a, dtype=dtype).view()
    out.flags.writeable = False
    return out


def positive(name: str, value) -> float:
    """``value`` as a finite float > 0, or ``ValueError`` naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def unit_quaternion(q) -> np.ndarray:
    """``q`` ``(w, x, y, z)`` normalised; a zero or non-finite quaternion is refused."""
    q = vector("orientation", q, 4)
    n = float(np.linalg.norm(q))
    if not n > 1e-12:
        raise ValueError(
            f"orientation must be a nonzero quaternion (w, x, y, z), got {q.tolist()}"
        )
    return q / n


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)`` (normalised here; a zero or non-finite
    quaternion is refused)."""
    w, x, y, z = unit_quaternion(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_quaternion(R: np.ndarray) -> np.ndarray:
    """The unit quaternion ``(w, x, y, z)`` of a rotation matrix (Shepperd's method), ``w ≥ 0``."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q) * (1.0 if q[0] >= 0 else -1.0)


@numba.njit(cache=True, inline="always")
def closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Barycentric weights ``(wa, wb, wc)`` of the point of triangle ``abc`` closest to ``p``
    (Ericson, Real-Time Collision Detection, 5.1.5)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3) if d1 != d3 else 0.0
        return 1.0 - v, v, 0.0
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6) if d2 != d6 else 0.0
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        den = (d4 - d3) + (d5 - d6)
        w = (d4 - d3) / den if den != 0.0 else 0.0
        return 0.0, 1.0 - w, w
    den = va + vb + vc
    if den == 0.0:  # degenerate triangle
        return 1.0, 0.0, 0.0
    v = vb / den
    w = vc / den
    return 1.0 - v - w, v, w


@numba.njit(cache=True, inline="always")
def triangle_weights(x, p, a, b, c):
    """:func:`closest_on_triangle` of particle ``p`` and triangle ``abc`` of ``x``."""
    # fmt: off
    return closest_on_triangle(
        x[p, 0], x[p, 1], x[p, 2],
        x[a, 0], x[a, 1], x[a, 2],
        x[b, 0], x[b, 1], x[b, 2],
        x[c, 0], x[c, 1], x[c, 2],
    )
    # fmt: on


@numba.njit(cache=True, inline="always")
def segment_parameters(x, a, b, c, d):
    """:func:`closest_on_segment_pair` of the segments ``ab`` and ``cd`` of ``x``."""
    # fmt: off
    return closest_on_segment_pair(
        x[a, 0], x[a, 1], x[a, 2],
        x[b, 0], x[b, 1], x[b, 2],
        x[c, 0], x[c, 1], x[c, 2],
        x[d, 0], x[d, 1], x[d, 2],
    )
    # fmt: on


@numba.njit(cache=True, inline="always")
def point_triangle_distance(x, p, a, b, c):
    """``(distance, wa, wb, wc)``: particle ``p``'s distance to triangle ``abc`` of ``x`` and the
    barycentric weights of the closest point."""
    wa, wb, wc = triangle_weights(x, p, a, b, c)
    dx = x[p, 0] - (wa * x[a, 0] + wb * x[b, 0] + wc * x[c, 0])
    dy = x[p, 1] - (wa * x[a, 1] + wb * x[b, 1] + wc * x[c, 1])
    dz = x[p, 2] - (wa * x[a, 2] + wb * x[b, 2] + wc * x[c, 2])
    return math.sqrt(dx * dx + dy * dy + dz * dz), wa, wb, wc


@numba.njit(cache=True, inline="always")
def closest_on_segment_pair(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    """``(s, t)``: the nearest points ``a + s(b − a)`` and ``c + t(d − c)`` of two segments given
    by their ends' coordinates (Ericson, Real-Time Collision Detection, 5.1.9; a parallel pair
    takes ``s = 0``)."""
    d1x, d1y, d1z = bx - ax, by - ay, bz - az
    d2x, d2y, d2z = dx - cx, dy - cy, dz - cz
    rx, ry, rz = ax - cx, ay - cy, az - cz
    aa = d1x * d1x + d1y * d1y + d1z * d1z
    ee = d2x * d2x + d2y * d2y + d2z * d2z
    ff = d2x * rx + d2y * ry + d2z * rz
    cc = d1x * rx + d1y * ry + d1z * rz
    bb = d1x * d2x + d1y * d2y + d1z * d2z
    den = aa * ee - bb * bb
    sv = min(max((bb * ff - cc * ee) / den, 0.0), 1.0) if den > 1e-30 * aa * ee else 0.0
    tv = (bb * sv + ff) / ee if ee > 0.0 else 0.0
    if tv < 0.0:
        tv = 0.0
        sv = min(max(-cc / aa, 0.0), 1.0) if aa > 0.0 else 0.0
    elif tv > 1.0:
        tv = 1.0
        sv = min(max((bb - cc) / aa, 0.0), 1.0) if aa > 0.0 else 0.0
    return sv, tv


@numba.njit(cache=True, inline="always")
def closest_on_segments(x, a, b, c, d):
    """``(s, t, distance)``: the nearest points ``a + s(b − a)`` and ``c + t(d − c)`` of two
    segments (:func:`closest_on_segment_pair` of the particles ``a``, ``b``, ``c``, ``d``)."""
    sv, tv = segment_parameters(x, a, b, c, d)
    d1x, d1y, d1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
    d2x, d2y, d2z = x[d, 0] - x[c, 0], x[d, 1] - x[c, 1], x[d, 2] - x[c, 2]
    rx, ry, rz = x[a, 0] - x[c, 0], x[a, 1] - x[c, 1], x[a, 2] - x[c, 2]
    px, py, pz = rx + sv * d1x - tv * d2x, ry + sv * d1y - tv * d2y, rz + sv * d1z - tv * d2z
    return sv, tv, math.sqrt(px * px + py * py + pz * pz)


@numba.njit(cache=True, inline="always")
def corners_d2(x, y, z, ax, ay, az, bx, by, bz, cx, cy, cz):
    """The point of the triangle of corners ``a``, ``b``, ``c`` nearest ``(x, y, z)``: the squared
    distance, the point and its barycentric weights (:func:`closest_on_triangle`)."""
    wa, wb, wc = closest_on_triangle(x, y, z, ax, ay, az, bx, by, bz, cx, cy, cz)
    px = wa * ax + wb * bx + wc * cx
    py = wa * ay + wb * by + wc * cy
    pz = wa * az + wb * bz + wc * cz
    return (x - px) ** 2 + (y - py) ** 2 + (z - pz) ** 2, px, py, pz, wa, wb, wc


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
