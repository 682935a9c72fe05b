"""One episode of a task under a policy, as a dataset's frames (:mod:`cloth_sim.envs` in, arrays
and encoded video out; no file is written here).

Episode ``e`` of a dataset of seed ``s`` resets the env with the seed ``SeedSequence([s, e])``
gives (which picks the variation), and the random policy draws from the generator of the same
sequence: an episode's frames depend on ``(task, options, s, e)`` alone, wherever it runs.

Frame ``t`` holds what the policy saw and did: ``observation.state`` (the key points, then the
pickers: :meth:`~cloth_sim.envs.cloth_env.ClothEnv.key_point_state`), the camera's colour and
depth images and, with ``observation`` ``"point_cloud"`` or ``"depth"``, the env's observation of
that mode, lossless (``observation.point_cloud``, ``observation.depth``); ``action``; and what
followed it, ``next.reward`` and ``next.done`` (the policy finished, or the horizon reached), as
LeRobot records them.
"""

from __future__ import annotations

import itertools

import numpy as np

from .lerobot import DatasetError, encode_video, feature_stats, video_feature

POLICIES = ("scripted", "random")
OBSERVATIONS = ("key_point", "point_cloud", "depth")
#: the depth video's grey levels: 1–255 from ``DEPTH_RANGE[0]`` to ``[1]`` metres, 0 where
#: nothing is seen (about 1.1 cm a level; ``--observation depth`` keeps the metres as they are)
DEPTH_RANGE = (0.25, 3.0)


def make_env(task: str, observation: str, image_size: int, cache_dir=None):
    """The task's env (its Gymnasium id or short name, ``TshirtFold`` for
    ``cloth_sim/TshirtFold-v0``), unwrapped; :class:`DatasetError` naming the accepted ones."""
    import gymnasium

    from .. import envs

    env_id = task if "/" in task else f"cloth_sim/{task}-v0"
    if env_id not in envs.ENV_IDS:
        names = ", ".join(i.split("/")[1].removesuffix("-v0") for i in envs.ENV_IDS)
        raise DatasetError(f"TASK {task!r} is not a cloth_sim task: expected one of {names}")
    if observation not in OBSERVATIONS:
        raise DatasetError(
            f"--observation {observation!r} is not accepted: expected one of "
            f"{', '.join(OBSERVATIONS)}"
        )
    kwargs = dict(observation_mode=observation, image_size=image_size)
    if cache_dir is not None:
        kwargs["cache_dir"] = cache_dir
    return gymnasium.make(env_id, **kwargs).unwrapped


def check_policy(env, policy: str) -> None:
    """:class:`DatasetError` when ``policy`` cannot act in ``env``."""
    from ..envs import policies

    if policy not in POLICIES:
        raise DatasetError(
            f"--policy {policy!r} is not accepted: expected one of {', '.join(POLICIES)}"
        )
    if policy != "scripted":
        return
    if env.task not in policies.SCRIPTED:
        raise DatasetError(
            f"--policy scripted: {env.task} has no scripted policy (those of "
            f"{', '.join(policies.SCRIPTED)}); use --policy random"
        )
    if env.action_mode != "picker" or env.num_picker != 2:
        raise DatasetError(
            f"--policy scripted: the scripted policies move two pickers by [dx, dy, dz, pick] "
            f"(action_mode 'picker', 8 numbers); this env's action space is "
            f"{env.action_mode!r} with {env.num_picker} pickers, shape "
            f"{env.action_space.shape}; use --policy random"
        )


def fps(env) -> float:
    """The env's control rate (Hz): an env step is ``action_repeat`` frames of 1/60 s (a
    pick-and-place step, however long it takes, counts as one of them)."""
    from ..envs.cloth_env import FRAME

    return 1.0 / (FRAME * env.action_repeat)


def features(env, observation: str) -> dict:
    """The dataset's features for ``env`` (``info.json``'s, without LeRobot's default ones)."""
    names = list(
        getattr(env, "key_point_names", None) or [f"corner_{k}" for k in range(len(env.corners))]
    )
    names += [f"picker_{i}" for i in range(env.num_picker)]
    parts = ("dx", "dy", "dz", "pick") if env.action_mode == "picker" else ("x", "y", "z", "pick")
    action_names = [f"picker_{i}.{c}" for i in range(env.num_picker) for c in parts]
    size = env.image_size
    out = {
        "observation.state": {
            "dtype": "float32",
            "shape": [3 * len(names)],
            "names": [f"{n}.{c}" for n in names for c in "xyz"],
        },
        "action": {"dtype": "float32", "shape": [len(action_names)], "names": action_names},
        "next.reward": {"dtype": "float32", "shape": [1], "names": None},
        "next.done": {"dtype": "bool", "shape": [1], "names": None},
        "observation.images.rgb": video_feature(size, size, fps(env)),
        "observation.images.depth": video_feature(size, size, fps(env), DEPTH_RANGE),
    }
    if observation == "point_cloud":
        out["observation.point_cloud"] = {
            "dtype": "float32",
            "shape": [env.max_points, 3],
            "names": ["points", "xyz"],
        }
    elif observation == "depth":
        out["observation.depth"] = {
            "dtype": "float32",
            "shape": [size, size],
            "names": ["height", "width"],
        }
    return out


def depth_levels(depth: np.ndarray) -> np.ndarray:
    """Metres (NaN where nothing is seen) as :data:`DEPTH_RANGE`'s grey levels, three channels."""
    lo, hi = DEPTH_RANGE
    level = np.clip(np.round(1 + 254 * (depth - lo) / (hi - lo)), 1, 255)
    level = np.where(np.isfinite(depth), level, 0).astype(np.uint8)
    return np.repeat(level[..., None], 3, axis=-1)


def episode_seed(seed: int, index: int) -> int:
    """The seed ``reset`` gets for episode ``index`` of a dataset of seed ``seed``."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


def episode(env, index: int, seed: int, policy: str) -> dict:
    """Run episode ``index`` (see the module docstring); returns ``frames`` (a column a feature),
    ``videos`` (``{key: (MP4 bytes, statistics)}``), ``task`` and ``extra`` (the episode's
    ``normalized_performance`` at its end, its variation)."""
    from ..envs import policies
    from ..envs.render import render_rgb

    obs, info = env.reset(seed=episode_seed(seed, index))
    rng = np.random.default_rng(np.random.SeedSequence([seed, index]))
    if policy == "scripted":
        actions = iter(policies.SCRIPTED[env.task](env))
    else:
        actions = (
            rng.uniform(env.action_space.low, env.action_space.high) for _ in itertools.count()
        )
    cols: dict[str, list] = {k: [] for k in ("observation.state", "action", "next.reward")}
    cols["next.done"] = []
    extra_obs = {"point_cloud": "observation.point_cloud", "depth": "observation.depth"}.get(
        env.observation_mode
    )
    if extra_obs:
        cols[extra_obs] = []
    rgb, depth = [], []
    action = next(actions, None)
    while action is not None:
        frame = env.cam.render(env.sim)
        rgb.append(render_rgb(frame, env.sim, env.cam, env.pickers))
        depth.append(depth_levels(frame.depth))
        cols["observation.state"].append(env.key_point_state())
        if extra_obs == "observation.point_cloud":
            cols[extra_obs].append(obs[: 3 * env.max_points].reshape(-1, 3))
        elif extra_obs:
            cols[extra_obs].append(obs)
        cols["action"].append(np.asarray(action, np.float32))
        obs, reward, terminated, truncated, info = env.step(action)
        action = None if terminated or truncated else next(actions, None)
        cols["next.reward"].append(np.float32(reward))
        cols["next.done"].append(action is None)
    if not rgb:
        raise DatasetError(f"episode {index}: the {policy} policy took no action")
    rate = fps(env)
    videos = {}
    for key, images in (("observation.images.rgb", rgb), ("observation.images.depth", depth)):
        images = np.stack(images)
        videos[key] = (encode_video(images, rate), feature_stats(images, image=True))
    return dict(
        frames={k: np.stack(v) for k, v in cols.items()},
        videos=videos,
        task=env.instruction,
        extra={
            "normalized_performance": float(info["normalized_performance"]),
            "variation": int(env.variation),
        },
    )
