"""Bad input: every value goes through one gate (the schema), a refusal names the field, the value
and the accepted range, and nothing a user sends stops the simulation. Scene files are
untrusted."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from cloth_sim import SimulationDiverged
from cloth_sim.cli import main as cli_main
from cloth_sim.parameters import SCHEMA, ParameterError
from cloth_sim.scene import SceneError, load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]

from malformed_scenes import CORPUS, SECRET, write_corpus  # noqa: E402


def test_the_corpus_has_at_least_30_malformed_files(tmp_path):
    assert len(write_corpus(tmp_path)) >= 30


def test_each_malformed_scene_is_one_message_naming_the_file(tmp_path, capsys):
    """`cloth-sim run` and the loader: one SceneError line naming the file, never its contents."""
    for name, path in write_corpus(tmp_path).items():
        with pytest.raises(SceneError) as e:
            load_scene(str(path))
        message = str(e.value)
        assert message.startswith(str(path)), (name, message)
        assert "\n" not in message and len(message) < 400, (name, message)
        assert SECRET not in message and "xxxxxxxxxx" not in message, (name, message)
        assert cli_main(["run", "--scene", str(path), "--duration", "0.01"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(path) in err[0], (name, err)


def test_a_yaml_error_gives_line_and_column_only(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_bytes(CORPUS["syntax_error"])
    with pytest.raises(SceneError, match=r"s.yaml: not valid YAML at line 3, column 1$"):
        load_scene(str(path))


def test_scene_names_that_cannot_be_files_are_refused():
    with pytest.raises(SceneError, match="cannot be opened"):
        load_scene("x" * 300)
    with pytest.raises(SceneError, match="unknown scene"):
        load_scene("no_such_scene")
    with pytest.raises(SceneError, match="scene must be"):
        load_scene("")


# ---------------------------------------------------------------- the defects, in the core
def hanging(n=16, **kw):
    return load_scene("hanging_provot").build_simulator(rows=n, cols=n, spacing=1 / (n - 1), **kw)


def test_no_stiffness_at_all_is_a_cloth_that_falls():
    """All three families at 0 once killed the node (ARPACK: starting vector is zero)."""
    sim = hanging()
    for f in ("structural", "shear", "bend"):
        sim.set_stiffness(f, 0.0)
    assert sim.fastest_mode() == (0.0, 0.0)
    # no oscillation, but the springs' damping still limits an explicit step: rate·dt ≤ 2
    assert sim.stable_dt() == pytest.approx(2 / sim.analysis.damping_rate, rel=1e-3)
    sim.advance(0.1)
    assert np.all(np.isfinite(sim.positions))
    for f in ("structural", "shear", "bend"):
        sim.set_damping(f, 0.0)
    assert sim.stable_dt() == math.inf


def test_the_limit_accounts_for_heavily_damped_springs():
    """A soft family with a heavy damping (bend k = 915, c = 1e6 on 52 kg particles) passed the
    fastest mode's check (ω = 8 rad/s: dt ≤ 0.24 s) and blew up at dt = 2e-5 s: the fastest decay
    limits an explicit method (symplectic Euler: rate·dt ≤ 2), whatever the stiffness, and over the
    shapes the cloth takes, not only the rest shape (this one stretches 17-fold: at the rest
    shape's decay limit, twice this one, it blows up)."""

    def sim_at(dt):
        return hanging(
            strain_limit=None,
            particle_mass=52.0,
            stiffness={"bend": 915.0},
            damping={"bend": 1e6},
            dt=dt,
        )

    sim = sim_at(1e-3)
    limit = sim.stable_dt()
    assert limit == pytest.approx(2 / sim.analysis.damping_rate, rel=1e-3)
    sim_at(0.97 * limit).advance(0.5)
    with pytest.raises(SimulationDiverged):
        sim_at(2 * limit).advance(0.5)


def test_the_limit_accounts_for_drag():
    """drag = 100 with symplectic Euler was accepted at dt = 1 ms and blew up: a particle's drag is
    a damping c = drag/m that an explicit method overshoots beyond c·dt = 2."""
    sim = hanging(drag=100.0, strain_limit=None)
    limit = sim.stable_dt()
    assert 0.9 * 2 * 0.01 / 100.0 <= limit <= 2 * 0.01 / 100.0  # c·dt ≤ 2, and the fastest mode
    sim.dt = 0.9 * limit
    sim.advance(0.3)
    sim = hanging(drag=100.0, strain_limit=None, dt=1.1 * limit)
    with pytest.raises(SimulationDiverged):
        sim.advance(0.3)


def test_choi_ko_with_the_prefactored_method_is_stable():
    """Its matrix used the bare bend k while Choi–Ko's buckling branch is far stiffer: it
    diverged."""
    sim = hanging(model="choi_ko", integrator="implicit_euler_prefactored", dt=1e-3)
    sim.advance(2.0)
    assert np.all(np.isfinite(sim.positions)) and np.max(np.abs(sim.velocities)) < 20


def test_the_strain_limit_behaves_at_the_smallest_dt():
    """Tightening the limit with dt = 1e-6 once gave a false 'speed above 1000 m/s': the correction
    of a stretch that was there before the step was divided by dt."""
    sim = hanging()
    sim.advance(1.0)
    sim.strain_limit = 0.05
    sim.dt = 1e-6
    sim.step(3000)
    assert np.max(np.linalg.norm(sim.velocities, axis=1)) < 10.0
    assert sim.max_strain() < 0.05 + 0.02


# ------------------------------------------------------------------ properties over the schema
def valid(spec, value) -> bool:
    """The schema's rule, written out independently of Param.check."""

    def number(x):
        return (
            isinstance(x, (int, float))
            and not isinstance(x, bool)
            and math.isfinite(x)
            and (spec.lo < x if spec.lo_open else spec.lo <= x)
            and x <= spec.hi
        )

    if spec.type is bool:
        return isinstance(value, bool)
    if spec.type is str:
        return (
            isinstance(value, str)
            and (spec.choices is None or value in spec.choices)
            and (not spec.nonempty or value != "")
        )
    if spec.type is int:
        return (
            isinstance(value, int) and not isinstance(value, bool) and spec.lo <= value <= spec.hi
        )
    if spec.type in ("vector2", "vector3"):
        n = 2 if spec.type == "vector2" else 3
        return isinstance(value, list) and len(value) == n and all(number(v) for v in value)
    return number(value)


values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["rk4", "kang", "provot", "choi_ko", "hanging", ""]),
    st.lists(st.floats(-2e3, 2e3), max_size=4),
    st.lists(st.one_of(st.floats(), st.text(max_size=3)), max_size=4),
)


@settings(max_examples=400, deadline=None)
@given(name=st.sampled_from(sorted(SCHEMA)), value=values)
@example(name="thickness", value=0)  # an open lower bound: 0 itself is refused
@example(name="thickness", value=0.0)
@example(name="thickness", value=1e-9)
def test_a_value_is_accepted_iff_the_schema_says_it_is_valid(name, value):
    spec = SCHEMA[name]
    try:
        out = spec.check(value)
    except ParameterError as e:
        assert not valid(spec, value)
        assert str(e).startswith(name) and e.name.startswith(name)
        return
    assert valid(spec, value)
    assert out == (
        float(value)
        if spec.type is float
        else [float(v) for v in value]
        if spec.type == "vector3"
        else value
    )


scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**9), 10**9), st.floats(), st.text(max_size=8)
)
trees = st.recursive(
    scalars,
    lambda kids: st.one_of(
        st.lists(kids, max_size=4),
        st.dictionaries(
            st.one_of(st.text(max_size=8), st.integers(), st.none()), kids, max_size=4
        ),
    ),
    max_leaves=20,
)
scene_keys = st.sampled_from(
    [
        "grid",
        "model",
        "particle_mass",
        "stiffness",
        "damping",
        "pinned",
        "pinned_edges",
        "gravity",
        "wind",
        "drag",
        "strain_limit",
        "integrator",
        "dt",
        "name",
    ]
)


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.one_of(trees, st.dictionaries(scene_keys, trees, max_size=6)))
def test_any_yaml_tree_is_a_scene_or_one_scene_error(data):
    try:
        scene = scene_from_dict(data, source="f.yaml")
    except SceneError as e:
        assert str(e).startswith("f.yaml:") and "\n" not in str(e)
        return
    scene.build_model()  # what the schema accepts builds


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(raw=st.one_of(st.binary(max_size=300), st.text(max_size=300).map(str.encode)))
def test_any_bytes_are_a_scene_or_one_scene_error(tmp_path_factory, raw):
    path = tmp_path_factory.mktemp("bytes") / "s.yaml"
    path.write_bytes(raw)
    try:
        load_scene(str(path))
    except SceneError as e:
        assert str(e).startswith(str(path)) and "\n" not in str(e)
