"""A named fabric in SI units on grids of three resolutions: the same cloth, the same physics.

Run: .venv/bin/python examples/materials.py [--quick]
"""

import sys

import numpy as np

from cloth_sim import ClothModel, Simulator, materials, textile
from cloth_sim.materials import Fabric

quick = "--quick" in sys.argv
print("library:", ", ".join(materials.names()))
denim = materials.get("denim")
print(
    f"denim: {denim.density} kg/m², stretch {denim.stretch[0]:.0f}/{denim.stretch[1]:.0f} N/m, "
    f"bending length {100 * denim.bending_length(0):.2f} cm"
)

# a 0.5 m square of denim hanging from two corners, at three resolutions
for n in (9, 17) if quick else (9, 17, 33):
    model = ClothModel.grid(
        rows=n, cols=n, size=(0.5, 0.5), material="denim", pinned=[(0, 0), (0, -1)]
    )
    sim = Simulator(model, integrator="vbd", dt=1 / 120, drag=model.masses.max() / 0.2)
    sim.advance(1.0 if quick else 3.0)
    low = sim.positions[:, 2].min()
    print(f"{n}×{n}: mass {model.masses.sum():.4f} kg, lowest point {low:.3f} m")

# your own fabric: the fields the textile tests measure
felt = Fabric(density=0.35, stretch=(800.0, 800.0), shear=60.0, bend=(8e-5, 8e-5), poisson=0.3)
r = textile.cantilever(felt, grid=32)
print(
    f"felt cantilever: bending length {100 * r['measured']:.3f} cm measured, "
    f"{100 * r['expected']:.3f} cm expected"
)
t = textile.tensile(felt, grid=16, direction="warp")
print(f"felt strip tensile: {t['measured']:.1f} N/m measured, {t['expected']:.1f} N/m expected")
print("an implicit method refuses the bending:", end=" ")
try:
    Simulator(ClothModel.grid(4, 4, size=(0.1, 0.1), material=felt), integrator="xpbd")
except ValueError as e:
    print(str(e).split(";")[0])
assert np.isfinite(r["measured"])
