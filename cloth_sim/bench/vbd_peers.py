"""cloth_sim's ``vbd`` beside Newton's ``SolverVBD`` (Newton 1.8 on NVIDIA Warp), in one process.

``cloth-sim bench vbd-peers [--sizes 32 64] [--seconds 2] [--twist-seconds 5] [--device cpu]``
(``make bench-peers`` runs it after Warp's table). Newton is an optional extra
(``requirements-peers.txt``), never installed by ``make test``. ``--device cuda:0`` runs Newton's
side on a GPU (cloth_sim's stays on the CPU), each frame's substeps captured in a CUDA graph as
Newton's examples do.

1. **The hanging_provot cloth, the same springs.** The hanging_provot scene at N×N (1 m, 10.24 kg:
   the speed tables' cloth), its particles, masses, pins and every structural, shear and bend
   spring given to Newton one by one (``ModelBuilder.add_spring``: Newton's VBD takes springs
   beside its FEM triangles), with our general sweep's greedy colour groups (Newton colours
   triangles and bending edges only, none here; ours runs the grid's nine classes on its blocks:
   ``vbd_grid``), no strain limit on either side. Both step each 1/60 s frame in 10 substeps of
   10 iterations (the numbers of Newton's cloth examples). Figures: wall seconds per simulated
   second, the worst stretch of any spring and the bottom row's swing (the range of its mean y),
   each over the run, sampled a frame.
2. **Newton's twist** (``example_cloth_twist``): Newton's own set-up — its FEM cloth of 50 × 50
   vertices (Lamé μ = λ = 1000 N/m, 0.2 kg/m², bending 1e-3), the two short edges fixed and turned
   in opposite senses at π/3 rad/s about the long axis, zero gravity, self-contact at a 2 mm
   margin, 10 substeps × 4 iterations a frame, the BVH rebuilt every frame — rebuilt here without
   its USD asset (the same vertices and triangles, written by ``tools/make_garments.py``), beside
   cloth_sim's ``twist`` scene (springs on the same triangles, grippers turning the edges at the
   same rate) as it ships. Figures: wall seconds per simulated second, and crossings by the
   independent check (:mod:`cloth_sim.bench.crossings`) between every two steps of ours and every
   two substeps of Newton's (every two frames on a GPU, where a frame is one captured graph),
   outside the timed part.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..scene import load_scene
from .crossings import crossings

FRAME = 1.0 / 60.0
#: the twist's turning rate (Newton's example: π/3 rad/s)
TWIST_RATE = math.pi / 3


def _newton():
    try:
        import newton
        import warp as wp
    except ImportError:
        return None
    wp.config.quiet = True
    wp.init()
    return newton, wp


def hanging_sim(n: int, iterations: int, substeps: int):
    """The hanging_provot scene at ``n``×``n`` (the speed tables' 1 m, 10.24 kg cloth), no strain
    limit, ``vbd`` at ``FRAME / substeps`` with ``iterations``."""
    return load_scene("hanging_provot").build_simulator(
        rows=n,
        cols=n,
        spacing=1.0 / (n - 1),
        particle_mass=10.24 / n**2,
        strain_limit=None,
        integrator="vbd",
        dt=FRAME / substeps,
        integrator_options={"iterations": iterations},
    )


class NewtonSprings:
    """A cloth_sim model's particles and springs as a Newton model stepped by its ``SolverVBD``."""

    def __init__(self, newton, wp, model, gravity, iterations: int, substeps: int, device: str):
        from ..integrators.vbd_kernels import colour_groups

        b = newton.ModelBuilder(gravity=tuple(float(g) for g in gravity))
        for i in range(model.n_particles):
            b.add_particle(
                tuple(float(c) for c in model.positions[i]),
                (0.0, 0.0, 0.0),
                0.0 if model.pinned[i] else float(model.masses[i]),
                radius=1e-3,
            )
        for (i, j), k, c in zip(model.springs, model.stiffness, model.damping):
            b.add_spring(int(i), int(j), float(k), float(c), 0.0)
        cptr, verts = colour_groups(model.springs, model.n_particles, ~model.pinned)
        b.particle_color_groups = [
            np.asarray(verts[cptr[g] : cptr[g + 1]], dtype=np.int32) for g in range(len(cptr) - 1)
        ]
        self.wp, self.device = wp, device
        self.model = b.finalize(device=device)
        self.solver = newton.solvers.SolverVBD(self.model, iterations=iterations)
        self.s0, self.s1 = self.model.state(), self.model.state()
        self.control = self.model.control()
        self.dt, self.substeps = FRAME / substeps, substeps
        self.graph = None
        if wp.get_device(device).is_cuda:
            with wp.ScopedCapture(device=device) as capture:
                self._frame()
            self.graph = capture.graph

    def _frame(self):
        for _ in range(self.substeps):
            self.s0.clear_forces()
            self.solver.step(self.s0, self.s1, self.control, None, self.dt)
            self.s0, self.s1 = self.s1, self.s0

    def frame(self):
        if self.graph is not None:
            self.wp.capture_launch(self.graph)
        else:
            self._frame()
        self.wp.synchronize_device(self.device)

    def positions(self) -> np.ndarray:
        return self.s0.particle_q.numpy().astype(np.float64)


def _run_frames(frame, positions, springs, rest, bottom, seconds):
    """Frames for ``seconds``: ``(wall s per simulated s, worst stretch, swing)``."""
    frame()  # warm-up: kernels load (Warp) or compile (numba)
    x = positions()
    ys, worst, wall = [x[bottom, 1].mean()], 0.0, 0.0
    for _ in range(int(round(seconds / FRAME))):
        t = time.perf_counter()
        frame()
        wall += time.perf_counter() - t
        x = positions()
        stretch = np.linalg.norm(x[springs[:, 0]] - x[springs[:, 1]], axis=1) / rest - 1.0
        worst = max(worst, float(stretch.max()))
        ys.append(x[bottom, 1].mean())
    return wall / seconds, worst, float(np.ptp(ys))


def hanging_rows(
    newton,
    wp,
    sizes,
    seconds: float,
    iterations: int,
    substeps: int,
    device: str,
    ours: bool = True,
):
    rows = []
    for n in sizes:
        scene = load_scene("hanging_provot")
        model = scene.build_model(
            rows=n, cols=n, spacing=1.0 / (n - 1), particle_mass=10.24 / n**2
        )
        common = (model.springs, model.rest_lengths, np.arange((n - 1) * n, n * n), seconds)
        row = {"N": n}
        if ours:
            sim = hanging_sim(n, iterations, substeps)
            a = _run_frames(lambda: sim.advance(sim.time + FRAME), lambda: sim.positions, *common)
            row.update(cloth_sim_s_per_s=a[0], cloth_sim_stretch=a[1], cloth_sim_swing=a[2])
        peer = NewtonSprings(newton, wp, model, scene.gravity, iterations, substeps, device)
        b = _run_frames(peer.frame, peer.positions, *common)
        row.update(newton_s_per_s=b[0], newton_stretch=b[1], newton_swing=b[2])
        if ours:
            row["speed_ratio"] = b[0] / a[0]
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------- the twist
class NewtonTwist:
    """Newton's ``example_cloth_twist`` set-up (module docstring), its ends turned by a kernel of
    this module that moves the fixed vertices to their place at the substep's time."""

    def __init__(self, newton, wp, device: str, substeps: int = 10, iterations: int = 4):
        from ..physics.mesh import read_mesh

        vertices, faces, _ = read_mesh(str(load_scene("twist").mesh["file"]), 1.0)
        # the asset's frame: the sheet in the x–z plane in centimetres (scaled by 0.01 below)
        verts = [wp.vec3(100.0 * x, 0.0, 100.0 * y) for x, y, _ in vertices]
        b = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
        b.add_cloth_mesh(
            pos=wp.vec3(0.0, 0.0, 0.0),
            rot=wp.quat_from_axis_angle(wp.vec3(0, 0, 1), np.pi / 2),
            scale=0.01,
            vertices=verts,
            indices=np.asarray(faces).ravel().tolist(),
            vel=wp.vec3(0.0, 0.0, 0.0),
            density=0.2,
            tri_ke=1.0e3,
            tri_ka=1.0e3,
            tri_kd=2.0e-4,
            edge_ke=1e-3,
            edge_kd=1e-2,
        )
        b.color()
        model = b.finalize(device=device)
        model.soft_contact_ke, model.soft_contact_kd, model.soft_contact_mu = 1.0e3, 1.0e-1, 0.2
        side = 50
        left = [side - 1 + i * side for i in range(side)]
        right = [i * side for i in range(side)]
        flags = model.particle_flags.numpy()
        for v in left + right:
            flags[v] &= ~newton.ParticleFlags.ACTIVE
        model.particle_flags = wp.array(flags, device=device)
        self.solver = newton.solvers.SolverVBD(
            model,
            iterations=iterations,
            particle_enable_self_contact=True,
            particle_self_contact_margin=0.002,
            particle_self_contact_gap=0.0015,
            particle_vertex_contact_buffer_size=64,
            particle_edge_contact_buffer_size=128,
        )
        self.s0, self.s1, self.control = model.state(), model.state(), model.control()
        self.pipeline = newton.CollisionPipeline(model)
        self.contacts = self.pipeline.contacts()
        q = self.s0.particle_q.numpy().astype(np.float64)
        fixed = np.array(right + left)
        axes = np.array([[0.0, 1.0, 0.0]] * len(right) + [[0.0, -1.0, 0.0]] * len(left))
        roots = np.einsum("ij,ij->i", q[fixed], axes)[:, None] * axes
        self._fixed = wp.array(fixed.astype(np.int32), dtype=wp.int32, device=device)
        self._axes = wp.array(axes, dtype=wp.vec3, device=device)
        self._roots = wp.array(roots, dtype=wp.vec3, device=device)
        self._arms = wp.array(q[fixed] - roots, dtype=wp.vec3, device=device)
        self._t = wp.zeros(1, dtype=float, device=device)
        self.wp, self.newton, self.device = wp, newton, device
        self.dt, self.substeps = FRAME / substeps, substeps
        self.tris = np.asarray(model.tri_indices.numpy(), dtype=np.int64)
        self.kernel = _turn_kernel(wp)
        self.graph = None
        if wp.get_device(device).is_cuda:
            self.graph = "capturing"
            with wp.ScopedCapture(device=device) as capture:
                self._frame()
            self.graph = capture.graph

    def _frame(self, check=None):
        """One frame as Newton's example steps it; ``check(x0, x1)`` between every two substeps
        (outside the timed part) when given. Returns the wall time of the stepping."""
        wp = self.wp
        t = time.perf_counter()
        self.pipeline.collide(self.s0, self.contacts)
        self.solver.rebuild_bvh(self.s0)
        wall = time.perf_counter() - t
        for _ in range(self.substeps):
            x0 = self.positions() if check else None
            t = time.perf_counter()
            self.s0.clear_forces()
            wp.launch(
                self.kernel,
                dim=self._fixed.shape[0],
                inputs=[
                    self._fixed,
                    self._axes,
                    self._roots,
                    self._arms,
                    self._t,
                    TWIST_RATE,
                    self.dt,
                ],
                outputs=[self.s0.particle_q, self.s1.particle_q],
                device=self.device,
            )
            self.solver.step(self.s0, self.s1, self.control, self.contacts, self.dt)
            self.s0, self.s1 = self.s1, self.s0
            if self.graph is None:  # (not while a graph is being captured)
                wp.synchronize_device(self.device)
            wall += time.perf_counter() - t
            if check:
                check(x0, self.positions())
        return wall

    def frame(self, check=None) -> float:
        """A frame (on a GPU, its captured graph: ``check`` then sees the frame's two ends only);
        returns the wall time of the stepping."""
        if self.graph is None:
            return self._frame(check)
        x0 = self.positions() if check else None
        t = time.perf_counter()
        self.wp.capture_launch(self.graph)
        self.wp.synchronize_device(self.device)
        wall = time.perf_counter() - t
        if check:
            check(x0, self.positions())
        return wall

    def positions(self) -> np.ndarray:
        return self.s0.particle_q.numpy().astype(np.float64)


def _turn_kernel(wp):
    @wp.kernel
    def turn(
        fixed: wp.array(dtype=wp.int32),
        axes: wp.array(dtype=wp.vec3),
        roots: wp.array(dtype=wp.vec3),
        arms: wp.array(dtype=wp.vec3),
        t: wp.array(dtype=float),
        rate: float,
        dt: float,
        q0: wp.array(dtype=wp.vec3),
        q1: wp.array(dtype=wp.vec3),
    ):
        k = wp.tid()
        turned = wp.quat_rotate(wp.quat_from_axis_angle(axes[k], t[0] * rate), arms[k])
        q0[fixed[k]] = roots[k] + turned
        q1[fixed[k]] = roots[k] + turned
        if k == 0:
            t[0] = t[0] + dt

    return turn


def twist_sim(rate: float = TWIST_RATE):
    """The shipped ``twist`` scene, and a function that sets its grippers' poses for time ``t``
    (each short edge turned about the long axis at ``rate`` rad/s, in opposite senses)."""
    sim = load_scene("twist").build_simulator()
    sim.motion = None  # turned here, past the scene script's 6 s too
    centres = {name: sim.positions[idx].mean(axis=0) for name, idx in sim.grippers.items()}

    def turn(t):
        for name, sense in (("left", -1.0), ("right", 1.0)):
            a = 0.5 * sense * rate * t
            sim.set_gripper_pose(name, centres[name], (math.cos(a), math.sin(a), 0.0, 0.0))

    return sim, turn


def twist_row(newton, wp, seconds: float, device: str, ours: bool = True) -> dict:
    row = {"seconds": seconds}
    if ours:
        warm, turn = twist_sim()  # a warm-up, thrown away: numba loads its kernels
        turn(warm.dt)
        warm.step()
        sim, turn = twist_sim()
        tris = sim.model.triangles
        wall, crossed = 0.0, 0
        while sim.time < seconds - 1e-9:
            turn(sim.time + sim.dt)
            x0 = sim.positions.copy()
            t = time.perf_counter()
            sim.step()
            wall += time.perf_counter() - t
            crossed += len(crossings(x0, sim.positions, tris))
        row.update(
            cloth_sim_s_per_s=wall / seconds,
            cloth_sim_crossings=crossed,
            cloth_sim_contacts=int(sim.integrator_stats["last_contacts"]),
            cloth_sim_dt=sim.dt,
            cloth_sim_iterations=sim.integrator_options.get("iterations"),
        )
    NewtonTwist(newton, wp, device).frame()  # a warm-up, thrown away: Warp loads its modules
    peer = NewtonTwist(newton, wp, device)
    found = [0]

    def check(x0, x1):
        found[0] += len(crossings(x0, x1, peer.tris))

    peer_wall = sum(peer.frame(check) for _ in range(int(round(seconds / FRAME))))
    row.update(newton_s_per_s=peer_wall / seconds, newton_crossings=found[0])
    if ours:
        row["speed_ratio"] = row["newton_s_per_s"] / row["cloth_sim_s_per_s"]
    return row


def _f(row, key, form="{:.3f}"):
    return form.format(row[key]) if key in row else "–"


def print_vbd_peer_table(
    sizes=(32, 64),
    seconds: float = 2.0,
    twist_seconds: float = 5.0,
    device: str = "cpu",
    iterations: int = 10,
    substeps: int = 10,
    ours: bool = True,
) -> int:
    """Both tables (module docstring); ``ours=False`` runs Newton's side alone (a GPU machine
    where cloth_sim's figures come from another run)."""
    peers = _newton()
    if peers is None:
        print(
            "newton is not installed: `make bench-peers` installs the pinned optional extra "
            "(requirements-peers.txt)"
        )
        return 1
    newton, wp = peers
    where = wp.get_device(device)
    print(
        f"# Newton {newton.__version__} SolverVBD on Warp {wp.config.version} {where.alias} "
        f"({where.name}) vs cloth_sim vbd on this CPU"
    )
    print(
        f"## 1. hanging_provot N×N (1 m, 10.24 kg), the same springs, no strain limit; 1/60 s "
        "frames of "
        f"{substeps} substeps × {iterations} iterations, {seconds:g} s"
    )
    print(
        "| N | cloth_sim s per sim s | Newton s per sim s | cloth_sim speed / Newton's | "
        "worst stretch (cloth_sim / Newton) | swing m (cloth_sim / Newton) |"
    )
    print("|---|---|---|---|---|---|")
    for r in hanging_rows(newton, wp, sizes, seconds, iterations, substeps, device, ours):
        print(
            f"| {r['N']} | {_f(r, 'cloth_sim_s_per_s')} | {_f(r, 'newton_s_per_s')} | "
            f"{_f(r, 'speed_ratio', '{:.1f}×')} | {_f(r, 'cloth_sim_stretch', '{:.4f}')} / "
            f"{_f(r, 'newton_stretch', '{:.4f}')} | {_f(r, 'cloth_sim_swing', '{:.4f}')} / "
            f"{_f(r, 'newton_swing', '{:.4f}')} |",
            flush=True,
        )
    if twist_seconds > 0:
        r = twist_row(newton, wp, twist_seconds, device, ours)
        mine = (
            f"cloth_sim's twist scene at dt {r['cloth_sim_dt']:.6g} s × "
            f"{r['cloth_sim_iterations']} iterations"
            if ours
            else "Newton's side alone"
        )
        print(
            f"## 2. Newton's example_cloth_twist ({twist_seconds:g} s): Newton 1/60 s frames of "
            "10 "
            f"substeps × 4 iterations; {mine}"
        )
        print(
            "| cloth_sim s per sim s | Newton s per sim s | cloth_sim speed / Newton's | "
            "crossings (cloth_sim / Newton) | cloth_sim contacts at the end |"
        )
        print("|---|---|---|---|---|")
        print(
            f"| {_f(r, 'cloth_sim_s_per_s')} | {_f(r, 'newton_s_per_s')} | "
            f"{_f(r, 'speed_ratio', '{:.1f}×')} | {_f(r, 'cloth_sim_crossings', '{}')} / "
            f"{r['newton_crossings']} | {_f(r, 'cloth_sim_contacts', '{}')} |",
            flush=True,
        )
    return 0
