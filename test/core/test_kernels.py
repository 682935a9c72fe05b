"""``compile_kernels`` leaves nothing to compile: after it, the steps and queries a real-time loop
runs (a cloth above vbd's parallel threshold with self-collision and a collider, the self-contact
search and the colliders' signed distances, each with writable arrays and with read-only views)
use the signatures it compiled, so no tick of the node compiles (a missing one cost 8–26 s)."""

import numba
import numpy as np

from cloth_sim import ClothModel, Simulator
from cloth_sim.contact import colliders as col
from cloth_sim.integrators.vbd import PARALLEL_MIN_VERTICES
from cloth_sim.simulator import compile_kernels


def _signatures() -> dict:
    """Every numba kernel of the package, by name: how many signatures it has compiled."""
    import sys

    out = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("cloth_sim.") or module is None:
            continue
        for attr, value in vars(module).items():
            if isinstance(value, numba.core.registry.CPUDispatcher):
                out[f"{name}.{attr}"] = len(value.signatures)
    return out


def test_after_compile_kernels_a_contact_rich_step_compiles_nothing():
    compile_kernels()
    before = _signatures()
    assert before, "no kernels found"
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
    sc = sim.stages[2]
    for x in (sim.positions, np.array(sim.positions)):  # a read-only view, a writable copy
        sc.candidates(x, 0.004)
        sim.colliders[0].signed_distance(x)
    after = _signatures()
    grown = {k: (before.get(k, 0), n) for k, n in after.items() if n > before.get(k, 0)}
    assert not grown, f"compiled after compile_kernels: {grown}"
