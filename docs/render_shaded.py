"""The site's and README's pictures, shaded by the package's own camera (the Gymnasium tasks'
renderer: the cloth lit by its normals, front and back in two colours, on a checkered floor):
an animated drape (``docs/img/drape.gif``), the T-shirt's scripted fold
(``docs/img/tshirt_fold.gif``) and a still of each shipped scene (``docs/img/scenes/<scene>.png``).

    .venv/bin/python docs/render_shaded.py [drape] [fold] [scenes]
    .venv/bin/python docs/render_shaded.py scenes robot_sweep robot_pick   # some scenes only
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from PIL import Image

from cloth_sim import settings
from cloth_sim.envs.render import render_rgb
from cloth_sim.sensors.camera import camera_from_settings

OUT = Path(__file__).resolve().parent / "img"
NO_PICKERS = SimpleNamespace(positions=np.zeros((0, 3)), radius=0.02, held=[])


def camera_for(sim, width=400, height=300, distance=1.35, elevation=0.8):
    """A camera looking at the cloth's centre from the front, above it, the cloth filling it."""
    x = sim.positions
    centre = (x.min(axis=0) + x.max(axis=0)) / 2
    span = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
    eye = centre + np.array([0.55, -1.0, elevation]) * distance * max(span, 0.5) / 1.4
    return camera_from_settings(
        dict(
            width=width,
            height=height,
            near=0.05,
            far=20.0,
            noise="none",
            position=tuple(eye),
            look_at=tuple(centre - (0, 0, 0.15 * span)),
            fov=45.0,
        )
    )


def shot(sim, cam, pickers=NO_PICKERS) -> Image.Image:
    return Image.fromarray(render_rgb(cam.render(sim), sim, cam, pickers))


def save_gif(frames, path: Path, fps: float) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    frames[0].save(
        path, save_all=True, append_images=frames[1:], duration=round(1000 / fps), loop=0
    )
    print(path, len(frames), "frames")


def drape() -> None:
    _, _, sim, _ = settings.configure("drape", {})
    cam = camera_for(sim)
    frames = [shot(sim, cam)]
    for _ in range(36):  # 2.4 s at 15 frames a second
        sim.advance(sim.time + 1 / 15)
        frames.append(shot(sim, cam))
    save_gif(frames + [frames[-1]] * 10, OUT / "drape.gif", 15)


def fold() -> None:
    import gymnasium as gym

    import cloth_sim.envs  # noqa: F401
    from cloth_sim.envs import policies

    env = gym.make("cloth_sim/TshirtFold-v0", render_mode="rgb_array", image_size=300)
    env.reset(seed=0, options={"variation": 0})
    frames = [Image.fromarray(env.render())]
    for action in policies.SCRIPTED["TshirtFold"](env.unwrapped):
        env.step(action)
        frames.append(Image.fromarray(env.render()))
    save_gif(frames + [frames[-1]] * 10, OUT / "tshirt_fold.gif", 10)


#: when a scene's still is taken (s), where 1.5 (2 for a step of 0.01 s or more) would miss what
#: it shows: the arm in the cloth, the corner lifted
SCENE_TIME = {"robot_sweep": 1.25, "robot_pick": 7.8}
#: a wider view (camera_for's distance, elevation) where the robot stands beside the cloth
SCENE_VIEW = {"robot_sweep": (1.7, 0.3), "robot_pick": (3.0, 0.5)}


def scenes(names=()) -> None:
    for path in sorted((OUT.parent.parent / "config" / "scenes").glob("*.yaml")):
        if names and path.stem not in names:
            continue
        _, _, sim, _ = settings.configure(path.stem, {})
        distance, elevation = SCENE_VIEW.get(path.stem, (1.35, 0.8))
        cam = camera_for(sim, distance=distance, elevation=elevation)
        sim.advance(SCENE_TIME.get(path.stem, 1.5 if sim.dt < 0.01 else 2.0))
        out = OUT / "scenes" / f"{path.stem}.png"
        out.parent.mkdir(parents=True, exist_ok=True)
        shot(sim, cam).save(out)
        print(out)


if __name__ == "__main__":
    args = sys.argv[1:] or ["drape", "fold", "scenes"]
    if args[0] == "scenes" and len(args) > 1:  # scenes NAME…: those scenes' stills only
        scenes(args[1:])
    else:
        for name in args:
            {"drape": drape, "fold": fold, "scenes": scenes}[name]()
