"""Depth camera render time: 320×240 / 640×480 / 1280×720 images of the drape scene (a cloth over a
sphere, a floor plane below) at 32×32 / 64×64 / 128×128, side by side in one process; one core (the
kernels are serial); min of 5 renders after one warm-up.

    .venv/bin/python -m cloth_sim.bench.render
"""

import time

from cloth_sim.scene import load_scene
from cloth_sim.sensors.camera import DepthCamera


def main() -> None:
    SIZES = ((320, 240), (640, 480), (1280, 720))
    print(
        "| cloth | " + " | ".join(f"{w}×{h} ms" for w, h in SIZES) + " | cloth pixels at 640×480 |"
    )
    print("|---|" + "---|" * (len(SIZES) + 1))
    for n in (32, 64, 128):
        sim = load_scene("drape").build_simulator(rows=n, cols=n, spacing=1.0 / (n - 1))
        sim.advance(1.0)
        row, covered = [], 0
        for w, h in SIZES:
            f = 0.8 * w  # a field of view of about 64° across
            cam = DepthCamera(
                width=w,
                height=h,
                fx=f,
                fy=f,
                cx=(w - 1) / 2,
                cy=(h - 1) / 2,
                position=(0.5, 0.5, 1.6),
                orientation=(0.0, 1.0, 0.0, 0.0),
            )
            frame = cam.render(sim)
            times = []
            for _ in range(5):
                t = time.perf_counter()
                frame = cam.render(sim)
                times.append(time.perf_counter() - t)
            row.append(f"{1e3 * min(times):.2f}")
            if w == 640:
                covered = int((frame.object == 0).sum())
        print(f"| {n}×{n} | " + " | ".join(row) + f" | {covered} |", flush=True)


if __name__ == "__main__":
    main()
