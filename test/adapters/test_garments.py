"""The garment tasks (cloth_sim.envs.garments): the T-shirt's key points are its landmarks, laid
flat it covers the most it can, and the scripted flatten spreads it where random actions do not.
(Gymnasium's checker runs over every id in test_envs.py.)"""

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import cloth_sim.envs  # noqa: E402,F401  (registers the ids)
from cloth_sim.envs import policies  # noqa: E402


def make(task, cache, **kw):
    kw.setdefault("num_variations", 1)
    return gym.make(f"cloth_sim/{task}-v0", cache_dir=cache, **kw)


def test_the_tshirt_observes_its_landmarks_and_lies_flat_at_full_coverage(cache):
    """TshirtFlatten's key points are the T-shirt's named vertices (then the pickers); laid flat,
    its panels a thickness apart on the floor, it covers the most it can: normalized 1."""
    env = make("TshirtFlatten", cache).unwrapped
    obs, info = env.reset(seed=0, options={"variation": 0})
    marks = env.model.meta["landmarks"]
    assert env.key_point_names == tuple(marks) and len(marks) == 16
    x = env.sim.positions
    expected = np.concatenate([x[list(marks.values())].ravel(), env.pickers.positions.ravel()])
    np.testing.assert_array_equal(obs, expected.astype(np.float32))
    assert env.self_collision and env.sim.integrator == "vbd"
    assert 0.0 == info["normalized_performance"]  # the crumpled start
    assert env.area_start < 0.6 * env.area_flat
    env.lay_flat()
    assert env._normalized(env._performance()[0]) == 1.0
    flat = env.flat_positions()
    assert flat[:, 2].min() == env.thickness and flat[:, 2].max() == 3 * env.thickness


def test_the_scripted_tshirt_flatten_spreads_it_and_a_random_policy_does_not(cache):
    """policies.flatten_garment: lay it down by the hem's corners, then place the sleeves and
    the shoulders where the flat shirt has them (seen from the hem): over half the way from the
    crumpled start to flat, where random pickers stay near the start."""
    env = make("TshirtFlatten", cache).unwrapped
    env.reset(seed=0, options={"variation": 0})
    for action in policies.flatten_garment(env):
        *_, info = env.step(action)
    scripted = info["normalized_performance"]
    env.reset(seed=0, options={"variation": 0})
    rng = np.random.default_rng(0)
    for _ in range(60):
        *_, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
    assert scripted > 0.5 and info["normalized_performance"] < scripted - 0.3, (
        scripted,
        info["normalized_performance"],
    )
