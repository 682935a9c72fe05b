"""``cloth-sim bench gpu``: the CUDA backend's figures (docs/gpu.md), on a GPU.

Five tables, each measured in one process:

1. **The same cloth**: 1 m of cotton hanging from two corners at 32×32, ``vbd`` with its defaults
   at 1/60 s for 1 s, on the GPU (float32 and float64) against the CPU (float64): the largest
   distance between the two at the end and along the way.
2. **One large cloth**: denim hanging at 128×128 and 256×256, ``vbd``'s defaults at 1/60 s on the
   GPU over 2 s: wall seconds a simulated second (the real-time factor is its inverse), the steps
   that ended unconverged, launches a frame, and the accuracy figures of ``cloth-sim bench
   convergence --accuracy`` against symplectic Euler at 0.9 of its stable step, also on the GPU.
3. **Many worlds**: ``N`` worlds of 32×32 cotton (and 64×64), each with its own wind, stepped
   together: world-seconds a second for ``vbd`` and symplectic Euler, from 1 world to 16,384.
4. **ClothFold's vector env** on the GPU (observations on the device), 1 to 4,096 envs, beside
   Gymnasium's ``AsyncVectorEnv`` on the machine's CPU cores (:mod:`cloth_sim.bench.vector_env`):
   env steps a second.
5. **Colliders and a robot**: the robots issue's 32×32 cloth resting on a box, the Box primitive
   against the same box as a 12-triangle mesh (read from its distance grid), ms a step on the GPU
   and their ratio (``python -m cloth_sim.bench.robot`` prints the CPU's); and the ``robot_pick``
   scene (its gripper's pads swept by symplectic Euler, its scripted lift) on the GPU: wall
   seconds a simulated second.

``--simulator`` runs a tiny version on numba-cuda's simulator (``NUMBA_ENABLE_CUDASIM=1``): what
CI checks of this script; its figures mean nothing.
"""

from __future__ import annotations

import time

import numpy as np

from .. import backends, settings
from ..batch import BatchSimulator
from ..contact import colliders
from ..contact.triangle_meshes import box_triangles
from ..model import ClothModel
from ..simulator import Simulator
from .convergence import REFERENCE_SHARE, accuracy, hanging, trajectory
from .vector_env import print_vector_table

#: sizes and world counts of a run on a GPU
SIZES = (128, 256)
WORLDS = (1, 16, 128, 1024, 4096, 16384)
#: the wind's strength range a world draws from (N per unit of normal projection)
WIND = 0.02
#: ClothFold vector envs' sizes on a GPU
VECTOR_ENVS = (1, 64, 1024, 4096)


def _worlds_rate(model, worlds: int, integrator: str, dt: float, seconds: float, rng) -> dict:
    batch = BatchSimulator(model, worlds=worlds, integrator=integrator, dt=dt, device="cuda")
    batch.set(None, wind=rng.uniform(-WIND, WIND, (worlds, 3)))
    batch.step()  # compiled, and the substeps chosen
    steps = max(1, int(round(seconds / dt)))
    t0 = time.perf_counter()
    batch.step(steps)
    batch.positions_host()  # (the launches are asynchronous: wait for them)
    wall = time.perf_counter() - t0
    return {"rate": worlds * steps * dt / wall, "launches": batch.last_launches}


def print_gpu_tables(sizes=SIZES, worlds=WORLDS, seconds: float = 2.0, simulator=False) -> dict:
    """Print the five tables (module docstring); return their figures."""
    why = backends.problem("cuda")
    if why is not None:
        raise SystemExit(f"cloth-sim bench gpu: {why}")
    figures: dict = {"same": [], "large": [], "worlds": []}
    small = 4 if simulator else 32
    same_s = 2 / 60 if simulator else 1.0
    print(
        f"1. the same cloth: cotton {small}x{small} hanging, vbd defaults at 1/60 s, {same_s:g} s"
    )
    model = hanging(small, "cotton")
    cpu = Simulator(model, integrator="vbd", dt=1 / 60)
    ref = trajectory(cpu, small, same_s)
    for precision in ("float32", "float64"):
        gpu = Simulator(model, integrator="vbd", dt=1 / 60, device="cuda", precision=precision)
        got = trajectory(gpu, small, same_s)
        end = float(np.max(np.abs(gpu.positions - cpu.positions)))
        path = float(np.max(np.abs(got["centroid"] - ref["centroid"])))
        figures["same"].append({"precision": precision, "end": end, "path": path})
        print(
            f"   {precision}: largest distance at the end {end:.2e} m; free edge's centroid "
            f"along the way {path:.2e} m"
        )
    print(f"2. one large cloth: denim hanging, vbd defaults at 1/60 s, {seconds:g} s, on the GPU")
    print(
        f"{'N':>6} {'launch':>7} {'substeps':>8} {'sweeps/frame':>12} {'unconverged':>11} "
        f"{'launches/frame':>14} {'wall s/s':>9} {'RTF':>7} {'Δ strain':>9} {'path':>7}"
    )
    for n in (4,) if simulator else sizes:
        model = hanging(n, "denim")
        probe = Simulator(model, integrator="symplectic_euler", dt=1.0)
        ref_sim = Simulator(
            model,
            integrator="symplectic_euler",
            dt=REFERENCE_SHARE * probe.stable_dt(),
            device="cuda",
        )
        ref = trajectory(ref_sim, n, seconds)
        sim = Simulator(model, integrator="vbd", dt=1 / 60, device="cuda")
        sim.step()  # compiled
        sim = Simulator(model, integrator="vbd", dt=1 / 60, device="cuda")
        got = trajectory(sim, n, seconds)
        st = sim.integrator_stats
        d_strain, path = accuracy(got, ref)
        row = {
            "n": n,
            "launch": sim.launch_mode,
            "substeps": st["last_substeps"],
            "sweeps": st["iterations"] / max(st["steps"], 1),
            "unconverged": got["unconverged"],
            "launches": st["last_launches"],
            "wall": got["wall"],
            "strain": d_strain,
            "path": path,
        }
        figures["large"].append(row)
        print(
            f"{n:>6} {row['launch']:>7} {row['substeps']:>8} {row['sweeps']:>12.1f} "
            f"{row['unconverged']:>11} {row['launches']:>14.1f} {row['wall']:>9.3f} "
            f"{1 / row['wall']:>7.2f} {d_strain:>+9.3f} {path:>7.1%}",
            flush=True,
        )
    print(f"3. many worlds, each its own wind: world-seconds a second ({seconds:g} s a run)")
    print(f"{'N':>4} {'worlds':>7} {'vbd ws/s':>11} {'launches':>9} {'s.Euler ws/s':>13}")
    rng = np.random.default_rng(7)
    for n in (4,) if simulator else (32, 64):
        model = hanging(n, "cotton")
        stable = 0.9 * Simulator(model, integrator="symplectic_euler", dt=1.0).stable_dt()
        for count in (1, 2) if simulator else worlds:
            if n == 64 and count > 4096:
                continue
            v = _worlds_rate(model, count, "vbd", 1 / 60, seconds, rng)
            e = _worlds_rate(model, count, "symplectic_euler", stable, seconds / 10, rng)
            figures["worlds"].append({"n": n, "worlds": count, "vbd": v, "euler": e})
            print(
                f"{n:>4} {count:>7} {v['rate']:>11.0f} {v['launches']:>9.1f} {e['rate']:>13.0f}",
                flush=True,
            )
    print("4. ClothFold's vector env on the GPU, beside the CPU's AsyncVectorEnv")
    if simulator:  # (a 4x4 cloth, a frame an env step, two processes)
        tiny = dict(cloth_size=(4, 4), spacing=0.1, action_repeat=1)
        figures["vector"] = print_vector_table(
            "cuda", (1, 2), 2, 1, tiny, launch="stages", observations="device"
        )
    else:
        figures["vector"] = print_vector_table(
            "cuda", VECTOR_ENVS, None, 10, observations="device"
        )
    figures["colliders"] = print_collider_table(simulator)
    return figures


def print_collider_table(simulator=False) -> dict:
    """Table 5 (module docstring): the box as a primitive and as a mesh under a resting cloth,
    each method's median of its rounds taken in turn, and robot_pick's wall time a simulated
    second; returns the figures."""
    half = (0.3, 0.3, 0.1)
    n, rounds, steps = (4, 1, 2) if simulator else (32, 7, 400)
    print("5. colliders and a robot on the GPU: a cloth resting on a box, primitive and mesh")
    print(f"{'method':>16} {'Box ms/step':>12} {'Mesh ms/step':>13} {'ratio':>6}")
    figures = {"box": []}
    for integrator, dt in (("symplectic_euler", 1e-3), ("vbd", 1 / 60)):
        sims = {}
        for kind in ("box", "mesh"):
            model = ClothModel.grid(
                n, n, 0.02, 0.001, stiffness=300.0, damping=0.01, origin=(-0.31, -0.31, 0.11)
            )
            shape = (
                colliders.Box(half_extents=half, friction=0.5)
                if kind == "box"
                else colliders.Mesh(box_triangles(half), friction=0.5)
            )
            options = {"iterations": 10} if integrator == "vbd" else None
            sims[kind] = Simulator(
                model, integrator=integrator, dt=dt, colliders=[shape], drag=0.01,
                integrator_options=options, device="cuda",
            )  # fmt: skip
            sims[kind].step(1 if simulator else 20)
        count = steps if integrator != "vbd" else max(1, steps // 8)
        walls = {kind: [] for kind in sims}
        for _ in range(rounds):
            for kind, sim in sims.items():
                t = time.perf_counter()
                sim.step(count)  # (its state checked on the host: the launches waited for)
                walls[kind].append((time.perf_counter() - t) / count)
        box, mesh = (float(np.median(walls[kind])) for kind in ("box", "mesh"))
        figures["box"].append({"integrator": integrator, "box": box, "mesh": mesh})
        print(
            f"{integrator:>16} {box * 1e3:>12.3f} {mesh * 1e3:>13.3f} {mesh / box:>6.2f}",
            flush=True,
        )
    values = {"device": "cuda"} | ({"rows": 4, "cols": 4} if simulator else {})
    sim = settings.build(settings.check("robot_pick", values))
    seconds = 2 * sim.dt if simulator else 2.0
    sim.step()
    t = time.perf_counter()
    sim.advance(sim.time + seconds)
    wall = (time.perf_counter() - t) / seconds
    figures["robot_pick"] = wall
    print(
        f"robot_pick on the GPU ({sim.model.n_particles} vertices, dt {sim.dt:g} s, its script): "
        f"{wall:.3f} wall s a simulated s ({1 / wall:.2f}x real time)"
    )
    return figures
