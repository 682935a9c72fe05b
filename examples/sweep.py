"""A sweep on Ray from Python: a grid of integrators times random stiffnesses, each run headless.

    .venv/bin/python examples/sweep.py [--quick] [-o OUT]

The same as ``cloth-sim sweep SPEC.yaml -o OUT``: the spec (a YAML file, see ``docs/sweeps/``)
names a scene, what is fixed, what is swept on a grid and what is drawn at random; every run
writes a bag of its frames and a row of ``OUT/runs.parquet``. Run again, it resumes.
"""

import argparse
import tempfile
from pathlib import Path

import pyarrow.parquet as pq
import yaml

from cloth_sim.sweep import engine

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--quick", action="store_true", help="4 short runs on 2 workers (the tests)")
p.add_argument("-o", "--output", default=None, help="OUT (default: a temporary directory)")
args = p.parse_args()

spec = {
    "scene": "hanging_provot",
    "duration": 0.2 if args.quick else 2.0,
    "frames": 10,  # a bag frame every 0.1 s of simulated time
    "seed": 3,
    "set": {"rows": 12, "cols": 12, "spacing": 0.09},
    "grid": {"integrator": ["symplectic_euler", "rk4"]},
    "random": {
        "samples": 2 if args.quick else 10,
        "stiffness.structural": {"loguniform": [300.0, 3000.0]},
    },
}
out = Path(args.output or tempfile.mkdtemp(prefix="cloth_sim_sweep_"))
out.mkdir(parents=True, exist_ok=True)
(out.parent / f"{out.name}.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
counts = engine.sweep(out.parent / f"{out.name}.yaml", out, workers=2, progress=False)
print("runs by status:", dict(counts))
rows = pq.read_table(out / "runs.parquet").to_pylist()
for row in rows:
    print(
        f"{row['integrator']:16s} k = {row['stiffness.structural']:7.1f}  {row['status']:8s} "
        f"max strain {row['max_strain']:.3f}, {row['wall_s']:.2f} s"
    )
print(engine.summary(out))
