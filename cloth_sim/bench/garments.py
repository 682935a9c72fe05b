"""The garment tasks' scores and speed: ``cloth_sim/TshirtFlatten-v0`` and ``TshirtFold-v0`` over
``--seeds`` variations, the scripted policy (:data:`cloth_sim.envs.policies.SCRIPTED`) against
seeded random actions for as many env steps, and env steps per second of each (self-contact on,
``vbd`` a frame a step).

    .venv/bin/python -m cloth_sim.bench.garments [--seeds 20] [--task TshirtFold] [--cache DIR]

The initial states are generated into ``--cache`` first (about 11 s a variation here), so
generation is not timed. Prints a Markdown table and the means.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--task", nargs="+", default=["TshirtFlatten", "TshirtFold"])
    p.add_argument("--cache", default=None, help="initial-state cache (default: the user cache)")
    args = p.parse_args(argv)
    for task in args.task:
        run(task, args.seeds, args.cache)


def run(task: str, seeds: int, cache) -> None:
    from cloth_sim.envs import garments, policies

    env = getattr(garments, f"{task}Env")(num_variations=seeds, cache_dir=cache)
    start_column = (
        "start coverage / flat" if task == "TshirtFlatten" else "start shape distance (m)"
    )
    print(
        f"\n### {task}\n\n| variation | {start_column} | scripted | env steps | random | "
        "steps/s scripted | steps/s random |"
    )
    print("|---|---|---|---|---|---|---|")
    rows = []
    for v in range(seeds):
        env.reset(seed=v, options={"variation": v})  # generates (untimed) on first use
        start = (
            env.area_start / env.area_flat if task == "TshirtFlatten" else -env.performance_start
        )
        t, n = time.perf_counter(), 0
        for action in policies.SCRIPTED[task](env):
            *_, info = env.step(action)
            n += 1
        scripted, rate = info["normalized_performance"], n / (time.perf_counter() - t)
        env.reset(seed=v, options={"variation": v})
        rng = np.random.default_rng(v)
        t = time.perf_counter()
        for _ in range(n):
            *_, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
        random, rate_r = info["normalized_performance"], n / (time.perf_counter() - t)
        rows.append((scripted, random, rate, rate_r))
        print(
            f"| {v} | {start:.3f} | {scripted:.3f} | {n} | {random:.3f} | {rate:.1f} | "
            f"{rate_r:.1f} |",
            flush=True,
        )
    s, r, a, b = np.array(rows).T
    print(
        f"\n{task}: scripted {s.mean():.3f} ± {s.std():.3f} (min {s.min():.3f}), random "
        f"{r.mean():.3f} ± {r.std():.3f}; env steps/s {a.mean():.1f} scripted, {b.mean():.1f} "
        "random"
    )


if __name__ == "__main__":
    main()
