"""``compile_kernels`` leaves nothing to compile: after it, the steps and queries a real-time loop
runs (a cloth above vbd's parallel threshold with self-collision and a collider, the same on the
grid's blocks with colliders and no self-contact, the self-contact search and the colliders'
signed distances, each with writable arrays and with read-only views)
use the signatures it compiled, so no tick of the node compiles (a missing one cost 8–26 s). Run in
a fresh process: in the test's own, an earlier test may have compiled what it looks for."""

import json
import subprocess
import sys

CHECK = """
import json, sys
import numba
import numpy as np
from cloth_sim import ClothModel, Simulator
from cloth_sim.contact import colliders as col
from cloth_sim.integrators.vbd import PARALLEL_MIN_VERTICES
from cloth_sim.kernels import compile_kernels


def signatures():
    out = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("cloth_sim.") and module is not None:
            for attr, value in vars(module).items():
                if isinstance(value, numba.core.registry.CPUDispatcher):
                    out[f"{name}.{attr}"] = len(value.signatures)
    return out


compile_kernels()
before = signatures()
model = ClothModel.grid(24, 24, 0.02, 0.01, stiffness=100.0, pinned=[(0, 0)])
assert model.n_particles >= PARALLEL_MIN_VERTICES
sim = Simulator(
    model,
    integrator="vbd",
    dt=1e-3,
    self_collision=True,
    thickness=0.004,
    colliders=[col.Sphere(center=(0.2, 0.2, -0.1), radius=0.1)],
)
sim.step(2)
# the grid's blocks with colliders and no self-contact (a drape or a table at vbd)
blocks = Simulator(
    model,
    integrator="vbd",
    dt=1e-3,
    thickness=0.004,
    colliders=[col.Sphere(center=(0.2, 0.2, -0.1), radius=0.1), col.Plane(offset=-0.3)],
)
blocks.step(2)
assert blocks.integrator_stats["grid_steps"] == 2
for x in (sim.positions, np.array(sim.positions)):  # a read-only view, a writable copy
    sim.stages[2].candidates(x, 0.004)
    sim.colliders[0].signed_distance(x)
after = signatures()
print(json.dumps({
    "kernels": len(before),
    "grown": {k: [before.get(k, 0), n] for k, n in after.items() if n > before.get(k, 0)},
}))
"""


def test_after_compile_kernels_a_contact_rich_step_compiles_nothing():
    run = subprocess.run(
        [sys.executable, "-c", CHECK], capture_output=True, text=True, timeout=600, check=True
    )
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["kernels"] > 50  # the package's kernels were found
    assert not report["grown"], f"compiled after compile_kernels: {report['grown']}"
