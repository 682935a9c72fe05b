"""Newton's ``example_cloth_franka`` beside cloth_sim on the CPU: its Franka FR3 arm and hand, its
shirt, its settings, the same arm motion.

``cloth-sim bench franka-peer [--frames 480] [--newton FILE] [--ours 10x5 5x5 ...]``
(``make bench-peers`` installs Newton, Warp and usd-core: ``requirements-peers.txt``, never in
``make test``).

**Newton's side** is its example as it ships (Newton 1.8 on NVIDIA Warp's CPU device): the FR3 with
its hand on a fixed base, following end-effector key poses through Newton's IK solver (Featherstone
for the arm, the joints driven to the IK solution each frame); the shirt of its wheel
(``unisex_shirt.usd``: 6,436 vertices, 12,736 triangles) dropped on a 0.8 × 0.8 × 0.2 m table, its
FEM triangles (``tri_ke`` = ``tri_ka`` = 1e4, bending 5, centimetre units); ``SolverVBD`` at 10
substeps × 5 iterations a 1/60 s frame, self-contact on (its BVH rebuilt each frame), contact
stiffness 5e4 and friction 1.5 against the arm and the table. Two changes, both outside the
physics: the arm's description is read from this repository's copy
(``test/data/newton-assets``: the newton-assets repository's ``franka_description``, the same FR3
and hand, its collision meshes; Newton downloads it at run time, which cannot happen here), and the
frame is stepped without a CUDA graph (there is none on the CPU). Each frame's joint positions and
shirt are recorded.

**cloth_sim's side**: the same shirt's vertices and triangles (read from the same USD file by
usd-core) at the same place, in the library's ``gray-interlock`` (a measured T-shirt knit:
cloth_sim has no FEM triangles, so the two fabrics are alike, not the same), the same table and
floor, the same FR3 (:class:`cloth_sim.robot.Robot` from the same URDF) driven frame by frame
through the joint positions Newton's IK produced: each frame's 10 substeps as 10 steps of
``vbd``, 5 iterations each (``--ours`` adds rows at other steps a frame and iterations a step),
the joints moving linearly between the frame's two positions (as Newton's substeps move them, at
the joint velocity that reaches the frame's IK solution);
self-contact on, friction 1.5 against the arm and the table, 0.25 between layers (Newton's). The
thickness is the largest self-collision allows on this mesh, half its shortest edge (0.73 mm;
Newton's self-contact margin is 2 mm and its body margin 8 mm).

**Figures**, each side over the same frames: wall time a frame (the median after the first
frame, which compiles Newton's kernels), the deepest any vertex comes inside any link of the arm
and hand (both sides' shirts at each frame, measured by the same exact signed distances of the
links' collision geometry at that frame's joint positions), and the self-crossings by the
independent check (:mod:`cloth_sim.bench.crossings`) between every two substeps; the checks are
outside the timed part.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..contact import colliders
from ..contact.self_collision import thickness_limit
from ..model import ClothModel
from ..robot import Robot
from ..simulator import Simulator
from .crossings import crossings

#: the FR3 with its hand (test/data/newton-assets: its README)
ASSETS = Path(__file__).resolve().parents[2] / "test" / "data" / "newton-assets"
URDF = ASSETS / "franka_description" / "urdf" / "fr3_franka_hand.urdf"
FRAME = 1.0 / 60.0
#: Newton's example works in centimetres
CM = 0.01
#: Newton's settings (example_cloth_franka)
SUBSTEPS, ITERATIONS = 10, 5
ARM_BASE = (-0.5, -0.5, 0.0)
SHIRT_POSITION, SHIRT_ORIENTATION = (0.0, 0.7, 0.3), (0.0, 0.0, 0.0, 1.0)  # π about z
TABLE_CENTER, TABLE_HALF = (0.0, -0.5, 0.1), (0.4, 0.4, 0.1)
FRICTION, SELF_FRICTION = 1.5, 0.25
FABRIC = "gray-interlock"
#: the arm's joints in Newton's order (its labels are ``fr3/<name>``); the second finger mimics
#: the first in the URDF
JOINTS = tuple(f"fr3_joint{i}" for i in range(1, 8)) + ("fr3_finger_joint1",)


def _newton():
    try:
        import newton
        import newton.examples
        import newton.utils
        import newton.viewer
        import warp as wp
        from newton.examples.cloth import example_cloth_franka
    except ImportError as e:
        raise SystemExit(
            f"franka-peer needs Newton, Warp and usd-core (make bench-peers installs them): {e}"
        ) from e
    wp.config.quiet = True
    wp.init()
    return newton, wp, example_cloth_franka


def shirt_mesh() -> tuple[np.ndarray, np.ndarray]:
    """The shirt of Newton's example: its vertices (cm, as the file has them) and triangles."""
    newton, _, _ = _newton()
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(newton.examples.get_asset("unisex_shirt.usd"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/root/shirt"))
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    if np.any(counts != 3):
        raise ValueError("unisex_shirt.usd: expected triangles only")
    vertices = np.asarray(mesh.GetPointsAttr().Get(), np.float64)
    return vertices, np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), np.int64).reshape(-1, 3)


def run_newton(frames: int) -> dict:
    """Newton's example on Warp's CPU device for ``frames`` frames: each frame's wall time (less
    the checks), joint positions (rad; the fingers in m) and shirt (m), its triangles, and the
    self-crossings between every two substeps (the check wraps the cloth solver's step)."""
    newton, wp, example = _newton()
    wp.set_device("cpu")
    # the arm from this repository's copy, and no CUDA graph (the CPU steps each frame as it is)
    fetch, capture = newton.utils.download_asset, example.Example.capture
    newton.utils.download_asset = lambda folder, *a, **k: URDF.parent.parent
    example.Example.capture = lambda self: setattr(self, "graph", None)
    try:
        sim = example.Example(newton.viewer.ViewerNull(), None)
    finally:
        newton.utils.download_asset, example.Example.capture = fetch, capture
    labels = [str(s).split("/")[-1] for s in sim.model.joint_label]
    starts = sim.model.joint_q_start.numpy()
    cols = [int(starts[labels.index(j)]) for j in JOINTS]
    tris = sim.model.tri_indices.numpy().astype(np.int64)
    solve = sim.cloth_solver.step
    check = {"x": sim.state_0.particle_q.numpy().astype(np.float64), "crossed": 0, "took": 0.0}

    def checked(state_in, state_out, control, contacts, dt):
        solve(state_in, state_out, control, contacts, dt)
        t = time.perf_counter()
        x = state_out.particle_q.numpy().astype(np.float64)
        check["crossed"] += len(crossings(check["x"], x, tris))
        check["x"] = x
        check["took"] += time.perf_counter() - t

    sim.cloth_solver.step = checked

    def joints():
        q = sim.state_0.joint_q.numpy()[cols].astype(np.float64)
        q[-1] *= CM
        return q

    q = np.empty((frames + 1, len(JOINTS)))
    x = np.empty((frames + 1, sim.model.particle_count, 3))
    wall = np.empty(frames)
    q[0], x[0] = joints(), sim.state_0.particle_q.numpy() * CM
    for f in range(frames):
        check["took"] = 0.0
        t = time.perf_counter()
        sim.step()
        wp.synchronize()
        wall[f] = time.perf_counter() - t - check["took"]
        q[f + 1], x[f + 1] = joints(), sim.state_0.particle_q.numpy() * CM
    return {"q": q, "x": x, "wall": wall, "tris": tris, "crossed": check["crossed"]}


def fr3() -> Robot:
    return Robot.from_urdf(URDF, package_paths=[ASSETS])


def ours(q: np.ndarray, steps: int = SUBSTEPS, iterations: int = ITERATIONS) -> Simulator:
    """cloth_sim's side at Newton's first frame (module docstring): ``vbd`` at ``steps`` steps a
    frame (Newton's substeps: 1/600 s) and ``iterations`` iterations a step (Newton's: 5)."""
    vertices, tris = shirt_mesh()
    model = ClothModel.from_mesh(
        (vertices, tris),
        material=FABRIC,
        scale=CM,
        position=SHIRT_POSITION,
        orientation=SHIRT_ORIENTATION,
    )
    sim = Simulator(
        model,
        integrator="vbd",
        dt=FRAME / steps,
        thickness=thickness_limit(model),
        self_collision=True,
        colliders=[
            colliders.Box(TABLE_CENTER, TABLE_HALF, friction=FRICTION, name="table"),
            colliders.Plane(friction=FRICTION, name="floor"),
        ],
        integrator_options={"iterations": iterations, "self_friction": SELF_FRICTION},
    )
    sim.add_robot(
        fr3(), name="fr3", position=ARM_BASE, joints=dict(zip(JOINTS, q[0])), friction=FRICTION
    )
    return sim


def run_ours(q: np.ndarray, steps: int = SUBSTEPS, iterations: int = ITERATIONS) -> dict:
    """cloth_sim's shirt under the arm driven through ``q`` (a row a frame): each frame ``steps``
    steps of ``iterations`` iterations (Newton's: :data:`SUBSTEPS`, :data:`ITERATIONS`), the
    joints moving linearly between the frame's two rows (as Newton's substeps drive them: at the
    joint velocity that reaches the frame's IK solution); the self-crossings between every two
    steps, outside the timed part."""
    sim = ours(q, steps, iterations)
    frames = len(q) - 1
    x = np.empty((frames + 1, sim.model.n_particles, 3))
    wall = np.empty(frames)
    x[0] = sim.positions
    tris, before, crossed = sim.model.triangles, sim.positions.copy(), 0
    for f in range(frames):
        took = 0.0
        for s in range(steps):
            a = (s + 1) / steps
            t = time.perf_counter()
            sim.set_joint_positions("fr3", dict(zip(JOINTS, (1.0 - a) * q[f] + a * q[f + 1])))
            sim.step()
            took += time.perf_counter() - t
            now = sim.positions
            crossed += len(crossings(before, now, tris))
            before = now.copy()
        wall[f] = took
        x[f + 1] = before
    return {
        "x": x, "wall": wall, "tris": tris, "crossed": crossed, "thickness": sim.thickness,
    }  # fmt: skip


def deepest(x: np.ndarray, q: np.ndarray) -> tuple[float, int]:
    """``(deepest inside a link (m), frame of it)`` of a shirt's frames ``x`` under the arm at
    ``q``: the links' own signed distances at each frame's joints (a robot alone in a simulator of
    its own, teleported)."""
    probe = Simulator(ClothModel.grid(2, 2, 0.01, 0.001, stiffness=1.0), integrator="vbd")
    probe.add_robot(fr3(), name="fr3", position=ARM_BASE, joints=dict(zip(JOINTS, q[0])))
    links = [c for c in probe.colliders if c.name.startswith("fr3/")]
    worst, at = 0.0, 0
    for f in range(len(x)):
        probe.set_joint_positions("fr3", dict(zip(JOINTS, q[f])), teleport=True)
        inside = -min(float(c.signed_distance(x[f]).min()) for c in links)
        if inside > worst:
            worst, at = inside, f
    return worst, at


def print_franka_table(
    frames: int = 480,
    newton_file: str | None = None,
    ours_settings: tuple[tuple[int, int], ...] = ((SUBSTEPS, ITERATIONS),),
) -> None:
    """Both sides over ``frames`` frames (Newton's run read from ``newton_file`` where it exists,
    else run and, where a file is named, written there); cloth_sim a row for each of
    ``ours_settings`` (``(steps a frame, iterations a step)``; Newton's own by default)."""
    if newton_file and Path(newton_file).is_file():
        with np.load(newton_file) as z:
            theirs = {k: z[k] for k in z.files}
        if frames < len(theirs["wall"]):
            theirs.pop("crossed", None)  # (counted over every recorded frame)
        frames = min(frames, len(theirs["wall"]))
        theirs = {
            **theirs,
            "q": theirs["q"][: frames + 1],
            "x": theirs["x"][: frames + 1],
            "wall": theirs["wall"][:frames],
        }
    else:
        theirs = run_newton(frames)
        if newton_file:
            np.savez_compressed(newton_file, **theirs)
    runs = [(f"Newton 1.8 (Warp CPU), {SUBSTEPS}x{ITERATIONS}", theirs, SUBSTEPS)]
    for steps, iterations in ours_settings:
        mine = run_ours(theirs["q"], steps, iterations)
        runs.append((f"cloth_sim vbd, {steps}x{iterations}", mine, steps))
    print(
        f"Newton's example_cloth_franka beside cloth_sim, {frames} frames of 1/60 s "
        f"({frames * FRAME:.1f} s), self-contact on, both on the CPU; STEPSxITERATIONS: steps "
        "(substeps) a frame x iterations a step"
    )
    print(
        "| | particles | ms a frame | real-time factor | Newton's time / ours "
        "| deepest inside a link | at frame | self-crossings (between steps) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    newton_wall = float(np.median(theirs["wall"][1:]))
    for name, run, steps in runs:
        wall = float(np.median(run["wall"][1:]))
        depth, at = deepest(run["x"], theirs["q"])
        print(
            f"| {name} | {run['x'].shape[1]:,} | {wall * 1e3:.0f} | {FRAME / wall:.3f} | "
            f"{newton_wall / wall:.2f} | {depth * 1e3:.2f} mm | {at} | "
            f"{run.get('crossed', 'not checked')} of {frames * steps:,} |"
        )
    print(f"(cloth_sim's thickness {runs[-1][1]['thickness'] * 1e3:.2f} mm; {FABRIC})")
