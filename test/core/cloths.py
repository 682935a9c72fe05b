"""The core tests' cloths and closed forms (shared by the test modules of this folder)."""

import math

import numpy as np

from cloth_sim import ClothModel, Simulator
from cloth_sim.scene import load_scene


def one_spring(k=100.0, m=1.0, L=1.0, amplitude=0.1, damping=0.0):
    """Particle 0 pinned at the origin, particle 1 free at L + amplitude on the x axis."""
    return ClothModel.from_springs(
        positions=[[0, 0, 0], [L + amplitude, 0, 0]],
        masses=[m, m],
        springs=[[0, 1]],
        stiffness=[k],
        damping=[damping],
        rest_lengths=[L],
        pinned=[0],
    )


def cloth16(k=1000.0, damping=0.0, model="provot"):
    """The tests' 16×16 cloth: 1 m square, k for every family, 0.01 kg particles, two corners
    pinned."""
    return ClothModel.grid(
        16, 16, 1.0 / 15, 0.01, stiffness=k, damping=damping, pinned=[(0, 0), (0, -1)], model=model
    )


def springy_fold(self_collision=True, **kw):
    """The fold scene at 12×12 on the per-family springs and mass it had before it took cotton
    (1000 N/m, bend 10; 0.04 kg particles): stiff and heavy enough to fold over itself in 1.5 s."""
    return load_scene("fold").build_simulator(
        rows=12,
        cols=12,
        spacing=1.0 / 11,
        particle_mass=0.04,
        material=None,
        stiffness={"structural": 1000.0, "shear": 1000.0, "bend": 10.0},
        damping={"structural": 0.02, "shear": 0.02, "bend": 0.005},
        self_collision=self_collision,
        **kw,
    )


def free_cloth(rng, rows=6, cols=6, damping=0.5, drift=(0.3, -0.1, 0.5)):
    """An unpinned 6×6 cloth and random initial velocities around a common ``drift``."""
    model = ClothModel.grid(rows, cols, 0.1, 0.01, stiffness=200.0, damping=damping)
    v0 = rng.normal(scale=0.2, size=(rows * cols, 3)) + np.asarray(drift)
    return model, v0


def free_fall(sim, v0, steps):
    """Give ``sim`` the velocities ``v0`` and take ``steps``. Returns the centre of mass then, the
    closed form ``x0 + v0·t + g·t²/2`` of the centre of mass under gravity alone, and ``t``."""
    m = sim.model.masses[:, None]
    x0 = (m * sim.positions).sum(0) / m.sum()
    vc = (m * np.asarray(v0)).sum(0) / m.sum()
    sim.velocities = v0
    sim.step(steps)
    t = sim.time
    return (m * sim.positions).sum(0) / m.sum(), x0 + vc * t + 0.5 * sim.gravity * t * t, t


def oscillator_order(name, dts, options=None) -> tuple[float, list]:
    """The observed order of ``name`` on :func:`one_spring` without gravity: the slope of the
    largest error of ``x(t) = L + A cos ωt`` over 1 s against ``dts`` (log–log), and the errors."""
    errs = []
    for dt in dts:
        sim = Simulator(
            one_spring(),
            integrator=name,
            dt=dt,
            gravity=(0.0, 0.0, 0.0),
            integrator_options=options,
        )
        err = 0.0
        for _ in range(round(1.0 / dt)):
            sim.step()
            err = max(err, abs(sim.positions[1, 0] - (1.0 + 0.1 * math.cos(10.0 * sim.time))))
        errs.append(err)
    return float(np.polyfit(np.log(dts), np.log(errs), 1)[0]), errs
