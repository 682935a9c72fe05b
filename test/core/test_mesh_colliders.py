"""Triangle-mesh colliders and the cylinder: distances against closed forms (a box as 12
triangles against the analytic box, which it is), Coulomb's law on an inclined mesh, no tunnelling
through a zero-thickness mesh plate at any speed, a cloth on a mesh at the contact distance as on
the primitive, and what the depth camera sees."""

import math
from pathlib import Path

import numpy as np
import pytest

from cloth_sim import ClothModel, Simulator, colliders, integrators
from cloth_sim.contact.triangle_meshes import box_triangles
from cloth_sim.sensors import DepthCamera

G = 9.81
H = 0.005


def quad(size):
    """A square plate of zero thickness in its own xy plane (2 triangles)."""
    s = size / 2
    return np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]]), np.array(
        [[0, 1, 2], [0, 2, 3]]
    )


def test_a_closed_box_mesh_is_the_box_signed_distance_from_every_point():
    """A closed mesh is a solid: its distance is the box's signed distance (negative inside), at
    any pose, whether its corners are shared, each triangle has its own (as an STL file has them),
    or its faces turn inwards (the file's winding reversed)."""
    half = (0.2, 0.15, 0.1)
    q = np.array([0.9, 0.1, -0.3, 0.2])
    q /= np.linalg.norm(q)
    box = colliders.Box(center=(0.1, 0.2, 0.3), half_extents=half, orientation=q)
    pts = np.random.default_rng(0).uniform(-0.4, 0.7, (3000, 3))
    db = box.signed_distance(pts)
    assert (db < 0).sum() > 50 and (db > 0).sum() > 50
    v, f = box_triangles(half)
    unwelded = (v[f].reshape(-1, 3), np.arange(3 * len(f)).reshape(-1, 3))
    for source in ((v, f), unwelded, (v, f[:, ::-1])):
        mesh = colliders.Mesh(source, position=(0.1, 0.2, 0.3), orientation=q)
        assert mesh.mesh.closed
        np.testing.assert_allclose(mesh.signed_distance(pts), db, atol=1e-12)


def test_an_open_mesh_is_two_sided():
    """The box without its top (two triangles removed) is open: both sides of every triangle are
    surfaces, so its distance is unsigned, the distance to the nearest remaining triangle."""
    half = (0.2, 0.15, 0.1)
    v, f = box_triangles(half)
    top = np.all(v[f][:, :, 2] > 0, axis=1)
    mesh = colliders.Mesh((v, f[~top]))
    assert not mesh.mesh.closed
    pts = np.random.default_rng(2).uniform(-0.3, 0.3, (2000, 3))
    d = mesh.signed_distance(pts)
    assert np.all(d >= 0.0)
    inside = np.all(np.abs(pts) < np.array(half) - 0.02, axis=1) & (pts[:, 2] < 0.0)
    # a point inside, below the missing top: as far as the nearest of the five walls left
    walls = np.minimum.reduce(
        [half[0] - np.abs(pts[:, 0]), half[1] - np.abs(pts[:, 1]), half[2] + pts[:, 2]]
    )
    np.testing.assert_allclose(d[inside], walls[inside], atol=1e-12)


def test_a_body_meshs_distance_is_trimeshs_everywhere():
    """The mannequin (3,656 triangles, a deep hierarchy, closed) against trimesh (an independent
    implementation): the distance is trimesh's closest-point distance, negative exactly where
    trimesh's own inside test (ray casting) says the point is inside, at a pose."""
    import trimesh

    path = Path(__file__).resolve().parents[2] / "config" / "meshes" / "mannequin.obj"
    body = trimesh.load(path, process=False)
    q = np.array([0.96, 0.0, 0.0, 0.28])
    q /= np.linalg.norm(q)
    mesh = colliders.Mesh(str(path), position=(0.1, -0.2, 0.3), orientation=q)
    assert mesh.mesh.closed
    pts = np.random.default_rng(1).uniform([-0.8, -0.6, -0.3], [0.9, 0.4, 1.4], (3000, 3))
    local = (pts - mesh.position) @ mesh.rotation  # into the mesh's frame
    _, expected, _ = trimesh.proximity.closest_point(body, local)
    inside = body.contains(local)
    assert inside.sum() > 20
    np.testing.assert_allclose(mesh.signed_distance(pts), np.where(inside, -expected, expected),
                               atol=1e-6)  # fmt: skip


def test_a_cylinder_is_as_far_as_its_closed_form():
    cyl = colliders.Cylinder(center=(0, 0, 0), radius=0.1, length=0.4)
    pts = [[0.3, 0, 0], [0, 0, 0.5], [0.2, 0, 0.3], [0.05, 0, 0], [0, 0.02, 0.19], [0, 0, 0]]
    expected = [0.2, 0.3, math.hypot(0.1, 0.1), -0.05, -0.01, -0.1]
    np.testing.assert_allclose(cyl.signed_distance(pts), expected, atol=1e-15)
    # its axis is its own z: turned a quarter about x, it lies along y
    turned = colliders.Cylinder(
        radius=0.1, length=0.4, orientation=(math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0)
    )
    np.testing.assert_allclose(turned.signed_distance([[0, 0.5, 0], [0, 0, 0.3]]), [0.3, 0.2])


def _particle_on_mesh(theta, mu, integrator):
    n = np.array([-math.sin(theta), 0.0, math.cos(theta)])
    q = (math.cos(-theta / 2), 0.0, math.sin(-theta / 2), 0.0)  # the plate turned to normal n
    model = ClothModel.from_springs(
        [H * n, [50.0, 50.0, 50.0]], [1.0, 1.0], [[0, 1]], [0.0], [0.0]
    )
    plate = colliders.Mesh(quad(4.0), orientation=q, friction=mu)
    sim = Simulator(model, integrator=integrator, dt=1e-3, thickness=H, colliders=[plate])
    return sim, n


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "implicit_euler", "vbd"])
@pytest.mark.parametrize("theta,mu", [(0.5, 0.3), (0.3, 0.5)])
def test_a_particle_on_an_inclined_mesh_obeys_coulomb(integrator, theta, mu):
    sim, n = _particle_on_mesh(theta, mu, integrator)
    downhill = np.array([-math.cos(theta), 0.0, -math.sin(theta)])
    x0 = sim.positions[0].copy()
    T = 1.0
    sim.advance(T)
    s = float((sim.positions[0] - x0) @ downhill)
    assert float(n @ sim.positions[0]) == pytest.approx(H, rel=0.02)
    if math.tan(theta) < mu:
        # (vbd's lagged, smoothed friction creeps a few µm in the second; sliding would be
        # tenths of a metre)
        assert abs(s) < 1e-5
    else:
        a = G * (math.sin(theta) - mu * math.cos(theta))
        assert s == pytest.approx(0.5 * a * T * T, rel=2e-2)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "implicit_euler"])
@pytest.mark.parametrize("speed", [3.0, 30.0, 300.0])
def test_a_fast_plate_of_zero_thickness_never_passes_a_particle(integrator, speed):
    """The plate sweeps up through a particle at rest; continuous detection carries it along on
    the side it started (the plate's motion over a step is many thicknesses at speed)."""
    model = ClothModel.from_springs(
        [[0.0, 0.0, 0.1], [50.0, 50.0, 50.0]], [1.0, 1.0], [[0, 1]], [0.0], [0.0]
    )
    plate = colliders.Mesh(quad(1.0), position=(0, 0, -0.2), friction=0.2)
    sim = Simulator(
        model, integrator=integrator, dt=1e-3, thickness=H, colliders=[plate], gravity=(0, 0, 0)
    )
    for k in range(60):
        sim.set_collider_pose(0, (0.0, 0.0, -0.2 + speed * 1e-3 * (k + 1)))
        sim.step()
        assert sim.positions[0, 2] - sim.colliders[0].position[2] >= H * (1 - 0.02)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "vbd"])
def test_a_cloth_on_a_box_mesh_rests_as_on_the_box(integrator):
    """A cloth dropped on a box as 12 triangles settles where it settles on the Box primitive."""

    def run(collider):
        model = ClothModel.grid(
            10, 10, 0.05, 0.01,
            stiffness={"structural": 500, "shear": 500, "bend": 50},
            damping={"structural": 0.05, "shear": 0.05, "bend": 0.01},
            origin=(-0.225, -0.225, 0.12),
        )  # fmt: skip
        dt = 1 / 60 if integrator == "vbd" else 1e-3
        sim = Simulator(
            model, integrator=integrator, dt=dt, thickness=H, colliders=[collider], drag=0.2
        )
        sim.advance(4.0)
        return sim

    half = (0.15, 0.15, 0.1)
    a = run(colliders.Box(half_extents=half, friction=0.5))
    b = run(colliders.Mesh(box_triangles(half), friction=0.5))
    for sim in (a, b):
        d = sim.colliders[0].signed_distance(sim.positions)
        assert d.min() >= H * (1 - 0.1)
        assert (d < H * 1.1).sum() >= 4  # it lies on the box at the contact distance
    if integrator != "vbd":  # the same stage on the same distances: the same path
        assert np.abs(a.positions - b.positions).max() < 0.01
    # (vbd bounds a vertex's steps by the far side of a solid box, by the surface of a two-sided
    # mesh: the corners' folds settle differently, each at rest on the same top)


def test_the_camera_sees_mesh_and_cylinder_colliders_and_labels_them():
    model = ClothModel.grid(2, 2, 0.01, 0.01, stiffness=1.0, origin=(5, 5, 5))
    mesh = colliders.Mesh(box_triangles((0.1, 0.1, 0.1)), position=(-0.2, 0, 0))
    cyl = colliders.Cylinder(center=(0.2, 0, 0), radius=0.05, length=0.2)
    sim = Simulator(model, colliders=[mesh, cyl])
    cam = DepthCamera(width=64, height=48, fx=60, fy=60, cx=31.5, cy=23.5, position=(0, 0, 1))
    cam.set_pose((0, 0, 1.0), (0, 1, 0, 0))  # straight down
    f = cam.render(sim)
    assert set(np.unique(f.object)) == {-1, 1, 2}
    assert np.all(f.triangle[f.object >= 1] == -1)
    # every pixel seen lies on its collider's surface
    world = f.points().reshape(-1, 3).astype(np.float64) @ cam.rotation.T + cam.position
    for label, c in ((1, mesh), (2, cyl)):
        on = (f.object == label).ravel()
        assert on.sum() > 20
        assert np.abs(c.signed_distance(world[on])).max() < 1e-5
    # the mesh box renders as the Box primitive does, pixel for pixel
    boxed = Simulator(
        model, colliders=[colliders.Box(center=(-0.2, 0, 0), half_extents=(0.1,) * 3), cyl]
    )
    g = cam.render(boxed)
    np.testing.assert_array_equal(g.object, f.object)
    np.testing.assert_allclose(g.depth, f.depth, atol=1e-6)


def test_bad_mesh_colliders_are_refused_by_name(tmp_path):
    with pytest.raises(ValueError, match="no triangles"):
        colliders.Mesh((np.zeros((3, 3)), np.zeros((0, 3), int)))
    with pytest.raises(ValueError, match="no such mesh file"):
        colliders.Mesh(str(tmp_path / "missing.stl"))
    with pytest.raises(ValueError, match="scale"):
        colliders.Mesh(quad(1.0), scale=(1, -1, 1))
    with pytest.raises(ValueError, match="out of range"):
        colliders.Mesh((np.zeros((3, 3)), [[0, 1, 5]]))
    with pytest.raises(ValueError, match="nonzero area"):
        colliders.Mesh((np.zeros((3, 3)), [[0, 1, 2]]))
    with pytest.raises(ValueError, match="length"):
        colliders.Cylinder(radius=0.1, length=0.0)


@pytest.mark.parametrize("integrator", integrators.available())
def test_every_integrator_keeps_a_cloth_off_a_mesh(integrator):
    model = ClothModel.grid(
        6, 6, 0.05, 0.01, stiffness=300.0, damping=0.05, origin=(-0.125, -0.125, 0.03)
    )
    probe = Simulator(model, integrator=integrator, dt=1e-3)
    limit = probe.stable_dt()
    dt = 1.0 / 60.0 if math.isinf(limit) else min(1e-3, 0.5 * limit)
    sim = Simulator(
        model, integrator=integrator, dt=dt, thickness=H,
        colliders=[colliders.Mesh(quad(1.0), friction=0.5)],
    )  # fmt: skip
    sim.advance(0.5)
    assert np.all(sim.positions[:, 2] >= H * (1 - 0.1))


@pytest.mark.parametrize("shape", ["box", "ell", "mannequin", "plate"])
def test_the_candidate_grid_answers_as_the_walk_does(shape):
    """A query inside the mesh's candidate grid reads only its cell: where the cell lists
    triangles, the signed distance and its gradient are the hierarchy walk's to the bit (the same
    triangles in the walk's order; to rounding where two triangles tie for the nearest); where
    one feature is nearest over the whole cell (a face's interior: its plane; an edge's interior:
    the segment; two faces and their edge: the crease), the feature gives them to rounding.
    Checked with and without a cutoff for points near the surface and beside its edges, in the
    box and beyond the grid, against the same mesh without a grid (every query walks); a cell
    lists a few triangles, not the mesh, and on a box or a plate, whose faces are large, many
    queries near the surface are answered by a plane, and on a box most beside its edges by an
    edge or a crease; an L-shaped prism has a concave edge, whose creases are answered too."""
    import trimesh

    from cloth_sim.contact.mesh_features import (
        CREASE_FEATURE,
        EDGE_FEATURE,
        NO_FEATURE,
        PLANE_FEATURE,
    )
    from cloth_sim.contact.triangle_meshes import TriangleMesh, mesh_distance, pack

    if shape == "box":
        v, f = box_triangles((0.3, 0.3, 0.1))
    elif shape == "plate":
        v, f = quad(0.4)
    elif shape == "ell":  # (a closed mesh with a concave edge)
        from shapely.geometry import Polygon

        ell = Polygon([(0, 0), (0.4, 0), (0.4, 0.15), (0.15, 0.15), (0.15, 0.4), (0, 0.4)])
        prism = trimesh.creation.extrude_polygon(ell, 0.2)
        v, f = np.asarray(prism.vertices), np.asarray(prism.faces)
    else:
        path = Path(__file__).resolve().parents[2] / "config" / "meshes" / "mannequin.obj"
        body = trimesh.load(path, process=False)
        v, f = np.asarray(body.vertices), np.asarray(body.faces)
    other = TriangleMesh(np.eye(3), [[0, 1, 2]], "other")
    mesh = TriangleMesh(v, f, shape)
    grid = pack([other, mesh])
    walk = pack([other, TriangleMesh(v, f, shape, grid=False)])
    rng = np.random.default_rng(7)
    lo, hi = mesh.lo[0], mesh.hi[0]
    end = mesh.grid_origin + mesh.grid_cell * mesh.grid_dims
    centres = v[f].mean(axis=1)
    near = np.concatenate([v, centres]) + rng.normal(scale=0.01, size=(len(v) + len(f), 3))
    inside = rng.uniform(lo, hi, size=(300, 3))
    around = rng.uniform(2 * mesh.grid_origin - end, 2 * end - mesh.grid_origin, size=(300, 3))
    # points over the faces, at a third of a cell (a cloth resting on them; either side of a plate)
    w = rng.dirichlet(np.ones(3), size=300)
    k = rng.integers(len(f), size=300)
    e1, e2 = v[f[k, 1]] - v[f[k, 0]], v[f[k, 2]] - v[f[k, 0]]
    normal = np.cross(e1, e2)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    if shape == "plate":
        normal *= rng.choice([-1.0, 1.0], size=(300, 1))
    on = np.einsum("ij,ijk->ik", w, v[f[k]])
    hover = on + 0.3 * mesh.grid_cell * normal
    # points beside the edges, a third of a cell out along the edge's pseudonormal (a cloth
    # draped over a box's edges), a tenth of a cell apart
    ends = f[k][:, [0, 1]]
    s = rng.uniform(0.05, 0.95, size=(300, 1))
    along = v[ends[:, 0]] + s * (v[ends[:, 1]] - v[ends[:, 0]])
    bisector = mesh.edge_normals[k, 0]
    crease = np.linalg.norm(bisector, axis=1) < 2.0 - 1e-9  # (not between two coplanar faces)
    bisector /= np.linalg.norm(bisector, axis=1, keepdims=True)
    beside = along + 0.3 * mesh.grid_cell * bisector
    beside += rng.normal(scale=0.1 * mesh.grid_cell, size=(300, 3))
    kinds = {PLANE_FEATURE: 0, EDGE_FEATURE: 0}
    exact = listed = edges = in_notch = 0
    notch = np.empty((0, 3))
    if shape == "ell":  # around the concave edge, the vertical one at (0.15, 0.15)
        notch = np.column_stack(
            [
                0.15 + rng.uniform(-0.5, 1.0, 300) * mesh.grid_cell,
                0.15 + rng.uniform(-0.5, 1.0, 300) * mesh.grid_cell,
                rng.uniform(0.05, 0.15, 300),
            ]
        )
    probes = np.concatenate([hover, near, inside, around, notch, beside])
    first_notch = len(probes) - len(beside) - len(notch)
    for n, p in enumerate(probes):
        kind = mesh.feature_at(p)
        for cutoff in (np.inf, 0.005, 0.05):
            got = np.array(mesh_distance(*grid, 1, *p, cutoff))
            want = np.array(mesh_distance(*walk, 1, *p, cutoff))
            # the walk's nearest triangle; where two triangles sharing an edge tie for it, the
            # cell's may be the other one (the walk passes over a box no nearer than the best
            # so far), the same point to rounding; and the walk's gradient is (x − nearest)/d,
            # its rounding growing as 1/d
            slack = 1e-12 + 8 * np.finfo(float).eps * np.abs(p).max() / max(abs(want[0]), 1e-300)
            assert abs(got[0] - want[0]) <= 1e-12, (p, cutoff, got, want, kind)
            assert np.allclose(got[1:], want[1:], rtol=0, atol=slack), (p, cutoff, got, want)
            exact += kind == NO_FEATURE and np.array_equal(got, want)
            listed += kind == NO_FEATURE
        if n < len(hover):
            kinds[kind] = kinds.get(kind, 0) + 1
        m = n - (len(probes) - len(beside))
        edges += m >= 0 and crease[m] and kind in (EDGE_FEATURE, CREASE_FEATURE)
        in_notch += m < 0 and n >= first_notch and kind == CREASE_FEATURE
    assert exact >= 0.98 * listed  # (the listed triangles are the walk's, in its order)
    counts = np.diff(mesh.cell_ptr)
    assert np.median(counts[counts > 0]) <= 16
    if shape != "mannequin":  # (a body's triangles are smaller than a cell and its margins)
        assert kinds[PLANE_FEATURE] > 0.3 * len(hover)
    if shape == "box":  # (beside a box's edges, most queries are answered by an edge or a crease)
        assert edges > 0.8 * crease.sum() > 0
    if shape == "ell":  # the concave edge's creases (their sign −1) answered queries too
        concave = mesh.cell_features[:, 0] == CREASE_FEATURE
        concave &= mesh.cell_features[:, 15] < 0
        assert concave.sum() > 0 and in_notch > 0.3 * len(notch)
        assert edges > 0.5 * crease.sum() > 0
