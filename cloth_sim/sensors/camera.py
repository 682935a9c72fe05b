"""A depth camera: what a robot's sensor sees of the cloth and the colliders, with ground-truth
labels.

:class:`DepthCamera` is a pinhole camera (no distortion) whose optical frame follows REP 103: z
forward, x right, y down; ``orientation`` ``(1, 0, 0, 0)`` looks along world +z with image x along
world +x and image y along world +y, ``(0, 1, 0, 0)`` looks straight down. Pixel ``(u, v)``
(column, row; centres at integer coordinates, as OpenCV and ``sensor_msgs/CameraInfo``) samples the
ray through ``K⁻¹(u, v, 1)``.

:meth:`DepthCamera.render` is a pure function of the simulator's state and the camera's settings.
Per pixel it finds the nearest surface along the ray with its depth ``z`` (along the optical axis)
in ``[near, far]``:

* the cloth's triangles, both sides, each pixel of a triangle's projected box tested by an exact
  ray–triangle intersection (Möller & Trumbore 1997), so the depth of a planar triangle is exact
  (perspective-correct), and a triangle crossing the near plane is clipped exactly;
* every collider by its analytic ray intersection (plane, sphere, box by slabs, capsule), exact,
  not a tessellation.

It returns a :class:`Frame`: ``depth`` (float32 metres, NaN where nothing is in range), ``object``
(int16: −1 nothing, 0 the cloth, ``1 + i`` collider ``i`` of ``sim.colliders``) and ``triangle``
(int32: the index into ``sim.model.triangles`` of the cloth triangle seen, −1 elsewhere), and
``points()``, ``depth · K⁻¹(u, v, 1)`` in the optical frame.

**Where a pixel lies on the rest-state cloth**: with the triangle ``t = frame.triangle[v, u]`` and
the point ``p = frame.points()[v, u]`` (optical frame, so ``R·p + position`` in the world), the
barycentric coordinates of that world point in triangle ``t`` of ``sim.positions`` are its
coordinates in the same triangle of ``sim.model.positions`` too: :meth:`Frame.rest_points` does
exactly that, giving each pixel's place on the cloth at rest (UV-like ground truth for
correspondence and flow).

Noise (``noise="kinect"``): Gaussian axial noise of standard deviation ``σ(z) = 0.0012 + 0.0019·(z
− 0.4)²`` metres (Nguyen, Izadi & Lovell 2012, "Modeling Kinect sensor noise for improved 3D
reconstruction and tracking", eq. 2 for surfaces facing the sensor), drawn from the camera's own
generator seeded by ``seed``: a new camera with the same seed rendering the same scene gives the
same images. Left out, as that paper's model allows: lateral noise (its σ_L ≈ 0.8 px, blur at
edges), the angle dependence near grazing incidence, depth quantisation (the Kinect's disparity
steps) and missing pixels at edges and dark or specular surfaces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from ..contact.collider_kernels import BOX, CAPSULE, CYLINDER, MESH, PLANE, SPHERE
from ..contact.geometry import matrix_quaternion, quaternion_matrix, unit_quaternion, vector
from ..kernel_cache import keep_true

NOISE_MODELS = (None, "kinect")
#: the largest image side accepted
MAX_SIDE = 8192


@dataclass(frozen=True)
class Frame:
    """One rendered image: ``depth`` (H, W) float32 metres along the optical axis (NaN: nothing in
    ``[near, far]``), ``object`` (H, W) int16 (−1 nothing, 0 the cloth, 1 + i collider i),
    ``triangle`` (H, W) int32 (the cloth triangle seen, −1 elsewhere)."""

    depth: np.ndarray
    object: np.ndarray
    triangle: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    rotation: np.ndarray
    position: np.ndarray

    def points(self, out: np.ndarray | None = None) -> np.ndarray:
        """``(H, W, 3)`` float32 in the optical frame: ``depth · K⁻¹(u, v, 1)``, NaN where depth
        is; written into ``out`` (a C-contiguous float32 ``(H, W, 3)`` array) when given."""
        h, w = self.depth.shape
        if out is None:
            out = np.empty((h, w, 3), np.float32)
        elif out.shape != (h, w, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(
                f"out must be a C-contiguous float32 array of shape {(h, w, 3)}, got "
                f"{out.dtype} {out.shape}"
            )
        back_project(self.depth, self.fx, self.fy, self.cx, self.cy, out)
        return out

    def rest_points(
        self, positions: np.ndarray, rest_positions: np.ndarray, triangles: np.ndarray
    ) -> np.ndarray:
        """``(H, W, 3)`` each cloth pixel's place on the cloth at rest (``rest_positions``, e.g.
        ``sim.model.positions``), from its point's barycentric coordinates in the triangle it sees
        (``positions``: the state it was rendered from); NaN elsewhere."""
        out = np.full(self.depth.shape + (3,), np.nan)
        rows, cols = np.nonzero(self.triangle >= 0)
        if len(rows) == 0:
            return out
        p = self.points()[rows, cols].astype(np.float64) @ self.rotation.T + self.position
        t = triangles[self.triangle[rows, cols]]
        a, b, c = positions[t[:, 0]], positions[t[:, 1]], positions[t[:, 2]]
        v0, v1, v2 = b - a, c - a, p - a
        d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
        d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
        den = d00 * d11 - d01 * d01
        wb = (d11 * d20 - d01 * d21) / den
        wc = (d00 * d21 - d01 * d20) / den
        ra, rb, rc = rest_positions[t[:, 0]], rest_positions[t[:, 1]], rest_positions[t[:, 2]]
        out[rows, cols] = (1 - wb - wc)[:, None] * ra + wb[:, None] * rb + wc[:, None] * rc
        return out


class DepthCamera:
    """A pinhole depth camera (module docstring). Every setting is checked: a bad one raises
    ``ValueError`` naming it and what is accepted."""

    def __init__(
        self,
        width: int = 640,
        height: int = 480,
        fx: float = 525.0,
        fy: float = 525.0,
        cx: float = 319.5,
        cy: float = 239.5,
        position=(0.0, 0.0, 1.0),
        orientation=(0.0, 1.0, 0.0, 0.0),
        near: float = 0.1,
        far: float = 10.0,
        noise: str | None = None,
        seed: int = 0,
    ):
        for name, value in (("width", width), ("height", height)):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, np.integer))
                or not 1 <= value <= MAX_SIDE
            ):
                raise ValueError(
                    f"{name} must be an integer in [1, {MAX_SIDE}] pixels, got {value!r}"
                )
        for name, value in (("fx", fx), ("fy", fy)):
            if not _finite(value) or value <= 0:
                raise ValueError(
                    f"{name} must be a finite focal length > 0 (pixels), got {value!r}"
                )
        for name, value in (("cx", cx), ("cy", cy)):
            if not _finite(value):
                raise ValueError(
                    f"{name} must be a finite principal point coordinate (pixels), got {value!r}"
                )
        if not _finite(near) or near <= 0:
            raise ValueError(f"near must be a finite distance > 0 (m), got {near!r}")
        if not _finite(far) or far <= near:
            raise ValueError(f"far must be a finite distance > near = {near!r} (m), got {far!r}")
        if noise not in NOISE_MODELS:
            raise ValueError(
                f"noise must be one of {', '.join(map(repr, NOISE_MODELS))}, got {noise!r}"
            )
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(f"seed must be an integer, got {seed!r}")
        self.width, self.height = int(width), int(height)
        self.fx, self.fy, self.cx, self.cy = float(fx), float(fy), float(cx), float(cy)
        self.near, self.far = float(near), float(far)
        self.noise, self.seed = noise, int(seed)
        self._rng = np.random.default_rng(self.seed)
        self.set_pose(position, orientation)

    def set_pose(self, position, orientation) -> None:
        """Place the optical frame: ``position`` in the world, ``orientation`` a unit quaternion
        ``(w, x, y, z)`` from the optical frame to the world (``ValueError`` for a non-finite
        position or a zero quaternion)."""
        self.position = vector("position", position)
        self.orientation = unit_quaternion(orientation)
        self.rotation = quaternion_matrix(self.orientation)

    @property
    def K(self) -> np.ndarray:
        """The 3×3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def render(self, sim) -> Frame:
        """Render ``sim`` (a :class:`~cloth_sim.simulator.Simulator`) now: cloth and colliders."""
        h, w = self.height, self.width
        depth = np.full((h, w), np.inf)
        obj = np.full((h, w), -1, np.int16)
        tri = np.full((h, w), -1, np.int32)
        R, p = self.rotation, self.position
        # the cloth in the optical frame: x_c = Rᵀ (x − p)
        xc = np.ascontiguousarray((sim.positions - p) @ R)
        intr = np.array([self.fx, self.fy, self.cx, self.cy, self.near, self.far])
        render_triangles(xc, np.ascontiguousarray(sim.model.triangles), intr, depth, obj, tri, 0)
        cs = sim.colliders
        for i, c in enumerate(cs):
            if c.kind == MESH:  # a mesh's triangles, labelled as the collider
                xm = np.ascontiguousarray((c.vertices - p) @ R)
                render_triangles(xm, c.triangles, intr, depth, obj, tri, 1 + i)
        if cs:
            kinds = np.array([c.kind for c in cs], np.int64)
            # each collider's pose in the optical frame
            rot = np.array([R.T @ c.rotation for c in cs])
            pos = np.array([R.T @ (c.position - p) for c in cs])
            geo = np.array([c.geometry for c in cs], np.float64).reshape(-1, 4)
            render_colliders(kinds, pos, rot, geo, intr, depth, obj, tri)
        miss = ~np.isfinite(depth)
        if self.noise == "kinect":
            z = depth[~miss]
            depth[~miss] = z + self._rng.standard_normal(z.shape) * kinect_sigma(z)
        depth[miss] = np.nan
        return Frame(
            depth.astype(np.float32),
            obj,
            tri,
            self.fx,
            self.fy,
            self.cx,
            self.cy,
            R.copy(),
            p.copy(),
        )


@numba.njit(cache=True)
def back_project(depth, fx, fy, cx, cy, out):
    """``out[v, u] = depth[v, u] · ((u − cx)/fx, (v − cy)/fy, 1)`` (float64 arithmetic, float32
    stored)."""
    h, w = depth.shape
    for v in range(h):
        y = (v - cy) / fy
        for u in range(w):
            z = np.float64(depth[v, u])
            out[v, u, 0] = z * ((u - cx) / fx)
            out[v, u, 1] = z * y
            out[v, u, 2] = z


def kinect_sigma(z):
    """Nguyen, Izadi & Lovell 2012's axial noise σ(z) = 0.0012 + 0.0019·(z − 0.4)² (m)."""
    return 0.0012 + 0.0019 * (np.asarray(z) - 0.4) ** 2


def _finite(x) -> bool:
    return (
        isinstance(x, (int, float, np.integer, np.floating))
        and not isinstance(x, bool)
        and math.isfinite(float(x))
    )


@numba.njit(cache=True)
def render_triangles(xc, tris, intr, depth, obj, tri, label=0):
    """The cloth's triangles (optical-frame vertices ``xc``) into the depth buffer: each pixel of a
    triangle's projected box (its part in front of the near plane, clipped) tested by an exact
    ray–triangle intersection, both sides; the nearest ``z`` in ``[near, far]`` wins. A pixel won
    is labelled ``label`` in ``obj`` and, for the cloth (label 0), its triangle in ``tri`` (−1 for
    a mesh collider's)."""
    fx, fy, cx, cy, near, far = intr[0], intr[1], intr[2], intr[3], intr[4], intr[5]
    h, w = depth.shape
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        # the projected box of the triangle's part with z >= near: vertices in front, and where
        # the edges cross the near plane
        umin, umax, vmin, vmax = np.inf, -np.inf, np.inf, -np.inf
        zmax = max(xc[a, 2], xc[b, 2], xc[c, 2])
        if zmax < near or min(xc[a, 2], xc[b, 2], xc[c, 2]) > far:
            continue
        for e in range(3):
            i = tris[t, e]
            j = tris[t, (e + 1) % 3]
            zi, zj = xc[i, 2], xc[j, 2]
            if zi >= near:
                u = fx * xc[i, 0] / zi + cx
                v = fy * xc[i, 1] / zi + cy
                umin, umax, vmin, vmax = min(umin, u), max(umax, u), min(vmin, v), max(vmax, v)
            if (zi - near) * (zj - near) < 0.0:
                s = (near - zi) / (zj - zi)
                x = xc[i, 0] + s * (xc[j, 0] - xc[i, 0])
                y = xc[i, 1] + s * (xc[j, 1] - xc[i, 1])
                u = fx * x / near + cx
                v = fy * y / near + cy
                umin, umax, vmin, vmax = min(umin, u), max(umax, u), min(vmin, v), max(vmax, v)
        u0 = max(0, int(math.ceil(umin)))
        u1 = min(w - 1, int(math.floor(umax)))
        v0 = max(0, int(math.ceil(vmin)))
        v1 = min(h - 1, int(math.floor(vmax)))
        if u0 > u1 or v0 > v1:
            continue
        # Möller–Trumbore with the ray o = 0, d = ((u − cx)/fx, (v − cy)/fy, 1), t the depth z. Its
        # quantities are linear in d: det = d·(e2 × e1), bu·det = d·(e2 × s), bv·det = d·(s × e1)
        # (s = o − a), and t·det = e2·(s × e1); so per pixel three dot products and, for a pixel
        # inside, one division.
        e1x, e1y, e1z = xc[b, 0] - xc[a, 0], xc[b, 1] - xc[a, 1], xc[b, 2] - xc[a, 2]
        e2x, e2y, e2z = xc[c, 0] - xc[a, 0], xc[c, 1] - xc[a, 1], xc[c, 2] - xc[a, 2]
        sx, sy, sz = -xc[a, 0], -xc[a, 1], -xc[a, 2]
        mx, my, mz = e2y * e1z - e2z * e1y, e2z * e1x - e2x * e1z, e2x * e1y - e2y * e1x
        ax_, ay_, az_ = e2y * sz - e2z * sy, e2z * sx - e2x * sz, e2x * sy - e2y * sx
        qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
        tnum = e2x * qx + e2y * qy + e2z * qz
        ifx, ify = 1.0 / fx, 1.0 / fy
        for v in range(v0, v1 + 1):
            dy = (v - cy) * ify
            det0, bu0, bv0 = dy * my + mz, dy * ay_ + az_, dy * qy + qz
            for u in range(u0, u1 + 1):
                dx = (u - cx) * ifx
                det = dx * mx + det0
                bu = dx * ax_ + bu0
                bv = dx * qx + bv0
                if det > 0.0:
                    if bu < 0.0 or bv < 0.0 or bu + bv > det:
                        continue
                elif det < 0.0:
                    if bu > 0.0 or bv > 0.0 or bu + bv < det:
                        continue
                else:
                    continue
                z = tnum / det
                if near <= z <= far and z < depth[v, u]:
                    depth[v, u] = z
                    obj[v, u] = label
                    tri[v, u] = t if label == 0 else -1


@numba.njit(cache=True, inline="always")
def _ray_collider(kind, P, Rm, g, dx, dy, dz):
    """Smallest ``t ≥ 0`` where the ray ``t·d`` from the origin meets the collider's surface
    (optical frame: centre ``P``, rotation ``Rm``, geometry ``g``), ``inf`` if never."""
    # the ray in the collider's own frame: o' = Rᵀ(0 − P), d' = Rᵀ d
    ox = -(Rm[0, 0] * P[0] + Rm[1, 0] * P[1] + Rm[2, 0] * P[2])
    oy = -(Rm[0, 1] * P[0] + Rm[1, 1] * P[1] + Rm[2, 1] * P[2])
    oz = -(Rm[0, 2] * P[0] + Rm[1, 2] * P[1] + Rm[2, 2] * P[2])
    ex = Rm[0, 0] * dx + Rm[1, 0] * dy + Rm[2, 0] * dz
    ey = Rm[0, 1] * dx + Rm[1, 1] * dy + Rm[2, 1] * dz
    ez = Rm[0, 2] * dx + Rm[1, 2] * dy + Rm[2, 2] * dz
    if kind == PLANE:  # n·(o + t d) = 0, n = g[:3] in its own frame
        den = g[0] * ex + g[1] * ey + g[2] * ez
        if den == 0.0:
            return np.inf
        t = -(g[0] * ox + g[1] * oy + g[2] * oz) / den
        return t if t >= 0.0 else np.inf
    if kind == SPHERE:
        return _ray_sphere(ox, oy, oz, ex, ey, ez, g[0])
    if kind == BOX:  # slabs
        tmin, tmax = -np.inf, np.inf
        for k in range(3):
            o = ox if k == 0 else (oy if k == 1 else oz)
            d = ex if k == 0 else (ey if k == 1 else ez)
            half = g[k]
            if d == 0.0:
                if o < -half or o > half:
                    return np.inf
                continue
            t1, t2 = (-half - o) / d, (half - o) / d
            if t1 > t2:
                t1, t2 = t2, t1
            tmin, tmax = max(tmin, t1), min(tmax, t2)
            if tmin > tmax:
                return np.inf
        if tmax < 0.0:
            return np.inf
        return tmin if tmin >= 0.0 else np.inf  # from inside a box the camera sees nothing of it
    if kind == CYLINDER:  # the side x² + y² = r² within |z| ≤ h, and the caps z = ±h
        r, half = g[0], g[1]
        best = np.inf
        A = ex * ex + ey * ey
        B = 2.0 * (ox * ex + oy * ey)
        C = ox * ox + oy * oy - r * r
        disc = B * B - 4 * A * C
        if A > 0.0 and disc >= 0.0:
            t = (-B - math.sqrt(disc)) / (2 * A)
            if t >= 0.0 and abs(oz + t * ez) <= half:
                best = t
        if ez != 0.0:
            for sgn in (-1.0, 1.0):
                t = (sgn * half - oz) / ez
                px, py = ox + t * ex, oy + t * ey
                if t >= 0.0 and px * px + py * py <= r * r:
                    best = min(best, t)
        return best
    # capsule: the segment from −g[:3] to +g[:3], radius g[3]: the nearest of the infinite
    # cylinder's hit within the segment and the two end spheres
    r = g[3]
    ax, ay, az = g[0], g[1], g[2]
    L2 = 4.0 * (ax * ax + ay * ay + az * az)
    best = min(
        _ray_sphere(ox - ax, oy - ay, oz - az, ex, ey, ez, r),
        _ray_sphere(ox + ax, oy + ay, oz + az, ex, ey, ez, r),
    )
    if L2 > 0.0:
        # axis unit w = 2a/|2a|; components perpendicular to it
        Ln = math.sqrt(L2)
        wx, wy, wz = 2 * ax / Ln, 2 * ay / Ln, 2 * az / Ln
        bx, by, bz = ox + ax, oy + ay, oz + az  # from the end −a
        dd = ex * wx + ey * wy + ez * wz
        bd = bx * wx + by * wy + bz * wz
        px, py, pz = ex - dd * wx, ey - dd * wy, ez - dd * wz
        qx, qy, qz = bx - bd * wx, by - bd * wy, bz - bd * wz
        A = px * px + py * py + pz * pz
        B = 2.0 * (px * qx + py * qy + pz * qz)
        C = qx * qx + qy * qy + qz * qz - r * r
        disc = B * B - 4 * A * C
        if A > 0.0 and disc >= 0.0:
            t = (-B - math.sqrt(disc)) / (2 * A)
            s = bd + t * dd
            if t >= 0.0 and 0.0 <= s <= Ln:
                best = min(best, t)
    return best


@numba.njit(cache=True, inline="always")
def _ray_sphere(ox, oy, oz, ex, ey, ez, r):
    A = ex * ex + ey * ey + ez * ez
    B = 2.0 * (ox * ex + oy * ey + oz * ez)
    C = ox * ox + oy * oy + oz * oz - r * r
    disc = B * B - 4 * A * C
    if disc < 0.0:
        return np.inf
    t = (-B - math.sqrt(disc)) / (2 * A)
    return t if t >= 0.0 else np.inf  # from inside the sphere the camera sees nothing of it


@numba.njit(cache=True)
def _pixel_box(pts, intr, w, h):
    """``(u0, u1, v0, v1)``: the pixels the projections of ``pts`` (optical frame, the corners of a
    box around a shape) can cover; the whole image when a point is not in front of the camera."""
    fx, fy, cx, cy = intr[0], intr[1], intr[2], intr[3]
    umin, umax, vmin, vmax = np.inf, -np.inf, np.inf, -np.inf
    for k in range(pts.shape[0]):
        z = pts[k, 2]
        if z <= 1e-9:
            return 0, w - 1, 0, h - 1
        u = fx * pts[k, 0] / z + cx
        v = fy * pts[k, 1] / z + cy
        umin, umax, vmin, vmax = min(umin, u), max(umax, u), min(vmin, v), max(vmax, v)
    return (
        max(0, int(math.floor(umin))),
        min(w - 1, int(math.ceil(umax))),
        max(0, int(math.floor(vmin))),
        min(h - 1, int(math.ceil(vmax))),
    )


@numba.njit(cache=True)
def render_colliders(kinds, pos, rot, geo, intr, depth, obj, tri):
    """Every collider by its analytic ray intersection into the depth buffer (``d`` has ``z = 1``,
    so the ray parameter is the depth): a plane over the whole image by ``t = (n·P)/(n·d)``, the
    bounded shapes over the pixels their bounding box projects to."""
    fx, fy, cx, cy, near, far = intr[0], intr[1], intr[2], intr[3], intr[4], intr[5]
    h, w = depth.shape
    ifx, ify = 1.0 / fx, 1.0 / fy
    corners = np.empty((16, 3))
    for i in range(kinds.shape[0]):
        P, Rm, g, kind = pos[i], rot[i], geo[i], kinds[i]
        if kind == PLANE:
            nx = Rm[0, 0] * g[0] + Rm[0, 1] * g[1] + Rm[0, 2] * g[2]
            ny = Rm[1, 0] * g[0] + Rm[1, 1] * g[1] + Rm[1, 2] * g[2]
            nz = Rm[2, 0] * g[0] + Rm[2, 1] * g[1] + Rm[2, 2] * g[2]
            num = nx * P[0] + ny * P[1] + nz * P[2]
            for v in range(h):
                den0 = ny * (v - cy) * ify + nz
                for u in range(w):
                    den = nx * (u - cx) * ifx + den0
                    if den == 0.0:
                        continue
                    z = num / den
                    if near <= z <= far and z < depth[v, u]:
                        depth[v, u] = z
                        obj[v, u] = 1 + i
                        tri[v, u] = -1
            continue
        # the corners of a box around the shape, in the optical frame
        m = 0
        if kind == SPHERE or kind == CAPSULE:
            r = g[0] if kind == SPHERE else g[3]
            for end in range(2 if kind == CAPSULE else 1):
                sgn = 1.0 if end == 0 else -1.0
                ex, ey, ez = P[0], P[1], P[2]
                if kind == CAPSULE:
                    ex += sgn * (Rm[0, 0] * g[0] + Rm[0, 1] * g[1] + Rm[0, 2] * g[2])
                    ey += sgn * (Rm[1, 0] * g[0] + Rm[1, 1] * g[1] + Rm[1, 2] * g[2])
                    ez += sgn * (Rm[2, 0] * g[0] + Rm[2, 1] * g[1] + Rm[2, 2] * g[2])
                for k in range(8):
                    corners[m, 0] = ex + (r if k & 1 else -r)
                    corners[m, 1] = ey + (r if k & 2 else -r)
                    corners[m, 2] = ez + (r if k & 4 else -r)
                    m += 1
        elif kind == MESH:  # rasterised with the cloth's triangles (render)
            continue
        else:  # a box or a cylinder: its own corners
            bx, by, bz = (g[0], g[1], g[2]) if kind == BOX else (g[0], g[0], g[1])
            for k in range(8):
                hx = bx if k & 1 else -bx
                hy = by if k & 2 else -by
                hz = bz if k & 4 else -bz
                corners[m, 0] = P[0] + Rm[0, 0] * hx + Rm[0, 1] * hy + Rm[0, 2] * hz
                corners[m, 1] = P[1] + Rm[1, 0] * hx + Rm[1, 1] * hy + Rm[1, 2] * hz
                corners[m, 2] = P[2] + Rm[2, 0] * hx + Rm[2, 1] * hy + Rm[2, 2] * hz
                m += 1
        u0, u1, v0, v1 = _pixel_box(corners[:m], intr, w, h)
        for v in range(v0, v1 + 1):
            dy = (v - cy) * ify
            for u in range(u0, u1 + 1):
                z = _ray_collider(kind, P, Rm, g, (u - cx) * ifx, dy, 1.0)
                if near <= z <= far and z < depth[v, u]:
                    depth[v, u] = z
                    obj[v, u] = 1 + i
                    tri[v, u] = -1


def look_at_orientation(position, target) -> np.ndarray:
    """The optical frame's unit quaternion ``(w, x, y, z)`` for a camera at ``position`` looking at
    ``target``: z along the view, image up (−y) towards world +z (world +y when looking straight up
    or down, −y straight up), x = y × z. ``ValueError`` when the two points coincide."""
    p, t = vector("camera.position", position), vector("camera.look_at", target)
    z = t - p
    if not np.linalg.norm(z) > 1e-9:
        raise ValueError(
            f"camera.look_at must be a point other than camera.position = {p.tolist()}"
        )
    z /= np.linalg.norm(z)
    # straight down or up: image up along world +y or −y, so that (0, 1, 0, 0) and (1, 0, 0, 0)
    # are those views' orientations, as the contract has them
    up = (
        np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 1 - 1e-9 else np.array([0.0, -np.sign(z[2]), 0.0])
    )
    y = -(up - (up @ z) * z)
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return matrix_quaternion(np.stack([x, y, z], axis=1))


def camera_from_settings(settings: dict, seed: int = 0) -> DepthCamera:
    """A :class:`DepthCamera` from the node's ``camera.*`` settings (keys without the prefix:
    width, height, fov in degrees, position, look_at, near, far, noise "none" or "kinect")."""
    w, h = int(settings["width"]), int(settings["height"])
    f = 0.5 * w / math.tan(math.radians(float(settings["fov"])) / 2)
    noise = None if settings["noise"] == "none" else settings["noise"]
    if not float(settings["far"]) > float(settings["near"]):
        raise ValueError(
            f"camera.far = {settings['far']!r} is not accepted: expected a distance above "
            f"camera.near = {settings['near']!r}"
        )
    return DepthCamera(
        width=w,
        height=h,
        fx=f,
        fy=f,
        cx=(w - 1) / 2,
        cy=(h - 1) / 2,
        position=settings["position"],
        orientation=look_at_orientation(settings["position"], settings["look_at"]),
        near=float(settings["near"]),
        far=float(settings["far"]),
        noise=noise,
        seed=seed,
    )


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
