"""Contacts: a cloth dropped over a ball onto a floor, past a box and a capsule, with friction.

    .venv/bin/python examples/contacts.py [--quick]

Colliders are analytic shapes (plane, sphere, box, capsule), each with its Coulomb friction; the
cloth keeps ``thickness`` from them (and from itself, with ``self_collision=True``). A collider
moved between steps drags the cloth by its friction.
"""

import argparse

import numpy as np

from cloth_sim import ClothModel, Simulator, colliders

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="0.2 s instead of 1.5 s (the tests)")
seconds = 0.2 if p.parse_args().quick else 1.5

model = ClothModel.grid(24, 24, 1 / 23, 0.01, stiffness=1e3, damping=0.02, origin=(0, 0, 0.6))
sim = Simulator(
    model,
    integrator="symplectic_euler",
    dt=1e-3,
    colliders=[
        colliders.Plane(normal=(0, 0, 1), offset=0.0, friction=0.5),
        colliders.Sphere(center=(0.5, 0.5, 0.3), radius=0.25, friction=0.3),
        colliders.Box(
            center=(0.0, 0.0, 0.05),
            half_extents=(0.1, 0.1, 0.05),
            orientation=(1, 0, 0, 0),
            friction=0.4,
        ),
        colliders.Capsule(a=(1.0, 0.0, 0.02), b=(1.0, 1.0, 0.02), radius=0.02, friction=0.8),
    ],
    thickness=0.005,
    self_collision=False,
)
sim.advance(seconds)
x = sim.positions
gap = np.linalg.norm(x - (0.5, 0.5, 0.3), axis=1).min() - 0.25
print(f"t = {sim.time:.2f} s: lowest particle at z = {x[:, 2].min():.4f} m")
print(f"closest to the ball's surface: {gap:.4f} m (thickness 0.005)")
sim.set_collider_pose(1, (0.5, 0.6, 0.3))  # moves over the next step: friction drags the cloth
sim.step()
print(f"after moving the ball 0.1 m: mean velocity {sim.velocities.mean(axis=0).round(3)} m/s")
