"""Layers that should come to rest under `vbd`'s self-contact, and how far they do.

    .venv/bin/python tools/resting_layers.py [SECONDS]

Cloth lying in layers on a floor with nothing driving it comes to rest: gravity, damping and
friction only take energy out. This prints, for each case, every simulated second (default 4), the
largest and the 90th-percentile particle speed (m/s) and the highest point (mm):

* ``tshirt flat``: the T-shirt laid flat as `TshirtFold-v0` starts it (the back panel a
  thickness up, the front three; every front vertex right above a back one), `vbd` at a frame a
  step with 3 iterations, self-contact, the floor: the tasks' settings. Also without self-contact,
  and with an air drag of 1e-3 N·s/m a particle (a time constant of ~0.08 s at its masses).
* ``stack aligned`` / ``stack shifted``: two 24×24 grids of the shirt's spacing, stiffness and
  areal mass, one a thickness above the other on the floor, the top one raised by up to 3 mm at
  random (the same draw every run); its vertices right above the lower grid's, or shifted half a
  spacing along x.

What it showed when written (issue 51, fourth session: docs/BENCHMARKS.md §11): without
self-contact the shirt settles (90 % of its particles below 1 mm/s within 3 s); with it, it does
not (0.02 m/s after 6 s, the largest 0.1), however much drag is added; at a contact stiffness of
100 N/m it does (0.0007 m/s after 4 s). The aligned stack creeps sideways at a few mm/s, slowing;
the shifted one gains speed and piles a ridge 2-3 cm high.
"""

from __future__ import annotations

import sys

import numpy as np

from cloth_sim.contact import colliders
from cloth_sim.model import ClothModel
from cloth_sim.simulator import Simulator

#: the two grids' step: the garment tasks' frame
FRAME = 1 / 60


def floor(friction=0.5):
    return [colliders.Plane(normal=(0, 0, 1), offset=0.0, friction=friction, name="floor")]


def report(name: str, sim: Simulator, seconds: float) -> None:
    out = []
    steps = int(round(1 / sim.dt))
    for _ in range(int(seconds)):
        sim.step(steps)
        v = np.linalg.norm(sim.velocities, axis=1)
        z = 1e3 * sim.positions[:, 2].max()
        out.append(f"{v.max():.4f}/{np.quantile(v, 0.9):.4f}/{z:.1f}")
    print(f"{name:34s}", " | ".join(out), flush=True)


def tshirt(self_collision=True, drag=0.0, contact_stiffness=None) -> Simulator:
    import gymnasium as gym

    import cloth_sim.envs  # noqa: F401 (registers the tasks)

    env = gym.make("cloth_sim/TshirtFold-v0", cache_dir=False, num_variations=1).unwrapped
    x = env.lay_flat().copy()
    sim = Simulator(
        env.model,
        "vbd",
        dt=env.sim.dt,
        integrator_options={
            "iterations": env.scene.vbd_iterations,
            **({} if contact_stiffness is None else {"contact_stiffness": contact_stiffness}),
        },
        strain_limit=env.scene.strain_limit,
        colliders=floor(),
        thickness=env.thickness,
        self_collision=self_collision,
        drag=drag,
    )
    sim.positions = x
    sim.velocities = np.zeros_like(x)
    return sim


def stack(shift: float, n=24, spacing=0.025, tau=0.004, raise_by=0.003) -> Simulator:
    g = ClothModel.grid(
        n,
        n,
        spacing=spacing,
        particle_mass=0.15 * spacing**2,
        stiffness={"structural": 200.0, "shear": 200.0, "bend": 0.05},
        damping={"structural": 0.01, "shear": 0.01, "bend": 0.001},
    )
    low = g.positions.copy()
    low[:, 2] = tau
    top = g.positions.copy()
    top[:, 0] += shift * spacing
    top[:, 2] = 2 * tau + raise_by * np.random.default_rng(1).random(len(top))
    m = len(low)
    model = ClothModel.from_springs(
        np.vstack([low, top]),
        np.concatenate([g.masses, g.masses]),
        np.vstack([g.springs, g.springs + m]),
        stiffness=np.concatenate([g.stiffness, g.stiffness]),
        damping=np.concatenate([g.damping, g.damping]),
        rest_lengths=np.concatenate([g.rest_lengths, g.rest_lengths]),
        triangles=np.vstack([g.triangles, g.triangles + m]),
    )
    return Simulator(
        model,
        "vbd",
        dt=FRAME,
        integrator_options={"iterations": 3},
        colliders=floor(),
        thickness=tau,
        self_collision=True,
    )


def main(seconds: float = 4.0) -> None:
    print("case · each second: largest speed (m/s) / 90th percentile (m/s) / highest point (mm)")
    report("tshirt flat", tshirt(), seconds)
    report("tshirt flat, no self-contact", tshirt(self_collision=False), seconds)
    report("tshirt flat, drag 1e-3 N·s/m", tshirt(drag=1e-3), seconds)
    report("tshirt flat, contact 100 N/m", tshirt(contact_stiffness=100.0), seconds)
    report("stack aligned", stack(0.0), seconds)
    report("stack shifted half a spacing", stack(0.5), seconds)


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 4.0)
