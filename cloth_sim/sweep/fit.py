"""``cloth-sim fit BAG --scene SCENE --params NAME[,NAME…] -o OUT [--workers N] [--address A]``:
a scene's material fitted to a recorded point-cloud sequence (:mod:`cloth_sim.fit`),
the bag read here and the candidates spread on Ray's workers."""

from __future__ import annotations

import numpy as np

from .. import fit as core
from ..bag.clouds import read_point_clouds


def load_recording(bag, topic: str | None = None):
    """``(topic, times (s since the first), clouds)`` of a bag's point clouds."""
    topic, frames = read_point_clouds(bag, topic)
    t0 = frames[0][0]
    return topic, np.array([(t - t0) * 1e-9 for t, _ in frames]), [p for _, p in frames]


def check(bag, scene: str, topic: str | None = None) -> None:
    """Refuse, before any work, a scene without a material and a bag without point clouds
    (:class:`~cloth_sim.bag.store.BagError` or ``ValueError`` naming them)."""
    core.scene_with_material(scene)
    read_point_clouds(bag, topic)


def add_parser(sub) -> None:
    f = sub.add_parser(
        "fit",
        help="fit a scene's material parameters to a recorded point-cloud sequence (a bag)",
    )
    f.add_argument("bag", metavar="BAG", help="bag directory or .mcap file of PointCloud2")
    f.add_argument("--scene", required=True, help="scene name or YAML file with a material:")
    f.add_argument(
        "--params",
        required=True,
        metavar="NAME[,NAME…]",
        help="material parameters to fit: stretch, shear, bend, density, damping",
    )
    f.add_argument("-o", "--output", required=True, metavar="OUT", help="scene file to write")
    f.add_argument("--topic", default=None, help="the cloud topic (default: the bag's only one)")
    f.add_argument("--workers", type=int, default=1, help="Ray workers (default 1: in process)")
    f.add_argument("--address", default=None, help="a running Ray cluster's address")
    f.add_argument("--generations", type=int, default=12, help="at most (default 12)")
    f.add_argument("--seed", type=int, default=0)
    f.set_defaults(func=_fit)


def _fit(args) -> int:
    params = core.parse_params(args.params)  # refused before the bag is read
    if args.workers < 1:
        raise ValueError(f"--workers: expected an integer >= 1, got {args.workers}")
    core.scene_with_material(args.scene)
    _, times, clouds = load_recording(args.bag, args.topic)
    kw = dict(generations=args.generations, seed=args.seed)
    if args.workers > 1 or args.address:
        from .cluster import pool_map

        with pool_map(args.workers, args.address) as mapper:
            r = core.fit(times, clouds, args.scene, params, mapper, args.workers, **kw)
    else:
        r = core.fit(times, clouds, args.scene, params, **kw)
    for p in params:
        v = r.params[p]
        shown = ", ".join(f"{x:.6g}" for x in v) if isinstance(v, tuple) else f"{v:.6g}"
        print(f"{p}: {shown}  (× {r.factors[p]:.4f} the scene's)")
    print(
        f"one-way Chamfer {100 * r.chamfer:.3f} cm (the scene's material: "
        f"{100 * r.start_chamfer:.3f} cm), one-way Hausdorff {100 * r.hausdorff:.3f} cm; "
        f"{r.frames} frames, {r.points} points; {r.evaluations} simulations in {r.wall:.1f} s "
        f"on {r.workers} worker{'s' if r.workers > 1 else ''}"
    )
    out = core.write_scene(args.scene, r.fabric, args.output)
    print(f"scene with the fitted material: {out}")
    return 0
