"""Robots on the CUDA device under symplectic Euler: their links are colliders swept over each step
by the contact stage as the joints move (a mesh link read from its distance grid), grippers bound
to links follow them, and the links' wrenches come from the impulses the stage records; against
the CPU with the same robot and cloth. Under ``vbd`` the device does not sweep a collider yet: a
robot there is refused, naming it."""

from pathlib import Path

import numpy as np
import pytest

from cloth_sim import ClothModel, Simulator
from cloth_sim.robot import Robot

ROBOTS = Path(__file__).resolve().parents[3] / "config" / "robots"
TAU = 0.004


def sheet():
    """A 4×4 sheet 5 cm apart, pinned at two corners, a few millimetres above the pads."""
    return ClothModel.grid(
        4, 4, 0.05, 0.01, stiffness=1e2, damping=0.05, pinned=[(0, 0), (0, 3)], origin=(0, 0, 0)
    )


def pinch_script(sim):
    """The pinch gripper under vertex (1, 1): its left pad rises through the sheet over 50 steps,
    one joint change a step (the pads swept there), then a gripper bound to that pad takes the
    vertices it lifted and the lift goes on 20 steps; the positions and the pads' wrenches
    after each part."""
    gripper = Robot.from_urdf(str(ROBOTS / "gripper.urdf"))
    sim.add_robot(gripper, "g", position=(0.064, 0.05, -0.03), joints={"finger_left": 0.01})
    out = []
    for k in range(50):
        sim.set_joint_positions("g", {"lift": 0.001 * (k + 1)})
        sim.step()
        if k == 44:
            out.append(sim.link_wrench("g", "finger_left"))
    out.append(sim.positions.copy())
    held = sim.grasp(
        "hold", sim.link_pose("g", "finger_left")[0], 0.015, link=("g", "finger_left")
    )
    for k in range(20):
        sim.set_joint_positions("g", {"lift": 0.05 + 0.001 * (k + 1)})
        sim.step()
    out += [held, sim.positions.copy(), sim.gripper_pose("hold")[0]]
    return out


def test_a_pinch_gripper_lifting_the_sheet_is_the_cpus():
    """The pinch gripper's pads (boxes) swept up through the sheet, then a gripper bound to a pad
    carrying what it lifted: the device's cloth is the CPU's to rounding at every part (float64),
    the pad's wrench the CPU's (to 1e-9 of it, their sums taken in other orders), the bound
    gripper at the pad, and the pad really lifted the sheet."""
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=TAU)
    m = sheet()
    cpu = Simulator(m, **kw)
    gpu = Simulator(m, device="cuda", precision="float64", **kw)
    a, b = pinch_script(cpu), pinch_script(gpu)
    (f_cpu, t_cpu), (f_gpu, t_gpu) = a[0], b[0]
    assert np.linalg.norm(f_cpu) > 1e-3  # the pad pushes the sheet up
    assert np.max(np.abs(f_gpu - f_cpu)) < 1e-9 * np.linalg.norm(f_cpu)
    assert np.max(np.abs(t_gpu - t_cpu)) < 1e-9 * np.linalg.norm(f_cpu)
    for x_cpu, x_gpu in zip(a[1:], b[1:], strict=True):
        assert np.max(np.abs(np.asarray(x_gpu) - np.asarray(x_cpu))) < 1e-12
    assert len(b[2]) > 0 and b[3][5, 2] > m.positions[5, 2] + 0.01  # vertex (1, 1) lifted
    assert np.allclose(b[4], gpu.link_pose("g", "finger_left")[0])


def test_an_arm_with_a_mesh_link_sweeps_through_the_sheet_kept_off_its_links():
    """The demo arm (a cylinder, a sphere, a capsule, a mesh forearm, boxes) swung down about its
    shoulder into the sheet, its forearm and hand pushing it: on the device the forearm is read
    from its distance grid, so the cloth is the CPU's within a fraction of the grid's cell (0.2
    mm measured, cells of 2.5 mm) rather than to rounding, and keeps at least 0.9 of the
    thickness from every link by their exact distances at every step (0.95 measured)."""
    arm = Robot.from_urdf(str(ROBOTS / "arm.urdf"))
    kw = dict(integrator="symplectic_euler", dt=1e-3, thickness=TAU)
    m = sheet()
    sims = [Simulator(m, **kw), Simulator(m, device="cuda", precision="float64", **kw)]
    nearest = []
    for sim in sims:
        sim.add_robot(arm, "arm", position=(-0.55, 0.075, -0.1), joints={"shoulder_pitch": -0.15})
        for k in range(60):
            sim.set_joint_positions("arm", {"shoulder_pitch": -0.15 + 0.005 * (k + 1)})
            sim.step()
            nearest.append(
                min(float(np.min(c.signed_distance(sim.positions))) for c in sim.colliders)
            )
    cpu, gpu = sims
    assert any(c.kind == 5 and c.name == "arm/forearm" for c in gpu.colliders)  # a mesh
    assert min(nearest[60:]) > 0.9 * TAU
    assert min(nearest[:60]) < 1.01 * TAU  # the arm met the sheet on the CPU too
    assert 0.0 < np.max(np.abs(gpu.positions - cpu.positions)) < 1e-3


def test_a_robot_under_vbd_is_refused_naming_it():
    """Under ``vbd`` the device does not sweep a collider: adding a robot, or switching to ``vbd``
    with one in the scene, raises ``ValueError`` naming it, and nothing changes; a link moved by
    ``set_collider_pose`` stays the robot's, and goes with it."""
    gripper = Robot.from_urdf(str(ROBOTS / "gripper.urdf"))
    sim = Simulator(sheet(), integrator="vbd", dt=1 / 60, device="cuda", precision="float64")
    with pytest.raises(ValueError, match=r"robot: a robot's links under vbd are not on the cuda"):
        sim.add_robot(gripper, "g")
    assert sim.robots == {} and sim.colliders == []
    sim = Simulator(sheet(), dt=1e-3, device="cuda", precision="float64")
    sim.add_robot(gripper, "g")
    with pytest.raises(ValueError, match=r"robot: a robot's links under vbd"):
        sim.set_integrator("vbd")
    assert sim.integrator == "symplectic_euler" and list(sim.robots) == ["g"]
    # a link moved by hand is still the robot's (the same collider object, as on the CPU)
    pad = [c.name for c in sim.colliders].index("g/finger_left")
    sim.set_collider_pose(pad, (0.1, 0.0, 0.0))
    assert np.allclose(sim.colliders[pad].position, (0.1, 0.0, 0.0))
    assert sim.remove_robot("g").name == "pinch_gripper" and sim.colliders == []


def test_the_node_settings_take_robot_pick_to_the_device():
    """``settings.check`` (what the node starts with) builds ``robot_pick`` (the pinch gripper on
    its lift, symplectic Euler) on cuda with its robot and scripted motion, which steps; under
    ``vbd`` the same scene is refused naming the robot."""
    from cloth_sim import settings
    from cloth_sim.cuda.simulator import CudaSimulator

    sim = settings.build(settings.check("robot_pick", {"device": "cuda", "rows": 4, "cols": 4}))
    assert isinstance(sim, CudaSimulator) and list(sim.robots) == ["gripper"]
    assert sim.motion is not None and "gripper/finger_left" in [c.name for c in sim.colliders]
    sim.step(5)
    assert np.all(np.isfinite(sim.positions))
    with pytest.raises(settings.Refusal, match=r"robot: not on the cuda device yet under vbd"):
        settings.check(
            "robot_pick", {"device": "cuda", "rows": 4, "cols": 4, "integrator": "vbd", "dt": 0.01}
        )
