"""Mesh colliders on the CUDA device, read from a distance grid baked at load
(:mod:`cloth_sim.contact.distance_grid`), against the CPU's exact mesh queries: the same cloth to
rounding where it lies on a face (the grid is exact there), within a fraction of a cell where it
drapes over an edge; per-world poses, and a mesh added between steps."""

import numpy as np
import pytest

from cloth_sim import BatchSimulator, ClothModel, Simulator
from cloth_sim.contact.colliders import Mesh
from cloth_sim.contact.distance_grid import grid_for
from cloth_sim.contact.triangle_meshes import box_triangles

TAU = 0.005


def slab(**pose):
    """A 0.4 × 0.4 × 0.04 m box as 12 triangles, turned about z, under the sheet below."""
    pose.setdefault("position", (0.07, 0.07, -0.03))
    pose.setdefault("orientation", (0.96, 0.0, 0.0, 0.28))
    return Mesh(box_triangles((0.2, 0.2, 0.02)), friction=0.3, name="slab", **pose)


def sheet(z):
    return ClothModel.grid(4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, origin=(0, 0, z))


@pytest.mark.parametrize("method", ["symplectic_euler", "vbd"])
def test_a_cloth_on_a_mesh_face_is_the_cpus(method):
    """A sheet falling onto a turned box given as a mesh, lying on its top face: the device's grid
    answers the face's plane there, so its cloth is the CPU's (exact mesh queries) to rounding,
    after symplectic Euler's contact stage (0 m after 80 steps) and inside ``vbd``'s iterations
    (20 sweeps, 1e-17 m), on the skin and never inside it."""
    mesh = slab()
    if method == "vbd":
        opts = dict(iterations=20, tolerance=0.0, substeps=1)
        kw = dict(integrator="vbd", dt=1 / 120, colliders=[mesh], thickness=TAU)
        m, steps = sheet(-0.0045), 2
        cpu = Simulator(m, integrator_options=dict(opts, grid=False), **kw)
        gpu = Simulator(m, integrator_options=opts, device="cuda", precision="float64", **kw)
    else:
        kw = dict(integrator="symplectic_euler", dt=1e-3, colliders=[mesh], thickness=TAU)
        m, steps = sheet(0.008), 80
        cpu = Simulator(m, **kw)
        gpu = Simulator(m, device="cuda", precision="float64", **kw)
    cpu.step(steps)
    gpu.step(steps)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    assert np.max(np.abs(cpu.positions - m.positions)) > 4e-4  # it fell
    assert float(np.min(mesh.signed_distance(gpu.positions))) == pytest.approx(TAU, abs=1e-12)


def test_a_cloth_over_a_mesh_edge_is_within_a_fraction_of_a_cell():
    """The sheet dropped across a narrow box's edge, sliding off it: near the edge the grid's
    interpolation is within a fraction of a cell of the exact distance (above it: the distance is
    convex there), so the device's cloth differs from the CPU's by at most half a cell (1.5 mm
    measured, cells of 3.1 mm) and keeps at least 0.9 of the thickness from the mesh (0.97)."""
    mesh = Mesh(box_triangles((0.05, 0.2, 0.02)), position=(0.0, 0.07, -0.03), friction=0.3)
    cell = grid_for(mesh.mesh, TAU).cell
    m = sheet(-0.004)
    kw = dict(integrator="symplectic_euler", dt=1e-3, colliders=[mesh], thickness=TAU)
    cpu, gpu = Simulator(m, **kw), Simulator(m, device="cuda", precision="float64", **kw)
    apart, nearest = 0.0, np.inf
    for _ in range(6):
        cpu.step(50)
        gpu.step(50)
        apart = max(apart, float(np.max(np.abs(gpu.positions - cpu.positions))))
        nearest = min(nearest, float(np.min(mesh.signed_distance(gpu.positions))))
    assert 0.0 < apart < 0.5 * cell
    assert nearest > 0.9 * TAU
    assert float(np.min(gpu.positions[:, 2])) < -0.1  # off the edge


def test_each_world_has_its_own_mesh_pose_and_a_mesh_added_between_steps():
    """A batch of two worlds, the slab put elsewhere in one (``set(colliders=...)``): each world is
    the CPU's cloth with the slab teleported there, to rounding; a mesh added to a running
    simulator (``add_collider``) is the CPU's added mesh from the next step."""
    m = sheet(0.008)
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=TAU)
    batch = BatchSimulator(
        m, worlds=2, colliders=[slab()], device="cuda", precision="float64", **kw
    )
    moved = ((0.07, 0.07, -0.04), (1.0, 0.0, 0.0, 0.0))
    batch.set([1], colliders={0: moved})
    still, there = Simulator(m, colliders=[slab()], **kw), Simulator(m, colliders=[slab()], **kw)
    there.set_collider_pose(0, *moved, teleport=True)
    for sim in (batch, still, there):
        sim.step(80)
    x = batch.positions_host()
    assert np.max(np.abs(x[0] - still.positions)) < 1e-15
    assert np.max(np.abs(x[1] - there.positions)) < 1e-15
    assert np.max(np.abs(x[1] - x[0])) > 5e-3  # lying 1 cm lower
    cpu, gpu = Simulator(m, **kw), Simulator(m, device="cuda", precision="float64", **kw)
    for sim in (cpu, gpu):
        sim.step(20)
        assert sim.add_collider(slab()) == 0
        sim.step(60)
    assert np.max(np.abs(gpu.positions - cpu.positions)) < 1e-15
    assert float(np.min(cpu.colliders[0].signed_distance(cpu.positions))) < 0.006  # on it
