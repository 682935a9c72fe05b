"""The depth camera: what a robot's sensor sees of the cloth, with ground truth per pixel.

    .venv/bin/python examples/depth_camera.py [--quick]

The ``drape`` scene (a cloth dropped over a ball) is stepped until it lies on it, then seen from
above: the depth image (metres along the optical axis), which object each pixel sees, which cloth
triangle, the points in the camera's optical frame, and where each seen point lies on the cloth at
rest (the correspondence a perception model is trained on).
"""

import argparse

import numpy as np

from cloth_sim import settings
from cloth_sim.sensors import DepthCamera

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="0.05 s of draping and a small image")
quick = p.parse_args().quick

_, _, sim, _ = settings.configure("drape", {})
sim.advance(0.05 if quick else 1.0)
w, h = (80, 60) if quick else (640, 480)
cam = DepthCamera(
    width=w,
    height=h,
    fx=525.0 * w / 640,
    fy=525.0 * h / 480,
    cx=(w - 1) / 2,
    cy=(h - 1) / 2,
    position=(0.5, 0.5, 1.5),
    orientation=(0, 1, 0, 0),  # the optical frame (z forward, y down), turned to look down
    near=0.1,
    far=10.0,
    noise=None,  # or "kinect": disparity quantisation and noise, seeded by seed
    seed=0,
)
frame = cam.render(sim)
seen = np.isfinite(frame.depth)
print(f"depth {frame.depth.shape}: {seen.mean():.0%} of the pixels see something")
print(f"nearest {np.nanmin(frame.depth):.3f} m, farthest {np.nanmax(frame.depth):.3f} m")
cloth = frame.object == 0  # -1 nothing, 0 the cloth, 1 + i collider i
print(f"the cloth fills {cloth.mean():.0%} of the image; the ball and floor the rest")
tri = frame.triangle[cloth]  # the cloth triangle each pixel sees (into sim.model.triangles)
print(f"{len(np.unique(tri))} of {len(sim.model.triangles)} triangles in view")
points = frame.points()  # (H, W, 3) float32 in the optical frame
rest = frame.rest_points(sim.positions, sim.model.positions, sim.model.triangles)
seen, at_rest = points[h // 2, w // 2].round(3), rest[h // 2, w // 2].round(3)
print("the centre pixel sees the cloth at", seen, "(optical frame); that point at rest:", at_rest)
