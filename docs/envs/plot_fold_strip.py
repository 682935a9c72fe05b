"""The README's strip of frames: a scripted fold on ClothFold-v0, seed 0.

.venv/bin/python docs/envs/plot_fold_strip.py   # writes docs/envs/fold_strip.png
"""

from pathlib import Path

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import cloth_sim.envs  # noqa: E402,F401
from cloth_sim.envs import policies  # noqa: E402

env = gym.make(
    "cloth_sim/ClothFold-v0",
    render_mode="rgb_array",
    image_size=240,
    cache_dir=False,
    num_variations=1000,
)
obs, info = env.reset(seed=0)
frames, scores = [env.render()], [info["normalized_performance"]]
for action in policies.fold(env.unwrapped):
    obs, reward, terminated, truncated, info = env.step(action)
    frames.append(env.render())
    scores.append(info["normalized_performance"])
pick = np.linspace(0, len(frames) - 1, 6).round().astype(int)
fig, axes = plt.subplots(1, len(pick), figsize=(2.2 * len(pick), 2.45))
for ax, i in zip(axes, pick):
    ax.imshow(frames[i])
    ax.set_title(f"step {i}: {scores[i]:.2f}", fontsize=9)
    ax.axis("off")
fig.suptitle("ClothFold-v0, seed 0, scripted fold (title: normalized_performance)", fontsize=10)
fig.tight_layout()
out = Path(__file__).with_name("fold_strip.png")
fig.savefig(out, dpi=80)
print(out, f"final normalized_performance {scores[-1]:.3f}")
