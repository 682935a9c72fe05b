"""``vbd`` on a grid's blocks (:mod:`cloth_sim.integrators.vbd_grid`): the nine classes are
colours, every spring and bending coupling sits in its slot, a converged step is the general
sweep's (the same backward Euler step), the general sweep runs wherever the blocks cannot, the
same bits at any thread count and with a time budget, and the sweep compiles to SIMD lanes."""

import json
import os
import subprocess
import sys
import tempfile

import numba
import numpy as np
import pytest

from cloth_sim import ClothModel, Simulator, colliders
from cloth_sim.integrators.vbd_grid import OFFSETS, GridLayout
from cloth_sim.scene import load_scene


def _layout(model):
    sim = Simulator(model, integrator="vbd", dt=1 / 60)
    return GridLayout.of(model, sim.forces), sim.forces


@pytest.mark.parametrize("rows,cols", [(5, 7), (9, 9), (10, 4), (2, 13)])
def test_each_spring_and_bending_coupling_sits_in_its_slot_between_two_colours(rows, cols):
    """Every spring of a Provot grid, and every bending coupling of a material's, joins two
    particles of different classes ``(i mod 3, j mod 3)``; from each end, its slot's shift lands on
    the other end, and the slot holds the spring's stiffness, rest length and damping (or the
    coupling ``Q_ij``). Nothing else is in the blocks: the stiffness summed over the slots is
    twice the springs' (each spring seen from both ends)."""
    provot = ClothModel.grid(rows, cols, 0.05, 0.01, stiffness=100.0, damping=0.3, pinned=[(0, 0)])
    fabric = ClothModel.grid(rows, cols, size=(0.5, 0.4), material="denim", pinned=[(0, 0)])
    for model in (provot, fabric):
        lay, forces = _layout(model)
        assert lay is not None
        i, j = np.divmod(np.arange(model.n_particles), cols)
        cls = (i % 3) * 3 + j % 3
        colour = (lay.slot // lay.PQ).astype(np.int64)
        shift = lay.shift.view(np.int64)
        where = {d: o for o, d in enumerate(OFFSETS)}
        Q = None if forces.bending is None else forces.bending.Q
        ends = forces.springs
        if Q is not None:
            ends = np.concatenate([ends, forces.bending.couplings()[0]])
        for e, (u, w) in enumerate(ends):
            for a, b in ((u, w), (w, u)):
                assert cls[a] != cls[b]
                o = where[(int(i[b] - i[a]), int(j[b] - j[a]))]
                t = lay.slot[a]
                assert t + shift[colour[a], o] == lay.slot[b]
                if e < len(forces.springs):
                    assert lay.K[o, t] == forces.k[e] and lay.REST[o, t] == forces.rest[e]
                    assert lay.C[o, t] == forces.c[e]
                else:  # the coupling as row a of Q holds it (what the general sweep reads)
                    assert lay.QO[o, t] == Q[a, b]
        if Q is not None:
            assert np.array_equal(lay.QD[lay.slot], Q.diagonal())
        assert lay.K.sum() == pytest.approx(2 * forces.k.sum(), rel=1e-14)
        assert np.all(colour == cls)


def _pair(model, iterations, **kw):
    """The same scene on the grid's blocks and on the general sweep."""
    sims = [
        Simulator(
            model,
            integrator="vbd",
            dt=1 / 60,
            integrator_options={"iterations": iterations, "grid": grid, "tolerance": 0.0},
            **kw,
        )
        for grid in (True, False)
    ]
    return sims


@pytest.mark.parametrize(
    "case",
    ["provot, damping, drag and wind", "a material's bending"],
)
def test_a_converged_step_is_the_general_sweeps(case):
    """Both sweeps minimise the same incremental potential: iterated to convergence (300
    iterations of a soft cloth), the two reach the same backward Euler steps to 1e-7 m over half
    a second of swinging (each term left out of the blocks — the damping, the drag, the bending
    couplings or their diagonal — moves them apart by 0.1 mm or more). The grid's run is counted in
    ``grid_steps``, the general one's is not."""
    if case.startswith("provot"):
        model = ClothModel.grid(
            12,
            12,
            0.05,
            0.02,
            stiffness={"structural": 60.0, "shear": 40.0, "bend": 5.0},
            damping={"structural": 0.05, "shear": 0.05, "bend": 0.01},
            pinned=[(0, 0), (0, 11)],
        )
        kw = {"drag": 0.002, "wind": (0.3, 0.0, 0.5)}
    else:
        model = ClothModel.grid(
            12, 12, size=(0.6, 0.6), material="cotton", pinned=[(11, 0), (11, 11)]
        )
        kw = {}
    grid, general = _pair(model, 300, **kw)
    for _ in range(3):
        grid.step(10)
        general.step(10)
        assert np.abs(grid.positions - general.positions).max() < 1e-7
        assert np.abs(grid.velocities - general.velocities).max() < 1e-5
    assert grid.integrator_stats["grid_steps"] == 30
    assert general.integrator_stats["grid_steps"] == 0
    # ten iterations: each sweep's own order, both short of the step by the same margin
    grid, general = _pair(model, 10, **kw)
    grid.step(30)
    general.step(30)
    gap = np.abs(grid.positions - general.positions).max()
    assert 0.0 < gap < 0.01


def test_a_converged_step_against_colliders_is_the_general_sweeps():
    """The drape scene (cotton over a ball, on a floor, with friction) at 12×12, two seconds in
    (34 vertices touching): one step from the same state, iterated to convergence (1,000
    iterations), on the blocks (the colliders' penalty, friction, onset and bounds in the second
    pass) and on the general sweep: the same step to 1e-9 m."""
    sc = load_scene("drape")
    base = sc.build_simulator(
        rows=12, cols=12, integrator="vbd", dt=1 / 60, integrator_options={"grid": False}
    )
    base.advance(2.0)
    steps = []
    for grid in (True, False):
        sim = sc.build_simulator(
            rows=12,
            cols=12,
            integrator="vbd",
            dt=1 / 60,
            integrator_options={"iterations": 1000, "grid": grid, "tolerance": 0.0},
        )
        sim.positions, sim.velocities = base.positions, base.velocities
        sim.step()
        assert sim.integrator_stats["grid_steps"] == int(grid)
        steps.append(sim.positions)
    assert np.abs(steps[0] - steps[1]).max() < 1e-9


def test_the_general_sweep_runs_wherever_the_blocks_cannot():
    """Choi–Ko's springs, self-contact, tethers, a spring network that is not a grid, and
    ``grid=False``: the general sweep (no grid step counted); a grid with colliders runs on the
    blocks."""
    grid = ClothModel.grid(6, 6, 0.05, 0.01, stiffness=100.0, pinned=[(0, 0)])
    cases = [
        (ClothModel.grid(6, 6, 0.05, 0.01, stiffness=100.0, pinned=[(0, 0)], model="choi_ko"), {}),
        (grid, {"self_collision": True, "thickness": 0.005}),
        (grid, {"strain_limit": 0.1, "integrator_options": {"tethers": True}}),
        (grid, {"integrator_options": {"grid": False}}),
        (
            ClothModel.from_springs(
                grid.positions,
                grid.masses,
                grid.springs,
                grid.stiffness,
                grid.damping,
                pinned=[0],
            ),
            {},
        ),
    ]
    for model, kw in cases:
        sim = Simulator(model, integrator="vbd", dt=1 / 60, **kw)
        sim.step(2)
        assert sim.integrator_stats["grid_steps"] == 0, kw
    for kw in ({}, {"colliders": [colliders.Plane(offset=-1.0)]}):
        sim = Simulator(grid, integrator="vbd", dt=1 / 60, **kw)
        sim.step(2)
        assert sim.integrator_stats["grid_steps"] == 2


def test_the_same_bits_at_any_thread_count_and_with_a_time_budget():
    """A 96×96 hanging cloth (each colour cut in chunks for both cores): the same bits on one
    thread and on two; and with a time budget it cannot exhaust (the iterations called one by one,
    Chebyshev's step from Python) the same bits as without."""
    out = {}
    for threads, budget in ((1, None), (2, None), (2, 100.0)):
        numba.set_num_threads(threads)
        try:
            sc = load_scene("hanging_provot")
            sc.integrator, sc.dt = "vbd", 1 / 60
            options = {} if budget is None else {"time_budget": budget}
            sim = sc.build_simulator(
                rows=96, cols=96, spacing=1 / 95, strain_limit=None, integrator_options=options
            )
            sim.step(5)
            assert sim.integrator_stats["grid_steps"] == 5
            out[threads, budget] = sim.positions.tobytes() + sim.velocities.tobytes()
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert out[1, None] == out[2, None] == out[2, 100.0]


CHECK = """
import json, re
from cloth_sim.integrators import vbd_grid
from cloth_sim.model import ClothModel
m = ClothModel.grid(6, 6, 0.1, 0.01, stiffness=100.0, damping=0.1, pinned=[(0, 0)])
lay = vbd_grid.GridLayout(6, 6, m.springs, m.rest_lengths, m.stiffness, m.damping, None, m.pinned)
lay.load(m.positions, m.positions, m.positions, m.masses)
lay.solve(1.0, 0.0, 0, 2, 2, 0.8, 1.0)
asm = "\\n".join(vbd_grid._sweeps.inspect_asm().values())
print(json.dumps({"packed": len(re.findall(r"v?sqrtpd", asm)),
                  "scalar": len(re.findall(r"v?sqrtsd", asm))}))
"""


def test_the_grid_sweep_runs_in_simd_lanes():
    """The colour's loop compiles to packed square roots (one per spring of the twelve; the
    scalar ones are the loop's remainder): numba declares the loop's arrays unaliased only while
    nothing in it takes a view, and its loads stay contiguous only with unsigned indices. Compiled
    afresh (an empty cache: numba shows no machine code of a cached kernel)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        run = subprocess.run(
            [sys.executable, "-c", CHECK],
            capture_output=True,
            text=True,
            timeout=600,
            check=True,
            env=env,
        )
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["packed"] >= 12, report
