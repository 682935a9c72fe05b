"""The CUDA backend against the CPU: the same method and options give the same cloth (float64 on
the device: to rounding; float32: within the tolerance the docs state), per-world parameters,
resets, and the errors for what the device does not run. Tiny cloths: on numba-cuda's simulator
each thread is a Python thread."""

import numpy as np
import pytest
from numba import cuda

from cloth_sim import BatchSimulator, ClothModel, SimulationDiverged, Simulator
from cloth_sim.contact.colliders import Box, Capsule, Cylinder, Plane, Sphere
from cloth_sim.cuda import simulated

WIND = (0.3, 0.1, 0.5)


def sheet(rows=4, cols=4, **kw):
    kw.setdefault("stiffness", 1e2)
    kw.setdefault("damping", 0.05)
    return ClothModel.grid(rows, cols, 0.05, 0.01, pinned=[(0, 0), (0, cols - 1)], **kw)


def cotton(n=4):
    return ClothModel.grid(n, n, material="cotton", size=(0.2, 0.2), pinned=[(0, 0), (0, n - 1)])


def test_symplectic_euler_is_the_cpus_to_rounding_in_float64():
    m = cotton()  # springs with damping, and the material's bending
    cpu = Simulator(m, integrator="symplectic_euler", dt=2e-4, wind=WIND, drag=0.01)
    gpu = Simulator(
        m,
        integrator="symplectic_euler",
        dt=2e-4,
        wind=WIND,
        drag=0.01,
        device="cuda",
        precision="float64",
    )
    assert m.bending is not None
    cpu.step(25)
    gpu.step(25)
    assert gpu.device == "cuda"
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-14
    assert np.max(np.abs(gpu.velocities - cpu.velocities)) < 1e-12
    assert gpu.time == pytest.approx(cpu.time)
    assert np.max(np.abs(cpu.positions - m.positions)) > 1e-4  # it moved


def test_float32_stays_within_its_rounding():
    m = sheet()
    cpu = Simulator(m, integrator="symplectic_euler", dt=1e-3, wind=WIND)
    gpu = Simulator(m, integrator="symplectic_euler", dt=1e-3, wind=WIND, device="cuda")
    cpu.step(40)
    gpu.step(40)
    moved = np.max(np.abs(cpu.positions - m.positions))
    assert moved > 5e-3
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-5


def converged_pair(m, opts):
    """``vbd`` with ``opts`` at 1/120 s in the wind on the cpu (the general sweep, whose order of
    colours is the device's kind) and on cuda in float64."""
    kw = dict(integrator="vbd", dt=1 / 120, wind=WIND)
    cpu = Simulator(m, integrator_options=dict(opts, grid=False), **kw)
    gpu = Simulator(m, integrator_options=opts, device="cuda", precision="float64", **kw)
    return cpu, gpu


def test_vbd_solves_the_same_backward_euler_step():
    # run to convergence (tolerance 0: every iteration) on both: the same step's solution, whatever
    # the order of the colours
    m = cotton()
    cpu, gpu = converged_pair(m, dict(iterations=80, tolerance=0.0, substeps=1))
    cpu.step(2)
    gpu.step(2)
    assert np.max(np.abs(cpu.positions - m.positions)) > 1e-3
    # (the two differ by 2.6e-5 m at 20 iterations, 4.2e-8 at 40, 1.2e-13 at 80)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-11
    assert gpu.integrator_stats["last_residual"] < 1e-9


def test_bdf2_solves_the_cpus_step():
    """vbd's BDF2 substeps (backward Euler's of 2h/3 from the extrapolated start, after one
    backward-Euler substep) run to convergence on both devices: the same cloth, its pins (whose
    velocity BDF2 must not touch) included; a state set from the host starts BDF2 again on both."""
    m = cotton()
    opts = dict(iterations=80, tolerance=0.0, substeps=1, scheme="bdf2")
    cpu, gpu = converged_pair(m, opts)
    for sim in (cpu, gpu):
        sim.step(3)
        sim.velocities = sim.velocities * 0.5  # (BDF2's history no longer serves)
        sim.step(1)
    euler = Simulator(
        m,
        integrator="vbd",
        dt=1 / 120,
        wind=WIND,
        integrator_options=dict(opts, grid=False, scheme="euler"),
    )
    euler.step(2)
    assert np.max(np.abs(euler.positions - cpu.positions)) > 1e-6  # BDF2 is not Euler
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-11
    assert np.max(np.abs(gpu.velocities - cpu.velocities)) < 1e-9


def test_vbd_says_whether_it_converged():
    m = sheet(stiffness=3e3)
    capped = Simulator(
        m,
        integrator="vbd",
        dt=1 / 60,
        device="cuda",
        integrator_options=dict(iterations=1, tolerance=1e-2),
    )
    roomy = Simulator(
        m,
        integrator="vbd",
        dt=1 / 60,
        device="cuda",
        integrator_options=dict(iterations=60, tolerance=1e-2),
    )
    capped.step()
    roomy.step()
    c, r = capped.integrator_stats, roomy.integrator_stats
    assert c["last_residual"] > 1e-2 and c["converged"] is False
    assert r["last_residual"] <= 1e-2 and r["converged"] is True
    assert r["last_iterations"] < 60  # it stopped at the tolerance
    assert r["last_iterations"] % 5 == 0  # measured every check_every iterations


def test_vbd_defaults_choose_the_cpus_substeps():
    m = cotton()
    cpu = Simulator(m, integrator="vbd", dt=1 / 60)
    gpu = Simulator(m, integrator="vbd", dt=1 / 60, device="cuda", precision="float64")
    cpu.step()
    gpu.step()
    assert gpu.integrator_stats["last_substeps"] == cpu.integrator_stats["last_substeps"] > 1
    # both converged to the default tolerance: the same cloth to what the tolerance leaves
    assert gpu.integrator_stats["converged"] and cpu.integrator_stats["converged"]
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-4


def test_worlds_take_their_own_parameters():
    m = sheet()
    kw = dict(integrator="symplectic_euler", dt=1e-3)
    gpu = BatchSimulator(m, worlds=3, device="cuda", precision="float64", **kw)
    cpu = BatchSimulator(m, worlds=3, **kw)
    for b in (gpu, cpu):
        b.set([1], wind=(0.0, 0.0, 1.0), drag=0.02)
        b.set(
            [2], stiffness={"structural": 50.0}, damping={"shear": 0.2}, gravity=(0.0, -9.81, 0.0)
        )
        b.step(15)
    x = gpu.positions_host()
    assert x.shape == (3, m.n_particles, 3)
    assert np.max(np.abs(x - cpu.positions_host())) < 1e-14
    assert np.min([np.max(np.abs(x[0] - x[w])) for w in (1, 2)]) > 1e-6  # they differ
    # the same parameters give the same bits in every world
    same = BatchSimulator(m, worlds=2, device="cuda", **kw)
    same.step(5)
    y = same.positions_host()
    assert np.array_equal(y[0], y[1])
    # a device array, not a host copy (the simulator's stand-in carries no CUDA array interface)
    p = same.positions
    if simulated():
        assert type(p).__name__ == "FakeCUDAArray"
    else:
        assert cuda.is_cuda_array(p) and p.shape == (2, m.n_particles, 3)


def test_a_world_resets_alone():
    m = sheet()
    b = BatchSimulator(
        m,
        worlds=2,
        integrator="vbd",
        dt=1 / 60,
        device="cuda",
        integrator_options=dict(iterations=5),
    )
    b.step(2)
    before = b.positions_host()
    b.reset([0])
    after = b.positions_host()
    assert np.allclose(after[0], m.positions, atol=1e-7)
    assert np.array_equal(after[1], before[1])
    assert list(b.time) == pytest.approx([0.0, 2 / 60])


def test_a_list_of_models_must_share_one_topology():
    a, b = sheet(), sheet(rows=5)
    with pytest.raises(ValueError, match=r"models\[1\]\.springs"):
        BatchSimulator([a, b], device="cuda")
    heavier = ClothModel.grid(
        4, 4, 0.05, 0.02, stiffness=1e2, damping=0.05, pinned=[(0, 0), (0, 3)]
    )
    batch = BatchSimulator(
        [a, heavier], integrator="symplectic_euler", dt=1e-3, device="cuda", precision="float64"
    )
    batch.step(10)
    ref = Simulator(heavier, integrator="symplectic_euler", dt=1e-3)
    ref.step(10)
    assert np.max(np.abs(batch.positions_host()[1] - ref.positions)) < 1e-14


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(integrator="rk4"), r"integrator 'rk4' has no cuda backend; on cuda: "),
        (
            dict(strain_limit=0.1, strain_limit_method="projection"),
            r"strain_limit_method: not on the cuda device yet \(the projection is not",
        ),
        (dict(self_collision=True), r"self_collision: not on the cuda device"),
        (
            dict(integrator="vbd", integrator_options={"collider_share": 0.4}),
            r"vbd option\(s\) collider_share not on the cuda device",
        ),
        (dict(precision="float16"), r"precision must be one of float32, float64"),
    ],
)
def test_what_the_device_does_not_run_is_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Simulator(sheet(), device="cuda", **kwargs)


def test_choi_ko_is_refused():
    choi = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, model="choi_ko")
    with pytest.raises(ValueError, match=r"model 'choi_ko': Choi & Ko's"):
        Simulator(choi, device="cuda")


def test_per_world_input_is_checked_before_anything_changes():
    b = BatchSimulator(sheet(), worlds=2, integrator="symplectic_euler", dt=1e-3, device="cuda")
    with pytest.raises(ValueError, match=r"worlds: indices must lie in \[0, 1\]"):
        b.set([2], drag=0.1)
    with pytest.raises(ValueError, match=r"stiffness: unknown family 'warp'"):
        b.set([0], wind=(1.0, 0.0, 0.0), stiffness={"warp": 3.0})
    with pytest.raises(ValueError, match=r"wind must be a finite 3-vector"):
        b.set([0], wind=(1.0, np.nan, 0.0))
    b.step(3)
    y = b.positions_host()
    assert np.array_equal(y[0], y[1])  # the refused wind never reached world 0


@pytest.mark.filterwarnings("ignore:overflow:RuntimeWarning", "ignore:invalid:RuntimeWarning")
def test_a_diverging_step_is_undone():
    m = sheet(stiffness=1e5)
    sim = Simulator(m, integrator="symplectic_euler", dt=5e-3, device="cuda")
    sim.step(2)
    x, t = sim.positions.copy(), sim.time
    with pytest.raises(SimulationDiverged):
        sim.step(200)
    assert np.array_equal(sim.positions, x) and sim.time == t


def test_state_set_and_read_back():
    m = sheet()
    sim = Simulator(
        m, integrator="vbd", dt=1 / 60, device="cuda", integrator_options=dict(iterations=5)
    )
    x = m.positions + np.array([0.0, 0.0, 0.01])
    sim.positions = x
    assert np.allclose(sim.positions, x, atol=1e-7)
    sim.move_pins([[0.0, 0.0, 0.1]], indices=[0])
    assert np.allclose(sim.positions[0], [0.0, 0.0, 0.1])
    saved = sim.save_state()
    sim.step(2)
    sim.restore_state(saved)
    assert np.allclose(sim.positions, saved.x, atol=1e-7) and sim.time == 0.0
    sim.set_integrator("symplectic_euler")
    assert sim.integrator == "symplectic_euler"
    assert np.allclose(sim.positions, saved.x, atol=1e-7)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "vbd"])
def test_every_launch_gives_the_same_bits(integrator):
    """A run of steps in one launch (a block a world, or the whole grid cooperating) or a launch a
    stage: the same arithmetic in the same order, the same positions."""
    m = cotton()
    # (vbd: a backward-Euler substep, then BDF2's)
    opts = dict(iterations=12, tolerance=0.0, scheme="bdf2") if integrator == "vbd" else None
    dt = 1 / 120 if integrator == "vbd" else 2e-4
    got = {}
    for launch in ("blocks", "grid", "stages"):
        b = BatchSimulator(
            m,
            worlds=2,
            integrator=integrator,
            dt=dt,
            device="cuda",
            precision="float64",
            integrator_options=opts,
            launch=launch,
        )
        b.set([1], wind=WIND)
        b.step(3)
        got[launch] = b.positions_host()
        if launch != "stages":  # three steps, one launch
            assert b.last_launches == pytest.approx(1 / 3)
        elif integrator == "symplectic_euler":  # a step, and the copy back from its buffers
            assert b.last_launches == 2
    assert np.array_equal(got["blocks"], got["stages"])
    assert np.array_equal(got["grid"], got["stages"])
    assert np.max(np.abs(got["stages"][1] - got["stages"][0])) > 1e-6


def test_the_cooperative_launch_reports_to_every_world():
    """The grid launch's counters (the residual, the sweeps, the steps that missed the tolerance)
    reach every world's row however few threads it has: on the simulator's one thread the rows
    past the first were left unwritten, and the iterations were read from whatever the buffer
    held (a NaN once in `make test-gpu`)."""
    b = BatchSimulator(
        cotton(),
        worlds=3,
        integrator="vbd",
        dt=1 / 120,
        device="cuda",
        precision="float64",
        integrator_options=dict(iterations=4, tolerance=0.0),
        launch="grid",
    )
    b._out.copy_to_device(np.full((3, 3), np.nan))
    b.step()
    assert np.isfinite(b.last_residual).all()
    assert np.all(b.iterations == b.iterations[0]) and b.iterations[0] >= 4


def test_worlds_in_blocks_stop_at_their_own_tolerance():
    """In a block a world, a world that converges stops sweeping while a stiffer one goes on."""
    m = sheet(stiffness=3e3)
    b = BatchSimulator(
        m,
        worlds=2,
        integrator="vbd",
        dt=1 / 60,
        device="cuda",
        integrator_options=dict(iterations=60, tolerance=1e-2),
        launch="blocks",
    )
    b.set([1], stiffness={"structural": 1.0, "shear": 1.0, "bend": 1.0})
    b.step()
    assert (b.last_residual <= 1e-2).all()
    assert b.iterations[1] < b.iterations[0]


def test_the_gpu_benchmark_runs(capsys):
    """``cloth-sim bench gpu --simulator``: the script's five tables on a tiny cloth (the figures
    on the simulator mean nothing; the same-cloth check still holds)."""
    from cloth_sim.bench.gpu import print_gpu_tables

    figures = print_gpu_tables(seconds=0.05, simulator=True)
    out = capsys.readouterr().out
    assert "1. the same cloth" in out and "3. many worlds" in out
    assert [f["precision"] for f in figures["same"]] == ["float32", "float64"]
    assert all(f["end"] < 1e-4 for f in figures["same"])
    assert figures["large"][0]["launch"] == "blocks" and figures["large"][0]["unconverged"] == 0
    assert [w["worlds"] for w in figures["worlds"]] == [1, 2]
    assert "4. ClothFold's vector env" in out
    assert [(r["kind"], r["envs"]) for r in figures["vector"]] == [
        ("ClothFoldVectorEnv cuda", 1),
        ("ClothFoldVectorEnv cuda", 2),
        ("AsyncVectorEnv cpu", 2),
    ]
    assert all(r["rate"] > 0 for r in figures["vector"])
    assert "5. colliders and a robot" in out and "robot_pick on the GPU" in out
    assert [r["integrator"] for r in figures["colliders"]["box"]] == ["symplectic_euler", "vbd"]
    assert figures["colliders"]["robot_pick"] > 0


def test_held_vertices_are_pins_a_world_sets():
    """A world's held vertices move only where they are put: the same cloth as a CPU model whose
    pins are those vertices, moved there by move_pins; released, they fall again."""
    m = sheet()
    corner = [m.index(3, 3)]
    b = BatchSimulator(
        m, worlds=2, integrator="symplectic_euler", dt=1e-3, device="cuda", precision="float64"
    )
    b.hold([1], corner, [[0.15, 0.15, 0.05]])
    assert b.held(1).tolist() == sorted([0, 3, corner[0]]) and b.held(0).tolist() == [0, 3]
    b.step(20)
    pinned = ClothModel.grid(
        4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0), (0, 3), (3, 3)]
    )
    ref = Simulator(pinned, integrator="symplectic_euler", dt=1e-3)
    ref.move_pins([[0.15, 0.15, 0.05]], indices=corner)
    ref.step(20)
    x = b.positions_host()
    assert np.max(np.abs(x[1] - ref.positions)) < 1e-14
    assert np.allclose(x[1, corner[0]], [0.15, 0.15, 0.05])
    b.release([1])
    assert b.held(1).tolist() == [0, 3]
    b.step(20)
    assert b.positions_host()[1, corner[0], 2] < 0.05 - 1e-4


# vbd starts nearer the plane: on the simulator each of its sweeps is slow, and the cloth lands by
# its third step and slides on the plane for the rest
@pytest.mark.parametrize(
    "integrator, height, dt, steps, opts, within",
    [
        ("symplectic_euler", 0.02, 1e-3, 150, None, 1e-15),
        ("vbd", 0.008, 1 / 120, 10, dict(iterations=40, tolerance=0.0, substeps=1), 5e-7),
    ],
)
def test_static_planes_are_the_cpus(integrator, height, dt, steps, opts, within):
    """A cloth falling onto a tilted plane with friction: symplectic Euler's contact stage (the
    path marched to the skin, the projection with friction, the velocity filter) gives the CPU's
    numbers; vbd's penalty and friction inside the iterations and the stage after them give the
    CPU's cloth to 5e-7 m (1.3e-7 at the landing: the CPU's bounds on the vertices' motion are not
    on the device), both resting on the plane's skin."""
    normal = np.array([0.0, 0.1, 1.0])
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, origin=(0, 0, height))
    kw = dict(
        integrator=integrator,
        dt=dt,
        thickness=0.005,
        colliders=[Plane(normal, 0.0, friction=0.3)],
    )
    cpu = Simulator(m, integrator_options=dict(opts, grid=False) if opts else None, **kw)
    gpu = Simulator(m, integrator_options=opts, device="cuda", precision="float64", **kw)
    cpu.step(steps)
    gpu.step(steps)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < within
    skin = gpu.positions @ (normal / np.linalg.norm(normal))
    assert skin.min() == pytest.approx(0.005, abs=1e-9)


#: static primitives under a 4×4 sheet falling from just above them: each shape a row of its
#: vertices lands on (a box turned about z, a capsule along x under the second row), and a
#: sphere beside a tilted plane, where a vertex touching both takes the crease pass
PRIMITIVES = {
    "sphere": [Sphere(center=(0.07, 0.07, -0.05), radius=0.06, friction=0.3)],
    "box": [
        Box(
            center=(0.07, 0.07, -0.03),
            half_extents=(0.05, 0.04, 0.02),
            friction=0.3,
            orientation=(0.96, 0.0, 0.0, 0.28),
        )
    ],
    "capsule": [Capsule(a=(0.0, 0.05, -0.03), b=(0.15, 0.05, -0.03), radius=0.02, friction=0.3)],
    "cylinder": [Cylinder(center=(0.07, 0.07, -0.04), radius=0.04, length=0.04, friction=0.3)],
    "sphere and plane": [
        Sphere(center=(0.07, 0.07, -0.02), radius=0.03, friction=0.3),
        Plane((0.0, 0.1, 1.0), -0.025, friction=0.5),
    ],
}


@pytest.mark.parametrize("shape", PRIMITIVES)
def test_static_primitives_are_the_cpus_on_symplectic_euler(shape):
    """The contact stage after symplectic Euler on a sphere, a box, a capsule, a cylinder and a
    sphere beside a plane gives the CPU's cloth to rounding (the path marched to the skin, the
    projection with friction, the velocity filter, the crease pass): 6e-17 to 1.8e-16 m after
    150 steps, the cloth on the colliders and never inside their skins."""
    colliders = PRIMITIVES[shape]
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, origin=(0, 0, 0.008))
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=0.005, colliders=colliders)
    cpu = Simulator(m, **kw)
    gpu = Simulator(m, device="cuda", precision="float64", **kw)
    cpu.step(150)
    gpu.step(150)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    skin = min(float(np.min(c.signed_distance(gpu.positions))) for c in colliders)
    assert 0.005 - 1e-9 <= skin < 0.01  # on the collider (within two skins), never inside it


def test_vbd_on_a_sphere_beside_a_plane_converged_is_the_cpus():
    """vbd's penalty and friction on a sphere and a tilted plane inside the iterations, the
    onset, and the contact stage after them: converged (120 sweeps a step, no tolerance), the
    device gives the CPU's cloth to rounding (8e-17 m after three steps, touching). Unconverged
    the two differ as their colour orders do: 40 sweeps, 12 steps, 1.2e-6 m on the sphere, and
    7.8e-14 at 200 sweeps."""
    colliders = [
        Sphere(center=(0.05, 0.05, -0.028), radius=0.03, friction=0.3),
        Plane((0.0, 0.1, 1.0), -0.03, friction=0.5),
    ]
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, origin=(0, 0, 0.006))
    opts = dict(iterations=120, tolerance=0.0, substeps=1)
    kw = dict(integrator="vbd", dt=1 / 120, thickness=0.005, colliders=colliders)
    cpu = Simulator(m, integrator_options=dict(opts, grid=False), **kw)
    gpu = Simulator(m, integrator_options=opts, device="cuda", precision="float64", **kw)
    cpu.step(3)
    gpu.step(3)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-12
    skin = min(float(np.min(c.signed_distance(gpu.positions))) for c in colliders)
    assert skin == pytest.approx(0.005, abs=1e-9)


def test_a_worlds_collider_put_elsewhere_is_the_cpus_teleported_collider():
    """``BatchSimulator.set(worlds, colliders={i: pose})`` on cuda: the named world's sphere is
    there at rest from the next step, as ``set_collider_pose(i, ..., teleport=True)`` puts it on
    the CPU, and the other world keeps its own (the CPU's cloth to rounding in both); bad input
    changes nothing; a swept move is refused."""
    sphere = Sphere(center=(0.07, 0.07, -0.05), radius=0.06, friction=0.3)
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, origin=(0, 0, 0.008))
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=0.005, colliders=[sphere])
    b = BatchSimulator(m, worlds=2, device="cuda", precision="float64", **kw)
    moved = ((0.02, 0.1, -0.04), (0.96, 0.28, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"colliders: index 1 must lie in \[0, 0\]"):
        b.set([1], colliders={1: moved})
    with pytest.raises(ValueError, match=r"colliders\[0\] must be \(position, orientation\)"):
        b.set([1], colliders={0: (0.0, 0.1, 0.2)})
    with pytest.raises(ValueError, match=r"colliders\[0\]: position must be 3 finite numbers"):
        b.set([1], colliders={0: ((0.0, np.nan, 0.0), (1.0, 0.0, 0.0, 0.0))})
    b.set([1], colliders={0: moved})
    b.step(120)
    still, there = Simulator(m, **kw), Simulator(m, **kw)
    there.set_collider_pose(0, *moved, teleport=True)
    still.step(120)
    there.step(120)
    x = b.positions_host()
    assert np.max(np.abs(x[0] - still.positions)) < 1e-15
    assert np.max(np.abs(x[1] - there.positions)) < 1e-15
    assert np.max(np.abs(there.positions - still.positions)) > 1e-3  # it did move the sphere
    one = Simulator(m, device="cuda", precision="float64", **dict(kw, integrator="vbd"))
    with pytest.raises(ValueError, match=r"swept motion under vbd is not on the cuda device yet"):
        one.set_collider_pose(0, (0.0, 0.0, 0.0))
    assert not one.sweeps_colliders
    one.set_collider_pose(0, *moved, teleport=True)
    assert np.allclose(one.colliders[0].position, moved[0])


def test_a_collider_swept_on_the_device_is_the_cpus():
    """A collider moved by ``set_collider_pose`` without ``teleport`` under symplectic Euler is
    swept over the next step as on the CPU: the cloth's paths carried with it, friction on the
    motion relative to it (a box under a resting cloth slid and turned carries it along; a
    sphere swept up through it lifts it), the CPU's cloth to rounding in float64 (< 1e-15 m),
    through runs of steps as through single ones; a bad index or pose is refused, nothing
    moved."""
    box = Box(center=(0.07, 0.07, -0.03), half_extents=(0.2, 0.2, 0.02), friction=0.8)
    ball = Sphere(center=(0.08, 0.08, -0.2), radius=0.04, friction=0.3)
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, origin=(0, 0, -0.004))
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=0.005, colliders=[box, ball])
    sims = [Simulator(m, **kw), Simulator(m, device="cuda", precision="float64", **kw)]
    assert sims[1].sweeps_colliders
    with pytest.raises(ValueError, match=r"collider index must be an integer in \[0, 1\]"):
        sims[1].set_collider_pose(2, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"position must be 3 finite numbers"):
        sims[1].set_collider_pose(0, (0.0, np.inf, 0.0))
    for sim in sims:
        sim.step(30)  # settle on the box
        for k in range(40):
            turn = (np.cos(0.01 * k), 0.0, 0.0, np.sin(0.01 * k))
            sim.set_collider_pose(0, (0.07 + 0.001 * k, 0.07, -0.03), turn)
            sim.set_collider_pose(1, (0.08, 0.08, -0.2 + 0.005 * k))
            sim.step()
        sim.set_collider_pose(1, (0.08, 0.08, 0.05))
        sim.step(5)  # swept over the first, standing over the rest
    cpu, gpu = sims
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    assert np.max(np.abs(cpu.positions[:, 0] - m.positions[:, 0])) > 0.005  # carried along
    assert np.allclose(gpu.colliders[1].position, (0.08, 0.08, 0.05))


def test_the_node_settings_take_a_scene_of_static_primitives_to_the_device():
    """``settings.check`` (what the node starts with) accepts ``device=cuda`` for the scenes whose
    colliders and strain limit the device has (drape: a sphere and a floor; table: a box and a
    floor; both symplectic Euler with Provot's limit) and builds them on it, with a mesh collider
    added too; a scene whose strain limit is the projection is refused naming the method."""
    from cloth_sim import settings
    from cloth_sim.cuda.simulator import CudaSimulator
    from cloth_sim.scene import load_scene

    for name in ("drape", "table"):
        scene = load_scene(name)
        checked = settings.check(scene, {"device": "cuda", "rows": 4, "cols": 4})
        sim = settings.build(checked)
        assert isinstance(sim, CudaSimulator) and len(sim.colliders) == len(scene.colliders)
        assert sim.strain_limit == 0.1 and sim.active_stages == ("strain_limit",)
    # a scene whose limit is the projection: refused naming the method, run with Provot's passes
    with pytest.raises(settings.Refusal, match=r"strain_limit_method: not on the cuda device"):
        settings.check("hanging", {"device": "cuda", "rows": 4, "cols": 4})
    checked = settings.check(
        "hanging", {"device": "cuda", "rows": 4, "cols": 4, "strain_limit_method": "provot"}
    )
    assert settings.build(checked).strain_limit == 0.1
    # a mesh collider too, read from its distance grid
    scene = load_scene("drape")
    v = np.array([[0.0, 0.0, -1.0], [0.1, 0.0, -1.0], [0.0, 0.1, -1.0], [0.0, 0.0, -0.95]])
    tet = (v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    scene.colliders.append(("mesh", {"source": tet, "name": "tet"}))
    checked = settings.check(scene, {"device": "cuda", "rows": 4, "cols": 4})
    sim = settings.build(checked)
    assert isinstance(sim, CudaSimulator) and sim.colliders[-1].name == "tet"


def test_colliders_added_and_removed_on_the_device_are_the_cpus():
    """``add_collider`` and ``remove_collider`` between steps, as the node's spawn and delete
    services call them: the device's cloth is the CPU's to rounding after each (a sphere added
    under the falling cloth at step 40, a box at 80, the sphere removed at 120, the box then at
    index 0); a name in use, a bad index and no collider are refused naming them, and
    the cloth and its colliders are as they were."""
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, origin=(0, 0, 0.008))
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=0.005)
    cpu = Simulator(m, **kw)
    gpu = Simulator(m, device="cuda", precision="float64", **kw)
    with pytest.raises(ValueError, match=r"there are no colliders to remove"):
        gpu.remove_collider(0)

    def both(call):
        return [call(sim) for sim in (cpu, gpu)]

    for sim in (cpu, gpu):
        sim.step(40)
    ball = dict(center=(0.07, 0.07, -0.03), radius=0.03, friction=0.3, name="ball")
    assert both(lambda s: s.add_collider(Sphere(**ball))) == [0, 0]
    for sim in (cpu, gpu):
        sim.step(40)
    block = dict(center=(0.0, 0.0, -0.06), half_extents=(0.2, 0.2, 0.01), friction=0.5)
    assert both(lambda s: s.add_collider(Box(**block, name="block"))) == [1, 1]
    x_before = gpu.positions.copy()
    with pytest.raises(ValueError, match=r"a collider named 'ball' exists already"):
        gpu.add_collider(Sphere(**ball))
    with pytest.raises(ValueError, match=r"a collider must be a cloth_sim.contact.colliders"):
        gpu.add_collider("ball")
    with pytest.raises(ValueError, match=r"collider index must be an integer in \[0, 1\]"):
        gpu.remove_collider(2)
    assert [c.name for c in gpu.colliders] == ["ball", "block"]
    assert np.array_equal(gpu.positions, x_before)
    for sim in (cpu, gpu):
        sim.step(40)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    assert [c.name for c in both(lambda s: s.remove_collider(0))] == ["ball", "ball"]
    assert [c.name for c in gpu.colliders] == ["block"]
    for sim in (cpu, gpu):
        sim.step(80)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    assert gpu.time == pytest.approx(cpu.time) and cpu.time == pytest.approx(0.2)
    assert float(np.min(cpu.colliders[0].signed_distance(cpu.positions))) < 0.006  # on the box


def _gripper_script(sim, short=False):
    """A corner grasped, swung and turned over single steps and a run of steps, teleported, a
    box of vertices grasped beside it, then both let go; the positions after each part
    (``short``: fewer steps of each, for ``vbd``'s 120 sweeps on the simulator)."""
    out = []
    corner = sim.grasp("hand", (0.15, 0.15, 0.0), 0.03)
    for k in range(2 if short else 6):
        turn = (np.cos(0.05 * k), 0.0, 0.0, np.sin(0.05 * k))
        sim.set_gripper_pose("hand", (0.15 + 0.004 * k, 0.15, 0.01 + 0.01 * k), turn)
        sim.step()
    out.append(sim.positions.copy())
    sim.set_gripper_pose("hand", (0.2, 0.17, 0.06))
    sim.step(2 if short else 4)  # reached over the first, at rest over the others
    out.append(sim.positions.copy())
    sim.set_gripper_pose("hand", (0.18, 0.12, 0.05), teleport=True)
    edge = sim.grasp_box("edge", (-0.03, 0.07, -0.1), (0.08, 0.13, 0.1))
    sim.step(1 if short else 3)
    out.append(sim.positions.copy())
    sim.set_gripper_pose("edge", (0.05, 0.12, 0.02))
    sim.step()
    wrench = sim.gripper_wrench("hand")
    sim.release("hand")
    sim.step(1 if short else 5)
    out.append(sim.positions.copy())
    return corner, edge, out, wrench


@pytest.mark.parametrize("integrator", ["symplectic_euler", "vbd"])
def test_grippers_on_the_device_are_the_cpus(integrator):
    """Grasp by radius and by box, moves over one step and over a run of steps, a teleport and a
    release on the device give the CPU's cloth to rounding (float64, symplectic Euler: < 1e-12 m)
    and vbd's nearly converged (30 sweeps, no tolerance, one substep: < 1e-9 m, the two colour
    orders' difference), the same held vertices, poses and (vbd, whose springs are evaluated at
    the step's end on both) wrench."""
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0)])
    if integrator == "vbd":
        opts = dict(iterations=30, tolerance=0.0, substeps=1)
        kw = dict(integrator="vbd", dt=1 / 120)
        cpu = Simulator(m, integrator_options=dict(opts, grid=False), **kw)
        gpu = Simulator(m, integrator_options=opts, device="cuda", precision="float64", **kw)
    else:
        kw = dict(integrator="symplectic_euler", dt=1e-3)
        cpu, gpu = Simulator(m, **kw), Simulator(m, device="cuda", precision="float64", **kw)
    short = integrator == "vbd"
    c_corner, c_edge, c_out, c_wrench = _gripper_script(cpu, short)
    g_corner, g_edge, g_out, g_wrench = _gripper_script(gpu, short)
    assert c_corner.tolist() == g_corner.tolist() == [15]
    assert c_edge.tolist() == g_edge.tolist() and len(c_edge) >= 2
    for a, b in zip(c_out, g_out):  # (vbd: 1.2e-10 m at 30 sweeps, 1.7e-17 at 60)
        assert np.max(np.abs(a - b)) < (1e-9 if integrator == "vbd" else 1e-12)
    assert np.max(np.abs(c_out[0] - m.positions)) > 0.005  # the gripper did move the cloth
    if integrator == "vbd":
        for a, b in zip(c_wrench, g_wrench):
            assert np.allclose(a, b, rtol=1e-6, atol=1e-9)
    assert gpu.grippers.keys() == {"edge"} and cpu.grippers.keys() == {"edge"}
    p, q = gpu.gripper_pose("edge")
    assert np.allclose(p, (0.05, 0.12, 0.02)) and np.allclose(q, (1, 0, 0, 0))
    assert np.allclose(gpu.positions[c_edge], cpu.positions[c_edge], atol=1e-12)


def test_device_grippers_refuse_bad_input_and_leave_the_cloth_alone():
    """A name in use, an unknown gripper, no vertex in reach, a bad radius, a box the wrong way
    round, a bad pose and a robot's link are refused naming them, with the cloth, the grippers
    and the held vertices as they were; reset lets every gripper go; a state put back keeps the
    held vertices with their gripper."""
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0)])
    sim = Simulator(m, integrator="symplectic_euler", dt=1e-3, device="cuda", precision="float64")
    sim.grasp("hand", (0.15, 0.15, 0.0), 0.01)
    sim.step(5)
    x = sim.positions.copy()
    bad = [
        (lambda: sim.grasp("hand", (0.0, 0.15, 0.0), 0.01), r"gripper 'hand' already holds 1"),
        (lambda: sim.grasp("other", (0.15, 0.15, 0.0), 0.01), r"no free particle within radius"),
        (lambda: sim.grasp("other", (0.0, 0.15, 0.0), -1.0), r"radius must be a finite number"),
        (lambda: sim.grasp("other", (0.0, 0.15, 0.0), 0.01, link=("arm", "hand")), r"robot"),
        (lambda: sim.grasp_box("other", (1, 0, 0), (0, 1, 1)), r"box: min \[1.0, 0.0, 0.0\]"),
        (lambda: sim.set_gripper_pose("foot", (0, 0, 0)), r"unknown gripper 'foot'; grippers"),
        (lambda: sim.set_gripper_pose("hand", (0, np.nan, 0)), r"position must be 3 finite"),
        (lambda: sim.release("foot"), r"unknown gripper 'foot'"),
    ]  # fmt: skip
    for call, match in bad:
        with pytest.raises(ValueError, match=match):
            call()
        assert np.array_equal(sim.positions, x) and list(sim.grippers) == ["hand"]
    saved = sim.save_state()
    sim.set_gripper_pose("hand", (0.1, 0.1, 0.1), teleport=True)
    sim.restore_state(saved)  # the held vertex stays with its gripper, at (0.1, 0.1, 0.1)
    assert (
        np.allclose(sim.positions[15], (0.1, 0.1, 0.1)) and sim.velocities[15].tolist() == [0] * 3
    )
    sim.reset()
    assert sim.grippers == {} and np.array_equal(sim.positions, m.positions)
    sim.step(20)  # the vertex once held falls with the rest
    assert sim.positions[15, 2] < -1e-4


def test_a_scripted_gripper_on_the_device_is_the_cpus():
    """A scene's script (:class:`cloth_sim.motion.Motion`) moves a gripper before each step on
    the device as on the CPU: a corner lifted and turned over 0.03 s, then held; the CPU's cloth
    to rounding (float64, symplectic Euler) and the gripper at the script's last pose."""
    from cloth_sim.motion import Motion

    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0)])
    q1 = np.array([np.cos(0.2), np.sin(0.2), 0.0, 0.0])
    frames = [(0.0, np.array([0.15, 0.15, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]))]
    frames.append((0.03, np.array([0.15, 0.12, 0.05]), q1))
    kw = dict(integrator="symplectic_euler", dt=1e-3)
    sims = [Simulator(m, **kw), Simulator(m, device="cuda", precision="float64", **kw)]
    for sim in sims:
        sim.grasp("hand", (0.15, 0.15, 0.0), 0.01)
        sim.motion = Motion(grippers={"hand": frames})
        sim.step(50)
    cpu, gpu = sims
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-12
    p, q = gpu.gripper_pose("hand")
    assert np.allclose(p, (0.15, 0.12, 0.05)) and np.allclose(q, q1)
    assert np.allclose(gpu.positions[15], (0.15, 0.12, 0.05))


def test_a_gripper_holds_through_a_collider_added_and_a_change_of_method():
    """Adding a collider and switching the method make the device's worlds again: a gripper's
    vertices stay held there (they had gone back into the solve while the gripper still listed
    them), and a later move carries them."""
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0)])
    sim = Simulator(m, integrator="symplectic_euler", dt=1e-3, device="cuda", precision="float64")
    held = sim.grasp("hand", (0.15, 0.15, 0.0), 0.01)
    sim.step(10)
    sim.add_collider(Plane((0.0, 0.0, 1.0), -0.5, name="floor"))
    sim.set_integrator("vbd")
    sim.step(5)
    assert np.allclose(sim.positions[held], (0.15, 0.15, 0.0))  # held, not fallen
    sim.set_gripper_pose("hand", (0.15, 0.15, 0.05))
    sim.step()
    assert np.allclose(sim.positions[held], (0.15, 0.15, 0.05))


def test_vertices_held_and_dragged_one_a_world_are_the_cpus():
    """``hold_pairs``, ``drag`` and ``release_pairs`` (a vertex a row, each in its own world: a
    vector env's pickers) give the CPU batch's cloth to rounding (symplectic Euler, float64): the
    dragged vertices end at their ends, and let go they fall; rows that do not pair up are
    refused before anything changes."""
    m = sheet()
    kw = dict(worlds=2, integrator="symplectic_euler", dt=1e-3)
    cpu = BatchSimulator(m, **kw)
    gpu = BatchSimulator(m, device="cuda", precision="float64", launch="stages", **kw)
    worlds, idx = [0, 1], [m.index(3, 3), m.index(2, 1)]
    ends = [[0.2, 0.2, 0.05], [0.1, 0.0, 0.08]]
    for b in (cpu, gpu):
        b.hold_pairs(worlds, idx)
        b.drag(worlds, idx, ends, 5)
        b.step(3)  # held where the drag left them
    xc, xg = cpu.positions_host(), gpu.positions_host()
    assert np.max(np.abs(xg - xc)) < 1e-14
    assert np.allclose(xg[[0, 1], idx], ends, atol=1e-15)
    assert np.max(np.abs(xg[0] - xg[1])) > 0.02
    for b in (cpu, gpu):
        b.release_pairs(worlds, idx)
        b.step(10)
    xc, xg = cpu.positions_host(), gpu.positions_host()
    assert np.max(np.abs(xg - xc)) < 1e-14
    assert xg[1, idx[1], 2] < 0.08 - 1e-4
    with pytest.raises(ValueError, match="one vertex a row, got 2 worlds and 1 indices"):
        gpu.hold_pairs([0, 1], [3])


def test_the_nearest_free_vertex_is_the_cpus():
    """``nearest_free`` (a vector env's grasp): a world's vertex nearest a point among those the
    solve moves, pins and held vertices passed over, −1 where none is left; the same
    answers and positions on the device as on the CPU batch."""
    m = sheet()
    kw = dict(worlds=3, integrator="symplectic_euler", dt=1e-3)
    cpu = BatchSimulator(m, **kw)
    gpu = BatchSimulator(m, device="cuda", precision="float64", **kw)
    rest = np.flatnonzero(~m.pinned)
    for b in (cpu, gpu):
        b.step(5)
        b.hold_pairs([1], [m.index(1, 1)])
        b.hold_pairs(np.full(len(rest), 2), rest)
    worlds = [0, 1, 1, 2]
    near = cpu.positions_host()[0, m.index(1, 1)] + (0.002, 0.0, 0.001)
    points = [near, near, m.positions[0], near]
    ci, cx = cpu.nearest_free(worlds, points)
    gi, gx = gpu.nearest_free(worlds, points)
    assert ci.tolist() == gi.tolist()
    assert ci[0] == m.index(1, 1) and ci[1] != m.index(1, 1)  # held in world 1, not in 0
    assert ci[2] not in (0, 3)  # the pins, at the point asked, are passed over
    assert ci[3] == -1  # every vertex of world 2 held or pinned
    assert np.max(np.abs(cx - gx)) < 1e-15
    assert np.allclose(cx[:3], cpu.positions_host()[worlds[:3], ci[:3]])


def test_mean_distances_are_measured_on_the_device_as_on_the_cpu():
    """``mean_distance`` (a vector env's metric): each world's mean distance between paired
    vertices, or from where the world was last set (``write``, ``reset``), the CPU batch's to
    rounding; 0 from the state just written."""
    m = sheet()
    kw = dict(worlds=2, integrator="symplectic_euler", dt=1e-3)
    cpu = BatchSimulator(m, **kw)
    gpu = BatchSimulator(m, device="cuda", precision="float64", **kw)
    a, b = [0, 1, 4, 5], [3, 2, 7, 6]  # the left columns and their mirror images
    start = np.stack([m.positions, m.positions + (0.0, 0.0, 0.1)])
    got = {}
    for name, s in (("cpu", cpu), ("gpu", gpu)):
        s.write([0, 1], start, np.zeros_like(start))
        zero = s.mean_distance(b, b, reference=True)
        s.step(20)
        got[name] = (zero, s.mean_distance(a, b), s.mean_distance(b, b, reference=True))
    assert got["gpu"][0].tolist() == [0.0, 0.0]
    for c, g in zip(got["cpu"], got["gpu"]):
        assert np.allclose(c, g, rtol=0, atol=1e-15)
    flat = np.mean(np.linalg.norm(m.positions[a] - m.positions[b], axis=1))
    assert got["gpu"][1][0] == pytest.approx(flat, rel=0.2) and got["gpu"][2][0] > 1e-4
    gpu.reset([1])
    assert gpu.mean_distance(b, b, reference=True)[1] == 0.0
