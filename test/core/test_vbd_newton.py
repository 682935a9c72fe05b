"""``vbd``'s direct solve (:mod:`cloth_sim.integrators.vbd_newton`): Newton's method on the step's
incremental potential with the Hessian factorised, for a small cloth of a real fabric.

Checked against the force Jacobians of :meth:`Forces.jacobians` (themselves checked by finite
differences in test_forces.py), against the sweeps' own converged step (the same minimiser),
for the convergence its residual reports, for when ``vbd`` chooses it, and on the cantilever
that the sweeps could not bring to rest (polyester at 32×4: still moving at 3.4 cm/s after 441 s
of wall time)."""

from dataclasses import replace

import numba
import numpy as np
import pytest
import scipy.sparse as sp

from cloth_sim import ClothModel, Simulator, colliders, textile
from cloth_sim.integrators.vbd_newton import NewtonSolve, direct_is_cheaper
from cloth_sim.materials import resolve


def _strip(material="polyester", grid=16, direction="warp"):
    fabric = resolve(material)
    c = fabric.bending_length(0 if direction == "warp" else 1)
    model, _ = textile._strip(fabric, grid + 1, 3, 2 * c / grid * (grid + 1), 0.025, direction, 2)
    return model


def _released(model, colliders_=(), **options):
    drag = float(np.median(model.masses)) / textile.AIR_RELAXATION
    return Simulator(
        model,
        integrator="vbd",
        dt=1 / 60,
        drag=drag,
        colliders=list(colliders_),
        integrator_options=options,
    )


@pytest.mark.parametrize("clamp", [False, True])
def test_the_assembled_hessian_is_the_inertia_minus_the_force_jacobians(clamp):
    model = _strip()
    sim = _released(model)
    forces, h = sim.forces, 1 / 60
    rng = np.random.default_rng(3)
    x = model.positions + rng.normal(0.0, 2e-4, model.positions.shape)  # some springs compressed
    solve = NewtonSolve(model, ~model.pinned)
    upper = solve.hessian(forces, x, h, clamp).toarray()
    H = upper + np.triu(upper, 1).T
    dfdx, dfdv = forces.jacobians(x, np.zeros_like(x), clamp=clamp)
    reference = sp.diags(np.repeat(model.masses, 3) / h**2) - dfdx - dfdv / h
    reference = reference.toarray()[np.ix_(solve.dofs, solve.dofs)]
    assert np.abs(H - reference).max() <= 1e-9 * np.abs(reference).max()
    assert np.allclose(upper, np.triu(upper))  # the upper triangle, as QDLDL takes it
    if clamp:  # the compressive part dropped: positive definite
        assert np.linalg.eigvalsh(H).min() > 0


def test_the_direct_step_is_the_sweeps_converged_step():
    """Both minimise the same incremental potential: a step from a moving state of a small sheet,
    solved directly to 1e-10 and by 20,000 sweeps, lands on the same positions."""
    model = ClothModel.grid(6, 6, size=(0.3, 0.3), material="cotton", pinned=[(5, 0), (5, 5)])
    rng = np.random.default_rng(0)
    start = (model.positions.copy(), rng.normal(0.0, 0.05, model.positions.shape))
    start[1][model.pinned] = 0.0
    ends = []
    for options in (
        {"direct": True, "tolerance": 1e-10, "iterations": 50},
        {"direct": False, "tolerance": 0.0, "iterations": 20_000, "grid": False},
    ):
        sim = _released(model, scheme="euler", substeps=1, **options)
        sim.positions, sim.velocities = start
        sim.step()
        ends.append(sim.positions.copy())
        stats = sim.integrator_stats
        assert stats["direct_steps"] == (1 if options["direct"] else 0)
    travel = np.abs(ends[0] - start[0]).max()
    assert travel > 1e-4
    assert np.abs(ends[0] - ends[1]).max() < 1e-6 * travel


def test_the_residual_says_whether_the_direct_step_converged():
    model = _strip()
    capped = _released(model, direct=True, iterations=1, tolerance=1e-7)
    capped.step()
    free = _released(model, direct=True, iterations=50, tolerance=1e-7)
    free.step()
    a, b = capped.integrator_stats, free.integrator_stats
    assert not a["converged"] and a["last_residual"] > 1e-7 and a["last_iterations"] == 1
    assert b["converged"] and b["last_residual"] <= 1e-7 and b["last_iterations"] <= 15


def test_vbd_chooses_the_direct_solve_where_it_costs_less_and_applies():
    def direct_steps(model, **options):
        sim = _released(model, **options)
        sim.step(2)
        return sim.integrator_stats["direct_steps"]

    strip = _strip()
    assert direct_steps(strip) == 2  # its sweeps would need over 64 substeps
    assert direct_steps(strip, direct=False) == 0
    assert direct_steps(strip, iterations=30) == 0  # the work was given: the sweeps' own
    sheet = ClothModel.grid(17, 17, size=(1.0, 1.0), material="cotton", pinned=[(16, 0), (16, 16)])
    assert direct_steps(sheet) == 0  # three substeps of sweeps cost less
    assert direct_steps(sheet, direct=True) == 2
    damped = ClothModel.grid(
        9, 9, size=(0.05, 0.05), material=replace(resolve("cotton"), damping=1e-3),
        pinned=[(8, 0), (8, 8)],
    )  # fmt: skip
    assert direct_steps(damped, direct=True) == 0  # no potential to descend on: the sweeps
    floor = colliders.Plane(offset=-0.01)
    assert direct_steps(strip, colliders_=[floor]) == 0  # contacts are the sweeps'
    # the cost model: direct for few, light vertices; sweeps for a grid that needs few substeps
    assert direct_is_cheaper(130, 200, grid=True)
    assert not direct_is_cheaper(1024, 5, grid=True)
    assert not direct_is_cheaper(50_000, 10_000, grid=False)  # past DIRECT_MAX_VERTICES


def test_a_direct_step_has_the_same_bits_on_one_thread_and_two():
    model = _strip(grid=32)
    runs = []
    before = numba.get_num_threads()
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            sim = _released(model)
            sim.step(10)
            runs.append(sim.positions.copy())
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(runs[0], runs[1])


@pytest.mark.parametrize(
    "material, direction, grid",
    [("polyester", "warp", 32), ("gray-interlock", "warp", 64), ("denim", "weft", 64)],
)
def test_a_released_cantilever_comes_to_rest_at_its_bending_length_on_vbds_defaults(
    material, direction, grid
):
    """The issue's target is 5 % and at rest; the statics give the same strip within 0.3 %."""
    r = textile.cantilever(material, grid=grid, direction=direction)
    assert r["method"] == "vbd"
    assert r["speed_at_end"] < textile.REST_SPEED and r["settled_at"] <= 3.0
    assert abs(r["error"]) < 0.02


def test_the_direct_option_is_checked():
    with pytest.raises(ValueError, match="direct must be true, false or None"):
        Simulator(_strip(), integrator="vbd", dt=1 / 60, integrator_options={"direct": "yes"})


def test_a_direct_step_keeps_its_time_budget():
    """A budget far below one factorisation's time: one Newton iteration a step, as the sweeps
    take at least one."""
    sim = _released(_strip(), direct=True, tolerance=1e-12, iterations=50, time_budget=1e-9)
    sim.step(3)
    stats = sim.integrator_stats
    assert stats["direct_steps"] == 3 and stats["iterations"] == 3 and not stats["converged"]
