"""What the node computes every tick besides the step, on a 128×128 library fabric: the state's
energies (~/stats and the energy balance), the energy balance's own (its restart), the largest
strain, the mesh's bytes, each as the best of 5 rounds of 20 calls (ms), beside a step of the
scene (``bench.steps.time_steps``).

    .venv/bin/python tools/tick_costs.py [scene ...]      (default: drape hanging)

(docs/BENCHMARKS.md §11, eighth session: the figures before and after.)
"""

import sys
import time

from builtin_interfaces.msg import Time

from cloth_sim.bench.steps import time_steps
from cloth_sim.materials import get
from cloth_sim.physics.energy_balance import EnergyBalance
from cloth_sim.ros.messages import MeshBytes
from cloth_sim.scene import load_scene


def best_ms(f, k: int = 20) -> float:
    f()
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(k):
            f()
        best = min(best, (time.perf_counter() - t) / k)
    return 1e3 * best


def main(scenes) -> None:
    stamp = Time(sec=1, nanosec=0)
    for name in scenes:
        sim = load_scene(name).build_simulator(
            rows=128, cols=128, material=get("cotton"), integrator="vbd", dt=1 / 60, size=(1, 1)
        )
        sim.step(30)
        balance = EnergyBalance(sim)
        mesh = MeshBytes()
        row = {
            "step": 1e3 * time_steps(sim),
            "Simulator.energy": best_ms(sim.energy),
            "balance restart (its energy and power)": best_ms(balance.restart),
            "max_strain": best_ms(sim.max_strain),
            "bending energy": best_ms(lambda: sim.forces.bending.energy(sim.positions)),
            "mesh bytes": best_ms(
                lambda: mesh(sim.positions, sim.model.triangles, "world", stamp)
            ),
        }
        print(name, "  ".join(f"{k} {v:.3f}" for k, v in row.items()), "ms", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ["drape", "hanging"])
