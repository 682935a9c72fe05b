"""Robots in the scene, measured: forward kinematics (ours against yourdfpy's), what a mesh
collider costs against the same shape as a primitive, and the robot_sweep scene (an arm through a
hanging 32×32 cloth): the deepest any vertex came into any link, self-crossings by the independent
check, and the real-time factor headless. Each comparison runs side by side in one process.

    .venv/bin/python -m cloth_sim.bench.robot [--seconds S]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ..bench.crossings import crossings
from ..contact import colliders
from ..model import ClothModel
from ..robot import Robot
from ..scene import find_scene, load_scene
from ..simulator import Simulator, compile_kernels


def forward_kinematics(repeat: int = 300) -> None:
    robot = Robot.from_urdf(find_scene("robot_sweep").parent.parent / "robots" / "arm.urdf")
    q = {j: 0.3 for j in robot.joint_names}
    for f in (robot.link_transforms, robot.link_transforms_yourdfpy):
        f(q)
    times = {}
    for f in (robot.link_transforms, robot.link_transforms_yourdfpy):
        t = time.perf_counter()
        for k in range(repeat):
            q["shoulder_yaw"] = 0.001 * k
            f(q)
        times[f.__name__] = (time.perf_counter() - t) / repeat
    ours, theirs = times["link_transforms"], times["link_transforms_yourdfpy"]
    print(
        f"forward kinematics, demo arm ({len(robot.all_links)} links): ours {ours * 1e3:.3f} ms, "
        f"yourdfpy's {theirs * 1e3:.3f} ms ({theirs / ours:.1f}x)"
    )


def mesh_against_primitive(steps: int = 400) -> None:
    """A 32×32 cloth resting on a box: the Box primitive against the same box as 12 triangles."""
    import trimesh

    half = (0.3, 0.3, 0.1)
    box = trimesh.creation.box(extents=2 * np.array(half))
    rows = []
    for integrator, dt in (("symplectic_euler", 1e-3), ("vbd", 1 / 60)):
        walls = {}
        for kind in ("box", "mesh"):
            model = ClothModel.grid(
                32, 32, 0.02, 0.001, stiffness=300.0, damping=0.01, origin=(-0.31, -0.31, 0.11)
            )
            shape = (
                colliders.Box(half_extents=half, friction=0.5)
                if kind == "box"
                else colliders.Mesh((box.vertices, box.faces), friction=0.5)
            )
            sim = Simulator(model, integrator=integrator, dt=dt, colliders=[shape], drag=0.01)
            sim.step(20)
            n = steps if integrator != "vbd" else steps // 8
            t = time.perf_counter()
            sim.step(n)
            walls[kind] = (time.perf_counter() - t) / n
        rows.append((integrator, walls["box"], walls["mesh"]))
    print("a cloth on a box: the Box primitive against the same box as a 12-triangle mesh")
    print("| integrator | Box ms/step | Mesh ms/step | ratio |\n|---|---|---|---|")
    for name, a, b in rows:
        print(f"| {name} | {a * 1e3:.3f} | {b * 1e3:.3f} | {b / a:.2f} |")


def sweep(seconds: float) -> None:
    scene = load_scene("robot_sweep")
    sim = scene.build_simulator()
    links = list(sim.colliders)
    tris = sim.model.triangles
    h = sim.thickness
    worst, crossed, wall = np.inf, 0, 0.0
    prev = sim.positions.copy()
    while sim.time < seconds:
        t = time.perf_counter()
        sim.step()
        wall += time.perf_counter() - t
        x = sim.positions
        worst = min(worst, min(float(c.signed_distance(x).min()) for c in links))
        crossed += len(crossings(prev, x, tris))
        prev = x.copy()
    depth = max(0.0, h - worst)
    print(
        f"robot_sweep ({sim.model.n_particles} particles, {sim.integrator}, dt {sim.dt:.4g} s, "
        f"{sum(s.triangles for s in sim.robots['arm'].shapes)} mesh triangles, "
        f"self-collision {'on' if sim.self_collision else 'off'}), {seconds:g} s: deepest into "
        f"the thickness {depth / h:.1%} of it (closest {worst / h:.3f} h), self-crossings "
        f"{crossed}, pushed {sim.positions[:, 1].max():.3f} m behind its plane, "
        f"headless real-time factor {sim.time / wall:.2f}"
    )


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=4.6, help="robot_sweep's simulated time")
    args = p.parse_args(argv)
    compile_kernels()
    forward_kinematics()
    mesh_against_primitive()
    sweep(args.seconds)


if __name__ == "__main__":
    main()
