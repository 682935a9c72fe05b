"""The hanging scene resized as the node resizes it (``-p rows:=N -p cols:=N``: its spacing and
particle mass kept, a larger cloth), stepped for 2 s by one method, with the scene's strain limit:
seconds per simulated second, the worst strain, and the bottom edge's lowest point.

    .venv/bin/python tools/vbd_tethers.py 64 symplectic_euler 0.001
    .venv/bin/python tools/vbd_tethers.py 64 vbd 0.0166667 iterations=10 tethers=0
    .venv/bin/python tools/vbd_tethers.py 64 vbd 0.0166667 iterations=10 tethers=1

(docs/BENCHMARKS.md §11: vbd's ``tethers`` option beside the shipped explicit step.)
"""

import sys
import time

from cloth_sim.scene import load_scene


def main(argv: list[str]) -> None:
    n, integrator, dt = int(argv[0]), argv[1], float(argv[2])
    options = {}
    for arg in argv[3:]:
        key, value = arg.split("=")
        options[key] = value == "1" if key == "tethers" else int(value)
    kw = dict(rows=n, cols=n, integrator=integrator, dt=dt)
    if integrator == "vbd":
        kw["integrator_options"] = options
    sim = load_scene("hanging").build_simulator(**kw)
    bottom = (n - 1) * n + n // 2
    seconds, spent, worst, low = 2.0, 0.0, 0.0, float("inf")
    for _ in range(int(round(seconds / dt))):
        t0 = time.perf_counter()
        sim.step()
        spent += time.perf_counter() - t0
        worst = max(worst, sim.max_strain())
        low = min(low, float(sim.positions[bottom, 2]))
    print(
        f"N={n} {integrator} dt={dt:g} {options}: {spent / seconds:.3f} s per simulated s, "
        f"worst strain {worst:.4f}, the bottom edge's lowest point {low:.3f} m"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
