"""``cloth-sim bench vector-env``: env steps a second of ClothFold as one vector env
(:class:`~cloth_sim.envs.vector.ClothFoldVectorEnv`, every world in one batch of cloths) against
Gymnasium's ``AsyncVectorEnv`` of single envs (a process each), in one process, side by side.

    cloth-sim bench vector-env [--device cpu|cuda] [--envs 1 2 16] [--async-envs 2] [--steps 20]

Each row: ``num_envs`` worlds, seeded random picker actions (every world its own), from a reset
state after one untimed step (compilation, initial states generated into a temporary cache
first); env steps a second is ``num_envs × steps / wall``. An env step is 8 frames of 8 steps
(SoftGym's action repeat; ClothFold's 24×24 cloth, symplectic Euler with its strain limit and the
floor), so world-seconds a second are env steps a second × 8/60. On a GPU, ``cloth-sim bench gpu``
prints the cuda rows (docs/gpu.md).
"""

from __future__ import annotations

import os
import tempfile
import time

import gymnasium as gym

import cloth_sim.envs  # noqa: F401  (registers the ids)

from ..envs.cloth_env import FRAME
from ..envs.vector import ClothFoldVectorEnv


def steps_per_second(envs, steps: int, seed: int = 0) -> float:
    """Env steps a second of ``steps`` seeded random actions on vector env ``envs`` (reset with
    ``seed`` first; one untimed step)."""
    envs.reset(seed=seed)
    envs.action_space.seed(seed)
    acts = [envs.action_space.sample() for _ in range(steps + 1)]
    envs.step(acts[0])
    t = time.perf_counter()
    for a in acts[1:]:
        envs.step(a)
    return envs.num_envs * steps / (time.perf_counter() - t)


def print_vector_table(
    device: str = "cpu",
    counts=(1, 2, 16),
    async_envs: int | None = None,
    steps: int = 20,
    task: dict | None = None,
    **kw,
) -> list:
    """One row a world count on ``device``, then the ``AsyncVectorEnv`` row (``async_envs``
    processes: the machine's cores when None); ``task``: ClothFold's keywords for both (its
    defaults when None: the 24×24 cloth), ``kw`` the vector env's (``precision``, ``launch``).
    Returns the rows."""
    async_envs = async_envs or os.cpu_count() or 1
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        env_kw = dict(task or {}, cache_dir=cache, num_variations=1, horizon=10**6)
        single = gym.make("cloth_sim/ClothFold-v0", **env_kw)
        single.reset(seed=0)  # the initial state generated, untimed
        u = single.unwrapped
        repeat = u.action_repeat
        print(
            f"ClothFold, {u.rows}x{u.cols}, {repeat} frames an env step; env steps a second "
            f"(world-seconds a second = env steps/s x {repeat * FRAME:.3f})"
        )
        print(f"{'vector env':>26} {'num_envs':>9} {'env steps/s':>12} {'world-s/s':>10}")
        for n in counts:
            envs = ClothFoldVectorEnv(num_envs=n, device=device, **env_kw, **kw)
            rate = steps_per_second(envs, steps)
            rows.append({"kind": f"ClothFoldVectorEnv {device}", "envs": n, "rate": rate})
            print(
                f"{rows[-1]['kind']:>26} {n:>9} {rate:>12.1f} {rate * repeat * FRAME:>10.2f}",
                flush=True,
            )
        envs = gym.make_vec(
            "cloth_sim/ClothFold-v0",
            num_envs=async_envs,
            vectorization_mode="async",
            **env_kw,
        )
        rate = steps_per_second(envs, max(2, steps // 2))
        envs.close()
        rows.append({"kind": "AsyncVectorEnv cpu", "envs": async_envs, "rate": rate})
        print(
            f"{'AsyncVectorEnv cpu':>26} {async_envs:>9} {rate:>12.1f} "
            f"{rate * repeat * FRAME:>10.2f}",
            flush=True,
        )
    return rows
