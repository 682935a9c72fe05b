"""The README's strips of frames: a scripted fold on ClothFold-v0 (seed 0) or TshirtFold-v0
(variation 0).

.venv/bin/python docs/envs/plot_fold_strip.py              # writes docs/envs/fold_strip.png
.venv/bin/python docs/envs/plot_fold_strip.py TshirtFold   # docs/envs/tshirt_fold_strip.png
"""

import sys
from pathlib import Path

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import cloth_sim.envs  # noqa: E402,F401
from cloth_sim.envs import policies  # noqa: E402

task = sys.argv[1] if len(sys.argv) > 1 else "ClothFold"
env = gym.make(
    f"cloth_sim/{task}-v0",
    render_mode="rgb_array",
    image_size=240,
    cache_dir=False,
    num_variations=1000 if task == "ClothFold" else 1,
)
obs, info = env.reset(seed=0)
frames, scores = [env.render()], [info["normalized_performance"]]
for action in policies.SCRIPTED[env.unwrapped.task](env.unwrapped):
    obs, reward, terminated, truncated, info = env.step(action)
    frames.append(env.render())
    scores.append(info["normalized_performance"])
pick = np.linspace(0, len(frames) - 1, 6).round().astype(int)
fig, axes = plt.subplots(1, len(pick), figsize=(2.2 * len(pick), 2.45))
for ax, i in zip(axes, pick):
    ax.imshow(frames[i])
    ax.set_title(f"step {i}: {scores[i]:.2f}", fontsize=9)
    ax.axis("off")
start = "seed 0" if task == "ClothFold" else "variation 0"
fig.suptitle(f"{task}-v0, {start}, scripted fold (title: normalized_performance)", fontsize=10)
fig.tight_layout()
out = Path(__file__).with_name(
    "fold_strip.png" if task == "ClothFold" else "tshirt_fold_strip.png"
)
fig.savefig(out, dpi=80)
print(out, f"final normalized_performance {scores[-1]:.3f}")
