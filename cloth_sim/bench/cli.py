"""``cloth-sim bench …``: every benchmark's command line, over the modules of this package.

Each subcommand prints its figures (tables, ratios measured side by side in one process);
docs/BENCHMARKS.md reports them with the commands that gave them. Those that need rclpy, or an
optional peer (``make bench-peers``), say so in their help.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .. import integrators
from ..kinds import STRAIN_LIMIT_METHODS


def _bench_steps(args) -> int:
    from .steps import print_step_table

    print_step_table(args.sizes, args.integrators, args.seconds)
    return 0


def _bench_implicit(args) -> int:
    from .steps import print_implicit_table

    print_implicit_table(args.sizes, args.dt, args.seconds)
    return 0


def _bench_blowup(args) -> int:
    from .steps import print_blowup_table

    print_blowup_table(args.size)
    return 0


def _bench_params(args) -> int:
    from .node import print_param_load_table

    print_param_load_table(args.size, args.rate)
    return 0


def _bench_node(args) -> int:
    from .node import print_grid_scene_table, print_node_table, print_scene_node_table

    if args.scene:
        if args.grid is not None:
            print_grid_scene_table(
                args.scene,
                args.grid,
                args.seconds,
                args.rate,
                args.integrator,
                args.dt,
                args.material,
                args.size,
            )
            return 0
        for scene in args.scene:
            print_scene_node_table(scene, args.seconds, args.rate)
        return 0
    print_node_table(
        args.sizes,
        args.seconds,
        args.integrator or "symplectic_euler",
        1e-3 if args.dt is None else args.dt,
        args.rate,
        args.strain_limit_passes,
        args.stiffness,
        (True,) if args.subscribed_only else (False, True),
        args.strain_limit_method,
    )
    return 0


def _bench_camera(args) -> int:
    from .node import print_camera_node_table

    print_camera_node_table(args.size, args.seconds, args.width, args.height, args.camera_rate)
    return 0


def _bench_lockstep(args) -> int:
    from .node import print_lockstep_table

    print_lockstep_table(args.size, args.calls)
    return 0


def _bench_startup(args) -> int:
    from .node import print_startup_table

    print_startup_table(args.trials, tuple(args.sizes))
    return 0


def _bench_contacts(args) -> int:
    from .steps import print_contacts_table, print_garment_contacts_table

    if args.scene:
        print_garment_contacts_table(tuple(args.scene), args.seconds or 10.0)
    else:
        print_contacts_table(tuple(args.sizes), args.seconds or 1.5)
    return 0


def _bench_strain(args) -> int:
    from .steps import print_strain_limit_table

    print_strain_limit_table(tuple(args.sizes), args.seconds)
    return 0


def _bench_threading(args) -> int:
    from .threading_layers import print_table

    print_table(args.size, args.seconds, args.rounds)
    return 0


def _bench_peers(args) -> int:
    from .peers import print_peer_table

    return print_peer_table(tuple(args.sizes), rounds=args.rounds)


def _bench_vbd_peers(args) -> int:
    from .vbd_peers import print_vbd_peer_table

    return print_vbd_peer_table(tuple(args.sizes), args.seconds, args.twist_seconds, args.device)


def _steps_by_iterations(text: str) -> tuple[int, int]:
    """``'10x5'`` -> ``(10, 5)``: steps a frame by iterations a step, both at least 1."""
    try:
        steps, iterations = (int(v) for v in text.lower().split("x"))
    except ValueError:
        steps = iterations = 0
    if steps < 1 or iterations < 1:
        raise argparse.ArgumentTypeError(
            f"--ours {text!r}: expected STEPSxITERATIONS, two integers >= 1 (e.g. 10x5)"
        )
    return steps, iterations


def _bench_franka_peer(args) -> int:
    from .franka_peer import print_franka_table

    print_franka_table(args.frames, args.newton, tuple(args.ours))
    return 0


def _bench_vbd_floor(args) -> int:
    from .vbd_floor import print_vbd_floor_table

    print_vbd_floor_table(tuple(args.sizes))
    return 0


def _bench_compile(args) -> int:
    from .compile import print_compile_table

    print_compile_table(args.parts, args.top, args.side_by_side)
    return 0


def _bench_hashes(args) -> int:
    from .scene_hashes import print_scene_hashes

    print_scene_hashes(args.steps, args.scenes, args.fresh_cache)
    return 0


def _bench_convergence(args) -> int:
    from .convergence import (
        print_accuracy_table,
        print_convergence_table,
        print_rest_by_method,
        print_rest_table,
        work_precision,
    )

    if args.work_precision:
        work_precision(args.material.split(","), tuple(args.sizes), args.seconds or 2.0, args.out)
    elif args.rest and args.methods:
        methods = None if args.methods == "all" else args.methods.split(",")
        print_rest_by_method(
            args.material.split(","),
            tuple(args.sizes),
            methods,
            args.seconds or 10.0,
            args.strain_limit,
        )
    elif args.rest:
        print_rest_table(
            args.material.split(","), tuple(args.sizes), args.seconds or 10.0, args.strain_limit
        )
    elif args.accuracy:
        print_accuracy_table(args.material.split(","), tuple(args.sizes), args.seconds or 2.0)
    else:
        print_convergence_table(args.material, tuple(args.sizes), args.seconds or 1.0)
    return 0


def _bench_gpu(args) -> int:
    from .gpu import print_gpu_tables

    print_gpu_tables(tuple(args.sizes), tuple(args.worlds), args.seconds, args.simulator)
    return 0


def _bench_vector_env(args) -> int:
    from .vector_env import print_vector_table

    kw = {k: v for k, v in (("precision", args.precision), ("launch", args.launch)) if v}
    print_vector_table(args.device, tuple(args.envs), args.async_envs, args.steps, **kw)
    return 0


def _bench_flex_peer(args) -> int:
    from .flex_peer import print_flex_table

    return print_flex_table(args.size, args.seconds)


def _bench_record(args) -> int:
    from .bag import print_record_table

    print_record_table(args.size, args.rate, args.seconds)
    return 0


def _bench_suite(args) -> int:
    import importlib

    module = importlib.import_module(f".{args.bench.replace('-', '_')}", __package__)
    module.main(Path(args.out or f"bench_out/{args.bench}"), quick=args.quick)
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``bench`` subcommand and its own subcommands, on the ``cloth-sim`` parser's ``sub``."""
    b = sub.add_parser("bench", help="benchmarks")
    bsub = b.add_subparsers(dest="bench", required=True)
    s = bsub.add_parser(
        "steps", help="ms/step per integrator and grid size on the hanging_provot cloth"
    )
    s.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    s.add_argument(
        "--integrators",
        nargs="+",
        default=["symplectic_euler", "rk4"],
        choices=integrators.available(),
    )
    s.add_argument("--seconds", type=float, default=1.0, help="wall time per measurement")
    s.set_defaults(func=_bench_steps)
    i = bsub.add_parser(
        "implicit", help="ms/step of the implicit methods, CG vs direct, CG iterations"
    )
    i.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    i.add_argument("--dt", type=float, default=1.0 / 60, help="time step (default 1/60 s)")
    i.add_argument("--seconds", type=float, default=1.0, help="wall time per measurement")
    i.set_defaults(func=_bench_implicit)
    sl = bsub.add_parser(
        "strain", help="worst strain and cost of the strain limit on the hanging_provot scene"
    )
    sl.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    sl.add_argument("--seconds", type=float, default=3.0, help="simulated time per run")
    sl.set_defaults(func=_bench_strain)
    ct = bsub.add_parser(
        "contacts", help="cost of colliders and self-collision on the hanging_provot scene"
    )
    ct.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    ct.add_argument(
        "--seconds",
        type=float,
        default=None,
        help="simulated time per run (default 1.5; with --scene, 10 after 2 s of settling)",
    )
    ct.add_argument(
        "--scene",
        nargs="+",
        default=None,
        help="garment scenes as they ship (e.g. tshirt tshirt_on_body) instead of "
        "hanging_provot: self-contact off and on side by side, with the crossings counted",
    )
    ct.set_defaults(func=_bench_contacts)
    th = bsub.add_parser(
        "threading",
        help="ms/step of the hanging_provot cloth under each of numba's threading "
        "layers (OpenMP, TBB, workqueue), each in its own process",
    )
    th.add_argument("--size", type=int, default=64)
    th.add_argument("--seconds", type=float, default=0.5, help="simulated time per run")
    th.add_argument("--rounds", type=int, default=3, help="rounds the layers take turns (median)")
    th.set_defaults(func=_bench_threading)
    pp = bsub.add_parser(
        "peers",
        help="NVIDIA Warp's CPU cloth kernel beside symplectic Euler and RK4 "
        "(needs the optional warp-lang: make bench-peers)",
    )
    pp.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    pp.add_argument("--rounds", type=int, default=9, help="alternating bursts per size (median)")
    pp.set_defaults(func=_bench_peers)
    vp = bsub.add_parser(
        "vbd-peers",
        help="Newton's SolverVBD beside vbd: the hanging_provot cloth's springs, "
        "and Newton's cloth twist (needs the optional newton: make "
        "bench-peers)",
    )
    vp.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    vp.add_argument(
        "--seconds", type=float, default=2.0, help="simulated time of the hanging runs"
    )
    vp.add_argument(
        "--twist-seconds",
        type=float,
        default=5.0,
        help="simulated time of the twist (Newton's example runs 300 frames: 5 s); 0: none",
    )
    vp.add_argument("--device", default="cpu", help="Warp device of Newton's side (cpu, cuda:0)")
    vp.set_defaults(func=_bench_vbd_peers)
    fr = bsub.add_parser(
        "franka-peer",
        help="Newton's example_cloth_franka (its FR3, its shirt, its settings) beside cloth_sim "
        "on the CPU: time a frame, deepest inside a link, self-crossings (needs the optional "
        "newton and usd-core: make bench-peers)",
    )
    fr.add_argument(
        "--frames", type=int, default=480, help="1/60 s frames (480: to the arm's first grasp)"
    )
    fr.add_argument(
        "--newton",
        default=None,
        help="an .npz of Newton's run: read where it exists (its frames), else written there",
    )
    fr.add_argument(
        "--ours",
        type=_steps_by_iterations,
        nargs="+",
        default=[(10, 5)],
        metavar="STEPSxITERATIONS",
        help="cloth_sim's settings, a row each: vbd steps a frame x iterations a step "
        "(default 10x5: Newton's substeps and iterations)",
    )
    fr.set_defaults(func=_bench_franka_peer)
    vf = bsub.add_parser(
        "vbd-floor",
        help="vbd's cost per vertex and iteration on the grid against its memory-bandwidth floor",
    )
    vf.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    vf.set_defaults(func=_bench_vbd_floor)
    ck = bsub.add_parser(
        "compile",
        help="make install's kernel compilation from an empty cache: each part's seconds and its "
        "dearest kernels (numba's compile events)",
    )
    ck.add_argument(
        "--parts", nargs="+", default=None, help="compile_kernels' parts (default: all)"
    )
    ck.add_argument("--top", type=int, default=12, help="kernels listed per part (default 12)")
    ck.add_argument(
        "--side-by-side",
        action="store_true",
        help="the parts at once in one shared cache, as make install runs them",
    )
    ck.set_defaults(func=_bench_compile)
    hs = bsub.add_parser(
        "hashes",
        help="every shipped scene's state after a fixed run on its own integrator and on vbd, "
        "hashed: diff two runs to see that a change kept the same bits",
    )
    hs.add_argument("--steps", type=int, default=300, help="steps a scene (default 300)")
    hs.add_argument("--scenes", nargs="+", default=None, help="scene names (default: all)")
    hs.add_argument(
        "--fresh-cache",
        action="store_true",
        help="kernels compiled from the source into an empty cache first, as make install does "
        "on a fresh clone (about 3 minutes)",
    )
    hs.set_defaults(func=_bench_hashes)
    cv = bsub.add_parser(
        "convergence",
        help="vbd on a library fabric: iterations a step against its residual, and substeps "
        "against iterations at equal cost",
    )
    cv.add_argument(
        "--material", default="cotton", help="a library fabric, or several with --accuracy: a,b"
    )
    cv.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    cv.add_argument(
        "--seconds",
        type=float,
        default=None,
        help="simulated seconds a run (1; 2 with --accuracy)",
    )
    cv.add_argument(
        "--accuracy",
        action="store_true",
        help="vbd's defaults at 1/60 s against a fine-step reference (the solver issue's targets)",
    )
    cv.add_argument(
        "--rest",
        action="store_true",
        help="vbd's defaults at 1/60 s in air until the sheet is at rest: its free edge's height "
        "at each size (10 s at most)",
    )
    cv.add_argument(
        "--strain-limit",
        type=float,
        default=None,
        help="with --rest: the strain limit on (hanging ships 0.1, by projection), symplectic "
        "Euler's edge at rest beside vbd's",
    )
    cv.add_argument(
        "--methods",
        default=None,
        help="with --rest: these integrators (comma-separated, or 'all') each until at rest, "
        "instead of vbd at each size",
    )
    cv.add_argument(
        "--work-precision",
        action="store_true",
        help="each method at several amounts of work against the fine-step reference: wall time "
        "against the path's error, a table and a figure under --out",
    )
    cv.add_argument(
        "--out",
        type=Path,
        default=Path("docs/bench/convergence"),
        help="with --work-precision: where the table and figure go",
    )
    cv.set_defaults(func=_bench_convergence)
    gp = bsub.add_parser(
        "gpu",
        help="the CUDA backend on a GPU: the same cloth as the CPU, one large cloth's real-time "
        "factor, many worlds' world-seconds a second (needs numba-cuda and a GPU: make bench-gpu)",
    )
    gp.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    gp.add_argument("--worlds", type=int, nargs="+", default=[1, 16, 128, 1024, 4096, 16384])
    gp.add_argument("--seconds", type=float, default=2.0, help="simulated seconds a run")
    gp.add_argument(
        "--simulator",
        action="store_true",
        help="a tiny run on numba-cuda's simulator (NUMBA_ENABLE_CUDASIM=1): the script's check",
    )
    gp.set_defaults(func=_bench_gpu)
    ve = bsub.add_parser(
        "vector-env",
        help="ClothFold as one vector env (every world in one batch, cpu or cuda) beside "
        "Gymnasium's AsyncVectorEnv: env steps a second",
    )
    ve.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    ve.add_argument("--envs", type=int, nargs="+", default=[1, 2, 16], help="num_envs, a row each")
    ve.add_argument(
        "--async-envs",
        type=int,
        default=None,
        help="the AsyncVectorEnv's processes (default: the machine's cores)",
    )
    ve.add_argument("--steps", type=int, default=20, help="timed env steps a row")
    ve.add_argument("--precision", choices=["float32", "float64"], default=None)
    ve.add_argument("--launch", choices=["auto", "blocks", "grid", "stages"], default=None)
    ve.set_defaults(func=_bench_vector_env)
    fp = bsub.add_parser(
        "flex-peer",
        help="MuJoCo's flex cloth beside cloth_sim on the drape scene "
        "(needs the optional mujoco: make bench-peers)",
    )
    fp.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    fp.add_argument("--seconds", type=float, default=2.0, help="simulated time per run")
    fp.set_defaults(func=_bench_flex_peer)
    bb = bsub.add_parser(
        "blowup", help="how long a diverging step holds the caller, per integrator"
    )
    bb.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    bb.set_defaults(func=_bench_blowup)
    bp = bsub.add_parser(
        "params", help="~/stats gaps while `ros2 param load` sets 26 parameters (needs rclpy)"
    )
    bp.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    bp.add_argument("--rate", type=float, default=60.0, help="publish_rate (Hz, default 60)")
    bp.set_defaults(func=_bench_params)
    nb = bsub.add_parser("node", help="real-time factor of cloth_sim_node (needs rclpy)")
    nb.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    nb.add_argument(
        "--scene",
        default=None,
        nargs="+",
        help="scenes as they ship (e.g. tshirt): self-collision off and on, instead of the "
        "hanging_provot scene at --sizes; with --grid N, each grid scene as the node runs it "
        "under -p rows:=N -p cols:=N",
    )
    nb.add_argument(
        "--grid",
        type=int,
        default=None,
        help="with --scene: rows and cols of the grid scenes, as -p rows:=N -p cols:=N "
        "(one given by spacing and particle mass grows; one given by size and density, fold, "
        "is the same cloth finer)",
    )
    nb.add_argument("--seconds", type=float, default=10.0, help="measured wall time per row")
    nb.add_argument(
        "--integrator",
        default=None,
        choices=integrators.available(),
        help="the node's integrator (default: symplectic_euler; with --scene --grid, the scene's)",
    )
    nb.add_argument(
        "--dt",
        type=float,
        default=None,
        help="s (default: 0.001; with --scene --grid, the scene's)",
    )
    nb.add_argument(
        "--material",
        default=None,
        help="with --scene --grid: a library fabric for the cloth (-p material:=…), of --size",
    )
    nb.add_argument(
        "--size",
        type=float,
        nargs=2,
        default=None,
        metavar=("W", "H"),
        help="with --material: the cloth's size in m (default 1 1)",
    )
    nb.add_argument("--rate", type=float, default=60.0, help="publish_rate (Hz)")
    nb.add_argument(
        "--strain-limit-passes",
        type=int,
        default=None,
        help="the node's strain_limit_passes (default: its own, 20)",
    )
    nb.add_argument(
        "--strain-limit-method",
        default=None,
        choices=STRAIN_LIMIT_METHODS,
        help="the node's strain_limit_method (default: the scene's, projection)",
    )
    nb.add_argument(
        "--stiffness",
        type=float,
        default=None,
        help="structural and shear stiffness, N/m (default: the scene's, 1000)",
    )
    nb.add_argument(
        "--subscribed-only",
        action="store_true",
        help="only the rows with ~/points and ~/mesh subscribed",
    )
    nb.set_defaults(func=_bench_node)
    cb = bsub.add_parser(
        "camera",
        help="real-time factor of cloth_sim_node with its depth camera "
        "unsubscribed and subscribed (needs rclpy)",
    )
    cb.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    cb.add_argument("--seconds", type=float, default=10.0, help="measured wall time per row")
    cb.add_argument("--width", type=int, default=640)
    cb.add_argument("--height", type=int, default=480)
    cb.add_argument("--camera-rate", type=float, default=30.0, help="camera.rate (Hz, default 30)")
    cb.set_defaults(func=_bench_camera)
    ls = bsub.add_parser(
        "lockstep", help="steps per second through ~/step from another process (needs rclpy)"
    )
    ls.add_argument("--size", type=int, default=32, help="cloth N×N (default 32)")
    ls.add_argument("--calls", type=int, default=300, help="~/step calls per row")
    ls.set_defaults(func=_bench_lockstep)
    su = bsub.add_parser(
        "startup", help="seconds from starting cloth_sim_node to its first cloud (needs rclpy)"
    )
    su.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    su.add_argument(
        "--trials", type=int, default=4, help="node starts per size (the first warms up)"
    )
    su.set_defaults(func=_bench_startup)
    for name, text in [
        (
            "work-precision",
            "wall time against error on hang16, reference DOP853; table, CSV, plot",
        ),
        ("stability", "largest stable dt by bisection vs linear theory; stress scenarios"),
        ("scaling", "ms/step against N, fitted exponents; what skipping unused terms buys"),
        (
            "materials",
            "the textile tests on every library fabric at several resolutions, a material's "
            "cost a step, the fit to a noisy depth recording at 1 and 2 Ray workers",
        ),
    ]:
        sp = bsub.add_parser(name, help=text)
        sp.add_argument("--out", metavar="DIR", help=f"output folder (default bench_out/{name})")
        sp.add_argument("--quick", action="store_true", help="a short run (CI)")
        sp.set_defaults(func=_bench_suite)
    br = bsub.add_parser(
        "record", help="write throughput of `cloth-sim record` against a running node"
    )
    br.add_argument("--size", type=int, default=64, help="cloth N×N (default 64)")
    br.add_argument(
        "--rate", type=float, default=60.0, help="the node's publish_rate (Hz, default 60)"
    )
    br.add_argument("--seconds", type=float, default=10.0, help="recorded wall time")
    br.set_defaults(func=_bench_record)
    return b
