"""An RGB picture for ``render_mode="rgb_array"``, drawn from the depth camera's labelled frame.

No rasteriser of its own: the camera already says, per pixel, which cloth triangle or collider is
seen and where. The cloth is shaded by the facing of that triangle (Lambert, a light at the camera;
one colour for the side the grid's normal points to, another for the back, as SoftGym colours its
cloth), the floor by a 10 cm checkerboard, and each picker is a disc of its radius (red while it
holds a particle, white otherwise) where it is nearer than the surface behind it.
"""

from __future__ import annotations

import numpy as np

FRONT = np.array([0.95, 0.55, 0.15])
BACK = np.array([0.25, 0.45, 0.85])
FLOOR = (np.array([0.78, 0.78, 0.76]), np.array([0.62, 0.62, 0.60]))
SKY = np.array([0.10, 0.10, 0.12])


def render_rgb(frame, sim, cam, pickers) -> np.ndarray:
    h, w = frame.depth.shape
    img = np.empty((h, w, 3))
    img[:] = SKY
    pts = frame.points()
    world = pts.astype(np.float64) @ cam.rotation.T + cam.position
    seen = np.isfinite(frame.depth)

    floor = seen & (frame.object >= 1)
    cell = np.floor(np.nan_to_num(world[..., :2]) / 0.1)
    check = (cell[..., 0] + cell[..., 1]).astype(np.int64) % 2
    img[floor & (check == 0)] = FLOOR[0]
    img[floor & (check == 1)] = FLOOR[1]

    cloth = frame.triangle >= 0
    if cloth.any():
        x = sim.positions
        t = sim.model.triangles
        n = np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        tri = frame.triangle[cloth]
        view = world[cloth] - cam.position
        view /= np.maximum(np.linalg.norm(view, axis=1, keepdims=True), 1e-12)
        facing = np.einsum("ij,ij->i", n[tri], view)
        shade = 0.35 + 0.65 * np.abs(facing)
        img[cloth] = np.where((facing < 0)[:, None], FRONT, BACK) * shade[:, None]

    # pickers: discs of their radius, depth-tested against what is behind them
    pc = (pickers.positions - cam.position) @ cam.rotation
    vv, uu = np.mgrid[0:h, 0:w]
    for i, (X, Y, Z) in enumerate(pc):
        if Z <= cam.near:
            continue
        u, v, r = (
            frame.fx * X / Z + frame.cx,
            frame.fy * Y / Z + frame.cy,
            frame.fx * pickers.radius / Z,
        )
        disc = ((uu - u) ** 2 + (vv - v) ** 2 <= r * r) & ~(frame.depth < Z - pickers.radius)
        img[disc] = (0.9, 0.15, 0.15) if pickers.held[i] is not None else (0.95, 0.95, 0.95)
    return (np.clip(img, 0, 1) * 255).astype(np.uint8)
