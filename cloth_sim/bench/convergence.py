"""What ``vbd``'s step costs to converge on a real fabric: iterations against the residual, and
substeps against iterations at equal cost.

``cloth-sim bench convergence --material cotton --sizes 32 64`` hangs the library fabric (1 m
square, two corners pinned, starting flat as ``hanging`` does) and, for each size:

* **iterations a step**: ``vbd`` at 1/60 s for 1 s of simulated time at several caps with the
  tolerance off (every iteration runs), printing the relative residual of the steps' end
  (:mod:`cloth_sim.integrators.vbd_residual`, the median over the second half), the share of steps
  at or below the default tolerance, the bottom edge's height and the worst strain at 1 s, and
  the wall time a simulated second (two cores);
* **substeps at equal cost**: the same work a frame (``substeps × iterations`` fixed) spent as
  more, shorter steps (``dt = 1/60 / substeps``) — Macklin et al. 2019's small steps; the residual
  of each step is of its own (shorter) step, so the columns to compare are the bottom edge and the
  strain against the finest converged run.

``--rest`` hangs it in air until it is at rest, at each size, on ``vbd``'s defaults: the free
edge's height below the pins, which the solver issue asks to agree within 1 cm from 16×16 to
128×128.

``--work-precision`` measures every method at several amounts of work against the fine-step
reference (:func:`work_precision`): ``vbd``'s defaults over their tolerance, one ``vbd`` step a
frame over its iterations, ``vbd`` substeps, Baraff–Witkin over its step and ``liu2013`` over its
iterations; a table and a figure under ``--out`` (docs/convergence.md shows them).

The figures say how many sweeps a converged step takes at each resolution, which is what the
default iteration count and the choice of a method must be made from (docs/convergence.md).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import integrators, textile
from ..integrators.vbd_options import TOLERANCE
from ..model import ClothModel
from ..simulator import Simulator
from ._out import machine, markdown_table, pyplot, write_rows

#: iteration caps timed a step at 1/60 s
CAPS = (10, 30, 100, 300)
#: (substeps, iterations) a frame of equal work
SPLITS = ((1, 200), (4, 50), (10, 20), (20, 10), (40, 5))
#: simulated seconds a run
SECONDS = 1.0


def hanging(n: int, material: str) -> ClothModel:
    """The ``n×n`` library fabric, 1 m square, hanging from its two top corners."""
    return ClothModel.grid(
        rows=n, cols=n, size=(1.0, 1.0), material=material, pinned=[(n - 1, 0), (n - 1, n - 1)]
    )


def run(model: ClothModel, n: int, substeps: int, iterations: int, seconds: float = SECONDS):
    """``vbd`` with the tolerance off over ``seconds``: a dict of the figures printed."""
    sim = Simulator(
        model,
        integrator="vbd",
        dt=1.0 / 60 / substeps,
        integrator_options={"iterations": iterations, "tolerance": 0.0},
    )
    steps = int(round(seconds * 60 * substeps))
    residuals = np.empty(steps)
    t0 = time.perf_counter()
    for s in range(steps):
        sim.step()
        residuals[s] = sim.integrator_stats["last_residual"]
    wall = time.perf_counter() - t0
    late = residuals[steps // 2 :]
    return {
        "residual": float(np.median(late)),
        "converged": float(np.mean(late <= TOLERANCE)),
        "bottom": float(sim.positions[:n, 2].mean()),
        "strain": float(sim.max_strain()),
        "wall": wall / seconds,
    }


def print_convergence_table(material: str, sizes, seconds: float = SECONDS) -> None:
    print(
        f"vbd on {material}, 1 m hanging from two corners, {seconds:g} s simulated, tolerance off "
        f"(default tolerance {TOLERANCE:g}); residual: median over the second half"
    )
    head = (
        f"{'N':>4} {'substeps':>8} {'iters':>6} {'residual':>10} {'<=tol':>6} "
        f"{'bottom z m':>10} {'worst strain':>12} {'wall s/s':>9}"
    )
    for n in sizes:
        model = hanging(n, material)
        run(model, n, 1, 2, 2 / 60)  # numba's kernels for this model's shapes
        print(head)
        for substeps, iterations in [(1, c) for c in CAPS] + list(SPLITS[1:]):
            r = run(model, n, substeps, iterations, seconds)
            print(
                f"{n:>4} {substeps:>8} {iterations:>6} {r['residual']:>10.3g} "
                f"{r['converged']:>6.0%} {r['bottom']:>10.4f} {r['strain']:>12.3f} "
                f"{r['wall']:>9.2f}",
                flush=True,
            )


#: frames a simulated second sampled for the accuracy table
FRAMES = 60
#: the reference's step: this share of symplectic Euler's stable step
REFERENCE_SHARE = 0.9


def trajectory(sim: Simulator, n: int, seconds: float) -> dict:
    """The free edge's centroid (row 0: the edge away from the pins) and the worst strain at
    every frame, the wall time, and ``vbd``'s unconverged steps."""
    frames = int(round(seconds * FRAMES))
    centroid = np.empty((frames + 1, 3))
    strain = np.empty(frames + 1)
    centroid[0], strain[0] = sim.positions[:n].mean(axis=0), sim.max_strain()
    t0 = time.perf_counter()
    unconverged = 0
    for f in range(1, frames + 1):
        sim.advance(f / FRAMES)
        centroid[f], strain[f] = sim.positions[:n].mean(axis=0), sim.max_strain()
        unconverged += int(not sim.integrator_stats.get("converged", True))
    return {
        "centroid": centroid,
        "strain": strain,
        "wall": (time.perf_counter() - t0) / seconds,
        "unconverged": unconverged,
    }


def reference(model: ClothModel, n: int, seconds: float) -> tuple[Simulator, dict]:
    """The fine-step reference: symplectic Euler at :data:`REFERENCE_SHARE` of its stable step,
    and its :func:`trajectory`."""
    sim = Simulator(model, integrator="symplectic_euler", dt=1.0)
    sim.dt = REFERENCE_SHARE * sim.stable_dt()
    return sim, trajectory(sim, n, seconds)


def accuracy(run: dict, ref: dict) -> tuple[float, float]:
    """The solver issue's two figures: the worst strain averaged over the last half against the
    reference's (difference), and the RMS distance between the free edge's centroid paths over
    the reference's travel (the farthest its centroid gets from where it started)."""
    half = len(ref["strain"]) // 2
    strain = float(run["strain"][half:].mean() - ref["strain"][half:].mean())
    travel = float(np.linalg.norm(ref["centroid"] - ref["centroid"][0], axis=1).max())
    rms = float(np.sqrt(((run["centroid"] - ref["centroid"]) ** 2).sum(axis=1).mean()))
    return strain, rms / travel


def print_accuracy_table(materials, sizes, seconds: float = 2.0) -> None:
    """``vbd`` at 1/60 s with its defaults against a fine-step reference (symplectic Euler at
    :data:`REFERENCE_SHARE` of its stable step), hanging from two corners from flat."""
    print(
        f"vbd at 1/60 s, defaults, against symplectic Euler at {REFERENCE_SHARE:g} of its stable "
        f"step; {seconds:g} s from flat; strain: the worst, averaged over the last half; path: "
        "RMS distance of the free edge's centroid over the reference's travel"
    )
    print(
        f"{'fabric':>10} {'N':>4} {'substeps':>8} {'sweeps/frame':>12} {'unconverged':>11} "
        f"{'strain':>7} {'ref strain':>10} {'Δ strain':>9} {'path':>7} {'wall s/s':>9} "
        f"{'ref s/s':>8}"
    )
    for material in materials:
        for n in sizes:
            model = hanging(n, material)
            _, ref = reference(model, n, seconds)
            sim = Simulator(model, integrator="vbd", dt=1.0 / 60)
            sim.step()  # numba's kernels for this model, and its substeps
            sim = Simulator(model, integrator="vbd", dt=1.0 / 60)
            got = trajectory(sim, n, seconds)
            stats = sim.integrator_stats
            d_strain, path = accuracy(got, ref)
            half = len(ref["strain"]) // 2
            print(
                f"{material:>10} {n:>4} {stats['last_substeps']:>8} "
                f"{stats['iterations'] / max(stats['steps'], 1):>12.1f} {got['unconverged']:>11} "
                f"{got['strain'][half:].mean():>7.3f} {ref['strain'][half:].mean():>10.3f} "
                f"{d_strain:>+9.3f} {path:>7.1%} {got['wall']:>9.2f} {ref['wall']:>8.2f}",
                flush=True,
            )


def _at_rest(model: ClothModel, n: int, integrator: str, seconds: float, strain_limit):
    """``(edge, sim, wall)``: ``model`` released in air (:func:`~cloth_sim.textile.released`)
    and stepped from flat by ``integrator`` (one without a stable step's limit, such as ``vbd``,
    at 1/60 s with its defaults; one with a limit, such as symplectic Euler, at
    :data:`REFERENCE_SHARE` of it) until at rest or ``seconds``; ``edge``: the free edge's mean
    height below the pins. ``ValueError`` where the method refuses the cloth (a material's
    bending it does not take, no stable step)."""
    pins = float(model.positions[model.pinned, 2].mean())
    t0 = time.perf_counter()
    sim = textile.released(model, integrator, 1.0 / 60)
    stable = sim.stable_dt()
    if not stable > 0.0:
        raise ValueError(f"no stable step on this cloth (stable_dt = {stable:g} s)")
    if math.isfinite(stable):
        sim.dt = REFERENCE_SHARE * stable
    if strain_limit is not None:
        sim.strain_limit_method = "projection"
        sim.strain_limit = strain_limit
    textile.until_rest(sim, seconds, textile.REST_SPEED)
    return pins - float(sim.positions[:n, 2].mean()), sim, time.perf_counter() - t0


def print_rest_table(materials, sizes, seconds: float = 10.0, strain_limit=None) -> None:
    """The sheet hanging at rest at each resolution: ``vbd`` at 1/60 s with its defaults, in air
    (:func:`~cloth_sim.textile.released`), from flat until :func:`~cloth_sim.textile.until_rest`
    or ``seconds``; the free edge's height below the pins (the solver issue's target: within
    1 cm at every resolution), the worst strain, when it came to rest and the wall time. With
    ``strain_limit`` (the ``hanging`` scene's 0.1, by projection), the limit on, and symplectic
    Euler's edge at rest beside it (at :data:`REFERENCE_SHARE` of its stable step, under the same
    limit). Without a limit the two corner pins' point loads stretch the cloth beside them more
    at each doubling and the edge moves with the resolution (docs/convergence.md); the limit
    bounds that stretch."""
    limit = "no strain limit" if strain_limit is None else f"strain limit {strain_limit:g}"
    print(
        f"vbd at 1/60 s, defaults, {limit}, in air (relaxation {textile.AIR_RELAXATION:g} s), "
        f"from flat until no particle moves faster than {1e3 * textile.REST_SPEED:g} mm/s (at "
        f"most {seconds:g} s); the free edge's mean height below the pins"
        + ("" if strain_limit is None else "; beside it symplectic Euler's at rest")
    )
    print(
        f"{'fabric':>10} {'N':>4} {'edge m':>8} {'worst strain':>12} {'at rest s':>9} "
        f"{'speed mm/s':>10} {'direct':>6} {'wall s':>7}"
        + ("" if strain_limit is None else f" {'explicit m':>10}")
    )
    for material in materials:
        edges = []
        for n in sizes:
            model = hanging(n, material)
            edge, sim, wall = _at_rest(model, n, "vbd", seconds, strain_limit)
            edges.append(edge)
            speed = float(np.abs(sim.velocities).max())
            beside = ""
            if strain_limit is not None:
                beside = (
                    f" {_at_rest(model, n, 'symplectic_euler', seconds, strain_limit)[0]:>10.4f}"
                )
            print(
                f"{material:>10} {n:>4} {edge:>8.4f} {sim.max_strain():>12.4f} "
                f"{sim.time:>9.2f} {1e3 * speed:>10.2f} "
                f"{sim.integrator_stats['direct_steps']:>6} {wall:>7.1f}{beside}",
                flush=True,
            )
        print(f"{material:>10} spread of the edge over the sizes: {max(edges) - min(edges):.4f} m")


def print_rest_by_method(materials, sizes, methods, seconds: float = 10.0, strain_limit=None):
    """:func:`print_rest_table` for each of ``methods`` (integrator names; ``None``: every one
    registered) on each fabric and size: its step (1/60 s where the method has no stable step's
    limit, else :data:`REFERENCE_SHARE` of it), the free edge's height below the pins, the worst
    strain, when it came to rest (or that it did not within ``seconds``) and its fastest
    particle then; a method that refuses the cloth says why. What a user choosing a method for a
    hanging cloth gets at rest, under the strain limit or without."""
    methods = integrators.available() if methods is None else methods
    limit = "no strain limit" if strain_limit is None else f"strain limit {strain_limit:g}"
    print(
        f"each method from flat in air (relaxation {textile.AIR_RELAXATION:g} s), {limit}, until "
        f"no particle moves faster than {1e3 * textile.REST_SPEED:g} mm/s (at most {seconds:g} s)"
    )
    print(
        f"{'fabric':>10} {'N':>4} {'method':>27} {'dt s':>9} {'edge m':>8} {'worst strain':>12} "
        f"{'at rest s':>9} {'speed mm/s':>10} {'wall s':>7}"
    )
    for material in materials:
        for n in sizes:
            model = hanging(n, material)
            for method in methods:
                head = f"{material:>10} {n:>4} {method:>27}"
                try:
                    edge, sim, wall = _at_rest(model, n, method, seconds, strain_limit)
                except ValueError as e:
                    print(f"{head}  refused: {str(e).split(';')[0]}", flush=True)
                    continue
                speed = float(np.abs(sim.velocities).max())
                rest = f"{sim.time:.2f}" if speed < textile.REST_SPEED else f"not by {seconds:g}"
                print(
                    f"{head} {sim.dt:>9.2e} {edge:>8.4f} {sim.max_strain():>12.4f} "
                    f"{rest:>9} {1e3 * speed:>10.2f} {wall:>7.1f}",
                    flush=True,
                )


class Setting(NamedTuple):
    """One point of the work–precision figure: a method's family (a line of the plot), the
    integrator, its step and options."""

    family: str
    integrator: str
    dt: float
    options: dict | None


def work_precision_settings() -> list[Setting]:
    """The methods measured on a real fabric, each at several amounts of work: ``vbd`` at its
    defaults over its tolerance; ``vbd`` one backward-Euler step a frame over its iterations;
    ``vbd`` in substeps of 10 iterations; Baraff–Witkin over its step; ``liu2013`` over its
    iterations. (``xpbd`` takes no material's bending rigidity, so it is not among them.)"""
    frame = 1.0 / 60
    out = [
        Setting("vbd, its defaults (over the tolerance)", "vbd", frame, {"tolerance": t})
        for t in (1e-1, 1e-2, 1e-3)
    ]
    out += [
        Setting(
            "vbd, one step a frame (over its iterations)",
            "vbd",
            frame,
            {"iterations": k, "tolerance": 0.0, "substeps": 1},
        )
        for k in (10, 30, 100, 300)
    ]
    out += [
        Setting(
            "vbd, substeps of 10 iterations (over the substeps)",
            "vbd",
            frame,
            {"iterations": 10, "tolerance": 0.0, "substeps": s},
        )
        for s in (2, 5, 10, 20)
    ]
    out += [
        Setting("Baraff–Witkin (over its step)", "implicit_euler", frame / k, None)
        for k in (1, 4, 16)
    ]
    out += [
        Setting("liu2013 at 1/60 s (over its iterations)", "liu2013", frame, {"iterations": k})
        for k in (10, 30, 100)
    ]
    return out


def work_precision(materials, sizes, seconds: float, out: Path) -> list[dict]:
    """Every :func:`work_precision_settings` point on each fabric and size, hanging from two
    corners from flat, against the fine-step reference (symplectic Euler at
    :data:`REFERENCE_SHARE` of its stable step, whose own cost is a line of the figure): its wall
    time a simulated second, the free edge's path error over the reference's travel and the
    worst strain's difference (:func:`accuracy`). Prints the table and writes
    ``work_precision.{csv,json,md,png}`` under ``out``."""
    rows = []
    for material in materials:
        for n in sizes:
            model = hanging(n, material)
            ref_sim, ref = reference(model, n, seconds)
            rows.append(
                {
                    "fabric": material,
                    "N": n,
                    "family": "symplectic Euler (the reference)",
                    "integrator": "symplectic_euler",
                    "dt": ref_sim.dt,
                    "options": "",
                    "wall_s_per_s": ref["wall"],
                    "path": 0.0,
                    "d_strain": 0.0,
                    "unconverged": 0,
                }
            )
            for s in work_precision_settings():
                Simulator(
                    model, integrator=s.integrator, dt=s.dt, integrator_options=s.options
                ).step(2)  # numba's kernels for this model
                sim = Simulator(
                    model, integrator=s.integrator, dt=s.dt, integrator_options=s.options
                )
                got = trajectory(sim, n, seconds)
                d_strain, path = accuracy(got, ref)
                rows.append(
                    {
                        "fabric": material,
                        "N": n,
                        "family": s.family,
                        "integrator": s.integrator,
                        "dt": s.dt,
                        "options": ", ".join(f"{k}={v:g}" for k, v in (s.options or {}).items()),
                        "wall_s_per_s": got["wall"],
                        "path": path,
                        "d_strain": d_strain,
                        "unconverged": got["unconverged"],
                    }
                )
                r = rows[-1]
                print(
                    f"{material:>8} {n:>4}  {s.integrator:<15} dt {s.dt:.5f}  {r['options']:<40} "
                    f"{got['wall']:>8.2f} s/s  path {path:>7.2%}  Δ strain {d_strain:+.3f}",
                    flush=True,
                )
    write_rows(
        out, "work_precision", rows, {"seconds": seconds, "reference_share": REFERENCE_SHARE}
    )
    write_work_precision_table(rows, seconds, out / "work_precision.md")
    plot_work_precision(rows, out / "work_precision.png")
    return rows


def write_work_precision_table(rows: list[dict], seconds: float, path: Path) -> None:
    """The rows of :func:`work_precision` as a Markdown page under a heading naming the machine."""
    cases = ", ".join(dict.fromkeys(f"{r['fabric']} {r['N']}×{r['N']}" for r in rows))
    head = (
        f"# Work against precision on real fabrics — {machine()}\n\n"
        f"{cases}: 1 m hanging from two corners from flat, {seconds:g} s, against symplectic "
        f"Euler at {REFERENCE_SHARE:g} of its stable step. Path: the free edge's centroid, its "
        "RMS distance from the reference's over the reference's travel; Δ worst strain: averaged "
        "over the last half. The figure (`work_precision.png`) and what it shows: "
        "docs/convergence.md.\n\n"
    )
    path.write_text(
        head
        + markdown_table(
            [
                "fabric",
                "N",
                "method",
                "dt (s)",
                "options",
                "wall s a simulated s",
                "path (of the travel)",
                "Δ worst strain",
                "unconverged steps",
            ],
            [
                [
                    r["fabric"],
                    r["N"],
                    r["family"],
                    f"{r['dt']:.5g}",
                    r["options"] or "–",
                    f"{r['wall_s_per_s']:.3g}",
                    f"{r['path']:.2%}",
                    f"{r['d_strain']:+.3f}",
                    r["unconverged"],
                ]
                for r in rows
            ],
        )
        + "\n"
    )


def plot_work_precision(rows: list[dict], path: Path) -> None:
    """One panel a fabric and size: each method's family a line of its path error (x) against
    its wall time a simulated second (y), the reference's cost a dashed level."""
    cases = sorted({(r["fabric"], r["N"]) for r in rows}, key=lambda c: (c[0], c[1]))
    plt = pyplot()
    cols = min(2, len(cases))
    rows_ = -(-len(cases) // cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(6.4 * cols, 4.8 * rows_), squeeze=False)
    for ax, (fabric, n) in zip(axes.ravel(), cases):
        here = [r for r in rows if r["fabric"] == fabric and r["N"] == n]
        for family in dict.fromkeys(r["family"] for r in here):
            rs = [r for r in here if r["family"] == family]
            if rs[0]["integrator"] == "symplectic_euler":
                ax.axhline(rs[0]["wall_s_per_s"], ls="--", c="k", lw=1, label=family)
                continue
            ax.loglog(
                [max(r["path"], 1e-4) for r in rs],
                [r["wall_s_per_s"] for r in rs],
                "o-",
                ms=4,
                label=family,
            )
        ax.axvline(0.05, ls=":", c="grey", lw=1)  # the solver issue's 5 % of the travel
        ax.axhline(1.0, ls=":", c="grey", lw=1)  # real time
        ax.xaxis.set_major_formatter(lambda v, _: f"{100 * v:g} %")
        ax.xaxis.set_minor_formatter(lambda v, _: "")
        ax.set_xlabel("free edge's path error (of the reference's travel)")
        ax.set_ylabel("wall s a simulated s (two cores)")
        ax.set_title(f"{fabric} {n}×{n}, 1 m hanging from two corners, 1/60 s frames")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(cases) :]:
        ax.set_visible(False)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
