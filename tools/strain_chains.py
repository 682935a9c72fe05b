"""The strain projection's preconditioner, its chains against its diagonal, side by side.

    .venv/bin/python tools/strain_chains.py [N] [SECONDS] [ROUNDS]

For `hanging` and `flag` resized to N×N (default 64: the 2 m, 41 kg cloths a user gets with
`-p rows:=64 -p cols:=64`), SECONDS of simulated time (default 2) from the start, ROUNDS times
(default 2) in turn: with `strain_projection.STRAIGHT` above 1 no two springs pair, every chain
is one spring long and the preconditioner is the system's diagonal (Jacobi, the method before
issue 51's third session); at its default the chains. Prints ms a step, the projection's share,
its linearisations and CG iterations a step, the worst strain and the lowest point reached.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from cloth_sim.constraints import strain_projection
from cloth_sim.scene import load_scene

CHAINS = strain_projection.STRAIGHT


def run(scene: str, n: int, seconds: float, straight: float) -> str:
    strain_projection.STRAIGHT = straight  # read when the projection's scratch is made
    sim = load_scene(scene).build_simulator(rows=n, cols=n)
    sim.step()  # the scratch, made at the first projection
    project = strain_projection.project
    spent = np.zeros(3)  # seconds, linearisations, CG iterations

    def timed(*args):
        t = time.perf_counter()
        out = project(*args)
        spent[0] += time.perf_counter() - t
        stats = args[-1]
        spent[1] += stats[0]
        spent[2] += stats[1]
        return out

    strain_projection.project = timed
    try:
        steps = round(seconds / sim.dt)
        lowest = np.inf
        t = time.perf_counter()
        for _ in range(steps):
            sim.step()
            lowest = min(lowest, float(sim.positions[:, 2].min()))
        wall = time.perf_counter() - t
    finally:
        strain_projection.project = project
        strain_projection.STRAIGHT = CHAINS
    worst = sim.max_strain()
    return (
        f"| {scene} | {'chains' if straight <= 1 else 'diagonal'} | {1e3 * wall / steps:.3f} | "
        f"{sim.dt * steps / wall:.2f} | {1e3 * spent[0] / steps:.3f} | {spent[1] / steps:.2f} | "
        f"{spent[2] / steps:.1f} | {worst:.4f} | {lowest:.4f} |"
    )


def main(argv: list[str]) -> None:
    n = int(argv[0]) if argv else 64
    seconds = float(argv[1]) if len(argv) > 1 else 2.0
    rounds = int(argv[2]) if len(argv) > 2 else 2
    print(f"# {n}×{n}, {seconds:g} s simulated from the start, {rounds} rounds in turn")
    print(
        "| scene | preconditioner | ms/step | real-time factor | projection ms/step | "
        "linearisations/step | CG iterations/step | worst strain at the end | lowest point (m) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for scene in ("hanging", "flag"):
        for _ in range(rounds):
            for straight in (2.0, CHAINS):
                print(run(scene, n, seconds, straight), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
