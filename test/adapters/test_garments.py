"""The garment tasks (cloth_sim.envs.garments): the T-shirt's key points are its landmarks, laid
flat it covers the most it can, and the scripted flatten spreads it where random actions do not;
the fold's metric and target, and the scripted fold against random actions.
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


def test_the_fold_metric_is_blind_to_the_frame_and_one_for_the_perfect_fold():
    """metrics.shape_distance compares the landmarks' distances pair by pair: 0 for the same
    shape turned, moved or mirrored, the mean distance error otherwise (one point moved by d along
    the line of the other two in a three-point set: |d| on two of the three pairs)."""
    from cloth_sim.envs import metrics

    rng = np.random.default_rng(3)
    x = rng.normal(size=(16, 3))
    a = 0.7
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    assert metrics.shape_distance(x @ rot.T + (1.0, -2.0, 0.5), x) < 1e-12
    assert metrics.shape_distance(x * (-1.0, 1.0, 1.0), x) < 1e-12  # mirrored
    line = np.array([[0.0, 0, 0], [1.0, 0, 0], [3.0, 0, 0]])
    moved = line.copy()
    moved[2, 0] += 0.25
    assert np.isclose(metrics.shape_distance(moved, line), 2 * 0.25 / 3)


def test_the_tshirt_fold_starts_at_zero_and_its_target_is_the_folded_shirt(cache):
    """TshirtFold: the shirt lies flat (turned), normalized 0 there; its target is its flat
    landmarks folded: the sleeve ends mirrored inside the armpit lines, then everything below the
    middle mirrored onto the top half, the armpits, shoulders and collar left where they are."""
    env = make("TshirtFold", cache).unwrapped
    obs, info = env.reset(seed=0, options={"variation": 0})
    assert info["normalized_performance"] == 0.0 and info["fixation_distance"] == 0.0
    assert env.self_collision and env.sim.integrator == "vbd"
    marks = list(env.model.meta["landmarks"])
    target, still = env.folded_landmarks()
    flat = env.flat_positions()[list(env.model.meta["landmarks"].values())]
    kept = {m for m, s in zip(marks, still) if s}
    assert kept == {
        "armpit_left",
        "armpit_right",
        "shoulder_left",
        "shoulder_right",
        "collar_left",
        "collar_right",
        "collar_middle_front",
        "collar_middle_back",
    }
    i = marks.index
    # the hem's corners land on the line through the shoulders' height mirrored about the middle
    mid = (flat[i("hem_left"), 1] + flat[i("shoulder_left"), 1]) / 2
    assert np.isclose(target[i("hem_left"), 1], 2 * mid - flat[i("hem_left"), 1])
    assert np.isclose(target[i("hem_left"), 1], flat[i("shoulder_left"), 1])
    # a sleeve's end: mirrored across x = armpit_left's x, so inside the body
    ax = flat[i("armpit_left"), 0]
    assert np.isclose(target[i("sleeve_left_top"), 0], 2 * ax - flat[i("sleeve_left_top"), 0])
    assert np.all(target[:, 2][~still] > flat[:, 2].max())  # moved layers lie on top
    # the cloth's landmarks put at the target, the fixed ones where they were: normalized 1
    x = env.sim.positions.copy()
    rot, shift = policies.rigid_fit(flat[:, :2], x[env.corners, :2])
    placed = target.copy()
    placed[:, :2] = target[:, :2] @ rot.T + shift
    env.start_positions[env.fixed] = x[env.fixed] = placed[still]  # the fit's frame
    x[env.corners] = placed
    env.sim.positions = x
    assert np.isclose(env._normalized(env._performance()[0]), 1.0)


def test_the_scripted_tshirt_fold_folds_it_and_a_random_policy_does_not(cache):
    """policies.fold_garment: each sleeve by its cuff over its armpit line, then the hem over the
    middle: most of the way to the perfect fold, where random pickers get nowhere (or worse)."""
    env = make("TshirtFold", cache).unwrapped
    env.reset(seed=0, options={"variation": 0})
    n = 0
    for action in policies.fold_garment(env):
        *_, info = env.step(action)
        n += 1
    scripted = info["normalized_performance"]
    env.reset(seed=0, options={"variation": 0})
    rng = np.random.default_rng(0)
    for _ in range(n):
        *_, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
    assert scripted > 0.6 and info["normalized_performance"] < 0.2, (
        scripted,
        info["normalized_performance"],
    )
