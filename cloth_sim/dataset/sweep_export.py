"""A sweep's runs as a LeRobot dataset: ``cloth-sim sweep SPEC -o OUT --format lerobot`` writes
``OUT/lerobot`` after the sweep, an episode a run whose status is ``ok``, in the spec's order.

The actions are the script's: each gripper it names (``grasp``, ``move``, ``release``) is a
"robot" whose action at frame ``k`` is where it is at frame ``k + 1`` and whether it holds then
(``<gripper>.x, .y, .z, .held``); ``observation.state`` is the cloth's key points (a grid's four
corners, a garment's landmarks) and the grippers where they are (zeros while they hold nothing);
the videos are the run's camera (its ``camera.*`` settings, whether or not the run's bag has it).
A bag holds the cloud but not where the grippers are, so each run is simulated again exactly as
the sweep ran it (the same code, :func:`cloth_sim.sweep.run.simulate`; a run's bytes depend on its
values alone), on Ray as the sweep is. No reward: a sweep has no task to score.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .. import settings
from ..sweep.engine import canonical
from ..sweep.run import read_row, simulate
from ..sweep.spec import Spec, run_id
from . import engine, rollout
from .lerobot import DatasetError, Writer, encode_video, feature_stats, video_feature


def grippers(spec: Spec) -> list[str]:
    """The grippers the script names, in the order it first names them."""
    names: list[str] = []
    for event in spec.script:
        body = next(v for k, v in event.items() if k != "at")
        name = body.get("gripper") if isinstance(body, dict) else None
        if name is None:
            continue
        if not isinstance(name, str) or name.startswith("$"):
            raise DatasetError(
                f"--format lerobot: script gripper {name!r}: a dataset needs the same grippers in "
                f"every run; name them without $variables"
            )
        if name not in names:
            names.append(name)
    return names


def key_points(model) -> tuple[np.ndarray, list[str]]:
    """The particles ``observation.state`` follows: a grid's four corners, a mesh's landmarks."""
    if model.rows:
        r, c = model.rows, model.cols
        return np.array([0, c - 1, (r - 1) * c, r * c - 1]), [f"corner_{i}" for i in range(4)]
    marks = model.meta.get("landmarks") or {}
    return np.array(list(marks.values()), np.int64), list(marks)


def task_string(spec: Spec) -> str:
    steps = []
    for event in spec.script:
        kind, body = next((k, v) for k, v in event.items() if k != "at")
        steps.append(f"{kind} {body.get('gripper') or body.get('collider')}")
    return f"{spec.scene}: " + ", then ".join(steps)


class _Recorder:
    """Per frame: the key points, the grippers (where, held), the camera's colour and depth."""

    def __init__(self, sim, cfg, names):
        from ..sensors.camera import camera_from_settings

        self.names = names
        self.keys, _ = key_points(sim.model)
        self.cam = camera_from_settings(settings.camera_settings(cfg))
        self.rows: list = []
        self.rgb: list = []
        self.depth: list = []

    def frame(self, sim) -> None:
        from ..envs.render import render_rgb

        held = sim.grippers
        where = np.zeros((len(self.names), 3))
        holds = np.zeros(len(self.names))
        for i, name in enumerate(self.names):
            if name in held:
                where[i], holds[i] = sim.gripper_pose(name)[0], 1.0
        self.rows.append((sim.positions[self.keys].ravel(), where, holds))
        f = self.cam.render(sim)
        markers = SimpleNamespace(
            positions=where[holds > 0], radius=0.02, held=[True] * int(holds.sum())
        )
        self.rgb.append(render_rgb(f, sim, self.cam, markers))
        self.depth.append(rollout.depth_levels(f.depth))

    def close(self) -> int:
        return len(self.rows)


def features(spec: Spec) -> tuple[dict, float]:
    """The dataset's features (from the first run's configuration: the same for every run but
    the values) and its fps (the spec's ``frames``)."""
    run = next(iter(spec.runs()))
    params, _ = spec.values_for(run)
    cfg, _, sim, _ = settings.configure(params.get("scene", spec.scene), params)
    _, marks = key_points(sim.model)
    names = grippers(spec)
    cam = settings.camera_settings(cfg)
    h, w = int(cam["height"]), int(cam["width"])
    state = [f"{m}.{c}" for m in marks for c in "xyz"]
    state += [f"{g}.{c}" for g in names for c in "xyz"]
    return {
        "observation.state": {"dtype": "float32", "shape": [len(state)], "names": state},
        "action": {
            "dtype": "float32",
            "shape": [4 * len(names)],
            "names": [f"{g}.{c}" for g in names for c in ("x", "y", "z", "held")],
        },
        "next.done": {"dtype": "bool", "shape": [1], "names": None},
        "observation.images.rgb": video_feature(h, w, spec.frames),
        "observation.images.depth": video_feature(h, w, spec.frames, rollout.DEPTH_RANGE),
    }, float(spec.frames)


def episode(spec: Spec, run: dict) -> dict | None:
    """Run ``run`` again, recording; ``None`` unless it ends ``ok`` (as it did in the sweep)."""
    names = grippers(spec)
    made: list[_Recorder] = []

    def recorder(sim, cfg):
        made.append(_Recorder(sim, cfg, names))
        return made[0]

    row = simulate(spec, run, run_id(run), None, recorder)
    if row["status"] != "ok" or len(made[0].rows) < 2:
        return None
    rec = made[0]
    kp = np.stack([r[0] for r in rec.rows])
    where = np.stack([r[1] for r in rec.rows])
    holds = np.stack([r[2] for r in rec.rows])
    n = len(rec.rows) - 1  # frame k's action is frame k + 1's grippers
    state = np.concatenate([kp[:n], where[:n].reshape(n, -1)], axis=1).astype(np.float32)
    action = np.concatenate([where[1:], holds[1:, :, None]], axis=2).reshape(n, -1)
    frames = {
        "observation.state": state,
        "action": action.astype(np.float32),
        "next.done": np.arange(n) == n - 1,
    }
    videos = {}
    for key, images in (
        ("observation.images.rgb", rec.rgb),
        ("observation.images.depth", rec.depth),
    ):
        images = np.stack(images[:n])
        videos[key] = (encode_video(images, spec.frames), feature_stats(images, image=True))
    return dict(frames=frames, videos=videos, task=task_string(spec), extra={"run": run_id(run)})


def check(spec: Spec) -> None:
    """:class:`DatasetError` when the spec's runs cannot make a dataset (before the sweep runs)."""
    if not spec.script:
        raise DatasetError(
            "--format lerobot: the spec has no script, so its runs have no actions to learn "
            "from; add grasps and moves (see docs/sweeps/dataset.yaml)"
        )
    if spec.frames <= 0:
        raise DatasetError("--format lerobot: the spec records no frames (frames: 0)")
    if not grippers(spec):
        raise DatasetError("--format lerobot: the script moves no gripper: no actions")


def export(spec: Spec, out, workers=None, address=None, overwrite=False, progress=True) -> Writer:
    """``OUT/lerobot`` from the sweep in ``out`` (every run committed); resumes as the dataset
    command does."""
    out = Path(out)
    check(spec)
    root = out / "lerobot"
    recorded = {"sweep": json.loads(canonical(spec)), "format": "lerobot"}
    engine.prepare(root, recorded, overwrite)
    if (root / "meta" / "info.json").exists():
        writer = Writer.open(root)
    else:
        feats, fps = features(spec)
        writer = Writer(root, feats, fps, robot_type="cloth_sim_grippers")
        (root / "meta").mkdir(parents=True, exist_ok=True)
        (root / engine.MARKER).write_text(json.dumps(recorded, indent=2))
    ok = [r for r in spec.runs() if read_row(out / "runs" / run_id(r))["status"] == "ok"]
    jobs = [(spec, r) for r in ok]
    engine.commit_in_order(writer, episode, jobs, writer.episodes, workers, address, progress)
    return writer
