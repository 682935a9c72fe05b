"""``cloth-sim dataset`` (cloth_sim.dataset): what it writes is a LeRobotDataset v3.0, checked
against the format with pyarrow and PyAV (LeRobot itself is an optional extra: make bench-learning
loads it with LeRobot's own loader); the frames are the env's (replaying the recorded actions gives
the recorded states and rewards); episodes made on Ray are the same bytes at any worker count and
after a resume; a full disk mid-episode leaves the committed episodes valid; bad input is refused
by name."""

import errno
import json
from pathlib import Path

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
av = pytest.importorskip("av")
pytest.importorskip("gymnasium")

from cloth_sim import cli  # noqa: E402
from cloth_sim.dataset import engine, lerobot, rollout  # noqa: E402
from cloth_sim.dataset.lerobot import DatasetError, Writer  # noqa: E402

TASK = "ClothFold"  # a scripted episode is ~20 env steps of a 24 × 24 cloth


def write(root, episodes, policy="scripted", observation="key_point", task=TASK, size=64):
    """A dataset written in this process (no Ray): the rollouts and the writer the engine uses."""
    env = rollout.make_env(task, observation, size)
    writer = Writer(root, rollout.features(env, observation), rollout.fps(env), "cloth_sim")
    for e in range(episodes):
        r = rollout.episode(env, e, 0, policy)
        writer.write_episode(r["frames"], r["videos"], r["task"], r["extra"])
    return env, writer


@pytest.fixture(scope="module")
def ray_session():
    """One local Ray for the module's runs on Ray made in this process (engine.generate, the
    sweep's lerobot export): each would otherwise start and stop its own, ~5 s here, seven times.
    The driver's own start and stop of Ray are the killed run's (a command of its own)."""
    from cloth_sim.sweep import cluster

    with cluster.session(2, None):
        yield


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds") / "ClothFold"
    env, _ = write(root, 2)
    return env, root


def files(root: Path) -> dict:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


def test_info_json_is_v3_with_the_features_and_their_video_encoding(dataset):
    env, root = dataset
    info = json.loads((root / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0"
    assert info["fps"] == pytest.approx(60 / 8)  # ClothFold: 8 frames of 1/60 s an env step
    assert info["total_episodes"] == 2 and info["total_tasks"] == 1
    assert info["splits"] == {"train": "0:2"}
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert (
        info["video_path"]
        == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    )
    f = info["features"]
    for key in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert f[key]["shape"] == [1]
    assert f["observation.state"]["shape"] == [3 * (4 + 2)]  # four corners, two pickers
    assert f["observation.state"]["names"][:3] == ["corner_0.x", "corner_0.y", "corner_0.z"]
    assert f["action"]["shape"] == [8] and f["action"]["names"][3] == "picker_0.pick"
    assert f["next.reward"]["dtype"] == "float32" and f["next.done"]["dtype"] == "bool"
    rgb, depth = f["observation.images.rgb"], f["observation.images.depth"]
    assert rgb["dtype"] == depth["dtype"] == "video" and rgb["shape"] == [64, 64, 3]
    assert rgb["info"]["video.is_depth_map"] is False
    assert depth["info"]["video.is_depth_map"] is True
    assert depth["info"]["video.depth_range_m"] == list(rollout.DEPTH_RANGE)


def test_the_frames_are_the_envs_replaying_the_actions_gives_the_states_and_rewards(dataset):
    """Each data file holds one episode: frame t's state is what the env showed before action t,
    next.reward what followed it, next.done only on the last frame; index runs on over the
    dataset. Replayed in a fresh env from the episode's seed, the actions give the same states and
    rewards, bit for bit."""
    env, root = dataset
    start = 0
    for e in range(2):
        t = pq.read_table(root / f"data/chunk-000/file-{e:03d}.parquet").to_pydict()
        n = len(t["frame_index"])
        assert t["frame_index"] == list(range(n)) and t["episode_index"] == [e] * n
        assert t["index"] == list(range(start, start + n)) and t["task_index"] == [0] * n
        np.testing.assert_allclose(t["timestamp"], np.arange(n) / 7.5, atol=1e-6)
        assert t["next.done"] == [False] * (n - 1) + [True]
        env.reset(seed=rollout.episode_seed(0, e))
        for k in range(n):
            np.testing.assert_array_equal(t["observation.state"][k], env.key_point_state())
            *_, info = env.step(np.array(t["action"][k]))
            assert np.float32(info["performance"]) == np.float32(t["next.reward"][k])
        episodes = pq.read_table(root / f"meta/episodes/chunk-000/file-{e:03d}.parquet")
        (row,) = episodes.to_pylist()
        assert row["normalized_performance"] == info["normalized_performance"] > 0.5
        assert (row["dataset_from_index"], row["dataset_to_index"]) == (start, start + n)
        assert row["length"] == n and row["tasks"] == [env.instruction]
        assert row["videos/observation.images.rgb/to_timestamp"] == pytest.approx(n / 7.5)
        start += n


def test_the_videos_hold_a_frame_a_step_of_the_cameras_colour_and_depth(dataset):
    """PyAV decodes each episode's MP4s: H.264, one frame a step at the env's rate; the first
    colour frame is the env's rendering of its start (to the codec's loss), the depth video's grey
    levels give back the camera's depth to within a few levels (~1 cm each)."""
    env, root = dataset
    t = pq.read_table(root / "data/chunk-000/file-000.parquet")
    n = t.num_rows
    decoded = {}
    for key in ("rgb", "depth"):
        with av.open(str(root / f"videos/observation.images.{key}/chunk-000/file-000.mp4")) as c:
            s = c.streams.video[0]
            assert s.codec_context.name == "h264" and (s.width, s.height) == (64, 64)
            assert float(s.average_rate) == pytest.approx(7.5)
            decoded[key] = np.stack([f.to_ndarray(format="rgb24") for f in c.decode(s)])
        assert len(decoded[key]) == n
    from cloth_sim.envs.render import render_rgb

    env.reset(seed=rollout.episode_seed(0, 0))
    frame = env.cam.render(env.sim)
    rgb = render_rgb(frame, env.sim, env.cam, env.pickers)
    assert np.abs(decoded["rgb"][0].astype(int) - rgb).mean() < 6
    levels = rollout.depth_levels(frame.depth)[..., 0].astype(int)
    error = np.abs(decoded["depth"][0][..., 0].astype(int) - levels)
    assert np.median(error) <= 2 and np.mean(error <= 4) > 0.95


def test_stats_json_is_the_statistics_of_every_frame(dataset):
    """meta/stats.json aggregates the episodes' statistics as LeRobot does: the same as computed
    over all the frames at once (means, standard deviations, extremes); images per channel in
    [0, 1], shaped (3, 1, 1)."""
    _, root = dataset
    stats = json.loads((root / "meta/stats.json").read_text())
    t = pa.concat_tables(
        [pq.read_table(root / f"data/chunk-000/file-{e:03d}.parquet") for e in range(2)]
    )
    for key in ("observation.state", "action", "next.reward", "index"):
        x = np.asarray(t.column(key).to_pylist(), np.float64).reshape(t.num_rows, -1)
        s = stats[key]
        np.testing.assert_allclose(np.ravel(s["mean"]), x.mean(axis=0), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(np.ravel(s["std"]), x.std(axis=0), rtol=1e-7, atol=1e-9)
        np.testing.assert_array_equal(np.ravel(s["max"]), x.max(axis=0))
        np.testing.assert_array_equal(np.ravel(s["min"]), x.min(axis=0))
        assert s["count"] == [t.num_rows]
    rgb = np.array(stats["observation.images.rgb"]["mean"])
    assert rgb.shape == (3, 1, 1) and np.all((0 < rgb) & (rgb < 1))


def test_tasks_parquet_is_indexed_by_the_task_as_pandas_writes_it(dataset):
    env, root = dataset
    table = pq.read_table(root / "meta/tasks.parquet")
    meta = json.loads(table.schema.metadata[b"pandas"])
    assert meta["index_columns"] == ["__index_level_0__"]
    assert table.column("__index_level_0__").to_pylist() == [env.instruction]
    assert table.column("task_index").to_pylist() == [0]


def test_the_same_bytes_at_one_and_two_workers_and_after_a_resume(tmp_path, ray_session):
    """On Ray: two episodes at one worker then the same command with --episodes 3 (a resume),
    against three at two workers: every file the same bytes; and the same as written in one
    process without Ray."""
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    kw = dict(image_size=64, progress=False)
    engine.generate(TASK, a, episodes=2, workers=1, **kw)
    assert engine.generate(TASK, a, episodes=3, workers=1, **kw).episodes == 3
    engine.generate(TASK, b, episodes=3, workers=2, **kw)
    write(c, 3)
    fa, fb, fc = files(a), files(b), files(c)
    marker = fa.pop(engine.MARKER)
    assert json.loads(marker)["policy"] == "scripted"
    fb.pop(engine.MARKER)
    assert fa == fb == fc


def test_a_full_disk_mid_episode_leaves_the_committed_ones_and_the_same_command_resumes(
    tmp_path, monkeypatch, ray_session
):
    """The disk fills while the second episode's files are written (its video): the command
    stops with a message saying what to do; the dataset holds one whole episode and none of the
    second's files; the same command then finishes it, to the bytes of a run never stopped."""
    root = tmp_path / "ds"
    replace = lerobot._replace
    calls = []

    def full(path, data):
        calls.append(path)
        if "file-001.mp4" in str(path):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        replace(path, data)

    monkeypatch.setattr(lerobot, "_replace", full)
    with pytest.raises(DatasetError, match="1 episodes committed before it are intact"):
        engine.generate(TASK, root, episodes=2, workers=1, image_size=64, progress=False)
    info = json.loads((root / "meta/info.json").read_text())
    assert info["total_episodes"] == 1
    assert not (root / "data/chunk-000/file-001.parquet").exists()
    assert not list(root.rglob("*.tmp"))
    monkeypatch.setattr(lerobot, "_replace", replace)
    engine.generate(TASK, root, episodes=2, workers=1, image_size=64, progress=False)
    clean = tmp_path / "clean"
    write(clean, 2)
    got = files(root)
    got.pop(engine.MARKER)
    assert got == files(clean)


def test_a_run_killed_mid_way_keeps_what_it_committed_and_the_same_command_finishes(tmp_path):
    """SIGKILL to the command (and its Ray) once it has committed two episodes: what info.json
    records is whole (LeRobot's layout, every file of every committed episode); the same command
    again finishes to the bytes of a run never killed."""
    import os
    import signal
    import subprocess
    import sys
    import time

    root = tmp_path / "ds"
    argv = [str(Path(sys.executable).parent / "cloth-sim"), "dataset", TASK, "-o", str(root)]
    argv += ["--episodes", "4", "--workers", "1", "--image-size", "64", "--no-progress"]
    env = dict(os.environ, RAY_AUTH_MODE="disabled")
    proc = subprocess.Popen(argv, env=env, start_new_session=True, stderr=subprocess.PIPE)
    info = root / "meta/info.json"
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None:
            if info.exists() and json.loads(info.read_text())["total_episodes"] >= 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "finished before it could be killed"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    committed = json.loads(info.read_text())["total_episodes"]
    assert 2 <= committed < 4
    for e in range(committed):
        assert (root / f"data/chunk-000/file-{e:03d}.parquet").exists()
        assert (root / f"videos/observation.images.depth/chunk-000/file-{e:03d}.mp4").exists()
        assert pq.read_table(root / f"data/chunk-000/file-{e:03d}.parquet").num_rows > 0
    assert Writer.open(root).episodes == committed
    subprocess.run(argv, env=env, check=True, timeout=300, capture_output=True)
    clean = tmp_path / "clean"
    write(clean, 4)
    got = files(root)
    got.pop(engine.MARKER)
    assert got == files(clean)


def test_a_killed_commit_leaves_files_that_reopening_drops(dataset, tmp_path):
    """A writer killed after an episode's data file but before its info.json: reopened, the
    dataset is its committed episodes, the orphan and any .tmp removed."""
    _, src = dataset
    root = tmp_path / "ds"
    for name, data in files(src).items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    orphan = root / "data/chunk-000/file-002.parquet"
    orphan.write_bytes(b"half")
    (root / "videos/observation.images.rgb/chunk-000/file-002.mp4.tmp").write_bytes(b"x")
    w = Writer.open(root)
    assert w.episodes == 2 and not orphan.exists() and not list(root.rglob("*.tmp"))
    assert len(w.stats["action"]) == 2


def _refused(capsys, *argv) -> str:
    assert cli.main(["dataset", *argv]) == 2
    return capsys.readouterr().err


def test_bad_input_is_refused_by_name(tmp_path, capsys):
    out = str(tmp_path / "x")
    err = _refused(capsys, "ShirtFold", "-o", out)
    assert "TASK 'ShirtFold' is not a cloth_sim task" in err and "TshirtFold" in err
    err = _refused(capsys, "ClothFoldPPP", "-o", out)  # pick-and-place: 4 numbers are targets
    assert "--policy scripted" in err and "'pickerpickplace'" in err and "random" in err
    err = _refused(capsys, "ClothDrop", "-o", out)
    assert "ClothDrop has no scripted policy" in err
    assert "--policy 'greedy'" in _refused(capsys, TASK, "-o", out, "--policy", "greedy")
    assert "--observation 'rgb'" in _refused(capsys, TASK, "-o", out, "--observation", "rgb")
    assert "--episodes 0" in _refused(capsys, TASK, "-o", out, "--episodes", "0")
    assert not Path(out).exists()  # nothing written for any of them


def test_a_directory_holding_something_else_is_refused(dataset, tmp_path, capsys):
    """A DIR holding another command's dataset is refused unless --overwrite; one holding files
    that are no dataset is refused even then (--overwrite removes only a dataset)."""
    _, src = dataset
    other = tmp_path / "other"
    for name, data in files(src).items():
        (other / name).parent.mkdir(parents=True, exist_ok=True)
        (other / name).write_bytes(data)
    (other / engine.MARKER).write_text(json.dumps({"task": "cloth_sim/TshirtFold-v0"}))
    err = _refused(capsys, TASK, "-o", str(other), "--episodes", "1")
    assert "holds a dataset of another command" in err and "--overwrite" in err
    assert json.loads((other / "meta/info.json").read_text())["total_episodes"] == 2
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    err = _refused(capsys, TASK, "-o", str(foreign), "--overwrite")
    assert "not a LeRobot dataset" in err and (foreign / "notes.txt").read_text() == "mine"
    engine.prepare(other, {"task": "x"}, overwrite=True)
    assert not any(other.iterdir())  # --overwrite: the other dataset removed


def test_the_point_cloud_and_depth_observations_are_kept_lossless(tmp_path):
    """--observation point_cloud adds the env's cloud (max_points × 3, camera frame), depth the
    depth image in metres; both are the env's observation of that mode, as float32."""
    env, _ = write(
        tmp_path / "pc", 1, policy="random", observation="point_cloud", task="ClothDrop"
    )
    t = pq.read_table(tmp_path / "pc/data/chunk-000/file-000.parquet")
    cloud = np.asarray(t.column("observation.point_cloud").to_pylist()[0], np.float32)
    assert cloud.shape == (env.max_points, 3) and np.abs(cloud).sum() > 0
    obs, _ = env.reset(seed=rollout.episode_seed(0, 0))
    np.testing.assert_array_equal(cloud, obs[: 3 * env.max_points].reshape(-1, 3))
    env, _ = write(tmp_path / "d", 1, policy="random", observation="depth", task="ClothDrop")
    t = pq.read_table(tmp_path / "d/data/chunk-000/file-000.parquet")
    depth = np.asarray(t.column("observation.depth").to_pylist()[0], np.float32)
    assert depth.shape == (64, 64) and 0.5 < depth[depth > 0].min() < depth.max() <= env.cam.far


#: a sweep whose runs have actions: a hanging 10 × 10 cloth's free corner grasped at gx, carried
#: up and released; the third run's grasp finds nothing (refused: no episode)
SWEEP = {
    "scene": "hanging_provot",
    "duration": 0.5,
    "frames": 20,
    "seed": 3,
    "set": {
        "rows": 10,
        "cols": 10,
        "spacing": 0.11,
        "integrator": "symplectic_euler",
        "camera.width": 48,
        "camera.height": 32,
    },
    "grid": {"gx": [0.0, 0.99, 3.0]},
    "script": [
        {"at": 0.0, "grasp": {"gripper": "hand", "point": ["$gx", 0.99, 0.0], "radius": 0.02}},
        {"at": 0.05, "move": {"gripper": "hand", "to": ["$gx", 0.5, 0.3], "duration": 0.2}},
        {"at": 0.4, "release": {"gripper": "hand"}},
    ],
}


def test_a_sweeps_runs_export_as_episodes_whose_actions_are_the_scripts(
    tmp_path, capsys, ray_session
):
    """cloth-sim sweep --format lerobot: an episode per run that ended ok (the third's grasp finds
    nothing: refused, none); the action of frame k is where the gripper is at frame k + 1 and
    whether it holds; the key points of each frame are the corners of the run's own bag's cloud
    (read back independently with rosbags)."""
    import yaml
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump(SWEEP, sort_keys=False))
    out = tmp_path / "out"
    argv = ["sweep", str(spec), "-o", str(out), "--workers", "2", "--format", "lerobot"]
    assert cli.main([*argv, "--no-progress"]) == 0
    assert "2 episodes (the runs that ended ok)" in capsys.readouterr().out
    root = out / "lerobot"
    info = json.loads((root / "meta/info.json").read_text())
    assert info["total_episodes"] == 2 and info["fps"] == 20
    assert info["features"]["action"]["names"] == ["hand.x", "hand.y", "hand.z", "hand.held"]
    assert info["features"]["observation.images.rgb"]["shape"] == [32, 48, 3]
    for e, gx in enumerate((0.0, 0.99)):
        t = pq.read_table(root / f"data/chunk-000/file-{e:03d}.parquet").to_pydict()
        (row,) = pq.read_table(root / f"meta/episodes/chunk-000/file-{e:03d}.parquet").to_pylist()
        state, action = np.array(t["observation.state"]), np.array(t["action"])
        assert len(state) == 10 and t["next.done"][-1]  # frames 0..10 at 20 fps, the last none
        np.testing.assert_array_equal(action[:-1, :3], state[1:, 12:15])
        assert action[0, 3] == 1.0 and action[-1, 3] == 0.0  # held, then released at 0.4 s
        np.testing.assert_allclose(action[4, :3], [gx, 0.5, 0.3], atol=1e-6)  # at 0.25 s
        bag = out / "runs" / row["run"]
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
            conn = [c for c in r.connections if c.topic == "/cloth_sim/points"]
            clouds = [
                np.frombuffer(bytes(r.deserialize(raw, c.msgtype).data), np.float32).reshape(-1, 3)
                for c, _, raw in r.messages(connections=conn)
            ]
        corners = [0, 9, 90, 99]
        for k in range(len(state)):
            np.testing.assert_allclose(
                state[k, :12], clouds[k][corners].ravel(), rtol=0, atol=1e-6
            )
    # again: the dataset is complete, nothing rewritten
    before = files(root)
    assert cli.main([*argv, "--no-progress"]) == 0
    assert files(root) == before


def test_a_sweep_without_actions_is_refused_before_it_runs(tmp_path, capsys):
    import yaml

    spec = tmp_path / "spec.yaml"
    no_script = {**SWEEP, "grid": {"stiffness.structural": [500.0, 1000.0]}, "script": []}
    spec.write_text(yaml.safe_dump(no_script, sort_keys=False))
    out = tmp_path / "out"
    argv = ["sweep", str(spec), "-o", str(out), "--format", "lerobot", "--no-progress"]
    assert cli.main(argv) == 2
    assert "the spec has no script" in capsys.readouterr().err and not out.exists()
