"""Baraff–Witkin's linear system with smoothed-aggregation multigrid and with a lagged factorisation
(issue 30's tries; prints figures, changes nothing).

``.venv/bin/python tools/try_amg.py [--size 64]`` — needs PyAMG, which cloth_sim does not depend on:
``.venv/bin/pip install pyamg==5.2.1`` first.

The hanging scene at N×N (1 m, 10.24 kg, no strain limit), ``implicit_euler`` at dt = 1/60 s, its
matrix ``M − h·∂f/∂v − h²·∂f/∂x`` after 0.5 s and 1, 10 and 30 steps later (the cloth swinging);
SciPy's CG to 1e-6 (iterations, wall ms) with

* block Jacobi (what the integrator uses, compiled there: ~0.1 ms an iteration at 64×64);
* PyAMG's smoothed aggregation built on that step's matrix (near-nullspace: the three translations,
  or the six rigid-body modes), one V-cycle a CG iteration;
* the same hierarchy built 0.5 s in and kept (a lagged preconditioner);
* the Cholesky factor (``cholespy``) of the matrix 0.5 s in, kept (a lagged factorisation).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

from cloth_sim.integrators.implicit import cholesky

sys.path.insert(0, str(Path(__file__).resolve().parent))
from try_large_steps import block_jacobi, hanging, system  # noqa: E402  (the same scene, matrix)


def cg(A, b, M) -> str:
    count = [0]
    t = time.perf_counter()
    spla.cg(A, b, rtol=1e-6, maxiter=5000, M=M, callback=lambda _: count.__setitem__(0, count[0] + 1))
    return f"{count[0]} ({1e3 * (time.perf_counter() - t):.0f} ms)"


def rigid_modes(x):
    """The six rigid-body modes of particles at ``x`` (three translations, three rotations)."""
    x = x - x.mean(axis=0)
    B = np.zeros((3 * len(x), 6))
    for d in range(3):
        B[d::3, d] = 1.0
    B[1::3, 3], B[2::3, 3] = -x[:, 2], x[:, 1]
    B[0::3, 4], B[2::3, 4] = x[:, 2], -x[:, 0]
    B[0::3, 5], B[1::3, 5] = -x[:, 1], x[:, 0]
    return B


def main() -> None:
    import pyamg

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=64)
    n = ap.parse_args().size
    for stiffness in (1e3, 1e5):
        k = {"structural": stiffness, "shear": stiffness, "bend": 100.0}
        sim = hanging(n, integrator="implicit_euler", dt=1 / 60, strain_limit=None, stiffness=k)
        sim.advance(0.5)
        start = sim.steps_taken
        free = sim._integrator._system[0]
        mats = {0: (*system(sim), sim.state.x[free].copy())}
        for lag in (1, 10, 30):
            sim.step(start + lag - sim.steps_taken)
            mats[lag] = (*system(sim), sim.state.x[free].copy())
        A0, b0, x0 = mats[0]

        def solver(A, modes):
            return pyamg.smoothed_aggregation_solver(A, B=modes, symmetry="hermitian",
                                                     max_coarse=500, coarse_solver="splu")

        translations = rigid_modes(x0)[:, :3]
        t = time.perf_counter()
        kept = solver(A0, translations)
        setup = 1e3 * (time.perf_counter() - t)
        v_cycle = kept.aspreconditioner(cycle="V")
        t = time.perf_counter()
        for _ in range(10):
            v_cycle @ b0
        cycle_ms = 1e3 * (time.perf_counter() - t) / 10
        t = time.perf_counter()
        factor = cholesky(A0.tocsc())
        factor_ms = 1e3 * (time.perf_counter() - t)

        def back_substitute(r):
            r = np.ascontiguousarray(r, dtype=np.float64).ravel()
            out = np.zeros_like(r)
            factor.solve(r, out)
            return out

        print(f"\n# {n}×{n}, structural and shear {stiffness:g} N/m, 1/60 s: SA setup {setup:.0f} ms "
              f"({len(kept.levels)} levels, operator complexity {kept.operator_complexity():.2f}), "
              f"a V-cycle {cycle_ms:.2f} ms; Cholesky factor {factor_ms:.0f} ms")
        print("| steps after | block Jacobi | SA of this step, translations | SA of this step, rigid "
              "modes | SA of step 0 | Cholesky of step 0 |")
        print("|---|---|---|---|---|---|")
        for lag, (A, b, x) in mats.items():
            fresh = solver(A, translations).aspreconditioner(cycle="V")
            rigid = solver(A, rigid_modes(x)).aspreconditioner(cycle="V")
            jacobi = spla.LinearOperator(A.shape, block_jacobi(A).__matmul__)
            print(f"| {lag} | {cg(A, b, jacobi)} | {cg(A, b, fresh)} | {cg(A, b, rigid)} | "
                  f"{cg(A, b, v_cycle)} | {cg(A, b, spla.LinearOperator(A.shape, back_substitute))} |",
                  flush=True)


if __name__ == "__main__":
    main()
