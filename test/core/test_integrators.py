"""The explicit integrators against closed forms, conservation laws and linear stability theory."""

import math

import numpy as np
import pytest
from cloths import cloth16, free_cloth, free_fall, one_spring

from cloth_sim import ClothModel, SimulationDiverged, Simulator, integrators

EXPLICIT = {"explicit_euler": 1, "symplectic_euler": 1, "midpoint": 2, "rk4": 4, "verlet": 2}
NO_GRAVITY = (0.0, 0.0, 0.0)


def test_registry_lists_every_explicit_method_and_rejects_unknown_names():
    assert set(EXPLICIT) <= set(integrators.available())
    with pytest.raises(ValueError, match="unknown integrator 'rk5'.*rk4.*verlet"):
        Simulator(one_spring(), integrator="rk5")


def oscillator_error(name, dt, T=1.0, k=100.0, m=1.0, A=0.1):
    """Max over the run of |x(t) − (L + A cos ωt)| for the one-spring oscillator."""
    sim = Simulator(one_spring(k, m, amplitude=A), integrator=name, dt=dt, gravity=NO_GRAVITY)
    omega = math.sqrt(k / m)
    err = 0.0
    for _ in range(round(T / dt)):
        sim.step()
        exact = 1.0 + A * math.cos(omega * sim.time)
        err = max(err, abs(sim.positions[1, 0] - exact))
    return err


@pytest.mark.parametrize("name,order", EXPLICIT.items())
def test_observed_order_on_the_harmonic_oscillator(name, order):
    dts = np.array([4e-3, 2e-3, 1e-3, 5e-4])
    errs = np.array([oscillator_error(name, dt) for dt in dts])
    observed = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert observed == pytest.approx(order, abs=0.15), (name, errs)


def test_rk4_matches_the_damped_oscillator_closed_form():
    k, m, c, A = 100.0, 1.0, 2.0, 0.1
    omega = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd = omega * math.sqrt(1 - zeta**2)

    def run(dt):
        sim = Simulator(
            one_spring(k, m, amplitude=A, damping=c), integrator="rk4", dt=dt, gravity=NO_GRAVITY
        )
        err = 0.0
        for _ in range(round(2.0 / dt)):
            sim.step()
            t = sim.time
            exact = 1.0 + A * math.exp(-zeta * omega * t) * (
                math.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * math.sin(wd * t)
            )
            err = max(err, abs(sim.positions[1, 0] - exact))
        return err

    e1, e2 = run(4e-3), run(2e-3)
    assert e2 < 1e-8
    assert math.log2(e1 / e2) == pytest.approx(4, abs=0.15)


@pytest.mark.parametrize(
    "name,offset_sign",
    [("explicit_euler", -1), ("symplectic_euler", +1), ("midpoint", 0), ("rk4", 0), ("verlet", 0)],
)
def test_free_fall_centre_of_mass(rng, name, offset_sign):
    """x_cm(t) = x0 + v0 t + g t²/2, shifted by ∓g·dt·t/2 for the two Euler methods."""
    model, v0 = free_cloth(rng)
    g = np.array([0.0, 0.0, -9.81])
    dt = 1e-3
    sim = Simulator(model, integrator=name, dt=dt, gravity=g)
    com, exact, t = free_fall(sim, v0, 300)
    np.testing.assert_allclose(com, exact + offset_sign * 0.5 * g * dt * t, rtol=0, atol=1e-12)
    if offset_sign:  # the offset is real: the exact law alone is off by it
        assert abs(com[2] - exact[2]) > 0.1 * 0.5 * 9.81 * dt * t


@pytest.mark.parametrize("name", EXPLICIT)
def test_momentum_is_conserved_without_external_force(rng, name):
    model, v0 = free_cloth(rng)
    sim = Simulator(model, integrator=name, dt=1e-3, gravity=NO_GRAVITY)
    sim.velocities = v0
    m = model.masses[:, None]
    p0 = (m * sim.velocities).sum(0)
    scale = float((m * np.abs(v0)).sum())
    sim.step(500)
    p = (m * sim.velocities).sum(0)
    assert np.max(np.abs(p - p0)) <= 1e-12 * scale


def energy_history(name, model, v0=None, dt=1e-3, T=10.0, gravity=NO_GRAVITY, every=50):
    sim = Simulator(model, integrator=name, dt=dt, gravity=gravity)
    if v0 is not None:
        sim.velocities = v0
    e0 = sum(sim.energy().values())
    out = []
    for _ in range(round(T / dt / every)):
        sim.step(every)
        out.append(sum(sim.energy().values()) - e0)
    return np.abs(np.array(out))


@pytest.mark.parametrize("name", ["symplectic_euler", "verlet"])
def test_symplectic_methods_keep_the_energy_error_bounded(rng, name):
    # the oscillator and an undamped cloth with internal motion, 10 s each
    err = energy_history(name, one_spring())
    first, last = err[: len(err) // 5].max(), err[-len(err) // 5 :].max()
    assert last < 1.5 * first and last < 0.02 * 0.5 * 100 * 0.1**2
    model, v0 = free_cloth(rng, damping=0.0)
    err = energy_history(name, model, v0, dt=5e-4)
    first, last = err[: len(err) // 5].max(), err[-len(err) // 5 :].max()
    assert last < 1.5 * first


def test_explicit_euler_gains_energy():
    err = energy_history("explicit_euler", one_spring())
    e0 = 0.5 * 100 * 0.1**2
    # |1 + iωdt|² = 1 + (ωdt)²: the energy grows as exp(ω²·dt·t) = e^1 over 10 s
    assert err[-1] > 1.5 * e0 and err[-1] > 5 * err[len(err) // 10]


def test_hanging_chain_stretches_by_the_weight_below():
    """Spring j, counted from the bottom, carries j particles: extension j·m·g/k."""
    n, k, m, g, L = 6, 200.0, 0.05, 9.81, 0.1
    x = np.zeros((n, 3))
    x[:, 2] = -L * np.arange(n)
    model = ClothModel.from_springs(
        x, np.full(n, m), [[i, i + 1] for i in range(n - 1)], stiffness=k, damping=1.0, pinned=[0]
    )
    sim = Simulator(model, integrator="symplectic_euler", dt=1e-3, gravity=(0, 0, -g), drag=0.05)
    sim.advance(30.0)
    lengths = np.linalg.norm(np.diff(sim.positions, axis=0), axis=1)  # top spring first
    j_from_bottom = np.arange(n - 1, 0, -1)
    np.testing.assert_allclose(lengths - L, j_from_bottom * m * g / k, rtol=1e-6)


@pytest.mark.parametrize(
    "name,survives,blows_up",
    [("symplectic_euler", 1.9, 2.1), ("verlet", 1.9, 2.1), ("rk4", 2.7, 2.95)],
)
def test_one_spring_stability_limits(name, survives, blows_up):
    omega = 10.0

    def run(wdt):
        """Largest displacement over the first and the last 500 of 2000 steps."""
        # a long spring keeps a growing oscillation linear until the guard's speed bound trips
        sim = Simulator(one_spring(L=1e3), integrator=name, dt=wdt / omega, gravity=NO_GRAVITY)
        amp = []
        for _ in range(2000):
            sim.step()
            amp.append(np.max(np.abs(sim.positions[1] - [1e3, 0, 0])))
        return max(amp[:500]), max(amp[-500:])

    early, late = run(survives)
    # near the limit the discrete orbit is an ellipse stretched by 1/sqrt(1 − (ω·dt/2)²), not
    # growing
    assert late < 1.01 * early < 1.0
    with pytest.raises(SimulationDiverged, match="restored"):
        run(blows_up)
    sim = Simulator(one_spring(), integrator=name, dt=0.01)
    assert sim.stable_dt() * omega == pytest.approx(
        blows_up - 0.1 if name != "rk4" else 2 * math.sqrt(2), rel=1e-3
    )


@pytest.mark.parametrize(
    "name", ["symplectic_euler", "verlet", "rk4", "explicit_euler", "midpoint"]
)
@pytest.mark.parametrize("zeta", [0.1, 0.3])
def test_damped_stability_limits_are_each_methods_own(name, zeta):
    """stable_dt() with damping, from each method's amplification matrix (Verlet's lagged velocity
    estimate gives it a lower damped limit than symplectic Euler's): 3 % below it the oscillation
    decays, 3 % above it grows until the guard trips."""
    omega, m = 10.0, 1.0
    model = one_spring(k=omega**2 * m, m=m, L=1e3, damping=2 * zeta * omega * m)
    limit = Simulator(model, integrator=name, dt=0.01, gravity=NO_GRAVITY).stable_dt()
    assert 0 < limit < math.inf

    def run(dt, steps=3000):
        sim = Simulator(model, integrator=name, dt=dt, gravity=NO_GRAVITY)
        amp = []
        for _ in range(steps):
            sim.step()
            amp.append(np.max(np.abs(sim.positions[1] - [1e3, 0, 0])))
        return max(amp[:300]), max(amp[-300:])

    early, late = run(0.97 * limit)
    assert late < early
    with pytest.raises(SimulationDiverged, match="restored"):
        run(1.03 * limit, steps=20000)


def _dense_extremes(sim):
    """Largest eigenvalues of ``M^-½ K M^-½`` and ``M^-½ C M^-½`` over the free coordinates,
    dense."""
    K, C = sim.rest_matrices()
    free = np.repeat(~sim.model.pinned, 3)
    s = np.repeat(1 / np.sqrt(sim.model.masses), 3)[free]
    return [
        np.linalg.eigvalsh(s[:, None] * X.toarray()[np.ix_(free, free)] * s[None, :])[-1]
        for X in (K, C)
    ]


@pytest.mark.parametrize("n,rel", [(16, 0.011), (32, 0.003)])
def test_cloth_omega_max_is_a_tight_upper_bound(n, rel):
    """On a grid, ω_max is the infinite grid's (von Neumann): never below the finite cloth's, whose
    quadratic form is the infinite grid's restricted to it, and within 1.1 % at 16×16, 0.3 % at
    32×32."""
    sim = Simulator(
        ClothModel.grid(
            n, n, 1.0 / (n - 1), 0.01, stiffness=1000.0, damping=0.5, pinned=[(0, 0), (0, -1)]
        ),
        dt=1e-3,
    )
    lam_k, lam_c = _dense_extremes(sim)
    omega, zeta = sim.fastest_mode()
    assert math.sqrt(lam_k) <= omega <= (1 + rel) * math.sqrt(lam_k)
    # the damping rate over every shape: the scalar graph Laplacian's (each spring along the
    # motion)
    n_p = n * n
    i, j = sim.model.springs.T
    L = np.zeros((n_p, n_p))
    np.add.at(L, (i, i), 0.5)
    np.add.at(L, (j, j), 0.5)
    np.add.at(L, (i, j), -0.5)
    np.add.at(L, (j, i), -0.5)
    free = ~sim.model.pinned
    lam_graph = np.linalg.eigvalsh(L[np.ix_(free, free)])[-1] / 0.01
    rate = sim.analysis.damping_rate
    assert lam_c <= lam_graph <= rate <= (1 + rel) ** 2 * lam_graph  # a rate, like ω²
    # uniform Rayleigh damping C = (c/k)·K: the fastest mode's ζ = (c/k)·ω/2
    assert zeta == pytest.approx(0.5 / 1000.0 * omega / 2, rel=1e-9)


def test_omega_max_of_an_irregular_network_is_exact():
    """Off the grid (here a grid with one heavier particle), Lanczos: the dense value to 1e-8."""
    model = cloth16()
    masses = model.masses.copy()
    masses[40] *= 3
    model = ClothModel.from_springs(
        model.positions,
        masses,
        model.springs,
        model.stiffness,
        model.damping,
        model.rest_lengths,
        np.flatnonzero(model.pinned),
    )
    sim = Simulator(model, dt=1e-3)
    assert sim.fastest_mode()[0] == pytest.approx(math.sqrt(_dense_extremes(sim)[0]), rel=1e-8)


def blows_up(name, dt, T=1.0):
    model = cloth16()
    sim = Simulator(model, integrator=name, dt=dt)
    M, W = model.masses.sum(), 1.0
    try:
        for _ in range(round(T / dt / 20)):
            sim.step(20)
            if sim.energy()["kinetic"] > 100 * M * 9.81 * W or sim.strains().max() > 1.0:
                return True
    except SimulationDiverged:
        return True
    return False


def test_stable_dt_predicts_the_cloth_blow_up_within_15_percent():
    sim = Simulator(cloth16(), integrator="symplectic_euler", dt=1e-3)
    predicted = sim.stable_dt()
    assert predicted == pytest.approx(2 / sim.fastest_mode()[0], rel=1e-3)
    lo, hi = 0.5 * predicted, 2.0 * predicted
    assert not blows_up("symplectic_euler", lo) and blows_up("symplectic_euler", hi)
    for _ in range(7):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if blows_up("symplectic_euler", mid) else (mid, hi)
    measured = 0.5 * (lo + hi)
    assert measured == pytest.approx(predicted, rel=0.15)


def test_stable_dt_of_euler_and_midpoint_is_the_damped_limit():
    undamped = Simulator(cloth16(), integrator="explicit_euler", dt=1e-4)
    assert undamped.stable_dt() == 0.0
    undamped.set_integrator("midpoint")
    assert undamped.stable_dt() == 0.0
    # uniform Rayleigh damping C = (c/k)·K: explicit Euler is stable for dt <= c/k on every mode
    damped = Simulator(cloth16(k=1000.0, damping=0.5), integrator="explicit_euler", dt=1e-4)
    assert damped.stable_dt() == pytest.approx(0.5 / 1000.0, rel=1e-3)
    damped.set_integrator("midpoint")
    assert damped.stable_dt() > 0.5 / 1000.0


@pytest.mark.parametrize(
    "first,second",
    [("rk4", "verlet"), ("verlet", "symplectic_euler"), ("symplectic_euler", "rk4")],
)
def test_switching_integrator_mid_run_keeps_the_state(first, second):
    ref = Simulator(cloth16(k=300.0, damping=0.05), integrator="rk4", dt=5e-4)
    sim = Simulator(cloth16(k=300.0, damping=0.05), integrator=first, dt=5e-4)
    ref.advance(0.3)
    sim.advance(0.3)
    before = sim.positions.copy(), sim.velocities.copy()
    sim.set_integrator(second)
    np.testing.assert_array_equal(sim.positions, before[0])
    np.testing.assert_array_equal(sim.velocities, before[1])
    ref.advance(0.6)
    sim.advance(0.6)
    # both stay on the true trajectory to within the first-order methods' error at this dt
    assert np.max(np.abs(sim.positions - ref.positions)) < 5e-3


@pytest.mark.parametrize("name", EXPLICIT)
def test_changing_dt_and_assigning_velocities_keep_the_state_consistent(name):
    ref = Simulator(one_spring(), integrator="rk4", dt=1e-4, gravity=NO_GRAVITY)
    sim = Simulator(one_spring(), integrator=name, dt=1e-4, gravity=NO_GRAVITY)
    sim.advance(0.5)
    sim.dt = 2e-4
    sim.advance(1.0)
    ref.advance(1.0)
    assert sim.time == pytest.approx(1.0)
    tol = {1: 5e-3, 2: 1e-5, 4: 1e-9}[EXPLICIT[name]]
    assert abs(sim.positions[1, 0] - ref.positions[1, 0]) < tol
    # a velocity kick: the next step moves the particle by about v·dt
    v = np.zeros((2, 3))
    v[1, 1] = 1.0
    x_before = sim.positions.copy()
    sim.velocities = v
    sim.step()
    assert sim.positions[1, 1] - x_before[1, 1] == pytest.approx(sim.dt, rel=1e-3)


@pytest.mark.parametrize("name", ["explicit_euler", "midpoint", "rk4"])
def test_runge_kutta_closed_form_radius_is_the_amplification_matrix_radius(name):
    """The stability limits use |R(hλ)| of the tableau's stability polynomial; it must be the
    spectral radius of the amplification matrix the tableau's stages build."""
    from cloth_sim.physics import stability

    cls = integrators.get(name)
    rng = np.random.default_rng(2)
    h, w, z = rng.uniform(0, 3, 200), rng.uniform(0.1, 3, 200), rng.uniform(0, 3, 200)
    np.testing.assert_allclose(
        cls.spectral_radii(h, w, z),
        stability.spectral_radii(cls.amplification(h, w, z)),
        rtol=1e-12,
    )


@pytest.mark.parametrize(
    "name",
    ["explicit_euler", "symplectic_euler", "midpoint", "rk4", "verlet", "implicit_euler", "kang"],
)
def test_a_step_allocates_no_array(name):
    """The hot loop reuses its buffers: over 20 steps of a 32×32 cloth with wind, drag and the
    strain limit, the traced memory never rises by as much as one (n, 3) array (24 kB) above where
    it started. (Baraff–Witkin's direct solve, and the prefactored method's, still allocate per
    step; its CG does not.)"""
    import tracemalloc

    model = ClothModel.grid(
        32, 32, 1 / 31, 0.01, stiffness=1000.0, damping=0.1, pinned=[(0, 0), (0, -1)]
    )
    sim = Simulator(
        model, integrator=name, dt=1e-4, wind=(0.0, 0.1, 0.2), drag=0.01, strain_limit=0.1
    )
    sim.step(5)
    tracemalloc.start()
    try:
        start, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        sim.step(20)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak - start < 8 * 1024, f"{peak - start} bytes above the start within 20 steps"


def test_rk4_under_a_strain_limit_comes_to_rest():
    """Cotton hanging from two corners at 16×16 under a strain limit of 0.1 (by projection), in
    air, RK4 at a quarter of its stable step: a particle the limit corrects takes its mean velocity
    over the step and the correction's, and the sheet rests as symplectic Euler's does. Following
    the correction alone (RK4's end velocity is ``a·dt/2`` ahead of its mean under a steady force)
    left the particle beside a pin at 0.21 m/s after 10 s."""
    n = 16
    model = ClothModel.grid(
        n, n, size=(1.0, 1.0), material="cotton", pinned=[(n - 1, 0), (n - 1, n - 1)]
    )
    sim = Simulator(
        model, integrator="rk4", dt=1.0, drag=float(np.median(model.masses)) / 0.1,
        strain_limit=0.1, strain_limit_method="projection",
    )  # fmt: skip
    sim.dt = 0.25 * sim.stable_dt()
    sim.advance(10.0)
    speed = np.linalg.norm(sim.velocities, axis=1)
    assert speed.max() < 5e-3, speed.max()
    assert sim.max_strain() <= 0.1 + 2e-3
