"""The implicit integrators: Jacobians by finite differences, convergence order, conservation laws,
large-step stability, the prefactored path's factorisation bookkeeping, and Kang's method."""

import math

import numpy as np
import pytest
import scipy.sparse as sp
from cloths import cloth16, free_cloth, free_fall, one_spring
from scipy.sparse.linalg import spsolve

from cloth_sim import ClothModel, SimulationDiverged, Simulator, integrators
from cloth_sim.physics.forces import Forces

NO_GRAVITY = (0.0, 0.0, 0.0)
IMPLICIT_EULER = [
    ("implicit_euler", {}),
    ("implicit_euler", {"solver": "direct"}),
    ("implicit_euler_prefactored", {}),
]
IDS = ["bw-cg", "bw-direct", "prefactored"]


def test_registry_has_the_implicit_methods_and_their_stability_claims():
    names = integrators.available()
    assert names[5:8] == ["implicit_euler", "implicit_euler_prefactored", "kang"]
    for name in ("implicit_euler", "implicit_euler_prefactored"):
        assert Simulator(cloth16(), integrator=name, dt=1.0).stable_dt() == math.inf
    with pytest.raises(ValueError, match="solver must be one of cg, direct"):
        Simulator(cloth16(), integrator="implicit_euler", integrator_options={"solver": "lu"})
    with pytest.raises(ValueError, match="sweeps must be >= 1"):
        Simulator(cloth16(), integrator="kang", integrator_options={"sweeps": 0})


# ------------------------------------------------------------------ Jacobians
def stretched_state(model, rng, stretch=1.08, noise=0.01):
    """A smooth, non-planar, stretched configuration and random velocities."""
    x = model.positions * stretch
    x[:, 2] += 0.05 * np.sin(3 * x[:, 0]) * np.cos(2 * x[:, 1])
    x += rng.normal(scale=noise, size=x.shape)
    v = rng.normal(scale=0.5, size=x.shape)
    return x, v


def fd_jacobian(fun, y, eps=1e-6):
    """Central differences of ``fun`` (``(n,3) → (n,3)``) with respect to ``y``, dense."""
    n = y.size
    J = np.empty((n, n))
    for c in range(n):
        yp, ym = y.copy(), y.copy()
        yp.flat[c] += eps
        ym.flat[c] -= eps
        J[:, c] = (fun(yp) - fun(ym)).ravel() / (2 * eps)
    return J


def rel_err(A, B):
    return np.linalg.norm(A - B) / np.linalg.norm(B)


TERMS = {
    # name: (model kwargs, stiffness, damping, drag, compress the bend pairs)
    "hooke": ("provot", 300.0, 0.0, 0.0),
    "damping": ("provot", 0.0, 0.7, 0.0),
    "hooke+damping+drag": ("provot", 300.0, 0.7, 0.3),
    "choi_ko": ("choi_ko", 300.0, 0.0, 0.0),
}


@pytest.mark.parametrize("term", TERMS)
def test_force_jacobians_match_finite_differences(rng, term):
    model_name, k, c, drag = TERMS[term]
    model = ClothModel.grid(5, 5, 0.1, 0.01, stiffness=k, damping=c, model=model_name)
    forces = Forces(
        model,
        np.array(model.stiffness, float),
        np.array(model.damping, float),
        gravity=NO_GRAVITY,
        drag=drag,
    )
    x, v = stretched_state(model, rng)
    if model_name == "choi_ko":
        # squeeze it so that the Choi–Ko bend pairs are compressed (buckling branch, r < 1)
        x[:, 0] *= 0.8
        bend = model.family == model.family_index("bend")
        r = (
            np.linalg.norm(x[model.springs[:, 1]] - x[model.springs[:, 0]], axis=1)
            / model.rest_lengths
        )
        assert np.any(r[bend & (model.kind == 2)] < 0.95) and np.any(r[model.kind == 1] > 1.0)
    dfdx, dfdv = forces.jacobians(x, v, clamp=False)
    Jx = fd_jacobian(lambda y: forces.force(y, v), x)
    Jv = fd_jacobian(lambda y: forces.force(x, y), v)
    assert rel_err(dfdx.toarray(), Jx) < 1e-6
    if np.linalg.norm(Jv) > 0:
        assert rel_err(dfdv.toarray(), Jv) < 1e-6
    else:
        assert dfdv.nnz == 0 or np.abs(dfdv.toarray()).max() == 0


def test_clamped_jacobian_is_negative_semidefinite_and_differs_only_under_compression(rng):
    model = ClothModel.grid(5, 5, 0.1, 0.01, stiffness=300.0)
    forces = Forces(model, np.array(model.stiffness, float), np.array(model.damping, float))
    x, v = stretched_state(model, rng, stretch=1.1, noise=0.0)
    exact, _ = forces.jacobians(x, v)
    clamped, _ = forces.jacobians(x, v, clamp=True)
    np.testing.assert_allclose(clamped.toarray(), exact.toarray(), atol=1e-9)  # all stretched
    x[:, 0] *= 0.7  # now some springs are compressed
    exact, _ = forces.jacobians(x, v)
    clamped, _ = forces.jacobians(x, v, clamp=True)
    assert np.linalg.eigvalsh(exact.toarray()).max() > 1.0  # indefinite
    assert np.linalg.eigvalsh(clamped.toarray()).max() < 1e-9


# ------------------------------------------------------------------ accuracy
def oscillator_error(name, options, dt, T=1.0, k=100.0, m=1.0, A=0.1):
    sim = Simulator(
        one_spring(k, m, amplitude=A),
        integrator=name,
        dt=dt,
        gravity=NO_GRAVITY,
        integrator_options=options,
    )
    omega = math.sqrt(k / m)
    err = 0.0
    for _ in range(round(T / dt)):
        sim.step()
        err = max(err, abs(sim.positions[1, 0] - (1.0 + A * math.cos(omega * sim.time))))
    return err


@pytest.mark.parametrize("name,options", IMPLICIT_EULER + [("kang", {})], ids=IDS + ["kang"])
def test_first_order_convergence_on_the_harmonic_oscillator(name, options):
    dts = np.array([2e-3, 1e-3, 5e-4, 2.5e-4])
    errs = np.array([oscillator_error(name, options, dt) for dt in dts])
    observed = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert observed == pytest.approx(1.0, abs=0.15), errs


@pytest.mark.parametrize("name,options", IMPLICIT_EULER, ids=IDS)
def test_free_fall_centre_of_mass_is_offset_like_symplectic_euler(rng, name, options):
    """Internal forces cancel in the sum, so the centre of mass follows v += dt·g, x += dt·v:
    x_cm = x0 + v0 t + g t²/2 + g·dt·t/2."""
    model, v0 = free_cloth(rng)
    g = np.array([0.0, 0.0, -9.81])
    dt = 1e-2
    opts = dict(options)
    if name == "implicit_euler" and opts.get("solver") != "direct":
        opts["cg_tolerance"] = 1e-12
    sim = Simulator(model, integrator=name, dt=dt, gravity=g, integrator_options=opts)
    com, exact, t = free_fall(sim, v0, 50)
    np.testing.assert_allclose(com, exact + 0.5 * g * dt * t, rtol=0, atol=1e-10)


@pytest.mark.parametrize(
    "name,options,tol",
    [
        ("implicit_euler", {"solver": "direct"}, 1e-12),
        ("implicit_euler", {"cg_tolerance": 1e-8}, 1e-7),
        ("implicit_euler_prefactored", {}, 1e-12),
    ],
    ids=["bw-direct", "bw-cg", "prefactored"],
)
def test_momentum_is_conserved_to_the_solver_tolerance(rng, name, options, tol):
    model, v0 = free_cloth(rng, drift=(0.0, 0.0, 0.0))
    sim = Simulator(
        model, integrator=name, dt=1e-2, gravity=NO_GRAVITY, integrator_options=options
    )
    sim.velocities = v0
    m = model.masses[:, None]
    p0 = (m * sim.velocities).sum(0)
    scale = float((m * np.abs(v0)).sum())
    sim.step(100)
    drift = np.max(np.abs((m * sim.velocities).sum(0) - p0))
    assert drift <= tol * scale
    assert np.max(np.abs(sim.velocities - v0)) > 1e-3  # the springs did act


# ------------------------------------------------------------------ large steps
@pytest.mark.parametrize("name", ["implicit_euler", "implicit_euler_prefactored"])
def test_stiff_cloth_stays_bounded_at_a_thirtieth_of_a_second(name):
    model = ClothModel.grid(
        32, 32, 1.0 / 31, 0.01, stiffness=1e4, damping=0.0, pinned=[(0, 0), (0, -1)]
    )
    sim = Simulator(model, integrator=name, dt=1.0 / 30)
    assert sim.stable_dt() == math.inf
    explicit_limit = Simulator(model, integrator="symplectic_euler").stable_dt()
    assert sim.dt > 50 * explicit_limit
    kinetic = []
    for _ in range(90):  # 3 s
        sim.step()
        kinetic.append(sim.energy()["kinetic"])
    x = sim.positions
    assert np.all(np.isfinite(x))
    assert np.max(np.abs(x)) < 2.0  # a 1 m cloth hanging from two corners
    # bounded: no more kinetic energy than the whole drop of the cloth's weight could give
    weight_drop = model.masses.sum() * 9.81 * 1.5
    assert max(kinetic) < weight_drop
    assert sim.max_strain() < 0.2
    assert x[:, 2].min() < -0.1  # and it did fall


@pytest.mark.parametrize("name,options", IMPLICIT_EULER + [("kang", {})], ids=IDS + ["kang"])
def test_hanging_chain_settles_to_the_static_extensions_with_large_steps(name, options):
    n, k, m, g, L = 6, 200.0, 0.05, 9.81, 0.1
    x = np.zeros((n, 3))
    x[:, 2] = -L * np.arange(n)
    model = ClothModel.from_springs(
        x, np.full(n, m), [[i, i + 1] for i in range(n - 1)], stiffness=k, damping=0.0, pinned=[0]
    )
    dt = 0.05 if name != "kang" else 0.005  # Kang goes unstable near 0.01 here
    sim = Simulator(model, integrator=name, dt=dt, gravity=(0, 0, -g), integrator_options=options)
    if name != "kang":
        assert dt * math.sqrt(k / m) > 3  # far beyond any explicit method's limit
    sim.advance(60.0)
    lengths = np.linalg.norm(np.diff(sim.positions, axis=0), axis=1)
    j_from_bottom = np.arange(n - 1, 0, -1)
    np.testing.assert_allclose(lengths - L, j_from_bottom * m * g / k, rtol=1e-6)


def test_cg_and_direct_solves_agree_and_cg_reports_its_iterations():
    sims = {
        s: Simulator(
            cloth16(damping=0.02),
            integrator="implicit_euler",
            dt=1 / 60,
            integrator_options={"solver": s, "cg_tolerance": 1e-10},
        )
        for s in ("cg", "direct")
    }
    for sim in sims.values():
        sim.step(20)
    np.testing.assert_allclose(sims["cg"].positions, sims["direct"].positions, atol=1e-8)
    stats = sims["cg"].integrator_stats
    assert stats["solves"] == 20 and stats["cg_iterations"] > 20 and stats["direct_fallbacks"] == 0


def test_matrix_free_cg_is_the_assembled_system_and_meets_its_tolerance_at_any_thread_count():
    """The compiled solve (:func:`~cloth_sim.integrators.implicit._pcg`) on a step's own system:
    its matrix-free product is the assembled matrix's (the one the direct solve factorises), the
    preconditioner's blocks are that matrix's 3×3 diagonal blocks, the true residual |b − A·x| is
    within the tolerance of |b| (scipy's product, not the solver's recurrence), the blocks need
    fewer iterations than no preconditioner, and 1 and 2 threads give the same bits."""
    import numba

    from cloth_sim.integrators import implicit as imp

    model = cloth16(damping=0.02)
    sim = Simulator(model, integrator="implicit_euler", dt=1 / 60)
    sim.step(5)
    integ, forces = sim._integrator, sim.forces
    x, v, dt = sim.positions.copy(), sim.velocities.copy(), sim.dt
    kx, _, cv = forces.spring_term.jacobian_blocks(x, v, True, position_damping=False)
    f = forces.force(x, v)
    diag = model.masses + dt * forces.drag
    imp._system_blocks(forces.springs, kx, cv, f, v, dt, diag, integ._rhs, *integ._system[4:])
    b = integ._rhs.ravel()[integ._free_dofs].copy()
    A = integ._matrix
    imp._assemble_baraff_witkin(
        forces.springs, kx, cv, f, v, dt, diag, integ._slot, integ._dslot, A.data, integ._rhs
    )
    np.testing.assert_array_equal(integ._rhs.ravel()[integ._free_dofs], b)
    probe = np.random.default_rng(3).normal(size=len(b))
    product, partial = np.empty_like(b), np.empty((imp._SLICES, 3))
    imp._system_product(*integ._system, probe, product, partial)
    np.testing.assert_allclose(
        product, A @ probe, rtol=1e-12, atol=1e-12 * np.abs(A @ probe).max()
    )
    assert partial[:, 0].sum() == pytest.approx(probe @ (A @ probe), rel=1e-12)
    inv = np.empty((len(b) // 3, 6))  # upper triangles
    imp._block_inverses(integ._system[0], integ._system[5], inv)
    full = inv[:, [[0, 1, 2], [1, 3, 4], [2, 4, 5]]]
    blocks = sp.block_diag([np.linalg.inv(full[k]) for k in range(len(full))])
    np.testing.assert_allclose(
        (blocks - A.multiply(blocks != 0)).toarray(), 0.0, atol=1e-9 * np.abs(A.diagonal()).max()
    )

    def solve(threads, inv=inv):
        before = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            y = np.zeros_like(b)
            its = imp._pcg(
                integ._system,
                inv,
                b,
                y,
                1e-10,
                5000,
                *np.empty((4, len(b))),
                np.empty((imp._SLICES, 3)),
            )
            return its, y
        finally:
            numba.set_num_threads(before)

    its, y = solve(1)
    assert 0 < its < 5000
    assert np.linalg.norm(b - A @ y) <= 1.5e-10 * np.linalg.norm(b)
    its2, y2 = solve(min(2, numba.config.NUMBA_NUM_THREADS))
    assert its2 == its and np.array_equal(y, y2)
    identity = np.tile([1.0, 0.0, 0.0, 1.0, 0.0, 1.0], (len(inv), 1))  # no preconditioner at all
    assert solve(1, identity)[0] > its


def test_cg_that_does_not_converge_hands_the_step_to_the_direct_solve_and_comes_back():
    """A cap of 2 iterations: CG gives up, the step and the next ``DIRECT_AFTER_FALLBACK`` are
    solved directly (the same states as the direct solver's), then CG is tried again."""
    from cloth_sim.integrators.implicit import ImplicitEuler

    capped = Simulator(
        cloth16(damping=0.02),
        integrator="implicit_euler",
        dt=1 / 60,
        integrator_options={"cg_max_iterations": 2},
    )
    direct = Simulator(
        cloth16(damping=0.02),
        integrator="implicit_euler",
        dt=1 / 60,
        integrator_options={"solver": "direct"},
    )
    while capped.integrator_stats["direct_fallbacks"] == 0 and capped.steps_taken < 5:
        capped.step()  # (the first step, from rest, converges at once: Δv = dt·g)
    stats = capped.integrator_stats
    assert stats["direct_fallbacks"] == 1
    its = stats["cg_iterations"]
    capped.step(ImplicitEuler.DIRECT_AFTER_FALLBACK)
    assert capped.integrator_stats["cg_iterations"] == its  # all direct
    direct.step(capped.steps_taken)
    np.testing.assert_allclose(capped.positions, direct.positions, rtol=0, atol=1e-9)
    capped.step()  # CG again, and it gives up again
    stats = capped.integrator_stats
    assert stats["cg_iterations"] == its + 2 and stats["direct_fallbacks"] == 2


def test_unclamped_jacobian_runs_with_the_direct_solver():
    sim = Simulator(
        cloth16(damping=0.02),
        integrator="implicit_euler",
        dt=1 / 60,
        integrator_options={"solver": "direct", "clamp_compression": False},
    )
    sim.advance(1.0)
    assert np.all(np.isfinite(sim.positions)) and sim.positions[:, 2].min() < -0.3


def test_the_guard_still_catches_a_blow_up_of_an_implicit_method():
    sim = Simulator(cloth16(), integrator="implicit_euler", dt=1 / 60, max_speed=0.5)
    before = None
    with pytest.raises(SimulationDiverged, match="restored"):
        for _ in range(100):
            before = sim.positions.copy()
            sim.step()
    np.testing.assert_array_equal(sim.positions, before)


# ------------------------------------------------------------------ prefactored bookkeeping
def prefactored_matrix(model, dt, drag=0.0):
    """``M − dt·C − dt²·H`` over the free particles, built independently with dense algebra."""
    n = model.n_particles
    W = np.zeros((n, n))
    for (i, j), k, c in zip(model.springs, model.stiffness, model.damping):
        w = dt * c + dt * dt * k
        W[i, j] -= w
        W[j, i] -= w
        W[i, i] += w
        W[j, j] += w
    W += np.diag(model.masses + dt * drag)
    free = ~model.pinned
    return W[np.ix_(free, free)]


def test_prefactored_factorises_once_and_again_after_a_parameter_change():
    model = cloth16(damping=0.02)
    sim = Simulator(model, integrator="implicit_euler_prefactored", dt=1 / 60)
    x, v = sim.positions.copy(), sim.velocities.copy()
    sim.step()
    # the first step equals a direct solve of the same system
    f = sim.forces.force(x, v)
    Hv = np.zeros_like(v)
    for (i, j), k in zip(model.springs, model.stiffness):
        Hv[i] += k * (v[j] - v[i])
        Hv[j] -= k * (v[j] - v[i])
    free = ~model.pinned
    dt = sim.dt
    dv = spsolve(sp.csc_matrix(prefactored_matrix(model, dt)), (dt * (f + dt * Hv))[free])
    np.testing.assert_allclose(sim.velocities[free], v[free] + dv, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sim.positions, x + dt * sim.velocities, rtol=0, atol=1e-15)
    sim.step(999)
    assert sim.integrator_stats == {"solves": 1000, "factorizations": 1}
    sim.gravity = (0.0, 0.0, -5.0)  # does not change the matrix
    sim.wind = (0.0, 0.0, 0.1)
    sim.step(10)
    assert sim.integrator_stats["factorizations"] == 1
    sim.set_stiffness("shear", 500.0)
    sim.step(10)
    assert sim.integrator_stats["factorizations"] == 2
    sim.dt = 1 / 120
    sim.step(10)
    assert sim.integrator_stats["factorizations"] == 3
    sim.set_damping("structural", 0.1)
    sim.drag = 0.01
    sim.step(10)
    assert sim.integrator_stats["factorizations"] == 4


# ------------------------------------------------------------------ Kang
def test_kang_runs_and_the_cloth_falls():
    sim = Simulator(cloth16(), integrator="kang", dt=5e-4)
    z0 = sim.positions[:, 2].mean()
    sim.advance(1.0)
    assert np.all(np.isfinite(sim.positions))
    assert sim.positions[:, 2].mean() < z0 - 0.2
    assert sim.max_strain() < 0.5


def test_kang_is_not_unconditionally_stable_and_the_guard_catches_it():
    sim = Simulator(cloth16(), integrator="kang", dt=1 / 60)
    limit = sim.stable_dt()
    assert 1e-4 < limit < 1 / 60
    with pytest.raises(SimulationDiverged, match="kang"):
        sim.advance(3.0)
    assert np.all(np.isfinite(sim.positions))


def test_more_kang_sweeps_approach_the_prefactored_solve():
    """With the damping matrix and drag off, Kang's sweeps are Jacobi iterations on the prefactored
    system: enough of them give the same step."""
    model = cloth16()
    ref = Simulator(model, integrator="implicit_euler_prefactored", dt=2e-3)
    errs = []
    for sweeps in (1, 4, 200):
        sim = Simulator(model, integrator="kang", dt=2e-3, integrator_options={"sweeps": sweeps})
        sim.step(5)
        errs.append(np.max(np.abs(sim.velocities - ref_velocities(ref, 5))))
    assert errs[0] > errs[1] > errs[2] and errs[2] < 1e-9


def ref_velocities(ref, n):
    if ref.steps_taken < n:
        ref.step(n - ref.steps_taken)
    return ref.velocities


def test_bench_implicit_prints_a_row_per_method(capsys):
    from cloth_sim.cli import main as cli_main

    assert (
        cli_main(["bench", "implicit", "--sizes", "8", "--seconds", "0.05", "--dt", "0.002"]) == 0
    )
    rows = [l for l in capsys.readouterr().out.splitlines() if l.startswith("| 8 |")]
    assert [r.split("|")[2].strip() for r in rows] == [
        "symplectic_euler (dt = 0.1 ms)",
        "implicit_euler (CG)",
        "implicit_euler (direct)",
        "implicit_euler_prefactored",
        "kang",
        "liu2013 (10 iterations)",
        "liu2013 (10, Chebyshev)",
        "xpbd (10 substeps)",
    ]
    cg = rows[1].split("|")
    # the ratio to the symplectic step, within what the printed milliseconds' rounding allows
    base, ms, ratio = float(rows[0].split("|")[3]), float(cg[3]), float(cg[4])
    assert (ms - 5e-4) / (base + 5e-4) - 0.5 <= ratio <= (ms + 5e-4) / max(base - 5e-4, 1e-9) + 0.5
    cg_iterations = float(cg[5])
    assert cg_iterations >= 1
