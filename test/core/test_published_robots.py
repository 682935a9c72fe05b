"""Published robot arms swept fast through a hanging cloth: no vertex ends inside a link and the
cloth never crosses itself, measured independently of the simulator.

The robots are the Franka Emika Panda and the Universal Robots UR5 as published (their URDFs and
collision meshes from example-robot-data, in ``test/data``), and the Franka FR3 with its hand that
Newton's ``example_cloth_franka`` uses (``test/data/newton-assets``; the Panda's kinematics, other
collision meshes and box fingers). The sweep is the robots issue's: a
32×32 sheet, 0.6 m square and 0.3 kg, springs of 300 N/m, hanging from its top corners in a
vertical plane 0.35 m in front of the robot's base; the first joint swings from −0.9 to +0.9 rad in
0.5 s (the Panda's hand at about 2.5 m/s) and the sheet swings on for 30 more steps; ``vbd`` at
1/240 s and 5 iterations, thickness 5 mm, self-contact on.

The depth is measured by trimesh on each link's collision geometry (its meshes, watertight, and its
boxes) placed by yourdfpy's forward kinematics: neither the simulator's kinematics nor its distance
queries. The crossings by :mod:`cloth_sim.bench.crossings`, which shares no code with the
simulator's collision handling. Before the fix these tests pin (vertices within a closed mesh's
skin held where they stood by their bound; a search every fifth iteration only), vertices ended
32 mm inside the Panda's wrist and 18 mm inside the UR5's, in the placements below.

The shipped robot_sweep scene (the demo arm through its own cloth) is measured the same way.
"""

from pathlib import Path

import numpy as np
import pytest

from cloth_sim import ClothModel, Simulator
from cloth_sim.bench.crossings import crossings
from cloth_sim.robot import Robot
from cloth_sim.scene import load_scene

trimesh = pytest.importorskip("trimesh")
yourdfpy = pytest.importorskip("yourdfpy")

DATA = Path(__file__).resolve().parents[1] / "data"
ROBOTS = DATA / "example-robot-data" / "robots"
TAU = 0.005
#: where each robot's ``package://`` URIs resolve (the folder holding its packages)
PACKAGES = {"fr3": DATA / "newton-assets"}

#: robot: its URDF (under ``ROBOTS``, or a whole path), its base, the joints held, the joint
#: swung, and the sheet's top-left corner
SWEEPS = {
    "fr3": (
        DATA / "newton-assets" / "franka_description" / "urdf" / "fr3_franka_hand.urdf",
        (0.0, 0.0, 0.0),
        {"fr3_joint2": 0.6, "fr3_joint4": -1.6, "fr3_joint6": 2.2},
        "fr3_joint1",
        (0.0, 0.35, 0.7),
    ),
    "panda": (
        "panda_description/urdf/panda.urdf",
        (0.0, 0.0, 0.0),
        {"panda_joint2": 0.6, "panda_joint4": -1.6, "panda_joint6": 2.2},
        "panda_joint1",
        (0.0, 0.35, 0.7),
    ),
    "ur5": (
        "ur_description/urdf/ur5_robot.urdf",
        (0.0, 0.0, 0.3),
        {"shoulder_lift_joint": -0.3, "elbow_joint": 0.6},
        "shoulder_pan_joint",
        (0.15, 0.35, 0.8),
    ),
}


def _uri(name: str, packages: Path = DATA) -> str:
    """A mesh's file: a ``package://`` URI under ``packages``; a relative path from there too
    (the demo arm's, relative to its URDF)."""
    name = str(name)
    if name.startswith("package://"):
        return name.replace("package://", str(packages) + "/")
    return str(packages / name)


def _link_solids(urdf, packages: Path = DATA):
    """Each link's collision geometry as trimesh solids in the link's frame."""
    solids = {}
    for link in urdf.robot.links:
        for c in link.collisions:
            g = c.geometry
            if g.mesh is not None:
                m = trimesh.load(_uri(g.mesh.filename, packages), force="mesh")
                if g.mesh.scale is not None:
                    m.apply_scale(g.mesh.scale)
            elif g.box is not None:
                m = trimesh.creation.box(extents=g.box.size)
            elif g.cylinder is not None:
                m = trimesh.creation.cylinder(radius=g.cylinder.radius, height=g.cylinder.length)
            elif g.sphere is not None:
                m = trimesh.creation.icosphere(subdivisions=4, radius=g.sphere.radius)
            else:
                continue
            assert m.is_watertight, (link.name, "its depth needs a closed solid")
            m.apply_transform(c.origin if c.origin is not None else np.eye(4))
            solids.setdefault(link.name, []).append(m)
    return solids


def _deepest(urdf, solids, base, x):
    """The deepest any point of ``x`` lies inside any link (m, 0 if none) and that link."""
    worst, where = 0.0, None
    for name, ms in solids.items():
        T = urdf.get_transform(name, urdf.base_link).copy()
        T[:3, 3] += base
        Ti = np.linalg.inv(T)
        local = x @ Ti[:3, :3].T + Ti[:3, 3]
        for m in ms:
            lo, hi = m.bounds
            near = np.all((local > lo - 1e-3) & (local < hi + 1e-3), axis=1)
            if near.any():
                inside = trimesh.proximity.signed_distance(m, local[near]).max()  # (+ inside)
                if inside > worst:
                    worst, where = float(inside), name
    return worst, where


@pytest.mark.parametrize("robot", sorted(SWEEPS))
def test_a_published_arm_swept_through_the_cloth_leaves_no_vertex_inside_and_no_crossing(robot):
    path, base, held, swing, corner = SWEEPS[robot]
    urdf_path, packages = ROBOTS / path, PACKAGES.get(robot, DATA)
    arm = Robot.from_urdf(urdf_path, package_paths=[packages])
    urdf = yourdfpy.URDF.load(
        str(urdf_path),
        filename_handler=lambda name: _uri(name, packages),
        load_meshes=False,
        load_collision_meshes=False,
    )
    solids = _link_solids(urdf, packages)
    model = ClothModel.grid(
        32, 32, size=(0.6, 0.6), particle_mass=0.3 / 1024, stiffness=300.0,
        pinned=[(0, 0), (0, -1)], orientation="vertical", origin=corner,
    )  # fmt: skip
    sim = Simulator(
        model, integrator="vbd", dt=1 / 240, thickness=TAU, self_collision=True,
        integrator_options={"iterations": 5},
    )  # fmt: skip
    sim.add_robot(arm, name=robot, position=base, joints={**held, swing: -0.9})
    tris, before = sim.model.triangles, sim.positions.copy()
    deepest, crossed, pushed = (0.0, None, -1), 0, 0.0
    for k in range(150):
        q = -0.9 + 1.8 * min(1.0, (k + 1) / 120)
        sim.set_joint_positions(robot, {swing: q})
        sim.step()
        x = sim.positions
        urdf.update_cfg({j: {**held, swing: q}.get(j, 0.0) for j in urdf.actuated_joint_names})
        depth, link = _deepest(urdf, solids, np.asarray(base), x)
        if depth > deepest[0]:
            deepest = (depth, link, k)
        crossed += len(crossings(before, x, tris))
        before = x.copy()
        pushed = max(pushed, float(x[:, 1].max()) - corner[1])
    assert pushed > 0.1  # the arm went through the sheet's plane and carried the cloth with it
    assert deepest[0] <= 0.1 * TAU, deepest
    assert crossed == 0


def test_the_demo_arm_swept_through_robot_sweeps_cloth_leaves_no_vertex_inside_and_no_crossing():
    """robot_sweep as it ships (the demo arm swings its shoulder at 2.5 rad/s through 1 m of cotton
    hanging at 32×32; ``vbd`` at 1/120 s × 10, self-contact on), over its first swing, 1.6 s: no
    vertex more than a tenth of the thickness inside a link, by trimesh on the arm's collision
    geometry placed by yourdfpy, and no crossing. Its links near the cloth travel up to 3.1
    thicknesses a step; with its steps left whole (``collider_share`` off) a fold the upper arm
    pushed ended 1.23 thicknesses inside it at t ≈ 1.02 s."""
    scene = load_scene("robot_sweep")
    sim = scene.build_simulator()
    spec = scene.robot
    urdf = yourdfpy.URDF.load(
        str(spec["urdf"]),
        filename_handler=lambda name: _uri(name, spec["urdf"].parent),
        load_meshes=False,
        load_collision_meshes=False,
    )
    solids = _link_solids(urdf, spec["urdf"].parent)
    base = np.asarray(spec["position"], dtype=float)
    assert spec["orientation"] == [1.0, 0.0, 0.0, 0.0]  # (_deepest places the base unturned)
    tris, before = sim.model.triangles, sim.positions.copy()
    deepest, crossed, pushed = (0.0, None, -1.0), 0, 0.0
    while sim.time < 1.6:
        sim.step()
        x = sim.positions
        q = sim.joint_positions(spec["name"])
        urdf.update_cfg({j: q.get(j, 0.0) for j in urdf.actuated_joint_names})
        depth, link = _deepest(urdf, solids, base, x)
        if depth > deepest[0]:
            deepest = (depth, link, sim.time)
        crossed += len(crossings(before, x, tris))
        before = x.copy()
        pushed = max(pushed, float(x[:, 1].max()))
    assert pushed > 0.03  # the arm pushed the cloth out of its plane (y = 0)
    assert deepest[0] <= 0.1 * sim.thickness, deepest
    assert crossed == 0


def test_the_panda_hand_closes_on_a_sheet_and_drags_it_into_a_fold_keeping_it_outside_its_links():
    """The Panda's hand, pointing down with its fingers across a hanging 0.2 m sheet (16×16, the
    issue's cloth per area), closes in 8 steps (0.033 s) to a gap of one thickness on the middle of
    its top edge, then the arm drags it 0.21 m aside in 0.5 s: the sheet, still pinned at its top
    corners, folds out of its plane, held by the fingers' friction alone. No vertex ends inside a
    finger or any link, no crossing, and the pinched vertex ends at the fingertips."""
    path = ROBOTS / "panda_description/urdf/panda.urdf"
    arm = Robot.from_urdf(path, package_paths=[DATA])
    urdf = yourdfpy.URDF.load(
        str(path), filename_handler=_uri, load_meshes=False, load_collision_meshes=False
    )
    solids = _link_solids(urdf)
    # joint 7 turns the fingers' axis along y, normal to the sheet
    joints = {
        "panda_joint1": 0.5, "panda_joint2": 0.6, "panda_joint4": -1.6, "panda_joint6": 2.2,
        "panda_joint7": 1.285, "panda_finger_joint1": 0.04, "panda_finger_joint2": 0.04,
    }  # fmt: skip

    def tcp(q):
        urdf.update_cfg({j: q.get(j, 0.0) for j in urdf.actuated_joint_names})
        return urdf.get_transform("panda_hand_tcp", urdf.base_link)[:3, 3].copy()

    start = tcp(joints)
    n, width = 16, 0.2
    model = ClothModel.grid(
        n, n, size=(width, width), particle_mass=0.3 / 0.36 * width**2 / n**2, stiffness=300.0,
        pinned=[(0, 0), (0, -1)], orientation="vertical",
        origin=(start[0] - (n // 2) * width / (n - 1), start[1], start[2] + 0.006),
    )  # fmt: skip
    sim = Simulator(
        model, integrator="vbd", dt=1 / 240, thickness=TAU, self_collision=True,
        integrator_options={"iterations": 5},
    )  # fmt: skip
    sim.add_robot(arm, name="panda", joints=joints, friction=1.0)
    tris, before, deepest, crossed = sim.model.triangles, sim.positions.copy(), (0.0, None), 0
    for k in range(8 + 120 + 30):
        finger = 0.04 + (TAU / 2 - 0.04) * min(1.0, (k + 1) / 8)
        swing = 0.5 + 0.3 * min(1.0, max(0.0, (k + 1 - 8) / 120))
        q = {"panda_joint1": swing, "panda_finger_joint1": finger, "panda_finger_joint2": finger}
        sim.set_joint_positions("panda", q)
        sim.step()
        x = sim.positions
        tip = tcp({**joints, **q})  # (also places the links for _deepest)
        depth, link = _deepest(urdf, solids, np.zeros(3), x)
        if depth > deepest[0]:
            deepest = (depth, link, k)
        crossed += len(crossings(before, x, tris))
        before = x.copy()
    assert np.linalg.norm(tip - start) > 0.2
    assert np.linalg.norm(x[n // 2] - tip) < 2 * TAU  # still between the fingertips
    assert deepest[0] <= 0.1 * TAU, deepest
    assert crossed == 0
