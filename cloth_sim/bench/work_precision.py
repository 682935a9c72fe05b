"""``cloth-sim bench work-precision``: wall time against error on scene hang16, one line per
integrator.

Reference: ``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-10, atol 1e-12) on the same forces,
cached on disk under a key of the scene and tolerances, and checked against a solve 100× tighter
(they must agree below 1e-9 m). Error at T: RMS over particles of |x(T) − x_ref(T)|, and the max.
Steps dt = 1e-3·2^−k (k = 0…5; explicit Euler k = 5…7) for the explicit methods and (1/60)·2^−k for
the implicit ones; ``vbd`` at 1, 2, 5, 10 and 20 iterations a step, a line each (``vbd-N``). Time:
``perf_counter`` around the stepping loop only, the minimum of ``repeats`` runs after a warm-up. A
run that diverges (the simulator's guard), or ends with a non-finite or > 1 m error, is recorded as
a failure. Observed orders: least-squares slope of log error against log dt on a T = 0.1 s sweep,
over the stable runs whose error is above 1000× the reference's own error.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from ..simulator import SimulationDiverged, Simulator
from ._out import G, fmt, hang16, machine, markdown_table, progress, pyplot, write_rows

EXPLICIT = ["explicit_euler", "symplectic_euler", "midpoint", "rk4", "verlet"]
#: vbd at a fixed iteration count a step: each is its own line (``vbd-N``)
VBD_ITERATIONS = (1, 2, 5, 10, 20)
IMPLICIT = ["implicit_euler", "implicit_euler_prefactored", "kang", "liu2013", "xpbd"] + [
    f"vbd-{k}" for k in VBD_ITERATIONS
]
ORDER_EXPECTED = {
    "explicit_euler": 1,
    "symplectic_euler": 1,
    "midpoint": 2,
    "rk4": 4,
    "verlet": 2,
    "implicit_euler": 1,
    "liu2013": 1,
    "xpbd": 1,
    "vbd-20": 1,
}


def method(label: str) -> tuple[str, dict]:
    """A line's integrator and options: ``vbd-N`` is vbd at N iterations a step."""
    if label.startswith("vbd-"):
        return "vbd", {"iterations": int(label[4:])}
    return label, {}


REF_RTOL, REF_ATOL = 1e-10, 1e-12


def dt_sweep(name: str, quick: bool) -> list[float]:
    # the sweeps; the two approximate implicit methods go 4 halvings further (they converge
    # late)
    ks = {
        "explicit_euler": range(5, 8),
        "implicit_euler_prefactored": range(0, 10),
        "kang": range(0, 10),
    }.get(name, range(0, 6))
    if quick:
        ks = {"explicit_euler": range(5, 8), "kang": range(2, 5)}.get(
            name, range(1, 4) if name in IMPLICIT else range(0, 3)
        )
    base = 1.0 / 60 if name in IMPLICIT else 1e-3
    return [base * 2.0**-k for k in ks]


def reference(
    T: float, cache: Path, rtol: float = REF_RTOL, atol: float = REF_ATOL
) -> tuple[np.ndarray, int]:
    """x(T) of hang16 by DOP853 (cached under ``cache``), and the force evaluations it took."""
    key = hashlib.sha256(
        json.dumps(
            {
                "scene": "hang16",
                "rows": 16,
                "cols": 16,
                "spacing": 1 / 15,
                "mass": 0.01,
                "k": 1000.0,
                "c": 0.0,
                "pins": [[0, 0], [0, 15]],
                "g": G,
                "T": T,
                "rtol": rtol,
                "atol": atol,
                "method": "DOP853",
            },
            sort_keys=True,
        ).encode()
    ).hexdigest()[:16]
    path = cache / f"reference-{key}.npz"
    if path.exists():
        d = np.load(path)
        return d["x"], int(d["nfev"])
    sim = Simulator(hang16(), dt=1e-3, gravity=G)
    forces, n = sim.forces, len(sim.positions)
    x0 = np.array(sim.positions)

    def rhs(_, y):
        x, v = y[: 3 * n].reshape(n, 3), y[3 * n :].reshape(n, 3)
        return np.concatenate([v.ravel(), forces.acceleration(x, v).ravel()])

    sol = solve_ivp(
        rhs,
        (0.0, T),
        np.concatenate([x0.ravel(), np.zeros(3 * n)]),
        method="DOP853",
        rtol=rtol,
        atol=atol,
    )
    if not sol.success:
        raise RuntimeError(f"reference solve failed: {sol.message}")
    x = sol.y[: 3 * n, -1].reshape(n, 3)
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, x=x, nfev=sol.nfev)
    return x, int(sol.nfev)


def checked_reference(T: float, cache: Path) -> dict:
    x, nfev = reference(T, cache)
    x_tight, nfev_tight = reference(T, cache, REF_RTOL / 100, REF_ATOL / 100)
    agree = float(np.abs(x - x_tight).max())
    if not agree < 1e-9:
        raise RuntimeError(
            f"the reference at T={T} s disagrees with a 100× tighter solve by {agree:.3g} m"
        )
    return {"x": x, "nfev": nfev, "nfev_tight": nfev_tight, "agreement": agree}


def run(label: str, dt: float, T: float, x_ref: np.ndarray, repeats: int) -> dict:
    n_steps = int(round(T / dt))
    row = {"integrator": label, "dt": dt, "steps": n_steps, "T": T}
    name, options = method(label)
    model = hang16()  # shared: a Simulator never modifies its model
    warm = Simulator(model, integrator=name, dt=dt, gravity=G, integrator_options=options)
    try:
        warm.step(min(n_steps, 10))
    except SimulationDiverged:
        pass
    best, sim = math.inf, None
    for _ in range(repeats):
        sim = Simulator(model, integrator=name, dt=dt, gravity=G, integrator_options=options)
        t0 = time.perf_counter()
        try:
            sim.step(n_steps)
        except SimulationDiverged as e:
            row.update(
                stable=False,
                failure=f"diverged at t={sim.time:.4g} s",
                wall_s=math.nan,
                rms_error=math.nan,
                max_error=math.nan,
            )
            row["detail"] = str(e).split(";")[0]
            return row
        best = min(best, time.perf_counter() - t0)
    err = np.linalg.norm(sim.positions - x_ref, axis=1)
    rms, mx = float(np.sqrt(np.mean(err**2))), float(err.max())
    stable = bool(np.isfinite(mx) and mx < 1.0)
    stats = sim.integrator_stats
    row.update(
        stable=stable,
        failure="" if stable else f"inaccurate: max error {mx:.3g} m > the cloth's size",
        wall_s=best,
        rms_error=rms,
        max_error=mx,
        force_evals=sim.force_evaluations,
        cg_iterations=int(stats.get("cg_iterations", 0)),
    )
    return row


def observed_order(rows: list[dict], floor: float) -> float:
    """Least-squares slope of log error against log dt over the stable runs whose error is above
    ``floor`` (1000× the reference's own error, estimated by its agreement with the tighter
    solve)."""
    pts = [(r["dt"], r["rms_error"]) for r in rows if r["stable"] and r["rms_error"] > floor]
    if len(pts) < 2:
        return math.nan
    dt, err = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(dt, err, 1)[0])


def pareto(rows: list[dict]) -> list[dict]:
    """The runs no other run beats on both wall time and error."""
    ok = sorted((r for r in rows if r["stable"]), key=lambda r: (r["wall_s"], r["rms_error"]))
    front, best = [], math.inf
    for r in ok:
        if r["rms_error"] < best:
            front.append(r)
            best = r["rms_error"]
    return front


def main(out: Path, quick: bool = False, cache: Path | None = None) -> dict:
    t_start = time.perf_counter()
    cache = (
        cache
        or Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "cloth_sim" / "bench"
    )
    names = EXPLICIT + IMPLICIT
    T = 0.1 if quick else 1.0
    repeats = 1 if quick else 3
    ref = checked_reference(T, cache)
    jobs = [(n, dt) for n in names for dt in dt_sweep(n, quick)]
    rows = [run(n, dt, T, ref["x"], repeats) for n, dt in progress(jobs, "work-precision")]
    # orders from a T = 0.1 s sweep (the same runs in quick mode)
    if quick:
        order_rows, ref01 = rows, ref
    else:
        ref01 = checked_reference(0.1, cache)
        order_rows = [
            run(n, dt, 0.1, ref01["x"], 1)
            for n, dt in progress(
                [(n, dt) for n in ORDER_EXPECTED for dt in dt_sweep(n, False)], "orders"
            )
        ]
    floor = max(1e3 * ref01["agreement"], 1e-13)
    orders = {
        n: observed_order([r for r in order_rows if r["integrator"] == n], floor)
        for n in ORDER_EXPECTED
    }
    front = pareto(rows)
    extra = {
        "T": T,
        "reference": {
            "method": "DOP853",
            "rtol": REF_RTOL,
            "atol": REF_ATOL,
            "nfev": ref["nfev"],
            "nfev_tight": ref["nfev_tight"],
            "agreement_m": ref["agreement"],
        },
        "orders": orders,
        "pareto": [(r["integrator"], r["dt"]) for r in front],
    }
    write_rows(out, "work_precision", rows, extra)

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 5.2))
    for n in names:
        rs = [r for r in rows if r["integrator"] == n and np.isfinite(r["rms_error"])]
        bad = sum(1 for r in rows if r["integrator"] == n and not np.isfinite(r["rms_error"]))
        if rs:
            ax.loglog(
                [r["rms_error"] for r in rs],
                [r["wall_s"] for r in rs],
                "o-",
                ms=4,
                label=n + (f" ({bad} diverged)" if bad else ""),
            )
    ax.set_xlabel(f"RMS position error at T = {T:g} s (m)")
    ax.set_ylabel("wall time of the stepping loop (s)")
    ax.set_title(f"hang16 work-precision (min of {repeats})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "work_precision.png", dpi=110)
    plt.close(fig)

    table = markdown_table(
        [
            "integrator",
            "dt (s)",
            "steps",
            "wall (s)",
            "RMS error (m)",
            "max error (m)",
            "force evals",
            "CG iterations",
            "status",
        ],
        [
            [
                r["integrator"],
                f"{r['dt']:.4g}",
                r["steps"],
                fmt(r["wall_s"]),
                fmt(r["rms_error"]),
                fmt(r["max_error"]),
                r.get("force_evals", "–"),
                r.get("cg_iterations", "–") or "–",
                "ok" if r["stable"] else r["failure"],
            ]
            for r in rows
        ],
    )
    order_table = markdown_table(
        ["integrator", "expected order", "observed (T = 0.1 s)"],
        [[n, ORDER_EXPECTED[n], fmt(orders[n], 3)] for n in ORDER_EXPECTED],
    )
    front_table = markdown_table(
        ["wall (s)", "RMS error (m)", "integrator", "dt (s)"],
        [
            [fmt(r["wall_s"]), fmt(r["rms_error"]), r["integrator"], f"{r['dt']:.4g}"]
            for r in front
        ],
    )
    text = (
        f"# work-precision, hang16, T = {T:g} s — {machine()}\n\n"
        f"Reference: DOP853 rtol {REF_RTOL:g} atol {REF_ATOL:g}, {ref['nfev']} force evaluations; "
        f"a 100× tighter solve ({ref['nfev_tight']} evaluations) agrees to {ref['agreement']:.2g} "
        "m.\n\n"
        f"{table}\n\n## Observed orders\n\n{order_table}\n\n## Pareto front (cheapest run for "
        "each error level)\n\n"
        f"{front_table}\n\n(run time {time.perf_counter() - t_start:.0f} s)\n"
    )
    (out / "work_precision.md").write_text(text)
    print(text)
    return {"rows": rows, "orders": orders, "pareto": front}
