"""Provot's strain limit after symplectic Euler on the CUDA device: closed forms on a chain, the
CPU's stretch on a sheet, the same bits in every launch and whatever the other worlds do, held
vertices as the attachments' pins, and what is refused. Tiny cloths and few steps: on numba-cuda's
simulator each thread is a Python thread."""

import numpy as np
import pytest

from cloth_sim import BatchSimulator, ClothModel, Simulator

L = 0.1
TAU = 0.1


def chain(stretch=1.5, pinned=(0,)):
    """Three particles in a line along x, springs of rest length ``L`` stretched ``stretch``
    times, no stiffness (the limit alone moves them)."""
    x = np.array([[0.0, 0, 0], [stretch * L, 0, 0], [2 * stretch * L, 0, 0]])
    return ClothModel.from_springs(
        x, 0.01, [(0, 1), (1, 2)], stiffness=0.0, rest_lengths=L, pinned=list(pinned)
    )


def pair(stretch=1.5):
    x = np.array([[0.0, 0, 0], [stretch * L, 0, 0]])
    return ClothModel.from_springs(x, 0.01, [(0, 1)], stiffness=0.0, rest_lengths=L)


def both(model, **kw):
    kw = dict(integrator="symplectic_euler", dt=1e-3, gravity=(0, 0, 0), strain_limit=TAU, **kw)
    return Simulator(model, **kw), Simulator(model, device="cuda", precision="float64", **kw)


def test_a_chain_is_shortened_to_the_limit_as_the_cpu_shortens_it():
    """Long-range attachments put each particle at ``(1 + τ)`` times its rest distance from the
    pin: ``x = 0.11, 0.22`` exactly, at rest (the step moved nothing, so no velocity follows).
    Without them, Provot's passes converge there (the CPU visits the springs outward from the pin,
    the device a colour at a time: here the same order, so the same bits)."""
    cpu, gpu = both(chain())
    cpu.step()
    gpu.step()
    assert gpu.positions[:, 0] == pytest.approx([0.0, 1.1 * L, 2.2 * L], abs=1e-15)
    assert np.array_equal(gpu.velocities, np.zeros((3, 3)))
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    cpu, gpu = both(chain(), strain_limit_long_range=False, strain_limit_passes=4)
    cpu.step()
    gpu.step()
    # each pass puts the pinned spring at its limit and halves the free end's excess over it:
    # 0.04 m after the first, 0.005 after the fourth
    assert gpu.positions[2, 0] == pytest.approx(2.2 * L + 0.04 / 2**3, abs=1e-12)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15


def test_a_free_pair_moves_equally_and_its_velocities_follow_no_more_than_the_step():
    """Both ends move half the excess (the centre stays); an end that moved outward over the step
    gets back the velocity of its correction, at most its own motion over ``h``."""
    cpu, gpu = both(pair())
    for s in (cpu, gpu):
        s.velocities = [[-1.0, 0, 0], [0.0, 0, 0]]  # the first end moves 1 mm out in the step
        s.step()
    x, v = gpu.positions, gpu.velocities
    assert x[1, 0] - x[0, 0] == pytest.approx(1.1 * L, abs=1e-15)
    # the spring was 0.151 m long after the step; each end moved 0.0205 m
    assert (x[0, 0] + x[1, 0]) / 2 == pytest.approx((-1e-3 + 1.5 * L) / 2, abs=1e-15)
    # the first end's correction (20.5 mm) is cut to its motion (1 mm): v = -1 + 1 m/s; the
    # second did not move over the step: its velocity stays
    assert v[0, 0] == pytest.approx(0.0, abs=1e-12) and v[1, 0] == 0.0
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    assert np.max(np.abs(gpu.velocities - cpu.velocities)) < 1e-12


def sheet(n=4):
    return ClothModel.grid(
        n, n, 0.05, 0.01, stiffness=20.0, damping=0.05, pinned=[(0, 0), (0, n - 1)]
    )


def test_a_hanging_sheet_keeps_the_cpus_stretch():
    """Soft springs stretch 40 % without the limit; with it the worst limited spring stays at ``τ``
    plus the passes' tolerance on the device as on the CPU, and the cloth is the CPU's to 0.2 mm
    (the passes visit the springs in another order: a colour at a time, not outward from the
    pins) where the limit moved it centimetres."""
    m = sheet()
    kw = dict(integrator="symplectic_euler", dt=2e-3)
    cpu = Simulator(m, strain_limit=TAU, **kw)
    free = Simulator(m, **kw)
    gpu = Simulator(m, strain_limit=TAU, device="cuda", precision="float64", launch="grid", **kw)
    for s in (cpu, free, gpu):
        s.step(60)
    assert free.max_strain() > 0.3
    for s in (cpu, gpu):
        assert np.max(s.strains(limited_only=True)) < TAU + 1.001e-4
    assert np.max(np.abs(free.positions - cpu.positions)) > 0.01
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 2e-4
    assert gpu.active_stages == ("strain_limit",)


def test_every_launch_gives_the_same_bits_whatever_the_other_worlds_do():
    """A block a world, the cooperative grid and a launch a stage: each world's passes stop at its
    own last correction, so the same positions in all three, and a world's are those it has
    alone (two winds: the limit acts in both worlds, in different passes)."""
    m = sheet(3)
    winds = [(3.0, 1.0, 5.0), (-1.0, -4.0, 6.0)]

    def run(launch, worlds=2, tau=TAU):
        b = BatchSimulator(
            m,
            worlds=worlds,
            integrator="symplectic_euler",
            dt=4e-3,
            device="cuda",
            precision="float64",
            launch=launch,
            strain_limit=tau,
        )
        b.set(None, wind=winds[:worlds])
        b.step(4)
        return b.positions_host()

    got = {launch: run(launch) for launch in ("blocks", "grid", "stages")}
    assert np.array_equal(got["blocks"], got["stages"])
    assert np.array_equal(got["grid"], got["stages"])
    assert np.array_equal(got["stages"][0], run("stages", worlds=1)[0])
    free = run("stages", tau=None)
    assert np.all(np.max(np.abs(got["stages"] - free), axis=(1, 2)) > 1e-3)  # it acted in both


def test_held_vertices_are_the_attachments_pins():
    """A corner held up and folded over in one world: its attachments are made for the new pin
    (as the CPU's, whose grippers pin what they hold), the stretch stays at the limit, and the
    cloth is the CPU batch's to 5 µm (1.2e-7 m measured after 15 steps, 6e-7 after 40: the
    passes' orders differ; the first step takes all 20 passes, later ones 2 to 10); the other
    world hangs as before. (A pose farther
    from the pins than the limit lets the cloth reach leaves every pass correcting, and the two
    orders then end millimetres apart.)"""
    m = sheet()
    corner = [m.index(3, 3)]
    up = [[0.05, 0.1, 0.08]]
    kw = dict(worlds=2, integrator="symplectic_euler", dt=2e-3, strain_limit=TAU)
    cpu = BatchSimulator(m, **kw)
    gpu = BatchSimulator(m, device="cuda", precision="float64", launch="grid", **kw)
    for b in (cpu, gpu):
        b.hold([1], corner, up)
        b.step(15)
    xc, xg = cpu.positions_host(), gpu.positions_host()
    assert np.allclose(xg[1, corner[0]], up[0])
    assert np.max(np.abs(xg - xc)) < 5e-6
    assert np.max(np.abs(xg[1] - xg[0])) > 0.05
    springs, rest = m.springs[m.strain_limited], m.rest_lengths[m.strain_limited]
    length = np.linalg.norm(xg[:, springs[:, 1]] - xg[:, springs[:, 0]], axis=2)
    assert np.max(length / rest - 1.0) < TAU + 1.001e-4


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (
            dict(strain_limit=TAU, strain_limit_method="projection"),
            r"strain_limit_method: not on the cuda device yet \(the projection is not",
        ),
        (dict(strain_limit=-0.1), r"strain_limit"),
    ],
)
def test_what_the_device_limit_does_not_run_is_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Simulator(sheet(3), device="cuda", **kwargs)


def test_the_limit_turned_on_and_off_live():
    """As on the CPU: ``sim.strain_limit = τ`` acts from the next step, ``None`` stops it; the
    projection method is refused while a limit is on."""
    m = sheet(3)
    gpu = Simulator(m, integrator="symplectic_euler", dt=4e-3, device="cuda", precision="float64")
    assert gpu.strain_limit is None and gpu.active_stages == ()
    gpu.strain_limit = TAU
    gpu.step(10)
    assert gpu.max_strain() < TAU + 1.001e-4 and gpu.active_stages == ("strain_limit",)
    gpu.strain_limit = None
    gpu.step(10)
    assert gpu.max_strain() > TAU + 0.01
    with pytest.raises(ValueError, match=r"strain_limit_method: not on the cuda device"):
        gpu.strain_limit_method = "projection"
        gpu.strain_limit = TAU
    vbd = Simulator(m, integrator="vbd", dt=1 / 60, device="cuda", precision="float64")
    vbd.strain_limit = TAU  # (after each of its substeps)
    assert vbd.strain_limit == TAU and vbd.active_stages == ("strain_limit",)


def test_vbd_substeps_are_limited_as_the_cpus():
    """After each ``vbd`` substep (backward Euler's then, as on the CPU), from the substep's
    start: the CPU's general sweep to 1e-11 m (30 sweeps a substep, two substeps a step) where
    the limit moved the cloth 8.5 mm and holds the worst spring at ``τ`` (the free cloth's:
    0.23); the cooperative grid and a launch a stage give the same bits (a block a world too:
    77 s on the simulator, checked by hand)."""
    m = sheet()
    opts = dict(iterations=30, tolerance=0.0, substeps=2)
    kw = dict(integrator="vbd", dt=1 / 30)
    cpu = Simulator(m, strain_limit=TAU, integrator_options=dict(opts, grid=False), **kw)
    free = Simulator(m, integrator_options=dict(opts, grid=False), **kw)
    got = {}
    for launch in ("grid", "stages"):
        gpu = Simulator(
            m,
            strain_limit=TAU,
            integrator_options=opts,
            device="cuda",
            precision="float64",
            launch=launch,
            **kw,
        )
        gpu.step(3)
        got[launch] = gpu.positions
    cpu.step(3)
    free.step(3)
    assert np.array_equal(got["grid"], got["stages"])
    assert np.max(np.abs(got["grid"] - cpu.positions)) < 5e-11
    assert np.max(np.abs(free.positions - cpu.positions)) > 0.005
    worst = np.max(gpu.strains(limited_only=True))  # (0.100107 on both)
    assert worst == pytest.approx(np.max(cpu.strains(limited_only=True)), abs=1e-9)
    assert worst < TAU + 2e-4 and np.max(free.strains(limited_only=True)) > TAU + 0.1


def test_a_grippers_wrench_takes_the_limits_pull_as_the_cpus():
    """A cloth hanging from a gripper at a corner (no other pin), lifted 1 cm, the limit holding
    its stretch: the wrench is the springs' pull where the CPU's ``vbd`` reads it (its last
    substep solved, before the limit's last correction) plus the force the limit's corrections
    put on the held vertex over the step (each vertex's momentum change on its nearest pin, the
    CPU's ``StrainLimit.reaction``): the CPU's to 1e-9 N with the cloth the CPU's to 1e-11 m,
    where the springs at the step's end alone are a third off. (Lifted 5 cm in one step under a
    pin elsewhere, the limit's large first corrections take the two orders of its passes 1e-4 m
    apart.)"""
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=20.0, damping=0.05, pinned=[])
    opts = dict(iterations=30, tolerance=0.0, substeps=2)
    kw = dict(integrator="vbd", dt=1 / 60, strain_limit=TAU)
    cpu = Simulator(m, integrator_options=dict(opts, grid=False), **kw)
    gpu = Simulator(
        m, integrator_options=opts, device="cuda", precision="float64", launch="stages", **kw
    )
    corner = m.positions[m.index(0, 0)]
    wrenches = []
    for s in (cpu, gpu):
        s.grasp("hand", corner, 1e-6)
        s.set_gripper_pose("hand", corner + (0.0, 0.0, 0.01))
        s.step(4)
        wrenches.append(s.gripper_wrench("hand"))
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-11
    assert np.max(cpu.strains(limited_only=True)) == pytest.approx(TAU, abs=1e-6)
    (fc, tc), (fg, tg) = wrenches
    assert np.allclose(fg, fc, rtol=0, atol=1e-9) and np.allclose(tg, tc, rtol=0, atol=1e-9)
    x, v = gpu.positions, gpu.velocities
    springs = np.zeros_like(x)
    gpu.forces.spring_term.add_force(x, v, springs)
    assert np.linalg.norm(fg - springs[m.index(0, 0)]) > 0.25 * np.linalg.norm(fg)


def test_a_batch_takes_the_limits_options_as_the_cpu_batch():
    """``BatchSimulator(..., device="cuda")`` takes the strain limit's options the CPU batch
    takes: long-range attachments off runs Provot's passes alone (the chain's passes then leave
    the free end's excess, as the single simulator's do), and the projection is refused naming
    it."""
    kw = dict(worlds=2, integrator="symplectic_euler", dt=1e-3, gravity=(0, 0, 0))
    model = chain()
    gpu = BatchSimulator(
        model,
        device="cuda",
        precision="float64",
        strain_limit=TAU,
        strain_limit_passes=4,
        strain_limit_long_range=False,
        **kw,
    )
    gpu.step()
    assert gpu.positions_host()[1, 2, 0] == pytest.approx(2.2 * L + 0.04 / 2**3, abs=1e-12)
    with pytest.raises(ValueError, match=r"strain_limit_method: not on the cuda device yet"):
        BatchSimulator(
            model, device="cuda", strain_limit=TAU, strain_limit_method="projection", **kw
        )
