"""A Gymnasium task: SoftGym's ClothFold on cloth_sim's physics, scripted and random actions.

    .venv/bin/python examples/gymnasium_task.py [--quick]

``import cloth_sim.envs`` registers the tasks (ClothFlatten, ClothFold, ClothDrop, their
pick-and-place forms, TshirtFlatten, TshirtFold). The scripted policy reads the cloth's corners
from the simulation; a learned one would read ``obs`` (key points here; ``"point_cloud"`` or
``"depth"`` for the camera's view).
"""

import argparse

import gymnasium as gym

import cloth_sim.envs  # noqa: F401  (registers the ids)
from cloth_sim.envs import policies

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="10 random steps, no vector env (the tests)")
quick = p.parse_args().quick

env = gym.make("cloth_sim/ClothFold-v0", observation_mode="key_point", render_mode="rgb_array")
obs, info = env.reset(seed=0)  # a flat cloth turned by a random angle (the variation: the seed)
for action in policies.fold(env.unwrapped):  # the scripted fold
    obs, reward, terminated, truncated, info = env.step(action)
print(f"scripted fold: normalized performance {info['normalized_performance']:.3f}")
frame = env.render()  # (128, 128, 3) uint8
print("frame", frame.shape, frame.dtype)

obs, info = env.reset(seed=0)
for _ in range(10 if quick else env.unwrapped.horizon):
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
print(f"random actions: normalized performance {info['normalized_performance']:.3f}")
env.close()

# ClothFold's own vector env: every world in one batch of cloths, in this process
# (device="cuda" steps them all in the same launches on a GPU: docs/gpu.md)
envs = gym.make_vec("cloth_sim/ClothFold-v0", num_envs=4)
obs, info = envs.reset(seed=0)
obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
print(type(envs).__name__, "observations", obs.shape, "rewards", reward.shape)
envs.close()

if not quick:  # four envs in four processes (any task, any observation)
    envs = gym.make_vec("cloth_sim/ClothFlatten-v0", num_envs=4, vectorization_mode="async")
    obs, info = envs.reset(seed=0)
    obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
    print("vector env observations", obs.shape)
    envs.close()
