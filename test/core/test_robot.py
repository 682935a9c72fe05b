"""Robots from URDF: forward kinematics against closed forms, every collision shape a collider that
follows its link, package:// look-up, grippers bound to links, a link sweeping through a cloth
without letting it in, and bad input refused by name with nothing changed."""

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cloth_sim import ClothModel, Simulator
from cloth_sim.contact.geometry import quaternion_matrix
from cloth_sim.robot import Robot

ROOT = Path(__file__).resolve().parents[2]
ARM = ROOT / "config" / "robots" / "arm.urdf"

PLANAR = """<robot name="planar">
  <link name="base"/>
  <link name="a"><collision><origin xyz="{h1} 0 0"/>
    <geometry><box size="{l1} 0.02 0.02"/></geometry></collision></link>
  <link name="b"><collision><origin xyz="{h2} 0 0"/>
    <geometry><sphere radius="0.01"/></geometry></collision></link>
  <link name="c"><collision>
    <geometry><cylinder radius="0.01" length="0.05"/></geometry></collision></link>
  <joint name="q1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="q2" type="continuous"><parent link="a"/><child link="b"/>
    <origin xyz="{l1} 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="slide" type="prismatic"><parent link="b"/><child link="c"/>
    <origin xyz="{l2} 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.5" effort="1" velocity="1"/></joint>
  <joint name="follow" type="revolute"><parent link="base"/><child link="d"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="q1" multiplier="-2" offset="0.1"/></joint>
  <link name="d"/>
</robot>"""
L1, L2 = 0.4, 0.3


def planar() -> Robot:
    return Robot.from_urdf(PLANAR.format(l1=L1, l2=L2, h1=L1 / 2, h2=L2 / 2))


def cloth(n=12, spacing=0.05, origin=(0.0, 0.0, 0.0), pinned=()):
    return ClothModel.grid(
        n, n, spacing, 0.01, stiffness={"structural": 800, "shear": 800, "bend": 20},
        damping=0.05, origin=origin, pinned=pinned,
    )  # fmt: skip


def test_forward_kinematics_is_the_planar_arms_closed_form():
    robot = planar()
    assert robot.joint_names == ["q1", "q2", "slide"]  # the mimic joint is not set directly
    assert robot.link_names == ["a", "b", "c"]
    q1, q2, s = 0.7, -1.1, 0.12
    T = robot.link_transforms({"q1": q1, "q2": q2, "slide": s})
    elbow = np.array([L1 * math.cos(q1), L1 * math.sin(q1), 0])
    tip = elbow + (L2 + s) * np.array([math.cos(q1 + q2), math.sin(q1 + q2), 0])
    np.testing.assert_allclose(T["b"][:3, 3], elbow, atol=1e-12)
    np.testing.assert_allclose(T["c"][:3, 3], tip, atol=1e-12)
    np.testing.assert_allclose(T["c"][:3, :3], quaternion_matrix(
        (math.cos((q1 + q2) / 2), 0, 0, math.sin((q1 + q2) / 2))), atol=1e-12)  # fmt: skip
    # the mimic joint: −2·q1 + 0.1
    a = -2 * q1 + 0.1
    np.testing.assert_allclose(T["d"][:2, 0], [math.cos(a), math.sin(a)], atol=1e-12)


def test_forward_kinematics_agrees_with_yourdfpys():
    robot = Robot.from_urdf(ARM)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = {j: float(v) for j, v in zip(robot.joint_names, rng.uniform(-1, 1, 5))}
        q["finger_left_joint"] = abs(q["finger_left_joint"]) * 0.04
        ours, theirs = robot.link_transforms(q), robot.link_transforms_yourdfpy(q)
        assert set(ours) == set(theirs)
        for link in ours:
            np.testing.assert_allclose(ours[link], theirs[link], atol=1e-12)


def test_link_colliders_follow_the_joints_and_the_base_pose():
    robot = planar()
    sim = Simulator(cloth(origin=(5, 5, 5)), dt=1e-3)
    q = (math.cos(0.25), 0, 0, math.sin(0.25))  # the base turned 0.5 rad about z
    name = sim.add_robot(robot, position=(1.0, 2.0, 0.5), orientation=q)
    assert name == "planar" and list(sim.robots) == ["planar"]
    assert [c.name for c in sim.colliders] == ["planar/a", "planar/b", "planar/c"]
    sim.set_joint_positions("planar", {"q1": 0.3, "q2": 0.2})
    sim.step()
    a = 0.5 + 0.3  # the first link's heading in the world
    box_centre = np.array([1.0, 2.0, 0.5]) + L1 / 2 * np.array([math.cos(a), math.sin(a), 0])
    np.testing.assert_allclose(sim.colliders[0].position, box_centre, atol=1e-12)
    # the sphere at the elbow's origin + h2 along the second link
    elbow = np.array([1.0, 2.0, 0.5]) + L1 * np.array([math.cos(a), math.sin(a), 0])
    b = a + 0.2
    np.testing.assert_allclose(
        sim.colliders[1].position, elbow + L2 / 2 * np.array([math.cos(b), math.sin(b), 0]),
        atol=1e-12,
    )  # fmt: skip
    p, o = sim.link_pose("planar", "b")
    np.testing.assert_allclose(p, elbow, atol=1e-12)
    np.testing.assert_allclose(o, [math.cos(b / 2), 0, 0, math.sin(b / 2)], atol=1e-12)
    assert sim.joint_positions("planar") == {"q1": 0.3, "q2": 0.2, "slide": 0.0}


def test_the_demo_arm_loads_every_shape_and_its_mesh():
    robot = Robot.from_urdf(ARM)
    assert robot.name == "demo_arm"
    assert robot.joint_names == [
        "shoulder_yaw", "shoulder_pitch", "elbow", "wrist", "finger_left_joint"
    ]  # fmt: skip
    assert {s.kind for s in robot.shapes} == {"box", "cylinder", "sphere", "mesh"}
    # the same from its text (a robot_description), meshes looked up through a package path
    pkg = Path(robot.source).parent
    text = ARM.read_text().replace('filename="meshes/', 'filename="package://demo_arm/meshes/')
    with pytest.raises(ValueError, match="package 'demo_arm' not found"):
        Robot.from_urdf(text)
    fake = pkg.parent / "_pkgs_for_test"
    shutil.rmtree(fake, ignore_errors=True)
    try:
        (fake / "demo_arm").mkdir(parents=True)
        shutil.copytree(pkg / "meshes", fake / "demo_arm" / "meshes")
        again = Robot.from_urdf(text, package_paths=[fake])
        assert [s.kind for s in again.shapes] == [s.kind for s in robot.shapes]
    finally:
        shutil.rmtree(fake, ignore_errors=True)


def test_package_uris_resolve_through_ros_package_path_and_the_ament_index(tmp_path, monkeypatch):
    share = tmp_path / "prefix" / "share" / "my_robot" / "meshes"
    share.mkdir(parents=True)
    shutil.copy(ROOT / "config" / "robots" / "meshes" / "forearm.obj", share / "link.obj")
    text = """<robot name="r"><link name="l"><collision><geometry>
      <mesh filename="package://my_robot/meshes/link.obj" scale="2 2 2"/>
      </geometry></collision></link></robot>"""
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    with pytest.raises(ValueError, match="my_robot"):
        Robot.from_urdf(text)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "prefix"))
    r = Robot.from_urdf(text)
    np.testing.assert_allclose(r.shapes[0].params["vertices"].max(axis=0), [0.6, 0.06, 0.04])
    monkeypatch.delenv("AMENT_PREFIX_PATH")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "prefix" / "share"))
    assert Robot.from_urdf(text).shapes[0].kind == "mesh"


def test_a_gripper_bound_to_a_link_carries_its_particles_with_the_joints():
    robot = planar()
    model = cloth(n=6, origin=(0.6, -0.125, 0.0))
    sim = Simulator(model, dt=1e-3, gravity=(0, 0, 0))
    sim.add_robot(robot, name="arm", joints={"q1": 0.0, "q2": 0.0})
    tip, _ = sim.link_pose("arm", "c")
    idx = sim.grasp("hand", point=tip + (0.05, 0, 0), radius=0.04, link=("arm", "c"))
    assert len(idx) > 0
    start = sim.positions[idx].copy()
    for k in range(1, 101):
        sim.set_joint_positions("arm", {"q1": 0.004 * k})
        sim.step()
    # the held particles turned with the arm about the base's z axis by 0.4 rad
    c, s = math.cos(0.4), math.sin(0.4)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    np.testing.assert_allclose(sim.positions[idx], start @ R.T, atol=1e-9)
    assert sim.gripper_pose("hand")[0] == pytest.approx(sim.link_pose("arm", "c")[0])
    sim.release("hand")
    sim.set_joint_positions("arm", {"q1": 1.0})
    sim.step()
    assert np.abs(sim.positions[idx] - start @ R.T).max() < 0.01  # no longer carried


@pytest.mark.parametrize("integrator", ["symplectic_euler", "vbd"])
def test_a_link_sweeping_at_1_m_s_pushes_a_hanging_cloth_aside_without_entering(integrator):
    """The demo arm's upper arm sweeps through a hanging 16×16 cloth at about 1 m/s: every
    particle stays at least 90 % of the thickness off every link, at every step."""
    n, spacing, h = 16, 0.04, 0.005
    model = ClothModel.grid(
        n, n, spacing, 0.002, stiffness={"structural": 2000, "shear": 2000, "bend": 20},
        damping=0.02, pinned=[(n - 1, 0), (n - 1, n - 1)],
    )  # fmt: skip
    # hang it in the xz plane at y = 0: rows up z, columns along x
    x0 = model.positions.copy()
    hung = np.stack([x0[:, 0] - 0.3, np.zeros(len(x0)), x0[:, 1] - 0.1], axis=1)
    model = ClothModel.from_springs(
        hung, model.masses, model.springs, model.stiffness, model.damping,
        rest_lengths=model.rest_lengths, pinned=np.flatnonzero(model.pinned),
    )  # fmt: skip
    dt = 1 / 240 if integrator == "vbd" else 5e-4
    sim = Simulator(model, integrator=integrator, dt=dt, thickness=h, drag=0.05)
    sim.add_robot(Robot.from_urdf(ARM), name="arm", position=(0.0, -0.3, 0.0))
    # the arm (0.8 m long, its base 0.3 m in front of the cloth) swung about its base's z from
    # alongside the cloth (yaw 0.2) to through it (yaw π/2) and past, at 2.5 rad/s: 1 m/s at the
    # elbow, 2 m/s at the hand
    sim.set_joint_positions("arm", {"shoulder_yaw": 0.2, "shoulder_pitch": -0.2}, teleport=True)
    links = sim.colliders
    steps = int(round(0.68 / dt))
    for k in range(1, steps + 1):
        sim.set_joint_positions("arm", {"shoulder_yaw": 0.2 + 2.5 * k * dt})
        sim.step()
        d = min(c.signed_distance(sim.positions).min() for c in links)
        assert d >= 0.9 * h, (k, d)
    assert sim.positions[:, 1].max() > 0.05  # pushed aside, behind its plane


def test_a_fast_link_is_taken_in_parts_of_a_share_of_the_thickness():
    """collider_share: the demo arm swung 0.0125 rad in a step of 1/240 s (3 rad/s, its forearm's
    tip ~9 mm) beside the cloth is taken in substeps in none of which any vertex of its mesh
    forearm moves more than the share of the thickness; the same swing 2 m from the cloth, and the
    same swing with the option off, in one step. 'auto', the default, cuts a step only where the
    cloth self-collides, at 2.5 thicknesses a substep (twice the swing: two substeps). Contacts.
    travels, which sets their number, is exact for a mesh (its vertices' largest move) and a box
    (its corners')."""
    from cloth_sim.contact.colliders import Box, Contacts, Sphere

    n, h, share = 8, 0.005, 0.4

    def swung(where, options, turn=3.0 / 240, self_collision=False):
        model = ClothModel.grid(n, n, 0.05, 0.001, stiffness=100.0, pinned=[(n - 1, 0)])
        sim = Simulator(
            model, integrator="vbd", dt=1 / 240, thickness=h, self_collision=self_collision,
            integrator_options={"iterations": 2, **options},
        )  # fmt: skip
        sim.add_robot(Robot.from_urdf(ARM), name="arm", position=where)
        forearm = next(c for c in sim.colliders if c.name.endswith("forearm"))
        before = forearm.vertices
        sim.set_joint_positions("arm", {"shoulder_yaw": turn})
        moved = float(np.linalg.norm(forearm.vertices - before, axis=1).max())
        travels = sim._contacts.travels(sim._contacts.packed())  # (before the step ends it)
        k = next(i for i, c in enumerate(sim.colliders) if c is forearm)
        sim.step()
        return moved, travels[k], sim.integrator_stats["last_substeps"]

    # the arm 0.15 m under the cloth, its forearm within its reach (0.3 m) of the cloth
    below = (-0.3, 0.15, -0.3)
    moved, travel, parts = swung(below, {"collider_share": share})
    assert travel == pytest.approx(moved, rel=1e-12)
    assert moved > h and parts == math.ceil(moved / (share * h))
    assert swung((0.0, -2.0, 0.0), {"collider_share": share})[2] == 1  # far from the cloth
    assert swung(below, {"collider_share": None})[2] == 1  # off
    moved, _, parts = swung(below, {}, turn=6.0 / 240, self_collision=True)
    assert 2.5 * h < moved < 5 * h and parts == 2
    assert swung(below, {}, turn=6.0 / 240)[2] == 1

    # a box of half extents (0.1, 0.2, 0.3) moved 4 mm along x and turned 0.01 rad about z: its
    # corners' largest move; a sphere of radius 0.1 the same: its centre's plus 0.1 × the chord
    model = ClothModel.grid(2, 2, 0.05, 0.001, stiffness=1.0)
    contacts = Contacts(model, [Box(half_extents=(0.1, 0.2, 0.3)), Sphere(radius=0.1)], h)
    turn = np.array([[math.cos(0.01), -math.sin(0.01), 0], [math.sin(0.01), math.cos(0.01), 0],
                     [0, 0, 1]])  # fmt: skip
    quaternion = Rotation.from_matrix(turn).as_quat(scalar_first=True)
    for i in range(2):
        contacts.set_pose(i, (0.004, 0.0, 0.0), quaternion)
    corners = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])
    corners = corners * [0.1, 0.2, 0.3]
    expected = np.linalg.norm(corners @ turn.T + [0.004, 0, 0] - corners, axis=1).max()
    box, ball = contacts.travels(contacts.packed())
    assert box == pytest.approx(expected, rel=1e-9)
    assert ball == pytest.approx(0.004 + 0.1 * 2 * math.sin(0.005), rel=1e-9)


def test_a_mesh_travels_as_far_as_its_hulls_corners_and_a_flat_one_keeps_every_vertex():
    """Contacts.travels reads a mesh's hull corners only (hull_corners: qhull's vertices of
    the mesh's convex hull): the same box subdivided, its edge and face points on the hull but
    not its corners, travels exactly as its eight corners do; a flat mesh spans no solid, and
    every vertex is kept."""
    import trimesh

    from cloth_sim.contact.colliders import Contacts, Mesh, hull_corners

    box = trimesh.creation.box(extents=(0.2, 0.4, 0.6)).subdivide().subdivide()
    assert len(box.vertices) > 8
    corners = hull_corners(np.asarray(box.vertices))
    expected = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])
    expected = expected * [0.1, 0.2, 0.3]
    assert sorted(map(tuple, corners)) == sorted(map(tuple, expected))
    flat = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.5, 0.5, 0.0]])
    np.testing.assert_array_equal(hull_corners(flat), flat)

    model = ClothModel.grid(2, 2, 0.05, 0.001, stiffness=1.0)
    contacts = Contacts(model, [Mesh((box.vertices, box.faces))], 0.005)
    turn = Rotation.from_rotvec([0.0, 0.02, 0.01])
    contacts.set_pose(0, (0.0, 0.003, -0.002), turn.as_quat(scalar_first=True))
    every = np.asarray(box.vertices)
    moves = every @ turn.as_matrix().T + [0.0, 0.003, -0.002] - every
    (travel,) = contacts.travels(contacts.packed())
    assert travel == pytest.approx(np.linalg.norm(moves, axis=1).max(), rel=1e-12)


def test_bad_robot_input_is_refused_by_name_and_changes_nothing(tmp_path):
    with pytest.raises(ValueError, match="does not parse"):
        Robot.from_urdf("<robot name='x'><link name='a'></robot>")
    with pytest.raises(ValueError, match="not <robot>"):
        Robot.from_urdf("<sdf/>")
    with pytest.raises(ValueError, match="no such URDF file"):
        Robot.from_urdf(tmp_path / "missing.urdf")
    with pytest.raises(ValueError, match="joint 'j' has type 'floating'"):
        Robot.from_urdf(
            "<robot name='x'><link name='a'/><link name='b'/><joint name='j' type='floating'>"
            "<parent link='a'/><child link='b'/></joint></robot>"
        )
    with pytest.raises(ValueError, match="child link 'c' does not exist"):
        Robot.from_urdf(
            "<robot name='x'><link name='a'/><joint name='j' type='fixed'>"
            "<parent link='a'/><child link='c'/></joint></robot>"
        )
    with pytest.raises(ValueError, match="link 'a', collision 0: .*no such mesh file"):
        Robot.from_urdf(
            "<robot name='x'><link name='a'><collision><geometry><mesh filename='nope.stl'/>"
            "</geometry></collision></link></robot>"
        )
    empty = tmp_path / "empty.obj"
    empty.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(ValueError, match="link 'a', collision 0: .*no triangles"):
        Robot.from_urdf(
            f"<robot name='x'><link name='a'><collision><geometry><mesh filename='{empty}'/>"
            "</geometry></collision></link></robot>"
        )
    with pytest.raises(ValueError, match="sphere radius"):
        Robot.from_urdf(
            "<robot name='x'><link name='a'><collision><geometry><sphere radius='-1'/>"
            "</geometry></collision></link></robot>"
        )
    sim = Simulator(cloth(origin=(5, 5, 5)), dt=1e-3)
    sim.add_robot(planar(), name="arm", joints={"q1": 0.2})
    poses = [c.position.copy() for c in sim.colliders]
    for bad, match in [
        ({"elbow": 1.0}, "no movable joint 'elbow'.*q1, q2, slide"),
        ({"q1": math.nan}, "joint 'q1': position must be a finite number"),
        ({"q1": 0.5, "q2": math.inf}, "joint 'q2'"),
        ({"q1": "x"}, "joint 'q1'"),
    ]:
        with pytest.raises(ValueError, match=match):
            sim.set_joint_positions("arm", bad)
    with pytest.raises(ValueError, match="unknown robot 'hand'; robots: arm"):
        sim.set_joint_positions("hand", {"q1": 0.0})
    with pytest.raises(ValueError, match="no link 'z'"):
        sim.link_pose("arm", "z")
    with pytest.raises(ValueError, match="already"):
        sim.add_robot(planar(), name="arm")
    sim.step()
    assert all(np.array_equal(c.position, p) for c, p in zip(sim.colliders, poses))
    assert sim.joint_positions("arm")["q1"] == 0.2
    assert len(sim.colliders) == 3
    sim.remove_robot("arm")
    assert sim.colliders == [] and sim.robots == {}


def test_a_parallel_gripper_lifts_a_cloth_by_friction_alone_and_feels_its_weight():
    """robot_pick: two pads pinch a hanging flap's corner (no gripper attaches anything) and lift
    the cloth 0.55 m off the shelf; once it has settled in their grip (a second: the cotton's
    pinched corner stretches up to 9 mm as the lift ends), the pinched cloth creeps at most 1 mm
    against the pads over a 4 s hold, and the pads' vertical force is the cloth's weight within
    5 % (Coulomb friction on the squeeze carries it all: the shelf feels nothing)."""
    from cloth_sim.scene import load_scene

    sim = load_scene("robot_pick").build_simulator()
    assert sim.grippers == {}
    sim.advance(7.8)  # settled, pinched, lifted
    pads = [c for c in sim.colliders if c.name.startswith("gripper/finger")]
    near = np.min([c.signed_distance(sim.positions) for c in pads], axis=0)
    held = np.flatnonzero(near < 1.5 * sim.thickness)
    assert len(held) >= 1
    assert sim.positions[:, 2].min() > 0.41 + sim.thickness  # all of it off the shelf
    pad = lambda: sim.link_pose("gripper", "finger_left")[0]  # noqa: E731
    sim.advance(8.8)
    before = sim.positions[held] - pad()
    sim.advance(12.8)
    slip = np.abs(sim.positions[held] - pad() - before).max()
    assert slip <= 0.001
    force = sum(sim.link_wrench("gripper", f)[0] for f in ("finger_left", "finger_right"))
    weight = sim.model.masses.sum() * 9.81
    assert -force[2] == pytest.approx(weight, rel=0.05)
    assert np.linalg.norm(force[:2]) < 0.05 * weight
    np.testing.assert_array_equal(sim.collider_wrench(0)[0], 0.0)  # the shelf holds nothing


def test_the_tshirt_put_on_the_body_settles_on_its_shoulders_without_entering_or_crossing():
    """tshirt_on_body: the shirt dropped over the mannequin (a closed mesh collider of 3,656
    triangles: a solid) comes to rest on its shoulders, its hem below the shoulders, and never
    crosses itself (the independent check). The flat sleeves' seams start up to 38 mm inside the
    form's round arms (the shirt as cut is narrower than the arm there): the solid body pushes
    them out within 0.1 s, and from then on no vertex is deeper than 10 % of the thickness into
    the body at any step. (While meshes were two-sided, those seams stayed inside the arms for
    the whole run, held at the thickness from the arms' inner surface.) It comes to rest by 3 s:
    its fastest vertex at 0.073 m/s then (0.015 before the self-contact pairs near their onset
    were put in the step's Hessian, ``vbd_terms.NEAR``, which slows the settling of the unconverged
    steps here; 0.114 and 0.061 at 2.5 s)."""
    from cloth_sim.bench.crossings import crossings
    from cloth_sim.scene import load_scene

    sim = load_scene("tshirt_on_body").build_simulator()
    body = sim.colliders[0]
    h, prev, crossed = sim.thickness, sim.positions.copy(), 0
    assert body.signed_distance(sim.positions).min() < -0.03  # the seams in the arms
    while sim.time < 3.0:
        sim.step()
        if sim.time > 0.1:
            assert body.signed_distance(sim.positions).min() >= 0.9 * h
        crossed += len(crossings(prev, sim.positions, sim.model.triangles))
        prev = sim.positions.copy()
    assert crossed == 0
    z = sim.positions[:, 2]
    shoulders = 0.3 + 0.63  # the form's origin and its shoulders' top
    assert z.max() == pytest.approx(shoulders + h, abs=0.03)  # hanging from the shoulders
    assert np.abs(sim.velocities).max() < 0.1  # coming to rest
