"""Env steps per second of the Gymnasium tasks, per task and observation mode: one env, and two
async envs (gymnasium.make_vec, one process each); and what an env step costs beyond the physics
it runs (the same frames stepped on the bare Simulator).

    .venv/bin/python -m cloth_sim.bench.envs [--steps 60] [--repeats 3]

Random actions (seeded) from a reset state; initial states are generated into a temporary cache
first, so generation is not timed. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import gymnasium as gym
import numpy as np

import cloth_sim.envs  # noqa: F401  (registers the ids)
from cloth_sim.envs.cloth_env import SUBSTEPS

TASKS = ("ClothFlatten", "ClothFold", "ClothDrop")
MODES = ("key_point", "point_cloud", "depth")


def _rate(env, steps) -> float:
    """Env steps per second of ``steps`` seeded random actions (``env`` may be a vector env)."""
    env.reset(seed=0)
    env.action_space.seed(0)
    acts = [env.action_space.sample() for _ in range(steps)]
    env.step(acts[0])
    t = time.perf_counter()
    for a in acts:
        env.step(a)
    return getattr(env, "num_envs", 1) * steps / (time.perf_counter() - t)


def one_env(task, mode, steps, cache):
    env = gym.make(
        f"cloth_sim/{task}-v0",
        observation_mode=mode,
        cache_dir=cache,
        num_variations=1,
        horizon=10**6,
    )
    rate = _rate(env, steps)
    # the physics alone: the same number of frames on the bare simulator
    u = env.unwrapped
    n = max(3, steps // 4)
    t = time.perf_counter()
    for _ in range(n):
        u.sim.step(u.action_repeat * SUBSTEPS)
    physics = (time.perf_counter() - t) / n
    env.close()
    return rate, 1.0 / rate / physics


def async_envs(task, mode, steps, cache, n=2):
    envs = gym.make_vec(
        f"cloth_sim/{task}-v0",
        num_envs=n,
        vectorization_mode="async",
        observation_mode=mode,
        cache_dir=cache,
        num_variations=1,
        horizon=10**6,
    )
    rate = _rate(envs, steps)
    envs.close()
    return rate


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=60)
    ap.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="the best of this many runs is printed "
        "(this machine is shared: single runs vary by ±30 %%)",
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as cache:
        for task in TASKS:  # the initial states, untimed
            gym.make(f"cloth_sim/{task}-v0", cache_dir=cache, num_variations=1).reset(seed=0)
        print(
            "| task | observation | frames/env step | env steps/s, 1 env | 2 async envs | "
            "1 env step / its physics alone |"
        )
        print("|---|---|---|---|---|---|")
        for task in TASKS:
            for mode in MODES:
                ones = [one_env(task, mode, args.steps, cache) for _ in range(args.repeats)]
                rate, ratio = max(r for r, _ in ones), min(q for _, q in ones)
                rate2 = max(async_envs(task, mode, args.steps, cache) for _ in range(args.repeats))
                repeat = gym.make(f"cloth_sim/{task}-v0", cache_dir=cache).unwrapped.action_repeat
                print(
                    f"| {task} | {mode} | {repeat} | {rate:.1f} | {rate2:.1f} | {ratio:.2f} |",
                    flush=True,
                )


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
