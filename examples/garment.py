"""A garment: the shipped T-shirt dropped on a table, self-contact inside Vertex Block Descent.

    .venv/bin/python examples/garment.py [--quick]

The ``tshirt`` scene (``config/scenes/tshirt.yaml``): the mesh and its 16 named landmarks, ``vbd``
at a frame a step with self-contact; a mesh of your own goes through ``ClothModel.from_mesh`` the
same way (any OBJ, PLY, STL, glTF or OFF file, or vertex and face arrays).
"""

import argparse

import numpy as np

from cloth_sim import ClothModel, settings

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="10 frames instead of 2 s (the tests)")
frames = 10 if p.parse_args().quick else 120

# the scene as the node builds it (its values checked, its table and self-contact included)
_, scene, sim, _ = settings.configure("tshirt", {})
model = sim.model
print(f"{model.n_particles} vertices, {len(model.triangles)} triangles, {model.family_names}")
print("landmarks:", ", ".join(model.meta["landmarks"]))
for _ in range(frames):
    sim.step()  # 1/60 s: vbd with the table and self-contact inside its iterations
hem = model.meta["landmarks"]["hem_left"]
print(f"t = {sim.time:.2f} s, left hem corner at {np.round(sim.positions[hem], 3).tolist()}")

# the same mesh, your own material: a mesh file (or arrays) and the springs' constants
own = ClothModel.from_mesh(
    "config/meshes/tshirt.obj",
    density=0.15,  # kg/m²: a vertex carries a third of its triangles
    stiffness={"structural": 200.0, "bend": 0.05},
    damping={"structural": 0.01, "bend": 0.001},
    model="choi_ko",  # bend springs that buckle
)
print("from_mesh:", own.n_particles, "vertices,", own.family_names)
