"""``cloth-sim textile cantilever|drape|tensile``: the textile standard tests
(:mod:`cloth_sim.textile`), each measured value printed beside the expected one."""

from __future__ import annotations

import time

from ..materials.library import MEASURED


def add_parser(sub) -> None:
    t = sub.add_parser(
        "textile",
        help="the textile standard tests on the simulator: cantilever bending length, strip "
        "tensile stiffness, Cusick drape coefficient",
    )
    t.add_argument("test", choices=("cantilever", "tensile", "drape"))
    t.add_argument(
        "--material",
        nargs="+",
        default=None,
        metavar="NAME",
        help="library fabrics (default: every measured one; cloth_sim.materials.names())",
    )
    t.add_argument(
        "--grid",
        nargs="+",
        type=int,
        default=None,
        metavar="N",
        help="cells along the strip or across the drape specimen (default: cantilever 32, "
        "tensile 4 16 64, drape 64)",
    )
    t.add_argument(
        "--method",
        choices=("vbd", "statics", "explicit"),
        default=None,
        help="cantilever: the strip released and stepped by vbd at 1/60 s with its defaults, in "
        "air, until at rest (vbd, the default), or its equilibrium (statics: Newton on its "
        "energy); drape: symplectic Euler at 0.9 of its stable step (explicit, the default) or "
        "vbd at 1/60 s with its defaults",
    )
    t.set_defaults(func=_textile)


def _textile(args) -> int:
    from .. import textile
    from ..materials import get

    names = args.material or list(MEASURED)
    fabrics = {n: get(n) for n in names}  # an unknown name is refused before anything runs
    grids = args.grid or {"cantilever": [32], "tensile": [4, 16, 64], "drape": [64]}[args.test]
    for g in grids:
        if g < 4:
            raise ValueError(f"--grid: expected integers >= 4, got {g}")
    accepted = {
        "cantilever": textile.METHODS,
        "drape": textile.DRAPE_METHODS,
        "tensile": ("statics",),
    }[args.test]
    method = args.method or accepted[0]
    if method not in accepted:
        raise ValueError(
            f"--method: {args.test} accepts {', '.join(accepted)}, got {args.method!r}"
        )
    if args.test == "drape":
        print(f"drape ({method}): the drape coefficient DC")
        print(
            f"{'material':20s} {'grid':>9s} {'c (cm)':>7s} {'DC':>7s} {'settled':>8s} {'wall':>7s}"
        )
        for n, f in fabrics.items():
            for g in grids:
                t = time.perf_counter()
                r = textile.drape(f, grid=g, method=method)
                print(
                    f"{n:20s} {r['grid']:>9s} {100 * r['bending_length']:7.3f} "
                    f"{r['drape_coefficient']:7.4f} {r['settled_at']:7.2f}s "
                    f"{time.perf_counter() - t:6.1f}s",
                    flush=True,
                )
        return 0
    cantilever = args.test == "cantilever"
    dynamic = cantilever and method == "vbd"
    unit, scale = ("cm", 100.0) if cantilever else ("N/m", 1.0)
    head = "bending length" if cantilever else "tensile stiffness"
    how = (
        f" ({'vbd at 1/60 s, its defaults, in air' if dynamic else 'statics'})"
        if cantilever
        else ""
    )
    print(f"{args.test}{how}: {head} ({unit}), measured beside expected")
    print(
        f"{'material':20s} {'dir':5s} {'grid':>7s} {'expected':>10s} {'measured':>10s} "
        f"{'error':>8s}"
        + (f" {'angle':>7s} {'Peirce':>8s}" if cantilever else "")
        + (f" {'at rest':>8s} {'wall':>7s}" if dynamic else "")
    )
    for n, f in fabrics.items():
        for d in ("warp", "weft"):
            for g in grids:
                t = time.perf_counter()
                if cantilever:
                    r = textile.cantilever(f, grid=g, direction=d, method=method)
                else:
                    r = textile.tensile(f, grid=g, direction=d)
                extra = f" {r['angle_deg']:6.2f}° {scale * r['peirce']:8.3f}" if cantilever else ""
                if dynamic:
                    still = r["speed_at_end"] < textile.REST_SPEED
                    extra += (
                        f" {r['settled_at']:6.2f}s{' ' if still else '!'} "
                        f"{time.perf_counter() - t:6.1f}s"
                    )
                print(
                    f"{n:20s} {d:5s} {r['grid']:>7s} {scale * r['expected']:10.4f} "
                    f"{scale * r['measured']:10.4f} {100 * r['error']:7.3f}%{extra}",
                    flush=True,
                )
    if dynamic:
        print(
            f"# at rest: no particle faster than {1e3 * textile.REST_SPEED:g} mm/s at two checks "
            "0.25 s apart; '!' marks a strip still moving when its simulated time ran out (10 s)"
        )
    return 0
