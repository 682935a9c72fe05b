"""cloth_sim beside NVIDIA Warp's own CPU cloth benchmark, on Warp's scene, in one process.

Warp's scene (``warp/examples/benchmarks/benchmark_cloth.py``): an N×N grid at 0.1 m spacing, 0.1
kg particles, structural, shear and bend springs with k = 1000 N/m and damping 10 N·s/m, two
corners pinned, gravity, symplectic Euler at dt = 1/960 s. Warp runs its own kernels
(``benchmark_cloth_warp.WpIntegrator``, float32, on the CPU device); cloth_sim runs
``symplectic_euler`` (float64), ``rk4`` and the two post-seed methods (``liu2013`` with 10
iterations, ``xpbd`` with 10 substeps, at the same dt: their cost per step) on the same springs.
The runs alternate in short bursts and the medians are compared, so a load change on a shared
machine hits both. Warp is an optional extra (``requirements-peers.txt``, installed by ``make
bench-peers``, never by ``make test``).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from ..model import ClothModel
from ..simulator import Simulator

DT = 1.0 / 960.0


def warp_scene(n: int) -> ClothModel:
    return ClothModel.grid(
        n, n, 0.1, 0.1, stiffness=1000.0, damping=10.0, pinned=[(0, 0), (0, -1)]
    )


class _WarpCloth:
    """The attributes Warp's benchmark integrator reads, from a cloth_sim model."""

    def __init__(self, model: ClothModel):
        self.positions = model.positions.astype(np.float32)
        self.inv_masses = np.where(model.pinned, 0.0, 1.0 / model.masses).astype(np.float32)
        self.spring_indices = model.springs.ravel().astype(np.int32)
        self.spring_lengths = model.rest_lengths.astype(np.float32)
        self.spring_stiffness = model.stiffness.astype(np.float32)
        self.spring_damping = model.damping.astype(np.float32)
        self.num_particles = model.n_particles
        self.num_springs = model.n_springs


def _burst(run, steps: int) -> float:
    t = time.perf_counter()
    run(steps)
    return (time.perf_counter() - t) / steps


def print_peer_table(sizes=(32, 64, 128), rounds: int = 9, burst_seconds: float = 0.1) -> int:
    try:
        import warp as wp

        wp.config.quiet = True
        from warp.examples.benchmarks.benchmark_cloth_warp import WpIntegrator
    except ImportError:
        print(
            "warp-lang is not installed: `make bench-peers` installs the pinned optional extra "
            "(requirements-peers.txt)"
        )
        return 1
    wp.init()
    print(
        f"# Warp {wp.config.version} CPU (float32) vs cloth_sim (float64) on Warp's cloth scene, "
        f"dt = 1/960 s; median of {rounds} alternating bursts"
    )
    print(
        "| N | Warp ms/step | symplectic_euler ms/step | cloth_sim speed / Warp's | rk4 ms/step | "
        "rk4 / symplectic_euler | liu2013 ms/step | xpbd ms/step |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for n in sizes:
        model = warp_scene(n)
        peer = WpIntegrator(_WarpCloth(model), "cpu")
        sims = {
            name: Simulator(model, integrator=name, dt=DT)
            for name in ("symplectic_euler", "rk4", "liu2013", "xpbd")
        }
        runs = {"warp": lambda k: peer.simulate(k * DT, k)}
        runs.update({name: sim.step for name, sim in sims.items()})
        steps = {}
        for name, run in runs.items():  # warm-up (Warp compiles, numba loads), and a burst size
            run(16)
            steps[name] = max(1, int(burst_seconds / max(_burst(run, 16), 1e-7)))
        times = {name: [] for name in runs}
        for _ in range(rounds):
            for name, run in runs.items():
                times[name].append(_burst(run, steps[name]))
        med = {name: statistics.median(t) for name, t in times.items()}
        print(
            f"| {n} | {1e3 * med['warp']:.3f} | {1e3 * med['symplectic_euler']:.3f} | "
            f"{med['warp'] / med['symplectic_euler']:.2f}× | {1e3 * med['rk4']:.3f} | "
            f"{med['rk4'] / med['symplectic_euler']:.2f}× | {1e3 * med['liu2013']:.3f} | "
            f"{1e3 * med['xpbd']:.3f} |"
        )
    return 0
