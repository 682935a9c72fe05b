"""The Gymnasium tasks (cloth_sim.envs): Gymnasium's own checker, determinism, SoftGym's metrics
against closed forms, the pickers' rules, scripted policies that must succeed, random policies that
must stay finite, vector envs, and bad input."""

import functools
import multiprocessing
import time

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
from gymnasium.utils.env_checker import check_env  # noqa: E402

import cloth_sim.envs  # noqa: E402
from cloth_sim.envs import initial_states, metrics, policies  # noqa: E402
from cloth_sim.envs.vector import ClothFoldVectorEnv  # noqa: E402

TASKS = ("ClothFlatten", "ClothFold", "ClothDrop")


def make(task, cache, **kw):
    kw.setdefault("num_variations", 2)
    return gym.make(f"cloth_sim/{task}-v0", cache_dir=cache, **kw)


# ---------------------------------------------------------------- Gymnasium's checker
@pytest.mark.parametrize("env_id", cloth_sim.envs.ENV_IDS)
def test_gymnasium_env_checker_passes_for_every_env(env_id, cache):
    # a garment's variation is several seconds of dropping and settling (TshirtFlatten's 11 s):
    # one, which test_garments.py shares; the grids' two are cheap
    garment = ".garments:" in gym.spec(env_id).entry_point
    env = gym.make(
        env_id, cache_dir=cache, num_variations=1 if garment else 2, render_mode="rgb_array"
    )
    check_env(env.unwrapped, skip_render_check=False)


@pytest.mark.parametrize("mode", ["point_cloud", "depth"])
@pytest.mark.parametrize("task", TASKS)
def test_env_checker_passes_for_each_observation_mode(task, mode, cache):
    env = make(
        task,
        cache,
        observation_mode=mode,
        image_size=48,
        max_points=256,
        render_mode="depth_array",
    )
    check_env(env.unwrapped, skip_render_check=False)


def test_the_ids_can_be_made_without_importing_the_module_first():
    env = gym.make("cloth_sim.envs:cloth_sim/ClothFold-v0", cache_dir=False, num_variations=1)
    assert env.unwrapped.task == "ClothFold"


# ---------------------------------------------------------------- determinism
def _episode(env, seed, steps=6, options=None):
    obs, info = env.reset(seed=seed, options=options)
    env.variation_seen = info["variation"]
    out = [obs]
    rng = np.random.default_rng(seed)
    lo, hi = env.action_space.low, env.action_space.high
    for _ in range(steps):
        obs, *_ = env.step(rng.uniform(lo, hi).astype(np.float32))
        out.append(obs)
    return np.stack(out)


@pytest.mark.parametrize("mode", ["key_point", "point_cloud", "depth"])
def test_the_same_seed_gives_the_same_episode_bitwise(mode, cache):
    kw = dict(observation_mode=mode, image_size=48, max_points=128)
    env = make("ClothFlatten", cache, **kw)
    a = _episode(env, seed=3)
    # generated afresh (no cache) in another env: the same bits
    b = _episode(make("ClothFlatten", False, **kw), seed=3)
    assert a.tobytes() == b.tobytes()
    # the other variation: another episode
    c = _episode(
        make("ClothFlatten", cache, **kw), seed=3, options={"variation": 1 - env.variation_seen}
    )
    assert a[0].tobytes() != c[0].tobytes()


def test_initial_states_are_cached_on_disk_and_a_damaged_file_is_made_again(tmp_path):
    env = make("ClothFold", str(tmp_path))
    obs, info = env.reset(seed=0, options={"variation": 1})
    files = list(tmp_path.glob("ClothFold-*/1.npz"))
    assert len(files) == 1
    files[0].write_bytes(b"not a zip")
    env2 = make("ClothFold", str(tmp_path))
    obs2, _ = env2.reset(seed=0, options={"variation": 1})
    assert obs.tobytes() == obs2.tobytes()
    with np.load(files[0]) as f:  # written again, whole
        assert f["positions"].shape == (24 * 24, 3)


def _slow_variation(rng, log):
    """A generator that takes half a second and says each time it runs."""
    with open(log, "a") as f:
        f.write("made\n")
    time.sleep(0.5)
    return {"x": rng.random(4)}


def _get_variation(folder, log, barrier, out):
    barrier.wait()  # both ask at once
    cache = initial_states.Cache("Slow", {}, functools.partial(_slow_variation, log=log), folder)
    out.put(cache.get(3)["x"].tobytes())


def test_processes_asking_for_the_same_missing_variation_at_once_make_it_once(tmp_path):
    """Two processes (vector envs, parallel test workers) missing the same variation: one makes
    it, the other waits and reads it, the same bytes; a third, later, reads it without making."""
    ctx = multiprocessing.get_context("fork")
    log, barrier, out = tmp_path / "log", ctx.Barrier(2), ctx.Queue()
    procs = [
        ctx.Process(target=_get_variation, args=(str(tmp_path), log, barrier, out))
        for _ in range(2)
    ]
    for p in procs:
        p.start()
    got = [out.get(timeout=60) for _ in procs]
    for p in procs:
        p.join(timeout=60)
        assert p.exitcode == 0
    assert log.read_text().count("made") == 1
    assert got[0] == got[1]
    again = initial_states.Cache(
        "Slow", {}, functools.partial(_slow_variation, log=log), str(tmp_path)
    ).get(3)
    assert again["x"].tobytes() == got[0] and log.read_text().count("made") == 1


# ---------------------------------------------------------------- metrics (closed forms)
def _grid(rows, cols, s):
    r, c = np.divmod(np.arange(rows * cols), cols)
    return np.stack([c * s, r * s, np.zeros(rows * cols)], axis=1)


def test_covered_area_of_a_flat_grid_is_its_area_and_a_fold_halves_it():
    s = 0.02
    x = _grid(20, 30, s)
    # each particle covers a square of side s, measured inside the centres' bounding box (SoftGym's
    # grid): a flat grid covers (cols − 1)·s × (rows − 1)·s
    assert metrics.covered_area(x, s / 2) == pytest.approx(29 * s * 19 * s, rel=0.01)
    folded = x.copy()
    right = folded[:, 0] > 14.5 * s
    folded[right, 0] = 29 * s - folded[right, 0]  # columns 15..29 onto 14..0
    folded[right, 2] = 0.005
    assert metrics.covered_area(folded, s / 2) == pytest.approx(14 * s * 19 * s, rel=0.01)
    # two particles far apart cover their squares, not the box between them; each square is at a
    # corner of the bounding box, which keeps a quarter of it
    two = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    assert metrics.covered_area(two, 0.05) == pytest.approx(2 * 0.05 * 0.05, rel=1e-9)


def test_fold_metric_is_zero_for_a_perfect_fold_and_the_normalisation_is_one():
    x = _grid(6, 8, 0.1)
    a, b = metrics.fold_groups(6, 8)
    assert len(a) == len(b) == 24
    # mirrored pairs share a row and their columns sum to cols − 1
    assert np.all(a // 8 == b // 8) and np.all(a % 8 + b % 8 == 7)
    p0, group, fix = metrics.fold_distance(x, x, a, b)
    assert fix == 0 and group == pytest.approx(np.mean(np.abs((a % 8 - b % 8)) * 0.1))
    folded = x.copy()
    folded[a] = x[b]
    p, group, fix = metrics.fold_distance(folded, x, a, b)
    assert p == group == fix == 0
    assert metrics.normalized(p, p0, 0.0) == 1.0
    assert metrics.normalized(p0, p0, 0.0) == 0.0


def test_drop_metric_is_zero_on_target(cache):
    env = make("ClothDrop", cache).unwrapped
    env.reset(seed=0)
    assert metrics.mean_distance(env.target(), env.target()) == 0.0
    p0 = env._performance()[0]
    assert p0 < -0.1 and env._normalized(p0) == 0.0


# ---------------------------------------------------------------- pickers
def test_a_pick_holds_the_nearest_particle_within_reach_and_moves_are_bounded(cache):
    env = make("ClothFold", cache, num_picker=1)
    env.reset(seed=0)
    u = env.unwrapped
    x = u.sim.positions.copy()
    j = int(u.corners[3])
    # put the picker 1 cm above corner 3: it is the nearest, within reach
    u.pickers.place([x[j] + (0, 0, 0.01)])
    obs, r, term, trunc, info = env.step(np.float32([0, 0, 0.01, 1]))
    assert info["picked"] == [True] and list(u.sim.grippers.values())[0].tolist() == [j]
    # 8 frames of at most 1 cm up: the corner rose 8 cm with the picker
    assert u.pickers.positions[0, 2] == pytest.approx(x[j, 2] + 0.01 + 0.08)
    assert u.sim.positions[j, 2] == pytest.approx(x[j, 2] + 0.08)
    # a move asked beyond the bound is clipped to it... by the action space: 1 cm per frame
    z = u.pickers.positions[0, 2]
    with pytest.raises(ValueError):  # (and a NaN refused)
        env.step(np.float32([0, 0, np.nan, 1]))
    env.step(np.float32([0, 0, 0.5, 1]))
    assert u.pickers.positions[0, 2] == pytest.approx(z + 0.08)
    # release: the corner falls back to the floor
    for _ in range(6):
        obs, r, term, trunc, info = env.step(np.float32([0, 0, 0, 0]))
    assert info["picked"] == [False] and not u.sim.grippers
    assert u.sim.positions[j, 2] < 0.01


def test_a_pick_out_of_reach_holds_nothing(cache):
    env = make("ClothFold", cache, num_picker=1)
    env.reset(seed=0)
    u = env.unwrapped
    u.pickers.place([[0.0, 0.0, 0.3]])  # 30 cm above the cloth: reach is about 3 cm
    *_, info = env.step(np.float32([0, 0, 0, 1]))
    assert info["picked"] == [False] and not u.sim.grippers


# ---------------------------------------------------------------- scripted and random policies
def _run(env, policy):
    info = None
    for a in policy(env.unwrapped):
        *_, trunc, info = env.step(a)
        if trunc:
            break
    return info


@pytest.mark.parametrize("seed", [1, 4])
def test_a_scripted_flatten_spreads_a_crumpled_cloth(seed, cache):
    env = make("ClothFlatten", cache, num_variations=1000)
    _, info0 = env.reset(seed=seed)
    u = env.unwrapped
    assert u.area_start < 0.6 * u.area_flat  # it starts crumpled
    info = _run(env, policies.flatten)
    assert info["normalized_performance"] > 0.8


@pytest.mark.parametrize("seed", [0, 1])
def test_a_scripted_fold_folds_the_cloth_in_half(seed, cache):
    env = make("ClothFold", cache, num_variations=1000)
    env.reset(seed=seed)
    info = _run(env, policies.fold)
    assert info["normalized_performance"] > 0.8
    assert -info["neg_group_dist"] < 0.03


@pytest.mark.parametrize("task", TASKS)
def test_a_random_policy_stays_finite_for_ten_episodes(task, cache):
    env = make(task, cache)
    env.action_space.seed(0)
    for episode in range(10):
        env.reset(seed=episode)
        trunc = False
        while not trunc:
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            assert np.isfinite(obs).all() and np.isfinite(r)
            assert np.isfinite(env.unwrapped.sim.positions).all()
        assert env.unwrapped.steps == env.unwrapped.horizon


# ---------------------------------------------------------------- vector envs
def test_sync_and_async_vector_envs_agree(cache):
    kw = dict(num_variations=2, cache_dir=cache, horizon=5)
    out = {}
    for mode in ("sync", "async"):
        envs = gym.make_vec("cloth_sim/ClothFold-v0", num_envs=2, vectorization_mode=mode, **kw)
        obs, info = envs.reset(seed=[0, 1])
        steps = [obs]
        rng = np.random.default_rng(0)
        for _ in range(3):
            a = rng.uniform(envs.action_space.low, envs.action_space.high).astype(np.float32)
            obs, r, term, trunc, info = envs.step(a)
            steps.append(obs)
        envs.close()
        out[mode] = np.stack(steps)
        assert out[mode].shape == (4, 2, 18)
        assert list(info["normalized_performance"].shape) == [2]
    assert out["sync"].tobytes() == out["async"].tobytes()


def _recorded_folds(cache, seeds):
    """The scripted fold on the single env, seed by seed: its actions and what each step
    returned."""
    runs = []
    for seed in seeds:
        env = make("ClothFold", cache, num_variations=1000)
        env.reset(seed=seed)
        steps = []
        for a in policies.fold(env.unwrapped):
            obs, r, term, trunc, info = env.step(a)
            steps.append((a, obs, r, trunc, info["picked"]))
            if trunc:
                break
        runs.append(steps)
    return runs


def test_the_vector_env_on_the_cpu_is_the_single_envs_cloth(cache):
    """ClothFoldVectorEnv's worlds, each given the actions the scripted fold gave a single env of
    the same seed: the same observations and rewards to rounding (5.6e-14 measured: a held
    particle's straight line is computed from its own place, not the picker's), the same grasps,
    and both folds succeed."""
    runs = _recorded_folds(cache, (0, 1))
    vec = ClothFoldVectorEnv(num_envs=2, num_variations=1000, cache_dir=cache)
    obs, info = vec.reset(seed=[0, 1])
    assert obs.shape == (2, 18) and obs.dtype == np.float32
    for k in range(max(len(r) for r in runs)):
        a = np.stack([r[min(k, len(r) - 1)][0] for r in runs])
        obs, rew, term, trunc, info = vec.step(a)
        for w, run in enumerate(runs):
            if k < len(run):
                _, o, r, t, picked = run[k]
                assert np.max(np.abs(obs[w] - o)) < 1e-12 and abs(rew[w] - r) < 1e-12
                assert trunc[w] == t and info["picked"][w].tolist() == picked
    assert np.all(info["normalized_performance"] > 0.8)
    assert any(p for run in runs for *_, p in run if any(p))  # it did grasp


def test_the_vector_env_resets_a_world_at_its_horizon_next_step(cache):
    """Gymnasium's next-step autoreset: the step after a world's last returns its first
    observation with reward 0 and ignores its action; the other worlds go on."""
    vec = ClothFoldVectorEnv(num_envs=2, num_variations=3, cache_dir=cache, horizon=2)
    first, _ = vec.reset(seed=[5, 6])
    down = np.tile(np.float32([0, 0, -0.01, 0]), (2, 2))
    vec.step(down)
    *_, trunc, _ = vec.step(down)
    assert trunc.tolist() == [True, True]
    obs, rew, term, trunc, info = vec.step(down)
    assert rew.tolist() == [0.0, 0.0] and not trunc.any() and not term.any()
    assert vec.steps.tolist() == [0, 0]
    # a reset world starts again: its cloth is its variation's initial state, the pickers placed
    single = make("ClothFold", cache, num_variations=3)
    for w in range(2):
        single.unwrapped.reset(options=dict(variation=int(info["variation"][w])))
        assert np.array_equal(obs[w], single.unwrapped.key_point_state())


@pytest.mark.parametrize(
    "kw, words",
    [
        (
            dict(observation_mode="depth"),
            "observation_mode = 'depth' is not accepted by the vector",
        ),
        (dict(action_mode="pickerpickplace"), "action_mode = 'pickerpickplace' is not accepted"),
        (dict(precision="float64"), "precision: the cuda device's options; device='cpu'"),
        (dict(num_envs=0), "num_envs = 0 is not accepted"),
        (dict(observations="device"), "observations = 'device' is not accepted on device='cpu'"),
        (dict(device="tpu"), "device = 'tpu' is not accepted: device must be one of cpu, cuda"),
    ],
)
def test_the_vector_env_refuses_what_it_cannot_run(kw, words, cache):
    kw = dict(dict(num_envs=2, num_variations=1, cache_dir=cache), **kw)
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        ClothFoldVectorEnv(**kw)


def test_the_vector_env_checks_actions_before_it_steps(cache):
    vec = gym.make_vec("cloth_sim/ClothFold-v0", num_envs=2, num_variations=1, cache_dir=cache)
    assert isinstance(vec, ClothFoldVectorEnv)  # (the id's vector entry point)
    vec.reset(seed=0)
    before = vec.sim.positions_host()
    with pytest.raises(ValueError, match=r"actions: expected shape \(2, 8\)"):
        vec.step(np.zeros(8))
    bad = np.zeros((2, 8))
    bad[1, 6] = np.nan
    with pytest.raises(ValueError, match=r"actions\[1, 6\] = nan is not finite"):
        vec.step(bad)
    assert np.array_equal(vec.sim.positions_host(), before) and vec.steps.tolist() == [0, 0]


# ---------------------------------------------------------------- render
def test_render_modes(cache):
    env = make("ClothFold", cache, render_mode="rgb_array", image_size=64)
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
    depth_env = make("ClothFold", cache, render_mode="depth_array", image_size=64)
    depth_env.reset(seed=0)
    d = depth_env.render()
    assert d.shape == (64, 64) and d.dtype == np.float32
    u = depth_env.unwrapped
    cloth = u.cam.render(u.sim).object == 0
    # cloth pixels are drawn in the cloth's colours (orange or blue dominant), never floor grey
    rgb = img[cloth].astype(int)
    assert cloth.sum() > 100
    assert np.mean(np.abs(rgb[:, 0] - rgb[:, 2]) > 40) > 0.9  # (the pickers' white discs aside)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "action, words",
    [
        (np.full(8, np.nan, np.float32), "action[0] = nan (picker 0, dx) is not finite"),
        (
            np.float32([0, 0, 0, 1, 0, 0, np.inf, 0]),
            "action[6] = inf (picker 1, dz) is not finite",
        ),
        (np.zeros(7, np.float32), "expected shape (8,)"),
        (np.zeros((2, 4), np.float32), "got shape (2, 4)"),
        ("left", "expected 8 numbers"),
    ],
)
def test_bad_actions_raise_a_clear_error_and_change_nothing(action, words, cache):
    env = make("ClothFlatten", cache)
    env.reset(seed=0)
    before = env.unwrapped.sim.positions.copy()
    with pytest.raises(ValueError) as e:
        env.step(action)
    assert words in str(e.value)
    assert np.array_equal(env.unwrapped.sim.positions, before)


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(observation_mode="cam_rgb"), "observation_mode = 'cam_rgb' is not accepted"),
        (dict(action_mode="sawyer"), "action_mode = 'sawyer'"),
        (dict(num_picker=0), "num_picker = 0"),
        (dict(cloth_size=(2, 24)), "cloth_size[0] (rows) = 2"),
        (dict(cloth_size=24), "cloth_size = 24"),
        (dict(spacing=-1.0), "spacing = -1.0"),
        (dict(horizon=0), "horizon = 0"),
        (dict(action_mode="pickerpickplace", action_repeat=8), "action_repeat = 8"),
        (dict(render_mode="ansi"), "render_mode = 'ansi'"),
        (dict(self_collision="yes"), "self_collision = 'yes'"),
    ],
)
def test_bad_settings_are_refused_naming_the_setting(kw, words):
    with pytest.raises(ValueError) as e:
        gym.make("cloth_sim/ClothFlatten-v0", cache_dir=False, **kw)
    assert words in str(e.value)


def test_drop_needs_two_pickers_and_reset_options_are_checked(cache):
    with pytest.raises(ValueError, match="num_picker = 1 is not accepted by ClothDrop"):
        gym.make("cloth_sim/ClothDrop-v0", cache_dir=False, num_picker=1)
    env = make("ClothFold", cache)
    with pytest.raises(ValueError, match=r"options\['variation'\] = 5"):
        env.reset(options={"variation": 5})
    with pytest.raises(ValueError, match="unknown"):
        env.reset(options={"level": 1})
