"""Render the contact and garment scenes (table, drape, fold, tshirt, towel) after a few seconds of
simulation into docs/img/<scene>.png, as shown in the README.

    .venv/bin/python docs/render_scenes.py [--seconds 3] [--out docs/img] [scene[:seconds] ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cloth_sim.contact.colliders import Box, Capsule, Plane, Sphere  # noqa: E402
from cloth_sim.scene import load_scene  # noqa: E402


def _draw_collider(ax, c, span):
    if isinstance(c, Sphere):
        u, v = np.mgrid[0 : 2 * np.pi : 40j, 0 : np.pi : 20j]
        r, (x, y, z) = c.radius, c.center
        ax.plot_surface(
            x + r * np.cos(u) * np.sin(v),
            y + r * np.sin(u) * np.sin(v),
            z + r * np.cos(v),
            color="0.6",
            alpha=0.5,
            linewidth=0,
        )
    elif isinstance(c, Box):
        h = c.half_extents
        corners = (
            np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
        )
        pts = corners @ c.rotation.T + c.center
        for i in range(8):
            for j in range(i + 1, 8):
                if np.sum(np.abs(corners[i] - corners[j]) > 1e-12) == 1:
                    ax.plot(*pts[[i, j]].T, color="0.35", linewidth=1)
    elif isinstance(c, Capsule):
        ax.plot(*np.stack([c.a, c.b]).T, color="0.35", linewidth=4)
    elif isinstance(c, Plane):
        n = c.normal
        (x0, x1), (y0, y1) = span
        xx, yy = np.meshgrid(np.linspace(x0, x1, 2), np.linspace(y0, y1, 2))
        if abs(n[2]) > 1e-6:  # z on the plane over the cloth's footprint
            zz = (c.offset - n[0] * xx - n[1] * yy) / n[2]
            ax.plot_surface(xx, yy, zz, color="0.8", alpha=0.4, linewidth=0)


def render(name: str, seconds: float, out: Path) -> Path:
    sim = load_scene(name).build_simulator()
    sim.advance(seconds)
    x = sim.positions
    fig = plt.figure(figsize=(5, 4.2))
    ax = fig.add_subplot(projection="3d")
    lo, hi = x.min(axis=0) - 0.2, x.max(axis=0) + 0.2
    for c in sim.colliders:
        _draw_collider(ax, c, ((lo[0], hi[0]), (lo[1], hi[1])))
    ax.plot_trisurf(
        x[:, 0],
        x[:, 1],
        x[:, 2],
        triangles=sim.model.triangles,
        color="tab:blue",
        edgecolor="navy",
        linewidth=0.1,
        alpha=0.9,
    )
    mid, half = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set(
        xlim=(mid[0] - half, mid[0] + half),
        ylim=(mid[1] - half, mid[1] + half),
        zlim=(max(lo[2], mid[2] - half), mid[2] + half),
        xlabel="x",
        ylabel="y",
        zlabel="z",
    )
    cloth = (
        f"{sim.model.rows}×{sim.model.cols}"
        if sim.model.rows
        else f"{sim.model.n_particles} vertices, {len(sim.model.triangles)} triangles"
    )
    ax.set_title(
        f"{name}: t = {sim.time:.1f} s, {cloth}, {', '.join(sim.active_stages)}", fontsize=9
    )
    ax.view_init(elev=22, azim=-60)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.png"
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "img")
    ap.add_argument(
        "scenes",
        nargs="*",
        default=["table", "drape", "fold:0.8", "tshirt:0.6", "towel:1.5"],
        help="scene names, each optionally :seconds (default --seconds)",
    )
    args = ap.parse_args(argv)
    for item in args.scenes:
        name, _, seconds = item.partition(":")
        print(render(name, float(seconds) if seconds else args.seconds, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
