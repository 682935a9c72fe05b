"""The strain limit's projection method (:mod:`cloth_sim.constraints.strain_projection`): closed
forms for one spring, conservation of the centre of mass, the bound held where Provot's passes
plateau, and bad values refused with the state kept."""

import dataclasses

import numba
import numpy as np
import pytest

from cloth_sim import ClothModel, Simulator
from cloth_sim.bench.steps import _hanging
from cloth_sim.constraints import strain_projection
from cloth_sim.constraints.strain_limit import StrainLimit
from cloth_sim.parameters import ParameterError
from cloth_sim.scene import SceneError, scene_from_dict

NO_GRAVITY = (0.0, 0.0, 0.0)


def chain(x, masses, pinned=None, rest=1.0):
    return ClothModel.from_springs(
        x,
        masses,
        [[i, i + 1] for i in range(len(x) - 1)],
        stiffness=0.0,
        rest_lengths=rest,
        pinned=pinned,
    )


def test_one_spring_goes_to_its_bound_each_end_moving_by_its_inverse_mass():
    # masses 1 and 3, rest 1, stretched to 2, τ = 0.1: 0.9 to remove, shared 3 : 1. The inverse
    # masses scaled so the largest is 1 (1 and 1/3), one iteration solves (w₁ + w₂ + ε) λ = 0.9
    # and leaves ε/(w₁ + w₂ + ε) of the excess (the regularisation), 6.7e-4 of strain: within the
    # tolerance, so it stops there
    eps = strain_projection.REGULARISATION
    model = chain([[0, 0, 0], [2, 0, 0]], [1.0, 3.0])
    limit = StrainLimit(model, 0.1, method="projection")
    x = model.positions.copy()
    limit.correct(x)
    lam = 0.9 / (1.0 + 1.0 / 3.0 + eps)
    assert 0.9 - lam * (1.0 + 1.0 / 3.0) <= strain_projection.TOLERANCE
    np.testing.assert_allclose(x[:, 0], [lam, 2.0 - lam / 3.0], rtol=1e-12, atol=0)
    assert x[0, 0] / (2.0 - x[1, 0]) == pytest.approx(3.0, rel=1e-12)  # moves ∝ 1/m, exactly
    np.testing.assert_allclose(x[:, 1:], 0.0)
    # a pinned end stays; the free one goes the whole way (its long-range attachment to the pin,
    # applied before the projection, takes it there)
    model = chain([[0, 0, 0], [2, 0, 0]], [1.0, 3.0], pinned=[0])
    x = model.positions.copy()
    StrainLimit(model, 0.1, method="projection").correct(x)
    np.testing.assert_allclose(x[:, 0], [0.0, 1.1], rtol=0, atol=1e-12)


def test_a_free_cloth_keeps_its_centre_of_mass_exactly():
    """Every move is ``−W Jᵀ λ``: the mass-weighted moves sum to zero. The worst case for the
    method, too: every structural and shear spring 40 % over and the cloth crumpled, so all of them
    are active at once and redundant; it comes within its tolerance of the bound in its 20
    iterations."""
    rng = np.random.default_rng(3)
    grid = ClothModel.grid(12, 12, 0.1, 0.01, stiffness=100.0)
    masses = rng.uniform(0.5, 2.0, grid.n_particles)
    model = dataclasses.replace(grid, masses=masses)
    x = 1.4 * model.positions + rng.normal(0.0, 0.02, model.positions.shape)
    before = masses @ x / masses.sum()
    limited = model.springs[model.strain_limited]
    rest = model.rest_lengths[model.strain_limited]

    def worst():
        return (np.linalg.norm(x[limited[:, 1]] - x[limited[:, 0]], axis=1) / rest - 1).max()

    assert worst() > 0.4  # it has work to do
    StrainLimit(model, 0.1, method="projection").correct(x)
    assert worst() <= 0.1 + strain_projection.TOLERANCE
    np.testing.assert_allclose(masses @ x / masses.sum(), before, rtol=0, atol=1e-14)


def test_a_long_pinned_chain_is_held_in_one_step_where_the_passes_are_not():
    # 40 springs stretched 50 % each below a pin: a pass carries a correction one spring down
    n = 41
    x = np.zeros((n, 3))
    x[:, 2] = -1.5 * np.arange(n)
    results = {}
    for method in ("provot", "projection"):
        sim = Simulator(
            chain(x, np.ones(n), pinned=[0]),
            gravity=NO_GRAVITY,
            strain_limit=0.1,
            dt=1.0,
            strain_limit_long_range=False,
            strain_limit_method=method,
        )
        sim.step()
        results[method] = sim.strains().max()
        assert sim.positions[0, 2] == 0.0
    assert results["provot"] > 0.2
    assert results["projection"] <= 0.1 + strain_projection.TOLERANCE


def project(x, springs, rest, w, tau=0.1, cg_tol=strain_projection.CG_TOLERANCE, outer=20):
    """One call of the projection on ``x`` (in place); returns its stats: linearisations, CG
    iterations, active springs, worst excess left."""
    springs = np.asarray(springs, np.uint32)
    scratch = strain_projection.Scratch(springs, x)
    settings = strain_projection.Settings(tau, max_outer=outer, cg_tol=cg_tol)
    rest, w = np.asarray(rest, float), np.asarray(w, float)
    strain_projection.project(x, springs, rest, w, settings, scratch.workspace())
    return scratch.stats.copy()


def test_the_chains_of_a_grid_are_its_lines():
    """The preconditioner's chains (:func:`strain_projection.chain_neighbours`): on a grid each
    strain-limited spring goes on, at either end, into the spring of the same direction, and stops
    only at the grid's border."""
    rows, cols = 5, 7
    model = ClothModel.grid(rows, cols, 0.1, 0.01, stiffness=100.0)
    springs = model.springs[model.strain_limited]
    scratch = strain_projection.Scratch(springs.astype(np.uint32), model.positions)
    cell = {(int(a), int(b)): s for s, (a, b) in enumerate(springs)}
    for s, (a, b) in enumerate(springs):
        (ra, ca), (rb, cb) = divmod(int(a), cols), divmod(int(b), cols)
        dr, dc = rb - ra, cb - ca
        for end, (r, c, step) in enumerate([(ra, ca, -1), (rb, cb, 1)]):
            far = (r + step * dr, c + step * dc)  # the next point on this spring's line
            expected = -1
            if 0 <= far[0] < rows and 0 <= far[1] < cols:
                p, o = r * cols + c, far[0] * cols + far[1]
                expected = cell.get((p, o), cell.get((o, p)))
            assert scratch.nb[s, end] == expected, (s, end)
    assert (scratch.nb >= 0).sum() > len(springs)  # most ends go on


def test_on_a_chain_the_preconditioner_is_the_system_one_cg_iteration_a_solve():
    """A pinned chain of 40 springs along an arc, their ends alternately reversed, all 15 % over:
    the set is one chain and its block all of ``J W Jᵀ + ε``, so each solve is exact in one CG
    iteration (the couplings' signs where a particle ends one spring and starts the next
    included; on the arc they are not all ±w)."""
    n = 41
    theta = np.linspace(0.0, 1.0, n)
    x = np.c_[30 * np.sin(theta), 30 * (1 - np.cos(theta)), np.zeros(n)]
    springs = [[i, i + 1] if i % 2 else [i + 1, i] for i in range(n - 1)]
    rest = np.linalg.norm(x[1:] - x[:-1], axis=1) / 1.15
    w = np.ones(n)
    w[0] = 0.0
    stats = project(x, springs, rest, w, cg_tol=1e-12)
    linearisations, cg = stats[0], stats[1]
    assert linearisations >= 2
    assert cg == linearisations
    assert stats[3] <= strain_projection.TOLERANCE
    assert x[0].tolist() == [0.0, 0.0, 0.0]


def test_a_closed_ring_is_cut_once_and_still_solved_in_three_cg_iterations():
    """A ring of 30 springs all 30 % over has no chain end: the walk cuts it where it starts, so
    the preconditioner misses one coupling of the system, a change of rank two: CG needs at most
    three iterations a solve. The moves keep the centre of mass."""
    n = 30
    angle = 2 * np.pi * np.arange(n) / n
    x = np.c_[np.cos(angle), np.sin(angle), np.zeros(n)]
    springs = [[i, (i + 1) % n] for i in range(n)]
    rest = np.full(n, 2 * np.sin(np.pi / n) / 1.3)
    masses = np.linspace(1.0, 2.0, n)
    before = masses @ x / masses.sum()
    stats = project(x, springs, rest, 1.0 / masses, cg_tol=1e-12)
    assert stats[1] <= 3 * stats[0]
    assert stats[3] <= strain_projection.TOLERANCE
    np.testing.assert_allclose(masses @ x / masses.sum(), before, rtol=0, atol=1e-14)


def crumpled_grid(cells, stretch, seed):
    """A free grid of ``cells``² cells scaled by ``stretch`` and shaken: its strain-limited
    springs, their rest lengths, unit inverse masses and the positions."""
    rng = np.random.default_rng(seed)
    model = ClothModel.grid(cells, cells, 0.02, 0.01, stiffness=100.0)
    x = stretch * model.positions + rng.normal(0.0, 0.002, model.positions.shape)
    limited = np.ascontiguousarray(model.springs[model.strain_limited], np.uint32)
    rest = np.ascontiguousarray(model.rest_lengths[model.strain_limited])
    return model, limited, rest, np.ones(model.n_particles), x


def test_the_first_measure_in_chunks_gives_the_same_bits_at_any_thread_count():
    """A step's first measure runs in parallel over fixed chunks of springs, merged in order: a
    cloth of several chunks, projected call after call (each call's set the next one's warm
    start), ends alike at one and two threads."""
    model, springs, rest, w, x0 = crumpled_grid(48, 1.25, 5)
    assert len(springs) > 2 * strain_projection.CHUNK  # several chunks
    settings = strain_projection.Settings(0.1)
    threads = numba.get_num_threads()
    runs = []
    try:
        for n_threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(n_threads)
            scratch = strain_projection.Scratch(springs, model.positions)
            x = x0.copy()
            out = []
            for call in range(4):
                x += 0.004 * np.sin(np.arange(x.size) * (call + 1.0)).reshape(x.shape)
                strain_projection.project(x, springs, rest, w, settings, scratch.workspace())
                assert scratch.stats[3] <= strain_projection.TOLERANCE
                out.append((x.copy(), scratch.stats.copy()))
            runs.append(out)
    finally:
        numba.set_num_threads(threads)
    for (xa, sa), (xb, sb) in zip(*runs):
        assert np.array_equal(xa, xb) and np.array_equal(sa, sb)


def test_the_warm_start_is_the_last_calls_set_and_only_it():
    """The first measure takes the last call's springs still within ``WARM_START`` of their bound.
    After a call that found nothing, springs just inside their bound join nothing, though a call
    before that had them all in its set."""
    model, springs, rest, w, x0 = crumpled_grid(48, 1.25, 6)
    settings = strain_projection.Settings(0.1)
    scratch = strain_projection.Scratch(springs, model.positions)

    def call(x):
        strain_projection.project(x, springs, rest, w, settings, scratch.workspace())
        return scratch.stats.copy()

    near = model.positions * (1.1 - strain_projection.WARM_START / 2)  # every spring near τ
    assert call(x0.copy())[2] > 0.9 * len(springs)  # crumpled: nearly all in the set
    assert call(near.copy())[2] > 0.9 * len(springs)  # still near their bound: kept, held
    assert call(model.positions.copy())[2] == 0  # at rest: none joins, the set empties
    x = near.copy()
    assert call(x)[2] == 0  # near again, but the last set was empty
    np.testing.assert_array_equal(x, near)


def test_the_hanging_cloth_keeps_its_stretch_at_the_limit_through_its_swing():
    """The 1 m, 10.24 kg cloth from its two corners (docs/BENCHMARKS.md §3): the passes leave
    0.1057 at 32×32 at the bottom of the swing; the projection holds τ + its tolerance."""
    worst = {}
    for method in ("provot", "projection"):
        sim = _hanging(32, strain_limit=0.1, strain_limit_method=method)
        w = 0.0
        while sim.time < 1.6:
            sim.step(10)
            w = max(w, sim.max_strain())
        worst[method] = w
    assert worst["provot"] > 0.104
    assert worst["projection"] <= 0.1 + strain_projection.TOLERANCE


def test_the_method_is_live_and_a_bad_one_is_refused_with_the_state_kept():
    sim = _hanging(12, strain_limit=0.1, strain_limit_method="provot")
    sim.step(50)
    x = sim.positions.copy()
    sim.strain_limit_method = "projection"
    assert sim.strain_limit_method == "projection"
    np.testing.assert_array_equal(sim.positions, x)
    sim.step(50)
    with pytest.raises(ParameterError, match=r"strain_limit_method 'jacobi' .*provot, projection"):
        sim.strain_limit_method = "jacobi"
    assert sim.strain_limit_method == "projection"
    with pytest.raises(ParameterError, match="strain_limit_method"):
        Simulator(sim.model, strain_limit=0.1, strain_limit_method="exact")


def test_a_scene_names_the_method_or_is_refused_naming_the_field():
    base = {"grid": {"rows": 4, "cols": 4, "spacing": 0.1}, "strain_limit": 0.1}
    scene = scene_from_dict({**base, "strain_limit_method": "projection"})
    assert scene.build_simulator().strain_limit_method == "projection"
    with pytest.raises(SceneError, match="strain_limit_method"):
        scene_from_dict({**base, "strain_limit_method": "fast"})
