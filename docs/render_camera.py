"""Render what the depth camera sees of the drape scene (a cloth over a ball, a floor below) after
1.5 s into docs/img/drape_depth.png (depth, metres) and docs/img/drape_labels.png (the ground-truth
labels:
cloth, ball, floor, nothing), as shown in the README.

    .venv/bin/python docs/render_camera.py [--out docs/img]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402

from cloth_sim.scene import load_scene  # noqa: E402
from cloth_sim.sensors.camera import camera_from_settings  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "img")
    args = ap.parse_args(argv)
    sim = load_scene("drape").build_simulator()
    sim.advance(1.5)
    cam = camera_from_settings(
        {
            "width": 320,
            "height": 240,
            "fov": 70.0,
            "position": [0.5, -0.7, 1.3],
            "look_at": [0.5, 0.5, 0.0],
            "near": 0.1,
            "far": 10.0,
            "noise": "kinect",
        }
    )
    frame = cam.render(sim)
    args.out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(4.6, 3.4))
    im = ax.imshow(frame.depth, cmap="viridis")
    fig.colorbar(im, ax=ax, label="depth (m), Kinect noise")
    ax.set_title("drape: ~/camera/depth/image", fontsize=9)
    ax.axis("off")
    fig.savefig(args.out / "drape_depth.png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(4.6, 3.4))
    labels = ["nothing", "cloth"] + [c.name for c in sim.colliders]
    cmap = ListedColormap(
        ["white", "tab:blue", "tab:orange", "tab:gray", "tab:green"][: len(labels)]
    )
    im = ax.imshow(frame.object + 1, cmap=cmap, vmin=-0.5, vmax=len(labels) - 0.5)
    cb = fig.colorbar(im, ax=ax, ticks=range(len(labels)))
    cb.ax.set_yticklabels(labels)
    ax.set_title("drape: ~/camera/labels", fontsize=9)
    ax.axis("off")
    fig.savefig(args.out / "drape_labels.png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    print(args.out / "drape_depth.png", args.out / "drape_labels.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
