"""Real-time factor of cloth_sim_node: the node and a subscriber in one process, side by side
sizes.

``cloth-sim bench node --sizes 32 64 --seconds 10`` prints, per size, the mean real-time factor
reported on ~/stats, ms per step, tick wall time, meshes per second, overruns and resident memory,
with and without ~/points and ~/mesh subscribers (building and sending them is skipped when nobody
listens). ``cloth-sim bench params`` times what ``ros2 param load`` costs the ticking node.
"""

from __future__ import annotations

import os
import platform
import time
from contextlib import contextmanager

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import Marker

#: the scene the speed tables run (the literature review's sheet on per-family springs, whose
#: stiffness and strain-limit rows they vary; ``hanging`` is it in cotton)
SHEET = "hanging_provot"
#: its cloth (32×32 particles of 0.01 kg): resized to N×N it keeps its 1 m side and this mass, so
#: every size is the same cloth, finer (particle_mass = CLOTH_MASS / N²)
CLOTH_MASS = 10.24


def measure(
    n: int,
    seconds: float,
    subscribe: bool,
    integrator: str,
    dt: float,
    rate: float,
    passes: int | None = None,
    stiffness: float | None = None,
    method: str | None = None,
) -> dict:
    """The :data:`SHEET` scene resized to ``n``×``n`` (the same 1 m, 10.24 kg cloth), with
    ``stiffness`` (N/m) on its structural and shear springs and the strain limit's ``method`` if
    given."""
    overrides = [
        Parameter("scene", value=SHEET),
        Parameter("rows", value=n),
        Parameter("cols", value=n),
        Parameter("spacing", value=1.0 / (n - 1)),
        Parameter("particle_mass", value=CLOTH_MASS / n**2),
        Parameter("integrator", value=integrator),
        Parameter("dt", value=dt),
        Parameter("publish_rate", value=rate),
    ]
    if passes is not None:
        overrides.append(Parameter("strain_limit_passes", value=passes))
    if method is not None:
        overrides.append(Parameter("strain_limit_method", value=method))
    if stiffness is not None:
        overrides += [
            Parameter("stiffness.structural", value=float(stiffness)),
            Parameter("stiffness.shear", value=float(stiffness)),
        ]
    return dict(measure_node(overrides, seconds, subscribe), N=n)


def measure_node(overrides: list, seconds: float, subscribe: bool) -> dict:
    """The node started with ``overrides``, run ``seconds`` after a 2 s warm-up, with or without
    ``~/points`` and ``~/mesh`` subscribed: real-time factor, step and tick costs, overruns, and
    the worst strain of a strain-limited spring, sampled every 0.1 s of wall time over the whole
    run (the warm-up, the cloth's fall from flat, included)."""
    with _node_and_probe(overrides) as (node, probe, ex, stats):
        worst = [0.0]

        def sample():
            if node.sim.model.n_springs:
                worst[0] = max(worst[0], float(node.sim.strains(limited_only=True).max()))

        probe.create_timer(0.1, sample)
        clouds, meshes = [0], [0]
        if (
            subscribe
        ):  # what RViz's two displays ask for; raw: this probe shares the node's thread,
            # so it only counts the messages, without deserialising or keeping them (RViz does that
            # in its own process)
            def counter(box):
                def count(_):
                    box[0] += 1

                return count

            probe.create_subscription(
                PointCloud2, "/cloth_sim/points", counter(clouds), 100, raw=True
            )
            probe.create_subscription(Marker, "/cloth_sim/mesh", counter(meshes), 100, raw=True)
        end = time.monotonic() + 2.0  # warm-up: numba caches, discovery
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        stats.clear()
        clouds[0] = meshes[0] = 0
        o0, s0, w0 = node.session.overruns, node.sim.time, time.monotonic()
        end = w0 + seconds
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        wall, sim = time.monotonic() - w0, node.sim.time - s0
        steps = sum(s.steps for s in stats)
        out = {
            "subscriber": subscribe,
            "rtf": sim / wall,
            "ms_per_step": 1e3 * sum(s.step_time_mean * s.steps for s in stats) / max(steps, 1),
            "tick_ms": 1e3 * sum(s.tick_wall_time for s in stats) / max(len(stats), 1),
            "ticks_per_s": len(stats) / wall,
            "clouds": clouds[0],
            "meshes_per_s": meshes[0] / wall,
            "overruns": node.session.overruns - o0,
            "rss_mb": _rss_mb(),
            "worst_strain": worst[0],
            "integrator": node.sim.integrator,  # what ran (a refused step is carried)
            "dt": node.sim.dt,
        }
        return out


@contextmanager
def _node_and_probe(overrides):
    """A cloth_sim node with ``overrides`` and a probe node collecting ~/stats, both on one
    executor in a context of their own; everything is shut down on the way out."""
    from cloth_sim.msg import Stats

    from ..ros.node import ClothSimNode

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0")))
    try:
        node = ClothSimNode(context=ctx, parameter_overrides=overrides)
        probe = rclpy.create_node("bench_probe", context=ctx)
        stats = []
        probe.create_subscription(Stats, "/cloth_sim/stats", stats.append, 1000)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        yield node, probe, ex, stats
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def _rss_mb() -> float:
    """This process's resident memory now (MB; the node and the probe share it, and the rows before
    this one in the same run add theirs), from /proc, or its peak from getrusage where /proc is
    missing."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def print_scene_node_table(scene: str, seconds: float, rate: float) -> list[dict]:
    """A named scene (a garment) in the node as it ships (its integrator and dt), with
    self-collision off and on, ``~/points`` and ``~/mesh`` subscribed."""
    print(
        f"# cloth_sim_node, scene {scene} as it ships, {rate:g} Hz, ~/points + ~/mesh subscribed, "
        f"{seconds:g} s per row after 2 s warm-up; {platform.machine()}, {os.cpu_count()} cores"
    )
    print(
        "| self_collision | real-time factor | ms/step | tick wall ms | ticks/s | meshes/s | "
        "overruns | worst strain |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    for on in (False, True):
        r = measure_node(
            [
                Parameter("scene", value=scene),
                Parameter("self_collision", value=on),
                Parameter("publish_rate", value=rate),
            ],
            seconds,
            True,
        )
        rows.append(dict(r, self_collision=on))
        print(
            f"| {'on' if on else 'off'} | {r['rtf']:.3f} | {r['ms_per_step']:.3f} | "
            f"{r['tick_ms']:.2f} | {r['ticks_per_s']:.1f} | {r['meshes_per_s']:.1f} | "
            f"{r['overruns']} | {r['worst_strain']:.4f} |",
            flush=True,
        )
    return rows


def print_grid_scene_table(
    scenes,
    n: int,
    seconds: float,
    rate: float,
    integrator: str | None = None,
    dt: float | None = None,
    material: str | None = None,
    size=None,
) -> list[dict]:
    """Each grid scene as a user's ``-p rows:=n -p cols:=n`` runs it (one given by its spacing and
    particle mass grows: a larger, heavier cloth; one given by its size and density, fold, is the
    same cloth finer), its integrator, step and self-collision as it ships unless ``integrator``
    and ``dt`` are given, a library fabric of ``size`` (w, h, m) where ``material`` is
    (``-p material:=… -p size:=[…]``), ``~/points`` and ``~/mesh`` subscribed."""
    from ..scene import load_scene

    extra = []
    if integrator is not None:
        extra.append(Parameter("integrator", value=integrator))
    if dt is not None:
        extra.append(Parameter("dt", value=float(dt)))
    if material is not None:
        extra.append(Parameter("material", value=material))
        extra.append(Parameter("size", value=[float(v) for v in (size or (1.0, 1.0))]))
    given = ", ".join(f"-p {p.name}:={p.value}" for p in extra)
    print(
        f"# cloth_sim_node, grid scenes at -p rows:={n} -p cols:={n}"
        f"{', ' + given if given else ''}, {rate:g} Hz, ~/points + ~/mesh "
        f"subscribed, {seconds:g} s per row after 2 s warm-up; {platform.machine()}, "
        f"{os.cpu_count()} cores"
    )
    print(
        "| scene | integrator, dt | real-time factor | ms/step | tick wall ms | overruns | "
        "worst strain |"
    )
    print("|---|---|---|---|---|---|---|")
    rows = []
    for scene in scenes:
        s = load_scene(scene)
        if s.mesh is not None:
            print(f"| {scene} | a mesh scene: no grid to resize | | | | | |")
            continue
        r = measure_node(
            [
                Parameter("scene", value=scene),
                Parameter("rows", value=n),
                Parameter("cols", value=n),
                Parameter("publish_rate", value=rate),
                *extra,
            ],
            seconds,
            True,
        )
        rows.append(dict(r, scene=scene))
        ran = f"{r['integrator']}, {r['dt']:.4g} s"
        print(
            f"| {scene} | {ran} | {r['rtf']:.3f} | {r['ms_per_step']:.3f} | "
            f"{r['tick_ms']:.2f} | {r['overruns']} | {r['worst_strain']:.4f} |",
            flush=True,
        )
    return rows


def print_node_table(
    sizes,
    seconds: float,
    integrator: str,
    dt: float,
    rate: float,
    passes: int | None = None,
    stiffness: float | None = None,
    subscribed=(False, True),
    method: str | None = None,
) -> list[dict]:
    limiter = "" if passes is None else f", strain_limit_passes {passes}"
    limiter += "" if method is None else f", strain_limit_method {method}"
    material = "" if stiffness is None else f", structural and shear stiffness {stiffness:g} N/m"
    print(
        f"# cloth_sim_node, {SHEET} scene resized to N×N (1 m, {CLOTH_MASS} kg), {integrator}, "
        f"dt={dt:g} s, {rate:g} Hz{limiter}{material}, {seconds:g} s per row after 2 s warm-up; "
        f"{platform.machine()}, {os.cpu_count()} cores"
    )
    print(
        "| N | ~/points + ~/mesh subscribers | real-time factor | ms/step | tick wall ms | "
        "ticks/s | "
        "meshes/s | overruns | worst strain | resident MB |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for n in sizes:
        for sub in subscribed:
            r = measure(n, seconds, sub, integrator, dt, rate, passes, stiffness, method)
            rows.append(r)
            print(
                f"| {n} | {'yes' if sub else 'no'} | {r['rtf']:.3f} | {r['ms_per_step']:.3f} | "
                f"{r['tick_ms']:.2f} | {r['ticks_per_s']:.1f} | {r['meshes_per_s']:.1f} | "
                f"{r['overruns']} | {r['worst_strain']:.4f} | {r['rss_mb']:.0f} |",
                flush=True,
            )
    return rows


def print_param_load_table(size: int = 32, rate: float = 60.0) -> list[dict]:
    """What `ros2 param load` costs the ticking node: its own 26 parameters sent in one
    ``set_parameters`` request (rclpy sets them one at a time), unchanged and then with every
    stiffness and damping ×1.1 and a new drag, the :data:`SHEET` scene at N×N and ``rate``.
    Prints the largest interval between consecutive ~/stats stamps around the request, in ticks,
    and how long the request took."""
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters

    print(
        f"# ros2 param load semantics on cloth_sim_node: {SHEET} scene at {size}×{size}, "
        f"{rate:g} Hz; {platform.machine()}, {os.cpu_count()} cores"
    )
    print(
        "| file | parameters | material changes | request ms | largest ~/stats interval (ticks) |"
    )
    print("|---|---|---|---|---|")
    rows = []
    overrides = [
        Parameter("scene", value=SHEET),
        Parameter("rows", value=size),
        Parameter("cols", value=size),
        Parameter("spacing", value=1.0 / (size - 1)),
        Parameter("publish_rate", value=rate),
    ]
    with _node_and_probe(overrides) as (node, probe, ex, stats):

        def call(srv, name, req):
            cli = probe.create_client(srv, name)
            while not cli.service_is_ready():
                ex.spin_once(timeout_sec=0.01)
            fut = cli.call_async(req)
            while not fut.done():
                ex.spin_once(timeout_sec=0.01)
            return fut.result()

        def spin(seconds):
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=0.005)

        spin(2.0)
        names = call(
            ListParameters, "/cloth_sim/list_parameters", ListParameters.Request()
        ).result.names
        values = call(
            GetParameters, "/cloth_sim/get_parameters", GetParameters.Request(names=names)
        ).values
        dump = [
            Parameter.from_parameter_msg(ParameterMsg(name=n, value=v))
            for n, v in zip(names, values)
        ]
        scaled = [
            Parameter(p.name, value=p.value * 1.1)
            if p.name.startswith(("stiffness", "damping"))
            else p
            for p in dump
        ] + [Parameter("drag", value=0.001)]
        for label, params, changes in (
            ("its own dump", dump, 0),
            ("material ×1.1, drag", scaled, 7),
        ):
            spin(1.0)
            n = len(stats)
            t = time.perf_counter()
            call(
                SetParameters,
                "/cloth_sim/set_parameters",
                SetParameters.Request(parameters=[p.to_parameter_msg() for p in params]),
            )
            request = time.perf_counter() - t
            spin(1.0)
            stamps = [s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in stats[n - 2 :]]
            gap = max(b - a for a, b in zip(stamps, stamps[1:])) * rate
            rows.append(
                {
                    "file": label,
                    "parameters": len(params),
                    "changes": changes,
                    "request_ms": 1e3 * request,
                    "gap_ticks": gap,
                }
            )
            print(
                f"| {label} | {len(params)} | {changes} | {1e3 * request:.1f} | {gap:.2f} |",
                flush=True,
            )
    return rows


def _bench_domain() -> int:
    """A ROS domain for a benchmark that talks to a node in another process (not another run's)."""
    return 50 + os.getpid() % 40


def _start_node(domain: int, size: int, params=()):
    """``cloth_sim_node`` in its own process on ``domain`` (localhost only), the :data:`SHEET`
    scene resized to ``size``×``size`` over the same 1 m, and ``params`` (``name:=value``
    strings)."""
    import subprocess
    import sys

    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    exe = os.path.join(sys.prefix, "bin", "cloth_sim_node")
    extra = [a for p in params for a in ("-p", p)]
    return subprocess.Popen(
        [
            exe,
            "--ros-args",
            "-p",
            f"scene:={SHEET}",
            "-p",
            f"rows:={size}",
            "-p",
            f"cols:={size}",
            "-p",
            f"spacing:={1.0 / (size - 1)}",
            *extra,
        ],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


@contextmanager
def _remote_client(domain: int, name: str):
    """A node of this process on ``domain`` with its executor, for talking to a node in another
    process; shut down on leaving."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    try:
        client = rclpy.create_node(name, context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(client)
        yield client, ex
        ex.shutdown()
        client.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def print_lockstep_table(size: int = 32, calls: int = 300, chunks=(1, 10, 100)) -> list[dict]:
    """Lockstep throughput: ``cloth_sim_node`` in its own process (N×N :data:`SHEET` scene,
    paused), this process calling ``~/step`` with ``steps`` = each of ``chunks``, one call after
    the other; prints steps per second and calls per second, beside the node's own stepping speed
    (the same cloth stepped in this process without ROS)."""
    domain = _bench_domain()
    node = _start_node(domain, size)
    print(
        f"# lockstep: ~/step from another process to cloth_sim_node ({size}×{size} {SHEET} scene, "
        f"symplectic Euler, dt = 1 ms); {platform.machine()}, {os.cpu_count()} cores"
    )
    print("| steps per call | calls/s | steps/s | × stepping in-process without ROS |")
    print("|---|---|---|---|")
    try:
        with _remote_client(domain, "lockstep_bench") as (client, ex):
            return _lockstep_rows(client, ex, size, calls, chunks)
    finally:
        node.terminate()
        node.wait(timeout=20)


def _lockstep_rows(client, ex, size, calls, chunks) -> list[dict]:
    """The lockstep table's rows: ``~/step`` calls from ``client`` to the paused node."""
    from std_srvs.srv import SetBool

    from cloth_sim.srv import Step

    from ..scene import load_scene

    def call(srv, name, req, timeout=60.0):
        cli = clients.setdefault(name, client.create_client(srv, name))
        end = time.monotonic() + timeout
        while not cli.service_is_ready():
            ex.spin_once(timeout_sec=0.01)
            if time.monotonic() > end:
                raise RuntimeError(f"{name} not available")
        fut = cli.call_async(req)
        while not fut.done():
            ex.spin_once(timeout_sec=0.001)
        return fut.result()

    clients, rows = {}, []
    call(SetBool, "/cloth_sim/pause", SetBool.Request(data=True))
    sim = load_scene(SHEET).build_simulator(rows=size, cols=size, spacing=1.0 / (size - 1))
    sim.step(100)
    t = time.perf_counter()
    sim.step(1000)
    local = 1000 / (time.perf_counter() - t)
    for chunk in chunks:
        call(Step, "/cloth_sim/step", Step.Request(steps=chunk))  # warm-up
        t = time.perf_counter()
        for _ in range(calls):
            res = call(Step, "/cloth_sim/step", Step.Request(steps=chunk))
            assert res.success, res.message
        wall = time.perf_counter() - t
        rows.append(
            {"steps": chunk, "calls_per_s": calls / wall, "steps_per_s": calls * chunk / wall}
        )
        print(
            f"| {chunk} | {calls / wall:.0f} | {calls * chunk / wall:.0f} | "
            f"{calls * chunk / wall / local:.2f} |",
            flush=True,
        )
    return rows


def print_startup_table(trials: int = 4, sizes=(32, 64)) -> list[dict]:
    """Seconds from starting ``cloth_sim_node`` (a new process, the default scene resized to N×N)
    to the first ``~/points`` cloud a subscriber in this process receives: interpreter, rclpy,
    numba's cached kernels (:func:`~cloth_sim.kernels.compile_kernels`), the stability analysis,
    DDS discovery. The first trial also warms the OS's file cache; the median of the rest is
    printed."""
    import statistics

    domain = _bench_domain()
    print(
        f"# start-up: process start to the first ~/points cloud; {platform.machine()}, "
        f"{os.cpu_count()} cores; median of {max(1, trials - 1)} after one warm-up"
    )
    print("| N | seconds to first cloud (median) | all trials |")
    print("|---|---|---|")
    rows = []
    with _remote_client(domain, "startup_bench") as (probe, ex):
        got: list[float] = []
        probe.create_subscription(
            PointCloud2, "/cloth_sim/points", lambda _: got.append(time.monotonic()), 10
        )
        for n in sizes:
            times = []
            for _ in range(trials):
                t0 = time.monotonic()
                node = _start_node(domain, n)
                got.clear()
                while not got and time.monotonic() - t0 < 60:
                    ex.spin_once(timeout_sec=0.01)
                times.append(got[0] - t0 if got else float("nan"))
                node.terminate()
                node.wait()
                drain = time.monotonic() + 1.0  # a cloud still in flight from this node
                while time.monotonic() < drain:
                    ex.spin_once(timeout_sec=0.05)
            kept = times[1:] or times
            rows.append({"n": n, "median_s": statistics.median(kept), "trials_s": times})
            print(
                f"| {n} | {statistics.median(kept):.2f} | {', '.join(f'{t:.2f}' for t in times)} |"
            )
    return rows


#: the camera's topics, by type, as a ROS user subscribes to them
CAMERA_TOPICS = (
    ("Image", "/cloth_sim/camera/depth/image"),
    ("CameraInfo", "/cloth_sim/camera/depth/camera_info"),
    ("PointCloud2", "/cloth_sim/camera/points"),
    ("Image", "/cloth_sim/camera/labels"),
    ("Image", "/cloth_sim/camera/triangles"),
)


def print_camera_node_table(
    size: int = 32,
    seconds: float = 10.0,
    width: int = 640,
    height: int = 480,
    camera_rate: float = 30.0,
) -> list[dict]:
    """The node's real-time factor with the depth camera on (``width``×``height`` at
    ``camera_rate``), its topics unsubscribed and all five subscribed: ``cloth_sim_node`` in its
    own process (the ``size``×``size`` :data:`SHEET` scene, the camera at (0.5, −0.8, 0.6) looking
    at the cloth), this process subscribing as a viewer in another process does (raw: it counts the
    messages without deserialising them) and reading ~/stats. The real-time factor is simulated
    time over wall time between the first and last ~/stats received in each window."""
    from sensor_msgs import msg as sensor_msgs

    from cloth_sim.msg import Stats

    domain = _bench_domain()
    params = [
        "camera.enable:=true",
        f"camera.width:={width}",
        f"camera.height:={height}",
        f"camera.rate:={camera_rate}",
        "camera.position:=[0.5, -0.8, 0.6]",
        "camera.look_at:=[0.5, 0.5, -0.4]",
    ]
    print(
        f"# cloth_sim_node in its own process, {SHEET} scene {size}×{size}, symplectic Euler, "
        f"dt = 1 ms, 60 Hz; depth camera {width}×{height} at {camera_rate:g} Hz; {seconds:g} s "
        "per "
        f"row after 3 s warm-up; {platform.machine()}, {os.cpu_count()} cores"
    )
    print(
        "| camera topics subscribed | real-time factor | camera frames/s received | MB/s received "
        "|"
    )
    print("|---|---|---|---|")
    node = _start_node(domain, size, params)
    rows = []
    try:
        with _remote_client(domain, "camera_bench") as (probe, ex):
            stats: list = []
            probe.create_subscription(
                Stats,
                "/cloth_sim/stats",
                lambda m: stats.append((time.monotonic(), m.sim_time)),
                100,
            )
            got = {"n": 0, "bytes": 0}

            def count(raw):
                got["n"] += 1
                got["bytes"] += len(raw)

            def window(secs):
                stats.clear()
                got["n"] = got["bytes"] = 0
                end = time.monotonic() + secs
                while time.monotonic() < end:
                    ex.spin_once(timeout_sec=0.01)
                (w0, s0), (w1, s1) = stats[0], stats[-1]
                return (s1 - s0) / (w1 - w0)

            end = time.monotonic() + 60
            while not stats and time.monotonic() < end:  # the node's start-up
                ex.spin_once(timeout_sec=0.05)
            window(3.0)
            for subscribed in (False, True):
                if subscribed:
                    for kind, topic in CAMERA_TOPICS:
                        probe.create_subscription(
                            getattr(sensor_msgs, kind), topic, count, 10, raw=True
                        )
                    window(3.0)  # discovery, first frames
                rtf = window(seconds)
                frames = got["n"] / len(CAMERA_TOPICS) / seconds
                rows.append(
                    {
                        "subscribed": subscribed,
                        "rtf": rtf,
                        "frames_per_s": frames,
                        "mb_per_s": got["bytes"] / seconds / 1e6,
                    }
                )
                print(
                    f"| {'all five' if subscribed else 'none'} | {rtf:.3f} | {frames:.1f} | "
                    f"{got['bytes'] / seconds / 1e6:.0f} |",
                    flush=True,
                )
    finally:
        node.terminate()
        node.wait(timeout=20)
    return rows
