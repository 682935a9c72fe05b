"""The ``cloth-sim`` command line.

``cloth-sim run [--scene NAME|FILE] [--duration S] [--integrator NAME] [--dt S]``
    Simulate a scene headless and print one summary line per simulated second.
``cloth-sim bench steps [--sizes 32 64 128] [--integrators ...]``
    Print ms/step of integrators on the hanging cloth at several grid sizes.
``cloth-sim bench implicit [--sizes 32 64] [--dt 0.016667]``
    Print ms/step of the implicit methods at a large step, CG vs direct solve, CG iterations.
``cloth-sim bench node [--sizes 32 64] [--seconds 10]``
    Print the node's real-time factor with and without a ~/points subscriber (needs rclpy).
"""

from __future__ import annotations

import argparse
import sys
import time

from . import integrators
from .scene import SceneError, load_scene
from .simulator import SimulationDiverged


def _run(args) -> int:
    scene = load_scene(args.scene)
    if args.integrator:
        scene.integrator = args.integrator
    if args.dt:
        scene.dt = args.dt
    sim = scene.build_simulator()
    print(f"scene {scene.name} ({scene.source}): {scene.rows}×{scene.cols} {scene.model}, "
          f"{sim.integrator}, dt={sim.dt:g} s, stable_dt={sim.stable_dt():.4g} s, "
          f"terms: {', '.join(sim.active_terms)}", flush=True)
    t_wall = time.perf_counter()
    second = 1
    while second <= args.duration:
        start = time.perf_counter()
        try:
            n = sim.advance(float(second))
        except SimulationDiverged as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
        wall = time.perf_counter() - start
        e = sim.energy()
        print(f"t={sim.time:6.2f} s  {sim.integrator}  dt={sim.dt:g}  max_strain={sim.max_strain():+.4f}  "
              f"E_kin={e['kinetic']:.4f} J  E_spring={e['spring']:.4f} J  E_grav={e['gravity']:.4f} J  "
              f"({1e3 * wall / max(n, 1):.3f} ms/step)", flush=True)
        second += 1
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


def _bench_node(args) -> int:
    from .ros.bench import print_node_table
    print_node_table(args.sizes, args.seconds, args.integrator, args.dt, args.rate)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cloth-sim", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="simulate a scene headless, one line per simulated second")
    r.add_argument("--scene", default="hanging", help="scene name or YAML file (default: hanging)")
    r.add_argument("--duration", type=float, default=5.0, help="simulated seconds (default 5)")
    r.add_argument("--integrator", choices=integrators.available())
    r.add_argument("--dt", type=float)
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
    nb = bsub.add_parser("node", help="real-time factor of cloth_sim_node (needs rclpy)")
    nb.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    nb.add_argument("--seconds", type=float, default=10.0, help="measured wall time per row")
    nb.add_argument("--integrator", default="symplectic_euler", choices=integrators.available())
    nb.add_argument("--dt", type=float, default=1e-3)
    nb.add_argument("--rate", type=float, default=60.0, help="publish_rate (Hz)")
    nb.set_defaults(func=_bench_node)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (SceneError, ValueError) as e:
        print(f"cloth-sim: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
