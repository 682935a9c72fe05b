"""Sweeps on Ray (cloth-sim sweep): the spec refused whole with the key named, grid × random
counts, the same bytes at 1 and 2 workers, resume after SIGKILL of the driver (every run exactly
once, no partial bag), diverged and refused runs as rows, bags that rosbags and `cloth-sim info`
open, a script's grasp, camera frames, and a two-node Ray cluster on this machine through
--address.

A real local Ray (2 CPUs) runs here; each sweep starts its own and stops it.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("ray", reason="Ray is installed by `make`")
import pyarrow.parquet as pq  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from cloth_sim.bag.store import bag_info  # noqa: E402
from cloth_sim.cli import main as cli_main  # noqa: E402
from cloth_sim.sweep import SpecError, load_spec, run_id, spec_from_dict  # noqa: E402
from cloth_sim.sweep.run import execute  # noqa: E402

BIN = Path(sys.executable).parent
#: 12 runs of a 10×10 cloth, 0.3 s each, 10 frames per second
SPEC = {
    "scene": "hanging_provot",
    "duration": 0.3,
    "frames": 10,
    "seed": 3,
    "set": {"rows": 10, "cols": 10, "spacing": 0.11},
    "grid": {"integrator": ["symplectic_euler", "rk4", "verlet"]},
    "random": {"samples": 4, "stiffness.structural": {"loguniform": [300.0, 3000.0]}},
}


def write_spec(path: Path, data: dict) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def sweep_cmd(*args, env=None, **kw) -> subprocess.Popen:
    env = env or dict(os.environ, RAY_AUTH_MODE="disabled")
    env = dict(env, PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [str(BIN / "cloth-sim"), "sweep", *map(str, args), "--no-progress"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        **kw,
    )


def run_sweep(*args, timeout=240, env=None):
    proc = sweep_cmd(*args, env=env)
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        _kill_group(proc)
    assert proc.returncode == 0, err[-3000:]
    return out


def _kill_group(proc):
    """The process and what it started (a local Ray's processes) killed."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=30)


def decoded(bag: Path) -> dict:
    """topic -> its messages, decoded by rosbags (an independent CDR reader)."""
    out: dict = {}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
        for conn, _, raw in r.messages():
            out.setdefault(conn.topic, []).append(r.deserialize(raw, conn.msgtype))
    return out


def tree_bytes(root: Path) -> dict:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """SPEC swept at 2 workers: (spec path, output)."""
    d = tmp_path_factory.mktemp("sweep")
    spec = write_spec(d / "spec.yaml", SPEC)
    run_sweep(spec, "-o", d / "two", "--workers", 2)
    return spec, d / "two"


# ------------------------------------------------------------------------------- spec (no Ray)
@pytest.mark.parametrize(
    "change, words",
    [
        ({"grid": {"dt": [1e-3, 5.0]}}, ["grid.dt[1]", "[1e-07, 1] s"]),
        (
            {"grid": {"integrator": ["rk4", "leapfrog"]}},
            ["grid.integrator[1]", "leapfrog", "symplectic_euler"],
        ),
        ({"grid": {"dt": [1e-3, 1e-3]}}, ["grid.dt[1]", "twice"]),
        ({"grid": {"dt": []}}, ["grid.dt", "non-empty list"]),
        (
            {"random": {"samples": 2, "dt": {"loguniform": [0.0, 1e-3]}}},
            ["random.dt.loguniform", "lo > 0"],
        ),
        (
            {"random": {"samples": 2, "dt": {"uniform": [1e-4, 2.0]}}},
            ["random.dt.uniform[1]", "[1e-07, 1] s"],
        ),
        (
            {"random": {"samples": 2, "dt": {"normal": [0, 1]}}},
            ["random.dt", "uniform", "loguniform", "choice"],
        ),
        ({"random": {"samples": 0, "dt": {"uniform": [1e-4, 1e-3]}}}, ["random.samples", ">= 1"]),
        (
            {"random": {"samples": 2, "rows": {"uniform": [4, 8]}}},
            ["random.rows.uniform", "choice"],
        ),
        (
            {"random": {"samples": 2, "gravity": {"uniform": [0, 1]}}},
            ["random.gravity.uniform", "choice"],
        ),
        (
            {"grid": {"stifness.structural": [1.0]}},
            ["stifness.structural", "not a parameter", "stiffness.structural"],
        ),
        ({"grid": {"gx": [1.0]}}, ["grid.gx", "not a parameter", "$gx"]),
        ({"duration": -1}, ["duration", "(0, 1e+06] s"]),
        ({"frames": "many"}, ["frames", "finite number"]),
        ({"scene": "no_such_scene"}, ["scene", "no_such_scene"]),
        ({"colour": "red"}, ["colour", "unknown key", "grid"]),
        ({"set": {"dt": "fast"}}, ["set.dt", "fast"]),
        (
            {"script": [{"at": 0.1, "grasp": {"point": [0, 0]}}]},
            ["script[0].grasp.point", "[x, y, z]"],
        ),
        (
            {"script": [{"at": 0.1, "grasp": {"point": ["$gx", 0, 0]}}]},
            ["script[0].grasp.point[0]", "$gx"],
        ),
        ({"script": [{"at": 0.1, "fly": {}}]}, ["script[0]", "grasp, move, release"]),
        (
            {"script": [{"at": 0.0, "move": {"collider": "moon", "to": [0, 0, 0]}}]},
            ["script[0].move.collider", "moon", "not a collider"],
        ),
        (
            {
                "script": [
                    {"at": 0.0, "move": {"gripper": "g", "collider": "ball", "to": [0, 0, 0]}}
                ]
            },
            ["script[0].move", "exactly one of gripper or collider"],
        ),
    ],
)
def test_a_bad_spec_is_refused_naming_the_key(change, words):
    data = {**SPEC, **change}
    with pytest.raises(SpecError) as e:
        spec_from_dict(data, source="spec.yaml")
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_a_bad_spec_runs_nothing_and_exits_2(tmp_path, capsys):
    spec = write_spec(tmp_path / "bad.yaml", {**SPEC, "grid": {"dt": [2.0]}})
    assert cli_main(["sweep", str(spec), "-o", str(tmp_path / "out")]) == 2
    assert "grid.dt[0]" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_grid_times_random_gives_the_runs_each_once_and_draws_in_range():
    spec = spec_from_dict(
        {
            **SPEC,
            "grid": {"integrator": ["rk4", "verlet"], "dt": [1e-4, 2e-4, 5e-4]},
            "random": {
                "samples": 5,
                "stiffness.structural": {"loguniform": [10.0, 1000.0]},
                "wind.strength": {"uniform": [0.0, 2.0]},
                "model": {"choice": ["provot", "choi_ko"]},
            },
        }
    )
    runs = list(spec.runs())
    assert len(spec) == len(runs) == 2 * 3 * 5
    assert len({run_id(r) for r in runs}) == 30
    # every grid point 5 times, in the spec's order (the last key fastest)
    points = [(r["integrator"], r["dt"]) for r in runs]
    assert (
        points[:5] == [("rk4", 1e-4)] * 5
        and points[5] == ("rk4", 2e-4)
        and points[-1] == ("verlet", 5e-4)
    )
    k = np.array([r["stiffness.structural"] for r in runs])
    assert np.all((k >= 10.0) & (k <= 1000.0))
    assert all(0.0 <= r["wind.strength"] <= 2.0 for r in runs)
    assert {r["model"] for r in runs} <= {"provot", "choi_ko"}
    # the draws are a function of the seed and the indices alone: the same spec gives the same runs
    assert runs == list(spec.runs())
    other = spec_from_dict(
        {
            **SPEC,
            "seed": 4,
            "grid": spec.grid,
            "random": {
                "samples": 5,
                "stiffness.structural": {"loguniform": [10.0, 1000.0]},
                "wind.strength": {"uniform": [0.0, 2.0]},
                "model": {"choice": ["provot", "choi_ko"]},
            },
        }
    )
    assert [r["stiffness.structural"] for r in other.runs()] != list(k)


# ------------------------------------------------------------------------- runs (no Ray)
def test_a_diverging_run_is_a_row_and_an_unstable_dt_without_allow_unstable_is_refused(tmp_path):
    spec = spec_from_dict(
        {
            **SPEC,
            "random": {},
            "grid": {"dt": [1e-3, 0.02], "allow_unstable": [False, True]},
            "set": {
                "rows": 10,
                "cols": 10,
                "spacing": 0.11,
                "integrator": "symplectic_euler",
                "strain_limit": 0.0,
            },
        }
    )  # (Provot's correction would hold it)
    rows = {(r["dt"], r["allow_unstable"]): execute(spec, r, tmp_path) for r in spec.runs()}
    assert rows[(1e-3, False)]["status"] == rows[(1e-3, True)]["status"] == "ok"
    refused = rows[(0.02, False)]
    assert refused["status"] == "refused" and "above the stable limit" in refused["message"]
    assert refused["steps"] == 0
    diverged = rows[(0.02, True)]
    assert diverged["status"] == "diverged" and diverged["message"]
    assert 0 < diverged["steps"] < 15 and diverged["dt"] / diverged["stable_dt"] > 2
    # the diverged run's bag is closed and holds the frames before the blow-up
    info = bag_info(tmp_path / "runs" / diverged["run"])
    assert info.closed and info.message_count == 2 * diverged["frames"] >= 2
    assert not any((tmp_path / ".partial").iterdir())


def test_a_script_grasps_lifts_and_releases(tmp_path):
    # the hanging cloth starts flat at z = 0 over [0, 0.99]², pinned at its corners (0, 0) and
    # (0.99, 0); grab a free corner (gx, 0.99, 0), carry it to (gx, 0.5, 0.3) over 0.2 s, hold,
    # then release
    spec = spec_from_dict(
        {
            **SPEC,
            "random": {},
            "grid": {"gx": [0.0, 0.99]},
            "duration": 0.5,
            "frames": 20,
            "set": {"rows": 10, "cols": 10, "spacing": 0.11, "integrator": "symplectic_euler"},
            "script": [
                {
                    "at": 0.0,
                    "grasp": {"gripper": "hand", "point": ["$gx", 0.99, 0.0], "radius": 0.02},
                },
                {
                    "at": 0.05,
                    "move": {"gripper": "hand", "to": ["$gx", 0.5, 0.3], "duration": 0.2},
                },
                {"at": 0.4, "release": {"gripper": "hand"}},
            ],
        }
    )
    for run in spec.runs():
        row = execute(spec, run, tmp_path)
        assert row["status"] == "ok", row["message"]
        xyz = [
            np.frombuffer(bytes(m.data), np.float32).reshape(-1, 3)
            for m in decoded(tmp_path / "runs" / row["run"])["/cloth_sim/points"]
        ]
        corner = int(np.argmin(np.linalg.norm(xyz[0] - [run["gx"], 0.99, 0.0], axis=1)))
        # at 0.3 s and 0.35 s (moved, still held) the corner is where the gripper put it
        for frame in (6, 7):
            np.testing.assert_allclose(xyz[frame][corner], [run["gx"], 0.5, 0.3], atol=2e-3)
        assert xyz[-1][corner][2] < 0.3 - 0.01  # released at 0.4 s: it falls
    # a grasp that reaches nothing makes the run refused, naming the event
    far = spec_from_dict(
        {
            **SPEC,
            "random": {},
            "grid": {},
            "set": {"rows": 10, "cols": 10, "spacing": 0.11},
            "script": [{"at": 0.1, "grasp": {"point": [5.0, 5.0, 5.0], "radius": 0.01}}],
        }
    )
    row = execute(far, next(far.runs()), tmp_path)
    assert row["status"] == "refused" and "script[0].grasp" in row["message"]


def test_camera_frames_are_recorded_with_their_labels(tmp_path):
    spec = spec_from_dict(
        {
            **SPEC,
            "random": {},
            "grid": {},
            "duration": 0.1,
            "set": {
                "rows": 10,
                "cols": 10,
                "spacing": 0.11,
                "camera.enable": True,
                "camera.width": 32,
                "camera.height": 24,
                "camera.position": [0.5, -0.5, 1.5],
                "camera.look_at": [0.5, -0.5, 0.0],
            },
        }
    )
    row = execute(spec, next(spec.runs()), tmp_path)
    assert row["status"] == "ok" and row["frames"] == 2
    by_topic = decoded(tmp_path / "runs" / row["run"])
    assert {k: len(v) for k, v in by_topic.items()} == {
        "/cloth_sim/points": 2,
        "/cloth_sim/stats": 2,
        "/cloth_sim/camera/depth/image": 2,
        "/cloth_sim/camera/depth/camera_info": 2,
        "/cloth_sim/camera/labels": 2,
        "/cloth_sim/camera/triangles": 2,
    }
    image, labels = (
        by_topic["/cloth_sim/camera/depth/image"][1],
        by_topic["/cloth_sim/camera/labels"][1],
    )
    depth = np.frombuffer(bytes(image.data), np.float32).reshape(24, 32)
    lab = np.frombuffer(bytes(labels.data), np.int16).reshape(24, 32)
    assert (lab == 0).sum() > 50 and np.all(np.isfinite(depth[lab == 0]))
    assert (
        image.header.stamp.nanosec == 100_000_000
        and image.header.frame_id == "cloth/camera_optical"
    )


# ---------------------------------------------------------------------------------- on Ray
def test_a_sweep_writes_parquet_and_bags_that_independent_readers_open(reference, capsys):
    spec_path, out = reference
    spec = load_spec(spec_path)
    table = pq.read_table(out / "runs.parquet").to_pylist()
    assert [r["run"] for r in table] == [run_id(r) for r in spec.runs()]
    assert {r["status"] for r in table} == {"ok"}
    for r in table:
        assert r["wall_s"] > 0 and r["steps"] == math.ceil(0.3 / 1e-3 - 1e-9)
        assert (
            math.isfinite(r["max_strain"])
            and math.isfinite(r["kinetic"])
            and math.isfinite(r["potential"])
        )
        assert 300.0 <= r["stiffness.structural"] <= 3000.0 and r["frames"] == 4
    assert sorted(p.name for p in (out / "runs").iterdir()) == sorted(r["run"] for r in table)
    # rosbags decodes every message; the cloud is the 10×10 cloth, stamped with simulated time
    bag = out / "runs" / table[0]["run"]
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
        msgs = [(conn.topic, t, r.deserialize(raw, conn.msgtype)) for conn, t, raw in r.messages()]
    clouds = [m for topic, _, m in msgs if topic == "/cloth_sim/points"]
    assert [(m.height, m.width) for m in clouds] == [(10, 10)] * 4
    assert [t for topic, t, _ in msgs if topic == "/cloth_sim/points"] == [
        0,
        100_000_000,
        200_000_000,
        300_000_000,
    ]
    stats = [m for topic, _, m in msgs if topic == "/cloth_sim/stats"]
    assert [round(s.sim_time, 9) for s in stats] == [0.0, 0.1, 0.2, 0.3]
    assert stats[-1].integrator == table[0]["integrator"]
    # cloth-sim info opens it
    assert cli_main(["info", str(bag)]) == 0
    out_text = capsys.readouterr().out
    assert "/cloth_sim/points" in out_text and "Count: 4" in out_text
    # the summary
    assert cli_main(["sweep", "--summary", str(out)]) == 0
    text = capsys.readouterr().out
    assert "12 runs (complete)" in text and "ok        12" in text and "slowest runs" in text


def test_one_worker_gives_the_same_bytes_as_two(reference, tmp_path):
    spec_path, two = reference
    run_sweep(spec_path, "-o", tmp_path / "one", "--workers", 1)
    assert tree_bytes(tmp_path / "one" / "runs") == tree_bytes(two / "runs")


def test_a_sweep_killed_mid_way_completes_on_rerun_with_every_run_once(reference, tmp_path):
    spec_path, two = reference
    out = tmp_path / "killed"
    proc = sweep_cmd(spec_path, "-o", out, "--workers", 2)
    try:
        end = time.monotonic() + 120
        while time.monotonic() < end and len(list((out / "runs").glob("*"))) < 3:
            time.sleep(0.05)
        assert proc.poll() is None, "the sweep ended before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)  # the driver only, mid-sweep
        proc.wait(timeout=30)
        time.sleep(1.0)
    finally:
        _kill_group(proc)  # then what it left (its local Ray)
    done = list((out / "runs").iterdir())
    assert 3 <= len(done) < 12 and not (out / "runs.parquet").exists()
    assert all((d / "row.json").exists() and bag_info(d).closed for d in done)
    run_sweep(spec_path, "-o", out, "--workers", 2)
    assert tree_bytes(out / "runs") == tree_bytes(two / "runs")
    assert not (out / ".partial").exists()
    rows = pq.read_table(out / "runs.parquet").column("run").to_pylist()
    assert len(rows) == len(set(rows)) == 12


def test_another_spec_into_the_same_output_is_refused(reference, tmp_path, capsys):
    spec_path, two = reference
    other = write_spec(tmp_path / "other.yaml", {**SPEC, "seed": 99})
    before = tree_bytes(two)
    assert cli_main(["sweep", str(other), "-o", str(two)]) == 2
    assert "holds a sweep of another spec" in capsys.readouterr().err
    assert tree_bytes(two) == before


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_two_node_ray_cluster_runs_a_sweep_through_address(reference, tmp_path):
    spec_path, two = reference
    ray = str(BIN / "ray")
    env = dict(os.environ, RAY_AUTH_MODE="disabled")
    port = _free_port()
    common = ["--node-ip-address=127.0.0.1", "--num-cpus=1", "--block", "--disable-usage-stats"]
    nodes = []
    try:
        nodes.append(
            subprocess.Popen(
                [ray, "start", "--head", f"--port={port}", "--include-dashboard=false", *common],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )
        address = f"127.0.0.1:{port}"
        end = time.monotonic() + 60
        while subprocess.run(
            [ray, "status", f"--address={address}"], env=env, capture_output=True
        ).returncode:
            assert time.monotonic() < end, "the head node did not start"
            time.sleep(0.5)
        nodes.append(
            subprocess.Popen(
                [ray, "start", f"--address={address}", *common],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )
        while (
            subprocess.run(
                [ray, "status", f"--address={address}"], env=env, capture_output=True, text=True
            ).stdout.count("node_")
            < 2
        ):
            assert time.monotonic() < end, "the second node did not join"
            time.sleep(0.5)
        run_sweep(spec_path, "-o", tmp_path / "cluster", "--address", address)
    finally:
        for n in nodes:
            _kill_group(n)
    assert tree_bytes(tmp_path / "cluster" / "runs") == tree_bytes(two / "runs")
    workers = {
        json.loads(p.read_text())["worker"] for p in (tmp_path / "cluster" / "timings").iterdir()
    }
    assert len(workers) >= 2  # both nodes ran runs


def test_a_cluster_that_ray_start_made_with_a_token_is_joined_by_address(reference, tmp_path):
    """Ray 2.60 starts a head node with token authentication where a token exists (a local
    ``ray.init()`` writes one to ~/.ray/auth_token). A sweep joins it by --address with nothing set
    (the token from ~/.ray/auth_token, as Ray's documentation asks), and a driver with no token
    is refused with one line saying what to set. The head stays on loopback (Ray's single-machine
    mode)."""
    spec_path, two = reference
    ray = str(BIN / "ray")
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    # (Ray's socket paths must stay short: its temporary directory is not under pytest's tmp_path)
    env.update(
        HOME=str(home),
        RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER="0",
        RAY_TMPDIR=tempfile.mkdtemp(prefix="ray", dir="/tmp"),
    )
    subprocess.run([ray, "get-auth-token", "--generate"], env=env, check=True, capture_output=True)
    port = _free_port()
    head = subprocess.Popen(
        [
            ray,
            "start",
            "--head",
            f"--port={port}",
            "--include-dashboard=false",
            "--num-cpus=2",
            "--block",
            "--disable-usage-stats",
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    address = f"127.0.0.1:{port}"
    try:
        end = time.monotonic() + 60
        while subprocess.run(
            [ray, "status", f"--address={address}"],
            env=dict(env, RAY_AUTH_MODE="token"),
            capture_output=True,
        ).returncode:
            assert time.monotonic() < end, "the head node did not start"
            time.sleep(0.5)
        proc = sweep_cmd(spec_path, "-o", tmp_path / "joined", "--address", address, env=env)
        out, err = proc.communicate(timeout=240)
        assert proc.returncode == 0, err[-3000:]
        assert "with token authentication" in err and str(home / ".ray" / "auth_token") in err
        assert tree_bytes(tmp_path / "joined" / "runs") == tree_bytes(two / "runs")
        # no token here: refused, saying where a token goes (Ray's 20 connection tries cut to 2)
        stranger = dict(env, HOME=str(tmp_path), RAY_gcs_server_port_wait_time_s="2")
        proc = sweep_cmd(spec_path, "-o", tmp_path / "refused", "--address", address, env=stranger)
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 2
        last = err.strip().splitlines()[-1]
        assert last.startswith("cloth-sim: error: --address") and "refused" in last
        assert "~/.ray/auth_token" in last and "RAY_AUTH_TOKEN" in last
    finally:
        _kill_group(head)
        shutil.rmtree(env["RAY_TMPDIR"], ignore_errors=True)


def test_the_bags_cdr_is_what_rclpy_reads_and_what_rosbags_writes():
    """cloth_sim.bag.cdr against two references: rclpy's deserialiser gives back the message the
    node's own builders make, and rosbags' serialiser (padding zero, like ours) gives the same
    bytes."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2

    from cloth_sim.bag import cdr
    from cloth_sim.msg import Stats
    from cloth_sim.ros import messages
    from cloth_sim.sensors.camera import DepthCamera
    from cloth_sim.tick_stats import TickStats

    store = get_typestore(Stores.ROS2_JAZZY)
    stamp, ns = Time(sec=3, nanosec=7), 3_000_000_007
    rng = np.random.default_rng(0)
    pts = rng.random((4, 5, 3))
    pts[1, 2] = np.nan
    data = cdr.point_cloud(pts, 4, 5, "cloth", ns)
    assert deserialize_message(data, PointCloud2) == messages.point_cloud(
        pts.reshape(-1, 3), 4, 5, "cloth", stamp
    )
    assert (
        store.serialize_cdr(
            store.deserialize_cdr(data, "sensor_msgs/msg/PointCloud2"),
            "sensor_msgs/msg/PointCloud2",
        )
        == data
    )
    for a, enc in (
        (rng.random((6, 7)).astype(np.float32), "32FC1"),
        (rng.integers(-1, 3, (6, 7)).astype(np.int16), "16SC1"),
        (rng.integers(-1, 99, (6, 7)).astype(np.int32), "32SC1"),
    ):
        data = cdr.image(a, enc, "o", ns)
        assert deserialize_message(data, Image) == messages.image(a, enc, "o", stamp)
        assert (
            store.serialize_cdr(
                store.deserialize_cdr(data, "sensor_msgs/msg/Image"), "sensor_msgs/msg/Image"
            )
            == data
        )
    cam = DepthCamera(width=64, height=48, fx=50.0, fy=51.0, cx=31.5, cy=23.5)
    data = cdr.camera_info(cam, "o", ns)
    assert deserialize_message(data, CameraInfo) == messages.camera_info(cam, "o", stamp)
    assert (
        store.serialize_cdr(
            store.deserialize_cdr(data, "sensor_msgs/msg/CameraInfo"), "sensor_msgs/msg/CameraInfo"
        )
        == data
    )
    tick = TickStats(
        integrator="rk4",
        dt=0.001,
        steps=3,
        step_time_mean=0.1,
        step_time_max=0.2,
        tick_wall_time=0.5,
        real_time_factor=1.0,
        sim_time=2.0,
        kinetic_energy=1.0,
        potential_energy=5.0,
        max_strain=0.1,
        overruns=4,
        stability_margin=0.5,
        paused=True,
        solver_iterations=7,
        solver_residual=2.5e-4,
        solver_converged=False,
    )
    data = cdr.stats(ns, "cloth", tick)
    # what rclpy reads is the message the node would publish (rclpy's own bytes differ only in
    # the alignment padding, which it leaves unset)
    assert deserialize_message(data, Stats) == messages.stats(Stats, stamp, "cloth", tick)
    msg = deserialize_message(data, Stats)
    assert (
        msg.header.stamp,
        msg.integrator,
        msg.steps,
        msg.step_time_mean,
        msg.potential_energy,
        msg.overruns,
        msg.stability_margin,
        msg.paused,
        msg.solver_iterations,
        msg.solver_residual,
        msg.solver_converged,
    ) == (stamp, "rk4", 3, 0.1, 5.0, 4, 0.5, True, 7, 2.5e-4, False)
