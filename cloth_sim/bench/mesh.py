"""Meshes against grids, side by side in one process: from_mesh time at 10k and 100k triangles
(arrays and an OBJ file), ms/step of a mesh and a grid of the same vertices (symplectic Euler,
Baraff–Witkin at 1/60 s), and the time to answer a stiffness change (stable_dt) on a 10,000-vertex
mesh.

    .venv/bin/python -m cloth_sim.bench.mesh
"""

import time

from cloth_sim import ClothModel, Simulator
from cloth_sim.kernels import compile_kernels


def main() -> None:
    compile_kernels()

    def best(f, n=3):
        ts = []
        for _ in range(n):
            t = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t)
        return min(ts)

    for N in (71, 224):
        g = ClothModel.grid(N, N, 1 / (N - 1), 0.01, stiffness=1)
        v, f = g.positions.copy(), g.triangles.copy()
        print(
            f"from_mesh {len(f)} triangles ({N * N} vertices): "
            f"{best(lambda: ClothModel.from_mesh((v, f), density=0.2, stiffness=1e3)) * 1e3:.1f} "
            "ms"
        )
    import os
    import tempfile

    import trimesh

    g = ClothModel.grid(224, 224, 1 / 223, 0.01, stiffness=1)
    d = tempfile.mkdtemp()
    p = os.path.join(d, "m.obj")
    trimesh.Trimesh(g.positions, g.triangles, process=False).export(p)
    print(
        f"from_mesh OBJ file {len(g.triangles)} triangles: "
        f"{best(lambda: ClothModel.from_mesh(p, density=0.2, stiffness=1e3)) * 1e3:.0f} ms"
    )
    N = 100
    mass = 10.24 / N**2
    g = ClothModel.grid(
        N,
        N,
        1 / (N - 1),
        mass,
        stiffness={"structural": 1e3, "shear": 1e3, "bend": 100},
        damping={"structural": 0.02, "shear": 0.02, "bend": 0.005},
        pinned=[(0, 0), (0, -1)],
    )
    m = ClothModel.from_mesh(
        (g.positions, g.triangles),
        density=10.24,
        stiffness={"structural": 1e3, "bend": 100},
        damping={"structural": 0.02, "bend": 0.005},
        pinned=[0, N - 1],
    )
    print(f"{N}x{N}: grid {g.n_springs} springs, mesh {m.n_springs} springs")
    for name, dt in (("symplectic_euler", 1e-4), ("implicit_euler", 1 / 60)):
        out = []
        for label, model in (("grid", g), ("mesh", m)):
            sim = Simulator(model, integrator=name, dt=dt)
            sim.step(20)
            k = 200 if name == "symplectic_euler" else 10
            w = best(lambda: sim.step(k)) / k
            out.append(w)
            print(f"  {name} {label}: {w * 1e3:.3f} ms/step")
        print(f"  {name} mesh/grid = {out[1] / out[0]:.2f}")
    sim = Simulator(m, integrator="symplectic_euler", dt=1e-4)
    sim.stable_dt()
    ts = []
    for k in (1100.0, 1200.0, 900.0, 5000.0):
        t = time.perf_counter()
        sim.set_stiffness("structural", k)
        sim.stable_dt()
        ts.append(time.perf_counter() - t)
    print("stiffness change + stable_dt on 10k-vertex mesh (ms):", [round(x * 1e3, 1) for x in ts])
    sim = Simulator(m, integrator="kang", dt=1e-4)
    t = time.perf_counter()
    sim.stable_dt()
    print(f"kang stable_dt 10k mesh: {(time.perf_counter() - t) * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
