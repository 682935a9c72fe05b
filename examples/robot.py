"""A robot from its URDF in the Python API: its links collide with a hanging cloth as its joints
move, and a gripper bound to its hand carries the cloth's corner.

    .venv/bin/python examples/robot.py [--quick]

Loads the demo arm (config/robots/arm.urdf: cylinders, a sphere, boxes and a mesh as its
links' collision geometry), places it in front of a hanging cloth, swings its shoulder through
the cloth at 1 m/s at the elbow, and reports how close the cloth came to any link (it keeps
``thickness``).
"""

import argparse
from pathlib import Path

import numpy as np

from cloth_sim import ClothModel, Simulator
from cloth_sim.robot import Robot

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="a 16×16 cloth and half the swing (the tests)")
quick = p.parse_args().quick

robot = Robot.from_urdf(Path(__file__).resolve().parents[1] / "config" / "robots" / "arm.urdf")
print(robot)
n = 16 if quick else 32
model = ClothModel.grid(
    n, n, 1.0 / (n - 1), 0.2 / n**2,  # 1 m square, 0.2 kg/m²
    stiffness={"structural": 600.0, "shear": 600.0, "bend": 2.0},
    damping={"structural": 0.01, "shear": 0.01, "bend": 0.001},
    pinned=[(0, 0), (0, n - 1)], orientation="vertical", origin=(-0.5, 0.0, 1.25),
)  # fmt: skip
sim = Simulator(model, integrator="vbd", dt=1 / 120, thickness=0.005, drag=0.002)
sim.add_robot(robot, name="arm", position=(0.0, -0.3, 0.45), joints={"shoulder_pitch": -0.2})
print("colliders:", ", ".join(c.name for c in sim.colliders))

swing = 1.35 if quick else 2.7  # rad, at 2.5 rad/s
closest = np.inf
while sim.time < swing / 2.5:
    sim.set_joint_positions("arm", {"shoulder_yaw": 0.2 + 2.5 * (sim.time + sim.dt)})
    sim.step()
    closest = min(closest, min(c.signed_distance(sim.positions).min() for c in sim.colliders))
print(f"closest the cloth came to a link: {closest / sim.thickness:.2f} × thickness")
print(f"pushed {sim.positions[:, 1].max():.3f} m behind its plane")

# a gripper bound to the hand: the cloth's nearest particle follows the hand as the arm turns
hand, _ = sim.link_pose("arm", "hand")
reach = np.linalg.norm(sim.positions - hand, axis=1).min() + 0.02
held = sim.grasp("hand", point=hand, radius=reach, link=("arm", "hand"))
before = sim.positions[held].copy()
sim.set_joint_positions("arm", {"shoulder_pitch": -0.5})
sim.step()
moved = np.abs(sim.positions[held] - before).max()
print(f"the hand holds {len(held)} particles; they moved {moved:.3f} m with it")
