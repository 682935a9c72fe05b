"""``vbd``'s cost per vertex and iteration on the grid against its memory-bandwidth floor.

``cloth-sim bench vbd-floor --sizes 32 64 128`` times the hanging_provot cloth (1 m, 10.24 kg, the
scene's springs, 1/60 s, no strain limit) at two iteration counts a step, so that the difference is
the iterations' cost alone (the step's set-up cancels), and prints it per vertex and iteration
beside the floor: the bytes an iteration must stream (:meth:`~cloth_sim.integrators.vbd.VBD.
iteration_traffic`: the model's positions, masses and springs, each once) over a STREAM triad's
bandwidth on arrays of that size (the caches they fit in, as :mod:`cloth_sim.bench.scaling`
measures symplectic Euler's). Two cores, numba's threads. Both sweeps, in turn: the grid's blocks
(what a grid runs, :mod:`cloth_sim.integrators.vbd_grid`) and the general one (``grid=False``);
the ratio to the floor is the blocks'.
"""

from __future__ import annotations

import os
import platform

from .scaling import triad_bandwidth
from .steps import time_steps

#: the iteration counts timed a step (their difference is what is measured)
LOW, HIGH = 4, 20


def _per_iteration(n: int, grid: bool) -> tuple[float, object]:
    """Seconds per iteration on the ``n``×``n`` hanging cloth, and the last simulator."""
    from ..scene import load_scene

    costs = {}
    for iterations in (LOW, HIGH):
        sim = load_scene("hanging_provot").build_simulator(
            rows=n,
            cols=n,
            spacing=1.0 / (n - 1),
            particle_mass=10.24 / n**2,
            integrator="vbd",
            dt=1.0 / 60,
            strain_limit=None,
            integrator_options={"iterations": iterations, "grid": grid},
        )
        costs[iterations] = time_steps(sim, seconds=1.0, repeats=5)
    return (costs[HIGH] - costs[LOW]) / (HIGH - LOW), sim


def measure(n: int) -> dict:
    """Seconds per iteration of ``vbd`` on the ``n``×``n`` hanging cloth (the grid's blocks and
    the general sweep, in turn), its traffic and floor."""
    from ..integrators.vbd import VBD

    general, _ = _per_iteration(n, grid=False)
    per_iteration, sim = _per_iteration(n, grid=True)
    traffic = VBD(sim.model).iteration_traffic(sim.forces)
    bandwidth = triad_bandwidth(traffic)
    floor = traffic / bandwidth
    return {
        "N": n,
        "ns_per_vertex_iteration": 1e9 * per_iteration / n**2,
        "general_ns_per_vertex_iteration": 1e9 * general / n**2,
        "ms_per_iteration": 1e3 * per_iteration,
        "traffic_mb": traffic / 1e6,
        "triad_gb_s": bandwidth / 1e9,
        "floor_ms": 1e3 * floor,
        "ratio": per_iteration / floor,
    }


def print_vbd_floor_table(sizes) -> list[dict]:
    print(
        "# vbd per vertex and iteration against the memory-bandwidth floor: the hanging_provot "
        f"cloth (1 m, 10.24 kg), 1/60 s, {LOW} and {HIGH} iterations a step (their difference); "
        f"{platform.machine()}, {os.cpu_count()} cores"
    )
    print(
        "| N | ms per iteration | ns per vertex and iteration (general sweep) | traffic per "
        "iteration (MB) | triad GB/s at that size | floor (ms) | measured / floor |"
    )
    print("|---|---|---|---|---|---|---|")
    rows = []
    for n in sizes:
        r = measure(n)
        rows.append(r)
        print(
            f"| {n} | {r['ms_per_iteration']:.3f} | {r['ns_per_vertex_iteration']:.1f} "
            f"({r['general_ns_per_vertex_iteration']:.1f}) | "
            f"{r['traffic_mb']:.2f} | {r['triad_gb_s']:.1f} | {r['floor_ms']:.4f} | "
            f"{r['ratio']:.1f}× |",
            flush=True,
        )
    return rows
