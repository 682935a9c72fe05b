"""cloth_sim beside MuJoCo's flex cloth on the drape scene, in one process.

``cloth-sim bench flex-peer [--size 32] [--seconds 2]`` (``make bench-peers`` runs it). MuJoCo is
an optional extra (``requirements-peers.txt``), never installed by ``make test``.

The drape scene at N×N with its 1 m side and its 5.76 kg kept (the 24×24 scene's cloth, finer): a
cloth dropped flat from 0.6 m over a 0.25 m ball on a floor. MuJoCo 4.0 builds the same grid as a
``flexcomp`` (``type="grid"``, ``dim="2"``) of the same mass, its edges held by equality
constraints (MuJoCo's own way to a cloth that does not stretch: cloth_sim holds its springs with
the strain limit), ``implicitfast`` at each step given; cloth_sim runs its shipped method and the
two large-step ones at theirs. Figures: wall seconds per simulated second over the run after one
warm-up step, and where the cloth ends — its highest point against the ball's top (0.55 m; the
cloth's thickness, 5 mm, above it: a lower top means the cloth sank into the ball).
"""

from __future__ import annotations

import time

import numpy as np

from ..scene import load_scene

#: the drape scene's cloth: 24 × 24 particles of 0.01 kg
CLOTH_MASS = 5.76
#: the ball's top (its centre's height and radius in the scene)
BALL_TOP = 0.55
#: cloth_sim's runs: (integrator, dt, options)
OURS = (
    ("symplectic_euler", 1e-3, {}),
    ("liu2013", 1 / 240, {}),
    ("vbd", 1 / 60, {"iterations": 10}),
)
#: MuJoCo's steps (s)
MUJOCO_STEPS = (0.02, 0.005)


def flex_model(mujoco, n: int, dt: float):
    scene = load_scene("drape")
    ball, floor = scene.colliders
    centre, radius = ball[1]["center"], ball[1]["radius"]
    h = 1.0 / (n - 1)
    xml = f"""<mujoco>
  <option timestep="{dt!r}" integrator="implicitfast" solver="CG" tolerance="1e-6"/>
  <size memory="200M"/>
  <worldbody>
    <geom name="floor" type="plane" size="3 3 0.1" friction="{floor[1]["friction"]}"/>
    <geom name="ball" type="sphere" size="{radius}" pos="{" ".join(map(str, centre))}"
          friction="{ball[1]["friction"]}"/>
    <flexcomp name="cloth" type="grid" count="{n} {n} 1" spacing="{h!r} {h!r} {h!r}"
              pos="0.5 0.5 {scene.origin[2]}" radius="{scene.thickness}" dim="2"
              mass="{CLOTH_MASS}">
      <contact condim="3" selfcollide="none" solref="0.01 1"/>
      <edge equality="true"/>
    </flexcomp>
  </worldbody>
</mujoco>"""
    return mujoco.MjModel.from_xml_string(xml)


def _timed(step, seconds: float, dt: float) -> float:
    step()  # warm-up
    steps = int(round(seconds / dt))
    t = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - t) / (steps * dt)


def print_flex_table(n: int = 32, seconds: float = 2.0) -> int:
    try:
        import mujoco
    except ImportError:
        print(
            "mujoco is not installed: `make bench-peers` installs the pinned optional extra "
            "(requirements-peers.txt)"
        )
        return 1
    print(
        f"# the drape scene at {n}×{n} (1 m, {CLOTH_MASS} kg) over {seconds:g} s: MuJoCo "
        f"{mujoco.__version__} flex vs cloth_sim; top of the cloth at the end against the ball's "
        f"top, {BALL_TOP} m"
    )
    print("| run | step (s) | s per simulated s | the cloth's top (m) | worst strain |")
    print("|---|---|---|---|---|")
    for name, dt, options in OURS:
        sim = load_scene("drape").build_simulator(
            rows=n,
            cols=n,
            spacing=1.0 / (n - 1),
            material=None,  # MuJoCo's flex takes a mass and springs, not a fabric
            particle_mass=CLOTH_MASS / n**2,
            integrator=name,
            dt=dt,
            integrator_options=options,
        )
        cost = _timed(sim.step, seconds, dt)
        print(
            f"| cloth_sim {name} | {dt:.4g} | {cost:.3f} | {sim.positions[:, 2].max():.4f} | "
            f"{sim.strains(limited_only=True).max():.3f} |",
            flush=True,
        )
    for dt in MUJOCO_STEPS:
        m = flex_model(mujoco, n, dt)
        d = mujoco.MjData(m)
        cost = _timed(lambda: mujoco.mj_step(m, d), seconds, dt)
        x = d.flexvert_xpos
        top = float(x[:, 2].max()) if np.isfinite(x).all() else float("nan")
        print(
            f"| MuJoCo flex (implicitfast, edge equality) | {dt:g} | {cost:.3f} | {top:.4f} | – |",
            flush=True,
        )
    return 0
