"""The device seam (cloth_sim.backends): a device is its own axis beside the method; a device that
cannot run here is refused with what is missing; a batch of worlds on the CPU has the GPU batch's
names and each world's parameters."""

import numpy as np
import pytest

from cloth_sim import BatchSimulator, ClothModel, Simulator, backends
from cloth_sim.contact.colliders import Sphere


def sheet():
    return ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0), (0, 3)])


def test_the_cpu_is_the_default_device():
    sim = Simulator(sheet(), device="cpu")
    assert sim.device == "cpu" and type(sim) is Simulator
    assert Simulator(sheet()).device == "cpu"


@pytest.mark.parametrize("device", ["gpu", "CUDA", "", 3])
def test_an_unknown_device_is_named(device):
    with pytest.raises(ValueError, match=r"device must be one of cpu, cuda, got "):
        Simulator(sheet(), device=device)
    with pytest.raises(ValueError, match=r"device must be one of cpu, cuda, got "):
        BatchSimulator(sheet(), device=device)


def test_cuda_runs_or_says_what_is_missing():
    why = backends.problem("cuda")
    if why is None:  # a machine with a GPU (or the simulator): the device's own simulator
        assert Simulator(sheet(), device="cuda").device == "cuda"
        return
    assert "numba-cuda" in why or "CUDA device" in why
    with pytest.raises(ValueError) as err:
        Simulator(sheet(), integrator="vbd", device="cuda")
    assert str(err.value) == why
    with pytest.raises(ValueError) as err:
        BatchSimulator(sheet(), worlds=4, device="cuda")
    assert str(err.value) == why


def test_without_numba_cuda_the_error_says_how_to_install_it(monkeypatch):
    real = backends.importlib.util.find_spec
    monkeypatch.setattr(
        backends.importlib.util,
        "find_spec",
        lambda name: None if name == "numba_cuda" else real(name),
    )
    with pytest.raises(ValueError, match=r"needs numba-cuda, which is not installed: `make gpu`"):
        Simulator(sheet(), device="cuda")


def test_a_method_the_device_lacks_is_named():
    backends.check_method("rk4", "cpu")
    backends.check_method("vbd", "cuda")
    with pytest.raises(
        ValueError,
        match=r"integrator 'rk4' has no cuda backend; on cuda: "
        r"symplectic_euler, vbd",
    ):
        backends.check_method("rk4", "cuda")


def test_a_cpu_batch_is_its_worlds_each_with_its_parameters():
    m = sheet()
    batch = BatchSimulator(m, worlds=3, integrator="symplectic_euler", dt=1e-3)
    batch.set([1], wind=(0.0, 0.0, 1.0), drag=0.02)
    batch.set([2], stiffness={"structural": 50.0}, gravity=(0.0, -9.81, 0.0))
    batch.step(20)
    alone = [Simulator(m, integrator="symplectic_euler", dt=1e-3) for _ in range(3)]
    alone[1].wind, alone[1].drag = (0.0, 0.0, 1.0), 0.02
    alone[2].set_stiffness("structural", 50.0)
    alone[2].gravity = (0.0, -9.81, 0.0)
    for s in alone:
        s.step(20)
    x = batch.positions_host()
    assert x.shape == (3, m.n_particles, 3)
    for w in range(3):
        assert np.array_equal(x[w], alone[w].positions)
    batch.reset([0])
    assert np.array_equal(batch.positions[0], m.positions)
    assert np.array_equal(batch.positions[1], x[1])
    assert batch.time.tolist() == pytest.approx([0.0, 0.02, 0.02])


def test_batch_arguments_are_checked():
    m = sheet()
    with pytest.raises(ValueError, match=r"worlds must be an integer in \[1, 1000000\]"):
        BatchSimulator(m, worlds=0)
    with pytest.raises(ValueError, match=r"worlds=3 but 2 models were given"):
        BatchSimulator([m, m], worlds=3)
    batch = BatchSimulator(m, worlds=2)
    with pytest.raises(ValueError, match=r"worlds: indices must lie in \[0, 1\]"):
        batch.reset([2])


def test_a_cpu_batch_holds_and_releases_vertices():
    m = sheet()
    corner = m.index(3, 3)
    batch = BatchSimulator(m, worlds=2, integrator="symplectic_euler", dt=1e-3)
    batch.hold([1], [corner], [[0.15, 0.15, 0.05]])
    assert batch.held(1).tolist() == [0, 3, corner] and batch.held(0).tolist() == [0, 3]
    batch.step(20)
    pinned = ClothModel.grid(
        4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0), (0, 3), (3, 3)]
    )
    ref = Simulator(pinned, integrator="symplectic_euler", dt=1e-3)
    ref.move_pins([[0.15, 0.15, 0.05]], indices=[corner])
    ref.step(20)
    assert np.max(np.abs(batch.positions[1] - ref.positions)) < 1e-12
    batch.release([1])
    assert batch.held(1).tolist() == [0, 3]
    batch.step(20)
    assert batch.positions[1, corner, 2] < 0.05 - 1e-4


def test_a_cpu_batch_puts_one_worlds_collider_elsewhere():
    """``set(worlds, colliders={i: (position, orientation)})`` on the cpu is each named world's
    ``set_collider_pose(i, ..., teleport=True)``: the other worlds, and the shapes the caller
    gave, keep theirs (each world has its own copy of the shapes)."""
    sphere = Sphere(center=(0.07, 0.07, -0.05), radius=0.06, friction=0.3)
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, origin=(0, 0, 0.008))
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=0.005, colliders=[sphere])
    b = BatchSimulator(m, worlds=2, **kw)
    moved = ((0.02, 0.1, -0.04), (1.0, 0.0, 0.0, 0.0))
    b.set([1], colliders={0: moved})
    assert np.allclose(sphere.position, (0.07, 0.07, -0.05))  # the caller's shape: not moved
    assert np.allclose(b.sims[0].colliders[0].position, (0.07, 0.07, -0.05))
    b.step(60)
    still, there = Simulator(m, **kw), Simulator(m, **kw)
    there.set_collider_pose(0, *moved, teleport=True)
    still.step(60)
    there.step(60)
    x = b.positions_host()
    assert np.array_equal(x[0], still.positions) and np.array_equal(x[1], there.positions)
    assert not np.array_equal(x[0], x[1])


def test_a_cpu_batch_set_checks_everything_before_it_changes_a_world():
    """``set`` on the cpu is atomic, as on cuda: a bad value for any world named (here the last
    one's collider index, after good values for every world) raises naming it, and no world's
    gravity, stiffness or collider changed; the good call then changes exactly those."""
    sphere = Sphere(center=(0.07, 0.07, -0.05), radius=0.06, friction=0.3)
    m = ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, origin=(0, 0, 0.008))
    b = BatchSimulator(m, worlds=3, integrator="symplectic_euler", dt=1e-3, colliders=[sphere])
    before = [(s.gravity, s.stiffness("structural"), s.colliders[0].position) for s in b.sims]
    good = dict(
        gravity=[(0.0, 0.0, -1.0), (0.0, 0.0, -2.0), (0.0, 0.0, -3.0)],
        stiffness={"structural": 50.0},
    )
    bad = [
        (dict(colliders={1: ((0, 0, 0), (1, 0, 0, 0))}), r"colliders: index 1 must lie in \[0, "),
        (dict(colliders={0: ((0, 0, np.nan), (1, 0, 0, 0))}), r"colliders\[0\]: "),
        (dict(colliders={0: (0, 0, 0)}), r"colliders\[0\] must be \(position, orientation\)"),
        (dict(stiffness={"structural": 50.0, "warp": 1.0}), r"unknown spring family 'warp'"),
        (dict(damping={"shear": -1.0}), r"damping\.shear"),
        (dict(wind=[(0.0, 0.0, 1.0)] * 2), r"wind must be a finite 3-vector or one a world \(3,"),
        (dict(drag=-1.0), r"drag"),
        (dict(gravity=(0.0, 0.0, 1e4)), r"gravity"),
    ]  # fmt: skip
    for extra, match in bad:
        with pytest.raises(ValueError, match=match):
            b.set(None, **{**good, **extra})
        for s, (g, k, c) in zip(b.sims, before):
            assert np.array_equal(s.gravity, g) and np.array_equal(s.stiffness("structural"), k)
            assert np.array_equal(s.colliders[0].position, c)
    b.set(None, colliders={0: ((0.0, 0.1, -0.05), (1, 0, 0, 0))}, **good)
    assert [s.gravity[2] for s in b.sims] == [-1.0, -2.0, -3.0]
    assert all(np.all(s.stiffness("structural") == 50.0) for s in b.sims)
    assert all(np.allclose(s.colliders[0].position, (0.0, 0.1, -0.05)) for s in b.sims)
