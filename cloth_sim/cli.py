"""The ``cloth-sim`` command line.

``cloth-sim run [--scene NAME|FILE] [--duration S] [--integrator NAME] [--dt S]``
    Simulate a scene headless and print one summary line per simulated second.
``cloth-sim bench steps [--sizes 32 64 128] [--integrators ...]``
    Print ms/step of integrators on the hanging cloth at several grid sizes.
``cloth-sim bench implicit [--sizes 32 64] [--dt 0.016667]``
    Print ms/step of the implicit methods at a large step, CG vs direct solve, CG iterations.
``cloth-sim bench blowup [--size 32]``
    Print how long a step that diverges holds the caller (guard, restore, message), per integrator.
``cloth-sim bench params [--size 32] [--rate 60]``
    Print the ~/stats gap while a 26-parameter file is loaded the way `ros2 param load` does (needs rclpy).
``cloth-sim bench node [--sizes 32 64] [--seconds 10]`` (or ``--scene tshirt``, or ``--scene hanging
drape … --grid 64``)

``cloth-sim bench peers [--sizes 32 64 128] [--rounds 9]`` (NVIDIA Warp's CPU cloth kernel beside ours)
``cloth-sim bench vbd-peers [--sizes 32 64] [--device cpu]`` (Newton's VBD beside ours, and its cloth twist)
``cloth-sim bench flex-peer [--size 32]`` (MuJoCo's flex cloth beside ours on the drape scene)

``cloth-sim bench strain [--sizes 32 64] [--seconds 3]`` (worst strain and cost of the strain limit)
``cloth-sim bench contacts [--sizes 32 64] [--seconds 1.5]`` (cost of colliders and self-collision)
``cloth-sim bench camera [--size 32] [--seconds 10]`` (the node's real-time factor, camera topics subscribed)
``cloth-sim bench lockstep [--size 32]`` (steps per second through ~/step from another process)
``cloth-sim bench startup [--sizes 32 64] [--trials 4]`` (process start to the first cloud)
    Print the node's real-time factor with and without a ~/points subscriber (needs rclpy).
``cloth-sim record -o BAG [TOPIC ...]``, ``play BAG``, ``info BAG``, ``reindex BAG``
    rosbag2-compatible MCAP bags: record the ROS graph, replay it, inspect it, repair an unclosed bag.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from . import integrators
from .bag.store import BagError
from .model import STRAIN_LIMIT_METHODS
from .parameters import SCHEMA
from .scene import SceneError, load_scene
from .simulator import SimulationDiverged


def _run(args) -> int:
    scene = load_scene(args.scene)
    if args.integrator:
        scene.integrator = args.integrator
    if args.dt is not None:
        scene.dt = args.dt
    sim = scene.build_simulator()
    cloth = (f"{scene.rows}×{scene.cols}" if scene.mesh is None else
             f"mesh {scene.mesh['file'].name} ({sim.model.n_particles} vertices)")
    print(f"scene {scene.name} ({scene.source}): {cloth} {scene.model}, "
          f"{sim.integrator}, dt={sim.dt:g} s, stable_dt={sim.stable_dt():.4g} s, "
          f"terms: {', '.join(sim.active_terms)}", flush=True)
    t_wall = time.perf_counter()
    # a line per simulated second, and one at the end of a duration that is not a whole number
    ends = [float(k) for k in range(1, int(args.duration) + 1)]
    if not ends or ends[-1] < args.duration:
        ends.append(float(args.duration))
    for end in ends:
        start = time.perf_counter()
        try:
            n = sim.advance(end)
        except SimulationDiverged as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
        wall = time.perf_counter() - start
        e = sim.energy()
        print(f"t={sim.time:6.2f} s  {sim.integrator}  dt={sim.dt:g}  max_strain={sim.max_strain():+.4f}  "
              f"E_kin={e['kinetic']:.4f} J  E_spring={e['spring']:.4f} J  E_grav={e['gravity']:.4f} J  "
              f"({1e3 * wall / max(n, 1):.3f} ms/step)", flush=True)
    print(f"done: {sim.steps_taken} steps in {time.perf_counter() - t_wall:.2f} s wall")
    return 0


def _bench_steps(args) -> int:
    from .bench.steps import print_step_table
    print_step_table(args.sizes, args.integrators, args.seconds)
    return 0


def _bench_implicit(args) -> int:
    from .bench.steps import print_implicit_table
    print_implicit_table(args.sizes, args.dt, args.seconds)
    return 0


def _bench_blowup(args) -> int:
    from .bench.steps import print_blowup_table
    print_blowup_table(args.size)
    return 0


def _bench_params(args) -> int:
    from .ros.bench import print_param_load_table
    print_param_load_table(args.size, args.rate)
    return 0


def _bench_node(args) -> int:
    from .ros.bench import print_grid_scene_table, print_node_table, print_scene_node_table
    if args.scene:
        if args.grid is not None:
            print_grid_scene_table(args.scene, args.grid, args.seconds, args.rate)
            return 0
        for scene in args.scene:
            print_scene_node_table(scene, args.seconds, args.rate)
        return 0
    print_node_table(args.sizes, args.seconds, args.integrator, args.dt, args.rate,
                     args.strain_limit_passes, args.stiffness,
                     (True,) if args.subscribed_only else (False, True), args.strain_limit_method)
    return 0


def _bench_camera(args) -> int:
    from .ros.bench import print_camera_node_table

    print_camera_node_table(args.size, args.seconds, args.width, args.height, args.camera_rate)
    return 0


def _bench_lockstep(args) -> int:
    from .ros.bench import print_lockstep_table

    print_lockstep_table(args.size, args.calls)
    return 0


def _bench_startup(args) -> int:
    from .ros.bench import print_startup_table

    print_startup_table(args.trials, tuple(args.sizes))
    return 0


def _bench_contacts(args) -> int:
    from .bench.steps import print_contacts_table

    print_contacts_table(tuple(args.sizes), args.seconds)
    return 0


def _bench_strain(args) -> int:
    from .bench.steps import print_strain_limit_table

    print_strain_limit_table(tuple(args.sizes), args.seconds)
    return 0


def _bench_threading(args) -> int:
    from .bench.threading_layers import print_table

    print_table(args.size, args.seconds, args.rounds)
    return 0


def _bench_peers(args) -> int:
    from .bench.peers import print_peer_table

    return print_peer_table(tuple(args.sizes), rounds=args.rounds)


def _bench_vbd_peers(args) -> int:
    from .bench.vbd_peers import print_vbd_peer_table

    return print_vbd_peer_table(tuple(args.sizes), args.seconds, args.twist_seconds, args.device)


def _bench_flex_peer(args) -> int:
    from .bench.flex_peer import print_flex_table

    return print_flex_table(args.size, args.seconds)


def _bench_record(args) -> int:
    from .bag.bench import print_record_table
    print_record_table(args.size, args.rate, args.seconds)
    return 0


def _bench_suite(args) -> int:
    import importlib
    from pathlib import Path
    module = importlib.import_module(f".bench.{args.bench.replace('-', '_')}", __package__)
    module.main(Path(args.out or f"bench_out/{args.bench}"), quick=args.quick)
    return 0


def _record(args) -> int:
    from .bag.record import main as record_main
    return record_main(args)


def _play(args) -> int:
    if not args.delay >= 0:
        raise BagError(f"--delay must be ≥ 0 s, got {args.delay}")
    if not args.wait_for_all_acked >= 0:
        raise BagError(f"--wait-for-all-acked must be ≥ 0 s, got {args.wait_for_all_acked}")
    from .bag.play import main as play_main
    return play_main(args)


def _info(args) -> int:
    from .bag.store import bag_info, format_info
    print(format_info(bag_info(args.bag)))
    return 0


def _reindex(args) -> int:
    from .bag.store import reindex
    for line in reindex(args.bag):
        print(line)
    return 0


def _schema_value(name: str, parse):
    """An argparse type that parses with ``parse`` and checks against the schema's ``name``."""
    spec = SCHEMA[name]

    def convert(text: str):
        try:
            return spec.check(parse(text))
        except (ValueError, TypeError):
            raise argparse.ArgumentTypeError(f"{name} = {text!r} is not accepted: expected "
                                             f"{spec.range_text()}") from None

    return convert


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cloth-sim", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="simulate a scene headless, one line per simulated second")
    r.add_argument("--scene", default="hanging", help="scene name or YAML file (default: hanging)")
    r.add_argument("--duration", type=float, default=5.0, help="simulated seconds (default 5)")
    r.add_argument("--integrator", type=_schema_value("integrator", str),
                   help=SCHEMA["integrator"].range_text())
    r.add_argument("--dt", type=_schema_value("dt", float), help=SCHEMA["dt"].range_text())
    r.set_defaults(func=_run)
    b = sub.add_parser("bench", help="benchmarks")
    bsub = b.add_subparsers(dest="bench", required=True)
    s = bsub.add_parser("steps", help="ms/step per integrator and grid size on the hanging cloth")
    s.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    s.add_argument("--integrators", nargs="+", default=["symplectic_euler", "rk4"],
                   choices=integrators.available())
    s.add_argument("--seconds", type=float, default=1.0, help="wall time per measurement")
    s.set_defaults(func=_bench_steps)
    i = bsub.add_parser("implicit", help="ms/step of the implicit methods, CG vs direct, CG iterations")
    i.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    i.add_argument("--dt", type=float, default=1.0 / 60, help="time step (default 1/60 s)")
    i.add_argument("--seconds", type=float, default=1.0, help="wall time per measurement")
    i.set_defaults(func=_bench_implicit)
    sl = bsub.add_parser("strain", help="worst strain and cost of the strain limit on the hanging scene")
    sl.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    sl.add_argument("--seconds", type=float, default=3.0, help="simulated time per run")
    sl.set_defaults(func=_bench_strain)
    ct = bsub.add_parser("contacts", help="cost of colliders and self-collision on the hanging scene")
    ct.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    ct.add_argument("--seconds", type=float, default=1.5, help="simulated time per run")
    ct.set_defaults(func=_bench_contacts)
    th = bsub.add_parser("threading", help="ms/step of the hanging cloth under each of numba's threading "
                                           "layers (OpenMP, TBB, workqueue), each in its own process")
    th.add_argument("--size", type=int, default=64)
    th.add_argument("--seconds", type=float, default=0.5, help="simulated time per run")
    th.add_argument("--rounds", type=int, default=3, help="rounds the layers take turns (median)")
    th.set_defaults(func=_bench_threading)
    pp = bsub.add_parser("peers", help="NVIDIA Warp's CPU cloth kernel beside symplectic Euler and RK4 "
                                      "(needs the optional warp-lang: make bench-peers)")
    pp.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    pp.add_argument("--rounds", type=int, default=9, help="alternating bursts per size (median)")
    pp.set_defaults(func=_bench_peers)
    vp = bsub.add_parser("vbd-peers", help="Newton's SolverVBD beside vbd: the hanging cloth's springs, "
                                          "and Newton's cloth twist (needs the optional newton: make "
                                          "bench-peers)")
    vp.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    vp.add_argument("--seconds", type=float, default=2.0, help="simulated time of the hanging runs")
    vp.add_argument("--twist-seconds", type=float, default=5.0,
                    help="simulated time of the twist (Newton's example runs 300 frames: 5 s); 0: none")
    vp.add_argument("--device", default="cpu", help="Warp device of Newton's side (cpu, cuda:0)")
    vp.set_defaults(func=_bench_vbd_peers)
    fp = bsub.add_parser("flex-peer", help="MuJoCo's flex cloth beside cloth_sim on the drape scene "
                                          "(needs the optional mujoco: make bench-peers)")
    fp.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    fp.add_argument("--seconds", type=float, default=2.0, help="simulated time per run")
    fp.set_defaults(func=_bench_flex_peer)
    bb = bsub.add_parser("blowup", help="how long a diverging step holds the caller, per integrator")
    bb.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    bb.set_defaults(func=_bench_blowup)
    bp = bsub.add_parser("params", help="~/stats gaps while `ros2 param load` sets 26 parameters (needs rclpy)")
    bp.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    bp.add_argument("--rate", type=float, default=60.0, help="publish_rate (Hz, default 60)")
    bp.set_defaults(func=_bench_params)
    nb = bsub.add_parser("node", help="real-time factor of cloth_sim_node (needs rclpy)")
    nb.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    nb.add_argument("--scene", default=None, nargs="+",
                    help="scenes as they ship (e.g. tshirt): self-collision off and on, instead of the "
                    "hanging scene at --sizes; with --grid N, each grid scene as the node runs it under "
                    "-p rows:=N -p cols:=N")
    nb.add_argument("--grid", type=int, default=None, help="with --scene: rows and cols of the grid "
                    "scenes (their spacing and particle mass kept: a larger cloth)")
    nb.add_argument("--seconds", type=float, default=10.0, help="measured wall time per row")
    nb.add_argument("--integrator", default="symplectic_euler", choices=integrators.available())
    nb.add_argument("--dt", type=float, default=1e-3)
    nb.add_argument("--rate", type=float, default=60.0, help="publish_rate (Hz)")
    nb.add_argument("--strain-limit-passes", type=int, default=None,
                    help="the node's strain_limit_passes (default: its own, 20)")
    nb.add_argument("--strain-limit-method", default=None, choices=STRAIN_LIMIT_METHODS,
                    help="the node's strain_limit_method (default: the scene's, projection)")
    nb.add_argument("--stiffness", type=float, default=None,
                    help="structural and shear stiffness, N/m (default: the scene's, 1000)")
    nb.add_argument("--subscribed-only", action="store_true",
                    help="only the rows with ~/points and ~/mesh subscribed")
    nb.set_defaults(func=_bench_node)
    cb = bsub.add_parser("camera", help="real-time factor of cloth_sim_node with its depth camera "
                         "unsubscribed and subscribed (needs rclpy)")
    cb.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    cb.add_argument("--seconds", type=float, default=10.0, help="measured wall time per row")
    cb.add_argument("--width", type=int, default=640)
    cb.add_argument("--height", type=int, default=480)
    cb.add_argument("--camera-rate", type=float, default=30.0, help="camera.rate (Hz, default 30)")
    cb.set_defaults(func=_bench_camera)
    ls = bsub.add_parser("lockstep", help="steps per second through ~/step from another process (needs rclpy)")
    ls.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    ls.add_argument("--calls", type=int, default=300, help="~/step calls per row")
    ls.set_defaults(func=_bench_lockstep)
    su = bsub.add_parser("startup", help="seconds from starting cloth_sim_node to its first cloud (needs rclpy)")
    su.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    su.add_argument("--trials", type=int, default=4, help="node starts per size (the first warms up)")
    su.set_defaults(func=_bench_startup)
    for name, text in [("work-precision", "wall time against error on hang16, reference DOP853; table, CSV, plot"),
                       ("stability", "largest stable dt by bisection vs linear theory; stress scenarios"),
                       ("scaling", "ms/step against N, fitted exponents; what skipping unused terms buys")]:
        sp = bsub.add_parser(name, help=text)
        sp.add_argument("--out", metavar="DIR", help=f"output folder (default bench_out/{name})")
        sp.add_argument("--quick", action="store_true", help="a short run (CI)")
        sp.set_defaults(func=_bench_suite)
    br = bsub.add_parser("record", help="write throughput of `cloth-sim record` against a running node")
    br.add_argument("--size", type=int, default=64, help="cloth N×N (default 64)")
    br.add_argument("--rate", type=float, default=60.0, help="the node's publish_rate (Hz, default 60)")
    br.add_argument("--seconds", type=float, default=10.0, help="recorded wall time")
    br.set_defaults(func=_bench_record)

    rec = sub.add_parser("record", help="record topics into a rosbag2 (MCAP) bag, like `ros2 bag record`")
    rec.add_argument("topics", nargs="*", metavar="TOPIC",
                     help="topics to record (default: /cloth_sim/points /cloth_sim/stats /diagnostics "
                          "/parameter_events)")
    rec.add_argument("-o", "--output", metavar="BAG", help="bag directory to create (default: rosbag2_<date>)")
    rec.add_argument("-a", "--all", action="store_true", help="record every topic (except /rosout)")
    rec.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    rec.add_argument("--max-messages", type=int, metavar="N", help="stop after N messages")
    rec.add_argument("--overwrite", action="store_true", help="replace an existing bag directory")
    rec.set_defaults(func=_record)
    pl = sub.add_parser("play", help="replay a bag's messages with their recorded timing and QoS")
    pl.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    pl.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    pl.add_argument("--loop", action="store_true", help="play again from the start when done")
    pl.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics")
    pl.add_argument("--start-offset", type=float, default=0.0, metavar="S",
                    help="skip the first S seconds of the bag")
    pl.add_argument("--delay", type=float, default=0.0, metavar="S",
                    help="wait S seconds after creating the publishers (lets subscribers connect)")
    pl.add_argument("--wait-for-all-acked", type=float, default=5.0, metavar="S",
                    help="at the end, wait up to S seconds for reliable subscribers to acknowledge (default 5)")
    pl.set_defaults(func=_play)
    inf = sub.add_parser("info", help="topics, types, counts, duration and size of a bag, like `ros2 bag info`")
    inf.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    inf.set_defaults(func=_info)
    sw = sub.add_parser("sweep", help="run every run of a sweep spec on Ray (a local one, or a cluster "
                        "with --address) into OUT: runs.parquet and a bag per run; again to resume",
                        description="Run a sweep spec (see docs/sweeps/ and the README): each run "
                        "headless on Ray, OUT/runs/<run>/ a bag of its frames, OUT/runs.parquet one "
                        "row per run. The same command again resumes an interrupted sweep.")
    sw.add_argument("spec", metavar="SPEC.yaml", nargs="?", help="the sweep spec")
    sw.add_argument("-o", "--output", metavar="OUT", help="output directory (local or shared path)")
    sw.add_argument("--workers", type=int, default=None, metavar="N",
                    help="runs at a time (default: every CPU of this machine or the cluster)")
    sw.add_argument("--address", default=None, metavar="ADDRESS",
                    help="join this Ray cluster (e.g. 10.0.0.5:6379, or auto) instead of starting one")
    sw.add_argument("--summary", metavar="OUT", help="print counts by status and the slowest runs of "
                    "the sweep in OUT, and run nothing")
    sw.add_argument("--no-progress", action="store_true", help="no progress bar")
    sw.set_defaults(func=_sweep)
    ri = sub.add_parser("reindex", help="make a bag whose recorder died whole again (MCAP summary, metadata.yaml)")
    ri.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    ri.set_defaults(func=_reindex)
    return p


def _sweep(args) -> int:
    from .sweep import engine

    if args.summary:
        print(engine.summary(args.summary))
        return 0
    if not args.spec or not args.output:
        raise ValueError("sweep needs SPEC.yaml and -o OUT (or --summary OUT)")
    t = time.perf_counter()
    counts = engine.sweep(args.spec, args.output, workers=args.workers, address=args.address,
                          progress=not args.no_progress)
    total = sum(counts.values())
    print(f"sweep {args.output}: {total} runs, " + ", ".join(
        f"{counts[s]} {s}" for s in ("ok", "unstable", "diverged", "refused", "failed")
        if counts[s] or s == "ok")
        + f"; {time.perf_counter() - t:.1f} s; {Path(args.output) / 'runs.parquet'}")
    return 0


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except BagError as e:
        print(f"cloth-sim: error: {e}", file=sys.stderr)
        return 1
    except (SceneError, ValueError) as e:
        print(f"cloth-sim: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
