"""Vertex Block Descent (integrator ``vbd``): backward Euler by block coordinate descent.

Checked against backward Euler's own closed form and a converged minimiser of its incremental
potential, as a descent method (the potential never rises over the iterations), for the same bits
at any thread count, and with its contacts inside the solve: resting at the thickness, Coulomb on
an incline (the registry-wide tests in test_contacts.py), never crossing itself (the independent
crossing check of test_contacts.py) and never tunnelling through a thin collider."""

import math

import numba
import numpy as np
import pytest
import scipy.optimize
from cloths import one_spring, oscillator_order
from test_contacts import _count_crossings, _fold

from cloth_sim import ClothModel, Simulator, colliders
from cloth_sim.integrators.vbd import VBD
from cloth_sim.integrators.vbd_contact import moving_within_reach
from cloth_sim.integrators.vbd_kernels import (
    FAR,
    RECORD_RUNS,
    collider_allowances,
    colour_groups,
    contact_records,
)
from cloth_sim.physics.force_kernels import BUCKLE_TABLE, spring_energy
from cloth_sim.scene import load_scene

NO_GRAVITY = (0.0, 0.0, 0.0)


@pytest.mark.parametrize("scheme", ["euler", "bdf2"])
def test_a_linear_oscillator_follows_the_schemes_recursion_exactly(scheme):
    """One free particle on a spring along its axis: each step solves its implicit step exactly
    (the vertex's Newton step is exact on a quadratic energy), so x and v follow the recursion to
    rounding, at any step size. Backward Euler: (x, v)_{n+1} = [[1, h], [−ω²h, 1]] (x, v)_n /
    (1 + ω²h²). BDF2, after one backward-Euler step: backward Euler's of ĥ = 2h/3 from
    x̂ = (4xₙ − xₙ₋₁)/3 with velocity v̂ = (4vₙ − vₙ₋₁)/3, so x = (x̂ + ĥv̂)/(1 + ω²ĥ²) and
    v = (x − x̂)/ĥ."""
    for h in (1e-3, 0.05, 0.5):
        sim = Simulator(
            one_spring(k=100.0, m=1.0),
            integrator="vbd",
            dt=h,
            gravity=NO_GRAVITY,
            integrator_options={"iterations": 1, "rho": 0.0, "scheme": scheme},
        )
        w2, hh = 100.0, 2.0 * h / 3.0
        x, v = 0.1, 0.0
        past = None
        for _ in range(50):
            sim.step()
            if past is None or scheme == "euler":
                new = (x + h * v) / (1 + w2 * h * h), (v - w2 * h * x) / (1 + w2 * h * h)
            else:
                xh, vh = (4 * x - past[0]) / 3, (4 * v - past[1]) / 3
                nx = (xh + hh * vh) / (1 + w2 * hh * hh)
                new = nx, (nx - xh) / hh
            past, (x, v) = (x, v), new
            assert sim.positions[1, 0] - 1.0 == pytest.approx(x, rel=1e-9, abs=1e-15)
            assert sim.velocities[1, 0] == pytest.approx(v, rel=1e-9, abs=1e-15)


def test_bdf2_is_second_order_and_the_default_where_vbd_chooses_its_work():
    """The harmonic oscillator's error over 1 s against dt: slope 2 under BDF2 (vbd's defaults),
    1 under backward Euler (iterations given)."""
    dts = np.array([4e-3, 2e-3, 1e-3, 5e-4])
    for options, order in ((None, 2), ({"iterations": 10}, 1)):
        observed, errs = oscillator_order("vbd", dts, options)
        assert observed == pytest.approx(order, abs=0.15), errs


def test_bdf2_follows_a_fine_step_reference_closer_than_backward_euler():
    """A 12×12 cotton sheet hanging from two corners, 1 s from flat at 1/60 s with vbd's
    defaults: the free edge's centroid path against symplectic Euler at 0.9 of its stable step
    (the solver issue's reference). Both converge every step; BDF2, second order and less damped,
    keeps the path closer than backward Euler (1.3 % of the travel against 4.4 %), and neither
    gains energy over the fall."""
    model = ClothModel.grid(12, 12, size=(1.0, 1.0), material="cotton", pinned=[(11, 0), (11, 11)])

    def path(sim):
        out = [sim.positions[:12].mean(axis=0)]
        for f in range(1, 61):
            sim.advance(f / 60)
            out.append(sim.positions[:12].mean(axis=0))
        return np.array(out)

    ref = Simulator(model, integrator="symplectic_euler", dt=1.0)
    ref.dt = 0.9 * ref.stable_dt()
    want = path(ref)
    travel = np.linalg.norm(want - want[0], axis=1).max()
    off = {}
    for scheme in ("bdf2", "euler"):
        sim = Simulator(model, integrator="vbd", dt=1 / 60, integrator_options={"scheme": scheme})
        got = path(sim)
        assert sim.integrator_stats["unconverged_steps"] == 0
        off[scheme] = np.sqrt(((got - want) ** 2).sum(axis=1).mean()) / travel
        e = sim.energy()
        z0 = (model.masses * model.positions[:, 2]).sum()
        fallen = 9.81 * (z0 - (model.masses * sim.positions[:, 2]).sum())
        assert e["kinetic"] + e["spring"] <= fallen
    assert off["bdf2"] < 0.5 * off["euler"], off


def test_a_strain_limited_cloth_comes_to_rest_on_vbds_substeps_where_the_explicit_step_does():
    """Cotton hanging from two corners at 16×16 with the shipped scene's strain limit (0.1, the
    projection), in air, from flat: ``vbd`` at 1/60 s with its defaults (3 substeps a step) comes
    to rest and hangs where symplectic Euler at 0.9 of its stable step does (within 5 mm; 3.8 mm
    here, the splitting of the limit from the solve at 5.6 ms substeps). Each substep's stretch is
    corrected before the next and a velocity follows its own substep's correction; corrected
    once a step, over the whole step, the cloth beside the pins kept moving at ~0.4 m/s after 10 s
    (a velocity that stretched the springs, left over by the correction, every step)."""
    n = 16
    model = ClothModel.grid(
        n, n, size=(1.0, 1.0), material="cotton", pinned=[(n - 1, 0), (n - 1, -1)]
    )
    drag = float(np.median(model.masses)) / 0.1
    options = dict(strain_limit=0.1, strain_limit_method="projection", drag=drag)
    ref = Simulator(model, integrator="symplectic_euler", dt=1.0, **options)
    ref.dt = 0.9 * ref.stable_dt()
    sim = Simulator(model, integrator="vbd", dt=1 / 60, **options)
    ref.advance(10.0)
    sim.advance(10.0)
    assert sim.integrator_stats["last_substeps"] > 1
    assert np.abs(ref.velocities).max() < 5e-3
    assert np.abs(sim.velocities).max() < 5e-3, np.abs(sim.velocities).max()
    assert sim.max_strain() < 0.1 + 2e-3
    edge, ref_edge = sim.positions[:n, 2].mean(), ref.positions[:n, 2].mean()
    assert abs(edge - ref_edge) < 5e-3, (edge, ref_edge)


def _potential(model, x, xt, y, h):
    m = model.masses[:, None]
    return float(
        (m * (x - y) ** 2).sum() / (2 * h * h)
        + spring_energy(
            x, model.springs, model.rest_lengths, model.stiffness, model.kind, BUCKLE_TABLE
        )
    )


@pytest.mark.parametrize("model_name", ["provot", "choi_ko"])
def test_iterations_descend_to_backward_eulers_minimiser(model_name):
    """On a small stretched and crumpled cloth at a large step, the incremental potential of
    backward Euler (the inertia and the elastic springs; no damping, no gravity) never rises from
    one iteration count to the next, and many iterations reach the minimiser scipy's L-BFGS finds,
    to 1e-9 (Provot's springs), or a local minimum it cannot improve (Choi–Ko's)."""
    rng = np.random.default_rng(4)
    model = ClothModel.grid(
        5,
        5,
        0.1,
        0.01,
        stiffness={"structural": 500.0, "shear": 200.0, "bend": 20.0},
        damping=0.0,
        pinned=[(0, 0), (0, 4)],
        model=model_name,
    )
    x0 = model.positions + rng.normal(scale=0.02, size=model.positions.shape)
    x0[model.pinned] = model.positions[model.pinned]
    v0 = rng.normal(scale=0.3, size=x0.shape)
    v0[model.pinned] = 0.0
    h = 1 / 30
    y = x0 + h * v0
    free = ~model.pinned
    values = []
    for iters in (1, 2, 3, 5, 10, 20, 50, 400):
        sim = Simulator(
            model,
            integrator="vbd",
            dt=h,
            gravity=NO_GRAVITY,
            integrator_options={"iterations": iters, "rho": 0.0, "tolerance": 0.0},
        )
        sim.positions, sim.velocities = x0, v0
        sim.step()
        values.append(_potential(model, sim.positions, x0, y, h))
    assert all(b <= a * (1 + 1e-12) for a, b in zip(values, values[1:])), values

    def g(z):
        x = x0.copy()
        x[free] = z.reshape(-1, 3)
        return _potential(model, x, x0, y, h)

    options = {"ftol": 1e-15, "gtol": 1e-12, "maxiter": 20000}
    if model_name == "provot":  # smooth: one minimiser, which L-BFGS finds from the inertial guess
        best = scipy.optimize.minimize(g, y[free].ravel(), method="L-BFGS-B", options=options)
        assert values[-1] == pytest.approx(best.fun, rel=1e-9, abs=1e-12)
        assert values[-1] <= best.fun + 1e-12
    else:  # Choi–Ko's energy has a corner at every rest length (the buckling load jumps in):
        # many local minima; VBD ends at one, which L-BFGS started there cannot improve
        sim = Simulator(
            model,
            integrator="vbd",
            dt=h,
            gravity=NO_GRAVITY,
            integrator_options={"iterations": 400, "rho": 0.0, "tolerance": 0.0},
        )
        sim.positions, sim.velocities = x0, v0
        sim.step()
        there = scipy.optimize.minimize(
            g, sim.positions[free].ravel(), method="L-BFGS-B", options=options
        )
        assert there.fun >= values[-1] * (1 - 1e-3)


def test_colours_never_join_two_ends_of_a_spring():
    model = ClothModel.grid(12, 12, 0.05, 0.01, stiffness=100.0, pinned=[(0, 0)], model="choi_ko")
    ptr, verts = colour_groups(model.springs, model.n_particles, ~model.pinned)
    colour = np.full(model.n_particles, -1)
    for c in range(len(ptr) - 1):
        colour[verts[ptr[c] : ptr[c + 1]]] = c
    assert (colour[model.pinned] == -1).all() and (colour[~model.pinned] >= 0).all()
    a, b = colour[model.springs[:, 0]], colour[model.springs[:, 1]]
    assert not np.any((a == b) & (a >= 0))
    assert len(ptr) - 1 <= 25  # a greedy colouring of the grid's springs (bend pairs two apart)


def _hash(sim) -> bytes:
    return sim.positions.tobytes() + sim.velocities.tobytes()


def test_the_same_bits_at_any_thread_count():
    """The 64×64 hanging cloth (its colours updated on every core) and the T-shirt with
    self-contact: the same bits on one thread and on two."""
    out = {}
    for threads in (1, 2):
        numba.set_num_threads(threads)
        try:
            sc = load_scene("hanging_provot")
            sc.integrator, sc.dt = "vbd", 1 / 120
            sim = sc.build_simulator(rows=64, cols=64, spacing=1 / 63)
            sim.step(20)
            sc = load_scene("tshirt")
            sc.integrator, sc.dt, sc.self_collision = "vbd", 1 / 60, True
            shirt = sc.build_simulator()
            shirt.step(6)
            out[threads] = (_hash(sim), _hash(shirt))
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert out[1] == out[2]


def test_contact_records_list_each_vertexs_pairs_in_pair_order_at_any_thread_count():
    """The records (CSR of ``4·pair + slot`` per vertex, counted and filled in runs on every core)
    against a loop over the pairs in order: each vertex's slots with a weight, in pair order, and
    apart those of the pairs that carry the energy; the same arrays on one thread and on two, with
    fewer pairs than runs and none."""
    rng = np.random.default_rng(11)
    n = 40
    for m in (0, RECORD_RUNS - 3, 500):
        idx = rng.integers(0, n, (m, 4))
        coef = np.where(rng.random((m, 4)) < 0.2, 0.0, rng.normal(size=(m, 4)))
        energy = rng.random(m) < 0.6
        want_all = [[] for _ in range(n)]
        want = [[] for _ in range(n)]
        for q in range(m):
            for slot in range(4):
                if coef[q, slot] != 0.0:
                    want_all[idx[q, slot]].append(4 * q + slot)
                    if energy[q]:
                        want[idx[q, slot]].append(4 * q + slot)
        got = {}
        for threads in (1, 2):
            numba.set_num_threads(threads)
            try:
                got[threads] = contact_records(n, idx, coef, energy)
            finally:
                numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        assert all(np.array_equal(a, b) for a, b in zip(got[1], got[2]))
        ptr, rec, aptr, arec = got[1]
        for i in range(n):
            assert rec[ptr[i] : ptr[i + 1]].tolist() == want[i]
            assert arec[aptr[i] : aptr[i + 1]].tolist() == want_all[i]


@pytest.mark.parametrize("iterations", [1, 2, 3, 5])
def test_any_iteration_count_gives_a_usable_state(iterations):
    """A few iterations a step of a stiff cloth at a frame-rate step (hang16, whose work-precision
    run at 2 iterations diverged while the step could end on a Chebyshev extrapolation): finite,
    its kinetic energy never above what gravity can have put in (the fall from the start), whatever
    the stiffness."""
    for k, dt in ((1e3, 1 / 60), (1e3, 1 / 30), (1e5, 1 / 30)):
        model = ClothModel.grid(
            16, 16, 1 / 15, 0.01, stiffness=k, damping=0.0, pinned=[(0, 0), (0, 15)]
        )
        sim = Simulator(
            model, integrator="vbd", dt=dt, integrator_options={"iterations": iterations}
        )
        z0 = (model.masses * model.positions[:, 2]).sum()
        for _ in range(int(round(1.0 / dt))):
            sim.step()
            e = sim.energy()
            fallen = 9.81 * (z0 - (model.masses * sim.positions[:, 2]).sum())
            assert np.isfinite(sim.positions).all() and e["kinetic"] <= fallen + 1e-9, (k, dt)


def test_contacts_are_solved_inside_and_their_stages_do_not_run():
    sim = Simulator(
        ClothModel.grid(6, 6, 0.05, 0.01, stiffness=100.0),
        integrator="vbd",
        colliders=[colliders.Plane()],
        self_collision=True,
        thickness=0.01,
    )
    assert sim.active_stages == ("contacts",)  # (an exact finish of the penalty's distance)
    sim.set_integrator("symplectic_euler")
    assert sim.active_stages == ("contacts", "self_collision")
    sim.set_integrator("vbd")
    sim.strain_limit = 0.1
    assert sim.active_stages == ("strain_limit", "contacts")


def test_a_resting_cloth_is_held_at_the_thickness_and_a_fast_one_does_not_tunnel():
    """A cloth on a box rests at the thickness (less its weight over the contact stiffness); one
    thrown at a thin box at 30 m/s, a step of 1/60 s covering 25 box thicknesses, stays above
    it."""
    model = ClothModel.grid(8, 8, 0.02, 0.001, stiffness=100.0, damping=0.01)
    x = model.positions + [0.0, 0.0, 0.05]
    box = colliders.Box(center=(0.07, 0.07, -0.01), half_extents=(0.5, 0.5, 0.01), friction=0.5)
    sim = Simulator(model, integrator="vbd", dt=1 / 120, colliders=[box], thickness=0.005)
    sim.positions = x
    sim.advance(1.0)
    gap = box.signed_distance(sim.positions)
    weight = 0.001 * 9.81 / 1e4  # a particle's weight over the contact stiffness
    assert gap.min() >= 0.005 - 2 * weight - 1e-9 and gap.max() <= 0.005 + 1e-6
    sim = Simulator(
        model, integrator="vbd", dt=1 / 60, colliders=[box], thickness=0.005, gravity=NO_GRAVITY
    )
    sim.positions = x
    sim.velocities = np.tile([0.0, 0.0, -30.0], (model.n_particles, 1))
    for _ in range(30):
        sim.step()
        assert (sim.positions[:, 2] > 0.0).all()  # never below the box's top face


def test_a_vertex_far_from_every_collider_skips_their_terms_and_cannot_reach_them():
    """Without self-contact a vertex's allowance is only its expected motion: it is near a
    collider (their terms in its iterations) unless it is farther than FAR times that from every
    collider's skin (1.01 τ out); then it is held within that distance (or a lower bound of it,
    from a collider's reach, no less than FAR times its motion) for the step, so that no motion
    within its bound brings it inside a skin (the signed distances are 1-Lipschitz):
    checked by random motions up to the bound. With self-contact the allowance is the bound,
    short of the far side of a thin collider. Either way each collider's lower bound on the
    distance (what lets the iterations skip it) holds for every such motion."""
    tau = 0.005
    shapes = [
        colliders.Plane(),
        colliders.Sphere(center=(0.5, 0.0, 0.2), radius=0.1),
        colliders.Box(center=(0.0, 0.0, 0.3), half_extents=(0.2, 0.2, 0.004)),
    ]
    sim = Simulator(
        ClothModel.grid(4, 4, 0.05, 0.01, stiffness=100.0),
        integrator="vbd",
        colliders=shapes,
        thickness=tau,
    )
    co = sim.stages[1].packed()
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.uniform(-0.2, 0.8, 400), rng.uniform(-0.2, 0.2, 400)])
    x = np.column_stack([x, rng.uniform(0.0, 0.4, 400)])
    allowance = rng.uniform(0.0, 0.02, len(x))
    d = np.min([c.signed_distance(x) for c in shapes], axis=0)
    for bounded in (False, True):
        allow, near = np.empty(len(x)), np.empty(len(x), np.bool_)
        clear = np.empty((len(x), len(shapes)))
        args = (co, VBD.depths(co), tau, allow, near, clear)
        collider_allowances(x, allowance, bounded, *args)
        # each collider's lower bound holds wherever the vertex is within its bound (the
        # iterations ask nothing of a collider whose bound is beyond τ), and some are beyond τ
        held = np.isfinite(allow)
        assert (clear[~held] == -np.inf).all() and (clear[held] >= tau).any()
        for _ in range(20):
            step = rng.normal(size=x.shape)
            step *= (np.where(held, allow, 0.0) * rng.uniform(0.0, 1.0, len(x)))[:, None] / (
                np.linalg.norm(step, axis=1)[:, None]
            )
            y = x + step
            for c, shape in enumerate(shapes):
                assert (shape.signed_distance(y)[held] >= clear[held, c] - 1e-12).all()
        if bounded:  # its allowance, or less near the thin box (its far side)
            assert (allow <= allowance).all() and (allow < allowance).any()
            continue
        room = d - 1.01 * tau
        far = room > FAR * allowance
        assert far.any() and (~far).any()
        np.testing.assert_array_equal(near, ~far)
        # within its room, and no hold on a motion below FAR times its expected one (a collider
        # far beyond its reach is measured by that lower bound: less than the room, not less)
        assert (allow[far] <= room[far]).all()
        assert (allow[far] >= (1 - 1e-9) * FAR * allowance[far]).all()
        assert (allow[far] > 0.999 * room[far]).any()
        for _ in range(20):  # any motion within the bound stays out of every skin
            step = rng.normal(size=x.shape)
            step *= (allow * rng.uniform(0.0, 1.0, len(x)) / np.linalg.norm(step, axis=1))[:, None]
            y = x[far] + step[far]
            assert np.min([c.signed_distance(y) for c in shapes], axis=0).min() >= 1.01 * tau


def test_the_search_cadence_counts_a_collider_as_moving_only_within_reach_of_the_cloth():
    """vbd searches again every other iteration while a collider moves near the cloth (a link
    pushes the vertices in front of it into their bounds), every fifth otherwise. A collider
    counts as moving when some free vertex, moving at most its allowance, could come within the
    thickness of it anywhere on its way over the step: sampled along the way of a sphere moved
    at random, every such case is counted (and none farther than its motion beyond that); a box
    turned in place counts by how far its corners moved; a half-space that moved always counts,
    nothing that stayed ever does."""
    tau = 0.005
    ball = colliders.Sphere(center=(0.0, 0.0, 1.0), radius=0.05)
    box = colliders.Box(center=(0.0, 0.0, 1.0), half_extents=(0.2, 0.05, 0.05))
    floor = colliders.Plane(offset=-1.0)
    sim = Simulator(
        ClothModel.grid(6, 6, 0.04, 0.01, stiffness=100.0, pinned=[(0, 0)]),
        integrator="vbd",
        colliders=[ball, box, floor],
        thickness=tau,
    )
    co = sim.stages[1].packed()
    x = sim.positions
    free = ~sim.model.pinned
    rng = np.random.default_rng(11)
    allow = rng.uniform(0.0, 0.01, len(x))

    def pose(i, p1, p0, r1=np.eye(3), r0=np.eye(3)):
        """``co`` with collider ``i`` moved from ``p0`` (turned ``r0``) to ``p1`` (``r1``) and
        the others at rest out of reach."""
        pos, rot = np.array([[0.0, 0.0, 5.0]] * 3), np.array([np.eye(3)] * 3)
        pos0, rot0 = pos.copy(), rot.copy()
        pos[i], pos0[i], rot[i], rot0[i] = p1, p0, r1, r0
        return co._replace(pos=pos, rot=rot, pos0=pos0, rot0=rot0)

    assert not moving_within_reach(x, free, pose(0, (0.1, 0.1, 0.0), (0.1, 0.1, 0.0)), allow, tau)
    counted = 0
    for _ in range(300):
        p1 = rng.uniform((-0.2, -0.2, -0.2), (0.4, 0.4, 0.2))
        p0 = p1 + rng.normal(size=3) * rng.uniform(0.0, 0.08)
        got = moving_within_reach(x, free, pose(0, p1, p0), allow, tau)
        way = p0 + np.linspace(0.0, 1.0, 101)[:, None] * (p1 - p0)
        gap = np.linalg.norm(x[free][:, None] - way[None], axis=2).min(axis=1) - 0.05
        assert got or (gap >= allow[free] + 1.01 * tau).all()
        end_gap = np.linalg.norm(x[free] - p1, axis=1) - 0.05
        shift = np.linalg.norm(p1 - p0)
        assert not got or (end_gap < allow[free] + 1.01 * tau + shift + 1e-12).any()
        counted += got
    assert 30 < counted < 270  # both answers met
    # turned in place, 0.3 m above the cloth: its 0.21 m reach turned 0.2 rad is 0.04 m of way
    turn = np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(0.2), -np.sin(0.2)], [0.0, np.sin(0.2), np.cos(0.2)]]
    )
    above = (0.1, 0.1, 0.3)
    assert not moving_within_reach(x, free, pose(1, above, above, turn), allow, tau)
    assert moving_within_reach(
        x, free, pose(1, (0.1, 0.1, 0.24), (0.1, 0.1, 0.24), turn), allow, tau
    )
    assert moving_within_reach(x, free, pose(2, (0.0, 0.0, 5.0), (0.0, 0.0, 5.1)), allow, tau)


def test_self_contact_inside_the_solve_never_crosses():
    """The fold scene under vbd with self-collision, checked by the independent crossing test (a
    particle passing through a triangle between two steps): none, at 1/240 s as the scene runs and
    at a frame-rate step."""
    for dt in (1 / 240, 1 / 60):
        sim = _fold(True)
        sim.set_integrator("vbd")
        sim.dt = dt
        assert _count_crossings(sim, 1.0) == 0


def test_the_crossing_check_sees_vbd_cross_without_self_contact():
    sim = _fold(False)
    sim.set_integrator("vbd")
    sim.dt = 1 / 240
    assert _count_crossings(sim, 1.0, stop_at_first=True) > 0


def test_counters_report_iterations_and_the_residual():
    """With the tolerance off, every iteration runs, and the residual (the step's force imbalance
    over the weight: test_vbd_residual.py) falls with more iterations of the same step."""
    model = ClothModel.grid(8, 8, 0.05, 0.01, stiffness=500.0, pinned=[(0, 0)])
    residual = {}
    for iters in (2, 7, 30):
        sim = Simulator(
            model,
            integrator="vbd",
            dt=1 / 60,
            integrator_options={"iterations": iters, "tolerance": 0.0},
        )
        sim.step(3)
        s = sim.integrator_stats
        assert s["steps"] == 3 and s["iterations"] == 3 * iters and s["last_iterations"] == iters
        residual[iters] = s["last_residual"]
    assert residual[2] > residual[7] > residual[30] > 0.0


@pytest.mark.parametrize(
    "bad,words",
    [
        ({"iterations": 0}, "iterations"),
        ({"rho": 1.0}, "rho"),
        ({"contact_stiffness": -1.0}, "contact_stiffness"),
        ({"self_contact_stiffness": 0.0}, r"self_contact_stiffness must be None \(contact_stiff"),
        ({"self_contact_stiffness": "stiff"}, "self_contact_stiffness"),
        ({"collision_interval": 1.5}, "collision_interval"),
        ({"time_budget": 0.0}, "time_budget"),
        ({"tethers": 1}, "tethers"),
        ({"substeps": "many"}, "substeps"),
        ({"iterations": float("inf")}, "iterations"),
        ({"substeps": float("nan")}, "substeps"),
        ({"scheme": "bdf3"}, "scheme"),
        ({"collider_share": "fast"}, r"collider_share must be 'auto' \(2.5 where the cloth"),
        ({"collider_share": 0.0}, "collider_share"),
        ({"iteration": 10}, "no option 'iteration'; its options: iterations, rho"),
    ],
)
def test_bad_options_are_refused_naming_them(bad, words):
    with pytest.raises(ValueError, match=words):
        VBD(one_spring(), **bad)


def test_tethers_hold_every_particle_within_its_attachment_after_the_iterations():
    """With ``tethers`` the long-range attachments run after each sweep, so the step itself (no
    post-step stage here) leaves every particle within ``(1 + τ)`` of its rest geodesic distance
    to its nearest pins; without them one iteration a step leaves the heavy strip stretched far
    beyond it. The iterate stays backward Euler's: the velocity is the step's displacement."""
    from cloth_sim.constraints.strain_limit import StrainLimit, nearest_attachments
    from cloth_sim.physics.forces import Forces
    from cloth_sim.state import State

    model = ClothModel.grid(
        30, 3, 0.05, 0.2, stiffness=200.0, damping=0.0, pinned=[(0, 0), (0, 2)]
    )
    anchor, reach = nearest_attachments(model)
    far = {}
    for tethers in (True, False):
        integ = VBD(model, iterations=1, rho=0.0, tethers=tethers)
        integ.attach(None, None, StrainLimit(model, tau=0.1))
        forces = Forces(model, np.array(model.stiffness), np.array(model.damping))
        state = State(model.positions)
        h = 1 / 60
        for _ in range(30):
            x0 = state.x.copy()
            integ.step(state, forces, h)
            assert np.allclose(state.v[~model.pinned], ((state.x - x0) / h)[~model.pinned])
        own = anchor[:, 1] >= 0
        far[tethers] = [
            float(
                (
                    np.linalg.norm(state.x[own] - state.x[anchor[own, a]], axis=1) / reach[own, a]
                ).max()
            )
            for a in (0, 1)
        ]
    # each particle's two attachments are projected one after the other: the last holds to
    # rounding, the first may be re-stretched by the second's move, slightly
    assert far[True][1] <= 1.1 * (1 + 1e-12) and far[True][0] <= 1.1 * 1.01
    assert min(far[False]) > 1.5


def test_a_time_budget_bounds_the_iterations():
    sc = load_scene("hanging_provot")
    sc.integrator, sc.dt = "vbd", 1 / 60
    sim = sc.build_simulator(rows=48, cols=48, spacing=1 / 47)
    sim.set_integrator("vbd", iterations=1000, time_budget=0.002)
    sim.step(5)
    s = sim.integrator_stats
    assert 1 <= s["last_iterations"] < 1000
    assert math.isfinite(s["last_residual"])


def test_the_twist_scene_turns_into_layers_and_never_crosses():
    """Newton's cloth twist rebuilt (the ``twist`` scene), its edges turned 4× faster than Newton's
    example (4π/3 rad/s each way) for 0.75 s: the sheet wraps into a rope of layers (self-contact
    pairs found, its middle narrowed to a few centimetres) and the independent check finds no
    particle passing through a triangle between any two steps; the held edges are where the turn
    puts them."""
    from cloth_sim.bench.crossings import crossings
    from cloth_sim.bench.vbd_peers import twist_sim

    rate = 4 * math.pi / 3
    sim, turn = twist_sim(rate)
    tris = sim.model.triangles
    right = sim.grippers["right"]
    start = sim.positions[right].copy()
    crossed = 0
    while sim.time < 0.75 - 1e-9:
        turn(sim.time + sim.dt)
        x0 = sim.positions.copy()
        sim.step()
        crossed += len(crossings(x0, sim.positions, tris))
    assert crossed == 0
    assert sim.integrator_stats["last_contacts"] > 100
    middle = np.abs(sim.positions[:, 0]) < 0.02
    assert np.ptp(sim.positions[middle, 2]) < 0.2  # was 1 m wide
    a = 0.5 * rate * sim.time  # half the angle turned about x, right edge
    c, s = math.cos(2 * a), math.sin(2 * a)
    centre = np.array([0.75, 0.0, 1.0])
    turned = centre + (start - centre) @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T
    assert np.allclose(sim.positions[right], turned, atol=1e-9)
