"""``cloth-sim bench materials``: every target of the materials issue, measured and printed.

* strip tensile: each library fabric, warp and weft, at 4, 16 and 64 cells: the worst error;
* cantilever: each fabric, warp and weft, at 16, 32 and 64 cells over the overhang, released and
  stepped by ``vbd`` with its defaults until at rest (what a user gets);
* Cusick drape: each fabric at 16, 32, 64 and 128 cells across the specimen: the coefficient, its
  change from 64 to 128, and the fabrics' rank against their bending lengths (Spearman's ρ);
* speed: a step of a material grid beside the same springs with Provot's bend springs in place of
  the bending, symplectic Euler and vbd, side by side in one process;
* the fit: a noisy depth-camera recording (Kinect noise) of the ``swing`` scene with a known
  fabric, fitted back at 1 and 2 Ray workers.

Writes ``materials.md``, CSV/JSON of each part and the plots the site shows into ``--out``.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from .. import textile
from ..materials import get
from ..materials.library import MEASURED
from ..model import ClothModel
from ..simulator import Simulator
from ._out import machine, markdown_table, pyplot, write_rows


def mean_bending_length(name: str) -> float:
    f = get(name)
    return (math.sqrt(f.bend[0] * f.bend[1]) / (f.density * 9.81)) ** (1.0 / 3.0)


def _directional_rows(names, grids, test, fields: dict) -> list[dict]:
    """``test(name, grid=, direction=)`` for every fabric, direction and grid: a row each, with
    ``fields`` (row key: the test's result key)."""
    return [
        {"fabric": n, "direction": d, "grid": g, **{k: r[v] for k, v in fields.items()}}
        for n in names
        for d in textile.DIRECTIONS
        for g in grids
        for r in (test(n, grid=g, direction=d),)
    ]


def tensile_rows(names, grids) -> list[dict]:
    return _directional_rows(
        names,
        grids,
        textile.tensile,
        {"expected_N_per_m": "expected", "measured_N_per_m": "measured", "error": "error"},
    )


def cantilever_rows(names, grids) -> list[dict]:
    return _directional_rows(
        names,
        grids,
        textile.cantilever,
        {
            "expected_m": "expected",
            "measured_m": "measured",
            "peirce_m": "peirce",
            "angle_deg": "angle_deg",
            "error": "error",
            "method": "method",
            "settled_at_s": "settled_at",
            "speed_at_end_m_per_s": "speed_at_end",
        },
    )


def drape_rows(names, grids) -> list[dict]:
    rows = []
    for n in names:
        for g in grids:
            t = time.perf_counter()
            r = textile.drape(n, grid=g)
            rows.append(
                {
                    "fabric": n,
                    "grid": g,
                    "drape_coefficient": r["drape_coefficient"],
                    "bending_length_m": mean_bending_length(n),
                    "settled_s": r["settled_at"],
                    "wall_s": time.perf_counter() - t,
                }
            )
            print(f"  drape {n} {g}: {r['drape_coefficient']:.4f}", flush=True)
    return rows


def speed_rows(sizes, repeats: int = 5) -> list[dict]:
    """ms a step: the material grid, the same without its bending (structural and shear only) and
    with Provot's bend springs instead (stiffness 1 N/m), each the best of ``repeats``."""
    rows = []
    for n in sizes:
        m = ClothModel.grid(
            rows=n, cols=n, size=(1, 1), material="denim", pinned=[(0, 0), (0, -1)]
        )
        kb = m.stiffness.copy()
        kb[m.family == m.family_index("bend")] = 1.0
        variants = {
            "springs": dataclasses.replace(m, bending=None),
            "bend_springs": dataclasses.replace(m, bending=None, stiffness=kb),
            "material": m,
        }
        for integ, dt, steps in (("symplectic_euler", 1e-5, 200), ("vbd", 1 / 120, 5)):
            row = {"n": n, "integrator": integ}
            for label, model in variants.items():
                sim = Simulator(model, integrator=integ, dt=dt)
                sim.step(2)
                best = math.inf
                for _ in range(repeats):
                    t = time.perf_counter()
                    sim.step(steps)
                    best = min(best, (time.perf_counter() - t) / steps)
                row[f"{label}_ms"] = 1e3 * best
            row["material_over_bend_springs"] = row["material_ms"] / row["bend_springs_ms"]
            rows.append(row)
    return rows


# ---------------------------------------------------------------------------- the fit
#: the fabric the benchmark's recording is made with: the swing scene's, scaled
TRUTH = {"stretch": 1.4, "bend": 0.75}


def record_swing(path, seconds: float = 1.5, rate: float = 30.0, seed: int = 1) -> int:
    """A bag of what a 160×120 depth camera with Kinect noise sees of the ``swing`` scene with
    the :data:`TRUTH` fabric: its cloth pixels' points, in the simulation's frame, at ``rate``;
    returns the points written."""
    from ..bag import cdr
    from ..bag.store import BagWriter
    from ..scene import load_scene
    from ..sensors.camera import camera_from_settings

    scene = load_scene("swing")
    sim = scene.build_simulator(material=scene.material.scaled(**TRUTH))
    cam = camera_from_settings(
        {
            "width": 160,
            "height": 120,
            "fov": 60.0,
            "position": [0.45, 0.95, 0.15],
            "look_at": [0.05, 0.15, -0.25],
            "near": 0.1,
            "far": 5.0,
            "noise": "kinect",
        },
        seed=seed,
    )
    w = BagWriter(path, overwrite=True)
    cid = w.add_topic("/cloth_sim/camera/points", "sensor_msgs/msg/PointCloud2")
    total = 0
    for k in range(int(seconds * rate) + 1):
        sim.advance(k / rate)
        frame = cam.render(sim)
        pts = frame.points()[frame.object == 0].astype(np.float64)
        world = pts @ frame.rotation.T + frame.position
        ns = 1_000_000_000 + round(k / rate * 1e9)
        w.write(cid, ns, cdr.point_cloud(world, 1, len(world), "cloth", ns))
        total += len(world)
    w.close()
    return total


def fit_rows(workers_list, generations: int = 12) -> list[dict]:
    from .. import fit
    from ..sweep.cluster import pool_map
    from ..sweep.fit import load_recording

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "swing_depth"
        points = record_swing(bag)
        _, times, clouds = load_recording(bag)
        args = (times, clouds, "swing", ["stretch", "bend"])
        for workers in workers_list:
            if workers == 1:
                r = fit.fit(*args, generations=generations)
            else:
                with pool_map(workers, None) as mapper:
                    r = fit.fit(*args, mapper, workers, generations=generations)
            rows.append(
                {
                    "workers": workers,
                    "stretch_factor": r.factors["stretch"],
                    "bend_factor": r.factors["bend"],
                    "stretch_error": r.factors["stretch"] / TRUTH["stretch"] - 1,
                    "bend_error": r.factors["bend"] / TRUTH["bend"] - 1,
                    "chamfer_m": r.chamfer,
                    "hausdorff_m": r.hausdorff,
                    "start_chamfer_m": r.start_chamfer,
                    "evaluations": r.evaluations,
                    "wall_s": r.wall,
                    "frames": r.frames,
                    "points_recorded": points,
                }
            )
            print(f"  fit at {workers} worker(s): {rows[-1]}", flush=True)
    return rows


# ---------------------------------------------------------------------------- main
def _plots(out: Path, cant, drape) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for n in sorted({r["fabric"] for r in cant}):
        rs = [r for r in cant if r["fabric"] == n and r["direction"] == "warp"]
        ax[0].loglog([r["grid"] for r in rs], [abs(r["error"]) + 1e-7 for r in rs], "o-", lw=1)
    ax[0].set(
        xlabel="cells over the overhang",
        ylabel="|bending length error|",
        title="cantilever (warp), every fabric",
    )
    for n in sorted({r["fabric"] for r in drape}):
        rs = [r for r in drape if r["fabric"] == n]
        ax[1].plot([r["grid"] for r in rs], [r["drape_coefficient"] for r in rs], "o-", label=n)
    ax[1].set(
        xscale="log",
        xlabel="cells across the specimen",
        ylabel="drape coefficient",
        title="Cusick drape against resolution",
    )
    ax[1].legend(fontsize=6)
    top = max(r["grid"] for r in drape)
    rs = [r for r in drape if r["grid"] == top]
    ax[2].plot(
        [100 * r["bending_length_m"] for r in rs], [r["drape_coefficient"] for r in rs], "o"
    )
    for r in rs:
        ax[2].annotate(
            r["fabric"], (100 * r["bending_length_m"], r["drape_coefficient"]), fontsize=6
        )
    ax[2].set(
        xlabel="bending length √(G_warp·G_weft)/(w g), cube root (cm)",
        ylabel="drape coefficient",
        title=f"drape at {top}×{top} against bending length",
    )
    fig.tight_layout()
    fig.savefig(out / "textile.png", dpi=110)
    plt.close(fig)


def main(out: Path, quick: bool = False) -> None:
    from scipy.stats import spearmanr

    out.mkdir(parents=True, exist_ok=True)
    names = ["denim", "gray-interlock"] if quick else list(MEASURED)
    print(f"materials benchmark on {machine()}", flush=True)
    ten = tensile_rows(names, [4, 16] if quick else [4, 16, 64])
    write_rows(out, "tensile", ten)
    cant = cantilever_rows(names, [16, 32] if quick else [16, 32, 64])
    write_rows(out, "cantilever", cant)
    grids = [16, 32] if quick else [16, 32, 64, 128]
    drape = drape_rows(names[:1] if quick else names, grids)
    write_rows(out, "drape", drape)
    speed = speed_rows([32] if quick else [32, 64, 128], repeats=3 if quick else 5)
    write_rows(out, "speed", speed)
    fits = [] if quick else fit_rows([1, 2])
    if fits:
        write_rows(out, "fit", fits)
    _plots(out, cant, drape)

    lines = [f"Machine: {machine()}.", ""]
    worst_t = max(ten, key=lambda r: abs(r["error"]))
    lines.append(
        f"- **Tensile**: worst error {100 * worst_t['error']:+.3f} % ({worst_t['fabric']}, "
        f"{worst_t['direction']}, {worst_t['grid']} cells); target 2 %."
    )
    for g in sorted({r["grid"] for r in cant}):
        w = max((r for r in cant if r["grid"] == g), key=lambda r: abs(r["error"]))
        lines.append(
            f"- **Cantilever** at {g}×4 (released, `{w['method']}` at 1/60 s with its defaults): "
            f"worst bending-length error {100 * w['error']:+.3f} % ({w['fabric']}, "
            f"{w['direction']}); target 5 %."
        )
    rows = []
    by = {}
    for r in drape:
        by.setdefault(r["fabric"], {})[r["grid"]] = r["drape_coefficient"]
    for n, d in by.items():
        rows.append(
            [
                n,
                f"{100 * mean_bending_length(n):.3f}",
                *[f"{d[g]:.4f}" for g in grids],
                f"{100 * (d[grids[-1]] - d[grids[-2]]):+.2f}",
            ]
        )
    lines += [
        "",
        markdown_table(
            [
                "fabric",
                "c (cm)",
                *[f"DC {g}" for g in grids],
                f"Δ {grids[-2]}→{grids[-1]} (points)",
            ],
            rows,
        ),
    ]
    if len(by) > 2:
        rho = spearmanr([mean_bending_length(n) for n in by], [d[grids[-1]] for d in by.values()])
        lines.append(
            f"\nDrape coefficients at {grids[-1]}×{grids[-1]} against the bending "
            f"lengths: Spearman ρ = {rho.statistic:.3f}."
        )
    lines += [
        "",
        markdown_table(
            [
                "N",
                "integrator",
                "springs ms",
                "+bend springs ms",
                "material ms",
                "material / bend springs",
            ],
            [
                [
                    r["n"],
                    r["integrator"],
                    f"{r['springs_ms']:.3f}",
                    f"{r['bend_springs_ms']:.3f}",
                    f"{r['material_ms']:.3f}",
                    f"{r['material_over_bend_springs']:.2f}",
                ]
                for r in speed
            ],
        ),
    ]
    if fits:
        lines += [
            "",
            markdown_table(
                [
                    "workers",
                    "stretch ×",
                    "bend ×",
                    "errors",
                    "Chamfer (cm)",
                    "Hausdorff (cm)",
                    "simulations",
                    "wall (s)",
                ],
                [
                    [
                        r["workers"],
                        f"{r['stretch_factor']:.4f}",
                        f"{r['bend_factor']:.4f}",
                        f"{100 * r['stretch_error']:+.2f} %, {100 * r['bend_error']:+.2f} %",
                        f"{100 * r['chamfer_m']:.3f}",
                        f"{100 * r['hausdorff_m']:.3f}",
                        r["evaluations"],
                        f"{r['wall_s']:.1f}",
                    ]
                    for r in fits
                ],
            ),
        ]
        lines.append(
            f"\nTruth: stretch × {TRUTH['stretch']}, bend × {TRUTH['bend']} of gray-interlock's."
        )
    text = "\n".join(lines) + "\n"
    (out / "materials.md").write_text(text)
    print(text)
