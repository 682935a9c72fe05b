"""Contacts: colliders with Coulomb friction, thickness, continuous detection, self-collision.

Checked against closed forms (a particle on an incline), rest states (a cloth on the ground) and an
independent crossing test (a particle against a triangle between consecutive steps, solved here
from the coplanarity cubic, not with the simulator's code).
"""

import math
import sys

import numpy as np
import pytest
from cloths import springy_fold

from cloth_sim import ClothModel, Simulator, colliders, integrators
from cloth_sim.bench.crossings import crossings  # the independent crossing check
from cloth_sim.contact.collision_tree import TriangleTree
from cloth_sim.contact.pair_list import PairList, tree_ranks
from cloth_sim.contact.self_collision import SKIN, Uncrossed
from cloth_sim.scene import SceneError, load_scene, scene_from_dict

G = 9.81
H = 0.005


def _particle_on(plane_normal, friction, integrator, dt=1e-3):
    """One free particle resting on a plane through the origin (and a far-away partner: a model
    needs a spring, of zero stiffness here)."""
    n = np.asarray(plane_normal, float) / np.linalg.norm(plane_normal)
    model = ClothModel.from_springs(
        [H * n, [50.0, 50.0, 50.0]], [1.0, 1.0], [[0, 1]], [0.0], [0.0]
    )
    sim = Simulator(
        model,
        integrator=integrator,
        dt=dt,
        thickness=H,
        colliders=[colliders.Plane(normal=n, offset=0.0, friction=friction)],
    )
    return sim, n


@pytest.mark.parametrize("integrator", integrators.available())
@pytest.mark.parametrize("theta,mu", [(0.5, 0.3), (0.5, 0.0), (0.3, 0.5), (0.5, 0.6)])
def test_particle_on_an_incline_obeys_coulomb(integrator, theta, mu):
    """Stays put when tan θ < μ; slides with g (sin θ − μ cos θ) when tan θ > μ (g sin θ without
    friction), at the contact distance all the way."""
    sim, n = _particle_on((-math.sin(theta), 0.0, math.cos(theta)), mu, integrator)
    downhill = np.array([-math.cos(theta), 0.0, -math.sin(theta)])
    x0 = sim.positions[0].copy()
    T = 1.0
    sim.advance(T)
    s = float((sim.positions[0] - x0) @ downhill)
    assert abs(float(n @ sim.positions[0]) - H) < 1e-9
    if math.tan(theta) < mu:
        assert abs(s) < 1e-12
        assert np.linalg.norm(sim.velocities[0]) < 1e-12
    else:
        a = G * (math.sin(theta) - mu * math.cos(theta))
        assert s == pytest.approx(0.5 * a * T * T, rel=5e-3)  # first order in dt = 1e-3
        assert float(sim.velocities[0] @ downhill) == pytest.approx(a * T, rel=5e-3)


def _ground_cloth(integrator, dt, n=8):
    model = ClothModel.grid(
        n,
        n,
        0.05,
        0.01,
        stiffness={"structural": 500, "shear": 500, "bend": 50},
        damping={"structural": 0.05, "shear": 0.05, "bend": 0.01},
        origin=(0.0, 0.0, 0.03),
    )
    return Simulator(
        model, integrator=integrator, dt=dt, thickness=H, colliders=[colliders.Plane(friction=0.5)]
    )


@pytest.mark.parametrize("integrator", integrators.available())
def test_cloth_dropped_on_the_ground_settles_at_the_contact_distance(integrator):
    probe = _ground_cloth(integrator, 1e-3)
    limit = probe.stable_dt()
    dt = 1.0 / 60.0 if math.isinf(limit) else min(1e-3, 0.5 * limit)
    sim = _ground_cloth(integrator, dt)
    sim.advance(2.0)
    z = sim.positions[:, 2]
    assert np.all(np.abs(z - H) <= 0.03 * H), (z.min(), z.max())
    assert np.abs(sim.velocities).max() < 1e-3


def test_cloth_drapes_over_a_sphere():
    scene = load_scene("drape")
    sim = scene.build_simulator()
    ball = sim.colliders[0]
    r, c = ball.radius, ball.center
    sim.advance(2.0)
    d = np.linalg.norm(sim.positions - c, axis=1) - r
    assert d.min() >= sim.thickness * (1 - 0.03)  # nothing inside r + thickness
    assert d.min() <= sim.thickness * 1.03  # it touches
    below = sim.positions[:, 2] < c[2]
    x = sim.positions[below]
    # it hangs on both sides of the ball, in both directions
    assert x[:, 0].min() < c[0] - r and x[:, 0].max() > c[0] + r
    assert x[:, 1].min() < c[1] - r and x[:, 1].max() > c[1] + r


@pytest.mark.parametrize(
    "integrator", ["symplectic_euler", "explicit_euler", "rk4", "verlet", "implicit_euler"]
)
@pytest.mark.parametrize("speed", [30.0, 300.0])
def test_a_fast_particle_does_not_tunnel_through_a_thin_box(integrator, speed):
    model = ClothModel.from_springs(
        [[0.0, 0.0, 0.1], [50.0, 50.0, 50.0]], [1.0, 1.0], [[0, 1]], [0.0], [0.0]
    )
    box = colliders.Box(center=(0.0, 0.0, 0.0), half_extents=(0.5, 0.5, 0.001), friction=0.2)
    sim = Simulator(
        model,
        integrator=integrator,
        dt=1e-3,
        gravity=(0, 0, 0),
        thickness=H,
        colliders=[box],
        max_speed=1e4,
    )
    v = np.zeros((2, 3))
    v[0] = (0.0, 0.0, -speed)
    sim.velocities = v
    for _ in range(20):
        sim.step()
        assert sim.positions[0, 2] >= 0.001 + H * (1 - 0.03)


def test_a_moving_box_carries_a_resting_particle_at_its_speed():
    model = ClothModel.from_springs(
        [[0.0, 0.0, 0.1 + H], [50.0, 50.0, 50.0]], [1.0, 1.0], [[0, 1]], [0.0], [0.0]
    )
    box = colliders.Box(center=(0.0, 0.0, 0.05), half_extents=(1.0, 1.0, 0.05), friction=1.0)
    dt, u = 1e-3, 0.5
    sim = Simulator(model, integrator="symplectic_euler", dt=dt, colliders=[box], thickness=H)
    for k in range(1, 1001):
        sim.set_collider_pose(0, (u * k * dt, 0.0, 0.05))
        sim.step()
    # it reaches the box's speed after u / (μ g) = 51 ms and then rides along
    assert sim.velocities[0, 0] == pytest.approx(u, rel=1e-9)
    assert sim.positions[0, 2] == pytest.approx(0.1 + H, abs=1e-9)
    slip = u * u / (2 * G)  # distance lost while it caught up
    assert sim.positions[0, 0] == pytest.approx(u * 1.0 - slip, rel=0.02)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "vbd"])
def test_a_particle_between_two_links_meeting_face_to_face_ends_inside_neither(integrator):
    """Two boxes meeting face to face, as a robot's upper arm and forearm do at the elbow: a
    particle pressed into the seam between them has no way out along either normal (pushed out of
    one, it is inside the other, and the way out is 0.2 m sideways). The contact stage leaves it
    on the seam, inside neither solid by their own signed distances (it left it a thickness
    inside the lower box, carried there step after step by friction)."""
    lower = colliders.Box(center=(0.0, 0.0, -0.1), half_extents=(0.2, 0.2, 0.1), friction=0.5)
    upper = colliders.Box(center=(0.0, 0.0, 0.1), half_extents=(0.2, 0.2, 0.1), friction=0.5)
    for z in (-0.3 * H, 0.3 * H, -0.9 * H):
        model = ClothModel.from_springs(
            [[0.0, 0.0, z], [0.01, 0.0, z]], [1e-3, 1e-3], [[0, 1]], [0.01], [1.0]
        )
        sim = Simulator(
            model, integrator=integrator, dt=1e-3, thickness=H, colliders=[lower, upper]
        )
        for _ in range(5):
            sim.step()
            x = sim.positions
            inside = min(
                float(lower.signed_distance(x).min()), float(upper.signed_distance(x).min())
            )
            assert inside >= -1e-9 * H, (z, inside / H)


def test_the_contact_stage_gives_the_same_bits_at_any_thread_count():
    """The contact stage's kernel runs its particles in tasks on every core: a 24×24 cloth (three
    tasks) thrown onto a box and a sphere that meet, half of it touching, ends every step with
    the same positions, velocities, number touching and the colliders' wrenches (each
    task's impulses summed in its particles' order, the tasks' sums in task order) at one and at
    two threads."""
    import numba

    from cloth_sim.contact.collider_kernels import CONTACT_CHUNK

    model = ClothModel.grid(24, 24, 0.02, 0.01, stiffness=200.0)
    assert model.n_particles > 2 * CONTACT_CHUNK
    runs = []
    threads = numba.get_num_threads()
    try:
        for n_threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(n_threads)
            sim = Simulator(
                model,
                integrator="symplectic_euler",
                dt=5e-4,
                thickness=H,
                colliders=[
                    colliders.Box(center=(0.2, 0.2, -0.1), half_extents=(0.3, 0.15, 0.1)),
                    colliders.Sphere(center=(0.25, 0.4, -0.05), radius=0.08, friction=0.3),
                ],
            )
            sim.velocities = np.tile([0.3, -0.2, -2.0], (model.n_particles, 1))
            steps = []
            for _ in range(120):
                sim.step()
                steps.append(
                    (
                        sim.positions,
                        sim.velocities,
                        np.array(sim.contact_counts[0]),
                        *sim.collider_wrench(0),
                        *sim.collider_wrench(1),
                    )
                )
            runs.append(steps)
    finally:
        numba.set_num_threads(threads)
    touching = int(runs[0][-1][2])
    assert model.n_particles // 4 < touching < model.n_particles
    assert np.abs(runs[0][-1][3]).max() > 0 and np.abs(runs[0][-1][5]).max() > 0
    for a, b in zip(*runs):
        assert all(np.array_equal(u, w) for u, w in zip(a, b))


def test_colliders_out_of_reach_change_nothing_where_a_cloth_lies_on_another():
    """A cloth landing on a box: a mesh block beside it (within its reach of the cloth's
    particles, beyond their thickness) and colliders far away leave every position to the bit
    as the box alone does. With more than one collider each touching particle is checked
    against them all after its projections (``collider_kernels.crease``), which answers a collider
    beyond the thickness without its exact distance."""
    import trimesh

    box = colliders.Box(center=(0.1, 0.1, -0.1), half_extents=(0.2, 0.2, 0.1), friction=0.4)
    block = trimesh.creation.box(extents=(0.05, 0.05, 0.05))
    others = [
        colliders.Mesh((block.vertices, block.faces), position=(0.1, -0.035, 0.025)),
        colliders.Mesh((block.vertices, block.faces), position=(3.0, 0.0, 0.0)),
        colliders.Sphere(center=(0.0, 0.0, 2.0), radius=0.1),
    ]
    runs = []
    for extra in ([], others):
        model = ClothModel.grid(10, 10, 0.02, 0.01, stiffness=200.0, origin=(0.0, 0.0, 0.01))
        sim = Simulator(
            model, integrator="symplectic_euler", dt=1e-3, thickness=H, colliders=[box, *extra]
        )
        sim.step(150)
        runs.append(sim.positions)
    near = np.linalg.norm(runs[1] - others[0].position, axis=1) - others[0].reach
    assert near.min() < 0.0  # the block's reach takes in particles of the cloth
    assert others[0].signed_distance(runs[1]).min() > 1.5 * H  # beyond the thickness
    assert np.array_equal(runs[0], runs[1])


def test_without_colliders_no_contact_code_runs_and_trajectories_are_unchanged():
    model = ClothModel.grid(8, 8, 0.05, 0.01, stiffness=300.0, damping=0.02, pinned=[(0, 0)])
    plain = Simulator(model, integrator="rk4", dt=1e-3, strain_limit=0.1)
    with_none = Simulator(
        model, integrator="rk4", dt=1e-3, strain_limit=0.1, colliders=[], self_collision=False
    )
    assert "contacts" not in with_none.active_stages
    assert "self_collision" not in with_none.active_stages
    plain.step(300)
    with_none.step(300)
    assert np.array_equal(plain.positions, with_none.positions)


def test_bad_collider_arguments_name_the_field():
    with pytest.raises(ValueError, match="radius"):
        colliders.Sphere(center=(0, 0, 0), radius=-1.0)
    with pytest.raises(ValueError, match="normal"):
        colliders.Plane(normal=(0, 0, 0))
    with pytest.raises(ValueError, match="half_extents"):
        colliders.Box(half_extents=(1, 1, 0))
    with pytest.raises(ValueError, match="friction"):
        colliders.Capsule(friction=float("nan"))
    model = ClothModel.grid(4, 4, 0.1, 0.01, stiffness=100.0)
    sim = Simulator(model, colliders=[colliders.Sphere(radius=0.1)])
    with pytest.raises(ValueError, match="index"):
        sim.set_collider_pose(3, (0, 0, 0))
    with pytest.raises(ValueError, match="position"):
        sim.set_collider_pose(0, (0, float("inf"), 0))
    with pytest.raises(ValueError, match="orientation"):
        sim.set_collider_pose(0, (0, 0, 0), (0, 0, 0, 0))
    assert np.array_equal(sim.colliders[0].center, (0, 0, 0))


def test_collider_distances_match_their_closed_forms():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, (200, 3))
    s = colliders.Sphere(center=(0.1, 0.2, 0.3), radius=0.4)
    assert np.allclose(s.signed_distance(pts), np.linalg.norm(pts - (0.1, 0.2, 0.3), axis=1) - 0.4)
    c = colliders.Capsule(a=(0, 0, -0.3), b=(0, 0, 0.3), radius=0.1)
    zc = np.clip(pts[:, 2], -0.3, 0.3)
    ref = np.linalg.norm(pts - np.stack([0 * zc, 0 * zc, zc], 1), axis=1) - 0.1
    assert np.allclose(c.signed_distance(pts), ref)
    # a box turned 90° about z swaps its x and y extents
    b = colliders.Box(
        center=(0, 0, 0),
        half_extents=(0.5, 0.1, 0.2),
        orientation=(math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)),
    )
    q = np.abs(pts) - (0.1, 0.5, 0.2)
    ref = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
    assert np.allclose(b.signed_distance(pts), ref)
    p = colliders.Plane(normal=(0, 0, 2), offset=0.25)
    assert np.allclose(p.signed_distance(pts), pts[:, 2] - 0.25)
    # moving: a plane lifted by set_pose keeps its normal
    p.set_pose((0, 0, 1.0))
    assert np.allclose(p.signed_distance(pts), pts[:, 2] - 1.0)


# --------------------------------------------------------------------------- self-collision
def _fold(self_collision: bool):
    return springy_fold(self_collision)


def _count_crossings(sim, seconds, stop_at_first=False):
    tris = sim.model.triangles
    total = 0
    for _ in range(int(round(seconds / sim.dt))):
        x0 = sim.positions.copy()
        sim.step()
        total += len(crossings(x0, sim.positions, tris))
        if total and stop_at_first:
            break
    return total


def test_crossing_check_finds_a_particle_passing_through_a_triangle():
    x0 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 0.5]], float)
    x1 = x0.copy()
    x1[3, 2] = -0.5
    assert crossings(x0, x1, np.array([[0, 1, 2]])) == [(3, 0)]
    x1[3, 0] = 2.0  # passes beside it
    assert crossings(x0, x1, np.array([[0, 1, 2]])) == []


def test_a_stage_after_vbd_is_kept_from_pushing_a_vertex_through_the_cloth():
    """vbd keeps the cloth uncrossed inside its step; the contact stage after it (the exact finish
    against the colliders) is wrapped so that what it moves cannot cross: a stage that pushes one
    particle of a two-layer cloth down through the layer under it is scaled back short of it (the
    independent check finds no crossing), one that moves it less than the gap is left whole."""
    from cloth_sim.contact.self_collision import SelfCollision, Uncrossed

    model = ClothModel.grid(6, 6, 0.02, 0.001, stiffness=100.0)
    x = model.positions.copy()
    top = x.copy()
    top[:, 2] += 0.004  # a second sheet 4 mm above, as a fold lies
    n = len(x)
    tris = np.vstack([model.triangles, model.triangles + n])
    both = ClothModel.from_springs(
        np.vstack([x, top]), np.tile(model.masses, 2), np.vstack([model.springs,
        model.springs + n]), np.tile(model.stiffness, 2), np.tile(model.damping, 2),
        triangles=tris,
    )  # fmt: skip
    sim = Simulator(both, integrator="vbd", dt=1 / 60, gravity=(0, 0, 0))
    layers = SelfCollision(both, thickness=0.002, enabled=True)
    p = n + 14  # a particle of the top sheet over the middle of the bottom one

    class Push:
        name, active = "contacts", True

        def __init__(self, by):
            self.by = np.asarray(by, float)

        def apply(self, state, start, dt, follow, origin=None):
            state.x[p] += self.by

    for by, whole in (([0.0, 0.0, -0.01], False), ([0.003, 0.0, 0.0], True)):
        guard = Uncrossed(Push(by), layers)
        state = sim.state.copy()
        before = state.x.copy()
        guard.apply(state, state, sim.dt, 1.0)
        assert crossings(before, state.x, tris) == []
        assert np.allclose(state.x[p] - before[p], by, rtol=0, atol=1e-15) == whole
        assert (guard.last_slowed == 0) == whole
        moved = state.x[p] - before[p]
        assert np.allclose(np.cross(moved, by), 0) and moved @ np.asarray(by) > 0


def test_fold_without_self_collision_crosses_itself():
    assert _count_crossings(_fold(False), 1.5, stop_at_first=True) > 0


def test_fold_with_self_collision_never_crosses_itself():
    sim = _fold(True)
    assert _count_crossings(sim, 1.5) == 0
    # and it did fold: layers over each other (cloth above cloth in the same place)
    assert sim.positions[:, 2].max() > 2 * sim.thickness


# --------------------------------------------------------------------------- scenes
@pytest.mark.parametrize("name", ["table", "drape", "fold"])
def test_contact_scenes_load_and_keep_the_thickness(name):
    sim = load_scene(name).build_simulator()
    assert "contacts" in sim.active_stages
    sim.advance(0.5)
    for c in sim.colliders:
        assert c.signed_distance(sim.positions).min() >= sim.thickness * (1 - 0.03)


def test_table_scene_half_hangs_over_the_edge():
    sim = load_scene("table").build_simulator()
    sim.advance(2.0)
    table = sim.colliders[0]
    edge = table.center[0] + table.half_extents[0]
    top = table.center[2] + table.half_extents[2]
    on = sim.positions[:, 0] < edge
    assert np.all(
        np.abs(sim.positions[on & (sim.positions[:, 0] < edge - 0.1), 2] - top - sim.thickness)
        < 0.03 * sim.thickness
    )
    assert sim.positions[~on, 2].min() < top - 0.2  # the rest hangs down


@pytest.mark.parametrize(
    "bad,field",
    [
        ({"colliders": {"type": "plane"}}, "colliders"),
        ({"colliders": [{"type": "cone"}]}, "colliders[0].type"),
        ({"colliders": [{"type": "sphere", "center": [0, 0, 0]}]}, "colliders[0].radius"),
        (
            {"colliders": [{"type": "sphere", "center": [0, 0], "radius": 1}]},
            "colliders[0].center",
        ),
        (
            {"colliders": [{"type": "sphere", "center": [0, 0, 0], "radius": -1}]},
            "colliders[0].radius",
        ),
        (
            {
                "colliders": [
                    {
                        "type": "box",
                        "center": [0, 0, 0],
                        "half_extents": [1, 1, 1],
                        "orientation": [0, 0, 0, 0],
                    }
                ]
            },
            "colliders[0].orientation",
        ),
        (
            {"colliders": [{"type": "plane", "normal": [0, 0, 1], "friction": -0.1}]},
            "colliders[0].friction",
        ),
        ({"colliders": [{"type": "plane", "normal": [0, 0, 1], "size": 3}]}, "colliders[0].size"),
        (
            {"colliders": [{"type": "capsule", "a": [0, 0, 0], "b": [1, 0, 0], "radius": "x"}]},
            "colliders[0].radius",
        ),
        ({"thickness": 0.0}, "thickness"),
        ({"thickness": "thin"}, "thickness"),
        ({"self_collision": "yes"}, "self_collision"),
        ({"grid": {"rows": 4, "cols": 4, "spacing": 0.1, "origin": [0, 0]}}, "grid.origin"),
    ],
)
def test_scene_collider_fields_are_validated(bad, field):
    data = {"grid": {"rows": 4, "cols": 4, "spacing": 0.1}}
    data.update(bad)
    with pytest.raises(SceneError) as e:
        scene_from_dict(data, source="bad.yaml")
    assert field in str(e.value) and "bad.yaml" in str(e.value)


def test_self_collision_refuses_a_thickness_beyond_half_an_edge():
    model = ClothModel.grid(8, 8, 0.02, 0.01, stiffness=100.0)
    with pytest.raises(ValueError, match="thickness"):
        Simulator(model, thickness=0.011, self_collision=True)
    sim = Simulator(model, thickness=0.011)
    with pytest.raises(ValueError, match="thickness"):
        sim.self_collision = True
    assert not sim.self_collision
    sim.thickness = 0.01
    sim.self_collision = True
    with pytest.raises(ValueError, match="thickness"):
        sim.thickness = 0.02
    assert sim.thickness == 0.01
    with pytest.raises(SceneError, match="thickness"):
        scene_from_dict(
            {
                "grid": {"rows": 4, "cols": 4, "spacing": 0.02},
                "thickness": 0.011,
                "self_collision": True,
            }
        )


def _brute_force_pairs(x, tris, edges, reach):
    """Every (particle, triangle) pair within the particle's ``reach`` plus the triangle's (the
    largest of its corners') with its exact distance (the projection on the plane when it falls
    inside, else the nearest of the three sides), and every (edge, edge) pair sharing no particle
    whose distance, sampled at 401 points along the first edge, is within 1 % above the two edges'
    reaches — all by testing every pair with numpy (those whose boxes lie farther apart than that
    along some axis skipped)."""

    def seg_point(p, a, b):
        ab = b - a
        t = np.clip(((p - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
        return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)

    tri_pairs = {}
    for i, (a, b, c) in enumerate(tris):
        p = np.setdiff1d(np.arange(len(x)), [a, b, c])
        A, B, C, P = x[a], x[b], x[c], x[p]
        nrm = np.cross(B - A, C - A)
        nrm /= np.linalg.norm(nrm)
        h = (P - A) @ nrm
        q = P - h[:, None] * nrm  # projection onto the plane
        # barycentric inside test of the projection
        v0, v1, v2 = C - A, B - A, q - A
        d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
        d02, d12 = v2 @ v0, v2 @ v1
        den = d00 * d11 - d01 * d01
        u = (d11 * d02 - d01 * d12) / den
        v = (d00 * d12 - d01 * d02) / den
        inside = (u >= 0) & (v >= 0) & (u + v <= 1)
        d = np.where(
            inside,
            np.abs(h),
            np.minimum.reduce([seg_point(P, A, B), seg_point(P, B, C), seg_point(P, C, A)]),
        )
        within = d < reach[p] + reach[[a, b, c]].max()
        for pp, dd in zip(p[within], d[within]):
            tri_pairs[(int(pp), i)] = dd
    edge_pairs = {}
    s = np.linspace(0.0, 1.0, 401)
    edge_reach = reach[edges].max(axis=1)
    for e, (a, b) in enumerate(edges):
        f = np.arange(e + 1, len(edges))
        f = f[~np.isin(edges[f], [a, b]).any(axis=1)]
        # only the edges whose boxes come within 1.01 reaches of e's on every axis can be that
        # close (their distance is at least the gap between the boxes along any axis)
        lo_e, hi_e = np.minimum(x[a], x[b]), np.maximum(x[a], x[b])
        lo_f = np.minimum(x[edges[f, 0]], x[edges[f, 1]])
        hi_f = np.maximum(x[edges[f, 0]], x[edges[f, 1]])
        gap = np.maximum(lo_f - hi_e, lo_e - hi_f).max(axis=1)
        f = f[gap < (edge_reach[e] + edge_reach[f]) * 1.01]
        # segment–segment distance, densely sampled along e against f exactly
        pts = x[a] + s[:, None] * (x[b] - x[a])  # (401, 3)
        c, d = x[edges[f, 0]], x[edges[f, 1]]
        dist = seg_point(pts[:, None, :], c[None], d[None]).min(axis=0)
        within = dist < (edge_reach[e] + edge_reach[f]) * 1.01
        for ff, dd in zip(f[within], dist[within]):
            edge_pairs[(e, int(ff))] = dd
    return tri_pairs, edge_pairs


def _folded_cloth(rng):
    """A 10×10 cloth (2 cm spacing) whose rows fold over at row 4.5, 6 mm above, jittered by
    ``rng``, with particle 44 in no triangle: ``(model, positions, triangles, features)``."""
    from cloth_sim.contact.self_collision import _features

    model = ClothModel.grid(10, 10, 0.02, 0.01, stiffness=100.0)
    r, c = np.divmod(np.arange(100), 10)
    x = np.stack(
        [0.02 * c, 0.02 * np.where(r < 5, r, 9 - r) + 0.01 * (r >= 5), 0.006 * (r >= 5)], axis=1
    ) + rng.normal(scale=0.002, size=(100, 3))
    tris = model.triangles[~(model.triangles == 44).any(axis=1)]
    return model, x, tris, _features(tris, 100)


def _same_pairs(want, got) -> bool:
    """Whether two answers ``(vf, vf_distance, ee, ee_distance)`` hold the same pairs with the
    same distances, to the bit, in whatever order."""
    for pairs_w, d_w, pairs_g, d_g in ((*want[:2], *got[:2]), (*want[2:], *got[2:])):
        ow = np.lexsort((pairs_w[:, 1], pairs_w[:, 0]))
        og = np.lexsort((pairs_g[:, 1], pairs_g[:, 0]))
        if not (np.array_equal(pairs_w[ow], pairs_g[og]) and np.array_equal(d_w[ow], d_g[og])):
            return False
    return True


def _in_rank_order(answer, ranks) -> bool:
    """Whether an answer's pairs come by the tree's rank of their first index, then by their
    second index, each once (pair_list's order: an answer does not depend on the list's
    history)."""
    for pairs, rank in ((answer[0], ranks[0]), (answer[2], ranks[1])):
        keys = np.stack([rank[pairs[:, 0]], pairs[:, 1]], axis=1)
        step = np.diff(keys, axis=0)
        if not np.all((step[:, 0] > 0) | ((step[:, 0] == 0) & (step[:, 1] > 0))):
            return False
    return True


def test_the_kept_pairs_of_a_cloth_with_nothing_to_pair_are_none():
    """A kept list over no particles answers no pairs, with a skin or without (it has no order
    of its features to give them in)."""
    from cloth_sim.contact.self_collision import _features

    none = np.zeros((0, 3), np.int64)
    kept = PairList(TriangleTree(none, np.zeros((0, 3)), _features(none, 0)))
    for skin in (0.002, 0.0):
        assert [len(a) for a in kept.pairs(np.zeros((0, 3)), 0.01, skin)] == [0, 0, 0, 0]


def test_the_kept_pairs_refreshed_for_the_particles_that_outran_them_are_the_trees():
    """The kept list (pair_list) where some particles outran their skin: their pairs searched
    again from where they are, the others' kept (a pair's cover is its features': each one's
    largest reach plus its corners' largest motion within the largest reach the list gave
    them). On the folded, jittered cloth, 200 queries of random motions (most particles still,
    a few moving farther than the skin, some reaches growing or shrinking): every
    answer holds the tree's pairs and distances to the bit, in the same order as a new list's
    (an answer does not depend on the list's history); most queries are answered by refreshes,
    a few by whole searches."""
    rng = np.random.default_rng(5)
    model, x, tris, features = _folded_cloth(rng)
    tree = TriangleTree(tris, model.positions, features)
    kept = PairList(TriangleTree(tris, model.positions, features))
    skin = 0.002
    base = rng.uniform(0.001, 0.004, 100)
    for k in range(200):
        reach = base * np.where(rng.random(100) < 0.05, rng.uniform(0.2, 3.0, 100), 1.0)
        moving = rng.random(100) < (0.6 if k % 50 == 49 else 0.04)
        x = x + moving[:, None] * rng.normal(scale=0.0015, size=(100, 3))
        x = x + rng.normal(scale=0.0001, size=(100, 3))
        want = tree.pairs(x, reach)
        got = kept.pairs(x, reach, skin)
        assert _same_pairs(want, got)
        if k % 10 == 0:  # the same arrays in the same order as a list with no history
            fresh = PairList(TriangleTree(tris, model.positions, features)).pairs(x, reach, skin)
            assert all(np.array_equal(a, b) for a, b in zip(got, fresh))
            assert _in_rank_order(got, tree_ranks(tree)) and len(got[0]) and len(got[2])
    assert kept.refreshes >= 100 and 4 <= kept.searches <= 40, (kept.refreshes, kept.searches)


@pytest.mark.parametrize("reaches", ["radius", "per particle"])
def test_self_collision_search_finds_every_pair_within_reach_at_any_thread_count(reaches):
    """The particle–triangle and edge–edge searches (a hierarchy over the triangles, traversed in
    tasks on every core) against a brute-force test of every pair on a crumpled cloth with a lone
    particle in no triangle: one radius for all, or a reach per particle (a pair within the sum of
    its sides' reaches); the same arrays at 1 and 2 threads, and with rows too few for the pairs
    (the search runs again, larger)."""
    import numba

    from cloth_sim.contact.collision_tree import TriangleTree

    rng = np.random.default_rng(3)
    model, x, tris, features = _folded_cloth(rng)
    edges = features[0]
    radius = 0.012 if reaches == "radius" else rng.uniform(0.002, 0.008, 100)
    reach = np.full(100, radius / 2) if reaches == "radius" else radius
    tri_truth, edge_truth = _brute_force_pairs(x, tris, edges, reach)
    assert len(tri_truth) > 150 and len(edge_truth) > 150  # plenty to find
    assert any(p == 44 for p, _ in tri_truth)  # the lone particle is near triangles
    threads = numba.get_num_threads()
    runs = []
    try:
        for n_threads, rows in (
            (1, None),
            (min(2, numba.config.NUMBA_NUM_THREADS), None),
            (min(2, numba.config.NUMBA_NUM_THREADS), 1),
        ):
            numba.set_num_threads(n_threads)
            tree = TriangleTree(tris, model.positions, features)
            if rows is not None:
                tree.caps[:] = rows
            runs.append(tree.pairs(x, radius))
    finally:
        numba.set_num_threads(threads)
    pairs, dist, e_pairs, e_dist = runs[0]
    found = {tuple(p): d for p, d in zip(pairs.tolist(), dist)}
    assert found.keys() == tri_truth.keys()
    assert max(abs(found[k] - tri_truth[k]) for k in found) < 1e-12
    e_found = {tuple(p): d for p, d in zip(e_pairs.tolist(), e_dist)}
    # the sampled truth is within 1 % of the reach of the exact distance: every exact pair is in
    # it, and what it adds lies within that band
    assert e_found.keys() <= edge_truth.keys()
    edge_reach = reach[edges].max(axis=1)
    assert all(
        edge_truth[k] >= edge_reach[k[0]] + edge_reach[k[1]]
        for k in edge_truth.keys() - e_found.keys()
    )
    step = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1).max() / 400  # the sampling's
    assert all(-1e-12 <= edge_truth[k] - e_found[k] <= step for k in e_found)
    assert len(found) == len(pairs) and len(e_found) == len(e_pairs)  # each pair once
    assert np.all(e_pairs[:, 0] < e_pairs[:, 1])
    for other in runs[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(runs[0], other))


def test_a_search_for_some_particles_finds_the_whole_searchs_pairs_of_their_features():
    """``pairs_touching``: on the folded, jittered cloth with a lone particle, for touched sets
    from one particle to most of them, the pairs of the whole search that have a feature with a
    touched particle (the particle or a corner of the triangle; an end of either edge), the same
    arrays in the same order, and nothing else; the whole search's rows stay as they were."""
    rng = np.random.default_rng(7)
    model, x, tris, features = _folded_cloth(rng)
    edges = features[0]
    tree = TriangleTree(tris, model.positions, features)
    for share in (0.01, 0.05, 0.2, 0.6):
        reach = rng.uniform(0.002, 0.008, 100)
        touched = rng.random(100) < share
        touched[[44, int(rng.integers(100))]] = share < 0.1, True
        vf, vf_d, ee, ee_d = tree.pairs(x, reach)
        caps = tree.caps.copy()
        got = tree.pairs_touching(x, reach, touched)
        keep = touched[vf[:, 0]] | touched[tris[vf[:, 1]]].any(axis=1)
        keep_e = touched[edges[ee]].any(axis=(1, 2))
        assert keep.any() and keep_e.any() and not keep_e.all()
        want = (vf[keep], vf_d[keep], ee[keep_e], ee_d[keep_e])
        assert all(np.array_equal(a, b) for a, b in zip(got, want))
        assert np.array_equal(tree.caps, caps)
    nothing = tree.pairs_touching(x, reach, np.zeros(100, bool))
    assert [len(a) for a in nothing] == [0, 0, 0, 0]


def test_a_search_where_few_particles_reach_walks_their_leaves_with_the_whole_walks_answer(
    monkeypatch,
):
    """A pair is kept only within the sum of its sides' reaches, so where most reaches are 0 (the
    guard after a contact stage that pushed a few particles) the search walks only the leaves
    holding the others: against a brute-force test of every pair, and the same arrays in the
    same order as the whole walk (forced by a share of 0), from one reaching particle to half."""
    from cloth_sim.contact import collision_tree

    rng = np.random.default_rng(11)
    model, x, tris, features = _folded_cloth(rng)
    edges = features[0]
    for share in (0.01, 0.1, 0.5):
        reach = rng.uniform(0.004, 0.012, 100) * (rng.random(100) < share)
        reach[int(rng.integers(100))] = 0.01
        tri_truth, edge_truth = _brute_force_pairs(x, tris, edges, reach)
        got = TriangleTree(tris, model.positions, features).pairs(x, reach)
        assert len(got[0]) and len(got[2])
        assert {tuple(p) for p in got[0].tolist()} == tri_truth.keys()
        assert {tuple(p) for p in got[2].tolist()} <= edge_truth.keys()
        with monkeypatch.context() as m:
            m.setattr(collision_tree, "REACHING_WALK_SHARE", 0.0)
            whole = TriangleTree(tris, model.positions, features).pairs(x, reach)
        assert all(np.array_equal(a, b) for a, b in zip(got, whole))
    nothing = TriangleTree(tris, model.positions, features).pairs(x, np.zeros(100))
    assert [len(a) for a in nothing] == [0, 0, 0, 0]


def test_vbd_searches_again_for_the_vertices_that_met_their_bounds_as_a_whole_search_would():
    """During the iterations, where a few vertices met their bounds, only those (and those near
    a collider that used half their allowance) are searched again: every other vertex keeps its
    place, allowance and pairs. The pairs then held are those a whole search finds from the
    places held (robot_sweep, its link pushing the sheet: every such search checked), and the
    vertices never come nearer to each other than the bounds allow (no crossing)."""
    sim = load_scene("robot_sweep").build_simulator()
    vbd = sim._integrator
    sc = vbd._self_collision
    checked = []
    searched = vbd._detect_touching

    def check(x, y, colliders, tau, x_cd, met):
        searched(x, y, colliders, tau, x_cd, met)
        vt, vt_d, ee, ee_d, allowance = vbd._found
        want = TriangleTree(sc.triangles, sim.model.positions, sc.features).pairs(
            x_cd, 0.5 * tau + allowance
        )
        have_vt = dict(zip(map(tuple, vt.tolist()), vt_d))
        have_ee = dict(zip(map(tuple, ee.tolist()), ee_d))
        assert len(have_vt) == len(vt) and len(have_ee) == len(ee)  # each pair once
        assert have_vt == dict(zip(map(tuple, want[0].tolist()), want[1]))
        assert have_ee == dict(zip(map(tuple, want[2].tolist()), want[3]))
        checked.append(int(met.sum()))

    vbd._detect_touching = check
    before = sim.positions.copy()
    for _ in range(150):
        sim.step()
        assert crossings(before, sim.positions, sc.triangles) == []
        before = sim.positions.copy()
    assert len(checked) > 20 and min(checked) >= 1
    assert max(checked) <= 0.03 * sim.model.n_particles


def test_a_search_keeps_its_rows_and_gives_back_what_one_crowded_search_grew(monkeypatch):
    """The search's rows (a block per task) are kept from search to search: a search allocates
    far less than they hold (made fresh each time, rows grown by one crowded moment cost more
    than the walk: 1.4 GB mapped a search on Newton's shirt). Rows far beyond what the searches
    need shrink back, and every answer is the one a fresh tree gives."""
    import tracemalloc

    from cloth_sim.contact import collision_tree
    from cloth_sim.contact.self_collision import _features

    model = ClothModel.grid(12, 12, 0.02, 0.01, stiffness=100.0)
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 0.05, size=(144, 3))  # crumpled into a 5 cm box: every pair is near
    features = _features(model.triangles, 144)
    tree = TriangleTree(model.triangles, model.positions, features)
    crowded = tree.pairs(x, 0.05)
    assert len(crowded[0]) > 10_000
    held = int(tree.caps.sum()) * len(tree.tasks) * 24  # bytes: two ints and a distance a row
    tracemalloc.start()
    try:
        again = tree.pairs(x, 0.05)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert all(np.array_equal(a, b) for a, b in zip(crowded, again))
    answer = sum(a.nbytes for a in again)
    assert peak < answer + held / 4, (peak, answer, held)  # the answer, not another set of rows
    # the rows shrink once they are far more than a search needs (here at any size)
    monkeypatch.setattr(collision_tree, "KEEP_ROWS", 0)
    big = tree.caps.copy()
    sparse = tree.pairs(model.positions, 0.004)
    assert np.all(tree.caps < big)
    fresh = TriangleTree(model.triangles, model.positions, features)
    for ours, theirs in zip(
        (sparse, tree.pairs(x, 0.05)),
        (fresh.pairs(model.positions, 0.004), fresh.pairs(x, 0.05)),
    ):
        assert all(np.array_equal(a, b) for a, b in zip(ours, theirs))


def test_the_guard_after_vbd_is_answered_by_vbd_s_last_search_as_the_tree_would():
    """After ``vbd``'s step the contact stage's push is kept from crossing the cloth
    (``Uncrossed``) by the pairs closer than its displacements: a query the last candidate
    search of the step covers (pair_list's cover: every primitive's reach plus its motion since
    within what that search gave it) is answered from that search's pairs, without another walk
    of the tree. On the T-shirt landing and resting on its table, every answer holds the tree's
    pairs and distances, to the bit, and the guard's come without a walk."""
    sim = load_scene("tshirt").build_simulator()
    stage = sim._self_collision
    tree = TriangleTree(stage.triangles, sim.model.positions, stage.features)
    sim.step()
    walk, walks = stage._pairs.tree.pairs, [0]

    def counted(x0, radius):
        walks[0] += 1
        return walk(x0, radius)

    stage._pairs.tree.pairs = counted
    kept = stage.candidates
    guards = [0, 0]  # the guard's queries, and those answered without a walk of the tree

    def checked(x0, reach, skin=0.0):
        before = walks[0]
        got = kept(x0, reach, skin)
        want = tree.pairs(x0, reach)  # every query's answer, vbd's own searches too
        assert _same_pairs(want, got)
        if isinstance(sys._getframe(1).f_locals.get("self"), Uncrossed):
            guards[0] += 1
            guards[1] += walks[0] == before
        return got

    stage.candidates = checked
    steps = int(round(2.0 / sim.dt))  # it lands at 0.14 s and flattens
    sim.step(steps)
    assert guards[0] >= 0.5 * steps and guards[1] >= 0.9 * guards[0]  # (108 of 108)


def test_the_kept_pairs_answer_as_the_tree_does_and_search_again_when_a_particle_outruns_them():
    """Self-collision's candidate pairs kept between searches (pair_list): on the fold scene's
    cotton piling onto itself at 12×12 (1.5 s of falling, folding and settling, every query the
    stage made), the kept list's answer holds the tree's own pairs with the same distances, to
    the bit, while most queries are answered without a whole search; a particle moved farther
    than the skin allows has its pairs searched again, alone."""
    sim = load_scene("fold").build_simulator(rows=12, cols=12)
    stage = sim._self_collision
    tree = TriangleTree(stage.triangles, sim.model.positions, stage.features)
    kept = PairList(TriangleTree(stage.triangles, sim.model.positions, stage.features))
    found = [0]

    def both(x0, reach, skin=0.0):
        want = tree.pairs(x0, reach)
        got = kept.pairs(x0, reach, SKIN * stage.thickness)
        assert _same_pairs(want, got)
        found[0] += len(want[0]) + len(want[2])
        return want

    assert stage.keeps_pairs  # 12×12 over 1 m, 7.5 mm: the stage keeps its pairs here
    assert not load_scene("fold").build_simulator(rows=48, cols=48)._self_collision.keeps_pairs
    stage.candidates = both
    sim.advance(1.5)
    assert found[0] > 1000  # it did pile up
    assert kept.queries >= 1500 and kept.searches < 0.5 * kept.queries  # (379 of 1,506)
    x = sim.positions.copy()
    reach = np.full(len(x), 0.5 * stage.thickness)
    searches, refreshes = kept.searches, kept.refreshes
    kept.pairs(x, reach, SKIN * stage.thickness)
    assert (kept.searches, kept.refreshes) == (searches, refreshes)  # at rest: covered
    x[7] += 1.01 * SKIN * stage.thickness
    want = tree.pairs(x, reach)
    got = kept.pairs(x, reach, SKIN * stage.thickness)
    assert (kept.searches, kept.refreshes) == (searches, refreshes + 1)
    assert _same_pairs(want, got)
