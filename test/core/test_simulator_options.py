"""One wiring of parameters: the schema says which simulator option each value feeds, and a
simulator built from a configuration and one changed to it live are the same."""

import inspect

import numpy as np
import pytest

from cloth_sim import settings
from cloth_sim.parameters import SCHEMA
from cloth_sim.scene import load_scene
from cloth_sim.simulator import Simulator
from cloth_sim.simulator_options import FED_BY, FIT_SHARE, LIVE, apply, options

FAMILY_PREFIXES = ("stiffness.", "damping.")


def test_every_live_parameter_feeds_a_simulator_option_that_the_simulator_takes_and_sets():
    keywords = inspect.signature(Simulator.__init__).parameters
    for name, p in SCHEMA.items():
        if p.apply == "live" and not name.startswith(FAMILY_PREFIXES):
            assert p.simulator is not None, f"{name} is live but feeds no simulator option"
    for option in FED_BY:
        assert option in keywords, f"{option} is not a keyword of Simulator"
    for option in LIVE:
        if option in ("integrator", "integrator_options"):  # (set_integrator, together)
            continue
        prop = getattr(Simulator, option, None)
        assert isinstance(prop, property) and prop.fset is not None, option


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    if isinstance(a, dict):
        return a == b
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))


def _values(scene, **changes):
    cfg = settings.defaults(scene)
    cfg.update(changes)
    return cfg


CHANGES = [
    {"dt": 5e-4},
    {"gravity": [0.5, 0.0, -3.0]},
    {"wind.strength": 2.0, "wind.direction": [0.0, 1.0, 0.0]},
    {"drag": 0.02},
    {"strain_limit": 0.05, "strain_limit_passes": 7, "strain_limit_method": "projection"},
    {"thickness": 0.004, "self_collision": True},
    {"integrator": "vbd", "vbd.iterations": 7, "vbd.substeps": 2},
    {"integrator": "vbd"},
    {"integrator": "xpbd"},
]


@pytest.mark.parametrize("change", CHANGES, ids=lambda c: ",".join(c))
def test_a_live_change_gives_the_simulator_that_building_from_the_new_values_gives(change):
    scene = load_scene("hanging_provot")
    old = _values(scene, rows=6, cols=6, spacing=0.1)
    new = {**old, **change}
    model = settings.build_model(old, scene)
    live = settings.build_simulator(old, model, scene)
    set_ = apply(live, new, old)
    built = settings.build_simulator(new, model, scene)
    assert set_, "nothing was set"
    for option in LIVE:
        assert _same(getattr(live, option), getattr(built, option)), option
    # and the two step alike, bit for bit
    live.step(3)
    built.step(3)
    np.testing.assert_array_equal(live.positions, built.positions)


def test_an_unchanged_configuration_sets_nothing():
    scene = load_scene("hanging_provot")
    cfg = _values(scene, rows=5, cols=5, spacing=0.1)
    sim = settings.build_simulator(cfg, settings.build_model(cfg, scene), scene)
    assert apply(sim, dict(cfg), cfg) == []


def test_fit_tick_gives_vbd_a_time_budget_from_the_step_and_the_real_time_factor():
    scene = load_scene("hanging_provot")
    cfg = _values(scene, integrator="vbd", dt=2e-3)
    assert "time_budget" not in options(cfg)["integrator_options"]
    fitted = {**cfg, "vbd.fit_tick": True, "real_time_factor": 0.5}
    budget = options(fitted)["integrator_options"]["time_budget"]
    assert budget == pytest.approx(FIT_SHARE * 2e-3 / 0.5)
    sim = settings.build_simulator(fitted, settings.build_model(fitted, scene), scene)
    assert sim.integrator_options["time_budget"] == pytest.approx(budget)
    # a real-time factor changed live changes the budget; fit_tick off takes it away
    faster = {**fitted, "real_time_factor": 2.0}
    assert apply(sim, faster, fitted) == ["integrator"]
    assert sim.integrator_options["time_budget"] == pytest.approx(FIT_SHARE * 2e-3 / 2.0)
    apply(sim, cfg, faster)
    assert "time_budget" not in sim.integrator_options


def test_a_scene_builds_the_simulator_its_values_build():
    for name in ("flag", "table", "fold"):
        scene = load_scene(name)
        cfg = settings.defaults(scene)
        a = scene.build_simulator()
        b = settings.build_simulator(cfg, settings.build_model(cfg, scene), scene)
        for option in LIVE:
            assert _same(getattr(a, option), getattr(b, option)), (name, option)


def test_vbd_in_a_scene_that_names_no_work_chooses_it_and_converges():
    """A scene that names neither iterations nor substeps (``hanging``, switched to ``vbd`` as a
    user would in the node) gets ``vbd``'s own choice: substeps from the cloth, iterations to the
    tolerance, every step converged, the cotton sheet at 32×32 held at the scene's strain limit.
    A scene that names its iterations keeps one step of at most that many (``tshirt``: 3)."""
    cfg, _, sim, _ = settings.configure("hanging", {"integrator": "vbd", "dt": 1 / 60})
    assert cfg["vbd.iterations"] == 0 and cfg["vbd.substeps"] == 0
    sim.advance(1.0)
    stats = sim.integrator_stats
    assert stats["last_substeps"] > 1 and stats["unconverged_steps"] == 0
    assert sim.max_strain() < 0.1 + 2e-3
    scene = load_scene("tshirt")
    assert (scene.vbd_iterations, scene.vbd_substeps) == (3, 1)
    want = {"tolerance": scene.vbd_tolerance, "iterations": 3, "substeps": 1}
    assert scene.vbd_options() == want
