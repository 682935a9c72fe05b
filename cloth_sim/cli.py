"""The ``cloth-sim`` command line.

``cloth-sim run [--scene NAME|FILE] [--duration S] [--integrator NAME] [--dt S]``
    Simulate a scene headless and print one summary line per simulated second.
``cloth-sim bench steps [--sizes 32 64 128] [--integrators ...]``
    Print ms/step of integrators on the hanging_provot cloth at several grid sizes.
``cloth-sim bench implicit [--sizes 32 64] [--dt 0.016667]``
    Print ms/step of the implicit methods at a large step, CG vs direct solve, CG iterations.
``cloth-sim bench blowup [--size 32]``
    Print how long a step that diverges holds the caller (guard, restore, message), per integrator.
``cloth-sim bench params [--size 32] [--rate 60]``
    Print the ~/stats gap while a 26-parameter file is loaded the way `ros2 param load` does (needs
    rclpy).
``cloth-sim bench node [--sizes 32 64] [--seconds 10]`` (or ``--scene tshirt``, or ``--scene
hanging drape … --grid 64``)

``cloth-sim bench peers [--sizes 32 64 128] [--rounds 9]`` (NVIDIA Warp's CPU cloth kernel beside
ours) ``cloth-sim bench vbd-peers [--sizes 32 64] [--device cpu]`` (Newton's VBD beside ours, and
its cloth twist) ``cloth-sim bench franka-peer [--frames 480]`` (Newton's Franka folding its shirt,
beside ours) ``cloth-sim bench flex-peer [--size 32]`` (MuJoCo's flex cloth beside ours on the
drape scene)

``cloth-sim bench strain [--sizes 32 64] [--seconds 3]`` (worst strain and cost of the strain
limit) ``cloth-sim bench contacts [--sizes 32 64] [--seconds 1.5]`` (cost of colliders and
self-collision; ``--scene tshirt`` the garments as they ship) ``cloth-sim bench camera [--size
32] [--seconds 10]`` (the node's real-time factor, camera topics subscribed) ``cloth-sim bench
lockstep [--size 32]`` (steps per second through ~/step from another process) ``cloth-sim bench
startup [--sizes 32 64] [--trials 4]`` (process start to the first cloud)
    Print the node's real-time factor with and without a ~/points subscriber (needs rclpy).
``cloth-sim textile cantilever|tensile|drape [--material NAME ...] [--grid N ...]``
    The textile standard tests on the simulator, each measured value beside the expected one.
``cloth-sim fit BAG --scene SCENE --params NAME[,NAME…] -o OUT [--workers N] [--address A]``
    Fit a scene's material to a recorded point-cloud sequence; write the scene with the result.
``cloth-sim record -o BAG [TOPIC ...]``, ``play BAG``, ``info BAG``, ``reindex BAG``
    rosbag2-compatible MCAP bags: record the ROS graph, replay it, inspect it, repair an unclosed
    bag.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .bag.store import BagError
from .bench.cli import add_parser as add_bench_parser
from .bench.textile import add_parser as add_textile_parser
from .parameters import SCHEMA
from .scene import SceneError, load_scene
from .simulator import SimulationDiverged
from .sweep.fit import add_parser as add_fit_parser


def _run(args) -> int:
    scene = load_scene(args.scene)
    if args.integrator:
        scene.integrator = args.integrator
    if args.dt is not None:
        scene.dt = args.dt
    sim = scene.build_simulator()
    cloth = (
        f"{scene.rows}×{scene.cols}"
        if scene.mesh is None
        else f"mesh {scene.mesh['file'].name} ({sim.model.n_particles} vertices)"
    )
    print(
        f"scene {scene.name} ({scene.source}): {cloth} {scene.model}, "
        f"{sim.integrator}, dt={sim.dt:g} s, stable_dt={sim.stable_dt():.4g} s, "
        f"terms: {', '.join(sim.active_terms)}",
        flush=True,
    )
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
        print(
            f"t={sim.time:6.2f} s  {sim.integrator}  dt={sim.dt:g}  "
            f"max_strain={sim.max_strain():+.4f}  "
            f"E_kin={e['kinetic']:.4f} J  E_spring={e['spring']:.4f} J  E_grav={e['gravity']:.4f} "
            "J  "
            f"({1e3 * wall / max(n, 1):.3f} ms/step)",
            flush=True,
        )
    print(f"done: {sim.steps_taken} steps in {time.perf_counter() - t_wall:.2f} s wall")
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
            raise argparse.ArgumentTypeError(
                f"{name} = {text!r} is not accepted: expected {spec.range_text()}"
            ) from None

    return convert


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cloth-sim", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="simulate a scene headless, one line per simulated second")
    r.add_argument("--scene", default="hanging", help="scene name or YAML file (default: hanging)")
    r.add_argument("--duration", type=float, default=5.0, help="simulated seconds (default 5)")
    r.add_argument(
        "--integrator",
        type=_schema_value("integrator", str),
        help=SCHEMA["integrator"].range_text(),
    )
    r.add_argument("--dt", type=_schema_value("dt", float), help=SCHEMA["dt"].range_text())
    r.set_defaults(func=_run)
    add_bench_parser(sub)
    add_textile_parser(sub)
    add_fit_parser(sub)

    rec = sub.add_parser(
        "record", help="record topics into a rosbag2 (MCAP) bag, like `ros2 bag record`"
    )
    rec.add_argument(
        "topics",
        nargs="*",
        metavar="TOPIC",
        help="topics to record (default: /cloth_sim/points /cloth_sim/stats /diagnostics "
        "/parameter_events)",
    )
    rec.add_argument(
        "-o", "--output", metavar="BAG", help="bag directory to create (default: rosbag2_<date>)"
    )
    rec.add_argument(
        "-a", "--all", action="store_true", help="record every topic (except /rosout)"
    )
    rec.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    rec.add_argument("--max-messages", type=int, metavar="N", help="stop after N messages")
    rec.add_argument("--overwrite", action="store_true", help="replace an existing bag directory")
    rec.set_defaults(func=_record)
    pl = sub.add_parser("play", help="replay a bag's messages with their recorded timing and QoS")
    pl.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    pl.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    pl.add_argument("--loop", action="store_true", help="play again from the start when done")
    pl.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics")
    pl.add_argument(
        "--start-offset",
        type=float,
        default=0.0,
        metavar="S",
        help="skip the first S seconds of the bag",
    )
    pl.add_argument(
        "--delay",
        type=float,
        default=0.0,
        metavar="S",
        help="wait S seconds after creating the publishers (lets subscribers connect)",
    )
    pl.add_argument(
        "--wait-for-subscribers",
        action="store_true",
        help="before playing (and before --delay), wait until every topic has a subscriber",
    )
    pl.add_argument(
        "--wait-for-all-acked",
        type=float,
        default=5.0,
        metavar="S",
        help="at the end, wait up to S seconds for reliable subscribers to acknowledge "
        "(default 5)",
    )
    pl.set_defaults(func=_play)
    inf = sub.add_parser(
        "info", help="topics, types, counts, duration and size of a bag, like `ros2 bag info`"
    )
    inf.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    inf.set_defaults(func=_info)
    sw = sub.add_parser(
        "sweep",
        help="run every run of a sweep spec on Ray (a local one, or a cluster "
        "with --address) into OUT: runs.parquet and a bag per run; again to resume",
        description="Run a sweep spec (see docs/sweeps/ and the README): each run "
        "headless on Ray, OUT/runs/<run>/ a bag of its frames, OUT/runs.parquet one "
        "row per run. The same command again resumes an interrupted sweep.",
    )
    sw.add_argument("spec", metavar="SPEC.yaml", nargs="?", help="the sweep spec")
    sw.add_argument(
        "-o", "--output", metavar="OUT", help="output directory (local or shared path)"
    )
    sw.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="runs at a time (default: every CPU of this machine or the cluster)",
    )
    sw.add_argument(
        "--address",
        default=None,
        metavar="ADDRESS",
        help="join this Ray cluster (e.g. 10.0.0.5:6379, or auto) instead of starting one",
    )
    sw.add_argument(
        "--summary",
        metavar="OUT",
        help="print counts by status and the slowest runs of the sweep in OUT, and run nothing",
    )
    sw.add_argument(
        "--format",
        choices=("bags", "lerobot"),
        default="bags",
        help="lerobot: also OUT/lerobot, a LeRobot dataset (v3.0) of the runs, an episode a run, "
        "the script's grippers its actions (the spec needs a script)",
    )
    sw.add_argument(
        "--overwrite", action="store_true", help="replace another dataset in OUT/lerobot"
    )
    sw.add_argument("--no-progress", action="store_true", help="no progress bar")
    sw.set_defaults(func=_sweep)
    ds = sub.add_parser(
        "dataset",
        help="episodes of a task under a policy, on Ray, written as a LeRobot dataset (v3.0) "
        "in DIR; again to resume",
        description="Write a LeRobotDataset v3.0 of a cloth_sim task (see the README's "
        "'Datasets'): observation.state (key points and pickers), action, the camera's colour "
        "and depth video, next.reward, next.done. The same command again resumes.",
    )
    ds.add_argument(
        "task", metavar="TASK", help="a task: TshirtFold, ClothFold, … or its id cloth_sim/…-v0"
    )
    ds.add_argument("-o", "--output", metavar="DIR", required=True, help="the dataset's root")
    ds.add_argument("--policy", default="scripted", help="scripted (default) or random")
    ds.add_argument("--episodes", type=int, default=50, metavar="N", help="default 50")
    ds.add_argument(
        "--observation",
        default="key_point",
        help="key_point (default), point_cloud or depth: the env's observation, kept lossless "
        "beside the key points and the videos",
    )
    ds.add_argument("--seed", type=int, default=0, metavar="S", help="default 0")
    ds.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="episodes at a time (default: every CPU of this machine or the cluster)",
    )
    ds.add_argument(
        "--address", default=None, metavar="ADDRESS", help="join this Ray cluster instead"
    )
    ds.add_argument(
        "--overwrite", action="store_true", help="replace a dataset DIR holds (of another command)"
    )
    ds.add_argument("--image-size", type=int, default=128, metavar="PX", help="default 128")
    ds.add_argument("--no-progress", action="store_true", help="no progress bar")
    ds.set_defaults(func=_dataset)
    ri = sub.add_parser(
        "reindex", help="make a bag whose recorder died whole again (MCAP summary, metadata.yaml)"
    )
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
    if args.format == "lerobot":  # refused before anything runs
        from .dataset import sweep_export
        from .sweep.spec import load_spec

        spec = load_spec(args.spec)
        sweep_export.check(spec)
    t = time.perf_counter()
    counts = engine.sweep(
        args.spec,
        args.output,
        workers=args.workers,
        address=args.address,
        progress=not args.no_progress,
    )
    total = sum(counts.values())
    print(
        f"sweep {args.output}: {total} runs, "
        + ", ".join(
            f"{counts[s]} {s}"
            for s in ("ok", "unstable", "diverged", "refused", "failed")
            if counts[s] or s == "ok"
        )
        + f"; {time.perf_counter() - t:.1f} s; {Path(args.output) / 'runs.parquet'}"
    )
    if args.format == "lerobot":
        writer = sweep_export.export(
            spec,
            args.output,
            workers=args.workers,
            address=args.address,
            overwrite=args.overwrite,
            progress=not args.no_progress,
        )
        print(
            f"dataset {writer.root}: {writer.episodes} episodes (the runs that ended ok), "
            f"{writer.info['total_frames']} frames at {writer.info['fps']:g} fps"
        )
    return 0


def _dataset(args) -> int:
    from .dataset import engine

    t = time.perf_counter()
    writer = engine.generate(
        args.task,
        args.output,
        policy=args.policy,
        episodes=args.episodes,
        observation=args.observation,
        seed=args.seed,
        workers=args.workers,
        address=args.address,
        overwrite=args.overwrite,
        image_size=args.image_size,
        progress=not args.no_progress,
    )
    info = writer.info
    print(
        f"dataset {args.output}: {info['total_episodes']} episodes, {info['total_frames']} "
        f"frames at {info['fps']:g} fps; {time.perf_counter() - t:.1f} s"
    )
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
