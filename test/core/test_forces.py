"""Force terms: Choi & Ko's energy and force, wind, the pipeline's active terms, strain
limiting."""

import numpy as np
import pytest
from cloths import cloth16

import cloth_sim.physics.force_kernels as force_kernels
import cloth_sim.physics.forces as forces
from cloth_sim import ClothModel, Simulator
from cloth_sim.physics.force_kernels import buckling_h, buckling_h_exact

NO_GRAVITY = (0.0, 0.0, 0.0)


def test_choi_ko_table_matches_exact_solution(rng):
    """The docstring's claim: relative error < 2e-10 (energy) and < 3e-8 (force) on [0, 1]."""
    r = np.concatenate(
        [rng.uniform(0, 1, 2000), np.linspace(0.99, 1, 100), np.linspace(0, 0.01, 100)]
    )
    for x in r:
        h, dh, _ = buckling_h(x)
        he, dhe = buckling_h_exact(x)
        # h = 2θ² where sin θ/θ = r
        theta = np.sqrt(he / 2)
        assert np.sinc(theta / np.pi) == pytest.approx(x, abs=1e-12)
        assert abs(h - he) <= 2e-10 * he + 1e-300
        assert abs(dh - dhe) <= 3e-8 * abs(dhe)


def choi_ko_patch(rng, k_struct=50.0, k_bend=0.02):
    model = ClothModel.grid(
        5,
        5,
        0.1,
        0.01,
        stiffness={"structural": k_struct, "shear": k_struct, "bend": k_bend},
        model="choi_ko",
    )
    x = model.positions.copy()
    # compress the patch to 85 % and crumple it: bend pairs buckle, some springs stretch
    x[:, :2] *= 0.85
    x += rng.normal(scale=0.01, size=x.shape)
    return model, x


def test_choi_ko_force_is_minus_the_energy_gradient(rng):
    model, x = choi_ko_patch(rng)
    sim = Simulator(model, gravity=NO_GRAVITY)
    sim.positions = x
    strains = sim.strains()
    bend = model.family == model.family_index("bend")
    assert np.any(strains[bend] < -0.05) and np.any(strains[~bend] > 0.01)  # both branches in play
    f = sim.forces.force(x, np.zeros_like(x))
    num = np.zeros_like(x)
    h = 1e-7
    for i in range(len(x)):
        for d in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, d] += h
            xm[i, d] -= h
            num[i, d] = -(sim.forces.spring_energy(xp) - sim.forces.spring_energy(xm)) / (2 * h)
    assert np.max(np.abs(f - num)) <= 1e-6 * np.max(np.abs(f))


def test_choi_ko_onset_force_is_12_kb_over_L_squared():
    kb = 0.3
    model = ClothModel.grid(2, 3, 0.1, 0.01, stiffness={"bend": kb}, model="choi_ko")
    assert model.n_springs and Simulator(model).active_terms == ("spring:bend", "gravity")
    sim = Simulator(model, gravity=NO_GRAVITY)
    L = 0.2
    for r in (1 - 1e-9, 1 - 1e-6):
        x = model.positions.copy()
        x[[2, 5], 0] = L * r  # columns 2 pulled in: the two bend pairs are compressed to r·L
        f = sim.forces.force(x, np.zeros_like(x))
        assert f[0, 0] == pytest.approx(-12 * kb / L**2, rel=1e-5)  # pushes the ends apart
        assert f[2, 0] == pytest.approx(12 * kb / L**2, rel=1e-5)


def test_choi_ko_type1_springs_do_not_resist_compression():
    model = ClothModel.grid(
        2, 2, 0.1, 0.01, stiffness={"structural": 100.0, "shear": 100.0}, model="choi_ko"
    )
    sim = Simulator(model, gravity=NO_GRAVITY)
    x = model.positions * 0.9
    assert np.all(sim.forces.force(x, np.zeros_like(x)) == 0.0)
    assert sim.forces.spring_energy(x) == 0.0
    x = model.positions * 1.1
    assert np.max(np.abs(sim.forces.force(x, np.zeros_like(x)))) > 0


def flat_cloth():
    return ClothModel.grid(6, 6, 0.1, 0.01, stiffness=100.0)


def test_wind_pushes_along_the_normal_and_vanishes_in_plane():
    w = 0.7
    sim = Simulator(flat_cloth(), gravity=NO_GRAVITY, wind=(0.3, -0.2, w))
    f = sim.forces.force(sim.positions.copy(), np.zeros((36, 3)))
    # flat in the xy plane: n = ±z, so every particle feels (n·W) n = (0, 0, w)
    np.testing.assert_allclose(f, np.tile([0, 0, w], (36, 1)), atol=1e-12)
    sim.wind = (1.0, 2.0, 0.0)
    f = sim.forces.force(sim.positions.copy(), np.zeros((36, 3)))
    np.testing.assert_allclose(f, 0, atol=1e-12)
    # tilt the cloth by 30° about x: the force follows the tilted normal, magnitude (n·W)
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    rot = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    x = sim.positions @ rot.T
    sim.wind = (0.0, 0.0, w)
    f = sim.forces.force(x, np.zeros((36, 3)))
    n = rot @ [0, 0, 1]
    np.testing.assert_allclose(f, np.tile((n @ [0, 0, w]) * n, (36, 1)), atol=1e-12)


def test_inactive_terms_are_not_evaluated(monkeypatch):
    model = ClothModel.grid(
        6,
        6,
        0.1,
        0.01,
        stiffness={"structural": 100.0, "shear": 50.0, "bend": 0.0},
        damping={"structural": 0.1},
    )
    sim = Simulator(model, wind=None)
    assert sim.active_terms == (
        "spring:structural",
        "spring:shear",
        "damping:structural",
        "gravity",
    )
    bend = model.family == model.family_index("bend")
    assert sim.forces.n_active_springs == np.count_nonzero(~bend)

    def forbidden(*args):
        raise AssertionError("an inactive term was evaluated")

    monkeypatch.setattr(forces, "wind_forces", forbidden)
    sim.step(10)  # no wind: the wind kernel is never called
    sim.set_damping("structural", 0.0)
    sim.gravity = (0, 0, 0)
    assert sim.active_terms == ("spring:structural", "spring:shear")
    assert not sim.forces.with_damping
    sim.set_stiffness("bend", 10.0)
    sim.drag = 0.01
    assert sim.active_terms == ("spring:structural", "spring:shear", "spring:bend", "drag")
    assert sim.forces.n_active_springs == model.n_springs
    sim.wind = (0, 0, 1.0)
    with pytest.raises(AssertionError, match="inactive term"):
        sim.step()  # now the wind term is live and calls its kernel


def test_damping_force_opposes_the_relative_velocity_along_the_spring():
    model = ClothModel.from_springs(
        [[0, 0, 0], [1, 0, 0]], [1, 1], [[0, 1]], stiffness=0.0, damping=2.0
    )
    sim = Simulator(model, gravity=NO_GRAVITY)
    v = np.array([[0.0, 0.0, 0.0], [3.0, 5.0, 0.0]])  # separating at 3 m/s, sliding sideways at 5
    f = sim.forces.force(sim.positions.copy(), v)
    np.testing.assert_allclose(f, [[6.0, 0, 0], [-6.0, 0, 0]])


def test_strain_limit_keeps_a_soft_hanging_cloth_within_tau():
    soft = cloth16(k=50.0, damping=0.05)
    free = Simulator(soft, dt=1e-3)
    worst_free = 0.0
    for _ in range(30):
        free.step(100)
        worst_free = max(worst_free, free.max_strain())
    assert worst_free > 0.5  # without the correction the cloth over-stretches
    tau = 0.1
    sim = Simulator(soft, dt=1e-3, strain_limit=tau)
    for _ in range(3000):
        sim.step()
        assert sim.max_strain() <= tau + 0.01
    # the pins never moved
    np.testing.assert_array_equal(sim.positions[soft.pinned], soft.positions[soft.pinned])


def test_strain_limit_moves_only_the_free_end_next_to_a_pin():
    def stretched(x, pinned):
        return ClothModel.from_springs(
            x,
            np.ones(len(x)),
            [[i, i + 1] for i in range(len(x) - 1)],
            stiffness=0.0,
            rest_lengths=1.0,
            pinned=pinned,
        )

    # one spring: the free end goes exactly to (1 + τ)·L; both free: each end moves half
    sim = Simulator(
        stretched([[0, 0, 0], [2, 0, 0]], [0]), gravity=NO_GRAVITY, strain_limit=0.2, dt=0.5
    )
    sim.step()
    np.testing.assert_allclose(sim.positions[:, 0], [0.0, 1.2])
    # the particle did not move during the step: moving it back is a projection, not a velocity
    # (divided by a small dt it would be a false speed)
    np.testing.assert_allclose(sim.velocities[:, 0], [0.0, 0.0])
    # a correction that undoes part of the step's own motion: v follows Δx/dt, v = (x⁺ − x)/dt
    sim = Simulator(
        stretched([[0, 0, 0], [1, 0, 0]], [0]), gravity=NO_GRAVITY, strain_limit=0.2, dt=0.5
    )
    sim.velocities = [[0, 0, 0], [1.0, 0, 0]]
    sim.step()
    np.testing.assert_allclose(sim.positions[:, 0], [0.0, 1.2])
    np.testing.assert_allclose(sim.velocities[:, 0], [0.0, (1.2 - 1.0) / 0.5])
    sim = Simulator(stretched([[0, 0, 0], [2, 0, 0]], None), gravity=NO_GRAVITY, strain_limit=0.2)
    sim.step()
    np.testing.assert_allclose(sim.positions[:, 0], [0.4, 1.6])
    # a chain converges over passes to strains <= τ (within the pass tolerance), the pin fixed
    x0 = np.array([[0, 0, 0], [2, 0, 0], [4.5, 0, 0], [5, 1, 0]], float)
    sim = Simulator(
        stretched(x0, [0]), gravity=NO_GRAVITY, strain_limit=0.2, dt=1.0, strain_limit_passes=100
    )
    sim.step()
    assert np.all(sim.strains() <= 0.2 + 1e-4)
    assert sim.positions[0, 0] == 0.0
    np.testing.assert_allclose(sim.velocities, 0.0)  # nothing moved in the step: a projection


def test_pins_stay_put_and_can_be_moved():
    model = cloth16(k=200.0, damping=0.05)
    sim = Simulator(model, integrator="verlet", dt=1e-3)
    pins = np.flatnonzero(model.pinned)
    sim.advance(0.2)
    np.testing.assert_array_equal(sim.positions[pins], model.positions[pins])
    assert np.all(sim.velocities[pins] == 0)
    target = model.positions[pins] + [0.0, 0.0, 0.05]
    sim.move_pins(target)
    sim.advance(0.4)
    np.testing.assert_array_equal(sim.positions[pins], target)
    assert np.all(sim.velocities[pins] == 0)
    with pytest.raises(ValueError, match="pinned particle"):
        sim.move_pins([[0, 0, 0]], indices=[5])


@pytest.mark.parametrize("model_name", ["provot", "choi_ko"])
def test_spring_forces_are_bit_identical_at_any_thread_count(model_name, monkeypatch):
    """The spring forces run on every core as a gather (each particle sums its springs' forces in
    spring order): the same bits as the serial scatter loop, and a whole run is the same bits at 1
    and at 2 threads, with the updates fused into the gather (symplectic Euler, Runge–Kutta stages)
    or not."""
    import numba

    rng = np.random.default_rng(5)
    monkeypatch.setattr(forces, "PARALLEL_MIN_SPRINGS", 1000)  # the parallel gather runs here
    n = 40
    model = ClothModel.grid(
        n, n, 1.0 / n, 0.01, stiffness=300.0, damping=0.05, pinned=[(0, 0)], model=model_name
    )
    sim = Simulator(model, dt=1e-4)
    term = sim.forces.spring_term
    assert len(term.springs) >= forces.PARALLEL_MIN_SPRINGS
    x = model.positions + rng.normal(scale=0.01, size=model.positions.shape)
    v = rng.normal(size=x.shape)
    serial, gathered = np.zeros_like(x), np.zeros_like(x)
    force_kernels.spring_forces(
        x,
        v,
        term.springs,
        term.rest,
        term.k,
        term.c,
        term.kind,
        force_kernels.BUCKLE_TABLE,
        True,
        serial,
    )
    term.add_force(x, v, gathered)
    assert np.array_equal(serial, gathered)

    v0 = rng.normal(scale=0.01, size=x.shape)
    provot = ClothModel.grid(n, n, 1.0 / n, 0.01, stiffness=300.0, damping=0.05, pinned=[(0, 0)])

    def run(threads, wind=(0.0, 0.01, 0.02), integrator="symplectic_euler", steps=200):
        before = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:  # a Provot run (Choi–Ko's onset force, 12k/L², throws a grid this fine apart)
            s = Simulator(provot, dt=2e-5, wind=wind, strain_limit=0.1, integrator=integrator)
            s.velocities = v0
            term = s.forces.spring_term
            if wind is None:  # the fused path runs exactly when the gather does
                assert s.forces.terms[-1] is term and term.parallel == (
                    forces.PARALLEL_MIN_SPRINGS < 10**9
                )
                assert s.forces.fuses_stages == term.parallel
            s.step(steps)
            return s.positions, s.velocities
        finally:
            numba.set_num_threads(before)

    two = min(2, numba.config.NUMBA_NUM_THREADS)
    assert all(np.array_equal(a, b) for a, b in zip(run(1), run(two)))
    # gravity and springs only: symplectic Euler's update runs inside the gather
    # (Forces.gather_update) and the Runge–Kutta stages' forces, mass division and next state in
    # one pass (force_kernels.runge_kutta_fused); with wind after the springs, the stages'
    # update alone on every core
    kinds = [
        dict(wind=None),
        dict(wind=None, integrator="rk4", steps=60),
        dict(wind=None, integrator="midpoint", steps=60),
        dict(integrator="rk4", steps=60),
    ]
    fused = [(run(1, **kw), run(two, **kw)) for kw in kinds]
    monkeypatch.setattr(forces, "PARALLEL_MIN_SPRINGS", 10**9)  # the serial loop and update pass
    for kw, (one, both) in zip(kinds, fused):
        serial = run(1, **kw)  # (Runge–Kutta: the stage-by-stage path, a kernel call per stage)
        assert all(
            np.array_equal(a, b) and np.array_equal(a, c) for a, b, c in zip(one, both, serial)
        ), kw


def test_long_range_attachments_reach_is_the_rest_geodesic_and_never_over_constrains():
    """Kim et al. 2012's attachments: a particle's reach to a pin is its rest distance along the
    springs; a chain stretched 50 % comes back within (1 + τ) of it, every spring within τ, and a
    cloth at rest is left exactly where it is."""
    from cloth_sim.constraints.strain_limit import StrainLimit, nearest_attachments

    n, L = 12, 0.1
    x = np.c_[np.arange(n) * L, np.zeros(n), np.zeros(n)]
    chain = ClothModel.from_springs(
        x, np.full(n, 0.01), [[i, i + 1] for i in range(n - 1)], 100.0, pinned=[0]
    )
    anchor, reach = nearest_attachments(chain)
    assert anchor[0, 0] == -1 and np.all(anchor[1:, 0] == 0) and np.all(anchor[:, 1] == -1)
    np.testing.assert_allclose(reach[1:, 0], np.arange(1, n) * L)
    stretched = 1.5 * x
    limit = StrainLimit(chain, 0.1)
    limit.correct(stretched)
    assert np.all(
        np.linalg.norm(stretched[1:] - stretched[0], axis=1) <= 1.1 * reach[1:, 0] * (1 + 1e-12)
    )
    assert np.max(np.linalg.norm(np.diff(stretched, axis=0), axis=1)) <= 1.1 * L * (1 + 1e-4)
    cloth = cloth16()
    at_rest = cloth.positions.copy()
    StrainLimit(cloth, 0.1).correct(at_rest)
    assert np.array_equal(at_rest, cloth.positions)


def test_long_range_attachments_on_every_core_are_the_serial_pass_bit_for_bit(monkeypatch):
    """From PARALLEL_MIN_PARTICLES on, the attachments before the strain limit's projection run
    on every core: a strain-limited hanging cloth after 0.2 s is the same bits with the serial
    pass, and at 1 and 2 threads. (Provot's passes look at the attachments of the particles they
    moved, inside their kernel.)"""
    import numba

    from cloth_sim.constraints import strain_limit as constraints

    def run(threshold, threads):
        monkeypatch.setattr(constraints, "PARALLEL_MIN_PARTICLES", threshold)
        before = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            model = ClothModel.grid(
                24,
                24,
                1 / 23,
                10.24 / 24**2,
                stiffness=1000.0,
                damping=0.02,
                pinned=[(0, 0), (0, 23)],
            )
            sim = Simulator(model, dt=1e-3, strain_limit=0.1, strain_limit_method="projection")
            assert (sim._strain._attach is constraints.attachment_pass_parallel) == (
                threshold == 1
            )
            sim.advance(0.2)
            return sim.state.x.copy(), sim.state.v.copy()
        finally:
            numba.set_num_threads(before)

    two = min(2, numba.config.NUMBA_NUM_THREADS)
    serial, one, both = run(10**9, 1), run(1, 1), run(1, two)
    assert all(np.array_equal(a, b) and np.array_equal(a, c) for a, b, c in zip(serial, one, both))
    assert np.abs(serial[0] - ClothModel.grid(24, 24, 1 / 23, 0.01, 1000.0).positions).max() > 0.01


def _full_passes(limit, x) -> int:
    """Provot's passes as they were, each over every spring, with the attachments over every
    particle after each (from the public kernels): what ``StrainLimit.correct`` must equal."""
    from cloth_sim.constraints import strain_limit as sl
    from cloth_sim.constraints import strain_limit_kernels as slk

    springs, rest, pinned = limit._springs, limit._rest, limit.model.pinned
    anchor, reach = sl.nearest_attachments(limit.model) if limit.long_range else (None, None)
    attach = anchor is not None and np.any(anchor >= 0)
    used = 1 if attach and slk.attachment_pass(x, anchor, reach, limit.tau) else 0
    for _ in range(limit.passes):
        changed = slk.provot_pass(x, springs, rest, limit.tau, sl.STRAIN_LIMIT_TOLERANCE, pinned)
        if attach and changed:
            slk.attachment_pass(x, anchor, reach, limit.tau)
        if changed == 0:
            break
        used += 1
    return used


@pytest.mark.parametrize("share", [0, 32, 10**9])
@pytest.mark.parametrize("pins", ["corners", "none", "corners, no attachments"])
def test_provot_passes_visit_what_can_change_and_are_every_springs_passes_bit_for_bit(
    monkeypatch, rng, share, pins
):
    """``provot_passes`` visits, after the first pass, only the springs at a particle moved after
    their last visit, and looks at the attachments of the particles moved since: the same
    corrections in the same order as passes over every spring, so the same positions to the bit
    and the same count, on cloths stretched at random (every spring over: full passes) and at
    rest with a few springs pulled (a few: the heap's passes), with and without pins and
    attachments; ``share`` 0 keeps to the heap after the first pass, 10⁹ to full passes."""
    from cloth_sim.constraints import strain_limit as sl

    monkeypatch.setattr(sl, "FULL_PASS_SHARE", share)
    pinned = [] if pins == "none" else [(0, 0), (0, 19)]
    model = ClothModel.grid(20, 20, 0.05, 0.01, stiffness=100.0, pinned=pinned)
    limit = sl.StrainLimit(model, 0.1, long_range=pins != "corners, no attachments")
    x0 = model.positions
    pulled = x0.copy()
    pulled[rng.choice(400, 6, replace=False)] += rng.normal(0.0, 0.02, (6, 3))
    noisy = x0 * 1.15 + rng.normal(0.0, 0.004, x0.shape)
    for start in (pulled, noisy, pulled):
        a, b = start.copy(), start.copy()
        used = limit.correct(a)
        assert used == _full_passes(limit, b)
        assert np.array_equal(a, b)
        assert used >= 2 and not np.array_equal(a, start)


def test_the_largest_strain_without_a_root_a_spring_is_the_largest_of_the_strains(rng):
    """``max_spring_strain`` (the largest ``(l/L)²``, one square root) gives the largest of
    ``spring_strains`` to rounding on random springs, NaN where a position is NaN (a diverged
    cloth is not hidden), and ``-inf`` for no spring."""
    from cloth_sim.physics.force_kernels import max_spring_strain, spring_strains

    for _ in range(100):
        x = rng.normal(size=(40, 3))
        springs = rng.integers(0, 40, size=(60, 2))
        springs = springs[springs[:, 0] != springs[:, 1]]
        rest = rng.uniform(0.1, 2.0, len(springs))
        expected = spring_strains(x, springs, rest).max()
        assert max_spring_strain(x, springs, rest) == pytest.approx(expected, rel=1e-13, abs=1e-13)
    x[springs[5, 1]] = np.nan
    assert np.isnan(max_spring_strain(x, springs, rest))
    assert max_spring_strain(x, springs[:0], rest[:0]) == -np.inf
