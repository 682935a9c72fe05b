"""cloth_sim_node over DDS: in-process (node and test node on one executor) and as a subprocess.

Every test runs on its own ROS_DOMAIN_ID with discovery limited to localhost.
"""

import ast
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="ROS 2 wheels are installed by `make`")
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from rcl_interfaces.msg import Parameter as ParameterMsg  # noqa: E402
from rcl_interfaces.srv import (  # noqa: E402
    DescribeParameters,
    GetParameters,
    ListParameters,
    SetParameters,
)
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from ros_helpers import end_node, next_domain, node_env, start_node  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402
from std_srvs.srv import SetBool, Trigger  # noqa: E402
from visualization_msgs.msg import Marker  # noqa: E402

from cloth_sim.msg import Stats  # noqa: E402
from cloth_sim.parameters import SCHEMA  # noqa: E402
from cloth_sim.scene import load_scene  # noqa: E402
from cloth_sim.tick_stats import TickStats, stability_margin  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def cloud_xyz(msg: PointCloud2) -> np.ndarray:
    return np.frombuffer(bytes(msg.data), dtype=np.float32).reshape(msg.height, msg.width, 3)


# ------------------------------------------------------------------ topics
def test_points_stats_mesh_and_diagnostics(ros):
    ros.start(publish_rate=30.0)
    clouds = ros.collect(PointCloud2, "/cloth_sim/points")
    stats = ros.collect(Stats, "/cloth_sim/stats")
    meshes = ros.collect(Marker, "/cloth_sim/mesh")
    diags = ros.collect(DiagnosticArray, "/diagnostics")
    assert ros.spin_until(lambda: len(clouds) >= 10 and len(diags) >= 2 and meshes, 15)
    c = clouds[-1]
    assert (c.height, c.width, c.point_step, c.row_step) == (12, 12, 12, 144)
    assert [(f.name, f.offset, f.datatype, f.count) for f in c.fields] == [
        ("x", 0, 7, 1),
        ("y", 4, 7, 1),
        ("z", 8, 7, 1),
    ]
    assert c.is_dense and c.header.frame_id == "cloth"
    xyz = cloud_xyz(c)
    assert np.all(np.isfinite(xyz))
    # organised: row 0, col 0 and col -1 are the pins of the hanging scene, at their rest places
    np.testing.assert_allclose(xyz[0, 0], [0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(xyz[0, -1], [1.0, 0, 0], atol=1e-6)
    assert xyz[:, :, 2].min() < -0.05  # the cloth falls
    m = meshes[-1]
    assert m.type == Marker.TRIANGLE_LIST and len(m.points) == 3 * 2 * 11 * 11
    s = stats[-1]
    assert s.integrator == "symplectic_euler" and s.dt == pytest.approx(1e-3)
    assert s.steps in (33, 34)  # 1/30 s in whole 1 ms steps, the remainder carried
    assert sum(x.steps for x in stats[-30:]) == pytest.approx(1000 * 30 / 30, abs=2)
    assert 0 < s.step_time_mean <= s.step_time_max < s.tick_wall_time < 1 / 30
    assert 0.5 < s.real_time_factor < 1.5 and s.sim_time > 0.1
    assert s.kinetic_energy > 0 and s.potential_energy < 0 and 0 < s.max_strain < 0.2
    assert 0 < s.stability_margin < 0.8 and not s.paused
    status = diags[-1].status[0]
    assert status.name == "cloth_sim: simulation" and status.hardware_id == "cloth_sim"
    # OK once running steadily (a loaded machine may show a short real-time-factor WARN first)
    assert status.level == DiagnosticStatus.OK or ros.spin_until(
        lambda: diags[-1].status[0].level == DiagnosticStatus.OK, 10
    ), diags[-1].status[0].message
    keys = {kv.key: kv.value for kv in status.values}
    assert {"integrator", "dt", "stable_dt", "real_time_factor", "max_strain", "overruns"} <= set(
        keys
    )
    assert float(keys["stable_dt"]) > 1e-3


def test_the_cloud_is_not_built_without_subscribers(ros, monkeypatch):
    node = ros.start()
    built = []
    original = node.publishing.point_cloud
    monkeypatch.setattr(
        node.publishing, "point_cloud", lambda stamp: built.append(1) or original(stamp)
    )
    stats = ros.collect(Stats, "/cloth_sim/stats")
    assert ros.spin_until(lambda: len(stats) >= 10)
    assert not built
    clouds = ros.collect(PointCloud2, "/cloth_sim/points")
    assert ros.spin_until(lambda: len(clouds) >= 3)
    assert built


def test_use_sim_time_is_honoured(ros):
    from rosgraph_msgs.msg import Clock

    ros.start(use_sim_time=True)
    stats = ros.collect(Stats, "/cloth_sim/stats")
    clock = ros.node.create_publisher(Clock, "/clock", 10)
    t = [123.0]

    def tick():
        t[0] += 0.01
        clock.publish(Clock(clock=rclpy.time.Time(seconds=t[0]).to_msg()))

    ros.node.create_timer(0.01, tick)
    assert ros.spin_until(lambda: len(stats) >= 3)
    # the timer runs on /clock and the stamps come from it
    assert 123 <= stats[-1].header.stamp.sec <= t[0]


# ------------------------------------------------------------------ parameters
def test_parameters_are_described(ros):
    ros.start()
    res = ros.call(
        DescribeParameters,
        "/cloth_sim/describe_parameters",
        DescribeParameters.Request(names=["dt", "stiffness.bend", "integrator", "rows"]),
    )
    dt, bend, integ, rows = res.descriptors
    assert "time step" in dt.description and dt.floating_point_range[0].from_value > 0
    assert bend.floating_point_range[0].from_value == 0.0
    assert "rk4" in integ.additional_constraints and "kang" in integ.additional_constraints
    assert rows.integer_range[0].from_value == 2


def test_a_softer_cloth_sags_more(ros):
    a = ros.start(namespace="a", strain_limit=0.0)
    b = ros.start(namespace="b", strain_limit=0.0)
    results = ros.set_params(
        "/b/cloth_sim", {"stiffness.structural": 100.0, "stiffness.shear": 100.0}
    )
    assert all(r.successful for r in results)
    assert b.sim.stiffness("structural")[0] == 100.0
    low_a, low_b = [], []

    def sample():
        low_a.append(a.sim.positions[:, 2].min())
        low_b.append(b.sim.positions[:, 2].min())
        return a.sim.time > 2.0 and b.sim.time > 2.0

    ros.spin_until(sample, 20)
    # averaged over the swing: the softer cloth hangs lower
    assert np.mean(low_b[len(low_b) // 2 :]) < np.mean(low_a[len(low_a) // 2 :]) - 0.05


def test_stats_and_diagnostics_say_whether_the_solver_converged(ros):
    """vbd capped at one iteration of one step a frame on a stiff step (the scene names no work,
    so vbd would choose it): ~/stats says solver_converged false with the relative residual above
    the tolerance, and /diagnostics' status warns that steps end unconverged; given room (and a
    live change of its iterations), the steps converge, the flag turns true with the residual at
    or below the tolerance, and the warning goes."""
    node = ros.start(integrator="vbd", dt=1 / 60, publish_rate=30.0)
    node.publishing.diagnostic_status()  # the report's window starts here
    capped = {"vbd.iterations": 1, "vbd.substeps": 1, "vbd.tolerance": 1e-4}
    assert ros.set_params("/cloth_sim", capped)[0].successful
    stats = ros.collect(Stats, "/cloth_sim/stats")
    assert ros.spin_until(lambda: len(stats) >= 3 and stats[-1].steps > 0)
    low = stats[-1]
    assert low.solver_iterations == 1 and not low.solver_converged
    assert low.solver_residual > 1e-4
    status = node.publishing.diagnostic_status()
    assert status.level == DiagnosticStatus.WARN and "unconverged" in status.message
    assert ros.set_params("/cloth_sim", {"vbd.iterations": 3000})[0].successful
    n = len(stats)
    assert ros.spin_until(lambda: len(stats) >= n + 3 and stats[-1].solver_converged, 20)
    assert stats[-1].solver_residual <= 1e-4 and stats[-1].solver_iterations < 3000
    node.publishing.diagnostic_status()  # the unconverged steps before the change
    assert ros.spin_until(lambda: len(stats) >= n + 6)
    assert "unconverged" not in node.publishing.diagnostic_status().message


def test_an_integrator_switch_keeps_the_state(ros):
    node = ros.start()
    ros.spin_until(lambda: node.sim.time > 0.5)
    assert ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=True)).success
    x, v = node.sim.positions.copy(), node.sim.velocities.copy()
    for name in ("rk4", "implicit_euler", "verlet"):
        assert ros.set_params("/cloth_sim", {"integrator": name})[0].successful
        assert node.sim.integrator == name
        np.testing.assert_array_equal(node.sim.positions, x)
        np.testing.assert_array_equal(node.sim.velocities, v)
    ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=False))
    t0 = node.sim.time
    ros.spin_until(lambda: node.sim.time > t0 + 0.03)
    # continuous: after the switch no particle moved further than its speed allows
    elapsed = node.sim.time - t0
    bound = (np.linalg.norm(v, axis=1).max() + 9.81 * elapsed) * elapsed * 1.5
    assert np.max(np.linalg.norm(node.sim.positions - x, axis=1)) < bound


INVALID = [
    ({"integrator": "rk5"}, "integrator 'rk5' is unknown; accepted values: explicit_euler"),
    ({"dt": -0.001}, "dt"),
    ({"dt": 0.01}, "above the stable limit of symplectic_euler"),
    ({"dt": float("nan")}, "dt"),
    ({"stiffness.shear": -5.0}, "stiffness.shear"),
    ({"damping.bend": -1.0}, "damping.bend"),
    ({"stiffness.structural": float("inf")}, "stiffness.structural"),
    ({"gravity": [0.0, -9.81]}, "gravity must have exactly 3 elements"),
    ({"wind.direction": [1.0, 0.0, 0.0, 0.0]}, "wind.direction must have exactly 3 elements"),
    ({"publish_rate": 5000.0}, "publish_rate"),
    ({"model": "cloth"}, "model 'cloth' is unknown"),
    ({"scene": "nowhere"}, "scene"),
]


@pytest.mark.parametrize(
    "change,reason", INVALID, ids=[next(iter(c)) + str(i) for i, (c, _) in enumerate(INVALID)]
)
def test_invalid_values_are_refused_with_a_reason(ros, change, reason):
    node = ros.start()
    stats = ros.collect(Stats, "/cloth_sim/stats")
    ros.spin_until(lambda: len(stats) >= 3)
    before = dict(node.cfg)
    result = ros.set_params("/cloth_sim", change)[0]
    assert not result.successful
    assert reason in result.reason, result.reason
    assert node.cfg == before
    name = next(iter(change))
    assert node.get_parameter(name).value == before[name] or (
        isinstance(before[name], list) and list(node.get_parameter(name).value) == before[name]
    )
    n = len(stats)
    assert ros.spin_until(lambda: len(stats) >= n + 3)  # still publishing


def test_a_publish_rate_that_cannot_be_met_is_refused(ros):
    node = ros.start()
    ros.spin_until(lambda: len(node.session.tick_costs) >= 20)
    result = ros.set_params("/cloth_sim", {"dt": 1e-7, "publish_rate": 30.0}, atomically=True)[0]
    assert not result.successful and "publish_rate=30 Hz cannot be met" in result.reason
    assert node.sim.dt == 1e-3


def test_a_batch_is_applied_all_or_nothing(ros):
    node = ros.start()
    result = ros.set_params(
        "/cloth_sim", {"stiffness.bend": 10.0, "integrator": "rk5"}, atomically=True
    )[0]
    assert not result.successful and "rk5" in result.reason
    assert node.sim.stiffness("bend")[0] == 100.0 and node.cfg["stiffness.bend"] == 100.0
    result = ros.set_params(
        "/cloth_sim", {"stiffness.bend": 10.0, "integrator": "rk4", "dt": 5e-4}, atomically=True
    )[0]
    assert result.successful, result.reason
    assert (node.sim.stiffness("bend")[0], node.sim.integrator, node.sim.dt) == (10.0, "rk4", 5e-4)


def test_topology_changes_rebuild_and_reset(ros):
    node = ros.start()
    clouds = ros.collect(PointCloud2, "/cloth_sim/points")
    ros.spin_until(lambda: node.sim.time > 0.3)
    assert ros.set_params("/cloth_sim", {"rows": 8, "cols": 10}, atomically=True)[0].successful
    assert node.sim.model.n_particles == 80 and node.sim.time < 0.1
    assert ros.spin_until(lambda: clouds and (clouds[-1].height, clouds[-1].width) == (8, 10))
    assert ros.set_params("/cloth_sim", {"scene": "flag"})[0].successful
    assert node.scene.name == "flag" and node.sim.wind is not None
    ros.spin_for(0.3)  # the scene's own values are then reported through the parameters
    assert node.get_parameter("wind.strength").value == load_scene("flag").wind_strength
    assert node.get_parameter("rows").value == 20


def test_reset_and_pause(ros):
    node = ros.start()
    stats = ros.collect(Stats, "/cloth_sim/stats")
    ros.spin_until(lambda: node.sim.time > 0.5)
    assert ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=True)).message == "paused"
    t = node.sim.time
    n = len(stats)
    ros.spin_until(lambda: len(stats) >= n + 5)
    assert node.sim.time == t and stats[-1].paused and stats[-1].steps == 0
    res = ros.call(Trigger, "/cloth_sim/reset", Trigger.Request())
    assert res.success and node.sim.time < 0.1
    np.testing.assert_array_equal(node.sim.positions, node.sim.model.positions)
    n = len(stats)
    ros.spin_until(lambda: len(stats) >= n + 5)
    assert not stats[-1].paused and stats[-1].sim_time > 0


def test_a_blow_up_never_reaches_a_topic_and_the_node_recovers(ros):
    node = ros.start()
    clouds = ros.collect(PointCloud2, "/cloth_sim/points")
    diags = ros.collect(DiagnosticArray, "/diagnostics")
    ros.spin_until(lambda: node.sim.time > 0.2)
    assert ros.set_params(
        "/cloth_sim", {"allow_unstable": True, "dt": 0.02, "strain_limit": 0.0}, atomically=True
    )[0].successful
    assert ros.spin_until(lambda: node.error is not None, 10)
    assert node.paused
    assert ros.spin_until(
        lambda: any(d.status[0].level == DiagnosticStatus.ERROR for d in diags), 5
    )
    err = [d for d in diags if d.status[0].level == DiagnosticStatus.ERROR][-1].status[0]
    assert "diverged" in err.message
    n = len(clouds)
    ros.spin_until(lambda: len(clouds) >= n + 3)
    assert all(np.all(np.isfinite(cloud_xyz(c))) for c in clouds)
    # still serving parameters and services: fix dt, un-pause, run again
    assert ros.set_params("/cloth_sim", {"dt": 1e-3, "allow_unstable": False}, atomically=True)[
        0
    ].successful
    ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=False))
    t = node.sim.time
    assert ros.spin_until(lambda: node.sim.time > t + 0.2)
    assert node.error is None
    diags.clear()
    assert (
        ros.spin_until(lambda: len(diags) >= 1, 3)
        and diags[-1].status[0].level != DiagnosticStatus.ERROR
    )


def test_diagnostics_warn_when_dt_is_close_to_the_limit(ros):
    node = ros.start()
    limit = node.session.stable_dt
    assert ros.set_params("/cloth_sim", {"dt": 0.9 * limit})[0].successful
    diags = ros.collect(DiagnosticArray, "/diagnostics")
    assert ros.spin_until(lambda: len(diags) >= 2, 5)
    st = diags[-1].status[0]
    assert st.level == DiagnosticStatus.WARN and "stable_dt" in st.message


# ------------------------------------------------------------------ as a process


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_node_process_publishes_at_the_rate_and_exits_cleanly(sig):
    domain = next_domain()
    exe = Path(sys.executable).parent / "cloth_sim_node"
    proc = subprocess.Popen(
        [
            str(exe),
            "--ros-args",
            "--params-file",
            str(ROOT / "config" / "cloth_sim.yaml"),
            "-p",
            "rows:=16",
            "-p",
            "cols:=16",
            "-p",
            "spacing:=0.0667",
            "-p",
            "publish_rate:=20.0",
        ],
        env=node_env(domain),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("rate_probe", context=ctx)
    stamps = []
    node.create_subscription(
        PointCloud2, "/cloth_sim/points", lambda m: stamps.append(time.monotonic()), 50
    )
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        end = time.monotonic() + 30
        while time.monotonic() < end and len(stamps) < 70:
            ex.spin_once(timeout_sec=0.05)
        assert len(stamps) >= 70, "no cloud from the node process"
        rate = (len(stamps[10:]) - 1) / (stamps[-1] - stamps[10])
        assert rate == pytest.approx(20.0, rel=0.10)
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        proc.send_signal(sig)
        out, _ = proc.communicate(timeout=20)
    assert proc.returncode == 0, out
    assert "Traceback" not in out


def test_node_refuses_a_malformed_scene_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("grid: {rows: 3, cols: -4, spacing: 0.1}\n")
    exe = Path(sys.executable).parent / "cloth_sim_node"
    out = subprocess.run(
        [str(exe), "--ros-args", "-p", f"scene:={bad}"],
        env=node_env(next_domain()),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert "bad.yaml" in out.stderr and "cols" in out.stderr and "Traceback" not in out.stderr


def test_launch_file_is_minimal_and_points_at_existing_files():
    path = ROOT / "launch" / "cloth_sim.launch.py"
    tree = ast.parse(path.read_text())
    mods = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            mods |= {a.name.split(".")[0] for a in n.names}
        elif isinstance(n, ast.ImportFrom):
            mods.add(n.module.split(".")[0])
    assert mods <= {"os", "launch", "launch_ros", "ament_index_python"}
    text = path.read_text()
    assert '"cloth_sim.yaml"' in text and (ROOT / "config" / "cloth_sim.yaml").is_file()
    assert 'executable="cloth_sim_node"' in text and "generate_launch_description" in text
    cmake = (ROOT / "CMakeLists.txt").read_text()
    assert "install(DIRECTORY config launch" in cmake and "scripts/cloth_sim_node" in cmake


# ------------------------------------------------------------------ the core split's defects
def test_kang_above_its_limit_is_refused_like_any_conditionally_stable_method(ros):
    """kang is not unconditionally stable: a 12×12 node once accepted it at dt = 1/60 s, reported
    stable_dt = inf and margin 0, and diverged."""
    node = ros.start()
    stats = ros.collect(Stats, "/cloth_sim/stats")
    result = ros.set_params("/cloth_sim", {"integrator": "kang", "dt": 1 / 60}, atomically=True)[0]
    assert not result.successful and "above the stable limit of kang" in result.reason
    assert node.sim.integrator == "symplectic_euler"
    limit = float(result.reason.split("stable_dt=")[1].split(" ")[0])
    assert 1e-4 < limit < 1 / 60
    assert ros.set_params("/cloth_sim", {"integrator": "kang"})[0].successful  # dt = 1 ms is below
    assert node.session.stable_dt == pytest.approx(limit, rel=1e-3)
    assert ros.spin_until(lambda: stats and stats[-1].integrator == "kang")
    assert stats[-1].stability_margin == pytest.approx(1e-3 / node.session.stable_dt, rel=1e-6)
    assert not ros.set_params("/cloth_sim", {"dt": 1 / 60})[0].successful


def test_a_scene_change_with_other_values_in_one_request(ros):
    """What `ros2 param load` sends: scene and other parameters together (once an InvalidHandle
    crash). The scene's values come in through the pre-set callback; the request's own win."""
    node = ros.start()
    stats = ros.collect(Stats, "/cloth_sim/stats")
    result = ros.set_params(
        "/cloth_sim", {"scene": "flag", "integrator": "rk4", "dt": 5e-4}, atomically=True
    )[0]
    assert result.successful, result.reason
    assert node.scene.name == "flag" and node.sim.integrator == "rk4" and node.sim.dt == 5e-4
    assert (
        node.get_parameter("rows").value == 20 and node.get_parameter("integrator").value == "rk4"
    )
    assert node.get_parameter("wind.strength").value == load_scene("flag").wind_strength
    assert node.sim.model.n_particles == 20 * 32
    n = len(stats)
    assert ros.spin_until(lambda: len(stats) >= n + 5)
    results = ros.set_params("/cloth_sim", {"scene": "hanging", "rows": 10, "cols": 10})
    assert all(r.successful for r in results)
    assert node.sim.model.n_particles == 100 and node.scene.name == "hanging"


def test_the_default_scene_is_cotton_and_moving_between_fabric_and_springs_is_no_spring_change(
    ros,
):
    """`make run`'s scene, hanging, is 1 m of the library's cotton: the fabric sets its masses and
    springs, so a spring parameter is refused naming the material. Moving to the per-family sheet
    and back changes no spring by itself (it once refused the move: the springs the scene brought
    counted as changed by the request); a spring value sent with the move still does."""
    node = ros.start(scene="hanging", spacing=1.0 / 11)
    assert node.get_parameter("material").value == "cotton"
    assert node.sim.model.masses.sum() == pytest.approx(0.276)
    (result,) = ros.set_params("/cloth_sim", {"stiffness.structural": 500.0})
    assert not result.successful and "set by the cloth's material (cotton)" in result.reason
    assert all(r.successful for r in ros.set_params("/cloth_sim", {"scene": "hanging_provot"}))
    assert node.sim.stiffness("structural")[0] == 1000.0
    assert ros.set_params("/cloth_sim", {"stiffness.structural": 500.0})[0].successful
    assert all(r.successful for r in ros.set_params("/cloth_sim", {"scene": "hanging"}))
    assert node.sim.model.meta["material"] is not None and node.scene.name == "hanging"
    (result,) = ros.set_params(
        "/cloth_sim", {"scene": "flag", "stiffness.structural": 5.0}, atomically=True
    )
    assert not result.successful and "stiffness.structural" in result.reason
    assert node.scene.name == "hanging"


def _stats_gaps(ros, stats, during):
    """Largest interval between consecutive ~/stats stamps around ``during()``, in ticks."""
    n = len(stats)
    during()
    assert ros.spin_until(lambda: len(stats) >= n + 10)
    stamps = [s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in stats[max(n - 3, 0) :]]
    return np.max(np.diff(stamps))


def test_loading_a_parameter_file_keeps_the_stats_flowing(ros):
    """`ros2 param load` sets one parameter at a time, inside one service call. Each set used to
    recompute stable_dt on the thread that ticks: loading the node's own dump stopped ~/stats for
    3–10 s. Now a set that changes nothing costs nothing, and a material change one analysis (tens
    of ms at 32×32, kept per material)."""
    rate = 30.0
    # the bound: 6 ticks (0.2 s). The stall this guards against was 3–10 s; a loaded 2-core CI
    # machine (the other test process stepping a garment on both cores) delays a healthy tick by
    # up to ~0.05 s (gaps of 0.115 and 0.124 s seen against the 3 ticks this once allowed)
    bound = 6
    node = ros.start(rows=16, cols=16, spacing=1 / 15, publish_rate=rate)
    stats = ros.collect(Stats, "/cloth_sim/stats")
    assert ros.spin_until(lambda: len(stats) >= 10)
    names = ros.call(
        ListParameters, "/cloth_sim/list_parameters", ListParameters.Request()
    ).result.names
    assert len(names) == len(SCHEMA) + 2  # what `ros2 param dump` writes (+ rclpy's two)
    values = ros.call(
        GetParameters, "/cloth_sim/get_parameters", GetParameters.Request(names=names)
    ).values
    dump = [
        Parameter.from_parameter_msg(ParameterMsg(name=n, value=v)) for n, v in zip(names, values)
    ]

    def load(params):
        req = SetParameters.Request(parameters=[p.to_parameter_msg() for p in params])
        results = ros.call(SetParameters, "/cloth_sim/set_parameters", req).results
        return [r for p, r in zip(params, results) if not r.successful and p.name in SCHEMA]

    period = 1.0 / rate
    gap = _stats_gaps(ros, stats, lambda: load(dump) == [] or pytest.fail("dump refused"))
    assert gap <= bound * period, f"~/stats stopped for {gap:.3f} s"
    changed = [
        Parameter(
            p.name,
            value=(p.value * 1.1 if p.name.startswith(("stiffness", "damping")) else p.value),
        )
        for p in dump
    ]
    changed += [Parameter("drag", value=0.001), Parameter("gravity", value=[0.0, 0.5, -9.81])]
    gap = _stats_gaps(ros, stats, lambda: load(changed) == [] or pytest.fail("file refused"))
    assert gap <= bound * period, f"~/stats stopped for {gap:.3f} s"
    assert node.sim.stiffness("bend")[0] == pytest.approx(110.0) and node.sim.drag == 0.001


def test_messages_are_built_by_pure_functions():
    from rclpy.time import Time

    from cloth_sim.ros import messages

    stamp = Time(seconds=12, nanoseconds=5).to_msg()
    x = np.arange(2 * 3 * 3, dtype=np.float64).reshape(6, 3) / 7
    cloud = messages.point_cloud(x, 2, 3, "base", stamp)
    assert (cloud.height, cloud.width, cloud.row_step, cloud.is_dense) == (2, 3, 36, True)
    np.testing.assert_array_equal(cloud_xyz(cloud).reshape(-1, 3), x.astype(np.float32))
    assert cloud.header.frame_id == "base" and cloud.header.stamp.sec == 12
    tris = np.array([[0, 1, 4], [0, 4, 3]])
    marker = messages.mesh(x, tris, "base", stamp)
    assert len(marker.points) == 6 and marker.points[2].x == pytest.approx(x[4, 0])
    # what the node publishes: the same marker, serialised without a Python object per point
    from rclpy.serialization import deserialize_message, serialize_message

    # (and by the node's MeshBytes, whose buffer is reused across calls and sizes)
    kept = messages.MeshBytes()
    for pts, frame, t in (
        (x, "base", tris),
        (np.random.default_rng(3).normal(size=(6, 3)), "a_longer_frame", tris),
        (np.random.default_rng(4).normal(size=(6, 3)), "base", tris[:1]),
    ):
        slow = deserialize_message(serialize_message(messages.mesh(pts, t, frame, stamp)), Marker)
        assert deserialize_message(messages.mesh_bytes(pts, t, frame, stamp), Marker) == slow
        assert deserialize_message(kept(pts, t, frame, stamp), Marker) == slow
    # the Stats message is TickStats field for field, in the message's order
    assert list(Stats.get_fields_and_field_types())[1:] == [f.name for f in fields(TickStats)]
    sim = load_scene("hanging_provot").build_simulator()
    sim.step(3)
    energy = sim.energy()
    tick = TickStats.of(
        sim, steps=3, step_time_mean=5e-4, stability_margin=stability_margin(1e-3, 4e-3)
    )
    s = messages.stats(Stats, stamp, "base", tick)
    assert (s.header.frame_id, s.integrator, s.steps, s.step_time_mean) == (
        "base",
        "symplectic_euler",
        3,
        5e-4,
    )
    assert s.potential_energy == energy["spring"] + energy["gravity"]
    assert s.kinetic_energy == energy["kinetic"] and s.sim_time == sim.time
    assert s.stability_margin == pytest.approx(0.25)
    assert (s.solver_iterations, s.solver_converged) == (0, True)
    assert stability_margin(1e-3, math.inf) == 0.0 and stability_margin(1e-3, None) == 0.0
    assert stability_margin(1e-3, 0.0) == math.inf
    kw = dict(
        paused=False,
        rtf=1.0,
        rtf_known=True,
        rtf_warn=0.95,
        dt=1e-3,
        warn_margin=0.8,
        values={"a": 1},
    )
    assert (
        messages.diagnostic_status(error=None, stable_dt=2e-3, **kw).level == DiagnosticStatus.OK
    )
    warn = messages.diagnostic_status(error=None, stable_dt=1.1e-3, **kw)
    assert warn.level == DiagnosticStatus.WARN and "stable_dt" in warn.message
    slow = messages.diagnostic_status(error=None, stable_dt=1.0, **dict(kw, rtf=0.5))
    assert slow.level == DiagnosticStatus.WARN and "real-time factor 0.50" in slow.message
    err = messages.diagnostic_status(error="boom", stable_dt=1.0, **kw)
    assert err.level == DiagnosticStatus.ERROR and "boom" in err.message
    assert err.values[0].key == "a" and err.values[0].value == "1"


# ------------------------------------------------------------------ signals (process)


def test_signals_at_random_moments_end_the_default_node_cleanly():
    """SIGINT and SIGTERM at random moments of the default node's life (`make run`'s scene: 32×32,
    60 Hz, a tick is most of its period, so most signals land inside a tick) end it with exit 0 and
    no traceback; so does a double SIGINT (what `ros2 launch` sends on Ctrl-C). Moments are drawn
    in [0, 4] s after the handlers are in place: start-up (scene, numba, DDS), the first ticks and
    steady running. 3 nodes run at a time; 8 draws per signal plus 4 double SIGINTs in `make test`
    (about 30 s); CLOTH_SIM_SIGNAL_DRAWS=25 runs the issue's 25 per signal."""
    draws = int(os.environ.get("CLOTH_SIM_SIGNAL_DRAWS", "8"))
    rng = np.random.default_rng(2026)
    early = max(1, draws // 4)
    plan = [
        (s, float(t))
        for s in (signal.SIGINT, signal.SIGTERM)
        for t in (
            rng.uniform(0, 0.5, early).tolist() + rng.uniform(0.5, 4.0, draws - early).tolist()
        )
    ]
    plan += [("double", float(t)) for t in rng.uniform(0.5, 4.0, max(4, draws // 2))]
    failures = []
    for batch in range(0, len(plan), 3):
        procs = []
        for sig, delay in plan[batch : batch + 3]:
            procs.append((sig, delay, start_node(next_domain()), time.monotonic()))
        for sig, delay, proc, t0 in sorted(procs, key=lambda p: p[1]):
            time.sleep(max(0.0, t0 + delay - time.monotonic()))
            if sig == "double":
                proc.send_signal(signal.SIGINT)
                time.sleep(0.01)
                proc.send_signal(signal.SIGINT)
            else:
                proc.send_signal(sig)
        for sig, delay, proc, _ in procs:
            code, out = end_node(proc)
            if code != 0 or "Traceback" in out:
                failures.append((str(sig), round(delay, 3), code, out[-2000:]))
    assert not failures, failures


def test_sigint_ends_a_node_started_with_sigint_ignored():
    """A node started in the background of a script inherits SIGINT ignored; it once exited 1 on
    SIGINT. Its handlers are its own: exit 0."""
    proc = start_node(next_domain(), "-p", "rows:=12", "-p", "cols:=12", ignore_sigint=True)
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    code, out = end_node(proc)
    assert code == 0 and "Traceback" not in out, out


def test_a_scene_whose_step_the_cloth_refuses_runs_at_a_step_that_carries_it(ros):
    """hanging's explicit step (1 ms) is above symplectic Euler's stable step for 1 m of cotton at
    128×128: with neither dt nor the method given, the node starts at 90 % of that stable step
    (the method and the declared dt say so) instead of exiting; a dt the user gave is still
    refused (test_a_bad_start_up_value_is_one_line_naming_it)."""
    from cloth_sim.settings import check

    node = ros.start(material="cotton", rows=128, cols=128, size=[1.0, 1.0])
    limit = check("hanging", {"material": "cotton", "rows": 128, "cols": 128, "size": [1.0, 1.0],
                              "allow_unstable": True}).stable_dt  # fmt: skip
    assert 0.0 < limit < 1e-3
    assert node.sim.integrator == "symplectic_euler"
    assert node.sim.dt == pytest.approx(0.9 * limit, rel=1e-12)
    assert node.get_parameter("dt").value == node.sim.dt
    t0 = node.sim.time
    assert ros.spin_until(lambda: node.sim.time > t0 + 0.01, 20)
    assert np.isfinite(node.sim.positions).all()


@pytest.mark.parametrize(
    "arg,words",
    [
        ("rows:=600", "rows = 600 is not accepted: expected an integer in [2, 512]"),
        ("dt:=-1.0", "dt = -1.0 is not accepted"),
        ("dt:=abc", "dt = 'abc' is not accepted"),
        ("publish_rate:=0.0", "publish_rate = 0.0 is not accepted"),
        ("dt:=1", "dt=1 s is above the stable limit"),
        ("rows:=16.0", "rows = 16.0 is not accepted"),
    ],
)
def test_a_bad_start_up_value_is_one_line_naming_it(arg, words):
    out = subprocess.run(
        [str(Path(sys.executable).parent / "cloth_sim_node"), "--ros-args", "-p", arg],
        env=node_env(next_domain()),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "Traceback" not in out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], out.stderr


def test_the_venv_is_an_ament_prefix_of_the_generated_interfaces():
    """`ros2 interface show cloth_sim/msg/Stats` said "Unknown package" in the `make` set-up: the
    generated interfaces' prefix was on no ament prefix path. `make` links them into the venv."""
    code = (
        "from ament_index_python import get_resource, get_package_share_directory\n"
        "import os\n"
        "content, prefix = get_resource('rosidl_interfaces', 'cloth_sim')\n"
        "share = get_package_share_directory('cloth_sim')\n"
        "print(content.split()); print(os.path.isfile(os.path.join(share, 'msg', 'Stats.msg')))\n"
        "print(os.path.isfile(os.path.join(share, 'launch', 'cloth_sim.launch.py')))\n"
        "print(os.access(os.path.join(prefix, 'lib', 'cloth_sim', 'cloth_sim_node'), os.X_OK))"
    )
    env = dict(os.environ, AMENT_PREFIX_PATH=sys.prefix)
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[:4] == [
        "['msg/Stats.idl', 'msg/Stats.msg', 'srv/Grasp.idl', 'srv/Grasp.srv', 'srv/Release.idl', "
        "'srv/Release.srv', 'srv/Step.idl', 'srv/Step.srv']",
        "True",
        "True",
        "True",
    ]


# ------------------------------------------------------------------ contacts
def test_colliders_are_shown_and_moved_through_their_topics(ros):
    from geometry_msgs.msg import PoseStamped
    from visualization_msgs.msg import MarkerArray

    node = ros.start(scene="drape", publish_rate=30.0)
    assert [c.name for c in node.sim.colliders] == ["ball", "floor"]
    markers = ros.collect(MarkerArray, "/cloth_sim/colliders")
    assert ros.spin_until(lambda: markers, 10)
    ball = next(m for m in markers[-1].markers if m.ns == "ball")
    assert ball.type == ball.SPHERE and ball.scale.x == pytest.approx(0.5)
    assert ball.pose.position.z == pytest.approx(0.3)
    pub = ros.node.create_publisher(PoseStamped, "/cloth_sim/colliders/ball/pose", 10)
    msg = PoseStamped()
    msg.header.frame_id = "cloth"
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = 0.5, 0.5, 0.1
    msg.pose.orientation.w = 1.0
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0, 10)
    pub.publish(msg)
    assert ros.spin_until(lambda: node.sim.colliders[0].center[2] == pytest.approx(0.1), 10)
    # a bad pose (wrong frame, not finite) is ignored: the ball stays
    msg.header.frame_id = "map"
    msg.pose.position.z = 0.4
    pub.publish(msg)
    msg.header.frame_id = ""
    msg.pose.position.z = float("nan")
    pub.publish(msg)
    ros.spin_for(0.5)
    assert node.sim.colliders[0].center[2] == pytest.approx(0.1)
    assert np.all(np.isfinite(node.sim.positions))


def test_thickness_and_self_collision_are_live_parameters(ros):
    node = ros.start(scene="fold", rows=10, cols=10, spacing=1.0 / 9, publish_rate=30.0)
    assert node.sim.self_collision and "self_collision" in node.sim.active_stages
    r = ros.set_params("/cloth_sim", {"self_collision": False, "thickness": 0.01})
    assert all(x.successful for x in r)
    assert not node.sim.self_collision and node.sim.thickness == 0.01
    for bad in (
        {"thickness": 0.0},
        {"thickness": -1.0},
        {"thickness": float("nan")},
        {"self_collision": 1.0},
    ):
        r = ros.set_params("/cloth_sim", bad)[0]
        name = next(iter(bad))
        assert not r.successful and name in r.reason
    assert node.sim.thickness == 0.01


def test_the_strain_limit_method_is_live_and_a_bad_one_refused(ros):
    node = ros.start(rows=12, cols=12, spacing=1.0 / 11, publish_rate=30.0)
    assert node.sim.strain_limit_method == "projection"  # the hanging scene's
    ros.spin_for(0.3)
    r = ros.set_params("/cloth_sim", {"strain_limit_method": "provot"})[0]
    assert r.successful and node.sim.strain_limit_method == "provot"
    t = node.sim.time
    ros.spin_for(0.3)
    assert node.sim.time > t  # it kept running, from where it was
    for bad in ("jacobi", "", 1.0):
        r = ros.set_params("/cloth_sim", {"strain_limit_method": bad})[0]
        assert not r.successful and "strain_limit_method" in r.reason
    assert node.sim.strain_limit_method == "provot"
    assert node.get_parameter("strain_limit_method").value == "provot"


# ------------------------------------------------------------------ manipulation and time
def _pose(x, y, z, frame="cloth"):
    from geometry_msgs.msg import PoseStamped

    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
    msg.pose.orientation.w = 1.0
    return msg


def test_grasp_lift_feel_and_release_through_the_node(ros):
    from geometry_msgs.msg import Point, PoseStamped, WrenchStamped

    from cloth_sim.srv import Grasp, Release

    node = ros.start(publish_rate=30.0)
    grasp = Grasp.Request(gripper="left", point=Point(x=0.5, y=0.0, z=0.0), radius=0.05)
    res = ros.call(Grasp, "/cloth_sim/grasp", grasp)
    assert res.success and res.count >= 1, res.message
    idx = node.sim.grippers["left"]
    start = node.sim.positions[idx].copy()
    wrenches = ros.collect(WrenchStamped, "/cloth_sim/grippers/left/wrench")
    pub = ros.node.create_publisher(PoseStamped, "/cloth_sim/grippers/left/pose", 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0 and wrenches, 10)
    pub.publish(_pose(0.5, 0.0, 0.2))
    assert ros.spin_until(lambda: abs(node.sim.gripper_pose("left")[0][2] - 0.2) < 1e-12, 10)
    assert np.abs(node.sim.positions[idx] - (start + [0, 0, 0.2])).max() < 1e-9
    assert wrenches[-1].header.frame_id == "cloth"
    # refusals: a name in use, nothing in reach, a bad name; unknown release
    again = ros.call(Grasp, "/cloth_sim/grasp", grasp)
    assert not again.success and "already" in again.message
    far = ros.call(
        Grasp, "/cloth_sim/grasp", Grasp.Request(gripper="far", point=Point(x=9.0), radius=0.01)
    )
    assert not far.success and "radius" in far.message and "point" in far.message
    bad = ros.call(Grasp, "/cloth_sim/grasp", Grasp.Request(gripper="no/slash", radius=0.1))
    assert not bad.success and "gripper" in bad.message
    nan = ros.call(
        Grasp,
        "/cloth_sim/grasp",
        Grasp.Request(gripper="n", point=Point(x=float("nan")), radius=0.1),
    )
    assert not nan.success and "point" in nan.message
    unknown = ros.call(Release, "/cloth_sim/release", Release.Request(gripper="right"))
    assert not unknown.success and "left" in unknown.message
    # a pose in another frame or not finite is ignored
    pub.publish(_pose(0.5, 0.0, 0.5, frame="map"))
    pub.publish(_pose(0.5, float("inf"), 0.5))
    ros.spin_for(0.4)
    assert node.sim.gripper_pose("left")[0][2] == pytest.approx(0.2)
    assert ros.call(Release, "/cloth_sim/release", Release.Request(gripper="left")).success
    assert node.sim.grippers == {}
    assert np.all(np.isfinite(node.sim.positions))


def test_clock_real_time_factor_and_step(ros):
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import SetBool

    from cloth_sim.srv import Step

    node = ros.start(publish_rate=30.0, publish_clock=True)
    clocks = ros.collect(Clock, "/clock")
    stats = ros.collect(Stats, "/cloth_sim/stats")
    assert ros.spin_until(lambda: len(clocks) >= 10 and len(stats) >= 10, 15)
    t = [c.clock.sec + 1e-9 * c.clock.nanosec for c in clocks]
    assert all(b >= a for a, b in zip(t, t[1:]))
    s = stats[-1]
    assert s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec == pytest.approx(
        s.sim_time, abs=1e-9
    )
    # running: ~/step is refused
    refused = ros.call(Step, "/cloth_sim/step", Step.Request(steps=5))
    assert not refused.success and "paused" in refused.message
    assert ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=True)).success
    before = node.sim.time
    res = ros.call(Step, "/cloth_sim/step", Step.Request(steps=250))
    assert res.success and res.sim_time == pytest.approx(before + 250 * node.sim.dt, abs=1e-12)
    assert node.sim.time == pytest.approx(before + 250 * node.sim.dt, abs=1e-12)
    too_many = ros.call(Step, "/cloth_sim/step", Step.Request(steps=10**9))
    assert not too_many.success and "steps" in too_many.message
    # real_time_factor 0: as fast as the CPU allows, ahead of the wall clock
    assert ros.call(SetBool, "/cloth_sim/pause", SetBool.Request(data=False)).success
    assert all(r.successful for r in ros.set_params("/cloth_sim", {"real_time_factor": 0.0}))
    sim0, wall0 = node.sim.time, time.monotonic()
    ros.spin_for(1.0)
    assert node.sim.time - sim0 > 1.5 * (time.monotonic() - wall0)
    r = ros.set_params("/cloth_sim", {"real_time_factor": -1.0})[0]
    assert not r.successful and "real_time_factor" in r.reason


def test_a_mesh_scene_publishes_an_unorganised_cloud_and_refuses_grid_parameters(ros, tmp_path):
    node = ros.start(scene="towel")
    clouds = ros.collect(PointCloud2, "/cloth_sim/points")
    meshes = ros.collect(Marker, "/cloth_sim/mesh")
    assert ros.spin_until(lambda: clouds and meshes, 15)
    n = node.sim.model.n_particles
    assert (clouds[-1].height, clouds[-1].width, clouds[-1].row_step) == (1, n, 12 * n)
    assert len(meshes[-1].points) == 3 * len(node.sim.model.triangles)
    for change in ({"rows": 20}, {"spacing": 0.05}, {"stiffness.shear": 5.0}):
        (result,) = ros.set_params("/cloth_sim", change)
        assert (
            not result.successful and "not used by scene towel, a triangle mesh" in result.reason
        )
    (result,) = ros.set_params("/cloth_sim", {"stiffness.bend": 0.2})  # a mesh family: live
    assert result.successful and node.sim.stiffness("bend")[0] == 0.2
    (result,) = ros.set_params("/cloth_sim", {"density": 0.8})  # rebuilds
    assert result.successful and node.sim.model.masses.sum() == pytest.approx(0.8 * 0.5 * 0.8)
    # back to a grid: its own parameters apply again, density does not
    assert all(
        r.successful for r in ros.set_params("/cloth_sim", {"scene": "hanging_provot", "rows": 10})
    )
    assert node.sim.model.rows == 10
    (result,) = ros.set_params("/cloth_sim", {"density": 0.3})
    assert not result.successful and "density applies to mesh scenes" in result.reason
    # a grid given by its size and mass per area: rows refine the same 1 m, 5.76 kg cloth,
    # density applies and sets the particles' mass
    dense = tmp_path / "dense.yaml"
    dense.write_text(
        "name: dense\n"
        "grid: {rows: 24, cols: 24, orientation: vertical, origin: [0.0, 0.0, 1.05]}\n"
        "size: [1.0, 1.0]\n"
        "density: 5.76\n"
        "stiffness: {structural: 1000.0, shear: 1000.0, bend: 10.0}\n"
    )
    assert all(
        r.successful for r in ros.set_params("/cloth_sim", {"scene": str(dense), "rows": 10})
    )
    model = node.sim.model
    assert model.rows == 10 and model.masses.sum() == pytest.approx(5.76)
    assert np.ptp(model.positions[:, 2]) == pytest.approx(1.0)
    (result,) = ros.set_params("/cloth_sim", {"density": 2.0})
    assert result.successful and node.sim.model.masses.sum() == pytest.approx(2.0)
    (result,) = ros.set_params("/cloth_sim", {"particle_mass": 0.02})
    assert not result.successful and "set by scene dense's density" in result.reason
    # a grid in a library fabric (fold, cotton): the fabric sets the masses
    assert all(r.successful for r in ros.set_params("/cloth_sim", {"scene": "fold", "rows": 10}))
    assert node.sim.model.masses.sum() == pytest.approx(0.276)
    (result,) = ros.set_params("/cloth_sim", {"density": 3.0})
    assert not result.successful and "set by the cloth's material" in result.reason


def test_the_launch_file_describes_every_scene_the_package_has(monkeypatch):
    """`ros2 launch -s cloth_sim cloth_sim.launch.py` lists the scenes from the package's scene
    directory (it once named 4 of 7). Run here with stand-ins for the launch packages."""
    import types

    from cloth_sim.scene import available_scenes

    captured = {}
    fakes = {
        "ament_index_python": types.ModuleType("ament_index_python"),
        "ament_index_python.packages": types.SimpleNamespace(
            get_package_share_directory=lambda pkg: str(ROOT)
        ),
        "launch": types.SimpleNamespace(LaunchDescription=list),
        "launch.actions": types.SimpleNamespace(
            DeclareLaunchArgument=lambda name, **kw: captured.setdefault(name, kw)
        ),
        "launch.substitutions": types.SimpleNamespace(LaunchConfiguration=str),
        "launch_ros.actions": types.SimpleNamespace(Node=lambda **kw: kw),
        "launch_ros": types.ModuleType("launch_ros"),
    }
    for name, module in fakes.items():
        monkeypatch.setitem(sys.modules, name, module)
    namespace = {}
    exec(
        compile((ROOT / "launch" / "cloth_sim.launch.py").read_text(), "launch", "exec"), namespace
    )
    namespace["generate_launch_description"]()
    described = captured["scene"]["description"]
    for scene in available_scenes():
        assert scene in described, scene
    assert "tshirt" in described and "towel" in described


def test_integer_arrays_are_taken_as_double_arrays(ros):
    """`gravity: [0, 0, -9]` in a params file, or `ros2 param set /cloth_sim gravity "[0, 0, -9]"`,
    was refused by rclpy's type check naming no parameter; an integer for a double already
    worked."""
    node = ros.start(gravity=[0, 0, -9])
    assert list(node.get_parameter("gravity").value) == [0.0, 0.0, -9.0]
    assert node.sim.gravity.tolist() == [0.0, 0.0, -9.0]
    results = ros.set_params("/cloth_sim", {"wind.direction": [0, 1, 0], "gravity": [0, 0, -5]})
    assert all(r.successful for r in results), [r.reason for r in results]
    assert node.sim.gravity.tolist() == [0.0, 0.0, -5.0]
    (result,) = ros.set_params("/cloth_sim", {"gravity": [0, -9]})
    assert not result.successful and "gravity must have exactly 3 elements" in result.reason


def test_a_material_scene_keeps_its_size_and_refuses_the_values_its_fabric_sets(ros):
    node = ros.start(scene="swing", rows=25, cols=5)
    assert ros.spin_until(lambda: node.sim.time > 0.1, 20)
    assert node.sim.model.meta["material"].density == pytest.approx(0.187)
    assert list(node.get_parameter("size").value) == [0.1, 0.6]
    (result,) = ros.set_params("/cloth_sim", {"stiffness.structural": 5.0})
    assert not result.successful and "set by the cloth's material" in result.reason
    # a finer grid of the same strip: the same extent and weight
    assert all(r.successful for r in ros.set_params("/cloth_sim", {"rows": 49, "cols": 9}))
    m = node.sim.model
    assert (m.rows, m.cols) == (49, 9)
    assert np.ptp(m.positions[:, 1]) == pytest.approx(0.6)
    assert m.masses.sum() == pytest.approx(0.187 * 0.06)
    # a library fabric by name: denim, stiffer, needs a smaller step with symplectic Euler
    (result,) = ros.set_params("/cloth_sim", {"material": "denim"})
    assert not result.successful and "stable_dt" in result.reason
    assert all(
        r.successful
        for r in ros.set_params("/cloth_sim", {"material": "denim", "dt": 5e-5}, atomically=True)
    )
    assert node.sim.model.masses.sum() == pytest.approx(0.324 * 0.06)
    (result,) = ros.set_params("/cloth_sim", {"material": "velvet"})
    assert not result.successful and "velvet" in result.reason


def test_a_device_that_cannot_run_here_is_refused_and_the_cpu_keeps_running(ros):
    """``device:=cuda`` on a machine where no CUDA device can run (these machines: no GPU) starts
    on the cpu with a warning naming what is missing, and is refused live with the same words;
    the simulation goes on untouched."""
    from cloth_sim import backends

    why = backends.problem("cuda")
    if why is None:
        pytest.skip("a CUDA device runs here: the node on it is test/gpu/sim/test_node_on_cuda.py")
    node = ros.start(device="cuda", rows=12, cols=12)
    assert node.sim.device == "cpu"
    assert node.get_parameter("device").value == "cpu"
    t0 = node.sim.time
    assert ros.spin_until(lambda: node.sim.time > t0 + 0.05, 20)
    result = ros.set_params("/cloth_sim", {"device": "cuda"})[0]
    assert not result.successful
    assert result.reason.startswith("device=cuda")
    assert why in result.reason, result.reason
    assert node.sim.device == "cpu" and node.get_parameter("device").value == "cpu"
    t1 = node.sim.time
    assert ros.spin_until(lambda: node.sim.time > t1 + 0.05, 20)
    bad = ros.set_params("/cloth_sim", {"device": "gpu"})[0]
    assert not bad.successful and "accepted values: cpu, cuda" in bad.reason
