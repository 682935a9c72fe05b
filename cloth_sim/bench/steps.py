"""ms/step of integrators on the hanging scene at several grid sizes, side by side in one process."""

from __future__ import annotations

import os
import platform
import time

from ..scene import load_scene


def time_steps(sim, seconds: float = 1.0, repeats: int = 3) -> float:
    """Minimum over ``repeats`` of the mean wall time of one step (s), after a warm-up."""
    sim.step(5)  # warm-up (numba caches, buffers)
    n = 5
    while True:  # find a batch size that takes about seconds/repeats
        t = time.perf_counter()
        sim.step(n)
        el = time.perf_counter() - t
        if el > seconds / repeats / 4 or n > 1_000_000:
            break
        n *= 4
    n = max(1, int(n * (seconds / repeats) / max(el, 1e-9)))
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        sim.step(n)
        best = min(best, (time.perf_counter() - t) / n)
    return best


def print_step_table(sizes, names, seconds: float = 1.0) -> list[dict]:
    scene = load_scene("hanging")
    print(f"# hanging scene ({scene.source}) resized to N×N over 1 m; k/m as in the scene, dt={scene.dt} s, "
          f"strain limit {scene.strain_limit}; {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores; min of 3")
    print("| N | particles | integrator | ms/step, no strain limit | ms/step, strain limit | "
          "force evals/step |")
    print("|---|---|---|---|---|---|")
    rows = []
    tau = scene.strain_limit
    for n in sizes:
        for name in names:
            scene.integrator = name
            sim = scene.build_simulator(rows=n, cols=n, spacing=1.0 / (n - 1))
            sim.advance(0.5)  # past the release, into the hanging motion
            sim.strain_limit = None
            e0, s0 = sim.force_evaluations, sim.steps_taken
            plain = 1e3 * time_steps(sim, seconds)
            evals = (sim.force_evaluations - e0) / max(sim.steps_taken - s0, 1)
            sim.strain_limit = tau
            limited = 1e3 * time_steps(sim, seconds)
            rows.append({"N": n, "integrator": name, "ms_per_step": plain, "ms_per_step_strain": limited})
            print(f"| {n} | {n * n} | {name} | {plain:.3f} | {limited:.3f} | {evals:.0f} |", flush=True)
    return rows
