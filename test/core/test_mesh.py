"""Garments: any triangle mesh as cloth. Topology counted here independently of
cloth_sim.physics.mesh, mass
against density × area, the same model from every format, welding, every bad mesh refused by name,
and the physics laws on a mesh: rest, free fall, a gripper's load, the explicit step limit, no
crossing in the T-shirt, and the thickness kept at hems (point–edge, edge–edge)."""

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
from cloths import springy_fold

from cloth_sim import ClothModel, Simulator, integrators
from cloth_sim.model import BUCKLING, TENSION_ONLY
from cloth_sim.physics import mesh as M
from cloth_sim.scene import SceneError, load_scene, scene_from_dict
from cloth_sim.simulator import SimulationDiverged

ROOT = Path(__file__).resolve().parents[2]
MESHES = ROOT / "config" / "meshes"
G = np.array([0.0, 0.0, -9.81])


def curved_patch(n=7, m=5, radius=0.3, width=0.4):
    """A piece of a cylinder (curved at rest), triangulated with alternating diagonals."""
    theta = np.linspace(0, 1.2, n)
    y = np.linspace(0, width, m)
    T, Y = np.meshgrid(theta, y, indexing="ij")
    v = np.stack([radius * np.sin(T), Y, radius * (1 - np.cos(T))], axis=-1).reshape(-1, 3)
    faces = []
    for i, j in itertools.product(range(n - 1), range(m - 1)):
        a, b, c, d = i * m + j, (i + 1) * m + j, (i + 1) * m + j + 1, i * m + j + 1
        faces += [(a, b, c), (a, c, d)] if (i + j) % 2 else [(a, b, d), (b, c, d)]
    return v, np.array(faces)


def write_obj(path, v, f):
    path.write_text(
        "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in v.tolist())
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)
    )


def write_ply(path, v, f):
    head = (
        f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty double x\nproperty double y\n"
        f"property double z\nelement face {len(f)}\nproperty list uchar int vertex_indices\n"
        "end_header\n"
    )
    path.write_text(
        head
        + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in v.tolist())
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in f)
    )


def build(source, **kw):
    kw.setdefault(
        "density", 2.0
    )  # with this stiffness, dt = 1 ms is stable for every explicit method
    kw.setdefault("stiffness", {"structural": 400.0, "bend": 2.0})
    kw.setdefault("damping", {"structural": 0.05, "bend": 0.01})
    return ClothModel.from_mesh(source, **kw)


# --------------------------------------------------------------------------- topology and mass
@pytest.mark.parametrize("source", ["patch", "tshirt.obj", "towel.obj"])
def test_springs_are_the_edges_and_the_opposite_vertices_of_interior_edges(source):
    model = build(curved_patch() if source == "patch" else MESHES / source)
    tris = model.triangles.tolist()
    # counted here with Python sets and dicts
    faces_of = {}
    for t, (a, b, c) in enumerate(tris):
        for u, w in ((a, b), (b, c), (c, a)):
            faces_of.setdefault(frozenset((u, w)), []).append(t)
    edges = set(faces_of)
    bends = set()
    for e, ts in faces_of.items():
        assert len(ts) <= 2
        if len(ts) == 2:
            bends.add(frozenset(v for t in ts for v in tris[t] if v not in e))
    structural = model.springs[model.family == 0]
    bend = model.springs[model.family == 1]
    assert (
        model.family_names == ("structural", "bend") and model.rows is None and model.cols is None
    )
    assert len(structural) == len(edges) and {frozenset(s) for s in structural.tolist()} == edges
    assert len(bend) == sum(len(ts) == 2 for ts in faces_of.values())
    assert {frozenset(s) for s in bend.tolist()} == bends
    # rest lengths are the mesh's own; only edges are strain limited
    x = model.positions
    np.testing.assert_allclose(
        model.rest_lengths, np.linalg.norm(x[model.springs[:, 0]] - x[model.springs[:, 1]], axis=1)
    )
    assert np.array_equal(model.strain_limited, model.family == 0)


def test_total_mass_is_density_times_area():
    v, f = curved_patch()
    model = build((v, f), density=0.37)  # (any density)
    a, b, c = (
        np.linalg.norm(v[f[:, i]] - v[f[:, j]], axis=1) for i, j in ((0, 1), (1, 2), (2, 0))
    )
    s = (a + b + c) / 2
    area = np.sqrt(s * (s - a) * (s - b) * (s - c)).sum()  # Heron
    assert model.masses.sum() == pytest.approx(0.37 * area, rel=1e-12)
    assert np.all(model.masses > 0)


def test_obj_ply_and_arrays_give_the_same_model(tmp_path):
    v, f = curved_patch()
    write_obj(tmp_path / "p.obj", v, f)
    write_ply(tmp_path / "p.ply", v, f)
    models = [build(s) for s in ((v, f), tmp_path / "p.obj", str(tmp_path / "p.ply"))]
    for m in models[1:]:
        for name in (
            "positions",
            "masses",
            "springs",
            "rest_lengths",
            "stiffness",
            "triangles",
            "family",
            "kind",
        ):
            np.testing.assert_array_equal(getattr(m, name), getattr(models[0], name), err_msg=name)
    # particle i is the file's vertex i
    np.testing.assert_array_equal(models[1].positions, v)


def test_stl_and_glb_load_through_the_mesh_library(tmp_path):
    import trimesh

    v, f = curved_patch()
    ref = build((v, f))
    for ext in ("stl", "glb", "off"):
        trimesh.Trimesh(v, f, process=False).export(tmp_path / f"p.{ext}")
        m = build(tmp_path / f"p.{ext}")
        # STL keeps every triangle's corners apart: welded back to the mesh's particles
        assert m.n_particles == len(v) and m.n_springs == ref.n_springs, ext
        assert m.masses.sum() == pytest.approx(ref.masses.sum(), rel=1e-6), ext


def test_a_seam_is_welded():
    v, f = curved_patch(n=7, m=5)
    # split the mesh along column 3 as an exporter does at a texture seam
    seam = np.flatnonzero(np.arange(len(v)) // 5 == 3)
    copies = len(v) + np.arange(len(seam))
    v2 = np.vstack([v, v[seam]])
    f2 = f.copy()
    right = np.all(f // 5 >= 3, axis=1)  # triangles right of the seam use the copies
    remap = np.arange(len(v))
    remap[seam] = copies
    f2[right] = remap[f[right]]
    split = ClothModel.from_mesh((v2, f2), density=0.2, stiffness=100.0)
    whole = ClothModel.from_mesh((v, f), density=0.2, stiffness=100.0)
    assert split.n_particles == whole.n_particles == len(v)
    np.testing.assert_array_equal(split.positions, whole.positions)
    assert {frozenset(s) for s in split.springs.tolist()} == {
        frozenset(s) for s in whole.springs.tolist()
    }
    np.testing.assert_allclose(split.masses, whole.masses, rtol=1e-12)
    # pins name the source's vertices: a copy pins the welded particle
    assert ClothModel.from_mesh((v2, f2), density=0.2, stiffness=1.0, pinned=[copies[0]]).pinned[
        seam[0]
    ]


def test_choi_ko_on_a_mesh_buckles_its_bend_springs():
    model = build(curved_patch(), model="choi_ko")
    assert np.all(model.kind[model.family == 0] == TENSION_ONLY)
    assert np.all(model.kind[model.family == 1] == BUCKLING)


# --------------------------------------------------------------------------- bad meshes
def _bad(tmp_path, text, ext="obj"):
    p = tmp_path / f"bad.{ext}"
    p.write_text(text)
    return p


TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


@pytest.mark.parametrize(
    "case, text, words",
    [
        ("no triangles", TRI, "bad.obj: the mesh has no triangles"),
        (
            "index out of range",
            TRI + "f 1 2 9\n",
            "bad.obj: cannot be read as OBJ: a face refers to a vertex index out of range",
        ),
        (
            "non-finite",
            "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n",
            "bad.obj: vertex 1 has a non-finite",
        ),
        (
            "degenerate",
            TRI + "v 2 0 0\nf 1 2 3\nf 1 2 4\n",
            "bad.obj: triangle 1 (vertices [0, 1, 3]) is degenerate",
        ),
        (
            "non-manifold",
            TRI + "v 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n",
            "bad.obj: non-manifold edge between vertices 0 and 1: shared by 3 triangles",
        ),
        ("twice", TRI + "f 1 2 3\nf 1 3 2\n", "bad.obj: triangles 0 and 1 have the same vertices"),
        ("lonely vertex", TRI + "v 5 5 5\nf 1 2 3\n", "bad.obj: vertex 3 belongs to no triangle"),
    ],
)
def test_a_bad_mesh_file_is_refused_naming_the_file_and_the_element(tmp_path, case, text, words):
    with pytest.raises(ValueError) as e:
        build(_bad(tmp_path, text))
    assert words in str(e.value), (case, str(e.value))


def test_unreadable_unknown_and_too_large_files_are_refused(tmp_path, monkeypatch):
    with pytest.raises(
        ValueError, match=r"bad.xyz: unknown mesh format '.xyz'; expected one of .obj"
    ):
        build(_bad(tmp_path, TRI, "xyz"))
    with pytest.raises(ValueError, match="nowhere.obj: no such mesh file"):
        build(tmp_path / "nowhere.obj")
    with pytest.raises(ValueError, match="bad.glb: cannot be read as GLB"):
        build(_bad(tmp_path, "not a binary glTF", "glb"))
    with pytest.raises(ValueError, match=r"bad.ply: cannot be read as PLY"):
        build(_bad(tmp_path, "ply\nformat nonsense\n", "ply"))
    monkeypatch.setattr(M, "MAX_MESH_BYTES", 10)
    with pytest.raises(ValueError, match=r"bad.obj: \d+ bytes, larger than the 10 bytes accepted"):
        build(_bad(tmp_path, TRI + "f 1 2 3\n"))


def test_bad_arrays_and_arguments_are_refused_naming_the_element():
    v, f = curved_patch()
    cases = [
        ((v, f[:0]), {}, "the mesh has no triangles"),
        ((v, np.r_[f, [[0, 1, len(v)]]]), {}, f"triangle {len(f)} refers to vertex"),
        ((v[:, :2], f), {}, "vertices must have shape (n, 3)"),
        ((v, f), {"density": -1.0}, "density = -1.0 is not accepted"),
        ((v, f), {"scale": 0.0}, "scale must be a finite number > 0"),
        ((v, f), {"pinned": [len(v)]}, "pinned must be vertex indices"),
        ((v, f), {"stiffness": {"shear": 1.0}}, "unknown spring families ['shear']"),
        ((v, f), {"model": "other"}, "unknown model 'other'"),
    ]
    for source, kw, words in cases:
        with pytest.raises(ValueError) as e:
            build(source, **kw)
        assert words in str(e.value), (words, str(e.value))


# --------------------------------------------------------------------------- physics on a mesh
@pytest.mark.parametrize("name", integrators.available())
def test_a_curved_mesh_at_rest_stays_at_rest_with_gravity_off(name):
    model = build(curved_patch(), pinned=[0])
    sim = Simulator(model, integrator=name, dt=1e-3, gravity=(0, 0, 0), strain_limit=0.1)
    sim.step(50)
    np.testing.assert_allclose(sim.positions, model.positions, atol=1e-12, rtol=0)
    assert np.abs(sim.velocities).max() < 1e-9


@pytest.mark.parametrize("name", ["rk4", "midpoint", "symplectic_euler", "implicit_euler"])
def test_the_centre_of_mass_of_a_free_mesh_falls_freely(name):
    model = build(curved_patch())
    sim = Simulator(model, integrator=name, dt=1e-3)
    v0 = np.array([0.3, -0.2, 0.5])
    sim.velocities = np.tile(v0, (model.n_particles, 1))
    sim.advance(0.2)
    m = model.masses / model.masses.sum()
    com0, com = m @ model.positions, m @ sim.positions
    t = sim.time
    # exact for methods exact on constant acceleration, first order in dt for the others
    tol = 1e-9 if name in ("rk4", "midpoint") else 0.5 * 9.81 * t * 1e-3 + 1e-9
    np.testing.assert_allclose(com - com0, v0 * t + 0.5 * G * t * t, atol=tol)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "implicit_euler"])
def test_a_mesh_hanging_from_one_gripper_pulls_it_with_its_weight(integrator):
    model = build(
        curved_patch(),
        stiffness={"structural": 300.0, "bend": 1.0},
        damping={"structural": 0.3, "bend": 0.01},
    )
    dt = 1.0 / 120 if integrator == "implicit_euler" else 1e-3
    sim = Simulator(model, integrator=integrator, dt=dt, drag=0.03)  # the swing settles in ~1 s
    corner = model.positions[0]
    idx = sim.grasp("g", corner, 1e-6)
    sim.advance(6.0)
    force, _ = sim.gripper_wrench("g")
    free = np.ones(model.n_particles, bool)
    free[idx] = False
    weight = model.masses[free].sum() * G
    assert np.linalg.norm(force - weight) <= 0.01 * np.linalg.norm(weight)


def _blows_up(model, dt, seconds=0.3):
    sim = Simulator(model, integrator="symplectic_euler", dt=dt, gravity=(0, 0, 0))
    rng = np.random.default_rng(1)
    sim.positions = model.positions + rng.normal(0, 1e-4, model.positions.shape)
    try:
        sim.advance(seconds)
    except SimulationDiverged:
        return True
    return float(np.abs(sim.positions - model.positions).max()) > 0.1


def test_the_explicit_step_limit_holds_on_a_mesh():
    model = build(
        MESHES / "towel.obj",
        stiffness={"structural": 400.0, "bend": 0.5},
        damping=0.0,
        pinned=[0, 20],
    )
    limit = Simulator(model, integrator="symplectic_euler").stable_dt()
    assert 0 < limit < 1
    assert not _blows_up(model, 0.95 * limit)
    assert _blows_up(model, 1.3 * limit)


def test_kang_on_a_large_mesh_is_analysed_in_bounded_time_by_its_equivalent_grid():
    from cloth_sim.integrators import kang_analysis as kang

    model = build(MESHES / "tshirt.obj")
    assert model.n_particles > kang.KANG_FULL_MAX
    sim = Simulator(model, integrator="kang", dt=1e-4)
    limit = sim.stable_dt()
    grid, k, c = kang.equivalent_grid(model, sim.analysis.k, sim.analysis.c)
    assert limit == kang.kang_stable_dt(grid, k, c, 0.0)
    assert 0 < limit < 1


def test_strain_limit_and_wind_act_on_a_mesh():
    free = load_scene("towel").build_simulator(strain_limit=None)
    free.advance(0.5)
    assert free.max_strain() > 0.005  # the towel's own stretch under its weight, unlimited
    sim = load_scene("towel").build_simulator(strain_limit=0.002)
    sim.advance(0.5)
    assert sim.max_strain() <= 0.002 + 2e-4
    windy = load_scene("towel").build_simulator(wind=(0.0, 1e-4, 0.0))
    assert "wind" in windy.active_terms
    windy.advance(0.3)
    # wind along the towel's normal (y) pushes it off its plane, the way the wind blows
    assert windy.positions[:, 1].max() > 0.01 and windy.positions[:, 1].min() > -1e-6


# --------------------------------------------------------------------------- self-collision
def point_triangle_distances(p, a, b, c):
    """Distances from points ``p`` to triangles ``abc`` (row by row), computed here: the projection
    onto the plane when it falls inside, else the nearest point of the three sides."""

    def seg(p, u, w):
        d = w - u
        t = np.clip(np.einsum("ij,ij->i", p - u, d) / np.einsum("ij,ij->i", d, d), 0, 1)
        return np.linalg.norm(p - (u + t[:, None] * d), axis=1)

    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    h = np.einsum("ij,ij->i", p - a, n)
    q = p - h[:, None] * n
    inside = np.ones(len(p), bool)
    for u, w in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(w - u, q - u), n) >= 0
    edge = np.minimum(np.minimum(seg(p, a, b), seg(p, b, c)), seg(p, c, a))
    return np.where(inside, np.abs(h), edge)


def nearest_far_feature(x, tris, springs, hops=3):
    """The smallest distance from a particle to a triangle none of whose corners is within
    ``hops`` edges of it: the gap between parts of the cloth that are not neighbours."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import shortest_path

    n = len(x)
    g = sp.coo_matrix((np.ones(len(springs)), (springs[:, 0], springs[:, 1])), shape=(n, n))
    hop = shortest_path(g, directed=False, unweighted=True)
    best = np.inf
    for p in range(n):
        T = tris[np.all(hop[p][tris] >= hops, axis=1)]
        if len(T):
            d = point_triangle_distances(
                np.repeat(x[p][None], len(T), 0), x[T[:, 0]], x[T[:, 1]], x[T[:, 2]]
            )
            best = min(best, float(d.min()))
    return best


def test_the_folded_cloth_keeps_its_thickness_at_its_hems_too():
    """A cloth folded over itself (the fold scene): the layers' edge particles came within 1.5–1.9
    mm of the other layer at a 5 mm thickness while only particles in front of a face were pushed.
    With the point–edge, point–point and edge–edge cases every part keeps the thickness."""
    sim = springy_fold(thickness=0.005)
    sim.advance(1.5)
    structural = sim.model.springs[sim.model.family == 0]
    assert sim.positions[:, 2].max() > 2 * sim.thickness  # it did fold over itself
    assert (
        nearest_far_feature(sim.positions, sim.model.triangles, structural) >= 0.97 * sim.thickness
    )


def test_crossing_edges_are_pushed_apart():
    """Two edges crossing like an X, 2 mm apart and closing: only the edge–edge case sees them (no
    particle is near the other edge's triangles' faces or corners)."""
    x = np.array(
        [[-1, 0, 0.0], [1, 0, 0], [0, -0.02, 0.5], [0, -1, 0.002], [0, 1, 0.002], [0.02, 0, 0.5]],
        float,
    )
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    model = ClothModel.from_mesh((x, tris), density=1.0, stiffness=0.0)
    sim = Simulator(
        model,
        integrator="symplectic_euler",
        dt=1e-3,
        gravity=(0, 0, 0),
        self_collision=True,
        thickness=0.005,
    )
    v = np.zeros_like(x)
    v[3:, 2] = -0.5  # the second triangle moves down onto the first edge
    sim.velocities = v
    sim.step(10)
    assert sim._self_collision.last_edge_pairs >= 1
    gap = sim.positions[3, 2] - sim.positions[0, 2]  # the two edges' heights at their crossing
    assert gap >= 0.97 * sim.thickness


def test_the_tshirt_never_crosses_itself():
    from cloth_sim.bench.crossings import crossings  # the independent crossing check

    sim = load_scene("tshirt").build_simulator()
    assert sim.self_collision
    tris = sim.model.triangles
    total = 0
    for _ in range(int(round(0.35 / sim.dt))):  # it lands on the table at 0.14 s and flattens
        x0 = sim.positions.copy()
        sim.step()
        total += len(crossings(x0, sim.positions, tris))
        # the table's skin holds too: cloth landing on cloth does not drive it into the table
        assert sim.colliders[0].signed_distance(sim.positions).min() >= 0.97 * sim.thickness
    assert total == 0


def test_the_tshirt_rests_on_its_table_with_self_contact():
    """The T-shirt settled on its table rests, with self-contact as stiff as the knit around it
    (``self_contact_stiffness='cloth'``, ``vbd.SELF_CONTACT_SHARE`` of the springs at a vertex) as
    without self-contact, its median vertex still to a hundredth of a millimetre a step, and at
    the default 1e4 N/m, forty times the knit's stiffness, to two hundredths. At 1e4 N/m its
    layers heaved (0.09 mm a step, a relative residual ~1,700 times the weight) while a step that
    would press a pair not yet pressed was cut at the pair's onset, moving one side of it alone;
    the pairs near their onset now add their stiffness to the step instead
    (``vbd_terms.NEAR``): 0.011 mm. The relative residual at the knit's stiffness is a tenth of
    the default's (72 against 706; two orders of magnitude below it before, when the default's
    was ~1,700). It is not the residual without self-contact (2.3): at rest it depends on the
    configuration the layers settle in, 2.5–49 over runs whose starts differ by a nanometre
    (2026-12-01), so that is not asserted."""
    scene = load_scene("tshirt")
    found = {}
    for case, on, options in (
        ("off", False, {"self_contact_stiffness": "cloth"}),
        ("cloth", True, {"self_contact_stiffness": "cloth"}),
        ("default", True, {}),
    ):
        sim = scene.build_simulator(
            self_collision=on, integrator_options={**scene.vbd_options(), **options}
        )
        assert sim.integrator_options["iterations"] == 3  # (the scene's)
        sim.advance(4.5)  # it lands at 0.14 s; with self-contact its layers settle by 4.5 s
        moved, residual = [], []
        for _ in range(30):
            x0 = sim.positions.copy()
            sim.step()
            moved.append(np.median(np.linalg.norm(sim.positions - x0, axis=1)))
            residual.append(sim.integrator_stats["last_residual"])
        found[case] = float(np.mean(moved)), float(np.median(residual))
    assert found["off"][0] <= 1e-5 and found["cloth"][0] <= 1e-5  # m a step
    assert found["default"][0] <= 2e-5, found
    assert found["cloth"][1] <= 0.2 * found["default"][1], found


# --------------------------------------------------------------------------- scenes and garments
def test_the_garment_scenes_load_and_hold():
    towel = load_scene("towel").build_simulator()
    assert towel.model.pinned.sum() == 2 and towel.model.rows is None
    towel.advance(0.2)
    np.testing.assert_array_equal(
        towel.positions[towel.model.pinned], towel.model.positions[towel.model.pinned]
    )
    shirt = load_scene("tshirt")
    assert shirt.mesh["file"] == MESHES / "tshirt.obj" and shirt.self_collision


def _mesh_scene(tmp_path, **extra):
    v, f = curved_patch()
    write_obj(tmp_path / "m.obj", v, f)
    data = {
        "mesh": {"file": "m.obj", "density": 0.2},
        "stiffness": {"structural": 100.0, "bend": 1.0},
    }
    data.update(extra)
    return scene_from_dict(data, source=str(tmp_path / "s.yaml"))


def test_a_mesh_scene_places_the_mesh_and_pins_a_box(tmp_path):
    scene = _mesh_scene(
        tmp_path, pinned=[1], pinned_box={"min": [-0.01, -0.01, 0.99], "max": [0.01, 0.41, 1.01]}
    )
    scene.mesh["position"] = [0.0, 0.0, 1.0]
    model = scene.build_model()
    v, _ = curved_patch()
    np.testing.assert_allclose(model.positions, v + [0, 0, 1.0])
    assert set(np.flatnonzero(model.pinned)) == {0, 1, 2, 3, 4}  # the box holds the first row


@pytest.mark.parametrize(
    "extra, words",
    [
        (
            {"grid": {"rows": 4, "cols": 4, "spacing": 0.1}},
            "fields 'grid' and 'mesh' are both given",
        ),
        ({"particle_mass": 0.01}, "field 'particle_mass' is for grid scenes"),
        ({"stiffness": {"shear": 1.0}}, "a mesh has no shear springs"),
        ({"pinned": [[0, 1]]}, "field 'pinned[0]' must be a vertex index"),
        (
            {"mesh": {"file": "none.obj", "density": 0.2}},
            "field 'mesh.file' must be an existing mesh file",
        ),
        ({"mesh": {"file": "m.obj"}}, "field 'mesh.density' is missing"),
        ({"mesh": {"file": "m.obj", "density": 0.2, "scale": -1}}, "field 'mesh.scale'"),
        (
            {"pinned_box": {"min": [1, 1, 1], "max": [0, 0, 0]}},
            "field 'pinned_box' must be min <= max",
        ),
    ],
)
def test_a_bad_mesh_scene_is_refused_naming_the_field(tmp_path, extra, words):
    with pytest.raises(SceneError) as e:
        _mesh_scene(tmp_path, **extra)
    assert words in str(e.value)


def test_the_shipped_garments_are_what_the_script_makes(tmp_path, monkeypatch):
    sys.path.insert(0, str(ROOT / "tools"))
    import make_garments

    monkeypatch.setattr(make_garments, "OUT", tmp_path)
    make_garments.main()
    for name in ("tshirt.obj", "tshirt.landmarks.yaml", "towel.obj", "twist_sheet.obj"):
        assert (tmp_path / name).read_bytes() == (MESHES / name).read_bytes(), name


def test_the_tshirts_landmarks_name_the_places_they_say():
    """The garment's named vertices are where their names put them: the hem's corners at the
    bottom of the side seams, the sleeves' ends the widest points, the shoulders and the collar on
    the shoulder seams, and the middles of the neck and hem once on each panel (the front bulges
    toward +z, the back toward −z)."""
    model = ClothModel.from_mesh(MESHES / "tshirt.obj", density=0.2, stiffness=100.0)
    marks = model.meta["landmarks"]
    x = model.positions
    assert len(marks) == 16 and len(set(marks.values())) == 16
    at = {name: x[i] for name, i in marks.items()}
    assert at["hem_left"][1] == at["hem_right"][1] == x[:, 1].min() == 0.0
    assert at["hem_left"][0] == -0.25 and at["hem_right"][0] == 0.25
    assert (
        at["sleeve_left_bottom"][0] == x[:, 0].min()
        and at["sleeve_right_bottom"][0] == x[:, 0].max()
    )
    for side, sign in (("left", -1), ("right", 1)):
        assert sign * at[f"sleeve_{side}_top"][0] > sign * at[f"shoulder_{side}"][0] > 0.0
        assert at[f"shoulder_{side}"][1] < at[f"collar_{side}"][1]
        for name in ("hem", "armpit", "sleeve", "shoulder", "collar"):
            for key in (k for k in marks if k.startswith(f"{name}_{side}")):
                assert at[key][2] == 0.0, key  # on a seam: one vertex of both panels
    for middle in ("hem_middle", "collar_middle"):
        front, back = at[f"{middle}_front"], at[f"{middle}_back"]
        assert np.array_equal(front[:2], back[:2]) and front[2] > 0.0 > back[2]
    scene = load_scene("tshirt").build_model()  # placed by its scene: the same particles
    assert scene.meta["landmarks"] == marks


@pytest.mark.parametrize(
    "text, words",
    [
        ("collar: 99999\n", "landmark collar = 99999 is not accepted: expected a vertex index"),
        ("collar: 1.5\n", "landmark collar = 1.5 is not accepted"),
        ("'not a name': 1\n", "landmark name 'not a name' is not accepted"),
        ("[1, 2]\n", "expected a mapping of landmark names to vertex indices"),
        ("collar: [\n", "cannot be read as YAML"),
    ],
)
def test_a_bad_landmarks_file_is_refused_naming_the_file_and_the_entry(tmp_path, text, words):
    mesh = tmp_path / "sheet.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "sheet.landmarks.yaml").write_text(text)
    with pytest.raises(ValueError) as e:
        ClothModel.from_mesh(mesh, density=0.2, stiffness=1.0)
    assert str(tmp_path / "sheet.landmarks.yaml") in str(e.value) and words in str(e.value)
    (tmp_path / "sheet.landmarks.yaml").unlink()  # without one: no landmarks
    assert ClothModel.from_mesh(mesh, density=0.2, stiffness=1.0).meta["landmarks"] == {}
