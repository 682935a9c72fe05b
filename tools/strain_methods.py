"""The strain limit's two methods side by side on the hanging cloth (prints figures, changes nothing).

``.venv/bin/python tools/strain_methods.py [--sizes 32 64 128] [--scenes curtain flag ...]``

The hanging scene at N×N (the 1 m, 10.24 kg cloth; symplectic Euler at 1 ms, 0.5 ms from 128×128,
whose stable step is 0.53 ms), τ = 0.1, Provot's 20 passes and the projection in one process: ms per
step, the worst and mean strain of the limited springs (sampled every 10 steps), and for the
projection its iterations, CG iterations and active springs per step and how often it stopped at its
iteration limit (``strain_limit_passes``, 20). ``--scenes``: instead, each named scene as it ships
(each method forced), 2 s: ms per step and the worst strain after the whole step (stages after the
strain limit, contacts and self-collision, may stretch a spring again).
"""

from __future__ import annotations

import argparse

import numpy as np

from cloth_sim.bench.steps import _hanging, _ms_per_step
from cloth_sim.scene import load_scene


def scenes(names) -> None:
    print("| scene | method | worst strain | ms/step |")
    print("|---|---|---|---|")
    for name in names:
        for method in ("provot", "projection"):
            scene = load_scene(name)
            scene.build_simulator(strain_limit_method=method).step(3)  # its kernels
            sim = scene.build_simulator(strain_limit_method=method)
            worst = []
            ms = _ms_per_step(sim, 2.0, lambda: worst.append(float(sim.strains(limited_only=True).max())))
            print(f"| {name} | {method} | {max(worst):.4f} | {ms:.3f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--scenes", nargs="+", default=None)
    args = ap.parse_args()
    if args.scenes:
        scenes(args.scenes)
        return
    print("| N | method | worst strain | mean strain | ms/step | iterations | at the limit | "
          "CG iterations | active springs (mean / most) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        dt, seconds = (1e-3, 3.0) if n < 128 else (5e-4, 1.5)
        for method in ("provot", "projection"):
            _hanging(n, strain_limit=0.1, dt=dt, strain_limit_method=method).step(5)  # its kernels
            sim = _hanging(n, strain_limit=0.1, dt=dt, strain_limit_method=method)
            stage, stats, worst, mean = sim._strain, [], [], []
            if method == "projection":
                project = stage._project

                def counted(x, project=project, stage=stage):
                    used = project(x)
                    stats.append(stage._scratch.stats.copy())
                    return used

                stage._project = counted

            def sample():
                s = sim.strains(limited_only=True)
                worst.append(float(s.max()))
                mean.append(float(s.mean()))

            ms = _ms_per_step(sim, seconds, sample)
            st = np.array(stats) if stats else np.zeros((1, 4))
            extra = (f"{st[:, 0].mean():.1f} | {np.mean(st[:, 0] >= stage.passes):.3f} | "
                     f"{st[:, 1].mean():.0f} | {st[:, 2].mean():.0f} / {st[:, 2].max():.0f}"
                     if stats else "— | — | — | —")
            print(f"| {n} | {method} | {max(worst):.4f} | {np.mean(mean):.4f} | {ms:.3f} | {extra} |",
                  flush=True)


if __name__ == "__main__":
    main()
