"""Robots in the scene, measured: forward kinematics (ours against yourdfpy's), what a mesh
collider costs against the same shape as a primitive (a cloth resting on it, and one query), the
distance grids the cuda device reads meshes from (their bake and their error), and the robot_sweep
scene (an arm through a hanging 32×32 cloth): the deepest any vertex came into any
link, self-crossings by the independent check, and the real-time factor headless. Each comparison
runs side by side in one process.

    .venv/bin/python -m cloth_sim.bench.robot [--seconds S] [--published]

``--published`` adds a Franka Panda and a UR5 from their published descriptions with their
collision meshes (example-robot-data: ``make bench-robots`` installs it and runs this), through
robot_sweep's cloth and through the robots issue's sheet (:func:`sweep_sheet`).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from ..bench.crossings import crossings
from ..contact import colliders
from ..integrators.vbd_options import COLLIDER_SHARE, VBDOptions
from ..kernels import compile_kernels
from ..model import ClothModel
from ..robot import Robot
from ..scene import find_scene, load_scene
from ..simulator import Simulator


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


def mesh_against_primitive(steps: int = 400, rounds: int = 7) -> None:
    """A 32×32 cloth resting on a box: the Box primitive against the same box as 12 triangles.
    The two simulations are stepped in turn, ``rounds`` rounds of ``steps`` steps each (``vbd``:
    an eighth of them), and each one's median round is reported: a quiet second on a shared
    machine moves both alike."""
    import trimesh

    half = (0.3, 0.3, 0.1)
    box = trimesh.creation.box(extents=2 * np.array(half))
    rows = []
    for integrator, dt in (("symplectic_euler", 1e-3), ("vbd", 1 / 60)):
        sims = {}
        for kind in ("box", "mesh"):
            model = ClothModel.grid(
                32, 32, 0.02, 0.001, stiffness=300.0, damping=0.01, origin=(-0.31, -0.31, 0.11)
            )
            shape = (
                colliders.Box(half_extents=half, friction=0.5)
                if kind == "box"
                else colliders.Mesh((box.vertices, box.faces), friction=0.5)
            )
            # (vbd: 10 iterations a step, one substep, as the node runs it)
            options = {"iterations": 10} if integrator == "vbd" else None
            sims[kind] = Simulator(
                model,
                integrator=integrator,
                dt=dt,
                colliders=[shape],
                drag=0.01,
                integrator_options=options,
            )
            sims[kind].step(20)
        n = steps if integrator != "vbd" else steps // 8
        walls = {kind: [] for kind in sims}
        for _ in range(rounds):
            for kind, sim in sims.items():
                t = time.perf_counter()
                sim.step(n)
                walls[kind].append((time.perf_counter() - t) / n)
        box_ms, mesh_ms = (float(np.median(walls[kind])) for kind in ("box", "mesh"))
        rows.append((integrator, box_ms, mesh_ms))
    print(
        f"a cloth on a box: the Box primitive against the same box as a 12-triangle mesh "
        f"(the median of {rounds} rounds, taken in turn)"
    )
    print("| integrator | Box ms/step | Mesh ms/step | ratio |\n|---|---|---|---|")
    for name, a, b in rows:
        print(f"| {name} | {a * 1e3:.3f} | {b * 1e3:.3f} | {b / a:.2f} |")


def mesh_queries(n: int = 200_000) -> None:
    """One signed-distance query against the same box as the Box primitive and as a 12-triangle
    mesh: points just above a face's interior (the mesh's planes), beside the top's edges (its
    creases) and anywhere in and around it (the listed triangles and the walk), the best of five
    runs each."""
    import trimesh

    half = (0.3, 0.3, 0.1)
    shapes = {
        "Box": colliders.Box(half_extents=half, friction=0.5),
        "Mesh": colliders.Mesh(
            (lambda m: (m.vertices, m.faces))(trimesh.creation.box(extents=2 * np.array(half))),
            friction=0.5,
        ),
    }
    rng = np.random.default_rng(0)
    face = rng.uniform(-0.25, 0.25, (n, 3))
    face[:, 2] = half[2] + rng.uniform(0.0, 0.01, n)
    # within 1 cm of the top's edges along x, outside (a cloth draped over them)
    edge = rng.uniform(-0.25, 0.25, (n, 3))
    side = rng.choice([-1.0, 1.0], n)
    angle = rng.uniform(-0.3, 0.5 * np.pi + 0.3, n)
    reach = rng.uniform(0.002, 0.01, n)
    edge[:, 1] = side * (half[1] + reach * np.cos(angle))
    edge[:, 2] = half[2] + reach * np.sin(angle)
    places = {
        "on a face": face,
        "over an edge": edge,
        "anywhere": rng.uniform(-0.6, 0.6, (n, 3)),
    }
    print("one signed-distance query, ns: the Box primitive against the same box as a mesh")
    print("| points | Box | Mesh | ratio |\n|---|---|---|---|")
    for where, pts in places.items():
        ns = {}
        for name, shape in shapes.items():
            shape.signed_distance(pts[:10])
            best = np.inf
            for _ in range(5):
                t = time.perf_counter()
                shape.signed_distance(pts)
                best = min(best, time.perf_counter() - t)
            ns[name] = best / n * 1e9
        print(f"| {where} | {ns['Box']:.0f} | {ns['Mesh']:.0f} | {ns['Mesh'] / ns['Box']:.1f} |")


def distance_grids(thickness: float = 0.005, points: int = 20_000) -> None:
    """The distance grids the cuda device reads a mesh collider from
    (:mod:`cloth_sim.contact.distance_grid`), for meshes of three sizes at ``thickness``: the
    grid's cell, band and nodes, the bake's wall time (the second of two: the first compiles),
    and against the exact mesh queries at ``points`` random points within the band, the largest
    error of the distance (in cells) and of the normal one cell out and farther (rad)."""
    from ..contact import distance_grid
    from ..contact.triangle_meshes import box_triangles

    robot = Robot.from_urdf(str(find_scene("robot_sweep").parent.parent / "robots" / "arm.urdf"))
    forearm = next(s for s in robot.shapes if s.link == "forearm").make("forearm", 0.5)
    meshes = {
        "box 0.4 x 0.4 x 0.1 m (12 triangles)": colliders.Mesh(box_triangles((0.2, 0.2, 0.05))),
        "the demo arm's forearm": forearm,
        "mannequin (tshirt_on_body)": colliders.Mesh(
            str(find_scene("tshirt_on_body").parent.parent / "meshes" / "mannequin.obj")
        ),
    }
    print(f"distance grids at a thickness of {thickness * 1e3:g} mm, against the exact queries")
    print(
        "| mesh | cell mm | band mm | nodes | bake ms | distance err (cells) | normal err (rad) |"
        "\n|---|---|---|---|---|---|---|"
    )
    rng = np.random.default_rng(0)
    for name, shape in meshes.items():
        mesh = shape.mesh
        cell, band = distance_grid.cell_for(mesh, thickness)
        distance_grid.bake(mesh, cell, band)
        t = time.perf_counter()
        grid = distance_grid.bake(mesh, cell, band)
        bake = time.perf_counter() - t
        lo, hi = mesh.lo[0] - band, mesh.hi[0] + band
        p = rng.uniform(lo, hi, (points, 3))
        # (the mesh in its own frame: the collider at the origin, unturned)
        exact = shape.signed_distance(p)
        d, n = grid.at(p)
        near = np.abs(exact) < band
        eps = 1e-6
        g = np.stack(
            [(shape.signed_distance(p + eps * e) - shape.signed_distance(p - eps * e)) / (2 * eps)
             for e in np.eye(3)], axis=1,
        )  # fmt: skip
        out = near & (exact > cell) & (np.linalg.norm(g, axis=1) > 0.5)
        cos = np.sum(n[out] * g[out], axis=1) / np.linalg.norm(g[out], axis=1)
        angle = float(np.max(np.arccos(np.clip(cos, -1.0, 1.0)), initial=0.0))
        print(
            f"| {name} | {cell * 1e3:.2f} | {band * 1e3:.1f} | {grid.values.size:,} | "
            f"{bake * 1e3:.0f} | {np.max(np.abs(d - exact)[near]) / cell:.2f} | {angle:.2f} |"
        )


#: a vertex deeper than this share of the thickness inside a link counts a step in
#: :func:`sweep`'s tally (the robots issue's target for the deepest: a tenth)
INSIDE_SHARE = 0.1


def sweep(seconds: float, options: dict | None = None) -> dict:
    """robot_sweep headless: the deepest vertex inside a link (the links' own signed distances:
    a closed mesh, as the forearm is, is a solid), which link and when, the steps that ended with
    some vertex more than :data:`INSIDE_SHARE` of the thickness inside one, the self-crossings and
    the speed; ``options``: vbd's options over the scene's (``collider_share``: the thicknesses a
    link near the cloth may move a substep). Prints a line and returns its figures."""
    scene = load_scene("robot_sweep")
    sim = scene.build_simulator()
    if options:
        sim.set_integrator("vbd", **{**sim.integrator_options, **options})
    collider_share = VBDOptions.of(sim.integrator_options).collider_share
    if collider_share == "auto":
        collider_share = f"auto ({COLLIDER_SHARE:g} with self-contact)"
    links = list(sim.colliders)
    tris = sim.model.triangles
    h = sim.thickness
    worst, where, when, inside, steps, crossed, wall = np.inf, None, 0.0, 0, 0, 0, 0.0
    prev = sim.positions.copy()
    while sim.time < seconds:
        t = time.perf_counter()
        sim.step()
        wall += time.perf_counter() - t
        steps += 1
        x = sim.positions
        distances = [float(c.signed_distance(x).min()) for c in links]
        deepest = int(np.argmin(distances))
        inside += distances[deepest] < -INSIDE_SHARE * h
        if distances[deepest] < worst:
            worst, where, when = distances[deepest], links[deepest].name, sim.time
        crossed += len(crossings(prev, x, tris))
        prev = x.copy()
    depth = max(0.0, h - worst)
    row = dict(
        inside=max(0.0, -worst) / h, link=where, at=when, steps_inside=inside, steps=steps,
        crossings=crossed, real_time=sim.time / wall,
    )  # fmt: skip
    print(
        f"robot_sweep ({sim.model.n_particles} particles, {sim.integrator}, dt {sim.dt:.4g} s, "
        f"collider_share {collider_share if collider_share is not None else 'off'}, "
        f"{sum(s.triangles for s in sim.robots['arm'].shapes)} mesh triangles, "
        f"self-collision {'on' if sim.self_collision else 'off'}), {seconds:g} s: deepest "
        f"inside a link {row['inside']:.1%} of the thickness h ({where}, t = {when:.3f} s), "
        f"into the skin {depth / h:.1%} of it (closest {worst / h:.3f} h), {inside} of "
        f"{steps} steps ending with a vertex over {INSIDE_SHARE:.0%} of h inside, "
        f"self-crossings {crossed}, pushed {sim.positions[:, 1].max():.3f} m behind its "
        f"plane, headless real-time factor {row['real_time']:.2f}"
    )
    return row


#: robots users have, from example-robot-data (make bench-robots installs it): the URDF, where
#: the base stands in front of the robot_sweep cloth, the joints it sweeps with, the joint that
#: swings and between which angles
PUBLISHED = {
    "panda": (
        "panda_description/urdf/panda.urdf",
        (0.0, -0.45, 0.35),
        {"panda_joint2": 0.9, "panda_joint4": -1.2, "panda_joint6": 1.6},
        "panda_joint1",
        (0.4, 2.7),
    ),
    "ur5": (
        "ur_description/urdf/ur5_robot.urdf",
        (0.0, -0.45, 0.45),
        {"shoulder_lift_joint": -0.2, "elbow_joint": 0.3},
        "shoulder_pan_joint",
        (0.4, 2.7),
    ),
}


def robot_data_share():
    """example-robot-data's share folder (its package:// root), or None where it is not
    installed."""
    import sysconfig
    from pathlib import Path

    share = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share"
    return share if (share / "example-robot-data").is_dir() else None


def sweep_published(name: str, share, seconds: float = 2.0, speed: float = 1.5) -> None:
    """A published robot swung through the robot_sweep cloth (the scene's own arm taken out)."""
    urdf, base, joints, swing, (a, b) = PUBLISHED[name]
    t = time.perf_counter()
    robot = Robot.from_urdf(share / "example-robot-data" / "robots" / urdf, package_paths=[share])
    load = time.perf_counter() - t
    sim = load_scene("robot_sweep").build_simulator()
    sim.motion = None
    sim.remove_robot("arm")
    sim.add_robot(robot, name=name, position=base, joints={**joints, swing: a})
    links = list(sim.colliders)
    h, worst, wall, steps, behind = sim.thickness, np.inf, 0.0, 0, 0.0
    tris, crossed, prev = sim.model.triangles, 0, sim.positions.copy()
    while sim.time < seconds:
        angle = min(b, a + speed * (sim.time + sim.dt))
        t = time.perf_counter()
        sim.set_joint_positions(name, {swing: angle})
        sim.step()
        wall += time.perf_counter() - t
        steps += 1
        worst = min(worst, min(float(c.signed_distance(sim.positions).min()) for c in links))
        behind = max(behind, float(sim.positions[:, 1].max()))
        crossed += len(crossings(prev, sim.positions, tris))
        prev = sim.positions.copy()
    tris = sum(s.triangles for s in robot.shapes)
    print(
        f"{name} ({len(robot.joint_names)} joints, {len(robot.link_names)} links, {tris} mesh "
        f"triangles, loaded in {load:.2f} s) swung at {speed:g} rad/s through the robot_sweep "
        f"cloth ({sim.integrator}, self-contact {'on' if sim.self_collision else 'off'}): "
        f"deepest inside a link {max(0.0, -worst) / h:.1%} of the thickness h, into the skin "
        f"{max(0.0, h - worst) / h:.1%} of it, self-crossings {crossed}, pushed up to "
        f"{behind:.3f} m behind its plane, {wall / steps * 1e3:.2f} ms a step, "
        f"headless real-time factor {sim.time / wall:.2f}"
    )


#: the robots issue's sweep (test/core/test_published_robots.py measures the same depth
#: independently): the robot's base, the joints it holds, the joint it swings from −0.9 to +0.9 rad
#: in 0.5 s, and the 0.6 m sheet's top-left corner
SHEET_SWEEPS = {
    "panda": ((0.0, 0.0, 0.0), PUBLISHED["panda"][0], (0.0, 0.35, 0.7)),
    "ur5": ((0.0, 0.0, 0.3), PUBLISHED["ur5"][0], (0.15, 0.35, 0.8)),
}
SHEET_JOINTS = {
    "panda": ({"panda_joint2": 0.6, "panda_joint4": -1.6, "panda_joint6": 2.2}, "panda_joint1"),
    "ur5": ({"shoulder_lift_joint": -0.3, "elbow_joint": 0.6}, "shoulder_pan_joint"),
}


def _measured_step(sim, links, tris, prev):
    """One step of ``sim``: its wall time, the smallest signed distance of any vertex from any of
    ``links`` after it, the self-crossings since ``prev`` (the independent check) and the new
    positions."""
    t = time.perf_counter()
    sim.step()
    took = time.perf_counter() - t
    x = sim.positions
    closest = min(float(c.signed_distance(x).min()) for c in links)
    return took, closest, len(crossings(prev, x, tris)), x.copy()


def sweep_sheet(
    name: str, share, options: dict | None = None, dt: float = 1 / 240, iterations: int = 5,
    self_collision: bool = True, swing_time: float = 0.5,
) -> None:  # fmt: skip
    """The robots issue's sweep: a 32×32 sheet (0.6 m, 0.3 kg, springs 300 N/m) hanging from its
    top corners 0.35 m in front of the robot, its first joint swung from −0.9 to +0.9 rad in
    ``swing_time`` (0.5 s, as the issue has it) and 0.125 s more, ``vbd`` at ``dt`` ×
    ``iterations`` (1/240 s × 5 as the issue has it; and ``options``), thickness 5 mm,
    self-contact on (or not): the deepest vertex inside a link by the links' own signed distances
    (closed meshes are solids), the self-crossings by the independent check, the time a step and
    the real-time factor."""
    base, urdf, corner = SHEET_SWEEPS[name]
    held, swing = SHEET_JOINTS[name]
    robot = Robot.from_urdf(share / "example-robot-data" / "robots" / urdf, package_paths=[share])
    model = ClothModel.grid(
        32, 32, size=(0.6, 0.6), particle_mass=0.3 / 1024, stiffness=300.0,
        pinned=[(0, 0), (0, -1)], orientation="vertical", origin=corner,
    )  # fmt: skip
    sim = Simulator(
        model, integrator="vbd", dt=dt, thickness=0.005, self_collision=self_collision,
        integrator_options={"iterations": iterations, **(options or {})},
    )  # fmt: skip
    sim.add_robot(robot, name=name, position=base, joints={**held, swing: -0.9})
    links, tris = list(sim.colliders), sim.model.triangles
    worst, crossed, wall, prev = np.inf, 0, 0.0, sim.positions.copy()
    swinging, steps = round(swing_time / dt), round((swing_time + 0.125) / dt)
    for k in range(steps):
        sim.set_joint_positions(name, {swing: -0.9 + 1.8 * min(1.0, (k + 1) / swinging)})
        took, closest, crossed_now, prev = _measured_step(sim, links, tris, prev)
        wall, worst, crossed = wall + took, min(worst, closest), crossed + crossed_now
    print(
        f"{name} swung through the issue's 32x32 sheet in {swing_time:g} s (vbd {dt:.4g} s x "
        f"{iterations}, "
        f"self-contact {'on' if self_collision else 'off'}, {options or 'defaults'}): deepest "
        f"inside a link {max(0.0, -worst) * 1e3:.2f} mm ({max(0.0, -worst) / 0.005:.0%} of the "
        f"thickness), self-crossings {crossed}, {wall / steps * 1e3:.1f} ms a step, real-time "
        f"factor {steps * dt / wall:.2f}"
    )


def pinch_sheet(share, gap: float) -> None:
    """The Panda's hand, pointing down with its fingers across a hanging 0.2 m sheet (16×16, the
    issue's cloth per area), closes in 8 steps to a fingertip gap of ``gap`` on the middle of its
    top edge and drags it 0.21 m aside in 0.5 s, then 30 steps more: the sheet, pinned at its top
    corners, folds out of its plane, held by friction (μ 1) alone. The deepest vertex in a link,
    the self-crossings, and how far the pinched vertex ends from the fingertips' centre. A gap
    below the thickness traps the vertex between two skins that cannot both be met."""
    robot = Robot.from_urdf(
        share / "example-robot-data" / "robots" / PUBLISHED["panda"][0], package_paths=[share]
    )
    joints = {
        "panda_joint1": 0.5, "panda_joint2": 0.6, "panda_joint4": -1.6, "panda_joint6": 2.2,
        "panda_joint7": 1.285, "panda_finger_joint1": 0.04, "panda_finger_joint2": 0.04,
    }  # fmt: skip
    start = robot.link_transforms(joints)["panda_hand_tcp"][:3, 3]
    n, width, tau = 16, 0.2, 0.005
    model = ClothModel.grid(
        n, n, size=(width, width), particle_mass=0.3 / 0.36 * width**2 / n**2, stiffness=300.0,
        pinned=[(0, 0), (0, -1)], orientation="vertical",
        origin=(start[0] - (n // 2) * width / (n - 1), start[1], start[2] + 0.006),
    )  # fmt: skip
    sim = Simulator(
        model, integrator="vbd", dt=1 / 240, thickness=tau, self_collision=True,
        integrator_options={"iterations": 5},
    )  # fmt: skip
    sim.add_robot(robot, name="panda", joints=joints, friction=1.0)
    links, tris = list(sim.colliders), sim.model.triangles
    worst, crossed, wall, prev = np.inf, 0, 0.0, sim.positions.copy()
    for k in range(8 + 120 + 30):
        finger = 0.04 + (gap / 2 - 0.04) * min(1.0, (k + 1) / 8)
        q = {
            "panda_joint1": 0.5 + 0.3 * min(1.0, max(0.0, (k + 1 - 8) / 120)),
            "panda_finger_joint1": finger,
            "panda_finger_joint2": finger,
        }
        sim.set_joint_positions("panda", q)
        took, closest, crossed_now, prev = _measured_step(sim, links, tris, prev)
        wall, worst, crossed = wall + took, min(worst, closest), crossed + crossed_now
    tip = robot.link_transforms({**joints, **q})["panda_hand_tcp"][:3, 3]
    held = float(np.linalg.norm(sim.positions[n // 2] - tip))
    print(
        f"panda hand closing to a {gap * 1e3:.0f} mm gap on a hanging sheet's edge and dragging "
        f"it 0.21 m into a fold: deepest inside a link {max(0.0, -worst) * 1e3:.2f} mm "
        f"({max(0.0, -worst) / tau:.0%} of the thickness), self-crossings {crossed}, the pinched "
        f"vertex {held * 1e3:.1f} mm from the fingertips at the end "
        f"({'held' if held < 2 * tau else 'slipped out'}), {wall / (k + 1) * 1e3:.1f} ms a step"
    )


def _share(text: str) -> dict:
    """``--collider-share``: a number of thicknesses > 0, or ``off``; as vbd's option."""
    if text == "off":
        return {"collider_share": None}
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"a number > 0 or 'off', got {text!r}")
    return {"collider_share": value}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=4.6, help="robot_sweep's simulated time")
    p.add_argument(
        "--published", action="store_true", help="also Panda and UR5 from example-robot-data"
    )
    p.add_argument(
        "--collider-share",
        type=_share,
        help="robot_sweep again with vbd's collider_share (a number of thicknesses, or 'off'), "
        "beside it as it ships",
    )
    args = p.parse_args(argv)
    compile_kernels()
    forward_kinematics()
    mesh_against_primitive()
    mesh_queries()
    distance_grids()
    sweep(args.seconds)
    if args.collider_share is not None:
        sweep(args.seconds, args.collider_share)
    if args.published:
        share = robot_data_share()
        if share is None:
            raise SystemExit("example-robot-data is not installed: make bench-robots installs it")
        for name in PUBLISHED:
            sweep_published(name, share)
        for name in SHEET_SWEEPS:  # as it ships, beside a search every fifth iteration
            sweep_sheet(name, share, {"collision_interval": 5})
            sweep_sheet(name, share)
        # the Panda with a 32×32 cloth standalone, as the robots issue times it
        for swing_time in (0.5, 1.5):
            sweep_sheet(
                "panda", share, dt=1 / 60, iterations=10, self_collision=False,
                swing_time=swing_time,
            )  # fmt: skip
        # with self-contact: as it ships (collider_share 'auto': substeps where a link near the
        # cloth travels over 2.5 thicknesses a step), beside the same uncut
        for options in (None, {"collider_share": None}):
            sweep_sheet("panda", share, options, dt=1 / 60, iterations=10)
        for gap in (0.005, 0.002, 0.0):  # one thickness, and a vertex trapped between two skins
            pinch_sheet(share, gap)


if __name__ == "__main__":
    main()
