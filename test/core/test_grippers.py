"""Grippers: rigid holds that follow their pose exactly, report the cloth's pull (checked against
the weight of a cloth at rest), hand their velocity over on release, and refuse bad input."""

import math

import numpy as np
import pytest

from cloth_sim import ClothModel, Simulator, integrators

G = np.array([0.0, 0.0, -9.81])
IMPLICIT = ("implicit_euler", "implicit_euler_prefactored")


def _cloth(n=10, **kw):
    model = ClothModel.grid(
        n, n, 0.05, 0.01, stiffness={"structural": 500, "shear": 500, "bend": 50}, damping=0.5
    )
    return model, Simulator(model, **kw)


def _dt(name):
    return 1.0 / 120 if name in IMPLICIT else 1e-3


@pytest.mark.parametrize("integrator", integrators.available())
def test_grasped_particles_follow_the_commanded_pose_exactly(integrator):
    model, sim = _cloth(integrator=integrator, dt=_dt(integrator))
    idx = sim.grasp("left", (0.0, 0.0, 0.0), 0.06)
    assert (
        len(idx) == 3
        and list(sim.grippers) == ["left"]
        and np.array_equal(sim.grippers["left"], idx)
    )
    steps = int(round(0.5 / sim.dt))
    for k in range(1, steps + 1):  # lift 0.2 m while turning 30° about z
        a = math.radians(30) * k / steps
        sim.set_gripper_pose(
            "left", (0.0, 0.0, 0.2 * k / steps), (math.cos(a / 2), 0, 0, math.sin(a / 2))
        )
        sim.step()
        c, s = math.cos(a), math.sin(a)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        want = np.array([0.0, 0.0, 0.2 * k / steps]) + model.positions[idx] @ R.T
        assert np.abs(sim.positions[idx] - want).max() < 1e-9
    position, orientation = sim.gripper_pose("left")
    assert np.allclose(position, (0, 0, 0.2)) and orientation[0] == pytest.approx(
        math.cos(math.radians(15))
    )


@pytest.mark.parametrize("strain_limit", [None, 0.1])
@pytest.mark.parametrize("integrator", integrators.available())
def test_a_cloth_hanging_at_rest_pulls_its_gripper_with_its_weight(integrator, strain_limit):
    model, sim = _cloth(
        integrator=integrator, dt=_dt(integrator), strain_limit=strain_limit, drag=0.05
    )
    idx = sim.grasp("corner", (0.0, 0.0, 0.0), 0.01)
    sim.advance(6.0)
    force, torque = sim.gripper_wrench("corner")
    free = np.ones(model.n_particles, bool)
    free[idx] = False
    weight = model.masses[free].sum() * G
    assert np.linalg.norm(force - weight) <= 0.01 * np.linalg.norm(weight)
    # one particle held at the gripper's own position: no moment about it
    assert np.linalg.norm(torque) < 1e-9


def test_vbds_substeps_corrections_all_reach_the_grippers_pull():
    """``vbd`` at 1/60 s steps this cloth in several substeps, and the strain limit corrects after
    each: the pull on the gripper gathers every substep's corrections (the last alone would miss
    most of the weight the limit carries)."""
    model, sim = _cloth(integrator="vbd", dt=1 / 60, strain_limit=0.1, drag=0.05)
    idx = sim.grasp("corner", (0.0, 0.0, 0.0), 0.01)
    sim.advance(6.0)
    assert sim.integrator_stats["last_substeps"] > 1
    assert sim.max_strain() > 0.099  # the limit carries part of the weight
    force, _ = sim.gripper_wrench("corner")
    free = np.ones(model.n_particles, bool)
    free[idx] = False
    weight = model.masses[free].sum() * G
    assert np.linalg.norm(force - weight) <= 0.01 * np.linalg.norm(weight)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "implicit_euler"])
def test_two_grippers_share_the_weight(integrator):
    model, sim = _cloth(integrator=integrator, dt=_dt(integrator), drag=0.05, strain_limit=0.1)
    a = sim.grasp("a", (0.0, 0.0, 0.0), 0.01)
    b = sim.grasp("b", (0.45, 0.0, 0.0), 0.01)
    sim.advance(6.0)
    fa, _ = sim.gripper_wrench("a")
    fb, _ = sim.gripper_wrench("b")
    free = np.ones(model.n_particles, bool)
    free[np.concatenate([a, b])] = False
    weight = model.masses[free].sum() * G
    assert np.linalg.norm(fa + fb - weight) <= 0.01 * np.linalg.norm(weight)
    assert fa[2] == pytest.approx(fb[2], rel=0.02)  # symmetric


@pytest.mark.parametrize("integrator", integrators.available())
def test_released_particles_keep_the_grippers_velocity_and_the_cloth_falls_freely(integrator):
    model, sim = _cloth(integrator=integrator, dt=_dt(integrator))
    idx = sim.grasp("g", (0.0, 0.0, 0.0), 0.06)
    u = np.array([0.3, 0.0, 0.4])
    for k in range(1, 31):
        sim.set_gripper_pose("g", u * sim.dt * k)
        sim.step()
    assert np.allclose(sim.velocities[idx], u, atol=1e-9)
    sim.release("g")
    assert sim.grippers == {}
    assert np.allclose(sim.velocities[idx], u, atol=1e-9)  # no jerk
    m = model.masses[:, None]
    c0 = (m * sim.positions).sum(0) / m.sum()
    v0 = (m * sim.velocities).sum(0) / m.sum()
    t0 = sim.time
    sim.advance(t0 + 0.3)
    t = sim.time - t0
    c = (m * sim.positions).sum(0) / m.sum()
    want = c0 + v0 * t + 0.5 * G * t * t
    assert np.linalg.norm(c - want) < 0.6 * 9.81 * t * sim.dt + 1e-9  # first order in dt


def test_bad_gripper_input_is_refused_and_changes_nothing():
    model, sim = _cloth()
    with pytest.raises(
        ValueError, match=r"point \[5.0, 5.0, 5.0\].*radius 0.01|radius 0.01.*point"
    ):
        sim.grasp("g", (5.0, 5.0, 5.0), 0.01)
    with pytest.raises(ValueError, match="radius"):
        sim.grasp("g", (0, 0, 0), -1.0)
    with pytest.raises(ValueError, match="point"):
        sim.grasp("g", (0, float("nan"), 0), 0.1)
    assert sim.grippers == {}
    sim.grasp("g", (0, 0, 0), 0.01)
    with pytest.raises(ValueError, match="already"):
        sim.grasp("g", (0.45, 0, 0), 0.01)
    with pytest.raises(ValueError, match="unknown gripper 'h'; grippers: g"):
        sim.set_gripper_pose("h", (0, 0, 0))
    with pytest.raises(ValueError, match="unknown gripper"):
        sim.release("h")
    with pytest.raises(ValueError, match="unknown gripper"):
        sim.gripper_wrench("h")
    with pytest.raises(ValueError, match="position"):
        sim.set_gripper_pose("g", (0, 0, float("inf")))
    with pytest.raises(ValueError, match="orientation"):
        sim.set_gripper_pose("g", (0, 0, 0), (0, 0, 0, 0))
    before = sim.positions.copy()
    sim.step()
    assert np.array_equal(sim.positions[sim.grippers["g"]], before[sim.grippers["g"]])


def test_a_grasp_with_no_grippers_costs_nothing_and_release_restores_the_model():
    model, sim = _cloth()
    assert sim.model is model
    sim.grasp("g", (0, 0, 0), 0.01)
    assert sim.model is not model and sim.model.pinned.sum() == 1
    sim.release("g")
    assert sim.model is model


def test_a_scene_declares_grippers_and_checks_them():
    from cloth_sim.scene import SceneError, scene_from_dict

    grid = {"rows": 6, "cols": 6, "spacing": 0.1}
    scene = scene_from_dict(
        {
            "grid": grid,
            "grippers": [
                {"name": "left", "point": [0, 0, 0], "radius": 0.01},
                {"name": "right", "point": [0.5, 0, 0], "radius": 0.01},
            ],
        }
    )
    sim = scene.build_simulator()
    assert {k: v.tolist() for k, v in sim.grippers.items()} == {"left": [0], "right": [5]}
    # a coarser grid than the radius allows: the nearest particle is held
    sim = scene.build_simulator(rows=3, cols=3, spacing=0.2)
    assert {k: v.tolist() for k, v in sim.grippers.items()} == {"left": [0], "right": [2]}
    for bad, field in [
        ({"name": "a/b", "point": [0, 0, 0], "radius": 0.1}, "grippers[0].name"),
        ({"name": "a", "point": [0, 0], "radius": 0.1}, "grippers[0].point"),
        ({"name": "a", "point": [0, 0, 0], "radius": 0.0}, "grippers[0].radius"),
        ({"name": "a", "point": [0, 0, 0], "radius": 0.1, "grip": 1}, "grippers[0].grip"),
    ]:
        with pytest.raises(SceneError, match=field.replace("[", r"\[").replace("]", r"\]")):
            scene_from_dict({"grid": grid, "grippers": [bad]}, source="s.yaml")
    with pytest.raises(SceneError, match="unique"):
        scene_from_dict(
            {"grid": grid, "grippers": [{"name": "a", "point": [0, 0, 0], "radius": 0.1}] * 2}
        )


def test_a_box_grips_a_whole_edge_and_turns_it_about_its_centre():
    """grasp_box holds every free particle inside the box (a grid's first column here, and nothing
    of the next one), placed at the box's centre: a quarter turn about x moves each held particle
    to its place turned about that centre."""
    model, sim = _cloth(integrator="symplectic_euler", dt=1e-3, gravity=(0.0, 0.0, 0.0))
    idx = sim.grasp_box("edge", (-0.01, -0.01, -0.01), (0.01, 0.46, 0.01))
    assert sorted(idx.tolist()) == [10 * r for r in range(10)]
    centre = np.array([0.0, 0.225, 0.0])
    before = sim.positions[idx].copy()
    q = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0)  # a quarter turn about x
    sim.set_gripper_pose("edge", centre, q)
    sim.step()
    turned = centre + (before - centre) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T
    assert np.allclose(sim.positions[idx], turned, atol=1e-12)
    with pytest.raises(ValueError, match="no free particle inside the box"):
        sim.grasp_box("far", (5, 5, 5), (6, 6, 6))
    with pytest.raises(ValueError, match="must not exceed"):
        sim.grasp_box("bad", (0, 0, 1), (1, 1, 0))
    with pytest.raises(ValueError, match="already holds"):
        sim.grasp_box("edge", (-1, -1, -1), (1, 1, 1))
    assert list(sim.grippers) == ["edge"]


def test_a_scene_gripper_may_hold_a_box():
    from cloth_sim.scene import SceneError, scene_from_dict

    grid = {"rows": 6, "cols": 6, "spacing": 0.1}
    scene = scene_from_dict(
        {
            "grid": grid,
            "grippers": [
                {"name": "edge", "box": {"min": [-0.01, -0.01, -0.01], "max": [0.01, 0.51, 0.01]}}
            ],
        }
    )
    sim = scene.build_simulator()
    assert sim.grippers["edge"].tolist() == [0, 6, 12, 18, 24, 30]
    for bad, field in [
        (
            {"name": "a", "box": {"min": [0, 0, 0], "max": [1, 1, 1]}, "radius": 0.1},
            "either point and radius or box",
        ),
        ({"name": "a", "box": [0, 0, 0]}, r"grippers\[0\].box"),
        ({"name": "a", "box": {"min": [0, 0], "max": [1, 1, 1]}}, r"grippers\[0\].box.min"),
        ({"name": "a", "box": {"min": [0, 0, 2], "max": [1, 1, 1]}}, "min <= max"),
        (
            {"name": "a", "box": {"min": [0, 0, 0], "max": [1, 1, 1], "x": 1}},
            r"grippers\[0\].box.x",
        ),
    ]:
        with pytest.raises(SceneError, match=field):
            scene_from_dict({"grid": grid, "grippers": [bad]}, source="s.yaml")


def test_a_scene_script_turns_its_grippers_at_a_constant_rate_and_then_lets_go():
    """A scene's ``motion:`` turns a box gripper's edge about its centre: keyframes a sixth of a
    turn apart are spherically interpolated, so the edge has turned pi/3·t at every step of the
    first fifth of a second (a constant rate); after the last keyframe the script sets nothing,
    so a pose set by hand (as a pose topic does) stays. The twist scene plays its own script."""
    from cloth_sim.scene import load_scene, scene_from_dict

    rate, half = math.pi / 3, 0.5 * math.pi / 3
    frames = [
        {
            "t": float(t),
            "position": [0.0, 0.225, 0.0],
            "orientation": [math.cos(half * t), math.sin(half * t), 0, 0],
        }
        for t in (0, 1, 2, 3)
    ]
    scene = scene_from_dict(
        {
            "grid": {"rows": 10, "cols": 10, "spacing": 0.05},
            "pinned": [],
            "gravity": [0.0, 0.0, 0.0],
            "integrator": "symplectic_euler",
            "dt": 0.001,
            "grippers": [
                {"name": "edge", "box": {"min": [-0.01, -0.01, -0.01], "max": [0.01, 0.46, 0.01]}}
            ],
            "motion": {"grippers": {"edge": frames}},
        }
    )
    sim = scene.build_simulator()
    idx = sim.grippers["edge"]
    centre = np.array([0.0, 0.225, 0.0])
    arm = sim.positions[idx] - centre
    for _ in range(200):
        sim.step()
        a = rate * sim.time
        turned = (
            arm
            @ np.array(
                [[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]]
            ).T
        )
        assert np.allclose(sim.positions[idx] - centre, turned, atol=1e-9)
    sim.step(2801)  # past the script's end: a full turn (pi), then it lets go
    assert sim.time >= 3.0
    sim.set_gripper_pose("edge", centre + [0.0, 0.0, 0.1], (1.0, 0.0, 0.0, 0.0))
    sim.step(3)
    assert np.allclose(sim.positions[idx] - centre, arm + [0.0, 0.0, 0.1], atol=1e-9)

    twist = load_scene("twist")
    assert set(twist.motion.grippers) == {"left", "right"} and twist.motion.duration == 6.0
    q = twist.motion.gripper_at("right", 1.5)[1]  # pi/3 rad/s: a quarter turn at 1.5 s
    assert np.allclose(q, [math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0], atol=1e-8)
