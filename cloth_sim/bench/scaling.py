"""``cloth-sim bench scaling``: ms/step against grid size per integrator, with the fitted exponent
of cost against particle count, and what skipping unused force terms buys.

Sizes N = 8 … 256 (N×N particles; the hanging_provot scene resized: 1 m square, its stiffness,
damping and mass, strain limit off, dt = 1 ms for the explicit methods and Kang, 1/60 s for
implicit Euler). An integrator stops growing N once one step took more than ``budget`` seconds. The
exponent is the least-squares slope of log(ms/step) against log(particles) over N ≥ 32 (below,
fixed per-step overheads dominate). "Skipping" times the N = 64 hanging_provot scene with wind,
bend springs, Provot's strain limit and damping each switched off in turn (a term that is off is
never evaluated), and the node's tick with and without a ~/points subscriber.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numba
import numpy as np

from ..kernel_cache import keep_true
from ..kinds import INTEGRATORS
from ..scene import load_scene
from ..simulator import SimulationDiverged, Simulator
from ._out import fmt, machine, markdown_table, progress, pyplot, write_rows
from .steps import time_steps

#: every integrator but vbd, whose iterations make its cost a choice (its own tables: bench
#: vbd-peers, work-precision)
METHODS = [name for name in INTEGRATORS if name != "vbd"]
#: methods without a step limit, timed at a frame-rate step
FRAME_RATE = ("implicit_euler", "implicit_euler_prefactored", "liu2013", "xpbd")


def build(
    n: int, integrator: str, *, wind=None, bend=True, strain_limit=None, damping=True
) -> Simulator:
    scene = load_scene("hanging_provot")
    k = dict(scene.stiffness)
    c = dict(scene.damping) if damping else {f: 0.0 for f in scene.damping}
    if not bend:
        k["bend"], c["bend"] = 0.0, 0.0
    dt = 1.0 / 60 if integrator in FRAME_RATE else 1e-3
    return scene.build_simulator(
        rows=n,
        cols=n,
        spacing=1.0 / (n - 1),
        stiffness=k,
        damping=c,
        integrator=integrator,
        dt=dt,
        wind=wind,
        strain_limit=strain_limit,
    )


@numba.njit(parallel=True, cache=True)
def _triad(a, b, c, s):
    for i in numba.prange(a.shape[0]):
        a[i] = b[i] + s * c[i]


def triad_bandwidth(total_bytes: int, seconds: float = 0.3) -> float:
    """Bytes per second of STREAM's triad ``a = b + s·c`` (McCalpin; two arrays read, one written,
    counted as 24 bytes per element as STREAM counts them) on every core numba uses, over three
    float64 arrays ``total_bytes`` together (at least 3 × 4 KiB); the best of repeated runs over
    ``seconds``."""
    n = max(512, int(total_bytes) // 24)
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    _triad(a, b, c, 3.0)  # compile and touch the pages
    best, spent, reps = math.inf, 0.0, 1
    while spent < seconds:
        t = time.perf_counter()
        for _ in range(reps):
            _triad(a, b, c, 3.0)
        el = time.perf_counter() - t
        spent += el
        best = min(best, el / reps)
        if el < 1e-3:
            reps *= 4
    return 24.0 * n / best


def step_traffic(sim: Simulator) -> int:
    """The bytes one symplectic Euler step must move at least: each array the step reads, once, and
    each it writes, once (positions and velocities both ways; the force array written; the springs'
    ends, rest lengths, stiffness, damping and kind, gravity's force and the inverse masses read;
    with the parallel gather, its incidence lists read and its per-spring force array written and
    read back). Caches and the particles' repeated reads by their springs are not counted: a lower
    bound."""
    forces = sim.forces
    term = forces.spring_term
    state = sim.state
    read = state.x.nbytes + state.v.nbytes + forces.inv_mass.nbytes
    term_read, term_written = term.streamed_bytes()
    read += term_read
    read += state.x.nbytes  # gravity's force, the sum's start (n × 3)
    written = state.x.nbytes + state.v.nbytes + state.x.nbytes + term_written  # x, v, the forces
    return int(read + written)


def fit_exponent(rows: list[dict]) -> float:
    pts = [
        (r["particles"], r["ms_per_step"]) for r in rows if r["N"] >= 32 and r["ms_per_step"] > 0
    ]
    if len(pts) < 2:
        return math.nan
    return float(np.polyfit(np.log([p[0] for p in pts]), np.log([p[1] for p in pts]), 1)[0])


def main(out: Path, quick: bool = False) -> dict:
    t_start = time.perf_counter()
    sizes = [8, 16, 32, 64] if quick else [8, 16, 32, 64, 128, 256]
    seconds = 0.2 if quick else 1.0
    budget = 0.05 if quick else 0.5
    methods = ["symplectic_euler", "rk4", "implicit_euler_prefactored"] if quick else METHODS
    rows = []
    for name in progress(methods, "scaling"):
        for n in sizes:
            # cost per step does not depend on dt for the explicit methods; one that diverges at 1
            # ms (explicit Euler, midpoint: no stable step with this little damping) is timed at a
            # smaller dt
            for shrink in (1, 10, 100, 1000):
                sim = build(n, name)
                sim.dt = sim.dt / shrink
                try:
                    t0 = time.perf_counter()
                    sim.step(1)
                    first = time.perf_counter() - t0
                    ms = 1e3 * time_steps(sim, seconds, repeats=3)
                    break
                except SimulationDiverged:
                    continue
            else:
                continue
            row = {
                "integrator": name,
                "N": n,
                "particles": n * n,
                "ms_per_step": ms,
                "ns_per_particle": 1e6 * ms / (n * n),
                "dt": sim.dt,
                "ms_per_simulated_s": ms / sim.dt,
            }
            if name == "symplectic_euler":
                traffic = step_traffic(sim)
                bandwidth = triad_bandwidth(traffic)
                row.update(
                    traffic_bytes=traffic,
                    triad_gb_s=bandwidth / 1e9,
                    bound_ms=1e3 * traffic / bandwidth,
                )
            rows.append(row)
            if ms / 1e3 > budget or first > 5 * budget:
                break
    exponents = {m: fit_exponent([r for r in rows if r["integrator"] == m]) for m in methods}
    dram = triad_bandwidth(768 << 20 if not quick else 96 << 20)  # far beyond any cache

    # what skipping buys: N = 64 hanging_provot scene, symplectic Euler
    n_skip = 32 if quick else 64
    full = dict(wind=(0.0, 2.0, 0.0), bend=True, strain_limit=0.1, damping=True)
    variants = [
        ("everything on (wind, bend, strain limit, damping)", {}),
        ("no wind", {"wind": None}),
        ("no bend springs", {"bend": False}),
        ("no strain limit", {"strain_limit": None}),
        ("no damping", {"damping": False}),
        ("none of them", {"wind": None, "bend": False, "strain_limit": None, "damping": False}),
    ]
    skip_rows = []
    for label, change in progress(variants, "skipping"):
        sim = build(n_skip, "symplectic_euler", **{**full, **change})
        terms = list(sim.active_terms) + (["strain_limit"] if sim.strain_limit is not None else [])
        skip_rows.append(
            {
                "variant": label,
                "N": n_skip,
                "terms": ", ".join(terms),
                "ms_per_step": 1e3 * time_steps(sim, seconds, repeats=3),
            }
        )
    node_rows = []
    if not quick:
        try:
            from .node import measure
        except ImportError:
            measure = None
        if measure is not None:
            for n in (32, 64):
                for subscribe in (False, True):
                    m = measure(n, 5.0, subscribe, "symplectic_euler", 1e-3, 60.0)
                    node_rows.append(
                        {
                            "N": n,
                            "subscriber": subscribe,
                            "tick_ms": m["tick_ms"],
                            "ms_per_step": m["ms_per_step"],
                            "rtf": m["rtf"],
                        }
                    )
    write_rows(
        out,
        "scaling",
        rows,
        {
            "exponents": exponents,
            "skipping": skip_rows,
            "node": node_rows,
            "dram_triad_gb_s": dram / 1e9,
        },
    )

    plt = pyplot()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12.5, 5.2))
    for name in methods:
        rs = [r for r in rows if r["integrator"] == name]
        ax.loglog(
            [r["particles"] for r in rs],
            [r["ms_per_step"] for r in rs],
            "o-",
            label=f"{name} (∝ n^{exponents[name]:.2f})"
            if exponents[name] == exponents[name]
            else name,
            ms=4,
        )
    ax.set_xlabel("particles n = N²")
    ax.set_ylabel("ms per step")
    ax.set_title("hanging_provot scene resized to N×N, strain limit off (min of 3)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    se = [r for r in rows if r["integrator"] == "symplectic_euler"]
    ax2.semilogx(
        [r["particles"] for r in se],
        [r["ns_per_particle"] for r in se],
        "o-",
        label="symplectic_euler, measured",
    )
    ax2.semilogx(
        [r["particles"] for r in se],
        [1e6 * r["bound_ms"] / r["particles"] for r in se],
        "s--",
        label="its memory traffic at the triad bandwidth (bound)",
    )
    ax2.set_xlabel("particles n = N²")
    ax2.set_ylabel("ns per particle per step")
    ax2.set_title("cost per particle against the bandwidth bound")
    ax2.set_ylim(bottom=0)
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "scaling.png", dpi=110)
    plt.close(fig)

    table = markdown_table(
        ["integrator"] + [f"N={n}" for n in sizes] + ["exponent (N ≥ 32)"],
        [
            [m]
            + [
                fmt(
                    next(
                        (r["ms_per_step"] for r in rows if r["integrator"] == m and r["N"] == n),
                        math.nan,
                    )
                )
                for n in sizes
            ]
            + [fmt(exponents[m])]
            for m in methods
        ],
    )
    per_particle = markdown_table(
        ["integrator"] + [f"N={n}" for n in sizes],
        [
            [m]
            + [
                fmt(
                    next(
                        (
                            r["ns_per_particle"]
                            for r in rows
                            if r["integrator"] == m and r["N"] == n
                        ),
                        math.nan,
                    )
                )
                for n in sizes
            ]
            for m in methods
        ],
    )
    bound_table = markdown_table(
        [
            "N",
            "bytes a step moves (MB)",
            "triad GB/s at that size",
            "bound ms/step",
            "measured ms/step",
            "measured / bound",
        ],
        [
            [
                r["N"],
                fmt(r["traffic_bytes"] / 1e6),
                fmt(r["triad_gb_s"]),
                fmt(r["bound_ms"]),
                fmt(r["ms_per_step"]),
                fmt(r["ms_per_step"] / r["bound_ms"]),
            ]
            for r in se
        ],
    )
    skip_table = markdown_table(
        ["variant", "active terms", "ms/step", "vs everything on"],
        [
            [
                r["variant"],
                r["terms"],
                fmt(r["ms_per_step"]),
                f"{r['ms_per_step'] / skip_rows[0]['ms_per_step']:.2f}×",
            ]
            for r in skip_rows
        ],
    )
    node_table = (
        markdown_table(
            ["N", "~/points subscriber", "tick wall (ms)", "ms/step", "real-time factor"],
            [
                [
                    r["N"],
                    "yes" if r["subscriber"] else "no",
                    fmt(r["tick_ms"]),
                    fmt(r["ms_per_step"]),
                    fmt(r["rtf"]),
                ]
                for r in node_rows
            ],
        )
        if node_rows
        else "(not run: --quick, or rclpy missing)"
    )
    text = (
        f"# scaling — {machine()}\n\nms per step (min of 3); a blank cell: the previous size "
        "exceeded "
        f"the {budget:g} s/step budget.\n\n{table}\n\nns per particle per "
        f"step:\n\n{per_particle}\n\n"
        f"## Symplectic Euler against the memory-bandwidth limit\n\nA step's compulsory traffic "
        f"(each array it reads and writes, once) over a STREAM triad's bandwidth on arrays of the "
        f"same total size, every core; far beyond the caches (768 MB) the triad gives "
        f"{dram / 1e9:.1f} GB/s.\n\n{bound_table}\n\n## What skipping buys (N = {n_skip}, "
        "symplectic Euler, "
        f"dt = 1 ms)\n\n{skip_table}\n\n## The node with and without a ~/points subscriber (60 "
        "Hz, "
        "dt = 1 ms, the hanging_provot scene's strain limit 0.1; the cloud is built only when "
        f"subscribed)\n\n{node_table}\n\n(run time {time.perf_counter() - t_start:.0f} s)\n"
    )
    (out / "scaling.md").write_text(text)
    print(text)
    return {"rows": rows, "exponents": exponents, "skipping": skip_rows, "node": node_rows}


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
