"""What a large step buys on the hanging cloth (issue 30's tries; prints figures, changes nothing).

``.venv/bin/python tools/try_large_steps.py [--size 64]``

1. **Stiff cloth at a frame-rate step, no strain limiter**: the hanging scene at N×N (1 m, 10.24 kg),
   structural and shear stiffness raised to 1e5 N/m, one 1/60 s step per frame with the implicit
   forms and xpbd, against symplectic Euler at 1 ms with Provot's limiter on the scene's own 1e3 N/m
   (what the node runs). For each: the worst strain of a limited spring over 3 s, how far the middle
   of the bottom edge swings (its y range after the first second) and where it ends (z at 3 s),
   against a reference of the same stiff cloth by symplectic Euler at 50 µs, and ms of wall time per
   simulated second.
2. **Baraff–Witkin's linear system at 1/60 s**, one step's matrix after 0.5 s: SciPy's CG iterations
   to 1e-6 with the block-Jacobi preconditioner (what the integrator uses), with the prefactored
   isotropic matrix ``M + h·C + h²·k·L`` (its Cholesky factor, constant) as the preconditioner, and
   with both as a two-level preconditioner (a damped block-Jacobi sweep, the factor on the residual,
   a sweep again), and what one back-substitution of that factor costs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cloth_sim.integrators.implicit import _assemble_baraff_witkin, cholesky, constant_system
from cloth_sim.scene import load_scene

STIFF = {"structural": 1e5, "shear": 1e5, "bend": 100.0}


def hanging(n: int, **kw):
    return load_scene("hanging").build_simulator(rows=n, cols=n, spacing=1 / (n - 1),
                                                 particle_mass=10.24 / n ** 2, **kw)


def trajectory(sim, n: int, seconds: float):
    probe = n * n - n // 2 - 1  # the middle of the last row
    path, worst, wall = [], 0.0, 0.0
    for frame in range(1, int(round(seconds * 60)) + 1):
        t = time.perf_counter()
        sim.advance(frame / 60)
        wall += time.perf_counter() - t
        path.append(sim.state.x[probe].copy())
        worst = max(worst, float(sim.strains(limited_only=True).max()))
    return np.array(path), worst, 1e3 * wall / seconds


def large_steps(n: int, seconds: float = 3.0) -> None:
    print(f"# 1. hanging scene {n}×{n} (1 m, 10.24 kg), {seconds:g} s; stiff = structural and shear "
          f"1e5 N/m; reference: the stiff cloth, symplectic Euler at 50 µs")
    ref, ref_worst, ref_ms = trajectory(hanging(n, stiffness=STIFF, integrator="symplectic_euler",
                                                dt=5e-5, strain_limit=None), n, seconds)
    print("| run | worst strain | bottom y range after 1 s (m) | bottom z at the end (m) | "
          "bottom's largest distance from the reference (m) | ms per simulated s |")
    print("|---|---|---|---|---|---|")
    print(f"| reference (stiff, symplectic Euler 50 µs) | {ref_worst:.3f} | {np.ptp(ref[60:, 1]):.3f} | "
          f"{ref[-1, 2]:.3f} | 0 | {ref_ms:.0f} |")
    runs = [("the node's: 1e3 N/m, symplectic Euler 1 ms + Provot (20 passes)",
             dict(integrator="symplectic_euler", dt=1e-3, strain_limit=0.1)),
            ("stiff, implicit_euler_prefactored 1/60", dict(integrator="implicit_euler_prefactored")),
            ("stiff, implicit_euler (Baraff–Witkin, CG) 1/60", dict(integrator="implicit_euler")),
            ("stiff, liu2013 (10 iterations) 1/60", dict(integrator="liu2013")),
            ("stiff, xpbd (10 substeps) 1/60", dict(integrator="xpbd")),
            ("stiff, xpbd (40 substeps) 1/60", dict(integrator="xpbd", integrator_options={"substeps": 40}))]
    for label, kw in runs:
        if "strain_limit" not in kw:
            kw = dict(kw, stiffness=STIFF, dt=1 / 60, strain_limit=None)
        path, worst, ms = trajectory(hanging(n, **kw), n, seconds)
        off = np.linalg.norm(path - ref, axis=1).max()
        print(f"| {label} | {worst:.3f} | {np.ptp(path[60:, 1]):.3f} | {path[-1, 2]:.3f} | {off:.3f} | "
              f"{ms:.0f} |", flush=True)


def system(sim):
    """Baraff–Witkin's matrix (CSR, the free particles' unknowns) and right-hand side at the
    simulator's state, as its ``implicit_euler`` integrator assembles them."""
    integ, forces, dt = sim._integrator, sim.forces, sim.dt
    x, v = sim.state.x, sim.state.v
    f = forces.force(x, v)
    kx, _, cv = forces.spring_term.jacobian_blocks(x, v, True, position_damping=False)
    A = integ._matrix.copy()
    rhs = np.empty((sim.model.n_particles, 3))
    _assemble_baraff_witkin(forces.springs, kx, cv, f, v, dt, sim.model.masses + dt * forces.drag,
                            integ._slot, integ._dslot, A.data, rhs)
    return A.tocsr(), rhs.ravel()[integ._free_dofs]


def block_jacobi(A):
    """The inverses of ``A``'s 3×3 diagonal blocks, as one block-diagonal CSR matrix."""
    coo = A.tocoo()
    own = coo.row // 3 == coo.col // 3
    blocks = np.zeros((A.shape[0] // 3, 3, 3))
    np.add.at(blocks, (coo.row[own] // 3, coo.row[own] % 3, coo.col[own] % 3), coo.data[own])
    return sp.block_diag(list(np.linalg.inv(blocks)), format="csr")


def preconditioners(n: int, stiffness: float) -> None:
    k = {"structural": stiffness, "shear": stiffness, "bend": 100.0}
    sim = hanging(n, integrator="implicit_euler", dt=1 / 60, strain_limit=None, stiffness=k)
    sim.advance(0.5)
    A, b = system(sim)
    size = A.shape[0]
    jacobi = block_jacobi(A)
    P = constant_system(sim.model, sim.forces, sim.dt)[0]
    factor = cholesky(P)

    def back_substitute(r):
        r = np.ascontiguousarray(np.asarray(r, dtype=np.float64).reshape(-1, 3))
        out = np.zeros_like(r)
        factor.solve(r, out)
        return out.ravel()

    def two_level(r, omega=0.7):
        z = omega * (jacobi @ r)
        z += back_substitute(r - A @ z)
        z += omega * (jacobi @ (r - A @ z))
        return z

    for label, apply in (("block Jacobi (the integrator's)", jacobi.__matmul__),
                         ("prefactored isotropic matrix", back_substitute),
                         ("two-level: block Jacobi + prefactored", two_level)):
        count = [0]
        spla.cg(A, b, rtol=1e-6, maxiter=20000, M=spla.LinearOperator((size, size), apply),
                callback=lambda _: count.__setitem__(0, count[0] + 1))
        print(f"| {n} | {stiffness:g} | {label} | {count[0]} |", flush=True)
    t = time.perf_counter()
    for _ in range(20):
        back_substitute(b)
    print(f"(one back-substitution of the {P.shape[0]}×{P.shape[0]} factor, three right-hand sides: "
          f"{(time.perf_counter() - t) / 20 * 1e3:.2f} ms)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=64)
    args = ap.parse_args()
    large_steps(args.size)
    print("\n# 2. Baraff–Witkin's system at 1/60 s after 0.5 s: CG iterations to 1e-6")
    print("| N | stiffness N/m | preconditioner | CG iterations |")
    print("|---|---|---|---|")
    for stiffness in (1e3, 1e5):
        preconditioners(args.size, stiffness)


if __name__ == "__main__":
    main()
