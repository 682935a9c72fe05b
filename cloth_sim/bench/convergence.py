"""What ``vbd``'s step costs to converge on a real fabric: iterations against the residual, and
substeps against iterations at equal cost.

``cloth-sim bench convergence --material cotton --sizes 32 64`` hangs the library fabric (1 m
square, two corners pinned, starting flat as ``hanging`` does) and, for each size:

* **iterations a step**: ``vbd`` at 1/60 s for 1 s of simulated time at several caps with the
  tolerance off (every iteration runs), printing the relative residual of the steps' end
  (:mod:`cloth_sim.integrators.vbd_residual`, the median over the second half), the share of steps
  at or below the default tolerance, the bottom edge's height and the worst strain at 1 s, and
  the wall time a simulated second (two cores);
* **substeps at equal cost**: the same work a frame (``substeps × iterations`` fixed) spent as
  more, shorter steps (``dt = 1/60 / substeps``) — Macklin et al. 2019's small steps; the residual
  of each step is of its own (shorter) step, so the columns to compare are the bottom edge and the
  strain against the finest converged run.

The figures say how many sweeps a converged step takes at each resolution, which is what the
default iteration count and the choice of a method must be made from (docs/convergence.md).
"""

from __future__ import annotations

import time

import numpy as np

from ..integrators.vbd import TOLERANCE
from ..model import ClothModel
from ..simulator import Simulator

#: iteration caps timed a step at 1/60 s
CAPS = (10, 30, 100, 300)
#: (substeps, iterations) a frame of equal work
SPLITS = ((1, 200), (4, 50), (10, 20), (20, 10), (40, 5))
#: simulated seconds a run
SECONDS = 1.0


def hanging(n: int, material: str) -> ClothModel:
    """The ``n×n`` library fabric, 1 m square, hanging from its two top corners."""
    return ClothModel.grid(
        rows=n, cols=n, size=(1.0, 1.0), material=material, pinned=[(n - 1, 0), (n - 1, n - 1)]
    )


def run(model: ClothModel, n: int, substeps: int, iterations: int, seconds: float = SECONDS):
    """``vbd`` with the tolerance off over ``seconds``: a dict of the figures printed."""
    sim = Simulator(
        model,
        integrator="vbd",
        dt=1.0 / 60 / substeps,
        integrator_options={"iterations": iterations, "tolerance": 0.0},
    )
    steps = int(round(seconds * 60 * substeps))
    residuals = np.empty(steps)
    t0 = time.perf_counter()
    for s in range(steps):
        sim.step()
        residuals[s] = sim.integrator_stats["last_residual"]
    wall = time.perf_counter() - t0
    late = residuals[steps // 2 :]
    return {
        "residual": float(np.median(late)),
        "converged": float(np.mean(late <= TOLERANCE)),
        "bottom": float(sim.positions[:n, 2].mean()),
        "strain": float(sim.max_strain()),
        "wall": wall / seconds,
    }


def print_convergence_table(material: str, sizes, seconds: float = SECONDS) -> None:
    print(
        f"vbd on {material}, 1 m hanging from two corners, {seconds:g} s simulated, tolerance off "
        f"(default tolerance {TOLERANCE:g}); residual: median over the second half"
    )
    head = (
        f"{'N':>4} {'substeps':>8} {'iters':>6} {'residual':>10} {'<=tol':>6} "
        f"{'bottom z m':>10} {'worst strain':>12} {'wall s/s':>9}"
    )
    for n in sizes:
        model = hanging(n, material)
        run(model, n, 1, 2, 2 / 60)  # numba's kernels for this model's shapes
        print(head)
        for substeps, iterations in [(1, c) for c in CAPS] + list(SPLITS[1:]):
            r = run(model, n, substeps, iterations, seconds)
            print(
                f"{n:>4} {substeps:>8} {iterations:>6} {r['residual']:>10.3g} "
                f"{r['converged']:>6.0%} {r['bottom']:>10.4f} {r['strain']:>12.3f} "
                f"{r['wall']:>9.2f}",
                flush=True,
            )
