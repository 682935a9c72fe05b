"""``cloth-sim bench stability``: the largest stable dt per integrator, measured against linear
theory, and stress scenarios that jolt a running simulation.

Scene: hang16 (16×16, 1 m, 0.01 kg particles, two corners pinned) with k ∈ {1e2, 1e3, 1e4, 1e5} N/m
for every family and spring damping c = 2ζ·√(k·m) for damping ratios ζ ∈ {0, 0.01, 0.1} (ζ of one
spring holding one particle). A run is unstable if within the horizon the simulator's guard trips
(non-finite, speed or coordinate runaway), the kinetic energy exceeds 100·M·g·W (M the cloth's
mass, W its width), or any structural/shear strain exceeds 100 %. The horizon is 1 s, shortened to
20 000 steps for tiny steps (explicit Euler without damping, which has no stable step at all).
Bisection in log dt to 2 %. Linear theory: ``Simulator.stable_dt()`` — ω_max from a sparse
eigensolver and each method's amplification matrix with the fastest mode's damping.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..simulator import SimulationDiverged, Simulator
from ._out import G, fmt, hang16, machine, markdown_table, progress, pyplot, write_rows

METHODS = ["explicit_euler", "symplectic_euler", "midpoint", "rk4", "verlet", "kang"]
UNCONDITIONAL = ["implicit_euler", "implicit_euler_prefactored", "liu2013", "xpbd"]
MASS, WIDTH = 0.01, 1.0
CAP_DT = 0.05


def damping_for(k: float, zeta: float) -> float:
    return 2.0 * zeta * math.sqrt(k * MASS)


def _steps(dt: float, horizon: float, max_steps: int) -> int:
    """Steps a probe takes: the horizon, capped at ``max_steps``."""
    return int(min(max_steps, math.ceil(horizon / dt)))


def _runaway(sim) -> str:
    """Why the state counts as blown up ('' if it does not): kinetic energy above 100·M·g·W, or a
    structural/shear strain above 100 %."""
    e_max = 100.0 * float(np.sum(sim.model.masses)) * 9.81 * WIDTH
    if sim.energy()["kinetic"] > e_max:
        return f"kinetic energy > {e_max:.0f} J at t={sim.time:.3g} s"
    if sim.max_strain() > 1.0:
        return f"strain > 100 % at t={sim.time:.3g} s"
    return ""


def survives(
    name: str, k: float, zeta: float, dt: float, horizon: float, max_steps: int
) -> tuple[bool, float, str]:
    """(stable, horizon actually simulated, reason if not)."""
    sim = Simulator(hang16(k, damping_for(k, zeta)), integrator=name, dt=dt, gravity=G)
    n = _steps(dt, horizon, max_steps)
    chunk = max(1, n // 50)
    done = 0
    try:
        while done < n:
            m = min(chunk, n - done)
            sim.step(m)
            done += m
            why = _runaway(sim)
            if why:
                return False, done * dt, why
    except SimulationDiverged:
        return False, done * dt, f"guard: diverged at t={sim.time:.3g} s"
    return True, n * dt, ""


def largest_stable_dt(name, k, zeta, linear, horizon, max_steps, rtol) -> dict:
    def ok(dt):
        return survives(name, k, zeta, dt, horizon, max_steps)

    guess = linear if 0 < linear < math.inf else 1e-4
    hi = min(guess * 1.5, CAP_DT)
    stable, _, _ = ok(hi)
    while stable and hi < CAP_DT:
        hi = min(hi * 2, CAP_DT)
        stable, _, _ = ok(hi)
    if stable:
        return {"measured_dt": math.inf, "note": f"stable at the cap {CAP_DT} s"}
    lo = hi / 2
    while True:
        stable, _, why = ok(lo)
        if stable:
            break
        lo /= 2
        if lo < guess / 64:
            # a failure that no step size cures is the physics meeting a criterion (e.g. a soft
            # cloth stretching past 100 % under its own weight), not an instability: no limit to
            # report
            return {
                "measured_dt": math.nan,
                "note": f"fails at every dt down to {2 * lo:.2g} s ({why}): "
                f"the criterion is met by the motion itself",
            }
    while hi / lo > 1 + rtol:
        mid = math.sqrt(lo * hi)
        if ok(mid)[0]:
            lo = mid
        else:
            hi = mid
    simulated = _steps(lo, horizon, max_steps) * lo  # what the stable probe at lo simulated
    note = "" if simulated >= horizon * 0.999 else f"horizon {simulated:.3g} s ({max_steps} steps)"
    return {"measured_dt": lo, "unstable_dt": hi, "note": note}


# -------------------------------------------------------------------------------- stress scenarios
def _pins(sim) -> np.ndarray:
    return np.flatnonzero(sim.model.pinned)


def _gust(sim):
    sim.wind = (0.0, 0.0, 0.5)
    sim.step(int(round(0.2 / sim.dt)))
    sim.wind = None


def _kick(sim):
    rng = np.random.default_rng(7)
    v = np.array(sim.velocities) + rng.normal(scale=3.0, size=sim.velocities.shape)
    v[_pins(sim)] = 0.0
    sim.velocities = v


def _yank(sim):
    pin = int(_pins(sim)[0])
    sim.move_pins(sim.positions[[pin]] + np.array([[0.3, 0.0, 0.0]]), [pin])


def _double_dt(sim):
    sim.dt = 2 * sim.dt


def _switch(sim):
    sim.set_integrator(
        {"rk4": "verlet", "implicit_euler_prefactored": "implicit_euler"}.get(
            sim.integrator, "rk4"
        )
    )


def _stiffen(sim):
    for fam in ("structural", "shear", "bend"):
        sim.set_stiffness(fam, 10 * float(sim.stiffness(fam).max()))


SCENARIOS = [
    ("wind gust 0.5 N/particle for 0.2 s", _gust),
    ("velocity kick σ = 3 m/s", _kick),
    ("pinned corner yanked 0.3 m in one step", _yank),
    ("dt doubled", _double_dt),
    ("integrator switched", _switch),
    ("stiffness ×10", _stiffen),
]
STRESS_SETUPS = [
    ("symplectic_euler", 1e-3),
    ("rk4", 1e-3),
    ("implicit_euler_prefactored", 1.0 / 100),
]


def stress(name, dt, event, after: float) -> dict:
    sim = Simulator(hang16(1000.0, damping_for(1000.0, 0.05)), integrator=name, dt=dt, gravity=G)
    sim.advance(0.5)
    try:
        event(sim)
        end = sim.time + after
        while sim.time < end:
            sim.step(max(1, int(0.05 / sim.dt)))
            if _runaway(sim):
                return {
                    "survived": False,
                    "what": f"kinetic energy or strain ran away (t={sim.time:.3g} s) below "
                    f"the guard's speed limit; stable_dt {sim.stable_dt():.3g} s, "
                    f"dt {sim.dt:.3g} s",
                }
    except SimulationDiverged as e:
        return {
            "survived": False,
            "what": "the guard restored the last good state and raised SimulationDiverged "
            f"(step {str(e).split(' diverged')[0].split('step ')[-1]}); "
            f"stable_dt {sim.stable_dt():.3g} s, dt {sim.dt:.3g} s",
        }
    return {"survived": True, "what": f"max strain {sim.max_strain():.3f} at the end"}


def plot(rows: list[dict], zetas: list[float], methods: list[str], path: Path) -> None:
    """Measured (solid) against linear theory (dashed) per damping ratio; open markers: a horizon
    cut short by the step cap, where "stable" means only "survived that long"."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(zetas), figsize=(6 * len(zetas), 4.6), squeeze=False)
    for ax, zeta in zip(axes[0], zetas):
        for name in methods:
            rs = [
                r
                for r in rows
                if r["integrator"] == name
                and r["zeta"] == zeta
                and 0 < r["measured_dt"] < math.inf
            ]
            if not rs:
                continue
            (line,) = ax.loglog(
                [r["k"] for r in rs], [r["measured_dt"] for r in rs], "-", label=f"{name} measured"
            )
            for r in rs:
                cut = "horizon" in (r.get("note") or "")
                ax.plot(
                    r["k"],
                    r["measured_dt"],
                    "o",
                    color=line.get_color(),
                    markerfacecolor="none" if cut else line.get_color(),
                )
            lin = [(r["k"], r["linear_dt"]) for r in rs if 0 < r["linear_dt"] < math.inf]
            if lin:
                ax.loglog(*zip(*lin), "--", color=line.get_color(), alpha=0.6)
        ax.set_xlabel("spring stiffness k (N/m)")
        ax.set_ylabel("largest stable dt (s)")
        ax.set_title(
            f"hang16, ζ = {zeta:g} (dashed: linear theory; open: horizon cut short)", fontsize=9
        )
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(out: Path, quick: bool = False) -> dict:
    t_start = time.perf_counter()
    ks = [1e3] if quick else [1e2, 1e3, 1e4, 1e5]
    zetas = [0.0] if quick else [0.0, 0.01, 0.1]
    methods = ["symplectic_euler", "rk4"] if quick else METHODS
    horizon, max_steps, rtol = (0.3, 3000, 0.05) if quick else (1.0, 20000, 0.02)
    rows = []
    jobs = [
        (m, k, z) for z in zetas for k in ks for m in methods + ([] if quick else UNCONDITIONAL)
    ]
    for name, k, zeta in progress(jobs, "stability"):
        sim = Simulator(hang16(k, damping_for(k, zeta)), integrator=name, dt=1e-4, gravity=G)
        linear = sim.stable_dt()
        omega, _ = sim.fastest_mode()
        row = {"integrator": name, "k": k, "zeta": zeta, "omega_max": omega, "linear_dt": linear}
        if name in UNCONDITIONAL:
            stable, _, why = survives(name, k, zeta, CAP_DT, horizon, max_steps)
            row.update(
                measured_dt=math.inf if stable else math.nan,
                note=f"stable at {CAP_DT} s" if stable else why,
            )
        else:
            row.update(largest_stable_dt(name, k, zeta, linear, horizon, max_steps, rtol))
        row["ratio"] = (
            row["measured_dt"] / linear
            if 0 < linear < math.inf and math.isfinite(row["measured_dt"])
            else math.nan
        )
        if name == "explicit_euler":
            row["seed_claim_dt"] = 0.4 * math.pi * math.sqrt(MASS / k)
        rows.append(row)

    stress_rows = []
    setups = STRESS_SETUPS[:1] if quick else STRESS_SETUPS
    scen = SCENARIOS[:2] if quick else SCENARIOS
    for (name, dt), (label, event) in progress([(s, e) for s in setups for e in scen], "stress"):
        r = stress(name, dt, event, 0.3 if quick else 1.0)
        stress_rows.append({"integrator": name, "dt": dt, "scenario": label, **r})
    write_rows(out, "stability", rows, {"stress": stress_rows, "horizon_s": horizon})

    plot(rows, zetas, methods, out / "stability.png")

    table = markdown_table(
        [
            "integrator",
            "k (N/m)",
            "ζ",
            "ω_max (rad/s)",
            "linear limit (s)",
            "measured (s)",
            "measured/linear",
            "seed: 0.4π√(m/k)",
            "note",
        ],
        [
            [
                r["integrator"],
                f"{r['k']:g}",
                r["zeta"],
                fmt(r["omega_max"], 4),
                fmt(r["linear_dt"]),
                fmt(r["measured_dt"]),
                fmt(r["ratio"]),
                fmt(r.get("seed_claim_dt")),
                r.get("note", ""),
            ]
            for r in rows
        ],
    )
    stress_table = markdown_table(
        ["integrator", "dt (s)", "scenario", "survived", "what happened"],
        [
            [
                r["integrator"],
                f"{r['dt']:.3g}",
                r["scenario"],
                "yes" if r["survived"] else "no",
                r["what"],
            ]
            for r in stress_rows
        ],
    )
    text = (
        f"# stability, hang16 — {machine()}\n\nHorizon {horizon:g} s (≤ {max_steps} steps), "
        "bisection to "
        f"{100 * rtol:g} %.\n\n{table}\n\n## Stress scenarios (k = 1e3, ζ = 0.05, 0.5 s settled "
        "first)\n\n"
        f"{stress_table}\n\n(run time {time.perf_counter() - t_start:.0f} s)\n"
    )
    (out / "stability.md").write_text(text)
    print(text)
    return {"rows": rows, "stress": stress_rows}
