"""Behaviour cloning with LeRobot on a dataset cloth_sim wrote, evaluated in the env it came from.

    make bench-learning       # the dataset, LeRobot in .venv-learning, then this script
    .venv-learning/bin/python examples/learning/train_act.py --dataset build/datasets/ClothFold

LeRobot's ``LeRobotDataset`` loads the dataset (``cloth-sim dataset ClothFold --policy scripted``);
LeRobot's ACT (action chunking with transformers, Zhao et al. 2023) learns the scripted policy's
actions from ``observation.state`` (the cloth's corners, ACT's "environment state", and the
pickers, its "robot state": the dataset's names tell them apart), normalized by the dataset's own
``meta/stats.json``. It trains on the CPU for ``--steps`` steps, then plays ``--eval`` episodes of
the task on variations no episode of the dataset started from (its ``meta/episodes`` records each
one's) and prints the normalized performance of the trained policy beside the scripted policy's
and a random one's on the same variations.

torch and LeRobot are not in cloth_sim's requirements: ``requirements-learning.txt`` pins them for
a venv of their own (LeRobot 0.4 pins numpy below 2.3; cloth_sim's venv has 2.4).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

CHUNK = 8  # actions predicted at once (an episode of ClothFold is about 20 env steps)


def load(root: str):
    """States, action chunks and their padding masks, from the dataset as LeRobot loads it."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("cloth_sim/dataset", root=root, video_backend="pyav")
    print(ds)
    item = ds[0]  # a frame as LeRobot serves it for training, the videos decoded
    for key, value in item.items():
        print(f"  {key}: {tuple(value.shape) if hasattr(value, 'shape') else repr(value)}")
    frames = ds.hf_dataset
    frames.reset_format()  # the columns as arrays, without decoding the videos per item
    state = np.asarray(frames["observation.state"], np.float32)
    action = np.asarray(frames["action"], np.float32)
    chunks = np.zeros((len(state), CHUNK, action.shape[1]), np.float32)
    pad = np.ones((len(state), CHUNK), bool)
    for ep in ds.meta.episodes:
        a, b = ep["dataset_from_index"], ep["dataset_to_index"]
        for i in range(a, b):
            n = min(CHUNK, b - i)
            chunks[i, :n], pad[i, :n] = action[i : i + n], False
            chunks[i, n:] = action[b - 1]
    stats = {
        k: {s: np.asarray(v, np.float32) for s, v in ds.meta.stats[k].items()}
        for k in ("observation.state", "action")
    }
    return ds, state, chunks, pad, stats


def split(ds):
    """The columns of ``observation.state`` that are the pickers (ACT's robot state) and those that
    are the cloth (its environment state), by the features' names."""
    names = ds.features["observation.state"]["names"]
    robot = np.array([n.startswith("picker_") for n in names])
    return robot, ~robot


def inputs(state: np.ndarray, parts) -> dict:
    robot, cloth = parts
    return {
        "observation.state": torch.from_numpy(np.ascontiguousarray(state[..., robot])),
        "observation.environment_state": torch.from_numpy(np.ascontiguousarray(state[..., cloth])),
    }


def make_policy(parts, action_dim: int):
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy

    config = ACTConfig(
        input_features={
            "observation.state": PolicyFeature(FeatureType.STATE, (int(parts[0].sum()),)),
            "observation.environment_state": PolicyFeature(
                FeatureType.ENV, (int(parts[1].sum()),)
            ),
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (action_dim,))},
        chunk_size=CHUNK,
        n_action_steps=CHUNK,
        dim_model=128,
        n_heads=4,
        dim_feedforward=512,
        n_encoder_layers=2,
        use_vae=False,
        dropout=0.0,
        device="cpu",
    )
    return ACTPolicy(config)


def normalizer(stats):
    def norm(key, x):
        return (x - stats[key]["mean"]) / np.maximum(stats[key]["std"], 1e-6)

    def denorm(key, x):
        return x * np.maximum(stats[key]["std"], 1e-6) + stats[key]["mean"]

    return norm, denorm


def train(policy, parts, state, chunks, pad, stats, steps: int, batch: int, seed: int):
    norm, _ = normalizer(stats)
    s = norm("observation.state", state).astype(np.float32)
    a = torch.from_numpy(norm("action", chunks).astype(np.float32))
    p = torch.from_numpy(pad)
    opt = torch.optim.AdamW(policy.parameters(), lr=3e-4, weight_decay=1e-4)
    g = torch.Generator().manual_seed(seed)
    policy.train()
    t = time.perf_counter()
    for step in range(1, steps + 1):
        i = torch.randint(len(s), (batch,), generator=g)
        loss, _ = policy.forward(
            {**inputs(s[i.numpy()], parts), "action": a[i], "action_is_pad": p[i]}
        )
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % max(1, steps // 10) == 0 or step == 1:
            print(f"step {step:5d}  L1 loss {loss.item():.4f}  {time.perf_counter() - t:.0f} s")
    policy.eval()


def evaluate(task: str, policy, parts, stats, episodes: int, seen: set):
    """Normalized performance at each episode's end: the trained policy, the scripted one, a
    random one, on the same variations."""
    import gymnasium

    import cloth_sim.envs  # noqa: F401  (registers the tasks)
    from cloth_sim.envs import policies

    norm, denorm = normalizer(stats)
    env = gymnasium.make(f"cloth_sim/{task}-v0").unwrapped
    scores = {"trained": [], "scripted": [], "random": []}
    unseen = [v for v in range(env.num_variations) if v not in seen][:episodes]
    for v in unseen:
        start = dict(seed=v, options={"variation": v})
        env.reset(**start)
        policy.reset()
        for _ in range(env.horizon):
            x = norm("observation.state", env.key_point_state())[None].astype(np.float32)
            with torch.no_grad():
                y = policy.select_action(inputs(x, parts)).numpy()[0]
            action = np.clip(denorm("action", y), env.action_space.low, env.action_space.high)
            *_, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        scores["trained"].append(info["normalized_performance"])
        env.reset(**start)
        n = 0
        for action in policies.SCRIPTED[env.task](env):
            *_, info = env.step(action)
            n += 1
        scores["scripted"].append(info["normalized_performance"])
        env.reset(**start)
        rng = np.random.default_rng(v)
        for _ in range(n):
            *_, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
        scores["random"].append(info["normalized_performance"])
        print(
            f"variation {env.variation:4d}: trained {scores['trained'][-1]:.3f}, scripted "
            f"{scores['scripted'][-1]:.3f}, random {scores['random'][-1]:.3f}"
        )
    return scores


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", default="build/datasets/ClothFold", help="the dataset's root")
    p.add_argument("--task", default="ClothFold", help="the env to evaluate in")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--eval", type=int, default=20, metavar="N", help="evaluation episodes")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    ds, state, chunks, pad, stats = load(args.dataset)
    print(f"{ds.num_episodes} episodes, {len(state)} frames; training ACT on the CPU")
    parts = split(ds)
    policy = make_policy(parts, chunks.shape[2])
    t = time.perf_counter()
    train(policy, parts, state, chunks, pad, stats, args.steps, args.batch, args.seed)
    print(f"trained in {time.perf_counter() - t:.0f} s")
    seen = set(ds.meta.episodes["variation"])
    scores = evaluate(args.task, policy, parts, stats, args.eval, seen)
    print()
    for name, s in scores.items():
        print(f"{name:9s} normalized performance {np.mean(s):.3f} ± {np.std(s):.3f}")


if __name__ == "__main__":
    main()
