"""ms/step of integrators on the hanging_provot scene at several grid sizes, side by side in one
process."""

from __future__ import annotations

import os
import platform
import time

import numpy as np

from ..scene import load_scene
from .crossings import crossings


def time_steps(sim, seconds: float = 1.0, repeats: int = 3) -> float:
    """Minimum over ``repeats`` of the mean wall time of one step (s), after a warm-up."""
    sim.step(5)  # warm-up (numba caches, buffers)
    n = 5
    while True:  # find a batch size that takes about seconds/repeats
        t = time.perf_counter()
        sim.step(n)
        el = time.perf_counter() - t
        if el > seconds / repeats / 4 or n > 1_000_000:
            break
        n *= 4
    n = max(1, int(n * (seconds / repeats) / max(el, 1e-9)))
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        sim.step(n)
        best = min(best, (time.perf_counter() - t) / n)
    return best


def print_step_table(sizes, names, seconds: float = 1.0) -> list[dict]:
    scene = load_scene("hanging_provot")
    print(
        f"# hanging_provot scene ({scene.source}) resized to N×N over 1 m; k/m as in the scene, "
        f"dt={scene.dt} s, "
        f"strain limit {scene.strain_limit} ({scene.strain_limit_method}); "
        f"{platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores; min of 3"
    )
    print(
        "| N | particles | integrator | ms/step, no strain limit | ms/step, strain limit | "
        "force evals/step |"
    )
    print("|---|---|---|---|---|---|")
    rows = []
    tau = scene.strain_limit
    for n in sizes:
        for name in names:
            scene.integrator = name
            sim = scene.build_simulator(rows=n, cols=n, spacing=1.0 / (n - 1))
            sim.advance(0.5)  # past the release, into the hanging motion
            sim.strain_limit = None
            e0, s0 = sim.force_evaluations, sim.steps_taken
            plain = 1e3 * time_steps(sim, seconds)
            evals = (sim.force_evaluations - e0) / max(sim.steps_taken - s0, 1)
            sim.strain_limit = tau
            limited = 1e3 * time_steps(sim, seconds)
            rows.append(
                {"N": n, "integrator": name, "ms_per_step": plain, "ms_per_step_strain": limited}
            )
            print(
                f"| {n} | {n * n} | {name} | {plain:.3f} | {limited:.3f} | {evals:.0f} |",
                flush=True,
            )
    return rows


IMPLICIT_VARIANTS = (
    ("implicit_euler", {"solver": "cg"}, "implicit_euler (CG)"),
    ("implicit_euler", {"solver": "direct"}, "implicit_euler (direct)"),
    ("implicit_euler_prefactored", {}, "implicit_euler_prefactored"),
    ("kang", {}, "kang"),
    ("liu2013", {}, "liu2013 (10 iterations)"),
    ("liu2013", {"iterations": 10, "chebyshev": True}, "liu2013 (10, Chebyshev)"),
    ("xpbd", {}, "xpbd (10 substeps)"),
)


def print_implicit_table(sizes, dt: float, seconds: float = 1.0) -> list[dict]:
    """ms/step of the implicit methods (and the linear solver behind them) at a large step, on the
    hanging_provot scene at N×N (the 1 m, 10.24 kg cloth: spacing 1/(N−1), mass 10.24/N², as the
    strain and node benchmarks), each also as a multiple of a symplectic Euler step of the same
    cloth timed in the same run (at dt = 0.1 ms, where it is stable at every size: a step's cost
    does not depend on dt; at 1 ms, 81×81 without the strain limit diverges)."""
    from ..simulator import SimulationDiverged

    print(
        f"# hanging_provot scene resized to N×N over 1 m and 10.24 kg, dt={dt:.6g} s, no strain "
        f"limit; {platform.processor() or platform.machine()}, {os.cpu_count()} cores; min of 3 "
        "after "
        f"0.5 s of simulated warm-up; × a symplectic Euler step of the same cloth"
    )
    print(
        "| N | method | ms/step | × a symplectic step | mean CG iterations/step | factorisations "
        "| note |"
    )
    print("|---|---|---|---|---|---|---|")
    rows = []
    for n in sizes:
        reference = _hanging(n, strain_limit=None, integrator="symplectic_euler", dt=1e-4)
        reference.advance(0.05)
        base = 1e3 * time_steps(reference, seconds)
        print(f"| {n} | symplectic_euler (dt = 0.1 ms) | {base:.3f} | 1 |  |  |  |", flush=True)
        for name, options, label in IMPLICIT_VARIANTS:
            sim = _hanging(
                n, strain_limit=None, integrator=name, dt=dt, integrator_options=options
            )
            row = {
                "N": n,
                "method": label,
                "ms_per_step": float("nan"),
                "cg_iterations": None,
                "factorizations": None,
                "note": "",
                "symplectic_ms": base,
            }
            try:
                sim.advance(0.5)
                before = sim.integrator_stats
                s0 = sim.steps_taken
                row["ms_per_step"] = 1e3 * time_steps(sim, seconds)
                after = sim.integrator_stats
                if "cg_iterations" in after and options.get("solver") == "cg":
                    row["cg_iterations"] = (after["cg_iterations"] - before["cg_iterations"]) / (
                        sim.steps_taken - s0
                    )
                row["factorizations"] = after.get("factorizations")
            except SimulationDiverged:
                row["note"] = f"diverged at t = {sim.time:.3f} s"
            rows.append(row)
            cg = "" if row["cg_iterations"] is None else f"{row['cg_iterations']:.1f}"
            fac = "" if row["factorizations"] is None else str(row["factorizations"])
            ms = "—" if row["note"] else f"{row['ms_per_step']:.3f}"
            ratio = "—" if row["note"] else f"{row['ms_per_step'] / base:.0f}"
            print(f"| {n} | {label} | {ms} | {ratio} | {cg} | {fac} | {row['note']} |", flush=True)
    return rows


def print_blowup_table(size: int = 32) -> list[dict]:
    """How long a step that blows up holds the caller, per integrator, on the hanging_provot cloth
    at N×N: from the call of the failing ``step()`` to its :class:`SimulationDiverged` (guard,
    restore of the state before the step, message). The stability analysis is not known yet (a
    fresh model), which is the worst case: the error path never computes it. Conditionally stable
    methods run at 10× their stable dt (measured on a twin model), the unconditionally stable ones
    with the guard's speed bound lowered to 0.5 m/s."""
    from .. import integrators
    from ..integrators.base import Stability
    from ..simulator import SimulationDiverged

    scene = load_scene("hanging_provot")
    spacing = 1.0 / (size - 1)
    print(
        f"# a blow-up's cost: hanging_provot scene at {size}×{size}, strain limit off; "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"
    )
    print(
        "| integrator | dt (s) | steps before the blow-up | ms in the failing step() | "
        "ms per normal step | message says |"
    )
    print("|---|---|---|---|---|---|")
    rows = []
    for name in integrators.available():
        twin = scene.build_simulator(
            rows=size, cols=size, spacing=spacing, integrator=name, strain_limit=None
        )
        unconditional = integrators.get(name).stability is Stability.UNCONDITIONAL
        dt = 1.0 / 60 if unconditional else min(1.0, 10.0 * twin.stable_dt()) or 1e-3
        sim = scene.build_simulator(
            rows=size, cols=size, spacing=spacing, integrator=name, dt=dt, strain_limit=None
        )
        if unconditional:
            sim.max_speed = 0.5
        steps, normal, failing, message = 0, 0.0, float("nan"), ""
        while steps < 100_000:
            t = time.perf_counter()
            try:
                sim.step()
            except SimulationDiverged as e:
                failing = time.perf_counter() - t
                message = (
                    "stable_dt not computed" if "not computed" in str(e) else "stable_dt known"
                )
                break
            normal += time.perf_counter() - t
            steps += 1
        row = {
            "integrator": name,
            "dt": dt,
            "steps": steps,
            "failing_ms": 1e3 * failing,
            "step_ms": 1e3 * normal / max(steps, 1),
            "message": message,
        }
        rows.append(row)
        print(
            f"| {name} | {dt:.3g} | {steps} | {row['failing_ms']:.2f} | {row['step_ms']:.3f} | "
            f"{message} |",
            flush=True,
        )
    return rows


def _hanging(n: int, **kw):
    """The hanging_provot scene at N×N: the same 1 m, 10.24 kg cloth (spacing 1/(N−1), mass
    10.24/N²)."""
    return load_scene("hanging_provot").build_simulator(
        rows=n, cols=n, spacing=1 / (n - 1), particle_mass=10.24 / n**2, **kw
    )


def _ms_per_step(sim, seconds: float, every_10=None) -> float:
    """ms per step over ``seconds`` of simulated time, in bursts of 10 (``every_10`` runs after
    each, outside the timing)."""
    wall, steps = 0.0, 0
    while sim.time < seconds - 1e-9:
        t = time.perf_counter()
        sim.step(10)
        wall += time.perf_counter() - t
        steps += 10
        if every_10:
            every_10()
    return 1e3 * wall / steps


def print_strain_limit_table(sizes=(32, 64), seconds: float = 3.0, tau: float = 0.1) -> list[dict]:
    """The hanging_provot scene at N×N (the 1 m, 10.24 kg cloth: spacing 1/(N−1), mass 10.24/N²)
    over ``seconds``: worst structural/shear strain (sampled every 10 steps) and ms/step without
    the strain limit, with Provot's passes alone, with long-range attachments at 20 (the default),
    10 and 5 passes, and with the projection method; the cost ratios to the run without, measured
    in one process."""
    print(
        f"# strain limit τ = {tau} on the hanging_provot scene, {seconds:g} s, symplectic Euler "
        f"dt = 1 ms; {platform.machine()}, {os.cpu_count()} cores"
    )
    print("| N | method | worst strain | ms/step | × the step without |")
    print("|---|---|---|---|---|")
    rows = []
    for n in sizes:
        base = None
        for label, kw in (
            ("off", dict(strain_limit=None)),
            (
                "provot (20 passes)",
                dict(
                    strain_limit=tau, strain_limit_long_range=False, strain_limit_method="provot"
                ),
            ),
            (
                "provot + long-range attachments (20 passes)",
                dict(strain_limit=tau, strain_limit_method="provot"),
            ),
            (
                "provot + long-range attachments, 10 passes",
                dict(strain_limit=tau, strain_limit_passes=10, strain_limit_method="provot"),
            ),
            (
                "provot + long-range attachments, 5 passes",
                dict(strain_limit=tau, strain_limit_passes=5, strain_limit_method="provot"),
            ),
            (
                "projection (Goldenthal et al. 2007) after the attachments",
                dict(strain_limit=tau, strain_limit_method="projection"),
            ),
        ):
            _hanging(n, **kw).step(
                5
            )  # load its kernels first (the first row's cost was 0.08–0.19 ms)
            sim = _hanging(n, **kw)
            samples = []
            ms = _ms_per_step(
                sim, seconds, lambda: samples.append(float(sim.strains(limited_only=True).max()))
            )
            worst = max(samples)
            base = base or ms
            rows.append({"N": n, "method": label, "worst": worst, "ms": ms})
            print(f"| {n} | {label} | {worst:.4f} | {ms:.3f} | {ms / base:.2f} |", flush=True)
    return rows


def print_contacts_table(sizes=(32, 64), seconds: float = 1.5) -> list[dict]:
    """The hanging_provot scene at N×N (as :func:`print_strain_limit_table`), swinging against a
    ball and onto a floor 0.7 m below its pins: ms/step without contacts, with the plane and the
    sphere, and with self-collision as well; each a ratio to the contact-free step of the same run,
    with how many particles touched a collider and how many self-collision pairs the last step
    had."""
    from ..contact.colliders import Plane, Sphere

    print(
        f"# contacts on the hanging_provot scene, {seconds:g} s, symplectic Euler dt = 1 ms, "
        f"strain limit 0.1; {platform.machine()}, {os.cpu_count()} cores"
    )
    print("| N | contacts | ms/step | × the step without | touching (last step) | self pairs |")
    print("|---|---|---|---|---|---|")
    rows = []
    for n in sizes:
        base = None
        for label, kw in (
            ("none", {}),
            ("plane + sphere", dict(colliders=True)),
            ("plane + sphere + self-collision", dict(colliders=True, self_collision=True)),
        ):
            cols = (
                [
                    Plane(normal=(0, 0, 1), offset=-0.7, friction=0.5),
                    Sphere(center=(0.5, 0.25, -0.5), radius=0.2, friction=0.3),
                ]
                if kw.get("colliders")
                else []
            )
            sim = _hanging(n, colliders=cols, self_collision=kw.get("self_collision", False))
            ms = _ms_per_step(sim, seconds)
            base = base or ms
            touching, pairs = sim.contact_counts
            rows.append({"N": n, "contacts": label, "ms": ms, "ratio": ms / base})
            print(
                f"| {n} | {label} | {ms:.3f} | {ms / base:.2f} | {touching} | {pairs} |",
                flush=True,
            )
    return rows


def print_garment_contacts_table(scenes=("tshirt",), seconds: float = 10.0, settle: float = 2.0):
    """Each scene as it ships (a garment; ``vbd`` resolves self-contact inside its step),
    self-contact off, on, and on as stiff as the cloth (``self_contact_stiffness='cloth'``), side
    by side in one process: after ``settle`` s of its drop, each steps ``seconds`` of simulated
    time, the three alternating in half-second bursts. Per row: ms a step, the ratio to the step
    without, candidate searches a step, the median vertex's motion a step over the last second
    (a garment at rest: near zero), how far its layers heave (each vertex's vertical range over
    the last second, the 99th percentile over the vertices: a fraction of a millimetre for a
    garment at rest), the kinetic energy at the end, and with self-contact the crossings over
    the whole run,
    counted by the independent check (:mod:`.crossings`) on every step of a second run of the
    same scene (the same steps, bit for bit; kept out of the timed run, whose caches it would
    stir)."""
    print(
        f"# self-contact on garments as they ship, {seconds:g} s each after {settle:g} s of "
        f"settling; off, on, and on as stiff as the cloth, alternating; {platform.machine()}, "
        f"{os.cpu_count()} cores"
    )
    print(
        "| scene | self-contact | ms/step | × the step without | searches/step | "
        "median motion/step (mm) | heave, p99 (mm) | kinetic energy (J) | crossings |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for name in scenes:
        scene = load_scene(name)
        cases = {
            "off": dict(self_collision=False),
            "on": dict(self_collision=True),
            "on, 'cloth'": dict(
                self_collision=True,
                integrator_options={**scene.vbd_options(), "self_contact_stiffness": "cloth"},
            ),
        }
        runs = {case: scene.build_simulator(**kw) for case, kw in cases.items()}
        end = settle + seconds
        for sim in runs.values():
            sim.advance(settle)
        state = {
            case: dict(wall=0.0, steps=0, moves=[], low=None, high=None, searches=_searches(sim))
            for case, sim in runs.items()
        }
        burst = max(1, round(0.5 / runs["on"].dt))
        while any(sim.time < end - 1e-9 for sim in runs.values()):
            for case, sim in runs.items():
                st = state[case]
                for _ in range(burst):
                    if sim.time >= end - 1e-9:
                        break
                    x0 = sim.positions.copy()
                    t = time.perf_counter()
                    sim.step()
                    st["wall"] += time.perf_counter() - t
                    st["steps"] += 1
                    if sim.time > end - 1.0:
                        st["moves"].append(np.median(np.linalg.norm(sim.positions - x0, axis=1)))
                        z = sim.positions[:, 2]
                        first = st["low"] is None
                        st["low"] = z.copy() if first else np.minimum(st["low"], z)
                        st["high"] = z.copy() if first else np.maximum(st["high"], z)
        crossed = {"off": None}
        for case in ("on", "on, 'cloth'"):
            again = scene.build_simulator(**cases[case])
            tris, crossed[case] = again.model.triangles, 0
            while again.time < end - 1e-9:
                x0 = again.positions.copy()
                again.step()
                crossed[case] += len(crossings(x0, again.positions, tris))
        base = None
        for case, sim in runs.items():
            st = state[case]
            ms = 1e3 * st["wall"] / st["steps"]
            base = base or ms
            searched = (_searches(sim) - st["searches"]) / st["steps"]
            row = dict(
                scene=name, self_contact=case, ms=ms, ratio=ms / base, searches=searched,
                motion_mm=1e3 * float(np.mean(st["moves"])),
                heave_mm=1e3 * float(np.percentile(st["high"] - st["low"], 99)),
                kinetic=sim.energy()["kinetic"], crossings=crossed[case],
            )  # fmt: skip
            rows.append(row)
            print(
                f"| {name} | {case} | {ms:.2f} | {ms / base:.2f} | {searched:.2f} | "
                f"{row['motion_mm']:.4f} | {row['heave_mm']:.2f} | {row['kinetic']:.1e} | "
                f"{'—' if crossed[case] is None else crossed[case]} |",
                flush=True,
            )
    return rows


def _searches(sim) -> int:
    """The candidate searches ``vbd`` has made, whole or for the vertices that met their bounds
    (0 for another integrator)."""
    stats = sim.integrator_stats
    return int(stats.get("detections", 0)) + int(stats.get("local_detections", 0))
