"""One cloth and a batch of worlds on a GPU, or on the CPU where no GPU can run.

    .venv/bin/python examples/gpu.py [--quick] [--device cuda|cpu]

The device is its own argument beside the method: ``Simulator(..., device="cuda")`` runs the
same ``vbd`` on the GPU (numba-cuda: ``make gpu``), and a device that cannot run here is refused
with what is missing. ``BatchSimulator`` steps many worlds of one cloth together, each with its
own wind, gravity, drag or stiffness, on either device.
"""

import argparse

import numpy as np

from cloth_sim import BatchSimulator, ClothModel, Simulator, backends

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="a 12×12 cloth and 4 worlds (the tests)")
p.add_argument("--device", default=None, help="cuda or cpu (default: cuda where it can run)")
args = p.parse_args()
n, worlds = (12, 4) if args.quick else (64, 1024)

why = backends.problem("cuda")
device = args.device or ("cuda" if why is None else "cpu")
print(f"cuda: {'available' if why is None else why}; running on {device}")

model = ClothModel.grid(
    n, n, material="denim", size=(1.0, 1.0), pinned=[(n - 1, 0), (n - 1, n - 1)]
)
sim = Simulator(model, integrator="vbd", dt=1 / 60, device=device)
sim.step(30)  # half a second; vbd chooses its substeps from the fabric
stats = sim.integrator_stats
print(
    f"one cloth on {sim.device}: {stats['last_substeps']} substeps a step, "
    f"residual {stats['last_residual']:.2g} (converged: {stats['converged']})"
)
print(f"its lowest point after 0.5 s: {sim.positions[:, 2].min():.3f} m")

batch = BatchSimulator(model, worlds=worlds, integrator="vbd", dt=1 / 60, device=device)
rng = np.random.default_rng(0)
weight = float(model.masses.mean()) * 9.81  # the wind acts per particle: a share of its weight
batch.set(None, wind=rng.uniform(-0.2, 0.2, (worlds, 3)) * weight)  # each world its own wind
batch.set([0], stiffness={"structural": 2 * model.stiffness[0]})
batch.step(30)
x = batch.positions_host()  # (worlds, n, 3); batch.positions stays on the device
print(
    f"{worlds} worlds on {batch.device}: positions {x.shape}, the lowest points "
    f"{x[:, :, 2].min(axis=1).round(3)[:4]} m"
)
batch.reset([1])
print(f"world 1 reset: time {batch.time[1]:.3f} s, the others at {batch.time[0]:.3f} s")
