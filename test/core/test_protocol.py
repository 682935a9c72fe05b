"""The core's seams: the integrator protocol (every registered method checked against the laws it
declares), the post-step stages, the parameter schema, and the stability analysis."""

import ast
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from cloths import free_cloth, free_fall, one_spring, oscillator_order

import cloth_sim.integrators.kang_analysis as kang
import cloth_sim.physics.stability as stab
from cloth_sim import ClothModel, SimulationDiverged, Simulator, integrators
from cloth_sim.integrators.base import Integrator, Stability
from cloth_sim.parameters import SCHEMA, ParameterError
from cloth_sim.scene import SceneError, load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]
NO_GRAVITY = (0.0, 0.0, 0.0)
METHODS = integrators.available()
#: options that make a method's linear solve exact enough for the laws below
EXACT = {"implicit_euler": {"cg_tolerance": 1e-12}, "vbd": {"iterations": 200, "tolerance": 0.0}}


def chain(n=4, k=100.0, m=1.0, L=1e3, c=0.0):
    """Particle 0 pinned, ``n − 1`` free ones along x, springs between neighbours; long springs
    keep small motions linear."""
    x = np.zeros((n, 3))
    x[:, 0] = L * np.arange(n)
    return ClothModel.from_springs(
        x, np.full(n, m), [[i, i + 1] for i in range(n - 1)], stiffness=k, damping=c, pinned=[0]
    )


# ------------------------------------------------------------------ the protocol
def test_integrators_import_nothing_from_the_simulator():
    for path in (ROOT / "cloth_sim" / "integrators").glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                assert "simulator" not in (node.module or ""), f"{path.name} imports the simulator"
                assert all(a.name != "simulator" for a in node.names), path.name
            elif isinstance(node, ast.Import):
                assert all("simulator" not in a.name for a in node.names), path.name
    # nor does the simulator probe the integrator for optional members
    source = (ROOT / "cloth_sim" / "simulator.py").read_text()
    assert "getattr(" not in source and "hasattr(" not in source


@pytest.mark.parametrize("name", METHODS)
def test_every_method_declares_the_protocol(name):
    cls = integrators.get(name)
    assert issubclass(cls, Integrator) and cls.name == name
    assert cls.order >= 1 and isinstance(cls.stability, Stability)
    assert cls.__doc__ and len(cls.__doc__) > 80  # the method, its order, its source
    integ = cls(one_spring())
    assert set(integ.counters) == set(cls.counter_names)
    if cls.stability is Stability.AMPLIFICATION:
        assert integ.amplification(0.01, 10.0, 0.1).shape[0] in (2, 3)


@pytest.mark.parametrize("name", METHODS)
def test_declared_order_is_observed_on_the_harmonic_oscillator(name):
    """Max error of x(t) = L + A cos ωt over 1 s against dt: the slope is the declared order."""
    order = integrators.get(name).order
    dts = (
        np.array([2e-3, 1e-3, 5e-4, 2.5e-4]) if order == 1 else np.array([4e-3, 2e-3, 1e-3, 5e-4])
    )
    # one free particle: each of vbd's iterations is a Newton step on the whole system, so 10 give
    # the errors of 200 to 12 digits (measured; 200 took 22 s of the core tests)
    options = {"iterations": 10} if name == "vbd" else EXACT.get(name)
    observed, errs = oscillator_order(name, dts, options)
    assert observed == pytest.approx(order, abs=0.15), errs


@pytest.mark.parametrize("name", METHODS)
def test_free_fall_centre_of_mass(rng, name):
    """x_cm = x0 + v0 t + g t²/2 whatever the springs do: exactly for a method of order ≥ 2, within
    a first-order method's g·dt·t/2 (the two Euler forms are off by exactly that)."""
    model, v0 = free_cloth(rng)
    dt = 1e-3
    sim = Simulator(model, integrator=name, dt=dt, integrator_options=EXACT.get(name))
    com, exact, t = free_fall(sim, v0, 300)
    bound = 1e-12 if integrators.get(name).order >= 2 else 0.5 * 9.81 * dt * t * (1 + 1e-9)
    assert np.max(np.abs(com - exact)) <= bound


@pytest.mark.parametrize("name", METHODS)
def test_momentum_without_external_force_is_what_the_method_declares(name):
    """Conserved to rounding (or the solver's tolerance) when the method says so. Kang's
    per-particle scaling does not conserve it: summed over particles its step adds
    ``dt²·Σ_s k_s·(Δv_prev − Δv)`` over each spring's ends, a sum that telescopes over the run, so
    the error is real (far above rounding) but bounded, and goes back towards zero as the motion
    settles."""
    model, v0 = free_cloth(np.random.default_rng(7), drift=(0.0, 0.0, 0.0))
    sim = Simulator(
        model, integrator=name, dt=1e-3, gravity=NO_GRAVITY, integrator_options=EXACT.get(name)
    )
    sim.velocities = v0
    m = model.masses[:, None]
    p0 = (m * sim.velocities).sum(0)
    scale = float((m * np.abs(v0)).sum())
    errors = []
    for t in (0.1, 0.2, 0.5):
        sim.advance(t)
        errors.append(np.max(np.abs((m * sim.velocities).sum(0) - p0)) / scale)
    if integrators.get(name).conserves_momentum:
        assert max(errors) <= 1e-10
    else:
        assert 1e-9 < max(errors) < 1e-5
        assert errors[-1] < 0.1 * errors[0]


@pytest.mark.parametrize("name", METHODS)
def test_stable_dt_is_sharp_on_a_damped_chain(name):
    """stable_dt() of every conditionally stable method, whichever way it is known (amplification
    matrix or the method's own analysis): 3 % below it a perturbation decays, 3 % above it grows
    until the guard trips. An unconditionally stable method stays bounded at ω·dt = 25."""
    unconditional = integrators.get(name).stability is Stability.UNCONDITIONAL
    model = chain(k=1e4 if unconditional else 100.0, c=2.0)
    x0 = model.positions.copy()
    x0[1:, 0] += np.random.default_rng(3).normal(scale=0.05, size=3)
    limit = Simulator(model, integrator=name, dt=0.01, gravity=NO_GRAVITY).stable_dt()

    def run(dt, steps):
        sim = Simulator(model, integrator=name, dt=dt, gravity=NO_GRAVITY)
        sim.positions = x0
        amp = []
        for _ in range(steps):
            sim.step()
            amp.append(np.max(np.abs(sim.positions - model.positions)))
        return max(amp[:300]), max(amp[-300:])

    if unconditional:
        assert limit == math.inf
        omega = Simulator(model, dt=0.01).fastest_mode()[0]
        early, late = run(25.0 / omega, 200)
        assert late <= early < 0.1
        return
    assert 0 < limit < math.inf
    early, late = run(0.97 * limit, 3000)
    assert late < early
    with pytest.raises(SimulationDiverged, match="restored"):
        run(1.03 * limit, 20000)


# ------------------------------------------------------------------ defects fixed in the split
def test_a_blow_up_never_runs_a_stability_analysis(monkeypatch):
    """The error path reports a limit only if it is already known: a kang blow-up on 24×24 once
    spent 18–29 s in an ARPACK bisection inside the exception's message."""

    def forbidden(*args, **kwargs):
        raise AssertionError("a stability analysis ran inside the error path")

    scene = load_scene("hanging_provot")
    for name in ("kang", "symplectic_euler"):
        sim = scene.build_simulator(
            rows=24, cols=24, spacing=1 / 23, integrator=name, dt=1 / 60, strain_limit=None
        )
        monkeypatch.setattr(stab, "fastest_mode", forbidden)
        monkeypatch.setattr(kang, "kang_stable_dt", forbidden)
        with pytest.raises(SimulationDiverged, match="not computed"):
            sim.advance(2.0)
        monkeypatch.undo()
        limit = sim.stable_dt()  # asked for: computed now, and reported by the next blow-up
        with pytest.raises(SimulationDiverged, match=f"stable_dt\\(\\)={limit:.4g} s"):
            sim.advance(2.0)


def test_kang_linear_step_matrix_is_the_step_it_takes_sweeps_included():
    """The linearised step of kang_step_matrix, applied to a small displacement of a chain, equals
    the method's actual step to second order in the displacement, for 1, 2 and 3 sweeps (it once
    ignored ``sweeps``)."""
    model = chain(n=5, c=0.5)
    k, c = np.array(model.stiffness), np.array(model.damping)
    rng = np.random.default_rng(11)
    dt, eps = 0.02, 1e-6
    free = np.repeat(~model.pinned, 3)
    results = []
    for sweeps in (1, 2, 3):
        sim = Simulator(
            model,
            integrator="kang",
            dt=dt,
            gravity=NO_GRAVITY,
            integrator_options={"sweeps": sweeps},
        )
        dx = eps * rng.normal(size=model.positions.shape)
        dx[model.pinned] = 0.0
        v = eps * rng.normal(size=dx.shape)
        v[model.pinned] = 0.0
        sim.positions = model.positions + dx
        sim.velocities = v
        dv_prev = eps * rng.normal(size=dx.shape)
        dv_prev[model.pinned] = 0.0
        sim.state.history["dv"][:] = dv_prev
        sim.step()
        T = kang.kang_step_matrix(model, k, c, 0.0, dt, sweeps)
        before = np.concatenate([dx.ravel()[free], v.ravel()[free], dv_prev.ravel()[free]])
        predicted = T @ before
        taken = np.concatenate(
            [
                (sim.positions - model.positions).ravel()[free],
                sim.velocities.ravel()[free],
                sim.state.history["dv"].ravel()[free],
            ]
        )
        assert np.max(np.abs(predicted - taken)) <= 1e-6 * np.max(np.abs(taken))
        results.append(taken)
    assert np.max(np.abs(results[0] - results[1])) > 1e-3 * np.max(np.abs(results[0]))


def test_damping_ratio_of_the_fastest_mode_includes_drag():
    """One free particle on a spring with drag d only: ζ = d / (2 m ω)."""
    k, m, d = 100.0, 2.0, 0.8
    sim = Simulator(one_spring(k=k, m=m), dt=1e-3, drag=d, gravity=NO_GRAVITY)
    omega, zeta = sim.fastest_mode()
    assert omega == pytest.approx(math.sqrt(k / m), rel=1e-9)
    assert zeta == pytest.approx(d / (2 * m * omega), rel=1e-9)
    # and the limit follows: symplectic Euler's damped limit is below the undamped 2/ω
    assert sim.stable_dt() < Simulator(one_spring(k=k, m=m), dt=1e-3).stable_dt()


def test_kangs_grid_analysis_is_conservative_against_the_whole_system():
    """The von Neumann analysis of the grid (tens of milliseconds) against the spectral radius of
    the whole 12×12 step matrix (seconds): below it, within 20 %."""
    model = load_scene("hanging_provot").build_model(rows=12, cols=12, spacing=1 / 11)
    k, c = np.array(model.stiffness), np.array(model.damping)
    fourier = kang.kang_stable_dt(model, k, c, 0.0, method="fourier", rel_tol=0.005)
    full = kang.kang_stable_dt(model, k, c, 0.0, method="full", rel_tol=0.005)
    assert 0.8 * full <= fourier <= full
    assert (
        stab.grid_stencil(
            ClothModel.from_springs([[0, 0, 0], [1, 0, 0]], [1, 1], [[0, 1]], 1.0),
            np.ones(1),
            np.zeros(1),
        )
        is None
    )


def test_the_analysis_is_computed_once_per_material(monkeypatch):
    calls = []
    original = stab.fastest_mode
    monkeypatch.setattr(
        stab, "fastest_mode", lambda *a, **kw: calls.append(1) or original(*a, **kw)
    )
    model = ClothModel.grid(10, 10, 0.1, 0.01, stiffness=500.0, damping=0.1, pinned=[(0, 0)])
    a = Simulator(model, integrator="rk4")
    b = Simulator(model, integrator="verlet")
    limits = (a.stable_dt(), b.stable_dt(), a.stable_dt())
    assert len(calls) == 1 and limits[0] == limits[2] and limits[0] != limits[1]
    a.set_stiffness("bend", 100.0)  # a new material: one new analysis, b's is kept
    a.stable_dt(), b.stable_dt()
    assert len(calls) == 2
    a.set_stiffness("bend", 500.0)  # back to the first material: nothing recomputed
    a.stable_dt()
    assert len(calls) == 2


# ------------------------------------------------------------------ stages
def test_inactive_stages_are_never_called(monkeypatch):
    import cloth_sim.constraints.strain_limit as constraints

    def forbidden(*args):
        raise AssertionError("an inactive stage ran")

    sim = Simulator(ClothModel.grid(6, 6, 0.1, 0.01, stiffness=100.0, pinned=[(0, 0)]))
    assert sim.active_stages == ()
    monkeypatch.setattr(constraints, "provot_passes", forbidden)  # the passes the stage calls
    sim.step(20)
    monkeypatch.undo()
    sim.strain_limit = 0.05
    assert sim.active_stages == ("strain_limit",)
    sim.step(200)
    assert sim.max_strain() <= 0.05 + 2e-3
    sim.strain_limit = None
    assert sim.active_stages == ()


# ------------------------------------------------------------------ one schema
NUMERIC = [p for p in SCHEMA.values() if p.type in (float, int, "vector3") and p.scene_key]


@pytest.mark.parametrize("spec", NUMERIC, ids=[p.name for p in NUMERIC])
def test_scene_files_accept_exactly_the_schema_range(spec):
    """A scene field's bounds are the parameter's (a scene with rows: 600 once ran in `cloth-sim
    run` and crashed the node)."""

    def scene_with(value):
        data = {"grid": {"rows": 4, "cols": 4, "spacing": 0.1}}
        node = data
        keys = spec.scene_key.split(".")
        for key in keys[:-1]:
            node = node.setdefault(key, {})
        node[keys[-1]] = value
        return scene_from_dict(data, source="s.yaml")

    def value(x):
        return [x, 0.0, 0.0] if spec.type == "vector3" else (int(x) if spec.type is int else x)

    scene_with(value(spec.hi))
    if not spec.lo_open:
        scene_with(value(spec.lo))
    over = spec.hi + 1 if spec.type is int else spec.hi * 1.01
    with pytest.raises(
        SceneError,
        match=f"s.yaml: field '{spec.scene_key}.*{spec.range_text().split(' ')[-1]}"
        if spec.type != "vector3"
        else f"s.yaml: field '{spec.scene_key}\\[0\\]'",
    ):
        scene_with(value(over))
    with pytest.raises(ParameterError):
        spec.check(value(over))


def test_the_schema_bounds_the_simulator_and_the_model():
    with pytest.raises(ValueError, match=r"grid: rows and cols: rows = 600 .*\[2, 512\]"):
        ClothModel.grid(600, 4, 0.1, 0.01, stiffness=1.0)
    sim = Simulator(one_spring())
    for setter, bad, name in [
        (lambda v: setattr(sim, "dt", v), 2.0, "dt"),
        (lambda v: setattr(sim, "drag", v), -1.0, "drag"),
        (lambda v: sim.set_stiffness("spring", v), 1e10, "stiffness.spring"),
        (lambda v: setattr(sim, "strain_limit", v), 11.0, "strain_limit"),
    ]:
        with pytest.raises(ParameterError, match=f"{name} = .* expected a number in"):
            setter(bad)


def test_cli_run_refuses_what_the_schema_refuses(tmp_path, capsys):
    from cloth_sim.cli import main as cli_main

    bad = tmp_path / "big.yaml"
    data = yaml.safe_load((ROOT / "config" / "scenes" / "hanging.yaml").read_text())
    data["grid"]["rows"] = 600
    bad.write_text(yaml.safe_dump(data))
    assert cli_main(["run", "--scene", str(bad), "--duration", "0.01"]) == 2
    err = capsys.readouterr().err
    assert "big.yaml: field 'grid.rows' must be an integer in [2, 512], got 600" in err
    with pytest.raises(SystemExit):
        cli_main(["run", "--dt", "5"])
    assert "dt = '5' is not accepted: expected a number in [1e-07, 1] s" in capsys.readouterr().err


@pytest.mark.parametrize("scene", ["hanging_provot", "curtain", "free_fall"])
@pytest.mark.parametrize("model", ["provot", "choi_ko"])
def test_every_node_cloth_has_kangs_fast_analysis(scene, model):
    """The node's cloths are regular grids with uniform families: kang's limit comes from the
    Fourier analysis (a fraction of a second), never the whole-system one (minutes at 32×32).
    Choi–Ko rest lengths differ in their last bits from spring to spring; that once sent the node
    there."""
    m = load_scene(scene).build_model(rows=12, cols=12, spacing=1 / 11, model=model)
    k, c = np.array(m.stiffness), np.array(m.damping)
    assert stab.grid_stencil(m, k, c) is not None
    assert 0 < kang.kang_stable_dt(m, k, c, 0.01, method="fourier") < 1


def test_choi_ko_stable_dt_accounts_for_the_buckling_onset_load():
    """Choi–Ko's compressed pair pushes with 12·k_b/L² from the first rounding-level compression: a
    jump no mode analysis sees. With a stiff bend family the modes' limit let symplectic Euler
    chatter at 36 m/s in a cloth that should barely move (and the fuzz found blow-ups in the first
    step); stable_dt() now also bounds the onset kick, and at 0.97× it the cloth stays calm."""
    from cloth_sim.integrators.explicit import SymplecticEuler

    model = ClothModel.grid(
        8,
        8,
        0.05,
        0.01,
        stiffness={"structural": 1000, "shear": 1000, "bend": 0.1},
        damping=0.02,
        pinned=[(0, 0), (0, -1)],
        model="choi_ko",
    )
    sim = Simulator(model, integrator="symplectic_euler", dt=1e-4)
    modes_only = stab.one_step_limit(SymplecticEuler, sim.analysis)
    limit = sim.stable_dt()
    assert limit == sim.analysis.onset_limit < 0.2 * modes_only
    # the kick of the most loaded pair: 12·k/L² from each of its ends' buckling pairs, per mass
    bend = model.kind == 2
    load = (
        np.bincount(
            model.springs[bend].ravel(),
            np.repeat(12 * 0.1 / model.rest_lengths[bend] ** 2, 2),
            minlength=model.n_particles,
        )
        / 0.01
    )
    load[model.pinned] = 0.0
    reach = load[model.springs[bend, 0]] + load[model.springs[bend, 1]]
    assert limit == pytest.approx(
        min(np.min(np.sqrt(0.01 * model.rest_lengths[bend] / reach)), 10.0 / reach.max()),
        rel=1e-12,
    )

    def fastest(dt, t=0.05):
        s = Simulator(model, integrator="symplectic_euler", dt=dt)
        s.advance(0.2)
        return np.max(np.abs(s.velocities))

    assert fastest(0.97 * limit) < 10.0
    assert fastest(0.97 * modes_only) > 20.0
    # a Provot cloth has no buckling pairs: no such limit
    provot = ClothModel.grid(8, 8, 0.05, 0.01, stiffness=1000.0, pinned=[(0, 0)])
    assert Simulator(provot, dt=1e-4).analysis.onset_limit == math.inf


@pytest.mark.parametrize("seed", range(4))
def test_kang_limit_from_the_coarse_search_is_the_fine_limit(seed):
    """kang_stable_dt brackets on a coarse subset of the wavenumbers first (its limit bounds the
    fine one from above), then searches the fine set down from there: the answer is still the fine
    set's own limit, on the 1 % grid: stable there, unstable one grid step above."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 30))
    model = ClothModel.grid(
        n,
        n,
        1 / (n - 1),
        0.01,
        stiffness={f: float(10 ** rng.uniform(1, 7)) for f in ("structural", "shear", "bend")},
        damping={f: float(10 ** rng.uniform(-3, 3)) for f in ("structural", "shear", "bend")},
        pinned=[(0, 0), (0, -1)],
    )
    k, c, drag = np.array(model.stiffness, float), np.array(model.damping, float), 0.01
    kang._KANG_GUESS.clear()
    limit = kang.kang_stable_dt(model, k, c, drag)
    st = stab.grid_stencil(model, k, c)
    symbols = stab.fourier_symbols(st, min(24, n))
    assert kang.kang_fourier_radius(st, drag, limit, 1, symbols) <= 1.0 + 1e-9
    assert kang.kang_fourier_radius(st, drag, limit * 1.01, 1, symbols) > 1.0 + 1e-9


def test_choi_ko_onset_band_of_the_methods_without_a_step_limit():
    """A method that solves with the pairs' stiffness absorbs the onset load at large steps and
    kicks little at tiny ones; between, a stiff bend rigidity throws the cloth about (Baraff–Witkin
    at 1e-5 s on the hanging scene with bend 100 N·m²: the guard trips at 1.5 ms). The
    band is refused in the node; the steps outside it run calmly."""
    from cloth_sim.scene import load_scene

    def fastest(dt, t=0.05):
        sim = load_scene("hanging_provot").build_simulator(
            model="choi_ko", integrator="implicit_euler", dt=dt, strain_limit=None
        )
        try:
            sim.advance(t)
        except SimulationDiverged:  # the guard tripped (1000 m/s)
            return math.inf, sim
        return np.max(np.abs(sim.velocities)), sim

    v, sim = fastest(1e-5)
    lo, hi = sim.analysis.onset_band
    assert lo < 1e-5 < hi and not sim.step_is_stable() and sim.stable_dt() == lo
    assert v > 100.0
    v, sim = fastest(1.0 / 60, 1.0)  # above the band: the kicks stay near the bound's 10 m/s
    assert sim.step_is_stable() and v < 20.0
    # a cloth's bend rigidity: no band at all
    calm = load_scene("hanging_provot").build_simulator(
        model="choi_ko", integrator="implicit_euler", stiffness={"bend": 1e-4}
    )
    assert calm.analysis.onset_band == (math.inf, math.inf) and calm.stable_dt() == math.inf


def test_strain_limit_passes_is_a_live_setting_checked_against_the_schema():
    """Fewer passes of the strain limit leave more stretch (the trade the node's parameter offers),
    the setting reaches the limiter, and a bad value is refused naming the field and its range."""
    model = ClothModel.grid(
        24, 24, 1 / 23, 0.01, stiffness=50.0, damping=0.05, pinned=[(0, 0), (0, -1)]
    )
    worst = {}
    for passes in (1, 20):
        sim = Simulator(model, dt=1e-3, strain_limit=0.1, strain_limit_passes=passes)
        assert sim.strain_limit_passes == passes
        worst[passes] = 0.0
        for _ in range(40):
            sim.step(20)
            worst[passes] = max(worst[passes], sim.max_strain())
    assert worst[1] > worst[20] + 0.005
    sim.strain_limit_passes = 7
    assert sim._strain.passes == 7
    for bad in (0, 101, 2.5, "5"):
        with pytest.raises(
            ParameterError, match=r"strain_limit_passes = .* expected an integer in \[1, 100\]"
        ):
            sim.strain_limit_passes = bad
    assert sim.strain_limit_passes == 7
